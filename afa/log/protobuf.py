"""Protocol Buffers for the viewer channels that carry arrays (decision 0038).

The viewer channels of point clouds and grids are written as Foxglove's protobuf
schemas ``foxglove.PointCloud`` and ``foxglove.Grid`` (message encoding ``protobuf``,
schema encoding ``protobuf``, the schema a ``google.protobuf.FileDescriptorSet``): their
data stays binary, copied once from the body's array into the chunk, where JSON needed
it in base64 (a third more bytes to write and to compress, and base64's time on the
event loop). The fields, their numbers and types are Foxglove's
(https://docs.foxglove.dev/docs/visualization/message-schemas/point-cloud and
``grid``; the ``.proto`` files of foxglove/schemas).

No protobuf package is needed to write them: this module encodes the few messages by
hand (proto3 wire format: a key ``field << 3 | wire type``, varints, little-endian
fixed 32/64-bit values, length-delimited strings, bytes and messages) and builds the
descriptor set the same way. Fields at their proto3 default (0, empty) are left out,
as protobuf's own encoders do.
"""

from __future__ import annotations

import base64
import functools
import math
import struct
from collections.abc import Sequence

__all__ = ["SCHEMAS", "ENCODING", "FLOAT32", "XYZ", "IDENTITY", "point_cloud", "grid", "pose",
           "Decoder"]

#: The message and schema encoding of these channels (MCAP's well-known name).
ENCODING = "protobuf"

_VARINT, _I64, _LEN, _I32 = 0, 1, 2, 5
_DOUBLE = struct.Struct("<d")
_FIXED32 = struct.Struct("<I")


def _varint(value: int) -> bytes:
    """An unsigned varint (negative int64 values as their two's complement)."""
    if 0 <= value < 0x4000:  # lengths, keys, small numbers: one or two bytes
        return bytes((value,)) if value < 0x80 else bytes((value & 0x7F | 0x80, value >> 7))
    if value < 0:
        value += 1 << 64
    out = bytearray()
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _key(field: int, wire: int) -> bytes:
    return _varint(field << 3 | wire)


def _len(field: int, payload: bytes) -> bytes:
    return _key(field, _LEN) + _varint(len(payload)) + payload


def _string(field: int, text: str) -> bytes:
    return _len(field, text.encode()) if text else b""


def _uint(field: int, value: int) -> bytes:
    return _key(field, _VARINT) + _varint(value) if value else b""


def _fixed32(field: int, value: int) -> bytes:
    return _key(field, _I32) + _FIXED32.pack(value) if value else b""


def _double(field: int, value: float) -> bytes:
    # -0.0 is written: its bits are not the default's
    if value == 0.0 and math.copysign(1.0, value) > 0:
        return b""
    return _key(field, _I64) + _DOUBLE.pack(value)


# -- the messages --------------------------------------------------------------------------

def pose(position: Sequence[float], orientation: Sequence[float]) -> bytes:
    """``foxglove.Pose``: a position (x, y, z) and a quaternion (x, y, z, w)."""
    vector = b"".join(_double(k + 1, float(v)) for k, v in enumerate(position))
    quaternion = b"".join(_double(k + 1, float(v)) for k, v in enumerate(orientation))
    return _len(1, vector) + _len(2, quaternion)


@functools.lru_cache(maxsize=64)
def _fields(number: int, fields: tuple[tuple[str, int, int], ...]) -> bytes:
    """Repeated ``foxglove.PackedElementField`` (name, offset, numeric type)."""
    return b"".join(_len(number, _string(1, name) + _fixed32(2, offset) + _uint(3, kind))
                    for name, offset, kind in fields)


def _data_head(number: int, size: int) -> bytes:
    """The key and length of a ``bytes`` field of ``size`` bytes (the bytes follow)."""
    return _key(number, _LEN) + _varint(size) if size else b""


