"""Sans-I/O codec of the nodding SICK LMS 211: SICK telegrams and the controller framing.

Two byte protocols meet here (see ``docs/protocols/nodding_laser.md``):

* **SICK LMS 2xx telegrams** (SICK "LMS 200/211/221/291 Telegram Listing"):
  ``STX 0x02 | ADR | LEN (u16 LE) | CMD | data | [status] | CRC-16 (u16 LE)``. ``LEN``
  counts CMD, data and, in replies, the status byte. Replies to the host carry
  ``ADR = LMS address | 0x80`` and end with the status byte; commands from the host
  carry the LMS address (0x00) and no status byte. The CRC is SICK's own CRC-16
  (generator 0x8005, the manual's two-byte routine, :func:`sick_crc16`).
* **The nodding-controller framing** (afa's design; DRDC's RTEMS controller protocol is
  not public): every TCP frame is ``sync A5 4E | version | type | seq | reserved |
  length (u16 LE) | header CRC | payload | frame CRC`` with CRC-16/CCITT-FALSE. A scan
  frame carries the scan counter, the controller's timestamp, the nod angle at the start
  and end of the scan and the SICK 0xB0 telegram verbatim.

Host side: :class:`NodControllerDecoder` (controller -> host frames) and the
``encode_*`` functions for controller commands and SICK commands. Device side (the fake
controller): :class:`NodHostCommandDecoder` (host -> controller frames) and
:func:`encode_controller_frame` / the SICK reply encoders. :class:`SickTelegramDecoder`
reads a raw LMS serial stream (either direction), for the controller's RS-422 side.

:func:`scan_line_to_points` turns one scan line into 3-D points in the laser frame
(x forward, y left, z up; nod angle = elevation of the scan plane, negative = down).
"""

from __future__ import annotations

import array
import binascii
import functools
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum, StrEnum
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

from afa.codec import Fault, Scan, StreamDecoder
from afa.errors import EOutOfBounds
from afa.kernels import compiled

__all__ = [
    "STX", "ACK", "NAK", "LMS_ADDRESS", "REPLY_ADDRESS_BIT", "MAX_TELEGRAM_LENGTH",
    "CMD_SWITCH_MODE", "CMD_REQUEST_VALUES", "CMD_SWITCH_VARIANT",
    "REPLY_SWITCH_MODE", "REPLY_MEASURED_VALUES", "REPLY_SWITCH_VARIANT",
    "REPLY_NOT_ACKNOWLEDGED", "SCAN_VARIANTS", "NO_RETURN_CODES",
    "SickMode", "RangeUnit", "sick_crc16", "ScanLineGeometry",
    "SickTelegram", "SickAck", "SwitchOperatingMode", "RequestMeasuredValues",
    "SwitchVariant", "OperatingModeReply", "VariantReply", "MeasuredValues",
    "SickMessage", "encode_sick_telegram", "parse_sick_telegram", "telegram_to_message",
    "encode_sick_message", "encode_switch_mode", "encode_start_continuous",
    "encode_stop_continuous", "encode_request_measured_values", "encode_switch_variant",
    "encode_mode_reply", "encode_variant_reply", "encode_measured_values",
    "encode_measured_words", "encode_scan_frame",
    "SickTelegramDecoder",
    "CONTROLLER_SYNC", "CONTROLLER_VERSION", "CONTROLLER_HEADER_SIZE",
    "CONTROLLER_MAX_PAYLOAD", "FrameType", "AckResult", "ControllerState",
    "controller_crc16", "udeg",
    "NodScan", "ControllerStatus", "CommandAck", "SickReply",
    "SetNodRate", "SetNodLimits", "StartNodding", "StopNodding", "GotoAngle",
    "RequestStatus", "SickCommand", "ControllerMessage", "HostCommand",
    "encode_controller_frame", "encode_controller_message", "encode_host_command",
    "NodControllerDecoder", "NodHostCommandDecoder",
    "scan_bearings_deg", "scan_line_to_points", "nod_scan_to_points",
]

# --------------------------------------------------------------------------------------
# SICK LMS 2xx telegrams
# --------------------------------------------------------------------------------------

STX = 0x02
ACK = 0x06
NAK = 0x15
#: Default LMS address; replies to the host carry ``address | REPLY_ADDRESS_BIT``.
LMS_ADDRESS = 0x00
REPLY_ADDRESS_BIT = 0x80
#: Largest LEN (command + data + status) of an LMS 2xx telegram (sicktoolbox
#: ``SICK_LMS_2XX_MSG_PAYLOAD_MAX_LEN``); a 401-value 0xB0 reply needs 806.
MAX_TELEGRAM_LENGTH = 812

CMD_SWITCH_MODE = 0x20
CMD_REQUEST_VALUES = 0x30
CMD_SWITCH_VARIANT = 0x3B
REPLY_SWITCH_MODE = 0xA0
REPLY_MEASURED_VALUES = 0xB0
REPLY_SWITCH_VARIANT = 0xBB
REPLY_NOT_ACKNOWLEDGED = 0x92

_CRC16_SICK_POLY = 0x8005
_HEADER = 4  # STX, ADR, LEN (2)
_TRAILER = 2  # CRC

#: The scan variants (field of view in degrees, resolution in 1/100 degree) and the
#: number of values a full 0xB0 scan of each carries; the count identifies the variant.
SCAN_VARIANTS: dict[int, tuple[int, int]] = {
    181: (180, 100),
    361: (180, 50),
    101: (100, 100),
    201: (100, 50),
    401: (100, 25),
}
_VALID_VARIANTS = frozenset(SCAN_VARIANTS.values())

#: How many of the largest raw range codes are "no return" codes rather than ranges
#: (8 m mode: 8183..8191 = 0x1FF7..0x1FFF: overflow, dazzle, signal too weak, ...).
NO_RETURN_CODES = 9


class SickMode(IntEnum):
    """Operating modes of command 0x20 (telegram listing; sicktoolbox ``SICK_OP_MODE_*``)."""

    INSTALLATION = 0x00  # needs the 8-byte password, default b"SICK_LMS"
    MONITOR_STREAM_VALUES = 0x24  # continuous output of all measured values (0xB0)
    MONITOR_REQUEST_VALUES = 0x25  # measured values only on request: stops streaming
    BAUD_38400 = 0x40
    BAUD_19200 = 0x41
    BAUD_9600 = 0x42
    BAUD_500000 = 0x48


class RangeUnit(StrEnum):
    """Unit of the measured values (bits 14-15 of the 0xB0 count word)."""

    CM = "cm"
    MM = "mm"

    @property
    def metres(self) -> float:
        """Metres per count."""
        return 0.01 if self is RangeUnit.CM else 0.001


_UNIT_CODE = {RangeUnit.CM: 0b00, RangeUnit.MM: 0b01}
_UNIT_FROM_CODE = {code: unit for unit, code in _UNIT_CODE.items()}


def _sick_shift(crc: int) -> int:
    """One step of SICK's register: shift left, XOR the generator when bit 15 falls out."""
    return (((crc << 1) & 0xFFFF) ^ _CRC16_SICK_POLY) if crc & 0x8000 else (crc << 1) & 0xFFFF


