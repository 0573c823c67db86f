"""Sans-I/O codec of the MPC555 vehicle-controller serial link (afa's designed protocol).

The Raptor's MPC555 measures the two front wheel encoders and drives steering, pedal and
brake (seed §3.1.5, §3.5). DRDC never published its serial protocol, so afa defines one;
``docs/protocols/mpc555.md`` is the normative description. In short, every frame is::

    A5 01 LEN TYPE SEQ PAYLOAD[LEN] CRC_HI CRC_LO

big-endian throughout (the MPC555 is a big-endian PowerPC), with a CRC-16/CCITT-FALSE
over every byte before the CRC. Message types with bit 7 set travel controller -> host
(reports), the others host -> controller (commands).

Two directions, two decoders:

- host side: :class:`Mpc555Decoder` decodes reports; :func:`encode_command` encodes commands;
- device side (the fake controller): :class:`Mpc555DeviceDecoder` decodes commands;
  :func:`encode_report` encodes reports.

Decoders yield :class:`Packet` objects (the frame's sequence number and its message) and
never raise. Messages hold wire units as integers; field names carry the unit.
"""

from __future__ import annotations

import binascii
import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import Any, ClassVar, Generic, TypeVar

from afa.codec import Fault, Scan, StreamDecoder

__all__ = [
    "SYNC", "VERSION", "HEADER_SIZE", "CRC_SIZE", "MAX_PAYLOAD", "MAX_FRAME",
    "MAX_PEDAL_POINTS", "CONTROLLER_WATCHDOG_MS", "MIN_STEER_SPEED_MM_S",
    "MessageType", "Mode", "StatusFlags", "Faults", "AckResult",
    "crc16_ccitt_false", "crc16_ccitt_false_reference", "encode_frame", "next_seq",
    "SequenceCounter", "Packet",
    "Heartbeat", "SetVelocity", "SetJoystickVelocity", "StartVehicle", "StopVehicle",
    "SetArbiter", "ConfigureReports", "SetLimits", "SetWheelCalibration",
    "SetSteerCalibration", "PedalBreakpoint", "SetPedalCalibration", "SetSteerPid",
    "WheelDistanceReport", "SpeedReport", "StatusReport", "CommandAck",
    "Command", "Report", "COMMAND_TYPES", "REPORT_TYPES",
    "encode_command", "encode_report", "Mpc555Decoder", "Mpc555DeviceDecoder",
    "steering_angle", "yaw_rate",
]

SYNC = 0xA5
"""Start-of-frame byte (1010 0101: alternating bits, rare in idle lines and small integers)."""
VERSION = 0x01
"""Protocol version; changes whenever a message type is added or a layout changes."""
HEADER_SIZE = 5  # SYNC, VERSION, LEN, TYPE, SEQ
CRC_SIZE = 2
MAX_PEDAL_POINTS = 8
MAX_PAYLOAD = 1 + 4 * MAX_PEDAL_POINTS  # the largest message: a full pedal table (33 bytes)
MAX_FRAME = HEADER_SIZE + MAX_PAYLOAD + CRC_SIZE
CONTROLLER_WATCHDOG_MS = 500
"""The controller brakes to a stop after this long without a valid host frame."""
MIN_STEER_SPEED_MM_S = 10
"""Below this speed the curvature omega/v is undefined; the controller holds its steering."""


# --------------------------------------------------------------------------- checksum

