"""A fake MPC555 vehicle controller: the device side of ``docs/protocols/mpc555.md``.

One :class:`FakeMpc555` is one controller. Every ``open`` of its factory is another
connection to the same controller (Wheel Odometry and Vehicle Control each open one,
as both name ``/dev/ttyS0``): every connection receives every report and ACK, as on a
shared serial line, and commands from any connection act on the one shared state.

The controller, as the protocol describes it:

- ACKs every decoded command (NAKs per the mode table and range rules) and sends
  STATUS at power-on, at a reset and at once when mode, flags or faults change;
- keeps the mode (STOPPED, RUNNING, ARBITER, JOYSTICK), the e-stop, the limits, the
  four calibrations (START_VEHICLE is refused until all arrived) and the report
  intervals;
- turns SET_VELOCITY / SET_JOYSTICK_VELOCITY into a translation and a bicycle-model
  steering angle (clamped to SET_LIMITS, ACK LIMITED) and hands them to the *plant*;
- sends WHEEL_DISTANCE, SPEED and STATUS at the configured intervals, drift-free on
  the clock (``clock.call_at``);
- runs its own 500 ms link watchdog: started and no valid host frame for 500 ms ->
  pedal neutral, brake, STOPPED, WATCHDOG flag, immediate STATUS.

The plant is a callable ``plant(t, command) -> WheelTruth``: advance the vehicle to
time ``t`` under the command adopted at the previous call, adopt ``command`` from ``t``
on, and return the state at ``t``. The default :class:`FirstOrderPlant` applies the
drive and steering commands through first-order lags and integrates the front wheel
distances with the wheelbase and track; the simulator passes its own plant that drives
the simulated vehicle. Encoder counts are the truth distances quantised by the
physical wheel travel per count (``mm_per_count``), whatever calibration the host sent.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from afa.clock import Clock, TimerHandle
from afa.errors import EDevIO
from afa.fake import FakeDevice, RecentLog
from afa.tasks import spawn
from afa.transport import ByteStream, MemoryByteStream
from components.mpc555.codec import (
    CONTROLLER_WATCHDOG_MS,
    AckResult,
    Command,
    CommandAck,
    ConfigureReports,
    Faults,
    Heartbeat,
    Mode,
    Mpc555DeviceDecoder,
    Packet,
    PedalBreakpoint,
    Report,
    SequenceCounter,
    SetArbiter,
    SetJoystickVelocity,
    SetLimits,
    SetPedalCalibration,
    SetSteerCalibration,
    SetSteerPid,
    SetVelocity,
    SetWheelCalibration,
    SpeedReport,
    StartVehicle,
    StatusFlags,
    StatusReport,
    StopVehicle,
    WheelDistanceReport,
    encode_report,
    steering_angle,
)
from components.mpc555.parameters import WHEEL_DISTANCE_PER_COUNT

__all__ = ["FakeMpc555", "FirstOrderPlant", "DriveCommand", "WheelTruth", "Plant",
           "ReceivedCommand", "DEFAULT_PEDAL_TABLE", "DRIVE_TAU", "BRAKE_TAU", "STEER_TAU"]

log = logging.getLogger("afa.fake.mpc555")

DRIVE_TAU = 0.5
"""Time constant (s) of the hydrostatic drive's speed response to a new target."""
BRAKE_TAU = 0.3
"""Time constant (s) of the speed decaying to 0 with the brake applied."""
STEER_TAU = 0.15
"""Time constant (s) of the steering servo following its target angle."""
NEUTRAL_PEDAL = 2048

#: The controller's built-in pedal table (equal to the PedalParam default).
DEFAULT_PEDAL_TABLE = (PedalBreakpoint(-1000, 1250), PedalBreakpoint(0, 2048),
                       PedalBreakpoint(200, 2350), PedalBreakpoint(1000, 2750),
                       PedalBreakpoint(2000, 3250))
_DEFAULT_STEER = SetSteerCalibration(512, 75_000, 112, 912)
_DEFAULT_WHEEL = SetWheelCalibration(506_200, 506_200)
_DEFAULT_PID = SetSteerPid(4000, 500, 100)
_CALIBRATIONS = frozenset((SetWheelCalibration, SetSteerCalibration, SetPedalCalibration,
                           SetSteerPid))


