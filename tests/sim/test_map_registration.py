"""Map registration: a short scripted drive past a known box and ditch, in both directions,
with a noise-free GPS, and the Terrain Map's heights compared with the world's truth.

With the GPS's own error taken out, whatever misplaces the map is the pipeline's: the
time stamps of scans and poses, the laser's mounting, the frames. The drive is fast
(2 m/s) so that a timing error shows as a shift along the track that flips with the
direction of travel: a pose stamped 0.24 s after the fix it carried put the map 0.3 to
0.5 m behind the truth (decision 0025).
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest

import components.gps_sokkia.emulator as gps_emulator
from afa import VirtualClock
from afa.sim.world import parse_world
from components.gps_sokkia.fake import GpsNoise
from components.map_quality import MapFrame, registration_world
from components.simulation import RaptorSimulation

RAPTOR = Path(__file__).resolve().parents[2] / "configs" / "raptor.xml"
SPEED = 2.0
# components.map_quality.registration_world: the box east -0.5..0.5, north 2..6
BOX_WEST, BOX_EAST, BOX_NORTH = -0.5, 0.5, 4.0


def drive(heading: float, start_east: float) -> tuple[RaptorSimulation, object]:
    async def simulate() -> tuple[RaptorSimulation, object]:
        world = parse_world(registration_world(heading, start_east, SPEED, 10.0))
        simulation = RaptorSimulation.from_xml(RAPTOR, world, clock=VirtualClock(), seed=0,
                                               teleop=True)
        async with simulation:
            await simulation.system.run(12.0)
            terrain = simulation.system.components["TerrainService"].latest_map.get()
        return simulation, terrain

    return asyncio.run(simulate())


@pytest.fixture(scope="module", params=[(90.0, -17.0), (270.0, 23.0)], ids=["east", "west"])
def run(request):
    patch = pytest.MonkeyPatch()
    # the GPS's own (correlated, 0.17 m) error would hide the pipeline's; noise-free here
    patch.setattr(gps_emulator, "GPS_NOISE",
                  GpsNoise(horizontal=0.0, vertical=0.0, velocity=0.0,
                           satellite_step_rate=0.0))
    try:
        yield request.param[0], *drive(*request.param)
    finally:
        patch.undo()


def cells(simulation, terrain):
    """World (east, north) of each observed cell's centre, its height above the truth's
    level and the truth's height there (``truth(de, dn)`` shifted)."""
    frame = MapFrame.of(simulation.world.origin, terrain.initialUTM)
    known = terrain.pointCount > 0
    i, j = np.nonzero(known)
    g = terrain.gridsize
    x = terrain.originX + (i + 0.5) * g
    y = terrain.originY + (j + 0.5) * g
    east, north = frame.to_world(x, y)
    height = terrain.elevation[known].astype(np.float64) - frame.dz
    return east, north, height


def test_the_map_lies_on_the_truth_in_both_directions(run):
    heading, simulation, terrain = run
    east, north, height = cells(simulation, terrain)
    truth = simulation.terrain.height
    level = float(np.median(height - truth(east, north)))  # the map's floating level
    height = height - level
    # cells within a metre of a height change of the truth: where a shift shows
    near = np.zeros(east.shape, bool)
    for d in (-1.0, 1.0):
        near |= np.abs(truth(east + d, north) - truth(east, north)) > 0.3
        near |= np.abs(truth(east, north + d) - truth(east, north)) > 0.3
    assert near.sum() > 100
    shifts = np.arange(-0.6, 0.61, 0.05)
    cost = [np.mean(np.minimum(np.abs(height[near] - truth(east[near] - dx, north[near])),
                               0.3)) for dx in shifts]
    best = float(shifts[int(np.argmin(cost))])
    assert abs(best) <= 0.1, f"heading {heading}: the map lies {best:+.2f} m east of truth"