def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16_ccitt_false(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR).

    Check value: ``crc16_ccitt_false(b"123456789") == 0x29B1``. Pass a previous result
    as ``crc`` to continue over more data. It is ``binascii.crc_hqx`` (the same CRC
    in C; every frame is checked on both sides, ~100 a simulated second);
    :func:`crc16_ccitt_false_reference` is the table loop the tests compare it with.
    """
    return binascii.crc_hqx(data, crc)


def crc16_ccitt_false_reference(data: bytes | bytearray | memoryview,
                                crc: int = 0xFFFF) -> int:
    """:func:`crc16_ccitt_false` as a byte-at-a-time table loop."""
    table = _CRC_TABLE
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ byte]
    return crc


# --------------------------------------------------------------------------- enums

class MessageType(IntEnum):
    """The TYPE byte. Bit 7 set: controller -> host report; clear: host -> controller."""

    HEARTBEAT = 0x01
    SET_VELOCITY = 0x02
    SET_JOYSTICK_VELOCITY = 0x03
    START_VEHICLE = 0x04
    STOP_VEHICLE = 0x05
    SET_ARBITER = 0x06
    CONFIGURE_REPORTS = 0x07
    SET_LIMITS = 0x08
    SET_WHEEL_CALIBRATION = 0x09
    SET_STEER_CALIBRATION = 0x0A
    SET_PEDAL_CALIBRATION = 0x0B
    SET_STEER_PID = 0x0C
    WHEEL_DISTANCE = 0x81
    SPEED = 0x82
    STATUS = 0x83
    ACK = 0x84

    @property
    def is_report(self) -> bool:
        return bool(self.value & 0x80)


class Mode(IntEnum):
    """Controller operating mode (STATUS byte 4); see the state table in the protocol doc."""

    STOPPED = 0  # brake applied, pedal neutral, motion commands refused
    RUNNING = 1  # started, arbiter off: obeys SET_VELOCITY
    ARBITER = 2  # started, arbiter on: obeys SET_VELOCITY from the Arc Arbiter path
    JOYSTICK = 3  # started, joystick override: obeys SET_JOYSTICK_VELOCITY only


class StatusFlags(IntFlag):
    """STATUS byte 5. Reserved bits are sent as 0 and kept if set."""

    ESTOP = 0x01  # the hardware e-stop chain is open
    WATCHDOG = 0x02  # the link watchdog stopped the vehicle (cleared by START_VEHICLE)
    BRAKE = 0x04  # the brake is applied
    ARBITER_ENABLED = 0x08  # SET_ARBITER(on) is in force
    CALIBRATED = 0x10  # all four calibration messages received since reset


class Faults(IntFlag):
    """STATUS bytes 6-7: latched hardware faults (cleared when the condition clears)."""

    LEFT_ENCODER = 0x0001
    RIGHT_ENCODER = 0x0002
    STEER_SENSOR = 0x0004  # steering sensor reading outside [Min, Max]
    STEER_SERVO = 0x0008  # steering tracking error above limit for > 1 s
    PEDAL_ACTUATOR = 0x0010
    BRAKE_ACTUATOR = 0x0020
    SUPPLY_LOW = 0x0040
    RX_OVERRUN = 0x0080  # UART receive overrun: bytes were lost


class AckResult(IntEnum):
    """ACK byte 2. Bit 7 clear: executed (ACK); set: refused (NAK) with the reason."""

    OK = 0x00
    LIMITED = 0x01  # executed with values clamped to the SET_LIMITS limits
    NOT_RUNNING = 0x80  # motion command while STOPPED
    WRONG_MODE = 0x81  # SET_VELOCITY during joystick override
    ESTOP = 0x82  # START_VEHICLE while the e-stop is open
    OUT_OF_RANGE = 0x83  # a parameter outside its valid range (see the protocol doc)
    NOT_CALIBRATED = 0x84  # START_VEHICLE before all calibration was received
    FAULT = 0x85  # START_VEHICLE with a latched fault

    @property
    def accepted(self) -> bool:
        return not self.value & 0x80


# --------------------------------------------------------------------------- framing

def encode_frame(message_type: int, seq: int, payload: bytes) -> bytes:
    """One complete frame: header, ``payload``, CRC.

    Raises ValueError if ``message_type`` or ``seq`` is not a byte or the payload is
    longer than :data:`MAX_PAYLOAD`.
    """
    if not 0 <= message_type <= 0xFF:
        raise ValueError(f"message type {message_type} is not a byte")
    if not 0 <= seq <= 0xFF:
        raise ValueError(f"sequence number {seq} is not in 0..255")
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    body = bytes((SYNC, VERSION, len(payload), message_type, seq)) + payload
    return body + crc16_ccitt_false(body).to_bytes(2, "big")


def next_seq(seq: int) -> int:
    """The sequence number after ``seq`` (wraps 255 -> 0)."""
    return (seq + 1) & 0xFF


class SequenceCounter:
    """Per-direction frame counter: 0, 1, ..., 255, 0, ..."""

    def __init__(self, start: int = 0) -> None:
        self._next = start & 0xFF

    def next(self) -> int:
        """Return the number for the next new frame (not for a retransmission)."""
        seq = self._next
        self._next = next_seq(seq)
        return seq


M = TypeVar("M")


@dataclass(frozen=True, slots=True)
class Packet(Generic[M]):
    """A decoded frame: its sequence number and its message."""

    seq: int
    message: M


# --------------------------------------------------------------------------- messages

def _pack(layout: struct.Struct, *values: int) -> bytes:
    try:
        return layout.pack(*values)
    except struct.error as error:
        raise ValueError(f"value out of range for its wire field: {error}") from error


def _flag(value: int) -> bool:
    if value not in (0, 1):
        raise ValueError(f"boolean byte must be 0 or 1, got {value}")
    return bool(value)


class _Message:
    """Mixin: the wire type, the payload layout and the length check."""

    __slots__ = ()
    TYPE: ClassVar[MessageType]
    LAYOUT: ClassVar[struct.Struct]

    @classmethod
    def accepts_length(cls, length: int) -> bool:
        """Whether a frame of this type may carry ``length`` payload bytes."""
        return length == cls.LAYOUT.size

    @classmethod
    def from_payload(cls, payload: bytes) -> Any:
        """The message in ``payload``; raises ValueError if it is not decodable."""
        raise NotImplementedError

    def payload(self) -> bytes:
        """The payload bytes; raises ValueError if a field does not fit the wire."""
        raise NotImplementedError


class _Empty(_Message):
    __slots__ = ()
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">")

    def payload(self) -> bytes:
        return b""

    @classmethod
    def from_payload(cls, payload: bytes) -> Any:
        return cls()


@dataclass(frozen=True, slots=True)
class Heartbeat(_Empty):
    """Keep-alive; resets the controller's link watchdog. Empty payload."""

    TYPE: ClassVar[MessageType] = MessageType.HEARTBEAT