def sick_crc16_reference(data: bytes | bytearray | memoryview) -> int:
    """SICK's CRC-16 of ``data``, byte by byte exactly as the LMS 2xx telegram listing
    writes it (generator 0x8005): per byte, shift the register left by one (XOR the
    generator when bit 15 falls out), then XOR the 16-bit word made of this byte (low)
    and the previous byte (high). No final XOR; transmitted little-endian."""
    crc = 0
    previous = 0
    for byte in bytes(data):
        crc = _sick_shift(crc) ^ (byte | (previous << 8))
        previous = byte
    return crc


#: Longest input :func:`sick_crc16` handles with its table (a telegram is at most 816).
_CRC_SPAN = 1024


@functools.cache
def _crc_contributions() -> npt.NDArray[np.uint16]:
    """Flattened (_CRC_SPAN, 256) table: what byte ``v`` adds to the CRC when ``k`` bytes
    follow it, at ``[k * 256 + v]``.

    The register update is linear over GF(2) (shift ``L``, then XOR the word of this byte
    and the previous one), so the CRC of ``n`` bytes is the XOR over the bytes of
    ``L^k(v) ^ L^(k-1)(v << 8)`` (the byte as the low half of its own word, then as the
    high half of the next one's).
    """
    def shift(x: npt.NDArray[np.uint32]) -> npt.NDArray[np.uint32]:
        shifted = ((x << 1) & 0xFFFF) ^ np.where(x & 0x8000, _CRC16_SICK_POLY, 0)
        return shifted.astype(np.uint32)

    low: npt.NDArray[np.uint32] = np.arange(256, dtype=np.uint32)  # L^k(v)
    high: npt.NDArray[np.uint32] = (low << 8).astype(np.uint32)  # L^k(v << 8)
    table = np.empty((_CRC_SPAN, 256), dtype=np.uint16)
    table[0] = low
    for k in range(1, _CRC_SPAN):
        low = shift(low)
        table[k] = low ^ high
        high = shift(high)
    table.flags.writeable = False
    return table.ravel()


_CRC_OFFSETS = np.arange(_CRC_SPAN - 1, -1, -1, dtype=np.intp) * 256


@functools.cache
def _crc_kernel() -> Callable[[npt.NDArray[np.uint8]], int] | None:
    """The compiled CRC loop (decision 0021), or None for the numpy form
    (:func:`afa.kernels.compiled`). Loaded on the first CRC, so importing the codec
    stays light."""
    return compiled("components.nodding_laser._crc_jit",  # type: ignore[no-any-return]
                    "crc_kernel")


def sick_crc16(data: bytes | bytearray | memoryview) -> int:
    """SICK's CRC-16 of ``data`` (:func:`sick_crc16_reference`): the compiled loop, or
    one table lookup per byte XORed together in numpy (a scan telegram is checked twice,
    by the emulator and by the driver, 75 times a simulated second)."""
    raw = np.frombuffer(data, dtype=np.uint8)
    kernel = _crc_kernel()
    if kernel is not None:
        raw.flags.writeable = False  # the kernel's one signature takes read-only bytes
        return int(kernel(raw))
    if raw.size > _CRC_SPAN:
        return sick_crc16_reference(data)
    if raw.size == 0:
        return 0
    return int(np.bitwise_xor.reduce(_crc_contributions().take(_CRC_OFFSETS[-raw.size:] + raw)))


@dataclass(frozen=True, slots=True)
class SickTelegram:
    """Any SICK telegram, undecoded beyond its framing.

    ``status`` is the trailing status byte of replies (``address & 0x80``), else None.
    """

    command: int
    data: bytes = b""
    address: int = LMS_ADDRESS
    status: int | None = None

    @property
    def is_reply(self) -> bool:
        return bool(self.address & REPLY_ADDRESS_BIT)


@dataclass(frozen=True, slots=True)
class SickAck:
    """The single ACK (0x06) or NAK (0x15) byte the LMS sends before its reply."""

    acknowledged: bool


@dataclass(frozen=True, slots=True)
class SwitchOperatingMode:
    """Host command 0x20: change operating mode (stream, request, baud rate, install)."""

    mode: int
    password: bytes = b""  # only for SickMode.INSTALLATION (8 bytes, e.g. b"SICK_LMS")
    address: int = LMS_ADDRESS


@dataclass(frozen=True, slots=True)
class RequestMeasuredValues:
    """Host command 0x30: send one scan (``variant`` 0x01 = all measured values)."""

    variant: int = 0x01
    address: int = LMS_ADDRESS


@dataclass(frozen=True, slots=True)
class SwitchVariant:
    """Host command 0x3B: field of view (100 or 180 deg) and resolution (1/100 deg)."""

    scan_angle_deg: int
    resolution_cdeg: int
    address: int = LMS_ADDRESS


@dataclass(frozen=True, slots=True)
class OperatingModeReply:
    """LMS reply 0xA0 to 0x20. ``result`` 0 = mode changed, 1 = wrong password,
    2 = LMS fault (telegram listing)."""

    result: int
    status: int
    address: int = LMS_ADDRESS | REPLY_ADDRESS_BIT

    @property
    def ok(self) -> bool:
        return self.result == 0


@dataclass(frozen=True, slots=True)
class VariantReply:
    """LMS reply 0xBB to 0x3B: ``accepted`` and the variant now in force."""

    accepted: bool
    scan_angle_deg: int
    resolution_cdeg: int
    status: int
    address: int = LMS_ADDRESS | REPLY_ADDRESS_BIT


@dataclass(frozen=True, slots=True)
class MeasuredValues:
    """LMS reply 0xB0: one scan line.

    ``raw`` keeps each 16-bit value word as sent; the low ``range_bits`` bits are the
    range in ``unit``, the bits above are flags (8 m mode: bit 13 field A, bit 14
    field B, bit 15 dazzle). ``range_bits`` is 13 in the 8 m / 80 m measuring modes (the
    Raptor's: ``MaxLaserRange`` 8191 mm), 14, 15 or 16 in the 16 m, 32 m and immediate
    modes; the telegram does not say which, so the receiver is told.
    ``scan_angle_deg`` and ``resolution_cdeg`` are inferred from the count
    (:data:`SCAN_VARIANTS`), None when the count is not a full scan of a variant.
    """

    raw: tuple[int, ...]
    unit: RangeUnit = RangeUnit.MM
    status: int = 0x10
    partial_scan_index: int = 0
    range_bits: int = 13
    address: int = LMS_ADDRESS | REPLY_ADDRESS_BIT

    @property
    def count(self) -> int:
        return len(self.raw)

    @property
    def range_counts(self) -> tuple[int, ...]:
        """The range field of every value, in ``unit``."""
        mask = (1 << self.range_bits) - 1
        return tuple(word & mask for word in self.raw)

    @property
    def flags(self) -> tuple[int, ...]:
        """The bits above the range field of every value, shifted down to bit 0."""
        return tuple(word >> self.range_bits for word in self.raw)

    @property
    def ranges(self) -> tuple[float, ...]:
        """Ranges in metres (no-return codes included; see :meth:`valid_mask`)."""
        scale = self.unit.metres
        return tuple(count * scale for count in self.range_counts)

    def ranges_array(self) -> npt.NDArray[np.float32]:
        """Ranges in metres as a float32 array (no-return codes included)."""
        return self.ranges_and_valid()[0]

    @property
    def no_return_threshold(self) -> int:
        """Smallest raw range code that means "no return" (8183 in the 8 m modes)."""
        return (1 << self.range_bits) - NO_RETURN_CODES

    def valid_mask(self) -> npt.NDArray[np.bool_]:
        """True for values that are ranges: not zero and not a no-return code."""
        return self.ranges_and_valid()[1]

    def ranges_and_valid(self) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
        """:meth:`ranges_array` and :meth:`valid_mask` from one conversion of ``raw``."""
        # through array.array: a third of the cost of np.array on a tuple of ints (the
        # same OverflowError for a word that is negative or beyond 32 bits)
        counts = np.frombuffer(array.array("I", self.raw), dtype=np.uint32)
        counts &= (1 << self.range_bits) - 1
        valid = (counts > 0) & (counts < self.no_return_threshold)
        return (counts * self.unit.metres).astype(np.float32), valid

    @property
    def scan_angle_deg(self) -> int | None:
        variant = SCAN_VARIANTS.get(self.count)
        return variant[0] if variant else None

    @property
    def resolution_cdeg(self) -> int | None:
        variant = SCAN_VARIANTS.get(self.count)
        return variant[1] if variant else None

    @property
    def start_angle_deg(self) -> float | None:
        """SICK bearing of the first value: 0 deg (180 variant) or 40 deg (100 variant)."""
        angle = self.scan_angle_deg
        return None if angle is None else (180 - angle) / 2

    @property
    def error_class(self) -> int:
        """Status bits 0-2: 0 no error, 1 info, 2 warning, 3 error, 4 fatal."""
        return self.status & 0x07


