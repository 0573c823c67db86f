"""A small system recorded with afa.log, for the tools' ``--log`` mode."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from afa import Client, SubscribePublishServer, System, VirtualClock
from idl import (
    Platform,
    PoseTransformIDL,
    Range3dSeqEventIDL,
    StringSequenceIDL,
    TimeIDL,
)

LASER_FRAME = "FrontNoddingSICKLeft:Base"


class Laser(SubscribePublishServer):
    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.scans = self.publishes("Laser11", Range3dSeqEventIDL)

    async def run(self) -> None:
        points = np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], dtype=np.float32)
        async for _ in self.clock.periodic(0.1, first=self.clock.monotonic() + 0.1):
            self.scans.publish(Range3dSeqEventIDL(
                time=TimeIDL.from_seconds(self.clock.now()), sensorId=11, frame=LASER_FRAME,
                points=points))


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


async def record(path: Path, seconds: float = 2.0) -> None:
    from afa.log.recorder import Recorder

    system = System([Model("model"), Laser("laser"), Display("display")],
                    clock=VirtualClock(start=0.0))
    recorder = Recorder(path, viewer=False).attach(system)
    async with system:
        await system.run(seconds)
        await recorder.close()
