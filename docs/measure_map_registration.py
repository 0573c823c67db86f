"""Measure where the maps put the world: the registration figures of docs/maps.md and
decisions 0025 and 0033.

Two measurements, each in virtual time (seed 0, deterministic):

``drive`` (default): a scripted straight drive at ``--speed`` past a 0.6 m box and a
0.8 m ditch, once east and once west. It prints the pose's lag behind the truth (the
time shift that best lays each published pose on the simulator's track) and the shift
(east, north) that best lays the Terrain Map's heights near the obstacles on the truth.
A shift that flips sign with the direction of travel is a timing error; one that does
not is geometry (or the GPS's own error, which ``--gps-noise off`` takes out).

``--world W [--teleop]``: the world's mission (or drive script) and the maps' quality
figures of the run summary with the pose error, with or without the GPS's noise, and
how the published pose and the Terrain Map's placement of the vehicle (decision 0033)
err against the truth: RMS, and the RMS of their change over 1, 3 and 10 s.

    python docs/measure_map_registration.py --speed 1.5 [--gps-noise off]
    python docs/measure_map_registration.py --world alternating-ditches [--gps-noise off]
    python docs/measure_map_registration.py --world alternating-ditches --gps-noise vertical
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import components.gps_sokkia.emulator as gps_emulator  # noqa: E402
from afa import VirtualClock  # noqa: E402
from afa.sim.world import load_world, parse_world  # noqa: E402
from components.gps_sokkia.fake import GpsNoise  # noqa: E402
from components.map_quality import MapFrame, registration_world  # noqa: E402
from components.simulation import RaptorSimulation  # noqa: E402

RAPTOR = ROOT / "configs" / "raptor.xml"


async def _run(simulation: RaptorSimulation, seconds: float | None,
               until: Any = None) -> dict[str, Any]:
    """Run, recording the truth every physics step and every published pose."""
    truth: list[tuple[float, float, float]] = []
    poses: list[tuple[float, float, float, Any]] = []
    placed: list[tuple[float, float, float, float, float, float, float]] = []
    async with simulation:
        clock = simulation.clock
        channel = simulation.system.channel
        subscription = channel.subscribe("Raptor", "Pose", maxsize=1_000_000)
        terrain_map = simulation.system.components["TerrainService"]

        async def record() -> None:
            async for k, _ in aenumerate(clock.periodic(0.02)):
                state = simulation.state
                truth.append((clock.now(), state.east, state.north))
                pose = terrain_map.pose
                if k % 10 == 0 and pose is not None:  # the Terrain Map's placement
                    placed.append((clock.now(), state.east, state.north,
                                   float(pose.HTransform[0][3]), float(pose.HTransform[1][3]),
                                   float(terrain_map.stable[0, 3]),
                                   float(terrain_map.stable[1, 3])))

        task = asyncio.ensure_future(record())
        await simulation.system.run(seconds, until=until)
        task.cancel()
        while (event := subscription.get_nowait()) is not None:
            pose = event.body
            poses.append((pose.time.to_seconds(), float(pose.HTransform[0][3]),
                          float(pose.HTransform[1][3]), pose.initialUTM))
        terrain = terrain_map.latest_map.get()
        summary = simulation.summary()
    return {"truth": np.array(truth), "poses": poses, "terrain": terrain, "summary": summary,
            "placed": np.array(placed)}


async def aenumerate(iterator: Any) -> Any:
    k = 0
    async for item in iterator:
        yield k, item
        k += 1


def placement(simulation: RaptorSimulation, run: dict[str, Any]) -> dict[str, Any]:
    """How the published pose and the Terrain Map's placement of the vehicle (decision
    0033) err against the truth, sampled every 0.2 s: RMS, and RMS of their change over
    1, 3 and 10 s (what smears a map stitched over those times)."""
    rows = run["placed"]
    frame = MapFrame.of(simulation.world.origin, run["poses"][-1][3])
    tx, ty = frame.to_map(rows[:, 1], rows[:, 2])
    out: dict[str, Any] = {}
    for name, cols in (("pose", (3, 4)), ("placement", (5, 6))):
        error = np.column_stack([rows[:, cols[0]] - tx, rows[:, cols[1]] - ty])
        figures = {"rms_m": round(float(np.sqrt((error ** 2).sum(1).mean())), 3)}
        for lag in (1, 3, 10):
            k = int(round(lag / 0.2))
            change = error[k:] - error[:-k]
            figures[f"change_{lag}s_rms_m"] = round(
                float(np.sqrt((change ** 2).sum(1).mean())), 3)
        out[name] = figures
    return out


def pose_lag(simulation: RaptorSimulation, run: dict[str, Any]) -> tuple[float, float]:
    """Median and 90th percentile of each moving pose's lag behind the truth (s)."""
    truth, poses = run["truth"], run["poses"]
    frame = MapFrame.of(simulation.world.origin, poses[-1][3])
    tx, ty = frame.to_map(truth[:, 1], truth[:, 2])
    lags = []
    candidates = np.arange(-0.3, 0.3, 0.005)
    for stamp, x, y, _ in poses:
        moved = math.hypot(np.interp(stamp, truth[:, 0], tx) - np.interp(stamp - 0.1,
                           truth[:, 0], tx), np.interp(stamp, truth[:, 0], ty)
                           - np.interp(stamp - 0.1, truth[:, 0], ty))
        if moved < 0.02:
            continue  # standing: no lag to see
        d = np.hypot(np.interp(stamp - candidates, truth[:, 0], tx) - x,
                     np.interp(stamp - candidates, truth[:, 0], ty) - y)
        lags.append(candidates[int(np.argmin(d))])
    return float(np.median(lags)), float(np.percentile(lags, 90))


