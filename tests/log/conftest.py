"""A recorded simulation shared by the log tests (recorded once per session)."""

import asyncio
from pathlib import Path

import pytest

from afa import VirtualClock
from afa.log import Recorder

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"
SIM_SECONDS = 12.0


async def record_simulation(path: Path, config: Path = RAPTOR, seconds: float = SIM_SECONDS,
                            **recorder_options):
    from components.simulation import RaptorSimulation

    clock = VirtualClock()
    sim = RaptorSimulation.from_xml(config, clock=clock, seed=3, teleop=True)
    recorder = Recorder(path, **recorder_options).attach(
        sim.system, metadata={"world": sim.world.name, "seed": 3})
    async with sim:
        await sim.system.run(seconds)
        await recorder.close()
    return sim, recorder


@pytest.fixture
def record():
    """``await record(path, config=..., seconds=..., **recorder_options)``."""
    return record_simulation


@pytest.fixture(scope="session")
def recorded(tmp_path_factory) -> Path:
    """A simulated run (teleop drive) recorded with every channel."""
    path = tmp_path_factory.mktemp("log") / "sim.mcap"
    asyncio.run(record_simulation(path))
    return path
