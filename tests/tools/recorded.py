"""A small system recorded with afa.log, for the tools' ``--log`` mode."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from afa import Client, SubscribePublishServer, System, VirtualClock
from afa.errors import EDevIO
from idl import (
    Platform,
    PoseTransformIDL,
    Range3dSensor,
    Range3dSeqEventIDL,
    StringSequenceIDL,
    TimeIDL,
)

LASER_FRAME = "FrontNoddingSICKLeft:Base"


class Laser(SubscribePublishServer):
    """Two points ten times a second, the second point 0.1 m further each scan (so that
    each scan is told apart); serves Range3dSensor as ``Laser11`` in the sequence form
    only (the other forms: EDevIO, as a real sensor of the other kind)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.scans = self.publishes("Laser11", Range3dSeqEventIDL)
        self.serves(Range3dSensor, "Laser11")
        self.latest: Range3dSeqEventIDL | None = None

    async def run(self) -> None:
        scan = 0
        async for _ in self.clock.periodic(0.1, first=self.clock.monotonic() + 0.1):
            scan += 1
            points = np.array([[1.0, 0.0, 0.0], [2.0 + 0.1 * scan, 0.0, 0.0]],
                              dtype=np.float32)
            self.latest = Range3dSeqEventIDL(
                time=TimeIDL.from_seconds(self.clock.now()), sensorId=11, frame=LASER_FRAME,
                points=points)
            self.scans.publish(self.latest)

    async def get3dSeqFullScan(self) -> Range3dSeqEventIDL:
        if self.latest is None:
            raise EDevIO("no scan yet")
        return self.latest

    async def _other_form(self) -> Any:
        raise EDevIO("a nodding laser in the sequence form only")

    get3dLaserFullScan = get3dLaserWaitFullScan = get3dSeqWaitFullScan = _other_form
    get3dStereoFullScan = get3dStereoWaitFullScan = _other_form
    get3dArrayFullScan = get3dArrayWaitFullScan = _other_form


class Model(SubscribePublishServer):
    """Platform: the laser's mount 0.5 m ahead of and 1 m above the rear axle."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.serves(Platform, "ModelService")

    def _pose(self, transform: np.ndarray) -> PoseTransformIDL:
        return PoseTransformIDL(time=TimeIDL.from_seconds(self.clock.now()),
                                HTransform=transform, initialUTM=np.zeros(3),
                                poseValidFlag=True)

    async def getTransformation(self, A: str, B: str) -> PoseTransformIDL:
        transform = np.eye(4)
        transform[:3, 3] = (0.5, 0.0, 1.0)
        return self._pose(transform)

    async def getBodyList(self) -> StringSequenceIDL:
        return StringSequenceIDL(values=("Raptor",))

    async def getBodyFrameList(self, body: str) -> StringSequenceIDL:
        return StringSequenceIDL(values=("Base",))

    async def getPose(self) -> PoseTransformIDL:
        return self._pose(np.eye(4))

    async def getWaitPose(self) -> PoseTransformIDL:
        return self._pose(np.eye(4))


class Display(Client):
    """Asks for the laser's mount once, as the seed's QtRange3dSensor did (Table 28)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.platform = self.uses(Platform, "ModelService")

    async def run(self) -> None:
        await self.bound(self.platform)
        await self.platform.getTransformation("Raptor:RearAxleCenter", LASER_FRAME)


async def record(path: Path, seconds: float = 2.0, *, display: bool = True,
                 viewer: bool = False) -> None:
    """Record ``seconds`` of the laser and the model (and the display, which polls the
    laser's mount once; ``viewer``: with the viewer channels, whose geometry the
    recorder asks the model for)."""
    from afa.log.recorder import Recorder

    parts = [Model("model"), Laser("laser"), *([Display("display")] if display else [])]
    system = System(parts, clock=VirtualClock(start=0.0))
    recorder = Recorder(path, viewer=viewer).attach(system)
    async with system:
        await system.run(seconds)
        await recorder.close()