@dataclass(frozen=True)
class DriveCommand:
    """What the controller asks of the vehicle: rear-axle speed and steering targets."""

    translation: float = 0.0  # m/s, forward +; 0 while stopped
    steering: float = 0.0  # rad, left +
    brake: bool = True
    pedal: int = NEUTRAL_PEDAL  # 12-bit actuator command


@dataclass(frozen=True)
class WheelTruth:
    """The vehicle's true state as the controller's sensors would see it."""

    time: float
    left_distance: float = 0.0  # m, cumulative, left front wheel
    right_distance: float = 0.0  # m, right front wheel
    left_speed: float = 0.0  # m/s
    right_speed: float = 0.0  # m/s
    speed: float = 0.0  # m/s, rear axle centre (the vehicle reference)
    steering: float = 0.0  # rad, front wheel angle, left +
    yaw_rate: float = 0.0  # rad/s

    @property
    def front_speed(self) -> float:
        """Mean of the front wheel speeds (what the SPEED report carries), m/s."""
        return 0.5 * (self.left_speed + self.right_speed)


Plant = Callable[[float, DriveCommand], WheelTruth]


def front_wheel_speeds(speed: float, yaw_rate: float, wheelbase: float,
                       track: float) -> tuple[float, float]:
    """Ground speed of the left and right front wheels (m/s, signed as the motion).

    A front wheel at (wheelbase, ±track/2) of a body moving at rear-axle speed v with
    yaw rate w moves at (v ∓ w·track/2, w·wheelbase) (rigid-body kinematics).
    """
    sign = -1.0 if speed < 0 else 1.0
    left = math.hypot(speed - yaw_rate * track / 2, yaw_rate * wheelbase)
    right = math.hypot(speed + yaw_rate * track / 2, yaw_rate * wheelbase)
    return sign * left, sign * right


class FirstOrderPlant:
    """The default vehicle: first-order speed and steering responses, bicycle model.

    Speed follows the target with :data:`DRIVE_TAU` (0.5 s; with the brake applied it
    decays to 0 with :data:`BRAKE_TAU`, 0.3 s); the steering angle follows its target
    with :data:`STEER_TAU` (0.15 s). Integrated in steps of at most ``max_step``
    seconds with the exact exponential for each lag and the midpoint rule for the
    wheel distances.
    """

    def __init__(self, wheelbase: float = 1.9, track: float = 1.3, *,
                 drive_tau: float = DRIVE_TAU, brake_tau: float = BRAKE_TAU,
                 steer_tau: float = STEER_TAU, max_step: float = 0.01) -> None:
        self.wheelbase = wheelbase
        self.track = track
        self.drive_tau, self.brake_tau, self.steer_tau = drive_tau, brake_tau, steer_tau
        self.max_step = max_step
        self._command = DriveCommand()
        self._t: float | None = None
        self._speed = 0.0
        self._steering = 0.0
        self._left = 0.0
        self._right = 0.0

    def _wheels(self, speed: float, steering: float) -> tuple[float, float, float]:
        yaw = speed * math.tan(steering) / self.wheelbase
        left, right = front_wheel_speeds(speed, yaw, self.wheelbase, self.track)
        return left, right, yaw

    def __call__(self, t: float, command: DriveCommand) -> WheelTruth:
        if self._t is None:
            self._t = t
        cmd = self._command
        target_speed = 0.0 if cmd.brake else cmd.translation
        speed_tau = self.brake_tau if cmd.brake else self.drive_tau
        while self._t < t:
            dt = min(self.max_step, t - self._t)
            left0, right0, _ = self._wheels(self._speed, self._steering)
            self._speed = target_speed + (self._speed - target_speed) * math.exp(-dt / speed_tau)
            self._steering = cmd.steering + (self._steering - cmd.steering) * math.exp(
                -dt / self.steer_tau)
            left1, right1, _ = self._wheels(self._speed, self._steering)
            self._left += 0.5 * (left0 + left1) * dt
            self._right += 0.5 * (right0 + right1) * dt
            self._t += dt
        self._t = t
        self._command = command
        left, right, yaw = self._wheels(self._speed, self._steering)
        return WheelTruth(t, self._left, self._right, left, right, self._speed,
                          self._steering, yaw)


@dataclass(frozen=True)
class ReceivedCommand:
    """A host command the fake decoded, with the clock time it arrived."""

    time: float
    seq: int
    command: Command


def _wrap32(value: int) -> int:
    return (value + 0x8000_0000) % 0x1_0000_0000 - 0x8000_0000


