"""Viewer channels: Foxglove schemas, exactly named, with the fields Foxglove documents,
from synthetic map, vote, pose and point bodies. Point clouds and grids are written as
protobuf: they are decoded here by the ``protobuf`` package from the descriptor set the
recording carries, an independent decoder."""

import base64
import json
import math

import numpy as np
import pytest

from afa.log import LogReader, protobuf
from afa.log import format as fmt
from afa.log.viewer import ENCODINGS, SCHEMAS, ViewerConverter, quaternion
from idl import (
    ArcVoteIDL,
    MapArrayEventIDL,
    PlanMapEventIDL,
    PlanningBoundaryIDL,
    PoseTransformIDL,
    Position3DIDL,
    Range3dSeqEventIDL,
    TimeIDL,
    TravMapArrayEventIDL,
    wire,
)


def conforms(value, schema, where="$"):
    """A small JSON-schema check (object, required, properties, array, oneOf const)."""
    if "oneOf" in schema:
        assert value in [option["const"] for option in schema["oneOf"]], where
        return
    kind = schema.get("type")
    if kind == "object":
        assert isinstance(value, dict), where
        for key in schema.get("required", []):
            assert key in value, f"{where}.{key} missing"
        for key, sub in schema.get("properties", {}).items():
            if key in value:
                conforms(value[key], sub, f"{where}.{key}")
    elif kind == "array":
        assert isinstance(value, list), where
        for k, item in enumerate(value):
            conforms(item, schema["items"], f"{where}[{k}]")
    elif kind == "number":
        assert isinstance(value, (int, float)) and math.isfinite(value), where
    elif kind == "integer":
        assert isinstance(value, int), where
    elif kind == "string":
        assert isinstance(value, str), where
        if schema.get("contentEncoding") == "base64":
            base64.b64decode(value, validate=True)
    elif kind == "boolean":
        assert isinstance(value, bool), where


