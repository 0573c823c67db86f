"""Wheel Odometry (seed §3.1.5, Tables 9, 10, A.5) over the MPC555 link, and the host
side of the link that Vehicle Control shares.

:class:`Mpc555Host` is the part both MPC555 drivers have in common
(``docs/protocols/mpc555.md``): the serial device, the report decoder, the host
sequence counter, acknowledged commands with the protocol's 50 ms ACK timeout and
retransmissions, counting of lost report frames (gaps in the controller's SEQ),
detection of a controller reset (its ``time`` going backwards) and the start-up
configuration, re-run after every (re)connection and controller reset.

:class:`WheelOdometry` configures the report intervals and the wheel and steering
calibration, turns every WHEEL_DISTANCE report into a :class:`~idl.WheelEventIDL`
published under ``RaptorOdometryEvent`` and answers ``getWheelData`` /
``getWaitWheelData`` (interface :class:`~idl.Odometry`, bound under the same name, as
the seed says).

Both components name the same serial port; each decoder sees every report and
:meth:`Mpc555Host.on_report` receives them all, so each driver simply ignores the
report types it does not use (they are valid frames, never counted as errors).
"""

from __future__ import annotations

import asyncio
import math
from typing import Any, ClassVar, Generic, Protocol, TypeVar, cast

from afa.component import PublishServerReactor
from afa.config.parameters import Parameters
from afa.errors import EDevIO, ETimeOut
from afa.polling import LatestSlot
from afa.transport import ByteStream, DeviceSpec, SerialSpec
from components.mpc555.codec import (
    AckResult,
    Command,
    CommandAck,
    ConfigureReports,
    Mpc555Decoder,
    Packet,
    Report,
    SequenceCounter,
    SetSteerCalibration,
    SetWheelCalibration,
    SpeedReport,
    WheelDistanceReport,
    encode_command,
    next_seq,
)
from components.mpc555.parameters import (
    SteerCalibration,
    WheelOdometryParameters,
)
from idl import Odometry, TimeIDL, WheelDataIDL, WheelEventIDL

__all__ = [
    "Mpc555Host", "WheelOdometry", "ACK_TIMEOUT", "COMMAND_RETRIES", "STATUS_INTERVAL_MS",
    "link_timeout", "steer_calibration", "wheel_calibration",
]

ACK_TIMEOUT = 0.050
"""Seconds the host waits for an ACK before retransmitting (protocol: 50 ms)."""
COMMAND_RETRIES = 3
"""Retransmissions of a configuration or mode command before the link is failed."""
STATUS_INTERVAL_MS = 500
"""The STATUS report interval the host configures (the controller's default)."""
RECONFIGURE_DELAY = 1.0
"""Seconds between attempts when the start-up configuration fails."""
_TIME_WRAP_MARGIN_MS = 60_000
"""A controller time falling from within this margin of 2**32 to near 0 is a wrap,
not a reset (the ms clock wraps after 49.7 days)."""


def link_timeout(*intervals_ms: int) -> float:
    """The host link watchdog: three times the shortest enabled report interval, at
    least 0.3 s (protocol, "Watchdogs and a lost link"). Seconds."""
    enabled = [i for i in intervals_ms if i > 0] or [STATUS_INTERVAL_MS]
    return max(0.3, 3 * min(enabled) / 1000.0)


def wheel_calibration(left_mm_per_count: float, right_mm_per_count: float) -> SetWheelCalibration:
    """SET_WHEEL_CALIBRATION from ``LfdParam``/``RfdParam`` (mm/count -> nm/count)."""
    return SetWheelCalibration(round(left_mm_per_count * 1e6), round(right_mm_per_count * 1e6))


def steer_calibration(steer: SteerCalibration) -> SetSteerCalibration:
    """SET_STEER_CALIBRATION from ``SteerParam`` (gain deg/count -> µdeg/count)."""
    return SetSteerCalibration(steer.Center, round(steer.Gain * 1e6), steer.Min, steer.Max)


#: The parameter models of the two components that share the MPC555 link.
LinkParameters = TypeVar("LinkParameters", bound=Parameters)


class _SerialLink(Protocol):
    """What both link parameter models say about the serial port."""

    Device: str
    Baudrate: int


