"""The Traversability Map as a component: the test publishes terrain maps (global and
ego, as the Terrain Map does), reads the traversability maps back through the TravMap
interface and the Traverse events, on a virtual clock.

The scene: flat, fully observed ground (0.2 m terrain cells, heights 0) over a
rectangle around the vehicle, a 1 m tall block 3 m ahead of the bumper, and a 0.4 m
tall one in the far field. Cell edges are whole multiples of the cell sizes, so which
traversability cells the blocks occupy follows from the geometry: a block cell and
its 8 neighbours differ by 1 m (a step over ``Stepheight`` 0.3 m: hazard 1), cells two
or more away from any block are flat (hazard 0), unobserved cells stay unknown (NaN).
"""

from __future__ import annotations

import math
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from afa import EDevIO, ETimeOut, System, VirtualClock
from components.traversability_map import TraversabilityMap, TraversabilityMapParameters
from idl import (
    EgoMapArrayEventIDL,
    MapArrayEventIDL,
    TimeIDL,
    TravMap,
)

UTM = np.array([500_000.0, 5_570_000.0, 750.0])
FINE = 0.2
COARSE = 0.5
BUMPER = (2.0, 0.0)        # the ego map frame (ground under the bumper), world x, y
OBSERVED = (-4.0, 16.0, -6.0, 6.0)      # x0, x1, y0, y1 of the observed ground
NEAR_BLOCK = (5.0, 6.0, 0.0, 1.0, 1.0)  # x0, x1, y0, y1, height: 3 m ahead of the bumper
FAR_BLOCK = (13.0, 14.0, -3.0, -2.0, 0.4)  # 11-12 m ahead: beyond Farfield (8 m)
POINTS = 20                # points per observed terrain cell


