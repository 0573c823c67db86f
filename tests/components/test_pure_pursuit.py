"""Pure Pursuit's core (components/pure_pursuit/pursuit.py): hand-computed curvatures,
the look-ahead walk, waypoint advance, patrol, stop and halt, the Gaussian votes, and
closed-loop drives on the exact arcs the simulated Raptor drives."""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.arcs import ArcSet, arc_point
from components.pure_pursuit.parameters import PurePursuitParameters
from components.pure_pursuit.pursuit import (
    PurePursuit,
    PursuitSettings,
    Waypoint,
    gaussian_votes,
    pursuit_curvature,
    to_vehicle_frame,
)

SETTINGS = PursuitSettings()  # look-ahead 5 m, σ_y 1 m


@pytest.fixture(scope="module")
def arcs() -> ArcSet:
    return ArcSet.from_parameters()


def started(arcs, waypoints, *, at=(0.0, 0.0, 0.0), patrol=False, settings=SETTINGS):
    """A pursuit whose path starts at ``at`` (the first update anchors it)."""
    pp = PurePursuit(arcs, settings)
    pp.set_waypoints(waypoints, patrol=patrol)
    pp.update(*at)
    return pp


def drive(pp, arcs, pose, steps, ds=0.2):
    """Drive the best-voted arc ds metres per update, as the simulated Raptor would."""
    x, y, yaw = pose
    log = []
    for _ in range(steps):
        out = pp.update(x, y, yaw)
        log.append((x, y, yaw, out))
        if out.state != "following":
            break
        kappa = float(arcs.curvatures[int(np.argmax(out.votes.vote))])
        dx, dy, dh = arc_point(ds, kappa)
        c, s = math.cos(yaw), math.sin(yaw)
        x, y = x + dx * c - dy * s, y + dx * s + dy * c
        yaw += dh
    return log


def advanced(log):
    return [i for *_, out in log for i in out.advanced]


# --- curvature -------------------------------------------------------------------------


def test_pursuit_curvature_by_hand(arcs):
    k_max = arcs.max_curvature
    assert pursuit_curvature(5.0, 0.0, k_max) == 0.0  # straight ahead
    assert pursuit_curvature(4.8, 1.4, k_max) == pytest.approx(2 * 1.4 / 5.0**2)  # D = L = 5
    assert pursuit_curvature(4.0, -3.0, k_max) == pytest.approx(-0.24)
    assert pursuit_curvature(3.0, 4.0, k_max) == k_max  # 0.32 clipped
    assert pursuit_curvature(-1.0, 2.0, k_max) == k_max  # behind, left: hardest left
    assert pursuit_curvature(-1.0, -2.0, k_max) == -k_max
    assert pursuit_curvature(-3.0, 0.0, k_max) == k_max  # dead behind: left
    assert pursuit_curvature(0.0, 0.0, k_max) == 0.0


def test_the_arc_through_the_lookahead_point_reaches_it(arcs):
    for ahead, left in ((4.8, 1.4), (4.0, -3.0), (6.0, 0.5)):
        kappa = pursuit_curvature(ahead, left, 10.0)
        # the circle of curvature κ tangent to x at the rear axle passes the point
        assert math.hypot(ahead, left - 1 / kappa) == pytest.approx(abs(1 / kappa))


def test_vehicle_frame():
    assert to_vehicle_frame(1.0, 1.0, 0.0, 0.0, math.pi / 2) == pytest.approx((1.0, -1.0))
    assert to_vehicle_frame(3.0, 4.0, 3.0, 0.0, 0.0) == pytest.approx((0.0, 4.0))


def test_on_the_path_the_lookahead_point_is_straight_ahead(arcs):
    pp = started(arcs, [Waypoint(30.0, 0.0)])
    out = pp.update(10.0, 0.0, 0.0)
    assert out.lookahead_point == pytest.approx((15.0, 0.0))
    assert out.curvature == 0.0
    assert int(np.argmax(out.votes.vote)) == arcs.straight_index


def test_beside_the_path_the_curvature_is_2y_over_d_squared(arcs):
    pp = started(arcs, [Waypoint(30.0, 0.0)])
    out = pp.update(10.0, 1.0, 0.0)  # 1 m left of the path, heading along it
    assert out.lookahead_point == pytest.approx((15.0, 0.0))  # 5 m *along the path*
    assert out.curvature == pytest.approx(2 * -1.0 / (5.0**2 + 1.0**2))
    turned = pp.update(10.0, 0.0, 0.3)  # on the path, heading 0.3 rad off: D = L_d
    assert turned.curvature == pytest.approx(2 * (-5.0 * math.sin(0.3)) / 5.0**2)


# --- the look-ahead walk and waypoint advance -------------------------------------------


