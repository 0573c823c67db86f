"""Shared IDL structs: time stamps, positions, name lists and the pose transform.

Field names follow IDL camelCase, as Miro's ``.idl`` files and the seed's tables spell
them (``HTransform``, ``initialUTM``, ``poseValidFlag``), so users searching for the
seed's names find them. Units are SI (metres, seconds, radians) unless a field says
otherwise; see ``docs/idl.md``.
"""

from __future__ import annotations

import math
from typing import Annotated, Any

import numpy as np
from pydantic import model_validator

from idl._base import Array, IDLModel, field

__all__ = [
    "TimeIDL",
    "Position3DIDL",
    "StringSequenceIDL",
    "PoseTransformIDL",
    "HTransform4x4",
    "Vector3",
    "check_homogeneous",
]

#: A 4x4 homogeneous transform ``| R t ; 0 0 0 1 |`` (float64).
HTransform4x4 = Annotated[np.ndarray, Array("float64", (4, 4))]
#: Three float64 values (a UTM position, a vector).
Vector3 = Annotated[np.ndarray, Array("float64", (3,))]

_BOTTOM_ROW = np.array([0.0, 0.0, 0.0, 1.0])


class _Struct(IDLModel):
    """Private base of this package's structs (scalar ``inf`` / ``NaN`` travel as the
    strings ``"Infinity"`` / ``"NaN"``, the one rule of :class:`~idl._base.IDLModel`)."""


def check_homogeneous(matrix: np.ndarray, what: str, *, tolerance: float = 1e-9) -> None:
    """Check that ``matrix`` is a finite 4x4 homogeneous transform.

    Raises ValueError if any entry is not finite or the bottom row is not
    ``0 0 0 1`` (within ``tolerance``, so the result of ``np.linalg.inv`` passes).
    """
    # (ndarray methods and a plain comparison: np.all and np.allclose cost several
    # times more in their Python wrappers than the check itself, on every Pose)
    if not np.isfinite(matrix).all():
        raise ValueError(f"{what} has non-finite entries")
    if not (np.abs(np.asarray(matrix)[3] - _BOTTOM_ROW) <= tolerance).all():
        raise ValueError(f"{what} bottom row must be [0, 0, 0, 1], got {matrix[3].tolist()}")


class TimeIDL(_Struct):
    """Time stamp of a sample (Miro's ``TimeIDL {long sec; long usec;}``).

    ``sec`` is seconds on the clock the runtime injects (wall time: the Unix epoch;
    virtual time: seconds since the simulation started); ``usec`` is 0..999999.
    """

    sec: int = field(unit="s", description="whole seconds (floor of the time)")
    usec: int = field(0, unit="us", ge=0, le=999_999,
                      description="microseconds past sec, 0..999999")

    @classmethod
    def from_seconds(cls, seconds: float) -> TimeIDL:
        """The time stamp of ``seconds`` (a clock's ``now()``), rounded to 1 µs.

        Negative times floor: -0.25 s is ``sec=-1, usec=750000``. Raises ValueError
        for a non-finite value.
        """
        if not math.isfinite(seconds):
            raise ValueError(f"time must be finite, got {seconds!r}")
        sec, usec = divmod(round(seconds * 1_000_000), 1_000_000)
        return cls(sec=sec, usec=usec)

    def to_seconds(self) -> float:
        """The time stamp as float seconds (inverse of :meth:`from_seconds`)."""
        return self.sec + self.usec / 1_000_000


class Position3DIDL(_Struct):
    """A point in 3-D: x, y, z in metres; the interface returning it names its frame."""

    x: float = field(0.0, unit="m", allow_inf_nan=False, description="x coordinate")
    y: float = field(0.0, unit="m", allow_inf_nan=False, description="y coordinate")
    z: float = field(0.0, unit="m", allow_inf_nan=False, description="z coordinate")


class StringSequenceIDL(_Struct):
    """A sequence of strings (CORBA ``sequence<string>``): body or frame names."""

    values: tuple[str, ...] = field((), unit="", description="the strings, in order")


class PoseTransformIDL(_Struct):
    """ModelServer's pose and geometry transform (seed Table 21).

    As a ``Pose`` event: ``HTransform`` is ^W T_V, the vehicle reference frame
    (``Raptor:RearAxleCenter``) in the world frame, whose origin is ``initialUTM``
    (easting, northing, elevation of the first pose; x east, y north, z up). As the
    result of ``getTransformation(A, B)``: ``HTransform`` is ^A T_B, ``initialUTM`` is
    zero and ``poseValidFlag`` true. A point p_B maps to p_A = R p_B + t.
    """

    time: TimeIDL = field(unit="", description="time stamp")
    HTransform: HTransform4x4 = field(
        unit="m", description="4x4 homogeneous transform [R t; 0 0 0 1]; t in metres")
    initialUTM: Vector3 = field(
        unit="m", description="startup UTM position (easting, northing, elevation) the "
                              "world frame's origin is placed at")
    poseValidFlag: bool = field(
        True, unit="", description="false warns that the pose is questionable (e.g. GPS "
                                   "heading while stationary)")

    @model_validator(mode="after")
    def _check(self) -> PoseTransformIDL:
        check_homogeneous(self.HTransform, "HTransform")
        if not np.isfinite(self.initialUTM).all():
            raise ValueError("initialUTM has non-finite entries")
        return self

    @classmethod
    def identity(cls, time: TimeIDL | None = None, **values: Any) -> PoseTransformIDL:
        """The identity transform (zero ``initialUTM``), e.g. ^A T_A."""
        return cls(time=time or TimeIDL(sec=0), HTransform=np.eye(4),
                   initialUTM=np.zeros(3), **values)

    @property
    def rotation(self) -> np.ndarray:
        """The 3x3 rotation R (read-only view)."""
        return self.HTransform[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        """The translation t, metres (read-only view)."""
        return self.HTransform[:3, 3]