SickMessage: TypeAlias = (
    SickTelegram | SickAck | SwitchOperatingMode | RequestMeasuredValues | SwitchVariant
    | OperatingModeReply | VariantReply | MeasuredValues
)


def encode_sick_telegram(command: int, data: bytes = b"", *, address: int = LMS_ADDRESS,
                         status: int | None = None) -> bytes:
    """Frame one telegram: STX, address, LEN, command, data, [status], CRC.

    Raises :class:`~afa.errors.EOutOfBounds` if a byte is out of range, the telegram is
    longer than :data:`MAX_TELEGRAM_LENGTH`, or ``status`` disagrees with the address
    (replies, ``address & 0x80``, must carry one; commands must not).
    """
    for name, value in (("command", command), ("address", address)):
        if not 0 <= value <= 0xFF:
            raise EOutOfBounds(f"SICK {name} {value:#x} is not a byte")
    if bool(address & REPLY_ADDRESS_BIT) != (status is not None):
        raise EOutOfBounds("a SICK reply (address bit 7 set) carries a status byte, "
                           "a command does not")
    body = bytes([command]) + bytes(data)
    if status is not None:
        if not 0 <= status <= 0xFF:
            raise EOutOfBounds(f"SICK status {status:#x} is not a byte")
        body += bytes([status])
    if len(body) > MAX_TELEGRAM_LENGTH:
        raise EOutOfBounds(f"SICK telegram of {len(body)} bytes exceeds "
                           f"{MAX_TELEGRAM_LENGTH}")
    frame = bytes([STX, address]) + struct.pack("<H", len(body)) + body
    return frame + struct.pack("<H", sick_crc16(frame))


def _split_telegram(frame: bytes | bytearray | memoryview) -> SickTelegram:
    """Check framing and CRC of exactly one telegram; raises EOutOfBounds."""
    frame = bytes(frame)
    if len(frame) < _HEADER + 1 + _TRAILER or frame[0] != STX:
        raise EOutOfBounds("not a SICK telegram (too short or no STX)")
    (length,) = struct.unpack_from("<H", frame, 2)
    if length == 0 or length > MAX_TELEGRAM_LENGTH:
        raise EOutOfBounds(f"SICK telegram length {length} out of range")
    if len(frame) != _HEADER + length + _TRAILER:
        raise EOutOfBounds(f"SICK telegram is {len(frame)} bytes, LEN says "
                           f"{_HEADER + length + _TRAILER}")
    (crc,) = struct.unpack_from("<H", frame, _HEADER + length)
    if crc != sick_crc16(frame[: _HEADER + length]):
        raise EOutOfBounds("SICK telegram CRC mismatch")
    address = frame[1]
    body = frame[_HEADER:_HEADER + length]
    if address & REPLY_ADDRESS_BIT:
        if len(body) < 2:
            raise EOutOfBounds("SICK reply without status byte")
        return SickTelegram(body[0], body[1:-1], address, body[-1])
    return SickTelegram(body[0], body[1:], address, None)


def parse_sick_telegram(frame: bytes | bytearray | memoryview) -> SickMessage:
    """Decode exactly one telegram (no leading ACK byte) into its typed message.

    Unknown commands come back as :class:`SickTelegram`. ``range_bits`` of measured
    values is assumed 13 (use :func:`telegram_to_message` for other modes).
    Raises :class:`~afa.errors.EOutOfBounds` on bad framing, CRC or content.
    """
    return telegram_to_message(_split_telegram(frame))


def telegram_to_message(telegram: SickTelegram, *, range_bits: int = 13) -> SickMessage:
    """Interpret a framed telegram by direction and command.

    Raises :class:`~afa.errors.EOutOfBounds` when a known command's data is malformed.
    """
    command, data, address = telegram.command, telegram.data, telegram.address
    if telegram.is_reply:
        status = telegram.status if telegram.status is not None else 0
        if command == REPLY_MEASURED_VALUES:
            return _parse_measured_values(data, status, address, range_bits)
        if command == REPLY_SWITCH_MODE:
            if len(data) != 1:
                raise EOutOfBounds("0xA0 reply carries one result byte")
            return OperatingModeReply(data[0], status, address)
        if command == REPLY_SWITCH_VARIANT:
            if len(data) != 5:
                raise EOutOfBounds("0xBB reply carries 5 data bytes")
            accepted, angle, resolution = struct.unpack("<BHH", data)
            return VariantReply(accepted == 0x01, angle, resolution, status, address)
        return telegram
    if command == CMD_SWITCH_MODE and len(data) >= 1:
        return SwitchOperatingMode(data[0], bytes(data[1:]), address)
    if command == CMD_REQUEST_VALUES and len(data) == 1:
        return RequestMeasuredValues(data[0], address)
    if command == CMD_SWITCH_VARIANT:
        if len(data) != 4:
            raise EOutOfBounds("0x3B command carries 4 data bytes")
        angle, resolution = struct.unpack("<HH", data)
        return SwitchVariant(angle, resolution, address)
    return telegram


def _parse_measured_values(data: bytes, status: int, address: int,
                           range_bits: int) -> MeasuredValues:
    if len(data) < 2:
        raise EOutOfBounds("0xB0 reply without count word")
    (word,) = struct.unpack_from("<H", data, 0)
    count = word & 0x03FF
    unit = _UNIT_FROM_CODE.get(word >> 14)
    if unit is None:
        raise EOutOfBounds(f"0xB0 unit code {word >> 14:#b} is not cm or mm")
    # Extra bytes after the values (real-time scan index in some modes) are ignored.
    if len(data) < 2 + 2 * count:
        raise EOutOfBounds(f"0xB0 reply announces {count} values but carries "
                           f"{(len(data) - 2) // 2}")
    raw = struct.unpack_from(f"<{count}H", data, 2)
    return MeasuredValues(raw, unit, status, (word >> 11) & 0x03, range_bits, address)


