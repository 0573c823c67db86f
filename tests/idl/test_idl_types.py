"""The IDL: every type round-trips losslessly, bad input is refused, and the interfaces
carry exactly the seed's method names."""

from __future__ import annotations

import base64
import hashlib
import json
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pydantic
import pytest
from pydantic import TypeAdapter

import idl
from idl import (
    ArcDecisionIDL,
    ArcVoteIDL,
    EgoMapArrayEventIDL,
    EgoMapSeqEventIDL,
    EtravMapArrayEventIDL,
    GpsIDL,
    IDLModel,
    ImuIDL,
    Interface,
    MapArrayEventIDL,
    MapSeqEventIDL,
    MinMaxVelocityIDL,
    PlanMapEventIDL,
    PlannedPathIDL,
    PlanningBoundaryIDL,
    PlanPointIDL,
    PoseTransformIDL,
    Position3DIDL,
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
    StringSequenceIDL,
    TimeIDL,
    TravMapArrayEventIDL,
    VelocityDataIDL,
    VelocityIDL,
    WaypointGroupIDL,
    WaypointIDL,
    WheelDataIDL,
    WheelEventIDL,
)

NAN = float("nan")
T0 = TimeIDL(sec=1_126_000_000, usec=123_456)


# --- sample factories: one non-trivial instance per IDL type ------------------------------


def _pose_matrix(yaw: float, x: float, y: float, z: float = 0.0) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1]], dtype=float)


def _map_header(frame: str = "World", rows: int = 3, cols: int = 4) -> dict[str, Any]:
    return dict(time=T0, frame=frame, mapPose=_pose_matrix(0.3, 12.5, -4.0),
                initialUTM=np.array([512_345.25, 5_543_210.5, 750.125]), gridsize=0.2,
                originX=-0.3, originY=-0.4, rows=rows, cols=cols)


def _terrain_layers() -> dict[str, np.ndarray]:
    elevation = np.full((3, 4), NAN, dtype=np.float32)
    elevation[0, 1], elevation[2, 3] = 0.25, -1.5
    low, high, var = elevation - 0.125, elevation + 0.5, np.where(np.isnan(elevation), NAN, 0.0625)
    count = np.zeros((3, 4), dtype=np.int32)
    count[0, 1], count[2, 3] = 7, 2
    return dict(elevation=elevation, minHeight=low, maxHeight=high, pointCount=count,
                variance=var.astype(np.float32))


def _terrain_seq() -> dict[str, np.ndarray]:
    return dict(cellRow=np.array([0, 2], dtype=np.int32), cellCol=np.array([1, 3], dtype=np.int32),
                elevation=np.array([0.25, -1.5], dtype=np.float32),
                minHeight=np.array([0.125, -1.625], dtype=np.float32),
                maxHeight=np.array([0.75, -1.0], dtype=np.float32),
                pointCount=np.array([7, 2], dtype=np.int32),
                variance=np.array([0.0625, 0.0625], dtype=np.float32))


def _trav_layers() -> dict[str, Any]:
    hazard = np.array([[0, 0.5, 1, NAN]] * 3, dtype=np.float32)
    goodness = np.array([[1, 0.75, 0.25, 0]] * 3, dtype=np.float32)
    return dict(hazard=hazard, goodness=goodness,
                vehiclePosition=Position3DIDL(x=12.5, y=-4.0, z=0.5), vehicleHeading=0.3)


def _laser() -> Range3dLaserIDL:
    points = np.array([[1.0, -0.5, 0.25], [NAN, NAN, NAN], [2.0, 0.5, -0.75]], dtype=np.float32)
    return Range3dLaserIDL(time=T0, sensorId=11, frame="FrontNoddingSICKLeft:AxleCenterFreeEnd",
                           nodAngleStart=-0.7, nodAngleEnd=-0.69, points=points,
                           valid=np.array([True, False, True]))


