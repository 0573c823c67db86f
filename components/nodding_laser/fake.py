"""The device side of the Nodding Laser: a fake nodding controller with its SICK LMS 211.

:class:`FakeNodLaser` speaks NLC v1 (``docs/protocols/nodding_laser.md``) over any byte
stream: it obeys the host's commands (nod rate, limits, start/stop, GOTO, status, SICK
commands forwarded to its LMS, which answers with real SICK telegrams), nods between
the limits as a triangle or sine wave at the commanded rate, and while the LMS streams
sends one SCAN frame per scan period (26.67 ms at 0.5 deg: 361 values, mm, 8 m mode).

Ranges come from a *source*, ``source(t, nod_deg, bearings_deg) -> ranges_m``: ``t`` is
the scan's start time (clock seconds), ``nod_deg`` the true elevation of the scan plane
per beam (encoder angle + the mount's ``offset_deg``), ``bearings_deg`` the SICK bearing
of each beam (0 = right, 90 = ahead). NaN, inf, <= 0 or beyond the 8 m mode's range
means no return. The default, :func:`flat_ground`, sees a level plane analytically; the
simulator plugs in ray casting.

Modelling choices (documented so a reader of a scan knows what is exact): the nod angle
of beam i is interpolated linearly between the angles at the scan's start and end by
beam index (the model the driver assumes; the LMS's interlaced sweeps and a turnaround
inside one scan are not modelled); a sweep started outside the limits first moves to the
nearest limit at the nod rate; ranges are rounded to millimetres after the optional
Gaussian noise; no-return beams carry code 0x1FFF.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

from afa.clock import Clock
from afa.codec import StreamDecoder
from afa.errors import EDevIO
from afa.fake import FakeDevice
from afa.kernels import compiled
from afa.transport import ByteStream
from components.nodding_laser.codec import (
    ACK,
    NAK,
    SCAN_VARIANTS,
    AckResult,
    CommandAck,
    ControllerState,
    ControllerStatus,
    FrameType,
    GotoAngle,
    HostCommand,
    MeasuredValues,
    NodHostCommandDecoder,
    OperatingModeReply,
    RangeUnit,
    RequestMeasuredValues,
    RequestStatus,
    SetNodLimits,
    SetNodRate,
    SickCommand,
    SickMessage,
    SickMode,
    SickReply,
    StartNodding,
    StopNodding,
    SwitchOperatingMode,
    SwitchVariant,
    VariantReply,
    encode_controller_message,
    encode_scan_frame,
    scan_bearings_deg,
)
from components.nodding_laser.component import SCAN_PERIODS

__all__ = ["FakeNodLaser", "RangeSource", "Waveform", "flat_ground", "NO_RETURN_WORD"]

@functools.cache
def _words_kernel() -> Callable[..., None] | None:
    """The compiled value-word loop (decision 0030), or None for the numpy form
    (:func:`afa.kernels.compiled`). Loaded on the first scan."""
    return compiled("components.nodding_laser._points_jit",  # type: ignore[no-any-return]
                    "words_kernel")


@functools.cache
def _beams(variant: tuple[int, int]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Bearings (deg) of a scan variant's beams and where each lies between the first (0)
    and the last (1); read-only, one pair per variant (sources may cache on them)."""
    count = next(n for n, v in SCAN_VARIANTS.items() if v == variant)
    bearings = scan_bearings_deg(count, *variant)
    fraction = np.arange(count) / max(count - 1, 1)
    bearings.flags.writeable = False
    fraction.flags.writeable = False
    return bearings, fraction


#: ``source(t, nod_deg per beam, bearings_deg) -> ranges in metres``.
RangeSource: TypeAlias = Callable[[float, npt.NDArray[np.float64], npt.NDArray[np.float64]],
                                  npt.ArrayLike]

#: The value word the fake sends for a beam without a return (8 m mode's top code).
NO_RETURN_WORD = 0x1FFF
_RANGE_BITS = 13
_MAX_COUNT = (1 << _RANGE_BITS) - 9  # 8183: the first no-return code
_PASSWORD = b"SICK_LMS"
_COMMAND_TYPES = {
    SetNodRate: FrameType.SET_NOD_RATE, SetNodLimits: FrameType.SET_NOD_LIMITS,
    StartNodding: FrameType.START_NODDING, StopNodding: FrameType.STOP_NODDING,
    GotoAngle: FrameType.GOTO_ANGLE, RequestStatus: FrameType.REQUEST_STATUS,
    SickCommand: FrameType.SICK_COMMAND,
}