def encode_sick_message(message: SickMessage) -> bytes:
    """Encode any typed SICK message (either direction) as a telegram.

    :class:`SickAck` encodes as its single byte. Raises
    :class:`~afa.errors.EOutOfBounds` on out-of-range fields.
    """
    if isinstance(message, SickAck):
        return bytes([ACK if message.acknowledged else NAK])
    if isinstance(message, SickTelegram):
        return encode_sick_telegram(message.command, message.data,
                                    address=message.address, status=message.status)
    if isinstance(message, SwitchOperatingMode):
        return encode_switch_mode(message.mode, message.password, address=message.address)
    if isinstance(message, RequestMeasuredValues):
        return encode_sick_telegram(CMD_REQUEST_VALUES, bytes([message.variant]),
                                    address=message.address)
    if isinstance(message, SwitchVariant):
        return encode_switch_variant(message.scan_angle_deg, message.resolution_cdeg,
                                     address=message.address)
    if isinstance(message, OperatingModeReply):
        return encode_mode_reply(message.result, message.status, address=message.address)
    if isinstance(message, VariantReply):
        return encode_variant_reply(message.accepted, message.scan_angle_deg,
                                    message.resolution_cdeg, message.status,
                                    address=message.address)
    return encode_measured_values(message)


# Host -> LMS --------------------------------------------------------------------------

def encode_switch_mode(mode: int, password: bytes = b"", *,
                       address: int = LMS_ADDRESS) -> bytes:
    """Command 0x20 with ``mode`` (:class:`SickMode`) and, for installation, the password.

    Raises :class:`~afa.errors.EOutOfBounds` if ``mode`` is not a byte.
    """
    if not 0 <= int(mode) <= 0xFF:
        raise EOutOfBounds(f"operating mode {mode!r} is not a byte")
    return encode_sick_telegram(CMD_SWITCH_MODE, bytes([int(mode)]) + bytes(password),
                                address=address)


def encode_start_continuous(*, address: int = LMS_ADDRESS) -> bytes:
    """0x20 0x24: stream every scan as a 0xB0 telegram (``02 00 02 00 20 24 34 08``)."""
    return encode_switch_mode(SickMode.MONITOR_STREAM_VALUES, address=address)


def encode_stop_continuous(*, address: int = LMS_ADDRESS) -> bytes:
    """0x20 0x25: back to values-on-request, which stops the stream."""
    return encode_switch_mode(SickMode.MONITOR_REQUEST_VALUES, address=address)


def encode_request_measured_values(*, address: int = LMS_ADDRESS) -> bytes:
    """0x30 0x01: send one scan of all measured values."""
    return encode_sick_telegram(CMD_REQUEST_VALUES, b"\x01", address=address)


def _check_variant(scan_angle_deg: int, resolution_cdeg: int) -> None:
    if (scan_angle_deg, resolution_cdeg) not in _VALID_VARIANTS:
        raise EOutOfBounds(
            f"the LMS 2xx has no variant {scan_angle_deg} deg / {resolution_cdeg / 100} "
            "deg (180 deg with 1 or 0.5 deg; 100 deg with 1, 0.5 or 0.25 deg)")


def encode_switch_variant(scan_angle_deg: int, resolution_cdeg: int, *,
                          address: int = LMS_ADDRESS) -> bytes:
    """Command 0x3B: scan angle (100/180 deg) and resolution (25/50/100 x 0.01 deg).

    Raises :class:`~afa.errors.EOutOfBounds` for a combination the LMS does not offer.
    """
    _check_variant(scan_angle_deg, resolution_cdeg)
    return encode_sick_telegram(CMD_SWITCH_VARIANT,
                                struct.pack("<HH", scan_angle_deg, resolution_cdeg),
                                address=address)


# LMS -> host (the fake's side) ------------------------------------------------------------

def encode_mode_reply(result: int = 0, status: int = 0x10, *,
                      address: int = LMS_ADDRESS | REPLY_ADDRESS_BIT) -> bytes:
    """Reply 0xA0 to a 0x20 command (without the leading ACK byte)."""
    return encode_sick_telegram(REPLY_SWITCH_MODE, bytes([result]), address=address,
                                status=status)


def encode_variant_reply(accepted: bool, scan_angle_deg: int, resolution_cdeg: int,
                         status: int = 0x10, *,
                         address: int = LMS_ADDRESS | REPLY_ADDRESS_BIT) -> bytes:
    """Reply 0xBB to a 0x3B command (without the leading ACK byte).

    Raises :class:`~afa.errors.EOutOfBounds` if the angle or resolution is not a u16.
    """
    if not (0 <= scan_angle_deg <= 0xFFFF and 0 <= resolution_cdeg <= 0xFFFF):
        raise EOutOfBounds("variant fields are 16-bit")
    data = struct.pack("<BHH", 0x01 if accepted else 0x00, scan_angle_deg,
                       resolution_cdeg)
    return encode_sick_telegram(REPLY_SWITCH_VARIANT, data, address=address,
                                status=status)


def encode_measured_words(words: npt.NDArray[np.integer], *, unit: RangeUnit = RangeUnit.MM,
                          status: int = 0x10, partial_scan_index: int = 0,
                          address: int = LMS_ADDRESS | REPLY_ADDRESS_BIT) -> bytes:
    """:func:`encode_measured_values` of ``MeasuredValues(tuple(words), unit, status,
    partial_scan_index, address=address)``, the same bytes, from an integer array of
    value words without making a tuple of them (the emulator's path, 75 scan lines a
    simulated second).

    Raises :class:`~afa.errors.EOutOfBounds` as :func:`encode_measured_values` does.
    """
    words = np.asarray(words).reshape(-1)
    if words.size > 0x03FF:
        raise EOutOfBounds(f"{words.size} values do not fit the 10-bit count")
    if not 0 <= partial_scan_index <= 3:
        raise EOutOfBounds("partial scan index is 0..3")
    if words.dtype != np.uint16 and (words.dtype.kind not in "iu" or (
            words.size and not (words.min() >= 0 and words.max() <= 0xFFFF))):
        raise EOutOfBounds("measured value words are 16-bit")  # (uint16 ones are)
    word = words.size | (partial_scan_index << 11) | (_UNIT_CODE[unit] << 14)
    data = _U16.pack(word) + words.astype("<u2").tobytes()
    return encode_sick_telegram(REPLY_MEASURED_VALUES, data, address=address, status=status)


_U16 = struct.Struct("<H")


def encode_measured_values(values: MeasuredValues) -> bytes:
    """Reply 0xB0: count word (count, partial scan index, unit), value words, status.

    Raises :class:`~afa.errors.EOutOfBounds` for more than 1023 values or a word that
    does not fit 16 bits.
    """
    if len(values.raw) > 0x03FF:
        raise EOutOfBounds(f"{len(values.raw)} values do not fit the 10-bit count")
    if not 0 <= values.partial_scan_index <= 3:
        raise EOutOfBounds("partial scan index is 0..3")
    word = (len(values.raw) | (values.partial_scan_index << 11)
            | (_UNIT_CODE[values.unit] << 14))
    try:
        data = struct.pack(f"<{len(values.raw) + 1}H", word, *values.raw)
    except struct.error:
        raise EOutOfBounds("measured value words are 16-bit") from None
    return encode_sick_telegram(REPLY_MEASURED_VALUES, data, address=values.address,
                                status=values.status)


