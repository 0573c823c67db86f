"""The simulated Raptor end to end: real drivers on emulated devices in virtual time."""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from afa import VirtualClock
from afa.sim.world import parse_world
from components.simulation import RaptorSimulation

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"
WORLDS = ROOT / "configs" / "worlds"


async def simulate(world, duration, seed=0):
    # the world's scripted drive: these tests are about the sensing stack
    simulation = RaptorSimulation.from_xml(RAPTOR, world, clock=VirtualClock(), seed=seed,
                                           teleop=True)
    async with simulation:
        await simulation.system.run(duration)
        statistics = simulation.system.statistics()
        health = simulation.system.health()
    return simulation, statistics, health


async def test_every_emulated_device_is_decoded_by_its_real_driver_at_the_seed_rates():
    simulation, statistics, health = await simulate(WORLDS / "open-field.xml", 10.0)
    events = statistics["events"]
    assert simulation.sim_time == pytest.approx(10.0)  # from the end of start-up
    elapsed = simulation.clock.monotonic()  # the whole run: start-up (Launcher dT) included
    assert 10.0 < elapsed < 12.0
    assert all(h.healthy for h in health.values()), {n: h.detail for n, h in health.items()}

    def rate(name, period):
        # each device started up to 1.5 s into the run (connection, configuration)
        assert (elapsed - 1.5) / period - 1 <= events[name] <= elapsed / period + 1, name

    rate("Gps", 0.25)  # Table 7
    rate("Imu", 0.1)  # Table 5
    rate("RaptorOdometry", 0.2)  # Table A.5 WheelDistRepTime
    rate("Stereo", 0.5)  # Table A.2 frameRate 2
    rate("Laser11", 0.02666)  # Table 1: 26.6 ms
    rate("Laser12", 0.02666)
    assert events["Pose"] > 100
    assert statistics["events_dropped"] == 0
    summary = simulation.summary()
    assert summary["distance_m"] > 8.0  # the drive script moved the vehicle at 1.5 m/s
    assert summary["collisions"] == []
    assert summary["pose_error"]["rms_position_m"] < 1.0


async def test_same_seed_same_event_digest_and_a_different_seed_differs():
    world = WORLDS / "slalom.xml"
    first, _, _ = await simulate(world, 3.0, seed=7)
    second, _, _ = await simulate(world, 3.0, seed=7)
    third, _, _ = await simulate(world, 3.0, seed=8)
    assert first.summary()["event_digest"] == second.summary()["event_digest"]
    assert first.summary()["event_digest"] != third.summary()["event_digest"]


BOX_AHEAD = b"""<world name="box-ahead">
  <origin latitude="50.2717" longitude="-111.1766" elevation="750.0"/>
  <terrain width="60" depth="60" resolution="0.1" roughness="0.0" seed="1"/>
  <obstacle type="box" east="10" north="0" length="2" width="4" height="1.0" heading="0"/>
  <vehicle east="0" north="0" heading="90"/>
  <drive><command time="0" speed="1.5" steering="0"/></drive>
</world>"""


async def test_driving_into_a_box_is_a_collision_that_stops_the_vehicle():
    world = parse_world(BOX_AHEAD)
    simulation, _, _ = await simulate(world, 12.0)
    summary = simulation.summary()
    assert len(summary["collisions"]) == 1
    collision = summary["collisions"][0]
    assert collision["obstacle"] == 0
    # heading 0: the box's 4 m width spans east 8..12; the front bumper (2.45 m ahead of
    # the rear axle) meets its face at east = 8
    assert collision["east"] == pytest.approx(8.0, abs=0.2)
    assert summary["vehicle"]["speed"] == 0.0
    assert summary["vehicle"]["east"] == pytest.approx(8.0 - 2.45, abs=0.2)