def _stereo() -> Range3dStereoEventIDL:
    points = np.arange(2 * 3 * 3, dtype=np.float32).reshape(2, 3, 3)
    valid = np.array([[True, False, True], [True, True, False]])
    points[~valid] = np.nan
    return Range3dStereoEventIDL(time=T0, sensorId=3, frame="Digiclops:ImagePlane",
                                 points=points, valid=valid)


SAMPLES: dict[str, Callable[[], IDLModel]] = {
    "TimeIDL": lambda: T0,
    "Position3DIDL": lambda: Position3DIDL(x=1.5, y=-2.25, z=3.125),
    "StringSequenceIDL": lambda: StringSequenceIDL(values=("Raptor", "Digiclops", "Imu")),
    "PoseTransformIDL": lambda: PoseTransformIDL(
        time=T0, HTransform=_pose_matrix(1.0, 3.5, -7.25, 0.5),
        initialUTM=np.array([512_345.25, 5_543_210.5, 750.125]), poseValidFlag=False),
    "ImuIDL": lambda: ImuIDL(time=T0, roll=0.01, pitch=-0.02, yaw=1.5, accelX=0.1, accelY=-0.2,
                             accelZ=-9.81, rateX=0.001, rateY=0.002, rateZ=-0.003),
    "GpsIDL": lambda: GpsIDL(
        time=T0, latitude=50.2712345678, longitude=-111.1734567891, elevation=752.5,
        undulation=-17.25, easting=416_123.5, northing=5_569_876.25, utmZone=12,
        utmZoneLetter="U", satellitesTracked=9, satellitesUsed=8, horizontalSpeed=2.5,
        track=359.5, verticalSpeed=-0.125, solutionStatus="SOL_COMPUTED",
        positionType="PSRDIFF", latitudeStd=0.5, longitudeStd=0.75, elevationStd=1.25,
        differentialAge=3.0, solutionAge=0.25, baseStationId="119"),
    "WheelDataIDL": lambda: WheelDataIDL(time=T0, leftDistance=105.25, rightDistance=104.75,
                                         leftSpeed=1.5, rightSpeed=1.25, steeringAngle=-0.2),
    "WheelEventIDL": lambda: WheelEventIDL(time=T0, leftDistance=105.25, rightDistance=104.75,
                                           leftSpeed=1.5, rightSpeed=1.25, steeringAngle=0.2,
                                           sequence=42, leftDelta=0.375, rightDelta=0.3125),
    "Range3dLaserIDL": _laser,
    "Range3dSeqEventIDL": lambda: _laser().to_seq(),
    "Range3dStereoEventIDL": _stereo,
    "Range3dArrayEventIDL": lambda: _stereo().to_array_event(),
    "MapArrayEventIDL": lambda: MapArrayEventIDL(**_map_header(), **_terrain_layers()),
    "MapSeqEventIDL": lambda: MapSeqEventIDL(**_map_header(), **_terrain_seq()),
    "EgoMapArrayEventIDL": lambda: EgoMapArrayEventIDL(
        **_map_header("Raptor:Front-BumperCenter"), **_terrain_layers()),
    "EgoMapSeqEventIDL": lambda: EgoMapSeqEventIDL(
        **_map_header("Raptor:Front-BumperCenter"), **_terrain_seq()),
    "TravMapArrayEventIDL": lambda: TravMapArrayEventIDL(**_map_header(), **_trav_layers()),
    "EtravMapArrayEventIDL": lambda: EtravMapArrayEventIDL(
        **_map_header("Raptor:Front-BumperCenter"), **_trav_layers()),
    "PlanMapEventIDL": lambda: PlanMapEventIDL(
        **_map_header(), **_trav_layers(),
        aPrioriCost=np.array([[1, 2, math.inf, 1]] * 3, dtype=np.float32),
        sensedCost=np.array([[1, 1.5, math.inf, 4]] * 3, dtype=np.float32),
        planningBoundary=PlanningBoundaryIDL(minX=0, minY=1, maxX=2, maxY=3)),
    "PlanPointIDL": lambda: PlanPointIDL(x=-3, y=17, aPrioriCost=2.5, sensedCost=math.inf,
                                         sensed=True),
    "PlanningBoundaryIDL": lambda: PlanningBoundaryIDL(minX=-5, minY=2, maxX=40, maxY=2),
    "WaypointIDL": lambda: WaypointIDL(latitude=50.25, longitude=-111.125, easting=416_000.5,
                                       northing=5_569_000.25, tolerance=3.5),
    "WaypointGroupIDL": lambda: WaypointGroupIDL(
        waypoints=(WaypointIDL(latitude=50.25, longitude=-111.125),
                   WaypointIDL(latitude=50.5, longitude=-111.0, tolerance=1.0)),
        patrolMode=True),
    "ArcVoteIDL": lambda: ArcVoteIDL(
        time=T0, behaviour="PurePursuit", curvatures=np.array([-0.25, 0.0, 0.25]),
        veto=np.array([True, False, False]), vote=np.array([0.0, 1.0, 0.5]),
        certainty=np.array([1.0, 0.75, 0.25]), maxSpeed=np.array([0.0, 2.0, 1.5])),
    "ArcDecisionIDL": lambda: ArcDecisionIDL(
        time=T0, curvatures=np.array([0.25, 0.0, -0.25]), scores=np.array([0.5, 1.75, 0.0]),
        vetoed=np.array([False, False, True]), index=1, curvature=0.0, steeringAngle=0.0,
        speed=0.5, fresh=("ObstacleAvoidance", "PurePursuit"), stale=("FindPath",)),
    "PlannedPathIDL": lambda: PlannedPathIDL(
        time=T0, points=np.array([[0.0, 0.0], [0.5, 0.5], [1.0, 1.5]]),
        initialUTM=np.array([512_345.25, 5_543_210.5, 750.125]), cost=2.5,
        goal=WaypointIDL(latitude=50.25, longitude=-111.125)),
    "VelocityIDL": lambda: VelocityIDL(translation=1.25, rotation=-0.3, steeringAngle=-0.35),
    "VelocityDataIDL": lambda: VelocityDataIDL(
        time=T0, velocity=VelocityIDL(translation=1.0, rotation=0.1, steeringAngle=0.2),
        target=VelocityIDL(translation=1.5), vehicleStarted=True, arbiterEnabled=True),
    "MinMaxVelocityIDL": lambda: MinMaxVelocityIDL(minTranslation=-1.0, maxTranslation=2.0,
                                                   minRotation=-1.0, maxRotation=1.0,
                                                   maxSteeringAngle=0.5235987755982988),
}