class SickTelegramDecoder(StreamDecoder[SickMessage]):
    """Decodes a raw LMS 2xx serial stream: ACK/NAK bytes and telegrams, either direction.

    SICK framing has no header check: a false STX with a plausible LEN makes the decoder
    wait for that many bytes before the CRC rejects it, so in a live stream a corrupted
    byte costs latency (up to one telegram), never a frame.

    ACK (0x06) and NAK (0x15) are single bytes the LMS sends between telegrams, in answer
    to a command. A byte 0x06 or 0x15 is decoded as :class:`SickAck` only where one can
    stand: at a telegram boundary while the decoder is in sync, that is at the start of
    the stream (or after :meth:`reset`), right after a telegram whose CRC checked, or
    right after another ACK/NAK. Once any byte has been skipped (garbage, a CRC failure,
    a bad LEN) the decoder is resynchronising: 0x06 and 0x15 are data, and only STX can
    start a frame, until a telegram passes its CRC. So noise yields no ACK/NAK (only a
    run of them at the very start of a stream could be taken for answers), while an ACK
    lost in damaged data costs nothing the reply telegram behind it does not carry.
    """

    def __init__(self, *, range_bits: int = 13, max_buffer: int = 1 << 16) -> None:
        super().__init__(max_buffer=max_buffer)
        self.range_bits = range_bits
        self._in_sync = True

    def reset(self) -> None:
        super().reset()
        self._in_sync = True

    def _skip(self, buffer: bytearray, fault: Fault) -> Scan[SickMessage]:
        """Drop the front up to the next STX and resynchronise."""
        self._in_sync = False
        position = buffer.find(STX, 1)
        return Scan.skip(position if position > 0 else len(buffer), fault)

    def scan(self, buffer: bytearray) -> Scan[SickMessage]:
        first = buffer[0]
        if (first == ACK or first == NAK) and self._in_sync:
            return Scan.frame(1, SickAck(first == ACK))
        if first != STX:
            return self._skip(buffer, Fault.GARBAGE)
        if len(buffer) < _HEADER:
            return Scan.need_more()
        (length,) = struct.unpack_from("<H", buffer, 2)
        if length == 0 or length > MAX_TELEGRAM_LENGTH:
            return self._skip(buffer, Fault.MALFORMED)
        total = _HEADER + length + _TRAILER
        if len(buffer) < total:
            return Scan.need_more()
        frame = bytes(buffer[:total])
        (crc,) = struct.unpack_from("<H", frame, _HEADER + length)
        if crc != sick_crc16(frame[: _HEADER + length]):
            return self._skip(buffer, Fault.CHECKSUM)
        self._in_sync = True  # the CRC checked: this is a telegram boundary
        try:
            telegram = _split_telegram(frame)
            return Scan.frame(total, telegram_to_message(telegram,
                                                         range_bits=self.range_bits))
        except (EOutOfBounds, struct.error):
            return Scan.skip(total, Fault.MALFORMED)


# --------------------------------------------------------------------------------------
# The nodding-controller framing (afa design, see docs/protocols/nodding_laser.md)
# --------------------------------------------------------------------------------------

CONTROLLER_SYNC = b"\xa5\x4e"
CONTROLLER_VERSION = 0x01
#: sync (2), version, type, seq, reserved, length (u16), header CRC (u16)
CONTROLLER_HEADER_SIZE = 10
CONTROLLER_MAX_PAYLOAD = 1024
_HEADER_FORMAT = "<2sBBBBH"  # without the header CRC
_SCAN_PREFIX = struct.Struct("<IQii")  # counter, timestamp us, nod start, nod end (udeg)
_STATUS = struct.Struct("<BBiiiIQ")
_ACK = struct.Struct("<BBB")


class FrameType(IntEnum):
    """Controller frame types: 0x01-0x7F controller -> host, 0x81-0xFF host -> controller."""

    SCAN = 0x01
    STATUS = 0x02
    ACK = 0x03
    SICK_REPLY = 0x04
    SET_NOD_RATE = 0x81
    SET_NOD_LIMITS = 0x82
    START_NODDING = 0x83
    STOP_NODDING = 0x84
    GOTO_ANGLE = 0x85
    REQUEST_STATUS = 0x86
    SICK_COMMAND = 0x87


class AckResult(IntEnum):
    """Result code of an ACK frame."""

    OK = 0
    BAD_ARGUMENT = 1
    BUSY = 2  # not allowed in the current state (e.g. limits while nodding)
    UNKNOWN_COMMAND = 3
    LASER_TIMEOUT = 4  # a forwarded SICK command got no reply from the LMS


class ControllerState(IntEnum):
    """``state`` of a STATUS frame."""

    IDLE = 0  # holding an angle
    NODDING = 1
    MOVING = 2  # moving to a GOTO angle
    FAULT = 3


def controller_crc16(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR).

    Check value: ``controller_crc16(b"123456789") == 0x29B1``.
    """
    return binascii.crc_hqx(bytes(data), 0xFFFF)


def udeg(degrees: float) -> int:
    """Degrees to the wire's micro-degrees (rounded to nearest)."""
    return int(round(degrees * 1_000_000))


@dataclass(frozen=True, slots=True)
class NodScan:
    """One scan line from the controller: the SICK 0xB0 reply plus the nod angles.

    Nod angles are elevations of the scan plane in micro-degrees (negative = down),
    sampled by the controller when the LMS started and finished the scan;
    ``timestamp_us`` is the controller's clock (microseconds since it booted) at the
    start of the scan.
    """

    scan_counter: int
    timestamp_us: int
    nod_start_udeg: int
    nod_end_udeg: int
    measured: MeasuredValues
    seq: int = 0

    @property
    def nod_start_deg(self) -> float:
        return self.nod_start_udeg / 1e6

    @property
    def nod_end_deg(self) -> float:
        return self.nod_end_udeg / 1e6


@dataclass(frozen=True, slots=True)
class ControllerStatus:
    """STATUS frame: sent on request and whenever the state or a fault changes."""

    state: int
    faults: int  # bit 0 motor, bit 1 LMS link, bit 2 limit switch, bit 3 encoder
    angle_udeg: int
    low_udeg: int
    high_udeg: int
    rate_udeg_per_s: int
    timestamp_us: int
    seq: int = 0


@dataclass(frozen=True, slots=True)
class CommandAck:
    """ACK frame: the result of the host command whose frame had sequence ``command_seq``."""

    command_type: int
    command_seq: int
    result: int
    seq: int = 0

    @property
    def ok(self) -> bool:
        return self.result == AckResult.OK


@dataclass(frozen=True, slots=True)
class SickReply:
    """SICK_REPLY frame: what the LMS answered to a forwarded command.

    ``ack`` is the byte the LMS sent first (0x06 ACK, 0x15 NAK, 0x00 none received);
    ``reply`` the decoded telegram that followed, if any.
    """

    ack: int
    reply: SickMessage | None
    seq: int = 0


@dataclass(frozen=True, slots=True)
class SetNodRate:
    """Set the nod rate (Table A.1 ``Motorrates``), micro-degrees per second, > 0."""

    rate_udeg_per_s: int
    seq: int = 0


