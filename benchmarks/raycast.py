"""Simulated-world costs: laser scans, stereo depth frames, vehicle steps, terrain builds.

Scenes come from ``configs/worlds/open-field.xml`` (200 m x 200 m at 0.1 m, slope and
roughness, obstacles): a SICK scan line of 361 beams (180 deg at 0.5 deg) from the
Raptor's laser mount, tilted 8 deg down, and a 320 x 240 depth image from the camera
mount. Figures are wall-clock medians of ``--repeat`` runs.

Usage: ``python benchmarks/raycast.py [--repeat R] [--world FILE]``
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

from afa.sim import Terrain, Vehicle, depth_image, laser_scan, load_world, run_drive  # noqa: E402


def median_seconds(fn: Callable[[], object], repeat: int) -> float:
    fn()  # warm caches (block maxima, footprints)
    samples = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def rot_y(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=50)
    parser.add_argument("--world", type=Path, default=Path(__file__).resolve().parent.parent
                        / "configs" / "worlds" / "open-field.xml")
    args = parser.parse_args()

    world = load_world(args.world)
    start = time.perf_counter()
    terrain = Terrain.from_spec(world.terrain, world.obstacles)
    build = time.perf_counter() - start
    print(f"terrain {terrain.nx} x {terrain.ny} samples: built in {build * 1e3:.0f} ms")

    vehicle = Vehicle.from_world(world, terrain)
    body = vehicle.state.rotation()
    laser_origin = vehicle.state.position + body @ np.array([2.20, 0.35, 1.555])
    laser_rotation = body @ rot_y(math.radians(8))
    bearings = np.radians(np.arange(-90.0, 90.25, 0.5))
    for max_range in (30.0, 80.0):
        t = median_seconds(lambda r=max_range: laser_scan(terrain, laser_origin, laser_rotation,
                                                          bearings, r), args.repeat)
        print(f"laser scan, 361 beams, max range {max_range:.0f} m: {t * 1e6:8.0f} us")

    camera_origin = vehicle.state.position + body @ np.array([2.05, 0.0, 1.45])
    optical = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float)  # body-from-optical
    camera_rotation = body @ rot_y(math.radians(10)) @ optical
    for max_range in (20.0, 40.0):
        t = median_seconds(lambda r=max_range: depth_image(terrain, camera_origin,
                                                           camera_rotation, 320, 240, 66.0, r),
                           max(3, args.repeat // 10))
        print(f"depth image 320 x 240, max range {max_range:.0f} m: {t * 1e3:8.1f} ms")

    start = time.perf_counter()
    result = run_drive(world, terrain, dt=0.05)
    elapsed = time.perf_counter() - start
    simulated = result.states[-1].time
    print(f"drive script: {len(result.states) - 1} steps of 50 ms ({simulated:.0f} s simulated) "
          f"in {elapsed * 1e3:.0f} ms: {(len(result.states) - 1) / elapsed:,.0f} steps/s, "
          f"{simulated / elapsed:,.0f}x real time")


if __name__ == "__main__":
    main()
