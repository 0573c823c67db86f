"""The course oracle's cost is bounded on large terrains (afa.sim.oracle.ORACLE_MAX_CELLS).

At its 0.25 m spacing a 5 km terrain was 4e8 cells, and building its graph exhausted
memory at the end of every run on it; a 1 km one took 18 GB. A terrain that needs more
than a million cells is planned at a coarser spacing, and the course stays right."""

import math
import tracemalloc
from pathlib import Path

import pytest

from afa.sim import Terrain, load_world
from afa.sim.oracle import ORACLE_MAX_CELLS, HazardField, shortest_course

WORLD = """<world name="wide">
  <origin latitude="50.27" longitude="-111.17"/>
  <terrain width="{size}" depth="{size}" resolution="10"/>
  <obstacle type="box" east="0" north="0" length="400" width="40" height="2" heading="0"/>
  <vehicle east="-{half}" north="0"/>
  <mission><waypoint east="{half}" north="0"/></mission>
</world>
"""


@pytest.mark.parametrize("size", [1000, 2000])
def test_a_large_terrain_is_planned_in_bounded_memory_and_round_its_wall(tmp_path: Path,
                                                                       size: int) -> None:
    half = size // 2 - 100
    path = tmp_path / "wide.xml"
    path.write_text(WORLD.format(size=size, half=half))
    world = load_world(path)
    field = HazardField(Terrain.from_spec(world.terrain, world.obstacles))
    tracemalloc.start()
    try:
        course = shortest_course(world, field)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 2_000 * ORACLE_MAX_CELLS  # ~2 kB a cell at most, whatever the terrain
    # round the 400 m wall (40 m thick, grown by the body's half width and the terrain's
    # 10 m samples): no shorter than the two straight lines past its ends
    past_end = 2 * math.hypot(half, 200.0)
    assert course.length is not None and past_end <= course.length <= 1.05 * past_end