@dataclass(frozen=True, slots=True)
class StartVehicle(_Empty):
    """startVehicle(): release the brake and accept motion commands. Empty payload."""

    TYPE: ClassVar[MessageType] = MessageType.START_VEHICLE


@dataclass(frozen=True, slots=True)
class StopVehicle(_Empty):
    """stopVehicle(): pedal to neutral and brake to a stop. Empty payload."""

    TYPE: ClassVar[MessageType] = MessageType.STOP_VEHICLE


_VELOCITY = struct.Struct(">hh")


class _Velocity(_Message):
    """Translation (mm/s) and rotation (mrad/s), each an int16: the two velocity commands."""

    __slots__ = ()
    LAYOUT: ClassVar[struct.Struct] = _VELOCITY
    translation_mm_s: int
    rotation_mrad_s: int

    def payload(self) -> bytes:
        """Raises ValueError if a field does not fit an int16."""
        return _pack(self.LAYOUT, self.translation_mm_s, self.rotation_mrad_s)

    @classmethod
    def from_payload(cls, payload: bytes) -> Any:
        return cls(*cls.LAYOUT.unpack(payload))


@dataclass(frozen=True, slots=True)
class SetVelocity(_Velocity):
    """setVelocity(VelocityIDL): translation (mm/s, forward +), rotation (mrad/s, left +).

    The controller turns the pair into a steering angle with :func:`steering_angle`.
    """

    TYPE: ClassVar[MessageType] = MessageType.SET_VELOCITY
    translation_mm_s: int
    rotation_mrad_s: int


