"""The Stereo Vision component: Digiclops disparity to 3-D points (seed §3.1.2, Tables 3, 4).

Every ``1 / frameRate`` seconds (2 frames/s by default) the component captures one
disparity image from its :class:`~components.stereo.backends.CameraBackend`, reprojects
it into ``Digiclops:ImagePlane`` (the optical frame of docs/geometry.md: x right, y down,
z along the optical axis), keeps the pixels whose depth ``Z`` is at most ``MaxRange``,
publishes the frame and keeps it for polls.

Forms (Tables 3, 4). Both of the seed's forms have one event name (``EventName``,
``Stereo``), and a subscriber to ``Raptor/Stereo`` cannot pick a body type. The
component therefore publishes only the sequence form, :class:`~idl.Range3dArrayEventIDL`
(the valid points; what the Terrain Map consumes), and builds the static-array form
:class:`~idl.Range3dStereoEventIDL` (240x320 slots with a validity mask) lazily, once
per frame, when ``get3dStereoFullScan`` / ``get3dStereoWaitFullScan`` asks for it.

Why not a PublishServerReactor: the seed derives the component from the PSR pattern
because its ACE reactor schedules the capture timer. afa's PSR base is specifically a
byte-stream reactor (a ``ByteStream`` plus a ``StreamDecoder``), and the Digiclops has no
byte protocol, only a library returning images. The component is a
:class:`~afa.component.SubscribePublishServer` whose main body is the timer loop the
seed describes, and the device seam is the camera backend, opened through
``context.devices.open(name, CameraSpec(...))`` exactly as a PSR opens its port.

Camera loss. If opening fails (no factory is installed: the real Digiclops is not
available to afa; or the backend's ``open`` raises EDevIO) the component reports itself
unhealthy (``no camera: ...``) and retries with :attr:`Stereo.backoff` on its clock. A
capture that raises EDevIO or takes longer than two frame periods (at least 1 s) closes
the backend, reports ``camera lost: ...`` and reopens with the same backoff. The
component itself never fails for a camera problem, like a PSR losing its device.
A recording that ends (:class:`~components.stereo.backends.EndOfRecording`) is not
reopened: the component reports ``end of recording`` and keeps serving the last frame.
"""

from __future__ import annotations

import asyncio
from typing import Any, ClassVar

import numpy as np

from afa.component import SubscribePublishServer
from afa.errors import EDevIO, ETimeOut
from afa.polling import LatestSlot
from afa.reactor import Backoff
from components.stereo.backends import (
    CameraBackend,
    CameraModel,
    CameraSpec,
    DisparityFrame,
    EndOfRecording,
    disparity_to_points,
)
from components.stereo.parameters import StereoParameters
from idl import (
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSensor,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
    TimeIDL,
    select_valid,
)

__all__ = ["Stereo", "StereoScan", "STEREO_FRAME", "STEREO_SENSOR_ID"]

#: The frame stereo points are expressed in (Table A.6 ``DigiclopsFrame``).
STEREO_FRAME = "Digiclops:ImagePlane"
#: ``sensorId`` of stereo events. Table A.2 gives the camera no id (the lasers have
#: 11 and 12); 0 marks "the stereo camera"; consumers should rely on ``frame``.
STEREO_SENSOR_ID = 0


class StereoScan:
    """One processed frame: the sequence form, and the static-array form on demand."""

    __slots__ = ("array_event", "_points", "_valid", "_static")

    def __init__(self, time: TimeIDL, points: np.ndarray, valid: np.ndarray,
                 sensor_id: int = STEREO_SENSOR_ID, frame: str = STEREO_FRAME) -> None:
        self._points = points
        self._valid = valid
        self._static: Range3dStereoEventIDL | None = None
        selected = select_valid(points, valid)
        selected.flags.writeable = False  # a fresh array: the IDL need not copy it again
        self.array_event = Range3dArrayEventIDL(time=time, sensorId=sensor_id, frame=frame,
                                                points=selected)

    @property
    def count(self) -> int:
        """Number of valid points."""
        return int(self.array_event.points.shape[0])

    def stereo_event(self) -> Range3dStereoEventIDL:
        """The static-array form (built at the first call, then cached)."""
        if self._static is None:
            a = self.array_event
            self._static = Range3dStereoEventIDL(time=a.time, sensorId=a.sensorId,
                                                 frame=a.frame, points=self._points,
                                                 valid=self._valid)
        return self._static


