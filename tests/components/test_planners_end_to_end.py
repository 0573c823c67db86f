"""The autonomous stack end to end in the simulator (configs/raptor.xml, every real driver
on its emulator, virtual time): a gap narrower than the vehicle on the straight line to
the only waypoint must be gone round or stopped short of, never driven into.
"""

from __future__ import annotations

from pathlib import Path

from afa import VirtualClock
from afa.sim.vehicle import VehicleParameters
from components.simulation import RaptorSimulation

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"

WALL_EAST = 9.0
WALL_HALF_THICKNESS = 0.2
GAP = 1.0  # m, centred on the line to the waypoint; the Raptor's body is 1.4 m wide
WALL_END = 7.5  # each half of the wall runs from the gap to 7.5 m off the line
#: docs/worlds.md format: two boxes leave the gap between them.
NARROW_GAP = f"""<?xml version="1.0" encoding="UTF-8"?>
<world name="narrow-gap">
  <description>A wall across the straight line to the only waypoint, with a {GAP} m gap
  on that line, narrower than the Raptor.</description>
  <origin latitude="50.2717" longitude="-111.1766" elevation="750.0"/>
  <terrain width="50" depth="40" resolution="0.1" roughness="0.0" seed="1"/>
  <obstacle type="box" east="{WALL_EAST}" north="{(GAP / 2 + WALL_END) / 2}"
            length="{WALL_END - GAP / 2}" width="{2 * WALL_HALF_THICKNESS}" height="1.0"
            heading="0"/>
  <obstacle type="box" east="{WALL_EAST}" north="{-(GAP / 2 + WALL_END) / 2}"
            length="{WALL_END - GAP / 2}" width="{2 * WALL_HALF_THICKNESS}" height="1.0"
            heading="0"/>
  <vehicle east="0" north="0" heading="90"/>
  <mission patrol="false">
    <waypoint east="18" north="0"/>
  </mission>
</world>
"""


async def test_a_gap_narrower_than_the_vehicle_is_gone_round_or_stopped_short_of(tmp_path):
    body = VehicleParameters()
    assert GAP < body.body_width
    world = tmp_path / "narrow-gap.xml"
    world.write_text(NARROW_GAP)
    sim = RaptorSimulation.from_xml(RAPTOR, world, clock=VirtualClock(), seed=0)
    track: list[tuple[float, float, float, float]] = []  # time, east, north, speed
    past_wall = WALL_EAST + WALL_HALF_THICKNESS + body.rear_overhang + 1.0
    async with sim:
        while sim.sim_time < 150.0 and not sim.finished.is_set():
            await sim.system.run(0.5)
            s = sim.state
            track.append((sim.sim_time, s.east, s.north, s.speed))
            if s.east > past_wall:
                break  # beyond the wall: it can no longer be driven into
            stopped = [p for p in track if sim.sim_time - p[0] <= 10.0]
            if len(stopped) >= 20 and all(p[3] == 0.0 for p in stopped) and s.east > 1.0:
                break  # it has set off and then stood still for 10 s
        summary = sim.summary()
    assert summary["collisions"] == []
    assert summary["clearance_m"] is not None and summary["clearance_m"] > 0.0
    crossings = [(a, b) for a, b in zip(track, track[1:], strict=False)
                 if a[1] < WALL_EAST <= b[1]]
    if crossings:  # went round: the rear axle crossed the wall's line beyond its ends
        for a, b in crossings:
            north = a[2] + (b[2] - a[2]) * (WALL_EAST - a[1]) / (b[1] - a[1])
            assert abs(north) > WALL_END, f"crossed the wall line at north {north:.2f}"
    else:  # stopped short: the front bumper before the wall
        final = track[-1]
        assert final[3] == 0.0
        front = body.body_length - body.rear_overhang  # front bumper ahead of the rear axle
        assert final[1] + front < WALL_EAST - WALL_HALF_THICKNESS
    print(f"\nnarrow gap: {'went round' if crossings else 'stopped'}; "
          f"{summary['distance_m']} m driven in {track[-1][0]:.1f} s, clearance "
          f"{summary['clearance_m']} m, halts {summary['halts']}")
