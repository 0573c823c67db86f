"""A fake Sokkia GSR2600 (NovAtel OEM4): the device side of the GPS codec, for tests and
simulation.

:class:`FakeGps` decodes the host's abbreviated ASCII commands with
:class:`~components.gps_sokkia.codec.GpsDeviceDecoder` and obeys them as the receiver
does: ``LOG [port] <name> [trigger [period [offset]]]`` adds a log, ``UNLOG`` removes
one, ``UNLOGALL`` clears the port, ``COM`` is acknowledged; each is answered with
``<OK`` (or ``<ERROR:...``) and the port prompt. Logs it can produce: BESTPOS, BESTVEL,
BESTUTM in ASCII (suffix ``A``) or binary (``B``), and GPGGA, GPRMC, GPVTG.

Timing: the receiver computes a solution every ``solution_period`` seconds (default
50 ms, 20 Hz) aligned to whole GPS time; an ``ONTIME p [offset]`` log is sent at the
solutions whose GPS time is a multiple of ``p`` (plus the offset), ``ONNEW`` /
``ONCHANGED`` logs at every solution, ``ONNEXT`` at the next one, ``ONCE`` at once. All
logs of one solution carry the same GPS time and are written in the order they were
requested. GPS time is the clock's UTC plus the GPS-UTC leap seconds.

Physical values come from ``source(t) -> GpsTruth`` (t: clock seconds), so the
simulator can plug in the vehicle's ground truth; the default is a receiver standing
still near DRDC Suffield. With a seeded ``numpy.random.Generator`` the fake adds the
noise of a differentially corrected receiver (:class:`GpsNoise`): position error as a
first-order Gauss-Markov process (0.3 m horizontal, 0.6 m vertical, 1 sigma), white
velocity noise (which makes the track erratic when standing still, as the seed notes),
and a satellite count that wanders by one. Runs are deterministic for a given seed
and clock.

The receiver keeps its logs across connections, as a powered receiver does when its
cable is pulled. ``obey_commands=False`` plays a receiver (or a port in an NMEA-only
interface mode) that ignores the host and just streams the logs it was configured with.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np

from afa.clock import Clock
from afa.codec import StreamDecoder
from afa.errors import EDevIO
from afa.fake import FakeDevice
from afa.transport import ByteStream
from components.gps_sokkia.codec import (
    KNOTS_TO_MPS,
    BestPos,
    BestUtm,
    BestVel,
    Gga,
    GpsCommand,
    GpsDeviceDecoder,
    LogCommand,
    LogHeader,
    OtherCommand,
    PositionType,
    Rmc,
    SolutionStatus,
    TimeStatus,
    UnlogAllCommand,
    UnlogCommand,
    Vtg,
    encode_bestpos_ascii,
    encode_bestpos_binary,
    encode_bestutm_ascii,
    encode_bestutm_binary,
    encode_bestvel_ascii,
    encode_bestvel_binary,
    encode_gga,
    encode_prompt,
    encode_response,
    encode_rmc,
    encode_vtg,
    latlon_to_utm,
)

__all__ = [
    "FakeGps", "GpsTruth", "GpsNoise", "GpsSource", "standing_still", "gps_time",
    "gps_utc_offset", "SUPPORTED_LOGS", "GPS_EPOCH_UNIX",
]

#: 1980-01-06 00:00:00 UTC, the start of GPS time, in Unix seconds.
GPS_EPOCH_UNIX = 315964800
_SECONDS_PER_WEEK = 604800

# GPS - UTC in seconds from each date on (IERS Bulletin C leap seconds since 1999).
_LEAP_SECONDS: tuple[tuple[int, int], ...] = (
    (915148800, 13),   # 1999-01-01
    (1136073600, 14),  # 2006-01-01
    (1230768000, 15),  # 2009-01-01
    (1341100800, 16),  # 2012-07-01
    (1435708800, 17),  # 2015-07-01
    (1483228800, 18),  # 2017-01-01
)

#: Log names the fake produces (format suffix included).
SUPPORTED_LOGS = frozenset({"BESTPOSA", "BESTPOSB", "BESTVELA", "BESTVELB", "BESTUTMA",
                            "BESTUTMB", "GPGGA", "GPRMC", "GPVTG"})

_WGS84_A = 6378137.0
_WGS84_E2 = (1 / 298.257223563) * (2 - 1 / 298.257223563)

# NovAtel position type -> NMEA GGA quality (NovAtel GPGGA page).
_GGA_QUALITY: dict[PositionType, int] = {
    PositionType.NONE: 0, PositionType.SINGLE: 1, PositionType.PSRDIFF: 2,
    PositionType.WAAS: 9, PositionType.OMNISTAR: 2, PositionType.CDGPS: 2,
    PositionType.NARROW_INT: 4, PositionType.WIDE_INT: 4, PositionType.L1_INT: 4,
    PositionType.NARROW_FLOAT: 5, PositionType.L1_FLOAT: 5, PositionType.IONOFREE_FLOAT: 5,
    PositionType.FLOATCONV: 5, PositionType.PROPAGATED: 6, PositionType.FIXEDPOS: 7,
}


def gps_utc_offset(unix_seconds: float) -> int:
    """GPS time minus UTC (leap seconds) at ``unix_seconds``; 13 before 1999 is not
    modelled (returns 13)."""
    offset = _LEAP_SECONDS[0][1]
    for start, value in _LEAP_SECONDS:
        if unix_seconds >= start:
            offset = value
    return offset


def gps_time(unix_seconds: float) -> tuple[int, int]:
    """GPS week and milliseconds of week at ``unix_seconds`` (UTC), rounded to 1 ms."""
    ms = round((unix_seconds - GPS_EPOCH_UNIX + gps_utc_offset(unix_seconds)) * 1000)
    week, ms_of_week = divmod(ms, _SECONDS_PER_WEEK * 1000)
    return week, ms_of_week


@dataclass(frozen=True, slots=True)
class GpsTruth:
    """What the receiver would measure without error: the simulator's ground truth.

    ``lat``/``lon`` in degrees (WGS-84), ``height`` above mean sea level in metres,
    ``undulation`` geoid minus ellipsoid (m), ``speed`` over ground (m/s), ``track``
    clockwise from true north (degrees), ``vertical_speed`` up positive (m/s). The
    reception fields let a simulator model an outage (``position_type=NONE``).
    """

    lat: float
    lon: float
    height: float
    speed: float = 0.0
    track: float = 0.0
    vertical_speed: float = 0.0
    undulation: float = -16.5
    satellites_tracked: int = 10
    satellites_used: int = 9
    solution_status: SolutionStatus = SolutionStatus.SOL_COMPUTED
    position_type: PositionType = PositionType.PSRDIFF
    differential_age: float = 1.0
    base_station_id: str = "0"


GpsSource = Callable[[float], GpsTruth]


def standing_still(t: float) -> GpsTruth:
    """The default source: a receiver at rest near DRDC Suffield, Alberta."""
    return GpsTruth(lat=50.2667, lon=-111.1750, height=750.0)


@dataclass(frozen=True, slots=True)
class GpsNoise:
    """The fake's error model (1 sigma).

    Horizontal and vertical position errors are first-order Gauss-Markov processes with
    ``correlation_time`` seconds (0: white), typical of pseudorange-differential fixes
    (sub-metre); velocity errors are white per axis. ``satellite_step_rate`` is the
    chance per second that the number of satellites used changes by one. The reported
    standard deviations are these sigmas.
    """

    horizontal: float = 0.3
    vertical: float = 0.6
    velocity: float = 0.03
    correlation_time: float = 10.0
    satellite_step_rate: float = 0.05


@dataclass(slots=True)
class _Solution:
    """One solution: what every log of an epoch reports."""

    unix: float
    week: int
    ms: int
    truth: GpsTruth
    lat: float
    lon: float
    height: float
    speed: float
    track: float
    vertical_speed: float
    satellites_used: int


@dataclass(slots=True)
class _ActiveLog:
    command: LogCommand
    order: int
    done: bool = field(default=False)


class FakeGps(FakeDevice[GpsCommand]):
    """The device side of a GSR2600 (see the module docstring).

    Args: ``clock``; ``source`` of ground truth; ``rng`` (None: no noise); ``noise``
    model; ``port`` the host is cabled to; ``logs`` active at power-up, as
    ``{name: ONTIME period}``; ``obey_commands`` (False: ignore the host);
    ``solution_period`` in seconds.
    """

    name = "gps"

    def __init__(self, clock: Clock, source: GpsSource = standing_still,
                 rng: np.random.Generator | None = None, *, noise: GpsNoise = GpsNoise(),
                 port: str = "COM1", logs: Mapping[str, float] | None = None,
                 obey_commands: bool = True, solution_period: float = 0.05) -> None:
        super().__init__(clock)
        if solution_period <= 0:
            raise ValueError("solution_period must be > 0")
        if clock.now() < GPS_EPOCH_UNIX:
            raise ValueError(
                f"the clock's time stamp {clock.now():g} s is before the GPS epoch "
                "(1980-01-06), where a receiver's time begins: use a clock with later "
                "stamps, e.g. VirtualClock() (2005-09-17) rather than VirtualClock(start=0)")
        self.source = source
        self.rng = rng
        self.noise = noise
        self.port = port.upper()
        self.obey_commands = obey_commands
        self.solution_period = solution_period
        self.active: dict[str, _ActiveLog] = {}
        self._order = 0
        for name, period in (logs or {}).items():
            self._add(LogCommand(self.port, name.upper(), "ONTIME", period))
        self.sequence = 0
        #: The latest solutions computed (newest last), for tests and the simulator.
        self.solutions: deque[_Solution] = deque(maxlen=1024)
        self._error_n = np.zeros(3)  # north, east, up position error (m)
        self._error_time: float | None = None
        self._satellite_offset = 0
        self._corrupt = 0
        self._live: ByteStream | None = None

    # -- test and simulator controls ----------------------------------------------------
    def corrupt_next(self, count: int = 1) -> None:
        """Flip one byte inside each of the next ``count`` logs sent (bad checksum)."""
        self._corrupt += count

    async def inject(self, data: bytes) -> None:
        """Write raw bytes (line noise) to the host now; raises EDevIO if unconnected."""
        if self._live is None or self._live.closed:
            raise EDevIO("gps: no host connected")
        await self._live.write(data)

    def truth(self, t: float) -> GpsTruth:
        """The ground truth at clock time ``t``."""
        return self.source(t)

    # -- FakeDevice hooks ---------------------------------------------------------------
    def command_decoder(self) -> StreamDecoder[GpsCommand]:
        return GpsDeviceDecoder()

    async def on_command(self, command: GpsCommand, stream: ByteStream) -> None:
        if not self.obey_commands:
            return
        ok, error = True, ""
        once: str | None = None  # a LOG ... ONCE is answered first, then sent
        if isinstance(command, LogCommand):
            if command.message not in SUPPORTED_LOGS:
                ok, error = False, "Invalid Message ID"
            elif self._on_this_port(command.port):
                if command.trigger == "ONCE":
                    once = command.message
                elif command.trigger != "ONMARK":  # no mark input on the fake
                    self._add(command)
        elif isinstance(command, UnlogCommand):
            if self._on_this_port(command.port):
                if self.active.pop(command.message, None) is None:
                    ok, error = False, "Invalid Message ID"
        elif isinstance(command, UnlogAllCommand):
            if self._on_this_port(command.port) or command.port in ("ALLPORTS", "THISPORT_ALL"):
                self.active.clear()
        elif isinstance(command, OtherCommand):
            if not command.valid:
                ok, error = False, "Invalid Message. Field = 2"
            elif command.verb != "COM":
                ok, error = False, "Invalid Message ID"
        await stream.write(encode_response(ok, error) + encode_prompt(self.port))
        if once is not None:
            await self._emit(stream, self._solve(self.clock.now()), [once])

    async def produce(self, stream: ByteStream) -> None:
        self._live = stream
        try:
            period = self.solution_period
            now = self.clock.now()  # GPS time is wall time; solutions align to its grid
            start = math.ceil(now / period - 1e-9) * period
            first = self.clock.monotonic() + (start - now)
            async for tick in self.clock.periodic(period, first=first):
                t = start + tick * period
                due = self._due(t)
                if due:
                    await self._emit(stream, self._solve(t), due)
        finally:
            if self._live is stream:
                self._live = None

    # -- internals ----------------------------------------------------------------------
    def _on_this_port(self, port: str | None) -> bool:
        return port is None or port in ("THISPORT", self.port)

    def _add(self, command: LogCommand) -> None:
        if command.message in self.active:
            self.active[command.message].command = command  # a new LOG replaces the old
            return
        self.active[command.message] = _ActiveLog(command, self._order)
        self._order += 1

    def _due(self, t: float) -> list[str]:
        """Names of the logs due at the solution of clock time ``t``, in request order."""
        _, ms = gps_time(t)
        due: list[str] = []
        for name, log in sorted(self.active.items(), key=lambda item: item[1].order):
            command = log.command
            if command.trigger == "ONTIME":
                period_ms = round(command.period_s * 1000)
                offset_ms = round(command.offset_s * 1000)
                if period_ms <= 0 or (ms - offset_ms) % period_ms == 0:
                    due.append(name)
            elif command.trigger in ("ONNEW", "ONCHANGED"):
                due.append(name)
            elif command.trigger == "ONNEXT" and not log.done:
                log.done = True
                due.append(name)
        for name in [n for n, log in self.active.items() if log.done]:
            del self.active[name]
        return due

    def _solve(self, t: float) -> _Solution:
        """The receiver's solution at clock time ``t``: truth plus the error model."""
        truth = self.source(t)
        week, ms = gps_time(t)
        lat, lon, height = truth.lat, truth.lon, truth.height
        speed, track, vertical = truth.speed, truth.track, truth.vertical_speed
        used = truth.satellites_used
        if self.rng is not None:
            noise = self.noise
            first = self._error_time is None
            dt = 0.0 if self._error_time is None else max(0.0, t - self._error_time)
            self._error_time = t
            sigma = np.array([noise.horizontal, noise.horizontal, noise.vertical])
            if first or noise.correlation_time <= 0:
                self._error_n = sigma * self.rng.standard_normal(3)
            elif dt > 0:
                a = math.exp(-dt / noise.correlation_time)
                self._error_n = a * self._error_n + math.sqrt(1 - a * a) * sigma * \
                    self.rng.standard_normal(3)
            d_north, d_east, d_up = (float(v) for v in self._error_n)
            m_radius, n_radius = _radii(lat)
            lon += math.degrees(d_east / ((n_radius + height) * math.cos(math.radians(lat))))
            lat += math.degrees(d_north / (m_radius + height))
            height += d_up
            v_north = speed * math.cos(math.radians(track)) + noise.velocity * \
                float(self.rng.standard_normal())
            v_east = speed * math.sin(math.radians(track)) + noise.velocity * \
                float(self.rng.standard_normal())
            vertical += noise.velocity * float(self.rng.standard_normal())
            speed = math.hypot(v_north, v_east)
            track = math.degrees(math.atan2(v_east, v_north)) % 360.0
            if self.rng.random() < noise.satellite_step_rate * dt:
                self._satellite_offset += int(self.rng.choice((-1, 1)))
            self._satellite_offset = max(-2, min(0, self._satellite_offset))
            used = max(0, min(truth.satellites_tracked, used + self._satellite_offset))
        if truth.position_type is PositionType.NONE \
                or truth.solution_status is not SolutionStatus.SOL_COMPUTED:
            lat = lon = height = speed = track = vertical = 0.0
            used = 0
        solution = _Solution(t, week, ms, truth, lat, lon, height, speed, track % 360.0,
                             vertical, used)
        self.solutions.append(solution)
        return solution

    async def _emit(self, stream: ByteStream, solution: _Solution, names: list[str]) -> None:
        for name in names:
            frame = self._encode(name, solution)
            if self._corrupt > 0:
                self._corrupt -= 1
                damaged = bytearray(frame)
                damaged[len(frame) // 2] ^= 0x01  # inside the payload: a checksum failure
                frame = bytes(damaged)
            await stream.write(frame)

    def _header(self, name: str, solution: _Solution) -> LogHeader:
        return LogHeader(name=name, port=self.port, sequence=0, idle_time_percent=80.0,
                         time_status=TimeStatus.FINESTEERING, gps_week=solution.week,
                         gps_seconds=solution.ms / 1000.0)

    def _encode(self, name: str, s: _Solution) -> bytes:
        truth = s.truth
        noise = self.noise
        status, ptype = truth.solution_status, truth.position_type
        if name.startswith("BESTPOS"):
            pos = BestPos(self._header("BESTPOS", s), status, ptype, s.lat, s.lon, s.height,
                          truth.undulation, "WGS84", noise.horizontal, noise.horizontal,
                          noise.vertical, truth.base_station_id, truth.differential_age, 0.0,
                          truth.satellites_tracked, s.satellites_used)
            return encode_bestpos_binary(pos) if name.endswith("B") else encode_bestpos_ascii(pos)
        if name.startswith("BESTVEL"):
            vtype = ptype if ptype is PositionType.NONE else PositionType.DOPPLER_VELOCITY
            vel = BestVel(self._header("BESTVEL", s), status, vtype, 0.0, 0.0, s.speed,
                          s.track, s.vertical_speed)
            return encode_bestvel_binary(vel) if name.endswith("B") else encode_bestvel_ascii(vel)
        if name.startswith("BESTUTM"):
            utm = latlon_to_utm(s.lat, s.lon)
            msg = BestUtm(self._header("BESTUTM", s), status, ptype, utm.zone_number,
                          utm.zone_letter, utm.northing_m, utm.easting_m, s.height,
                          truth.undulation, "WGS84", noise.horizontal, noise.horizontal,
                          noise.vertical, truth.base_station_id, truth.differential_age,
                          0.0, truth.satellites_tracked, s.satellites_used)
            return encode_bestutm_binary(msg) if name.endswith("B") else encode_bestutm_ascii(msg)
        has_fix = status is SolutionStatus.SOL_COMPUTED and ptype is not PositionType.NONE
        utc = s.unix % 86400.0
        mode = "N" if not has_fix else ("A" if ptype is PositionType.SINGLE else "D")
        if name == "GPGGA":
            quality = _GGA_QUALITY.get(ptype, 1) if has_fix else 0
            differential = quality in (2, 4, 5, 9)
            gga = Gga("GP", utc, s.lat if has_fix else None, s.lon if has_fix else None,
                      quality, s.satellites_used, 0.9 if has_fix else None,
                      s.height if has_fix else None, truth.undulation if has_fix else None,
                      truth.differential_age if differential else None,
                      truth.base_station_id if differential else "")
            return encode_gga(gga, minute_decimals=4)  # NovAtel's GPGGA precision
        day = datetime.fromtimestamp(s.unix, UTC).date()
        if name == "GPRMC":
            rmc = Rmc("GP", utc, has_fix, s.lat if has_fix else None,
                      s.lon if has_fix else None, s.speed / KNOTS_TO_MPS, s.track, day, 0.0,
                      mode)
            return encode_rmc(rmc)
        assert name == "GPVTG", name
        vtg = Vtg("GP", s.track, s.track, s.speed / KNOTS_TO_MPS, s.speed * 3.6, mode)
        return encode_vtg(vtg)


def _radii(latitude_deg: float) -> tuple[float, float]:
    """Meridian and prime-vertical radii of curvature (m) of WGS-84 at a latitude."""
    s = math.sin(math.radians(latitude_deg))
    w = 1.0 - _WGS84_E2 * s * s
    return _WGS84_A * (1.0 - _WGS84_E2) / w ** 1.5, _WGS84_A / math.sqrt(w)

