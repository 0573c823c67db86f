"""Pictures of the map layers from a simulated run, for docs/maps.md.

Runs the Raptor's configuration on a shipped world in virtual time, driving the world's
script (``--teleop``, so the pictures do not depend on the planners), and draws

- ``maps-terrain.png``: the Terrain Map's global map (mean height and point count per
  0.2 m cell) at ``--at`` seconds;
- ``maps-traversability.png``: the Traversability Map's global map (hazard and goodness
  per 0.5 m cell) at the same moment;
- ``maps-global.png``: the Global Map's planning cost at the end of the run over the
  ground the vehicle saw, with the vehicle's track and the world's obstacles outlined
  (ground truth, resampled into the map frame);
- ``maps-ego.png``: the Terrain Map's ego map at ``--at`` seconds in its own,
  heading-aligned frame (ahead up, left to the left), beside the global map with the
  ego map's footprint drawn where its ``mapPose`` places it;
- ``maps-cell-stats.png``: the Terrain Map's per-cell statistics at ``--at`` seconds:
  minimum and maximum point height and the variance of the heights;
- ``maps-global-layers.png``: the Global Map's two cost layers at the end: the *a
  priori* layer (operator knowledge; for the picture an a-priori cost of 3 is set on a
  10 m x 6 m patch through ``setPlanningMap``'s core, ``PlanningGrid.set_a_priori``,
  after the drive, which does not change the sensed layer), the *sensed* layer, and the
  planning cost the planner reads (sensed where sensed, else a priori).

Every map is drawn in its own frame, the pose frame: metres east (x) and north (y) of
the first GPS fix. Usage (matplotlib needed: ``pip install -e '.[docs]'``)::

    python docs/make_map_figures.py [--world rock-field] [--at 30] [--out docs/images]

The run is deterministic (a seed, virtual time), so the same command draws the same
pictures; it takes about a minute.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's afa and components, not an installed one

from afa import VirtualClock  # noqa: E402
from components.global_map.component import GlobalMap  # noqa: E402
from components.map_quality import MapFrame, truth_in_map_frame  # noqa: E402
from components.simulation import RaptorSimulation  # noqa: E402
from components.terrain_map.component import TerrainMap  # noqa: E402
from components.traversability_map.component import TraversabilityMap  # noqa: E402

WORLDS = ROOT / "configs" / "worlds"
CONFIG = ROOT / "configs" / "raptor.xml"


def component(system: Any, kind: type) -> Any:
    return next(c for c in system.components.values() if isinstance(c, kind))


async def simulate(world: str, at: float, seed: int) -> dict[str, Any]:
    """Run the world's drive script; the terrain and traversability maps at ``at`` s, the
    Global Map's layers at the end."""
    simulation = RaptorSimulation.from_xml(CONFIG, WORLDS / f"{world}.xml",
                                           clock=VirtualClock(), seed=seed, teleop=True)
    async with simulation:
        system = simulation.system
        await system.run(at)
        terrain = component(system, TerrainMap).latest_map.get()
        ego = component(system, TerrainMap).latest_ego.get()
        trav = component(system, TraversabilityMap).latest_map.get()
        vehicle = (simulation.state.east, simulation.state.north)
        limit = simulation.time_limit or 120.0
        runner = asyncio.ensure_future(system.run(max(0.0, limit - at)))
        finished = asyncio.ensure_future(simulation.finished.wait())
        await asyncio.wait([runner, finished], return_when=asyncio.FIRST_COMPLETED)
        for task in (runner, finished):
            task.cancel()
        await asyncio.gather(runner, finished, return_exceptions=True)
        global_map = component(system, GlobalMap)
        summary = simulation.summary()
        sensed_cost = global_map.grid.sensed_cost.copy()
        sensed = global_map.grid.sensed.copy()
        a_priori_patch(global_map, simulation)
        return {"terrain": terrain, "trav": trav, "ego": ego, "vehicle_at": vehicle,
                "cost": global_map.grid.cost(), "sensed": sensed,
                "a_priori": global_map.grid.a_priori.copy(), "sensed_cost": sensed_cost,
                "geometry": global_map.grid.geometry, "initial_utm": global_map.initial_utm,
                "track": np.array(simulation.track), "simulation": simulation,
                "maps": summary["maps"], "world": world}