@dataclass(frozen=True, slots=True)
class SetJoystickVelocity(_Velocity):
    """setJoystickVelocity(VelocityIDL): as :class:`SetVelocity`; takes over from autonomy."""

    TYPE: ClassVar[MessageType] = MessageType.SET_JOYSTICK_VELOCITY
    translation_mm_s: int
    rotation_mrad_s: int


@dataclass(frozen=True, slots=True)
class SetArbiter(_Message):
    """setArbiter(): arbiter on (1) or off (0)."""

    TYPE: ClassVar[MessageType] = MessageType.SET_ARBITER
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">B")
    enabled: bool

    def payload(self) -> bytes:
        return bytes((1 if self.enabled else 0,))

    @classmethod
    def from_payload(cls, payload: bytes) -> SetArbiter:
        """Raises ValueError unless the byte is 0 or 1."""
        return cls(_flag(payload[0]))


@dataclass(frozen=True, slots=True)
class ConfigureReports(_Message):
    """Report intervals in ms (0 disables the report): WheelDistRepTime, SpeedRepTime, status."""

    TYPE: ClassVar[MessageType] = MessageType.CONFIGURE_REPORTS
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">HHH")
    wheel_distance_ms: int = 200
    speed_ms: int = 1000
    status_ms: int = 500

    def payload(self) -> bytes:
        """Raises ValueError if an interval does not fit a uint16."""
        return _pack(self.LAYOUT, self.wheel_distance_ms, self.speed_ms, self.status_ms)

    @classmethod
    def from_payload(cls, payload: bytes) -> ConfigureReports:
        return cls(*cls.LAYOUT.unpack(payload))


@dataclass(frozen=True, slots=True)
class SetLimits(_Message):
    """Controller-side limits and the wheelbase used to turn rotation into steering."""

    TYPE: ClassVar[MessageType] = MessageType.SET_LIMITS
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">HHHH")
    max_translation_mm_s: int = 2000  # MaxTransVelocity
    max_rotation_mrad_s: int = 1000  # MaxRotVelocity (1 rad/s)
    max_steering_cdeg: int = 3000  # MaxSteeringAngle (30 deg) in 0.01 deg
    wheelbase_mm: int = 1900

    def payload(self) -> bytes:
        """Raises ValueError if a field does not fit a uint16."""
        return _pack(self.LAYOUT, self.max_translation_mm_s, self.max_rotation_mrad_s,
                     self.max_steering_cdeg, self.wheelbase_mm)

    @classmethod
    def from_payload(cls, payload: bytes) -> SetLimits:
        return cls(*cls.LAYOUT.unpack(payload))


@dataclass(frozen=True, slots=True)
class SetWheelCalibration(_Message):
    """LfdParam / RfdParam: wheel travel per encoder count, in nanometres (1e-6 mm)."""

    TYPE: ClassVar[MessageType] = MessageType.SET_WHEEL_CALIBRATION
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">II")
    left_nm_per_count: int
    right_nm_per_count: int

    def payload(self) -> bytes:
        """Raises ValueError if a field does not fit a uint32."""
        return _pack(self.LAYOUT, self.left_nm_per_count, self.right_nm_per_count)

    @classmethod
    def from_payload(cls, payload: bytes) -> SetWheelCalibration:
        return cls(*cls.LAYOUT.unpack(payload))


@dataclass(frozen=True, slots=True)
class SetSteerCalibration(_Message):
    """SteerParam: angle = (sensor - center) * gain; sensor limits min/max (10-bit counts)."""

    TYPE: ClassVar[MessageType] = MessageType.SET_STEER_CALIBRATION
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">HIHH")
    center: int
    gain_udeg_per_count: int  # micro-degrees per count
    minimum: int
    maximum: int

    def payload(self) -> bytes:
        """Raises ValueError if a field does not fit its unsigned field."""
        return _pack(self.LAYOUT, self.center, self.gain_udeg_per_count, self.minimum,
                     self.maximum)

    @classmethod
    def from_payload(cls, payload: bytes) -> SetSteerCalibration:
        return cls(*cls.LAYOUT.unpack(payload))