def test_the_lookahead_stays_on_the_line_through_the_target_until_it_is_reached(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0, 1.0), Waypoint(10.0, 10.0, 1.0)])
    out = pp.update(8.0, 0.0, 0.0)  # 2 m before the corner: 3 m beyond it on the line
    assert out.lookahead_point == pytest.approx((13.0, 0.0))
    assert out.target == 0 and out.advanced == () and out.curvature == 0.0
    out = pp.update(8.0, 0.5, 0.0)  # beside the line: pursue the line, not the corner
    assert out.lookahead_point == pytest.approx((13.0, 0.0))
    assert out.curvature == pytest.approx(2 * -0.5 / (5.0**2 + 0.5**2))


def test_a_waypoint_within_its_tolerance_is_passed(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0, 1.0), Waypoint(10.0, 10.0, 1.0)])
    out = pp.update(9.5, 0.3, 0.5)
    assert out.advanced == (0,) and out.target == 1
    assert pp.current_waypoint == Waypoint(10.0, 10.0, 1.0)
    # the next segment starts at the passed waypoint: the look-ahead follows x = 10
    assert out.lookahead_point == pytest.approx((10.0, 0.3 + 5.0))


def test_the_front_point_reaches_a_waypoint_too(arcs):
    # a waypoint 1.2 m short of a wall at x = 11.2: facing it, the rear axle stays 2.45 m
    # behind the bumper and never comes within 1 m; the bumper's ground point does
    pp = started(arcs, [Waypoint(10.0, 0.0, 1.0), Waypoint(10.0, 10.0, 1.0)])
    pp.set_front(2.45)
    assert pp.update(6.5, 0.0, 0.0).advanced == ()  # bumper at x = 8.95: 1.05 m off
    out = pp.update(6.6, 0.0, 0.0)  # bumper at x = 9.05: 0.95 m
    assert out.advanced == (0,) and out.target == 1
    # the point turns with the vehicle, and may sit to one side: 2 m ahead, 0.5 m left
    pp = started(arcs, [Waypoint(0.0, 3.0, 0.5)], at=(0.5, 0.0, 0.0))
    pp.set_front(2.0, 0.5)
    assert pp.front == (2.0, 0.5)
    assert pp.update(0.5, 0.6, 0.0).advanced == ()  # facing east: the point at (2.5, 1.1)
    assert pp.update(0.5, 0.6, math.pi / 2).state == "finished"  # facing north: (0, 2.6)
    with pytest.raises(ValueError):
        pp.set_front(math.nan)


def test_passing_beside_a_via_point_outside_its_tolerance_is_not_reaching_it(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0, 1.0), Waypoint(10.0, 10.0, 1.0)])
    out = pp.update(10.5, 3.0, math.pi / 2)  # cut the corner: 3.04 m from it, past it
    assert out.advanced == () and out.target == 0
    assert out.lookahead_point == (10.0, 0.0)  # turn back to it


def test_a_via_point_passed_far_off_is_sought_not_skipped(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0, 1.0), Waypoint(10.0, 10.0, 1.0)])
    out = pp.update(11.0, 8.0, math.pi / 2)  # past its perpendicular but 8 m away
    assert out.advanced == () and out.target == 0
    assert out.lookahead_point == (10.0, 0.0)  # the via-point itself, behind: turn back
    assert abs(out.curvature) == arcs.max_curvature


def test_several_waypoints_can_be_passed_in_one_update(arcs):
    pp = started(arcs, [Waypoint(1.0, 0.0, 0.5), Waypoint(1.5, 0.0, 0.5), Waypoint(9.0, 0.0)])
    out = pp.update(1.4, 0.0, 0.0)
    assert out.advanced == (0, 1) and out.target == 2


def test_the_square_is_driven_in_order_without_skipping_or_oscillating(arcs):
    square = [Waypoint(20.0, 0.0), Waypoint(20.0, 20.0), Waypoint(0.0, 20.0),
              Waypoint(0.0, 0.0)]
    pp = PurePursuit(arcs, SETTINGS)
    pp.set_waypoints(square)
    log = drive(pp, arcs, (0.0, 0.0, 0.0), 1000)
    assert log[-1][3].state == "finished" and pp.finished
    assert advanced(log) == [0, 1, 2, 3]
    xy = np.array([(x, y) for x, y, *_ in log])
    for w in square:  # every corner visited within its tolerance (2 m), none cut
        assert np.min(np.hypot(xy[:, 0] - w.x, xy[:, 1] - w.y)) <= w.tolerance
    # along each side the steering settles: few sign changes of the chosen curvature
    kappas = [o.curvature for *_, o in log if o.state == "following"]
    signs = np.sign([k for k in kappas if abs(k) > 1e-3])
    assert np.count_nonzero(np.diff(signs)) <= 8


