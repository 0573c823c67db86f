"""The console's WebSocket frames: a JSON header and the wire encoding of events.

Every message from the console to the browser is one binary WebSocket message::

    offset  size  field
    0       4     magic b"AFC1"
    4       4     h: length of the JSON header (u32, little-endian)
    8       4     n: number of events in the message (u32)
    12      4     reserved, 0
    16      h     the header, UTF-8 JSON: {"kind": ..., "stream": ..., ...}
    16+h    8·n   the event table: (u32 offset, u32 length) of each event in the message
    .             each event, after zero padding: :meth:`afa.events.Event.encode` (an
                  ``AFE1`` envelope and the body's ``AFW1`` wire frame, :mod:`idl.wire`)

The padding before each event is chosen so that its ``AFW1`` frame starts at a multiple
of 8 in the message: the wire codec aligns every array buffer to 8 bytes from the start
of its frame, so the browser makes typed arrays (``Float32Array``, ...) that are *views*
of the received ``ArrayBuffer``, with no copy (``static/js/wire.js`` decodes it). A
stream that sends several entries at once (laser scan lines) sends them in one message.

Messages without events (the component table, the geometry model, waypoints, replay
state) are the header alone. The browser sends JSON text messages (which kinds it shows
and at what rate); control requests are HTTP POSTs (see :mod:`afa.console.server`).
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Sequence
from typing import Any

from afa.events import Event

__all__ = ["MAGIC", "encode_frame", "decode_frame", "event_names_length", "finite",
           "EVENT_ENVELOPE_SIZE"]

MAGIC = b"AFC1"
_FIXED = struct.Struct("<4sIII")
_ENTRY = struct.Struct("<II")
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


def encode_frame(header: dict[str, Any],
                 events: Sequence[tuple[bytes, int]] = ()) -> bytes:
    """One console message: ``header`` and the encoded ``events``, each given as
    (``Event.encode()``, total UTF-8 length of its domain, type and origin) so that its
    body frame can be 8-aligned."""
    head = _json(header)
    if not events:
        return _FIXED.pack(MAGIC, len(head), 0, 0) + head
    offset = _FIXED.size + len(head) + 8 * len(events)
    table, parts = [], []
    for data, names_length in events:
        pad = -(offset + EVENT_ENVELOPE_SIZE + names_length) % 8
        offset += pad
        table.append(_ENTRY.pack(offset, len(data)))
        parts.append(b"\x00" * pad)
        parts.append(data)
        offset += len(data)
    return b"".join((_FIXED.pack(MAGIC, len(head), len(events), 0), head, *table, *parts))


def event_names_length(event: Event) -> int:
    """The UTF-8 length of an event's domain, type and origin."""
    return len(event.domain.encode()) + len(event.type.encode()) + len(event.origin.encode())


def decode_frame(data: bytes) -> tuple[dict[str, Any], list[Event]]:
    """Inverse of :func:`encode_frame` (for tests and tools; the browser has its own).
    Raises ValueError for a message that is not a console frame."""
    if len(data) < _FIXED.size:
        raise ValueError("truncated console frame")
    magic, length, count, _ = _FIXED.unpack_from(data)
    if magic != MAGIC:
        raise ValueError(f"not a console frame (magic {magic!r})")
    header = json.loads(data[_FIXED.size:_FIXED.size + length])
    events = []
    for k in range(count):
        offset, size = _ENTRY.unpack_from(data, _FIXED.size + length + 8 * k)
        events.append(Event.decode(data[offset:offset + size]))
    return header, events