class Waveform(StrEnum):
    TRIANGLE = "triangle"
    SINE = "sine"


def flat_ground(height_m: float) -> RangeSource:
    """A level ground plane ``height_m`` below the nod axis, seen analytically.

    A beam at bearing b on a scan plane of elevation n points along
    (sin b cos n, -cos b, sin b sin n); it meets z = -h at r = h / (-sin b sin n) when
    that is positive, and never otherwise.
    """

    def source(t: float, nod_deg: npt.NDArray[np.float64],
               bearings_deg: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        down = -np.sin(np.deg2rad(bearings_deg)) * np.sin(np.deg2rad(nod_deg))
        with np.errstate(divide="ignore"):
            return np.where(down > 1e-12, height_m / np.where(down > 1e-12, down, 1.0),
                            np.inf)

    return source


@dataclass
class _Motion:
    """The nod axis: what it does since ``t0``, starting from ``a0`` (encoder deg)."""

    state: ControllerState
    t0: float
    a0: float
    target: float = 0.0  # for MOVING
    rising: bool = True  # for NODDING: the sweep's direction at t0


class FakeNodLaser(FakeDevice[HostCommand]):
    """A nodding controller and its LMS 211 (device side of NLC v1 and SICK telegrams).

    ``source`` gives the ranges (default: flat ground 2 m below); ``offset_deg`` is the
    mount's misalignment, true elevation = encoder angle + offset (the host's
    ``LaserOffsetAngle`` corrects it); ``noise_m`` adds Gaussian range noise from
    ``rng`` (a seeded ``numpy.random.Generator`` keeps runs reproducible). The
    controller keeps its state (limits, rate, nodding, LMS mode) across connections,
    as the real one does.
    """

    name = "nodding-laser"

    def __init__(self, clock: Clock, *, source: RangeSource | None = None,
                 offset_deg: float = 0.0, waveform: Waveform | str = Waveform.TRIANGLE,
                 noise_m: float = 0.0, rng: np.random.Generator | None = None,
                 initial_angle_deg: float = 0.0) -> None:
        super().__init__(clock)
        self.source: RangeSource = source or flat_ground(2.0)
        self.offset_deg = offset_deg
        self.waveform = Waveform(waveform)
        self.noise_m = noise_m
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.boot = clock.monotonic()
        # controller state (firmware defaults: Table A.1's values, holding level)
        self.rate_deg_s = 15.0
        self.low_deg = -40.0
        self.high_deg = -10.0
        self.motion = _Motion(ControllerState.IDLE, self.boot, initial_angle_deg)
        self.faults = 0
        # LMS state
        self.streaming = False
        self.variant: tuple[int, int] = (180, 50)
        self.installation = False
        # counters and test hooks
        self.scan_counter = 0
        self.scans_sent = 0
        self._seq = 0
        self._corrupt_pending = 0
        self._current: list[ByteStream] = []

    # -- test and simulator hooks ------------------------------------------------------------
    def corrupt_scans(self, count: int = 1) -> None:
        """Flip one payload bit in each of the next ``count`` SCAN frames (the frame CRC
        then fails, as after line noise); the scan counter still advances."""
        self._corrupt_pending += count

    async def inject(self, data: bytes) -> None:
        """Write raw ``data`` (e.g. garbage) between frames on every open connection."""
        for stream in list(self._current):
            try:
                await stream.write(data)
            except EDevIO:
                pass

    @property
    def scan_period(self) -> float:
        return SCAN_PERIODS[self.variant[1]]

    # -- the nod axis ---------------------------------------------------------------------------
    def angle_at(self, t: float) -> float:
        """Encoder angle (deg) at time ``t`` (not before the last command)."""
        m = self.motion
        dt = max(0.0, t - m.t0)
        rate = self.rate_deg_s
        if m.state is ControllerState.MOVING:
            step = rate * dt
            if abs(m.target - m.a0) <= step:
                return m.target
            return m.a0 + math.copysign(step, m.target - m.a0)
        if m.state is not ControllerState.NODDING:
            return m.a0
        low, high = self.low_deg, self.high_deg
        span = high - low
        # outside the limits: move to the nearest one first, then sweep inward
        if m.a0 < low or m.a0 > high:
            entry = low if m.a0 < low else high
            approach = abs(entry - m.a0) / rate
            if dt < approach:
                return m.a0 + math.copysign(rate * dt, entry - m.a0)
            dt -= approach
            start, rising = entry, entry == low
        else:
            start, rising = m.a0, m.rising
        if self.waveform is Waveform.TRIANGLE:
            s0 = (start - low) if rising else 2 * span - (start - low)
            s = (s0 + rate * dt) % (2 * span)
            return low + (s if s <= span else 2 * span - s)
        mid, amplitude = (low + high) / 2, span / 2
        omega = math.pi * rate / span  # same period as the triangle: 2 span / rate
        cosine = max(-1.0, min(1.0, (mid - start) / amplitude))
        phase0 = math.acos(cosine) if rising else 2 * math.pi - math.acos(cosine)
        return mid - amplitude * math.cos(omega * dt + phase0)

    def _state_at(self, t: float) -> ControllerState:
        m = self.motion
        if m.state is ControllerState.MOVING and self.angle_at(t) == m.target:
            return ControllerState.IDLE
        return m.state

    def _set_motion(self, state: ControllerState, target: float = 0.0) -> None:
        now = self.clock.monotonic()
        angle = self.angle_at(now)
        rising = True
        if state is ControllerState.NODDING and self.motion.state is ControllerState.NODDING:
            rising = self.angle_at(now + 1e-3) >= angle  # keep the sweep's direction
        self.motion = _Motion(state, now, angle, target, rising)

    # -- FakeDevice hooks -----------------------------------------------------------------------
    def command_decoder(self) -> StreamDecoder[HostCommand]:
        return NodHostCommandDecoder()

    async def on_command(self, command: HostCommand, stream: ByteStream) -> None:
        result = AckResult.OK
        before = self._state_at(self.clock.monotonic())
        if isinstance(command, SetNodRate):
            if command.rate_udeg_per_s <= 0:
                result = AckResult.BAD_ARGUMENT
            else:
                self._set_motion(self.motion.state, self.motion.target)  # re-anchor
                self.rate_deg_s = command.rate_udeg_per_s / 1e6
        elif isinstance(command, SetNodLimits):
            if command.low_udeg >= command.high_udeg:
                result = AckResult.BAD_ARGUMENT
            elif before is ControllerState.NODDING:
                result = AckResult.BUSY
            else:
                self.low_deg, self.high_deg = command.low_udeg / 1e6, command.high_udeg / 1e6
        elif isinstance(command, StartNodding):
            self._set_motion(ControllerState.NODDING)
        elif isinstance(command, StopNodding):
            self._set_motion(ControllerState.IDLE)
        elif isinstance(command, GotoAngle):
            self._set_motion(ControllerState.MOVING, command.angle_udeg / 1e6)
        elif isinstance(command, SickCommand):
            result = await self._forward_to_lms(command, stream)
        if isinstance(command, RequestStatus) or self._state_at(self.clock.monotonic()) != before:
            await self._send(stream, self._status())
        await self._send(stream, CommandAck(_COMMAND_TYPES[type(command)], command.seq, result,
                                            self._next_seq()))

    async def produce(self, stream: ByteStream) -> None:
        self._current.append(stream)
        try:
            deadline = self.clock.monotonic()
            while True:
                period = self.scan_period
                deadline += period
                await self.clock.sleep_until(deadline)
                if self.streaming:
                    await self._send_scan(stream, deadline - period, deadline)
        finally:
            self._current.remove(stream)

    # -- the LMS -----------------------------------------------------------------------------
    async def _forward_to_lms(self, command: SickCommand, stream: ByteStream) -> AckResult:
        sick = command.command
        reply: SickMessage | None = None
        ack = ACK
        if isinstance(sick, SwitchOperatingMode):
            result = 0
            if sick.mode == SickMode.INSTALLATION:
                result = 0 if sick.password == _PASSWORD else 1
                self.installation = result == 0
            elif sick.mode == SickMode.MONITOR_STREAM_VALUES:
                self.streaming = True
            elif sick.mode == SickMode.MONITOR_REQUEST_VALUES:
                self.streaming = False
            elif sick.mode not in (SickMode.BAUD_9600, SickMode.BAUD_19200,
                                   SickMode.BAUD_38400, SickMode.BAUD_500000):
                ack = NAK
            if ack == ACK:
                reply = OperatingModeReply(result, 0x10)
        elif isinstance(sick, SwitchVariant):
            wanted = (sick.scan_angle_deg, sick.resolution_cdeg)
            accepted = wanted in SCAN_VARIANTS.values()
            if accepted:
                self.variant = wanted
                self.streaming = False  # the LMS stops streaming on a variant change
            reply = VariantReply(accepted, *self.variant, 0x10)
        elif isinstance(sick, RequestMeasuredValues):
            now = self.clock.monotonic()
            words = self._measure(now - self.scan_period, now)[1]
            reply = MeasuredValues(tuple(words.tolist()), RangeUnit.MM, 0x10, 0, _RANGE_BITS)
        else:
            ack = NAK  # commands this LMS model does not implement
        await self._send(stream, SickReply(ack, reply, self._next_seq()))
        return AckResult.OK

    def _measure(self, start: float, end: float) -> tuple[tuple[float, float],
                                                          npt.NDArray[np.uint16]]:
        """Encoder angles at both ends and the value words of the LMS's 0xB0 reply for
        one scan."""
        bearings, fraction = _beams(self.variant)
        count = bearings.size
        nod_start, nod_end = self.angle_at(start), self.angle_at(end)
        nod = (nod_start + self.offset_deg) + (nod_end - nod_start) * fraction
        ranges = np.ascontiguousarray(self.source(start, nod, bearings),
                                      dtype=np.float64).reshape(-1)
        if ranges.shape != bearings.shape:
            raise ValueError(f"range source returned {ranges.size} values for {count} beams")
        noisy = self.noise_m > 0
        noise = self.rng.normal(0.0, self.noise_m, ranges.shape) if noisy else ranges
        kernel = _words_kernel()
        if kernel is not None:  # the same words in one compiled loop (decision 0030)
            words = np.empty(count, dtype=np.uint16)
            kernel(ranges, noise, noisy, _MAX_COUNT, NO_RETURN_WORD, words)
            return (nod_start, nod_end), words
        if noisy:
            ranges = ranges + noise
        counts = np.rint(ranges * 1000.0)  # np.round without its Python wrapper
        good = (counts >= 1) & (counts < _MAX_COUNT)  # False for NaN and inf
        # (1 .. 8182 mm or the no-return word: all 16-bit)
        return (nod_start, nod_end), np.where(good, counts, NO_RETURN_WORD).astype(np.uint16)

    async def _send_scan(self, stream: ByteStream, start: float, end: float) -> None:
        (nod_start, nod_end), words = self._measure(start, end)
        # the bytes of encode_controller_message(NodScan(..., MeasuredValues(words))),
        # without a tuple of 361 ints
        frame = encode_scan_frame(self.scan_counter, max(0, round((start - self.boot) * 1e6)),
                                  round(nod_start * 1e6), round(nod_end * 1e6), words,
                                  seq=self._next_seq())
        self.scan_counter = (self.scan_counter + 1) & 0xFFFFFFFF
        if self._corrupt_pending:
            self._corrupt_pending -= 1
            damaged = bytearray(frame)
            damaged[len(damaged) // 2] ^= 0x10
            frame = bytes(damaged)
        self.scans_sent += 1
        await stream.write(frame)

    # -- controller frames ---------------------------------------------------------------------
    def _status(self) -> ControllerStatus:
        now = self.clock.monotonic()
        return ControllerStatus(self._state_at(now), self.faults, round(self.angle_at(now) * 1e6),
                                round(self.low_deg * 1e6), round(self.high_deg * 1e6),
                                round(self.rate_deg_s * 1e6),
                                max(0, round((now - self.boot) * 1e6)), self._next_seq())

    def _next_seq(self) -> int:
        seq, self._seq = self._seq, (self._seq + 1) & 0xFF
        return seq

    async def _send(self, stream: ByteStream, message: CommandAck | ControllerStatus
                    | SickReply) -> None:
        await stream.write(encode_controller_message(message))
