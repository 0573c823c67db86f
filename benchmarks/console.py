"""What the browser console costs a simulated run.

Runs the simulated Raptor's autonomous mission under ``--fast`` (virtual time, as fast as
possible) for ``--duration`` simulated seconds, alternately without the console and with
the console serving a headless Chromium that shows every view at the default rates (a
separate process, as a user's browser would be), and prints the real-time factors, the
afa process's CPU time per simulated second, and the cost: 1 - (factor with console /
factor without). Issue 15's bound: at most 10 %.

Usage: ``python benchmarks/console.py [--duration S] [--trials N] [--world NAME]
[--chromium PATH] [--json]``. Figures are medians of interleaved trials; the machine's
other load moves them, so read them as orders of magnitude (``docs/console.md``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import resource
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from afa import VirtualClock  # noqa: E402
from afa.console import Console, ConsoleOptions  # noqa: E402
from components.simulation import RaptorSimulation  # noqa: E402

CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync",
                  "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                  "--window-size=1600,1400"]
BOUND = 0.10
#: A client that takes every kind at the default rates and renders nothing (``--client
#: ws``): the console's own cost, without a browser competing for the CPU.
WS_CLIENT = """
import asyncio, json, struct, sys
import aiohttp
async def main(url):
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url + "ws", headers={"Origin": url.rstrip("/")}) as ws:
            data = await ws.receive_bytes()
            hello = json.loads(data[16:16 + struct.unpack_from("<I", data, 4)[0]])
            await ws.send_str(json.dumps({"op": "subscribe",
                                          "kinds": {k: None for k in hello["policies"]}}))
            async for _ in ws:
                pass
asyncio.run(main(sys.argv[1]))
"""


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _tree_cpu(root: int) -> float:
    """CPU seconds (user + system) of process ``root`` and its descendants (Linux /proc)."""
    parents: dict[int, int] = {}
    times: dict[int, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parents[int(entry.name)] = int(fields[1])
        times[int(entry.name)] = (int(fields[11]) + int(fields[12])) / tick
    total, stack = 0.0, [root]
    while stack:
        pid = stack.pop()
        total += times.get(pid, 0.0)
        stack.extend(child for child, parent in parents.items() if parent == pid)
    return total


async def trial(world: Path, duration: float, with_console: bool,
                chromium: str | None, client: str = "chromium") -> dict[str, Any]:
    simulation = RaptorSimulation.from_xml(ROOT / "configs" / "raptor.xml", world,
                                           clock=VirtualClock(), seed=0)
    console = Console(simulation.system, ConsoleOptions(port=0)) if with_console else None
    browser = None
    profile = tempfile.mkdtemp(prefix="afa-bench-chromium-")
    try:
        if console is not None:
            await console.start()
            command = None
            if client == "ws":
                command = [sys.executable, "-c", WS_CLIENT, console.url]
            elif client == "chromium" and chromium is not None:
                command = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", console.url]
            if command is not None:
                browser = await asyncio.create_subprocess_exec(
                    *command, stdout=asyncio.subprocess.DEVNULL,
                    stderr=asyncio.subprocess.DEVNULL)
                for _ in range(300):  # until the page shows its views
                    if any(len(s.kinds) > 3 for s in console.hub.sessions):
                        break
                    await asyncio.sleep(0.1)
                else:
                    raise RuntimeError("the browser did not connect to the console")
        wall0, cpu0 = time.perf_counter(), _cpu()
        browser0 = _tree_cpu(browser.pid) if browser is not None else 0.0
        async with simulation:
            await simulation.system.run(duration)
            sim_time = simulation.sim_time
        wall, cpu = time.perf_counter() - wall0, _cpu() - cpu0
        browser_cpu = _tree_cpu(browser.pid) - browser0 if browser is not None else None
        result: dict[str, Any] = {"console": with_console, "sim_time_s": round(sim_time, 2),
                                  "wall_time_s": round(wall, 3),
                                  "realtime_factor": round(sim_time / wall, 3),
                                  "cpu_s_per_sim_s": round(cpu / sim_time, 4)}
        if console is not None:
            sessions = [s.statistics() for s in console.hub.sessions]
            shares = console.hub.profiler.snapshot()
            result["console_loop_s"] = round(shares.get("console", 0.0), 3)
            result["messages"] = sum(s["messages"] for s in sessions)
            result["megabytes"] = round(sum(s["bytes"] for s in sessions) / 1e6, 2)
            if browser_cpu is not None:
                result["browser_cpu_share"] = round(browser_cpu / wall, 3)
        return result
    finally:
        if browser is not None:
            if browser.returncode is None:
                browser.terminate()
            await browser.wait()
        if console is not None:
            await console.stop()
        shutil.rmtree(profile, ignore_errors=True)


async def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--world", default="rock-field")
    parser.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    parser.add_argument("--client", choices=["chromium", "ws", "none"], default="chromium",
                        help="what watches the console: headless Chromium showing every view "
                             "(default), a WebSocket client taking every kind and rendering "
                             "nothing, or nobody")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    world = ROOT / "configs" / "worlds" / f"{args.world}.xml"
    chromium = args.chromium if os.path.exists(args.chromium) else None
    runs: dict[bool, list[dict[str, Any]]] = {False: [], True: []}
    for _ in range(args.trials):
        for with_console in (False, True):
            runs[with_console].append(await trial(world, args.duration, with_console, chromium,
                                                  args.client))
    factor = {k: statistics.median(r["realtime_factor"] for r in v) for k, v in runs.items()}
    cpu = {k: statistics.median(r["cpu_s_per_sim_s"] for r in v) for k, v in runs.items()}
    cost = 1.0 - factor[True] / factor[False]
    browser = {"chromium": chromium or "none (not found)", "ws": "WebSocket client (no rendering)",
               "none": "none"}[args.client]
    report = {"world": args.world, "duration_s": args.duration, "trials": args.trials,
              "browser": browser,
              "realtime_factor_without": factor[False], "realtime_factor_with": factor[True],
              "cpu_s_per_sim_s_without": cpu[False], "cpu_s_per_sim_s_with": cpu[True],
              "cost": round(cost, 4), "bound": BOUND, "runs": runs}
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"{args.world}, {args.duration:g} s simulated, {args.trials} interleaved trials, "
          f"browser: {report['browser']}")
    for with_console in (False, True):
        for run in runs[with_console]:
            extra = (f"  console {run['console_loop_s']:.2f} s of loop, {run['messages']} msgs, "
                     f"{run['megabytes']} MB, browser {run.get('browser_cpu_share', 0) * 100:.0f} %"
                     " of a core" if with_console else "")
            label = "with" if with_console else "without"
            print(f"  {label:7s} console: x{run['realtime_factor']:6.2f}"
                  f"  cpu {run['cpu_s_per_sim_s']:.3f} s/sim s{extra}")
    print(f"median real-time factor: x{factor[False]:.2f} without, x{factor[True]:.2f} with; "
          f"cost {cost * 100:.1f} % of the run's speed (bound {BOUND * 100:.0f} %); "
          f"CPU {cpu[False]:.3f} -> {cpu[True]:.3f} s per simulated second")


if __name__ == "__main__":
    asyncio.run(main())
