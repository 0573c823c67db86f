"""The Raptor drives itself: every shipped world's mission, driven autonomously (no
script) by the whole stack on emulated devices in virtual time, judged against the
shortest collision-free course on the fully known world (afa.sim.oracle: scipy's Dijkstra
on the obstacles grown by the vehicle's half width).

Acceptance (issue 12): every waypoint reached in order, no collision, and the distance
driven to the last waypoint within 1.25x the oracle's course (1.6x for the cul-de-sac,
whose trap is discovered only by driving into it).
"""

import os
from pathlib import Path

import pytest

from afa import VirtualClock
from components.simulation import RaptorSimulation

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"
ALL_WORLDS = sorted((ROOT / "configs" / "worlds").glob("*.xml"))
#: The worlds the default test run drives, one of each hard kind the suite's ten minutes
#: allow (a dead end needing a back-out, a field of obstacles, a planner detour);
#: ``AFA_MISSIONS=all`` drives every shipped world (docs/autonomy.md has the whole table,
#: from docs/make_autonomy_figures.py).
DEFAULT = {"cul-de-sac", "rock-field", "long-wall"}
WORLDS = ALL_WORLDS if os.environ.get("AFA_MISSIONS") == "all" else \
    [w for w in ALL_WORLDS if w.stem in DEFAULT]

#: Worlds allowed a longer course than 1.25x the oracle's, and why.
ALLOWANCE = {
    "cul-de-sac": 1.6,  # the trap is discovered only by driving into it
}


async def drive(world: Path, seed: int = 0) -> dict:
    simulation = RaptorSimulation.from_xml(RAPTOR, world, clock=VirtualClock(), seed=seed)
    async with simulation:
        await simulation.run_mission()
    return {**simulation.summary(), **simulation.course_reference()}


#: Worlds the Raptor does not yet complete within the acceptance, and why
#: (docs/autonomy.md): expected to fail, so that a fix shows as an unexpected pass.
KNOWN_FAILURES = {
    "narrow-gate": "completes, but drives 1.39x the oracle's course: the vehicle finds "
                   "the gate beside it, and the arbiter refuses the back that would line "
                   "it up (the front discs would come within RecoverMargin of the wall), "
                   "so it loops once before going through",
    "ditch-crossing": "completes, but drives 1.57x the oracle's course: the ditch's nearer "
                      "end lies beyond the lasers' reach when FindPath must choose one, and "
                      "the plan switches ends; the vehicle, able to back (decision 0046), "
                      "follows the switch at once (1.21x at seed 1)",
}


@pytest.mark.timeout(900)  # minutes of simulated driving: the whole stack, emulated devices
@pytest.mark.parametrize("world", [
    pytest.param(w, marks=pytest.mark.xfail(reason=KNOWN_FAILURES[w.stem], strict=True))
    if w.stem in KNOWN_FAILURES else w for w in WORLDS], ids=[w.stem for w in WORLDS])
async def test_the_raptor_completes_the_mission(world):
    summary = await drive(world)
    outcome = {k: summary[k] for k in ("waypoints_reached", "waypoints_total", "collisions",
                                       "mission_complete_time_s", "mission_distance_m",
                                       "oracle_distance_m", "path_ratio", "clearance_m",
                                       "halts", "oscillation_per_min")}
    assert summary["mission_complete"], outcome
    assert summary["waypoints_reached"] >= summary["waypoints_total"], outcome
    assert summary["collisions"] == [], outcome
    assert summary["oracle_distance_m"] is not None, outcome
    assert summary["path_ratio"] <= ALLOWANCE.get(world.stem, 1.25), outcome
