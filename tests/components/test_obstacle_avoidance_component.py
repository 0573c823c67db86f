"""Obstacle Avoidance as a component, with its configured parameters (configs/raptor.xml)
and ModelServer's geometry: ego traversability maps (``TraverseEgo``) in, ArcVote out.

Which arcs must be vetoed is worked out here from the arcs' centre lines (the rear axle's
path, exact circles), not by the component's sweep: an arc whose centre line runs into a
hazard, or through a gap narrower than the vehicle, takes the vehicle's body into it.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from afa import System, VirtualClock
from components.arcs import DESIGN_VEHICLE_WIDTH
from components.model_server import ModelServer
from components.model_server.geometry import GeometryModel
from components.model_server.parameters import ModelServerParameters
from components.obstacle_avoidance import ObstacleAvoidance
from idl import EtravMapArrayEventIDL, Position3DIDL, TimeIDL

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "raptor.xml"
VEHICLE = "Raptor:RearAxleCenter"
#: The ego traversability map of the shipped configuration: 16 m × 16 m at 0.5 m, hung
#: from the front bumper, rows ahead, columns to the left (EgoTravMapDescription).
GROUND_FRAME = "Raptor: Front-BumperCenter"
CELL = 0.5
ROWS = COLS = 32
ORIGIN_Y = -COLS * CELL / 2
EXTENT = ROWS * CELL
BUMPER_X = float(GeometryModel.load(ROOT / "configs" / "050917raptor01.XML")
                 .transformation(VEHICLE, "Raptor:Front-BumperCenter")[0, 3])


def ego_map(hazard: np.ndarray, t: float, cell: float = CELL) -> EtravMapArrayEventIDL:
    rows, cols = hazard.shape
    return EtravMapArrayEventIDL(
        time=TimeIDL.from_seconds(t), frame=GROUND_FRAME, mapPose=np.eye(4),
        initialUTM=np.array([500000.0, 5570000.0, 750.0]), gridsize=cell, originX=0.0,
        originY=-cols * cell / 2, rows=rows, cols=cols, hazard=hazard.astype(np.float32),
        goodness=np.ones((rows, cols), dtype=np.float32), vehiclePosition=Position3DIDL(),
        vehicleHeading=0.0)


def clear(cell: float = CELL) -> np.ndarray:
    n = int(round(EXTENT / cell))
    return np.zeros((n, n))


def column(y: float, cell: float = CELL) -> int:
    return int(np.floor((y + EXTENT / 2) / cell))


def edge(y: float, cell: float) -> int:
    """The column whose right edge is at ``y`` (a cell boundary)."""
    return int(round((y + EXTENT / 2) / cell))


def row(x_map: float, cell: float = CELL) -> int:
    return int(np.floor(x_map / cell))


def centre_line(kappa: float, length: float, step: float = 0.01) -> np.ndarray:
    """The rear axle's path on the arc of curvature ``kappa`` (left +), in map-frame
    coordinates (x ahead of the bumper, y left), up to ``length`` m or half a circle."""
    if abs(kappa) > 1e-12:
        length = min(length, np.pi / abs(kappa))
    s = np.arange(0.0, length, step)
    if abs(kappa) < 1e-12:
        x, y = s, np.zeros_like(s)
    else:
        x, y = np.sin(kappa * s) / kappa, (1 - np.cos(kappa * s)) / kappa
    return np.stack([x - BUMPER_X, y], axis=1)


def cells_on(path: np.ndarray, cell: float = CELL) -> set[tuple[int, int]]:
    inside = (path[:, 0] >= 0) & (path[:, 0] < EXTENT) & (np.abs(path[:, 1]) < EXTENT / 2)
    return {(row(x, cell), column(y, cell)) for x, y in path[inside]}


@asynccontextmanager
async def running(radius: float | None = None) -> AsyncIterator[tuple[System, VirtualClock,
                                                                       Any]]:
    """obsAvoid and modelServer as configs/raptor.xml has them (``radius``: with that
    VehicleRadius instead of the configured one)."""
    clock = VirtualClock(start=0.0)
    system = System.from_xml(CONFIG, clock=clock, only=["obsAvoid", "modelServer"])
    if radius is not None:
        configured = system.components["obsAvoid"].parameters
        system = System([ModelServer("modelServer", ModelServerParameters()),
                         ObstacleAvoidance("obsAvoid", configured.model_copy(
                             update={"VehicleRadius": radius}))],
                        clock=clock, base_dir=CONFIG.parent)
    async with system:
        votes = system.channel.subscribe("Raptor", "ArcVote", maxsize=256)
        yield system, clock, votes


def drain(subscription: Any) -> list[Any]:
    events = []
    while (event := subscription.get_nowait()) is not None:
        events.append(event)
    return events


async def scored(hazard: np.ndarray, cell: float = CELL, radius: float | None = None) -> Any:
    async with running(radius) as (system, clock, votes):
        await clock.advance(1.0)
        system.channel.publish("Raptor", "TraverseEgo", ego_map(hazard, clock.now(), cell))
        await clock.advance(0.1)
        (event,) = drain(votes)
        return event.body


async def test_it_votes_at_once_on_each_ego_map():
    async with running() as (system, clock, votes):
        oa = system.components["obsAvoid"]
        await clock.advance(3.0)
        assert drain(votes) == []  # no map, no opinion
        sent = []
        for t in (3.2, 3.45, 4.7, 4.71):
            await clock.advance(t - clock.monotonic())
            system.channel.publish("Raptor", "TraverseEgo", ego_map(clear(), clock.now()))
            sent.append(clock.now())
        await clock.advance(1.0)
        got = drain(votes)
        assert [e.time for e in got] == sent
        assert {e.body.behaviour for e in got} == {"ObstacleAvoidance"}
        assert all(e.body.curvatures.tolist() == oa.arcs.curvatures.tolist() for e in got)
        assert not any(e.body.veto.any() for e in got)  # open ground


async def test_arcs_into_a_near_hazard_are_vetoed_and_arcs_turning_away_are_not():
    hazard = clear()
    rows = slice(row(2.0), row(3.0) + 1)  # 2..3.5 m ahead of the bumper
    cols = slice(column(-0.75), column(0.75) + 1)
    hazard[rows, cols] = 1.0
    vote = await scored(hazard)
    blocked = {(i, j) for i in range(rows.start, rows.stop) for j in range(cols.start, cols.stop)}
    into = [k for k, kappa in enumerate(vote.curvatures)
            if cells_on(centre_line(kappa, 20.0)) & blocked]
    assert len(into) >= 3 and len(vote.curvatures) // 2 in into
    assert all(vote.veto[k] for k in into)
    # the hardest turns never come within 2 m of the block: free
    assert not vote.veto[0] and not vote.veto[-1]
    assert vote.maxSpeed[into].max() == 0.0


async def test_a_hazard_beyond_the_veto_distance_lowers_the_votes_of_arcs_into_it():
    hazard = clear()
    rows = slice(row(6.0), row(7.0) + 1)  # 6..7.5 m ahead of the bumper: 5.8 m of travel
    cols = slice(column(-0.75), column(0.75) + 1)
    hazard[rows, cols] = 1.0
    vote = await scored(hazard)
    straight = len(vote.curvatures) // 2
    assert not vote.veto.any()  # VetoDistance 2.5 m in configs/raptor.xml: time to turn
    into = np.flatnonzero(vote.vote < 1.0)
    assert straight in into and len(into) <= 7  # the arcs into it, no others
    assert vote.vote[straight] < 0.6  # free for 5.8 m of an 11 m horizon


#: configs/raptor.xml's VehicleRadius is 0.7 m (Table A.10's 0.5 m would draw a 1.0 m
#: vehicle, narrower than the Raptor, and let it into a 1.2 m gap on a fine grid).
@pytest.mark.parametrize(("cell", "gap", "radius"), [
    (0.5, 1.0, None),
    (0.2, 1.2, None),  # configs/raptor.xml's VehicleRadius (0.7 m)
    (0.1, 1.3, None),
    (0.2, 1.2, DESIGN_VEHICLE_WIDTH / 2),
    (0.1, 1.3, DESIGN_VEHICLE_WIDTH / 2),
])
async def test_a_gap_narrower_than_the_vehicle_vetoes_every_arc_through_it(cell, gap, radius):
    """A wall across the path 2.5 m ahead of the bumper (within VetoDistance, 2.5 m of
    travel, for every disc) with a gap narrower than the Raptor's 1.4 m body, centred on
    the straight arc, on the map's own grid (the ego map's Gridsize is configurable;
    0.5 m in the shipped configuration; FarZone counts rows, 39 rows of 0.1 m reach
    3.9 m)."""
    assert gap < DESIGN_VEHICLE_WIDTH
    hazard = clear(cell)
    wall = row(2.5, cell)
    first, last = edge(-gap / 2, cell), edge(gap / 2, cell)  # gap cells [first, last)
    assert (last - first) * cell == pytest.approx(gap)  # centred on the straight arc
    hazard[wall, :] = 1.0
    hazard[wall, first:last] = 0.0
    # as the Traversability Map marks a wall: its cells and, the step beside them, their
    # neighbours (configs/raptor.xml's HazardMargin takes a hazard cell's obstacle to lie
    # half a cell beyond its centre because of that)
    hazard = ndimage.binary_dilation(hazard > 0, structure=np.ones((3, 3), bool)
                                     ).astype(np.float32)
    vote = await scored(hazard, cell, radius)
    gap_cells = {(wall, j) for j in range(first, last)}
    wall_cells = {(wall, j) for j in range(hazard.shape[1])}
    lines = [cells_on(centre_line(kappa, 20.0), cell) for kappa in vote.curvatures]
    through = [k for k, line in enumerate(lines) if line & gap_cells]
    reaching = [k for k, line in enumerate(lines) if line & wall_cells]
    assert len(vote.curvatures) // 2 in through
    assert [k for k in through if not vote.veto[k]] == [], "arcs through the gap allowed"
    assert all(vote.veto[k] for k in reaching)
    assert not vote.veto.all()  # the hard turns stay short of the wall


async def test_a_gate_wider_than_the_vehicle_is_threaded():
    hazard = clear()
    wall = row(5.0)
    hazard[wall, :] = 1.0
    hazard[wall, column(-1.0):column(1.0)] = 0.0  # 2 m: the design gate of components/arcs
    vote = await scored(hazard)
    assert not vote.veto[len(vote.curvatures) // 2]


async def test_maps_in_a_frame_modelserver_does_not_know_are_ignored_and_reported():
    async with running() as (system, clock, votes):
        oa = system.components["obsAvoid"]
        await clock.advance(1.0)
        body = ego_map(clear(), clock.now()).model_copy(update={"frame": "NoSuchBody:Frame"})
        system.channel.publish("Raptor", "TraverseEgo", body)
        await clock.advance(0.5)
        assert drain(votes) == []
        assert oa.statistics()["unknown_frames"] == 1
        health = oa.health()
        assert not health.healthy and "NoSuchBody:Frame" in health.detail
