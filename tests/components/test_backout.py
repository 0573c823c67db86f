"""Backing out of a dead end (components/arc_arbiter/recovery.py, the Arc Arbiter's
back-out): the reverse sweep on the global Traversability map, and the arbiter reversing
on the wire (the fake MPC555) when every arc has been vetoed for RecoverAfter seconds.

The expected geometry is worked out here by hand: a vehicle at the origin heading east
(x), its map position (the front bumper) 2.45 m ahead of the rear axle.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_arc_arbiter_component import ARCS, N, rig, vote
from vehicle_rig import stops_after, wire_commands

from components.arc_arbiter.parameters import ArcArbiterParameters
from components.arc_arbiter.recovery import reverse_candidates, reverse_clearance
from components.mpc555.codec import SetVelocity
from idl import Position3DIDL, TimeIDL
from idl.maps import TravMapArrayEventIDL

CELL = 0.5
ORIGIN = -16.0
CELLS = 64
BUMPER = 2.45
INITIAL_UTM = np.array([500000.0, 5570000.0, 800.0])


def trav(boxes: list[tuple[float, float, float, float]], *, heading: float = 0.0,
         t: float = 0.0) -> TravMapArrayEventIDL:
    """Free ground, hazard 1 in the cells whose centres lie in each (x0, x1, y0, y1); the
    rear axle at the origin heading ``heading`` (rad, counter-clockwise from east)."""
    centres = ORIGIN + (np.arange(CELLS) + 0.5) * CELL
    x, y = np.meshgrid(centres, centres, indexing="ij")
    hazard = np.zeros((CELLS, CELLS), dtype=np.float32)
    for x0, x1, y0, y1 in boxes:
        hazard[(x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)] = 1.0
    return TravMapArrayEventIDL(
        time=TimeIDL.from_seconds(t), frame="World", mapPose=np.eye(4),
        initialUTM=INITIAL_UTM, gridsize=CELL, originX=ORIGIN, originY=ORIGIN,
        rows=CELLS, cols=CELLS, hazard=hazard, goodness=np.ones_like(hazard),
        vehiclePosition=Position3DIDL(x=BUMPER * math.cos(heading),
                                      y=BUMPER * math.sin(heading)),
        vehicleHeading=heading)


def clear(m: TravMapArrayEventIDL, curvature: float, distance: float = 2.5) -> bool:
    return reverse_clearance(m, curvature, distance, radius=0.7,
                             offsets=(0.0, 0.8, 1.6, 2.4), map_offset=BUMPER)


def test_open_ground_behind_is_clear_and_a_wall_behind_is_not():
    assert clear(trav([]), 0.0)
    # a wall across the way back, its cells from 3.5 m behind the rear axle: the rear
    # disc (0.7 m) reaches 0.7 m behind the axle, so 2.5 m of reverse ends 0.3 m short
    # of it ...
    wall = [(-3.9, -3.6, -5.0, 5.0)]
    assert clear(trav(wall), 0.0, 2.5)
    # ... and 2.9 m of reverse would overlap it by 0.1 m
    assert not clear(trav(wall), 0.0, 2.9)


def test_the_map_is_read_in_the_vehicle_heading():
    # the vehicle heads north: the same wall, now south of it, blocks; east of it not
    north = math.pi / 2
    assert not clear(trav([(-5.0, 5.0, -3.2, -2.7)], heading=north), 0.0, 2.5)
    assert clear(trav([(-3.2, -2.7, -5.0, 5.0)], heading=north), 0.0, 2.5)


def test_a_turning_reverse_swings_the_nose_into_what_is_beside_it():
    # a block 1.3 m left of the front bumper: reversing with the wheels right swings the
    # nose left, into it; reversing with the wheels left swings it away
    hard = float(ARCS.curvatures.max())
    block = [(2.0, 3.0, 1.15, 2.0)]
    assert clear(trav(block), 0.0, 2.5)
    assert not clear(trav(block), -hard, 2.5)
    assert clear(trav(block), hard, 2.5)


def test_a_hazard_the_body_already_overlaps_blocks_only_when_the_sweep_closes_in():
    # a hazard cell 0.4 m right of the rear axle (within the 0.7 m disc): the vehicle is
    # there, not collided; going straight back keeps the distance, turning into it not
    beside = [(-0.5, 0.0, -0.75, -0.5)]
    assert clear(trav(beside), 0.0, 2.5)
    hard = float(ARCS.curvatures.max())
    assert not clear(trav(beside), hard, 2.5)   # reversing left-wheeled: the tail swings right


def test_unknown_ground_behind_blocks_a_back_out():
    # the world's unseen edge 3.5 m behind the rear axle: as good as a wall
    m = trav([])
    hazard = np.array(m.hazard)
    hazard[:25, :] = np.nan  # cells behind x = -3.5 m never seen
    unseen = m.model_copy(update={"hazard": hazard})
    assert clear(unseen, 0.0, 2.5)
    assert not clear(unseen, 0.0, 2.9)


def test_candidates_start_from_the_mirror_of_the_preferred_arc():
    order = reverse_candidates(ARCS.curvatures, float(ARCS.curvatures[0]))
    assert order[0] == N - 1 and order[-1] == 0
    assert reverse_candidates(ARCS.curvatures, 0.0)[0] == ARCS.straight_index


# --------------------------------------------------------------------- on the wire

BACKOUT = ArcArbiterParameters(RecoverAfter=3.0, RecoverDistance=1.5, RecoverSpeed=0.3)


def placed(m: TravMapArrayEventIDL) -> TravMapArrayEventIDL:
    """``m`` as a vehicle just put down sees it: nothing mapped behind the rear axle."""
    hazard = np.array(m.hazard)
    hazard[:32, :] = np.nan  # cells behind x = 0 never seen
    return m.model_copy(update={"hazard": hazard})


def test_the_start_apron_lets_a_vehicle_just_put_down_back_out():
    # the apron: 4 m behind the rear axle to 3.8 m ahead, 1.4 m either side
    apron = (0.0, 0.0, 0.0, 4.0, 3.8, 1.4)
    m = placed(trav([]))
    assert not clear(m, 0.0, 2.5)  # without it, the unseen ground blocks
    assert reverse_clearance(m, 0.0, 2.5, radius=0.7, offsets=(0.0, 0.8, 1.6, 2.4),
                             map_offset=BUMPER, apron=apron)
    # a hazard in the apron still blocks, and so does unseen ground beyond it: 3.2 m of
    # reverse takes the rear disc to 3.9 m behind, within a cell of the apron's end
    hazard = np.array(m.hazard)
    hazard[27, 31:33] = 1.0  # the cells centred 2.25 m behind the axle, 0.25 m either side
    rock = m.model_copy(update={"hazard": hazard})
    assert not reverse_clearance(rock, 0.0, 2.5, radius=0.7, offsets=(0.0, 0.8, 1.6, 2.4),
                                 map_offset=BUMPER, apron=apron)
    assert not reverse_clearance(m, 0.0, 3.4, radius=0.7, offsets=(0.0, 0.8, 1.6, 2.4),
                                 map_offset=BUMPER, apron=apron)
    # an apron elsewhere (where the vehicle was put down, 10 m away) does not help
    assert not reverse_clearance(m, 0.0, 2.5, radius=0.7, offsets=(0.0, 0.8, 1.6, 2.4),
                                 map_offset=BUMPER, apron=(10.0, 0.0, 0.0, 4.0, 3.8, 1.4))


def reverses(r, after: float = -math.inf) -> list:
    return [c for c in wire_commands(r.fake, SetVelocity, after)
            if c.command.translation_mm_s < 0]


def veto_all_until(r, start: float, end: float, *, preferred: int = 0) -> None:
    """Obstacle Avoidance vetoes every arc, Pure Pursuit prefers arc ``preferred``, at
    10 Hz from ``start`` to ``end``."""
    votes = np.zeros(N, dtype=np.float32)
    votes[preferred] = 1.0
    t = start
    while t < end:
        r.publish_at(t, vote("ObstacleAvoidance", veto=True, votes=0.0))
        r.publish_at(t, vote("PurePursuit", votes=votes))
        t = round(t + 0.1, 6)


async def test_every_arc_vetoed_for_recover_after_seconds_backs_out_then_stops():
    async with rig(cruise=False, parameters=BACKOUT) as r:
        r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        veto_all_until(r, 2.0, 12.0, preferred=0)
        await r.until(12.0)
        back = reverses(r)
        assert back, "no reverse on the wire"
        # after RecoverAfter of all-vetoed (first decision at 2.0 s), within a vote period
        assert 5.0 - 1e-6 <= back[0].time <= 5.0 + 0.1 + r.frames(11)
        # the mirror of the preferred hard left: wheels right, nose swinging left
        assert back[0].command.translation_mm_s == -300
        assert back[0].command.rotation_mrad_s > 0
        # RecoverDistance at RecoverSpeed: 5 s of reverse, then a stop
        end = back[-1].time
        assert 5.0 + 1.5 / 0.3 - 0.2 <= end <= 5.0 + 1.5 / 0.3 + 0.2
        assert stops_after(r.fake, end)
        # still vetoed: it tries again RecoverAfter after the first back-out ended
        assert reverses(r, end + 0.1) == [] or reverses(r, end + 0.1)[0].time >= end + 2.9
        assert r.arbiter.statistics()["backouts"] >= 1


async def test_no_back_out_when_the_way_back_is_blocked_or_without_a_map():
    async with rig(cruise=False, parameters=BACKOUT) as r:
        veto_all_until(r, 2.0, 8.0)  # no Traverse map yet: nothing known behind
        await r.until(8.0)
        assert reverses(r) == []
        boxed = trav([(-3.0, -1.0, -6.0, 6.0), (-3.0, 4.0, -1.6, -1.0),
                      (-3.0, 4.0, 1.0, 1.6)])  # walls behind and on both sides
        r.system.channel.publish("Raptor", "Traverse", boxed, origin="test")
        veto_all_until(r, 8.0, 14.0)
        await r.until(14.0)
        assert reverses(r) == []
        assert r.arbiter.statistics()["backouts_blocked"] >= 1


async def test_a_stale_vote_ends_a_back_out_at_once():
    async with rig(cruise=False, parameters=BACKOUT.model_copy(update={
            "RequiredBehaviours": ["PurePursuit"]})) as r:
        r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        veto_all_until(r, 2.0, 5.3)  # every vote stops at 5.3 s: stale at 6.8 s
        await r.until(9.0)
        back = reverses(r)
        assert back and back[-1].time < 6.8 + 0.1
        stale = ArcArbiterParameters().stale_vote_time
        assert stops_after(r.fake, 5.2 + stale)


@pytest.mark.parametrize("margin", [0.3, 0.0])
async def test_a_back_out_keeps_recover_margin_beyond_its_discs(margin):
    # a wall whose cells start 2.5 m behind the rear axle; a back-out of 1.6 m (on any
    # arc: straight back goes furthest) leaves the rear disc's centre 0.9 m short of
    # it: room for the 0.7 m disc, but the Raptor's rear corners stand 0.11 m outside
    # that disc and the map places the vehicle with the GPS's decimetres of error. With
    # the default margin (0.3 m) the vehicle stands.
    wall = [(-4.0, -2.6, -3.0, 3.0)]
    async with rig(cruise=False, parameters=BACKOUT.model_copy(
            update={"RecoverMargin": margin, "RecoverDistance": 1.6})) as r:
        r.system.channel.publish("Raptor", "Traverse", trav(wall), origin="test")
        veto_all_until(r, 2.0, 10.0)
        await r.until(10.0)
        if margin:
            assert reverses(r) == []
            assert r.arbiter.statistics()["backouts_blocked"] >= 1
        else:
            assert reverses(r), "the discs alone have room"


@pytest.mark.parametrize("apron", [4.0, 0.0])
async def test_a_vehicle_put_down_facing_a_wall_backs_out_over_its_start_apron(apron):
    # the first map: nothing seen behind the vehicle (it has not moved); every arc vetoed
    # (Obstacle Detection halts it in front of the wall)
    async with rig(cruise=False, parameters=BACKOUT.model_copy(
            update={"StartApron": apron})) as r:
        r.system.channel.publish("Raptor", "Traverse", placed(trav([(3.0, 3.5, -9.0, 9.0)])),
                                 origin="test")
        veto_all_until(r, 2.0, 10.0)
        await r.until(10.0)
        if apron:
            assert reverses(r), "no back-out over the start apron"
        else:
            assert reverses(r) == []  # StartApron 0: only mapped ground, as before
            assert r.arbiter.statistics()["backouts"] == 0


@pytest.mark.parametrize("recover_after", [0.0])
async def test_recover_after_zero_stands_still_as_the_seed_does(recover_after):
    async with rig(cruise=False, parameters=BACKOUT.model_copy(
            update={"RecoverAfter": recover_after})) as r:
        r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        veto_all_until(r, 2.0, 10.0)
        await r.until(10.0)
        assert reverses(r) == []


def drive_until(r, start: float, end: float) -> None:
    """Votes that let the vehicle drive (no veto), at 10 Hz from ``start`` to ``end``."""
    votes = np.zeros(N, dtype=np.float32)
    votes[ARCS.straight_index] = 1.0
    t = start
    while t < end:
        r.publish_at(t, vote("ObstacleAvoidance", votes=votes))
        r.publish_at(t, vote("PurePursuit", votes=votes))
        t = round(t + 0.1, 6)


async def test_after_recover_limit_back_outs_in_a_row_it_stands_until_the_votes_clear():
    """Votes that stay vetoed (FindPath with no path at all: the waypoint inside a
    building) back the vehicle out RecoverLimit times, then it stands and says why,
    rather than reverse blind for ever; a decision that lets it drive starts a new row."""
    async with rig(cruise=False, parameters=BACKOUT.model_copy(
            update={"RecoverLimit": 2})) as r:
        r.system.channel.publish("Raptor", "Traverse", trav([]), origin="test")
        veto_all_until(r, 2.0, 40.0)
        await r.until(40.0)
        stats = r.arbiter.statistics()
        health = r.arbiter.health()
        assert stats["backouts"] == 2 and stats["backouts_refused"] >= 1
        assert not health.healthy and "2 back-outs in a row" in health.detail
        assert reverses(r, 13.0) and reverses(r, 19.0) == []  # the second ended at 18 s
        drive_until(r, 40.0, 42.0)
        veto_all_until(r, 42.0, 50.0)
        await r.until(50.0)
        assert r.arbiter.health().healthy
        assert r.arbiter.statistics()["backouts"] == 3  # a new row
        assert reverses(r, 44.0)