#: foxglove.PackedElementField.NumericType FLOAT32
FLOAT32 = 7
#: Points of three float32 coordinates, x, y, z.
XYZ = (("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32))
#: The identity ``foxglove.Pose``, encoded.
IDENTITY = pose((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def point_cloud(seconds: int, nanos: int, frame: str, data: memoryview, *,
                origin: bytes = IDENTITY, stride: int = 12,
                fields: tuple[tuple[str, int, int], ...] = XYZ) -> list[bytes | memoryview]:
    """``foxglove.PointCloud`` as the parts of its bytes: the head, then ``data`` (a
    byte view, not copied: :meth:`afa.log.writer.McapWriter.add_message` copies it once
    into the chunk). ``origin``: an encoded :func:`pose`; ``fields``: (name, offset,
    numeric type) of each field of a point. A laser's scan line comes every 12 ms: what
    does not change between two clouds of a sensor is encoded once (cached)."""
    head = (_timestamp_field(seconds, nanos) + _cloud_middle(frame, origin, stride, fields)
            + _data_head(6, data.nbytes))
    return [head, data] if data.nbytes else [head]


def _timestamp_field(seconds: int, nanos: int) -> bytes:
    """Field 1, a ``google.protobuf.Timestamp``."""
    stamp = _seconds(seconds) + (_key(2, _VARINT) + _varint(nanos) if nanos else b"")
    return _key(1, _LEN) + _varint(len(stamp)) + stamp


@functools.lru_cache(maxsize=16)
def _seconds(seconds: int) -> bytes:
    """A Timestamp's field 1 (the same for every message of a second)."""
    return _uint(1, seconds)


@functools.lru_cache(maxsize=256)
def _cloud_middle(frame: str, origin: bytes, stride: int,
                  fields: tuple[tuple[str, int, int], ...]) -> bytes:
    """A PointCloud's fields 2 to 5."""
    return _string(2, frame) + _len(3, origin) + _fixed32(4, stride) + _fields(5, fields)


def grid(seconds: int, nanos: int, frame: str, origin: bytes, columns: int,
         cell: tuple[float, float], cell_stride: int,
         fields: tuple[tuple[str, int, int], ...], data: memoryview
         ) -> list[bytes | memoryview]:
    """``foxglove.Grid`` as the parts of its bytes, as :func:`point_cloud`; a row is
    ``columns`` cells of ``cell_stride`` bytes."""
    cell_size = _double(1, cell[0]) + _double(2, cell[1])
    head = b"".join((_timestamp_field(seconds, nanos), _string(2, frame), _len(3, origin),
                     _fixed32(4, columns), _len(5, cell_size),
                     _fixed32(6, cell_stride * columns), _fixed32(7, cell_stride),
                     _fields(8, fields), _data_head(9, data.nbytes)))
    return [head, data] if data.nbytes else [head]


# -- the schemas: google.protobuf.FileDescriptorSet ------------------------------------------

# FieldDescriptorProto.Type and .Label (google/protobuf/descriptor.proto)
_T_DOUBLE, _T_INT64, _T_INT32, _T_FIXED32 = 1, 3, 5, 7
_T_STRING, _T_MESSAGE, _T_BYTES, _T_ENUM = 9, 11, 12, 14
_L_OPTIONAL, _L_REPEATED = 1, 3


def _field(name: str, number: int, kind: int, type_name: str = "", *,
           repeated: bool = False) -> bytes:
    """A ``FieldDescriptorProto`` (name 1, number 3, label 4, type 5, type_name 6,
    json_name 10)."""
    json_name = name.split("_")[0] + "".join(p.title() for p in name.split("_")[1:])
    return (_string(1, name) + _uint(3, number)
            + _uint(4, _L_REPEATED if repeated else _L_OPTIONAL) + _uint(5, kind)
            + _string(6, type_name) + _string(10, json_name))


def _enum(name: str, values: Sequence[str]) -> bytes:
    """An ``EnumDescriptorProto`` (name 1, value 2: name 1, number 2)."""
    return _string(1, name) + b"".join(
        _len(2, _string(1, value) + _key(2, _VARINT) + _varint(number))
        for number, value in enumerate(values))


def _message(name: str, fields: Sequence[bytes], enums: Sequence[bytes] = ()) -> bytes:
    """A ``DescriptorProto`` (name 1, field 2, enum_type 4)."""
    return (_string(1, name) + b"".join(_len(2, f) for f in fields)
            + b"".join(_len(4, e) for e in enums))


def _file(name: str, package: str, dependencies: Sequence[str], message: bytes) -> bytes:
    """A ``FileDescriptorProto`` (name 1, package 2, dependency 3, message_type 4,
    syntax 12)."""
    return (_string(1, name) + _string(2, package)
            + b"".join(_string(3, d) for d in dependencies) + _len(4, message)
            + _string(12, "proto3"))


_TIMESTAMP = "google/protobuf/timestamp.proto"
_FILES: dict[str, tuple[list[str], bytes]] = {  # file -> (dependencies, FileDescriptorProto)
    _TIMESTAMP: ([], _file(_TIMESTAMP, "google.protobuf", [], _message("Timestamp", [
        _field("seconds", 1, _T_INT64), _field("nanos", 2, _T_INT32)]))),
    "foxglove/Vector2.proto": ([], _file("foxglove/Vector2.proto", "foxglove", [], _message(
        "Vector2", [_field(axis, k + 1, _T_DOUBLE) for k, axis in enumerate("xy")]))),
    "foxglove/Vector3.proto": ([], _file("foxglove/Vector3.proto", "foxglove", [], _message(
        "Vector3", [_field(axis, k + 1, _T_DOUBLE) for k, axis in enumerate("xyz")]))),
    "foxglove/Quaternion.proto": ([], _file("foxglove/Quaternion.proto", "foxglove", [],
                                            _message("Quaternion", [
                                                _field(axis, k + 1, _T_DOUBLE)
                                                for k, axis in enumerate("xyzw")]))),
}
_FILES["foxglove/Pose.proto"] = (
    ["foxglove/Vector3.proto", "foxglove/Quaternion.proto"],
    _file("foxglove/Pose.proto", "foxglove",
          ["foxglove/Quaternion.proto", "foxglove/Vector3.proto"], _message("Pose", [
              _field("position", 1, _T_MESSAGE, ".foxglove.Vector3"),
              _field("orientation", 2, _T_MESSAGE, ".foxglove.Quaternion")])))
_FILES["foxglove/PackedElementField.proto"] = ([], _file(
    "foxglove/PackedElementField.proto", "foxglove", [], _message("PackedElementField", [
        _field("name", 1, _T_STRING), _field("offset", 2, _T_FIXED32),
        _field("type", 3, _T_ENUM, ".foxglove.PackedElementField.NumericType")],
        [_enum("NumericType", ["UNKNOWN", "UINT8", "INT8", "UINT16", "INT16", "UINT32",
                               "INT32", "FLOAT32", "FLOAT64"])])))
_HEAD = ["foxglove/PackedElementField.proto", "foxglove/Pose.proto", _TIMESTAMP]
_FILES["foxglove/PointCloud.proto"] = (_HEAD, _file(
    "foxglove/PointCloud.proto", "foxglove", _HEAD, _message("PointCloud", [
        _field("timestamp", 1, _T_MESSAGE, ".google.protobuf.Timestamp"),
        _field("frame_id", 2, _T_STRING),
        _field("pose", 3, _T_MESSAGE, ".foxglove.Pose"),
        _field("point_stride", 4, _T_FIXED32),
        _field("fields", 5, _T_MESSAGE, ".foxglove.PackedElementField", repeated=True),
        _field("data", 6, _T_BYTES)])))
_GRID_DEPENDENCIES = ["foxglove/PackedElementField.proto", "foxglove/Pose.proto",
                      "foxglove/Vector2.proto", _TIMESTAMP]
_FILES["foxglove/Grid.proto"] = (_GRID_DEPENDENCIES, _file(
    "foxglove/Grid.proto", "foxglove", _GRID_DEPENDENCIES, _message("Grid", [
        _field("timestamp", 1, _T_MESSAGE, ".google.protobuf.Timestamp"),
        _field("frame_id", 2, _T_STRING),
        _field("pose", 3, _T_MESSAGE, ".foxglove.Pose"),
        _field("column_count", 4, _T_FIXED32),
        _field("cell_size", 5, _T_MESSAGE, ".foxglove.Vector2"),
        _field("row_stride", 6, _T_FIXED32),
        _field("cell_stride", 7, _T_FIXED32),
        _field("fields", 8, _T_MESSAGE, ".foxglove.PackedElementField", repeated=True),
        _field("data", 9, _T_BYTES)])))


def _descriptor_set(root: str) -> bytes:
    """The ``FileDescriptorSet`` (file 1) of ``root`` and everything it imports,
    dependencies first."""
    order: list[str] = []

    def visit(name: str) -> None:
        if name in order:
            return
        for dependency in _FILES[name][0]:
            visit(dependency)
        order.append(name)

    visit(root)
    return b"".join(_len(1, _FILES[name][1]) for name in order)


#: Foxglove schema name -> its FileDescriptorSet (the MCAP schema's data).
SCHEMAS: dict[str, bytes] = {
    "foxglove.PointCloud": _descriptor_set("foxglove/PointCloud.proto"),
    "foxglove.Grid": _descriptor_set("foxglove/Grid.proto"),
}


# -- reading (afa log echo): a decoder driven by the descriptor set ------------------------

def _read_varint(data: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if at >= len(data):
            raise ValueError("a varint runs past the end of the message")
        byte = data[at]
        at += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, at
        shift += 7
        if shift > 63:
            raise ValueError("a varint longer than 10 bytes")


def _wire_fields(data: bytes) -> list[tuple[int, int, int | bytes]]:
    """The (field number, wire type, value) of each field of an encoded message: an int
    for a varint, the bytes of the others. Raises ValueError for malformed data."""
    fields: list[tuple[int, int, int | bytes]] = []
    at = 0
    while at < len(data):
        key, at = _read_varint(data, at)
        number, wire = key >> 3, key & 7
        value: int | bytes
        if wire == _VARINT:
            value, at = _read_varint(data, at)
        elif wire in (_I64, _I32):
            size = 8 if wire == _I64 else 4
            value, at = data[at:at + size], at + size
        elif wire == _LEN:
            size, at = _read_varint(data, at)
            value, at = data[at:at + size], at + size
        else:
            raise ValueError(f"unsupported wire type {wire}")
        if at > len(data):
            raise ValueError("a field runs past the end of the message")
        fields.append((number, wire, value))
    return fields


def _text(value: int | bytes) -> str:
    return bytes(value).decode() if isinstance(value, bytes) else ""


_SCALARS: dict[int, struct.Struct] = {1: _DOUBLE, 2: struct.Struct("<f"), 6: struct.Struct("<Q"),
                                      7: _FIXED32, 15: struct.Struct("<i"),
                                      16: struct.Struct("<q")}


class Decoder:
    """Decodes the messages a ``FileDescriptorSet`` describes into JSON-ready dicts
    (field names as in the schema, bytes in base64, enums as numbers, absent scalar
    fields at their defaults, absent messages left out): what ``afa log echo`` prints
    of a protobuf channel. Raises ValueError for malformed data."""

    def __init__(self, descriptor_set: bytes) -> None:
        # message full name -> field number -> (name, type, type name, repeated)
        self.messages: dict[str, dict[int, tuple[str, int, str, bool]]] = {}
        for number, _, file in _wire_fields(descriptor_set):
            if number != 1 or not isinstance(file, bytes):
                continue
            parts = _wire_fields(file)
            package = next((_text(v) for n, _, v in parts if n == 2), "")
            for n, _, message in parts:
                if n == 4 and isinstance(message, bytes):
                    self._add(package, message)

    def _add(self, scope: str, data: bytes) -> None:
        parts = _wire_fields(data)
        name = next((_text(v) for n, _, v in parts if n == 1), "")
        full = f"{scope}.{name}" if scope else name
        fields: dict[int, tuple[str, int, str, bool]] = {}
        for n, _, value in parts:
            if n == 2 and isinstance(value, bytes):
                spec = {k: v for k, _, v in _wire_fields(value)}
                fields[int(spec.get(3, 0))] = (
                    _text(spec.get(1, b"")), int(spec.get(5, 0)),
                    _text(spec.get(6, b"")).lstrip("."), spec.get(4) == _L_REPEATED)
            elif n == 3 and isinstance(value, bytes):
                self._add(full, value)
        self.messages[full] = fields

    def decode(self, name: str, data: bytes) -> dict[str, object]:
        """The message ``name`` (a full name, ``foxglove.PointCloud``) in ``data``."""
        fields = self.messages.get(name)
        if fields is None:
            raise ValueError(f"no message {name} in the schema")
        out: dict[str, object] = {}
        for number, _, raw in _wire_fields(data):
            spec = fields.get(number)
            if spec is None:
                continue  # an unknown field, as protobuf readers skip it
            field, kind, type_name, repeated = spec
            value: object
            if isinstance(raw, int):
                value = raw - (1 << 64) if kind in (3, 5, 18) and raw >= 1 << 63 else raw
                if kind == 8:
                    value = bool(raw)
            elif kind in _SCALARS:
                (value,) = _SCALARS[kind].unpack(raw)
            elif kind == _T_STRING:
                value = raw.decode()
            elif kind == _T_MESSAGE:
                value = self.decode(type_name, raw)
            else:
                value = base64.b64encode(raw).decode("ascii")
            if repeated:
                items = out.setdefault(field, [])
                assert isinstance(items, list)
                items.append(value)
            else:
                out[field] = value
        for field, kind, _, repeated in fields.values():  # proto3: absent is default
            if field not in out and kind != _T_MESSAGE:
                out[field] = ([] if repeated else "" if kind in (_T_STRING, _T_BYTES)
                              else 0.0 if kind in (1, 2) else False if kind == 8 else 0)
        return out