def a_priori_patch(global_map: Any, simulation: Any) -> None:
    """An example of operator knowledge for the a-priori picture: cost 3 on a 10 m x 6 m
    patch whose corner lies on the track's midpoint."""
    grid, track = global_map.grid, list(simulation.track)
    frame = MapFrame.of(simulation.world.origin, global_map.initial_utm)
    x, y = frame.to_map(*track[len(track) // 2])
    i0, j0 = grid.world_to_cell(x, y)
    cells = round(10.0 / grid.geometry.gridsize), round(6.0 / grid.geometry.gridsize)
    i, j = np.meshgrid(np.arange(i0, i0 + cells[0]), np.arange(j0, j0 + cells[1]),
                       indexing="ij")
    grid.set_a_priori(i, j, 3.0)


def extent(layer_map: Any) -> list[float]:
    """imshow extent of a map's (rows along x, cols along y) layers, drawn transposed."""
    g = layer_map.gridsize
    return [layer_map.originX, layer_map.originX + layer_map.rows * g,
            layer_map.originY, layer_map.originY + layer_map.cols * g]


def draw(run: dict[str, Any], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import colors

    out.mkdir(parents=True, exist_ok=True)
    simulation = run["simulation"]
    frame = MapFrame.of(simulation.world.origin, run["initial_utm"])
    track_x, track_y = frame.to_map(run["track"][:, 0], run["track"][:, 1])
    vx, vy = frame.to_map(*run["vehicle_at"])
    written = []

    def finish(fig: Any, name: str) -> None:
        path = out / name
        fig.savefig(path, dpi=80, pil_kwargs={"optimize": True})
        plt.close(fig)
        written.append(path)

    def grey_bad(cmap: str) -> Any:
        cm = plt.get_cmap(cmap).copy()
        cm.set_bad("#d9d9d9")
        return cm

    def vehicle(ax: Any) -> None:
        ax.plot(track_x, track_y, color="black", lw=0.8, alpha=0.5, label="track")
        ax.plot([vx], [vy], marker="o", color="magenta", ms=6, label="vehicle")
        ax.set_xlabel("x east (m)")
        ax.set_ylabel("y north (m)")

    # -- terrain -----------------------------------------------------------------------
    terrain = run["terrain"]
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.6), constrained_layout=True)
    heights = np.ma.masked_invalid(terrain.elevation.T)
    image = axes[0].imshow(heights, origin="lower", extent=extent(terrain),
                           cmap=grey_bad("terrain"), interpolation="nearest")
    fig.colorbar(image, ax=axes[0], label="mean height (m)", shrink=0.85)
    counts = np.ma.masked_equal(terrain.pointCount.T, 0)
    image = axes[1].imshow(counts, origin="lower", extent=extent(terrain),
                           cmap=grey_bad("viridis"), norm=colors.LogNorm(),
                           interpolation="nearest")
    fig.colorbar(image, ax=axes[1], label="points per cell", shrink=0.85)
    for ax, title in zip(axes, ("terrain height", "points fused"), strict=True):
        vehicle(ax)
        ax.set_xlim(extent(terrain)[:2])
        ax.set_ylim(extent(terrain)[2:])
        ax.set_title(f"Terrain Map: {title} (0.2 m cells)")
    axes[0].legend(loc="lower left", fontsize=8)
    finish(fig, "maps-terrain.png")

    # -- traversability ----------------------------------------------------------------
    trav = run["trav"]
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.6), constrained_layout=True)
    hazard_cmap = grey_bad("RdYlGn_r")
    image = axes[0].imshow(np.ma.masked_invalid(trav.hazard.T), origin="lower",
                           extent=extent(trav), cmap=hazard_cmap, vmin=0.0, vmax=1.0,
                           interpolation="nearest")
    fig.colorbar(image, ax=axes[0], label="hazard (1: untraversable)", shrink=0.85)
    image = axes[1].imshow(trav.goodness.T, origin="lower", extent=extent(trav),
                           cmap="Blues", vmin=0.0, vmax=1.0, interpolation="nearest")
    fig.colorbar(image, ax=axes[1], label="goodness", shrink=0.85)
    for ax, title in zip(axes, ("hazard", "goodness"), strict=True):
        vehicle(ax)
        ax.set_xlim(extent(trav)[:2])
        ax.set_ylim(extent(trav)[2:])
        ax.set_title(f"Traversability Map: {title} (0.5 m cells)")
    axes[0].legend(loc="lower left", fontsize=8)
    finish(fig, "maps-traversability.png")

    # -- global map --------------------------------------------------------------------
    geometry = run["geometry"]
    sensed = run["sensed"]
    rows, cols = np.nonzero(sensed)
    i0, i1 = max(rows.min() - 4, 0), min(rows.max() + 5, geometry.rows)
    j0, j1 = max(cols.min() - 4, 0), min(cols.max() + 5, geometry.cols)
    g = geometry.gridsize
    box = [geometry.origin_x + i0 * g, geometry.origin_x + i1 * g,
           geometry.origin_y + j0 * g, geometry.origin_y + j1 * g]
    cost = run["cost"][i0:i1, j0:j1].T
    # never sensed: NaN (grey); impassable: inf, drawn as a large cost (black, "over")
    shown = np.where(sensed[i0:i1, j0:j1].T, np.minimum(cost, 1e6), np.nan)
    cost_cmap = plt.get_cmap("YlOrBr").copy()
    cost_cmap.set_bad("#d9d9d9")
    cost_cmap.set_over("black")
    width = 11.0
    height = max(3.0, min(8.0, width * (box[3] - box[2]) / (box[1] - box[0]) + 1.2))
    fig, ax = plt.subplots(figsize=(width, height), constrained_layout=True)
    image = ax.imshow(np.ma.masked_where(np.isnan(shown), shown), origin="lower", extent=box,
                      cmap=cost_cmap, norm=colors.LogNorm(vmin=1.0, vmax=10.0),
                      interpolation="nearest")
    fig.colorbar(image, ax=ax, label="cost (black: impassable, grey: never sensed)",
                 extend="max", shrink=0.9)
    truth = truth_in_map_frame(simulation.terrain, frame, (box[0], box[1]), (box[2], box[3]))
    ny, nx = truth.obstacle.shape
    tx = truth.east0 + truth.resolution * np.arange(nx)
    ty = truth.north0 + truth.resolution * np.arange(ny)
    ax.contour(tx, ty, truth.obstacle.astype(float), levels=[0.5], colors="tab:blue",
               linewidths=0.9)
    ax.plot(track_x, track_y, color="black", lw=0.8, alpha=0.6)
    ax.set_xlim(box[:2])
    ax.set_ylim(box[2:])
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    hazards = run["maps"]["hazards"]
    ax.set_title(f"Global Map: planning cost at the end of {run['world']} (0.5 m cells); "
                 f"blue: obstacles (truth); black line: track. Detected "
                 f"{hazards['detected_cells']}/{hazards['obstacle_cells']}, false hazards "
                 f"{hazards['false_hazard_cells']}/{hazards['free_observed_cells']}",
                 fontsize=9)
    finish(fig, "maps-global.png")

    # -- the ego map -------------------------------------------------------------------
    ego = run["ego"]
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.8), constrained_layout=True,
                             gridspec_kw={"width_ratios": [1.0, 1.25]})
    g = ego.gridsize
    ahead = [ego.originX, ego.originX + ego.rows * g]
    left = [ego.originY, ego.originY + ego.cols * g]
    # rows run ahead (drawn up), columns to the left (drawn leftwards: the x axis flipped)
    image = axes[0].imshow(np.ma.masked_invalid(ego.elevation), origin="lower",
                           extent=[left[0], left[1], ahead[0], ahead[1]],
                           cmap=grey_bad("terrain"), interpolation="nearest")
    axes[0].set_xlim(left[1], left[0])
    axes[0].plot([0.0], [0.0], marker="^", color="magenta", ms=8)
    axes[0].set_xlabel("y to the left (m)")
    axes[0].set_ylabel("x ahead of the front bumper (m)")
    axes[0].set_title(f"ego map: heading-aligned ({g:g} m cells)")
    fig.colorbar(image, ax=axes[0], label="height above the bumper's ground (m)", shrink=0.85)
    heights = np.ma.masked_invalid(terrain.elevation.T)
    image = axes[1].imshow(heights, origin="lower", extent=extent(terrain),
                           cmap=grey_bad("terrain"), interpolation="nearest")
    pose = np.asarray(ego.mapPose)
    corners = np.array([[ahead[0], left[0]], [ahead[1], left[0]], [ahead[1], left[1]],
                        [ahead[0], left[1]], [ahead[0], left[0]]])
    footprint = corners @ pose[:2, :2].T + pose[:2, 3]  # mapPose: into the pose frame
    axes[1].plot(footprint[:, 0], footprint[:, 1], color="magenta", lw=1.2,
                 label="ego map (mapPose)")
    vehicle(axes[1])
    axes[1].set_xlim(extent(terrain)[:2])
    axes[1].set_ylim(extent(terrain)[2:])
    axes[1].set_title("global terrain map (north-up) and the ego map's footprint")
    axes[1].legend(loc="lower left", fontsize=8)
    fig.colorbar(image, ax=axes[1], label="mean height (m)", shrink=0.85)
    finish(fig, "maps-ego.png")

    # -- cell statistics ---------------------------------------------------------------
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 4.4), constrained_layout=True)
    known = terrain.pointCount.T > 0
    low = np.ma.masked_where(~known, terrain.minHeight.T)
    high = np.ma.masked_where(~known, terrain.maxHeight.T)
    levels = (float(np.ma.min(low)), float(np.ma.max(high)))
    for ax, layer, title in ((axes[0], low, "minimum height"), (axes[1], high,
                                                                 "maximum height")):
        image = ax.imshow(layer, origin="lower", extent=extent(terrain), vmin=levels[0],
                          vmax=levels[1], cmap=grey_bad("terrain"), interpolation="nearest")
        fig.colorbar(image, ax=ax, label=f"{title} (m)", shrink=0.8)
        ax.set_title(f"Terrain Map: {title} per cell")
    variance = np.ma.masked_where(~known | (terrain.variance.T <= 0), terrain.variance.T)
    image = axes[2].imshow(variance, origin="lower", extent=extent(terrain),
                           cmap=grey_bad("magma"), norm=colors.LogNorm(vmin=1e-5, vmax=1.0),
                           interpolation="nearest")
    fig.colorbar(image, ax=axes[2], label="variance of point heights (m²)", shrink=0.8)
    axes[2].set_title("Terrain Map: height variance per cell")
    for ax in axes:
        vehicle(ax)
        ax.set_xlim(extent(terrain)[:2])
        ax.set_ylim(extent(terrain)[2:])
    finish(fig, "maps-cell-stats.png")

    # -- the Global Map's layers -------------------------------------------------------
    fig, axes = plt.subplots(1, 3, figsize=(13.5, max(3.2, height * 0.55)),
                             constrained_layout=True)
    window = (slice(i0, i1), slice(j0, j1))
    layers = (("a priori cost", run["a_priori"][window].T),
              ("sensed cost (grey: never sensed)",
               np.where(sensed[window].T, run["sensed_cost"][window].T, np.nan)),
              ("planning cost: sensed, else a priori", run["cost"][window].T))
    for ax, (title, layer) in zip(axes, layers, strict=True):
        shown = np.ma.masked_invalid(np.where(np.isinf(layer), 1e6, layer))
        image = ax.imshow(shown, origin="lower", extent=box, cmap=cost_cmap,
                          norm=colors.LogNorm(vmin=1.0, vmax=10.0), interpolation="nearest")
        ax.plot(track_x, track_y, color="black", lw=0.6, alpha=0.6)
        ax.set_xlim(box[:2])
        ax.set_ylim(box[2:])
        ax.set_aspect("equal")
        ax.set_title(f"Global Map: {title}", fontsize=9)
        ax.set_xlabel("x east (m)")
    axes[0].set_ylabel("y north (m)")
    fig.colorbar(image, ax=axes, label="cost (black: impassable)", extend="max", shrink=0.8)
    finish(fig, "maps-global-layers.png")
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--world", default="rock-field", help="a world in configs/worlds")
    parser.add_argument("--at", type=float, default=30.0,
                        help="simulated seconds at which to draw the terrain and "
                             "traversability maps")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images")
    args = parser.parse_args(argv)
    run = asyncio.run(simulate(args.world, args.at, args.seed))
    for path in draw(run, args.out):
        print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: "
              f"{path.stat().st_size // 1024} KB")
    print("maps:", run["maps"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