def message_class(name, descriptor_set):
    """The protobuf package's message class of ``name`` built from a FileDescriptorSet."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(descriptor_set).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


def decoded(name, data, descriptor_set=None):
    """A protobuf ``foxglove.PointCloud`` or ``foxglove.Grid`` (bytes, or the parts the
    converter gives) decoded by the protobuf package, as the JSON document ``convert``
    builds (data in base64)."""
    if isinstance(data, list):
        data = b"".join(bytes(part) for part in data)
    cls = message_class(name, descriptor_set or protobuf.SCHEMAS[name])
    message = cls.FromString(data)
    assert message.SerializeToString() == data  # nothing unknown, canonical order

    def vector(v, axes):
        return {axis: getattr(v, axis) for axis in axes}

    document = {"timestamp": {"sec": message.timestamp.seconds,
                              "nsec": message.timestamp.nanos},
                "frame_id": message.frame_id,
                "pose": {"position": vector(message.pose.position, "xyz"),
                         "orientation": vector(message.pose.orientation, "xyzw")}}
    if name == "foxglove.PointCloud":
        document["point_stride"] = message.point_stride
    else:
        document.update(column_count=message.column_count,
                        cell_size=vector(message.cell_size, "xy"),
                        row_stride=message.row_stride, cell_stride=message.cell_stride)
    document["fields"] = [{"name": f.name, "offset": f.offset, "type": f.type}
                          for f in message.fields]
    document["data"] = base64.b64encode(message.data).decode("ascii")
    return document


def header(rows=4, cols=3):
    pose = np.eye(4)
    pose[:2, 3] = [10.0, 20.0]
    return dict(time=TimeIDL(sec=5, usec=250000), frame="World", mapPose=pose,
                initialUTM=np.array([487000.0, 5568000.0, 750.0]), gridsize=0.5,
                originX=-1.0, originY=-0.5, rows=rows, cols=cols)


def test_a_traversability_map_is_a_grid_with_cells_where_afa_puts_them():
    hazard = np.arange(12, dtype=np.float32).reshape(4, 3) / 12
    body = TravMapArrayEventIDL(**header(), hazard=hazard, goodness=np.ones((4, 3), np.float32),
                                vehiclePosition=Position3DIDL())
    [(topic, schema, grid)] = ViewerConverter().convert("TravMap", "trav", body)
    assert (topic, schema) == ("/viz/TravMap", "foxglove.Grid")
    conforms(grid, SCHEMAS[schema])
    assert grid["column_count"] == 4 and grid["cell_stride"] == 8 and grid["row_stride"] == 32
    assert grid["pose"]["position"] == {"x": 9.0, "y": 19.5, "z": 0.0}  # mapPose · origin
    data = np.frombuffer(base64.b64decode(grid["data"]), "<f4").reshape(3, 4, 2)
    i, j = 2, 1  # afa cell [i, j]: x index i, y index j -> Foxglove row j, column i
    assert data[j, i, 0] == hazard[i, j] and data[j, i, 1] == 1.0
    assert [f["name"] for f in grid["fields"]] == ["hazard", "goodness"]


def test_terrain_and_plan_maps_are_grids_too():
    grid = np.full((4, 3), np.nan, np.float32)
    grid[1, 1] = 2.0
    terrain = MapArrayEventIDL(**header(), elevation=grid, minHeight=grid, maxHeight=grid,
                               pointCount=np.zeros((4, 3), np.int32), variance=grid)
    plan = PlanMapEventIDL(**header(), hazard=np.zeros((4, 3), np.float32),
                           goodness=np.zeros((4, 3), np.float32),
                           vehiclePosition=Position3DIDL(),
                           aPrioriCost=np.ones((4, 3), np.float32),
                           sensedCost=np.full((4, 3), np.inf, np.float32),
                           planningBoundary=PlanningBoundaryIDL(minX=0, minY=0, maxX=3, maxY=2))
    converter = ViewerConverter()
    for body in (terrain, plan):
        [(_, schema, message)] = converter.convert("Map", "map", body)
        assert schema == "foxglove.Grid"
        conforms(message, SCHEMAS[schema])


def test_arc_votes_are_a_scene_update_of_arcs_in_the_vehicle_frame():
    votes = ArcVoteIDL(time=TimeIDL(sec=1), behaviour="PurePursuit",
                       curvatures=np.array([-0.2, 0.0, 0.2]), veto=np.array([True, False, False]),
                       vote=np.array([0.0, 1.0, 0.5]), certainty=np.array([1.0, 1.0, 0.0]),
                       maxSpeed=np.array([0.0, 2.0, 1.0]))
    [(topic, schema, update)] = ViewerConverter().convert("ArcVote", "pp", votes)
    assert schema == "foxglove.SceneUpdate"
    conforms(update, SCHEMAS[schema])
    [entity] = update["entities"]
    assert entity["id"] == "PurePursuit" and entity["frame_id"] == "Raptor:RearAxleCenter"
    lines = entity["lines"]
    assert len(lines) == 3 and lines[0]["color"]["r"] == 1.0  # the vetoed arc is red
    straight, left = lines[1]["points"], lines[2]["points"]
    assert all(p["y"] == 0.0 for p in straight) and straight[-1]["x"] == pytest.approx(6.0)
    assert left[-1]["y"] > 0  # positive curvature turns left
    # what the recorder writes is the same document, encoded the fast way
    [(_, _, encoded)] = ViewerConverter().encode("ArcVote", "pp", votes)
    assert json.loads(encoded) == json.loads(json.dumps(update))


def test_a_pose_is_a_pose_in_frame_and_a_transform_and_points_a_point_cloud():
    yaw = 0.7
    transform = np.eye(4)
    transform[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    transform[:3, 3] = [1.0, 2.0, 3.0]
    pose = PoseTransformIDL(time=TimeIDL(sec=3), HTransform=transform, initialUTM=np.zeros(3))
    converter = ViewerConverter()
    (t1, s1, in_frame), (t2, s2, tf) = converter.convert("Pose", "ms", pose)
    assert (s1, s2) == ("foxglove.PoseInFrame", "foxglove.FrameTransform")
    conforms(in_frame, SCHEMAS[s1])
    conforms(tf, SCHEMAS[s2])
    assert in_frame["pose"]["orientation"]["z"] == pytest.approx(math.sin(yaw / 2))
    assert tf["parent_frame_id"] == "world" and tf["child_frame_id"] == "Raptor:RearAxleCenter"
    points = np.array([[1, 2, 3], [4, 5, 6]], np.float32)
    scan = Range3dSeqEventIDL(time=TimeIDL(sec=3), sensorId=11, frame="L:F", points=points)
    [(_, schema, cloud)] = converter.convert("Laser11", "laser", scan)
    conforms(cloud, SCHEMAS[schema])
    assert np.array_equal(np.frombuffer(base64.b64decode(cloud["data"]), "<f4").reshape(-1, 3),
                          points)


def test_quaternions_of_rotations_about_each_axis():
    for axis in range(3):
        angle = 2.5
        c, s = math.cos(angle), math.sin(angle)
        m = np.eye(3)
        a, b = [k for k in range(3) if k != axis]
        m[a, a], m[a, b], m[b, a], m[b, b] = c, -s, s, c
        q = quaternion(m)
        sign = 1 if axis != 1 else -1  # about y the plane (z, x) turns the other way
        assert q["xyz"[axis]] == pytest.approx(sign * math.sin(angle / 2))
        assert q["w"] == pytest.approx(math.cos(angle / 2))


def test_a_recorded_simulation_has_viewer_channels_with_foxglove_schema_names(recorded):
    with LogReader(recorded) as reader:
        viewer = {c.topic: c for c in reader.topics(fmt.VIEWER)}
        assert viewer["/viz/Pose"].schema == "foxglove.PoseInFrame"
        assert viewer["/viz/tf"].schema == "foxglove.FrameTransform"
        assert viewer["/viz/Laser11"].schema == viewer["/viz/Stereo"].schema == \
            "foxglove.PointCloud"
        assert viewer["/viz/Terrain"].schema == "foxglove.Grid"
        assert all(c.encoding == ENCODINGS.get(c.schema, "json") for c in viewer.values())
        assert {c.encoding for c in viewer.values()} == {"json", "protobuf"}
        frames = set()
        for message in reader.messages(channels=[viewer["/viz/tf"].id]):
            frames.add(json.loads(message.data)["child_frame_id"])
        # the clouds and grids decode with the descriptor set the file carries, and
        # hold the points and cells of the recorded events
        schemas = {name: (encoding, data) for name, encoding, data in reader.schemas.values()}
        events = {c.topic: c for c in reader.topics(fmt.EVENT)}
        for topic, event_topic in (("/viz/Stereo", "/Raptor/Stereo"),
                                   ("/viz/Terrain", "/Raptor/Terrain")):
            channel = viewer[topic]
            encoding, descriptor_set = schemas[channel.schema]
            assert encoding == "protobuf"
            drawn = [decoded(channel.schema, m.data, descriptor_set)
                     for m in reader.messages(channels=[channel.id])]
            recorded_events = [reader.decode_event(m) for m in
                               reader.messages(channels=[events[event_topic].id])]
            assert drawn and recorded_events
            first = drawn[0]
            body = next(e.body for e in recorded_events
                        if e.body.time.sec == first["timestamp"]["sec"]
                        and e.body.time.usec * 1000 == first["timestamp"]["nsec"])
            [(_, _, expected)] = ViewerConverter().convert(event_topic[8:], "x", body)
            assert first == expected
    assert {"FrontNoddingSICKLeft:AxleCenterFreeEnd", "Digiclops:ImagePlane"} <= frames


def test_votes_and_maps_are_drawn_at_display_rates_poses_at_every_stamp():
    """100 votes a second from each of two behaviours, four maps a second and a pose at
    every vote, for 2 s of stamps: each behaviour's votes are drawn every
    VOTE_INTERVAL, the maps every GRID_INTERVAL, every pose; a stamp going back (a
    replay's seek) is drawn again."""
    from afa.log.viewer import GRID_INTERVAL, VOTE_INTERVAL

    converter = ViewerConverter()
    drawn: dict[str, list[float]] = {}

    def vote(t, behaviour):
        return ArcVoteIDL(time=TimeIDL.from_seconds(t), behaviour=behaviour,
                          curvatures=np.array([-0.2, 0.0, 0.2]), veto=np.zeros(3, bool),
                          vote=np.array([0.0, 1.0, 0.5]), certainty=np.ones(3),
                          maxSpeed=np.ones(3))

    def terrain(t):
        fields = header()
        fields["time"] = TimeIDL.from_seconds(t)
        heights = np.zeros((4, 3), np.float32)
        return MapArrayEventIDL(**fields, elevation=heights, minHeight=heights,
                                maxHeight=heights, pointCount=np.zeros((4, 3), np.int32),
                                variance=heights)

    for k in range(200):
        t = 100.0 + k / 100.0
        for behaviour in ("PurePursuit", "FindPath"):
            if converter.encode("ArcVote", behaviour, vote(t, behaviour)):
                drawn.setdefault(behaviour, []).append(t)
        pose = PoseTransformIDL(time=TimeIDL.from_seconds(t), HTransform=np.eye(4),
                                initialUTM=np.zeros(3))
        drawn.setdefault("Pose", []).extend(
            t for topic, _, _ in converter.encode("Pose", "ms", pose) if topic == "/viz/Pose")
        if k % 25 == 0:
            for _ in converter.encode("Terrain", "terrain", terrain(t)):
                drawn.setdefault("Terrain", []).append(t)
    expected_votes = [100.0 + VOTE_INTERVAL * n for n in range(int(2 / VOTE_INTERVAL))]
    for behaviour in ("PurePursuit", "FindPath"):
        assert drawn[behaviour] == pytest.approx(expected_votes)
    assert drawn["Terrain"] == pytest.approx(
        [100.0 + GRID_INTERVAL * n for n in range(int(2 / GRID_INTERVAL))])
    assert len(drawn["Pose"]) == 200
    # seeking back draws at once
    assert converter.encode("ArcVote", "PurePursuit", vote(100.1, "PurePursuit"))


def test_what_the_recorder_writes_is_the_converted_document():
    """``encode`` writes point clouds and maps as protobuf: decoded by the protobuf
    package they must be exactly what ``convert`` builds, for every point-cloud form and
    every map type, NaN cells and points included."""
    rng = np.random.default_rng(4)
    beams = rng.normal(size=(7, 3))
    valid = np.array([True, False, True, True, False, True, True])
    beams[~valid] = np.nan
    pixels = rng.normal(size=(3, 4, 3)).astype(np.float32)
    seen = rng.random((3, 4)) > 0.4
    pixels[~seen] = np.nan
    stamp = TimeIDL(sec=1126958401, usec=123456)
    from idl import Range3dArrayEventIDL, Range3dLaserIDL, Range3dStereoEventIDL

    bodies = [
        ("Laser11", "laser", Range3dSeqEventIDL(time=stamp, sensorId=11, frame="L:F \u00e9",
                                                points=beams[valid])),
        ("Laser12", "laser", Range3dLaserIDL(time=stamp, sensorId=12, frame="L:G",
                                             points=beams, valid=valid)),
        ("Stereo", "stereo", Range3dStereoEventIDL(time=stamp, sensorId=3, frame="D:I",
                                                   points=pixels, valid=seen)),
        ("StereoSeq", "stereo2", Range3dArrayEventIDL(time=stamp, sensorId=4, frame="D:I",
                                                      points=pixels[seen])),
        ("Empty", "laser", Range3dSeqEventIDL(time=stamp, sensorId=13, frame="L:H",
                                              points=np.zeros((0, 3)))),
    ]
    cells = np.arange(12, dtype=np.float32).reshape(4, 3) / 13
    cells[0, 2] = np.nan
    fields = header()
    fields["time"] = stamp
    bodies += [
        ("Terrain", "terrain", MapArrayEventIDL(
            **fields, elevation=cells, minHeight=cells - 1, maxHeight=cells + 1,
            pointCount=np.ones((4, 3), np.int32), variance=cells * 2)),
        ("Traverse", "trav", TravMapArrayEventIDL(
            **fields, hazard=cells, goodness=np.nan_to_num(1 - cells),
            vehiclePosition=Position3DIDL())),
        ("PlanMap", "plan", PlanMapEventIDL(
            **fields, hazard=cells, goodness=np.nan_to_num(cells),
            vehiclePosition=Position3DIDL(),
            aPrioriCost=np.ones((4, 3), np.float32),
            sensedCost=np.full((4, 3), np.inf, np.float32),
            planningBoundary=PlanningBoundaryIDL(minX=0, minY=0, maxX=3, maxY=2))),
    ]
    for event_type, origin, body in bodies:
        converted = ViewerConverter().convert(event_type, origin, body)
        encoded = ViewerConverter().encode(event_type, origin, body)
        assert len(converted) == len(encoded) == 1, event_type
        [(topic, schema, message)], [(topic2, schema2, data)] = converted, encoded
        assert (topic, schema) == (topic2, schema2)
        assert ENCODINGS[schema] == "protobuf"
        document = decoded(schema, data)
        # NaN cells and points: compare their bytes, then the rest as values
        assert document.pop("data") == message["data"]
        assert document == {k: v for k, v in message.items() if k != "data"}, event_type
        conforms(message, SCHEMAS[schema])
    # the drawn points of a static form are its valid ones, NaN-free
    [(_, _, data)] = ViewerConverter().encode("Stereo", "stereo", bodies[2][2])
    drawn = np.frombuffer(base64.b64decode(decoded("foxglove.PointCloud", data)["data"]),
                          "<f4").reshape(-1, 3)
    assert np.array_equal(drawn, pixels[seen])
    # a sensor whose sequence form is drawn is not drawn again from its static form
    converter = ViewerConverter()
    assert converter.encode("Laser11", "laser", bodies[0][2])
    static = Range3dLaserIDL(time=stamp, sensorId=11, frame="L:F", points=beams, valid=valid)
    assert converter.encode("Laser11Array", "laser", static) == []


def _rotation_of(q):
    """The rotation matrix of a unit quaternion (the textbook formula)."""
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    return q if np.linalg.det(q) > 0 else -q


def test_poses_are_written_byte_for_byte_as_converted_and_their_quaternions_turn_back():
    """``encode`` writes a pose's two documents as text: the bytes must be exactly
    ``json.dumps`` of what ``convert`` builds, for rotations through each branch of the
    quaternion's formula (trace positive, and each diagonal element largest), and the
    quaternion must give the rotation back."""
    rng = np.random.default_rng(11)
    rotations = [_random_rotation(rng) for _ in range(40)]
    rotations += [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]),
                  np.diag([-1.0, -1.0, 1.0]), np.eye(3)]
    branches = set()
    for k, rotation in enumerate(rotations):
        transform = np.eye(4)
        transform[:3, :3] = rotation
        transform[:3, 3] = rng.normal(size=3) * 10.0 ** rng.integers(-6, 7)
        pose = PoseTransformIDL(time=TimeIDL(sec=1126958401 + k, usec=k * 977),
                                HTransform=transform, initialUTM=np.zeros(3))
        converted = ViewerConverter().convert("Pose", "ms", pose)
        encoded = ViewerConverter().encode("Pose", "ms", pose)
        assert [(t, s) for t, s, _ in converted] == [(t, s) for t, s, _ in encoded]
        for (_, schema, message), (_, _, data) in zip(converted, encoded, strict=True):
            assert data == json.dumps(message, separators=(",", ":"), allow_nan=False).encode()
            conforms(json.loads(data), SCHEMAS[schema])
        q = quaternion(rotation)
        assert q["w"] >= 0
        assert np.allclose(_rotation_of(q), rotation, atol=1e-12)
        diagonal = np.diag(rotation)
        branches.add("trace" if diagonal.sum() > 0 else int(np.argmax(diagonal)))
    assert branches == {"trace", 0, 1, 2}