def _i16(value: float) -> int:
    return max(-32768, min(32767, round(value)))


class _RecordingDecoder(Mpc555DeviceDecoder):
    """The command decoder of one connection: records the bytes (if asked) and counts
    the frames it drops into the controller's one ``rx_errors`` counter."""

    def __init__(self, sink: bytearray | None, errors: Callable[[int], None]) -> None:
        super().__init__()
        self._sink = sink
        self._errors = errors

    def feed(self, data: bytes) -> list[Packet[Command]]:
        if self._sink is not None:
            self._sink += data
        before = self.stats.checksum_failures + self.stats.malformed
        packets = super().feed(data)
        dropped = self.stats.checksum_failures + self.stats.malformed - before
        if dropped:
            self._errors(dropped)
        return packets


@dataclass
class _Settings:
    """What a controller reset restores."""

    reports: ConfigureReports = field(default_factory=ConfigureReports)
    limits: SetLimits = field(default_factory=SetLimits)
    wheel: SetWheelCalibration = _DEFAULT_WHEEL
    steer: SetSteerCalibration = _DEFAULT_STEER
    pedal: tuple[PedalBreakpoint, ...] = DEFAULT_PEDAL_TABLE
    pid: SetSteerPid = _DEFAULT_PID
    calibrated: set[type] = field(default_factory=set)