def test_a_lateral_offset_converges_without_oscillation(arcs):
    pp = PurePursuit(arcs, SETTINGS)
    pp.set_waypoints([Waypoint(0.0, 0.0), Waypoint(200.0, 0.0)])
    pp.update(0.0, 0.0, 0.0)  # first segment anchored at the origin, reached at once
    log = drive(pp, arcs, (0.0, 3.0, 0.4), 400)  # 3 m off, heading away from the path
    ys = np.array([y for _, y, *_ in log])
    assert abs(ys[-1]) < 0.3
    assert ys.min() > -1.0  # converges with little overshoot
    crossings = np.count_nonzero(np.diff(np.sign(ys[ys != 0])))
    assert crossings <= 3


# --- patrol, stop, halt ------------------------------------------------------------------


def test_patrol_loops_back_to_the_first_waypoint(arcs):
    triangle = [Waypoint(15.0, 0.0), Waypoint(15.0, 15.0), Waypoint(0.0, 0.0)]
    pp = PurePursuit(arcs, SETTINGS)
    pp.set_waypoints(triangle, patrol=True)
    log = drive(pp, arcs, (0.0, 0.0, 0.0), 800)
    assert all(o.state == "following" for *_, o in log)
    assert advanced(log)[:7] == [0, 1, 2, 0, 1, 2, 0]
    assert all(math.isinf(o.distance_to_goal) for *_, o in log)


def test_on_patrol_the_target_wraps_to_the_first_waypoint(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0), Waypoint(10.0, 10.0), Waypoint(0.0, 10.0)],
                 patrol=True)
    assert pp.update(10.0, 0.5, math.pi / 2).advanced == (0,)
    assert pp.update(10.0, 9.0, math.pi / 2).advanced == (1,)
    assert pp.update(1.0, 10.0, math.pi).advanced == (2,)
    out = pp.update(1.0, 10.0, math.pi)  # the loop goes on w2 -> w0
    assert out.target == 0
    direction = np.array([10.0, -10.0]) / math.hypot(10.0, 10.0)
    assert out.lookahead_point == pytest.approx(tuple(np.array([0.0, 10.0])
                                                      + (1.0 / math.sqrt(2) + 5.0)
                                                      * direction))


def test_patrol_with_one_waypoint_finishes(arcs):
    pp = started(arcs, [Waypoint(5.0, 0.0)], patrol=True)
    assert pp.update(4.0, 0.0, 0.0).state == "finished"


def test_after_the_last_waypoint_the_vote_is_to_stop(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0, 1.0)])
    out = pp.update(9.5, 0.0, 0.0)
    assert out.state == "finished" and out.advanced == (0,)
    assert pp.current_waypoint is None and out.target is None
    v = out.votes
    assert not v.veto.any() and np.all(v.max_speed == 0) and np.all(v.certainty == 1)
    assert int(np.argmax(v.vote)) == arcs.straight_index
    assert pp.update(50.0, 50.0, 1.0).state == "finished"  # stays finished


def test_without_waypoints_the_vote_is_to_stop(arcs):
    pp = PurePursuit(arcs, SETTINGS)
    out = pp.update(0.0, 0.0, 0.0)
    assert out.state == "idle" and np.all(out.votes.max_speed == 0)
    assert not out.votes.veto.any()


def test_halt_vetoes_every_arc_and_keeps_the_target(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0, 1.0), Waypoint(10.0, 10.0, 1.0)])
    pp.update(9.5, 0.0, 0.0)
    pp.set_halt(True)
    out = pp.update(9.8, 0.0, 0.0)
    assert out.state == "halted" and out.votes.all_vetoed and pp.halted
    pp.set_halt(False)
    resumed = pp.update(9.8, 0.0, 0.0)
    assert resumed.state == "following" and resumed.target == 1


def test_a_new_list_restarts_from_where_the_vehicle_is(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0)])
    pp.set_waypoints([Waypoint(0.0, 20.0)])
    out = pp.update(5.0, 0.0, math.pi / 2)
    assert out.target == 0
    # the new segment runs from (5, 0) to (0, 20)
    direction = np.array([-5.0, 20.0]) / math.hypot(5, 20)
    assert out.lookahead_point == pytest.approx(tuple(np.array([5.0, 0.0]) + 5 * direction))


# --- goal behind, near the goal -------------------------------------------------------------


@pytest.mark.parametrize("side, index", [(1.0, 0), (-1.0, -1)])
def test_a_goal_behind_takes_the_hardest_turn_towards_it(arcs, side, index):
    pp = started(arcs, [Waypoint(-15.0, side)])
    out = pp.update(0.0, 0.0, 0.0)
    assert out.curvature == side * arcs.max_curvature
    assert int(np.argmax(out.votes.vote)) == range(len(arcs))[index]
    log = drive(pp, arcs, (0.0, 0.0, 0.0), 400)
    assert log[-1][3].state == "finished"