#: Foxglove's documented protobuf schemas (foxglove/schemas, schemas/proto/foxglove/
#: PointCloud.proto, Grid.proto, PackedElementField.proto, Pose.proto, Vector2.proto,
#: Vector3.proto, Quaternion.proto; google/protobuf/timestamp.proto): message ->
#: [(field, number, type, message or enum type, repeated)].
FOXGLOVE = {
    "foxglove.PointCloud": [
        ("timestamp", 1, "MESSAGE", "google.protobuf.Timestamp", False),
        ("frame_id", 2, "STRING", "", False), ("pose", 3, "MESSAGE", "foxglove.Pose", False),
        ("point_stride", 4, "FIXED32", "", False),
        ("fields", 5, "MESSAGE", "foxglove.PackedElementField", True),
        ("data", 6, "BYTES", "", False)],
    "foxglove.Grid": [
        ("timestamp", 1, "MESSAGE", "google.protobuf.Timestamp", False),
        ("frame_id", 2, "STRING", "", False), ("pose", 3, "MESSAGE", "foxglove.Pose", False),
        ("column_count", 4, "FIXED32", "", False),
        ("cell_size", 5, "MESSAGE", "foxglove.Vector2", False),
        ("row_stride", 6, "FIXED32", "", False), ("cell_stride", 7, "FIXED32", "", False),
        ("fields", 8, "MESSAGE", "foxglove.PackedElementField", True),
        ("data", 9, "BYTES", "", False)],
    "foxglove.PackedElementField": [
        ("name", 1, "STRING", "", False), ("offset", 2, "FIXED32", "", False),
        ("type", 3, "ENUM", "foxglove.PackedElementField.NumericType", False)],
    "foxglove.Pose": [("position", 1, "MESSAGE", "foxglove.Vector3", False),
                      ("orientation", 2, "MESSAGE", "foxglove.Quaternion", False)],
    "foxglove.Vector2": [(a, k + 1, "DOUBLE", "", False) for k, a in enumerate("xy")],
    "foxglove.Vector3": [(a, k + 1, "DOUBLE", "", False) for k, a in enumerate("xyz")],
    "foxglove.Quaternion": [(a, k + 1, "DOUBLE", "", False) for k, a in enumerate("xyzw")],
    "google.protobuf.Timestamp": [("seconds", 1, "INT64", "", False),
                                  ("nanos", 2, "INT32", "", False)],
}


