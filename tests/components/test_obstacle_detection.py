"""The laser safety catch (components/obstacle_detection/detect.py).

Points are in the laser-level vehicle frame: the ground is z = -LaserHeight (2 m)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.arcs import ArcSet
from components.obstacle_detection.detect import ObstacleDetector, count_hits
from components.obstacle_detection.parameters import ObstacleDetectionParameters
from idl.common import TimeIDL

GROUND = -2.0


@pytest.fixture(scope="module")
def arcs() -> ArcSet:
    return ArcSet.from_parameters()


def params(**overrides) -> ObstacleDetectionParameters:
    return ObstacleDetectionParameters(**overrides)


def ground_scan(n: int = 181) -> np.ndarray:
    """A flat-ground scan line 4 m ahead of the laser, wide of the corridor both sides."""
    y = np.linspace(-4.0, 4.0, n)
    return np.column_stack([np.full(n, 2.5), y, np.full(n, GROUND)])


def with_returns(scan: np.ndarray, count: int, *, height: float, x: float = 2.0,
                 y: float = 0.0) -> np.ndarray:
    """``scan`` plus ``count`` returns ``height`` above (negative: below) the ground."""
    extra = np.tile([x, y, GROUND + height], (count, 1))
    return np.vstack([scan, extra])


def test_flat_ground_is_clear(arcs):
    hits = count_hits(ground_scan(), params())
    assert hits.total == 0 and hits.considered > 0


@pytest.mark.parametrize("height, kind", [(0.5, "positive"), (-0.5, "negative")])
def test_a_positive_or_negative_obstacle_halts_at_the_tolerance(arcs, height, kind):
    detector = ObstacleDetector(params(), arcs)
    below = detector.update(with_returns(ground_scan(), 4, height=height))
    assert not below.halt and below.votes is detector.clear_votes
    result = detector.update(with_returns(ground_scan(), 5, height=height))
    assert result.halt and result.votes is not None and result.votes.all_vetoed
    assert getattr(result.hits, kind) == 5 and result.hits.total == 5


def test_heights_within_the_safety_band_are_not_hits():
    p = params()
    scan = np.vstack([with_returns(ground_scan(), 5, height=0.29),
                      with_returns(ground_scan(), 5, height=-0.29)])
    assert count_hits(scan, p).total == 0
    assert count_hits(with_returns(ground_scan(), 3, height=0.31), p).positive == 3
    assert count_hits(with_returns(ground_scan(), 3, height=-0.31), p).negative == 3


def test_the_laser_height_sets_the_ground_plane():
    point = np.array([[2.0, 0.0, -1.5]])  # 0.5 m above ground from 2 m, 1.0 m from 2.5 m
    assert count_hits(point, params(LaserHeight=2.0)).positive == 1
    assert count_hits(point, params(LaserHeight=1.5)).total == 0
    assert count_hits(point, params(LaserHeight=1.0)).negative == 1


def test_check_flags_select_the_kinds(arcs):
    scan = with_returns(with_returns(ground_scan(), 3, height=0.5), 3, height=-0.5)
    assert count_hits(scan, params()).total == 6
    only_neg = count_hits(scan, params(CheckPosObs=False))
    assert (only_neg.positive, only_neg.negative) == (0, 3)
    only_pos = count_hits(scan, params(CheckNegObs=False))
    assert (only_pos.positive, only_pos.negative) == (3, 0)
    assert count_hits(scan, params(CheckPosObs=False, CheckNegObs=False)).total == 0
    detector = ObstacleDetector(params(CheckNegObs=False), arcs)
    assert not detector.update(with_returns(ground_scan(), 9, height=-0.5)).halt


@pytest.mark.parametrize("x, y", [(3.2, 0.0), (-0.1, 0.0), (1.0, 0.51), (1.0, -0.51)])
def test_returns_outside_the_corridor_are_ignored(x, y):
    scan = with_returns(ground_scan(), 10, height=1.0, x=x, y=y)
    assert count_hits(scan, params()).total == 0


@pytest.mark.parametrize("x, y", [(0.0, 0.0), (3.0, 0.0), (1.0, 0.5), (1.0, -0.5)])
def test_the_corridor_edges_are_inside(x, y):
    scan = with_returns(ground_scan(), 10, height=1.0, x=x, y=y)
    assert count_hits(scan, params()).total == 10


def test_the_corridor_follows_safety_dist_vehicle_width_and_default_ymax():
    scan = with_returns(ground_scan(), 10, height=1.0, x=4.0, y=0.6)
    assert count_hits(scan, params()).total == 0
    assert count_hits(scan, params(SafetyDist=4.5, VehicleWidth=1.4)).total == 10
    # DefaultYMax limits the half width
    assert count_hits(scan, params(SafetyDist=4.5, VehicleWidth=1.4, DefaultYMax=0.5)).total == 0


def test_returns_at_or_beyond_the_maximum_range_and_nan_are_ignored():
    p = params(MaxLaserRange=2500)
    scan = with_returns(ground_scan(), 10, height=1.0, x=1.5)
    near = np.linalg.norm(scan, axis=1)
    assert count_hits(scan, p).total == 10  # ranges 1.5 m .. < 2.5 m
    ranges = near.copy()
    ranges[-10:] = 2.5  # the "no echo" maximum
    assert count_hits(scan, p, ranges).total == 0
    far = with_returns(ground_scan(), 10, height=-0.5, x=2.5)  # |p| > 2.5 m
    assert count_hits(far, p).total == 0
    broken = with_returns(ground_scan(), 10, height=1.0)
    broken[-10:, 0] = np.nan
    assert count_hits(broken, params()).total == 0
    ranges = np.linalg.norm(with_returns(ground_scan(), 10, height=1.0), axis=1)
    ranges[-10:] = np.nan
    assert count_hits(with_returns(ground_scan(), 10, height=1.0), params(), ranges).total == 0


def test_noise_below_the_tolerance_never_halts(arcs):
    detector = ObstacleDetector(params(NumHitsTolerance=5), arcs)
    for _ in range(50):  # hits do not accumulate across scans
        result = detector.update(with_returns(ground_scan(), 4, height=0.5))
        assert not result.halt and result.state == "armed"
    clear = result.votes
    assert clear is not None and not clear.veto.any()
    assert np.all(clear.certainty == 0) and np.all(clear.vote == 0)
    assert np.all(clear.max_speed == 2.0)
    clear.to_idl(time=TimeIDL(sec=0), behaviour="ObstacleDetection", arcs=arcs)


def test_after_a_halt_reset_counter_scans_are_ignored(arcs):
    detector = ObstacleDetector(params(ResetCounter=3), arcs)
    blocked = with_returns(ground_scan(), 8, height=0.6)
    first = detector.update(blocked)
    assert first.halt and first.state == "holding" and first.scans_to_recheck == 3
    for left in (2, 1, 0):
        held = detector.update(blocked)
        assert held.votes is None and not held.halt and held.hits is None
        assert held.scans_to_recheck == left
    assert detector.state == "armed"
    again = detector.update(blocked)  # rechecked: still there
    assert again.halt
    for _ in range(3):
        detector.update(blocked)
    assert detector.update(ground_scan()).votes is detector.clear_votes


def test_reset_counter_zero_rechecks_every_scan(arcs):
    detector = ObstacleDetector(params(ResetCounter=0), arcs)
    blocked = with_returns(ground_scan(), 8, height=0.6)
    assert detector.update(blocked).halt and detector.update(blocked).halt
    assert not detector.update(ground_scan()).halt


def test_reset_re_arms(arcs):
    detector = ObstacleDetector(params(), arcs)
    detector.update(with_returns(ground_scan(), 8, height=0.6))
    assert detector.state == "holding"
    detector.reset()
    assert detector.state == "armed" and detector.update(ground_scan()).votes is not None


def test_bad_input_is_refused(arcs):
    with pytest.raises(ValueError):
        count_hits(np.zeros((4, 2)), params())
    with pytest.raises(ValueError):
        count_hits(np.zeros((4, 3)), params(), np.zeros(3))
    with pytest.raises(ValueError):
        ObstacleDetector(params(), arcs, max_speed=math.inf)


def test_an_empty_scan_is_clear(arcs):
    result = ObstacleDetector(params(), arcs).update(np.empty((0, 3)))
    assert not result.halt and result.hits is not None and result.hits.considered == 0
