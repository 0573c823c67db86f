"""Obstacle Detection (the laser safety catch) as a component, through its ports.

The latency test runs the real chain of the shipped configuration: the nodding lasers'
drivers on fake controllers (NLC v1 scans), ModelServer's geometry, LaserSafetyService
(ObstacleDetection) → ArcVote → arcArbiter (ArcArbiter) → setVelocity → RaptorService
(Vehicle Control, the MPC555 driver) → a 115200 baud serial line → the fake MPC555, whose
received bytes are decoded with the MPC555 codec. The scene is computed here, by its own
geometry: flat ground 2 m below the nod axis and, from a chosen moment, a wall across the
path 1.5 m ahead of the lasers.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from vehicle_rig import Cruise, SerialLine, decode_host_bytes, stops_after, wire_commands

from afa import System, VirtualClock
from afa.testing import until
from components.model_server.geometry import GeometryModel
from components.mpc555.codec import SetVelocity
from components.mpc555.fake import FakeMpc555
from components.nodding_laser.component import LASER_FRAMES, SCAN_PERIODS
from components.nodding_laser.fake import FakeNodLaser
from idl import Range3dLaserIDL, Range3dSeqEventIDL, TimeIDL
from idl import VehicleControl as VehicleControlInterface

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "raptor.xml"
CONFIGS = ROOT / "configs"
GEOMETRY = GeometryModel.load(CONFIGS / "050917raptor01.XML")
VEHICLE = "Raptor:RearAxleCenter"
#: Seed Table 1 / issue 12: the bound on the safety catch's halt, one scan period.
SCAN_PERIOD_BOUND = 0.0266
#: The nod axis above the ground (the fakes' flat ground; Table A.11 LaserHeight).
NOD_AXIS_HEIGHT = 2.0


class WallAhead:
    """A range source for a fake nodding laser: flat ground ``NOD_AXIS_HEIGHT`` below
    the nod axis and, for scans starting at or after ``appears``, a wall across the path
    ``distance`` m ahead of the laser (vehicle-aligned), ``height`` m high and
    ``half_width`` m either side of the vehicle's centre line.

    For every scan it records when the frame went out and how many returns it put on the
    wall inside ``corridor`` (half width, length) higher than ``threshold`` above the
    ground: its own geometry, not the detector's.
    """

    def __init__(self, clock: VirtualClock, frame: str, *, appears: float,
                 distance: float = 1.5, height: float = 1.2, half_width: float = 2.0,
                 corridor: tuple[float, float], threshold: float) -> None:
        mount = GEOMETRY.transformation(VEHICLE, frame)
        self.rotation = mount[:3, :3]
        self.lateral = float(mount[1, 3])  # the laser beside the centre line
        self.clock = clock
        self.appears = appears
        self.distance, self.height, self.half_width = distance, height, half_width
        self.corridor, self.threshold = corridor, threshold
        self.scans: list[tuple[float, float, int]] = []  # (frame sent, scan start, hits)

    def __call__(self, t: float, nod_deg: np.ndarray, bearings_deg: np.ndarray) -> np.ndarray:
        b, n = np.deg2rad(bearings_deg), np.deg2rad(nod_deg)
        beams = np.stack([np.sin(b) * np.cos(n), -np.cos(b), np.sin(b) * np.sin(n)], axis=1)
        d = beams @ self.rotation.T  # vehicle-aligned directions
        with np.errstate(divide="ignore", invalid="ignore"):
            ranges = np.where(d[:, 2] < 0, NOD_AXIS_HEIGHT / -d[:, 2], np.inf)
            hits = 0
            if t >= self.appears:
                to_wall = np.where(d[:, 0] > 0, self.distance / d[:, 0], np.inf)
                height = NOD_AXIS_HEIGHT + to_wall * d[:, 2]
                side = self.lateral + to_wall * d[:, 1]
                on_wall = ((d[:, 0] > 0) & (height <= self.height) & (height >= 0)
                           & (np.abs(side) <= self.half_width) & (to_wall < ranges))
                ranges = np.where(on_wall, to_wall, ranges)
                half, length = self.corridor
                hits = int(np.count_nonzero(on_wall & (np.abs(side) <= half)
                                            & (self.distance <= length)
                                            & (height > self.threshold)))
        # the fake sends the frame right after asking its source (at the scan's end)
        self.scans.append((self.clock.monotonic(), t, hits))
        return ranges


async def test_a_halt_reaches_the_mpc555_wire_within_one_scan_period(capsys):
    clock = VirtualClock(start=0.0)
    appears = 6.0123  # between scans, not on any timer's grid
    probe = System.from_xml(CONFIG, only=["LaserSafetyService"], clock=clock)
    detection = probe.components["LaserSafetyService"].parameters
    corridor = (min(detection.VehicleWidth / 2, detection.DefaultYMax), detection.SafetyDist)
    walls = {name: WallAhead(clock, LASER_FRAMES[laser_id], appears=appears,
                             corridor=corridor, threshold=detection.SafetyHeight)
             for name, laser_id in (("NodLaserService", 11), ("NodLaserService12", 12))}
    lasers = {name: FakeNodLaser(clock, source=wall, offset_deg=-2.0)
              for name, wall in walls.items()}
    mpc = FakeMpc555(clock, record=True)
    line = SerialLine(clock)
    devices = {name: fake.factory() for name, fake in lasers.items()}
    devices["RaptorService"] = line.factory(mpc.factory())
    system = System.from_xml(
        CONFIG, clock=clock, devices=devices,
        only=["NodLaserService", "NodLaserService12", "RaptorService", "modelServer",
              "LaserSafetyService", "arcArbiter"])
    system.add(Cruise(speed=0.5))
    try:
        async with system:
            decisions = system.channel.subscribe("Raptor", "ArcDecision", maxsize=4096)
            vc = system.components["RaptorService"]
            await until(lambda: vc.configured, clock, what="the MPC555 configured")
            control = await system.resolve(VehicleControlInterface, "RaptorMotion")
            await control.startVehicle()
            await control.setArbiter(True)
            await clock.advance(appears + 1.0 - clock.monotonic())
            od_stats = system.components["LaserSafetyService"].statistics()
    finally:
        for fake in [*lasers.values(), mpc]:
            await fake.aclose()

    # The vehicle was driving before the wall appeared: 0.5 m/s commands on the wire.
    drives = [r for r in wire_commands(mpc, SetVelocity) if r.command.translation_mm_s > 0]
    assert drives and drives[0].time < appears - 1.0
    assert not stops_after(mpc, drives[0].time) or stops_after(mpc, drives[0].time)[0].time \
        > appears, "stopped before the wall appeared"
    # The first scan (of either laser) that shows the wall inside the corridor.
    shown = sorted((sent, start, hits) for wall in walls.values()
                   for sent, start, hits in wall.scans if hits > 0)
    assert shown and shown[0][2] >= detection.NumHitsTolerance
    sent, start, _ = shown[0]
    assert appears <= start < appears + SCAN_PERIODS[50]
    stop = stops_after(mpc, sent)[0]
    latency = stop.time - sent
    print(f"\nObstacle Detection halt latency on the MPC555 wire: {latency * 1000:.3f} ms "
          f"after the scan frame ({(stop.time - start) * 1000:.3f} ms after the scan's first "
          f"beam; scan period {SCAN_PERIODS[50] * 1000:.2f} ms)")
    assert 0.0 < latency <= SCAN_PERIOD_BOUND
    # It is the arbiter's fail-safe on Obstacle Detection's veto, decoded off the wire.
    assert stop.command == SetVelocity(0, 0)
    assert SetVelocity(0, 0) in decode_host_bytes(mpc)
    halts = [e for e in _drain(decisions) if e.body.failsafe == "all-vetoed"]
    assert halts and halts[0].time >= sent  # published once the command is acknowledged
    assert "ObstacleDetection" in halts[0].body.fresh
    assert od_stats["halts"] == 1
    with capsys.disabled():
        print(f"OD latency: {latency * 1000:.3f} ms")


def _drain(subscription) -> list:
    events = []
    while (event := subscription.get_nowait()) is not None:
        events.append(event)
    return events


# --------------------------------------------------------------------------- through the ports

def scan_of(points_vehicle: np.ndarray, laser_id: int = 11, t: float = 0.0,
            array: bool = False) -> Range3dSeqEventIDL | Range3dLaserIDL:
    """A scan line whose points, in the laser's frame, lie at ``points_vehicle``: (x ahead
    of the laser, y left of the vehicle's centre line, height above the ground)."""
    mount = GEOMETRY.transformation(VEHICLE, LASER_FRAMES[laser_id])
    offset = np.array([0.0, mount[1, 3], NOD_AXIS_HEIGHT])
    local = (np.asarray(points_vehicle, dtype=np.float64) - offset) @ mount[:3, :3]
    header = {"time": TimeIDL.from_seconds(t), "sensorId": laser_id,
              "frame": LASER_FRAMES[laser_id]}
    if array:
        return Range3dLaserIDL(**header, points=local.astype(np.float32),
                               valid=np.ones(len(local), dtype=bool))
    return Range3dSeqEventIDL(**header, points=local.astype(np.float32))


