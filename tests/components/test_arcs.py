"""The shared candidate arc set (components/arcs.py): limits, density, symmetry,
geometry, and the vote container."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from afa.sim.vehicle import Vehicle, VehicleParameters
from components.arcs import (
    DESIGN_GAP_DISTANCE,
    DESIGN_GAP_WIDTH,
    DESIGN_VEHICLE_WIDTH,
    ArcSet,
    ArcSetMismatchError,
    ArcSetParameters,
    ArcVotes,
    arc_point,
    arc_points,
    curvature_for_steering,
    max_curvature,
    minimum_count,
    required_spacing,
    steering_for_curvature,
)
from idl.common import TimeIDL
from idl.planning import ArcVoteIDL

RAPTOR = VehicleParameters()
KAPPA_MAX = math.tan(math.radians(30.0)) / 1.9
FREE_WIDTH = DESIGN_GAP_WIDTH - DESIGN_VEHICLE_WIDTH


@pytest.fixture(scope="module")
def arcs() -> ArcSet:
    return ArcSet.from_parameters()


# --- limits, symmetry, determinism -------------------------------------------------------


def test_the_default_set_spans_the_raptors_steering_limits(arcs):
    assert arcs.parameters.MaxSteeringAngle == RAPTOR.max_steering_deg
    assert arcs.parameters.Wheelbase == RAPTOR.wheelbase
    assert arcs.max_curvature == pytest.approx(KAPPA_MAX, rel=1e-15)
    assert arcs.curvatures[0] == arcs.max_curvature  # hard left first
    assert arcs.curvatures[-1] == -arcs.max_curvature  # hard right last
    assert np.degrees(arcs.steering_angles()[[0, -1]]) == pytest.approx([30.0, -30.0])
    assert np.all(np.diff(arcs.curvatures) < 0)


def test_the_set_is_exactly_symmetric_with_an_exact_straight_arc(arcs):
    k = arcs.curvatures
    assert len(k) % 2 == 1
    assert k[arcs.straight_index] == 0.0
    assert np.array_equal(k, -k[::-1])  # bitwise, not approximately
    assert np.allclose(np.diff(k), -arcs.spacing, rtol=1e-12, atol=0)


def test_the_set_is_deterministic_and_read_only(arcs):
    again = ArcSet.from_parameters(ArcSetParameters())
    assert again.curvatures.tobytes() == arcs.curvatures.tobytes()
    with pytest.raises(ValueError):
        arcs.curvatures[0] = 0.0


def test_the_constructor_refuses_curvatures_that_break_the_invariants():
    p = ArcSetParameters(Count=3)
    with pytest.raises(ValueError, match="symmetric"):
        ArcSet(p, np.array([0.3, 0.0, -0.2]))
    with pytest.raises(ValueError, match="symmetric"):
        ArcSet(p, np.array([0.3, 0.01, -0.3]))
    with pytest.raises(ValueError, match="Count"):
        ArcSet(p, np.array([0.3, 0.1, 0.0, -0.1, -0.3]))
    with pytest.raises(ValueError, match="finite"):
        ArcSet(p, np.array([np.inf, 0.0, -np.inf]))


# --- density: threading the design gap ---------------------------------------------------


def test_the_spacing_bound_is_the_documented_arithmetic():
    assert required_spacing() == pytest.approx(FREE_WIDTH / DESIGN_GAP_DISTANCE**2)
    assert required_spacing(5.0, 2.0, 1.4) == pytest.approx(0.024)
    assert minimum_count(30.0, 1.9) == 27
    with pytest.raises(ValueError):
        required_spacing(5.0, 1.2, 1.4)  # narrower than the vehicle: nothing threads it


def test_the_default_count_is_the_smallest_that_threads_the_design_gap():
    assert ArcSetParameters().Count == minimum_count(RAPTOR.max_steering_deg, RAPTOR.wheelbase)
    dense = ArcSet.from_parameters()
    sparse = ArcSet.from_parameters(ArcSetParameters(Count=25))
    assert dense.spacing <= required_spacing() < sparse.spacing


@pytest.mark.parametrize("count, threads", [(27, True), (25, False)])
def test_neighbouring_arcs_are_at_most_half_the_free_width_apart_5_m_along(count, threads):
    arcs = ArcSet.from_parameters(ArcSetParameters(Count=count))
    s = DESIGN_GAP_DISTANCE
    x, y, _ = arc_points(s, arcs.curvatures)
    gaps = np.hypot(np.diff(x), np.diff(y))
    # the bound of the derivation, reached next to the straight arc
    assert np.all(gaps <= arcs.spacing * s**2 / 2 + 1e-12)
    middle = arcs.straight_index
    assert gaps[middle] == pytest.approx(arcs.spacing * s**2 / 2, rel=2e-3)
    assert bool(np.all(gaps <= FREE_WIDTH / 2)) is threads


def test_every_gap_position_near_ahead_is_threaded_with_margin(arcs):
    # A 2 m gate square to the heading, 5 m ahead, centred anywhere within ±0.6 m of the
    # heading: some arc crosses the line x = 5 m within a quarter of the free width of the
    # gate's centre (farther off, the crossings spread: see the module docstring).
    reach = arcs.curvatures[np.abs(arcs.curvatures) * DESIGN_GAP_DISTANCE < 1]
    crossing = (1 - np.sqrt(1 - (reach * DESIGN_GAP_DISTANCE) ** 2)) / np.where(
        reach == 0, 1, reach)
    crossing[reach == 0] = 0.0
    for centre in np.linspace(-0.6, 0.6, 121):
        assert np.min(np.abs(crossing - centre)) <= FREE_WIDTH / 4 + 1e-9, centre
    assert np.diff(np.sort(crossing))[5:11] == pytest.approx(
        [0.313, 0.299, 0.293, 0.293, 0.299, 0.313], abs=1e-3)


# --- parameters ----------------------------------------------------------------------------


def test_parameters_read_miro_strings_and_refuse_bad_values():
    p = ArcSetParameters.model_validate({"Count": "31", "MaxSteeringAngle": "25",
                                         "Wheelbase": "2.0"})
    assert (p.Count, p.MaxSteeringAngle, p.Wheelbase) == (31, 25.0, 2.0)
    assert ArcSetParameters.miro_type == "Raptor::ArcSetParameters"
    for bad in ({"Count": 26}, {"Count": 1}, {"MaxSteeringAngle": 0}, {"MaxSteeringAngle": 90},
                {"Wheelbase": 0}, {"Extra": 1}):
        with pytest.raises(ValidationError):
            ArcSetParameters.model_validate(bad)
    with pytest.raises(ValidationError):
        ArcSetParameters().Count = 5  # type: ignore[misc]  # frozen


def test_other_parameters_give_other_sets():
    arcs = ArcSet.from_parameters(ArcSetParameters(Count=5, MaxSteeringAngle=20, Wheelbase=2))
    k = math.tan(math.radians(20)) / 2
    assert arcs.curvatures.tolist() == pytest.approx([k, k / 2, 0.0, -k / 2, -k])


# --- geometry ----------------------------------------------------------------------------


def test_the_straight_arc_is_a_line_and_curved_arcs_are_exact_circles():
    assert arc_point(5.0, 0.0) == (5.0, 0.0, 0.0)
    kappa = 0.25  # radius 4 m, centre (0, 4)
    assert arc_point(math.pi / 2 / kappa, kappa) == pytest.approx((4.0, 4.0, math.pi / 2))
    assert arc_point(math.pi / kappa, kappa) == pytest.approx((0.0, 8.0, math.pi), abs=1e-12)
    x, y, h = arc_points(np.linspace(0, 20, 41), -kappa)
    assert np.allclose(np.hypot(x, y + 4.0), 4.0)  # right turn: centre (0, -4)
    assert np.allclose(h, -kappa * np.linspace(0, 20, 41))


def test_tiny_curvatures_agree_with_the_straight_line_and_the_circle():
    for kappa in (1e-12, 1e-6, 1e-3):
        s = 7.0
        x, y, _ = arc_point(s, kappa)
        assert x == pytest.approx(math.sin(kappa * s) / kappa, rel=1e-12)
        assert y == pytest.approx(kappa * s * s / 2, rel=1e-4)
        assert y > 0


def test_a_body_point_rides_on_its_own_circle():
    kappa, a = 0.2, 2.45
    x, y, _ = arc_points(np.linspace(0, 10, 21), kappa, offset=a)
    assert np.allclose(np.hypot(x, y - 1 / kappa), math.hypot(1 / kappa, a))
    assert arc_point(3.0, 0.0, offset=a) == (5.45, 0.0, 0.0)


@pytest.mark.parametrize("index", [0, 5, 13, 20, 26])
def test_the_simulated_raptor_drives_exactly_the_arc(arcs, index):
    vehicle = Vehicle()
    delta = arcs.steering_angle(index)
    vehicle.reset(0.0, 0.0, 90.0, speed=1.0, steering_deg=math.degrees(delta))  # facing east
    state = vehicle.step(4.0, 1.0, math.degrees(delta))  # 4 m of travel at constant (v, δ)
    x, y, heading = arc_point(4.0, float(arcs.curvatures[index]))
    assert (state.east, state.north) == pytest.approx((x, y), abs=1e-9)
    assert math.remainder(state.yaw - heading, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_steering_and_curvature_convert_both_ways(arcs):
    assert curvature_for_steering(math.radians(30), 1.9) == pytest.approx(KAPPA_MAX)
    for k in arcs.curvatures:
        delta = steering_for_curvature(float(k), arcs.wheelbase)
        assert curvature_for_steering(delta, arcs.wheelbase) == pytest.approx(k, abs=1e-15)
    with pytest.raises(ValueError):
        max_curvature(90.0, 1.9)


def test_nearest_index(arcs):
    for k, kappa in enumerate(arcs.curvatures):
        assert arcs.nearest_index(float(kappa)) == k
        assert arcs.nearest_index(float(kappa) + 0.4 * arcs.spacing) == k
    assert arcs.nearest_index(10.0) == 0
    assert arcs.nearest_index(-10.0) == len(arcs) - 1
    # exactly half-way between two arcs: the straighter one
    left = float(arcs.curvatures[5] + arcs.curvatures[6]) / 2
    assert arcs.nearest_index(left) == 6
    assert arcs.nearest_index(-left) == len(arcs) - 1 - 6
    with pytest.raises(ValueError):
        arcs.nearest_index(math.nan)


def test_votes_over_another_set_are_refused_with_a_reason(arcs):
    arcs.check(arcs.curvatures.copy())
    arcs.check(arcs.curvatures.astype(np.float32).astype(np.float64) * 0 + arcs.curvatures)
    assert arcs.matches(arcs.curvatures + 1e-12)
    other = ArcSet.from_parameters(ArcSetParameters(Count=25))
    with pytest.raises(ArcSetMismatchError, match="25 arcs.*27"):
        arcs.check(other.curvatures)
    wheelbase = ArcSet.from_parameters(ArcSetParameters(Wheelbase=2.0))
    with pytest.raises(ArcSetMismatchError, match="arc 0 .*26 arcs differ"):
        arcs.check(wheelbase.curvatures)
    assert not arcs.matches(wheelbase.curvatures)
    assert issubclass(ArcSetMismatchError, ValueError)


# --- the vote container ---------------------------------------------------------------------


def test_arc_votes_check_ranges_and_convert_to_the_idl(arcs):
    n = len(arcs)
    votes = ArcVotes(np.arange(n) == 3, np.linspace(0, 1, n), np.full(n, 0.5), np.full(n, 1.5))
    body = votes.to_idl(time=TimeIDL(sec=3, usec=5), behaviour="PurePursuit", arcs=arcs)
    assert isinstance(body, ArcVoteIDL)
    assert body.behaviour == "PurePursuit" and body.time.to_seconds() == 3.000005
    assert np.array_equal(body.curvatures, arcs.curvatures)
    assert body.veto.tolist() == votes.veto.tolist()
    assert body.vote == pytest.approx(votes.vote, abs=1e-7)
    assert ArcVoteIDL.from_json(body.to_json()) == body
    for bad in (dict(vote=np.full(n, 1.01)), dict(certainty=np.full(n, -0.1)),
                dict(max_speed=np.full(n, math.inf)), dict(vote=np.zeros(n - 1))):
        fields = dict(veto=np.zeros(n, bool), vote=np.zeros(n), certainty=np.zeros(n),
                      max_speed=np.zeros(n))
        fields.update(bad)
        with pytest.raises(ValueError):
            ArcVotes(**fields)
    with pytest.raises(ArcSetMismatchError):
        ArcVotes.halt(n - 2).to_idl(time=TimeIDL(sec=0), behaviour="x", arcs=arcs)


def test_votes_published_again_equal_a_validated_body(arcs):
    """to_idl re-stamps the body it validated for the same votes, behaviour and arc set:
    the result equals a fresh validated construction, field by field and in its
    fingerprint (the run digest); another behaviour or arc set is validated anew."""
    n = len(arcs)
    votes = ArcVotes(np.arange(n) == 5, np.linspace(0, 1, n), np.full(n, 0.25),
                     np.full(n, 2.0))
    first = votes.to_idl(time=TimeIDL(sec=1, usec=2), behaviour="ObstacleDetection",
                         arcs=arcs)
    for stamp in (TimeIDL(sec=2, usec=999_999), TimeIDL(sec=-1, usec=0)):
        again = votes.to_idl(time=stamp, behaviour="ObstacleDetection", arcs=arcs)
        validated = ArcVoteIDL(time=stamp, behaviour="ObstacleDetection",
                               curvatures=arcs.curvatures, veto=votes.veto, vote=votes.vote,
                               certainty=votes.certainty, maxSpeed=votes.max_speed)
        assert again == validated and again.fingerprint() == validated.fingerprint()
        assert again.to_json() == validated.to_json()
        assert again.model_fields_set == validated.model_fields_set
        assert all(not getattr(again, name).flags.writeable
                   for name in ("curvatures", "veto", "vote", "certainty", "maxSpeed"))
    assert first.time == TimeIDL(sec=1, usec=2)  # the earlier body is not changed
    other = votes.to_idl(time=TimeIDL(sec=3), behaviour="PurePursuit", arcs=arcs)
    assert other.behaviour == "PurePursuit"
    with pytest.raises(ArcSetMismatchError):
        votes.to_idl(time=TimeIDL(sec=3), behaviour="PurePursuit",
                     arcs=ArcSet.from_parameters(ArcSetParameters(Count=n + 2)))
    # an unchecked producer's bad votes still fail validation, the first time and later
    bad = ArcVotes.unchecked(np.zeros(n, bool), np.full(n, 1.5), np.ones(n), np.ones(n))
    for _ in range(2):
        with pytest.raises(ValueError):
            bad.to_idl(time=TimeIDL(sec=0), behaviour="x", arcs=arcs)


def test_a_checked_votes_first_body_equals_a_validated_one(arcs):
    """The first body of checked votes is built without validating them again
    (components/trusted.py): it equals the validated construction field by field, dtype
    by dtype, in its JSON and its fingerprint; the arrays are the votes' read-only
    ones, as validation leaves them."""
    n = len(arcs)
    rng = np.random.default_rng(3)
    for _ in range(5):
        votes = ArcVotes(rng.random(n) < 0.3, rng.random(n), rng.random(n),
                         2.0 * rng.random(n))
        stamp = TimeIDL(sec=int(rng.integers(-5, 5)), usec=int(rng.integers(0, 999_999)))
        body = votes.to_idl(time=stamp, behaviour="PurePursuit", arcs=arcs)
        validated = ArcVoteIDL(time=stamp, behaviour="PurePursuit",
                               curvatures=arcs.curvatures, veto=votes.veto, vote=votes.vote,
                               certainty=votes.certainty, maxSpeed=votes.max_speed)
        assert type(body) is ArcVoteIDL and body == validated
        assert body.fingerprint() == validated.fingerprint()
        assert body.to_json() == validated.to_json()
        assert body.model_fields_set == validated.model_fields_set
        for name in ("curvatures", "veto", "vote", "certainty", "maxSpeed"):
            mine, theirs = getattr(body, name), getattr(validated, name)
            assert mine.dtype == theirs.dtype and not mine.flags.writeable, name
    # a body that is not a TimeIDL is validated (and refused), as before
    with pytest.raises(ValueError):
        ArcVotes.halt(n).to_idl(time="now", behaviour="x", arcs=arcs)  # type: ignore[arg-type]


def test_a_halt_vetoes_every_arc(arcs):
    halt = ArcVotes.halt(len(arcs))
    assert halt.all_vetoed and not np.any(halt.max_speed)
    assert halt.to_idl(time=TimeIDL(sec=0), behaviour="ObstacleDetection", arcs=arcs).all_vetoed
