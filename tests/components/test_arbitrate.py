"""The Arc Arbiter's decision (components/arc_arbiter/arbitrate.py): weights, certainty,
vetoes, speed, staleness, tie-breaks and every fail-safe; then the behaviours' cores
voting together."""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.arc_arbiter.arbitrate import BEHAVIOUR_WEIGHTS, VoteArbiter, weight_for
from components.arc_arbiter.parameters import ArcArbiterParameters
from components.arcs import ArcSet, ArcSetMismatchError, ArcSetParameters, ArcVotes
from components.obstacle_avoidance.parameters import ObstacleAvoidanceParameters
from components.obstacle_avoidance.sweep import ArcSweeper, MapGeometry
from components.obstacle_detection.detect import ObstacleDetector
from components.obstacle_detection.parameters import ObstacleDetectionParameters
from components.pure_pursuit.pursuit import PurePursuit, Waypoint
from idl.common import TimeIDL
from idl.planning import ArcVoteIDL

ARCS = ArcSet.from_parameters()
N = len(ARCS)
MID = ARCS.straight_index


def vote(behaviour: str, *, votes=None, peak: int | None = None, veto=(), certainty=1.0,
         max_speed=2.0, arcs: ArcSet = ARCS, t: float = 0.0) -> ArcVoteIDL:
    n = len(arcs)
    if votes is None:
        votes = np.zeros(n)
        if peak is not None:
            votes[peak] = 1.0
    veto_mask = np.zeros(n, dtype=bool)
    veto_mask[list(veto)] = True
    return ArcVotes(veto_mask, votes, np.broadcast_to(certainty, (n,)),
                    np.broadcast_to(max_speed, (n,))).to_idl(
        time=TimeIDL.from_seconds(t), behaviour=behaviour, arcs=arcs)


def arbiter(**overrides) -> VoteArbiter:
    return VoteArbiter(ArcArbiterParameters(**overrides), ARCS)


# --- weights and certainty ----------------------------------------------------------


def test_weights_are_mapped_from_behaviour_names():
    p = ArcArbiterParameters(ObsWeight=2, PursuitWeight=3, PlannerWeight=4, LaserSafetyWeight=5)
    assert {b: weight_for(b, p) for b in BEHAVIOUR_WEIGHTS} == {
        "ObstacleAvoidance": 2, "PurePursuit": 3, "FindPath": 4, "ObstacleDetection": 5}
    assert weight_for("Mystery", p) == 0.0 and weight_for("Mystery", p, 0.5) == 0.5


@pytest.mark.parametrize("pursuit_weight, winner", [(1.0, 5), (3.0, 20)])
def test_the_weighted_sum_chooses(pursuit_weight, winner):
    a = arbiter(PursuitWeight=pursuit_weight, ObsWeight=2.0)
    a.receive(vote("ObstacleAvoidance", peak=5), 0.0)
    a.receive(vote("PurePursuit", peak=20), 0.0)
    d = a.decide(0.1)
    assert d.index == winner and d.failsafe is None
    assert d.curvature == ARCS.curvatures[winner]
    assert d.steering == pytest.approx(math.atan(1.9 * ARCS.curvatures[winner]))
    assert d.scores[5] == 2.0 and d.scores[20] == pursuit_weight


def test_certainty_scales_a_vote():
    a = arbiter()
    a.receive(vote("ObstacleAvoidance", peak=5, certainty=0.4), 0.0)
    a.receive(vote("PurePursuit", peak=20, certainty=0.5), 0.0)
    d = a.decide(0.0)
    assert d.index == 20 and d.scores[5] == pytest.approx(0.4)
    a.receive(vote("PurePursuit", peak=20, certainty=0.3), 0.0)
    assert a.decide(0.0).index == 5