class Mpc555Host(PublishServerReactor[LinkParameters, Packet[Report]], Generic[LinkParameters]):
    """Host side of the MPC555 link shared by Wheel Odometry and Vehicle Control.

    Subclasses provide :meth:`configuration` (the commands sent after every connection
    and controller reset) and :meth:`on_report` (every decoded report except ACKs).
    :meth:`command` sends one acknowledged command.
    """

    #: Where this component's host sequence counter starts. The two components share
    #: one port and so interleave two counters; ACKs are matched by (SEQ, TYPE) among a
    #: component's own outstanding commands, and distinct starting points keep the two
    #: counters apart.
    seq_start: ClassVar[int] = 0

    def __init__(self, name: str, parameters: LinkParameters | None = None) -> None:
        super().__init__(name, parameters)
        self._seq = SequenceCounter(self.seq_start)
        self._pending: dict[tuple[int, int], asyncio.Future[AckResult]] = {}
        self._last_report_seq: int | None = None
        self._last_controller_ms: int | None = None
        self._configure_task: asyncio.Task[None] | None = None
        self.configured = False
        self.configuring = False
        self.link_up = False  # a report arrived since the last (re)connection
        self.ready = asyncio.Event()  # set while configured
        self.last_tx: float | None = None
        self.link_counters: dict[str, int] = dict.fromkeys(
            ("acks", "naks", "ack_timeouts", "retransmissions", "unmatched_acks",
             "lost_reports", "controller_resets", "configurations"), 0)

    # -- hooks for subclasses ----------------------------------------------------------
    def configuration(self) -> list[Command]:
        """The commands sent (acknowledged, in order) after connecting and after a
        controller reset."""
        return []

    def on_report(self, report: Report) -> None:
        """One report from the controller (WHEEL_DISTANCE, SPEED or STATUS)."""

    def on_controller_reset(self) -> None:
        """The controller restarted: its counters and settings are back at reset state."""

    def on_configured(self) -> None:
        """The start-up configuration was acknowledged in full."""

    # -- PublishServerReactor hooks ------------------------------------------------------
    def device(self) -> DeviceSpec:
        p = cast(_SerialLink, self.parameters)
        return SerialSpec(p.Device, p.Baudrate)

    def decoder(self) -> Mpc555Decoder:
        return Mpc555Decoder()

    async def setup(self) -> None:
        # A restarted component starts unconfigured (the counters are kept).
        self.configured = self.configuring = self.link_up = False
        self.ready.clear()
        self._configure_task = None

    async def on_connect(self, stream: ByteStream) -> None:
        # Reading starts only after this returns, so the configuration (which waits for
        # ACKs) runs in its own task.
        self._last_report_seq = None
        self.configured = False
        self.link_up = False
        self._start_configuration()

    async def teardown(self) -> None:
        for future in self._pending.values():
            future.cancel()
        self._pending.clear()
        self._configure_task = None
        self.configuring = False

    def handle(self, message: Packet[Report]) -> None:
        self.link_up = True
        seq = message.seq
        if self._last_report_seq is not None:
            self.link_counters["lost_reports"] += (seq - next_seq(self._last_report_seq)) & 0xFF
        self._last_report_seq = seq
        report = message.message
        if isinstance(report, CommandAck):
            self._acknowledge(report)
            return
        self._check_controller_time(report.time_ms)
        self.on_report(report)

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.link_counters)
        stats["configured"] = self.configured
        return stats

    # -- commands ------------------------------------------------------------------------
    async def send_unacknowledged(self, command: Command) -> None:
        """Send ``command`` without waiting for its ACK (heartbeats, link-loss stops).

        Raises EDevIO while the device is not connected.
        """
        await self.send(encode_command(command, self._seq.next()))
        self.last_tx = self.clock.monotonic()

    async def command(self, command: Command, *, retries: int = COMMAND_RETRIES) -> AckResult:
        """Send ``command`` and wait for its ACK, retransmitting it with the same SEQ up to
        ``retries`` times, ``ACK_TIMEOUT`` apart.

        Returns the (accepting) result, OK or LIMITED. Raises EDevIO when the controller
        refuses it (a NAK, the reason in the message), when no ACK arrives after the
        retransmissions, or while the device is not connected.
        """
        seq = self._seq.next()
        frame = encode_command(command, seq)
        key = (seq, int(command.TYPE))
        future: asyncio.Future[AckResult] = asyncio.get_running_loop().create_future()
        self._pending[key] = future
        try:
            for attempt in range(retries + 1):
                if attempt:
                    self.link_counters["retransmissions"] += 1
                await self.send(frame)
                self.last_tx = self.clock.monotonic()
                try:
                    async with self.clock.timeout(ACK_TIMEOUT, "MPC555 ACK"):
                        result = await asyncio.shield(future)
                    break
                except ETimeOut:
                    continue
            else:
                self.link_counters["ack_timeouts"] += 1
                raise EDevIO(f"{self.name}: no ACK from the MPC555 for "
                             f"{command.TYPE.name} (SEQ {seq}) after {retries + 1} "
                             f"transmission(s)")
        finally:
            if self._pending.get(key) is future:
                del self._pending[key]
            if not future.done():
                future.cancel()
        if not result.accepted:
            raise EDevIO(f"{self.name}: the MPC555 refused {command.TYPE.name}: {result.name}")
        return result

    def _acknowledge(self, ack: CommandAck) -> None:
        future = self._pending.get((ack.acked_seq, int(ack.acked_type)))
        if future is None or future.done():
            # The other component's command on the shared port, or a late ACK.
            self.link_counters["unmatched_acks"] += 1
            return
        self.link_counters["acks" if ack.accepted else "naks"] += 1
        future.set_result(ack.result)

    # -- configuration and controller resets ----------------------------------------------
    def _start_configuration(self) -> None:
        if self._configure_task is not None and not self._configure_task.done():
            self._configure_task.cancel()
        self.configuring = True
        self.ready.clear()
        self._configure_task = self.spawn(self._configure(), f"{self.name}:configure")

    async def _configure(self) -> None:
        try:
            while True:
                try:
                    for command in self.configuration():
                        await self.command(command)
                except EDevIO as exc:
                    if self.reactor is not None and self.reactor.connected:
                        self.set_health(False, f"configuration failed: {exc}")
                    await self.clock.sleep(RECONFIGURE_DELAY)
                    continue
                break
            self.configured = True
            self.ready.set()
            self.link_counters["configurations"] += 1
            self.set_health(True, "connected, configured")
            self.on_configured()
        finally:
            if self._configure_task is asyncio.current_task():
                self.configuring = False

    def _check_controller_time(self, time_ms: int) -> None:
        last, self._last_controller_ms = self._last_controller_ms, time_ms
        if last is None or time_ms >= last:
            return
        if last > 0xFFFFFFFF - _TIME_WRAP_MARGIN_MS and time_ms < _TIME_WRAP_MARGIN_MS:
            return  # the ms clock wrapped
        self.link_counters["controller_resets"] += 1
        self.log.warning("MPC555 controller reset (time %d ms after %d ms)", time_ms, last)
        self.configured = False
        self.on_controller_reset()
        self._start_configuration()


