"""Comparing a re-run with a recording, field by field (``afa replay --check``).

:func:`first_difference` walks two IDL bodies and returns the first field that differs
as a dotted path (``HTransform[0, 3]``, ``time.usec``, ``points[17, 2]``) with both
values; arrays are compared element-wise (NaN equals NaN) and report their first
differing index. :class:`Divergence` is what the check reports; :class:`CheckReport` the
whole verdict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from idl._base import IDLModel

__all__ = ["first_difference", "Divergence", "CheckReport"]


def _close(a: Any, b: Any, atol: float) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not (
                isinstance(a, bool) or isinstance(b, bool)):
            if math.isnan(a) and math.isnan(b):
                return True
            return a == b or abs(a - b) <= atol
    return bool(a == b)


def first_difference(recorded: Any, replayed: Any, path: str = "", *,
                     atol: float = 0.0) -> tuple[str, Any, Any] | None:
    """The first differing field of two values as ``(path, recorded, replayed)``, or
    None if they are equal (within ``atol`` for floating-point numbers)."""
    if isinstance(recorded, IDLModel) or isinstance(replayed, IDLModel):
        if type(recorded) is not type(replayed):
            return (path or "(type)", type(recorded).__name__, type(replayed).__name__)
        for name in type(recorded).model_fields:
            found = first_difference(getattr(recorded, name), getattr(replayed, name),
                                     f"{path}.{name}" if path else name, atol=atol)
            if found is not None:
                return found
        return None
    if isinstance(recorded, np.ndarray) or isinstance(replayed, np.ndarray):
        a, b = np.asarray(recorded), np.asarray(replayed)
        if a.dtype != b.dtype:
            return (f"{path}.dtype", str(a.dtype), str(b.dtype))
        if a.shape != b.shape:
            return (f"{path}.shape", a.shape, b.shape)
        if a.dtype.kind == "f":
            with np.errstate(invalid="ignore"):  # inf - inf: equal infinities match below
                same = (np.abs(a - b) <= atol) | (np.isnan(a) & np.isnan(b)) | (a == b)
        else:
            same = a == b
        if bool(np.all(same)):
            return None
        index = tuple(int(i) for i in np.argwhere(~same)[0])
        where = f"{path}[{', '.join(map(str, index))}]"
        return (where, a[index].item(), b[index].item())
    if isinstance(recorded, (list, tuple)) and isinstance(replayed, (list, tuple)):
        for k, (a, b) in enumerate(zip(recorded, replayed, strict=False)):
            found = first_difference(a, b, f"{path}[{k}]", atol=atol)
            if found is not None:
                return found
        if len(recorded) != len(replayed):
            return (f"{path}.length", len(recorded), len(replayed))
        return None
    if isinstance(recorded, dict) and isinstance(replayed, dict):
        for key in sorted(set(recorded) | set(replayed), key=str):
            found = first_difference(recorded.get(key), replayed.get(key), f"{path}[{key!r}]",
                                     atol=atol)
            if found is not None:
                return found
        return None
    if _close(recorded, replayed, atol):
        return None
    return (path or "(value)", recorded, replayed)


@dataclass(frozen=True)
class Divergence:
    """Where a re-run first differs from the recording."""

    time: float  #: the recorded (or produced) stamp, s since the epoch
    offset: float  #: seconds since the recording's first message
    topic: str  #: the event topic, or the poll's server and method
    origin: str  #: the component that produced it
    field: str  #: dotted path of the differing field, or what is missing
    recorded: Any
    replayed: Any

    def text(self) -> str:
        return (f"first divergence at t={self.offset:.6f} s (stamp {self.time:.6f}) on "
                f"{self.topic} from {self.origin}: {self.field}: recorded "
                f"{_show(self.recorded)}, replayed {_show(self.replayed)}")


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 200 else text[:197] + "..."


@dataclass
class CheckReport:
    """The verdict of a check: identical, or the first divergence."""

    path: str
    components: list[str]  #: the components re-run
    replayed: list[str]  #: the recorded topics published into the re-run
    compared: dict[str, int] = field(default_factory=dict)  #: outputs compared per topic
    divergence: Divergence | None = None
    problems: list[str] = field(default_factory=list)
    #: outputs of re-run components the recording did not keep (not compared)
    unchecked: list[str] = field(default_factory=list)

    @property
    def identical(self) -> bool:
        return self.divergence is None and sum(self.compared.values()) > 0

    def text(self) -> str:
        lines = [f"{self.path}: re-ran {', '.join(self.components) or 'nothing'} on "
                 f"{len(self.replayed)} recorded topic(s)"]
        total = sum(self.compared.values())
        if self.divergence is not None:
            lines.append(self.divergence.text())
            lines.append(f"({total} output(s) identical before it)")
        elif total == 0:
            lines.append("nothing to compare: no re-run component produced a recorded output")
        else:
            counts = ", ".join(f"{topic} {n}" for topic, n in sorted(self.compared.items()))
            lines.append(f"identical: {total} output(s) compared ({counts})")
        if self.unchecked:
            lines.append(f"not compared (not in the recording): {', '.join(self.unchecked)}")
        lines += [f"warning: {p}" for p in self.problems]
        return "\n".join(lines)
