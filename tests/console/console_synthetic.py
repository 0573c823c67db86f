"""A small test system whose components publish synthetic but realistic bodies for the
console's map, local-map and arc views: global terrain, traversability and planning maps
with obstacle cells where the hazards are, egocentric maps with an obstacle ahead, the
four behaviours' arc votes (Obstacle Avoidance vetoing the arcs that would hit it), the
arbiter's ArcDecision and FindPath's PlannedPath. The geometry comes from the real
ModelServer (the Raptor's model), so the console places ego maps and arcs from it.

Also used by ``docs/console/capture.py`` for the screenshots.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from afa import SubscribePublishServer, System
from components.model_server.geometry import GeometryModel
from idl import (
    ArcDecisionIDL,
    ArcVoteIDL,
    EgoMapArrayEventIDL,
    EtravMapArrayEventIDL,
    MapArrayEventIDL,
    PlanMapEventIDL,
    PlannedPathIDL,
    PlanningBoundaryIDL,
    PoseTransformIDL,
    Position3DIDL,
    Range3dSeqEventIDL,
    TimeIDL,
    TravMapArrayEventIDL,
    VelocityDataIDL,
    VelocityIDL,
)
from idl import VehicleControl as VehicleControlInterface
from idl.vehicle import MinMaxVelocityIDL

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"
INITIAL_UTM = np.array([416_000.0, 5_570_000.0, 750.0])

#: The global maps: 64 x 64 cells of 0.5 m around the world origin.
GLOBAL_CELLS, GLOBAL_GRID, GLOBAL_ORIGIN = 64, 0.5, -16.0
#: Obstacles of the global maps: world x range, y range (metres).
GLOBAL_OBSTACLES = (((8.0, 10.0), (4.0, 6.0)), ((-10.0, -9.5), (-12.0, 2.0)))
#: A free world point (no hazard there).
GLOBAL_FREE = (2.0, -6.0)
#: The ego maps: 32 rows (ahead, 0..16 m) x 32 columns (left, -8..8 m), 0.5 m.
EGO_ROWS, EGO_COLS, EGO_GRID = 32, 32, 0.5
#: The obstacle ahead of the bumper (ego x range, y range).
EGO_OBSTACLE = ((6.0, 7.5), (-1.5, 0.5))
ARCS = np.linspace(0.3, -0.3, 27)
BEHAVIOURS = ("ObstacleAvoidance", "PurePursuit", "FindPath", "ObstacleDetection")
SPEED = 0.5
HEADING = math.radians(30.0)


def _yaw(yaw: float, x: float = 0.0, y: float = 0.0) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)


def _cells(extent: tuple[tuple[float, float], tuple[float, float]], origin_x: float,
           origin_y: float, grid: float) -> tuple[slice, slice]:
    (x0, x1), (y0, y1) = extent
    return (slice(round((x0 - origin_x) / grid), round((x1 - origin_x) / grid)),
            slice(round((y0 - origin_y) / grid), round((y1 - origin_y) / grid)))


def global_hazard() -> np.ndarray:
    n = GLOBAL_CELLS
    rng = np.random.default_rng(3)
    hazard = (rng.random((n, n)) * 0.25).astype(np.float32)
    for extent in GLOBAL_OBSTACLES:
        hazard[_cells(extent, GLOBAL_ORIGIN, GLOBAL_ORIGIN, GLOBAL_GRID)] = 1.0
    hazard[:6, :] = np.nan  # the far west is unknown
    return hazard


def ego_hazard() -> np.ndarray:
    hazard = np.full((EGO_ROWS, EGO_COLS), 0.05, dtype=np.float32)
    hazard[_cells(EGO_OBSTACLE, 0.0, -8.0, EGO_GRID)] = 1.0
    hazard[24:, :6] = 0.6          # rough ground far right
    hazard[28:, :] = np.nan        # not seen yet
    return hazard


def bumper_offset() -> float:
    model = GeometryModel.load(ROOT / "configs" / "050917raptor01.XML")
    return float(model.transformation("Raptor:RearAxleCenter", "Raptor:Front-BumperCenter")[0, 3])


def arc_hits(curvature: float, rear_x: float, extent: tuple[tuple[float, float], ...],
             radius: float = 0.7) -> bool:
    """Does the arc from the rear axle (ego x = rear_x) pass within ``radius`` of the box?"""
    (x0, x1), (y0, y1) = extent
    for s in np.arange(0.0, 16.0, 0.1):
        if abs(curvature) > 1e-9:
            x, y = math.sin(curvature * s) / curvature, (1 - math.cos(curvature * s)) / curvature
        else:
            x, y = s, 0.0
        x += rear_x
        dx = max(x0 - x, 0.0, x - x1)
        dy = max(y0 - y, 0.0, y - y1)
        if math.hypot(dx, dy) <= radius:
            return True
    return False


class SyntheticStack(SubscribePublishServer):
    """Publishes the maps, votes, decision, path and pose of a vehicle driving slowly
    north-east past an obstacle (see the module docstring); ``period`` seconds apart."""

    def __init__(self, name: str = "synthetic", period: float = 0.1) -> None:
        super().__init__(name)
        self.period = period
        self.pose = self.publishes("Pose", PoseTransformIDL)
        self.terrain = self.publishes("Terrain", MapArrayEventIDL)
        self.ego_terrain = self.publishes("Terrain", EgoMapArrayEventIDL)
        self.traverse = self.publishes("Traverse", TravMapArrayEventIDL)
        self.ego_traverse = self.publishes("Traverse", EtravMapArrayEventIDL)
        self.plan = self.publishes("PlanMap", PlanMapEventIDL)
        self.votes = self.publishes("ArcVote", ArcVoteIDL)
        self.decision = self.publishes("ArcDecision", ArcDecisionIDL)
        self.path = self.publishes("PlannedPath", PlannedPathIDL)
        self.laser = self.publishes("Laser11", Range3dSeqEventIDL)
        self.rear_x = -bumper_offset()
        self.published = 0

    def vehicle(self, t: float) -> tuple[float, float]:
        distance = min(SPEED * t, 10.0)
        return distance * math.cos(HEADING), distance * math.sin(HEADING)

    def _global(self, stamp: TimeIDL, vx: float, vy: float) -> dict[str, object]:
        return dict(time=stamp, frame="World", mapPose=np.eye(4), initialUTM=INITIAL_UTM,
                    gridsize=GLOBAL_GRID, originX=GLOBAL_ORIGIN, originY=GLOBAL_ORIGIN,
                    rows=GLOBAL_CELLS, cols=GLOBAL_CELLS)

    def _ego(self, stamp: TimeIDL, vx: float, vy: float) -> dict[str, object]:
        bumper = _yaw(HEADING, vx, vy) @ np.array([-self.rear_x, 0.0, 0.0, 1.0])
        return dict(time=stamp, frame="Raptor:Front-BumperCenter",
                    mapPose=_yaw(HEADING, float(bumper[0]), float(bumper[1])),
                    initialUTM=INITIAL_UTM, gridsize=EGO_GRID, originX=0.0, originY=-8.0,
                    rows=EGO_ROWS, cols=EGO_COLS)

    def _votes(self, stamp: TimeIDL) -> list[ArcVoteIDL]:
        n = ARCS.shape[0]
        vetoes = np.array([arc_hits(k, self.rear_x, EGO_OBSTACLE) for k in ARCS])
        avoid = np.where(vetoes, 0.0, 1.0 - 0.5 * np.abs(ARCS) / 0.3)
        pursuit = np.exp(-0.5 * ((ARCS - 0.12) / 0.08) ** 2)
        planner = np.exp(-0.5 * ((ARCS - 0.18) / 0.1) ** 2)
        ones, zeros = np.ones(n), np.zeros(n, dtype=bool)
        return [
            ArcVoteIDL(time=stamp, behaviour="ObstacleAvoidance", curvatures=ARCS, veto=vetoes,
                       vote=avoid, certainty=ones, maxSpeed=np.where(vetoes, 0.0, 1.0)),
            ArcVoteIDL(time=stamp, behaviour="PurePursuit", curvatures=ARCS, veto=zeros,
                       vote=pursuit, certainty=ones, maxSpeed=np.full(n, 1.5)),
            ArcVoteIDL(time=stamp, behaviour="FindPath", curvatures=ARCS, veto=zeros,
                       vote=planner, certainty=np.full(n, 0.8), maxSpeed=np.full(n, 1.5)),
            ArcVoteIDL(time=stamp, behaviour="ObstacleDetection", curvatures=ARCS, veto=zeros,
                       vote=zeros.astype(float), certainty=zeros.astype(float),
                       maxSpeed=np.full(n, 2.0)),
        ]

    @staticmethod
    def _scan_line(stamp: TimeIDL, tick: int) -> Range3dSeqEventIDL:
        """A laser scan line on the ground ahead, in the laser's frame (a fan in the
        frame's x-y plane, nodding back and forth with the ticks)."""
        bearings = np.deg2rad(np.arange(0.0, 180.5, 1.0))
        reach = 6.0 + 3.0 * math.sin(tick * 0.3)
        points = np.stack([reach * np.sin(bearings), -reach * np.cos(bearings),
                           np.full(bearings.shape, -2.0)], axis=1).astype(np.float32)
        return Range3dSeqEventIDL(time=stamp, sensorId=11,
                                  frame="FrontNoddingSICKLeft:AxleCenterFreeEnd",
                                  points=points)

    @staticmethod
    def decide(stamp: TimeIDL, votes: list[ArcVoteIDL]) -> ArcDecisionIDL:
        scores = sum(v.vote.astype(float) * v.certainty.astype(float) for v in votes)
        vetoed = np.logical_or.reduce([v.veto for v in votes])
        admissible = np.where(vetoed, -np.inf, scores)
        index = int(np.argmax(admissible))
        curvature = float(ARCS[index])
        return ArcDecisionIDL(time=stamp, curvatures=ARCS, scores=np.asarray(scores),
                              vetoed=vetoed, index=index, curvature=curvature,
                              steeringAngle=math.atan(curvature * 1.9), speed=SPEED,
                              fresh=tuple(v.behaviour for v in votes))

    async def run(self) -> None:
        hazard, ego = global_hazard(), ego_hazard()
        goodness = np.ones_like(hazard)
        n = GLOBAL_CELLS
        x = GLOBAL_ORIGIN + (np.arange(n) + 0.5) * GLOBAL_GRID
        elevation = np.broadcast_to((0.03 * x)[:, None], (n, n)).astype(np.float32).copy()
        elevation[hazard >= 1.0] += 0.8
        elevation[np.isnan(hazard)] = np.nan
        counts = np.where(np.isnan(elevation), 0, 12).astype(np.int32)
        variance = np.where(np.isnan(elevation), np.nan, 0.01).astype(np.float32)
        sensed = np.where(hazard >= 1.0, np.inf, 1.0 + 9.0 * np.nan_to_num(hazard) ** 2)
        ego_elevation = np.where(np.isnan(ego), np.nan,
                                 np.where(ego >= 1.0, 0.9, 0.0)).astype(np.float32)
        ego_counts = np.where(np.isnan(ego), 0, 8).astype(np.int32)
        start = self.clock.monotonic()
        async for tick in self.clock.periodic(self.period):
            t = self.clock.monotonic() - start
            stamp = TimeIDL.from_seconds(self.clock.now())
            vx, vy = self.vehicle(t)
            self.pose.publish(PoseTransformIDL(time=stamp, HTransform=_yaw(HEADING, vx, vy),
                                               initialUTM=INITIAL_UTM, poseValidFlag=True))
            votes = self._votes(stamp)
            for vote in votes:
                self.votes.publish(vote)
            self.decision.publish(self.decide(stamp, votes))
            self.laser.publish(self._scan_line(stamp, tick))
            if tick % 2 == 0:
                g = self._global(stamp, vx, vy)
                trav = dict(hazard=hazard, goodness=goodness,
                            vehiclePosition=Position3DIDL(x=vx, y=vy), vehicleHeading=HEADING)
                self.traverse.publish(TravMapArrayEventIDL(**g, **trav))
                self.terrain.publish(MapArrayEventIDL(
                    **g, elevation=elevation, minHeight=elevation, maxHeight=elevation,
                    pointCount=counts, variance=variance))
                e = self._ego(stamp, vx, vy)
                self.ego_traverse.publish(EtravMapArrayEventIDL(
                    **e, hazard=ego, goodness=np.ones_like(ego),
                    vehiclePosition=Position3DIDL(x=vx, y=vy), vehicleHeading=HEADING))
                self.ego_terrain.publish(EgoMapArrayEventIDL(
                    **e, elevation=ego_elevation, minHeight=ego_elevation,
                    maxHeight=ego_elevation, pointCount=ego_counts,
                    variance=np.where(np.isnan(ego), np.nan, 0.0).astype(np.float32)))
            if tick % 10 == 0:
                self.plan.publish(PlanMapEventIDL(
                    **self._global(stamp, vx, vy), hazard=hazard, goodness=goodness,
                    vehiclePosition=Position3DIDL(x=vx, y=vy), vehicleHeading=HEADING,
                    aPrioriCost=np.ones((n, n), dtype=np.float32),
                    sensedCost=sensed.astype(np.float32),
                    planningBoundary=PlanningBoundaryIDL(minX=0, minY=0, maxX=n - 1,
                                                         maxY=n - 1)))
                self.path.publish(PlannedPathIDL(
                    time=stamp, points=np.array([[vx, vy], [6.0, 7.5], [11.0, 8.0],
                                                 [14.0, 12.0]]),
                    initialUTM=INITIAL_UTM, cost=25.0))
            self.published += 1