@dataclass(frozen=True, slots=True)
class SetNodLimits:
    """Set the nod limits (Table A.1 ``LowAngle``/``HighAngle``), low < high."""

    low_udeg: int
    high_udeg: int
    seq: int = 0


@dataclass(frozen=True, slots=True)
class StartNodding:
    """Start nodding between the limits at the set rate."""

    seq: int = 0


@dataclass(frozen=True, slots=True)
class StopNodding:
    """Stop nodding and hold the current angle."""

    seq: int = 0


@dataclass(frozen=True, slots=True)
class GotoAngle:
    """Stop nodding, move to ``angle_udeg`` and hold it (fixed-tilt operation)."""

    angle_udeg: int
    seq: int = 0


@dataclass(frozen=True, slots=True)
class RequestStatus:
    """Ask for one STATUS frame."""

    seq: int = 0


@dataclass(frozen=True, slots=True)
class SickCommand:
    """Forward ``command`` (a host -> LMS SICK message) to the LMS over RS-422."""

    command: SickMessage
    seq: int = 0


ControllerMessage: TypeAlias = NodScan | ControllerStatus | CommandAck | SickReply
HostCommand: TypeAlias = (
    SetNodRate | SetNodLimits | StartNodding | StopNodding | GotoAngle | RequestStatus
    | SickCommand
)


def encode_controller_frame(frame_type: int, payload: bytes = b"", *, seq: int = 0) -> bytes:
    """Frame ``payload`` with the controller header, header CRC and frame CRC.

    Raises :class:`~afa.errors.EOutOfBounds` if the type or seq is not a byte or the
    payload exceeds :data:`CONTROLLER_MAX_PAYLOAD`.
    """
    if not (0 <= frame_type <= 0xFF and 0 <= seq <= 0xFF):
        raise EOutOfBounds("frame type and seq are bytes")
    if len(payload) > CONTROLLER_MAX_PAYLOAD:
        raise EOutOfBounds(f"controller payload of {len(payload)} bytes exceeds "
                           f"{CONTROLLER_MAX_PAYLOAD}")
    header = struct.pack(_HEADER_FORMAT, CONTROLLER_SYNC, CONTROLLER_VERSION, frame_type,
                         seq, 0, len(payload))
    header += struct.pack("<H", controller_crc16(header))
    body = header + bytes(payload)
    return body + struct.pack("<H", controller_crc16(body))


def _check_int(name: str, value: int, low: int, high: int) -> None:
    if not low <= value <= high:
        raise EOutOfBounds(f"{name} {value} outside {low}..{high}")


_I32 = (-(1 << 31), (1 << 31) - 1)


def encode_controller_message(message: ControllerMessage) -> bytes:
    """Device side: encode a controller -> host frame.

    Raises :class:`~afa.errors.EOutOfBounds` on out-of-range fields.
    """
    if isinstance(message, NodScan):
        _check_int("scan counter", message.scan_counter, 0, 0xFFFFFFFF)
        _check_int("timestamp", message.timestamp_us, 0, (1 << 64) - 1)
        _check_int("nod start", message.nod_start_udeg, *_I32)
        _check_int("nod end", message.nod_end_udeg, *_I32)
        payload = _SCAN_PREFIX.pack(message.scan_counter, message.timestamp_us,
                                    message.nod_start_udeg, message.nod_end_udeg)
        payload += encode_measured_values(message.measured)
        return encode_controller_frame(FrameType.SCAN, payload, seq=message.seq)
    if isinstance(message, ControllerStatus):
        _check_int("state", message.state, 0, 0xFF)
        _check_int("faults", message.faults, 0, 0xFF)
        for name in ("angle_udeg", "low_udeg", "high_udeg"):
            _check_int(name, getattr(message, name), *_I32)
        _check_int("rate", message.rate_udeg_per_s, 0, 0xFFFFFFFF)
        _check_int("timestamp", message.timestamp_us, 0, (1 << 64) - 1)
        payload = _STATUS.pack(message.state, message.faults, message.angle_udeg,
                               message.low_udeg, message.high_udeg,
                               message.rate_udeg_per_s, message.timestamp_us)
        return encode_controller_frame(FrameType.STATUS, payload, seq=message.seq)
    if isinstance(message, CommandAck):
        for name in ("command_type", "command_seq", "result"):
            _check_int(name, getattr(message, name), 0, 0xFF)
        payload = _ACK.pack(message.command_type, message.command_seq, message.result)
        return encode_controller_frame(FrameType.ACK, payload, seq=message.seq)
    _check_int("ack byte", message.ack, 0, 0xFF)
    payload = bytes([message.ack])
    if message.reply is not None:
        payload += encode_sick_message(message.reply)
    return encode_controller_frame(FrameType.SICK_REPLY, payload, seq=message.seq)


def encode_scan_frame(scan_counter: int, timestamp_us: int, nod_start_udeg: int,
                      nod_end_udeg: int, words: npt.NDArray[np.integer], *, seq: int = 0,
                      status: int = 0x10) -> bytes:
    """Device side: the SCAN frame that :func:`encode_controller_message` makes of
    ``NodScan(scan_counter, timestamp_us, nod_start_udeg, nod_end_udeg,
    MeasuredValues(tuple(words), RangeUnit.MM, status), seq)``, the same bytes, from an
    array of value words (:func:`encode_measured_words`).

    Raises :class:`~afa.errors.EOutOfBounds` on out-of-range fields.
    """
    _check_int("scan counter", scan_counter, 0, 0xFFFFFFFF)
    _check_int("timestamp", timestamp_us, 0, (1 << 64) - 1)
    _check_int("nod start", nod_start_udeg, *_I32)
    _check_int("nod end", nod_end_udeg, *_I32)
    payload = _SCAN_PREFIX.pack(scan_counter, timestamp_us, nod_start_udeg, nod_end_udeg)
    payload += encode_measured_words(words, status=status)
    return encode_controller_frame(FrameType.SCAN, payload, seq=seq)


def encode_host_command(command: HostCommand) -> bytes:
    """Host side: encode a host -> controller command frame.

    Raises :class:`~afa.errors.EOutOfBounds` on out-of-range fields (rate <= 0,
    low >= high, angles beyond int32 micro-degrees).
    """
    seq = command.seq
    if isinstance(command, SetNodRate):
        _check_int("nod rate", command.rate_udeg_per_s, 1, 0xFFFFFFFF)
        return encode_controller_frame(FrameType.SET_NOD_RATE,
                                       struct.pack("<I", command.rate_udeg_per_s), seq=seq)
    if isinstance(command, SetNodLimits):
        _check_int("low angle", command.low_udeg, *_I32)
        _check_int("high angle", command.high_udeg, *_I32)
        if not command.low_udeg < command.high_udeg:
            raise EOutOfBounds("the low nod angle must be below the high one")
        return encode_controller_frame(
            FrameType.SET_NOD_LIMITS,
            struct.pack("<ii", command.low_udeg, command.high_udeg), seq=seq)
    if isinstance(command, StartNodding):
        return encode_controller_frame(FrameType.START_NODDING, seq=seq)
    if isinstance(command, StopNodding):
        return encode_controller_frame(FrameType.STOP_NODDING, seq=seq)
    if isinstance(command, GotoAngle):
        _check_int("angle", command.angle_udeg, *_I32)
        return encode_controller_frame(FrameType.GOTO_ANGLE,
                                       struct.pack("<i", command.angle_udeg), seq=seq)
    if isinstance(command, RequestStatus):
        return encode_controller_frame(FrameType.REQUEST_STATUS, seq=seq)
    return encode_controller_frame(FrameType.SICK_COMMAND,
                                   encode_sick_message(command.command), seq=seq)