def face_crossing(simulation, terrain, heading):
    """East of the box's near face where the map's mean height crosses half the box's
    height, interpolated along each map row through the box's middle; the median."""
    frame = MapFrame.of(simulation.world.origin, terrain.initialUTM)
    g = terrain.gridsize
    found = []
    for north_row in np.arange(BOX_NORTH - 1.2, BOX_NORTH + 1.21, 0.1):
        x0, y0 = frame.to_map(-3.0, north_row)
        j = int((y0 - terrain.originY) // g)
        i0 = int((x0 - terrain.originX) // g)
        i = np.arange(i0, i0 + int(6.0 / g))
        if j < 0 or j >= terrain.cols or i[0] < 0 or i[-1] >= terrain.rows:
            continue
        z = terrain.elevation[i, j].astype(np.float64)
        xc = terrain.originX + (i + 0.5) * g
        east, _ = frame.to_world(xc, np.full(xc.shape, terrain.originY + (j + 0.5) * g))
        ground = np.nanmedian(np.r_[z[:5], z[-5:]])
        up = z - ground > 0.3
        if heading == 90.0:
            k = int(np.argmax(up))  # first high cell from the west
            if k == 0 or not up[k] or np.isnan(z[k - 1]):
                continue
            a, b = k - 1, k
        else:
            k = len(up) - 1 - int(np.argmax(up[::-1]))
            if k == len(up) - 1 or not up[k] or np.isnan(z[k + 1]):
                continue
            a, b = k + 1, k
        w = (0.3 - (z[a] - ground)) / ((z[b] - ground) - (z[a] - ground))
        found.append(east[a] + w * (east[b] - east[a]))
    return float(np.median(found)), len(found)


def test_the_box_face_met_first_is_mapped_where_it_stands(run):
    # where the mean height crosses half the box's height: 0.06-0.07 m outside the face
    # in either direction (a 0.2 m cell straddling the face averages many hits on it);
    # 0.23-0.24 m behind with the stale raw pose
    heading, simulation, terrain = run
    crossing, rows = face_crossing(simulation, terrain, heading)
    assert rows >= 15
    face = BOX_WEST if heading == 90.0 else BOX_EAST
    assert abs(crossing - face) <= 0.15, f"heading {heading}: face at {crossing:+.2f} m"


def test_frame_pose_at_interpolates_the_last_physics_steps():
    # the laser's emulator casts each scan line from the pose at its first beam
    frame = "FrontNoddingSICKLeft:AxleCenterFreeEnd"

    async def simulate():
        world = parse_world(registration_world(90.0, -17.0, SPEED, 10.0))
        simulation = RaptorSimulation.from_xml(RAPTOR, world, clock=VirtualClock(), seed=0,
                                               teleop=True)
        async with simulation:
            await simulation.system.run(4.0)  # moving at 2 m/s
            history = list(simulation._history)
            mount = simulation.mount(frame)
            for t, state, _ in history:
                assert np.array_equal(simulation.frame_pose_at(frame, t),
                                      state.transform() @ mount)
            (t0, a, _), (t1, b, _) = history[-3], history[-2]
            middle = simulation.frame_pose_at(frame, 0.5 * (t0 + t1))
            ends = (a.transform() @ mount, b.transform() @ mount)
            assert b.east - a.east == pytest.approx(SPEED * (t1 - t0), rel=0.05)
            np.testing.assert_allclose(middle, 0.5 * (ends[0] + ends[1]), atol=1e-12)
            rotation = middle[:3, :3]  # still a rotation to well under a millimetre at 8 m
            assert np.abs(rotation @ rotation.T - np.eye(3)).max() < 1e-5
            assert np.array_equal(simulation.frame_pose_at(frame, t1 + 1.0),
                                  simulation.frame_pose(frame))
            assert np.array_equal(simulation.frame_pose_at(frame, history[0][0] - 1.0),
                                  history[0][1].transform() @ mount)

    asyncio.run(simulate())
