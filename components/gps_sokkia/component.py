"""The GPS Sokkia component: a Sokkia GSR2600 (NovAtel OEM4) on a serial port (seed §3.1.4,
Tables 7, 8, A.4).

A Publish Server and Reactor: the reactor owns the serial line and the
:class:`~components.gps_sokkia.codec.GpsDecoder`; this class combines the logs of one
measurement epoch into a :class:`~idl.GpsIDL`, keeps it for ``getPosition`` /
``getWaitPosition`` and publishes ``Raptor/<EventName>`` every 250 ms (the seed's rate).

At every (re)connection (``on_connect``) it sends, in abbreviated ASCII::

    unlogall thisport
    log bestposb ontime 0.25
    log bestvelb ontime 0.25
    log bestutmb ontime 0.25

Binary logs: 292 bytes per epoch (1168 B/s at 4 Hz) against about 3 kB/s for the ASCII
ones, and the doubles arrive exactly. Whatever arrives is accepted, though: the ASCII
forms of the same logs are handled identically, and when no NovAtel position log has
arrived for :data:`NOVATEL_HOLD` seconds, NMEA GGA/RMC/VTG sentences (a receiver or port
that ignores our commands) are combined the same way. Other logs, responses and prompts
are counted and ignored.

Epochs: the logs of one epoch carry the same GPS time (NMEA: the same UTC time).
:class:`EpochCombiner` groups them and releases an epoch as soon as every kind of log
the receiver is known to send has arrived, or when the next epoch starts. Eastings and
northings come from BESTUTM when it is logged, else from
:func:`~components.gps_sokkia.codec.latlon_to_utm`. See ``docs/protocols/gps_sokkia.md``,
"Driver".
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable
from dataclasses import dataclass, field
from typing import Any, ClassVar

from pydantic import ValidationError

from afa.codec import StreamDecoder
from afa.component import PublishServerReactor
from afa.polling import LatestSlot
from afa.reactor import Backoff
from afa.transport import ByteStream, DeviceSpec, SerialSpec
from components.gps_sokkia.codec import (
    BestPos,
    BestUtm,
    BestVel,
    CommandResponse,
    Gga,
    GpsDecoder,
    GpsMessage,
    PositionType,
    Rmc,
    SolutionStatus,
    UnknownLog,
    Vtg,
    encode_log_command,
    encode_unlogall_command,
    latlon_to_utm,
)
from components.gps_sokkia.parameters import GpsSokkiaParameters
from idl import UTM_ZONE_LETTERS, GpsIDL, TimeIDL
from idl import Gps as GpsInterface

__all__ = [
    "GpsSokkia", "EpochCombiner", "Epoch", "LOG_PERIOD", "PUBLISH_PERIOD", "NOVATEL_HOLD",
    "REQUESTED_LOGS", "VELOCITY_MAX_AGE", "configuration_commands", "nmea_quality_to_novatel",
    "novatel_epoch_to_idl", "nmea_epoch_to_idl",
]

#: The seed's publication period (Table 7: GpsIDL every 250 msec).
PUBLISH_PERIOD = 0.25
#: The ONTIME period requested from the receiver.
LOG_PERIOD = 0.25
#: The logs requested at every connection (binary; the ASCII forms are accepted too).
REQUESTED_LOGS: tuple[str, ...] = ("BESTPOSB", "BESTVELB", "BESTUTMB")
#: NMEA sentences are ignored while a NovAtel position log arrived this recently (s).
NOVATEL_HOLD = 2.0
#: An epoch without a velocity log reuses the previous velocity if it is this recent (s).
VELOCITY_MAX_AGE = 1.0
#: Device-time tolerance of the publication grid (the receiver's times are exact to 1 ms).
_PUBLISH_TOLERANCE = 0.001
_SECONDS_PER_WEEK = 604800

# NMEA GGA fix quality (NovAtel GPGGA page: 0 invalid, 1 single point, 2 pseudorange
# differential, 4 RTK fixed, 5 RTK float, 6 dead reckoning, 7 manual input, 8 simulator,
# 9 WAAS) -> NovAtel position type. 3 (PPS) is not used by NovAtel; read as SINGLE.
_QUALITY_TYPES: dict[int, PositionType] = {
    1: PositionType.SINGLE, 2: PositionType.PSRDIFF, 3: PositionType.SINGLE,
    4: PositionType.NARROW_INT, 5: PositionType.NARROW_FLOAT, 6: PositionType.PROPAGATED,
    7: PositionType.FIXEDPOS, 8: PositionType.SINGLE, 9: PositionType.WAAS,
}
# RMC/VTG mode indicator (NMEA 2.3) -> position type when no GGA is available.
_MODE_TYPES: dict[str, PositionType] = {
    "A": PositionType.SINGLE, "D": PositionType.PSRDIFF, "E": PositionType.PROPAGATED,
    "M": PositionType.FIXEDPOS, "S": PositionType.SINGLE, "N": PositionType.NONE,
}


def configuration_commands() -> list[bytes]:
    """The command lines sent at every connection (see the module docstring)."""
    commands = [encode_unlogall_command("THISPORT")]
    commands += [encode_log_command(name, port=None, trigger="ONTIME", period_s=LOG_PERIOD)
                 for name in REQUESTED_LOGS]
    return commands


def nmea_quality_to_novatel(quality: int) -> tuple[SolutionStatus, PositionType]:
    """The NovAtel solution status and position type of a GGA fix quality."""
    if quality == 0:
        return SolutionStatus.INSUFFICIENT_OBS, PositionType.NONE
    return SolutionStatus.SOL_COMPUTED, _QUALITY_TYPES.get(quality, PositionType.SINGLE)


# ----------------------------------------------------------------------------- epochs


@dataclass
class Epoch:
    """The logs of one measurement epoch: ``parts`` maps a log kind to its message.

    ``key`` identifies the epoch (GPS week and milliseconds, or NMEA UTC milliseconds;
    None until a timed log arrives); ``time`` is the clock time its first log arrived.
    """

    key: Hashable | None
    time: float
    parts: dict[str, GpsMessage] = field(default_factory=dict)


class EpochCombiner:
    """Groups logs by epoch and releases each epoch once, as soon as it is complete.

    ``expected`` are the log kinds an epoch should have (what was requested); an epoch is
    complete when it has all of them and at least one of ``anchors`` (a log with a
    position). The expectation adapts to what the receiver really sends: an epoch that
    is superseded by the next one before it is complete is released as it is (if it has
    an anchor) and the kinds it lacked are no longer waited for; a kind that arrives
    unexpectedly is waited for from then on. A log for an epoch already released
    (``late``) is dropped. Logs without a time (``key`` None, e.g. VTG) join the epoch
    being assembled, or the one just released if it lacks that kind. Never raises.
    """

    def __init__(self, expected: Iterable[str], anchors: Iterable[str]) -> None:
        self._initial = frozenset(expected)
        self.anchors = frozenset(anchors)
        self.expected: set[str] = set(self._initial)
        self._pending: Epoch | None = None
        self._last_key: Hashable | None = None
        self._last_kinds: set[str] = set()
        self.released = 0
        self.incomplete = 0
        self.dropped = 0
        self.late = 0

    def reset(self) -> None:
        """Forget the epoch being assembled and what was learnt (after a reconnect)."""
        self.expected = set(self._initial)
        self._pending = None
        self._last_key = None
        self._last_kinds = set()

    def add(self, kind: str, key: Hashable | None, message: GpsMessage,
            now: float) -> list[Epoch]:
        """Add one log; returns the epochs released by it (oldest first)."""
        released: list[Epoch] = []
        pending = self._pending
        if pending is not None and (
                (key is not None and pending.key is not None and key != pending.key)
                or kind in pending.parts):
            released += self._flush()
            pending = None
        if pending is None and ((key is not None and key == self._last_key) or (
                key is None and self._last_kinds and kind not in self._last_kinds)):
            # A part of the epoch just released (an untimed log joins the latest epoch).
            self.late += 1
            self._last_kinds.add(kind)
            self.expected.add(kind)
            return released
        self.expected.add(kind)
        if pending is None:
            pending = self._pending = Epoch(key, now)
        if pending.key is None:
            pending.key = key
        pending.parts[kind] = message
        if self.expected <= pending.parts.keys() and self.anchors & pending.parts.keys():
            released.append(self._release(pending))
        return released

    def _flush(self) -> list[Epoch]:
        pending = self._pending
        self._pending = None
        if pending is None:
            return []
        if not self.anchors & pending.parts.keys():
            self.dropped += 1
            return []
        self.incomplete += 1
        self.expected = set(pending.parts)
        return [self._release(pending)]

    def _release(self, epoch: Epoch) -> Epoch:
        self._pending = None
        self._last_key = epoch.key
        self._last_kinds = set(epoch.parts)
        self.released += 1
        return epoch


# ---------------------------------------------------------------- epochs -> GpsIDL


@dataclass(frozen=True, slots=True)
class _Velocity:
    speed: float
    track: float
    vertical: float


def _track(degrees: float) -> float:
    track = degrees % 360.0
    return 0.0 if track >= 360.0 else track  # -1e-17 % 360 == 360.0


def _utm(latitude: float, longitude: float) -> tuple[int, str, float, float]:
    try:
        utm = latlon_to_utm(latitude, longitude)
    except ValueError:  # polar: outside the UTM grid
        return 0, "", 0.0, 0.0
    return utm.zone_number, utm.zone_letter, utm.easting_m, utm.northing_m


def novatel_epoch_to_idl(epoch: Epoch, velocity: _Velocity | None = None) -> GpsIDL:
    """The GpsIDL of an epoch holding a BESTPOS and optionally BESTVEL and BESTUTM.

    ``velocity`` is used when the epoch has no valid BESTVEL. Raises KeyError without a
    BESTPOS and pydantic's ValidationError for values outside the IDL's ranges.
    """
    pos = epoch.parts["BESTPOS"]
    assert isinstance(pos, BestPos)
    vel = epoch.parts.get("BESTVEL")
    utm = epoch.parts.get("BESTUTM")
    has_fix = pos.solution_status is SolutionStatus.SOL_COMPUTED \
        and pos.position_type is not PositionType.NONE
    if isinstance(utm, BestUtm) and utm.solution_status is SolutionStatus.SOL_COMPUTED \
            and 1 <= utm.zone_number <= 60 and len(utm.zone_letter) == 1 \
            and utm.zone_letter in UTM_ZONE_LETTERS:
        zone, letter, easting, northing = (utm.zone_number, utm.zone_letter, utm.easting_m,
                                           utm.northing_m)
    elif has_fix:
        zone, letter, easting, northing = _utm(pos.latitude_deg, pos.longitude_deg)
    else:
        zone, letter, easting, northing = 0, "", 0.0, 0.0
    if isinstance(vel, BestVel) and vel.solution_status is SolutionStatus.SOL_COMPUTED:
        velocity = _Velocity(vel.horizontal_speed_m_s, vel.track_over_ground_deg,
                             vel.vertical_speed_m_s)
    velocity = velocity or _Velocity(0.0, 0.0, 0.0)
    return GpsIDL(
        time=TimeIDL.from_seconds(epoch.time),
        latitude=pos.latitude_deg, longitude=pos.longitude_deg,
        elevation=pos.height_msl_m, undulation=pos.undulation_m,
        easting=easting, northing=northing, utmZone=zone, utmZoneLetter=letter,
        satellitesTracked=pos.satellites_tracked,
        satellitesUsed=pos.satellites_in_solution,
        horizontalSpeed=abs(velocity.speed), track=_track(velocity.track),
        verticalSpeed=velocity.vertical,
        solutionStatus=pos.solution_status.name, positionType=pos.position_type.name,
        latitudeStd=abs(pos.latitude_std_m), longitudeStd=abs(pos.longitude_std_m),
        elevationStd=abs(pos.height_std_m),
        differentialAge=max(0.0, pos.differential_age_s),
        solutionAge=max(0.0, pos.solution_age_s), baseStationId=pos.base_station_id,
    )


def nmea_epoch_to_idl(epoch: Epoch, velocity: _Velocity | None = None) -> GpsIDL:
    """The GpsIDL of an NMEA epoch holding a GGA and/or an RMC, optionally a VTG.

    Position from the RMC when it is valid (NovAtel prints 7 decimals of a minute there,
    4 in GGA), else from the GGA; fix type, satellites, heights and differential data
    from the GGA. NMEA has no standard deviations: they are 0 (unknown). Raises
    KeyError without GGA and RMC, ValidationError for values outside the IDL's ranges.
    """
    gga = epoch.parts.get("GGA")
    rmc = epoch.parts.get("RMC")
    vtg = epoch.parts.get("VTG")
    if not isinstance(gga, Gga) and not isinstance(rmc, Rmc):
        raise KeyError("an NMEA epoch needs a GGA or an RMC")
    latitude = longitude = None
    if isinstance(rmc, Rmc) and rmc.valid:
        latitude, longitude = rmc.latitude_deg, rmc.longitude_deg
    if (latitude is None or longitude is None) and isinstance(gga, Gga):
        latitude, longitude = gga.latitude_deg, gga.longitude_deg
    if isinstance(gga, Gga):
        status, ptype = nmea_quality_to_novatel(gga.quality)
    else:
        assert isinstance(rmc, Rmc)
        ptype = _MODE_TYPES.get(rmc.mode, PositionType.SINGLE) if rmc.valid \
            else PositionType.NONE
        status = SolutionStatus.SOL_COMPUTED if ptype is not PositionType.NONE \
            else SolutionStatus.INSUFFICIENT_OBS
    if latitude is None or longitude is None:
        latitude = longitude = 0.0
        status, ptype = SolutionStatus.INSUFFICIENT_OBS, PositionType.NONE
    has_fix = status is SolutionStatus.SOL_COMPUTED and ptype is not PositionType.NONE
    zone, letter, easting, northing = _utm(latitude, longitude) if has_fix else (0, "", 0.0, 0.0)
    if isinstance(vtg, Vtg) and vtg.speed_m_s is not None:
        velocity = _Velocity(vtg.speed_m_s, vtg.course_true_deg or 0.0, 0.0)
    elif isinstance(rmc, Rmc) and rmc.valid and rmc.speed_m_s is not None:
        velocity = _Velocity(rmc.speed_m_s, rmc.course_deg or 0.0, 0.0)
    velocity = velocity or _Velocity(0.0, 0.0, 0.0)
    satellites = gga.satellites if isinstance(gga, Gga) and gga.satellites is not None else 0
    return GpsIDL(
        time=TimeIDL.from_seconds(epoch.time),
        latitude=latitude, longitude=longitude,
        elevation=(gga.altitude_msl_m or 0.0) if isinstance(gga, Gga) else 0.0,
        undulation=(gga.geoid_separation_m or 0.0) if isinstance(gga, Gga) else 0.0,
        easting=easting, northing=northing, utmZone=zone, utmZoneLetter=letter,
        satellitesTracked=satellites, satellitesUsed=satellites,
        horizontalSpeed=abs(velocity.speed), track=_track(velocity.track),
        verticalSpeed=velocity.vertical,
        solutionStatus=status.name, positionType=ptype.name,
        differentialAge=max(0.0, gga.dgps_age_s or 0.0) if isinstance(gga, Gga) else 0.0,
        baseStationId=gga.dgps_station if isinstance(gga, Gga) else "",
    )


# -------------------------------------------------------------------------- component


class GpsSokkia(PublishServerReactor[GpsSokkiaParameters, GpsMessage]):
    """The Raptor's GPS component (seed §3.1.4); serves the ``Gps`` interface.

    Polls: ``getPosition`` (latest fix; EDevIO before the first one) and
    ``getWaitPosition`` (next fix; ETimeOut after ``Gps.wait_timeout``). Every epoch
    updates the polled fix; events are published on a 250 ms grid of the receiver's
    own time (so a receiver logging faster is decimated, never published twice). With
    ``Notify`` false no events are published but polls are answered. ``ChannelName``
    is accepted for configuration compatibility: afa has one event channel.
    """

    #: No message for 2 s (the receiver logs at 4 Hz) means the device is lost.
    stale_after = 2.0
    backoff: ClassVar[Backoff] = Backoff(initial=0.2, factor=2.0, maximum=5.0)

    def __init__(self, name: str = "Gps", parameters: GpsSokkiaParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self._events = self.publishes(p.EventName, GpsIDL, enabled=p.Notify)
        self.serves(GpsInterface, p.EventName)
        self._novatel = EpochCombiner({"BESTPOS", "BESTVEL", "BESTUTM"}, {"BESTPOS"})
        self._nmea = EpochCombiner({"GGA"}, {"GGA", "RMC"})
        self._latest: LatestSlot[GpsIDL] | None = None
        self._novatel_seen: float | None = None
        self._velocity: tuple[float, _Velocity] | None = None
        self._last_published: float | None = None
        self.source: str | None = None  # "novatel" or "nmea": where the last fix came from
        self.fixes = 0
        self.published = 0
        self.rejected = 0
        self.ignored_nmea = 0
        self.unknown_logs = 0
        self.command_errors = 0

    # -- PSR hooks ---------------------------------------------------------------------
    async def setup(self) -> None:
        self._latest = self.slot("GPS fix")

    def device(self) -> DeviceSpec:
        return SerialSpec(self.parameters.Device, self.parameters.Baudrate)

    def decoder(self) -> StreamDecoder[GpsMessage]:
        return GpsDecoder()

    async def on_connect(self, stream: ByteStream) -> None:
        """Stop every log on this port, then request the three binary logs at 4 Hz.

        Responses are not awaited (they are decoded and counted like any message): a
        receiver that ignores the commands but talks NMEA still works. Raises EDevIO
        (from the stream) if the device goes away meanwhile; the reactor reconnects.
        """
        self._novatel.reset()
        self._nmea.reset()
        self._novatel_seen = None
        self._last_published = None
        for command in configuration_commands():
            await stream.write(command)

    def handle(self, message: GpsMessage) -> None:
        now = self.clock.now()  # the fix's time stamp
        if isinstance(message, (BestPos, BestVel, BestUtm)):
            self._novatel_seen = self.clock.monotonic()
            key = (message.header.gps_week, round(message.header.gps_seconds * 1000))
            for epoch in self._novatel.add(message.header.name, key, message, now):
                self._integrate(epoch, "novatel")
        elif isinstance(message, (Gga, Rmc, Vtg)):
            if (self._novatel_seen is not None
                    and self.clock.monotonic() - self._novatel_seen < NOVATEL_HOLD):
                self.ignored_nmea += 1
                return
            utc = None if isinstance(message, Vtg) else message.utc_seconds
            nmea_key = None if utc is None else round(utc * 1000)
            kind = type(message).__name__.upper()
            for epoch in self._nmea.add(kind, nmea_key, message, now):
                self._integrate(epoch, "nmea")
        elif isinstance(message, CommandResponse):
            if not message.ok:
                self.command_errors += 1
                self.log.warning("receiver rejected a command: %s", message.text)
        elif isinstance(message, UnknownLog):
            self.unknown_logs += 1
        # Prompts need nothing.

    # -- polls (idl.Gps) ---------------------------------------------------------------
    async def getPosition(self) -> GpsIDL:
        """The latest fix; raises EDevIO if none has been received yet."""
        assert self._latest is not None
        return self._latest.get()

    async def getWaitPosition(self) -> GpsIDL:
        """The next fix; raises ETimeOut after ``Gps.wait_timeout`` seconds."""
        assert self._latest is not None
        return await self._latest.wait_next(GpsInterface.wait_timeout)

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(
            fixes=self.fixes, published=self.published, rejected=self.rejected,
            source=self.source, ignored_nmea=self.ignored_nmea,
            unknown_logs=self.unknown_logs, command_errors=self.command_errors,
            incomplete_epochs=self._novatel.incomplete + self._nmea.incomplete,
            late_logs=self._novatel.late + self._nmea.late,
            dropped_epochs=self._novatel.dropped + self._nmea.dropped)
        return stats

    # -- internals ---------------------------------------------------------------------
    def _integrate(self, epoch: Epoch, source: str) -> None:
        """Convert one epoch, keep it for the polls, publish it if its slot is due."""
        carried = None
        if self._velocity is not None and epoch.time - self._velocity[0] <= VELOCITY_MAX_AGE:
            carried = self._velocity[1]
        device_time: float | None
        try:
            if source == "novatel":
                body = novatel_epoch_to_idl(epoch, carried)
                device_time = self._novatel_time(epoch)
            else:
                body = nmea_epoch_to_idl(epoch, carried)
                device_time = (None if epoch.key is None
                               else float(epoch.key) / 1000.0)  # type: ignore[arg-type]
        except (ValidationError, KeyError) as exc:
            self.rejected += 1
            self.log.warning("dropping a GPS epoch that does not fit GpsIDL: %s", exc)
            return
        if self._has_velocity(epoch):
            self._velocity = (epoch.time, _Velocity(body.horizontalSpeed, body.track,
                                                    body.verticalSpeed))
        self.fixes += 1
        self.source = source
        assert self._latest is not None
        self._latest.set(body)
        if self._events.enabled and self._due(epoch.time if device_time is None
                                              else device_time):
            self._events.publish(body)
            self.published += 1

    @staticmethod
    def _novatel_time(epoch: Epoch) -> float:
        week, ms = epoch.key  # type: ignore[misc]
        return week * _SECONDS_PER_WEEK + ms / 1000.0

    @staticmethod
    def _has_velocity(epoch: Epoch) -> bool:
        vel = epoch.parts.get("BESTVEL")
        if isinstance(vel, BestVel):
            return vel.solution_status is SolutionStatus.SOL_COMPUTED
        vtg, rmc = epoch.parts.get("VTG"), epoch.parts.get("RMC")
        return (isinstance(vtg, Vtg) and vtg.speed_m_s is not None) or \
            (isinstance(rmc, Rmc) and rmc.valid and rmc.speed_m_s is not None)

    def _due(self, device_time: float) -> bool:
        """True if ``device_time`` opens the next slot of the publication grid.

        A time that goes backwards (NMEA midnight, a receiver reset) restarts the grid.
        """
        last = self._last_published
        if last is None or device_time < last \
                or device_time - last >= PUBLISH_PERIOD - _PUBLISH_TOLERANCE:
            self._last_published = device_time
            return True
        return False