def test_scores_sum_over_behaviours():
    a = arbiter(ObsWeight=0.5, PlannerWeight=2.0)
    ramp = np.linspace(0, 1, N)
    a.receive(vote("ObstacleAvoidance", votes=ramp), 0.0)
    a.receive(vote("FindPath", votes=ramp[::-1], certainty=0.5), 0.0)
    d = a.decide(0.0)
    assert d.scores == pytest.approx(0.5 * ramp + 1.0 * ramp[::-1])


# --- vetoes and speed -----------------------------------------------------------------


def test_a_veto_from_any_behaviour_removes_the_arc():
    a = arbiter()
    a.receive(vote("PurePursuit", votes=np.exp(-0.5 * ((np.arange(N) - 10) / 3.0) ** 2)), 0.0)
    assert a.decide(0.0).index == 10
    a.receive(vote("ObstacleAvoidance", votes=np.ones(N), veto=range(8, 13)), 0.0)
    d = a.decide(0.0)
    assert d.index == 13  # the best remaining (13 ties 7; 13 is straighter)
    assert d.vetoed[8:13].all() and not d.vetoed[13]
    a.receive(vote("ObstacleDetection", veto=[13], certainty=0.0), 0.0)
    assert a.decide(0.0).index == 7  # vetoes need no weight or certainty


def test_speed_is_the_least_of_the_chosen_arcs_max_speeds_and_the_set_point():
    # (speeds that float32, the IDL's type for maxSpeed, holds exactly)
    a = arbiter(TransVelocitySetPoint=1.5)
    speeds = np.full(N, 2.0)
    speeds[MID] = 1.25
    a.receive(vote("PurePursuit", peak=MID, max_speed=speeds), 0.0)
    a.receive(vote("ObstacleAvoidance", votes=np.ones(N), max_speed=1.75), 0.0)
    assert a.decide(0.0).speed == 1.25
    a.receive(vote("ObstacleAvoidance", votes=np.ones(N), max_speed=0.625), 0.0)
    assert a.decide(0.0).speed == 0.625
    a.receive(vote("ObstacleAvoidance", votes=np.ones(N), max_speed=2.0), 0.0)
    a.receive(vote("PurePursuit", peak=MID, max_speed=2.0), 0.0)
    assert a.decide(0.0).speed == 1.5  # TransVelocitySetPoint
    # only the chosen arc's limit matters
    slow_elsewhere = np.full(N, 2.0)
    slow_elsewhere[MID + 1] = 0.1
    a.receive(vote("FindPath", votes=np.zeros(N), max_speed=slow_elsewhere), 0.0)
    assert a.decide(0.0).speed == 1.5


def test_a_zero_speed_vote_stops_the_vehicle_without_a_failsafe():
    a = arbiter()
    a.receive(vote("PurePursuit", peak=MID + 2, max_speed=0.0), 0.0)
    d = a.decide(0.0)
    assert d.stopped and d.failsafe is None and d.index == MID + 2


# --- staleness --------------------------------------------------------------------------


def test_votes_go_stale_after_stale_vote_time():
    a = arbiter(StaleVoteTimeSec=1, StaleVoteTimeUSec=500000)
    a.receive(vote("PurePursuit", peak=3), 10.0)
    assert a.decide(11.5).index == 3  # exactly 1.5 s old: still fresh
    assert a.decide(11.5000005).index == 3  # within afa.clock.TIME_TOLERANCE (1 µs)
    d = a.decide(11.50001)
    assert d.failsafe == "no-fresh-vote" and d.stale == ("PurePursuit",) and d.fresh == ()
    assert a.behaviours == ()
    a.receive(vote("PurePursuit", peak=4), 12.0)
    assert a.decide(12.1).index == 4  # a new vote brings it back


def test_expires_is_when_the_oldest_vote_in_the_book_goes_stale():
    a = arbiter(StaleVoteTimeSec=1, StaleVoteTimeUSec=500000)
    assert a.expires() is None
    a.receive(vote("PurePursuit", peak=3), 10.0)
    a.receive(vote("ObstacleAvoidance", peak=3), 10.4)
    expiry = a.expires()
    assert expiry is not None and 11.5 < expiry <= 11.5 + 1e-5
    assert a.decide(11.5).fresh == ("ObstacleAvoidance", "PurePursuit")
    assert a.decide(expiry).fresh == ("ObstacleAvoidance",)  # stale exactly then
    assert a.expires() == pytest.approx(11.9, abs=1e-5)
    a.decide(12.0)
    assert a.expires() is None


