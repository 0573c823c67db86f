"""Simulation speed: how many times faster than real time the simulated Raptor runs.

The reference workload is ``configs/raptor.xml`` on one world, seed and duration under
``--fast`` (virtual time), in two stacks:

- **sensing**: the drivers and ModelServer only (NodLaser x2, Stereo, Imu, GpsSokkia,
  WheelOdometry, VehicleControl, ModelServer: the Launcher entries of those types),
  with the emulators on the real wire protocols, the world's physics and the run
  digest; the vehicle follows the world's drive script (tele-operation);
- **autonomous**: every configured component (maps, planners, arbiter), the
  simulation playing the control station as ``afa run --sim`` does.

(A third stack, ``maps``, the sensing stack with the three maps, is run by
``benchmarks/maps.py --section stack`` through this script's runner.)

Each run is a fresh interpreter (``--one``), so no run inherits another's caches; the
two stacks alternate (sensing, autonomous, sensing, ...) and the medians of the trials
are printed: the real-time factor by wall time and by CPU time of the process (the
second is less disturbed by other work on the machine). Start-up (configuration,
imports) is not counted. ``--components`` adds one sampled run of the autonomous stack
that splits its CPU time between the components, the emulators, the simulation and the
framework (ms of CPU per simulated second). ``--rays`` adds the cost of the ray casting
behind one laser scan line and one stereo frame. Every run also times a fixed
*yardstick* workload (interpreted Python, small numpy operations, hashing) in its own
interpreter right after the simulation, and the medians are printed beside the factors:
the machine's speed at the time, so that figures from different days compare.

The targets (issues): sensing >= 20x, autonomous >= 10x real time on a 2-core
machine. This script prints figures; it never asserts them.

Usage::

    python benchmarks/sim.py [--world rock-field] [--seed 0] [--duration 60]
                             [--trials 3] [--components] [--rays] [--json]
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import json
import logging
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

#: The Launcher types of the sensing stack: the device drivers and ModelServer.
SENSING_TYPES = ("NodLaser", "Stereo", "Imu", "GpsSokkia", "WheelOdometry", "VehicleControl",
                 "ModelServer")
#: The Launcher types of each stack a run may use (None: every configured component).
#: ``maps`` is the sensing stack with the three maps (benchmarks/maps.py compares the two).
STACK_TYPES: dict[str, tuple[str, ...] | None] = {
    "sensing": SENSING_TYPES,
    "maps": (*SENSING_TYPES, "TerrainMap", "TraversabilityMap", "GlobalMap"),
    "autonomous": None,
}
TARGETS = {"sensing": 20.0, "autonomous": 10.0}
CONFIG = ROOT / "configs" / "raptor.xml"


def world_path(name: str) -> Path:
    path = Path(name)
    return path if path.suffix == ".xml" else ROOT / "configs" / "worlds" / f"{name}.xml"


def stack_components(types: tuple[str, ...]) -> list[str]:
    """The names of the enabled Launcher entries of these types."""
    from afa.config.loader import load_configuration

    entries = load_configuration(CONFIG).launcher.Components
    return [e.Name for e in entries if e.Enabled and e.Type in types]


# -- one run (in its own interpreter) -------------------------------------------------------


async def _run(stack: str, world: Path, seed: int, duration: float,
               sampler: Sampler | None) -> dict[str, Any]:
    from afa import VirtualClock
    from components.simulation import RaptorSimulation

    options: dict[str, Any] = {}
    types = STACK_TYPES[stack]
    if types is not None:  # a partial stack follows the drive script
        options["only"] = stack_components(types)
    simulation = RaptorSimulation.from_xml(CONFIG, world, clock=VirtualClock(), seed=seed,
                                           teleop=types is not None, **options)
    wall, cpu = time.perf_counter(), time.process_time()
    if sampler is not None:
        sampler.start()
    async with simulation:
        await simulation.system.run(duration)
        events = sum(simulation.system.statistics()["events"].values())
    if sampler is not None:
        sampler.stop()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    sim_time = simulation.sim_time
    result: dict[str, Any] = {
        "stack": stack, "components": len(simulation.system.components),
        "sim_time_s": round(sim_time, 3), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
        "realtime_factor": round(sim_time / wall, 2),
        "cpu_realtime_factor": round(sim_time / cpu, 2), "events": events,
        "event_digest": simulation.summary()["event_digest"]}
    if sampler is not None:
        result["owners_ms_per_sim_s"] = {
            owner: round(1e3 * cpu * share / sim_time, 2)
            for owner, share in sampler.shares().most_common()}
    return result


def one(stack: str, world: Path, seed: int, duration: float, components: bool) -> None:
    """A single run, its figures as one JSON line on stdout."""
    logging.disable(logging.WARNING)  # start-up notes and the run's own warnings
    sampler = Sampler() if components else None
    result = asyncio.run(_run(stack, world, seed, duration, sampler))
    result["yardstick_ms"] = yardstick()
    print(json.dumps(result))


# -- the yardstick: a fixed workload timed in every run ----------------------------------------


def yardstick(repeat: int = 5) -> float:
    """CPU ms of a fixed workload shaped like the simulator's (interpreted Python, small
    numpy operations, hashing; no ray casting, no I/O), the median of ``repeat``, timed
    in the same interpreter right after the run: how fast this machine was then. A run's
    real-time factor times its yardstick is steadier across days and machine load than
    either alone (figures from different days compare through it)."""
    import hashlib

    import numpy as np

    rng = np.random.default_rng(0)
    small = rng.normal(size=(361, 3))
    blob = rng.bytes(1 << 16)
    samples = []
    for _ in range(repeat):
        t0 = time.process_time()
        total = 0
        for i in range(240_000):  # interpreted arithmetic
            total += (i * 7) % 13
        for _ in range(1_600):  # small array operations
            lengths = np.sqrt(np.einsum("ij,ij->i", small, small))
            total += int(np.count_nonzero(lengths > 1.0))
        for _ in range(160):
            hashlib.sha256(blob).digest()
        samples.append(time.process_time() - t0)
    return round(statistics.median(samples) * 1e3, 2)


# -- where the CPU time goes ------------------------------------------------------------------


class Sampler:
    """A statistical CPU profile by owner: every ``interval`` seconds of the process's
    CPU time (``SIGPROF``) the signal handler, which Python runs in the main thread
    between bytecodes, charges one sample to the owner of the innermost frame that has
    one: a component (by name; a driver's reactor counts as its component), a device
    emulator (by class), the simulation (physics, drive script or mission, digest and
    summary), or else the framework (event loop, virtual clock, channel, polls)."""

    def __init__(self, interval: float = 0.002) -> None:
        self.interval = interval
        self.samples: collections.Counter[str] = collections.Counter()

    def start(self) -> None:
        import signal

        from afa.component import Component
        from afa.fake import FakeDevice
        from afa.reactor import Reactor
        from components.simulation import RaptorSimulation

        self._kinds = (Component, Reactor, FakeDevice, RaptorSimulation)
        signal.signal(signal.SIGPROF, self._sample)
        signal.setitimer(signal.ITIMER_PROF, self.interval, self.interval)

    def stop(self) -> None:
        import signal

        signal.setitimer(signal.ITIMER_PROF, 0.0, 0.0)
        signal.signal(signal.SIGPROF, signal.SIG_DFL)

    def shares(self) -> collections.Counter[str]:
        total = sum(self.samples.values()) or 1
        return collections.Counter({k: v / total for k, v in self.samples.items()})

    def _sample(self, signum: int, frame: Any) -> None:
        self.samples[self._owner(frame)] += 1

    def _owner(self, frame: Any) -> str:
        component, reactor, fake, simulation = self._kinds
        while frame is not None:
            code = frame.f_code
            if code.co_argcount and code.co_varnames[0] == "self":
                obj = frame.f_locals.get("self")
                if isinstance(obj, (component, reactor)):
                    # (a sample can land in __init__, before the name is set)
                    return str(getattr(obj, "name", type(obj).__name__))
                if isinstance(obj, fake):
                    return f"emulator {type(obj).__name__}"
                if isinstance(obj, simulation):
                    return "simulation"
            frame = frame.f_back
        return "framework"


# -- ray casting --------------------------------------------------------------------------------


def ray_casting(world: Path, repeat: int = 50) -> dict[str, float]:
    import numpy as np

    from afa import VirtualClock
    from afa.sim.raycast import cast_rays, depth_image
    from components.simulation import RaptorSimulation
    from components.stereo.emulator import STEREO_SUBSAMPLE

    simulation = RaptorSimulation(world, VirtualClock(), seed=0)
    pose = simulation.frame_pose("FrontNoddingSICKLeft:AxleCenterFreeEnd")
    bearings = np.deg2rad(np.arange(361) * 0.5)
    nod = math.radians(-25.0)
    local = np.stack([np.sin(bearings) * math.cos(nod), -np.cos(bearings),
                      np.sin(bearings) * math.sin(nod)], axis=1)
    directions = local @ pose[:3, :3].T

    def timed(fn: Any, n: int) -> float:
        samples = []
        for _ in range(n):
            t0 = time.process_time()
            fn()
            samples.append(time.process_time() - t0)
        return statistics.median(samples)

    scan = timed(lambda: cast_rays(simulation.terrain, pose[:3, 3], directions, 8.183), repeat)
    camera = simulation.frame_pose("Digiclops:ImagePlane")
    w, h = 320 // STEREO_SUBSAMPLE, 240 // STEREO_SUBSAMPLE
    coarse = timed(lambda: depth_image(simulation.terrain, camera[:3, 3], camera[:3, :3], w, h,
                                       66.0, 10.0), 20)
    return {"laser_scan_361_rays_ms": round(scan * 1e3, 3),
            f"stereo_frame_{w}x{h}_ms": round(coarse * 1e3, 2)}


# -- the driver ---------------------------------------------------------------------------------


def spawn(stack: str, args: argparse.Namespace, components: bool = False) -> dict[str, Any]:
    command = [sys.executable, str(Path(__file__).resolve()), "--one", stack,
               "--world", str(world_path(args.world)), "--seed", str(args.seed),
               "--duration", str(args.duration)]
    if components:
        command.append("--components")
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    if done.returncode != 0:
        raise SystemExit(f"benchmark run failed ({' '.join(command)}):\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    def med(key: str) -> float:
        return round(statistics.median(r[key] for r in runs), 2)

    return {"sim_time_s": runs[0]["sim_time_s"], "components": runs[0]["components"],
            "events": runs[0]["events"], "trials": len(runs),
            "realtime_factor": med("realtime_factor"),
            "realtime_factor_range": [min(r["realtime_factor"] for r in runs),
                                      max(r["realtime_factor"] for r in runs)],
            "cpu_realtime_factor": med("cpu_realtime_factor"),
            "cpu_realtime_factor_range": [min(r["cpu_realtime_factor"] for r in runs),
                                          max(r["cpu_realtime_factor"] for r in runs)],
            "wall_s": med("wall_s"), "cpu_s": med("cpu_s"), "yardstick_ms": med("yardstick_ms"),
            "event_digests": sorted({r["event_digest"] for r in runs})}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="rock-field",
                        help="a shipped world's name or a world file (default rock-field)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=60.0,
                        help="simulated seconds per run (default 60)")
    parser.add_argument("--trials", type=int, default=3,
                        help="runs of each stack, interleaved; medians reported (default 3)")
    parser.add_argument("--components", action="store_true",
                        help="one more, sampled run of the autonomous stack: CPU per owner")
    parser.add_argument("--rays", action="store_true", help="ray casting costs too")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--one", choices=tuple(STACK_TYPES), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        one(args.one, world_path(args.world), args.seed, args.duration, args.components)
        return

    runs: dict[str, list[dict[str, Any]]] = {"sensing": [], "autonomous": []}
    for _ in range(args.trials):
        for stack in runs:
            runs[stack].append(spawn(stack, args))
    results: dict[str, Any] = {
        "workload": {"config": "configs/raptor.xml", "world": args.world, "seed": args.seed,
                     "duration_s": args.duration, "cpus": os.cpu_count(),
                     "load_average": [round(x, 2) for x in os.getloadavg()]},
        **{stack: summarise(r) for stack, r in runs.items()}}
    if args.components:
        results["autonomous_components"] = spawn("autonomous", args, components=True)
    if args.rays:
        results["ray_casting"] = ray_casting(world_path(args.world))
    if args.json:
        print(json.dumps(results, indent=2))
        return

    w = results["workload"]
    print(f"{w['config']}, world {w['world']}, seed {w['seed']}, {w['duration_s']:g} s "
          f"simulated per run, {args.trials} interleaved trials per stack, medians "
          f"({w['cpus']} CPUs, load average {w['load_average'][0]:g} at the end)")
    for stack in ("sensing", "autonomous"):
        r = results[stack]
        lo, hi = r["realtime_factor_range"]
        clo, chi = r["cpu_realtime_factor_range"]
        print(f"  {stack:10s} ({r['components']:2d} components, {r['events']} events): "
              f"{r['realtime_factor']:6.2f}x real time by wall clock ({lo}-{hi}), "
              f"{r['cpu_realtime_factor']:6.2f}x by CPU time ({clo}-{chi}); "
              f"target {TARGETS[stack]:g}x; yardstick {r['yardstick_ms']:g} ms")
        if len(r["event_digests"]) != 1:
            print(f"    the runs' event digests differ: {r['event_digests']}")
    if args.components:
        r = results["autonomous_components"]
        print(f"  where the autonomous stack's CPU goes (one sampled run, "
              f"{r['cpu_realtime_factor']}x by CPU time), ms of CPU per simulated second:")
        for owner, ms in r["owners_ms_per_sim_s"].items():
            print(f"    {owner:28s} {ms:7.2f}")
    if args.rays:
        for name, value in results["ray_casting"].items():
            print(f"  {name:28s} {value}")


if __name__ == "__main__":
    main()
