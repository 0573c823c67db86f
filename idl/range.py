"""3-D range events of the Nodding Laser and Stereo Vision (seed Tables 1-4, 14, 31).

The seed publishes each range scan in two forms: a fixed-size "static array" and a
variable-length "CORBA sequence". Here:

- **static array** forms (:class:`Range3dLaserIDL`, :class:`Range3dStereoEventIDL`)
  keep one slot per beam or pixel, whether or not it measured anything; ``valid``
  marks the slots that hold a point, and every invalid slot holds ``NaN`` in all
  three coordinates. Their size is the sensor's configuration (361 beams for the
  SICK at 0.5°, 240x320 pixels for the Digiclops), not a compile-time constant.
- **sequence** forms (:class:`Range3dSeqEventIDL`, :class:`Range3dArrayEventIDL`)
  carry only the valid points, ``(n, 3)``.

Points are float32 metres in the sensor frame named by ``frame`` (ModelServer's
``getTransformation`` maps that frame to any other). float32 keeps 0.5 µm at 8 m,
far below the sensors' millimetre resolution, and halves the size of a stereo frame.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

import numpy as np
from pydantic import model_validator

from idl._base import Array, field
from idl.common import TimeIDL, _Struct

__all__ = [
    "Range3dLaserIDL",
    "Range3dSeqEventIDL",
    "Range3dStereoEventIDL",
    "Range3dArrayEventIDL",
    "Points",
    "select_valid",
]

#: An ``(n, 3)`` float32 point array, metres.
Points = Annotated[np.ndarray, Array("float32", (None, 3))]


class _RangeHeader(_Struct):
    """Fields every range event carries."""

    time: TimeIDL = field(unit="", description="time stamp of the scan (its first beam)")
    sensorId: int = field(unit="1", description="sensor id: LaserID of Table A.1 (11, 12) "
                                                "for lasers")
    frame: str = field(unit="", description="Body:Frame the points are expressed in")


class _NodAngles(_Struct):
    """Nod angles of one nodding-laser scan line."""

    nodAngleStart: float = field(0.0, unit="rad", allow_inf_nan=False,
                                 description="nod angle at the first beam")
    nodAngleEnd: float = field(0.0, unit="rad", allow_inf_nan=False,
                               description="nod angle at the last beam (the mount keeps "
                                           "nodding during the 26.6 ms scan)")


def _check_static(points: np.ndarray, valid: np.ndarray, what: str) -> None:
    if valid.shape != points.shape[:-1]:
        raise ValueError(f"{what}: valid has shape {valid.shape}, points need "
                         f"{points.shape[:-1]}")
    finite = np.isfinite(points)
    if not finite[valid].all():
        raise ValueError(f"{what}: a valid point has a non-finite coordinate")
    if not np.isnan(points[~valid]).all():
        raise ValueError(f"{what}: invalid slots must hold NaN in all coordinates")


def select_valid(points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``points[valid]`` as a fresh ``(n, 3)`` array in row-major order, for the static
    array forms (beams ``(N, 3)`` with ``(N,)`` flags, pixels ``(R, C, 3)`` with
    ``(R, C)``). ``compress`` on the flattened rows is several times faster than a
    boolean mask over a 3-D array (the method: ``np.compress`` and ``np.ravel`` add a
    Python wrapper each, on every scan line)."""
    return np.asarray(points).reshape(-1, 3).compress(np.asarray(valid).reshape(-1), axis=0)


def _check_sequence(points: np.ndarray, what: str) -> None:
    if not np.isfinite(points).all():
        raise ValueError(f"{what}: a sequence holds only valid (finite) points")


class Range3dLaserIDL(_NodAngles, _RangeHeader):
    """One nodding-laser scan line, static array form (Table 1, every 26.6 ms).

    ``points[i]`` is beam i (right to left, in the scan's angular order); ``valid[i]``
    is false for a beam with no return (beyond range, dazzle), whose point is NaN.
    """

    points: Points = field(unit="m", description="(N, 3) one slot per beam, NaN if invalid")
    valid: Annotated[np.ndarray, Array("bool", (None,))] = field(
        unit="", description="(N,) true where the beam measured a point")

    @model_validator(mode="after")
    def _check(self) -> Range3dLaserIDL:
        _check_static(self.points, self.valid, "Range3dLaserIDL")
        return self

    @property
    def count(self) -> int:
        """Number of valid points."""
        return int(np.count_nonzero(self.valid))

    def valid_points(self) -> np.ndarray:
        """The valid points, ``(count, 3)``, in beam order."""
        return select_valid(self.points, self.valid)

    def to_seq(self) -> Range3dSeqEventIDL:
        """The sequence form of this scan (only the valid points)."""
        return Range3dSeqEventIDL(
            time=self.time, sensorId=self.sensorId, frame=self.frame,
            nodAngleStart=self.nodAngleStart, nodAngleEnd=self.nodAngleEnd,
            points=self.valid_points())


class Range3dSeqEventIDL(_NodAngles, _RangeHeader):
    """One nodding-laser scan line, sequence form (Table 1): only the valid points."""

    points: Points = field(unit="m", description="(n, 3) valid points in beam order")

    @model_validator(mode="after")
    def _check(self) -> Range3dSeqEventIDL:
        _check_sequence(self.points, "Range3dSeqEventIDL")
        return self

    def valid_points(self) -> np.ndarray:
        """The valid points, ``(n, 3)`` (all of a sequence form's points), so consumers
        treat both forms alike."""
        return self.points


class Range3dStereoEventIDL(_RangeHeader):
    """One stereo frame, static array form (Table 3): the disparity image as points.

    ``points[r, c]`` is the point seen by pixel (row r, column c) of the rectified
    reference image, NaN where the disparity was rejected; ``valid[r, c]`` marks the
    pixels with a point. The Raptor runs the Digiclops at 320x240 (ROWS x COLS).
    """

    ROWS: ClassVar[int] = 240
    COLS: ClassVar[int] = 320

    points: Annotated[np.ndarray, Array("float32", (None, None, 3))] = field(
        unit="m", description="(rows, cols, 3) one slot per pixel, NaN if invalid")
    valid: Annotated[np.ndarray, Array("bool", (None, None))] = field(
        unit="", description="(rows, cols) true where the pixel has a point")

    @model_validator(mode="after")
    def _check(self) -> Range3dStereoEventIDL:
        _check_static(self.points, self.valid, "Range3dStereoEventIDL")
        return self

    @property
    def count(self) -> int:
        """Number of valid points."""
        return int(np.count_nonzero(self.valid))

    def valid_points(self) -> np.ndarray:
        """The valid points, ``(count, 3)``, in row-major pixel order."""
        return select_valid(self.points, self.valid)

    def to_array_event(self) -> Range3dArrayEventIDL:
        """The sequence form of this frame (only the valid points)."""
        return Range3dArrayEventIDL(time=self.time, sensorId=self.sensorId,
                                    frame=self.frame, points=self.valid_points())


class Range3dArrayEventIDL(_RangeHeader):
    """A 3-D point set, sequence form (Table 3): only the valid points.

    Despite its name this is the seed's *CORBA sequence* form of a stereo frame (the
    static array form is :class:`Range3dStereoEventIDL`).
    """

    points: Points = field(unit="m", description="(n, 3) valid points")

    @model_validator(mode="after")
    def _check(self) -> Range3dArrayEventIDL:
        _check_sequence(self.points, "Range3dArrayEventIDL")
        return self

    def valid_points(self) -> np.ndarray:
        """The valid points, ``(n, 3)`` (all of a sequence form's points)."""
        return self.points