class _FrameScanner:
    """Shared framing checks of both controller-stream decoders."""

    @staticmethod
    def next_sync(buffer: bytearray, after: int) -> int:
        position = buffer.find(CONTROLLER_SYNC[0], after)
        return position if position >= 0 else len(buffer)

    @classmethod
    def frame(cls, buffer: bytearray) -> tuple[Scan[object] | None, int, int, int, bytes]:
        """Check sync, header CRC, version, length and frame CRC.

        Returns (scan, 0, 0, 0, b"") when the decoder must return ``scan`` (need more,
        or skip with a fault), else (None, type, seq, total length, payload).
        """
        if buffer[0] != CONTROLLER_SYNC[0]:
            return Scan.skip(cls.next_sync(buffer, 1), Fault.GARBAGE), 0, 0, 0, b""
        if len(buffer) < 2:
            return Scan.need_more(), 0, 0, 0, b""
        if buffer[1] != CONTROLLER_SYNC[1]:
            return Scan.skip(cls.next_sync(buffer, 1), Fault.GARBAGE), 0, 0, 0, b""
        if len(buffer) < CONTROLLER_HEADER_SIZE:
            return Scan.need_more(), 0, 0, 0, b""
        _, version, frame_type, seq, _, length = struct.unpack_from(_HEADER_FORMAT, buffer)
        (header_crc,) = struct.unpack_from("<H", buffer, 8)
        if header_crc != controller_crc16(buffer[:8]):
            return Scan.skip(cls.next_sync(buffer, 1), Fault.CHECKSUM), 0, 0, 0, b""
        if version != CONTROLLER_VERSION or length > CONTROLLER_MAX_PAYLOAD:
            return Scan.skip(cls.next_sync(buffer, 1), Fault.MALFORMED), 0, 0, 0, b""
        total = CONTROLLER_HEADER_SIZE + length + 2
        if len(buffer) < total:
            return Scan.need_more(), 0, 0, 0, b""
        frame = bytes(buffer[:total])
        (crc,) = struct.unpack_from("<H", frame, total - 2)
        if crc != controller_crc16(frame[: total - 2]):
            return Scan.skip(cls.next_sync(buffer, 1), Fault.CHECKSUM), 0, 0, 0, b""
        return None, frame_type, seq, total, frame[CONTROLLER_HEADER_SIZE:total - 2]


class NodControllerDecoder(StreamDecoder[ControllerMessage]):
    """Host side: decodes the controller's TCP stream into :data:`ControllerMessage`.

    A frame that passes both CRCs but whose content is wrong (host-direction type,
    bad SICK telegram inside) is skipped whole and counted as malformed.
    ``range_bits`` is the LMS measuring mode's range field width (13 for 8 m mode).
    """

    def __init__(self, *, range_bits: int = 13, max_buffer: int = 1 << 16) -> None:
        super().__init__(max_buffer=max_buffer)
        self.range_bits = range_bits

    def scan(self, buffer: bytearray) -> Scan[ControllerMessage]:
        result, frame_type, seq, total, payload = _FrameScanner.frame(buffer)
        if result is not None:
            return result  # type: ignore[return-value]
        try:
            return Scan.frame(total, self._decode(frame_type, seq, payload))
        except (EOutOfBounds, struct.error):
            return Scan.skip(total, Fault.MALFORMED)

    def _decode(self, frame_type: int, seq: int, payload: bytes) -> ControllerMessage:
        if frame_type == FrameType.SCAN:
            if len(payload) < _SCAN_PREFIX.size:
                raise EOutOfBounds("short SCAN frame")
            counter, stamp, start, end = _SCAN_PREFIX.unpack_from(payload)
            telegram = _split_telegram(payload[_SCAN_PREFIX.size:])
            if telegram.command != REPLY_MEASURED_VALUES or not telegram.is_reply:
                raise EOutOfBounds("SCAN frame does not carry a 0xB0 reply")
            measured = telegram_to_message(telegram, range_bits=self.range_bits)
            if not isinstance(measured, MeasuredValues):  # pragma: no cover - 0xB0 always is
                raise EOutOfBounds("SCAN frame does not carry measured values")
            return NodScan(counter, stamp, start, end, measured, seq)
        if frame_type == FrameType.STATUS:
            if len(payload) != _STATUS.size:
                raise EOutOfBounds("STATUS frame has the wrong size")
            state, faults, angle, low, high, rate, stamp = _STATUS.unpack(payload)
            return ControllerStatus(state, faults, angle, low, high, rate, stamp, seq)
        if frame_type == FrameType.ACK:
            if len(payload) != _ACK.size:
                raise EOutOfBounds("ACK frame has the wrong size")
            command_type, command_seq, result = _ACK.unpack(payload)
            return CommandAck(command_type, command_seq, result, seq)
        if frame_type == FrameType.SICK_REPLY:
            if not payload:
                raise EOutOfBounds("empty SICK_REPLY frame")
            reply = None
            if len(payload) > 1:
                reply = telegram_to_message(_split_telegram(payload[1:]),
                                            range_bits=self.range_bits)
            return SickReply(payload[0], reply, seq)
        raise EOutOfBounds(f"frame type {frame_type:#x} is not a controller frame")


class NodHostCommandDecoder(StreamDecoder[HostCommand]):
    """Device side (the fake controller): decodes host -> controller command frames."""

    def scan(self, buffer: bytearray) -> Scan[HostCommand]:
        result, frame_type, seq, total, payload = _FrameScanner.frame(buffer)
        if result is not None:
            return result  # type: ignore[return-value]
        try:
            return Scan.frame(total, self._decode(frame_type, seq, payload))
        except (EOutOfBounds, struct.error):
            return Scan.skip(total, Fault.MALFORMED)

    @staticmethod
    def _decode(frame_type: int, seq: int, payload: bytes) -> HostCommand:
        def sized(n: int) -> bytes:
            if len(payload) != n:
                raise EOutOfBounds(f"frame type {frame_type:#x} carries {n} bytes")
            return payload

        if frame_type == FrameType.SET_NOD_RATE:
            (rate,) = struct.unpack("<I", sized(4))
            return SetNodRate(rate, seq)
        if frame_type == FrameType.SET_NOD_LIMITS:
            low, high = struct.unpack("<ii", sized(8))
            return SetNodLimits(low, high, seq)
        if frame_type == FrameType.START_NODDING:
            sized(0)
            return StartNodding(seq)
        if frame_type == FrameType.STOP_NODDING:
            sized(0)
            return StopNodding(seq)
        if frame_type == FrameType.GOTO_ANGLE:
            (angle,) = struct.unpack("<i", sized(4))
            return GotoAngle(angle, seq)
        if frame_type == FrameType.REQUEST_STATUS:
            sized(0)
            return RequestStatus(seq)
        if frame_type == FrameType.SICK_COMMAND:
            telegram = _split_telegram(payload)
            if telegram.is_reply:
                raise EOutOfBounds("SICK_COMMAND carries a reply, not a command")
            return SickCommand(telegram_to_message(telegram), seq)
        raise EOutOfBounds(f"frame type {frame_type:#x} is not a host command")


