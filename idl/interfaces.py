# mypy: disable-error-code="empty-body"
"""Polled interfaces, with the seed's method names (Tables 2, 4, 6, 8, 10, 12, 16, 18,
19, 24, 26, 31-33).

Conventions:

- ``getX()`` returns the latest sample at once; a server with no sample yet raises
  ``EDevIO``. ``getWaitX()`` returns the next sample stored after the call, or raises
  ``ETimeOut`` after the interface's ``wait_timeout`` (Miro's deadlines: odometry
  1 s, range sensors 0.5 s, laser 5 s, GPS 10 s).
- ``call_timeout`` (the client's deadline for any call) is raised above
  ``wait_timeout`` where the default 5 s would cut a ``getWait…`` short.
- Miro's ``boolean f(out T x)`` becomes ``f() -> T | None``: ``None`` is Miro's
  ``false``. ``void f(out a, out b, …)`` becomes a result struct
  (:class:`~idl.vehicle.MinMaxVelocityIDL`).
- A server implements every method of the interface it serves; a method whose data
  it does not produce (a laser asked for a stereo frame) raises ``EDevIO``.
"""

from __future__ import annotations

from typing import ClassVar

from idl._base import Interface
from idl.common import PoseTransformIDL, Position3DIDL, StringSequenceIDL
from idl.maps import (
    EgoMapArrayEventIDL,
    EgoMapSeqEventIDL,
    EtravMapArrayEventIDL,
    MapArrayEventIDL,
    MapSeqEventIDL,
    PlanMapEventIDL,
    TravMapArrayEventIDL,
)
from idl.planning import Cost, PlanningBoundaryIDL, PlanPointIDL, WaypointGroupIDL, WaypointIDL
from idl.range import (
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
)
from idl.sensors import GpsIDL, ImuIDL, WheelDataIDL
from idl.vehicle import MinMaxVelocityIDL, VelocityIDL

__all__ = [
    "Range3dSensor",
    "Imu",
    "Gps",
    "Odometry",
    "Map",
    "TravMap",
    "GlobalMap",
    "Platform",
    "VehiclePlan",
    "VehicleControl",
]

_MARGIN = 2.0  # seconds a client waits beyond a server's getWait deadline


class Range3dSensor(Interface):
    """3-D range sensors: Nodding Laser and Stereo Vision (Tables 2, 4, 31).

    One interface for both sensors, as Table 31 polls ``NodLaser`` for every form.
    ``wait_timeout`` is Miro's laser deadline (5 s), which also covers the stereo
    camera's 2 s default period (Miro's 0.5 s range-sensor deadline would not).
    """

    wait_timeout: ClassVar[float] = 5.0
    call_timeout: ClassVar[float] = 5.0 + _MARGIN

    async def get3dLaserFullScan(self) -> Range3dLaserIDL:
        """The latest laser scan line, static array form."""
        ...

    async def get3dLaserWaitFullScan(self) -> Range3dLaserIDL:
        """The next laser scan line, static array form; ETimeOut after wait_timeout."""
        ...

    async def get3dSeqFullScan(self) -> Range3dSeqEventIDL:
        """The latest laser scan line, sequence form (valid points only)."""
        ...

    async def get3dSeqWaitFullScan(self) -> Range3dSeqEventIDL:
        """The next laser scan line, sequence form; ETimeOut after wait_timeout."""
        ...

    async def get3dStereoFullScan(self) -> Range3dStereoEventIDL:
        """The latest stereo frame, static array form."""
        ...

    async def get3dStereoWaitFullScan(self) -> Range3dStereoEventIDL:
        """The next stereo frame, static array form; ETimeOut after wait_timeout."""
        ...

    async def get3dArrayFullScan(self) -> Range3dArrayEventIDL:
        """The latest stereo frame, sequence form (Table 4 misprints it as
        ``Range3dArrayEventIDL()``; Table 31 names it)."""
        ...

    async def get3dArrayWaitFullScan(self) -> Range3dArrayEventIDL:
        """The next stereo frame, sequence form; ETimeOut after wait_timeout."""
        ...


class Imu(Interface):
    """The IMU (Table 6); ``getWaitImuData`` added in Miro's get/getWait pattern."""

    wait_timeout: ClassVar[float] = 1.0

    async def getImuData(self) -> ImuIDL:
        """The latest orientation, acceleration and rate sample."""
        ...

    async def getWaitImuData(self) -> ImuIDL:
        """The next IMU sample; ETimeOut after wait_timeout."""
        ...