def map_shift(simulation: RaptorSimulation, terrain: Any) -> tuple[float, float, float]:
    """The (east, north) shift that best lays the Terrain Map's cell heights within a
    metre of the truth's height changes on the truth, and the mean mismatch there."""
    frame = MapFrame.of(simulation.world.origin, terrain.initialUTM)
    i, j = np.nonzero(terrain.pointCount > 0)
    g = terrain.gridsize
    east, north = frame.to_world(terrain.originX + (i + 0.5) * g,
                                 terrain.originY + (j + 0.5) * g)
    height = terrain.elevation[i, j].astype(np.float64) - frame.dz
    truth = simulation.terrain.height
    height -= float(np.median(height - truth(east, north)))  # the map's floating level
    near = np.zeros(east.shape, bool)
    for d in (-1.0, 1.0):
        near |= np.abs(truth(east + d, north) - truth(east, north)) > 0.3
        near |= np.abs(truth(east, north + d) - truth(east, north)) > 0.3
    e, n, z = east[near], north[near], height[near]
    best = (math.inf, 0.0, 0.0)
    for de in np.arange(-0.6, 0.601, 0.05):
        for dn in np.arange(-0.6, 0.601, 0.05):
            cost = float(np.mean(np.minimum(np.abs(z - truth(e - de, n - dn)), 0.3)))
            if cost < best[0]:
                best = (cost, float(de), float(dn))
    return best[1], best[2], best[0]


def drive(speed: float) -> None:
    seconds = 20.0 / speed
    for heading, start in ((90.0, -17.0), (270.0, 23.0)):
        world = parse_world(registration_world(heading, start, speed, seconds))
        simulation = RaptorSimulation.from_xml(RAPTOR, world, clock=VirtualClock(), seed=0,
                                               teleop=True)
        run = asyncio.run(_run(simulation, seconds + 2.0))
        lag, lag90 = pose_lag(simulation, run)
        de, dn, cost = map_shift(simulation, run["terrain"])
        pose = run["summary"]["pose_error"]
        print(f"heading {heading:5.1f} at {speed} m/s: pose lag behind the truth median "
              f"{lag:.3f} s (p90 {lag90:.3f} s), pose error RMS {pose['rms_position_m']} m; "
              f"map best fit {de:+.2f} m east {dn:+.2f} m north (mismatch {cost:.3f} m)")


def mission(name: str, teleop: bool) -> None:
    world = load_world(ROOT / "configs" / "worlds" / f"{name}.xml")
    simulation = RaptorSimulation.from_xml(RAPTOR, world, clock=VirtualClock(), seed=0,
                                           teleop=teleop)
    # as `afa run --sim`: until the mission is complete (or the drive script is over)
    run = asyncio.run(_run(simulation, simulation.time_limit, until=simulation.finished))
    summary = run["summary"]
    print(json.dumps({"world": name, "pose_error": summary["pose_error"],
                      "placement": placement(simulation, run),
                      "hazards": summary["maps"]["hazards"]}, indent=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=1.5)
    parser.add_argument("--world", help="run this shipped world instead of the drive")
    parser.add_argument("--teleop", action="store_true", help="the world's drive script")
    parser.add_argument("--gps-noise", choices=("on", "off", "horizontal", "vertical"),
                        default="on", help="the GPS's error: all, none, or one part only")
    args = parser.parse_args()
    noise = gps_emulator.GPS_NOISE
    if args.gps_noise == "off":
        gps_emulator.GPS_NOISE = GpsNoise(horizontal=0.0, vertical=0.0, velocity=0.0,
                                          satellite_step_rate=0.0)
    elif args.gps_noise == "horizontal":
        gps_emulator.GPS_NOISE = GpsNoise(horizontal=noise.horizontal, vertical=0.0,
                                          velocity=0.0, satellite_step_rate=0.0)
    elif args.gps_noise == "vertical":
        gps_emulator.GPS_NOISE = GpsNoise(horizontal=0.0, vertical=noise.vertical,
                                          velocity=noise.velocity,
                                          satellite_step_rate=noise.satellite_step_rate)
    if args.world:
        mission(args.world, args.teleop)
    else:
        drive(args.speed)


if __name__ == "__main__":
    main()