_PEDAL_POINT = struct.Struct(">hH")


@dataclass(frozen=True, slots=True)
class PedalBreakpoint:
    """One PedalParam breakpoint: the actuator command (12-bit) giving this velocity."""

    velocity_mm_s: int
    command: int


@dataclass(frozen=True, slots=True)
class SetPedalCalibration(_Message):
    """PedalParam: 2..8 breakpoints of the piecewise-linear velocity -> pedal command map."""

    TYPE: ClassVar[MessageType] = MessageType.SET_PEDAL_CALIBRATION
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">B")  # the count; points follow
    points: tuple[PedalBreakpoint, ...]

    @classmethod
    def accepts_length(cls, length: int) -> bool:
        count, rest = divmod(length - 1, _PEDAL_POINT.size)
        return length >= 1 and rest == 0 and 2 <= count <= MAX_PEDAL_POINTS

    def payload(self) -> bytes:
        """Raises ValueError unless there are 2..8 points with fields in range."""
        if not 2 <= len(self.points) <= MAX_PEDAL_POINTS:
            raise ValueError(f"pedal table needs 2..{MAX_PEDAL_POINTS} points, "
                             f"got {len(self.points)}")
        return bytes((len(self.points),)) + b"".join(
            _pack(_PEDAL_POINT, point.velocity_mm_s, point.command) for point in self.points)

    @classmethod
    def from_payload(cls, payload: bytes) -> SetPedalCalibration:
        """Raises ValueError if the count byte disagrees with the length."""
        count = payload[0]
        if len(payload) != 1 + count * _PEDAL_POINT.size:
            raise ValueError(f"pedal count {count} disagrees with {len(payload)} payload bytes")
        return cls(tuple(PedalBreakpoint(*_PEDAL_POINT.unpack_from(payload, 1 + 4 * i))
                         for i in range(count)))


@dataclass(frozen=True, slots=True)
class SetSteerPid(_Message):
    """SteerPID gains in thousandths: P (%/deg), I (%/(deg*s)), D (%*s/deg)."""

    TYPE: ClassVar[MessageType] = MessageType.SET_STEER_PID
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">III")
    kp_milli: int
    ki_milli: int
    kd_milli: int

    def payload(self) -> bytes:
        """Raises ValueError if a gain does not fit a uint32."""
        return _pack(self.LAYOUT, self.kp_milli, self.ki_milli, self.kd_milli)

    @classmethod
    def from_payload(cls, payload: bytes) -> SetSteerPid:
        return cls(*cls.LAYOUT.unpack(payload))


@dataclass(frozen=True, slots=True)
class WheelDistanceReport(_Message):
    """Cumulative signed front-wheel encoder counts since controller reset (wrap mod 2^32)."""

    TYPE: ClassVar[MessageType] = MessageType.WHEEL_DISTANCE
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">Iii")
    time_ms: int  # controller clock, ms since reset, wraps mod 2^32
    left_counts: int
    right_counts: int

    def payload(self) -> bytes:
        """Raises ValueError if a field does not fit its wire field."""
        return _pack(self.LAYOUT, self.time_ms, self.left_counts, self.right_counts)

    @classmethod
    def from_payload(cls, payload: bytes) -> WheelDistanceReport:
        return cls(*cls.LAYOUT.unpack(payload))