def returns(count: int, *, ahead: float = 1.5, height: float = 1.0, side: float = 0.0
            ) -> np.ndarray:
    """``count`` returns on a small object ``ahead`` m in front of the laser."""
    y = side + np.linspace(-0.1, 0.1, count) if count > 1 else np.full(count, side)
    return np.stack([np.full(count, ahead), y, np.full(count, height)], axis=1)


GROUND = np.stack([np.linspace(1.0, 6.0, 40), np.linspace(-0.6, 0.6, 40), np.zeros(40)],
                  axis=1)


@asynccontextmanager
async def detection() -> AsyncIterator[tuple[System, VirtualClock, Any, Any]]:
    clock = VirtualClock(start=0.0)
    system = System.from_xml(CONFIG, clock=clock, only=["LaserSafetyService", "modelServer"])
    async with system:
        votes = system.channel.subscribe("Raptor", "ArcVote", maxsize=1024)
        yield system, clock, votes, system.components["LaserSafetyService"]


def publish(system: System, scan: Any, event: str = "Laser11") -> None:
    system.channel.publish("Raptor", event, scan, origin="test")


async def test_a_halt_vetoes_every_arc_then_holds_for_reset_counter_scans_and_rechecks():
    async with detection() as (system, clock, votes, od):
        p = od.parameters
        obstacle = np.concatenate([GROUND, returns(p.NumHitsTolerance)])
        await clock.advance(1.0)
        publish(system, scan_of(GROUND))
        await clock.advance(0.0266)
        (clear,) = _drain(votes)
        assert not clear.body.veto.any() and not clear.body.certainty.any()
        publish(system, scan_of(obstacle))
        await clock.advance(0.0266)
        (halt,) = _drain(votes)
        assert halt.body.behaviour == "ObstacleDetection" and halt.body.veto.all()
        assert halt.body.curvatures.tolist() == od.arcs.curvatures.tolist()
        # the next ResetCounter scans are not checked: nothing is published
        for _ in range(p.ResetCounter):
            publish(system, scan_of(obstacle))
            await clock.advance(0.0266)
        assert _drain(votes) == []
        # then it checks again: still there, halt again; gone, a clear vote
        publish(system, scan_of(obstacle))
        await clock.advance(0.0266)
        assert [e.body.veto.all() for e in _drain(votes)] == [True]
        for _ in range(p.ResetCounter):
            publish(system, scan_of(GROUND))
            await clock.advance(0.0266)
        publish(system, scan_of(GROUND))
        await clock.advance(0.0266)
        assert [e.body.veto.any() for e in _drain(votes)] == [False]
        assert od.statistics()["halts"] == 2


