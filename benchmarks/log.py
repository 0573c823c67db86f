"""Record and replay figures (issue 13), in one run, printed and never asserted.

- recording cost: the same simulated run (teleop drive, every sensor) with and without
  the recorder, interleaved trials, medians; target: at most 20 % slower; beside it the
  same figure for the autonomous stack ``afa run --sim --record`` runs (the mission, with
  maps and planners);
- replay of a two-minute simulated recording at ``--speed max`` (virtual time, ModelServer
  re-run on the recorded GPS and IMU); target: at least 20x real time;
- seeking to the middle of a ten-minute recording (the latest value of every topic
  republished, the feeder restarted); target: under 100 ms;
- file size per simulated minute: zstd, lz4 and no compression.

Usage: ``python benchmarks/log.py [--trials N] [--trial-seconds S] [--long S]
[--recording-only] [--stacks teleop,autonomous] [--json]``
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from afa import VirtualClock  # noqa: E402
from afa.log import Player, Recorder  # noqa: E402
from components.simulation import RaptorSimulation  # noqa: E402

CONFIG = ROOT / "configs" / "raptor.xml"
#: The simulated runs the recording cost is measured on (simulate_timed's ``teleop``).
STACKS = ("teleop", "autonomous")


async def simulate(seconds: float, record: Path | None = None, **options: Any) -> float:
    """Wall seconds of a simulated run (optionally recorded)."""
    return (await simulate_timed(seconds, record, **options))[0]


async def simulate_timed(seconds: float, record: Path | None = None, *, teleop: bool = True,
                         **options: Any) -> tuple[float, float, float]:
    """(wall, CPU, loop-thread CPU) seconds of a simulated run (optionally recorded); CPU
    time is the figure to trust on a shared machine. The process's CPU time counts the
    recorder's compression thread; the loop thread's is what the simulation waited
    for. ``teleop``: the sensing stack driven by a script (every sensor, no planners);
    False: the autonomous mission of ``afa run --sim``."""
    clock = VirtualClock()
    sim = RaptorSimulation.from_xml(CONFIG, clock=clock, seed=1, teleop=teleop)
    recorder = Recorder(record, **options).attach(sim.system) if record else None
    start, cpu, loop = time.perf_counter(), time.process_time(), time.thread_time()
    async with sim:
        await sim.system.run(seconds)
        if recorder is not None:
            await recorder.close()
    return (time.perf_counter() - start, time.process_time() - cpu,
            time.thread_time() - loop)


async def replay(path: Path) -> tuple[float, float, float]:
    """(wall seconds, recorded seconds, CPU seconds) of a replay at max speed, opening
    included."""
    start, cpu = time.perf_counter(), time.process_time()
    player = Player(path, CONFIG, speed=None)
    async with player:
        await player.run()
    return time.perf_counter() - start, player.elapsed, time.process_time() - cpu


async def seek(path: Path, repeat: int) -> tuple[float, list[float]]:
    """(open seconds, seek seconds each) to points around the middle."""
    start = time.perf_counter()
    player = Player(path, CONFIG, speed=None, paused=True)
    opened = time.perf_counter() - start
    times = []
    async with player:
        middle = player.reader.duration / 2
        for k in range(repeat):
            target = middle + (k - repeat // 2) * 7.0
            t = time.perf_counter()
            await player.seek(target)
            times.append(time.perf_counter() - t)
    return opened, times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--trial-seconds", type=float, default=60.0)
    parser.add_argument("--replay-seconds", type=float, default=120.0)
    parser.add_argument("--long", type=float, default=600.0, help="the seek recording (s)")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--recording-only", action="store_true",
                        help="only the recording cost (skip sizes, replay and seek)")
    parser.add_argument("--stacks", default="teleop,autonomous",
                        help="the runs whose recording cost is measured, of "
                             f"{', '.join(STACKS)} (default: both)")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    out: dict[str, object] = {}
    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(folder)
        stacks = [name.strip() for name in args.stacks.split(",") if name.strip()]
        for stack in stacks:
            if stack not in STACKS:
                parser.error(f"unknown stack {stack!r}; use {', '.join(STACKS)}")
        runs: dict[str, tuple[list[Any], list[Any]]] = {stack: ([], []) for stack in stacks}
        for trial in range(args.trials):  # interleaved: load on the machine hits both
            for stack in stacks:
                plain, recorded = runs[stack]
                teleop = stack == "teleop"
                plain.append(asyncio.run(simulate_timed(args.trial_seconds, teleop=teleop)))
                recorded.append(asyncio.run(simulate_timed(
                    args.trial_seconds, tmp / f"{stack}{trial}.mcap", teleop=teleop)))
        for stack in stacks:
            key = "recording" if stack == "teleop" else f"recording_{stack}"
            out[key] = _cost(args.trial_seconds, *runs[stack])
        if args.recording_only:
            _print(out, args.json)
            return
        sizes = {}
        for compression in ("zstd", "lz4", "none"):
            path = tmp / f"size-{compression}.mcap"
            asyncio.run(simulate(args.trial_seconds, path, compression=compression))
            sizes[compression] = round(path.stat().st_size / 1e6 * 60 / args.trial_seconds, 1)
        path = tmp / "size-events.mcap"
        asyncio.run(simulate(args.trial_seconds, path, viewer=False))
        sizes["zstd_without_viewer"] = round(path.stat().st_size / 1e6 * 60
                                             / args.trial_seconds, 1)
        out["mb_per_sim_minute"] = sizes

        two = tmp / "two-minutes.mcap"
        asyncio.run(simulate(args.replay_seconds, two))
        walls = [asyncio.run(replay(two)) for _ in range(args.trials)]
        wall = statistics.median(w for w, _, _ in walls)
        cpu = statistics.median(c for _, _, c in walls)
        out["replay_max"] = {"recorded_s": round(walls[0][1], 1), "wall_s": round(wall, 3),
                             "times_real_time": round(walls[0][1] / wall, 1),
                             "cpu_s": round(cpu, 3),
                             "times_real_time_cpu": round(walls[0][1] / cpu, 1)}

        ten = tmp / "ten-minutes.mcap"
        asyncio.run(simulate(args.long, ten))
        opened, seeks = asyncio.run(seek(ten, 5))
        out["seek_middle"] = {"recording_s": args.long, "file_mb": round(ten.stat().st_size / 1e6),
                              "open_ms": round(1000 * opened, 1),
                              "seek_ms_median": round(1000 * statistics.median(seeks), 1),
                              "seek_ms_max": round(1000 * max(seeks), 1)}
    _print(out, args.json)


def _cost(seconds: float, plain: list[tuple[float, float, float]],
          recorded: list[tuple[float, float, float]]) -> dict[str, Any]:
    """The recording's cost from interleaved (wall, CPU, loop CPU) trials: medians."""
    base, rec = (statistics.median(w for w, _, _ in plain),
                 statistics.median(w for w, _, _ in recorded))
    base_cpu, rec_cpu = (statistics.median(c for _, c, _ in plain),
                         statistics.median(c for _, c, _ in recorded))
    base_loop, rec_loop = (statistics.median(t for _, _, t in plain),
                           statistics.median(t for _, _, t in recorded))
    return {
        "sim_seconds": seconds, "wall_without_s": round(base, 3),
        "wall_with_s": round(rec, 3), "speed_without": round(seconds / base, 2),
        "speed_with": round(seconds / rec, 2),
        "cost_percent": round(100 * (1 - base / rec), 1),
        "cpu_without_s": round(base_cpu, 3), "cpu_with_s": round(rec_cpu, 3),
        "cost_percent_cpu": round(100 * (1 - base_cpu / rec_cpu), 1),
        "loop_cpu_without_s": round(base_loop, 3), "loop_cpu_with_s": round(rec_loop, 3),
        "cost_percent_loop_cpu": round(100 * (1 - base_loop / rec_loop), 1),
        "trials_without": [round(w, 2) for w, _, _ in plain],
        "trials_with": [round(w, 2) for w, _, _ in recorded],
        "cpu_trials_without": [round(c, 2) for _, c, _ in plain],
        "cpu_trials_with": [round(c, 2) for _, c, _ in recorded]}