# --------------------------------------------------------------------------------------
# Scan line -> 3-D points
# --------------------------------------------------------------------------------------

def scan_bearings_deg(count: int, scan_angle_deg: int, resolution_cdeg: int) -> npt.NDArray[
        np.float64]:
    """SICK bearings (0 = right, 90 = ahead, 180 = left) of ``count`` values.

    The 180 deg variant starts at 0 deg, the 100 deg variant at 40 deg.
    Raises :class:`~afa.errors.EOutOfBounds` for an unknown variant.
    """
    _check_variant(scan_angle_deg, resolution_cdeg)
    start = (180 - scan_angle_deg) / 2
    return start + np.arange(count, dtype=np.float64) * (resolution_cdeg / 100)


class ScanLineGeometry:
    """The beams of one scan variant, their sines and cosines computed once: turns each
    scan line into 3-D points with a handful of array operations (the driver's path).

    Frame and formula as :func:`scan_line_to_points`.
    """

    def __init__(self, bearings_deg: npt.ArrayLike) -> None:
        bearings = np.deg2rad(np.asarray(bearings_deg, dtype=np.float64).reshape(-1))
        self.count = bearings.size
        self._sin = np.sin(bearings)
        self._minus_cos = -np.cos(bearings)
        # where each beam lies between the first (0) and the last (1)
        self._fraction = (np.arange(self.count) / (self.count - 1) if self.count > 1
                          else np.zeros(self.count))

    def points(self, ranges_m: npt.ArrayLike, nod_deg: float | tuple[float, float], *,
               dtype: npt.DTypeLike = np.float64) -> npt.NDArray[np.floating]:
        """(count, 3) points of every beam, whatever its range (filter them yourself; a
        NaN range gives a NaN point). Raises :class:`~afa.errors.EOutOfBounds` if there
        are not ``count`` ranges.
        """
        r = np.asarray(ranges_m, dtype=np.float64).reshape(-1)
        if r.size != self.count:
            raise EOutOfBounds(f"{r.size} ranges but {self.count} bearings")
        start, end = nod_deg if isinstance(nod_deg, tuple) else (nod_deg, nod_deg)
        start = math.radians(start)
        nod = start + (math.radians(end) - start) * self._fraction
        forward = r * self._sin
        out = np.empty((self.count, 3), dtype=dtype)
        np.multiply(forward, np.cos(nod), out=out[:, 0], casting="same_kind")
        np.multiply(r, self._minus_cos, out=out[:, 1], casting="same_kind")
        np.multiply(forward, np.sin(nod), out=out[:, 2], casting="same_kind")
        return out


    def scan_line(self, measured: MeasuredValues, nod_deg: tuple[float, float]
                  ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
        """The driver's path: (count, 3) float32 points of every beam of ``measured``,
        NaN where a value is not a range, and the validity flags
        (:meth:`MeasuredValues.ranges_and_valid`, NaN for the invalid ranges, then
        :meth:`points` in float32). Compiled where numba is available (decision 0030), bit
        for bit the numpy form. Raises :class:`~afa.errors.EOutOfBounds` if there are not
        ``count`` values."""
        if measured.count != self.count:
            raise EOutOfBounds(f"{measured.count} ranges but {self.count} bearings")
        kernel = _points_kernel()
        if kernel is None:
            ranges, valid = measured.ranges_and_valid()
            ranges[~valid] = np.nan  # no-return codes become NaN points
            points = self.points(ranges, nod_deg, dtype=np.float32)
            return points, valid  # type: ignore[return-value]
        # (as ranges_and_valid reads the words: the same OverflowError for a bad one)
        words = np.frombuffer(array.array("I", measured.raw), dtype=np.uint32)
        start = math.radians(nod_deg[0])
        nod = start + (math.radians(nod_deg[1]) - start) * self._fraction
        points = np.empty((self.count, 3), dtype=np.float32)
        valid = np.empty(self.count, dtype=np.bool_)
        kernel(words, (1 << measured.range_bits) - 1, measured.no_return_threshold,
               measured.unit.metres, self._sin, self._minus_cos, np.cos(nod), np.sin(nod),
               points, valid)
        return points, valid


@functools.cache
def _points_kernel() -> Callable[..., None] | None:
    """The compiled scan-line loop (decision 0030), or None for the numpy form
    (:func:`afa.kernels.compiled`). Loaded on the first scan line."""
    return compiled("components.nodding_laser._points_jit",  # type: ignore[no-any-return]
                    "points_kernel")


def scan_line_to_points(ranges_m: npt.ArrayLike, bearings_deg: npt.ArrayLike,
                        nod_deg: float | tuple[float, float],
                        valid: npt.ArrayLike | None = None) -> npt.NDArray[np.float64]:
    """3-D points (N x 3, metres) of one scan line in the laser frame.

    Frame: x forward, y left, z up; the scan plane is the x-y plane at nod 0 and is
    pitched by the nod angle (an elevation: negative looks down). A value at SICK
    bearing b and range r lies at ``(r sin b cos n, -r cos b, r sin b sin n)``.
    ``nod_deg`` is one angle or (start, end) of the scan, interpolated linearly by
    beam index. Values where ``valid`` is False (default: range not finite or <= 0)
    are left out, so N <= len(ranges). Raises :class:`~afa.errors.EOutOfBounds` if the
    array lengths differ.
    """
    r = np.asarray(ranges_m, dtype=np.float64).reshape(-1)
    b = np.asarray(bearings_deg, dtype=np.float64).reshape(-1)
    if r.shape != b.shape:
        raise EOutOfBounds(f"{r.size} ranges but {b.size} bearings")
    keep = np.isfinite(r) & (r > 0)
    if valid is not None:
        mask = np.asarray(valid, dtype=bool).reshape(-1)
        if mask.shape != r.shape:
            raise EOutOfBounds(f"{r.size} ranges but {mask.size} validity flags")
        keep &= mask
    with np.errstate(invalid="ignore"):
        points = ScanLineGeometry(b).points(r, nod_deg)[keep]
    return points.astype(np.float64, copy=False)


def nod_scan_to_points(scan: NodScan, *, offset_deg: float = 0.0,
                       variant: tuple[int, int] | None = None) -> npt.NDArray[np.float64]:
    """3-D points of a :class:`NodScan`, no-return codes left out.

    ``offset_deg`` is added to both nod angles (Table A.1 ``LaserOffsetAngle``);
    ``variant`` (field of view, resolution in 1/100 deg) overrides the variant inferred
    from the value count. Raises :class:`~afa.errors.EOutOfBounds` when the variant is
    neither given nor inferable.
    """
    measured = scan.measured
    if variant is None:
        variant = SCAN_VARIANTS.get(measured.count)
        if variant is None:
            raise EOutOfBounds(f"cannot infer the scan variant from {measured.count} "
                               "values; pass variant=")
    bearings = scan_bearings_deg(measured.count, *variant)
    return scan_line_to_points(measured.ranges_array(), bearings,
                               (scan.nod_start_deg + offset_deg,
                                scan.nod_end_deg + offset_deg),
                               measured.valid_mask())
