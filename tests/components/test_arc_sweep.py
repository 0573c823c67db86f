"""Obstacle Avoidance's arc sweeps (components/obstacle_avoidance/sweep.py).

The oracle is a per-step walk written independently of the tables: step along each arc
every CurveMakingConst metres, test every cell within each disc's bounding box, and
note the first obstacle, the first blocking cell, and the cells met on the way. The
table-based scorer must agree with it exactly on veto and distances, on random maps.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.arcs import ArcSet, ArcSetParameters, arc_point
from components.obstacle_avoidance.parameters import ObstacleAvoidanceParameters
from components.obstacle_avoidance.sweep import (
    ArcSweeper,
    ArcSweepScorer,
    MapGeometry,
    build_sweep_tables,
    discounted_distance,
    distance_weight,
)
from idl.common import TimeIDL
from idl.maps import EtravMapArrayEventIDL

BUMPER = (2.45, 0.0)  # Raptor:Front-BumperCenter in the rear-axle frame (docs/geometry.md)
RAPTOR_EGO = MapGeometry(rows=32, cols=32, gridsize=0.5, origin_x=0.0, origin_y=-8.0)


@pytest.fixture(scope="module")
def arcs() -> ArcSet:
    return ArcSet.from_parameters()


def params(**overrides) -> ObstacleAvoidanceParameters:
    """The sweep's geometry alone: any obstacle within the horizon vetoes, unless a test
    sets VetoDistance (configs/raptor.xml's 2.5 m leaves farther obstacles to the vote),
    and a hazard may lie anywhere in its cell, unless a test sets HazardMargin."""
    return ObstacleAvoidanceParameters(**{"VehicleRadius": 0.7, "VetoDistance": math.inf,
                                          "HazardMargin": 0.0, **overrides})


_SCORERS: dict[tuple, ArcSweepScorer] = {}


def sweeper(arcs, p, geometry, offsets=(0.0,), frame=BUMPER, **kw) -> ArcSweepScorer:
    """A scorer, its tables built once per configuration for the whole module."""
    key = (id(arcs), p, geometry, offsets, frame, tuple(sorted(kw.items())))
    if key not in _SCORERS:
        sw = ArcSweeper(arcs, p, map_frame=frame, disc_offsets=offsets, **kw)
        _SCORERS[key] = sw.scorer(geometry)
    return _SCORERS[key]


# --- the per-step reference ----------------------------------------------------------


def reference_walk(arcs, geometry, p, hazard, goodness, *, frame, offsets, threshold=1.0):
    """Per arc: (veto, obstacle distance, free distance, vote, certainty), by walking."""
    g, R, c = geometry.gridsize, p.VehicleRadius, p.CurveMakingConst
    first_ahead = max(0, math.ceil(-geometry.origin_x / g - 1e-9))
    row_lo = min(first_ahead + p.NearZone, geometry.rows)
    row_hi = max(min(first_ahead + p.FarZone, geometry.rows), row_lo)
    horizon = max(0.0, frame[0] + geometry.origin_x + row_hi * g + R - min(offsets))
    results = []
    for kappa in arcs.curvatures.tolist():
        length = horizon if kappa == 0 else min(horizon, math.pi / abs(kappa))
        met: dict[tuple[int, int], float] = {}
        d_obs = math.inf
        d_block = math.inf
        for step in range(math.floor(length / c + 1e-9) + 1):
            s = step * c
            if s > d_obs:
                break
            for a in offsets:
                x, y, _ = arc_point(s, kappa, a)
                xm, ym = x - frame[0], y - frame[1]
                for i in range(math.floor((xm - R - geometry.origin_x) / g),
                               math.floor((xm + R - geometry.origin_x) / g) + 1):
                    if not row_lo <= i < row_hi:
                        continue
                    for j in range(math.floor((ym - R - geometry.origin_y) / g),
                                   math.floor((ym + R - geometry.origin_y) / g) + 1):
                        if not 0 <= j < geometry.cols:
                            continue
                        x0 = geometry.origin_x + i * g
                        y0 = geometry.origin_y + j * g
                        dx = max(x0 - xm, xm - (x0 + g), 0.0)
                        dy = max(y0 - ym, ym - (y0 + g), 0.0)
                        if dx**2 + dy**2 > R**2:
                            continue
                        met.setdefault((i, j), s)
                        h = float(hazard[i, j])
                        unknown = math.isnan(h)
                        obstacle = h >= threshold or (unknown and p.VetoUnknownCells)
                        if obstacle:
                            d_obs = min(d_obs, s)
                        if obstacle or (unknown and p.CostUnknownCells):
                            d_block = min(d_block, s)
        free = min(d_block, length)
        rough = 0.0
        good = []
        for (i, j), s in met.items():
            h = float(hazard[i, j])
            if s < free and not math.isnan(h):
                w = max(p.MinDistDiscount, 1 - p.DistFactor / 100 * s)
                rough = max(rough, h * w)
            if s <= free:
                good.append(float(goodness[i, j]))
        results.append((math.isfinite(d_obs) and d_obs <= p.VetoDistance, d_obs, free, rough,
                        sum(good) / len(good) if good else 0.0))
    return results


def random_map(rng, geometry, obstacles=0.03, unknown=0.05):
    shape = (geometry.rows, geometry.cols)
    hazard = rng.uniform(0.0, 0.9, shape)
    hazard[rng.random(shape) < obstacles] = 1.0
    hazard[rng.random(shape) < unknown] = np.nan
    return hazard.astype(np.float32), rng.uniform(0.0, 1.0, shape).astype(np.float32)


CASES = [
    # geometry, parameters, disc offsets, map frame, obstacle and unknown densities
    (MapGeometry(16, 16, 0.5, 0.0, -4.0),
     dict(CurveMakingConst=0.05, NearZone=1, FarZone=12, DistFactor=5, MinDistDiscount=0.6),
     (0.0, 2.45), BUMPER, 0.03, 0.05),
    (MapGeometry(16, 16, 0.5, 0.0, -4.0),
     dict(CurveMakingConst=0.05, CostUnknownCells=True), (0.0,), BUMPER, 0.005, 0.05),
    (MapGeometry(14, 18, 0.4, -1.2, -3.0),
     dict(CurveMakingConst=0.03, VehicleRadius=0.5, VetoUnknownCells=True, FarZone=9),
     (0.0, 1.9), (2.45, 0.2), 0.01, 0.005),
    (MapGeometry(10, 10, 0.5, 0.0, -2.5),
     dict(CurveMakingConst=0.01, DistFactor=10, MinDistDiscount=0.2, CostUnknownCells=True,
          VetoUnknownCells=True), (0.0,), BUMPER, 0.02, 0.01),
    # the shipped veto distance: farther obstacles shorten the free distance, no veto
    (MapGeometry(16, 16, 0.5, 0.0, -4.0),
     dict(CurveMakingConst=0.05, VetoDistance=2.5), (0.0, 0.8, 1.6, 2.4), BUMPER, 0.01, 0.05),
]


@pytest.mark.parametrize("case", range(len(CASES)))
def test_the_tables_agree_with_the_per_step_walk_on_random_maps(arcs, case):
    geometry, overrides, offsets, frame, density, unknown = CASES[case]
    p = params(**overrides)
    scorer = sweeper(arcs, p, geometry, offsets, frame)
    rng = np.random.default_rng(1000 + case)
    vetoes = 0
    for _ in range(2):
        hazard, goodness = random_map(rng, geometry, obstacles=density, unknown=unknown)
        got = scorer.score(hazard, goodness)
        want = reference_walk(arcs, geometry, p, hazard, goodness, frame=frame,
                              offsets=offsets)
        veto, d_obs, free, rough, certainty = (np.array(c) for c in zip(*want, strict=True))
        assert got.votes.veto.tolist() == veto.tolist()
        assert got.obstacle_distance.tolist() == d_obs.tolist()
        assert got.free_distance.tolist() == free.tolist()
        assert got.votes.certainty == pytest.approx(certainty, abs=1e-12)
        clear = discounted_distance(np.minimum(free, got.horizons.min()), p.DistFactor,
                                    p.MinDistDiscount)
        norm = discounted_distance(got.horizons.min(), p.DistFactor, p.MinDistDiscount)
        assert got.votes.vote == pytest.approx(np.clip(clear / norm * (1 - rough), 0, 1),
                                               abs=1e-12)
        vetoes += int(veto.sum())
    assert 0 < vetoes < 2 * len(arcs)  # the maps exercised both outcomes


def test_the_reference_walk_itself_finds_a_wall_where_it_is(arcs):
    geometry = MapGeometry(16, 16, 0.5, 0.0, -4.0)
    p = params(CurveMakingConst=0.02)
    hazard = np.zeros((16, 16), np.float32)
    hazard[6, :] = 1.0  # map x 3.0 .. 3.5 m, rear-axle x 5.45 m
    walk = reference_walk(arcs, geometry, p, hazard, np.ones_like(hazard), frame=BUMPER,
                          offsets=(0.0,))
    veto, d_obs = walk[13][0], walk[13][1]
    assert veto and d_obs == pytest.approx(5.45 - 0.7, abs=0.021)


# --- tables --------------------------------------------------------------------------


def test_tables_are_built_once_per_geometry(arcs):
    sw = ArcSweeper(arcs, params(), map_frame=BUMPER)
    zeros = np.zeros((32, 32), np.float32)
    for _ in range(3):
        sw.score(RAPTOR_EGO, zeros, zeros)
    assert sw.tables_built == 1
    other = MapGeometry(40, 40, 0.4, 0.0, -8.0)
    sw.score(other, np.zeros((40, 40)), np.zeros((40, 40)))
    assert sw.tables_built == 2
    assert sw.scorer(other).tables.geometry == other


def test_mirrored_arcs_sweep_mirrored_cells(arcs):
    tables = sweeper(arcs, params(), RAPTOR_EGO, (0.0, 2.45)).tables
    n, cols = len(arcs), RAPTOR_EGO.cols
    for k in range(n):
        rows, columns, reach = tables.arc_cells(k)
        mrows, mcolumns, mreach = tables.arc_cells(n - 1 - k)
        assert sorted(zip(rows.tolist(), (cols - 1 - columns).tolist(), reach.tolist(),
                          strict=True)) == sorted(zip(mrows.tolist(), mcolumns.tolist(),
                                                      mreach.tolist(), strict=True))


def test_tables_are_ordered_by_reach_and_respect_the_zones(arcs):
    p = params(NearZone=2, FarZone=10)
    tables = sweeper(arcs, p, RAPTOR_EGO).tables
    assert tables.row_range == (2, 10)
    for k in range(len(arcs)):
        rows, _, reach = tables.arc_cells(k)
        assert np.all(np.diff(reach) >= 0)
        assert rows.size == 0 or (rows.min() >= 2 and rows.max() < 10)
        assert np.all(reach <= tables.horizons[k])
    # horizon: the straight arc's disc clears row 10 (x 5 m past the bumper); no arc
    # sweeps farther, and none more than half a circle
    assert tables.horizons[arcs.straight_index] == pytest.approx(2.45 + 5.0 + 0.7)
    assert tables.horizons.max() == tables.horizons[arcs.straight_index]
    whole = sweeper(arcs, params(), RAPTOR_EGO).tables
    assert whole.horizons[arcs.straight_index] == pytest.approx(2.45 + 16.0 + 0.7)
    assert whole.horizons[0] == whole.horizons[-1] == pytest.approx(math.pi / arcs.max_curvature)


def test_table_arguments_are_checked(arcs):
    for bad in (dict(radius=0.0), dict(step=-1.0), dict(disc_offsets=()),
                dict(near_zone=-1), dict(horizon=-2.0)):
        kw = dict(radius=0.5, step=0.1, near_zone=0, far_zone=5, map_frame=BUMPER)
        kw.update(bad)
        with pytest.raises(ValueError):
            build_sweep_tables(arcs, RAPTOR_EGO, **kw)
    with pytest.raises(ValueError):
        MapGeometry(0, 3, 0.5, 0, 0)
    with pytest.raises(ValueError):
        MapGeometry(3, 3, math.nan, 0, 0)


# --- scoring behaviour ---------------------------------------------------------------


def wall_with_gap(columns_free: range, row: int = 10) -> np.ndarray:
    hazard = np.zeros((32, 32), np.float32)
    hazard[row, :] = 1.0
    hazard[row, list(columns_free)] = 0.0
    return hazard


def arcs_reaching_row(tables, row: int) -> np.ndarray:
    return np.array([row in tables.arc_cells(k)[0].tolist() for k in range(len(tables.arcs))])


@pytest.mark.parametrize("offsets", [(0.0,), (0.0, 2.45)])
def test_a_gap_narrower_than_the_vehicle_vetoes_every_arc_through_it(arcs, offsets):
    scorer = sweeper(arcs, params(), RAPTOR_EGO, offsets)
    good = np.ones((32, 32), np.float32)
    # 1.0 m gap (columns 15, 16: y -0.5 .. 0.5) 5 m past the bumper, for a 1.4 m vehicle
    narrow = scorer.score(wall_with_gap(range(15, 17)), good)
    reaching = arcs_reaching_row(scorer.tables, 10)
    assert reaching[arcs.straight_index] and reaching.sum() >= 9
    assert np.all(narrow.votes.veto[reaching])
    assert not np.any(narrow.votes.veto[~reaching])  # the hard arcs turn away before it
    assert np.all(narrow.votes.max_speed[reaching] == 0)
    # a 2.0 m gap (columns 14..17: y -1.0 .. 1.0) lets the straight arc through, 0.3 m
    # clear each side
    wide = scorer.score(wall_with_gap(range(14, 18)), good)
    assert not wide.votes.veto[arcs.straight_index]
    assert wide.votes.veto[reaching].sum() == reaching.sum() - 1


def test_the_seed_default_radius_lets_the_raptor_into_a_gap_narrower_than_its_body(arcs):
    # VehicleRadius 0.5 (Table A.10) is a 1.0 m vehicle: a 1.5 m gap is open to it,
    # though the Raptor is 1.4 m wide; with 0.7 the straight arc through it stays free
    # only when centred (documented in the module: configure ≥ 0.7 m).
    scorer = sweeper(arcs, params(VehicleRadius=0.5), RAPTOR_EGO)
    gap = wall_with_gap(range(15, 18))  # y -0.5 .. 1.0
    result = scorer.score(gap, np.ones((32, 32), np.float32))
    assert not result.votes.veto.all()


def test_an_obstacle_just_beyond_the_bumper_is_found_at_the_right_distance(arcs):
    hazard = np.zeros((32, 32), np.float32)
    hazard[0, 15:17] = 1.0  # map x 0 .. 0.5 m, y -0.5 .. 0.5 m
    good = np.ones((32, 32), np.float32)
    rear = sweeper(arcs, params(), RAPTOR_EGO).score(hazard, good)
    assert rear.obstacle_distance[arcs.straight_index] == pytest.approx(2.45 - 0.7, abs=0.011)
    front = sweeper(arcs, params(), RAPTOR_EGO, (0.0, 2.45)).score(hazard, good)
    assert front.obstacle_distance[arcs.straight_index] == 0.0
    assert front.votes.veto[arcs.straight_index] and front.votes.vote[arcs.straight_index] == 0


def test_zones_hide_rows_from_the_sweep(arcs):
    good = np.ones((32, 32), np.float32)
    near = np.zeros((32, 32), np.float32)
    near[0, :] = 1.0
    assert sweeper(arcs, params(), RAPTOR_EGO, (0.0, 2.45)).score(near, good).votes.veto.any()
    assert not sweeper(arcs, params(NearZone=1), RAPTOR_EGO,
                       (0.0, 2.45)).score(near, good).votes.veto.any()
    far = np.zeros((32, 32), np.float32)
    far[20, :] = 1.0
    assert sweeper(arcs, params(), RAPTOR_EGO).score(far, good).votes.veto.any()
    assert not sweeper(arcs, params(FarZone=20), RAPTOR_EGO).score(far, good).votes.veto.any()


def test_unknown_cells_are_free_cost_or_obstacle_by_flag(arcs):
    hazard = np.zeros((32, 32), np.float32)
    hazard[8:, :] = np.nan  # unknown from 4 m past the bumper on
    goodness = np.where(np.isnan(hazard), 0.0, 1.0).astype(np.float32)
    straight = arcs.straight_index

    free = sweeper(arcs, params(), RAPTOR_EGO).score(hazard, goodness)
    assert not free.votes.veto.any()
    assert free.votes.vote[straight] == 1.0
    assert 0 < free.votes.certainty[straight] < 1  # the unknown cells carry no evidence

    cost = sweeper(arcs, params(CostUnknownCells=True), RAPTOR_EGO).score(hazard, goodness)
    assert not cost.votes.veto.any()
    assert cost.free_distance[straight] == pytest.approx(2.45 + 4.0 - 0.7, abs=0.011)
    assert cost.votes.vote[straight] < 1.0
    assert cost.votes.certainty[straight] == pytest.approx(1.0, abs=0.1)
    assert np.isinf(cost.obstacle_distance).all()

    veto = sweeper(arcs, params(VetoUnknownCells=True), RAPTOR_EGO).score(hazard, goodness)
    assert veto.votes.veto[straight]
    assert veto.obstacle_distance[straight] == cost.free_distance[straight]


def test_votes_grow_with_free_distance_and_speeds_follow(arcs):
    p = params(CostUnknownCells=True, DiscountSpeeds=True, MinVelocity=0.5, MaxVelocity=2.0)
    scorer = sweeper(arcs, p, RAPTOR_EGO)
    good = np.ones((32, 32), np.float32)
    votes, speeds = [], []
    for row in (4, 8, 12, 31):
        hazard = np.zeros((32, 32), np.float32)
        hazard[row:, :] = np.nan
        result = scorer.score(hazard, good)
        votes.append(result.votes.vote[arcs.straight_index])
        speeds.append(result.votes.max_speed[arcs.straight_index])
    assert votes == sorted(votes) and votes[0] < votes[-1] == 1.0
    assert speeds == sorted(speeds) and speeds[-1] == 2.0
    assert all(0.5 <= s <= 2.0 for s in speeds)
    assert speeds == pytest.approx([0.5 + 1.5 * v for v in votes])
    plain = sweeper(arcs, params(CostUnknownCells=True), RAPTOR_EGO).score(hazard, good)
    assert np.all(plain.votes.max_speed == 2.0)  # DiscountSpeeds off: MaxVelocity


def test_rough_ground_lowers_the_vote_less_when_discounted_for_distance(arcs):
    good = np.ones((32, 32), np.float32)

    def straight_vote(p, row):
        hazard = np.zeros((32, 32), np.float32)
        hazard[row, :] = 0.6  # traversable but rough
        return sweeper(arcs, p, RAPTOR_EGO).score(hazard, good).votes.vote[arcs.straight_index]

    plain = params()
    assert straight_vote(plain, 2) == pytest.approx(0.4) == straight_vote(plain, 12)
    discounted = params(DistFactor=5, MinDistDiscount=0.5)
    near, far = straight_vote(discounted, 2), straight_vote(discounted, 12)
    assert 0.4 < near < far < 1.0
    very_far = straight_vote(discounted, 30)  # floored at MinDistDiscount
    assert very_far == pytest.approx(1 - 0.6 * 0.5)


def test_distance_weights():
    assert distance_weight([0, 5, 10, 100], 10, 0.3).tolist() == pytest.approx([1, .5, .3, .3])
    d = np.array([0.0, 2.0, 7.0, 20.0])
    numeric = [np.trapezoid(distance_weight(np.linspace(0, x, 20001), 10, 0.3),
                            np.linspace(0, x, 20001)) for x in d]
    assert discounted_distance(d, 10, 0.3) == pytest.approx(numeric, abs=1e-6)
    assert discounted_distance(d, 0, 0.3).tolist() == d.tolist()
    assert discounted_distance(math.inf, 10, 0.3) == math.inf


def test_certainty_is_the_goodness_of_the_cells_behind_the_verdict(arcs):
    scorer = sweeper(arcs, params(), RAPTOR_EGO)
    hazard = np.zeros((32, 32), np.float32)
    assert scorer.score(hazard, np.full((32, 32), 0.25, np.float32)).votes.certainty == \
        pytest.approx(np.full(len(arcs), 0.25))
    nothing = sweeper(arcs, params(NearZone=5, FarZone=5), RAPTOR_EGO)
    result = nothing.score(hazard, np.ones((32, 32), np.float32))
    assert np.all(result.votes.certainty == 0)  # no evaluated cell: no opinion


def test_score_map_reads_an_ego_traversability_event(arcs):
    hazard = wall_with_gap(range(0))
    event = EtravMapArrayEventIDL(
        time=TimeIDL(sec=1), frame="Raptor:Front-BumperCenter", mapPose=np.eye(4),
        initialUTM=np.zeros(3), gridsize=0.5, originX=0.0, originY=-8.0, rows=32, cols=32,
        hazard=hazard, goodness=np.ones((32, 32), np.float32),
        vehiclePosition={"x": 0, "y": 0, "z": 0})
    sw = ArcSweeper(arcs, params(), map_frame=BUMPER)
    result = sw.score_map(event)
    assert result.votes.veto[arcs.straight_index]
    with pytest.raises(ValueError, match="geometry"):
        sw.scorer(RAPTOR_EGO).score(np.zeros((31, 32)), np.zeros((31, 32)))


def test_votes_are_in_range_on_random_maps(arcs):
    rng = np.random.default_rng(7)
    p = params(DiscountSpeeds=True, DistFactor=3, MinDistDiscount=0.5, CostUnknownCells=True)
    scorer = sweeper(arcs, p, RAPTOR_EGO, (0.0, 2.45))
    for _ in range(20):
        hazard, goodness = random_map(rng, RAPTOR_EGO, obstacles=0.01, unknown=0.1)
        v = scorer.score(hazard, goodness).votes
        v.to_idl(time=TimeIDL(sec=0), behaviour="ObstacleAvoidance", arcs=arcs)  # validates
        assert np.all(v.max_speed[~v.veto] >= 0.5) and np.all(v.max_speed[v.veto] == 0)


def test_hazard_threshold(arcs):
    hazard = np.zeros((32, 32), np.float32)
    hazard[10, :] = 0.8
    good = np.ones((32, 32), np.float32)
    assert not sweeper(arcs, params(), RAPTOR_EGO).score(hazard, good).votes.veto.any()
    strict = sweeper(arcs, params(), RAPTOR_EGO, hazard_threshold=0.75)
    assert strict.score(hazard, good).votes.veto[arcs.straight_index]
    with pytest.raises(ValueError):
        sweeper(arcs, params(), RAPTOR_EGO, hazard_threshold=0.0)


def test_a_different_arc_set_gets_its_own_tables():
    small = ArcSet.from_parameters(ArcSetParameters(Count=5))
    result = sweeper(small, params(), RAPTOR_EGO).score(np.zeros((32, 32)), np.ones((32, 32)))
    assert len(result.votes) == 5


def test_a_hazard_margin_takes_hazards_at_their_cells_centres(arcs):
    """HazardMargin shrinks each hazard cell (to its centre at half a cell): a gap whose
    hazard cells' centres are 2 m apart (1.5 m between their edges) is shut to a 1.4 m
    body read conservatively and open to the straight arc read at the centres; one whose
    centres are 1 m apart stays shut either way."""
    good = np.ones((32, 32), np.float32)
    conservative = sweeper(arcs, params(), RAPTOR_EGO)
    centred = sweeper(arcs, params(HazardMargin=0.25), RAPTOR_EGO)
    reaching = arcs_reaching_row(conservative.tables, 10)
    # columns 14..16 free: y -1.0 .. 0.5, hazard centres at y -1.25 and 0.75
    gap = wall_with_gap(range(14, 17))
    shut = conservative.score(gap, good).votes.veto
    opened = centred.score(gap, good).votes.veto
    assert np.all(shut[reaching])
    assert not np.all(opened[reaching])
    assert np.all(opened <= shut)  # the margin only ever opens arcs
    # one free column (0.5 m): centres 1 m apart, no room for a 1.4 m body either way
    slit = wall_with_gap(range(15, 16))
    assert np.all(centred.score(slit, good).votes.veto[reaching])
