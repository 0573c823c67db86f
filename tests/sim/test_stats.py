"""Running statistics of a simulation: constant memory, the same numbers."""

from __future__ import annotations

import math
import random
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from afa import VirtualClock
from afa.sim.stats import SETTLE_TIME, RunningError
from components.simulation import RaptorSimulation
from idl import PoseTransformIDL, TimeIDL

WORLDS = Path(__file__).resolve().parents[2] / "configs" / "worlds"


def test_running_error_matches_the_statistics_of_the_settled_samples() -> None:
    rng = random.Random(2)
    samples = [(0.25 * i, rng.uniform(0, 3), rng.uniform(-5, 5)) for i in range(400)]
    running = RunningError()
    for sample in samples:
        running.add(*sample)
    settled = np.array([(p, h) for t, p, h in samples if t >= SETTLE_TIME])
    summary = running.summary()
    assert summary is not None
    assert summary["samples"] == 400 and summary["settled_samples"] == len(settled) == 360
    assert summary["rms_position_m"] == pytest.approx(
        math.sqrt(np.mean(settled[:, 0] ** 2)), abs=1e-4)
    assert summary["max_position_m"] == pytest.approx(np.max(settled[:, 0]), abs=1e-4)
    assert summary["rms_heading_deg"] == pytest.approx(
        math.sqrt(np.mean(settled[:, 1] ** 2)), abs=1e-4)


def test_a_run_shorter_than_the_settling_time_is_summarised_whole() -> None:
    running = RunningError()
    assert running.summary() is None
    running.add(1.0, 3.0, 4.0)
    running.add(2.0, 4.0, 3.0)
    assert running.summary() == {"samples": 2, "settled_samples": 2,
                                 "rms_position_m": round(math.sqrt(12.5), 4),
                                 "max_position_m": 4.0,
                                 "rms_heading_deg": round(math.sqrt(12.5), 4)}


def test_the_simulation_keeps_pose_errors_in_constant_memory() -> None:
    """A long run's pose errors (here 3,000 Pose events) do not accumulate."""
    simulation = RaptorSimulation(WORLDS / "slalom.xml", VirtualClock())
    pose = PoseTransformIDL(time=TimeIDL(sec=0), HTransform=np.eye(4),
                            initialUTM=np.array([500_000.0, 5_570_000.0, 750.0]))
    simulation._pose_error(pose)  # noqa: SLF001 - warm up caches before measuring
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for _ in range(3_000):
            simulation._pose_error(pose)  # noqa: SLF001 - the bookkeeping under test
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 32 * 1024, grown  # a list of the samples would hold ~300 kB
    summary = simulation.summary()["pose_error"]
    assert summary["samples"] == 3_001