async def test_clear_votes_go_out_at_pure_pursuits_rate_and_a_halt_at_once():
    """A clear vote weighs nothing: one per CLEAR_REFRESH keeps it fresh (two lasers
    scanning 75 times a second would otherwise make 75 arbiter decisions of nothing); a
    halt is never held back, whatever went out just before it."""
    from components.obstacle_detection.component import CLEAR_REFRESH
    period = 0.0266
    async with detection() as (system, clock, votes, od):
        p = od.parameters
        await clock.advance(1.0)
        for _ in range(76):  # two seconds of both lasers
            publish(system, scan_of(GROUND, laser_id=11), "Laser11")
            publish(system, scan_of(GROUND, laser_id=12), "Laser12")
            await clock.advance(period)
        clears = _drain(votes)
        times = [e.time for e in clears]
        assert all(not e.body.veto.any() for e in clears)
        assert len(clears) == pytest.approx(76 * period / CLEAR_REFRESH, abs=2)
        assert min(np.diff(times)) >= CLEAR_REFRESH - 1e-9
        assert max(np.diff(times)) <= CLEAR_REFRESH + period + 1e-9
        while not (sent := _drain(votes)):  # up to the scan that sends a clear vote
            publish(system, scan_of(GROUND))
            await clock.advance(period)
        publish(system, scan_of(np.concatenate([GROUND, returns(p.NumHitsTolerance)])))
        await clock.advance(0.001)
        (halt,) = _drain(votes)
        assert halt.body.veto.all() and halt.time - sent[-1].time < CLEAR_REFRESH


