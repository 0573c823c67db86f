"""Drive every shipped world's mission autonomously and draw docs/autonomy.md's pictures
and outcome table.

    python docs/make_autonomy_figures.py [WORLD ...] [--seed N] [--jobs N]

A WORLD is a shipped world's name or the path of a world file (``something.xml``).

Each world runs in its own interpreter (``--jobs`` at a time, default 2), in virtual time
with the whole stack of configs/raptor.xml on emulated devices, as
``afa run configs/raptor.xml --sim --world WORLD --fast`` does. Writes
``docs/images/autonomy-WORLD.png`` (the driven track over the world's obstacles and
waypoints) and prints the Markdown table docs/autonomy.md holds.
Needs the ``docs`` extra (matplotlib).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
IMAGES = ROOT / "docs" / "images"


def drive(world: str, seed: int) -> dict[str, Any]:
    """One world's mission in this interpreter; its summary and the picture."""
    sys.path.insert(0, str(ROOT))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from afa import VirtualClock
    from components.simulation import RaptorSimulation

    path = Path(world) if world.endswith(".xml") else \
        ROOT / "configs" / "worlds" / f"{world}.xml"
    world = path.stem

    async def run() -> tuple[RaptorSimulation, dict[str, Any]]:
        sim = RaptorSimulation.from_xml(ROOT / "configs" / "raptor.xml", path,
                                        clock=VirtualClock(), seed=seed)
        async with sim:
            await sim.run_mission()
        return sim, {**sim.summary(), **sim.course_reference()}

    sim, summary = asyncio.run(run())
    terrain = sim.terrain
    e0, e1, n0, n1 = terrain.extent
    fig, ax = plt.subplots(figsize=(7, max(3.0, 7 * (n1 - n0) / (e1 - e0))))
    relief = np.clip(terrain.surface - terrain.ground, -1.0, 1.0)
    ax.imshow(relief, origin="lower", extent=(e0, e1, n0, n1), cmap="RdBu_r", vmin=-1, vmax=1)
    track = np.asarray(sim.track)
    if len(track):
        ax.plot(track[:, 0], track[:, 1], "k-", lw=1.4, label="driven")
    waypoints = sim.world.mission.waypoints
    ax.plot([w.east for w in waypoints], [w.north for w in waypoints], "*", color="tab:green",
            ms=13, label="waypoints")
    ax.plot(sim.world.vehicle.east, sim.world.vehicle.north, "o", color="tab:green", ms=7)
    ratio = summary.get("path_ratio")
    ax.set_title(f"{world}: " + (f"complete, {ratio:.2f}× the shortest course"
                                 if summary["mission_complete"] and ratio is not None
                                 else "not complete"), fontsize=10)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    IMAGES.mkdir(parents=True, exist_ok=True)
    fig.savefig(IMAGES / f"autonomy-{world}.png", dpi=70)
    plt.close(fig)
    keys = ("mission_complete", "waypoints_reached", "waypoints_total", "collisions",
            "mission_complete_time_s", "mission_distance_m", "oracle_distance_m",
            "path_ratio", "clearance_m", "halts", "oscillation_per_min")
    out = {k: summary.get(k) for k in keys}
    out["world"] = world
    out["backouts"] = sim.system.components["arcArbiter"].statistics().get("backouts") \
        if "arcArbiter" in sim.system.components else None
    return out


def row(s: dict[str, Any]) -> str:
    def f(v: Any, fmt: str) -> str:
        return "–" if v is None else format(v, fmt)
    return (f"| {s['world']} | {'yes' if s['mission_complete'] else '**no**'} | "
            f"{s['waypoints_reached']}/{s['waypoints_total']} | {len(s['collisions'])} | "
            f"{f(s['path_ratio'], '.2f')} | {f(s['mission_complete_time_s'], '.0f')} | "
            f"{f(s['clearance_m'], '.2f')} | {s['halts']} | "
            f"{f(s['oscillation_per_min'], '.1f')} | {f(s['backouts'], 'd')} |")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("worlds", nargs="*",
                        help="world names or files (default: every shipped world)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--json", type=Path, help="also write the summaries here")
    args = parser.parse_args()
    worlds = args.worlds or sorted(p.stem for p in (ROOT / "configs" / "worlds").glob("*.xml"))
    with ProcessPoolExecutor(args.jobs) as pool:
        results = list(pool.map(drive, worlds, [args.seed] * len(worlds)))
    print("| world | complete | waypoints | collisions | path ratio | time (s) | "
          "clearance (m) | halts | oscillation (/min) | back-outs |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for s in results:
        print(row(s))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0 if all(s["mission_complete"] and not s["collisions"] for s in results) else 1


if __name__ == "__main__":
    sys.exit(main())