class FakeVehicleControl(SubscribePublishServer):
    """Serves VehicleControl as ``RaptorMotion`` and records the calls (no vehicle);
    publishes VelocityData every period."""

    def __init__(self, name: str = "RaptorService", period: float = 0.2) -> None:
        super().__init__(name)
        self.period = period
        self.calls: list[str] = []
        self.started = False
        self.arbiter = False
        self.motion = self.publishes("RaptorMotion", VelocityDataIDL)
        self.serves(VehicleControlInterface, "RaptorMotion")

    async def run(self) -> None:
        async for _ in self.clock.periodic(self.period):
            speed = SPEED if self.started else 0.0
            self.motion.publish(VelocityDataIDL(
                time=TimeIDL.from_seconds(self.clock.now()),
                velocity=VelocityIDL(translation=speed, steeringAngle=0.1),
                target=VelocityIDL(translation=speed, steeringAngle=0.12),
                vehicleStarted=self.started, arbiterEnabled=self.arbiter))

    async def setVelocity(self, velocity: VelocityIDL) -> None:
        self.calls.append("setVelocity")

    async def getTargetVelocity(self) -> VelocityIDL:
        return VelocityIDL()

    async def startVehicle(self) -> None:
        self.calls.append("startVehicle")
        self.started = True

    async def stopVehicle(self) -> None:
        self.calls.append("stopVehicle")
        self.started = False

    async def setJoystickVelocity(self, velocity: VelocityIDL) -> None:
        self.calls.append("setJoystickVelocity")

    async def setArbiter(self, enabled: bool) -> None:
        self.calls.append(f"setArbiter({enabled})")
        self.arbiter = enabled

    async def getMinMaxVelocity(self) -> MinMaxVelocityIDL:
        return MinMaxVelocityIDL(minTranslation=-1.0, maxTranslation=2.0, minRotation=-1.0,
                                 maxRotation=1.0, maxSteeringAngle=0.5)


def synthetic_system(clock: object, period: float = 0.1) -> System:
    """ModelServer (the geometry, from the Raptor's configuration), the synthetic stack
    and a fake Vehicle Control."""
    system = System.from_xml(RAPTOR, only=["modelServer"], clock=clock)
    system.add(SyntheticStack(period=period))
    system.add(FakeVehicleControl())
    return system
