"""Planning costs: FindPath's D* Lite against scipy's full Dijkstra replan.

Section ``dstar``: a robot drives from one corner of a seeded random obstacle field
(discs of impassable cells, patches of rough cells of cost 2-5) to the other. It
starts knowing nothing (the freespace assumption: every cell costs 1) and, at every
cell, reveals the true costs within its sensor radius; the planner then replans and
the robot moves one cell along the new path (move, scan, replan: the D* Lite order).
Each cycle is timed twice, interleaved on the same known map:

- D* Lite replan: ``update_costs`` (given the whole sensor window; it diffs the window
  itself) + ``replan`` (incremental within the fallback budget, else a rebuild; the
  rebuilds are counted);
- scipy full replan: the reversed graph built vectorised from the known map
  (:func:`reverse_graph`) + ``scipy.sparse.csgraph.dijkstra`` from the goal. On the
  large grid it is timed every ``--scipy-every`` cycles only (its cost barely varies).

Per trial: mean, p95 and max over all cycles, and the mean over the cycles whose scan
changed something; expansions per replan; the initial plan (incremental ``compute`` on
the first known map, and ``rebuild``). Figures are medians over the trials.

Section ``fallback``: changes near the goal (3x3 and 7x7 squares on the path, blocked or
freed, 2-50 % of the way from the goal), each timed from the same exact state as an
uncapped incremental repair, as a from-scratch ``rebuild`` and as ``replan()`` (repair
within the budget, else rebuild); prints the break-even expansion count behind the
budget (docs/decisions/0016-dstar-fallback.md).

Section ``refine``: FindPath's kinematic refinement (Hybrid A* over forward arcs,
decision 0024) into a 3 m gate in a wall, from five approaches (along the wall, square to
it, from the far side of the gate), each query timed with the compiled search and with
the Python loop it compiles (decision 0028), interleaved; they return the same path. A
third contender is the compiled search with reverse motions too, as FindPath runs it
(FindPath's ``ReverseCost`` and ``ReverseSwitchCost``, decision 0046): its expansions,
time, and whether its path backs.

Usage: ``python benchmarks/planning.py [--sections dstar fallback refine] [--trials N]
[--seed S] [--cpu]``

Other sections (arc scoring, arbitration) add a function taking the parsed arguments
and an entry in ``SECTIONS``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from components.find_path.dstar_lite import (  # noqa: E402
    DStarLite,
    PlanStatus,
    reverse_graph,
)

# ---------------------------------------------------------------------- shared helpers

now: Callable[[], float] = time.perf_counter  # main() switches to process_time for --cpu


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (0-100) of values, linear interpolation; nan if empty."""
    return float(np.percentile(values, q)) if values else math.nan


def median(values: list[float]) -> float:
    return statistics.median(values) if values else math.nan


# ---------------------------------------------------------------------- section: dstar

@dataclass(frozen=True)
class DriveCase:
    """One benchmark configuration: grid size, sensor radius, obstacle field."""

    name: str
    size: int
    radius: int
    obstacle_fraction: float = 0.20
    rough_fraction: float = 0.10


@dataclass
class DriveResult:
    """What one trial measured (times in seconds)."""

    initial_compute: float = 0.0
    initial_expansions: int = 0
    initial_rebuild: float = 0.0
    replans: list[float] = field(default_factory=list)
    changed_replans: list[float] = field(default_factory=list)
    expansions: list[int] = field(default_factory=list)
    scipy: list[float] = field(default_factory=list)
    steps: int = 0
    reached: bool = False
    rebuilds: int = 0


