"""ModelServer (seed §3.2.4): the geometry database and the pose filter, served together.

- Geometry: the assembly file ``ModelFileName`` (relative to the configuration's folder)
  is loaded at start; the Platform interface answers ``getTransformation(A, B)``,
  ``getBodyList()`` and ``getBodyFrameList(body)`` (Table 19) under every name of
  ``OfferedNames`` whose type is ``Platform`` (``Raptor/ModelService`` by default).
- Pose: a Subscribe-Publish Server. It subscribes to the events named in
  ``Subscriptions`` (Gps, Imu; odometry too when listed: Table 20), feeds them to the
  EKF (:class:`PoseFilter`) or, with ``UseRawPose``, to the unfiltered solution
  (:class:`RawPose`), and publishes ``Pose`` (PoseTransformIDL, Table 21) under each
  ``Publications`` name: on every input event when ``UpdatePeriod`` is 0, else every
  ``UpdatePeriod`` ms. ``initialUTM`` is the first GPS fix (easting, northing, elevation);
  ``HTransform`` is ^W T_V of ``Raptor:RearAxleCenter`` measured from it.
- Sensor geometry comes from the model: the GPS antenna lever arm
  (``GpsAntenna:PhaseCenter`` in the vehicle frame) and the IMU's mounting rotation
  (``Imu:SensorCenter``), so the 3DM-GX1's z-down rates become the vehicle's yaw rate.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from afa import ComponentError, EOutOfBounds, Event, SubscribePublishServer
from components.gps_sokkia.codec import grid_convergence, latlon_to_utm
from components.model_server.geometry import GeometryModel
from components.model_server.parameters import ModelServerParameters
from components.model_server.pose_filter import (
    PoseFilter,
    PoseFilterTuning,
    PoseUnavailableError,
    RawPose,
    enu_attitude_from_ned,
)
from components.waypoints import VEHICLE_FRAME
from idl import GpsIDL, ImuIDL, Platform, PoseTransformIDL, StringSequenceIDL, TimeIDL, WheelDataIDL

__all__ = ["ModelServer", "VEHICLE_FRAME", "ANTENNA_FRAME", "IMU_FRAME"]

ANTENNA_FRAME = "GpsAntenna:PhaseCenter"
IMU_FRAME = "Imu:SensorCenter"
#: The Raptor's geometry model that afa ships (the default ModelFileName names it).
SHIPPED_MODEL = Path(__file__).resolve().parents[2] / "configs" / "050917raptor01.XML"


#: Table A.8's IDL-type names, as the Subscriptions list spells them, and their types.
SUBSCRIPTION_TYPES: dict[str, type[GpsIDL] | type[ImuIDL] | type[WheelDataIDL]] = {
    "Gps": GpsIDL, "GpsIDL": GpsIDL, "Imu": ImuIDL, "ImuIDL": ImuIDL,
    "Odometry": WheelDataIDL, "WheelDataIDL": WheelDataIDL, "WheelEventIDL": WheelDataIDL,
    "RaptorOdometry": WheelDataIDL}


class ModelServer(SubscribePublishServer[ModelServerParameters]):
    """Geometry database + pose estimation (seed §3.2.4, Tables 19–21, A.8)."""

    def __init__(self, name: str, parameters: ModelServerParameters | None = None) -> None:
        super().__init__(name, parameters)
        self.model: GeometryModel | None = None
        self.initial_utm: np.ndarray | None = None
        self._grid: tuple[int, str] = (0, "N")  # UTM zone and hemisphere of initial_utm
        self.gps_regridded = 0  # fixes moved into that grid from the receiver's next one
        #: the grid's rotation from true east and north here (rad, counter-clockwise):
        #: true ENU yaw + convergence = the pose frame's yaw (0 before the first fix)
        self.convergence = 0.0
        self.inputs = {"gps": 0, "imu": 0, "odometry": 0}
        self.poses_published = 0
        # replaced in setup by the configured filter; an empty one until then
        self.filter: PoseFilter | RawPose = RawPose("imu")
        description = self.parameters.EventChannelDescription
        self.publishers = [self.publishes(b.Name, PoseTransformIDL)
                           for b in description.Publications]
        for binding in description.OfferedNames:
            if binding.Type == "Platform":
                self.serves(Platform, binding.Name)
        handlers = {GpsIDL: self._on_gps_event, ImuIDL: self._on_imu_event,
                    WheelDataIDL: self._on_odometry_event}
        for binding in description.Subscriptions:
            body_type = SUBSCRIPTION_TYPES.get(binding.Type)
            if body_type is None:
                raise ComponentError(
                    f"{name}: Subscriptions names IDL type {binding.Type!r} for "
                    f"{binding.Name!r}; ModelServer fuses {', '.join(SUBSCRIPTION_TYPES)}")
            self.subscribes(binding.Name, body_type, handlers[body_type], maxsize=64,
                            required=True)

    # -- lifecycle ---------------------------------------------------------------------
    async def setup(self) -> None:
        p = self.parameters
        self.model = GeometryModel.load(self.model_path(self.context.base_dir))
        antenna = self.model.transformation(VEHICLE_FRAME, ANTENNA_FRAME)[:3, 3]
        self._imu_rotation = self.model.transformation(VEHICLE_FRAME, IMU_FRAME)[:3, :3]
        offset = (float(antenna[0]), float(antenna[1]), float(antenna[2]))
        if p.UseRawPose:
            # GPS position with the IMU's attitude: the GPS track is erratic at low speed
            self.filter = RawPose("imu", antenna_offset=offset)
        else:
            self.filter = PoseFilter(PoseFilterTuning(
                fidget_delay=p.FidgetDelay, fidget_period=p.FidgetPeriod,
                antenna_offset=offset))
        self.latest = self.slot("pose")

    def model_path(self, base_dir: Path) -> Path:
        """The geometry assembly file: ``ModelFileName``, relative to ``base_dir``."""
        name = self.parameters.ModelFileName
        path = Path(name)
        if path.is_absolute():
            return path
        path = base_dir / path
        default = ModelServerParameters.model_fields["ModelFileName"].default
        if not path.exists() and name == default and SHIPPED_MODEL.exists():
            # the default names the Raptor's geometry, which afa ships (a file from
            # `afa config defaults` need not sit beside a copy of it)
            self.log.info("no %s beside the configuration: using the shipped %s",
                          name, SHIPPED_MODEL)
            return SHIPPED_MODEL
        return path

    def check_files(self, base_dir: Path) -> None:
        GeometryModel.load(self.model_path(base_dir))

    async def run(self) -> None:
        period = self.parameters.UpdatePeriod
        if period > 0:
            async for _ in self.clock.periodic(period / 1000.0):
                self._publish()

    # -- pose ---------------------------------------------------------------------------
    def _on_gps_event(self, event: Event) -> None:
        self._on_gps(event.time, event.body)  # type: ignore[arg-type]
        self._updated()

    def _on_imu_event(self, event: Event) -> None:
        self._on_imu(event.time, event.body)  # type: ignore[arg-type]
        self._updated()

    def _on_odometry_event(self, event: Event) -> None:
        self._on_odometry(event.time, event.body)  # type: ignore[arg-type]
        self._updated()

    def _updated(self) -> None:
        if self.parameters.UpdatePeriod == 0:
            self._publish()

    def _on_gps(self, t: float, gps: GpsIDL) -> None:
        self.inputs["gps"] += 1
        easting, northing = gps.easting, gps.northing
        grid = (gps.utmZone, "N" if gps.latitude >= 0 else "S")
        if self.initial_utm is None:
            self.initial_utm = np.array([easting, northing, gps.elevation])
            self._grid = grid
        elif grid != self._grid and self._grid[0]:
            # across a zone boundary or the equator the receiver changes grid; the pose
            # frame keeps the first fix's (its origin is in it), hundreds of km away
            try:
                utm = latlon_to_utm(gps.latitude, gps.longitude, zone=self._grid[0],
                                    hemisphere=self._grid[1])
            except ValueError:  # beyond the UTM latitudes: no position in this frame
                return
            easting, northing = utm.easting_m, utm.northing_m
            self.gps_regridded += 1
        if self._grid[0]:
            try:
                self.convergence = grid_convergence(gps.latitude, gps.longitude, *self._grid)
            except ValueError:  # beyond the UTM latitudes: keep the last one
                pass
        # the receiver's track is from true north; the pose frame's yaw from grid east
        track = math.radians(gps.track) - self.convergence
        if isinstance(self.filter, RawPose):
            self.filter.update_gps(t, easting, northing, speed=gps.horizontalSpeed,
                                   track=track, elevation=gps.elevation)
        else:
            std = max(0.05, math.hypot(gps.latitudeStd, gps.longitudeStd) / math.sqrt(2))
            self.filter.update_gps(t, easting, northing, std, speed=gps.horizontalSpeed,
                                   track=track, elevation=gps.elevation)

    def _on_imu(self, t: float, imu: ImuIDL) -> None:
        self.inputs["imu"] += 1
        roll, pitch, yaw = enu_attitude_from_ned(imu.roll, imu.pitch, imu.yaw)
        if isinstance(self.filter, RawPose):
            # the IMU's yaw is from true north; the pose frame's from the grid's axes
            self.filter.update_imu(t, yaw=yaw + self.convergence, roll=roll, pitch=pitch)
            return
        rates = self._imu_rotation @ np.array([imu.rateX, imu.rateY, imu.rateZ])
        self.filter.update_imu(t, float(rates[2]), roll=roll, pitch=pitch)

    def _on_odometry(self, t: float, wheels: WheelDataIDL) -> None:
        self.inputs["odometry"] += 1
        if isinstance(self.filter, PoseFilter):
            self.filter.update_odometry(t, wheels.leftDistance, wheels.rightDistance)

    def pose(self) -> PoseTransformIDL | None:
        """The current pose, or None before the first GPS fix."""
        if self.initial_utm is None:
            return None
        now = self.clock.now()
        try:
            if isinstance(self.filter, RawPose):
                # the fix is up to an epoch old: move it to the stamp (decision 0025)
                transform = self.filter.transform(self.initial_utm.tolist(), at=now)
            else:
                transform = self.filter.transform(self.initial_utm.tolist())
        except PoseUnavailableError:
            return None
        return PoseTransformIDL(time=TimeIDL.from_seconds(now),
                                HTransform=transform, initialUTM=self.initial_utm,
                                poseValidFlag=bool(self.filter.pose_valid))

    def _publish(self) -> None:
        pose = self.pose()
        if pose is None:
            return
        self.latest.set(pose)
        for publisher in self.publishers:
            publisher.publish(pose)
        self.poses_published += 1

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update({f"{k}_events": v for k, v in self.inputs.items()})
        stats["gps_regridded"] = self.gps_regridded
        stats["poses_published"] = self.poses_published
        if isinstance(self.filter, PoseFilter):
            stats["gps_rejections"] = self.filter.gps_rejections
        return stats

    # -- Platform (Table 19) --------------------------------------------------------------
    def _geometry(self) -> GeometryModel:
        if self.model is None:  # pragma: no cover - served only after setup
            raise EOutOfBounds("the geometry model is not loaded")
        return self.model

    async def getTransformation(self, A: str, B: str) -> PoseTransformIDL:
        transform = self._geometry().transformation(A, B)
        return PoseTransformIDL(time=TimeIDL.from_seconds(self.clock.now()),
                                HTransform=transform, initialUTM=np.zeros(3),
                                poseValidFlag=True)

    async def getBodyList(self) -> StringSequenceIDL:
        return StringSequenceIDL(values=tuple(self._geometry().bodies()))

    async def getBodyFrameList(self, body: str) -> StringSequenceIDL:
        return StringSequenceIDL(values=tuple(self._geometry().frames(body)))

    async def getPose(self) -> PoseTransformIDL:
        return self.latest.get()

    async def getWaitPose(self) -> PoseTransformIDL:
        return await self.latest.wait_next(Platform.wait_timeout)
