"""The Terrain Map (seed §3.2.1, Tables 11–14, A.6): laser and stereo returns fused into
2.5-D grids.

- At start it polls ModelServer (``PlatformEvent``) for ``getTransformation`` of the frames
  its parameters name (``GroundFrame``, ``SickLaserFrame1/2``, ``DigiclopsFrame``), and
  of any other frame a scan names, once each.
- It subscribes to ``RangeEventName1..3`` (laser scan lines in either form, stereo frames
  in either form) and to ``PoseEventName``. Each scan is placed with the pose at its own
  time stamp (:class:`~components.terrain_map.grid.PoseBuffer`: interpolated between
  poses; a scan newer than the newest pose waits for the next one, for at most
  ``PENDING_LIMIT`` seconds; a scan older than the buffer is counted and dropped). The
  pose audit of Table A.6 (``MaxVelocity``, ``PoseInterval``, ``OrientationDevError``)
  refuses pose jumps the vehicle could not make: scans in such an interval are counted,
  not fused. Invalid poses (``poseValidFlag`` false) are counted and not used. Stereo
  frames are decimated so that they add no more points than the lasers gave in
  ``StereoPeriod`` (:class:`~components.terrain_map.grid.StereoBalance`).
- Bad input (:mod:`components.bad_input`) is counted in ``statistics()`` and makes the
  component unhealthy for ``BAD_INPUT_WINDOW`` seconds, its detail naming what was
  refused: non-finite points (dropped; the scan's finite points are fused), a scan in a
  frame ModelServer does not know, a scan older than the pose buffer, a scan in a pose
  jump, a scan for which no pose came within ``PENDING_LIMIT``, a malformed scan or pose (one
  that bypassed the IDL's validation), a pose stamped in the future. It is unhealthy
  as long as the latest pose is marked invalid, and as long as ModelServer does not
  know the ground frame. Scans that arrive before the map's first pose (at start, or
  after the pose frame's origin moved) are routine: counted as ``before_pose``.
- Placement (:mod:`components.terrain_map.stabiliser`): a 2.5-D map stitches scans
  taken seconds apart, so the vehicle's position must be consistent over seconds, which
  the GPS's (the RT-20's correlated decimetres) is not. Scans are placed with a height
  predicted from the vehicle's motion (the forward part of the measured motion times
  the slope of its x axis, from the IMU's attitude) and pulled towards the GPS's with
  600 s. When ``OdometryEventName`` names the wheel reports (off in the shipped
  configuration, decision 0033), the whole position is predicted from the rear axle's
  distance rolled along that axis, and pulled towards the GPS's with 10 s horizontally.
- The *global* map (``Depth`` × ``Width`` at ``Gridsize``, frame ``World``: metres from
  ``initialUTM``, north up) scrolls with the vehicle, centred on the ground frame (the
  front bumper), so the ego view ahead stays inside it. A cell's min and max heights
  cover its latest ``EXTREMES_WINDOW`` to twice that seconds of observation (the grid's
  generations, decision 0040): the placement's error wanders, and over minutes of
  watching one cell its extremes would grow into a step. The *ego* map
  (``EgoDepth`` × ``EgoWidth`` ahead of the bumper, heading-aligned, ground
  ``BumperHeight`` below the bumper) is a view of it at each publication.
- Publication: every ``MapEventInterval`` seconds once ``MapUpdateTime`` has passed since
  the map was (re)started empty, when ``notify`` is true: ``<EventName>``
  (MapArrayEventIDL), ``<EventName>Ego`` (EgoMapArrayEventIDL), and the sequence forms
  ``<EventName>Seq`` / ``<EventName>EgoSeq`` when someone subscribes to them (one event
  name carries one type, so the forms get suffixes, as the lasers' ``Array`` form does).
- Serves the Map interface (Table 12) under ``EventName``.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, cast

import numpy as np

from afa import EOutOfBounds, Event, SubscribePublishServer
from afa.clock import TIME_TOLERANCE
from afa.errors import AfaError, EDevIO
from components.bad_input import BAD_INPUT_WINDOW, FUTURE_TOLERANCE, BadInputLog
from components.terrain_map.grid import (
    EgoView,
    PoseAudit,
    PoseBuffer,
    PoseStatus,
    StereoBalance,
    TerrainGrid,
    TerrainLayers,
    ego_map_pose,
)
from components.terrain_map.parameters import TerrainMapParameters
from components.terrain_map.stabiliser import PoseStabiliser
from components.trusted import trusted
from components.waypoints import VEHICLE_FRAME
from idl import (
    EgoMapArrayEventIDL,
    EgoMapSeqEventIDL,
    Map,
    MapArrayEventIDL,
    MapSeqEventIDL,
    Platform,
    PoseTransformIDL,
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
    TimeIDL,
    WheelDataIDL,
)

__all__ = ["TerrainMap", "VEHICLE_FRAME", "PENDING_LIMIT", "POSE_BUFFER", "EXTREMES_WINDOW"]

#: A scan newer than the newest pose waits this long (s) for the pose that follows it.
PENDING_LIMIT = 0.5
#: Poses kept for placing scans (ModelServer publishes ~14 a second: ~18 s).
POSE_BUFFER = 256
#: The length (s) of a cell's generations (:class:`TerrainGrid`): its min and max heights
#: cover its latest 30 to 60 s of observation.
EXTREMES_WINDOW = 30.0
_LASER = (Range3dSeqEventIDL, Range3dLaserIDL)
_STEREO = (Range3dArrayEventIDL, Range3dStereoEventIDL)
_RangeEvent = Range3dSeqEventIDL | Range3dLaserIDL | Range3dArrayEventIDL | Range3dStereoEventIDL


def frame_name(text: str) -> str:
    """``Body:Frame`` without the spaces the seed prints around the colon."""
    body, _, frame = text.partition(":")
    return f"{body.strip()}:{frame.strip()}"


class TerrainMap(SubscribePublishServer[TerrainMapParameters]):
    """The Terrain Map (module docstring)."""

    def __init__(self, name: str, parameters: TerrainMapParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self.ground_frame = frame_name(p.GroundFrame)
        self.maps = self.publishes(p.EventName, MapArrayEventIDL, enabled=p.notify)
        self.ego_maps = self.publishes(p.EventName + "Ego", EgoMapArrayEventIDL,
                                       enabled=p.notify)
        self.map_seqs = self.publishes(p.EventName + "Seq", MapSeqEventIDL, enabled=p.notify)
        self.ego_seqs = self.publishes(p.EventName + "EgoSeq", EgoMapSeqEventIDL,
                                       enabled=p.notify)
        for event_name, types in ((p.RangeEventName1, _LASER), (p.RangeEventName2, _LASER),
                                  (p.RangeEventName3, _STEREO)):
            if event_name:
                self.subscribes(event_name, types, self._on_scan, maxsize=64)
        self.subscribes(p.PoseEventName, PoseTransformIDL, self._on_pose, maxsize=64,
                        required=True)
        if p.OdometryEventName:
            self.subscribes(p.OdometryEventName, WheelDataIDL, self._on_odometry, maxsize=64)
        self.serves(Map, p.EventName)
        self.platform = self.uses(Platform, p.PlatformEvent)
        g = p.Gridsize / 1000.0
        self.grid = TerrainGrid.centred(0.0, 0.0, p.Depth / 1000.0, p.Width / 1000.0, g,
                                        window=EXTREMES_WINDOW)
        self.ego = EgoView.ahead(p.EgoDepth / 1000.0, p.EgoWidth / 1000.0, g)
        self.poses = PoseBuffer(POSE_BUFFER, PoseAudit.from_parameters(p))
        self.stabiliser = PoseStabiliser()
        self.stable = np.eye(4)  # the latest pose, placed by the stabiliser
        self.stereo = StereoBalance(p.StereoPeriod)
        self.frames: dict[str, np.ndarray | None] = {}
        self.initial_utm: np.ndarray | None = None
        self.pose: PoseTransformIDL | None = None
        self._pending: deque[tuple[float, Event]] = deque()
        self._filling_since = 0.0
        self._first_pose: float | None = None  # stamp of the first pose since a reset
        self._pose_invalid = False
        self.bad_input = BadInputLog(BAD_INPUT_WINDOW)
        self.counters = {"scans": 0, "points_fused": 0, "points_outside": 0,
                         "points_nonfinite": 0, "invalid_poses": 0, "too_old": 0,
                         "future_dropped": 0, "implausible": 0, "unknown_frames": 0,
                         "no_geometry": 0, "malformed_scans": 0, "malformed_poses": 0,
                         "future_poses": 0, "malformed_odometry": 0, "before_pose": 0,
                         "maps_published": 0, "resets": 0}

    async def setup(self) -> None:
        self.latest_map = self.slot("terrain map")
        self.latest_ego = self.slot("egocentric terrain map")
        self.latest_seq = self.slot("terrain map (sequence)")
        self.latest_ego_seq = self.slot("egocentric terrain map (sequence)")
        self._pose_invalid = False
        self.bad_input.clear()
        self._reset()

    async def run(self) -> None:
        await self.bound(self.platform)
        p = self.parameters
        for text in (p.GroundFrame, p.SickLaserFrame1, p.SickLaserFrame2, p.DigiclopsFrame):
            await self._transform(frame_name(text))
        self._update_health()
        async for _ in self.clock.periodic(p.MapEventInterval):
            self._expire_pending()
            self._update_health()
            self._publish()

    # -- health ------------------------------------------------------------------------------
    def _bad(self, counter: str, what: str, count: int = 1) -> None:
        """Count ``count`` refused inputs under ``counter`` and note ``what`` for health."""
        self.counters[counter] += count
        self.bad_input.note(what, self.clock.monotonic())
        self._update_health()

    def _update_health(self) -> None:
        problems = []
        if self.ground_frame in self.frames and self.frames[self.ground_frame] is None:
            problems.append(f"ModelServer does not know the ground frame "
                            f"{self.ground_frame}: no ego map")
        if self._pose_invalid:
            problems.append("the latest pose is marked invalid (poseValidFlag false): "
                            "scans wait for a valid one")
        problems += self.bad_input.recent(self.clock.monotonic())
        self.set_health(not problems, "; ".join(problems))

    # -- inputs -----------------------------------------------------------------------------
    def _on_pose(self, event: Event) -> None:
        pose: PoseTransformIDL = event.body  # type: ignore[assignment]
        transform = np.asarray(pose.HTransform)
        utm_ok = np.shape(pose.initialUTM) == (3,) and np.all(np.isfinite(pose.initialUTM))
        if transform.shape != (4, 4) or not np.all(np.isfinite(transform)) or not utm_ok:
            self._bad("malformed_poses", f"malformed poses on {event.type} (ignored)")
            return
        stamp = pose.time.to_seconds()
        if stamp > self.clock.now() + FUTURE_TOLERANCE:
            self._bad("future_poses", f"poses on {event.type} stamped in the future "
                                      "(ignored)")
            return
        if not pose.poseValidFlag:
            self.counters["invalid_poses"] += 1
            if not self._pose_invalid:
                self._pose_invalid = True
                self._update_health()
            return
        if self._pose_invalid:
            self._pose_invalid = False
            self._update_health()
        utm = pose.initialUTM
        if self.initial_utm is None or not np.array_equal(utm, self.initial_utm):
            if self.initial_utm is not None:
                self.log.warning("%s: the pose frame's origin moved (initialUTM): the map "
                                 "starts again", self.name)
            self.initial_utm = np.array(utm)
            self._reset()
        if self._first_pose is None:
            self._first_pose = stamp
        self.stable = self.stabiliser(stamp, pose.HTransform)
        self.poses.add(stamp, self.stable)  # audited (and counted) there
        self.pose = pose
        ground = self.frames.get(self.ground_frame)
        bumper = (pose.HTransform @ ground)[:3, 3] if ground is not None \
            else pose.HTransform[:3, 3]
        self.grid.recentre(float(bumper[0]), float(bumper[1]), slack=2)
        self._retry_pending()

    def _on_odometry(self, event: Event) -> None:
        wheels: WheelDataIDL = event.body  # type: ignore[assignment]
        values = (wheels.time.to_seconds(), wheels.leftDistance, wheels.rightDistance,
                  wheels.leftSpeed, wheels.rightSpeed, wheels.steeringAngle)
        if not all(math.isfinite(v) for v in values):
            self._bad("malformed_odometry", f"malformed {event.type} reports (ignored)")
            return
        self.stabiliser.odometry.add(*values)

    async def _on_scan(self, event: Event) -> None:
        scan: _RangeEvent = event.body  # type: ignore[assignment]
        points = np.asarray(scan.points)
        valid = getattr(scan, "valid", None)  # the static-array forms' flags
        if (points.ndim < 2 or points.shape[-1] != 3 or not isinstance(scan.frame, str)
                or (valid is not None and np.shape(valid) != points.shape[:-1])):
            self._bad("malformed_scans", f"malformed {event.type} scans (ignored)")
            return
        transform = await self._transform(scan.frame)
        if transform is None:
            if frame_name(scan.frame) in self.frames:
                self._bad("unknown_frames", f"{event.type} scans in frame "
                                            f"{frame_name(scan.frame)!r}, which ModelServer "
                                            "does not know (ignored)")
            else:
                self._bad("no_geometry", f"{event.type} scans while ModelServer could not "
                                         "be asked for their frame (ignored)")
            return
        self._place(event, transform)

    def _place(self, event: Event, transform: np.ndarray) -> None:
        scan: _RangeEvent = event.body  # type: ignore[assignment]
        stamp = scan.time.to_seconds()
        found = self.poses.lookup(stamp)
        if found.status is PoseStatus.FUTURE or found.status is PoseStatus.EMPTY:
            self._pending.append((self.clock.monotonic(), event))
            return
        if found.status is PoseStatus.TOO_OLD:
            if self._first_pose is not None and stamp < self._first_pose:
                self.counters["before_pose"] += 1  # the map started after this scan
            else:
                self._bad("too_old", f"{event.type} scans older than the pose buffer "
                                     "(dropped)")
            return
        if found.status is PoseStatus.IMPLAUSIBLE:
            self._bad("implausible", f"{event.type} scans during a pose jump the vehicle "
                                     "cannot make (not fused)")
            return
        assert found.transform is not None
        points = scan.valid_points()
        if isinstance(scan, _STEREO):
            points = self.stereo.select(stamp, points)
        else:
            self.stereo.note_laser(stamp, len(points))
        stats = self.grid.fuse_transformed(points, found.transform @ transform, stamp)
        self.counters["scans"] += 1
        self.counters["points_fused"] += stats.fused
        self.counters["points_outside"] += stats.outside
        if stats.nonfinite:
            self._bad("points_nonfinite", f"non-finite points in {event.type} scans "
                                          "(dropped)", stats.nonfinite)

    def _retry_pending(self) -> None:
        now = self.clock.monotonic()
        pending, self._pending = self._pending, deque()
        for queued, event in pending:
            if now - queued > PENDING_LIMIT:
                self._drop_late(event)
                continue
            transform = self.frames.get(frame_name(event.body.frame))  # type: ignore[attr-defined]
            if transform is not None:
                self._place(event, transform)

    def _expire_pending(self) -> None:
        """Drop scans no pose has come for within PENDING_LIMIT (poses stopped)."""
        now = self.clock.monotonic()
        while self._pending and now - self._pending[0][0] > PENDING_LIMIT:
            self._drop_late(self._pending.popleft()[1])

    def _drop_late(self, event: Event) -> None:
        self._bad("future_dropped", f"{event.type} scans dropped: no pose came within "
                                    f"{PENDING_LIMIT:g} s of them")

    async def _transform(self, frame: str) -> np.ndarray | None:
        """^V T_frame from ModelServer, polled once per frame (None if unknown)."""
        frame = frame_name(frame)
        if frame in self.frames:
            return self.frames[frame]
        try:
            pose = await self.platform.getTransformation(VEHICLE_FRAME, frame)
        except EOutOfBounds as exc:
            self.log.warning("%s: ModelServer does not know frame %r (%s): its scans are "
                             "ignored", self.name, frame, exc)
            self.frames[frame] = None
            return None
        except AfaError:
            return None  # ModelServer not reachable yet: the next scan asks again
        self.frames[frame] = np.asarray(pose.HTransform, dtype=np.float64)
        return self.frames[frame]

    def _reset(self) -> None:
        self.grid.reset()
        self.poses = PoseBuffer(POSE_BUFFER, self.poses.audit)
        self.stabiliser.reset()
        self.counters["before_pose"] += len(self._pending)
        self._pending.clear()
        self._first_pose = None
        self._filling_since = self.clock.monotonic()
        self.counters["resets"] += 1

    # -- outputs -----------------------------------------------------------------------------
    def _publish(self) -> None:
        if self.pose is None or self.initial_utm is None:
            return
        if (self.clock.monotonic() - self._filling_since
                < self.parameters.MapUpdateTime - TIME_TOLERANCE):
            return  # a cleared map is still filling (Table A.6 MapUpdateTime)
        stamp = TimeIDL.from_seconds(self.clock.now())
        layers = self.grid.layers()
        terrain = trusted(MapArrayEventIDL, **_header(layers, stamp, "World", np.eye(4),
                                                      self.initial_utm), **_layers(layers))
        self.latest_map.set(terrain)
        self.maps.publish(terrain)
        if self.map_seqs.subscribed:
            seq = cast(MapSeqEventIDL, terrain.to_seq())
            self.latest_seq.set(seq)
            self.map_seqs.publish(seq)
        ground = self.frames.get(self.ground_frame)
        if ground is not None:
            pose = ego_map_pose(self.stable, ground,
                                self.parameters.BumperHeight / 1000.0)
            ego_layers = self.ego.sample(self.grid, pose)
            ego = trusted(EgoMapArrayEventIDL, **_header(ego_layers, stamp, self.ground_frame,
                                                         pose, self.initial_utm),
                          **_layers(ego_layers))
            self.latest_ego.set(ego)
            self.ego_maps.publish(ego)
            if self.ego_seqs.subscribed:
                ego_seq = cast(EgoMapSeqEventIDL, ego.to_seq())
                self.latest_ego_seq.set(ego_seq)
                self.ego_seqs.publish(ego_seq)
        self.counters["maps_published"] += 1

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        stats["pending_scans"] = len(self._pending)
        stats["poses"] = dict(self.poses.statistics)
        stats["placement"] = {**self.stabiliser.counts,
                              "odometry_restarts": self.stabiliser.odometry.restarts}
        return stats

    # -- Map (Table 12) ----------------------------------------------------------------------
    async def getMapArray(self) -> MapArrayEventIDL:
        return self.latest_map.get()  # type: ignore[no-any-return]

    async def getWaitMapArray(self) -> MapArrayEventIDL:
        return await self.latest_map.wait_next(Map.wait_timeout)  # type: ignore[no-any-return]

    async def getMapSeq(self) -> MapSeqEventIDL:
        return self.latest_map.get().to_seq()  # type: ignore[no-any-return]

    async def getWaitMapSeq(self) -> MapSeqEventIDL:
        return (await self.latest_map.wait_next(Map.wait_timeout)).to_seq()  # type: ignore[no-any-return]

    async def getEgoMapArray(self) -> EgoMapArrayEventIDL:
        return self._ego_slot().get()  # type: ignore[no-any-return]

    async def getWaitEgoMapArray(self) -> EgoMapArrayEventIDL:
        return await self._ego_slot().wait_next(Map.wait_timeout)  # type: ignore[no-any-return]

    async def getEgoMapSeq(self) -> EgoMapSeqEventIDL:
        return self._ego_slot().get().to_seq()  # type: ignore[no-any-return]

    async def getWaitEgoMapSeq(self) -> EgoMapSeqEventIDL:
        return (await self._ego_slot().wait_next(Map.wait_timeout)).to_seq()  # type: ignore[no-any-return]

    def _ego_slot(self) -> Any:
        if self.frames.get(self.ground_frame) is None and self.latest_ego.version == 0:
            raise EDevIO(f"{self.name} has no ego map: ModelServer does not know the ground "
                         f"frame {self.ground_frame}")
        return self.latest_ego


def _header(layers: TerrainLayers, stamp: TimeIDL, frame: str, map_pose: np.ndarray,
            initial_utm: np.ndarray) -> dict[str, Any]:
    geo = layers.geometry
    return {"time": stamp, "frame": frame, "mapPose": map_pose, "initialUTM": initial_utm,
            "gridsize": geo.gridsize, "originX": geo.origin_x, "originY": geo.origin_y,
            "rows": geo.rows, "cols": geo.cols}


def _layers(layers: TerrainLayers) -> dict[str, Any]:
    return {"elevation": layers.elevation, "minHeight": layers.min_height,
            "maxHeight": layers.max_height, "pointCount": layers.count,
            "variance": layers.variance}