#: The package's types by class name (the registry keys them by qualified name).
BY_NAME = {cls.__name__: cls for cls in idl.idl_types().values()
           if cls.__module__.startswith("idl.")}
IDL_TYPES = sorted(BY_NAME)


# --- round trips --------------------------------------------------------------------------


def test_every_type_in_the_package_is_exported_and_sampled():
    assert set(IDL_TYPES) == set(SAMPLES)
    assert set(IDL_TYPES) <= set(idl.__all__)


@pytest.mark.parametrize("name", IDL_TYPES)
def test_round_trip_is_lossless(name):
    cls = BY_NAME[name]
    assert name in SAMPLES, f"{name} has no sample factory"
    sample = SAMPLES[name]()
    assert type(sample) is cls
    again = cls.from_json(sample.to_json())
    assert again == sample
    for field_name in cls.model_fields:
        before, after = getattr(sample, field_name), getattr(again, field_name)
        if isinstance(before, np.ndarray):
            assert after.dtype == before.dtype and after.shape == before.shape
            assert not after.flags.writeable
    # and through a generic JSON parser (what the event log and the network bridge use)
    assert cls.model_validate(json.loads(sample.to_json())) == sample


@pytest.mark.parametrize("name", IDL_TYPES)
def test_every_field_declares_a_unit_or_is_a_name(name):
    cls = BY_NAME[name]
    for field_name, info in cls.model_fields.items():
        assert info.description, f"{name}.{field_name} has no description"