def obstacle_field(size: int, fraction: float, rough: float, seed: int) -> np.ndarray:
    """A seeded random field: impassable discs (radius 1-4) and rough patches (cost 2-5).

    The start and goal corners are kept clear.
    """
    rng = np.random.default_rng(seed)
    cost = np.ones((size, size))
    for value, target in ((None, rough), (math.inf, fraction)):
        mask = np.zeros((size, size), dtype=bool)
        covered, goal = 0, target * size * size
        while covered < goal:
            cx, cy = rng.integers(0, size, 2)
            r = rng.uniform(1.0, 4.5)
            x0, x1 = max(0, cx - 5), min(size, cx + 6)
            y0, y1 = max(0, cy - 5), min(size, cy + 6)
            xx, yy = np.mgrid[x0:x1, y0:y1]
            disc = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
            covered += int((disc & ~mask[x0:x1, y0:y1]).sum())
            mask[x0:x1, y0:y1] |= disc
            cost[x0:x1, y0:y1][disc] = rng.uniform(2.0, 5.0) if value is None else value
    clear = 8
    cost[:clear, :clear] = 1.0
    cost[-clear:, -clear:] = 1.0
    return cost


def sensor_offsets(radius: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell offsets within a Euclidean radius (a disc window)."""
    r = np.arange(-radius, radius + 1)
    dx, dy = np.meshgrid(r, r, indexing="ij")
    inside = dx * dx + dy * dy <= radius * radius
    return dx[inside], dy[inside]


def scipy_replan(known: np.ndarray, goal: tuple[int, int]) -> float:
    """A full from-scratch replan with scipy: build the reversed graph, run Dijkstra."""
    graph = reverse_graph(known)
    dist = dijkstra(graph, directed=True, indices=goal[0] * known.shape[1] + goal[1])
    return float(dist[0])


def drive(case: DriveCase, seed: int, scipy_every: int) -> DriveResult:
    """One trial: drive corner to corner through unknown terrain, timing each replan."""
    size = case.size
    truth = obstacle_field(size, case.obstacle_fraction, case.rough_fraction, seed)
    known = np.ones_like(truth)
    start, goal = (3, 3), (size - 4, size - 4)
    ox, oy = sensor_offsets(case.radius)
    result = DriveResult()

    def window(cell: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        xs = ox + cell[0]
        ys = oy + cell[1]
        keep = (xs >= 0) & (xs < size) & (ys >= 0) & (ys < size)
        return xs[keep], ys[keep]

    planner = DStarLite(known, start, goal)
    xs, ys = window(start)
    known[xs, ys] = truth[xs, ys]
    planner.update_costs(xs, ys, truth[xs, ys])
    t0 = now()
    status = planner.compute()
    result.initial_compute = now() - t0
    result.initial_expansions = planner.statistics().last_expansions
    twin = DStarLite(known, start, goal)
    t0 = now()
    twin.rebuild()
    result.initial_rebuild = now() - t0
    del twin

    position = start
    for step in range(4 * size):
        if status is not PlanStatus.DONE or position == goal:
            break
        position = planner.path(max_cells=2)[1]
        planner.move_start(position)
        xs, ys = window(position)
        changed = bool((known[xs, ys] != truth[xs, ys]).any())
        known[xs, ys] = truth[xs, ys]
        scipy_first = step % 2 == 1  # alternate the order of the two timings
        if scipy_first and step % scipy_every == 0:
            t0 = now()
            scipy_replan(known, goal)
            result.scipy.append(now() - t0)
        t0 = now()
        planner.update_costs(xs, ys, truth[xs, ys])
        status = planner.replan()
        elapsed = now() - t0
        if not scipy_first and step % scipy_every == 0:
            t0 = now()
            scipy_replan(known, goal)
            result.scipy.append(now() - t0)
        result.replans.append(elapsed)
        if changed:
            result.changed_replans.append(elapsed)
        result.expansions.append(planner.statistics().last_expansions)
        result.steps += 1
    result.reached = position == goal
    result.rebuilds = planner.statistics().rebuilds
    return result


def dstar_section(args: argparse.Namespace) -> None:
    """D* Lite replans while driving into unknown terrain, against scipy full replans."""
    cases = [DriveCase("160 x 160, sensor radius 16", 160, 16),
             DriveCase("500 x 500, sensor radius 20", 500, 20)]
    results: dict[str, list[DriveResult]] = {case.name: [] for case in cases}
    every = {160: 1, 500: args.scipy_every}
    for trial in range(args.trials):  # trials interleaved across the cases
        for case in cases:
            results[case.name].append(drive(case, args.seed + trial, every[case.size]))
    print(f"D* Lite replanning while driving into unknown terrain "
          f"(medians over {args.trials} trials, seeds {args.seed}..{args.seed + args.trials - 1})")
    for case in cases:
        rs = results[case.name]

        def med(fn: Callable[[DriveResult], float], rs: list[DriveResult] = rs) -> float:
            return median([fn(r) for r in rs])

        ms = 1e3
        mean = med(lambda r: statistics.fmean(r.replans)) * ms
        p95 = med(lambda r: percentile(r.replans, 95)) * ms
        worst = med(lambda r: max(r.replans)) * ms
        changed_mean = med(lambda r: statistics.fmean(r.changed_replans)) * ms
        sp_mean = med(lambda r: statistics.fmean(r.scipy)) * ms
        exp_mean = med(lambda r: statistics.fmean(r.expansions))
        exp_p95 = med(lambda r: percentile([float(e) for e in r.expansions], 95))
        exp_max = med(lambda r: float(max(r.expansions)))
        us_per_exp = med(lambda r: sum(r.replans) / max(1, sum(r.expansions))) * 1e6
        print(f"\n{case.name}: {med(lambda r: r.steps):.0f} cycles per drive, "
              f"{med(lambda r: len(r.changed_replans)):.0f} with changes, goal reached in "
              f"{sum(r.reached for r in rs)}/{len(rs)} trials, "
              f"{sum(r.rebuilds for r in rs)} fallback rebuilds in all")
        print(f"  initial plan    D* Lite compute {med(lambda r: r.initial_compute) * ms:7.1f} ms "
              f"({med(lambda r: r.initial_expansions):.0f} expansions), "
              f"rebuild (scipy) {med(lambda r: r.initial_rebuild) * ms:7.1f} ms")
        print(f"  D* Lite replan  mean {mean:6.2f} ms  p95 {p95:6.2f} ms  max {worst:7.2f} ms  "
              f"(mean over changed cycles {changed_mean:.2f} ms)")
        print(f"  expansions      mean {exp_mean:6.0f}     p95 {exp_p95:6.0f}     "
              f"max {exp_max:7.0f}     ({us_per_exp:.2f} us per expansion, update_costs "
              f"included)")
        print(f"  scipy replan    mean {sp_mean:6.2f} ms  -> D* Lite {sp_mean / mean:.1f}x faster "
              f"on the mean")


# ---------------------------------------------------------------------- section: fallback

@dataclass(frozen=True)
class NearGoalChange:
    """A square of cells centred on the path, ``fraction`` of the way from goal to start."""

    size: int  # side of the square, cells
    fraction: float  # 0: at the goal, 1: at the start
    free: bool  # True: the square was impassable and is freed; False: it becomes impassable


def near_goal_trial(cost: np.ndarray, start: tuple[int, int], goal: tuple[int, int],
                    change: NearGoalChange) -> dict[str, float]:
    """Time one near-goal change three ways, each from the same exact (rebuilt) state."""
    reference = DStarLite(cost, start, goal)
    reference.rebuild()
    path = reference.path()
    cx, cy = path[len(path) - 1 - int(change.fraction * (len(path) - 1))]
    half = change.size // 2
    xs, ys = np.meshgrid(np.arange(cx - half, cx - half + change.size),
                         np.arange(cy - half, cy - half + change.size), indexing="ij")
    keep = ((xs >= 0) & (xs < cost.shape[0]) & (ys >= 0) & (ys < cost.shape[1])
            & ~((xs == goal[0]) & (ys == goal[1])) & ~((xs == start[0]) & (ys == start[1])))
    xs, ys = xs[keep], ys[keep]
    before = cost.copy()
    if change.free:
        before[xs, ys] = math.inf
    after_values = np.ones(xs.size) if change.free else np.full(xs.size, math.inf)
    out: dict[str, float] = {"distance": float(max(abs(cx - goal[0]), abs(cy - goal[1])))}
    for how in ("incremental", "rebuild", "replan"):
        planner = DStarLite(before, start, goal)
        planner.rebuild()
        t0 = now()
        planner.update_costs(xs, ys, after_values)
        if how == "incremental":
            planner.compute()
        elif how == "rebuild":
            planner.rebuild()
        else:
            planner.replan()
        out[how] = now() - t0
        stats = planner.statistics()
        if how == "incremental":
            out["expansions"] = float(stats.last_expansions)
        if how == "replan":
            out["replan_rebuilt"] = float(stats.rebuilds > 1)
            out["budget"] = float(planner.fallback_expansions)
    return out


def fallback_section(args: argparse.Namespace) -> None:
    """Near-goal changes: incremental repair against a from-scratch rebuild, and replan()."""
    changes = [NearGoalChange(size, fraction, free)
               for fraction in (0.02, 0.05, 0.1, 0.25, 0.5)
               for size in (3, 7) for free in (False, True)]
    print("\nNear-goal changes on the obstacle field, start and goal in opposite corners "
          f"(medians over {args.fallback_trials} trials; times in ms)")
    for size in (160, 500):
        cost = obstacle_field(size, 0.20, 0.10, args.seed)
        start, goal = (3, 3), (size - 4, size - 4)
        rows = []
        for change in changes:
            trials = [near_goal_trial(cost, start, goal, change)
                      for _ in range(args.fallback_trials)]
            rows.append((change, {k: median([t[k] for t in trials]) for k in trials[0]}))
        budget = rows[0][1]["budget"]
        print(f"\n{size} x {size} ({size * size} cells), replan() budget {budget:.0f} expansions")
        print("  change            from goal  expansions  incremental  rebuild  replan()")
        per_expansion = []
        for change, m in rows:
            what = f"{change.size}x{change.size} {'freed' if change.free else 'blocked'}"
            print(f"  {what:16s}  {m['distance']:7.0f}    {m['expansions']:9.0f}  "
                  f"{m['incremental'] * 1e3:10.1f}  {m['rebuild'] * 1e3:7.1f}  "
                  f"{m['replan'] * 1e3:7.1f}{' (rebuilt)' if m['replan_rebuilt'] else ''}")
            if m["expansions"] >= 1000:
                per_expansion.append(m["incremental"] / m["expansions"])
        rebuild = median([m["rebuild"] for _, m in rows])
        us = median(per_expansion) * 1e6 if per_expansion else math.nan
        print(f"  rebuild median {rebuild * 1e3:.1f} ms = {rebuild / (size * size) * 1e9:.0f} ns "
              f"per cell; large repairs {us:.1f} us per expansion; break-even "
              f"{rebuild / (us * 1e-6):.0f} expansions = {rebuild / (us * 1e-6) / size ** 2:.3f} "
              f"per cell")


# ---------------------------------------------------------------------- main

# ---------------------------------------------------------------------- refine section

def gate_scene(cell: float = 0.5, cells: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """A 0.6 m wall along x = 0 with a gate from y = 8 to 11 m on an 80 × 80 grid of
    0.5 m from (-20, -20): the blocked cells as the Traversability Map marks them (the
    wall's cells and their neighbours) and FindPath's grown cost (inf within 1.5 cells,
    3 within 3 cells)."""
    from scipy import ndimage

    edges = -20.0 + cell * np.arange(cells + 1)
    blocked = np.zeros((cells, cells), dtype=bool)
    across = (edges[:-1] < 0.3) & (edges[1:] > -0.3)
    for y0, y1 in ((-20.0, 8.0), (11.0, 20.0)):
        blocked |= np.outer(across, (edges[:-1] < y1) & (edges[1:] > y0))
    blocked = ndimage.binary_dilation(blocked, structure=np.ones((3, 3), dtype=bool))
    distance = ndimage.distance_transform_edt(~blocked)
    cost = np.where(distance <= 3.0, 3.0, 1.0)
    cost[distance <= 1.5] = np.inf
    return blocked, cost


def refine_section(args: argparse.Namespace) -> None:
    from components.arcs import max_curvature
    from components.find_path.kinematic import Refiner
    from components.find_path.parameters import FindPathParameters

    blocked, cost = gate_scene()
    starts = {"along the wall": (-3.0, -2.0, math.pi / 2),
              "near the gate": (-4.0, 2.0, math.pi / 2), "square to it": (-8.0, 0.0, 0.0),
              "far down it": (-3.0, -5.0, math.pi / 2),
              "from the north": (-6.0, 14.0, -math.pi / 2)}
    fast = Refiner(0.9 * max_curvature(30.0, 1.9), (0.0, 0.8, 1.6, 2.4), 0.81,
                   hazard_margin=0.25)
    slow = Refiner(0.9 * max_curvature(30.0, 1.9), (0.0, 0.8, 1.6, 2.4), 0.81,
                   hazard_margin=0.25)
    slow.kernel = None
    shipped = FindPathParameters()
    backing = Refiner(0.9 * max_curvature(30.0, 1.9), (0.0, 0.8, 1.6, 2.4), 0.81,
                      hazard_margin=0.25, reverse_cost=shipped.ReverseCost,
                      switch_cost=shipped.ReverseSwitchCost)
    print("\nKinematic refinement into a 3 m gate (target 4 m beyond it), per query")
    if fast.kernel is None:
        print("  no compiled search here (numba missing, or AFA_KERNELS=numpy)")
        return
    print("  approach          expansions   compiled    Python   ratio | with backing: "
          "expansions  compiled  backs")
    for name, start in starts.items():
        times: dict[str, list[float]] = {"fast": [], "slow": [], "back": []}
        expansions: dict[str, int] = {}
        backs = False
        for _ in range(max(3, args.trials)):
            for key, refiner in (("fast", fast), ("back", backing), ("slow", slow)):
                t0 = now()
                refined = refiner.plan(blocked, cost, (-20.0, -20.0), 0.5, start,
                                       (4.0, 9.5, 0.0))
                times[key].append(now() - t0)
                expansions[key] = refined.expansions if refined is not None else -1
                if key == "back":
                    backs = refined is not None and -1 in refined.directions
        f, s, b = median(times["fast"]), median(times["slow"]), median(times["back"])
        print(f"  {name:16s}  {expansions['fast']:10d}  {f * 1e3:7.2f} ms {s * 1e3:7.1f} ms "
              f"{s / f:6.1f}x | {expansions['back']:24d}  {b * 1e3:5.2f} ms  "
              f"{'yes' if backs else 'no'}")


SECTIONS: dict[str, Callable[[argparse.Namespace], None]] = {
    "dstar": dstar_section,
    "fallback": fallback_section,
    "refine": refine_section,
}


def main(argv: list[str] | None = None) -> None:
    """Run the named sections (all by default) and print their figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sections", nargs="+", choices=sorted(SECTIONS),
                        default=list(SECTIONS), help="which sections to run (default: all)")
    parser.add_argument("--trials", type=int, default=5, help="trials per case (default 5)")
    parser.add_argument("--seed", type=int, default=1, help="first obstacle-field seed")
    parser.add_argument("--scipy-every", type=int, default=10,
                        help="time scipy's replan every N cycles on the large grid (default 10)")
    parser.add_argument("--fallback-trials", type=int, default=3,
                        help="trials per near-goal change in the fallback section (default 3)")
    parser.add_argument("--cpu", action="store_true",
                        help="time with this process's CPU time instead of the wall clock "
                             "(steadier on a shared, loaded machine)")
    args = parser.parse_args(argv)
    global now
    now = time.process_time if args.cpu else time.perf_counter
    print(f"clock: {'process CPU time' if args.cpu else 'wall (perf_counter)'}")
    for name in args.sections:
        SECTIONS[name](args)


if __name__ == "__main__":
    main()
