"""A wall across the whole field with one 3 m gate, at offsets from the straight line
to the goal: the kind narrow-gate is one of (docs/autonomy.md, "A gate in a wall").

The vehicle starts 32 m before the wall, heading at the goal 32 m beyond it. A gate
whose near post is within about 4 m of the line is in the lasers' view when FindPath
first sees the wall; one farther out is found by driving along the wall, and by then
the vehicle is beside the gate, too close to turn in: it backs to line up on it
(decision 0046), and whether the plan stays on the gate meanwhile decides the course.

Slow (a minute of wall time each): driven with ``AFA_MISSIONS=all``, like the shipped
worlds' missions. The offsets that miss the acceptance are strict expected failures,
so that a fix shows.
"""

import os

import pytest

pytestmark = pytest.mark.skipif(os.environ.get("AFA_MISSIONS") != "all",
                                reason="minutes of simulated driving: AFA_MISSIONS=all")

GATE = 3.0  # m
HALF = 30.0  # the field reaches 30 m either side of the line


def world(offset: float) -> str:
    """The wall along east = 0 from north −30 to 30, open from ``offset`` − 1.5 to
    ``offset`` + 1.5 (north is the vehicle's left)."""
    low, high = offset - GATE / 2, offset + GATE / 2
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<world name="gate-{offset:+g}">
  <origin latitude="50.2717" longitude="-111.1766" elevation="750.0"/>
  <terrain width="90" depth="{2 * HALF:g}" resolution="0.1" roughness="0.03" seed="25"/>
  <obstacle type="box" east="0" north="{(low - HALF) / 2:g}" length="{low + HALF:g}"
            width="0.6" height="1.5" heading="0"/>
  <obstacle type="box" east="0" north="{(high + HALF) / 2:g}" length="{HALF - high:g}"
            width="0.6" height="1.5" heading="0"/>
  <vehicle east="-32" north="0" heading="90"/>
  <mission patrol="false"><waypoint east="32" north="0"/></mission>
</world>
"""


#: Offsets driven beyond the acceptance, with the distance driven over the oracle's
#: course when this was written (docs/autonomy.md says what happens).
MISSES = {
    -7.0: 2.25, 5.0: 1.78, 7.0: 1.46, 11.0: 1.86,
}
OFFSETS = [-11.0, -9.5, -7.0, -5.0, -3.0, 3.0, 5.0, 7.0, 11.0]  # +9.5: narrow-gate


@pytest.mark.timeout(900)
@pytest.mark.parametrize("offset", [
    pytest.param(o, marks=pytest.mark.xfail(
        strict=True, reason=f"{MISSES[o]}x the oracle's course: the plan switches "
                            "between the gate and the wall's unseen end, or the first "
                            "choice of side is the wrong one"))
    if o in MISSES else o for o in OFFSETS], ids=lambda o: f"{o:+g}m")
async def test_the_raptor_drives_through_a_gate_off_the_line(simulate, offset):
    simulation = simulate(world(offset))
    async with simulation:
        await simulation.run_mission()
        summary = {**simulation.summary(), **simulation.course_reference()}
    outcome = {k: summary[k] for k in ("mission_complete", "collisions", "path_ratio",
                                       "mission_distance_m", "oracle_distance_m",
                                       "clearance_m", "halts")}
    assert summary["mission_complete"], outcome
    assert summary["collisions"] == [], outcome
    assert summary["path_ratio"] <= 1.25, outcome