def test_array_bytes_are_little_endian_base64_as_computed_by_hand():
    seq = Range3dArrayEventIDL(time=T0, sensorId=1, frame="Digiclops:ImagePlane",
                               points=np.array([[1.0, 2.0, -2.0]], dtype=np.float32))
    data = json.loads(seq.to_json())["points"]
    # 1.0f = 00 00 80 3F, 2.0f = 00 00 00 40, -2.0f = 00 00 00 C0
    assert data == {"dtype": "<f4", "shape": [1, 3], "data": "AACAPwAAAEAAAADA"}
    assert base64.b64decode(data["data"]) == bytes.fromhex("0000803f00000040000000c0")


def test_fingerprint_digests_array_bytes_and_tells_values_apart():
    points = np.array([[1.0, 2.0, -2.0], [0.5, 0.25, 4.0]], dtype=np.float32)
    seq = Range3dArrayEventIDL(time=T0, sensorId=1, frame="Digiclops:ImagePlane", points=points)
    data = json.loads(seq.fingerprint())["points"]
    # the SHA-256 of the little-endian bytes, computed independently of the serialiser
    assert data == {"dtype": "<f4", "shape": [2, 3],
                    "sha256": hashlib.sha256(points.astype("<f4").tobytes()).hexdigest()}
    same = Range3dArrayEventIDL(time=T0, sensorId=1, frame="Digiclops:ImagePlane",
                                points=points.copy())
    assert same.fingerprint() == seq.fingerprint()
    nudged = points.copy()
    nudged[1, 2] = np.nextafter(nudged[1, 2], np.float32(5))  # one ulp on one element
    other = Range3dArrayEventIDL(time=T0, sensorId=1, frame="Digiclops:ImagePlane",
                                 points=nudged)
    assert other.fingerprint() != seq.fingerprint()
    assert json.loads(seq.to_json())["points"]["data"]  # to_json is unchanged


