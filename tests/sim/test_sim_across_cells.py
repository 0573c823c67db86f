"""A simulation as a notebook uses it, one cell after another: start, run N simulated
seconds and stop there, time standing still between cells, stop; and what happens when
a cell starts a simulation again."""

import asyncio
from pathlib import Path

import pytest

from afa import VirtualClock
from components.simulation import RaptorSimulation

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"
OPEN_FIELD = ROOT / "configs" / "worlds" / "open-field.xml"


async def between_cells(ticks: int = 300) -> None:
    """The loop idle for a while, as between notebook cells (another virtual clock ticks
    meanwhile; the driver moving every virtual clock would move ours too if it ran)."""
    other = VirtualClock(start=0.0)
    async for tick in other.periodic(0.1):
        if tick >= ticks:
            return


def build(clock: VirtualClock) -> RaptorSimulation:
    return RaptorSimulation.from_xml(RAPTOR, OPEN_FIELD, clock=clock, seed=3, teleop=True)


async def test_cell_by_cell_run_for_stops_and_time_stands_still_between_cells():
    clock = VirtualClock()  # runs by itself until the simulation starts
    sim = build(clock)
    await sim.start()
    try:
        assert clock.paused  # held between cells
        started = clock.monotonic()
        await between_cells()
        assert clock.monotonic() == started
        await sim.run_for(2.0)
        assert clock.monotonic() == pytest.approx(started + 2.0) and clock.paused
        assert sim.sim_time == pytest.approx(2.0)
        events = sim.system.statistics()["events_published"]
        await between_cells()
        assert clock.monotonic() == pytest.approx(started + 2.0)
        assert sim.system.statistics()["events_published"] == events
        await sim.run_for(1.0)
        assert sim.sim_time == pytest.approx(3.0)
        assert sim.state.distance > 1.0  # the drive script drove
    finally:
        await sim.stop()
    await sim.stop()  # again: nothing


async def test_a_stopped_simulation_says_it_cannot_start_again_and_a_new_one_runs():
    clock = VirtualClock(auto_advance=False)
    first = build(clock)
    await first.start()
    with pytest.raises(RuntimeError, match="already running"):
        await first.start()
    await first.run_for(1.0)
    await first.stop()
    with pytest.raises(RuntimeError, match="cannot be started again: build a new one"):
        await first.start()
    with pytest.raises(RuntimeError, match="cannot be started again"):
        async with first:
            pass
    with pytest.raises(RuntimeError, match="start the simulation first"):
        await first.run_for(1.0)
    # the next cell builds a new one, on the same loop and even the same clock
    second = build(clock)
    async with second:
        await second.run_for(1.5)
        assert second.sim_time == pytest.approx(1.5)
        health = second.system.health()
        events = second.system.statistics()["events"]
    devices = ["NodLaserService", "NodLaserService12", "StereoService", "3dmgService",
               "GpsSokkiaService", "RaptorOdometryService", "RaptorService", "modelServer"]
    unhealthy = {n: health[n].detail for n in devices if not health[n].healthy}
    assert not unhealthy
    assert events["Pose"] > 0 and second.state.distance > 0.5
    assert clock.paused


async def test_run_for_before_start_and_a_cancelled_cell_leave_the_clock_paused():
    clock = VirtualClock(auto_advance=False)
    sim = build(clock)
    with pytest.raises(RuntimeError, match="start the simulation first"):
        await sim.run_for(1.0)
    await sim.start()
    try:
        cell = asyncio.get_running_loop().create_task(sim.run_for(60.0))
        await clock.sleep_until(clock.monotonic() + 0.5)  # drives with it, then stops
        cell.cancel()  # the notebook's interrupt button
        with pytest.raises(asyncio.CancelledError):
            await cell
        assert clock.paused
        held = clock.monotonic()
        await between_cells()
        assert clock.monotonic() == held
    finally:
        await sim.stop()