class Gps(Interface):
    """The GPS (Table 8); ``getWaitPosition`` as in Miro's Gps interface (10 s)."""

    wait_timeout: ClassVar[float] = 10.0
    call_timeout: ClassVar[float] = 10.0 + _MARGIN

    async def getPosition(self) -> GpsIDL:
        """The latest GPS fix."""
        ...

    async def getWaitPosition(self) -> GpsIDL:
        """The next GPS fix; ETimeOut after wait_timeout."""
        ...


class Odometry(Interface):
    """Wheel odometry (Table 10); ``getWaitWheelData`` added (Miro odometry: 1 s)."""

    wait_timeout: ClassVar[float] = 1.0

    async def getWheelData(self) -> WheelDataIDL:
        """The latest wheel distances, speeds and steering angle."""
        ...

    async def getWaitWheelData(self) -> WheelDataIDL:
        """The next odometry report; ETimeOut after wait_timeout."""
        ...


class Map(Interface):
    """The Terrain Map (Tables 12, 32, 33). Ego methods return the Ego types
    (Table 12 prints the global types for them; Table 33 has the Ego ones)."""

    wait_timeout: ClassVar[float] = 5.0
    call_timeout: ClassVar[float] = 5.0 + _MARGIN

    async def getMapArray(self) -> MapArrayEventIDL:
        """The latest global terrain map, static array form."""
        ...

    async def getWaitMapArray(self) -> MapArrayEventIDL:
        """The next global terrain map, static array form; ETimeOut after wait_timeout."""
        ...

    async def getMapSeq(self) -> MapSeqEventIDL:
        """The latest global terrain map, sequence form (known cells)."""
        ...

    async def getWaitMapSeq(self) -> MapSeqEventIDL:
        """The next global terrain map, sequence form; ETimeOut after wait_timeout."""
        ...

    async def getEgoMapArray(self) -> EgoMapArrayEventIDL:
        """The latest egocentric terrain map, static array form."""
        ...

    async def getWaitEgoMapArray(self) -> EgoMapArrayEventIDL:
        """The next egocentric terrain map, static array form; ETimeOut after
        wait_timeout."""
        ...

    async def getEgoMapSeq(self) -> EgoMapSeqEventIDL:
        """The latest egocentric terrain map, sequence form (Table 33 misprints it as
        ``getEgoSeqArray``)."""
        ...

    async def getWaitEgoMapSeq(self) -> EgoMapSeqEventIDL:
        """The next egocentric terrain map, sequence form; ETimeOut after wait_timeout."""
        ...


class TravMap(Interface):
    """The Traversability Map (Table 16)."""

    wait_timeout: ClassVar[float] = 5.0
    call_timeout: ClassVar[float] = 5.0 + _MARGIN

    async def getTravMapArray(self) -> TravMapArrayEventIDL:
        """The latest global traversability map."""
        ...

    async def getWaitTravMapArray(self) -> TravMapArrayEventIDL:
        """The next global traversability map; ETimeOut after wait_timeout."""
        ...

    async def getEtravMapArray(self) -> EtravMapArrayEventIDL:
        """The latest egocentric traversability map."""
        ...

    async def getWaitEtravMapArray(self) -> EtravMapArrayEventIDL:
        """The next egocentric traversability map; ETimeOut after wait_timeout."""
        ...