def test_stale_time_combines_seconds_and_microseconds():
    a = arbiter(StaleVoteTimeSec=0, StaleVoteTimeUSec=200000)
    assert a.stale_after == 0.2
    a.receive(vote("PurePursuit", peak=3), 0.0)
    assert a.decide(0.2).failsafe is None
    assert a.decide(0.21).failsafe == "no-fresh-vote"


def test_a_behaviour_that_stops_voting_loses_its_veto():
    a = arbiter()
    a.receive(vote("ObstacleDetection", veto=range(N)), 0.0)  # a halt, then silence
    for t in (0.5, 1.0):
        a.receive(vote("PurePursuit", peak=MID), t)
        assert a.decide(t).failsafe == "all-vetoed"
    a.receive(vote("PurePursuit", peak=MID), 1.6)
    d = a.decide(1.6)
    assert d.failsafe is None and d.index == MID and d.speed > 0
    assert d.fresh == ("PurePursuit",) and d.stale == ("ObstacleDetection",)


def test_the_latest_vote_of_a_behaviour_replaces_the_earlier_one():
    a = arbiter()
    a.receive(vote("PurePursuit", peak=2), 0.0)
    a.receive(vote("PurePursuit", peak=22), 0.1)
    assert a.decide(0.1).index == 22
    assert int(np.argmax(a.latest("PurePursuit").vote)) == 22
    a.forget("PurePursuit")
    assert a.decide(0.1).failsafe == "no-fresh-vote"


def test_staleness_uses_the_receive_time_not_the_stamp():
    a = arbiter()
    a.receive(vote("PurePursuit", peak=2, t=-100.0), 5.0)  # an old stamp from another clock
    assert a.decide(6.0).failsafe is None


def test_a_re_stamped_vote_keeps_its_behaviour_fresh_and_decides_alike():
    # The safety catch publishes its "clear" every scan: the same arrays, a new stamp.
    a = arbiter(StaleVoteTimeSec=1, StaleVoteTimeUSec=0)
    clear = vote("ObstacleDetection", veto=[MID])
    a.receive(vote("PurePursuit", peak=MID - 1), 0.0)
    a.receive(clear, 0.0)
    first = a.decide(0.0)
    again = clear.model_copy(update={"time": TimeIDL.from_seconds(0.9)})
    a.receive(again, 0.9)
    a.receive(vote("PurePursuit", peak=MID - 1), 0.9)
    d = a.decide(1.5)  # the first "clear" would be stale now; the re-stamped one is not
    assert d.failsafe is None and d.fresh == ("ObstacleDetection", "PurePursuit")
    assert d.index == first.index == MID - 1 and d.time == 1.5
    assert a.latest("ObstacleDetection") is again
    a.receive(vote("ObstacleDetection", veto=range(N)), 1.6)  # new arrays: a new decision
    assert a.decide(1.6).failsafe == "all-vetoed"
    a.receive(vote("PurePursuit", peak=MID), 2.0)
    assert a.decide(2.7).failsafe is None  # the halt went stale


# --- fail-safes and ties ------------------------------------------------------------------


def test_no_vote_at_all_is_a_stop():
    d = arbiter().decide(0.0)
    assert d.failsafe == "no-fresh-vote" and d.stopped and d.index == MID
    assert d.curvature == 0.0 and d.steering == 0.0 and not d.vetoed.any()


def test_every_arc_vetoed_is_a_stop_straight():
    a = arbiter()
    a.receive(vote("PurePursuit", peak=1, veto=range(0, 14)), 0.0)
    a.receive(vote("ObstacleAvoidance", votes=np.ones(N), veto=range(14, N)), 0.0)
    d = a.decide(0.0)
    assert d.failsafe == "all-vetoed" and d.stopped and d.curvature == 0.0
    assert d.vetoed.all() and d.scores[1] == 2.0