def _repeated(field):
    """Whether a protobuf field is repeated (``is_repeated`` since protobuf 6, ``label``
    before)."""
    repeated = getattr(field, "is_repeated", None)
    return field.label == field.LABEL_REPEATED if repeated is None else repeated


def test_the_protobuf_schemas_are_foxglove_s_field_for_field():
    from google.protobuf.descriptor import FieldDescriptor

    types = {name[5:]: value for name, value in vars(FieldDescriptor).items()
             if name.startswith("TYPE_")}
    for root in ("foxglove.PointCloud", "foxglove.Grid"):
        cls = message_class(root, protobuf.SCHEMAS[root])
        pool = cls.DESCRIPTOR.file.pool
        seen = set()
        pending = [root]
        while pending:
            name = pending.pop()
            seen.add(name)
            descriptor = pool.FindMessageTypeByName(name)
            got = []
            for f in descriptor.fields:
                target = f.message_type or f.enum_type
                got.append((f.name, f.number, f.type, target.full_name if target else "",
                            _repeated(f)))
                if f.message_type is not None and f.message_type.full_name not in seen:
                    pending.append(f.message_type.full_name)
            assert got == [(n, k, types[t], target, repeated)
                           for n, k, t, target, repeated in FOXGLOVE[name]], name
        assert seen == ({"foxglove.PointCloud"} if root.endswith("Cloud") else
                        {"foxglove.Grid", "foxglove.Vector2"}) | {
            "foxglove.Pose", "foxglove.Vector3", "foxglove.Quaternion",
            "foxglove.PackedElementField", "google.protobuf.Timestamp"}
        numeric = pool.FindEnumTypeByName("foxglove.PackedElementField.NumericType")
        assert [(v.name, v.number) for v in numeric.values] == list(zip(
            ["UNKNOWN", "UINT8", "INT8", "UINT16", "INT16", "UINT32", "INT32", "FLOAT32",
             "FLOAT64"], range(9), strict=True))


