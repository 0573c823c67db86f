"""Sokkia GSR2600 (NovAtel OEM4 firmware) serial protocol: a sans-I/O codec for both ends.

The receiver talks three framings on one port, interleaved:

- NovAtel ASCII logs: ``#BESTPOSA,<header>;<data>*xxxxxxxx`` + CR LF, where
  ``xxxxxxxx`` is the NovAtel CRC-32 of every byte between ``#`` and ``*``;
- NovAtel binary logs: sync ``AA 44 12``, a 28-byte little-endian header, the payload,
  then the CRC-32 of header + payload (little-endian);
- NMEA 0183 sentences: ``$GPGGA,...*hh`` + CR LF, ``hh`` the XOR of the bytes between
  ``$`` and ``*``;

plus the short abbreviated-ASCII command responses ``<OK`` / ``<ERROR:...`` and the port
prompt ``[COM1]``.

Host side (the GPS component): :class:`GpsDecoder` decodes all of the above from one
stream; ``encode_*_command`` functions build the abbreviated ASCII commands the host
sends (``log com1 bestposa ontime 0.25``, ``unlogall``). Device side (the fake receiver
and the simulator): ``encode_best*_ascii`` / ``encode_best*_binary`` / ``encode_gga`` ...
build what the receiver sends, and :class:`GpsDeviceDecoder` decodes the host's
commands. :func:`latlon_to_utm` converts WGS-84 latitude/longitude to UTM because the
GpsIDL carries eastings/northings and BESTUTM may not be logged.

Units: degrees, metres, seconds, metres per second (NMEA speeds are also kept in the
units the sentence carries: knots, km/h). Byte layouts and sources:
``docs/protocols/gps_sokkia.md``.
"""

from __future__ import annotations

import binascii
import math
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass
from datetime import date
from enum import IntEnum
from typing import Final, TypeAlias, TypeVar

from afa.codec import Fault, Scan, StreamDecoder

__all__ = [
    "BESTPOS_ID",
    "BESTUTM_ID",
    "BESTVEL_ID",
    "BINARY_HEADER_LENGTH",
    "BINARY_SYNC",
    "KNOTS_TO_MPS",
    "MESSAGE_IDS",
    "BestPos",
    "BestUtm",
    "BestVel",
    "CommandResponse",
    "Gga",
    "GpsCommand",
    "GpsDecoder",
    "GpsDeviceDecoder",
    "GpsMessage",
    "LogCommand",
    "LogHeader",
    "OtherCommand",
    "PositionType",
    "Prompt",
    "Rmc",
    "SolutionStatus",
    "TimeStatus",
    "UnknownLog",
    "UnlogAllCommand",
    "UnlogCommand",
    "UtmCoordinate",
    "Vtg",
    "crc32_novatel",
    "crc32_novatel_reference",
    "encode_ascii_log",
    "encode_bestpos_ascii",
    "encode_bestpos_binary",
    "encode_bestutm_ascii",
    "encode_bestutm_binary",
    "encode_bestvel_ascii",
    "encode_bestvel_binary",
    "encode_binary_log",
    "encode_com_command",
    "encode_gga",
    "encode_log_command",
    "encode_nmea",
    "encode_prompt",
    "encode_response",
    "encode_rmc",
    "encode_unlog_command",
    "encode_unlogall_command",
    "encode_vtg",
    "latlon_to_utm",
    "nmea_checksum",
]

# --------------------------------------------------------------------------- constants

BINARY_SYNC: Final = b"\xaa\x44\x12"
BINARY_HEADER_LENGTH: Final = 28
BESTPOS_ID: Final = 42
BESTVEL_ID: Final = 99
BESTUTM_ID: Final = 726
MESSAGE_IDS: Final[dict[str, int]] = {"BESTPOS": BESTPOS_ID, "BESTVEL": BESTVEL_ID,
                                      "BESTUTM": BESTUTM_ID}
_NAMES_BY_ID: Final = {v: k for k, v in MESSAGE_IDS.items()}

KNOTS_TO_MPS: Final = 1852.0 / 3600.0  # 1 international knot = 1852 m per hour
_KMH_TO_MPS: Final = 1.0 / 3.6

_BESTPOS_PAYLOAD = struct.Struct("<IIdddfIfff4sffBBBB4B")  # 72 bytes
_BESTVEL_PAYLOAD = struct.Struct("<IIffdddf")  # 44 bytes
_BESTUTM_PAYLOAD = struct.Struct("<IIIIdddfIfff4sffBBBB4B")  # 80 bytes
# sync, header length, message id, message type, port, message length, sequence,
# idle time, time status, week, milliseconds, receiver status, reserved, sw version
_HEADER = struct.Struct("<3sBHBBHHBBHIIHH")
_PAYLOAD_LENGTHS: Final = {BESTPOS_ID: _BESTPOS_PAYLOAD.size, BESTVEL_ID: _BESTVEL_PAYLOAD.size,
                           BESTUTM_ID: _BESTUTM_PAYLOAD.size}
_CRC = struct.Struct("<I")

_MAX_BINARY_FRAME: Final = 16384  # bigger than any OEM4 log we expect; larger = corrupt
_MAX_ASCII_LOG: Final = 8192
_MAX_NMEA: Final = 128  # NMEA says 82 characters; leave room for proprietary sentences
_MAX_RESPONSE: Final = 256
_MAX_PROMPT: Final = 16
_MAX_COMMAND_LINE: Final = 512
_MAX_LEADING_BLANKS: Final = 64

_CR, _LF = 0x0D, 0x0A
_HOST_SYNC_BYTES: Final = frozenset(b"\xaa#$<[")

_WGS84_DATUM_ID: Final = 61  # OEM4 datum table: 61 = WGS84
_PORTS: Final[dict[str, int]] = {"COM1": 0x20, "COM2": 0x40, "COM3": 0x60}
_PORT_NAMES: Final = {v: k for k, v in _PORTS.items()}

# ----------------------------------------------------------------------------- checks


def _make_crc_table() -> tuple[int, ...]:
    table = []
    for n in range(256):
        c = n
        for _ in range(8):
            c = (c >> 1) ^ 0xEDB88320 if c & 1 else c >> 1
        table.append(c)
    return tuple(table)


_CRC_TABLE: Final = _make_crc_table()


