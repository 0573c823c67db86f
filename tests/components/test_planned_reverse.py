"""Backing as part of the plan (decision 0046): the refinement's reverse motions
(components/find_path/kinematic.py) and the Arc Arbiter backing when a vote asks it to
(ArcVoteIDL.reverse), on the wire.

The refinement's checks are plain geometry, as in test_kinematic_refinement.py (whose
``drive`` re-drives each motion from its start pose along its arc, forwards or
backwards): the Raptor's body rectangle never overlaps a wall.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_arc_arbiter_component import ARCS, N, drives, rig, vote
from test_backout import BACKOUT, reverses, trav
from test_kinematic_refinement import (
    CELL,
    K_MAX,
    OFFSETS,
    ORIGIN,
    RADIUS,
    body_points,
    drive,
    grids,
    overlaps,
    walls_with_gate,
)

from components.arc_arbiter.component import REVERSE_RESET
from components.find_path.kinematic import Refined, Refiner
from components.find_path.parameters import FindPathParameters

#: FindPath's own costs of backing (configs/raptor.xml sets the same).
SHIPPED = FindPathParameters()


def redrive(refined: Refined) -> list[tuple[float, float, float]]:
    return drive(refined.poses, refined.curvatures, refined.step, refined.directions)


def refiner(reverse: float = SHIPPED.ReverseCost) -> Refiner:
    return Refiner(0.9 * K_MAX, OFFSETS, RADIUS, hazard_margin=0.5 * CELL,
                   reverse_cost=reverse, switch_cost=SHIPPED.ReverseSwitchCost)


def length(refined: Refined) -> float:
    return len(refined.curvatures) * refined.step


#: Beside a 3 m gate (y 8..11 in a wall along x = 0), 2.6 m from the wall and heading
#: along it (north), the gate starting 1 m ahead on the right: too close to turn in.
BESIDE = (-2.6, 7.0, math.pi / 2)
BEYOND = (4.0, 9.5, None)


def test_beside_a_gate_the_drivable_path_is_a_three_point_turn_and_far_shorter():
    walls = walls_with_gate(8.0, 11.0)
    blocked, cost = grids(walls)
    forward = refiner(0.0).plan(blocked, cost, ORIGIN, CELL, BESIDE, BEYOND, open_cost=6.0)
    backing = refiner().plan(blocked, cost, ORIGIN, CELL, BESIDE, BEYOND, open_cost=6.0)
    assert forward is not None and backing is not None
    assert forward.directions == ()  # forward arcs only: it loops
    # forwards, back, forwards through the gate: a three-point turn
    legs = [d for m, d in enumerate(backing.directions)
            if m == 0 or d != backing.directions[m - 1]]
    assert legs == [1, -1, 1]
    assert length(backing) < 0.5 * length(forward)
    for path in (forward, backing):
        for x, y, h in redrive(path):
            assert not overlaps(body_points(x, y, h), walls)
        assert path.poses[-1][0] > 2.0  # through the gate


def test_no_back_over_ground_the_map_has_not_seen():
    walls = walls_with_gate(8.0, 11.0)
    blocked, cost = grids(walls)
    unseen = np.zeros(blocked.shape, dtype=bool)
    blind = refiner().plan(blocked, cost, ORIGIN, CELL, BESIDE, BEYOND, open_cost=6.0,
                           seen=unseen)
    forward = refiner(0.0).plan(blocked, cost, ORIGIN, CELL, BESIDE, BEYOND, open_cost=6.0)
    assert blind is not None and forward is not None
    assert -1 not in blind.directions
    assert blind.poses == forward.poses


def test_in_a_corridor_too_narrow_to_turn_the_way_back_is_backing_all_the_way():
    # a 3.2 m corridor along x, closed 4 m ahead of the rear axle: no forward way at all
    walls = [(-20.0, 20.0, -3.0, -1.6), (-20.0, 20.0, 1.6, 3.0), (4.0, 6.0, -3.0, 3.0)]
    blocked, cost = grids(walls)
    start, behind = (0.0, 0.0, 0.0), (-8.0, 0.0, None)
    assert refiner(0.0).plan(blocked, cost, ORIGIN, CELL, start, behind,
                             open_cost=6.0) is None
    back = refiner().plan(blocked, cost, ORIGIN, CELL, start, behind, open_cost=6.0)
    assert back is not None and set(back.directions) == {-1}
    for x, y, h in redrive(back):
        assert not overlaps(body_points(x, y, h), walls)
    # the look-ahead point never lies past a change of direction
    assert back.at(1.5)[0] < 0.0


# --------------------------------------------------------------------- on the wire

HARD = float(ARCS.curvatures.max())


def ask(behaviour: str, distance: float, curvature: float, *, veto: bool = False):
    """A vote for straight ahead that asks to back ``distance`` on ``curvature``."""
    votes = np.zeros(N, dtype=np.float32)
    votes[ARCS.straight_index] = 1.0
    return vote(behaviour, veto=veto, votes=votes).model_copy(
        update={"reverse": distance, "reverseCurvature": curvature})


def vote_at(r, times, make) -> None:
    for t in times:
        r.publish_at(t, make(t))


def straight(behaviour: str):
    votes = np.zeros(N, dtype=np.float32)
    votes[ARCS.straight_index] = 1.0
    return vote(behaviour, votes=votes)


async def test_a_vote_that_asks_to_back_backs_at_once_that_far_then_drives_on():
    async with rig(cruise=False, parameters=BACKOUT) as r:
        r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        vote_at(r, np.arange(1.0, 20.0, 0.1).round(6), lambda t: straight("ObstacleAvoidance"))
        # FindPath asks at 2 and 3 s (planned from where the vehicle stood), then not
        vote_at(r, [1.0], lambda t: straight("FindPath"))
        vote_at(r, [2.0, 3.0], lambda t: ask("FindPath", 1.2, -HARD))
        vote_at(r, np.arange(4.0, 20.0, 1.0), lambda t: straight("FindPath"))
        await r.until(20.0)
        back = reverses(r)
        assert back, "no reverse on the wire"
        assert 2.0 <= back[0].time <= 2.0 + 0.1
        assert back[0].command.translation_mm_s == -300  # RecoverSpeed
        # the hard right arc backwards: the nose swings left (yaw rate = speed ×
        # curvature = −0.3 × −κ > 0, counter-clockwise)
        assert back[0].command.rotation_mrad_s > 0
        end = back[-1].time
        assert 2.0 + 1.2 / 0.3 - 0.25 <= end <= 2.0 + 1.2 / 0.3 + 0.25  # 1.2 m, once
        assert drives(r, end + 0.3)  # then the votes drive again
        assert r.arbiter.statistics()["reverses"] == 1


async def test_a_back_is_capped_at_recover_distance():
    async with rig(cruise=False, parameters=BACKOUT) as r:  # RecoverDistance 1.5 m
        r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        vote_at(r, np.arange(1.0, 12.0, 0.1).round(6), lambda t: straight("ObstacleAvoidance"))
        vote_at(r, [2.0], lambda t: ask("FindPath", 6.0, 0.0))
        vote_at(r, np.arange(3.0, 12.0, 1.0), lambda t: straight("FindPath"))
        await r.until(12.0)
        back = reverses(r)
        assert back and back[-1].time <= 2.0 + 1.5 / 0.3 + 0.25


@pytest.mark.parametrize("case", ["unweighted", "blocked", "no-map"])
async def test_no_back_for_a_behaviour_without_a_say_or_where_the_map_shows_no_room(case):
    async with rig(cruise=False, parameters=BACKOUT) as r:
        if case == "blocked":  # a wall 1 m behind the rear axle
            r.system.channel.publish("Raptor", "Traverse", trav([(-2.0, -1.0, -5.0, 5.0)]),
                                     origin="test")
        elif case == "unweighted":
            r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        asker = "Stranger" if case == "unweighted" else "FindPath"
        vote_at(r, np.arange(1.0, 10.0, 0.1).round(6), lambda t: straight("ObstacleAvoidance"))
        vote_at(r, np.arange(2.0, 10.0, 1.0), lambda t: ask(asker, 1.5, 0.0))
        await r.until(10.0)
        assert reverses(r) == []
        assert drives(r, 2.5), "the forward votes still drive"
        if case == "blocked":
            assert r.arbiter.statistics()["reverses_blocked"] >= 1


async def test_backs_asked_for_in_a_row_stop_at_recover_limit():
    async with rig(cruise=False, parameters=BACKOUT.model_copy(
            update={"RecoverLimit": 2})) as r:
        r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        vote_at(r, np.arange(1.0, 40.0, 0.1).round(6), lambda t: straight("ObstacleAvoidance"))
        vote_at(r, np.arange(2.0, 40.0, 1.0), lambda t: ask("FindPath", 0.6, 0.0))
        # 0.6 m at 0.3 m/s: backs from 2 to 4 s and 5 to 7 s, then refused ...
        await r.until(7.0 + REVERSE_RESET - 0.5)
        stats = r.arbiter.statistics()
        assert stats["reverses"] == 2 and stats["reverses_refused"] >= 10
        assert reverses(r, 7.5) == [] and drives(r, 8.0)  # the forward votes drive
        # ... until a request comes REVERSE_RESET after the last back ended: a new row
        await r.until(7.0 + REVERSE_RESET + 1.5)
        assert r.arbiter.statistics()["reverses"] == 3


async def test_a_stale_vote_ends_a_planned_back_at_once():
    async with rig(cruise=False, parameters=BACKOUT.model_copy(update={
            "RequiredBehaviours": ["FindPath"]})) as r:
        r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        vote_at(r, np.arange(1.0, 12.0, 0.1).round(6), lambda t: straight("ObstacleAvoidance"))
        vote_at(r, [2.0], lambda t: ask("FindPath", 1.5, 0.0))  # then FindPath falls silent
        await r.until(12.0)
        stale = BACKOUT.stale_vote_time
        back = reverses(r)
        assert back and back[-1].time < 2.0 + stale + 0.15


@pytest.mark.parametrize("bad", [{"reverse": -0.5}, {"reverse": math.inf},
                                 {"reverseCurvature": math.nan}])
def test_a_vote_cannot_ask_for_a_negative_or_endless_back(bad):
    good = vote("FindPath").model_dump()
    with pytest.raises(ValueError, match="reverse"):
        type(vote("FindPath"))(**{**good, **bad})