def test_fingerprint_of_a_shared_array_is_its_own_each_time():
    """Array heads are remembered by identity for frozen arrays that own their memory:
    a body carrying the same array again gives the same fingerprint as one carrying an
    equal copy, a different array (even reusing a freed array's id) its own, and
    writable arrays or views are hashed anew every time."""
    rng = np.random.default_rng(5)

    def body(points: np.ndarray) -> Range3dArrayEventIDL:
        return Range3dArrayEventIDL(time=T0, sensorId=1, frame="f", points=points)

    def expected(points: np.ndarray) -> str:
        return hashlib.sha256(points.astype("<f4").tobytes()).hexdigest()

    first = body(rng.normal(size=(4, 3)).astype(np.float32))
    shared = first.points  # validated: a read-only copy that owns its memory
    assert shared.base is None and not shared.flags.writeable
    for _ in range(3):
        again = Range3dArrayEventIDL.model_construct(time=T0, sensorId=1, frame="f",
                                                     points=shared)
        assert again.fingerprint() == body(shared.copy()).fingerprint()
        assert json.loads(again.fingerprint())["points"]["sha256"] == expected(shared)
    for _ in range(300):  # more arrays than are kept, ids reused as they are freed
        points = rng.normal(size=(2, 3)).astype(np.float32)
        assert json.loads(body(points).fingerprint())["points"]["sha256"] == expected(points)
    assert first.fingerprint() == body(shared.copy()).fingerprint()
    # a large array is not kept alive by the cache
    import idl._base as base
    big = body(np.zeros((base._HEAD_BYTES // 12 + 1, 3), dtype=np.float32))
    big.fingerprint()
    assert all(kept is not big.points for kept, _ in base._HEADS.values())
    # a view of a writable array is hashed from its current bytes every time
    base = rng.normal(size=(2, 3)).astype(np.float32)
    view = base[:]
    view.flags.writeable = False
    seen = Range3dArrayEventIDL.model_construct(time=T0, sensorId=1, frame="f", points=view)
    before = json.loads(seen.fingerprint())["points"]["sha256"]
    base[0, 0] += 1.0
    after = json.loads(seen.fingerprint())["points"]["sha256"]
    assert before != after == expected(base)


def test_time_json_is_the_miro_struct():
    assert TimeIDL(sec=12, usec=250_000).to_json() == b'{"sec":12,"usec":250000}'


def test_infinite_cost_survives_json_as_a_string():
    point = PlanPointIDL(x=1, y=2, aPrioriCost=math.inf)
    assert b'"aPrioriCost":"Infinity","sensedCost":1.0' in point.to_json()
    assert PlanPointIDL.from_json(point.to_json()).aPrioriCost == math.inf
    assert PlanPointIDL.model_validate(json.loads(point.to_json())).aPrioriCost == math.inf


# --- helpers ------------------------------------------------------------------------------


@pytest.mark.parametrize("seconds, sec, usec", [
    (12.25, 12, 250_000),
    (0.0, 0, 0),
    (-0.25, -1, 750_000),
    (1.9999996, 2, 0),          # rounds up into the next second
    (1_126_000_000.123456, 1_126_000_000, 123_456),
])
def test_time_from_seconds(seconds, sec, usec):
    assert TimeIDL.from_seconds(seconds) == TimeIDL(sec=sec, usec=usec)


def test_time_to_seconds_inverts_from_seconds():
    assert TimeIDL(sec=-1, usec=750_000).to_seconds() == -0.25
    assert TimeIDL(sec=3, usec=500_000).to_seconds() == 3.5
    with pytest.raises(ValueError):
        TimeIDL.from_seconds(math.nan)


def test_pose_transform_accessors():
    pose = SAMPLES["PoseTransformIDL"]()
    assert pose.translation.tolist() == [3.5, -7.25, 0.5]
    assert pose.rotation[2].tolist() == [0.0, 0.0, 1.0]
    identity = PoseTransformIDL.identity()
    assert identity.HTransform.tolist() == np.eye(4).tolist() and identity.poseValidFlag


def test_laser_to_seq_keeps_only_valid_points_in_beam_order():
    seq = _laser().to_seq()
    assert seq.points.tolist() == [[1.0, -0.5, 0.25], [2.0, 0.5, -0.75]]
    assert (seq.sensorId, seq.nodAngleStart, seq.nodAngleEnd) == (11, -0.7, -0.69)
    assert _laser().count == 2


def test_stereo_valid_points_are_row_major():
    assert _stereo().valid_points().tolist() == [[0, 1, 2], [6, 7, 8], [9, 10, 11],
                                                 [12, 13, 14]]


def test_terrain_array_and_seq_convert_both_ways():
    array = SAMPLES["MapArrayEventIDL"]()
    seq = array.to_seq()
    assert type(seq) is MapSeqEventIDL
    assert seq == SAMPLES["MapSeqEventIDL"]()
    assert seq.to_array() == array
    ego = SAMPLES["EgoMapSeqEventIDL"]().to_array()
    assert type(ego) is EgoMapArrayEventIDL and ego.pointCount[2, 3] == 2
    assert ego.pointCount[0, 0] == 0 and math.isnan(ego.elevation[0, 0])


def test_map_cell_geometry():
    grid = SAMPLES["TravMapArrayEventIDL"]()      # origin (-0.3, -0.4), gridsize 0.2
    assert grid.cell_center(0, 0) == pytest.approx((-0.2, -0.3))
    assert grid.cell_center(2, 3) == pytest.approx((0.2, 0.3))
    assert grid.cell_index(0.25, 0.3) == (2, 3)
    assert grid.cell_index(-0.31, -0.4) == (-1, 0)
    assert grid.contains(2, 3) and not grid.contains(3, 0) and not grid.contains(-1, 0)


def test_small_helpers():
    assert WheelDataIDL(time=T0, leftDistance=2.0, rightDistance=4.0, leftSpeed=1.0,
                        rightSpeed=2.0).distance == 3.0
    assert PlanPointIDL(x=0, y=0, aPrioriCost=3.0, sensedCost=2.0).cost == 3.0
    assert PlanPointIDL(x=0, y=0, aPrioriCost=3.0, sensedCost=2.0, sensed=True).cost == 2.0
    assert PlanningBoundaryIDL(minX=0, minY=0, maxX=2, maxY=2).contains(2, 0)
    assert not PlanningBoundaryIDL(minX=0, minY=0, maxX=2, maxY=2).contains(3, 0)
    assert SAMPLES["GpsIDL"]().has_fix and not GpsIDL(time=T0).has_fix
    limits = SAMPLES["MinMaxVelocityIDL"]()
    assert limits.accepts(VelocityIDL(translation=2.0, steeringAngle=-0.5))
    assert not limits.accepts(VelocityIDL(translation=2.5))
    assert not SAMPLES["ArcVoteIDL"]().all_vetoed


# --- validation failures ------------------------------------------------------------------


def test_models_are_frozen_and_arrays_read_only():
    pose = SAMPLES["PoseTransformIDL"]()
    with pytest.raises(pydantic.ValidationError):
        pose.poseValidFlag = True
    with pytest.raises(ValueError):
        pose.HTransform[0, 3] = 1.0


def test_unknown_field_is_refused():
    with pytest.raises(pydantic.ValidationError, match="extra"):
        VelocityIDL(translation=1.0, speed=2.0)


@pytest.mark.parametrize("build", [
    lambda: PoseTransformIDL(time=T0, HTransform=np.eye(3), initialUTM=np.zeros(3)),
    lambda: PoseTransformIDL(time=T0, HTransform=np.eye(4), initialUTM=np.zeros(2)),
    lambda: PoseTransformIDL(time=T0, HTransform=np.full((4, 4), "x"), initialUTM=np.zeros(3)),
    lambda: PoseTransformIDL(time=T0, HTransform=np.ones((4, 4)), initialUTM=np.zeros(3)),
    lambda: Range3dSeqEventIDL(time=T0, sensorId=11, frame="f", points=np.zeros((4, 2))),
    lambda: Range3dSeqEventIDL(time=T0, sensorId=11, frame="f",
                               points=np.array([[0.0, NAN, 1.0]])),
    lambda: Range3dLaserIDL(time=T0, sensorId=11, frame="f", points=np.zeros((3, 3)),
                            valid=np.ones(2, dtype=bool)),
    lambda: Range3dLaserIDL(time=T0, sensorId=11, frame="f", points=np.zeros((2, 3)),
                            valid=np.array([True, False])),             # invalid slot not NaN
    lambda: MapArrayEventIDL(**_map_header(rows=4), **_terrain_layers()),  # rows mismatch
    lambda: MapArrayEventIDL(**{**_map_header(), "mapPose": _tilted()}, **_terrain_layers()),
    lambda: MapSeqEventIDL(**_map_header(), **{**_terrain_seq(),
                                               "cellRow": np.array([0, 3], dtype=np.int32)}),
    lambda: MapSeqEventIDL(**_map_header(), **{**_terrain_seq(),
                                               "cellRow": np.array([2, 2], dtype=np.int32),
                                               "cellCol": np.array([3, 3], dtype=np.int32)}),
    lambda: TravMapArrayEventIDL(**_map_header(), **{**_trav_layers(),
                                                     "goodness": np.full((3, 4), 1.5)}),
    lambda: ArcVoteIDL(time=T0, behaviour="b", curvatures=np.zeros(3), veto=np.zeros(2),
                       vote=np.zeros(3), certainty=np.zeros(3), maxSpeed=np.zeros(3)),
    lambda: ArcVoteIDL(time=T0, behaviour="b", curvatures=np.zeros(1), veto=np.zeros(1),
                       vote=np.array([1.5]), certainty=np.zeros(1), maxSpeed=np.zeros(1)),
    lambda: ArcDecisionIDL(time=T0, curvatures=np.zeros(3), scores=np.zeros(2),
                           vetoed=np.zeros(3, dtype=bool)),                # lengths differ
    lambda: ArcDecisionIDL(time=T0, curvatures=np.zeros(2), scores=np.zeros(2),
                           vetoed=np.zeros(2, dtype=bool), index=2),       # no arc 2
    lambda: ArcDecisionIDL(time=T0, curvatures=np.zeros(1), scores=np.array([NAN]),
                           vetoed=np.zeros(1, dtype=bool)),
    lambda: PlannedPathIDL(time=T0, points=np.array([[0.0, NAN]]), initialUTM=np.zeros(3)),
    lambda: GpsIDL(time=T0, utmZoneLetter="I"),
    lambda: GpsIDL(time=T0, latitude=91.0),
    lambda: GpsIDL(time=T0, track=360.0),
    lambda: TimeIDL(sec=1, usec=1_000_000),
    lambda: ImuIDL(time=T0, roll=math.nan),
    lambda: PlanPointIDL(x=0, y=0, sensedCost=0.5),
    lambda: PlanningBoundaryIDL(minX=3, minY=0, maxX=2, maxY=5),
    lambda: WaypointIDL(latitude=50.0, longitude=-111.0, easting=1.0),
    lambda: WaypointIDL(latitude=50.0, longitude=-111.0, tolerance=0.0),
    lambda: MinMaxVelocityIDL(minTranslation=2.0, maxTranslation=1.0, minRotation=0,
                              maxRotation=0, maxSteeringAngle=0.5),
])
def test_bad_values_are_refused(build):
    with pytest.raises(pydantic.ValidationError):
        build()


def _tilted() -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # 90° roll: not gravity-aligned
    return matrix


# --- interfaces ---------------------------------------------------------------------------

# Method names as the seed's tables print them (typos corrected as noted), then the
# getWait/afa additions the docs list.
SEED_METHODS: dict[type[Interface], list[str]] = {
    idl.Range3dSensor: [  # Tables 2, 4, 31
        "get3dLaserFullScan", "get3dLaserWaitFullScan", "get3dSeqFullScan",
        "get3dSeqWaitFullScan", "get3dStereoFullScan", "get3dStereoWaitFullScan",
        "get3dArrayFullScan", "get3dArrayWaitFullScan"],
    idl.Imu: ["getImuData", "getWaitImuData"],                      # Table 6 + getWait
    idl.Gps: ["getPosition", "getWaitPosition"],                    # Table 8 + getWait
    idl.Odometry: ["getWheelData", "getWaitWheelData"],             # Table 10 + getWait
    idl.Map: [  # Tables 12, 32, 33
        "getMapArray", "getWaitMapArray", "getMapSeq", "getWaitMapSeq", "getEgoMapArray",
        "getWaitEgoMapArray", "getEgoMapSeq", "getWaitEgoMapSeq"],
    idl.TravMap: ["getTravMapArray", "getWaitTravMapArray", "getEtravMapArray",
                  "getWaitEtravMapArray"],                          # Table 16
    idl.GlobalMap: [  # Table 18, then §3.2.3's waypoints and boundary, then getPlanMap
        "valid", "getPlanningMap", "getSensingMap", "setPlanningMap", "setSensingMap",
        "getMap", "setMap", "getTransformToPlanningFromWorld",
        "getTransformToWorldFromPlanning", "getVehiclePosition", "getNextWaypoint",
        "setWaypointList", "getWaypointList", "getCurrentWaypoint", "setPlanningBoundary",
        "getPlanningBoundary", "getPlanMap", "getPlanMapChanges"],
    idl.Platform: ["getTransformation", "getBodyList", "getBodyFrameList",  # Table 19
                   "getPose", "getWaitPose"],
    idl.VehiclePlan: ["setWaypointList", "getWaypointList", "getCurrentWaypoint",
                      "setPatrolMode", "getPatrolMode", "setHalt"],  # Table 24
    idl.VehicleControl: ["setVelocity", "getTargetVelocity", "startVehicle", "stopVehicle",
                         "setJoystickVelocity", "setArbiter", "getMinMaxVelocity"],  # Table 26
}

WAIT_TIMEOUTS = {idl.Range3dSensor: 5.0, idl.Gps: 10.0, idl.Odometry: 1.0, idl.Imu: 1.0,
                 idl.Platform: 1.0, idl.Map: 5.0, idl.TravMap: 5.0}


def test_every_interface_is_listed():
    exported = {getattr(idl, name) for name in idl.__all__}
    interfaces = {c for c in exported if isinstance(c, type) and issubclass(c, Interface)
                  and c is not Interface}
    assert interfaces == set(SEED_METHODS)


@pytest.mark.parametrize("interface", list(SEED_METHODS), ids=lambda i: i.__name__)
def test_interface_method_names_are_the_seeds(interface):
    assert list(interface.methods) == SEED_METHODS[interface]
    for spec in interface.methods.values():
        assert spec.doc, f"{interface.__name__}.{spec.name} has no docstring"


@pytest.mark.parametrize("interface", list(SEED_METHODS), ids=lambda i: i.__name__)
def test_annotations_validate_and_serialise(interface):
    for spec in interface.methods.values():
        hints = spec.hints()
        assert set(spec.parameters) | {"return"} == set(hints), spec.name
        for annotation in hints.values():
            TypeAdapter(annotation)  # raises if pydantic cannot handle it
        returns = hints["return"]
        if isinstance(returns, type) and issubclass(returns, IDLModel):
            adapter = TypeAdapter(returns)
            value = SAMPLES[returns.__name__]()
            assert adapter.validate_json(adapter.dump_json(value)) == value


@pytest.mark.parametrize("interface", list(SEED_METHODS), ids=lambda i: i.__name__)
def test_timeouts(interface):
    assert interface.wait_timeout == WAIT_TIMEOUTS.get(interface, 1.0)
    assert interface.call_timeout >= 5.0
    if any("Wait" in name for name in interface.methods):  # getWaitX, get3dXWaitFullScan
        assert interface.call_timeout > interface.wait_timeout


def test_out_parameters_become_optional_results():
    hints = idl.GlobalMap.methods["getVehiclePosition"].hints()
    adapter = TypeAdapter(hints["return"])
    assert adapter.validate_python(None) is None
    assert adapter.validate_json(b'{"x":1.0,"y":2.0,"z":0.5}') == Position3DIDL(x=1, y=2, z=0.5)
    next_waypoint = idl.GlobalMap.methods["getNextWaypoint"]
    assert next_waypoint.parameters == ["current"]
    assert TypeAdapter(next_waypoint.hints()["return"]).validate_python(None) is None


@pytest.mark.parametrize("name", ["Range3dLaserIDL", "PlanPointIDL", "PlanMapEventIDL"])
def test_bodies_cross_the_event_log_format(name):
    from afa.events import Event

    event = Event("Raptor", "Laser11", 12.5, 3, SAMPLES[name](), "NodLaserService")
    again = Event.decode(event.encode())
    assert again[:4] == event[:4] and again.origin == "NodLaserService"
    assert type(again.body) is type(event.body) and again.body == event.body


def test_the_reference_documents_every_type_and_method():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "idl.md").read_text()
    for name in IDL_TYPES:
        assert f"### {name}\n" in text, f"docs/idl.md lacks {name}"
    for interface, methods in SEED_METHODS.items():
        assert f"#### {interface.__name__}\n" in text
        for method in methods:
            assert f"`{method}(" in text, f"docs/idl.md lacks {interface.__name__}.{method}"
