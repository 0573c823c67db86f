"""Arc voting costs: Obstacle Avoidance's table-based scoring and the Arc Arbiter's decision.

- *score*: every candidate arc scored on a 32 x 32 ego traversability map (0.5 m cells,
  the Raptor's Table A.7 ego map) through precomputed arc-to-cell tables, discs at the
  rear axle and the front bumper, VehicleRadius 0.7 m, CurveMakingConst 0.01 m; random
  hazard with obstacles and unknown cells, a fresh map each trial.
- *decide*: the arbiter's decision over 4 fresh behaviours' votes (ObstacleAvoidance,
  PurePursuit, FindPath, ObstacleDetection) x N arcs.
- *vote event*: what the component does per ArcVote event: receive one vote, decide.

Figures are medians over ``--trials`` interleaved trials (score, decide and vote event
take turns, so a load spike hits all three alike), each the mean of ``--inner`` calls:
wall-clock time, and the process's CPU time (``time.process_time``), which a busy shared
machine inflates much less because time spent descheduled is not counted.

Usage: ``python benchmarks/arcs.py [--arcs N] [--trials T] [--inner K]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from components.arc_arbiter.arbitrate import VoteArbiter  # noqa: E402
from components.arc_arbiter.parameters import ArcArbiterParameters  # noqa: E402
from components.arcs import ArcSet, ArcSetParameters, ArcVotes  # noqa: E402
from components.obstacle_avoidance.parameters import ObstacleAvoidanceParameters  # noqa: E402
from components.obstacle_avoidance.sweep import ArcSweeper, MapGeometry  # noqa: E402
from idl.common import TimeIDL  # noqa: E402
from idl.planning import ArcVoteIDL  # noqa: E402

BEHAVIOURS = ("ObstacleAvoidance", "PurePursuit", "FindPath", "ObstacleDetection")


def per_call(fn: Callable[[], object], inner: int) -> tuple[float, float]:
    """(wall, CPU) seconds per call, averaged over ``inner`` calls."""
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(inner):
        fn()
    return ((time.perf_counter() - start) / inner, (time.process_time() - cpu) / inner)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arcs", type=int, default=ArcSetParameters().Count)
    parser.add_argument("--trials", type=int, default=41)
    parser.add_argument("--inner", type=int, default=200)
    args = parser.parse_args()

    arcs = ArcSet.from_parameters(ArcSetParameters(Count=args.arcs))
    n = len(arcs)
    rng = np.random.default_rng(2006)
    geometry = MapGeometry(rows=32, cols=32, gridsize=0.5, origin_x=0.0, origin_y=-8.0)
    sweeper = ArcSweeper(arcs, ObstacleAvoidanceParameters(VehicleRadius=0.7),
                         map_frame=(2.45, 0.0), disc_offsets=(0.0, 2.45))
    start = time.perf_counter()
    scorer = sweeper.scorer(geometry)
    build = time.perf_counter() - start
    cells = int(scorer.tables.counts.sum())
    print(f"{n} arcs; tables for a 32 x 32 map built in {build * 1e3:.0f} ms "
          f"({cells} arc-cell entries, {scorer.tables.cells.shape[1]} per arc at most)")

    maps = []
    for _ in range(8):
        hazard = rng.uniform(0.0, 0.6, (32, 32)).astype(np.float32)
        hazard[rng.random((32, 32)) < 0.02] = 1.0
        hazard[rng.random((32, 32)) < 0.1] = np.nan
        maps.append((hazard, rng.uniform(0.2, 1.0, (32, 32)).astype(np.float32)))

    arbiter = VoteArbiter(ArcArbiterParameters(), arcs)
    stamp = TimeIDL(sec=0)
    bodies = []
    for b in BEHAVIOURS:
        votes = ArcVotes(rng.random(n) < 0.1, rng.random(n), rng.random(n), rng.random(n) * 2)
        bodies.append(votes.to_idl(time=stamp, behaviour=b, arcs=arcs))
    for body in bodies:
        arbiter.receive(body, 0.0)

    score_us: list[tuple[float, float]] = []
    decide_us: list[tuple[float, float]] = []
    event_us: list[tuple[float, float]] = []
    for trial in range(args.trials):
        hazard, goodness = maps[trial % len(maps)]
        body = bodies[trial % len(bodies)]

        def score(hazard: np.ndarray = hazard, goodness: np.ndarray = goodness) -> None:
            scorer.score(hazard, goodness)

        def event(body: ArcVoteIDL = body) -> None:
            arbiter.receive(body, 0.5)
            arbiter.decide(0.5)

        score_us.append(per_call(score, args.inner))
        decide_us.append(per_call(lambda: arbiter.decide(0.5), args.inner))
        event_us.append(per_call(event, args.inner))

    print(f"{'median per call':<52} {'wall':>9} {'(IQR)':>15} {'CPU':>9}")

    def show(name: str, samples: list[tuple[float, float]]) -> None:
        wall = [w * 1e6 for w, _ in samples]
        cpu = [c * 1e6 for _, c in samples]
        q = statistics.quantiles(wall, n=4)
        print(f"{name:<52} {statistics.median(wall):6.1f} us {f'({q[0]:.0f}..{q[2]:.0f})':>15} "
              f"{statistics.median(cpu):6.1f} us")

    show(f"score {n} arcs on a 32x32 ego map (tables precomputed)", score_us)
    show(f"decide: 4 behaviours x {n} arcs", decide_us)
    show("vote event: receive one ArcVote + decide", event_us)


if __name__ == "__main__":
    main()
