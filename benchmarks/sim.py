"""Simulation speed: the world, every emulator and every sensing component in virtual time.

Prints the real-time factor of the whole stack of ``configs/raptor.xml`` under ``--fast``
(world physics, GPS/IMU/MPC555/laser/stereo emulators on the real wire protocols, the real
drivers decoding them, ModelServer) and the cost of the ray casting behind one laser scan
line and one stereo frame. Target (issue 5): the whole sensing stack at >= 20x real time.

Usage: ``python benchmarks/sim.py [--duration S] [--world FILE] [--repeat N] [--json]``
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from afa import VirtualClock  # noqa: E402
from afa.sim.raycast import cast_rays, depth_image  # noqa: E402
from components.simulation import RaptorSimulation  # noqa: E402
from components.stereo.emulator import STEREO_SUBSAMPLE  # noqa: E402

#: Issue 5's target for the whole sensing stack under --fast.
TARGET = 20.0


async def whole_stack(world: Path, duration: float) -> dict[str, float]:
    simulation = RaptorSimulation.from_xml(ROOT / "configs" / "raptor.xml", world,
                                           clock=VirtualClock(), seed=0, teleop=True)
    start = time.perf_counter()
    async with simulation:
        await simulation.system.run(duration)
        events = sum(simulation.system.statistics()["events"].values())
    wall = time.perf_counter() - start
    return {"sim_time_s": round(simulation.sim_time, 2), "wall_time_s": round(wall, 3),
            "realtime_factor": round(simulation.sim_time / wall, 2), "events": events,
            "events_per_wall_s": round(events / wall)}


def ray_casting(world: Path, repeat: int = 50) -> dict[str, float]:
    clock = VirtualClock()
    simulation = RaptorSimulation(world, clock, seed=0)
    pose = simulation.frame_pose("FrontNoddingSICKLeft:AxleCenterFreeEnd")
    bearings = np.deg2rad(np.arange(361) * 0.5)
    nod = math.radians(-25.0)
    local = np.stack([np.sin(bearings) * math.cos(nod), -np.cos(bearings),
                      np.sin(bearings) * math.sin(nod)], axis=1)
    directions = local @ pose[:3, :3].T

    def timed(fn, n):
        samples = []
        for _ in range(n):
            t0 = time.perf_counter()
            fn()
            samples.append(time.perf_counter() - t0)
        return statistics.median(samples)

    scan = timed(lambda: cast_rays(simulation.terrain, pose[:3, 3], directions, 8.183), repeat)
    camera = simulation._frame("Digiclops:ImagePlane")
    full = timed(lambda: depth_image(simulation.terrain, camera[:3, 3], camera[:3, :3], 320, 240,
                                     66.0, 10.0), 5)
    coarse = timed(lambda: depth_image(simulation.terrain, camera[:3, 3], camera[:3, :3],
                                       320 // STEREO_SUBSAMPLE, 240 // STEREO_SUBSAMPLE, 66.0,
                                       10.0), 20)
    return {"laser_scan_361_rays_ms": round(scan * 1e3, 3),
            "stereo_frame_320x240_ms": round(full * 1e3, 2),
            f"stereo_frame_{320 // STEREO_SUBSAMPLE}x{240 // STEREO_SUBSAMPLE}_ms":
                round(coarse * 1e3, 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--world", type=Path,
                        default=ROOT / "configs" / "worlds" / "open-field.xml")
    parser.add_argument("--repeat", type=int, default=3,
                        help="whole-stack runs; the median is reported (default 3)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    logging.disable(logging.WARNING)  # the notes about components not written yet
    runs = [asyncio.run(whole_stack(args.world, args.duration)) for _ in range(args.repeat)]
    factors = [run["realtime_factor"] for run in runs]
    stack = sorted(runs, key=lambda run: run["realtime_factor"])[len(runs) // 2]
    stack["realtime_factor_min"], stack["realtime_factor_max"] = min(factors), max(factors)
    results = {"whole_stack": stack, "ray_casting": ray_casting(args.world)}
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"whole sensing stack, {args.world.name}: {stack['sim_time_s']} s simulated in "
          f"{stack['wall_time_s']} s wall = {stack['realtime_factor']}x real time, median of "
          f"{len(runs)} (range {min(factors)}-{max(factors)}x; target {TARGET:g}x: "
          f"{'met' if stack['realtime_factor'] >= TARGET else 'NOT met'}) "
          f"({stack['events']} events, {stack['events_per_wall_s']}/s wall)")
    for name, value in results["ray_casting"].items():
        print(f"  {name:28s} {value}")


if __name__ == "__main__":
    main()
