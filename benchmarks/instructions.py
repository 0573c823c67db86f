"""Instructions per simulated second of the reference workload, counted by valgrind.

CPU time on a shared 2-core VM spreads by +-10-15 % between runs of one commit; the
number of instructions a run executes does not depend on the load. This script runs one
stack of ``benchmarks/sim.py``'s reference workload (configs/raptor.xml on rock-field,
seed 0) under ``valgrind --tool=callgrind`` and counts exactly the instructions of the
simulated seconds after a warm-up: the run zeroes callgrind's counters once the warm-up
has been simulated and dumps them once the measured seconds have (callgrind's client
requests, through a three-line C shim compiled here with ``cc`` against
``valgrind/callgrind.h``). Start-up, imports, numba's cache loading and the warm-up are
not counted, so two commits compare on one run each (the earlier method, cachegrind
totals of two durations subtracted, carried start-up differences of +-40 M instructions
between runs). The run has one OpenBLAS thread and a fixed hash seed (below): with
OpenBLAS's spinning worker threads the counts of one commit differed by up to 5 %.

Needs valgrind (with its headers: Debian's ``valgrind`` package) and a C compiler. A run
takes a few minutes (valgrind is ~50 times slower than the program). Prints the count,
the count per simulated second and the run's event digest (of the warm-up and the
measured seconds), as JSON with ``--json``.

``--record`` attaches the recorder (``afa run --record``: every event, poll and viewer
channel, zstd in its worker thread, whose instructions count too) before the start, so
the difference of two runs is the recording's cost in instructions, whatever the load
(decision 0034).

Usage::

    python benchmarks/instructions.py [--stack sensing|autonomous] [--warm 2] [--duration 10]
                                      [--record]
"""

from __future__ import annotations

import argparse
import asyncio
import ctypes
import json
import logging
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SHIM = """#include <valgrind/callgrind.h>
void afa_cg_zero(void) { CALLGRIND_ZERO_STATS; }
void afa_cg_dump(void) { CALLGRIND_DUMP_STATS_AT("measured"); }
"""


def build_shim(directory: Path) -> Path:
    source, library = directory / "shim.c", directory / "libafacg.so"
    source.write_text(SHIM)
    subprocess.run(["cc", "-O1", "-shared", "-fPIC", "-o", str(library), str(source)],
                   check=True)
    return library


async def _inner(stack: str, warm: float, duration: float, shim: Path,
                 record: Path | None = None) -> dict[str, Any]:
    """The run under valgrind: warm up, zero the counters, run, dump them (``record``:
    recorded into that file)."""
    import benchmarks.sim as sim_bench
    from afa import VirtualClock
    from components.simulation import RaptorSimulation

    library = ctypes.CDLL(str(shim))
    options: dict[str, Any] = {}
    types = sim_bench.STACK_TYPES[stack]
    if types is not None:
        options["only"] = sim_bench.stack_components(types)
    simulation = RaptorSimulation.from_xml(sim_bench.CONFIG, sim_bench.world_path("rock-field"),
                                           clock=VirtualClock(), seed=0,
                                           teleop=types is not None, **options)
    recorder = None
    if record is not None:
        from afa.log import Recorder

        recorder = Recorder(record).attach(simulation.system)
    async with simulation:
        await simulation.system.run(warm)
        library.afa_cg_zero()
        await simulation.system.run(duration)
        if recorder is not None:
            await recorder.close()  # what the measured seconds queued, compressed
        library.afa_cg_dump()
    return {"event_digest": simulation.summary()["event_digest"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stack", choices=("sensing", "autonomous"), default="sensing")
    parser.add_argument("--warm", type=float, default=2.0,
                        help="simulated seconds before counting (default 2)")
    parser.add_argument("--duration", type=float, default=10.0,
                        help="simulated seconds counted (default 10)")
    parser.add_argument("--record", action="store_true",
                        help="record the run (the recorder's instructions counted too)")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--inner", help=argparse.SUPPRESS)  # the shim's path, under valgrind
    parser.add_argument("--inner-record", help=argparse.SUPPRESS)  # the file, under valgrind
    args = parser.parse_args()
    if args.inner:
        logging.disable(logging.WARNING)
        record = Path(args.inner_record) if args.inner_record else None
        print(json.dumps(asyncio.run(_inner(args.stack, args.warm, args.duration,
                                            Path(args.inner), record))))
        return

    with tempfile.TemporaryDirectory(prefix="afa-instructions-") as tmp:
        directory = Path(tmp)
        shim = build_shim(directory)
        out = directory / "callgrind.out"
        command = ["valgrind", "--tool=callgrind", "--cache-sim=no", "--branch-sim=no",
                   f"--callgrind-out-file={out}", sys.executable, str(Path(__file__).resolve()),
                   "--stack", args.stack, "--warm", str(args.warm), "--duration",
                   str(args.duration), "--inner", str(shim)]
        if args.record:
            command += ["--inner-record", str(directory / "recorded.mcap")]
        # OpenBLAS's worker threads spin while they wait, for as long as the (valgrind-
        # slowed, load-dependent) wall clock says: one thread makes the count repeatable.
        # A fixed hash seed makes dict and set layouts repeatable too.
        env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1",
               "PYTHONHASHSEED": "0"}
        done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, env=env)
        if done.returncode != 0:
            raise SystemExit(f"run failed ({' '.join(command)}):\n{done.stderr[-3000:]}")
        dumps = sorted(directory.glob("callgrind.out.*"))  # the dump; .out is the rest
        text = dumps[0].read_text(errors="replace") if dumps else ""
        found = re.search(r"^(?:summary|totals):\s+(\d+)", text, re.MULTILINE)
        if found is None:
            raise SystemExit(f"no counts dumped (valgrind said:\n{done.stderr[-3000:]})")
        instructions = int(found.group(1))
    result = {"stack": args.stack, "world": "rock-field", "seed": 0, "record": args.record,
              "warm_s": args.warm,
              "duration_s": args.duration, "instructions": instructions,
              "instructions_per_sim_s": round(instructions / args.duration),
              **json.loads(done.stdout.strip().splitlines()[-1])}
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"{args.stack}{' recorded' if args.record else ''}: "
          f"{instructions / 1e9:.4f} G instructions in {args.duration:g} "
          f"simulated s after {args.warm:g} s of warm-up = "
          f"{result['instructions_per_sim_s'] / 1e6:.1f} M per simulated second "
          f"(event digest {result['event_digest'][:16]}...)")


if __name__ == "__main__":
    main()
