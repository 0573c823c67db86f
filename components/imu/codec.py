"""MicroStrain 3DM-GX1 serial protocol: a sans-I/O codec for both ends of the wire.

The host sends a command (one byte, or a few for commands that carry arguments); the
device answers with a fixed-length reply that starts with the same command byte and ends
with a 16-bit big-endian checksum: the header byte plus every big-endian 16-bit word
between it and the checksum, modulo 2^16. Nothing else marks a frame, so the host
decoder recognises a frame only by a known reply byte *and* a matching checksum.

Host side (the IMU component): :class:`ImuDecoder` decodes replies; ``encode_*``
functions build commands. Device side (the fake IMU and the simulator):
:class:`ImuDeviceDecoder` decodes commands; ``encode_*_reply`` functions build replies
from physical values. Byte layouts, scale factors and sources: ``docs/protocols/
imu_3dmgx1.md``.

Units: angles in radians, accelerations in m/s^2 (``accel_g`` gives g), angular rates
in rad/s, temperature in degrees Celsius, timer in ticks (``timer_seconds`` gives s).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Final, TypeAlias

from afa.codec import Fault, Scan, StreamDecoder

__all__ = [
    "ACCEL_GAIN_SCALE_ADDRESS",
    "CMD_CAPTURE_GYRO_BIAS",
    "CMD_FIRMWARE_VERSION",
    "CMD_GYRO_STAB_EULER",
    "CMD_GYRO_STAB_EULER_ACCEL_RATE",
    "CMD_INSTANT_EULER",
    "CMD_READ_EEPROM",
    "CMD_SERIAL_NUMBER",
    "CMD_SET_CONTINUOUS",
    "CMD_TEMPERATURE",
    "CMD_WRITE_EEPROM",
    "COMMAND_LENGTHS",
    "CONTINUOUS_COMMANDS",
    "DEFAULT_ACCEL_GAIN_SCALE",
    "DEFAULT_GYRO_GAIN_SCALE",
    "DEFAULT_MAG_GAIN_SCALE",
    "EULER_COUNTS_PER_TURN",
    "GAIN_DIVIDEND",
    "GYRO_GAIN_SCALE_ADDRESS",
    "MAG_GAIN_SCALE_ADDRESS",
    "POLL_COMMANDS",
    "REPLY_LENGTHS",
    "STANDARD_GRAVITY",
    "TIMER_TICK_SECONDS",
    "ContinuousModeSet",
    "EepromValue",
    "EulerAccelRate",
    "EulerAngles",
    "FirmwareVersion",
    "GainScales",
    "GyroBiasCaptured",
    "ImuCommand",
    "ImuDecoder",
    "ImuDeviceDecoder",
    "ImuReply",
    "PollCommand",
    "ReadEepromCommand",
    "SerialNumber",
    "SetContinuousCommand",
    "Temperature",
    "WriteEepromCommand",
    "checksum",
    "encode_command",
    "encode_continuous_mode_set_reply",
    "encode_eeprom_value_reply",
    "encode_euler_accel_rate_reply",
    "encode_euler_angles_reply",
    "encode_firmware_version_reply",
    "encode_gyro_bias_captured_reply",
    "encode_poll",
    "encode_read_eeprom",
    "encode_reply",
    "encode_serial_number_reply",
    "encode_set_continuous",
    "encode_stop_continuous",
    "encode_temperature_reply",
    "encode_write_eeprom",
]

# --- command bytes (3DM-GX1 Data Communications Protocol, command set summary) -------

CMD_CAPTURE_GYRO_BIAS: Final = 0x06
CMD_TEMPERATURE: Final = 0x07
CMD_INSTANT_EULER: Final = 0x0D
CMD_GYRO_STAB_EULER: Final = 0x0E
CMD_SET_CONTINUOUS: Final = 0x10
CMD_READ_EEPROM: Final = 0x28  # "Read EEPROM value with checksum"
CMD_WRITE_EEPROM: Final = 0x29  # "Write EEPROM value with checksum"
CMD_GYRO_STAB_EULER_ACCEL_RATE: Final = 0x31
CMD_FIRMWARE_VERSION: Final = 0xF0
CMD_SERIAL_NUMBER: Final = 0xF1

#: Reply length in bytes (header + data + 2 checksum bytes) for each reply we decode.
REPLY_LENGTHS: Final[Mapping[int, int]] = {
    CMD_CAPTURE_GYRO_BIAS: 5,
    CMD_TEMPERATURE: 7,
    CMD_INSTANT_EULER: 11,
    CMD_GYRO_STAB_EULER: 11,
    CMD_SET_CONTINUOUS: 7,
    CMD_READ_EEPROM: 7,
    CMD_WRITE_EEPROM: 7,
    CMD_GYRO_STAB_EULER_ACCEL_RATE: 23,
    CMD_FIRMWARE_VERSION: 5,
    CMD_SERIAL_NUMBER: 5,
}

#: Length in bytes of each host command we encode and the device side decodes.
COMMAND_LENGTHS: Final[Mapping[int, int]] = {
    CMD_CAPTURE_GYRO_BIAS: 1,
    CMD_TEMPERATURE: 1,
    CMD_INSTANT_EULER: 1,
    CMD_GYRO_STAB_EULER: 1,
    CMD_GYRO_STAB_EULER_ACCEL_RATE: 1,
    CMD_FIRMWARE_VERSION: 1,
    CMD_SERIAL_NUMBER: 1,
    CMD_SET_CONTINUOUS: 3,  # 0x10, 0x00 (confirms intent), command to repeat (0x00 = stop)
    CMD_READ_EEPROM: 3,  # 0x28, address MSB, address LSB
    CMD_WRITE_EEPROM: 7,  # 0x29, 0x71, address MSB, LSB, value MSB, LSB, 0xAA
}

#: Single-byte commands (polls).
POLL_COMMANDS: Final = frozenset(c for c, n in COMMAND_LENGTHS.items() if n == 1)
#: Commands this codec lets the host put into continuous mode (their replies decode here).
CONTINUOUS_COMMANDS: Final = frozenset(
    {CMD_TEMPERATURE, CMD_INSTANT_EULER, CMD_GYRO_STAB_EULER, CMD_GYRO_STAB_EULER_ACCEL_RATE}
)

_CONTINUOUS_CONFIRM: Final = 0x00
_WRITE_EEPROM_KEY: Final = 0x71  # second byte of 0x29: guards against stray writes
_WRITE_EEPROM_END: Final = 0xAA  # last byte of 0x29

# --- scale factors ---------------------------------------------------------------------

#: Euler angles: 65536 counts per full turn, i.e. 360/65536 degrees per count.
EULER_COUNTS_PER_TURN: Final = 65536
#: accel [g] = counts / (GAIN_DIVIDEND / AccelGainScale); rate [rad/s] likewise with
#: GyroGainScale; magnetic field [gauss] likewise with MagGainScale.
GAIN_DIVIDEND: Final = 32_768_000.0
#: EEPROM word addresses of the gain constants (read them with 0x28 at start-up).
GYRO_GAIN_SCALE_ADDRESS: Final = 130
ACCEL_GAIN_SCALE_ADDRESS: Final = 230
MAG_GAIN_SCALE_ADDRESS: Final = 232
#: The values the manual's conversion examples use; a real unit stores its own.
DEFAULT_ACCEL_GAIN_SCALE: Final = 7000
DEFAULT_GYRO_GAIN_SCALE: Final = 8500
DEFAULT_MAG_GAIN_SCALE: Final = 2000
#: Period of the 16-bit free-running TimerTicks counter (it wraps every ~429.5 s).
TIMER_TICK_SECONDS: Final = 0.0065536
#: g to m/s^2 (ISO 80000-3 standard gravity).
STANDARD_GRAVITY: Final = 9.80665

_INT16_MIN: Final = -32768
_INT16_MAX: Final = 32767
_RADIANS_PER_COUNT: Final = 2.0 * math.pi / EULER_COUNTS_PER_TURN


def checksum(data: bytes | bytearray | memoryview) -> int:
    """The 3DM-GX1 checksum of ``data`` = header byte followed by big-endian words.

    Returns header + sum of the words, modulo 2^16. ``data`` excludes the checksum.

    Raises:
        ValueError: ``data`` is empty or its length is even (an incomplete word).
    """
    if len(data) % 2 == 0:
        raise ValueError(f"3DM-GX1 frame body must be header + whole words, got {len(data)} bytes")
    words = struct.unpack_from(f">{len(data) // 2}H", data, 1)
    return (data[0] + sum(words)) & 0xFFFF


def _frame(header: int, words: Iterable[int]) -> bytes:
    """Header byte, each word as big-endian 16 bits (two's complement), checksum."""
    unsigned = [word & 0xFFFF for word in words]
    total = (header + sum(unsigned)) & 0xFFFF
    return struct.pack(f">B{len(unsigned) + 1}H", header, *unsigned, total)


def _int16(frame: bytes, offset: int) -> int:
    return int.from_bytes(frame[offset : offset + 2], "big", signed=True)


def _uint16(frame: bytes, offset: int) -> int:
    return int.from_bytes(frame[offset : offset + 2], "big", signed=False)


# --- gains --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class GainScales:
    """The unit's gain constants (EEPROM words 230 and 130); they fix the vector scales.

    Raises:
        ValueError: a gain is not in 1..32767 (a signed EEPROM word that is positive).
    """

    accel: int = DEFAULT_ACCEL_GAIN_SCALE
    gyro: int = DEFAULT_GYRO_GAIN_SCALE

    def __post_init__(self) -> None:
        for name, value in (("accel", self.accel), ("gyro", self.gyro)):
            if not 1 <= value <= _INT16_MAX:
                raise ValueError(f"{name} gain scale must be in 1..32767, got {value}")

    @property
    def g_per_count(self) -> float:
        """Acceleration in g of one count."""
        return self.accel / GAIN_DIVIDEND

    @property
    def rad_per_second_per_count(self) -> float:
        """Angular rate in rad/s of one count."""
        return self.gyro / GAIN_DIVIDEND


# --- replies (device -> host) ---------------------------------------------------------


@dataclass(frozen=True, slots=True)
class EulerAccelRate:
    """Reply 0x31: gyro-stabilised Euler angles, acceleration and angular rate vectors.

    Angles in radians (roll, pitch, yaw, each in [-pi, pi)), accelerations in m/s^2,
    rates in rad/s, all in the sensor frame. ``counts`` keeps the nine signed words as
    sent (roll, pitch, yaw, accel x/y/z, rate x/y/z) so they can be rescaled later.
    """

    roll: float
    pitch: float
    yaw: float
    accel_x: float
    accel_y: float
    accel_z: float
    rate_x: float
    rate_y: float
    rate_z: float
    timer_ticks: int
    counts: tuple[int, ...]

    @property
    def accel_g(self) -> tuple[float, float, float]:
        """The acceleration vector in g."""
        return (
            self.accel_x / STANDARD_GRAVITY,
            self.accel_y / STANDARD_GRAVITY,
            self.accel_z / STANDARD_GRAVITY,
        )

    @property
    def timer_seconds(self) -> float:
        """The timer reading in seconds (it wraps every 65536 ticks)."""
        return self.timer_ticks * TIMER_TICK_SECONDS


@dataclass(frozen=True, slots=True)
class EulerAngles:
    """Reply 0x0E (gyro-stabilised) or 0x0D (instantaneous): roll, pitch, yaw in rad."""

    roll: float
    pitch: float
    yaw: float
    timer_ticks: int
    stabilised: bool
    counts: tuple[int, int, int]

    @property
    def timer_seconds(self) -> float:
        """The timer reading in seconds."""
        return self.timer_ticks * TIMER_TICK_SECONDS


@dataclass(frozen=True, slots=True)
class GyroBiasCaptured:
    """Reply 0x06: the gyro bias capture finished (the unit must have been still)."""

    timer_ticks: int


@dataclass(frozen=True, slots=True)
class Temperature:
    """Reply 0x07: temperature inside the housing in degrees Celsius."""

    celsius: float
    timer_ticks: int
    count: int


@dataclass(frozen=True, slots=True)
class EepromValue:
    """Reply 0x28 (read) or 0x29 (write, echoing the value written).

    The reply does not carry the address: the host must remember what it asked for.
    ``value`` is the unsigned 16-bit word; ``signed_value`` is its two's complement.
    """

    value: int
    timer_ticks: int
    written: bool

    @property
    def signed_value(self) -> int:
        """The word as a signed 16-bit integer (gain constants are stored this way)."""
        return self.value - 0x10000 if self.value & 0x8000 else self.value


@dataclass(frozen=True, slots=True)
class ContinuousModeSet:
    """Reply 0x10: continuous mode now repeats ``command`` (0x00: continuous mode off)."""

    command: int
    timer_ticks: int


@dataclass(frozen=True, slots=True)
class FirmwareVersion:
    """Reply 0xF0: the firmware version number, e.g. 3104 for 3.1.04."""

    number: int

    @property
    def text(self) -> str:
        """The version as MicroStrain prints it: major.minor.build from #.#.##."""
        return f"{self.number // 1000}.{(self.number % 1000) // 100}.{self.number % 100}"


@dataclass(frozen=True, slots=True)
class SerialNumber:
    """Reply 0xF1: the device serial number."""

    number: int


ImuReply: TypeAlias = (
    EulerAccelRate
    | EulerAngles
    | GyroBiasCaptured
    | Temperature
    | EepromValue
    | ContinuousModeSet
    | FirmwareVersion
    | SerialNumber
)


# --- commands (host -> device) --------------------------------------------------------


@dataclass(frozen=True, slots=True)
class PollCommand:
    """A single-byte command: asks for one reply of the same type."""

    command: int


@dataclass(frozen=True, slots=True)
class SetContinuousCommand:
    """0x10 0x00 <command>: repeat ``command``'s reply continuously; 0x00 stops."""

    command: int


@dataclass(frozen=True, slots=True)
class ReadEepromCommand:
    """0x28: read the EEPROM word at ``address``."""

    address: int


@dataclass(frozen=True, slots=True)
class WriteEepromCommand:
    """0x29: write the unsigned 16-bit ``value`` to the EEPROM word at ``address``."""

    address: int
    value: int


ImuCommand: TypeAlias = PollCommand | SetContinuousCommand | ReadEepromCommand | WriteEepromCommand


# --- host side: command encoders -------------------------------------------------------


def encode_poll(command: int) -> bytes:
    """One single-byte command, e.g. ``encode_poll(CMD_GYRO_STAB_EULER_ACCEL_RATE)``.

    Raises:
        ValueError: ``command`` is not one of :data:`POLL_COMMANDS`.
    """
    if command not in POLL_COMMANDS:
        raise ValueError(f"0x{command:02X} is not a single-byte 3DM-GX1 command this codec knows")
    return bytes([command])


def encode_set_continuous(command: int) -> bytes:
    """Start continuous mode repeating ``command``'s reply: ``10 00 <command>``.

    Raises:
        ValueError: ``command`` is not one of :data:`CONTINUOUS_COMMANDS`.
    """
    if command not in CONTINUOUS_COMMANDS:
        raise ValueError(f"0x{command:02X} cannot be put into continuous mode by this codec")
    return bytes([CMD_SET_CONTINUOUS, _CONTINUOUS_CONFIRM, command])


def encode_stop_continuous() -> bytes:
    """Stop continuous mode: ``10 00 00``."""
    return bytes([CMD_SET_CONTINUOUS, _CONTINUOUS_CONFIRM, 0x00])


def _check_word(name: str, value: int, low: int, high: int) -> None:
    if not low <= value <= high:
        raise ValueError(f"{name} must be in {low}..{high}, got {value}")


def encode_read_eeprom(address: int) -> bytes:
    """Read an EEPROM word: ``28 <address MSB> <address LSB>``.

    Raises:
        ValueError: ``address`` is not in 0..65535.
    """
    _check_word("EEPROM address", address, 0, 0xFFFF)
    return bytes([CMD_READ_EEPROM]) + address.to_bytes(2, "big")


def encode_write_eeprom(address: int, value: int) -> bytes:
    """Write an EEPROM word: ``29 71 <address> <value> AA``; ``value`` may be signed.

    Raises:
        ValueError: ``address`` is not in 0..65535 or ``value`` not in -32768..65535.
    """
    _check_word("EEPROM address", address, 0, 0xFFFF)
    _check_word("EEPROM value", value, _INT16_MIN, 0xFFFF)
    return (
        bytes([CMD_WRITE_EEPROM, _WRITE_EEPROM_KEY])
        + address.to_bytes(2, "big")
        + (value & 0xFFFF).to_bytes(2, "big")
        + bytes([_WRITE_EEPROM_END])
    )


def encode_command(command: ImuCommand) -> bytes:
    """Encode any command message (the inverse of :class:`ImuDeviceDecoder`).

    A ``SetContinuousCommand(0)`` encodes the stop command.

    Raises:
        ValueError: as the specific encoder does.
    """
    if isinstance(command, PollCommand):
        return encode_poll(command.command)
    if isinstance(command, SetContinuousCommand):
        if command.command == 0x00:
            return encode_stop_continuous()
        return encode_set_continuous(command.command)
    if isinstance(command, ReadEepromCommand):
        return encode_read_eeprom(command.address)
    return encode_write_eeprom(command.address, command.value)


# --- host side: reply decoder ---------------------------------------------------------


class ImuDecoder(StreamDecoder[ImuReply]):
    """Decodes the 3DM-GX1's replies from a byte stream; never raises.

    A frame is accepted only if its first byte is an accepted reply byte and its
    checksum matches; otherwise one byte is skipped and the search goes on, so a valid
    frame hidden behind a false start is not lost. ``accept`` narrows the reply bytes
    looked for (e.g. ``{0x31, 0x10}`` in continuous 0x31 mode), which makes false
    starts rarer. ``gains`` scales acceleration and rate; set it after reading the
    unit's EEPROM.

    Raises (constructor only):
        ValueError: ``accept`` holds a byte that is not one of :data:`REPLY_LENGTHS`.
    """

    def __init__(
        self,
        gains: GainScales | None = None,
        *,
        accept: Iterable[int] | None = None,
        max_buffer: int = 1 << 16,
    ) -> None:
        super().__init__(max_buffer=max_buffer)
        self.gains = gains if gains is not None else GainScales()
        wanted = set(REPLY_LENGTHS) if accept is None else set(accept)
        unknown = wanted - set(REPLY_LENGTHS)
        if unknown:
            raise ValueError(f"unknown 3DM-GX1 reply bytes: {sorted(unknown)}")
        self._lengths = {c: n for c, n in REPLY_LENGTHS.items() if c in wanted}

    def scan(self, buffer: bytearray) -> Scan[ImuReply]:
        length = self._lengths.get(buffer[0])
        if length is None:
            return Scan.skip(_next_candidate(buffer, self._lengths), Fault.GARBAGE)
        if len(buffer) < length:
            return Scan.need_more()
        frame = bytes(buffer[:length])
        if checksum(frame[:-2]) != _uint16(frame, length - 2):
            return Scan.skip(1, Fault.CHECKSUM)
        return Scan.frame(length, self._decode(frame))

    def _decode(self, frame: bytes) -> ImuReply:
        header = frame[0]
        if header == CMD_GYRO_STAB_EULER_ACCEL_RATE:
            counts = struct.unpack_from(">9h", frame, 1)
            g = self.gains.g_per_count * STANDARD_GRAVITY
            w = self.gains.rad_per_second_per_count
            return EulerAccelRate(
                roll=counts[0] * _RADIANS_PER_COUNT,
                pitch=counts[1] * _RADIANS_PER_COUNT,
                yaw=counts[2] * _RADIANS_PER_COUNT,
                accel_x=counts[3] * g,
                accel_y=counts[4] * g,
                accel_z=counts[5] * g,
                rate_x=counts[6] * w,
                rate_y=counts[7] * w,
                rate_z=counts[8] * w,
                timer_ticks=_uint16(frame, 19),
                counts=counts,
            )
        if header in (CMD_GYRO_STAB_EULER, CMD_INSTANT_EULER):
            angles = (_int16(frame, 1), _int16(frame, 3), _int16(frame, 5))
            return EulerAngles(
                roll=angles[0] * _RADIANS_PER_COUNT,
                pitch=angles[1] * _RADIANS_PER_COUNT,
                yaw=angles[2] * _RADIANS_PER_COUNT,
                timer_ticks=_uint16(frame, 7),
                stabilised=header == CMD_GYRO_STAB_EULER,
                counts=angles,
            )
        if header == CMD_CAPTURE_GYRO_BIAS:
            return GyroBiasCaptured(timer_ticks=_uint16(frame, 1))
        if header == CMD_TEMPERATURE:
            count = _uint16(frame, 1)
            return Temperature(
                celsius=_temperature_celsius(count), timer_ticks=_uint16(frame, 3), count=count
            )
        if header in (CMD_READ_EEPROM, CMD_WRITE_EEPROM):
            return EepromValue(
                value=_uint16(frame, 1),
                timer_ticks=_uint16(frame, 3),
                written=header == CMD_WRITE_EEPROM,
            )
        if header == CMD_SET_CONTINUOUS:
            # byte 1 is the 0x00 the host sent; byte 2 echoes the repeated command
            return ContinuousModeSet(command=frame[2], timer_ticks=_uint16(frame, 3))
        if header == CMD_FIRMWARE_VERSION:
            return FirmwareVersion(number=_uint16(frame, 1))
        return SerialNumber(number=_uint16(frame, 1))


def _next_candidate(buffer: bytearray, starts: Mapping[int, int]) -> int:
    """Index of the first byte after the front one that may start a frame, else len."""
    for index in range(1, len(buffer)):
        if buffer[index] in starts:
            return index
    return len(buffer)


def _temperature_celsius(count: int) -> float:
    return (count * 5.0 / 65536.0 - 0.5) * 100.0


# --- device side: command decoder -----------------------------------------------------


class ImuDeviceDecoder(StreamDecoder[ImuCommand]):
    """Decodes the host's commands, as the device (or a fake of it) sees them.

    Commands carry no checksum; the fixed bytes of the multi-byte commands (0x00 after
    0x10; 0x71 and 0xAA around a 0x29 write) are checked, and a mismatch skips one byte
    as malformed. Bytes that are not a known command are skipped as garbage.
    """

    def scan(self, buffer: bytearray) -> Scan[ImuCommand]:
        command = buffer[0]
        length = COMMAND_LENGTHS.get(command)
        if length is None:
            return Scan.skip(_next_candidate(buffer, COMMAND_LENGTHS), Fault.GARBAGE)
        if length == 1:
            return Scan.frame(1, PollCommand(command))
        if len(buffer) >= 2 and command == CMD_SET_CONTINUOUS and buffer[1] != _CONTINUOUS_CONFIRM:
            return Scan.skip(1, Fault.MALFORMED)
        if len(buffer) >= 2 and command == CMD_WRITE_EEPROM and buffer[1] != _WRITE_EEPROM_KEY:
            return Scan.skip(1, Fault.MALFORMED)
        if len(buffer) < length:
            return Scan.need_more()
        frame = bytes(buffer[:length])
        if command == CMD_SET_CONTINUOUS:
            return Scan.frame(length, SetContinuousCommand(frame[2]))
        if command == CMD_READ_EEPROM:
            return Scan.frame(length, ReadEepromCommand(_uint16(frame, 1)))
        if frame[6] != _WRITE_EEPROM_END:
            return Scan.skip(1, Fault.MALFORMED)
        return Scan.frame(length, WriteEepromCommand(_uint16(frame, 2), _uint16(frame, 4)))


# --- device side: reply encoders ------------------------------------------------------


def _finite(name: str, value: float) -> float:
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    return value


def _angle_counts(name: str, radians: float) -> int:
    """Nearest count, wrapped into int16: angles are modular, so +pi becomes -pi."""
    counts = round(_finite(name, radians) / _RADIANS_PER_COUNT)
    return ((counts + 32768) % 65536) - 32768


def _clamped_counts(name: str, value: float, per_count: float) -> int:
    """Nearest count, clamped to int16 as a saturated sensor would report it."""
    counts = round(_finite(name, value) / per_count)
    return max(_INT16_MIN, min(_INT16_MAX, counts))


def encode_euler_accel_rate_reply(
    roll: float,
    pitch: float,
    yaw: float,
    accel: tuple[float, float, float],
    rate: tuple[float, float, float],
    timer_ticks: int,
    gains: GainScales | None = None,
) -> bytes:
    """Reply 0x31 from angles [rad], acceleration [m/s^2] and angular rate [rad/s].

    Values are rounded to the nearest count; angles wrap, vectors saturate at the int16
    limits. ``timer_ticks`` is taken modulo 2^16, as the device counter wraps.

    Raises:
        ValueError: a value is NaN or infinite.
    """
    gains = gains if gains is not None else GainScales()
    g = gains.g_per_count * STANDARD_GRAVITY
    w = gains.rad_per_second_per_count
    vectors = (*accel, *rate)
    if len(accel) != 3 or len(rate) != 3:
        raise ValueError("accel and rate must each have three components")
    # (100 replies a simulated second: the names are only formatted for an error)
    if not all(map(math.isfinite, (roll, pitch, yaw, *vectors))):
        _angle_counts("roll", roll), _angle_counts("pitch", pitch), _angle_counts("yaw", yaw)
        for i in range(3):
            _finite(f"accel[{i}]", accel[i]), _finite(f"rate[{i}]", rate[i])
    lo, hi = _INT16_MIN, _INT16_MAX
    words = [((round(roll / _RADIANS_PER_COUNT) + 32768) % 65536) - 32768,
             ((round(pitch / _RADIANS_PER_COUNT) + 32768) % 65536) - 32768,
             ((round(yaw / _RADIANS_PER_COUNT) + 32768) % 65536) - 32768]
    words += [max(lo, min(hi, round(a / g))) for a in vectors[:3]]
    words += [max(lo, min(hi, round(r / w))) for r in vectors[3:]]
    words.append(timer_ticks)
    return _frame(CMD_GYRO_STAB_EULER_ACCEL_RATE, words)


def encode_euler_angles_reply(
    roll: float, pitch: float, yaw: float, timer_ticks: int, *, stabilised: bool = True
) -> bytes:
    """Reply 0x0E (or 0x0D when not ``stabilised``) from angles in radians.

    Raises:
        ValueError: an angle is NaN or infinite.
    """
    header = CMD_GYRO_STAB_EULER if stabilised else CMD_INSTANT_EULER
    angles = [_angle_counts("roll", roll), _angle_counts("pitch", pitch), _angle_counts("yaw", yaw)]
    return _frame(header, [*angles, timer_ticks])


def encode_gyro_bias_captured_reply(timer_ticks: int) -> bytes:
    """Reply 0x06, sent when the gyro bias capture has finished."""
    return _frame(CMD_CAPTURE_GYRO_BIAS, [timer_ticks])


def encode_temperature_reply(celsius: float, timer_ticks: int) -> bytes:
    """Reply 0x07 from a temperature in degrees Celsius (clamped to the 0..65535 count).

    Raises:
        ValueError: ``celsius`` is NaN or infinite.
    """
    count = round((_finite("celsius", celsius) / 100.0 + 0.5) * 65536.0 / 5.0)
    return _frame(CMD_TEMPERATURE, [max(0, min(0xFFFF, count)), timer_ticks])


def encode_eeprom_value_reply(value: int, timer_ticks: int, *, written: bool = False) -> bytes:
    """Reply 0x28 (or 0x29 when ``written``) carrying an EEPROM word (signed or not).

    Raises:
        ValueError: ``value`` is not in -32768..65535.
    """
    _check_word("EEPROM value", value, _INT16_MIN, 0xFFFF)
    return _frame(CMD_WRITE_EEPROM if written else CMD_READ_EEPROM, [value, timer_ticks])


def encode_continuous_mode_set_reply(command: int, timer_ticks: int) -> bytes:
    """Reply 0x10: ``10 00 <command> <ticks> <checksum>``.

    Raises:
        ValueError: ``command`` is not a byte.
    """
    _check_word("command", command, 0, 0xFF)
    return _frame(CMD_SET_CONTINUOUS, [command, timer_ticks])


def encode_firmware_version_reply(number: int) -> bytes:
    """Reply 0xF0 carrying a version number such as 3104.

    Raises:
        ValueError: ``number`` is not in 0..65535.
    """
    _check_word("firmware version", number, 0, 0xFFFF)
    return _frame(CMD_FIRMWARE_VERSION, [number])


def encode_serial_number_reply(number: int) -> bytes:
    """Reply 0xF1 carrying a serial number.

    Raises:
        ValueError: ``number`` is not in 0..65535.
    """
    _check_word("serial number", number, 0, 0xFFFF)
    return _frame(CMD_SERIAL_NUMBER, [number])


def encode_reply(reply: ImuReply, gains: GainScales | None = None) -> bytes:
    """Encode any reply message from its physical fields (what :class:`ImuDecoder` reads).

    Raises:
        ValueError: as the specific encoder does.
    """
    if isinstance(reply, EulerAccelRate):
        return encode_euler_accel_rate_reply(
            reply.roll,
            reply.pitch,
            reply.yaw,
            (reply.accel_x, reply.accel_y, reply.accel_z),
            (reply.rate_x, reply.rate_y, reply.rate_z),
            reply.timer_ticks,
            gains,
        )
    if isinstance(reply, EulerAngles):
        return encode_euler_angles_reply(
            reply.roll, reply.pitch, reply.yaw, reply.timer_ticks, stabilised=reply.stabilised
        )
    if isinstance(reply, GyroBiasCaptured):
        return encode_gyro_bias_captured_reply(reply.timer_ticks)
    if isinstance(reply, Temperature):
        return encode_temperature_reply(reply.celsius, reply.timer_ticks)
    if isinstance(reply, EepromValue):
        return encode_eeprom_value_reply(reply.value, reply.timer_ticks, written=reply.written)
    if isinstance(reply, ContinuousModeSet):
        return encode_continuous_mode_set_reply(reply.command, reply.timer_ticks)
    if isinstance(reply, FirmwareVersion):
        return encode_firmware_version_reply(reply.number)
    return encode_serial_number_reply(reply.number)