@dataclass(frozen=True, slots=True)
class SpeedReport(_Message):
    """Measured speed and steering, with the raw pedal command and steering sensor."""

    TYPE: ClassVar[MessageType] = MessageType.SPEED
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">IhhHH")
    time_ms: int
    speed_mm_s: int  # forward +
    steering_cdeg: int  # 0.01 deg, left +
    pedal_command: int  # 12-bit actuator command, 2048 neutral
    steer_sensor: int  # 10-bit steering sensor reading

    def payload(self) -> bytes:
        """Raises ValueError if a field does not fit its wire field."""
        return _pack(self.LAYOUT, self.time_ms, self.speed_mm_s, self.steering_cdeg,
                     self.pedal_command, self.steer_sensor)

    @classmethod
    def from_payload(cls, payload: bytes) -> SpeedReport:
        return cls(*cls.LAYOUT.unpack(payload))


@dataclass(frozen=True, slots=True)
class StatusReport(_Message):
    """Mode, flags, faults, age of the last valid host frame, count of dropped host frames."""

    TYPE: ClassVar[MessageType] = MessageType.STATUS
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">IBBHHH")
    time_ms: int
    mode: Mode
    flags: StatusFlags
    faults: Faults
    command_age_ms: int  # saturates at 65535
    rx_errors: int  # host frames dropped (CRC, version, type, length), wraps mod 2^16

    def payload(self) -> bytes:
        """Raises ValueError if a field does not fit its wire field."""
        return _pack(self.LAYOUT, self.time_ms, int(self.mode), int(self.flags),
                     int(self.faults), self.command_age_ms, self.rx_errors)

    @classmethod
    def from_payload(cls, payload: bytes) -> StatusReport:
        """Raises ValueError on an unknown mode."""
        time_ms, mode, flags, faults, age, errors = cls.LAYOUT.unpack(payload)
        return cls(time_ms, Mode(mode), StatusFlags(flags), Faults(faults), age, errors)


@dataclass(frozen=True, slots=True)
class CommandAck(_Message):
    """ACK/NAK of one command frame: its sequence number, its type and the result."""

    TYPE: ClassVar[MessageType] = MessageType.ACK
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(">BBB")
    acked_seq: int
    acked_type: MessageType
    result: AckResult

    @property
    def accepted(self) -> bool:
        return self.result.accepted

    def payload(self) -> bytes:
        """Raises ValueError if the sequence number is not a byte or the type not a command."""
        if MessageType(self.acked_type).is_report:
            raise ValueError(f"{self.acked_type!r} is a report, not a command")
        return _pack(self.LAYOUT, self.acked_seq, int(self.acked_type), int(self.result))

    @classmethod
    def from_payload(cls, payload: bytes) -> CommandAck:
        """Raises ValueError on an unknown result or a non-command type."""
        seq, acked, result = cls.LAYOUT.unpack(payload)
        acked_type = MessageType(acked)
        if acked_type.is_report:
            raise ValueError(f"ACK names report type {acked_type!r}")
        return cls(seq, acked_type, AckResult(result))


Command = (Heartbeat | SetVelocity | SetJoystickVelocity | StartVehicle | StopVehicle
           | SetArbiter | ConfigureReports | SetLimits | SetWheelCalibration
           | SetSteerCalibration | SetPedalCalibration | SetSteerPid)
Report = WheelDistanceReport | SpeedReport | StatusReport | CommandAck

COMMAND_TYPES: Mapping[int, type[Command]] = {
    cls.TYPE: cls for cls in (Heartbeat, SetVelocity, SetJoystickVelocity, StartVehicle,
                              StopVehicle, SetArbiter, ConfigureReports, SetLimits,
                              SetWheelCalibration, SetSteerCalibration, SetPedalCalibration,
                              SetSteerPid)
}
REPORT_TYPES: Mapping[int, type[Report]] = {
    cls.TYPE: cls for cls in (WheelDistanceReport, SpeedReport, StatusReport, CommandAck)
}


def encode_command(command: Command, seq: int) -> bytes:
    """Host side: one frame carrying ``command`` with sequence number ``seq``.

    Raises TypeError if ``command`` is not a command; ValueError if a field or ``seq``
    is out of range.
    """
    if COMMAND_TYPES.get(getattr(command, "TYPE", -1)) is not type(command):
        raise TypeError(f"{type(command).__name__} is not an MPC555 command")
    return encode_frame(command.TYPE, seq, command.payload())