@pytest.mark.parametrize(("what", "points", "halts"), [
    ("a post ahead", returns(5), True),
    ("noise below NumHitsTolerance", returns(4), False),
    ("a ditch ahead", returns(8, height=-0.6), True),
    ("a shallow dip", returns(8, height=-0.2), False),
    ("a post beside the corridor", returns(8, side=1.5), False),
    ("a post beyond SafetyDist", returns(8, ahead=4.0), False),
    ("a low stone", returns(8, height=0.2), False),
])
async def test_what_halts_and_what_does_not(what, points, halts):
    async with detection() as (system, clock, votes, od):
        p = od.parameters
        # the configured thresholds these cases sit on either side of
        assert p.NumHitsTolerance == 5 and p.SafetyHeight == p.SafetyDepth == 0.3
        assert p.SafetyDist == 3.0 and p.VehicleWidth / 2 < 1.5
        await clock.advance(1.0)
        publish(system, scan_of(np.concatenate([GROUND, points])))
        await clock.advance(0.0266)
        (vote,) = _drain(votes)
        assert bool(vote.body.veto.all()) is halts, what


async def test_both_scan_forms_and_both_lasers_are_checked():
    async with detection() as (system, clock, votes, od):
        await clock.advance(1.0)
        publish(system, scan_of(np.concatenate([GROUND, returns(6)]), laser_id=12,
                                array=True), event="Laser12")
        await clock.advance(0.0266)
        (vote,) = _drain(votes)
        assert vote.body.veto.all()


async def test_scans_in_a_frame_modelserver_does_not_know_are_ignored_and_counted():
    async with detection() as (system, clock, votes, od):
        await clock.advance(1.0)
        scan = scan_of(np.concatenate([GROUND, returns(6)]))
        publish(system, scan.model_copy(update={"frame": "NoSuchBody:Frame"}))
        await clock.advance(0.0266)
        assert _drain(votes) == []
        assert od.statistics()["unknown_frames"] == 1
        health = od.health()  # blind to that laser: not healthy, and it says why
        assert not health.healthy and "NoSuchBody:Frame" in health.detail


async def test_the_corridor_covers_the_vehicles_width():
    """A post 0.6 m off the centre line, 1.5 m ahead: the Raptor's 1.4 m body would hit
    it, so the safety catch must halt."""
    async with detection() as (system, clock, votes, od):
        await clock.advance(1.0)
        publish(system, scan_of(np.concatenate([GROUND, returns(8, side=0.6)])))
        await clock.advance(0.0266)
        (vote,) = _drain(votes)
        assert vote.body.veto.all()