class Stereo(SubscribePublishServer[StereoParameters]):
    """Publishes ``Raptor/<EventName>`` (:class:`~idl.Range3dArrayEventIDL`) at
    ``frameRate`` and serves :class:`~idl.Range3dSensor` under ``EventName``.

    The four laser methods of the shared interface raise EDevIO; the stereo methods
    raise EDevIO before the first frame (``get``) or ETimeOut after the interface's
    5 s (``getWait``).
    """

    #: Reopen delays after a camera failure (clock seconds).
    backoff: ClassVar[Backoff] = Backoff(initial=0.5, factor=2.0, maximum=10.0)
    #: The camera the component asks for (the seed runs the Digiclops at 320x240).
    camera_model_name: ClassVar[str] = "PointGreyDigiclops"

    def __init__(self, name: str, parameters: StereoParameters | None = None) -> None:
        super().__init__(name, parameters)
        self.events = self.publishes(self.parameters.EventName, Range3dArrayEventIDL)
        self.serves(Range3dSensor, self.parameters.EventName)
        self.latest: LatestSlot[StereoScan] | None = None
        self.backend: CameraBackend | None = None
        self._counters = {"frames": 0, "points": 0, "opens": 0, "open_failures": 0,
                          "camera_failures": 0}

    # -- configuration -----------------------------------------------------------------
    def camera_spec(self) -> CameraSpec:
        """What to ask ``context.devices`` for."""
        return CameraSpec(self.camera_model_name, Range3dStereoEventIDL.COLS,
                          Range3dStereoEventIDL.ROWS, self.parameters.frameRate)

    @property
    def period(self) -> float:
        """Seconds between frames (``1 / frameRate``)."""
        return 1.0 / self.parameters.frameRate

    @property
    def capture_timeout(self) -> float:
        """A capture slower than this counts as a lost camera."""
        return max(1.0, 2.0 * self.period)

    @property
    def max_depth(self) -> float:
        """``MaxRange`` in metres."""
        return self.parameters.MaxRange / 1000.0

    # -- lifecycle ---------------------------------------------------------------------
    async def setup(self) -> None:
        self.latest = self.slot("stereo frame")
        self.set_health(False, "opening the camera")  # healthy once a frame has arrived

    async def run(self) -> None:
        """Open the camera, capture at ``frameRate``; on failure reopen with backoff."""
        attempt = 0
        while True:
            backend = await self._open_camera()
            if backend is None:
                await self.clock.sleep(self.backoff.delay(attempt))
                attempt += 1
                continue
            attempt = 0
            try:
                await self._capture_loop(backend)
            except EndOfRecording as exc:
                self.set_health(False, f"end of recording: {exc}")
                await asyncio.Event().wait()  # keep serving the last frame until stopped
            except (EDevIO, ETimeOut) as exc:
                self._counters["camera_failures"] += 1
                self.set_health(False, f"camera lost: {exc}")
            finally:
                self.backend = None
                backend.close()
            await self.clock.sleep(self.backoff.delay(attempt))
            attempt += 1

    async def teardown(self) -> None:
        if self.backend is not None:
            self.backend.close()
            self.backend = None

    async def _open_camera(self) -> CameraBackend | None:
        spec = self.camera_spec()
        try:
            backend: CameraBackend = await self.context.devices.open(self.name, spec)
            await backend.open()
            model = backend.model
            if (model.width, model.height) != (spec.width, spec.height):
                backend.close()
                raise EDevIO(f"the camera delivers {model.width}x{model.height}, "
                             f"expected {spec.width}x{spec.height}")
        except EDevIO as exc:
            self._counters["open_failures"] += 1
            self.set_health(False, f"no camera: {exc}")
            return None
        self._counters["opens"] += 1
        self.backend = backend
        self.set_health(False, "camera open, no frame yet")
        return backend

    async def _capture_loop(self, backend: CameraBackend) -> None:
        model = backend.model
        async for _tick in self.clock.periodic(self.period):
            async with self.clock.timeout(self.capture_timeout, "stereo capture"):
                frame = await backend.capture()
            self._integrate(frame, model)

    def _integrate(self, frame: DisparityFrame, model: CameraModel) -> None:
        """Reproject, publish and store one frame; raises EDevIO for a malformed one."""
        try:
            points, valid = disparity_to_points(frame.disparity, model, self.max_depth)
        except ValueError as exc:
            raise EDevIO(f"bad frame from the camera: {exc}") from exc
        scan = StereoScan(TimeIDL.from_seconds(frame.time), points, valid)
        if not self.health().healthy:
            self.set_health(True, "receiving frames")
        self._counters["frames"] += 1
        self._counters["points"] = scan.count
        assert self.latest is not None
        self.latest.set(scan)
        self.events.publish(scan.array_event)

    def statistics(self) -> dict[str, Any]:
        """Frames processed, valid points in the last frame, camera opens and failures."""
        stats = super().statistics()
        stats.update(self._counters)
        return stats

    # -- Range3dSensor: stereo ---------------------------------------------------------
    def _slot(self) -> LatestSlot[StereoScan]:
        if self.latest is None:
            raise EDevIO(f"{self.name} is not running")
        return self.latest

    async def get3dStereoFullScan(self) -> Range3dStereoEventIDL:
        """The latest frame, static array form; EDevIO before the first frame."""
        return self._slot().get().stereo_event()

    async def get3dStereoWaitFullScan(self) -> Range3dStereoEventIDL:
        """The next frame, static array form; ETimeOut after Range3dSensor.wait_timeout."""
        return (await self._slot().wait_next(Range3dSensor.wait_timeout)).stereo_event()

    async def get3dArrayFullScan(self) -> Range3dArrayEventIDL:
        """The latest frame, sequence form; EDevIO before the first frame."""
        return self._slot().get().array_event

    async def get3dArrayWaitFullScan(self) -> Range3dArrayEventIDL:
        """The next frame, sequence form; ETimeOut after Range3dSensor.wait_timeout."""
        return (await self._slot().wait_next(Range3dSensor.wait_timeout)).array_event

    # -- Range3dSensor: laser (not this sensor) ----------------------------------------
    def _no_laser(self) -> EDevIO:
        return EDevIO(f"{self.name}: this sensor produces no laser scans")

    async def get3dLaserFullScan(self) -> Range3dLaserIDL:
        """Always EDevIO: the stereo camera produces no laser scans."""
        raise self._no_laser()

    async def get3dLaserWaitFullScan(self) -> Range3dLaserIDL:
        """Always EDevIO: the stereo camera produces no laser scans."""
        raise self._no_laser()

    async def get3dSeqFullScan(self) -> Range3dSeqEventIDL:
        """Always EDevIO: the stereo camera produces no laser scans."""
        raise self._no_laser()

    async def get3dSeqWaitFullScan(self) -> Range3dSeqEventIDL:
        """Always EDevIO: the stereo camera produces no laser scans."""
        raise self._no_laser()