def heights(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The scene's height at world points (NaN where not observed)."""
    x0, x1, y0, y1 = OBSERVED
    z = np.where((x >= x0) & (x < x1) & (y >= y0) & (y < y1), 0.0, np.nan)
    for bx0, bx1, by0, by1, h in (NEAR_BLOCK, FAR_BLOCK):
        z = np.where((x >= bx0) & (x < bx1) & (y >= by0) & (y < by1), h, z)
    return z


def layers(origin_x: float, origin_y: float, rows: int, cols: int, shift=(0.0, 0.0)):
    """Terrain layers of a grid whose map frame is the world shifted by ``shift``."""
    i, j = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    x = origin_x + (i + 0.5) * FINE + shift[0]
    y = origin_y + (j + 0.5) * FINE + shift[1]
    z = heights(x, y)
    known = ~np.isnan(z)
    z32 = z.astype(np.float32)
    return {"elevation": z32, "minHeight": z32, "maxHeight": z32,
            "pointCount": np.where(known, POINTS, 0).astype(np.int32),
            "variance": np.where(known, 0.0, np.nan).astype(np.float32)}


def ego_pose() -> np.ndarray:
    pose = np.eye(4)
    pose[:2, 3] = BUMPER
    return pose


def terrain_maps(t: float, gridsize: float = FINE) -> tuple[MapArrayEventIDL,
                                                            EgoMapArrayEventIDL]:
    stamp = TimeIDL.from_seconds(t)
    rows = cols = int(round(32.0 / gridsize))
    header = {"time": stamp, "initialUTM": UTM, "gridsize": gridsize}
    world = MapArrayEventIDL(**header, frame="World", mapPose=np.eye(4), originX=-14.0,
                             originY=-16.0, rows=rows, cols=cols,
                             **layers(-14.0, -16.0, rows, cols) if gridsize == FINE
                             else _blank(rows, cols))
    ego = EgoMapArrayEventIDL(**header, frame="Raptor:Front-BumperCenter", mapPose=ego_pose(),
                              originX=0.0, originY=-8.0, rows=80, cols=80,
                              **layers(0.0, -8.0, 80, 80, shift=BUMPER))
    return world, ego


def _blank(rows: int, cols: int) -> dict[str, np.ndarray]:
    flat = np.zeros((rows, cols), dtype=np.float32)
    return {"elevation": flat, "minHeight": flat, "maxHeight": flat,
            "pointCount": np.full((rows, cols), POINTS, dtype=np.int32), "variance": flat}


@dataclass
class Rig:
    clock: VirtualClock
    system: System
    trav: TraversabilityMap
    events: Any
    ego_events: Any

    def publish(self, t: float | None = None) -> None:
        world, ego = terrain_maps(self.clock.now() if t is None else t)
        self.system.channel.publish("Raptor", "Terrain", world)
        self.system.channel.publish("Raptor", "TerrainEgo", ego)

    async def feed(self, seconds: float, period: float = 0.5) -> None:
        """Terrain maps every ``period`` s, as the Terrain Map publishes them."""
        for _ in range(int(round(seconds / period))):
            self.publish()
            await self.clock.sleep(period)

    @property
    def proxy(self):
        return self.system.proxy(TravMap, "Traverse")

    def health(self):
        return self.system.health()["TraverseService"]


@asynccontextmanager
async def rig(**overrides: Any):
    clock = VirtualClock()
    trav = TraversabilityMap("TraverseService", TraversabilityMapParameters(**overrides))
    system = System([trav], clock=clock)
    async with system:
        events = system.channel.subscribe("Raptor", "Traverse", maxsize=1000)
        ego_events = system.channel.subscribe("Raptor", "TraverseEgo", maxsize=1000)
        yield Rig(clock, system, trav, events, ego_events)


def drain(subscription: Any) -> list[Any]:
    out = []
    while (event := subscription.get_nowait()) is not None:
        out.append(event)
    return out


def cells(trav: Any, x0: float, x1: float, y0: float, y1: float,
          pose_xy=(0.0, 0.0)) -> tuple[slice, slice]:
    """The traversability cells covering map-frame box [x0, x1) x [y0, y1)."""
    g = trav.gridsize
    i0 = round((x0 - pose_xy[0] - trav.originX) / g)
    i1 = round((x1 - pose_xy[0] - trav.originX) / g)
    j0 = round((y0 - pose_xy[1] - trav.originY) / g)
    j1 = round((y1 - pose_xy[1] - trav.originY) / g)
    return slice(i0, i1), slice(j0, j1)


def grown(box: tuple[slice, slice], by: int) -> tuple[slice, slice]:
    return (slice(box[0].start - by, box[0].stop + by), slice(box[1].start - by,
                                                             box[1].stop + by))


def flat_cells(trav: Any, pose_xy=(0.0, 0.0)) -> np.ndarray:
    """Observed cells two or more cells away from both blocks."""
    mask = np.zeros((trav.rows, trav.cols), dtype=bool)
    mask[cells(trav, *OBSERVED, pose_xy=pose_xy)] = True
    for block in (NEAR_BLOCK, FAR_BLOCK):
        mask[grown(cells(trav, *block[:4], pose_xy=pose_xy), 2)] = False
    return mask


# --- the maps and the interface -----------------------------------------------------------


async def test_hazards_from_the_terrain_maps_served_in_both_forms():
    async with rig(MapUpdateTime=2.0) as r:
        await r.feed(4.0)
        trav = await r.proxy.getTravMapArray()
        etrav = await r.proxy.getEtravMapArray()
    assert trav.frame == "World" and np.array_equal(trav.initialUTM, UTM)
    assert trav.gridsize == COARSE and (trav.rows, trav.cols) == (64, 64)
    # centred on the vehicle (the ego map's origin) with whole-cell origins
    assert (trav.originX, trav.originY) == (BUMPER[0] - 16.0, BUMPER[1] - 16.0)
    assert (trav.vehiclePosition.x, trav.vehiclePosition.y) == BUMPER
    assert trav.vehicleHeading == 0.0
    near = cells(trav, *NEAR_BLOCK[:4])
    assert np.all(trav.hazard[near] == 1.0)  # the block (its higher side of every step)
    flat = flat_cells(trav)
    assert flat.sum() > 800 and np.all(trav.hazard[flat] == 0.0)
    observed = np.zeros_like(flat)
    observed[cells(trav, *OBSERVED)] = True
    assert np.all(np.isnan(trav.hazard[~observed]))  # unknown stays unknown, never free
    assert np.all(trav.goodness[~observed] == 0.0)
    # goodness: plenty of fresh points; in the far field scaled by 1 / Farfieldscale
    cx = trav.originX + (np.arange(trav.rows)[:, None] + 0.5) * COARSE
    cy = trav.originY + (np.arange(trav.cols)[None, :] + 0.5) * COARSE
    far_field = np.hypot(cx - BUMPER[0], cy - BUMPER[1]) > 8.0
    near_goodness = trav.goodness[flat & ~far_field]
    assert near_goodness.min() > 0.9
    assert trav.goodness[flat & far_field] == pytest.approx(near_goodness.max() / 1.5,
                                                            rel=1e-4)
    # the far block (0.4 m) is under the far field's relaxed step (0.3 m x 1.5)
    far = cells(trav, *FAR_BLOCK[:4])
    assert np.all(trav.hazard[far] < 1.0) and np.all(trav.hazard[far] > 0.0)
    # the ego map: heading-aligned ahead of the bumper, same hazards in its own frame
    assert etrav.frame == "Raptor:Front-BumperCenter"
    assert np.array_equal(etrav.mapPose, ego_pose())
    assert (etrav.originX, etrav.originY, etrav.rows, etrav.cols) == (0.0, -8.0, 32, 32)
    ego_near = cells(etrav, *NEAR_BLOCK[:4], pose_xy=BUMPER)
    assert np.all(etrav.hazard[ego_near] == 1.0)
    assert np.all(etrav.hazard[flat_cells(etrav, pose_xy=BUMPER)] == 0.0)


async def test_farfield_sets_where_thresholds_relax():
    async with rig(MapUpdateTime=2.0, Farfield=20000.0) as r:
        await r.feed(4.0)
        trav = await r.proxy.getTravMapArray()
    assert np.all(trav.hazard[cells(trav, *FAR_BLOCK[:4])] == 1.0)  # near field now


async def test_stepheight_and_the_step_switch_reach_the_hazards():
    async with rig(MapUpdateTime=2.0, Stepheight=1100.0, SlopeOn=0) as r:
        await r.feed(4.0)
        high = await r.proxy.getTravMapArray()
    async with rig(MapUpdateTime=2.0, StepOn=0, SlopeOn=0) as r:
        await r.feed(4.0)
        off = await r.proxy.getTravMapArray()
    near = cells(high, *NEAR_BLOCK[:4])
    assert np.all(high.hazard[near] == 0.0)  # 1 m is under a 1.1 m step
    known = ~np.isnan(off.hazard)
    assert known.sum() == 40 * 24 and np.all(off.hazard[known] == 0.0)


async def test_no_map_before_map_update_time_then_one_every_interval():
    async with rig(MapUpdateTime=7.0, MapEventInterval=1.0) as r:
        start = r.clock.now()
        with pytest.raises(EDevIO):
            await r.proxy.getTravMapArray()
        await r.feed(3.0)  # a getWait... waits up to 5 s for the next map
        waiter = r.system.tasks.spawn(r.proxy.getWaitTravMapArray(), owner="test")
        ego_waiter = r.system.tasks.spawn(r.proxy.getWaitEtravMapArray(), owner="test")
        await r.feed(8.5)
        events, egos = drain(r.events), drain(r.ego_events)
        first, first_ego = waiter.result(), ego_waiter.result()
    published = [e.time for e in events]
    assert published[0] == pytest.approx(start + 7.0)  # not one before MapUpdateTime
    assert np.allclose(np.diff(published), 1.0) and len(published) == 5
    assert [e.time for e in egos] == published
    # a map carries its terrain map's stamp; the waiter got the first one
    assert first.time == events[0].body.time and first_ego.time == egos[0].body.time
    assert r.trav.statistics()["maps_published"] == 5


async def test_get_wait_times_out_without_a_new_map():
    async with rig(MapUpdateTime=60.0) as r:
        r.publish()
        before = r.clock.monotonic()
        with pytest.raises(ETimeOut):
            await r.proxy.getWaitTravMapArray()
        with pytest.raises(ETimeOut):
            await r.proxy.getWaitEtravMapArray()
        assert r.clock.monotonic() - before == pytest.approx(2 * TravMap.wait_timeout)


@pytest.mark.parametrize("switch, served, refused", [
    ("GlobalMap", "getEtravMapArray", "getTravMapArray"),
    ("EgoMap", "getTravMapArray", "getEtravMapArray"),
])
async def test_each_map_can_be_switched_off(switch, served, refused):
    async with rig(MapUpdateTime=2.0, **{switch: False}) as r:
        await r.feed(4.0)
        await getattr(r.proxy, served)()
        with pytest.raises(EDevIO, match=f"{switch} is false"):
            await getattr(r.proxy, refused)()
        events, egos = drain(r.events), drain(r.ego_events)
    assert (events == []) == (switch == "GlobalMap")
    assert (egos == []) == (switch == "EgoMap")


# --- bad input ----------------------------------------------------------------------------


async def test_a_terrain_map_from_the_future_is_counted_and_ignored():
    async with rig(MapUpdateTime=2.0) as r:
        await r.feed(4.0)
        before = await r.proxy.getTravMapArray()
        future = r.clock.now() + 3600.0
        world, ego = terrain_maps(future)
        moved = world.model_copy(update={"elevation": np.full_like(world.elevation, 5.0)})
        r.system.channel.publish("Raptor", "Terrain", moved)
        r.system.channel.publish("Raptor", "TerrainEgo", ego)
        await r.clock.sleep(1.0)
        health = r.health()
        after = await r.proxy.getTravMapArray()
        stats = r.trav.statistics()
        await r.feed(3.0)
        recovered = r.health()
    assert stats["future_maps"] == 2
    assert not health.healthy and "Terrain maps stamped in the future" in health.detail
    assert "TerrainEgo maps stamped in the future" in health.detail
    assert after.time.to_seconds() < future  # still the present map
    assert np.array_equal(after.hazard, before.hazard, equal_nan=True)
    assert recovered.healthy


async def test_a_terrain_map_on_another_grid_is_counted_and_ignored():
    async with rig(MapUpdateTime=2.0) as r:
        await r.feed(4.0)
        before = await r.proxy.getTravMapArray()
        world, _ = terrain_maps(r.clock.now(), gridsize=1.0)  # flat everywhere, 1 m cells
        r.system.channel.publish("Raptor", "Terrain", world)
        await r.clock.sleep(1.0)
        health = r.health()
        after = await r.proxy.getTravMapArray()
        stats = r.trav.statistics()
    assert stats["grid_mismatch"] == 1
    assert not health.healthy
    assert "Terrain maps with 1 m cells, not the 0.2 m of their description" in health.detail
    assert np.array_equal(after.hazard, before.hazard, equal_nan=True)
    assert math.isnan(after.hazard[0, 0])  # the 1 m map would have made it known


async def test_the_description_names_the_expected_grid():
    """With a description of 1 m terrain cells, the 1 m map is the right one."""
    async with rig(MapUpdateTime=1.0, EgoMap=False,
                   TerrainMapDescription={"Gridsize": 1000}) as r:
        for _ in range(4):
            world, _ = terrain_maps(r.clock.now(), gridsize=1.0)
            r.system.channel.publish("Raptor", "Terrain", world)
            await r.clock.sleep(0.5)
        trav = await r.proxy.getTravMapArray()
        stats = r.trav.statistics()
    assert stats["grid_mismatch"] == 0 and stats["terrain_maps"] == 4
    assert trav.gridsize == COARSE
