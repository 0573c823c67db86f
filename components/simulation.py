"""The simulated Raptor: the world, the vehicle, and every device emulator (SPEC §2).

:class:`RaptorSimulation` owns the terrain and the vehicle model (``afa.sim``) and gives
each configured device component an emulator in place of its real device, fed with
ground truth: the emulators speak the real wire protocols, so the real drivers run.
Each device package registers its emulator beside its codec and fake (entry point group
``afa.emulators``: ``components/<device>/emulator.py``); the simulation looks them up by
component type and offers them to the System at construction
(``System(devices=sim.device_for)``), through the :class:`SimulatedWorld` API.

In a world with a mission the simulation plays the control station, as an operator
would: it sends the waypoints (latitude/longitude) to Pure Pursuit and the Global Map
through their interfaces, sets patrol mode, starts the vehicle and switches the arbiter
on; the autonomous stack drives. With ``teleop`` (``afa run --teleop``), or in a world
without a mission, it runs the world's ``drive`` script through Vehicle Control's
joystick interface instead.

It keeps the run summary: distance, collisions, least clearance, waypoints reached in
order by the vehicle's actual track, mission time and distance, halts by Obstacle
Detection, oscillation of the commanded steering, pose error against ground truth, and a
digest of every event.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import math
from collections import deque
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any, Literal, Protocol, TypeVar

import numpy as np

from afa import (
    ByteStream,
    Clock,
    EDevIO,
    Event,
    SerialSpec,
    System,
    TcpSpec,
    VirtualClock,
    registry,
)
from afa.component import Component
from afa.ports import Direction, interface_name
from afa.sim.oracle import HazardField, shortest_course
from afa.sim.stats import RunningError
from afa.sim.terrain import Terrain
from afa.sim.vehicle import Vehicle, VehicleState
from afa.sim.world import World, load_world
from afa.tasks import spawn
from afa.transport import AsyncioByteStream, DeviceFactory, PtyDeviceStream, open_tcp
from components.gps_sokkia.codec import latlon_to_grid_near, latlon_to_utm
from components.map_quality import map_summary
from components.model_server.geometry import GeometryModel
from components.waypoints import VEHICLE_FRAME, reached, to_local
from idl import (
    ArcVoteIDL,
    PlanningBoundaryIDL,
    PoseTransformIDL,
    VelocityDataIDL,
    VelocityIDL,
    WaypointGroupIDL,
    WaypointIDL,
)
from idl import GlobalMap as GlobalMapInterface
from idl import VehicleControl as VehicleControlInterface
from idl import VehiclePlan as VehiclePlanInterface

__all__ = ["RaptorSimulation", "SimulatedWorld", "DEFAULT_WORLD", "WAYPOINT_TOLERANCE"]

log = logging.getLogger("afa.sim")

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
DEFAULT_WORLD = CONFIGS / "worlds" / "open-field.xml"
#: A waypoint counts as reached when the rear axle or the middle of the front bumper (the
#: points the Global Map and the behaviours judge by) passes within this distance (m).
WAYPOINT_TOLERANCE = 3.0
#: The mission area given to the Global Map: the terrain less this margin (m).
GEOFENCE_MARGIN = 1.0
#: Physics step (s): 50 Hz, finer than every sensor but the laser's scan lines, which
#: are ray-cast from the pose interpolated at their first beam (frame_pose_at).
PHYSICS_STEP = 0.02
#: Physics steps kept for frame_pose_at: 0.1 s, more than a scan line's 27 ms.
HISTORY_STEPS = 6
#: How often the drive script repeats its joystick command (s): Vehicle Control's
#: watchdog stops the vehicle when commands stop arriving, as a real joystick link would.
JOYSTICK_PERIOD = 0.1
#: Steering commands within this angle of straight ahead (rad, 1 degree) count as
#: straight when oscillation (sign changes of the commanded steering) is counted.
STEERING_DEADBAND = math.radians(1.0)
#: The vehicle's track (``RaptorSimulation.track``): a point every TRACK_STEP metres
#: driven, at most TRACK_POINTS of them (the latest).
TRACK_STEP = 0.5
TRACK_POINTS = 100_000

F = TypeVar("F")
#: A simulation runs once: new, running (started), stopped.
Phase = Literal["new", "running", "stopped"]


def served_name(system: System, interface: type[Any]) -> str | None:
    """The name the first component serving ``interface`` binds (from the catalog)."""
    wanted = interface_name(interface)
    for port in system.catalog().by(Direction.SERVES):
        if port.types == (wanted,):
            return port.name
    return None


class SimulatedWorld(Protocol):
    """What a device emulator (``components/<device>/emulator.py``) may use."""

    clock: Clock
    world: World
    terrain: Terrain
    vehicle: Vehicle

    @property
    def state(self) -> VehicleState: ...

    def mount(self, frame: str) -> np.ndarray:
        """^V T_frame from the geometry model (constant)."""
        ...

    def frame_pose(self, frame: str) -> np.ndarray:
        """^W T_frame now: the vehicle's pose times the frame's mounting."""
        ...

    def frame_pose_at(self, frame: str, t: float) -> np.ndarray:
        """^W T_frame at clock time ``t`` (``clock.monotonic()`` scale) within the last
        few physics steps: the vehicle's pose interpolated between the two steps around
        ``t`` (the latest one for a later ``t``, the oldest kept for an earlier one)."""
        ...

    def rng(self) -> np.random.Generator:
        """A generator of its own, seeded from the simulation's seed."""
        ...

    def command(self, translation: float, steering: float, brake: bool) -> None:
        """What the vehicle controller commands the physics to do."""
        ...

    def shared(self, key: str, make: Callable[[], F]) -> F:
        """One object per simulation under ``key`` (a controller serving two
        components)."""
        ...

    def adopt(self, component: Component[Any], fake: Any,
              kind: Literal["serial", "tcp"] = "serial") -> DeviceFactory:
        """The device factory serving ``fake`` to ``component`` (an in-memory pipe, or
        with ``expose`` a pseudo-terminal or loopback port); the simulation closes the
        fake at the end."""
        ...