def encode_report(report: Report, seq: int) -> bytes:
    """Device side: one frame carrying ``report`` with sequence number ``seq``.

    Raises TypeError if ``report`` is not a report; ValueError if a field or ``seq`` is
    out of range.
    """
    if REPORT_TYPES.get(getattr(report, "TYPE", -1)) is not type(report):
        raise TypeError(f"{type(report).__name__} is not an MPC555 report")
    return encode_frame(report.TYPE, seq, report.payload())


# --------------------------------------------------------------------------- decoders

def _next_sync(buffer: bytearray) -> int:
    """Bytes to drop so the buffer starts at the next possible frame start."""
    index = buffer.find(SYNC, 1)
    return index if index > 0 else len(buffer)


class _FrameDecoder(StreamDecoder[Packet[M]]):
    """Shared framing; subclasses name the message set they accept."""

    _messages: ClassVar[Mapping[int, type[_Message]]] = {}

    def scan(self, buffer: bytearray) -> Scan[Packet[M]]:
        size = len(buffer)
        if buffer[0] != SYNC:
            return Scan.skip(_next_sync(buffer), Fault.GARBAGE)
        if size < 2:
            return Scan.need_more()
        if buffer[1] != VERSION:
            return Scan.skip(_next_sync(buffer), Fault.GARBAGE)
        if size < 4:
            return Scan.need_more()
        length, message_type = buffer[2], buffer[3]
        cls = self._messages.get(message_type)
        # Checked before waiting for the body: a false header in noise claiming a long
        # frame would otherwise hold back the valid frames behind it.
        if cls is None or not cls.accepts_length(length):
            return Scan.skip(_next_sync(buffer), Fault.MALFORMED)
        total = HEADER_SIZE + length + CRC_SIZE
        if size < total:
            return Scan.need_more()
        end = HEADER_SIZE + length
        frame = bytes(buffer[:total])
        if crc16_ccitt_false(frame[:end]) != int.from_bytes(frame[end:], "big"):
            return Scan.skip(_next_sync(buffer), Fault.CHECKSUM)
        try:
            message = cls.from_payload(frame[HEADER_SIZE:end])
        except (ValueError, struct.error):
            return Scan.skip(_next_sync(buffer), Fault.MALFORMED)
        return Scan.frame(total, Packet(frame[4], message))


class Mpc555Decoder(_FrameDecoder[Report]):
    """Host side: decodes the controller's reports into :class:`Packet` objects.

    Command frames (e.g. an echo) and unknown types are dropped as malformed.
    """

    _messages = REPORT_TYPES


class Mpc555DeviceDecoder(_FrameDecoder[Command]):
    """Device side (the fake controller): decodes the host's commands into packets."""

    _messages = COMMAND_TYPES


# --------------------------------------------------------------------------- kinematics

def steering_angle(translation_mm_s: float, rotation_mrad_s: float,
                   wheelbase_mm: float) -> float | None:
    """Front-wheel steering angle (rad, left +) for a velocity, by the bicycle model.

    The turn centre lies on the rear axle line, so the curvature is ``w / v`` and
    ``tan(delta) = wheelbase * w / v``. Returns None when ``|v|`` is below
    :data:`MIN_STEER_SPEED_MM_S`, where the curvature is undefined (the controller then
    keeps its present steering angle). The result is not clamped.
    """
    if abs(translation_mm_s) < MIN_STEER_SPEED_MM_S:
        return None
    curvature_per_mm = (rotation_mrad_s / 1000.0) / translation_mm_s
    return math.atan(wheelbase_mm * curvature_per_mm)


def yaw_rate(translation_mm_s: float, steering_rad: float, wheelbase_mm: float) -> float:
    """Rotational velocity (rad/s, left +) of the bicycle model: ``v * tan(delta) / L``."""
    return translation_mm_s * math.tan(steering_rad) / wheelbase_mm
