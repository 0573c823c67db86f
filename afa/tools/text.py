"""Text output of the tools: one-line event summaries, JSON lines, aligned tables, and
an output that survives a closed pipe (``afa echo Pose | head -3``)."""

from __future__ import annotations

import json
import math
import os
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from afa.events import Event
from idl._base import IDLModel, type_name

__all__ = ["brief", "event_line", "event_json", "table", "Output", "PipeClosed"]


class PipeClosed(Exception):
    """The reader of our standard output went away."""


def brief(value: Any, depth: int = 0) -> str:
    """A compact, readable form: arrays as dtype and shape (small ones in full), floats
    to 6 significant digits."""
    if isinstance(value, IDLModel):
        inner = " ".join(f"{name}={brief(getattr(value, name), depth + 1)}"
                         for name in type(value).model_fields)
        return inner if depth == 0 else f"{{{inner}}}"
    if isinstance(value, np.ndarray):
        if value.size <= 4:
            return "[" + ", ".join(brief(v, depth + 1) for v in value.ravel().tolist()) + "]"
        return f"<{value.dtype} {'x'.join(map(str, value.shape))}>"
    if isinstance(value, (list, tuple)):
        if len(value) > 8:
            return f"[{len(value)} items]"
        return "[" + ", ".join(brief(v, depth + 1) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.6g}" if math.isfinite(value) else str(value)
    if isinstance(value, str):
        return json.dumps(value)
    return str(value)


def event_line(event: Event) -> str:
    return (f"{event.time:.6f} {event.domain}/{event.type} from {event.origin or '?'}: "
            f"{type(event.body).__name__} {brief(event.body)}")


def event_json(event: Event) -> str:
    """One JSON line: the envelope and the body's lossless JSON (arrays in base64, as
    :meth:`IDLModel.to_json`; ``IDLModel.from_json`` reads it back)."""
    return json.dumps({"time": event.time, "domain": event.domain, "type": event.type,
                       "origin": event.origin, "seq": event.seq,
                       "body_type": type_name(type(event.body)),
                       "body": json.loads(event.body.to_json())})


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    cells = [[str(h) for h in headers]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    lines = ["  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True))
             .rstrip() for row in cells]
    return "\n".join(lines)


class Output:
    """Writes lines to standard output, flushing each (a tool is watched live); a
    closed pipe raises :class:`PipeClosed` once and silences the rest."""

    def __init__(self, stream: Any = None) -> None:
        self.stream = stream or sys.stdout

    def write(self, text: str) -> None:
        try:
            self.stream.write(text if text.endswith("\n") else text + "\n")
            self.stream.flush()
        except BrokenPipeError:
            self._silence()
            raise PipeClosed() from None

    def _silence(self) -> None:
        # Python would complain when it flushes stdout at exit: point it at /dev/null
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self.stream.fileno())
        except (OSError, ValueError, AttributeError):
            pass