def test_protobuf_values_at_their_limits_decode_as_written():
    """Varints of every length, negative and signed-zero doubles, empty data."""
    cls = message_class("foxglove.PointCloud", protobuf.SCHEMAS["foxglove.PointCloud"])
    for seconds, nanos in ((0, 0), (1, 1), (127, 128), (16383, 16384), (2**31, 999_999_999),
                           (2**63 - 1, 5)):
        origin = protobuf.pose((-0.0, -1.5e-300, 2.0**70), (0.0, -0.0, 1e308, -1.0))
        parts = protobuf.point_cloud(seconds, nanos, "frame \u00e9",
                                     wire.byte_view(np.zeros((0, 3), "<f4")),
                                     origin=origin, stride=2**32 - 1,
                                     fields=(("x", 2**32 - 1, 8), ("", 0, 0)))
        message = cls.FromString(b"".join(bytes(p) for p in parts))
        assert (message.timestamp.seconds, message.timestamp.nanos) == (seconds, nanos)
        assert message.frame_id == "frame \u00e9" and message.point_stride == 2**32 - 1
        position, orientation = message.pose.position, message.pose.orientation
        assert (position.x, position.y, position.z) == (0.0, -1.5e-300, 2.0**70)
        assert math.copysign(1.0, position.x) == -1.0  # -0.0 kept
        assert (orientation.x, orientation.y, orientation.z, orientation.w) == \
            (0.0, 0.0, 1e308, -1.0)
        assert math.copysign(1.0, orientation.y) == -1.0
        assert [(f.name, f.offset, f.type) for f in message.fields] == \
            [("x", 2**32 - 1, 8), ("", 0, 0)]
        assert message.data == b""