class GlobalMap(Interface):
    """The Global Map's planning interface for FindPath (Table 18, §3.2.3).

    Planning node (x, y) is cell [x, y] of the plan map; see :mod:`idl.planning`.
    """

    async def valid(self, p: PlanPointIDL) -> bool:
        """True if node p is inside the planning grid and boundary, and reachable."""
        ...

    async def getPlanningMap(self, p: PlanPointIDL) -> Cost:
        """The a priori cost of entering node p from a neighbour (inf = impassable)."""
        ...

    async def getSensingMap(self, p: PlanPointIDL) -> Cost:
        """The sensed cost of entering node p from a neighbour (inf = impassable)."""
        ...

    async def setPlanningMap(self, p: PlanPointIDL) -> bool:
        """Set node p's a priori cost to ``p.aPrioriCost``; false if p is outside."""
        ...

    async def setSensingMap(self, p: PlanPointIDL) -> bool:
        """Set node p's sensed cost to ``p.sensedCost``; false if p is outside."""
        ...

    async def getMap(self, p: PlanPointIDL) -> PlanPointIDL:
        """The full PlanPointIDL stored at node (p.x, p.y); EOutOfBounds if outside."""
        ...

    async def setMap(self, p: PlanPointIDL) -> bool:
        """Store p at node (p.x, p.y); false if p is outside the grid."""
        ...

    async def getTransformToPlanningFromWorld(self) -> PoseTransformIDL:
        """^P T_W: world metres to planning-grid units (scale 1/gridsize included)."""
        ...

    async def getTransformToWorldFromPlanning(self) -> PoseTransformIDL:
        """^W T_P: planning-grid units to world metres (the inverse transform)."""
        ...

    async def getVehiclePosition(self) -> Position3DIDL | None:
        """The vehicle position (world frame) of the latest TravMapArrayEventIDL;
        None (Miro's false) before the first map."""
        ...

    async def getNextWaypoint(self, current: WaypointIDL) -> WaypointIDL | None:
        """The waypoint after ``current`` in the list (wrapping in patrol mode); None
        (Miro's false) if there is none."""
        ...

    async def setWaypointList(self, waypoints: WaypointGroupIDL) -> None:
        """Replace the waypoint list (as VehiclePlan.setWaypointList)."""
        ...

    async def getWaypointList(self) -> WaypointGroupIDL:
        """The current waypoint list."""
        ...

    async def getCurrentWaypoint(self) -> WaypointIDL | None:
        """The waypoint being sought; None if the list is empty or finished."""
        ...

    async def setPlanningBoundary(self, boundary: PlanningBoundaryIDL) -> bool:
        """Limit planning to ``boundary``; false if it lies wholly outside the grid."""
        ...

    async def getPlanningBoundary(self) -> PlanningBoundaryIDL:
        """The current planning boundary (the whole grid unless set)."""
        ...

    async def getPlanMap(self) -> PlanMapEventIDL:
        """The whole planning map at once (afa addition: saves per-node polls;
        docs/decisions/0009)."""
        ...

    async def getPlanMapChanges(self, revision: int) -> PlanMapEventIDL | None:
        """The smallest window holding every cell changed since ``revision`` (the whole
        map if that revision is older than the change log or unknown); None (Miro's
        false) if nothing changed. afa addition for FindPath's incremental replanning
        (docs/decisions/0009)."""
        ...


class Platform(Interface):
    """ModelServer: geometry (Table 19) and the latest pose (``Pose`` events)."""

    wait_timeout: ClassVar[float] = 1.0

    async def getTransformation(self, A: str, B: str) -> PoseTransformIDL:
        """^A T_B between frames ``Body:Frame`` A and B; EOutOfBounds for an unknown
        frame."""
        ...

    async def getBodyList(self) -> StringSequenceIDL:
        """All body names in the model."""
        ...

    async def getBodyFrameList(self, body: str) -> StringSequenceIDL:
        """All frame names of ``body``; EOutOfBounds for an unknown body."""
        ...

    async def getPose(self) -> PoseTransformIDL:
        """The latest pose (^W T_V with initialUTM and poseValidFlag)."""
        ...

    async def getWaitPose(self) -> PoseTransformIDL:
        """The next pose; ETimeOut after wait_timeout."""
        ...


class VehiclePlan(Interface):
    """Pure Pursuit's waypoint interface (Table 24)."""

    async def setWaypointList(self, waypoints: WaypointGroupIDL) -> None:
        """Assign the waypoints (and patrol mode) to follow, from the first."""
        ...

    async def getWaypointList(self) -> WaypointGroupIDL:
        """The current working waypoint list."""
        ...

    async def getCurrentWaypoint(self) -> WaypointIDL | None:
        """The waypoint the vehicle is trying to reach; None if there is none."""
        ...

    async def setPatrolMode(self, patrol: bool) -> None:
        """Loop through the waypoints (true) or stop after the last (false)."""
        ...

    async def getPatrolMode(self) -> bool:
        """True if in patrol mode (Table 24 misprints it as a second getWaypointList)."""
        ...

    async def setHalt(self, halt: bool) -> None:
        """True vetoes every arc (the vehicle stops); false resumes."""
        ...


class VehicleControl(Interface):
    """Vehicle Control's command interface (Table 26)."""

    async def setVelocity(self, velocity: VelocityIDL) -> None:
        """Command translation and steering (the Arc Arbiter's call); EOutOfBounds
        outside getMinMaxVelocity's limits."""
        ...

    async def getTargetVelocity(self) -> VelocityIDL:
        """The velocity currently commanded."""
        ...

    async def startVehicle(self) -> None:
        """Enable driving (release the brake, accept commands)."""
        ...

    async def stopVehicle(self) -> None:
        """Stop: zero speed, brake, ignore velocity commands until startVehicle."""
        ...

    async def setJoystickVelocity(self, velocity: VelocityIDL) -> None:
        """Command a velocity from an operator's joystick (honoured with the arbiter
        off)."""
        ...

    async def setArbiter(self, enabled: bool) -> None:
        """Let the Arc Arbiter command the vehicle (true) or not (false)."""
        ...

    async def getMinMaxVelocity(self) -> MinMaxVelocityIDL:
        """The accepted translation, rotation and steering ranges."""
        ...