def test_nothing_to_steer_by_is_a_stop():
    a = arbiter()
    a.receive(vote("ObstacleDetection", certainty=0.0), 0.0)  # the clear safety-catch vote
    assert a.decide(0.0).failsafe == "no-valid-vote"
    a.receive(vote("PurePursuit", peak=MID, certainty=0.0), 0.0)
    assert a.decide(0.0).failsafe == "no-valid-vote"
    a.receive(vote("FindPath", peak=4), 0.0)
    zero = arbiter(PlannerWeight=0.0)
    zero.receive(vote("FindPath", peak=4), 0.0)
    assert zero.decide(0.0).failsafe == "no-valid-vote"
    assert a.decide(0.0).index == 4
    # the only positive score on a vetoed arc is no valid vote either
    b = arbiter()
    b.receive(vote("PurePursuit", peak=4, veto=[4]), 0.0)
    d = b.decide(0.0)
    assert d.failsafe == "no-valid-vote" and d.stopped and d.index == MID


def test_a_required_behaviour_without_a_fresh_vote_is_a_stop():
    a = VoteArbiter(ArcArbiterParameters(), ARCS, required={"PurePursuit"})
    a.receive(vote("ObstacleAvoidance", votes=np.ones(N)), 0.0)
    assert a.decide(0.0).failsafe == "missing-required"
    a.receive(vote("PurePursuit", peak=3), 0.5)
    assert a.decide(0.5).failsafe is None
    a.receive(vote("ObstacleAvoidance", votes=np.ones(N)), 2.0)
    d = a.decide(2.1)  # Pure Pursuit silent since 0.5: stale
    assert d.failsafe == "missing-required" and d.stopped and d.stale == ("PurePursuit",)
    plain = arbiter()  # the seed's arbiter: Obstacle Avoidance alone still drives
    plain.receive(vote("ObstacleAvoidance", votes=np.ones(N)), 0.0)
    assert plain.decide(0.0).failsafe is None


def test_ties_go_to_the_straighter_arc_then_the_left_one():
    a = arbiter()
    a.receive(vote("PurePursuit", votes=np.ones(N)), 0.0)
    assert a.decide(0.0).index == MID
    a.receive(vote("PurePursuit", votes=np.ones(N), veto=[MID]), 0.0)
    assert a.decide(0.0).index == MID - 1  # left (positive curvature) of the two
    symmetric = np.zeros(N)
    symmetric[[MID - 5, MID + 5, 2]] = 0.8
    a.receive(vote("PurePursuit", votes=symmetric), 0.0)
    d = a.decide(0.0)
    assert d.index == MID - 5 and d.curvature > 0
    nearly = symmetric.copy()
    nearly[MID + 5] += 1e-6  # a real difference beats the tie-break
    a.receive(vote("PurePursuit", votes=nearly), 0.0)
    assert a.decide(0.0).index == MID + 5


# --- unknown behaviours and other arc sets --------------------------------------------------


def test_an_unknown_behaviour_does_not_steer_but_its_veto_and_speed_count():
    a = arbiter()
    a.receive(vote("PurePursuit", peak=MID), 0.0)
    a.receive(vote("Mystery", peak=0, veto=[MID + 1], max_speed=0.375), 0.0)
    d = a.decide(0.0)
    assert d.index == MID and d.speed == 0.375
    assert d.vetoed[MID + 1] and d.unknown == ("Mystery",)
    assert d.fresh == ("Mystery", "PurePursuit")
    weighted = VoteArbiter(ArcArbiterParameters(), ARCS, unknown_weight=2.0)
    weighted.receive(vote("PurePursuit", peak=MID), 0.0)
    weighted.receive(vote("Mystery", peak=0), 0.0)
    assert weighted.decide(0.0).index == 0
    with pytest.raises(ValueError):
        VoteArbiter(ArcArbiterParameters(), ARCS, unknown_weight=-1.0)