def _print(out: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print(json.dumps(out, indent=2))
        return
    for key, label in (("recording", "teleop sensing run"),
                       ("recording_autonomous", "autonomous mission")):
        r = out.get(key)
        if r is None:
            continue
        print(f"recording ({label}): {r['sim_seconds']:.0f} s simulated in "
              f"{r['wall_without_s']} s without, {r['wall_with_s']} s with the recorder "
              f"(x{r['speed_without']} -> x{r['speed_with']} real time): costs "
              f"{r['cost_percent']} % by wall time, {r['cost_percent_cpu']} % by CPU time "
              f"({r['cpu_without_s']} s -> {r['cpu_with_s']} s), "
              f"{r['cost_percent_loop_cpu']} % by the event loop thread's CPU time "
              f"({r['loop_cpu_without_s']} s -> {r['loop_cpu_with_s']} s) (target <= 20 %)")
    if "mb_per_sim_minute" not in out:
        return
    print(f"size per simulated minute (MB): {out['mb_per_sim_minute']}")
    p = out["replay_max"]
    print(f"replay --speed max of {p['recorded_s']} s: {p['wall_s']} s wall, "
          f"x{p['times_real_time']} real time; {p['cpu_s']} s of CPU, "
          f"x{p['times_real_time_cpu']} (target >= 20)")
    s = out["seek_middle"]
    print(f"seek to the middle of a {s['recording_s']:.0f} s recording ({s['file_mb']} MB): "
          f"median {s['seek_ms_median']} ms, max {s['seek_ms_max']} ms (target < 100 ms); "
          f"open {s['open_ms']} ms")


if __name__ == "__main__":
    main()
