"""Fixtures for the simulator's tests."""

from collections.abc import Callable
from pathlib import Path

import pytest

from afa import VirtualClock
from components.simulation import RaptorSimulation

RAPTOR = Path(__file__).resolve().parents[2] / "configs" / "raptor.xml"


@pytest.fixture
def simulate(tmp_path: Path) -> Callable[[str], RaptorSimulation]:
    """``simulate(xml)``: the shipped configuration on the world ``xml`` (written to
    ``world.xml`` in the test's tmp dir), seed 0, in unpaced virtual time; not started
    (use ``async with``)."""

    def build(xml: str) -> RaptorSimulation:
        world = tmp_path / "world.xml"
        world.write_text(xml)
        return RaptorSimulation.from_xml(RAPTOR, world, clock=VirtualClock(), seed=0)

    return build