def test_votes_over_another_arc_set_are_rejected():
    a = arbiter()
    fewer = ArcSet.from_parameters(ArcSetParameters(Count=25))
    with pytest.raises(ArcSetMismatchError, match="'PurePursuit' votes are over 25 arcs"):
        a.receive(vote("PurePursuit", peak=3, arcs=fewer), 0.0)
    other = ArcSet.from_parameters(ArcSetParameters(MaxSteeringAngle=25.0))
    with pytest.raises(ArcSetMismatchError, match="other curvatures: arc 0"):
        a.receive(vote("ObstacleAvoidance", peak=3, arcs=other), 0.0)
    assert a.behaviours == ()  # nothing was kept
    with pytest.raises(ValueError):
        a.receive(vote("PurePursuit", peak=3), math.nan)
    with pytest.raises(ValueError):
        a.decide(math.inf)


def test_the_decision_is_read_as_a_display_record():
    a = arbiter()
    a.receive(vote("PurePursuit", peak=MID, veto=[0]), 3.0)
    d = a.decide(3.25)
    assert d.time == 3.25 and d.scores.shape == (N,) and d.vetoed.tolist() == [True] + [
        False] * (N - 1)


# --- the cores together ------------------------------------------------------------------------


def test_pursuit_obstacle_avoidance_and_the_safety_catch_decide_together():
    arcs = ARCS
    pp = PurePursuit(arcs)
    pp.set_waypoints([Waypoint(30.0, 0.0)])
    pursuit = pp.update(0.0, 0.0, 0.0).votes
    # a rock straight ahead, 3 m past the bumper, slightly right of centre
    hazard = np.zeros((32, 32), np.float32)
    hazard[6:8, 14:17] = 1.0
    # the rock's own cells, read as anywhere in them (no Traversability Map marking round it)
    sweeper = ArcSweeper(arcs, ObstacleAvoidanceParameters(VehicleRadius=0.7, HazardMargin=0.0),
                         map_frame=(2.45, 0.0), disc_offsets=(0.0, 2.45))
    avoid = sweeper.score(MapGeometry(32, 32, 0.5, 0.0, -8.0), hazard,
                          np.ones((32, 32), np.float32)).votes
    catch = ObstacleDetector(ObstacleDetectionParameters(), arcs)
    ground = np.column_stack([np.full(50, 2.5), np.linspace(-3, 3, 50), np.full(50, -2.0)])
    clear = catch.update(ground).votes
    a = VoteArbiter(ArcArbiterParameters(TransVelocitySetPoint=1.0), arcs)
    stamp = TimeIDL(sec=0)
    for name, v in (("PurePursuit", pursuit), ("ObstacleAvoidance", avoid),
                    ("ObstacleDetection", clear)):
        a.receive(v.to_idl(time=stamp, behaviour=name, arcs=arcs), 0.0)
    d = a.decide(0.0)
    assert avoid.veto[MID] and d.failsafe is None
    free = np.flatnonzero(~avoid.veto)
    nearest = free[np.argmin(np.abs(free - MID))]
    assert d.index == nearest < MID  # the nearest way round: left, the rock is right
    assert d.speed == 1.0
    # the safety catch sees the rock's face: a halt stops everything
    rock = np.vstack([ground, np.tile([2.0, 0.0, -1.5], (6, 1))])
    halt = catch.update(rock).votes
    a.receive(halt.to_idl(time=stamp, behaviour="ObstacleDetection", arcs=arcs), 0.1)
    assert a.decide(0.1).failsafe == "all-vetoed"
    # while the catch holds it publishes nothing; its halt goes stale after 1.5 s
    assert catch.update(rock).votes is None
    for name, v in (("PurePursuit", pursuit), ("ObstacleAvoidance", avoid)):
        a.receive(v.to_idl(time=stamp, behaviour=name, arcs=arcs), 1.7)
    assert a.decide(1.7).failsafe is None
