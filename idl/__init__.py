"""The IDL of afa: every event type and polled interface the seed names.

Types are frozen pydantic models (:class:`IDLModel`) with read-only numpy arrays; they
serialise losslessly to the binary wire form (:mod:`idl.wire`: logs, network, console)
and to JSON (``to_json`` / ``from_json``). Interfaces subclass
:class:`Interface` and carry the seed's method names. This package imports only the
standard library, numpy and pydantic. Reference: ``docs/idl.md``.
"""

from idl import wire
from idl._base import (
    Array,
    IDLModel,
    Interface,
    MethodSpec,
    TypeRegistryError,
    field,
    idl_types,
    type_name,
)
from idl.common import (
    HTransform4x4,
    PoseTransformIDL,
    Position3DIDL,
    StringSequenceIDL,
    TimeIDL,
    Vector3,
    check_homogeneous,
)
from idl.interfaces import (
    GlobalMap,
    Gps,
    Imu,
    Map,
    Odometry,
    Platform,
    Range3dSensor,
    TravMap,
    VehicleControl,
    VehiclePlan,
)
from idl.maps import (
    EgoMapArrayEventIDL,
    EgoMapSeqEventIDL,
    EtravMapArrayEventIDL,
    MapArrayEventIDL,
    MapSeqEventIDL,
    PlanMapEventIDL,
    TravMapArrayEventIDL,
)
from idl.planning import (
    IMPASSABLE,
    ArcDecisionIDL,
    ArcVoteIDL,
    Cost,
    PlannedPathIDL,
    PlanningBoundaryIDL,
    PlanPointIDL,
    WaypointGroupIDL,
    WaypointIDL,
)
from idl.range import (
    Points,
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
    select_valid,
)
from idl.sensors import UTM_ZONE_LETTERS, GpsIDL, ImuIDL, WheelDataIDL, WheelEventIDL
from idl.vehicle import MinMaxVelocityIDL, VelocityDataIDL, VelocityIDL

__all__ = [
    # foundations
    "IDLModel", "Array", "field", "Interface", "MethodSpec", "idl_types", "type_name",
    "TypeRegistryError", "wire",
    # common
    "TimeIDL", "Position3DIDL", "StringSequenceIDL", "PoseTransformIDL",
    "HTransform4x4", "Vector3", "check_homogeneous",
    # sensors
    "ImuIDL", "GpsIDL", "WheelDataIDL", "WheelEventIDL", "UTM_ZONE_LETTERS",
    # range
    "Range3dLaserIDL", "Range3dSeqEventIDL", "Range3dStereoEventIDL",
    "Range3dArrayEventIDL", "Points", "select_valid",
    # maps
    "MapArrayEventIDL", "MapSeqEventIDL", "EgoMapArrayEventIDL", "EgoMapSeqEventIDL",
    "TravMapArrayEventIDL", "EtravMapArrayEventIDL", "PlanMapEventIDL",
    # planning
    "PlanPointIDL", "PlanningBoundaryIDL", "WaypointIDL", "WaypointGroupIDL",
    "ArcVoteIDL", "ArcDecisionIDL", "PlannedPathIDL", "IMPASSABLE", "Cost",
    # vehicle
    "VelocityIDL", "VelocityDataIDL", "MinMaxVelocityIDL",
    # interfaces
    "Range3dSensor", "Imu", "Gps", "Odometry", "Map", "TravMap", "GlobalMap",
    "Platform", "VehiclePlan", "VehicleControl",
]
