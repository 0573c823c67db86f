"""The console's WebSocket frames: a JSON header and, for events, the wire encoding.

Every message from the console to the browser is one binary WebSocket message::

    offset  size  field
    0       4     magic b"AFC1"
    4       4     h: length of the JSON header (u32, little-endian)
    8       4     e: offset of the event in the message, 0 if none (u32)
    12      4     reserved, 0
    16      h     the header, UTF-8 JSON: {"kind": ..., "stream": ..., ...}
    .             zero padding
    e             the event: :meth:`afa.events.Event.encode` (an ``AFE1`` envelope and the
                  body's ``AFW1`` wire frame, :mod:`idl.wire`)

The padding is chosen so that the ``AFW1`` frame starts at a multiple of 8 in the
message: the wire codec aligns every array buffer to 8 bytes from the start of its frame,
so the browser can make typed arrays (``Float32Array``, ...) that are *views* of the
received ``ArrayBuffer``, with no copy (``static/js/wire.js`` decodes it).

Messages without an event (the component table, the geometry model, waypoints, replay
state, replies) are the header alone. The browser sends JSON text messages (which
streams it wants and at what rate); control requests are HTTP POSTs (see
:mod:`afa.console.server`).
"""

from __future__ import annotations

import json
import math
import struct
from typing import Any

from afa.events import Event

__all__ = ["MAGIC", "encode_frame", "decode_frame", "event_names_length", "finite",
           "EVENT_ENVELOPE_SIZE"]

MAGIC = b"AFC1"
_FIXED = struct.Struct("<4sIII")
#: Size of the AFE1 envelope before the three names (magic, time, seq, three lengths).
EVENT_ENVELOPE_SIZE = 4 + 8 + 8 + 2 + 2 + 2


def finite(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    return value


def _json(header: dict[str, Any]) -> bytes:
    try:
        text = json.dumps(header, separators=(",", ":"), allow_nan=False, default=str)
    except ValueError:  # a NaN or infinity somewhere: JSON has none
        text = json.dumps(finite(header), separators=(",", ":"), allow_nan=False, default=str)
    return text.encode()


def encode_frame(header: dict[str, Any], event: bytes | None = None,
                 names_length: int = 0) -> bytes:
    """One console message: ``header`` and, optionally, an encoded event.

    ``event`` is ``Event.encode()`` of the event and ``names_length`` the total UTF-8
    length of its domain, type and origin (so the body frame can be 8-aligned).
    """
    head = _json(header)
    if event is None:
        return _FIXED.pack(MAGIC, len(head), 0, 0) + head
    start = _FIXED.size + len(head)
    body_start = start + EVENT_ENVELOPE_SIZE + names_length
    pad = -body_start % 8
    offset = start + pad
    return b"".join((_FIXED.pack(MAGIC, len(head), offset, 0), head, b"\x00" * pad, event))


def event_names_length(event: Event) -> int:
    """The UTF-8 length of an event's domain, type and origin."""
    return len(event.domain.encode()) + len(event.type.encode()) + len(event.origin.encode())


def decode_frame(data: bytes) -> tuple[dict[str, Any], Event | None]:
    """Inverse of :func:`encode_frame` (for tests and tools; the browser has its own).
    Raises ValueError for a message that is not a console frame."""
    if len(data) < _FIXED.size:
        raise ValueError("truncated console frame")
    magic, length, offset, _ = _FIXED.unpack_from(data)
    if magic != MAGIC:
        raise ValueError(f"not a console frame (magic {magic!r})")
    header = json.loads(data[_FIXED.size:_FIXED.size + length])
    if offset == 0:
        return header, None
    return header, Event.decode(data[offset:])
