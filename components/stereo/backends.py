"""Camera backends of the Stereo Vision component: the seam in place of a byte codec.

The Digiclops talks to its host over IEEE 1394 through Point Grey's closed Digiclops
and Triclops libraries; there is no public wire protocol to re-implement. The driver
is therefore written against a small :class:`CameraBackend` protocol that delivers
rectified *disparity images* plus the pinhole :class:`CameraModel` needed to turn them
into 3-D points. Two backends are provided:

- :class:`RecordedBackend` replays frames from a ``.npz`` recording (format below,
  written by :func:`write_recording`);
- :class:`SyntheticBackend` renders a depth image with a callable (the simulator passes
  its ray caster; the default is an analytic flat ground plane), converts it to
  disparity ``d = f·B / Z``, adds optional seeded noise and quantises to 1/16 pixel as
  real block-matching stereo does.

The component opens a backend through ``context.devices.open(name, CameraSpec(...))``;
a test or simulator installs the factory (``System(devices={"Stereo": ...})``).

Recording format (``.npz``, read with ``allow_pickle=False``):

=================  =========================  ========================================
key                dtype / shape              meaning
=================  =========================  ========================================
``disparity``      float32 (N, rows, cols)    disparity in pixels, NaN = no match
``times``          float64 (N,)               capture times, clock seconds
``focal_px``       float64 ()                 focal length, pixels
``baseline_m``     float64 ()                 stereo baseline, metres
``cx``, ``cy``     float64 ()                 principal point (column, row), pixels
``format``         str ()                     ``"afa-disparity-1"``
=================  =========================  ========================================

Pixel coordinates are array indices: pixel (row v, column u) has its centre at (u, v),
so a principal point in the middle of a 320x240 image is (159.5, 119.5).
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from afa.clock import Clock
from afa.errors import EDevIO

__all__ = [
    "CameraSpec", "CameraModel", "DisparityFrame", "CameraBackend", "RecordedBackend",
    "SyntheticBackend", "EndOfRecording", "write_recording", "flat_ground", "disparity_to_points",
    "serve_camera", "DIGICLOPS_MODEL", "RECORDING_FORMAT", "DISPARITY_QUANTUM",
]

#: ``format`` key of a recording written by :func:`write_recording`.
RECORDING_FORMAT = "afa-disparity-1"
#: Sub-pixel step of the synthetic disparity (OpenCV StereoBM/SGBM: 4 fractional bits).
DISPARITY_QUANTUM = 1.0 / 16.0

Float32Image = NDArray[np.float32]
DepthRenderer = Callable[[float], NDArray[np.floating]]


@dataclass(frozen=True, slots=True)
class CameraSpec:
    """What the Stereo component asks ``context.devices`` to open.

    There is no real opener for it in afa (the Digiclops needs Point Grey's libraries):
    without an installed factory :meth:`afa.transport.DeviceOpener.open` raises EDevIO.
    """

    model: str = "PointGreyDigiclops"
    width: int = 320
    height: int = 240
    frame_rate: float = 2.0


@dataclass(frozen=True, slots=True)
class CameraModel:
    """The rectified reference camera: a pinhole with a stereo baseline.

    ``focal_px`` and ``cx``, ``cy`` are in pixels of the ``width`` x ``height`` disparity
    image; ``baseline_m`` is the distance between the optical centres of the matched pair.
    Raises ValueError for non-positive sizes or non-finite values.
    """

    width: int
    height: int
    focal_px: float
    baseline_m: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        if not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise ValueError(f"focal_px must be positive, got {self.focal_px}")
        if not (math.isfinite(self.baseline_m) and self.baseline_m > 0):
            raise ValueError(f"baseline_m must be positive, got {self.baseline_m}")
        if not (math.isfinite(self.cx) and math.isfinite(self.cy)):
            raise ValueError("the principal point must be finite")

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float, baseline_m: float) -> CameraModel:
        """A centred pinhole with horizontal field of view ``hfov_deg`` (square pixels),
        the model :func:`afa.sim.raycast.camera_directions` uses."""
        if not 0 < hfov_deg < 180:
            raise ValueError(f"hfov_deg must be in (0, 180), got {hfov_deg}")
        focal = 0.5 * width / math.tan(math.radians(hfov_deg) / 2)
        return cls(width, height, focal, baseline_m, (width - 1) / 2, (height - 1) / 2)

    @property
    def fb(self) -> float:
        """``focal_px * baseline_m``: depth (m) times disparity (px) is this constant."""
        return self.focal_px * self.baseline_m


#: afa's default Digiclops model at the Raptor's 320x240: 10 cm baseline and a 66°
#: horizontal field of view (f = 246.4 px), the simulator's default camera. These are
#: estimates for the 3.8 mm-lens class head, not a Point Grey calibration file.
DIGICLOPS_MODEL = CameraModel.from_fov(320, 240, 66.0, 0.10)


@dataclass(frozen=True, eq=False)
class DisparityFrame:
    """One rectified disparity image (float32 pixels, NaN = no match) and its capture
    time (clock seconds). Raises ValueError for a non-2-D image or a non-finite time."""

    disparity: Float32Image
    time: float
    sequence: int = field(default=0)

    def __post_init__(self) -> None:
        image = np.asarray(self.disparity, dtype=np.float32)
        if image.ndim != 2:
            raise ValueError(f"disparity must be 2-D, got shape {image.shape}")
        if not math.isfinite(self.time):
            raise ValueError(f"capture time must be finite, got {self.time!r}")
        image = image.copy() if image is self.disparity else image
        image.flags.writeable = False
        object.__setattr__(self, "disparity", image)


@runtime_checkable
class CameraBackend(Protocol):
    """What the Stereo component needs from a camera.

    ``open`` and ``capture`` raise :class:`~afa.errors.EDevIO` when the camera fails;
    ``close`` never raises and may be called more than once.
    """

    @property
    def model(self) -> CameraModel: ...

    async def open(self) -> None: ...

    async def capture(self) -> DisparityFrame: ...

    def close(self) -> None: ...


def disparity_to_points(disparity: NDArray[np.floating], model: CameraModel,
                        max_depth: float) -> tuple[Float32Image, NDArray[np.bool_]]:
    """Reproject a disparity image into the optical frame (x right, y down, z forward).

    ``Z = f·B/d``, ``X = (u - cx)·Z/f``, ``Y = (v - cy)·Z/f`` for pixel (row v, column
    u). A pixel is valid when its disparity is finite and positive and ``Z <= max_depth``
    (metres). Returns ``(points, valid)``: float32 (rows, cols, 3) with NaN in every
    invalid slot, and the (rows, cols) mask. Raises ValueError if the image's shape is
    not the model's.
    """
    d = np.asarray(disparity, dtype=np.float32)
    if d.shape != (model.height, model.width):
        raise ValueError(f"disparity image is {d.shape[::-1]} (cols, rows), the camera model "
                         f"says {model.width}x{model.height}")
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.float32(model.fb) / d  # NaN stays NaN; 0 and negative are rejected below
        valid = (d > 0) & (z <= max_depth)  # comparisons with NaN are False
    z[~valid] = np.nan
    across, down = _pixel_slopes(model)
    points = np.empty((model.height, model.width, 3), dtype=np.float32)
    np.multiply(across, z, out=points[..., 0])
    np.multiply(down, z, out=points[..., 1])
    points[..., 2] = z
    return points, valid


@functools.lru_cache(maxsize=8)
def _pixel_slopes(model: CameraModel) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """``(u - cx) / f`` as a row and ``(v - cy) / f`` as a column, float32."""
    across = ((np.arange(model.width) - model.cx) / model.focal_px).astype(np.float32)
    down = ((np.arange(model.height) - model.cy) / model.focal_px).astype(np.float32)
    return across[np.newaxis, :], down[:, np.newaxis]


def flat_ground(model: CameraModel, height: float = 1.83, pitch_deg: float = 10.0
                ) -> Callable[[float], NDArray[np.float64]]:
    """A renderer of level ground ``height`` metres below the optical centre, the camera
    pitched ``pitch_deg`` down (docs/geometry.md: ``Digiclops:ImagePlane`` is 1.83 m
    above ground, pitched 10° down). Pixels above the horizon see nothing (NaN).

    In the optical frame the downward vertical is ``g = (0, cos θ, sin θ)``; the ray
    through pixel (v, u) is ``r = ((u-cx)/f, (v-cy)/f, 1)`` (z = 1), which meets the
    ground at depth ``Z = h / (g·r)`` when ``g·r > 0``.
    """
    theta = math.radians(pitch_deg)
    v = (np.arange(model.height, dtype=np.float64) - model.cy) / model.focal_px
    down = math.cos(theta) * v + math.sin(theta)
    with np.errstate(divide="ignore"):
        column = np.where(down > 0, height / np.where(down > 0, down, 1.0), np.nan)
    depth = np.repeat(column[:, np.newaxis], model.width, axis=1)
    depth.flags.writeable = False

    def render(t: float) -> NDArray[np.float64]:
        return depth

    return render


class SyntheticBackend:
    """A camera that renders depth with ``render(t)`` and reports what stereo matching
    would: ``d = f·B/Z`` plus optional Gaussian noise (``noise_px``, drawn from ``rng``),
    quantised to ``quantum`` pixels. Disparities below one quantum (too far) or above
    ``max_disparity`` (closer than the search range reaches) are NaN, as a matcher
    rejects them. ``unplug()``/``plug()`` simulate a lost camera: meanwhile ``open``
    and ``capture`` raise EDevIO.
    """

    def __init__(self, clock: Clock, model: CameraModel = DIGICLOPS_MODEL,
                 render: DepthRenderer | None = None, *, noise_px: float = 0.0,
                 rng: np.random.Generator | None = None, quantum: float = DISPARITY_QUANTUM,
                 max_disparity: float = 64.0) -> None:
        if noise_px < 0 or quantum <= 0 or max_disparity <= 0:
            raise ValueError("noise_px must be >= 0, quantum and max_disparity positive")
        self.clock = clock
        self._model = model
        self.render = render or flat_ground(model)
        self.noise_px = noise_px
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.quantum = quantum
        self.max_disparity = max_disparity
        self.plugged = True
        self.is_open = False
        self.captures = 0

    @property
    def model(self) -> CameraModel:
        return self._model

    def unplug(self) -> None:
        """Make the camera fail until :meth:`plug`."""
        self.plugged = False
        self.is_open = False

    def plug(self) -> None:
        self.plugged = True

    async def open(self) -> None:
        """Raises EDevIO while unplugged."""
        if not self.plugged:
            raise EDevIO("camera unplugged")
        self.is_open = True

    async def capture(self) -> DisparityFrame:
        """The frame seen now; raises EDevIO if not open, unplugged, or the renderer
        returns the wrong shape."""
        if not (self.plugged and self.is_open):
            raise EDevIO("camera unplugged" if not self.plugged else "camera not open")
        now = self.clock.now()
        depth = np.asarray(self.render(now), dtype=np.float64)
        shape = (self._model.height, self._model.width)
        if depth.shape != shape:
            raise EDevIO(f"renderer returned shape {depth.shape}, expected {shape}")
        self.captures += 1
        return DisparityFrame(self.depth_to_disparity(depth), now, self.captures)

    def depth_to_disparity(self, depth: NDArray[np.floating]) -> Float32Image:
        """Disparity in pixels for a depth image (m), quantised; NaN where unmatched."""
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.float32(self._model.fb) / np.asarray(depth, dtype=np.float32)
        if self.noise_px > 0:
            d += self.rng.normal(0.0, self.noise_px, d.shape).astype(np.float32)
        step = np.float32(self.quantum)
        with np.errstate(invalid="ignore"):
            np.divide(d, step, out=d)
            np.round(d, out=d)
            np.multiply(d, step, out=d)
            matched = (d >= step) & (d <= self.max_disparity)  # False for NaN and inf
        d[~matched] = np.nan
        return d

    def close(self) -> None:
        self.is_open = False


class EndOfRecording(EDevIO):
    """A recording without ``loop`` has no more frames."""


class RecordedBackend:
    """Replays a recording written by :func:`write_recording`.

    Frames come out in order, one per ``capture``. Their time is the recorded time,
    or ``clock.now()`` when a ``clock`` is given (live replay). At the end it starts
    again if ``loop``, else raises :class:`EndOfRecording` (an EDevIO). A looped
    replay with recorded times repeats them; pass a clock for monotonic times.
    """

    def __init__(self, path: str | os.PathLike[str], *, loop: bool = False,
                 clock: Clock | None = None) -> None:
        self.path = Path(path)
        self.loop = loop
        self.clock = clock
        self._frames: NDArray[np.float32] | None = None
        self._times: NDArray[np.float64] | None = None
        self._model: CameraModel | None = None
        self._next = 0
        self.captures = 0

    @property
    def model(self) -> CameraModel:
        """The recording's camera model; raises EDevIO before :meth:`open`."""
        if self._model is None:
            raise EDevIO(f"{self.path}: recording not open")
        return self._model

    async def open(self) -> None:
        """Load the file (from the start); raises EDevIO if it is missing or malformed."""
        self._frames, self._times, self._model = read_recording(self.path)
        self._next = 0

    async def capture(self) -> DisparityFrame:
        """The next recorded frame; raises EDevIO if not open, EndOfRecording at the end."""
        if self._frames is None or self._times is None:
            raise EDevIO(f"{self.path}: recording not open")
        if self._next >= len(self._frames):
            if not self.loop or len(self._frames) == 0:
                raise EndOfRecording(f"{self.path}: end of recording after "
                                     f"{len(self._frames)} frames")
            self._next = 0
        index = self._next
        self._next += 1
        self.captures += 1
        time = float(self._times[index]) if self.clock is None else self.clock.now()
        return DisparityFrame(self._frames[index], time, self.captures)

    def close(self) -> None:
        self._frames = self._times = None


def write_recording(path: str | os.PathLike[str], frames: Sequence[DisparityFrame],
                    model: CameraModel) -> None:
    """Write ``frames`` and ``model`` as an ``.npz`` recording (format in the module
    docstring). Raises ValueError if a frame's shape is not the model's; OSError if the
    file cannot be written."""
    shape = (model.height, model.width)
    for frame in frames:
        if frame.disparity.shape != shape:
            raise ValueError(f"frame {frame.sequence} has shape {frame.disparity.shape}, "
                             f"the model says {shape}")
    disparity = (np.stack([f.disparity for f in frames]).astype(np.float32) if frames
                 else np.empty((0, *shape), dtype=np.float32))
    with open(path, "wb") as out:  # a file object keeps numpy from appending ".npz"
        np.savez_compressed(
            out, disparity=disparity,
            times=np.array([f.time for f in frames], dtype=np.float64),
            focal_px=np.float64(model.focal_px), baseline_m=np.float64(model.baseline_m),
            cx=np.float64(model.cx), cy=np.float64(model.cy),
            format=np.array(RECORDING_FORMAT))


def read_recording(path: str | os.PathLike[str]
                   ) -> tuple[NDArray[np.float32], NDArray[np.float64], CameraModel]:
    """Read a recording: ``(disparity (N, rows, cols), times (N,), model)``. Raises
    EDevIO if the file is missing, not a recording, or inconsistent."""
    try:  # (our own handle: np.load leaves its file open when the archive is broken)
        with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as data:
            fmt = str(data["format"])
            disparity = np.asarray(data["disparity"], dtype=np.float32)
            times = np.asarray(data["times"], dtype=np.float64)
            scalars = {k: float(data[k]) for k in ("focal_px", "baseline_m", "cx", "cy")}
    except Exception as exc:  # a damaged archive fails in zipfile, zlib, numpy's header
        # parser or a conversion: whatever it is, the file is not a usable recording
        raise EDevIO(f"{path}: cannot read the recording: {type(exc).__name__}: {exc}"
                     ) from exc
    if fmt != RECORDING_FORMAT:
        raise EDevIO(f"{path}: format {fmt!r}, expected {RECORDING_FORMAT!r}")
    if disparity.ndim != 3 or times.shape != (disparity.shape[0],):
        raise EDevIO(f"{path}: disparity {disparity.shape} and times {times.shape} disagree")
    if not (np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)):
        raise EDevIO(f"{path}: frame times must be finite and increasing")
    try:
        model = CameraModel(disparity.shape[2], disparity.shape[1], **scalars)
    except ValueError as exc:
        raise EDevIO(f"{path}: bad camera model: {exc}") from exc
    return disparity, times, model


def serve_camera(backend: CameraBackend) -> Callable[[object], Awaitable[CameraBackend]]:
    """A device factory for ``System(devices={name: ...})`` that hands out ``backend``
    for every open (the component opens and closes it)."""

    async def factory(spec: object) -> CameraBackend:
        return backend

    return factory