def test_cli_sim_fast_writes_the_summary(tmp_path):
    summary_path = tmp_path / "s.json"
    result = subprocess.run(
        [sys.executable, "-m", "afa", "run", str(RAPTOR), "--sim", "--fast", "--duration", "10",
         "--world", str(WORLDS / "rock-field.xml"), "--seed", "3", "--summary",
         str(summary_path)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    summary = json.loads(summary_path.read_text())
    for key in ("sim_time_s", "wall_time_s", "realtime_factor", "distance_m", "collisions",
                "waypoints_reached", "waypoints_total", "events", "events_dropped",
                "component_errors", "pose_error", "event_digest"):
        assert key in summary, key
    assert summary["world"] == "rock-field" and summary["sim_time_s"] >= 10.0
    assert math.isfinite(summary["realtime_factor"])


async def test_exposed_emulators_go_through_real_ptys_and_loopback_tcp():
    """The pyserial-asyncio and TCP transports end to end (wall clock: real I/O)."""
    from afa import WallClock

    simulation = RaptorSimulation.from_xml(RAPTOR, WORLDS / "open-field.xml", clock=WallClock(),
                                           expose=True, real_devices=True)
    async with simulation:
        system = simulation.system
        await system.run(3.0)  # a bounded run, not a timing assertion
        events = system.statistics()["events"]
        health = system.health()
    for name in ("Gps", "Imu", "RaptorOdometry", "Laser11", "Laser12"):
        assert events.get(name, 0) > 0, (name, events)
    for name in ("3dmgService", "GpsSokkiaService", "RaptorOdometryService", "RaptorService",
                 "NodLaserService", "NodLaserService12"):
        # came up through the real transports (healthy at the end would also ask that a
        # loaded machine never starved a 0.6 s device watchdog of wall time)
        assert health[name].ever_healthy, (name, health[name].detail)
    assert sorted(simulation.endpoints) == sorted(
        ["3dmgService", "GpsSokkiaService", "RaptorOdometryService", "RaptorService",
         "NodLaserService", "NodLaserService12"])
    assert all(value.startswith(("/dev/pts/", "127.0.0.1:"))
               for value in simulation.endpoints.values())


def test_a_paced_run_keeps_to_its_realtime_factor_and_takes_a_world_by_name(tmp_path):
    summary_path = tmp_path / "s.json"
    result = subprocess.run(
        [sys.executable, "-m", "afa", "run", str(RAPTOR), "--sim", "--world", "slalom",
         "--teleop", "--realtime-factor", "40", "--duration", "10", "--summary",
         str(summary_path)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    summary = json.loads(summary_path.read_text())
    assert summary["world"] == "slalom" and summary["mode"] == "teleop"
    # pacing caps the speed (an upper bound: a slow machine cannot make this fail)
    assert summary["realtime_factor"] <= 40 * 1.05


async def test_the_least_clearance_is_the_least_over_every_physics_step(monkeypatch):
    """The lookups the simulation skips (decision 0021) never hide a closer approach:
    after every physics step the least clearance equals the least of the outline's
    clearance looked up at every step so far."""
    simulation = RaptorSimulation.from_xml(RAPTOR, WORLDS / "rock-field.xml",
                                           clock=VirtualClock(), seed=0, teleop=True)
    every_step: list[float] = []
    mismatches: list[tuple[int, float, float]] = []
    track = simulation._track_clearance

    def track_and_look(self=simulation):
        state, outline = self.state, self.vehicle.footprint(0.35)
        c, s = math.cos(state.yaw), math.sin(state.yaw)
        every_step.append(self._hazards.clearance(
            state.east + outline[:, 0] * c - outline[:, 1] * s,
            state.north + outline[:, 0] * s + outline[:, 1] * c))
        track()
        if self.clearance != min(every_step):
            mismatches.append((len(every_step), self.clearance, min(every_step)))

    monkeypatch.setattr(simulation, "_track_clearance", track_and_look)
    async with simulation:
        await simulation.system.run(12.0)
    assert len(every_step) > 500 and simulation.state.distance > 5.0
    assert math.isfinite(simulation.clearance)
    assert simulation.clearance == min(every_step)
    assert mismatches == []


def test_the_hazard_field_is_built_before_the_system_starts(monkeypatch):
    """The clearance field takes a CPU-bound half second on a big world: built when the
    physics started, with the drivers already running on the wall clock of a real-time
    `--sim` run, it starved them (the MPC555 link "lost" for 0.6 s at start-up). It is
    built with the simulation, before anything runs."""
    import components.simulation as simulation
    from afa.cli import main
    from afa.system import System

    order: list[str] = []
    field, start = simulation.HazardField, System.start

    def hazard_field(*args, **kwargs):
        order.append("hazards")
        return field(*args, **kwargs)

    async def system_start(self):
        order.append("system")
        await start(self)

    monkeypatch.setattr(simulation, "HazardField", hazard_field)
    monkeypatch.setattr(System, "start", system_start)
    config = Path(__file__).resolve().parents[2] / "configs" / "raptor.xml"
    assert main(["run", str(config), "--sim", "--fast", "--world", "short-hop",
                 "--duration", "0.5"]) == 0
    assert order[:2] == ["hazards", "system"], order


def test_the_judge_counts_a_waypoint_reached_by_the_rear_axle_or_the_front_bumper():
    """The mission's judge takes the points the vehicle itself judges by (the Global Map,
    FindPath and Pure Pursuit: rear axle or front bumper), on the true pose: a waypoint
    short of a wall is reached bumper first."""
    from components.simulation import WAYPOINT_TOLERANCE
    simulation = RaptorSimulation(WORLDS / "short-hop.xml", VirtualClock())
    first, second = simulation.world.mission.waypoints[:2]
    bumper = 2.45  # the simulated Raptor's front bumper, ahead of the rear axle (m)
    vehicle = simulation.vehicle
    # facing east towards the first: the bumper just outside the tolerance, then inside
    vehicle.reset(first.east - bumper - WAYPOINT_TOLERANCE - 0.05, first.north, 90.0)
    simulation._track_waypoints()  # noqa: SLF001 - the judge under test
    assert simulation.waypoints_reached == 0
    vehicle.reset(first.east - bumper - WAYPOINT_TOLERANCE + 0.05, first.north, 90.0)
    simulation._track_waypoints()  # noqa: SLF001
    assert simulation.waypoints_reached == 1
    # beyond the second, facing away from it (east): the rear axle reaches it
    vehicle.reset(second.east + WAYPOINT_TOLERANCE + 0.05, second.north, 90.0)
    simulation._track_waypoints()  # noqa: SLF001
    assert simulation.waypoints_reached == 1
    vehicle.reset(second.east + WAYPOINT_TOLERANCE - 0.05, second.north, 90.0)
    simulation._track_waypoints()  # noqa: SLF001
    assert simulation.waypoints_reached == 2


def test_a_patrol_of_one_waypoint_is_reached_once(tmp_path):
    """A patrol needs two waypoints (Pure Pursuit and the Global Map finish one of one
    waypoint there): the judge counts the arrival once, not on every step the vehicle
    stands on it."""
    world = tmp_path / "one.xml"
    world.write_text(
        '<world name="one"><origin latitude="50.27" longitude="-111.18" elevation="750"/>'
        '<terrain width="40" depth="40" resolution="0.5"/>'
        '<vehicle east="0" north="0" heading="90"/>'
        '<mission patrol="true"><waypoint east="10" north="0"/></mission></world>')
    simulation = RaptorSimulation(world, VirtualClock())
    simulation.vehicle.reset(9.0, 0.0, 90.0)
    for _ in range(5):
        simulation._track_waypoints()  # noqa: SLF001 - the judge under test
    assert simulation.waypoints_reached == 1
    assert simulation.finished.is_set()
