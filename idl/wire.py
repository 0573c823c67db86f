"""The wire codec: every IDL model to bytes and back, lossless and fast.

One binary form serves the event log, the network bridge and the browser console.
Scalars and structure travel as compact JSON (the model's own serialisation, with the
IDL's rule for non-finite numbers: ``"Infinity"``, ``"-Infinity"``, ``"NaN"``); numpy
arrays travel as raw buffers beside it, never base64, so a 20 MB map costs a memory copy
to encode and nothing to decode (the arrays are read-only views of the frame).

Frame layout (integers little-endian)::

    offset  size   field
    0       4      magic b"AFW1" (format version 1)
    4       2      n: length of the type name
    6       n      type name, UTF-8: qualified and versioned, "idl.sensors.GpsIDL@1"
    .       4      m: length of the JSON body
    .       m      JSON body; an array is {"dtype": "<f4", "shape": [..], "$array": k}
    .       2      b: number of array buffers
    .       8·b    the buffers' lengths (u64)
    then each buffer k, starting at the next multiple of 8 (zero padding)

Decoding looks the type name up in the registry of :mod:`idl._base` (unknown names and
versions newer than this program's are refused with a message saying so) and validates
the body with the model, so a frame from outside the process is checked like any other
input. Nothing in a frame can make the decoder run code: type names select only
registered IDL classes, and arrays are plain numeric buffers (object dtypes refused).
"""

from __future__ import annotations

import functools
import struct
from typing import Any, TypeVar

import numpy as np
from pydantic import ValidationError

from idl._base import WIRE_BUFFERS, IDLModel, idl_types, type_name

__all__ = ["encode", "encode_parts", "byte_view", "decode", "peek_type", "schema",
           "WireError", "MAGIC"]

MAGIC = b"AFW1"
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
#: Bounds that keep a hostile frame from asking for absurd work.
MAX_TYPE_NAME = 512
MAX_BUFFERS = 4096

M = TypeVar("M", bound=IDLModel)


class WireError(ValueError):
    """A frame that is not a valid encoding of a known IDL type (the message says why)."""


def encode_parts(model: IDLModel) -> list[bytes | memoryview]:
    """The frame as a list of byte strings to write one after the other (no copy of the
    array data; for writers that take several buffers)."""
    buffers: list[Any] = []
    cls = type(model)
    body = cls.__pydantic_serializer__.to_json(model, context={WIRE_BUFFERS: buffers})
    name = _NAMES.get(cls)
    if name is None:
        name = _NAMES[cls] = type_name(cls).encode()
    head = MAGIC + _U16.pack(len(name)) + name + _U32.pack(len(body))
    if not buffers:
        return [head, body, b"\x00\x00"]
    count = len(buffers)
    table = _table(count).pack(count, *[array.nbytes for array in buffers])
    parts: list[bytes | memoryview] = [head, body, table]
    offset = len(head) + len(body) + len(table)
    for array in buffers:
        pad = -offset % 8
        if pad:
            parts.append(_PADDING[pad])
        parts.append(byte_view(array))
        offset += pad + array.nbytes
    return parts


def byte_view(array: np.ndarray) -> memoryview:
    """A C-contiguous array's bytes as a flat byte view, not copied (an empty array, a
    scan with no return, has no buffer to view)."""
    return array.data.cast("B") if array.nbytes else _EMPTY


#: Each class's encoded type name (classes are never renamed once defined).
_NAMES: dict[type, bytes] = {}
_PADDING = [b"\x00" * n for n in range(8)]
_EMPTY = memoryview(b"")


@functools.lru_cache(maxsize=64)
def _table(count: int) -> struct.Struct:
    """The buffer table's layout: the count (u16), then each buffer's length (u64)."""
    return struct.Struct(f"<H{count}Q")


def encode(model: IDLModel) -> bytes:
    """The wire frame of ``model`` (see the module docstring)."""
    return b"".join(encode_parts(model))


def peek_type(data: bytes | bytearray | memoryview) -> str:
    """The type name a frame carries, without decoding it. Raises :class:`WireError`."""
    view = memoryview(data)
    if bytes(view[:4]) != MAGIC:
        raise WireError(f"not an afa wire frame (magic {bytes(view[:4])!r}, expected {MAGIC!r})")
    if len(view) < 6:
        raise WireError("truncated frame: no type name length")
    (n,) = _U16.unpack_from(view, 4)
    if n > MAX_TYPE_NAME or len(view) < 6 + n:
        raise WireError(f"truncated or invalid type name ({n} bytes)")
    try:
        return bytes(view[6:6 + n]).decode()
    except UnicodeDecodeError as exc:
        raise WireError(f"type name is not UTF-8: {exc}") from None


def decode(data: bytes | bytearray | memoryview, cls: type[M] | None = None) -> M:
    """The model a frame holds; ``cls`` (optional) is the class expected.

    Arrays are read-only views of ``data`` when it is immutable (``bytes``), copies
    otherwise. Raises :class:`WireError` for a malformed frame, an unknown type, a type
    version newer than this program knows, or a body its model rejects.
    """
    view = memoryview(data)
    name = peek_type(view)
    model_cls = _lookup(name) if cls is None else cls
    if cls is not None and name != type_name(cls):
        raise WireError(f"frame holds {name}, expected {type_name(cls)}")
    offset = 6 + len(name.encode())
    try:
        (m,) = _U32.unpack_from(view, offset)
        offset += 4
        body = bytes(view[offset:offset + m])
        if len(body) != m:
            raise WireError(f"truncated JSON body ({len(body)} of {m} bytes)")
        offset += m
        (count,) = _U16.unpack_from(view, offset)
        offset += 2
        if count > MAX_BUFFERS:
            raise WireError(f"{count} array buffers (at most {MAX_BUFFERS})")
        lengths = [_U64.unpack_from(view, offset + 8 * k)[0] for k in range(count)]
        offset += 8 * count
    except struct.error as exc:
        raise WireError(f"truncated frame: {exc}") from None
    buffers = []
    for length in lengths:
        offset += -offset % 8
        if offset + length > len(view):
            raise WireError(f"truncated array buffer ({len(view) - offset} of {length} bytes)")
        buffers.append(view[offset:offset + length])
        offset += length
    if offset != len(view):
        raise WireError(f"{len(view) - offset} unexpected bytes after the last buffer")
    try:
        return model_cls.__pydantic_validator__.validate_json(  # type: ignore[no-any-return]
            body, context={WIRE_BUFFERS: buffers})
    except ValidationError as exc:
        raise WireError(f"invalid {name}: {exc}") from None


def _lookup(name: str) -> type[IDLModel]:
    qualified, _, version_text = name.rpartition("@")
    try:
        version = int(version_text)
    except ValueError:
        raise WireError(f"type name {name!r} has no version") from None
    cls = idl_types().get(qualified)
    if cls is None:
        raise WireError(f"unknown IDL type {qualified!r} (a plug-in that is not installed, "
                        "or a newer afa?)")
    if version > cls.idl_version:
        raise WireError(f"{name} was written by a newer afa; this one reads "
                        f"{type_name(cls)}: upgrade afa to read it")
    return cls


def schema(cls: type[IDLModel]) -> dict[str, Any]:
    """The JSON schema of ``cls``'s JSON body (arrays described by dtype and shape), with
    its wire type name under ``"x-afa-type"``."""
    document = cls.model_json_schema(mode="serialization")
    document["x-afa-type"] = type_name(cls)
    return document
