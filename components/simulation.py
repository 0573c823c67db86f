"""The simulated Raptor: the world, the vehicle, and every device emulator (SPEC §2).

:class:`RaptorSimulation` owns the terrain and the vehicle model (``afa.sim``) and puts a
fake device in place of each configured device component, fed with ground truth: the
emulators speak the real wire protocols, so the real drivers run unchanged.

- GPS Sokkia: NovAtel logs of the antenna's position and velocity (with the receiver's
  noise model);
- IMU: 3DM-GX1 packets of the sensor's attitude, rates and specific force;
- MPC555: the controller's commands drive the vehicle model (its ``plant``), its reports
  carry the front wheels' distances;
- Nodding lasers: each scan line ray-cast against the heightfield at the beam angles
  and the nod angle the controller reports;
- Stereo: depth images ray-cast from the camera and turned into disparity.

Sensor poses come from the geometry model (``ModelFileName``), the vehicle pose from the
motion model. The simulation also runs the world's ``drive`` script through the Vehicle
Control interface and keeps the run summary (distance, collisions, waypoints, pose error
against ground truth, a digest of every event).
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from afa import ByteStream, Clock, EDevIO, Event, SerialSpec, System, TcpSpec
from afa.component import Component
from afa.sim.raycast import cast_rays, depth_image
from afa.sim.stats import RunningError
from afa.sim.terrain import Terrain
from afa.sim.vehicle import Vehicle, VehicleState
from afa.sim.world import World, load_world
from afa.transport import AsyncioByteStream, PtyDeviceStream, open_tcp
from components.gps_sokkia import GpsSokkia
from components.gps_sokkia.codec import PositionType, latlon_to_utm
from components.gps_sokkia.fake import FakeGps, GpsNoise, GpsTruth
from components.imu import Imu
from components.imu.fake import FakeImu, ImuTruth
from components.model_server.geometry import GeometryModel
from components.mpc555 import VehicleControl, WheelOdometry
from components.mpc555.fake import DriveCommand, FakeMpc555, WheelTruth, front_wheel_speeds
from components.nodding_laser import NodLaser
from components.nodding_laser.fake import FakeNodLaser
from components.stereo import Stereo
from components.stereo.backends import DIGICLOPS_MODEL, SyntheticBackend, serve_camera
from idl import PoseTransformIDL, VelocityIDL
from idl import VehicleControl as VehicleControlInterface

__all__ = ["RaptorSimulation", "DEFAULT_WORLD", "WAYPOINT_TOLERANCE"]

log = logging.getLogger("afa.sim")

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
DEFAULT_WORLD = CONFIGS / "worlds" / "open-field.xml"
VEHICLE_FRAME = "Raptor:RearAxleCenter"
#: A waypoint counts as reached when the rear axle passes within this distance (m).
WAYPOINT_TOLERANCE = 3.0
#: Physics step (s): 50 Hz, finer than every sensor but the laser's scan lines, which
#: are ray-cast at their own times from the latest state.
PHYSICS_STEP = 0.02
#: How often the drive script repeats its joystick command (s): Vehicle Control's
#: watchdog stops the vehicle when commands stop arriving, as a real joystick link would.
JOYSTICK_PERIOD = 0.1
#: The Raptor's GSR2600 took RTCA corrections from a Pacific Crest radio: NovAtel's RT-20
#: carrier-phase differential mode, 0.20 m CEP (OEM4 specification), i.e. about 0.17 m
#: per axis; errors correlated over ~10 s as the receiver's noise model says.
GPS_NOISE = GpsNoise(horizontal=0.17, vertical=0.34)
#: The stereo emulator ray-casts one depth sample per STEREO_SUBSAMPLE^2 pixels.
STEREO_SUBSAMPLE = 4


class RaptorSimulation:
    """A world, a vehicle, and the emulators for a System's device components.

    Use: ``sim = RaptorSimulation(world, clock, seed=...)``; ``sim.attach(system)``
    before the system starts; then ``async with sim: async with system: ...``.
    """

    @staticmethod
    def default_world() -> Path:
        return DEFAULT_WORLD

    def __init__(self, world: World | str | Path, clock: Clock, *, seed: int = 0,
                 geometry: GeometryModel | None = None, expose: bool = False) -> None:
        """``expose``: serve the serial emulators on pseudo-terminals (the drivers open
        them through pyserial-asyncio) and the lasers on loopback TCP ports, instead of
        in-memory pipes. Real I/O is not deterministic: use it with the wall clock."""
        self.world = world if isinstance(world, World) else load_world(world)
        self.clock = clock
        self.seed = seed
        self.terrain = Terrain.from_spec(self.world.terrain, self.world.obstacles)
        self.vehicle = Vehicle.from_world(self.world, self.terrain)
        self.geometry = geometry or GeometryModel.load(CONFIGS / "050917raptor01.XML")
        self._seeds = np.random.SeedSequence(seed)
        self._start = 0.0
        self._command = DriveCommand()
        self.collisions: list[dict[str, Any]] = []
        self.waypoints_reached = 0
        self._next_waypoint = 0
        self._digest = hashlib.sha256()
        self._pose_errors = RunningError()  # constant memory however long the run
        self.fakes: list[Any] = []
        self._mounts: dict[str, np.ndarray] = {}
        self._imu_cache: tuple[VehicleState, ImuTruth] | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._system: System | None = None
        self._mpc555: FakeMpc555 | None = None
        self.expose = expose
        self._exposed: dict[str, tuple[Any, str]] = {}  # component -> (fake, "serial"|"tcp")
        self._endpoints: list[Any] = []

    # -- wiring --------------------------------------------------------------------------
    def attach(self, system: System) -> None:
        """Install an emulator in place of each device component's real device."""
        self._system = system
        overrides = system.devices.overrides
        for component in system.components.values():
            if isinstance(component, Stereo):
                backend = SyntheticBackend(self.clock, render=self._stereo_renderer(component),
                                           rng=self._rng())
                overrides[component.name] = serve_camera(backend)
                continue
            fake = self._fake_for(component)
            if fake is None:
                continue
            overrides[component.name] = fake.factory()
            if self.expose:
                kind = "tcp" if isinstance(component, NodLaser) else "serial"
                self._exposed[component.name] = (fake, kind)
        system.channel.add_tap(self._observe)

    def _rng(self) -> np.random.Generator:
        return np.random.default_rng(self._seeds.spawn(1)[0])

    def _fake_for(self, component: Component) -> Any:
        """The emulator playing ``component``'s device, or None for a non-device."""
        if isinstance(component, GpsSokkia):
            fake: Any = FakeGps(self.clock, self._gps_truth, self._rng(), noise=GPS_NOISE)
        elif isinstance(component, Imu):
            fake = FakeImu(self.clock, self._imu_truth, rng=self._rng())
        elif isinstance(component, (WheelOdometry, VehicleControl)):
            if self._mpc555 is not None:  # one controller serves both components
                return self._mpc555
            fake = self._mpc555 = FakeMpc555(self.clock, plant=self._plant)
        elif isinstance(component, NodLaser):
            fake = FakeNodLaser(self.clock, source=self._laser_source(component),
                                offset_deg=component.parameters.LaserOffsetAngle,
                                rng=self._rng())
        else:
            return None
        self.fakes.append(fake)
        return fake

    # -- ground truth for the emulators ----------------------------------------------------
    @property
    def state(self) -> VehicleState:
        return self.vehicle.state

    def _mount(self, frame: str) -> np.ndarray:
        """^V T_frame from the geometry model (constant: looked up once per frame)."""
        mount = self._mounts.get(frame)
        if mount is None:
            mount = self._mounts[frame] = self.geometry.transformation(VEHICLE_FRAME, frame)
        return mount

    def _frame(self, frame: str) -> np.ndarray:
        """^W T_frame now: vehicle pose times the geometry model's ^V T_frame."""
        return self.state.transform() @ self._mount(frame)

    def _gps_truth(self, t: float) -> GpsTruth:
        state = self.state
        antenna = self._mount("GpsAntenna:PhaseCenter")[:3, 3]
        rotation = state.rotation()
        position = state.position + rotation @ antenna
        omega = rotation @ state.angular_velocity_body()
        velocity = state.velocity() + np.cross(omega, rotation @ antenna)
        lat, lon, height = self.world.origin.enu_to_geodetic(*position)
        speed = float(math.hypot(velocity[0], velocity[1]))
        track = math.degrees(math.atan2(velocity[0], velocity[1])) % 360.0 if speed > 1e-6 \
            else state.heading_deg
        return GpsTruth(lat=lat, lon=lon, height=self.world.origin.elevation + position[2],
                        speed=speed, track=track, vertical_speed=float(velocity[2]),
                        position_type=PositionType.L1_FLOAT)

    def _imu_truth(self, t: float) -> ImuTruth:
        state = self.state
        cached = self._imu_cache
        if cached is not None and cached[0] is state:  # the IMU samples 2x per physics step
            return cached[1]
        mount = self._mount("Imu:SensorCenter")[:3, :3]
        to_sensor = mount.T  # sensor-from-vehicle
        # The 3DM-GX1's angles are NED-style (x forward, y right, z down).
        yaw = math.remainder(math.pi / 2 - state.yaw, 2 * math.pi)
        truth = ImuTruth(roll=state.roll, pitch=-state.pitch, yaw=yaw,
                         accel=tuple((to_sensor @ state.specific_force_body()).tolist()),
                         rates=tuple((to_sensor @ state.angular_velocity_body()).tolist()))
        self._imu_cache = (state, truth)
        return truth

    def _plant(self, t: float, command: DriveCommand) -> WheelTruth:
        """The MPC555's view of the vehicle: its commands become the physics loop's
        targets; it reads back the front wheels' distances and speeds."""
        self._command = command
        state = self.state
        parameters = self.vehicle.parameters
        left, right = front_wheel_speeds(state.speed, state.yaw_rate, parameters.wheelbase,
                                         parameters.track)
        return WheelTruth(time=t, left_distance=state.front_left_distance,
                          right_distance=state.front_right_distance, left_speed=left,
                          right_speed=right, speed=state.speed, steering=state.steering,
                          yaw_rate=state.yaw_rate)

    def _laser_source(self, component: NodLaser) -> Callable[..., np.ndarray]:
        frame = ("FrontNoddingSICKLeft:AxleCenterFreeEnd"
                 if component.parameters.LaserID == 11 else
                 "FrontNoddingSICKRight:AxleCenterFreeEnd")
        max_range = 8.183

        beams: list[np.ndarray] = []  # the last bearings seen, their sines and -cosines

        def source(t: float, nod_deg: np.ndarray, bearings_deg: np.ndarray) -> np.ndarray:
            pose = self._frame(frame)
            if not beams or beams[0] is not bearings_deg:  # the fake reuses one array
                b = np.deg2rad(bearings_deg)
                beams[:] = [bearings_deg, np.sin(b), -np.cos(b)]
            _, sin_b, minus_cos_b = beams
            n = np.deg2rad(nod_deg)
            local = np.empty((sin_b.size, 3))
            np.multiply(sin_b, np.cos(n), out=local[:, 0])
            local[:, 1] = minus_cos_b
            np.multiply(sin_b, np.sin(n), out=local[:, 2])
            # NaN (nothing within range) is a no-return for the fake, as inf would be
            return cast_rays(self.terrain, pose[:3, 3], local @ pose[:3, :3].T, max_range)

        return source

    def _stereo_renderer(self, component: Stereo) -> Callable[[float], np.ndarray]:
        """Depth images ray-cast from the camera, ``STEREO_SUBSAMPLE`` times coarser than
        the 320x240 disparity image and repeated to full size (a 76,800-ray image costs
        ~0.1 s; the coarse one ~6 ms, and the component still sees 320x240)."""
        max_range = component.parameters.MaxRange / 1000.0 * 1.25
        model, k = DIGICLOPS_MODEL, STEREO_SUBSAMPLE
        fov = math.degrees(2 * math.atan(0.5 * model.width / model.focal_px))

        def render(t: float) -> np.ndarray:
            pose = self._frame("Digiclops:ImagePlane")
            coarse = depth_image(self.terrain, pose[:3, 3], pose[:3, :3], model.width // k,
                                 model.height // k, fov, max_range)
            h, w = coarse.shape
            return np.broadcast_to(coarse[:, None, :, None], (h, k, w, k)).reshape(h * k, w * k)

        return render

    # -- running ---------------------------------------------------------------------------
    async def _expose_devices(self) -> None:
        """Serve each exposed emulator on a pseudo-terminal or a loopback TCP port and
        point its component at it (through the real serial and TCP transports)."""
        assert self._system is not None
        devices = self._system.devices
        loop = asyncio.get_running_loop()
        ptys: dict[int, PtyDeviceStream] = {}
        for name, (fake, kind) in self._exposed.items():
            if kind == "serial":
                pty = ptys.get(id(fake))
                if pty is None:  # one terminal per emulated device (MPC555: two components)
                    pty = ptys[id(fake)] = PtyDeviceStream()
                    self._endpoints.append(pty)
                    self._tasks.append(loop.create_task(fake.serve(pty)))

                async def open_pty(spec: SerialSpec, path: str = pty.path) -> ByteStream:
                    return await devices.open_serial(SerialSpec(path, spec.baudrate))

                devices.overrides[name] = open_pty
                log.info("%s: emulated on %s", name, pty.path)
            else:
                async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                                 fake: Any = fake) -> None:
                    await fake.serve(AsyncioByteStream(reader, writer, "laser"))

                server = await asyncio.start_server(handle, "127.0.0.1", 0)
                self._endpoints.append(server)
                port = server.sockets[0].getsockname()[1]

                async def open_socket(spec: TcpSpec, port: int = port) -> ByteStream:
                    return await open_tcp("127.0.0.1", port)

                devices.overrides[name] = open_socket
                log.info("%s: emulated on 127.0.0.1:%d", name, port)

    async def __aenter__(self) -> RaptorSimulation:
        self._start = self.clock.now()
        loop = asyncio.get_running_loop()
        self._tasks = [loop.create_task(self._physics(), name="afa-sim-physics")]
        if self._exposed:
            await self._expose_devices()
        if self.world.drive and self._system is not None:
            self._tasks.append(loop.create_task(self._drive_script(), name="afa-sim-drive"))
        return self

    async def __aexit__(self, *exc: object) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            try:
                await task
            except asyncio.CancelledError:
                pass
            except Exception:
                log.exception("simulation task failed")
        for fake in self.fakes:
            await fake.aclose()
        for endpoint in self._endpoints:
            if isinstance(endpoint, asyncio.AbstractServer):
                endpoint.close()
            else:
                await endpoint.close()

    @property
    def sim_time(self) -> float:
        return self.clock.now() - self._start

    async def _physics(self) -> None:
        async for _ in self.clock.periodic(PHYSICS_STEP):
            command = self._command
            speed = 0.0 if command.brake else command.translation
            before = self.vehicle.collision
            self.vehicle.step(PHYSICS_STEP, speed, math.degrees(command.steering), self.terrain)
            collision = self.vehicle.collision
            if collision is not None and before is None:
                record = {"time": round(self.sim_time, 3), "east": round(collision.east, 3),
                          "north": round(collision.north, 3), "obstacle": collision.obstacle,
                          "kind": str(getattr(collision.kind, "value", collision.kind))}
                self.collisions.append(record)
                log.warning("collision: %s", record)
            self._track_waypoints()

    def _track_waypoints(self) -> None:
        waypoints = self.world.mission.waypoints
        if not waypoints or self._next_waypoint >= len(waypoints):
            return
        target = waypoints[self._next_waypoint]
        distance = math.hypot(self.state.east - target.east, self.state.north - target.north)
        if distance <= WAYPOINT_TOLERANCE:
            self.waypoints_reached += 1
            self._next_waypoint += 1
            if self.world.mission.patrol:
                self._next_waypoint %= len(waypoints)

    async def _drive_script(self) -> None:
        """Tele-operation: the world's timed commands, sent as a joystick would."""
        assert self._system is not None
        names = [c.name for c in self._system.components.values() if isinstance(c, VehicleControl)]
        if not names:
            log.warning("the world has a drive script but no VehicleControl is configured")
            return
        control_name = self._system.components[names[0]].parameters.RaptorMotionEvent
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
                return

    # -- observation -------------------------------------------------------------------------
    def _observe(self, event: Event) -> None:
        digest = self._digest
        digest.update(f"{event.type}|{event.time:.6f}|".encode())
        digest.update(event.body.fingerprint())  # arrays by their SHA-256
        if isinstance(event.body, PoseTransformIDL) and event.type == "Pose":
            self._pose_error(event.body)

    def _pose_error(self, pose: PoseTransformIDL) -> None:
        state = self.state
        lat, lon = self.world.origin.to_geodetic(state.east, state.north)
        utm = latlon_to_utm(lat, lon)
        ahead = self.world.origin.to_geodetic(state.east + 10 * math.cos(state.yaw),
                                              state.north + 10 * math.sin(state.yaw))
        utm_ahead = latlon_to_utm(*ahead, zone=utm.zone_number)
        grid_yaw = math.atan2(utm_ahead.northing_m - utm.northing_m,
                              utm_ahead.easting_m - utm.easting_m)
        east = pose.HTransform[0, 3] + pose.initialUTM[0]
        north = pose.HTransform[1, 3] + pose.initialUTM[1]
        yaw = math.atan2(pose.HTransform[1, 0], pose.HTransform[0, 0])
        self._pose_errors.add(self.sim_time,
                              math.hypot(east - utm.easting_m, north - utm.northing_m),
                              math.degrees(math.remainder(yaw - grid_yaw, 2 * math.pi)))

    def summary(self) -> dict[str, Any]:
        """The simulation's part of the run summary."""
        pose_error = self._pose_errors.summary()  # after the filter's first seconds
        return {
            "world": self.world.name,
            "seed": self.seed,
            "distance_m": round(self.state.distance, 3),
            "collisions": list(self.collisions),
            "waypoints_reached": self.waypoints_reached,
            "waypoints_total": len(self.world.mission.waypoints),
            "pose_error": pose_error,
            "event_digest": self._digest.hexdigest(),
            "vehicle": {"east": round(self.state.east, 3), "north": round(self.state.north, 3),
                        "heading_deg": round(self.state.heading_deg, 2),
                        "speed": round(self.state.speed, 3)},
        }

    def progress(self) -> str:
        s = self.state
        return (f"pos=({s.east:7.1f},{s.north:7.1f}) hdg={s.heading_deg:5.1f} "
                f"v={s.speed:4.2f} m/s dist={s.distance:6.1f} m collisions={len(self.collisions)}")