def test_near_the_goal_the_lookahead_runs_past_it_instead_of_pulling_in(arcs):
    pp = started(arcs, [Waypoint(20.0, 0.0, 0.5)])
    out = pp.update(18.0, 1.0, 0.0)
    assert out.lookahead_point == pytest.approx((23.0, 0.0))
    assert abs(out.curvature) < 0.1  # pulling in to (20, 0) would ask for -0.4


def test_a_goal_inside_the_turning_circle_does_not_stall_the_vehicle(arcs):
    pp = PurePursuit(arcs, SETTINGS)
    pp.set_waypoints([Waypoint(4.0, 2.5, 1.0)])
    log = drive(pp, arcs, (0.0, 0.0, 0.0), 300)
    assert log[-1][3].state == "finished"
    assert len(log) < 150  # no circling round the goal


# --- votes and speeds ------------------------------------------------------------------------


def test_gaussian_shape_peak_symmetry_and_width():
    sigma = 0.08
    k = np.array([2, 1, 0, -1, -2]) * sigma
    assert gaussian_votes(k, 0.0, sigma) == pytest.approx(np.exp(-0.5 * np.array([4, 1, 0, 1, 4])))
    off = gaussian_votes(k, 0.5 * sigma, sigma)
    assert off.max() == 1.0 and np.argmax(off) in (1, 2)
    assert off[1] == off[2]  # the ideal half-way: equal votes either side
    far = gaussian_votes(k, 100.0, sigma)  # no underflow to 0/0
    assert far[0] == 1.0 and np.all(np.isfinite(far))
    with pytest.raises(ValueError):
        gaussian_votes(k, 0.0, 0.0)


def test_votes_peak_at_the_ideal_arc_and_spread_by_sigma(arcs):
    pp = started(arcs, [Waypoint(30.0, 0.0)])
    out = pp.update(10.0, 0.0, 0.0)
    v = out.votes.vote
    assert v[arcs.straight_index] == 1.0
    assert np.allclose(v, v[::-1])  # symmetric about the straight arc
    sigma_k = SETTINGS.sigma_curvature
    assert sigma_k == pytest.approx(2 * 1.0 / 5.0**2)
    assert v == pytest.approx(np.exp(-0.5 * (arcs.curvatures / sigma_k) ** 2))
    assert v[arcs.straight_index + 1] == pytest.approx(0.958, abs=1e-3)


def test_speeds_are_slower_on_sharper_arcs_and_near_the_goal(arcs):
    pp = started(arcs, [Waypoint(100.0, 0.0)])
    far = pp.update(10.0, 0.0, 0.0).votes.max_speed
    assert far[arcs.straight_index] == SETTINGS.max_speed
    half = far[: arcs.straight_index + 1]
    assert np.all(np.diff(half) >= 0) and half[0] < half[-1]
    assert far[0] == pytest.approx(math.sqrt(0.5 / arcs.max_curvature))
    assert np.allclose(far, far[::-1])
    near = pp.update(97.0, 0.0, 0.0)
    assert near.distance_to_goal == pytest.approx(3.0)
    assert near.votes.max_speed.max() == pytest.approx(math.sqrt(2 * 0.5 * 3.0))
    tight = started(arcs, [Waypoint(100.0, 0.0, 0.01)])
    closest = tight.update(99.98, 0.0, 0.0)  # 2 cm from the goal, outside its tolerance
    assert closest.state == "following"
    assert math.sqrt(2 * 0.5 * 0.02) < SETTINGS.min_speed
    assert np.all(closest.votes.max_speed == SETTINGS.min_speed)  # never stalls


def test_speeds_are_not_capped_by_the_goal_on_patrol(arcs):
    pp = started(arcs, [Waypoint(10.0, 0.0), Waypoint(10.0, 10.0)], patrol=True)
    out = pp.update(6.0, 0.0, 0.0)
    assert out.votes.max_speed[arcs.straight_index] == SETTINGS.max_speed


def test_settings():
    assert PursuitSettings.from_parameters(PurePursuitParameters(Lookahead=8.0)).lookahead == 8
    for bad in (dict(lookahead=0), dict(sigma_lateral=-1), dict(min_speed=3.0),
                dict(max_speed=math.inf)):
        with pytest.raises(ValueError):
            PursuitSettings(**bad)
    with pytest.raises(ValueError):
        Waypoint(0.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        Waypoint(math.nan, 0.0)
    with pytest.raises(ValueError):
        PurePursuit(ArcSet.from_parameters()).update(math.nan, 0.0, 0.0)