def crc32_novatel(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """NovAtel's CRC-32: reflected polynomial 0xEDB88320, initial value 0, no final XOR.

    ``crc`` (a 32-bit value) continues a previous computation. Never raises for
    bytes-like input. It is the standard CRC-32's register without its inversions, so
    the C implementation in ``binascii`` computes it: inverting the register going in
    and the result coming out cancels them (every GPS log is checked twice in
    simulation, by the emulator and the driver; :func:`crc32_novatel_reference` is the
    table loop of the manual, which the tests compare with this).
    """
    return binascii.crc32(data, crc ^ 0xFFFFFFFF) ^ 0xFFFFFFFF


def crc32_novatel_reference(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """:func:`crc32_novatel` as the manual's byte-at-a-time table loop."""
    table = _CRC_TABLE
    for byte in bytes(data):
        crc = table[(crc ^ byte) & 0xFF] ^ (crc >> 8)
    return crc


def nmea_checksum(body: bytes | bytearray | memoryview) -> int:
    """NMEA 0183 checksum: XOR of every byte between ``$`` and ``*`` (pass just those)."""
    value = 0
    for byte in bytes(body):
        value ^= byte
    return value


# ------------------------------------------------------------------------------ enums


class SolutionStatus(IntEnum):
    """Solution status as the OEM4 manual names it (binary value = enum value)."""

    SOL_COMPUTED = 0
    INSUFFICIENT_OBS = 1
    NO_CONVERGENCE = 2
    SINGULARITY = 3
    COV_TRACE = 4
    TEST_DIST = 5
    COLD_START = 6
    V_H_LIMIT = 7
    VARIANCE = 8
    RESIDUALS = 9
    DELTA_POS = 10
    NEGATIVE_VAR = 11
    INTEGRITY_WARNING = 13
    INS_INACTIVE = 14
    INS_ALIGNING = 15
    INS_BAD = 16
    IMU_UNPLUGGED = 17
    PENDING = 18
    INVALID_FIX = 19
    UNAUTHORIZED = 20


class PositionType(IntEnum):
    """Position or velocity type as the OEM4 manual names it (later firmware adds more)."""

    NONE = 0
    FIXEDPOS = 1
    FIXEDHEIGHT = 2
    FLOATCONV = 4
    WIDELANE = 5
    NARROWLANE = 6
    DOPPLER_VELOCITY = 8
    SINGLE = 16
    PSRDIFF = 17
    WAAS = 18
    PROPAGATED = 19
    OMNISTAR = 20
    L1_FLOAT = 32
    IONOFREE_FLOAT = 33
    NARROW_FLOAT = 34
    L1_INT = 48
    WIDE_INT = 49
    NARROW_INT = 50
    RTK_DIRECT_INS = 51
    INS = 52
    INS_PSRSP = 53
    INS_PSRDIFF = 54
    INS_RTKFLOAT = 55
    INS_RTKFIXED = 56
    OMNISTAR_HP = 64
    OMNISTAR_XP = 65
    CDGPS = 66
    PPP_CONVERGING = 68
    PPP = 69


class TimeStatus(IntEnum):
    """GPS reference time status of a log header (how well the receiver knows GPS time)."""

    UNKNOWN = 20
    APPROXIMATE = 60
    COARSEADJUSTING = 80
    COARSE = 100
    COARSESTEERING = 120
    FREEWHEELING = 130
    FINEADJUSTING = 140
    FINE = 160
    FINEBACKUPSTEERING = 170
    FINESTEERING = 180
    SATTIME = 200


# ---------------------------------------------------------------------------- messages


@dataclass(frozen=True, slots=True)
class LogHeader:
    """The header common to NovAtel ASCII and binary logs.

    ``name`` is the log name without its format suffix (``BESTPOS``, not ``BESTPOSA``).
    ``idle_time_percent`` is the receiver's idle CPU (binary: half-percent units).
    ``gps_seconds`` is the GPS time of week (binary: milliseconds).
    """

    name: str
    port: str = "COM1"
    sequence: int = 0
    idle_time_percent: float = 0.0
    time_status: TimeStatus = TimeStatus.FINESTEERING
    gps_week: int = 0
    gps_seconds: float = 0.0
    receiver_status: int = 0
    reserved: int = 0
    receiver_sw_version: int = 0


class _HeaderTime:
    """GPS week and seconds of week of a NovAtel log, from its header."""

    __slots__ = ()
    header: LogHeader

    @property
    def gps_week(self) -> int:
        return self.header.gps_week

    @property
    def gps_seconds(self) -> float:
        return self.header.gps_seconds


@dataclass(frozen=True, slots=True)
class BestPos(_HeaderTime):
    """BESTPOS (id 42): the receiver's best position.

    Heights are above mean sea level; ``undulation_m`` is geoid minus ellipsoid, so the
    ellipsoidal height is ``height_msl_m + undulation_m``. Standard deviations are 1-sigma
    metres. ``satellites_tracked``/``satellites_in_solution`` are the manual's #obs and
    #GPSL1; the two ``*_above_mask`` counts are its #L1 and #L2 (ranges above the RTK mask
    angle). ``extended`` keeps the four trailing bytes (reserved on OEM4; extended
    solution status and signal masks on later firmware).
    """

    header: LogHeader
    solution_status: SolutionStatus
    position_type: PositionType
    latitude_deg: float
    longitude_deg: float
    height_msl_m: float
    undulation_m: float
    datum: str
    latitude_std_m: float
    longitude_std_m: float
    height_std_m: float
    base_station_id: str
    differential_age_s: float
    solution_age_s: float
    satellites_tracked: int
    satellites_in_solution: int
    satellites_l1_above_mask: int = 0
    satellites_l2_above_mask: int = 0
    extended: tuple[int, int, int, int] = (0, 0, 0, 0)


@dataclass(frozen=True, slots=True)
class BestVel(_HeaderTime):
    """BESTVEL (id 99): the receiver's best velocity.

    The velocity is valid at the header time minus ``latency_s``. ``track_over_ground_deg``
    is measured clockwise from true north; ``vertical_speed_m_s`` is positive up.
    """

    header: LogHeader
    solution_status: SolutionStatus
    velocity_type: PositionType
    latency_s: float
    age_s: float
    horizontal_speed_m_s: float
    track_over_ground_deg: float
    vertical_speed_m_s: float


@dataclass(frozen=True, slots=True)
class BestUtm(_HeaderTime):
    """BESTUTM (id 726): the best position in UTM coordinates.

    ``zone_letter`` is the latitude band; northings in the southern hemisphere carry the
    10 000 000 m false northing, eastings the 500 000 m false easting.
    """

    header: LogHeader
    solution_status: SolutionStatus
    position_type: PositionType
    zone_number: int
    zone_letter: str
    northing_m: float
    easting_m: float
    height_msl_m: float
    undulation_m: float
    datum: str
    northing_std_m: float
    easting_std_m: float
    height_std_m: float
    base_station_id: str
    differential_age_s: float
    solution_age_s: float
    satellites_tracked: int
    satellites_in_solution: int
    satellites_l1_above_mask: int = 0
    satellites_l2_above_mask: int = 0
    extended: tuple[int, int, int, int] = (0, 0, 0, 0)


@dataclass(frozen=True, slots=True)
class Gga:
    """NMEA GGA: fix data. ``None`` marks an empty field.

    ``utc_seconds`` is seconds since UTC midnight; latitude/longitude are signed degrees
    (south/west negative); ``quality`` is the NMEA fix quality (0 invalid, 1 GPS,
    2 DGPS, 4 RTK fixed, 5 RTK float, ...).
    """

    talker: str
    utc_seconds: float | None
    latitude_deg: float | None
    longitude_deg: float | None
    quality: int
    satellites: int | None
    hdop: float | None
    altitude_msl_m: float | None
    geoid_separation_m: float | None
    dgps_age_s: float | None = None
    dgps_station: str = ""


@dataclass(frozen=True, slots=True)
class Rmc:
    """NMEA RMC: recommended minimum data. ``valid`` is the A/V status flag.

    ``magnetic_variation_deg`` is signed, east positive. ``mode`` is the NMEA 2.3 mode
    indicator (A autonomous, D differential, N not valid, ...), empty if absent.
    """

    talker: str
    utc_seconds: float | None
    valid: bool
    latitude_deg: float | None
    longitude_deg: float | None
    speed_knots: float | None
    course_deg: float | None
    date: date | None
    magnetic_variation_deg: float | None = None
    mode: str = ""

    @property
    def speed_m_s(self) -> float | None:
        return None if self.speed_knots is None else self.speed_knots * KNOTS_TO_MPS


@dataclass(frozen=True, slots=True)
class Vtg:
    """NMEA VTG: course and speed over ground."""

    talker: str
    course_true_deg: float | None
    course_magnetic_deg: float | None
    speed_knots: float | None
    speed_kmh: float | None
    mode: str = ""

    @property
    def speed_m_s(self) -> float | None:
        if self.speed_kmh is not None:
            return self.speed_kmh * _KMH_TO_MPS
        return None if self.speed_knots is None else self.speed_knots * KNOTS_TO_MPS


@dataclass(frozen=True, slots=True)
class UnknownLog:
    """A well-formed frame with a valid checksum that this codec does not decode.

    ``kind`` is ``"ascii"``, ``"binary"`` or ``"nmea"``; ``name`` the log name (without
    format suffix), NMEA address (``GPGSV``) or ``ID<n>`` for an unnamed binary id.
    """

    kind: str
    name: str
    message_id: int | None = None


@dataclass(frozen=True, slots=True)
class CommandResponse:
    """An abbreviated-ASCII command response: ``<OK`` or ``<ERROR:reason``."""

    ok: bool
    text: str


@dataclass(frozen=True, slots=True)
class Prompt:
    """The port prompt the receiver prints after a response, e.g. ``[COM1]``."""

    port: str


GpsMessage: TypeAlias = (BestPos | BestVel | BestUtm | Gga | Rmc | Vtg | UnknownLog
                         | CommandResponse | Prompt)


@dataclass(frozen=True, slots=True)
class LogCommand:
    """``LOG [port] message [trigger [period [offset [hold]]]]``."""

    port: str | None
    message: str
    trigger: str = "ONNEW"
    period_s: float = 0.0
    offset_s: float = 0.0
    hold: bool = False


@dataclass(frozen=True, slots=True)
class UnlogCommand:
    """``UNLOG [port] message``."""

    port: str | None
    message: str


@dataclass(frozen=True, slots=True)
class UnlogAllCommand:
    """``UNLOGALL [port]``."""

    port: str | None


@dataclass(frozen=True, slots=True)
class OtherCommand:
    """Any other command line, split into an upper-case verb and its arguments.

    ``valid`` is False when the verb is known (LOG, UNLOG, UNLOGALL) but its arguments do
    not parse; the fake receiver answers those with ``<ERROR``.
    """

    verb: str
    args: tuple[str, ...]
    valid: bool = True


GpsCommand: TypeAlias = LogCommand | UnlogCommand | UnlogAllCommand | OtherCommand


# ---------------------------------------------------------------- field conversions


class _Malformed(ValueError):
    """Internal: a frame whose checksum is fine but whose fields do not decode."""


def _port_name(value: int) -> str:
    return _PORT_NAMES.get(value, f"PORT_{value}")


def _port_value(name: str) -> int:
    name = name.upper()
    if name in _PORTS:
        return _PORTS[name]
    if name.startswith("PORT_") and name[5:].isdigit() and int(name[5:]) < 256:
        return int(name[5:])
    raise ValueError(f"port {name!r} has no OEM4 binary port address (use COM1..COM3)")


def _datum_name(value: int) -> str:
    return "WGS84" if value == _WGS84_DATUM_ID else f"DATUM_{value}"


def _datum_value(name: str) -> int:
    if name.upper() == "WGS84":
        return _WGS84_DATUM_ID
    if name.upper().startswith("DATUM_") and name[6:].isdigit():
        return int(name[6:])
    raise ValueError(f"datum {name!r} has no binary id here (only WGS84 or DATUM_<n>)")


_E = TypeVar("_E", bound=IntEnum)


def _enum_by_value(enum: type[_E], value: int) -> _E:
    try:
        return enum(value)
    except ValueError:
        raise _Malformed(f"{enum.__name__} value {value} is not known") from None


def _enum_by_name(enum: type[_E], name: str) -> _E:
    try:
        return enum[name]
    except KeyError:
        raise _Malformed(f"{enum.__name__} {name!r} is not known") from None


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _Malformed(f"non-finite number {text!r}")
    return value


def _station_from_bytes(raw: bytes) -> str:
    return raw.split(b"\x00", 1)[0].decode("ascii", "replace")


def _station_to_bytes(station: str) -> bytes:
    raw = station.encode("ascii")
    if len(raw) > 4:
        raise ValueError(f"base station id {station!r} is longer than 4 characters")
    return raw.ljust(4, b"\x00")


def _unquote(text: str) -> str:
    if len(text) >= 2 and text[0] == '"' and text[-1] == '"':
        return text[1:-1]
    raise _Malformed(f"expected a quoted string, got {text!r}")


def _split_fields(text: str) -> list[str]:
    """Split on commas outside double quotes (station ids are quoted)."""
    fields: list[str] = []
    current: list[str] = []
    quoted = False
    for ch in text:
        if ch == '"':
            quoted = not quoted
            current.append(ch)
        elif ch == "," and not quoted:
            fields.append("".join(current))
            current = []
        else:
            current.append(ch)
    fields.append("".join(current))
    return fields


# ---------------------------------------------------------------- NovAtel binary logs


def _decode_binary_header(frame: bytes | bytearray) -> tuple[int, int, LogHeader]:
    (_, _, message_id, message_type, port, _, sequence, idle, time_status, week, ms,
     rx_status, reserved, sw_version) = _HEADER.unpack_from(frame, 0)
    name = _NAMES_BY_ID.get(message_id, f"ID{message_id}")
    header = LogHeader(
        name=name, port=_port_name(port), sequence=sequence, idle_time_percent=idle / 2.0,
        time_status=_enum_by_value(TimeStatus, time_status),
        gps_week=week, gps_seconds=ms / 1000.0, receiver_status=rx_status,
        reserved=reserved, receiver_sw_version=sw_version)
    return message_id, message_type, header


def _decode_binary_payload(message_id: int, header: LogHeader,
                           payload: bytes | bytearray) -> GpsMessage:
    if message_id == BESTPOS_ID:
        if len(payload) < _BESTPOS_PAYLOAD.size:
            raise _Malformed("BESTPOS payload too short")
        (sol, pos, lat, lon, hgt, und, datum, lat_sd, lon_sd, hgt_sd, stn, diff_age,
         sol_age, n_obs, n_sol, n_l1, n_l2, *ext) = _BESTPOS_PAYLOAD.unpack_from(payload)
        return BestPos(header, _enum_by_value(SolutionStatus, sol),
                       _enum_by_value(PositionType, pos),
                       lat, lon, hgt, und, _datum_name(datum), lat_sd, lon_sd, hgt_sd,
                       _station_from_bytes(stn), diff_age, sol_age, n_obs, n_sol, n_l1,
                       n_l2, tuple(ext))
    if message_id == BESTVEL_ID:
        if len(payload) < _BESTVEL_PAYLOAD.size:
            raise _Malformed("BESTVEL payload too short")
        sol, vel, latency, age, speed, track, vert, _ = _BESTVEL_PAYLOAD.unpack_from(payload)
        return BestVel(header, _enum_by_value(SolutionStatus, sol),
                       _enum_by_value(PositionType, vel),
                       latency, age, speed, track, vert)
    if message_id == BESTUTM_ID:
        if len(payload) < _BESTUTM_PAYLOAD.size:
            raise _Malformed("BESTUTM payload too short")
        (sol, pos, zone, letter, north, east, hgt, und, datum, n_sd, e_sd, h_sd, stn,
         diff_age, sol_age, n_obs, n_sol, n_l1, n_l2, *ext) = \
            _BESTUTM_PAYLOAD.unpack_from(payload)
        if not 0 < letter < 128:
            raise _Malformed(f"zone letter code {letter} is not ASCII")
        return BestUtm(header, _enum_by_value(SolutionStatus, sol),
                       _enum_by_value(PositionType, pos),
                       zone, chr(letter), north, east, hgt, und, _datum_name(datum), n_sd,
                       e_sd, h_sd, _station_from_bytes(stn), diff_age, sol_age, n_obs,
                       n_sol, n_l1, n_l2, tuple(ext))
    return UnknownLog("binary", header.name, message_id)


def encode_binary_log(message_id: int, header: LogHeader, payload: bytes) -> bytes:
    """Frame ``payload`` as a NovAtel binary log: sync, 28-byte header, payload, CRC-32.

    Raises ValueError if a header field does not fit its binary slot.
    """
    if len(payload) > 0xFFFF:
        raise ValueError("payload longer than 65535 bytes")
    idle = round(header.idle_time_percent * 2)
    ms = round(header.gps_seconds * 1000)
    if not 0 <= idle <= 255 or not 0 <= ms <= 0xFFFFFFFF or not 0 <= header.gps_week <= 0xFFFF:
        raise ValueError("idle time, week or seconds out of range")
    body = _HEADER.pack(BINARY_SYNC, BINARY_HEADER_LENGTH, message_id, 0,
                        _port_value(header.port), len(payload), header.sequence, idle,
                        int(header.time_status), header.gps_week, ms,
                        header.receiver_status, header.reserved,
                        header.receiver_sw_version) + payload
    return body + _CRC.pack(crc32_novatel(body))


def encode_bestpos_binary(msg: BestPos) -> bytes:
    """BESTPOSB: the binary BESTPOS log. Raises ValueError/struct.error on bad fields."""
    payload = _BESTPOS_PAYLOAD.pack(
        int(msg.solution_status), int(msg.position_type), msg.latitude_deg,
        msg.longitude_deg, msg.height_msl_m, msg.undulation_m, _datum_value(msg.datum),
        msg.latitude_std_m, msg.longitude_std_m, msg.height_std_m,
        _station_to_bytes(msg.base_station_id), msg.differential_age_s,
        msg.solution_age_s, msg.satellites_tracked, msg.satellites_in_solution,
        msg.satellites_l1_above_mask, msg.satellites_l2_above_mask, *msg.extended)
    return encode_binary_log(BESTPOS_ID, msg.header, payload)


def encode_bestvel_binary(msg: BestVel) -> bytes:
    """BESTVELB: the binary BESTVEL log. Raises ValueError/struct.error on bad fields."""
    payload = _BESTVEL_PAYLOAD.pack(
        int(msg.solution_status), int(msg.velocity_type), msg.latency_s, msg.age_s,
        msg.horizontal_speed_m_s, msg.track_over_ground_deg, msg.vertical_speed_m_s, 0.0)
    return encode_binary_log(BESTVEL_ID, msg.header, payload)


def encode_bestutm_binary(msg: BestUtm) -> bytes:
    """BESTUTMB: the binary BESTUTM log. Raises ValueError/struct.error on bad fields."""
    if len(msg.zone_letter) != 1:
        raise ValueError(f"zone letter {msg.zone_letter!r} must be one character")
    payload = _BESTUTM_PAYLOAD.pack(
        int(msg.solution_status), int(msg.position_type), msg.zone_number,
        ord(msg.zone_letter), msg.northing_m, msg.easting_m, msg.height_msl_m,
        msg.undulation_m, _datum_value(msg.datum), msg.northing_std_m, msg.easting_std_m,
        msg.height_std_m, _station_to_bytes(msg.base_station_id), msg.differential_age_s,
        msg.solution_age_s, msg.satellites_tracked, msg.satellites_in_solution,
        msg.satellites_l1_above_mask, msg.satellites_l2_above_mask, *msg.extended)
    return encode_binary_log(BESTUTM_ID, msg.header, payload)


# ----------------------------------------------------------------- NovAtel ASCII logs


def _decode_ascii_header(fields: list[str]) -> LogHeader:
    if len(fields) != 10:
        raise _Malformed(f"ASCII header has {len(fields)} fields, expected 10")
    name = fields[0]
    if name.endswith("A"):
        name = name[:-1]
    return LogHeader(
        name=name, port=fields[1], sequence=int(fields[2]),
        idle_time_percent=_finite(fields[3]),
        time_status=_enum_by_name(TimeStatus, fields[4]),
        gps_week=int(fields[5]), gps_seconds=_finite(fields[6]),
        receiver_status=int(fields[7], 16), reserved=int(fields[8], 16),
        receiver_sw_version=int(fields[9]))


def _decode_counts(fields: list[str]) -> tuple[int, int, int, int, tuple[int, int, int, int]]:
    counts = [int(f) for f in fields[:4]]
    # The four trailing fields are hexadecimal on every firmware that fills them
    # (extended solution status, signal masks); OEM4 prints reserved zeros.
    tail = [int(f, 16) for f in fields[4:8]]
    tail += [0] * (4 - len(tail))
    if any(not 0 <= v <= 255 for v in counts + tail):
        raise _Malformed("satellite count or status byte out of range")
    return counts[0], counts[1], counts[2], counts[3], (tail[0], tail[1], tail[2], tail[3])


def _decode_ascii_log(text: str) -> GpsMessage:
    head, sep, data = text.partition(";")
    if not sep:
        raise _Malformed("ASCII log without ';'")
    header = _decode_ascii_header(head.split(","))
    if header.name not in MESSAGE_IDS:
        return UnknownLog("ascii", header.name, None)
    f = _split_fields(data)
    if header.name == "BESTPOS":
        if len(f) < 17:
            raise _Malformed(f"BESTPOSA has {len(f)} fields, expected at least 17")
        n_obs, n_sol, n_l1, n_l2, ext = _decode_counts(f[13:21])
        return BestPos(header, _enum_by_name(SolutionStatus, f[0]),
                       _enum_by_name(PositionType, f[1]),
                       _finite(f[2]), _finite(f[3]), _finite(f[4]), _finite(f[5]), f[6],
                       _finite(f[7]), _finite(f[8]), _finite(f[9]), _unquote(f[10]),
                       _finite(f[11]), _finite(f[12]), n_obs, n_sol, n_l1, n_l2, ext)
    if header.name == "BESTVEL":
        if len(f) < 8:
            raise _Malformed(f"BESTVELA has {len(f)} fields, expected 8")
        return BestVel(header, _enum_by_name(SolutionStatus, f[0]),
                       _enum_by_name(PositionType, f[1]),
                       _finite(f[2]), _finite(f[3]), _finite(f[4]), _finite(f[5]),
                       _finite(f[6]))
    # BESTUTM
    if len(f) < 19:
        raise _Malformed(f"BESTUTMA has {len(f)} fields, expected at least 19")
    if len(f[3]) != 1:
        raise _Malformed(f"zone letter {f[3]!r}")
    n_obs, n_sol, n_l1, n_l2, ext = _decode_counts(f[15:23])
    return BestUtm(header, _enum_by_name(SolutionStatus, f[0]),
                   _enum_by_name(PositionType, f[1]),
                   int(f[2]), f[3], _finite(f[4]), _finite(f[5]), _finite(f[6]),
                   _finite(f[7]), f[8], _finite(f[9]), _finite(f[10]), _finite(f[11]),
                   _unquote(f[12]), _finite(f[13]), _finite(f[14]), n_obs, n_sol, n_l1,
                   n_l2, ext)


def encode_ascii_log(header: LogHeader, data_fields: list[str]) -> bytes:
    """Frame an ASCII log: ``#<NAME>A,<header>;<fields>*<crc>`` CR LF.

    Raises ValueError if the result would not be ASCII.
    """
    head = ",".join([
        header.name + "A", header.port, str(header.sequence),
        f"{header.idle_time_percent:.1f}", header.time_status.name, str(header.gps_week),
        f"{header.gps_seconds:.3f}", f"{header.receiver_status:08x}",
        f"{header.reserved:04x}", str(header.receiver_sw_version)])
    body = (head + ";" + ",".join(data_fields)).encode("ascii")
    return b"#" + body + b"*" + f"{crc32_novatel(body):08x}".encode("ascii") + b"\r\n"


def _count_fields(msg: BestPos | BestUtm) -> list[str]:
    return [str(msg.satellites_tracked), str(msg.satellites_in_solution),
            str(msg.satellites_l1_above_mask), str(msg.satellites_l2_above_mask)] + \
           [f"{v:02x}" for v in msg.extended]


def encode_bestpos_ascii(msg: BestPos) -> bytes:
    """BESTPOSA, formatted as the receiver prints it (11 decimals of a degree)."""
    return encode_ascii_log(msg.header, [
        msg.solution_status.name, msg.position_type.name, f"{msg.latitude_deg:.11f}",
        f"{msg.longitude_deg:.11f}", f"{msg.height_msl_m:.4f}", f"{msg.undulation_m:.4f}",
        msg.datum, f"{msg.latitude_std_m:.4f}", f"{msg.longitude_std_m:.4f}",
        f"{msg.height_std_m:.4f}", f'"{msg.base_station_id}"',
        f"{msg.differential_age_s:.3f}", f"{msg.solution_age_s:.3f}",
    ] + _count_fields(msg))


def encode_bestvel_ascii(msg: BestVel) -> bytes:
    """BESTVELA, formatted as the receiver prints it."""
    return encode_ascii_log(msg.header, [
        msg.solution_status.name, msg.velocity_type.name, f"{msg.latency_s:.3f}",
        f"{msg.age_s:.3f}", f"{msg.horizontal_speed_m_s:.4f}",
        f"{msg.track_over_ground_deg:.6f}", f"{msg.vertical_speed_m_s:.4f}", "0.0"])


def encode_bestutm_ascii(msg: BestUtm) -> bytes:
    """BESTUTMA, formatted as the receiver prints it."""
    return encode_ascii_log(msg.header, [
        msg.solution_status.name, msg.position_type.name, str(msg.zone_number),
        msg.zone_letter, f"{msg.northing_m:.4f}", f"{msg.easting_m:.4f}",
        f"{msg.height_msl_m:.4f}", f"{msg.undulation_m:.4f}", msg.datum,
        f"{msg.northing_std_m:.4f}", f"{msg.easting_std_m:.4f}",
        f"{msg.height_std_m:.4f}", f'"{msg.base_station_id}"',
        f"{msg.differential_age_s:.3f}", f"{msg.solution_age_s:.3f}",
    ] + _count_fields(msg))


# ------------------------------------------------------------------------------- NMEA


def _opt_float(text: str) -> float | None:
    return None if text == "" else _finite(text)


def _opt_int(text: str) -> int | None:
    return None if text == "" else int(text)


def _utc_seconds(text: str) -> float | None:
    if text == "":
        return None
    if len(text) < 6 or not text[:6].isdigit():
        raise _Malformed(f"time {text!r}")
    hh, mm = int(text[0:2]), int(text[2:4])
    ss = _finite(text[4:])
    if hh > 23 or mm > 59 or not 0 <= ss < 61:
        raise _Malformed(f"time {text!r}")
    return hh * 3600 + mm * 60 + ss


def _angle(text: str, hemisphere: str, max_degrees: int, negative: str,
           positive: str) -> float | None:
    if text == "":
        return None
    dot = text.find(".")
    if dot < 0:
        dot = len(text)
    if dot < 3 or not text[:dot - 2].isdigit():
        raise _Malformed(f"angle {text!r}")
    degrees = int(text[:dot - 2])
    minutes = _finite(text[dot - 2:])
    if not 0 <= minutes < 60 or degrees + minutes / 60 > max_degrees:
        raise _Malformed(f"angle {text!r}")
    value = degrees + minutes / 60.0
    if hemisphere == negative:
        return -value
    if hemisphere == positive:
        return value
    raise _Malformed(f"hemisphere {hemisphere!r}")


def _nmea_date(text: str) -> date | None:
    if text == "":
        return None
    if len(text) != 6 or not text.isdigit():
        raise _Malformed(f"date {text!r}")
    yy = int(text[4:6])
    try:
        return date(2000 + yy if yy < 80 else 1900 + yy, int(text[2:4]), int(text[0:2]))
    except ValueError:
        raise _Malformed(f"date {text!r}") from None


def _pad(fields: list[str], n: int, minimum: int, name: str) -> list[str]:
    if len(fields) < minimum:
        raise _Malformed(f"{name} has {len(fields)} fields, expected at least {minimum}")
    return fields + [""] * (n - len(fields))


def _decode_nmea(text: str) -> GpsMessage:
    fields = text.split(",")
    address = fields[0]
    kind = address[2:] if len(address) == 5 else ""
    talker = address[:2]
    if kind == "GGA":
        f = _pad(fields, 15, 10, "GGA")
        return Gga(talker, _utc_seconds(f[1]), _angle(f[2], f[3], 90, "S", "N"),
                   _angle(f[4], f[5], 180, "W", "E"), int(f[6]) if f[6] else 0,
                   _opt_int(f[7]), _opt_float(f[8]), _opt_float(f[9]), _opt_float(f[11]),
                   _opt_float(f[13]), f[14])
    if kind == "RMC":
        f = _pad(fields, 13, 10, "RMC")
        if f[2] not in ("A", "V"):
            raise _Malformed(f"RMC status {f[2]!r}")
        variation = _opt_float(f[10])
        if variation is not None and f[11] == "W":
            variation = -variation
        return Rmc(talker, _utc_seconds(f[1]), f[2] == "A",
                   _angle(f[3], f[4], 90, "S", "N"), _angle(f[5], f[6], 180, "W", "E"),
                   _opt_float(f[7]), _opt_float(f[8]), _nmea_date(f[9]), variation, f[12])
    if kind == "VTG":
        f = _pad(fields, 10, 9, "VTG")
        return Vtg(talker, _opt_float(f[1]), _opt_float(f[3]), _opt_float(f[5]),
                   _opt_float(f[7]), f[9])
    return UnknownLog("nmea", address, None)


def encode_nmea(body: str) -> bytes:
    """Frame an NMEA sentence body (without ``$`` and ``*``): ``$body*hh`` CR LF.

    Raises ValueError if ``body`` is not ASCII.
    """
    raw = body.encode("ascii")
    return b"$" + raw + f"*{nmea_checksum(raw):02X}".encode("ascii") + b"\r\n"


def _fmt_time(seconds: float | None) -> str:
    if seconds is None:
        return ""
    cs = round(seconds * 100)
    hh, rest = divmod(cs, 360000)
    mm, rest = divmod(rest, 6000)
    return f"{hh % 24:02d}{mm:02d}{rest // 100:02d}.{rest % 100:02d}"


def _fmt_angle(value: float | None, degree_digits: int, positive: str, negative: str,
               decimals: int) -> tuple[str, str]:
    if value is None:
        return "", ""
    scale = 10 ** decimals
    total = round(abs(value) * 60 * scale)  # minutes in units of 10^-decimals
    degrees, minutes = divmod(total, 60 * scale)
    whole, frac = divmod(minutes, scale)
    text = f"{degrees:0{degree_digits}d}{whole:02d}" + (f".{frac:0{decimals}d}" if decimals else "")
    return text, negative if value < 0 else positive


def _fmt_opt(value: float | int | None, spec: str) -> str:
    return "" if value is None else format(value, spec)


def encode_gga(msg: Gga, minute_decimals: int = 7) -> bytes:
    """GGA sentence from ``msg`` (``minute_decimals`` digits of arc-minutes), laid out
    as NovAtel prints it: heights to the centimetre, differential age in whole seconds.
    """
    lat, ns = _fmt_angle(msg.latitude_deg, 2, "N", "S", minute_decimals)
    lon, ew = _fmt_angle(msg.longitude_deg, 3, "E", "W", minute_decimals)
    return encode_nmea(",".join([
        f"{msg.talker}GGA", _fmt_time(msg.utc_seconds), lat, ns, lon, ew, str(msg.quality),
        _fmt_opt(msg.satellites, "02d"), _fmt_opt(msg.hdop, ".1f"),
        _fmt_opt(msg.altitude_msl_m, ".2f"), "M", _fmt_opt(msg.geoid_separation_m, ".2f"),
        "M", "" if msg.dgps_age_s is None else f"{round(msg.dgps_age_s):02d}",
        msg.dgps_station]))


def encode_rmc(msg: Rmc, minute_decimals: int = 7) -> bytes:
    """RMC sentence from ``msg``."""
    lat, ns = _fmt_angle(msg.latitude_deg, 2, "N", "S", minute_decimals)
    lon, ew = _fmt_angle(msg.longitude_deg, 3, "E", "W", minute_decimals)
    day = "" if msg.date is None else msg.date.strftime("%d%m") + f"{msg.date.year % 100:02d}"
    var = msg.magnetic_variation_deg
    fields = [
        f"{msg.talker}RMC", _fmt_time(msg.utc_seconds), "A" if msg.valid else "V", lat, ns,
        lon, ew, _fmt_opt(msg.speed_knots, ".3f"), _fmt_opt(msg.course_deg, ".1f"), day,
        "" if var is None else f"{abs(var):.1f}", "" if var is None else ("W" if var < 0 else "E")]
    if msg.mode:
        fields.append(msg.mode)
    return encode_nmea(",".join(fields))


def encode_vtg(msg: Vtg) -> bytes:
    """VTG sentence from ``msg``."""
    fields = [f"{msg.talker}VTG", _fmt_opt(msg.course_true_deg, ".3f"), "T",
              _fmt_opt(msg.course_magnetic_deg, ".3f"), "M", _fmt_opt(msg.speed_knots, ".3f"),
              "N", _fmt_opt(msg.speed_kmh, ".3f"), "K"]
    if msg.mode:
        fields.append(msg.mode)
    return encode_nmea(",".join(fields))


def encode_response(ok: bool = True, text: str = "") -> bytes:
    """Abbreviated-ASCII response: ``<OK`` or ``<ERROR:text``, then CR LF."""
    line = "<OK" if ok else f"<ERROR:{text}"
    return line.encode("ascii") + b"\r\n"


def encode_prompt(port: str = "COM1") -> bytes:
    """The port prompt the receiver sends after a response: CR LF ``[COM1]``."""
    return b"\r\n[" + port.encode("ascii") + b"]"


# ------------------------------------------------------------------ host-side decoder

_NAME_FIRST = frozenset(b"ABCDEFGHIJKLMNOPQRSTUVWXYZ")
_NAME_CHARS = _NAME_FIRST | frozenset(b"0123456789_")
_MAX_ASCII_NAME: Final = 40  # '#', the log name and its ',' (longest OEM4 name: 20)
_NMEA_ADDRESS_CHARS = frozenset(b"ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789")
_HEX = frozenset(b"0123456789abcdefABCDEF")
#: Sync and header-length byte: where a binary log can start (the header length is fixed).
_BINARY_HEAD: Final = BINARY_SYNC + bytes([BINARY_HEADER_LENGTH])
#: Bytes that start a text frame. None occurs inside an NMEA sentence ('$' is reserved by
#: NMEA 0183) or a command response, so meeting one ends such a frame as damaged.
_TEXT_STARTS: Final = frozenset(b"#$<[")
#: A NovAtel ASCII log may carry quoted free text, so only '#' ends one as damaged (its
#: CRC-32 rejects any other frame it might run into).
_ASCII_LOG_STOPS: Final = frozenset(b"#")
#: Bytes fed to the lookahead decoder at a time (it stops at its first message).
_PROBE_PIECE: Final = 256


def _printable(byte: int) -> bool:
    return 0x20 <= byte <= 0x7E


class GpsDecoder(StreamDecoder[GpsMessage]):
    """Host side: decodes NovAtel ASCII and binary logs, NMEA, responses and prompts.

    Every frame with a valid checksum becomes a message: BESTPOS/BESTVEL/BESTUTM in either
    format, GGA/RMC/VTG from any talker, and :class:`UnknownLog` for any other well-formed
    log or sentence (counted as a frame, not a fault; the driver drops it). A frame with a
    valid checksum whose fields do not decode counts as malformed. Carriage returns and
    line feeds between frames are absorbed into the next frame.

    Resynchronisation: a bad frame is dropped only up to the next byte that could start
    a frame (``AA # $ < [``). A binary sync must carry the 28-byte header length, and
    BESTPOS/BESTVEL/BESTUTM their fixed payload lengths (72/44/80), to count as a frame
    start. A frame never contains the start of another frame where that can be told:

    - a binary log never contains ``AA 44 12 1C`` (another binary header; 2^-32 per byte
      of a real log), so a header whose claimed length reaches past the next header is
      dropped when that header arrives;
    - an NMEA sentence or a command response ends at ``# $ < [`` (none occurs inside
      one), so a sentence or ``<ERROR:...`` that lost its line end never absorbs the log
      behind it;
    - a NovAtel ASCII log ends at ``#`` (its CRC-32 rejects any other frame it runs into).

    A binary header that claims more bytes than have arrived is waited for unless the
    bytes after it already decode to a frame (``lookahead``: a second decoder reads them
    as they arrive; a false header in line noise then costs no latency). Decoding costs
    a bounded amount of work per byte, whatever the bytes (see :mod:`afa.codec`).
    ``feed`` never raises.
    """

    def __init__(self, *, max_buffer: int = 1 << 16, lookahead: bool = True) -> None:
        super().__init__(max_buffer=max_buffer)
        self._lookahead = lookahead
        # Resume state of the front frame, valid while self.searched > 0 (same front):
        self._blanks = 0  # CR/LF bytes before the frame
        self._ascii_body = -1  # index of an ASCII log's first body byte; -1: in the name
        # The lookahead decoder, reading what follows a pending binary frame:
        self._probe: GpsDecoder | None = None
        self._probe_at = -1  # stream offset of that frame
        self._probe_fed = 0  # stream offset of the next byte to give the probe
        self._probe_used = False

    def reset(self) -> None:
        super().reset()
        self._probe = None
        self._probe_at = -1

    def scan(self, buffer: bytearray) -> Scan[GpsMessage]:
        self._probe_used = False
        result = self._scan(buffer)
        if not self._probe_used:
            self._probe = None  # the frame it looked behind is gone
        return result

    def _scan(self, buffer: bytearray) -> Scan[GpsMessage]:
        n = len(buffer)
        start = self._blanks if self.searched else 0
        while start < n and buffer[start] in (_CR, _LF):
            start += 1
        self._blanks = start
        if start == n:
            if n <= _MAX_LEADING_BLANKS:
                return Scan.need_more(searched=n)
            return Scan.skip(n, Fault.GARBAGE)
        if buffer[start] not in _HOST_SYNC_BYTES:
            return Scan.skip(self._next_sync(buffer, start), Fault.GARBAGE)
        result = self._scan_at(buffer, start)
        if result.consumed == 0:
            return result
        if result.fault is None and result.message is not None:
            return Scan.frame(start + result.consumed, result.message)
        # A bad frame: drop it only up to the next byte that could start a frame.
        return Scan.skip(self._next_sync(buffer, start), result.fault or Fault.MALFORMED)

    def _scan_at(self, buffer: bytearray, start: int) -> Scan[GpsMessage]:
        first = buffer[start]
        if first == 0xAA:
            return self._scan_binary(buffer, start)
        if first == 0x23:  # '#'
            return self._scan_ascii(buffer, start)
        if first == 0x24:  # '$'
            return self._scan_nmea(buffer, start)
        if first == 0x3C:  # '<'
            return self._scan_response(buffer, start)
        return self._scan_prompt(buffer, start)

    def _resume(self, start: int) -> int:
        """Where the search of the frame at ``start`` goes on: after what earlier reads
        searched already."""
        return max(start + 1, self.searched)

    @staticmethod
    def _next_sync(buffer: bytearray, start: int) -> int:
        """Index of the next byte after ``start`` that could begin a frame, else len."""
        for i in range(start + 1, len(buffer)):
            if buffer[i] in _HOST_SYNC_BYTES:
                return i
        return len(buffer)

    # Each _scan_* looks at buffer[start:]; a frame's consumed count is relative to start.

    def _scan_binary(self, buffer: bytearray, start: int) -> Scan[GpsMessage]:
        n = len(buffer)
        avail = n - start
        head = bytes(buffer[start:start + 4])
        if head != _BINARY_HEAD[:len(head)]:
            return Scan.skip(1, Fault.GARBAGE)  # not a sync, or a header length not 28
        if avail < 10:
            return Scan.need_more()
        (message_id,) = struct.unpack_from("<H", buffer, start + 4)
        (message_length,) = struct.unpack_from("<H", buffer, start + 8)
        expected = _PAYLOAD_LENGTHS.get(message_id)
        if expected is not None and message_length != expected:
            return Scan.skip(1, Fault.GARBAGE)  # a known log always has its length
        total = BINARY_HEADER_LENGTH + message_length + 4
        if total > _MAX_BINARY_FRAME:
            return Scan.skip(1, Fault.OVERFLOW)
        end = start + total
        resume = self._resume(start)
        if buffer.find(_BINARY_HEAD, resume, min(n, end)) >= 0:
            return Scan.skip(1, Fault.GARBAGE)  # another header inside: this one is false
        if n < end:
            if self._lookahead and self._frames_follow(buffer, start):
                return Scan.skip(1, Fault.GARBAGE)
            return Scan.need_more(searched=max(resume, n - len(_BINARY_HEAD) + 1))
        frame = bytes(buffer[start:end])
        (crc,) = _CRC.unpack_from(frame, total - 4)
        if crc32_novatel(frame[:-4]) != crc:
            return Scan.skip(1, Fault.CHECKSUM)
        try:
            message_id, _, header = _decode_binary_header(frame)
            payload = frame[BINARY_HEADER_LENGTH:BINARY_HEADER_LENGTH + message_length]
            return Scan.frame(total, _decode_binary_payload(message_id, header, payload))
        except (_Malformed, ValueError, struct.error):
            return Scan.skip(1, Fault.MALFORMED)

    def _frames_follow(self, buffer: bytearray, start: int) -> bool:
        """Whether the bytes after the pending binary frame at ``start`` decode to a
        frame. A second decoder (without lookahead) reads them once, as they arrive, and
        stops at its first message."""
        self._probe_used = True
        base = self.front_position
        if self._probe is None or self._probe_at != base + start:
            self._probe = type(self)(max_buffer=self._max_buffer, lookahead=False)
            self._probe_at = base + start
            self._probe_fed = base + start + 1
        while self._probe_fed < base + len(buffer):
            offset = self._probe_fed - base
            piece = bytes(buffer[offset:offset + _PROBE_PIECE])
            self._probe_fed += len(piece)
            if self._probe.feed(piece):
                self._probe = None
                return True
        return False

    def _find_star(self, buffer: bytearray, start: int, limit: int, stops: frozenset[int],
                   resume: int) -> int | None | Fault:
        """Index of the ``*`` ending a text frame, searching on from ``resume``; None:
        need more; a Fault: not a frame (a byte in ``stops`` or not printable)."""
        end = min(len(buffer), start + limit)
        for i in range(resume, end):
            byte = buffer[i]
            if byte == 0x2A:  # '*'
                return i
            if byte in stops or not _printable(byte):
                return Fault.MALFORMED
        if len(buffer) - start >= limit:
            return Fault.OVERFLOW
        return None

    def _scan_ascii(self, buffer: bytearray, start: int) -> Scan[GpsMessage]:
        # '#' + upper-case log name + ',' or it is not a NovAtel log at all.
        body = self._ascii_body if self.searched > start else -1
        if body < 0:
            i = self._resume(start)
            end = min(len(buffer), start + _MAX_ASCII_NAME)
            while i < end:
                byte = buffer[i]
                if byte == 0x2C and i > start + 1:  # ','
                    body = i + 1
                    break
                if byte not in (_NAME_CHARS if i > start + 1 else _NAME_FIRST):
                    return Scan.skip(1, Fault.GARBAGE)
                i += 1
            else:
                if len(buffer) - start >= _MAX_ASCII_NAME:
                    return Scan.skip(1, Fault.GARBAGE)
                self._ascii_body = -1
                return Scan.need_more(searched=i)
            self._ascii_body = body
        return self._scan_starred(buffer, start, _MAX_ASCII_LOG, _ASCII_LOG_STOPS,
                                  max(body, self.searched), 8, crc32_novatel,
                                  _decode_ascii_log)

    def _scan_nmea(self, buffer: bytearray, start: int) -> Scan[GpsMessage]:
        # '$' + at least two address characters before anything else.
        for i in range(start + 1, min(len(buffer), start + 3)):
            if buffer[i] not in _NMEA_ADDRESS_CHARS:
                return Scan.skip(1, Fault.GARBAGE)
        return self._scan_starred(buffer, start, _MAX_NMEA, _TEXT_STARTS,
                                  self._resume(start), 2, nmea_checksum, _decode_nmea)

    def _scan_starred(self, buffer: bytearray, start: int, limit: int,
                      stops: frozenset[int], resume: int, n_digits: int,
                      checksum: Callable[[bytes], int],
                      decode: Callable[[str], GpsMessage]) -> Scan[GpsMessage]:
        """The common tail of NovAtel ASCII logs and NMEA sentences: the body up to
        ``*`` (searched from ``resume``), ``n_digits`` hex digits of ``checksum(body)``,
        then ``decode`` the body."""
        star = self._find_star(buffer, start, limit, stops, resume)
        if star is None:
            return Scan.need_more(searched=len(buffer))
        if isinstance(star, Fault):
            return Scan.skip(1, star)
        digits = bytes(buffer[star + 1:star + 1 + n_digits])
        if not all(b in _HEX for b in digits):
            return Scan.skip(1, Fault.MALFORMED)
        if len(digits) < n_digits:
            return Scan.need_more(searched=star)
        body = bytes(buffer[start + 1:star])
        if checksum(body) != int(digits, 16):
            return Scan.skip(1, Fault.CHECKSUM)
        try:
            return Scan.frame(star + 1 + n_digits - start, decode(body.decode("ascii")))
        except (_Malformed, ValueError, IndexError):
            return Scan.skip(1, Fault.MALFORMED)

    def _scan_response(self, buffer: bytearray, start: int) -> Scan[GpsMessage]:
        # '<OK' or '<ERROR:text', ended by CR or LF. A frame start inside means the
        # response lost its line end: it is dropped, and the frame behind it decodes.
        end = min(len(buffer), start + _MAX_RESPONSE)
        for i in range(self._resume(start), end):
            byte = buffer[i]
            if byte in (_CR, _LF):
                if byte == _CR and i + 1 >= len(buffer):
                    return Scan.need_more(searched=i)  # is an LF coming?
                text = bytes(buffer[start + 1:i]).decode("ascii")
                consumed = i + 1 - start
                if byte == _CR and buffer[i + 1] == _LF:
                    consumed += 1
                if text == "OK":
                    return Scan.frame(consumed, CommandResponse(True, "OK"))
                if text.startswith("ERROR:"):
                    return Scan.frame(consumed, CommandResponse(False, text[6:]))
                return Scan.skip(1, Fault.GARBAGE)
            if byte in _TEXT_STARTS or not _printable(byte):
                return Scan.skip(1, Fault.GARBAGE)
        if len(buffer) - start >= _MAX_RESPONSE:
            return Scan.skip(1, Fault.GARBAGE)
        return Scan.need_more(searched=end)

    @staticmethod
    def _scan_prompt(buffer: bytearray, start: int) -> Scan[GpsMessage]:
        end = min(len(buffer), start + _MAX_PROMPT)
        for i in range(start + 1, end):
            byte = buffer[i]
            if byte == 0x5D and i > start + 1:  # ']'
                return Scan.frame(i + 1 - start, Prompt(bytes(buffer[start + 1:i]).decode("ascii")))
            if byte not in _NMEA_ADDRESS_CHARS and byte != 0x5F:  # A-Z 0-9 _
                return Scan.skip(1, Fault.GARBAGE)
        if len(buffer) - start >= _MAX_PROMPT:
            return Scan.skip(1, Fault.GARBAGE)
        return Scan.need_more()


# ------------------------------------------------------------ host-side command encoders


def _command(*words: str) -> bytes:
    text = " ".join(w for w in words if w)
    if not text.isascii() or any(c in text for c in "\r\n"):
        raise ValueError(f"command {text!r} is not one line of ASCII")
    return text.encode("ascii") + b"\r\n"


def _fmt_number(value: float) -> str:
    return f"{value:g}" if value == int(value) else repr(float(value))


def encode_log_command(message: str, port: str | None = "COM1", trigger: str = "ONTIME",
                       period_s: float | None = 0.25, offset_s: float | None = None,
                       hold: bool = False) -> bytes:
    """Abbreviated ASCII LOG command, e.g. ``log com1 bestposa ontime 0.25`` CR LF.

    ``message`` includes its format suffix (``BESTPOSA``, ``BESTPOSB``, ``GPGGA``).
    Raises ValueError on a negative period or offset, or non-ASCII text.
    """
    if (period_s is not None and period_s < 0) or (offset_s is not None and offset_s < 0):
        raise ValueError("period and offset must be >= 0")
    words = ["log", (port or "").lower(), message.lower(), trigger.lower()]
    if period_s is not None:
        words.append(_fmt_number(period_s))
        if offset_s is not None:
            words.append(_fmt_number(offset_s))
            if hold:
                words.append("hold")
    return _command(*words)


def encode_unlog_command(message: str, port: str | None = None) -> bytes:
    """``unlog [port] message`` CR LF. Raises ValueError on non-ASCII text."""
    return _command("unlog", (port or "").lower(), message.lower())


def encode_unlogall_command(port: str | None = None) -> bytes:
    """``unlogall [port]`` CR LF: stop every log (on one port). Raises ValueError."""
    return _command("unlogall", (port or "").lower())


def encode_com_command(port: str, baud: int) -> bytes:
    """``com <port> <baud> n 8 1 n off on`` CR LF: set a port's bit rate (8N1, no
    handshake, no echo, break detection on: the OEM4 defaults apart from the rate).

    Raises ValueError for a non-positive rate.
    """
    if baud <= 0:
        raise ValueError("baud must be > 0")
    return _command("com", port.lower(), str(baud), "n", "8", "1", "n", "off", "on")


# ------------------------------------------------------------ device-side command decoder

_TRIGGERS: Final = frozenset({"ONNEW", "ONCHANGED", "ONTIME", "ONNEXT", "ONCE", "ONMARK"})
_PORT_WORD = re.compile(r"(COM\d|USB\d|THISPORT|ALLPORTS|ICOM\d|XCOM\d|AUX)(_ALL)?", re.I)


def _parse_command(line: str) -> GpsCommand:
    words = [w for w in re.split(r"[ ,\t]+", line.strip()) if w]
    if not words:
        return OtherCommand("", (), valid=False)
    verb, args = words[0].upper(), tuple(words[1:])
    try:
        if verb == "UNLOGALL":
            if len(args) > 2:
                raise ValueError("too many parameters")
            return UnlogAllCommand(args[0].upper() if args else None)
        if verb in ("LOG", "UNLOG"):
            rest = list(args)
            port = rest.pop(0).upper() if rest and _PORT_WORD.fullmatch(rest[0]) else None
            if not rest:
                raise ValueError("missing message")
            message = rest.pop(0).upper()
            if verb == "UNLOG":
                if rest:
                    raise ValueError("too many parameters")
                return UnlogCommand(port, message)
            trigger = rest.pop(0).upper() if rest else "ONNEW"
            if trigger not in _TRIGGERS:
                raise ValueError(f"unknown trigger {trigger}")
            period = float(rest.pop(0)) if rest else 0.0
            offset = float(rest.pop(0)) if rest else 0.0
            hold = rest.pop(0).upper() == "HOLD" if rest else False
            if rest or not (math.isfinite(period) and math.isfinite(offset)) \
                    or period < 0 or offset < 0:
                raise ValueError("bad parameters")
            return LogCommand(port, message, trigger, period, offset, hold)
    except ValueError:
        return OtherCommand(verb, args, valid=False)
    return OtherCommand(verb, args)


class GpsDeviceDecoder(StreamDecoder[GpsCommand]):
    """Device side: decodes the host's abbreviated ASCII command lines.

    A line ends at CR, LF or CR LF; fields are separated by spaces or commas and are
    case-insensitive. Blank lines are absorbed. Non-printable bytes are skipped as
    garbage. A line has no start marker, so a line that lost its line end runs into the
    next (as it does in the receiver). A line arriving byte by byte is searched once.
    ``feed`` never raises.
    """

    def __init__(self, *, max_buffer: int = 1 << 16) -> None:
        super().__init__(max_buffer=max_buffer)
        self._blanks = 0  # blanks before the line; valid while self.searched > 0

    def scan(self, buffer: bytearray) -> Scan[GpsCommand]:
        n = len(buffer)
        resume = self.searched
        start = self._blanks if resume else 0
        if not resume or resume == start:  # still among the leading blanks
            while start < n and buffer[start] in (_CR, _LF, 0x20):
                start += 1
            self._blanks = start
            if start == n:
                if n <= _MAX_LEADING_BLANKS:
                    return Scan.need_more(searched=n)
                return Scan.skip(n, Fault.GARBAGE)
            resume = start
        end = min(n, start + _MAX_COMMAND_LINE)
        for i in range(resume, end):
            byte = buffer[i]
            if byte in (_CR, _LF):
                consumed = i + 1
                if byte == _CR and consumed < n and buffer[consumed] == _LF:
                    consumed += 1
                line = bytes(buffer[start:i]).decode("ascii")
                return Scan.frame(consumed, _parse_command(line))
            if not _printable(byte):
                return Scan.skip(i + 1, Fault.GARBAGE)
        if n - start >= _MAX_COMMAND_LINE:
            return Scan.skip(n, Fault.OVERFLOW)
        return Scan.need_more(searched=end)


# ------------------------------------------------------------------------------- UTM

_WGS84_A: Final = 6378137.0
_WGS84_F: Final = 1 / 298.257223563
_UTM_K0: Final = 0.9996
_UTM_FALSE_EASTING: Final = 500000.0
_UTM_FALSE_NORTHING_SOUTH: Final = 10000000.0
_BANDS: Final = "CDEFGHJKLMNPQRSTUVWX"


@dataclass(frozen=True, slots=True)
class UtmCoordinate:
    """A UTM position: zone 1..60, latitude band letter, hemisphere ``N``/``S``, metres."""

    zone_number: int
    zone_letter: str
    hemisphere: str
    easting_m: float
    northing_m: float


def latlon_to_grid_near(latitude_deg: float, longitude_deg: float, easting_m: float,
                        northing_m: float) -> UtmCoordinate:
    """The UTM coordinates of a point in the grid (zone and hemisphere) where it lies
    nearest the position (``easting_m``, ``northing_m``) of another grid: the grid of a
    local frame whose origin is that position, when the point is across a zone boundary
    or the equator from it. Zones side by side are 6° apart and the two conventions of
    northing 10,000 km, so for points within a few hundred kilometres of the origin the
    nearest candidate (the point's own zone or a neighbour, either convention) is the
    origin's grid. Neighbours are taken around both the point's zone and its 6° band's
    zone, because the Norway and Svalbard exceptions make zones 12° wide: at 78° N a
    point just east of 9° E is in zone 33 while the ground just west of it is in 31."""
    own = latlon_to_utm(latitude_deg, longitude_deg)
    band = min(int((float(longitude_deg) + 180.0) // 6.0) + 1, 60)
    zones = {(centre - 1 + step) % 60 + 1 for centre in (own.zone_number, band)
             for step in (-1, 0, 1)}  # each centre and its neighbours, 60 next to 1
    best, best_distance = own, math.inf
    for zone in sorted(zones):
        for hemisphere in ("N", "S"):
            candidate = latlon_to_utm(latitude_deg, longitude_deg, zone=zone,
                                      hemisphere=hemisphere)
            distance = math.hypot(candidate.easting_m - easting_m,
                                  candidate.northing_m - northing_m)
            if distance < best_distance:
                best, best_distance = candidate, distance
    return best


def grid_convergence(latitude_deg: float, longitude_deg: float, zone: int,
                     hemisphere: str = "N") -> float:
    """The angle (rad, counter-clockwise) from true east to the grid's east at a point of
    a UTM grid: a direction at ENU yaw θ from true east lies at θ + this from grid east
    (about (λ − λ0)·sin φ: 0.14° at the Raptor's range, 2° at a zone's edge at 45°
    latitude). Measured along the parallel through the point, 1e-5° of longitude long."""
    step = 1e-5 if longitude_deg + 1e-5 <= 180.0 else -1e-5  # westward at the antimeridian
    here = latlon_to_utm(latitude_deg, longitude_deg, zone=zone, hemisphere=hemisphere)
    other = latlon_to_utm(latitude_deg, longitude_deg + step, zone=zone, hemisphere=hemisphere)
    sign = 1.0 if step > 0 else -1.0
    return math.atan2(sign * (other.northing_m - here.northing_m),
                      sign * (other.easting_m - here.easting_m))


def _utm_zone(lat: float, lon: float) -> int:
    zone = int((lon + 180.0) // 6.0) + 1
    if zone > 60:  # lon == 180 belongs to zone 60
        zone = 60
    if 56.0 <= lat < 64.0 and 3.0 <= lon < 12.0:  # south-western Norway
        return 32
    if lat >= 72.0:  # Svalbard
        if 0.0 <= lon < 9.0:
            return 31
        if 9.0 <= lon < 21.0:
            return 33
        if 21.0 <= lon < 33.0:
            return 35
        if 33.0 <= lon < 42.0:
            return 37
    return zone


def latlon_to_utm(latitude_deg: float, longitude_deg: float,
                  zone: int | None = None, hemisphere: str | None = None) -> UtmCoordinate:
    """WGS-84 latitude/longitude to UTM (Krüger series to third order in n: about a
    millimetre within a zone). ``zone`` forces a zone (to stay in one grid across a
    boundary); by default the standard zone, with the Norway and Svalbard exceptions.
    ``hemisphere`` (``"N"``/``"S"``) forces the northing's convention (to stay in one
    grid across the equator: a point south of it has a negative northing in ``"N"``);
    by default the point's own.

    Raises ValueError outside the UTM latitude limits (80 S to 84 N), for a longitude
    outside [-180, 180], or for a zone outside 1..60.
    """
    lat, lon = float(latitude_deg), float(longitude_deg)
    if not (math.isfinite(lat) and -80.0 <= lat <= 84.0):
        raise ValueError(f"latitude {latitude_deg} is outside the UTM limits (-80..84)")
    if not (math.isfinite(lon) and -180.0 <= lon <= 180.0):
        raise ValueError(f"longitude {longitude_deg} is outside -180..180")
    zone_number = _utm_zone(lat, lon) if zone is None else zone
    if not 1 <= zone_number <= 60:
        raise ValueError(f"UTM zone {zone_number} is outside 1..60")
    central = math.radians(zone_number * 6 - 183)
    dlon = math.radians(lon) - central
    dlon = (dlon + math.pi) % (2 * math.pi) - math.pi

    n = _WGS84_F / (2 - _WGS84_F)
    e = math.sqrt(_WGS84_F * (2 - _WGS84_F))
    rect_a = _WGS84_A / (1 + n) * (1 + n * n / 4 + n ** 4 / 64)
    alpha = (n / 2 - 2 * n * n / 3 + 5 * n ** 3 / 16,
             13 * n * n / 48 - 3 * n ** 3 / 5,
             61 * n ** 3 / 240)
    phi = math.radians(lat)
    sin_phi = math.sin(phi)
    # conformal latitude, as tan: t = sinh(atanh(sin phi) - e atanh(e sin phi))
    t = math.sinh(math.atanh(sin_phi) - e * math.atanh(e * sin_phi))
    xi_p = math.atan2(t, math.cos(dlon))
    eta_p = math.asinh(math.sin(dlon) / math.hypot(t, math.cos(dlon)))
    xi, eta = xi_p, eta_p
    for j, a_j in enumerate(alpha, start=1):
        xi += a_j * math.sin(2 * j * xi_p) * math.cosh(2 * j * eta_p)
        eta += a_j * math.cos(2 * j * xi_p) * math.sinh(2 * j * eta_p)
    easting = _UTM_FALSE_EASTING + _UTM_K0 * rect_a * eta
    northing = _UTM_K0 * rect_a * xi
    if hemisphere is None:
        hemisphere = "N" if lat >= 0 else "S"
    elif hemisphere not in ("N", "S"):
        raise ValueError(f"hemisphere {hemisphere!r} is neither 'N' nor 'S'")
    if hemisphere == "S":
        northing += _UTM_FALSE_NORTHING_SOUTH
    band = _BANDS[min(int((lat + 80.0) // 8.0), len(_BANDS) - 1)]
    return UtmCoordinate(zone_number, band, hemisphere, easting, northing)
