"""The Traversability Map (seed §3.2.2, Tables 15–17, A.7): terrain maps into hazard and
goodness grids on a coarser grid.

- Subscribes to the Terrain Map's global map (``TerrainMapDescription.EventName``,
  MapArrayEventIDL) and ego map (``<EventName>Ego``, EgoMapArrayEventIDL; Table 17).
- Every ``MapEventInterval`` seconds, once ``MapUpdateTime`` has passed since it started
  empty, it computes from the latest of each (:mod:`components.traversability_map.hazards`:
  step and slope hazards, far-field scaling beyond ``Farfield``, negative obstacles,
  goodness) and publishes the global map (``GlobalTravMapDescription``, when ``GlobalMap``)
  as TravMapArrayEventIDL and the ego map (``EgoTravMapDescription``, event name with the
  ``Ego`` suffix, when ``EgoMap``) as EtravMapArrayEventIDL. Unknown cells stay NaN.
- ``vehiclePosition`` and ``vehicleHeading`` are those of the ego map's frame (the ground
  under the front bumper) at the map's time.
- Bad input is counted in ``statistics()`` and ignored, and makes the component unhealthy
  for ``BAD_INPUT_WINDOW`` seconds, the health detail naming it
  (:mod:`components.bad_input`): a terrain map stamped in the future (more than
  ``FUTURE_TOLERANCE`` ahead of the clock; ``future_maps``), and a terrain map whose cell
  size is not the one its description (``TerrainMapDescription`` or
  ``EgoTerrainMapDescription``) names (``grid_mismatch``): the configuration says which
  terrain map this component reads, and the hazard rules' resampling assumes it (a 1 m
  terrain grid, for one, fills only one 0.5 m traversability cell in four).
- Serves TravMap (Table 16) under the global map's event name.
"""

from __future__ import annotations

import math
from typing import Any

from afa import Event, SubscribePublishServer
from afa.clock import TIME_TOLERANCE
from afa.errors import EDevIO
from components.bad_input import BAD_INPUT_WINDOW, FUTURE_TOLERANCE, BadInputLog
from components.terrain_map.grid import GridGeometry, TerrainLayers, yaw_of
from components.traversability_map.hazards import (
    HazardRules,
    LastSeenTracker,
    TraversabilityLayers,
    TraversabilityMapper,
)
from components.traversability_map.parameters import (
    MapDescription,
    TraversabilityMapParameters,
)
from idl import (
    EgoMapArrayEventIDL,
    EtravMapArrayEventIDL,
    MapArrayEventIDL,
    Position3DIDL,
    TravMap,
    TravMapArrayEventIDL,
)

__all__ = ["TraversabilityMap", "FUTURE_TOLERANCE"]


