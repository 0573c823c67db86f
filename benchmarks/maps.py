"""Map core costs: terrain fusion, scrolling and the ego view, traversability, Global Map.

Each section runs its contenders in one process with the trials interleaved (trial 1 of
every contender, then trial 2, ...), so drifts in machine speed hit all of them alike,
and reports medians of CPU time (``time.process_time``). Small calls are timed in
batches (``inner`` calls per sample). Figures are printed, never asserted.

Sections:

- ``fusion``: points/s of ``TerrainGrid.fuse`` (map-frame points) and
  ``fuse_transformed`` (sensor-frame points and a 4x4) on a 361-point scan line and on
  batches of 1e5 and 1e6 points, against the per-point Python loop (the definition the
  tests check against; small sizes only) and a numpy floor (the same arithmetic with
  every buffer preallocated and no checks or statistics).
- ``scroll``: ``recentre`` by one cell and the ego view (16 m x 16 m at 0.2 m).
- ``traversability``: hazards for the global (32 m at 0.5 m from 32 m at 0.2 m) and ego
  (16 m from 16 m) maps on rough terrain with obstacles, ms per event.
- ``global``: merging a 64 x 64 traversability map into the 500 x 500 planning grid.
- ``stack``: the whole stack under ``--fast`` (virtual time) as a real-time factor, with
  the three maps running (the ``maps`` stack: drivers, ModelServer, Terrain,
  Traversability and Global Map) beside the same run without them (``sensing``), both
  following the world's drive script (``--teleop``) so that the vehicle takes the same
  path. Each run is a fresh interpreter (``benchmarks/sim.py``'s runner and summary);
  ``--trials`` runs of each, interleaved, medians by wall and by CPU time. Slow (about
  15 s of CPU per run at the default 60 simulated seconds), so not run by default.

Usage: ``python benchmarks/maps.py [--repeat R] [--section NAME ...]
[--world W] [--duration S] [--trials N]``
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/sim.py

from components.global_map.accumulate import PlanningGrid  # noqa: E402
from components.terrain_map.grid import (  # noqa: E402
    EgoView,
    GridGeometry,
    TerrainGrid,
    ego_map_pose,
    transform_points,
)
from components.traversability_map.hazards import (  # noqa: E402
    HazardRules,
    TraversabilityMapper,
)

Contender = tuple[str, Callable[[], object], int]  # name, call, calls per sample


def interleaved(contenders: list[Contender], repeat: int) -> dict[str, float]:
    """Median seconds of CPU (``time.process_time``: steadier than wall time on a
    machine shared with other work) per call of each contender, trials interleaved."""
    for _, call, _ in contenders:  # warm up
        call()
    samples: dict[str, list[float]] = {name: [] for name, _, _ in contenders}
    for _ in range(repeat):
        for name, call, inner in contenders:
            start = time.process_time()
            for _ in range(inner):
                call()
            samples[name].append((time.process_time() - start) / inner)
    return {name: statistics.median(values) for name, values in samples.items()}


# --- fusion ----------------------------------------------------------------------------


def loop_fuse(grid: TerrainGrid, points: list[list[float]], time_: float) -> None:
    """The per-point definition (as the tests' oracle), on Python lists."""
    geo = grid.geometry
    count, sz, sz2 = grid.count, grid.sum_z, grid.sum_z2
    low, high, seen = grid.min_z, grid.max_z, grid.last_seen
    for x, y, z in points:
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            continue
        i = math.floor((x - geo.origin_x) / geo.gridsize)
        j = math.floor((y - geo.origin_y) / geo.gridsize)
        if 0 <= i < geo.rows and 0 <= j < geo.cols:
            c = i * geo.cols + j
            count[c] += 1
            sz[c] += z
            sz2[c] += z * z
            if z < low[c]:
                low[c] = z
            if z > high[c]:
                high[c] = z
            if time_ > seen[c]:
                seen[c] = time_


class NumpyFloor:
    """The fusion arithmetic on preallocated buffers: no checks, no statistics, no
    errstate, every point assumed inside (a lower bound for ``TerrainGrid.fuse``)."""

    def __init__(self, grid: TerrainGrid, n: int) -> None:
        self.grid = grid
        self.fi = np.empty(n)
        self.fj = np.empty(n)
        self.z = np.empty(n)
        self.zz = np.empty(n)
        self.flat = np.empty(n, dtype=np.intp)
        self.mask = np.empty(n, dtype=bool)
        self.tmp = np.empty(n, dtype=bool)

    def __call__(self, p: np.ndarray, time_: float) -> None:
        g, geo = self.grid, self.grid.geometry
        fi, fj, mask, tmp = self.fi, self.fj, self.mask, self.tmp
        np.subtract(p[:, 0], geo.origin_x, out=fi)
        np.divide(fi, geo.gridsize, out=fi)
        np.floor(fi, out=fi)
        np.subtract(p[:, 1], geo.origin_y, out=fj)
        np.divide(fj, geo.gridsize, out=fj)
        np.floor(fj, out=fj)
        np.greater_equal(np.minimum(fi, fj, out=self.zz), 0, out=mask)  # bounds: 4 tests
        np.less(fi, geo.rows, out=tmp)
        mask &= tmp
        np.less(fj, geo.cols, out=tmp)
        mask &= tmp
        np.multiply(fi, geo.cols, out=fi)
        np.add(fi, fj, out=fi)
        self.flat[:] = fi
        np.copyto(self.z, p[:, 2])
        np.multiply(self.z, self.z, out=self.zz)
        np.add.at(g.count, self.flat, 1)
        np.add.at(g.sum_z, self.flat, self.z)
        np.add.at(g.sum_z2, self.flat, self.zz)
        np.minimum.at(g.min_z, self.flat, self.z)
        np.maximum.at(g.max_z, self.flat, self.z)
        g.last_seen[self.flat] = time_


def scan_points(rng: np.random.Generator, n: int) -> np.ndarray:
    """Sensor-frame points of a nodding laser 2 m up looking 2.4-8 m ahead."""
    bearing = rng.uniform(-math.pi / 2, math.pi / 2, n)
    ground = rng.uniform(2.4, 8.0, n)
    return np.column_stack([ground * np.cos(bearing), ground * np.sin(bearing),
                            np.full(n, -2.0) + rng.normal(0, 0.05, n)])


def fusion_case(sensor: np.ndarray, sensor_pose: np.ndarray, inner: int, with_loop: bool,
                repeat: int) -> dict[str, float]:
    """Median seconds per call of each fusion contender on one batch."""
    world = transform_points(sensor_pose, sensor)
    sensor32 = sensor.astype(np.float32)
    grid = TerrainGrid.centred(0.0, 0.0, 32.0, 32.0, 0.2)
    floor = NumpyFloor(grid, len(sensor))
    contenders: list[Contender] = [
        ("fuse (map-frame float64)", lambda: grid.fuse(world, 1.0), inner),
        ("fuse_transformed (sensor float32 + 4x4)",
         lambda: grid.fuse_transformed(sensor32, sensor_pose, 1.0), inner),
        ("numpy floor", lambda: floor(world, 1.0), inner),
    ]
    if with_loop:
        as_list = world.tolist()
        contenders.append(("per-point Python loop", lambda: loop_fuse(grid, as_list, 1.0),
                           max(1, inner // 20)))
    return interleaved(contenders, repeat)


def section_fusion(repeat: int) -> None:
    print("== fusion: 32 m x 32 m grid at 0.2 m (160 x 160 cells)")
    rng = np.random.default_rng(1)
    sensor_pose = np.eye(4)
    sensor_pose[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    sensor_pose[:3, 3] = (0.3, 2.2, 2.0)
    for n, inner, with_loop in ((361, 200, True), (100_000, 1, False), (1_000_000, 1, False)):
        result = fusion_case(scan_points(rng, n), sensor_pose, inner, with_loop,
                             repeat if n < 1_000_000 else max(3, repeat // 3))
        print(f"-- {n:,} points")
        for name, seconds in result.items():
            print(f"   {name:42s} {seconds * 1e6:12.1f} us  {n / seconds / 1e6:8.2f} M points/s")


# --- scrolling and the ego view --------------------------------------------------------


def section_scroll(repeat: int) -> None:
    print("== scroll: 32 m x 32 m grid at 0.2 m; ego view 16 m x 16 m at 0.2 m")
    rng = np.random.default_rng(2)
    grid = TerrainGrid.centred(0.0, 0.0, 32.0, 32.0, 0.2)
    grid.fuse(rng.uniform(-16, 16, (200_000, 3)), 1.0)
    state = {"x": 0.0}

    def step() -> None:  # one cell east, every call
        state["x"] += 0.2
        grid.recentre(state["x"], 0.0)

    view = EgoView.ahead(16.0, 16.0, 0.2)
    vehicle = np.eye(4)
    yaw = math.radians(30)
    vehicle[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    bumper = np.eye(4)
    bumper[:3, 3] = (2.45, 0.0, 0.17)
    result = interleaved([
        ("recentre by one cell", step, 50),
        ("ego view sample (80 x 80)",
         lambda: view.sample(grid, ego_map_pose(vehicle, bumper, -0.5)), 20),
        ("layers() of the 160 x 160 grid", grid.layers, 20),
    ], repeat)
    for name, seconds in result.items():
        print(f"   {name:42s} {seconds * 1e6:12.1f} us")


# --- traversability --------------------------------------------------------------------


def rough_terrain_layers(rng: np.random.Generator, depth: float, gridsize: float
                         ) -> tuple[TerrainGrid, GridGeometry]:
    """A fused grid of rough ground with boxes and a trench, partly unseen."""
    grid = TerrainGrid.centred(0.0, 0.0, depth, depth, gridsize)
    n = int(20 * (depth / gridsize) ** 2)
    xy = rng.uniform(-depth / 2, depth / 2, (n, 2))
    x, y = xy[:, 0], xy[:, 1]
    z = 0.05 * np.sin(0.7 * x) * np.cos(0.5 * y) + rng.normal(0, 0.01, n)
    for cx, cy in rng.uniform(-depth / 3, depth / 3, (8, 2)):
        z = np.where((np.abs(x - cx) < 0.5) & (np.abs(y - cy) < 0.5), 0.6, z)
    trench = (np.abs(x - 3.0) < 1.0) & (np.abs(y) < 3.0)
    keep = ~trench | (np.abs(x - 3.9) < 0.1)
    z = np.where(trench, -0.5, z)
    grid.fuse(np.column_stack([x, y, z])[keep], 1.0)
    return grid, GridGeometry.centred(0.0, 0.0, depth, depth, 0.5)


def section_traversability(repeat: int) -> None:
    print("== traversability: hazards and goodness per event")
    rng = np.random.default_rng(3)
    mapper_global = TraversabilityMapper(HazardRules())
    mapper_ego = TraversabilityMapper(HazardRules())
    global_grid, global_geo = rough_terrain_layers(rng, 32.0, 0.2)
    ego_grid, ego_geo = rough_terrain_layers(rng, 16.0, 0.2)
    global_layers, ego_layers = global_grid.layers(), ego_grid.layers()
    result = interleaved([
        ("global: 160x160 terrain -> 64x64", lambda: mapper_global.update(
            global_layers, global_geo, (0.0, 0.0), 2.0), 5),
        ("ego: 80x80 terrain -> 32x32", lambda: mapper_ego.update(
            ego_layers, ego_geo, (0.0, 0.0), 2.0), 10),
        ("global, resampling only", lambda: mapper_global.resample(global_layers, global_geo),
         10),
    ], repeat)
    for name, seconds in result.items():
        print(f"   {name:42s} {seconds * 1e3:12.3f} ms")


# --- global map ------------------------------------------------------------------------


def section_global(repeat: int) -> None:
    print("== global: 64 x 64 traversability map into the 500 x 500 planning grid")
    rng = np.random.default_rng(4)
    plan = PlanningGrid.centred(0.0, 0.0, 250.0, 250.0, 0.5)
    hazard = rng.uniform(0, 1, (64, 64)) ** 4
    hazard[rng.random((64, 64)) < 0.2] = np.nan
    hazard[rng.random((64, 64)) < 0.05] = 1.0
    goodness = rng.uniform(0.2, 1.0, (64, 64))
    state = {"t": 0.0, "x": 0.0}

    def merge() -> None:  # the vehicle moves 0.5 m per event: a fresh strip each time
        state["t"] += 1.0
        state["x"] += 0.5
        pose = np.eye(4)
        pose[0, 3] = state["x"]
        plan.merge(hazard, goodness, pose, -16.0, -16.0, 0.5, state["t"])

    rotated = np.eye(4)
    rotated[:2, :2] = [[math.cos(0.5), -math.sin(0.5)], [math.sin(0.5), math.cos(0.5)]]
    result = interleaved([
        ("merge (aligned, moving)", merge, 20),
        ("merge (rotated 29 deg)",
         lambda: plan.merge(hazard, goodness, rotated, -16.0, -16.0, 0.5, 1e6), 20),
        ("cost() of the whole grid", plan.cost, 20),
    ], repeat)
    for name, seconds in result.items():
        print(f"   {name:42s} {seconds * 1e3:12.3f} ms")


# --- the whole stack ---------------------------------------------------------------------


def section_stack(args: argparse.Namespace) -> None:
    import sim  # benchmarks/sim.py: one run per interpreter, and the medians

    print(f"== stack: configs/raptor.xml on {Path(args.world).stem} (drive script), "
          f"{args.duration:g} s simulated per run, {args.trials} interleaved trials, medians")
    runs: dict[str, list[dict[str, object]]] = {"sensing": [], "maps": []}
    for _ in range(args.trials):
        for stack in runs:
            runs[stack].append(sim.spawn(stack, args))
    summary = {stack: sim.summarise(r) for stack, r in runs.items()}
    for stack, label in (("sensing", "without the maps"), ("maps", "with the maps")):
        r = summary[stack]
        print(f"   {label:18s} ({r['components']:2d} components): {r['realtime_factor']:7.2f}x "
              f"real time by wall clock {r['realtime_factor_range']}, "
              f"{r['cpu_realtime_factor']:7.2f}x by CPU time {r['cpu_realtime_factor_range']}; "
              f"{r['cpu_s']:.2f} s of CPU")
    extra = summary["maps"]["cpu_s"] - summary["sensing"]["cpu_s"]
    print(f"   the maps cost {extra:.2f} s of CPU over {summary['maps']['sim_time_s']:g} "
          f"simulated seconds: {1e3 * extra / summary['maps']['sim_time_s']:.1f} ms of CPU "
          f"per simulated second (medians' difference)")


#: Sections taking the trial count (``--repeat``); ``stack`` takes the parsed arguments.
SECTIONS: dict[str, Callable[[int], None]] = {
    "fusion": section_fusion,
    "scroll": section_scroll,
    "traversability": section_traversability,
    "global": section_global,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=15, help="trials per contender")
    parser.add_argument("--section", action="append", choices=[*sorted(SECTIONS), "stack"],
                        help="run only these sections (repeatable; default: all but stack)")
    parser.add_argument("--world", default="rock-field", help="stack: a shipped world")
    parser.add_argument("--seed", type=int, default=0, help="stack: the simulation's seed")
    parser.add_argument("--duration", type=float, default=60.0,
                        help="stack: simulated seconds per run")
    parser.add_argument("--trials", type=int, default=3, help="stack: runs of each stack")
    args = parser.parse_args()
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}; medians of "
          f"{args.repeat} interleaved trials, CPU time")
    for name in args.section or list(SECTIONS):
        if name == "stack":
            args.world = str(sim_world(args.world))
            section_stack(args)
        else:
            SECTIONS[name](args.repeat)


def sim_world(name: str) -> Path:
    """A shipped world's file (as benchmarks/sim.py resolves it)."""
    import sim

    return sim.world_path(name)


if __name__ == "__main__":
    main()
