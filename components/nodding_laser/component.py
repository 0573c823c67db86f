"""The Nodding Laser component (seed §3.1.1, Tables 1, 2, A.1): a Publish Server and
Reactor over TCP to the nodding controller of a SICK LMS 211.

On every (re)connection the driver configures the controller and the LMS through the
NLC v1 framing (``docs/protocols/nodding_laser.md``): LMS streaming off, nodding off,
LMS variant (180 deg, or 100 deg for 0.25 deg, at ``Laserres``), nod rate and limits,
nodding on, LMS streaming on. Every SCAN frame then becomes one scan line of 3-D points
in the laser's frame, offered in the seed's two forms:

- ``Range3dSeqEventIDL`` (sequence: valid points only) published as ``<EventName>``
  (``Raptor/Laser11``), the event name Table A.6 consumers subscribe to;
- ``Range3dLaserIDL`` (static array: one slot per beam, NaN where invalid) published as
  ``<EventName>Array`` (``Raptor/Laser11Array``). Both forms share one seed event name,
  and one afa event name carries one body type, so the static form gets a suffix.

Each form is built only when someone subscribes to it or polls it (Miro's "skip
building unwanted events"). ``Raptor/<EventName>`` serves :class:`~idl.Range3dSensor`.

Adaptive nodding (off by default, see :func:`nod_plan`) derives the nod's upper limit
and rate from ``MountAngle``, ``MountHeight`` and ``ScanDistance``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from afa.codec import StreamDecoder
from afa.component import PublishServerReactor
from afa.errors import EDevIO, EOutOfBounds
from afa.reactor import Backoff
from afa.transport import ByteStream, DeviceSpec, TcpSpec
from components.nodding_laser.codec import (
    ACK,
    SCAN_VARIANTS,
    AckResult,
    CommandAck,
    ControllerMessage,
    ControllerState,
    ControllerStatus,
    FrameType,
    HostCommand,
    NodControllerDecoder,
    NodScan,
    OperatingModeReply,
    RequestStatus,
    ScanLineGeometry,
    SetNodLimits,
    SetNodRate,
    SickCommand,
    SickMode,
    SickReply,
    StartNodding,
    StopNodding,
    SwitchOperatingMode,
    SwitchVariant,
    VariantReply,
    encode_host_command,
    scan_bearings_deg,
    udeg,
)
from components.nodding_laser.parameters import NodLaserParameters
from idl import (
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSensor,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
    TimeIDL,
    select_valid,
)

__all__ = [
    "NodLaser", "NodPlan", "nod_plan", "adaptive_nod_rate", "scan_variant",
    "SCAN_PERIODS", "LASER_FRAMES", "laser_frame", "ARRAY_EVENT_SUFFIX",
    "configuration_commands",
]

#: Seconds per full scan by resolution (1/100 deg). The LMS mirror turns at 75 Hz; a
#: 0.5 deg scan interlaces 2 sweeps, a 0.25 deg scan 4 (seed Table 1: 26.6 ms at 0.5 deg).
SCAN_PERIODS: dict[int, float] = {100: 1 / 75, 50: 2 / 75, 25: 4 / 75}

#: Laser frame by LaserID: Table A.6 ``SickLaserFrame1`` (ID 11, left) and
#: ``SickLaserFrame2`` (ID 12, right), in the geometry model's canonical spelling.
LASER_FRAMES: dict[int, str] = {
    11: "FrontNoddingSICKLeft:AxleCenterFreeEnd",
    12: "FrontNoddingSICKRight:AxleCenterFreeEnd",
}

#: The static-array form is published as ``<EventName><ARRAY_EVENT_SUFFIX>``.
ARRAY_EVENT_SUFFIX = "Array"

#: How fast the controller-to-host clock offset estimate may grow (s per s): lets the
#: minimum filter follow a controller clock that runs slow (crystals: ~50 ppm).
_OFFSET_CREEP = 1e-4


def laser_frame(laser_id: int) -> str:
    """The frame the points of laser ``laser_id`` are expressed in.

    IDs without a Table A.6 frame get ``NoddingSICK<id>:AxleCenterFreeEnd``, a body the
    geometry model must then define.
    """
    return LASER_FRAMES.get(laser_id, f"NoddingSICK{laser_id}:AxleCenterFreeEnd")


def scan_variant(resolution_cdeg: int) -> tuple[int, int]:
    """(field of view deg, resolution) the driver asks for: 180 deg where the LMS offers
    the resolution, else 100 deg (0.25 deg exists only over 100 deg).

    Raises :class:`~afa.errors.EOutOfBounds` for a resolution the LMS does not have.
    """
    for field in (180, 100):
        if (field, resolution_cdeg) in SCAN_VARIANTS.values():
            return field, resolution_cdeg
    raise EOutOfBounds(f"the LMS 2xx has no {resolution_cdeg / 100:g} deg resolution")


def adaptive_nod_rate(far_angle_deg: float, mount_height_m: float, scan_distance_m: float,
                      scan_period_s: float, max_rate_deg_s: float) -> float:
    """The nod rate (deg/s) that keeps consecutive scan lines at most ``scan_distance_m``
    apart on flat ground up to the elevation ``far_angle_deg``, capped at
    ``max_rate_deg_s``.

    A scan plane at elevation n < 0 from height h meets flat ground at d = h / tan(-n);
    a nod step dn moves that line by h dn / sin^2 n, largest at the highest (farthest)
    elevation. One step per scan period T at rate w: w <= s sin^2 n / (h T). A far angle
    at or above level never meets the ground: the cap applies.
    """
    if far_angle_deg >= 0.0:
        return max_rate_deg_s
    sine = math.sin(math.radians(far_angle_deg))
    rate = math.degrees(scan_distance_m * sine * sine / (mount_height_m * scan_period_s))
    return min(max_rate_deg_s, rate)


@dataclass(frozen=True, slots=True)
class NodPlan:
    """What the driver commands: nod limits and rate as the controller's encoder sees
    them (true elevation minus ``LaserOffsetAngle``), and the true limits."""

    low_deg: float
    high_deg: float
    rate_deg_s: float
    command_low_deg: float
    command_high_deg: float
    adaptive: bool


def nod_plan(parameters: NodLaserParameters, *, adaptive: bool = False) -> NodPlan:
    """The nod limits and rate for ``parameters``.

    Fixed (``adaptive`` False): ``LowAngle`` .. ``HighAngle`` at ``Motorrates``.
    Adaptive (afa's documented reading of the seed's "used for adaptive nodding"):
    the sweep's upper limit is ``MountAngle`` when it lies inside the configured range
    (the scan plane never rises above the mount's look angle), and the rate is lowered
    by :func:`adaptive_nod_rate` so that scan lines land at most ``ScanDistance`` apart on
    flat ground seen from ``MountHeight``, at the sweep's upper limit (where they are
    sparsest); never faster than ``Motorrates``.

    The controller's encoder reads true elevation minus ``LaserOffsetAngle`` (the host
    adds the offset back to every reported angle), so the commanded limits are shifted
    by the offset.
    """
    low, high, rate = parameters.LowAngle, parameters.HighAngle, parameters.Motorrates
    if adaptive:
        if low < parameters.MountAngle < high:
            high = parameters.MountAngle
        period = SCAN_PERIODS[scan_variant(parameters.Laserres)[1]]
        rate = adaptive_nod_rate(high, parameters.MountHeight, parameters.ScanDistance,
                                 period, parameters.Motorrates)
    offset = parameters.LaserOffsetAngle
    return NodPlan(low, high, rate, low - offset, high - offset, adaptive)


def configuration_commands(parameters: NodLaserParameters, plan: NodPlan,
                           first_seq: int = 0) -> list[HostCommand]:
    """The start-up sequence sent on every connection, in order.

    LMS streaming off and nodding off first (limits are refused while nodding, and the
    LMS drops a variant change made mid-stream), then variant, rate, limits, nodding on,
    streaming on, and a status request. The controller keeps its state across TCP
    connections, so the whole sequence is repeated after a reconnect.
    """
    field, resolution = scan_variant(parameters.Laserres)
    commands: list[HostCommand] = [
        SickCommand(SwitchOperatingMode(SickMode.MONITOR_REQUEST_VALUES)),
        StopNodding(),
        SickCommand(SwitchVariant(field, resolution)),
        SetNodRate(max(1, udeg(plan.rate_deg_s))),
        SetNodLimits(udeg(plan.command_low_deg), udeg(plan.command_high_deg)),
        StartNodding(),
        SickCommand(SwitchOperatingMode(SickMode.MONITOR_STREAM_VALUES)),
        RequestStatus(),
    ]
    return [_with_seq(command, (first_seq + i) & 0xFF) for i, command in enumerate(commands)]


def _with_seq(command: HostCommand, seq: int) -> HostCommand:
    return dataclasses.replace(command, seq=seq)


class _ScanLine:
    """One scan line, with both IDL forms built on first use."""

    def __init__(self, time: TimeIDL, sensor_id: int, frame: str, nod_start_rad: float,
                 nod_end_rad: float, points: npt.NDArray[np.float32],
                 valid: npt.NDArray[np.bool_]) -> None:
        self.time = time
        self.sensor_id = sensor_id
        self.frame = frame
        self.nod_start = nod_start_rad
        self.nod_end = nod_end_rad
        self.points = points  # (N, 3) float32, NaN where not valid
        self.valid = valid

    @cached_property
    def laser(self) -> Range3dLaserIDL:
        return Range3dLaserIDL(time=self.time, sensorId=self.sensor_id, frame=self.frame,
                               nodAngleStart=self.nod_start, nodAngleEnd=self.nod_end,
                               points=self.points, valid=self.valid)

    @cached_property
    def seq(self) -> Range3dSeqEventIDL:
        points = select_valid(self.points, self.valid)
        points.flags.writeable = False  # a fresh array: the IDL need not copy it again
        return Range3dSeqEventIDL(time=self.time, sensorId=self.sensor_id, frame=self.frame,
                                  nodAngleStart=self.nod_start, nodAngleEnd=self.nod_end,
                                  points=points)


class NodLaser(PublishServerReactor[NodLaserParameters, ControllerMessage]):
    """One nodding SICK LMS 211 (an instance of Table A.1: ``Laser11``, ``Laser12``).

    ``adaptive_nodding`` switches the adaptive rule of :func:`nod_plan` on (default off:
    the configured limits and rate are obeyed exactly). Table A.1 has no switch for it;
    pass ``adaptive_nodding=True`` or set the class attribute.
    """

    #: Seconds without a decoded frame before the controller counts as lost (the
    #: controller flags its own LMS link after 100 ms; scans come every 13-53 ms).
    stale_after = 1.0
    backoff: ClassVar[Backoff] = Backoff(initial=0.2, factor=2.0, maximum=5.0)
    adaptive_nodding: ClassVar[bool] = False

    def __init__(self, name: str, parameters: NodLaserParameters | None = None, *,
                 adaptive_nodding: bool | None = None) -> None:
        super().__init__(name, parameters)
        configured = bool(getattr(self.parameters, "AdaptiveNodding", False))
        default = configured or type(self).adaptive_nodding
        self.adaptive = default if adaptive_nodding is None else adaptive_nodding
        p = self.parameters
        self.variant = scan_variant(p.Laserres)
        self.scan_period = SCAN_PERIODS[self.variant[1]]
        self.plan = nod_plan(p, adaptive=self.adaptive)
        self.frame = laser_frame(p.LaserID)
        self._expected_count = next(n for n, v in SCAN_VARIANTS.items() if v == self.variant)
        self._geometry = ScanLineGeometry(scan_bearings_deg(self._expected_count, *self.variant))
        self._seq = 0
        self._offset: float | None = None  # host time - controller time, estimated
        self._last_receipt = 0.0
        self._last_counter: int | None = None
        self._last_controller_time: int | None = None
        self.controller_status: ControllerStatus | None = None
        self.counters = {"scans": 0, "scans_lost": 0, "scans_rejected": 0,
                         "commands_rejected": 0, "array_events": 0, "seq_events": 0}
        self.events = self.publishes(p.EventName, Range3dSeqEventIDL)
        self.array_events = self.publishes(self.array_event_name, Range3dLaserIDL)
        self.serves(Range3dSensor, p.EventName)

    @property
    def array_event_name(self) -> str:
        """Event name of the static-array form (``<EventName>Array``)."""
        return self.parameters.EventName + ARRAY_EVENT_SUFFIX

    # -- PSR hooks -----------------------------------------------------------------------
    async def setup(self) -> None:
        p = self.parameters
        if p.LaserID not in LASER_FRAMES:
            self.log.warning("LaserID %d has no Table A.6 frame; points are in %s",
                             p.LaserID, self.frame)
        self.latest = self.slot("laser scan line")

    def device(self) -> DeviceSpec:
        return TcpSpec(self.parameters.Host, self.parameters.Port)

    def decoder(self) -> StreamDecoder[ControllerMessage]:
        return NodControllerDecoder()

    async def on_connect(self, stream: ByteStream) -> None:
        self._offset = None
        self._last_counter = None
        self._last_controller_time = None
        commands = configuration_commands(self.parameters, self.plan, self._seq)
        self._seq = (self._seq + len(commands)) & 0xFF
        self.log.info("configuring: nod %.2f..%.2f deg at %.3f deg/s%s, LMS %d deg / %.2f deg",
                      self.plan.low_deg, self.plan.high_deg, self.plan.rate_deg_s,
                      " (adaptive)" if self.adaptive else "", self.variant[0],
                      self.variant[1] / 100)
        await stream.write(b"".join(encode_host_command(c) for c in commands))

    def handle(self, message: ControllerMessage) -> None:
        if isinstance(message, NodScan):
            self._scan(message)
        elif isinstance(message, CommandAck):
            if not message.ok:
                self.counters["commands_rejected"] += 1
                self._fault(f"controller refused {_frame_name(message.command_type)} "
                            f"(seq {message.command_seq}): {_ack_name(message.result)}")
        elif isinstance(message, SickReply):
            self._sick_reply(message)
        else:
            self._status(message)

    # -- scans ---------------------------------------------------------------------------
    def _scan(self, scan: NodScan) -> None:
        now = self.clock.now()
        measured = scan.measured
        if measured.count != self._expected_count:
            self.counters["scans_rejected"] += 1
            self.log.warning("scan of %d values, expected %d (variant %s): dropped",
                             measured.count, self._expected_count, self.variant)
            return
        self.counters["scans"] += 1
        if self._last_counter is not None:
            gap = (scan.scan_counter - self._last_counter - 1) & 0xFFFFFFFF
            if gap < 1 << 31:  # a huge gap is a controller restart, not lost scans
                self.counters["scans_lost"] += gap
        self._last_counter = scan.scan_counter
        stamp = self._stamp(scan.timestamp_us, now)

        offset = self.parameters.LaserOffsetAngle
        nod_start, nod_end = scan.nod_start_deg + offset, scan.nod_end_deg + offset
        points, valid = self._geometry.scan_line(measured, (nod_start, nod_end))
        points.flags.writeable = False
        valid.flags.writeable = False
        line = _ScanLine(TimeIDL.from_seconds(stamp), self.parameters.LaserID, self.frame,
                         math.radians(nod_start), math.radians(nod_end), points, valid)
        self.latest.set(line)
        # The sequence form is the laser's event (loggers and the run summary count it
        # even before a map subscribes); the fixed-size form only when someone wants it.
        self.events.publish(line.seq)
        self.counters["seq_events"] += 1
        if self.array_events.subscribed:
            self.array_events.publish(line.laser)
            self.counters["array_events"] += 1

    def _stamp(self, controller_us: int, receipt: float) -> float:
        """Host time of the scan's first beam from the controller's clock.

        Minimum filter on (receipt - controller time): the smallest difference is the
        clock offset plus the scan duration plus the least transfer latency. It may
        creep up by _OFFSET_CREEP s/s (a slow controller clock) and is reset on a
        reconnect, a controller clock that went backwards, or a jump of over 0.5 s.
        """
        controller = controller_us / 1e6
        sample = receipt - controller
        restarted = (self._last_controller_time is not None
                     and controller_us < self._last_controller_time)
        if self._offset is None or restarted or sample - self._offset > 0.5:
            self._offset = sample
        else:
            crept = self._offset + _OFFSET_CREEP * max(0.0, receipt - self._last_receipt)
            self._offset = min(crept, sample)
        self._last_receipt = receipt
        self._last_controller_time = controller_us
        return controller + self._offset - self.scan_period

    # -- replies and status -----------------------------------------------------------------
    def _sick_reply(self, message: SickReply) -> None:
        reply = message.reply
        if message.ack != ACK:
            what = "no answer" if message.ack == 0 else f"NAK ({message.ack:#04x})"
            self.counters["commands_rejected"] += 1
            self._fault(f"LMS: {what} to a forwarded command")
        elif isinstance(reply, OperatingModeReply) and not reply.ok:
            self.counters["commands_rejected"] += 1
            self._fault(f"LMS refused the operating mode change (result {reply.result})")
        elif isinstance(reply, VariantReply) and (
                not reply.accepted or (reply.scan_angle_deg, reply.resolution_cdeg)
                != self.variant):
            self.counters["commands_rejected"] += 1
            self._fault(f"LMS refused variant {self.variant[0]} deg / "
                        f"{self.variant[1] / 100:g} deg")

    def _status(self, status: ControllerStatus) -> None:
        self.controller_status = status
        if status.faults or status.state == ControllerState.FAULT:
            self._fault(f"controller fault bits {status.faults:#06b} (state {status.state})")
        else:
            self.log.debug("controller state %d at %.3f deg", status.state,
                           status.angle_udeg / 1e6)

    def _fault(self, detail: str) -> None:
        self.log.warning("%s", detail)
        self.set_health(False, detail)

    # -- observation -----------------------------------------------------------------------
    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        stats["nod_plan"] = {"low_deg": self.plan.low_deg, "high_deg": self.plan.high_deg,
                             "rate_deg_s": self.plan.rate_deg_s,
                             "adaptive": self.plan.adaptive}
        return stats

    # -- Range3dSensor ---------------------------------------------------------------------
    async def get3dLaserFullScan(self) -> Range3dLaserIDL:
        """The latest scan line, static array; EDevIO before the first scan."""
        line: _ScanLine = self.latest.get()
        return line.laser

    async def get3dLaserWaitFullScan(self) -> Range3dLaserIDL:
        """The next scan line, static array; ETimeOut after Range3dSensor.wait_timeout."""
        line: _ScanLine = await self.latest.wait_next(Range3dSensor.wait_timeout)
        return line.laser

    async def get3dSeqFullScan(self) -> Range3dSeqEventIDL:
        """The latest scan line, valid points only; EDevIO before the first scan."""
        line: _ScanLine = self.latest.get()
        return line.seq

    async def get3dSeqWaitFullScan(self) -> Range3dSeqEventIDL:
        """The next scan line, valid points only; ETimeOut after wait_timeout."""
        line: _ScanLine = await self.latest.wait_next(Range3dSensor.wait_timeout)
        return line.seq

    async def get3dStereoFullScan(self) -> Range3dStereoEventIDL:
        """Raises EDevIO: a laser produces no stereo frames (as idl.Range3dSensor says)."""
        raise EDevIO(_NO_STEREO)

    async def get3dStereoWaitFullScan(self) -> Range3dStereoEventIDL:
        """Raises EDevIO: a laser produces no stereo frames (as idl.Range3dSensor says)."""
        raise EDevIO(_NO_STEREO)

    async def get3dArrayFullScan(self) -> Range3dArrayEventIDL:
        """Raises EDevIO: a laser produces no stereo frames (as idl.Range3dSensor says)."""
        raise EDevIO(_NO_STEREO)

    async def get3dArrayWaitFullScan(self) -> Range3dArrayEventIDL:
        """Raises EDevIO: a laser produces no stereo frames (as idl.Range3dSensor says)."""
        raise EDevIO(_NO_STEREO)


_NO_STEREO = "this sensor produces no stereo scans"


def _frame_name(frame_type: int) -> str:
    try:
        return FrameType(frame_type).name
    except ValueError:
        return f"frame type {frame_type:#04x}"


def _ack_name(result: int) -> str:
    try:
        return AckResult(result).name.lower().replace("_", " ")
    except ValueError:
        return f"result {result}"