class FakeMpc555(FakeDevice[Packet[Command]]):
    """A fake MPC555 controller serving any number of connections (see module doc).

    ``plant``: the vehicle (default :class:`FirstOrderPlant` with ``wheelbase`` and
    ``track``, metres, from ``docs/geometry.md``). ``mm_per_count``: the encoders' true
    wheel travel per count. ``rng`` with ``speed_noise`` (m/s) and ``steering_noise``
    (rad): Gaussian noise on the SPEED report's measurements. ``record``: keep every
    byte sent (``device_bytes``) and received (``host_bytes``); for tests, as it grows
    with the run (about 1 kB/s).

    Test controls: :attr:`estop`, :attr:`faults`, :attr:`mute_acks`, :meth:`inject`,
    :meth:`corrupt_next`, :meth:`reset`. Observations: :attr:`received` (the latest
    :attr:`received_history` commands with their arrival times; ``received.total``
    counts all), :attr:`truth`, :attr:`last_wheel_truth`, :attr:`mode`, :attr:`flags`.
    """

    name = "mpc555"
    #: How many of the latest commands :attr:`received` keeps (about a minute of the
    #: 20 Hz command stream a driving host sends).
    received_history = 1024

    def __init__(self, clock: Clock, *, plant: Plant | None = None, wheelbase: float = 1.9,
                 track: float = 1.3, mm_per_count: float = WHEEL_DISTANCE_PER_COUNT,
                 rng: np.random.Generator | None = None, speed_noise: float = 0.0,
                 steering_noise: float = 0.0, record: bool = False) -> None:
        super().__init__(clock)
        self.plant: Plant = plant if plant is not None else FirstOrderPlant(wheelbase, track)
        self.mm_per_count = mm_per_count
        self.rng = rng
        self.speed_noise = speed_noise
        self.steering_noise = steering_noise
        self.host_bytes: bytearray | None = bytearray() if record else None
        self.device_bytes: bytearray | None = bytearray() if record else None
        self.received: RecentLog[ReceivedCommand] = RecentLog(self.received_history)
        self.mute_acks = False
        self.watchdog_trips = 0
        self.resets = 0
        self._estop = False
        self._faults = Faults(0)
        self._connections: list[ByteStream] = []
        self._rx_errors = 0  # host frames dropped, all connections
        self._timers: dict[str, TimerHandle] = {}
        self._corrupt = 0
        self._powered = False
        self.truth = WheelTruth(clock.now())
        self.last_wheel_truth: WheelTruth | None = None

    # -- controller state ----------------------------------------------------------------
    def _reset_state(self) -> None:
        now = self.clock.monotonic()
        self._boot = now
        self._seq = SequenceCounter()
        self.settings = _Settings()
        self.started = False
        self.arbiter_enabled = False
        self.joystick = False
        self.watchdog_flag = False
        self.target_translation = 0.0  # m/s
        self.target_steering = self.truth.steering  # the wheels stay where they are
        self._last_host_frame: float | None = None
        self._advance()
        self._origin = (self.truth.left_distance, self.truth.right_distance)
        self._announced: tuple[Mode, StatusFlags, Faults] | None = None

    @property
    def mode(self) -> Mode:
        if not self.started:
            return Mode.STOPPED
        if self.joystick:
            return Mode.JOYSTICK
        return Mode.ARBITER if self.arbiter_enabled else Mode.RUNNING

    @property
    def calibrated(self) -> bool:
        return self.settings.calibrated >= _CALIBRATIONS

    @property
    def flags(self) -> StatusFlags:
        flags = StatusFlags(0)
        if self._estop:
            flags |= StatusFlags.ESTOP
        if self.watchdog_flag:
            flags |= StatusFlags.WATCHDOG
        if not self.started:
            flags |= StatusFlags.BRAKE
        if self.arbiter_enabled:
            flags |= StatusFlags.ARBITER_ENABLED
        if self.calibrated:
            flags |= StatusFlags.CALIBRATED
        return flags

    @property
    def estop(self) -> bool:
        """The e-stop chain is open: the vehicle stops and START_VEHICLE is refused."""
        return self._estop

    @estop.setter
    def estop(self, value: bool) -> None:
        self._estop = value
        if value:
            self._stop()
        self._changed()

    @property
    def faults(self) -> Faults:
        """Latched hardware faults (START_VEHICLE is refused while any is set)."""
        return self._faults

    @faults.setter
    def faults(self, value: Faults) -> None:
        self._faults = Faults(value)
        self._changed()

    def drive_command(self) -> DriveCommand:
        """The command the controller is giving the vehicle now."""
        if not self.started:
            return DriveCommand(0.0, self.target_steering, True, NEUTRAL_PEDAL)
        return DriveCommand(self.target_translation, self.target_steering, False,
                            self._pedal(self.target_translation * 1000.0))

    def _pedal(self, velocity_mm_s: float) -> int:
        points = self.settings.pedal
        if velocity_mm_s <= points[0].velocity_mm_s:
            return points[0].command
        for a, b in zip(points, points[1:], strict=False):
            if velocity_mm_s <= b.velocity_mm_s:
                share = (velocity_mm_s - a.velocity_mm_s) / (b.velocity_mm_s - a.velocity_mm_s)
                return round(a.command + share * (b.command - a.command))
        return points[-1].command

    def _advance(self) -> None:
        self.truth = self.plant(self.clock.now(), self.drive_command())

    def _stop(self) -> None:
        self.started = False
        self.joystick = False
        self.target_translation = 0.0

    def _changed(self) -> None:
        """Hand the new command to the plant; STATUS at once if mode/flags/faults changed."""
        if not self._powered:
            return
        self._advance()
        if (self.mode, self.flags, self.faults) != self._announced:
            self._send_status()

    # -- connections ---------------------------------------------------------------------
    def command_decoder(self) -> Mpc555DeviceDecoder:
        return _RecordingDecoder(self.host_bytes, self._count_rx_errors)

    def _count_rx_errors(self, count: int) -> None:
        self._rx_errors += count

    async def produce(self, stream: ByteStream) -> None:
        self._connections.append(stream)
        self._power_on()
        try:
            await asyncio.Event().wait()
        finally:
            if stream in self._connections:
                self._connections.remove(stream)

    def _power_on(self) -> None:
        if not self._powered:
            self._powered = True
            self._reset_state()
            self._schedule_reports()
            self._send_status()

    def _broadcast(self, data: bytes) -> None:
        if self.device_bytes is not None:
            self.device_bytes += data
        for stream in list(self._connections):
            try:
                if isinstance(stream, MemoryByteStream):
                    stream.write_nowait(data)
                else:  # a pseudo-terminal (the simulator's --expose): write in a task
                    task = spawn(stream.write(data), owner=f"fake {self.name}")
                    self._tasks.add(task)
                    task.add_done_callback(self._tasks.discard)
            except EDevIO:
                self._connections.remove(stream)

    def _send_report(self, report: Report) -> None:
        frame = bytearray(encode_report(report, self._seq.next()))
        if self._corrupt and not isinstance(report, CommandAck):
            self._corrupt -= 1
            frame[5] ^= 0x40  # first payload byte: the CRC no longer matches
        self._broadcast(bytes(frame))

    def inject(self, data: bytes) -> None:
        """Send raw bytes to every connection (line noise, a corrupt frame)."""
        self._broadcast(data)

    def corrupt_next(self, count: int = 1) -> None:
        """Flip a payload bit in the next ``count`` periodic reports (CRC failures)."""
        self._corrupt += count

    def reset(self) -> None:
        """A controller reset: clock, counters and settings back to power-on state."""
        self.resets += 1
        self._reset_state()
        self._schedule_reports()
        self._send_status()

    async def aclose(self) -> None:
        for handle in self._timers.values():
            handle.cancel()
        self._timers.clear()
        await super().aclose()

    # -- periodic reports and the watchdog -----------------------------------------------
    def _time_ms(self) -> int:
        return round((self.clock.monotonic() - self._boot) * 1000.0) & 0xFFFFFFFF

    def _schedule_reports(self) -> None:
        reports = self.settings.reports
        start = self.clock.monotonic()
        for kind, interval_ms in (("wheel", reports.wheel_distance_ms),
                                  ("speed", reports.speed_ms), ("status", reports.status_ms)):
            old = self._timers.pop(kind, None)
            if old is not None:
                old.cancel()
            if interval_ms:
                self._schedule(kind, start, interval_ms, 1)

    def _schedule(self, kind: str, start: float, period_ms: int, tick: int) -> None:
        def fire() -> None:
            self._schedule(kind, start, period_ms, tick + 1)
            self._guarded(self._emit, kind)

        # Integer milliseconds times the tick: no drift, and 15 x 200 ms is 3.0 s exactly.
        self._timers[kind] = self.clock.call_at(start + tick * period_ms / 1000.0, fire)

    def _guarded(self, action: Callable[..., None], *args: Any) -> None:
        # Timer callbacks run inside the clock's driver: an error must not escape.
        try:
            action(*args)
        except Exception:  # pragma: no cover - a bug in the fake
            log.exception("fake MPC555 %s failed", getattr(action, "__name__", action))

    def _emit(self, kind: str) -> None:
        self._advance()
        if kind == "wheel":
            self._send_wheel_distance()
        elif kind == "speed":
            self._send_speed()
        else:
            self._send_status()

    def _send_wheel_distance(self) -> None:
        truth = self.truth
        left = round((truth.left_distance - self._origin[0]) * 1000.0 / self.mm_per_count)
        right = round((truth.right_distance - self._origin[1]) * 1000.0 / self.mm_per_count)
        self.last_wheel_truth = truth
        self._send_report(WheelDistanceReport(self._time_ms(), _wrap32(left), _wrap32(right)))

    def _send_speed(self) -> None:
        truth = self.truth
        speed, steering = truth.front_speed, truth.steering
        if self.rng is not None:
            speed += self.rng.normal(0.0, self.speed_noise) if self.speed_noise else 0.0
            steering += self.rng.normal(0.0, self.steering_noise) if self.steering_noise else 0.0
        steer = self.settings.steer
        sensor = steer.center + math.degrees(steering) * 1e6 / steer.gain_udeg_per_count
        self._send_report(SpeedReport(
            self._time_ms(), _i16(speed * 1000.0), _i16(math.degrees(steering) * 100.0),
            self.drive_command().pedal, max(0, min(1023, round(sensor)))))

    def _send_status(self) -> None:
        now = self.clock.monotonic()
        age = 65535 if self._last_host_frame is None else min(
            65535, round((now - self._last_host_frame) * 1000.0))
        errors = self._rx_errors
        self._announced = (self.mode, self.flags, self.faults)
        self._send_report(StatusReport(self._time_ms(), self.mode, self.flags, self.faults,
                                       age, errors & 0xFFFF))

    def _arm_watchdog(self) -> None:
        if "watchdog" not in self._timers and self._last_host_frame is not None:
            deadline = self._last_host_frame + CONTROLLER_WATCHDOG_MS / 1000.0
            self._timers["watchdog"] = self.clock.call_at(
                deadline, lambda: self._guarded(self._watchdog))

    def _watchdog(self) -> None:
        del self._timers["watchdog"]
        if not self.started or self._last_host_frame is None:
            return
        silence = self.clock.monotonic() - self._last_host_frame
        if silence < CONTROLLER_WATCHDOG_MS / 1000.0 - 1e-9:
            self._arm_watchdog()
            return
        self.watchdog_trips += 1
        self._stop()
        self.watchdog_flag = True
        self._changed()

    # -- commands ------------------------------------------------------------------------
    async def on_command(self, command: Packet[Command], stream: ByteStream) -> None:
        self._power_on()
        message = command.message
        self.received.append(ReceivedCommand(self.clock.monotonic(), command.seq, message))
        self._last_host_frame = self.clock.monotonic()
        result = self._execute(message)
        if not self.mute_acks:
            self._send_report(CommandAck(command.seq, message.TYPE, result))
        self._changed()
        if self.started:
            self._arm_watchdog()

    def _execute(self, message: Command) -> AckResult:
        """Apply one command per the protocol's mode table; the ACK result."""
        s = self.settings
        if isinstance(message, Heartbeat):
            return AckResult.OK
        if isinstance(message, (SetVelocity, SetJoystickVelocity)):
            if not self.started:
                return AckResult.NOT_RUNNING
            if isinstance(message, SetVelocity) and self.joystick:
                return AckResult.WRONG_MODE
            if isinstance(message, SetJoystickVelocity):
                self.joystick = True
            return self._apply_velocity(message.translation_mm_s, message.rotation_mrad_s)
        if isinstance(message, StartVehicle):
            if self._estop:
                return AckResult.ESTOP
            if not self.calibrated:
                return AckResult.NOT_CALIBRATED
            if self._faults:
                return AckResult.FAULT
            self.started, self.joystick, self.watchdog_flag = True, False, False
            self.target_translation = 0.0
            return AckResult.OK
        if isinstance(message, StopVehicle):
            self._stop()
            return AckResult.OK
        if isinstance(message, SetArbiter):
            if self.joystick:
                self.joystick = False
                self.target_translation = 0.0
            self.arbiter_enabled = message.enabled
            return AckResult.OK
        if isinstance(message, ConfigureReports):
            values = (message.wheel_distance_ms, message.speed_ms, message.status_ms)
            if any(0 < v < 10 for v in values):
                return AckResult.OUT_OF_RANGE
            changed = message != s.reports
            s.reports = message
            if changed:
                self._schedule_reports()
            return AckResult.OK
        if isinstance(message, SetLimits):
            if (0 in (message.max_translation_mm_s, message.max_rotation_mrad_s,
                      message.max_steering_cdeg, message.wheelbase_mm)
                    or message.max_steering_cdeg > 4500):
                return AckResult.OUT_OF_RANGE
            s.limits = message
            return AckResult.OK
        if isinstance(message, SetWheelCalibration):
            if not message.left_nm_per_count or not message.right_nm_per_count:
                return AckResult.OUT_OF_RANGE
            s.wheel = message
        elif isinstance(message, SetSteerCalibration):
            if not (message.minimum < message.center < message.maximum <= 1023
                    and message.gain_udeg_per_count > 0):
                return AckResult.OUT_OF_RANGE
            s.steer = message
        elif isinstance(message, SetPedalCalibration):
            points = message.points
            pairs = zip(points, points[1:], strict=False)
            if (any(b.velocity_mm_s <= a.velocity_mm_s for a, b in pairs)
                    or all(p.velocity_mm_s != 0 for p in points)
                    or any(p.command > 4095 for p in points)):
                return AckResult.OUT_OF_RANGE
            s.pedal = points
        elif isinstance(message, SetSteerPid):
            s.pid = message
        else:  # pragma: no cover - the decoder yields commands only
            return AckResult.OUT_OF_RANGE
        s.calibrated.add(type(message))
        return AckResult.OK

    def _apply_velocity(self, translation_mm_s: int, rotation_mrad_s: int) -> AckResult:
        limits = self.settings.limits
        limited = False
        v, w = translation_mm_s, rotation_mrad_s
        if abs(v) > limits.max_translation_mm_s:
            v, limited = int(math.copysign(limits.max_translation_mm_s, v)), True
        if abs(w) > limits.max_rotation_mrad_s:
            w, limited = int(math.copysign(limits.max_rotation_mrad_s, w)), True
        delta = steering_angle(v, w, limits.wheelbase_mm)
        if delta is None:  # |v| < 10 mm/s: keep the steering, stop the drive
            self.target_translation = 0.0
            return AckResult.LIMITED if limited else AckResult.OK
        max_steer = math.radians(limits.max_steering_cdeg / 100.0)
        if abs(delta) > max_steer + 1e-12:
            delta, limited = math.copysign(max_steer, delta), True
        self.target_translation = v / 1000.0
        self.target_steering = delta
        return AckResult.LIMITED if limited else AckResult.OK
