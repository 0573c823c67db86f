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
                            teleop: bool = True, **recorder_options):
    from components.simulation import RaptorSimulation

    clock = VirtualClock()
    sim = RaptorSimulation.from_xml(config, clock=clock, seed=3, teleop=teleop)
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


AUTONOMOUS_SECONDS = 6.0


@pytest.fixture(scope="session")
def recorded_autonomous(tmp_path_factory) -> Path:
    """A simulated autonomous run (the control station sets the waypoints at about
    1.3 s, then the arbiter drives), recorded with every channel."""
    path = tmp_path_factory.mktemp("log") / "autonomous.mcap"
    asyncio.run(record_simulation(path, seconds=AUTONOMOUS_SECONDS, teleop=False))
    return path