class RaptorSimulation:
    """A world, a vehicle, and the emulators for a System's device components.

    The short way (tests, notebooks, the CLI)::

        sim = RaptorSimulation.from_xml("configs/raptor.xml", "rock-field.xml",
                                        clock=VirtualClock(), seed=1)
        async with sim:                      # the system started, the physics running
            await sim.system.run(60.0)
        sim.summary()

    across notebook cells (time stands still between them; docs/notebooks.md)::

        sim = RaptorSimulation.from_xml("configs/raptor.xml", clock=VirtualClock())
        await sim.start()                    # started; the clock is paused
        await sim.run_for(10)                # ten simulated seconds, then it stops
        await sim.stop()                     # a new simulation for another run

    and the parts it is made of::

        sim = RaptorSimulation(world, clock, seed=...)
        system = System.from_xml(config, clock=clock, devices=sim.device_for)
        sim.attach(system)                   # observes every event from the start
        async with system, sim.running():    # physics, drive script
            await system.run(duration)
    """

    _phase: Phase

    @staticmethod
    def default_world() -> Path:
        return DEFAULT_WORLD

    @classmethod
    def from_xml(cls, config: str | Path, world: World | str | Path | None = None, *,
                 clock: Clock, seed: int = 0, expose: bool = False, teleop: bool = False,
                 **system_options: Any) -> RaptorSimulation:
        """A simulation of ``world`` (default: the open field) with the System that
        ``config`` describes attached (``sim.system``); ``system_options`` go to
        :meth:`System.from_xml`. Raises ConfigError for a bad file."""
        simulation = cls(DEFAULT_WORLD if world is None else world, clock, seed=seed,
                         expose=expose, teleop=teleop)
        system = System.from_xml(config, clock=clock, devices=simulation.device_for,
                                 **system_options)
        simulation.attach(system)
        return simulation

    @property
    def system(self) -> System:
        if self._system is None:
            raise RuntimeError("the simulation is not attached to a System")
        return self._system

    async def __aenter__(self) -> RaptorSimulation:
        self._begin()
        try:
            await self.system.start()
            try:
                self._running = self.running()
                await self._running.__aenter__()
            except BaseException:
                await self.system.stop(raise_failures=False)
                raise
        except BaseException:
            self._phase = "stopped"
            await self.aclose()
            raise
        return self

    async def __aexit__(self, *exc_info: Any) -> None:
        if self._phase != "running":
            return
        try:
            with self.clock.running():  # the physics' and emulators' clean-up
                await self._running.__aexit__(*exc_info)
        finally:
            try:
                await self.system.stop(raise_failures=exc_info[0] is None)
            finally:
                await self.aclose()
                self._phase = "stopped"

    # -- across notebook cells ---------------------------------------------------------------
    async def start(self) -> RaptorSimulation:
        """Start the system and the physics, for use across notebook cells (``async
        with`` cannot span cells); :meth:`stop` ends it. On a
        :class:`~afa.clock.VirtualClock` time then stands still between calls: the clock
        is paused once started, and runs only inside :meth:`run_for`,
        :meth:`run_mission` or ``system.run`` (``clock.resume()`` lets it run on by
        itself). A simulation runs once: starting it again raises RuntimeError saying
        to build a new one."""
        await self.__aenter__()
        if isinstance(self.clock, VirtualClock):
            self.clock.pause()
        return self

    async def stop(self) -> None:
        """Stop the physics, the system and the emulators (see :meth:`start`); again:
        nothing."""
        await self.__aexit__(None, None, None)

    async def run_for(self, seconds: float) -> None:
        """Run ``seconds`` of simulated time and stop there (a started simulation;
        paced if the clock is). Raises TaskFailed if the physics or a fake failed."""
        if self._phase != "running":
            raise RuntimeError("start the simulation first: await sim.start() "
                               "(or async with sim:)")
        await self.system.run(seconds)

    def _begin(self) -> None:
        if self._phase == "running":
            raise RuntimeError("the simulation is already running")
        if self._phase == "stopped":
            raise RuntimeError(
                "this simulation has run and stopped (its emulators are closed and its "
                "vehicle is where the run left it); it cannot be started again: build a new "
                "one, e.g. sim = RaptorSimulation.from_xml(config, world, clock=VirtualClock())")
        if self._system is None:
            raise RuntimeError("the simulation is not attached to a System")
        self._phase = "running"

    def __init__(self, world: World | str | Path, clock: Clock, *, seed: int = 0,
                 geometry: GeometryModel | None = None, expose: bool = False,
                 teleop: bool = False) -> None:
        """``expose``: serve the serial emulators on pseudo-terminals (the drivers open
        them through pyserial-asyncio) and the lasers on loopback TCP ports, instead of
        in-memory pipes. Real I/O is not deterministic: use it with the wall clock.
        ``teleop``: drive the world's script instead of the mission."""
        self.world = world if isinstance(world, World) else load_world(world)
        self.clock = clock
        self.seed = seed
        self.terrain = Terrain.from_spec(self.world.terrain, self.world.obstacles)
        self.vehicle = Vehicle.from_world(self.world, self.terrain)
        self.geometry = geometry or GeometryModel.load(CONFIGS / "050917raptor01.XML")
        self.expose = expose
        self.teleop = teleop or not self.world.mission.waypoints
        self.mission_complete_time: float | None = None
        #: set when the mission's course is done (a patrol: when the loop closes again
        #: at its first waypoint); ``afa run --sim`` stops there
        self.finished = asyncio.Event()
        self.mission_distance: float | None = None
        self.clearance = math.inf
        self.halts = 0
        self._halted = False
        self._steering_sign = 0
        self.steering_sign_changes = 0
        # built now, before anything runs: half a second of CPU on a big world would
        # starve the drivers of a real-time run if it were built when the physics starts
        self._hazards: HazardField | None = HazardField(self.terrain, self.vehicle.parameters)
        self._outline_reach: float | None = None  # metres from the rear axle centre
        # where the outline's clearance was last looked up: east, north, yaw, clearance
        self._clearance_at: tuple[float, float, float, float] | None = None
        self._seeds = np.random.SeedSequence(seed)
        self._start = 0.0
        self._command = (0.0, 0.0, True)  # translation m/s, steering rad, brake
        self.collisions: list[dict[str, Any]] = []
        #: (east, north) of the rear axle every TRACK_STEP m driven
        self.track: deque[tuple[float, float]] = deque(maxlen=TRACK_POINTS)
        self._track_next = 0.0
        self.waypoints_reached = 0
        self._next_waypoint = 0
        self._digest = hashlib.sha256()
        self._pose_errors = RunningError()  # constant memory however long the run
        self._last_pose_error: tuple[float, float] | None = None  # for displays
        self._waypoints_utm: list[list[float]] | None = None
        self._grid: tuple[int, str] | None = None  # the pose frame's UTM zone, hemisphere
        self._digests: dict[str, Any] = {}  # per event name: one stream's digest
        self.fakes: list[Any] = []
        self.endpoints: dict[str, str] = {}  # component -> pty path or host:port
        #: told ``(component, endpoint)`` as each exposed device is served (``afa run
        #: --expose`` prints them); None logs them at info level
        self.announce: Callable[[str, str], None] | None = None
        self._shared: dict[str, Any] = {}
        self._mounts: dict[str, np.ndarray] = {}
        self._poses_of: VehicleState | None = None  # the state _poses were computed at
        self._poses: dict[str, np.ndarray] = {}
        #: (clock.monotonic(), state, its frame poses) of the last physics steps, for
        #: frame_pose_at
        self._history: deque[tuple[float, VehicleState, dict[str, np.ndarray]]] = \
            deque(maxlen=HISTORY_STEPS)
        self._system: System | None = None
        self._observer: Any = None
        self._phase: Phase = "new"

    # -- SimulatedWorld ------------------------------------------------------------------
    @property
    def state(self) -> VehicleState:
        return self.vehicle.state

    def mount(self, frame: str) -> np.ndarray:
        mount = self._mounts.get(frame)
        if mount is None:
            mount = self._mounts[frame] = self.geometry.transformation(VEHICLE_FRAME, frame)
        return mount

    def frame_pose(self, frame: str) -> np.ndarray:
        # One product per frame and physics step, however many scans and frames read it
        # (both lasers and the camera often sense between the same two steps); read-only,
        # as it is shared.
        state = self.state
        if self._poses_of is not state:
            self._poses_of, self._poses = state, {}
        pose = self._poses.get(frame)
        if pose is None:
            pose = self._poses[frame] = _body_pose(self._poses, state) @ self.mount(frame)
            pose.flags.writeable = False
        return pose

    def frame_pose_at(self, frame: str, t: float) -> np.ndarray:
        history = self._history
        if not history or t >= history[-1][0]:
            return self.frame_pose(frame)
        if t <= history[0][0]:
            return self._step_pose(history[0], frame)
        k = len(history) - 1
        while history[k - 1][0] > t:
            k -= 1
        before, after = history[k - 1], history[k]
        w = (t - before[0]) / (after[0] - before[0])
        a, b = self._step_pose(before, frame), self._step_pose(after, frame)
        # element-wise: within a 20 ms step the rotation turns by milliradians, and the
        # blend's departure from a rotation (of their square) is far below a millimetre
        return a + w * (b - a)

    def _step_pose(self, step: tuple[float, VehicleState, dict[str, np.ndarray]],
                   frame: str) -> np.ndarray:
        poses = step[2]
        pose = poses.get(frame)
        if pose is None:
            pose = poses[frame] = _body_pose(poses, step[1]) @ self.mount(frame)
            pose.flags.writeable = False  # (the dict may be frame_pose's: shared)
        return pose

    def rng(self) -> np.random.Generator:
        return np.random.default_rng(self._seeds.spawn(1)[0])

    def command(self, translation: float, steering: float, brake: bool) -> None:
        self._command = (translation, steering, brake)

    def shared(self, key: str, make: Callable[[], F]) -> F:
        if key not in self._shared:
            self._shared[key] = make()
        return self._shared[key]  # type: ignore[no-any-return]

    def adopt(self, component: Component[Any], fake: Any,
              kind: Literal["serial", "tcp"] = "serial") -> DeviceFactory:
        if fake not in self.fakes:
            self.fakes.append(fake)
        if not self.expose:
            return fake.factory()  # type: ignore[no-any-return]
        return self._exposed(component.name, fake, kind)

    # -- wiring --------------------------------------------------------------------------
    def device_for(self, component: Component[Any]) -> DeviceFactory | None:
        """The emulator factory for ``component`` (None for a component with no device);
        pass as ``System(devices=sim.device_for)``."""
        emulate = registry.emulator_for(component.type_name)
        if emulate is None:
            return None
        return emulate(component, self)  # type: ignore[no-any-return]

    def attach(self, system: System) -> None:
        """Observe ``system``'s events (digest, pose error) from its start."""
        self._system = system
        self._observer = system.observe(self._observe, name="simulation", maxsize=1 << 16)

    def _announce(self, name: str, endpoint: str) -> None:
        self.endpoints[name] = endpoint
        if self.announce is not None:
            self.announce(name, endpoint)
        else:
            log.info("%s: emulated on %s", name, endpoint)

    def _exposed(self, name: str, fake: Any, kind: str) -> DeviceFactory:
        """A factory serving ``fake`` on a pseudo-terminal (one per emulated device, so
        the MPC555's two components share it) or a loopback TCP port, opened through
        the real transports."""
        if kind == "serial":
            async def open_pty(spec: SerialSpec) -> ByteStream:
                pty = self._shared.get(f"pty:{id(fake)}")
                if pty is None:
                    pty = self._shared[f"pty:{id(fake)}"] = PtyDeviceStream(self.clock)
                    spawn(fake.serve(pty), owner=f"emulator {name}")
                if name not in self.endpoints:
                    self._announce(name, pty.path)
                assert self._system is not None
                return await self._system.devices.open_serial(SerialSpec(pty.path,
                                                                         spec.baudrate))
            return open_pty  # type: ignore[return-value]

        async def open_socket(spec: TcpSpec) -> ByteStream:
            port = self._shared.get(f"tcp:{name}")
            if port is None:
                async def handle(reader: asyncio.StreamReader,
                                 writer: asyncio.StreamWriter) -> None:
                    await fake.serve(AsyncioByteStream(reader, writer, "laser", self.clock))

                server = await asyncio.start_server(handle, "127.0.0.1", 0)
                self._shared[f"server:{name}"] = server
                port = self._shared[f"tcp:{name}"] = server.sockets[0].getsockname()[1]
                self._announce(name, f"127.0.0.1:{port}")
            return await open_tcp("127.0.0.1", port, clock=self.clock)
        return open_socket  # type: ignore[return-value]

    # -- running ---------------------------------------------------------------------------
    @asynccontextmanager
    async def running(self) -> AsyncIterator[RaptorSimulation]:
        """Run the physics (and the world's drive script) in the attached system's task
        group; at the end stop them (then stop the system and :meth:`aclose`). A failure
        in the physics fails the system (``System.run`` raises TaskFailed)."""
        system = self._system
        if system is None:
            raise RuntimeError("attach the simulation to a System before running it")
        self._start = self.clock.monotonic()
        self._history.append((self._start, self.state, {}))
        if self._hazards is None:
            self._hazards = HazardField(self.terrain, self.vehicle.parameters)
        tasks = [system.tasks.spawn(self._physics(), owner="simulation physics")]
        if not self.teleop:
            tasks.append(system.tasks.spawn(self._mission(), owner="simulation mission"))
        elif self.world.drive:
            tasks.append(system.tasks.spawn(self._drive_script(), owner="simulation drive"))
        try:
            yield self
        finally:
            for task in tasks:
                task.cancel()
            for task in tasks:
                try:
                    await task
                except (asyncio.CancelledError, Exception):  # reported by the task group
                    pass
            if self._observer is not None:
                await self._observer.drain()

    async def aclose(self) -> None:
        """Close the emulators and their endpoints (after the system has stopped, so no
        driver reports its device lost)."""
        for fake in self.fakes:
            await fake.aclose()
        for key, endpoint in list(self._shared.items()):
            if key.startswith("server:"):
                endpoint.close()
            elif key.startswith("pty:"):
                await endpoint.close()

    async def run_mission(self) -> bool:
        """Run the attached system until the mission (or the drive script) is finished
        or its :attr:`time_limit` has passed; True if finished. Inside ``async with``."""
        await self.system.run(self.time_limit, until=self.finished)
        return self.finished.is_set()

    @property
    def time_limit(self) -> float | None:
        """Seconds the mission may take: the world's ``time-limit``, else 120 s plus 8 s
        per metre of the straight-line course (a patrol: the closed loop); in tele-operation
        the drive script's length and 10 s; None with neither."""
        mission = self.world.mission
        if self.teleop:
            return self.world.drive_duration + 10.0 if self.world.drive else None
        if not mission.waypoints:
            return None
        if mission.time_limit is not None:
            return mission.time_limit
        points = [(self.world.vehicle.east, self.world.vehicle.north)]
        points += [(w.east, w.north) for w in mission.waypoints]
        if mission.patrol:
            points.append(points[1])
        legs = zip(points, points[1:], strict=False)
        return 120.0 + 8.0 * sum(math.dist(a, b) for a, b in legs)

    @property
    def sim_time(self) -> float:
        return self.clock.monotonic() - self._start

    async def _physics(self) -> None:
        async for _ in self.clock.periodic(PHYSICS_STEP):
            translation, steering, brake = self._command
            speed = 0.0 if brake else translation
            before = self.vehicle.collision
            self.vehicle.step(PHYSICS_STEP, speed, math.degrees(steering), self.terrain)
            # the new state's frame poses: one dict for frame_pose and frame_pose_at
            self._poses_of, self._poses = self.state, {}
            self._history.append((self.clock.monotonic(), self.state, self._poses))
            if self.state.travelled >= self._track_next:
                self.track.append((self.state.east, self.state.north))
                self._track_next = self.state.travelled + TRACK_STEP
            collision = self.vehicle.collision
            if collision is not None and before is None:
                record = {"time": round(self.sim_time, 3), "east": round(collision.east, 3),
                          "north": round(collision.north, 3), "obstacle": collision.obstacle,
                          "kind": str(getattr(collision.kind, "value", collision.kind))}
                self.collisions.append(record)
                log.warning("collision: %s", record)
            self._track_waypoints()
            self._track_clearance()

    def _track_waypoints(self) -> None:
        waypoints = self.world.mission.waypoints
        if not waypoints or self._next_waypoint >= len(waypoints):
            return
        target = waypoints[self._next_waypoint]
        state = self.state
        p = self.vehicle.parameters
        if reached(state.east, state.north, math.cos(state.yaw), math.sin(state.yaw),
                   (p.body_length - p.rear_overhang, 0.0), target.east, target.north,
                   WAYPOINT_TOLERANCE):
            # a patrol needs two waypoints: with one it is a plain mission, as the
            # vehicle's Pure Pursuit and Global Map take it
            patrol = self.world.mission.patrol and len(waypoints) >= 2
            self.waypoints_reached += 1
            self._next_waypoint += 1
            if self.waypoints_reached == len(waypoints):  # the course (one lap) is done
                self.mission_complete_time = self.sim_time
                self.mission_distance = self.state.travelled  # backing counts too
            if patrol:
                self._next_waypoint %= len(waypoints)
            if self.waypoints_reached == len(waypoints) + (1 if patrol else 0):
                self.finished.set()

    def _track_clearance(self) -> None:
        """The least distance from the body's outline to a hazard so far.

        The outline's lookups are skipped while they cannot lower the least clearance:
        since the last lookup no outline point has moved farther than the rear axle's
        move plus the turn times the outline's reach, and a point's clearance changes by
        at most its move plus :attr:`HazardField.sample_jump`."""
        if self._hazards is None:
            return
        state = self.state
        outline = self.vehicle.footprint(0.35)
        if self._outline_reach is None:
            self._outline_reach = float(np.hypot(outline[:, 0], outline[:, 1]).max())
        if self._clearance_at is not None:
            east0, north0, yaw0, there = self._clearance_at
            moved = (math.hypot(state.east - east0, state.north - north0)
                     + abs(math.remainder(state.yaw - yaw0, math.tau)) * self._outline_reach)
            if there - moved - self._hazards.sample_jump >= self.clearance:
                return
        c, sn = math.cos(state.yaw), math.sin(state.yaw)
        east = state.east + outline[:, 0] * c - outline[:, 1] * sn
        north = state.north + outline[:, 0] * sn + outline[:, 1] * c
        here = self._hazards.clearance(east, north)
        self._clearance_at = (state.east, state.north, state.yaw, here)
        self.clearance = min(self.clearance, here)

    async def _mission(self) -> None:
        """The control station: waypoints to Pure Pursuit and the Global Map, patrol
        mode, start the vehicle, arbiter on (then the stack drives)."""
        system = self.system
        plan_name = served_name(system, VehiclePlanInterface)
        control_name = served_name(system, VehicleControlInterface)
        if plan_name is None or control_name is None:
            log.warning("the world has a mission but no %s is configured: nothing drives",
                        "Pure Pursuit" if plan_name is None else "Vehicle Control")
            return
        mission = self.world.mission
        group = WaypointGroupIDL(waypoints=tuple(
            WaypointIDL(latitude=w.latitude, longitude=w.longitude) for w in mission.waypoints),
            patrolMode=mission.patrol)
        plan = await system.resolve(VehiclePlanInterface, plan_name)
        await plan.setWaypointList(group)
        await plan.setPatrolMode(mission.patrol)
        global_name = served_name(system, GlobalMapInterface)
        global_map = None
        if global_name is not None:
            global_map = await system.resolve(GlobalMapInterface, global_name)
            await global_map.setWaypointList(group)
        control = await system.resolve(VehicleControlInterface, control_name)
        while True:  # the controller link comes up a moment after the component
            try:
                await control.startVehicle()
                await control.setArbiter(True)
                break
            except EDevIO as exc:
                log.info("mission waiting for the vehicle: %s", exc)
                await self.clock.sleep(0.5)
        log.info("mission started: %d waypoints%s", len(mission.waypoints),
                 " (patrol)" if mission.patrol else "")
        if global_map is not None:
            await self._geofence(global_map)

    async def _geofence(self, global_map: Any) -> None:
        """The operator's mission area: the world's terrain (there is nothing beyond
        it), less ``GEOFENCE_MARGIN``, as the Global Map's planning boundary, once the
        map knows its world frame (``initialUTM``, from the first merged map)."""
        while True:
            transform = await global_map.getTransformToPlanningFromWorld()
            if np.any(transform.initialUTM):
                break
            await self.clock.sleep(0.5)
        planning = np.asarray(transform.HTransform)
        e0, e1, n0, n1 = self.terrain.extent
        m = GEOFENCE_MARGIN
        corners = {}
        for key, (east, north) in {"sw": (e0 + m, n0 + m), "se": (e1 - m, n0 + m),
                                   "nw": (e0 + m, n1 - m), "ne": (e1 - m, n1 - m)}.items():
            lat, lon = self.world.origin.to_geodetic(east, north)
            x, y = to_local(WaypointIDL(latitude=lat, longitude=lon), transform.initialUTM)
            corners[key] = planning @ np.array([x, y, 0.0, 1.0])
        # the largest grid-aligned box inside the (slightly rotated) UTM quadrilateral
        boundary = PlanningBoundaryIDL(
            minX=math.ceil(max(corners["sw"][0], corners["nw"][0])),
            maxX=math.floor(min(corners["se"][0], corners["ne"][0])) - 1,
            minY=math.ceil(max(corners["sw"][1], corners["se"][1])),
            maxY=math.floor(min(corners["nw"][1], corners["ne"][1])) - 1)
        if not await global_map.setPlanningBoundary(boundary):
            log.warning("the mission area %s lies outside the Global Map", boundary)

    async def _drive_script(self) -> None:
        """Tele-operation: the world's timed commands, sent as a joystick would."""
        assert self._system is not None
        control_name = served_name(self._system, VehicleControlInterface)
        if control_name is None:
            log.warning("the world has a drive script but no VehicleControl is configured")
            return
        control = await self._system.resolve(VehicleControlInterface, control_name)
        while True:  # the controller link comes up a moment after the component
            try:
                await control.startVehicle()
                await control.setArbiter(False)
                break
            except EDevIO as exc:
                log.info("drive script waiting for the vehicle: %s", exc)
                await self.clock.sleep(0.5)
        end = self.world.drive_duration
        async for _ in self.clock.periodic(JOYSTICK_PERIOD):
            t = self.sim_time
            speed, steering = self.world.command_at(t)
            wheelbase = self.vehicle.parameters.wheelbase
            rotation = speed * math.tan(math.radians(steering)) / wheelbase
            try:
                await control.setJoystickVelocity(VelocityIDL(
                    translation=speed, rotation=rotation, steeringAngle=math.radians(steering)))
            except Exception as exc:  # the link may be down for a moment; keep steering
                log.info("drive script: %s", exc)
            if t > end + 1.0 and speed == 0.0:
                self.finished.set()
                return

    # -- observation -------------------------------------------------------------------------
    def _observe(self, event: Event) -> None:
        digest = self._digest
        head = f"{event.type}|{event.time:.6f}|".encode()
        body = event.body
        fingerprint = body.fingerprint()  # arrays by their SHA-256
        digest.update(head)
        digest.update(fingerprint)
        stream = self._digests.get(event.type)
        if stream is None:
            stream = self._digests[event.type] = hashlib.sha256()
        stream.update(head)
        stream.update(fingerprint)
        if isinstance(body, PoseTransformIDL) and event.type == "Pose":
            self._pose_error(body)
        elif isinstance(body, ArcVoteIDL) and body.behaviour == "ObstacleDetection":
            halted = body.all_vetoed
            if halted and not self._halted:
                self.halts += 1
            self._halted = halted
        elif isinstance(body, VelocityDataIDL):
            self._steering(body.target.steeringAngle)

    def _steering(self, angle: float) -> None:
        """Count sign changes of the commanded steering (outside the dead band) while
        the mission runs."""
        if self.mission_complete_time is not None:
            return
        sign = 0 if abs(angle) < STEERING_DEADBAND else (1 if angle > 0 else -1)
        if sign and self._steering_sign and sign != self._steering_sign:
            self.steering_sign_changes += 1
        if sign:
            self._steering_sign = sign

    def _truth_utm(self) -> tuple[float, float, float, int, str]:
        """The vehicle reference point's true UTM easting, northing, grid yaw (rad,
        counter-clockwise from grid east), zone and hemisphere: in the pose frame's grid
        once a pose has come (the first GPS fix's, kept across a zone boundary or the
        equator), in the vehicle's own grid before."""
        state = self.state
        lat, lon = self.world.origin.to_geodetic(state.east, state.north)
        zone, hemisphere = self._grid if self._grid is not None else (None, None)
        utm = latlon_to_utm(lat, lon, zone=zone, hemisphere=hemisphere)
        ahead = self.world.origin.to_geodetic(state.east + 10 * math.cos(state.yaw),
                                              state.north + 10 * math.sin(state.yaw))
        utm_ahead = latlon_to_utm(*ahead, zone=utm.zone_number, hemisphere=utm.hemisphere)
        grid_yaw = math.atan2(utm_ahead.northing_m - utm.northing_m,
                              utm_ahead.easting_m - utm.easting_m)
        return utm.easting_m, utm.northing_m, grid_yaw, utm.zone_number, utm.hemisphere

    def _pose_error(self, pose: PoseTransformIDL) -> None:
        if self._grid is None:
            lat, lon = self.world.origin.to_geodetic(self.state.east, self.state.north)
            near = latlon_to_grid_near(lat, lon, float(pose.initialUTM[0]),
                                       float(pose.initialUTM[1]))
            self._grid = (near.zone_number, near.hemisphere)
        easting, northing, grid_yaw, _, _ = self._truth_utm()
        east = pose.HTransform[0, 3] + pose.initialUTM[0]
        north = pose.HTransform[1, 3] + pose.initialUTM[1]
        yaw = math.atan2(pose.HTransform[1, 0], pose.HTransform[0, 0])
        error = (math.hypot(east - easting, north - northing),
                 math.degrees(math.remainder(yaw - grid_yaw, 2 * math.pi)))
        self._pose_errors.add(self.sim_time, *error)
        self._last_pose_error = error

    def truth(self) -> dict[str, Any]:
        """Ground truth now, for displays (the browser console's pose error and map
        overlay): the vehicle reference point's true UTM position and grid heading, the
        latest pose error (``None`` before the first Pose), the mission's waypoints in UTM
        and how many were reached, the collisions so far."""
        easting, northing, grid_yaw, zone, hemisphere = self._truth_utm()
        if self._waypoints_utm is None:
            self._waypoints_utm = []
            for waypoint in self.world.mission.waypoints:
                utm = latlon_to_utm(waypoint.latitude, waypoint.longitude, zone=zone,
                                    hemisphere=hemisphere)
                self._waypoints_utm.append([utm.easting_m, utm.northing_m])
        error = self._last_pose_error
        return {"world": self.world.name, "sim_time": self.sim_time,
                "utm": [easting, northing], "heading_deg": math.degrees(grid_yaw),
                "speed": self.state.speed, "distance": self.state.distance,
                "pose_error_m": None if error is None else error[0],
                "heading_error_deg": None if error is None else error[1],
                "waypoints_utm": list(self._waypoints_utm),
                "waypoints_reached": self.waypoints_reached,
                "patrol": self.world.mission.patrol, "collisions": len(self.collisions)}

    def summary(self) -> dict[str, Any]:
        """The simulation's part of the run summary."""
        pose_error = self._pose_errors.summary()  # after the filter's first seconds
        mission_minutes = (self.mission_complete_time or self.sim_time) / 60.0
        return {
            "world": self.world.name,
            "seed": self.seed,
            "mode": "teleop" if self.teleop else "autonomous",
            "distance_m": round(self.state.travelled, 3),
            "collisions": list(self.collisions),
            "clearance_m": None if math.isinf(self.clearance) else round(self.clearance, 3),
            "waypoints_reached": self.waypoints_reached,
            "waypoints_total": len(self.world.mission.waypoints),
            "mission_complete": self.mission_complete_time is not None,
            "time_limit_s": self.time_limit,
            "mission_complete_time_s": None if self.mission_complete_time is None
            else round(self.mission_complete_time, 3),
            "mission_distance_m": None if self.mission_distance is None
            else round(self.mission_distance, 3),
            "halts": self.halts,
            "planning": self._planning(),
            "oscillation_per_min": round(self.steering_sign_changes / mission_minutes, 3)
            if mission_minutes > 0 else None,
            "pose_error": pose_error,
            "event_digest": self._digest.hexdigest(),
            "maps": map_summary(self._system, self) if self._system is not None else None,
            # each event name's stream alone: equal in a split run, whose processes
            # interleave events of one instant differently (decision 0011)
            "event_digests": {name: d.hexdigest() for name, d in sorted(self._digests.items())},
            "vehicle": {"east": round(self.state.east, 3), "north": round(self.state.north, 3),
                        "heading_deg": round(self.state.heading_deg, 2),
                        "speed": round(self.state.speed, 3)},
        }

    def _planning(self) -> dict[str, Any]:
        """FindPath's plans, incremental replans and planning times, per instance."""
        from components.find_path.component import FindPath

        found: dict[str, Any] = {}
        for component in (self._system.components.values() if self._system else ()):
            if isinstance(component, FindPath):
                stats = component.statistics()
                found[component.name] = {key: stats.get(key) for key in (
                    "plans", "replans", "tracking_replans", "no_path", "plan_ms", "refined",
                    "undrivable", "refine_ms")}
        return found

    def course_reference(self) -> dict[str, Any]:
        """The shortest collision-free course on the fully known world
        (:func:`afa.sim.oracle.shortest_course`) and this run's ratio to it."""
        field = self._hazards or HazardField(self.terrain, self.vehicle.parameters)
        course = shortest_course(self.world, field)
        ratio = None
        if course.length and self.mission_distance is not None:
            ratio = round(self.mission_distance / course.length, 3)
        return {"oracle_distance_m": None if course.length is None
                else round(course.length, 3), "path_ratio": ratio}

    def progress(self) -> str:
        s = self.state
        return (f"pos=({s.east:7.1f},{s.north:7.1f}) hdg={s.heading_deg:5.1f} "
                f"v={s.speed:4.2f} m/s dist={s.travelled:6.1f} m collisions={len(self.collisions)}")


def _body_pose(poses: dict[str, np.ndarray], state: VehicleState) -> np.ndarray:
    """``state.transform()``, kept in ``poses`` (the frame poses of that state) under
    the key "" (no frame's name) so that the lasers' and the camera's frames share it."""
    body = poses.get("")
    if body is None:
        body = poses[""] = state.transform()
    return body