class TraversabilityMap(SubscribePublishServer[TraversabilityMapParameters]):
    """The Traversability Map (module docstring)."""

    def __init__(self, name: str, parameters: TraversabilityMapParameters | None = None,
                 ) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        global_name = p.GlobalTravMapDescription.EventName
        self.maps = self.publishes(global_name, TravMapArrayEventIDL, enabled=p.GlobalMap)
        self.ego_maps = self.publishes(p.EgoTravMapDescription.EventName + "Ego",
                                       EtravMapArrayEventIDL, enabled=p.EgoMap)
        if p.GlobalMap:
            self.subscribes(p.TerrainMapDescription.EventName, MapArrayEventIDL,
                            self._on_terrain, maxsize=2, required=True)
        if p.EgoMap:
            self.subscribes(p.EgoTerrainMapDescription.EventName + "Ego", EgoMapArrayEventIDL,
                            self._on_ego_terrain, maxsize=2, required=True)
        self.serves(TravMap, global_name)
        self.rules = HazardRules.from_parameters(p)
        self._global = TraversabilityMapper(self.rules)
        self._ego = TraversabilityMapper(self.rules)
        self._global_seen = LastSeenTracker()
        self._ego_seen = LastSeenTracker()
        self.terrain: MapArrayEventIDL | None = None
        self.ego_terrain: EgoMapArrayEventIDL | None = None
        self._filling_since = 0.0
        self.bad_input = BadInputLog(BAD_INPUT_WINDOW)
        self.counters = {"terrain_maps": 0, "future_maps": 0, "grid_mismatch": 0,
                         "maps_published": 0}

    async def setup(self) -> None:
        self.latest_map = self.slot("traversability map")
        self.latest_ego = self.slot("egocentric traversability map")
        self._filling_since = self.clock.monotonic()
        self.bad_input.clear()
        # a restart (after a failure, or a replay going back) starts from no terrain
        self.terrain = self.ego_terrain = None
        self._global_seen, self._ego_seen = LastSeenTracker(), LastSeenTracker()

    async def run(self) -> None:
        async for _ in self.clock.periodic(self.parameters.MapEventInterval):
            self._update_health()
            if (self.clock.monotonic() - self._filling_since
                    >= self.parameters.MapUpdateTime - TIME_TOLERANCE):
                self._publish()

    def _update_health(self) -> None:
        problems = self.bad_input.recent(self.clock.monotonic())
        self.set_health(not problems, "; ".join(problems))

    def _bad(self, counter: str, what: str) -> None:
        self.counters[counter] += 1
        self.bad_input.note(what, self.clock.monotonic())
        self._update_health()

    def _accept(self, event: Event, description: MapDescription) -> bool:
        """Whether a terrain map is fresh and on the grid its description names."""
        body: MapArrayEventIDL | EgoMapArrayEventIDL = event.body  # type: ignore[assignment]
        if body.time.to_seconds() > self.clock.now() + FUTURE_TOLERANCE:
            self._bad("future_maps", f"{event.type} maps stamped in the future (ignored)")
            return False
        expected = description.Gridsize / 1000.0
        if not math.isclose(body.gridsize, expected, rel_tol=1e-9):
            self._bad("grid_mismatch", f"{event.type} maps with {body.gridsize:g} m cells, "
                                       f"not the {expected:g} m of their description "
                                       "(ignored)")
            return False
        self.counters["terrain_maps"] += 1
        return True

    def _on_terrain(self, event: Event) -> None:
        if self._accept(event, self.parameters.TerrainMapDescription):
            self.terrain = event.body  # type: ignore[assignment]

    def _on_ego_terrain(self, event: Event) -> None:
        if self._accept(event, self.parameters.EgoTerrainMapDescription):
            self.ego_terrain = event.body  # type: ignore[assignment]

    def _publish(self) -> None:
        p = self.parameters
        ego = self.ego_terrain
        vehicle = (float(ego.mapPose[0, 3]), float(ego.mapPose[1, 3])) if ego is not None \
            else None
        heading = yaw_of(ego.mapPose) if ego is not None else 0.0
        if self.terrain is not None and p.GlobalMap:
            terrain = self.terrain
            fine = _layers(terrain, self._global_seen)
            description = p.GlobalTravMapDescription
            centre = vehicle if vehicle is not None else _centre(fine.geometry)
            coarse = GridGeometry.centred(*centre, description.Depth / 1000.0,
                                          description.Width / 1000.0,
                                          description.Gridsize / 1000.0)
            layers = self._global.update(fine, coarse, centre, terrain.time.to_seconds())
            body = TravMapArrayEventIDL(**_header(terrain, layers, centre, heading))
            self.latest_map.set(body)
            self.maps.publish(body)
        if ego is not None and p.EgoMap:
            fine = _layers(ego, self._ego_seen)
            description = p.EgoTravMapDescription
            g = description.Gridsize / 1000.0
            rows = int(round(description.Depth / description.Gridsize))
            cols = int(round(description.Width / description.Gridsize))
            coarse = GridGeometry(ego.originX, -cols * g / 2.0, g, rows, cols)
            layers = self._ego.update(fine, coarse, (0.0, 0.0), ego.time.to_seconds())
            assert vehicle is not None
            ego_body = EtravMapArrayEventIDL(**_header(ego, layers, vehicle, heading))
            self.latest_ego.set(ego_body)
            self.ego_maps.publish(ego_body)
        self.counters["maps_published"] += 1

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        return stats

    # -- TravMap (Table 16) ----------------------------------------------------------------
    async def getTravMapArray(self) -> TravMapArrayEventIDL:
        return self._slot(self.latest_map, "GlobalMap").get()  # type: ignore[no-any-return]

    async def getWaitTravMapArray(self) -> TravMapArrayEventIDL:
        return await self._slot(self.latest_map, "GlobalMap").wait_next(  # type: ignore[no-any-return]
            TravMap.wait_timeout)

    async def getEtravMapArray(self) -> EtravMapArrayEventIDL:
        return self._slot(self.latest_ego, "EgoMap").get()  # type: ignore[no-any-return]

    async def getWaitEtravMapArray(self) -> EtravMapArrayEventIDL:
        return await self._slot(self.latest_ego, "EgoMap").wait_next(  # type: ignore[no-any-return]
            TravMap.wait_timeout)

    def _slot(self, slot: Any, switch: str) -> Any:
        if not getattr(self.parameters, switch):
            raise EDevIO(f"{self.name} makes no such map ({switch} is false)")
        return slot


def _layers(terrain: MapArrayEventIDL | EgoMapArrayEventIDL,
            seen: LastSeenTracker) -> TerrainLayers:
    geometry = GridGeometry(terrain.originX, terrain.originY, terrain.gridsize, terrain.rows,
                            terrain.cols)
    return TerrainLayers(geometry=geometry, elevation=terrain.elevation,
                         min_height=terrain.minHeight, max_height=terrain.maxHeight,
                         count=terrain.pointCount, variance=terrain.variance,
                         last_seen=seen.update(geometry, terrain.pointCount,
                                               terrain.time.to_seconds()))


def _centre(geometry: GridGeometry) -> tuple[float, float]:
    return (geometry.origin_x + geometry.rows * geometry.gridsize / 2.0,
            geometry.origin_y + geometry.cols * geometry.gridsize / 2.0)


def _header(terrain: MapArrayEventIDL | EgoMapArrayEventIDL, layers: TraversabilityLayers,
            vehicle: tuple[float, float], heading: float) -> dict[str, Any]:
    geo = layers.geometry
    return {"time": terrain.time, "frame": terrain.frame, "mapPose": terrain.mapPose,
            "initialUTM": terrain.initialUTM, "gridsize": geo.gridsize,
            "originX": geo.origin_x, "originY": geo.origin_y, "rows": geo.rows,
            "cols": geo.cols, "hazard": layers.hazard, "goodness": layers.goodness,
            "vehiclePosition": Position3DIDL(x=vehicle[0], y=vehicle[1]),
            "vehicleHeading": heading}



