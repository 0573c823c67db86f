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

from pathlib import Path

import numpy as np
from vehicle_rig import Cruise, SerialLine, decode_host_bytes, stops_after, wire_commands

from afa import System, VirtualClock
from afa.testing import until
from components.model_server.geometry import GeometryModel
from components.mpc555.codec import SetVelocity
from components.mpc555.fake import FakeMpc555
from components.nodding_laser.component import LASER_FRAMES, SCAN_PERIODS
from components.nodding_laser.fake import FakeNodLaser
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