def _as_dict(message):
    """Every field of a protobuf package message, bytes in base64 (what Decoder gives)."""
    out = {}
    for field in message.DESCRIPTOR.fields:
        value = getattr(message, field.name)
        if field.message_type is not None:
            value = [_as_dict(v) for v in value] if _repeated(field) else _as_dict(value)
        elif isinstance(value, bytes):
            value = base64.b64encode(value).decode("ascii")
        out[field.name] = value
    return out


def test_the_echo_tool_s_decoder_reads_what_the_protobuf_package_reads():
    rng = np.random.default_rng(2)
    points = rng.normal(size=(50, 3)).astype(np.float32)
    scan = Range3dSeqEventIDL(time=TimeIDL(sec=7, usec=5), sensorId=11, frame="L:F",
                              points=points)
    cells = rng.random((6, 5)).astype(np.float32)
    fields = header(rows=6, cols=5)
    travel = TravMapArrayEventIDL(**fields, hazard=cells, goodness=1 - cells,
                                  vehiclePosition=Position3DIDL())
    for event_type, body in (("Laser11", scan), ("Traverse", travel)):
        [(_, schema, parts)] = ViewerConverter().encode(event_type, "x", body)
        data = b"".join(bytes(p) for p in parts)
        expected = _as_dict(message_class(schema, protobuf.SCHEMAS[schema]).FromString(data))
        assert protobuf.Decoder(protobuf.SCHEMAS[schema]).decode(schema, data) == expected
    with pytest.raises(ValueError):
        protobuf.Decoder(protobuf.SCHEMAS[schema]).decode(schema, data[:-3])