def _signed32(value: int) -> int:
    return (value + 0x8000_0000) % 0x1_0000_0000 - 0x8000_0000


class WheelOdometry(Mpc555Host[WheelOdometryParameters]):
    """The Wheel Odometry component (seed §3.1.5): a Publish Server and Reactor.

    Distances are cumulative front-wheel travel in metres since the controller first
    reported: the host accumulates count differences modulo 2**32, so the distance
    neither jumps at a counter wrap nor across a reconnection or a controller reset
    (the travel between the last report before a reset and the reset is lost). Wheel
    speeds are count differences over the controller's own report clock; the first
    report after start-up has speed 0. The steering angle is the controller's measured
    angle from the latest SPEED report (it is calibrated with ``SteerParam``, which
    this component sends).
    """

    seq_start = 0x80

    def __init__(self, name: str, parameters: WheelOdometryParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self.stale_after = link_timeout(p.WheelDistRepTime, p.SpeedRepTime, STATUS_INTERVAL_MS)
        self.events = self.publishes(p.RaptorOdometryEvent, WheelEventIDL)
        self.serves(Odometry, p.RaptorOdometryEvent)
        self._total = [0, 0]  # cumulative counts, host side, left and right
        self._previous: tuple[int, int, int] | None = None  # time_ms, left, right
        self._steering = 0.0
        self._sequence = 0

    async def setup(self) -> None:
        await super().setup()
        self.latest: LatestSlot[WheelEventIDL] = self.slot("wheel odometry")

    def configuration(self) -> list[Command]:
        p = self.parameters
        return [ConfigureReports(p.WheelDistRepTime, p.SpeedRepTime, STATUS_INTERVAL_MS),
                wheel_calibration(p.LfdParam, p.RfdParam),
                steer_calibration(p.SteerParam)]

    def on_controller_reset(self) -> None:
        # The controller's counters and clock restarted at 0.
        self._previous = (0, 0, 0)

    def on_report(self, report: Report) -> None:
        if isinstance(report, WheelDistanceReport):
            self._wheel_distance(report)
        elif isinstance(report, SpeedReport):
            self._steering = math.radians(report.steering_cdeg / 100.0)
        # STATUS and the rest belong to Vehicle Control.

    def _wheel_distance(self, report: WheelDistanceReport) -> None:
        p = self.parameters
        previous = self._previous or (report.time_ms, 0, 0)
        left_delta = _signed32(report.left_counts - previous[1])
        right_delta = _signed32(report.right_counts - previous[2])
        self._total[0] += left_delta
        self._total[1] += right_delta
        dt = ((report.time_ms - previous[0]) & 0xFFFFFFFF) / 1000.0
        left_m, right_m = left_delta * p.LfdParam / 1000.0, right_delta * p.RfdParam / 1000.0
        have_speed = self._previous is not None and dt > 0
        self._previous = (report.time_ms, report.left_counts, report.right_counts)
        self._sequence += 1
        body = WheelEventIDL(
            time=TimeIDL.from_seconds(self.clock.now()),
            leftDistance=self._total[0] * p.LfdParam / 1000.0,
            rightDistance=self._total[1] * p.RfdParam / 1000.0,
            leftSpeed=left_m / dt if have_speed else 0.0,
            rightSpeed=right_m / dt if have_speed else 0.0,
            steeringAngle=self._steering,
            sequence=self._sequence,
            leftDelta=left_m,
            rightDelta=right_m,
        )
        self.latest.set(body)
        self.events.publish(body)

    # -- Odometry interface (Table 10) ---------------------------------------------------
    async def getWheelData(self) -> WheelDataIDL:
        """The latest odometry report; EDevIO if none arrived yet."""
        return self.latest.get()

    async def getWaitWheelData(self) -> WheelDataIDL:
        """The next odometry report; ETimeOut after ``Odometry.wait_timeout`` (1 s)."""
        return await self.latest.wait_next(Odometry.wait_timeout)
