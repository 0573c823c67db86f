"""Viewer channels: afa events as Foxglove schemas, so a recording opens usefully in
Foxglove or Lichtblick (their 3-D panel draws a topic only if its schema name is exactly
one of Foxglove's), and only long-standing schemas Lichtblick also reads. Point clouds
and grids are protobuf messages (message and schema encoding ``protobuf``, the schema a
FileDescriptorSet, :mod:`afa.log.protobuf`): their data binary, not base64 (decision
0038); the others JSON (schema encoding ``jsonschema``, message encoding ``json``):

================================  ======================  ==================================
afa body                          topic                   Foxglove schema
================================  ======================  ==================================
PoseTransformIDL (``Pose``)       ``/viz/<event>``        ``foxglove.PoseInFrame`` (world)
                                  ``/viz/tf``             ``foxglove.FrameTransform`` world ->
                                                          ``Raptor:RearAxleCenter``
geometry model (Platform polls)   ``/viz/tf``             ``foxglove.FrameTransform`` vehicle
                                                          -> every frame the model has
laser and stereo points           ``/viz/<event>``        ``foxglove.PointCloud`` (x, y, z
                                                          float32, in the sensor's frame)
terrain, traversability, plan     ``/viz/<event>``        ``foxglove.Grid`` in ``world``
maps
ArcVoteIDL                        ``/viz/<event>``        ``foxglove.SceneUpdate``: one entity
                                                          per behaviour, an arc per curvature
================================  ======================  ==================================

Each converter is a pure function of the body (no clock, no I/O); :class:`ViewerConverter`
picks one per body type and remembers which sensors have a sequence form, so a laser's
points are drawn once, not once per form.

**Display rates.** Votes and maps are drawn at most every :data:`VOTE_INTERVAL` (per
behaviour) and :data:`GRID_INTERVAL` (per map topic) seconds of their own time stamps:
a viewer refreshes no faster, and at full rate the two were two thirds of a recording's
bytes (a 27-arc scene for each of ~80 votes a second, a 160 × 160 grid four times a
second as JSON). The afa events themselves are always recorded whole; poses, frames and
points are drawn at full rate.
"""

from __future__ import annotations

import base64
import functools
import json
import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from afa.log import protobuf
from idl import (
    ArcVoteIDL,
    EgoMapArrayEventIDL,
    EtravMapArrayEventIDL,
    MapArrayEventIDL,
    PlanMapEventIDL,
    PoseTransformIDL,
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
    TimeIDL,
    TravMapArrayEventIDL,
    wire,
)
from idl._base import IDLModel

__all__ = ["WORLD_FRAME", "VEHICLE_FRAME", "TF_TOPIC", "SCHEMAS", "ViewerMessage",
           "VOTE_INTERVAL", "GRID_INTERVAL",
           "ViewerConverter", "pose_in_frame", "frame_transform", "point_cloud", "grid",
           "point_cloud_protobuf", "grid_protobuf", "arc_votes", "arc_votes_json",
           "pose_json", "quaternion", "viewer_topic", "ENCODINGS", "schema_of"]

#: The frame ``Pose`` events place the vehicle in (x east, y north, origin initialUTM).
WORLD_FRAME = "world"
#: The vehicle reference frame a Pose's HTransform is ^W T_V of (idl.PoseTransformIDL).
VEHICLE_FRAME = "Raptor:RearAxleCenter"
TF_TOPIC = "/viz/tf"
#: Least time (s, of the bodies' stamps) between two drawings of one behaviour's votes
#: and of one map topic (module docstring: display rates).
VOTE_INTERVAL = 0.5
GRID_INTERVAL = 1.0
#: How far an arc of ArcVoteIDL is drawn (m) and with how many points.
ARC_LENGTH = 6.0
ARC_POINTS = 13

#: A message for a viewer channel: (topic, schema name, JSON-ready object).
ViewerMessage = tuple[str, str, dict[str, Any]]

FLOAT32 = 7  # foxglove.NumericType
_LINE_STRIP = 0  # foxglove.LineType


def viewer_topic(event_type: str) -> str:
    return f"/viz/{event_type}"


# -- the JSON schemas (written from Foxglove's documented fields) ----------------------------

def _object(title: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "type": "object", "properties": properties,
            "required": list(properties)}


_NUMBER = {"type": "number"}
_TIME = _object("time", {"sec": {"type": "integer", "minimum": 0},
                         "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}})
_DURATION = _object("duration", {"sec": {"type": "integer"},
                                 "nsec": {"type": "integer", "minimum": 0,
                                          "maximum": 999_999_999}})
_VECTOR3 = _object("foxglove.Vector3", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER})
_POINT3 = _object("foxglove.Point3", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER})
_QUATERNION = _object("foxglove.Quaternion", {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER,
                                              "w": _NUMBER})
_POSE = _object("foxglove.Pose", {"position": _VECTOR3, "orientation": _QUATERNION})
_COLOR = _object("foxglove.Color", {"r": _NUMBER, "g": _NUMBER, "b": _NUMBER, "a": _NUMBER})
_NUMERIC_TYPE = {"title": "foxglove.NumericType", "oneOf": [
    {"title": name, "const": value} for value, name in enumerate(
        ["UNKNOWN", "UINT8", "INT8", "UINT16", "INT16", "UINT32", "INT32", "FLOAT32",
         "FLOAT64"])]}
_PACKED_FIELD = _object("foxglove.PackedElementField", {
    "name": {"type": "string"}, "offset": {"type": "integer", "minimum": 0},
    "type": _NUMERIC_TYPE})
_BYTES = {"type": "string", "contentEncoding": "base64"}
_LINE = _object("foxglove.LinePrimitive", {
    "type": {"title": "foxglove.LineType", "oneOf": [
        {"title": "LINE_STRIP", "const": 0}, {"title": "LINE_LOOP", "const": 1},
        {"title": "LINE_LIST", "const": 2}]},
    "pose": _POSE, "thickness": _NUMBER, "scale_invariant": {"type": "boolean"},
    "points": {"type": "array", "items": _POINT3}, "color": _COLOR,
    "colors": {"type": "array", "items": _COLOR},
    "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}}})
_EMPTY_LIST = {"type": "array", "items": {"type": "object"}}
_ENTITY = _object("foxglove.SceneEntity", {
    "timestamp": _TIME, "frame_id": {"type": "string"}, "id": {"type": "string"},
    "lifetime": _DURATION, "frame_locked": {"type": "boolean"},
    "metadata": {"type": "array", "items": _object("foxglove.KeyValuePair", {
        "key": {"type": "string"}, "value": {"type": "string"}})},
    "arrows": _EMPTY_LIST, "cubes": _EMPTY_LIST, "spheres": _EMPTY_LIST,
    "cylinders": _EMPTY_LIST, "lines": {"type": "array", "items": _LINE},
    "triangles": _EMPTY_LIST, "texts": _EMPTY_LIST, "models": _EMPTY_LIST})

#: Foxglove schema name -> JSON schema document.
SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.PoseInFrame": _object("foxglove.PoseInFrame", {
        "timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE}),
    "foxglove.FrameTransform": _object("foxglove.FrameTransform", {
        "timestamp": _TIME, "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"}, "translation": _VECTOR3,
        "rotation": _QUATERNION}),
    "foxglove.PointCloud": _object("foxglove.PointCloud", {
        "timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE,
        "point_stride": {"type": "integer", "minimum": 0},
        "fields": {"type": "array", "items": _PACKED_FIELD}, "data": _BYTES}),
    "foxglove.Grid": _object("foxglove.Grid", {
        "timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE,
        "column_count": {"type": "integer", "minimum": 0},
        "cell_size": _object("foxglove.Vector2", {"x": _NUMBER, "y": _NUMBER}),
        "row_stride": {"type": "integer", "minimum": 0},
        "cell_stride": {"type": "integer", "minimum": 0},
        "fields": {"type": "array", "items": _PACKED_FIELD}, "data": _BYTES}),
    "foxglove.SceneUpdate": _object("foxglove.SceneUpdate", {
        "deletions": {"type": "array", "items": _object("foxglove.SceneEntityDeletion", {
            "timestamp": _TIME, "type": {"title": "foxglove.SceneEntityDeletionType",
                                         "oneOf": [{"title": "MATCHING_ID", "const": 0},
                                                   {"title": "ALL", "const": 1}]},
            "id": {"type": "string"}})},
        "entities": {"type": "array", "items": _ENTITY}}),
}


#: The viewer channels written as protobuf (their data binary, decision 0038), by schema
#: name; the others are JSON.
ENCODINGS: dict[str, str] = {"foxglove.PointCloud": protobuf.ENCODING,
                             "foxglove.Grid": protobuf.ENCODING}


def schema_of(name: str) -> tuple[str, bytes]:
    """(schema encoding, schema data) of a Foxglove schema as the recorder writes it:
    ``protobuf`` and its FileDescriptorSet, or ``jsonschema`` and its JSON schema."""
    if ENCODINGS.get(name) == protobuf.ENCODING:
        return protobuf.ENCODING, protobuf.SCHEMAS[name]
    return "jsonschema", json.dumps(SCHEMAS[name]).encode()

# -- conversions ---------------------------------------------------------------------------

def _time(stamp: TimeIDL | float) -> dict[str, int]:
    if isinstance(stamp, TimeIDL):
        sec, nsec = _stamp(stamp)
        return {"sec": sec, "nsec": nsec}
    nanoseconds = max(0, round(stamp * 1e9))
    return {"sec": nanoseconds // 1_000_000_000, "nsec": nanoseconds % 1_000_000_000}


def quaternion(rotation: np.ndarray) -> dict[str, float]:
    """The unit quaternion (x, y, z, w) of a 3x3 rotation matrix (w ≥ 0)."""
    x, y, z, w = _quaternion(np.asarray(rotation, dtype=float)[:3, :3].tolist())
    return {"x": x, "y": y, "z": z, "w": w}


def _quaternion(m: list[list[float]]) -> tuple[float, float, float, float]:
    """:func:`quaternion` of a rotation given as nested lists of Python floats (the
    same IEEE operations in the same order as on numpy scalars, several times faster)."""
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        w, x = 0.25 * s, (m[2][1] - m[1][2]) / s
        y, z = (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s
    elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2])
        w, x = (m[2][1] - m[1][2]) / s, 0.25 * s
        y, z = (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s
    elif m[1][1] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2])
        w, x = (m[0][2] - m[2][0]) / s, (m[0][1] + m[1][0]) / s
        y, z = 0.25 * s, (m[1][2] + m[2][1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1])
        w, x = (m[1][0] - m[0][1]) / s, (m[0][2] + m[2][0]) / s
        y, z = (m[1][2] + m[2][1]) / s, 0.25 * s
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    sign = -1.0 if w < 0 else 1.0
    return sign * x / norm, sign * y / norm, sign * z / norm, sign * w / norm


def _pose(transform: np.ndarray) -> dict[str, Any]:
    rows = np.asarray(transform, dtype=float).tolist()
    x, y, z, w = _quaternion(rows)
    return {"position": {"x": rows[0][3], "y": rows[1][3], "z": rows[2][3]},
            "orientation": {"x": x, "y": y, "z": z, "w": w}}


def pose_in_frame(pose: PoseTransformIDL) -> dict[str, Any]:
    """``foxglove.PoseInFrame``: the vehicle in the world frame."""
    return {"timestamp": _time(pose.time), "frame_id": WORLD_FRAME,
            "pose": _pose(pose.HTransform)}


def frame_transform(parent: str, child: str, transform: np.ndarray,
                    stamp: TimeIDL | float) -> dict[str, Any]:
    """``foxglove.FrameTransform``: ``transform`` is ^parent T_child."""
    pose = _pose(transform)
    return {"timestamp": _time(stamp), "parent_frame_id": parent, "child_frame_id": child,
            "translation": pose["position"], "rotation": pose["orientation"]}


def _float_json(value: float) -> str:
    """A finite float as json writes it (its repr); ValueError otherwise, as
    ``dumps`` (``allow_nan=False``) raises for any other message."""
    if not math.isfinite(value):
        raise ValueError(f"Out of range float values are not JSON compliant: {value!r}")
    return repr(value)


def pose_json(pose: PoseTransformIDL) -> tuple[bytes, bytes]:
    """``dumps`` of :func:`pose_in_frame` and of the world -> vehicle
    :func:`frame_transform`, the same bytes (a test compares them), the quaternion
    computed once and the documents written as text: a pose comes 14 times a second."""
    rows = pose.HTransform.tolist()
    x, y, z, w = map(_float_json, _quaternion(rows))
    px, py, pz = _float_json(rows[0][3]), _float_json(rows[1][3]), _float_json(rows[2][3])
    stamp = _time_json(pose.time)
    position = f'{{"x":{px},"y":{py},"z":{pz}}}'
    rotation = f'{{"x":{x},"y":{y},"z":{z},"w":{w}}}'
    return (f'{{"timestamp":{stamp},"frame_id":{_WORLD_JSON},"pose":{{"position":'
            f'{position},"orientation":{rotation}}}}}'.encode(),
            f'{{"timestamp":{stamp},"parent_frame_id":{_WORLD_JSON},"child_frame_id":'
            f'{_VEHICLE_JSON},"translation":{position},"rotation":{rotation}}}'.encode())


_WORLD_JSON = json.dumps(WORLD_FRAME)
_VEHICLE_JSON = json.dumps(VEHICLE_FRAME)


_IDENTITY_POSE = {"position": {"x": 0.0, "y": 0.0, "z": 0.0},
                  "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
_XYZ = [{"name": axis, "offset": 4 * k, "type": FLOAT32} for k, axis in enumerate("xyz")]


def point_cloud(stamp: TimeIDL, frame: str, points: np.ndarray) -> dict[str, Any]:
    """``foxglove.PointCloud`` of ``(n, 3)`` float32 points in ``frame``."""
    data = np.ascontiguousarray(points, dtype="<f4")
    return {"timestamp": _time(stamp), "frame_id": frame, "pose": _IDENTITY_POSE,
            "point_stride": 12, "fields": _XYZ,
            "data": base64.b64encode(data.data).decode("ascii")}


def grid(body: Any, layers: Iterable[str]) -> dict[str, Any]:
    """``foxglove.Grid`` of a map's ``layers`` (float32 each), placed in the world frame.

    afa's cell [i, j] lies at map x = originX + i·g, y = originY + j·g (i along x); a
    Foxglove grid is row-major with rows along y, so its data is the layers transposed.
    """
    names = list(layers)
    data = base64.b64encode(_grid_cells(body, names).data).decode("ascii")
    cell = 4 * len(names)
    return {"timestamp": _time(body.time), "frame_id": WORLD_FRAME,
            "pose": _pose(_grid_origin(body)),
            "column_count": int(body.rows), "cell_size": {"x": float(body.gridsize),
                                                         "y": float(body.gridsize)},
            "row_stride": cell * int(body.rows), "cell_stride": cell,
            "fields": [{"name": n, "offset": 4 * k, "type": FLOAT32}
                       for k, n in enumerate(names)],
            "data": data}


def _grid_cells(body: Any, names: Iterable[str]) -> np.ndarray:
    """A map's layers as a Foxglove grid's cells: rows along y (the layers transposed),
    each cell the layers' float32 values, C-contiguous."""
    cells = [np.asarray(getattr(body, name)).T for name in names]
    stack = np.empty((*cells[0].shape, len(cells)), dtype="<f4")
    for k, layer in enumerate(cells):
        stack[..., k] = layer  # one strided copy per layer, no intermediate float32 arrays
    return stack


def _grid_origin(body: Any) -> np.ndarray:
    """^W T of a map's corner cell (the grid's pose): the map's pose at its origin."""
    corner = np.eye(4)
    corner[0, 3], corner[1, 3] = body.originX, body.originY
    return np.asarray(body.mapPose) @ corner


def _time_json(stamp: TimeIDL | float) -> str:
    """``_compact(_time(stamp))``."""
    if isinstance(stamp, TimeIDL):
        sec, nsec = _stamp(stamp)
        return f'{{"sec":{sec},"nsec":{nsec}}}'
    return _compact(_time(stamp))


def _stamp(stamp: TimeIDL) -> tuple[int, int]:
    """A time stamp as a Foxglove time's (seconds, nanoseconds), 0 s at the earliest."""
    return max(0, int(stamp.sec)), int(stamp.usec) * 1000


def point_cloud_protobuf(stamp: TimeIDL, frame: str, points: np.ndarray
                         ) -> list[bytes | memoryview]:
    """:func:`point_cloud` as protobuf (:mod:`afa.log.protobuf`), the parts of its bytes:
    the points' bytes are not copied (the recorder copies them once, into the chunk);
    the viewer channel written most (a laser scan line every 12 ms, a stereo frame of
    ~30 000 points)."""
    data = np.ascontiguousarray(points, dtype="<f4")
    return protobuf.point_cloud(*_stamp(stamp), frame, wire.byte_view(data))


def grid_protobuf(body: Any, layers: Iterable[str]) -> list[bytes | memoryview]:
    """:func:`grid` as protobuf (:mod:`afa.log.protobuf`), the parts of its bytes."""
    names = tuple(layers)
    rows = _grid_origin(body).tolist()
    origin = protobuf.pose((rows[0][3], rows[1][3], rows[2][3]), _quaternion(rows))
    size = float(body.gridsize)
    return protobuf.grid(*_stamp(body.time), WORLD_FRAME, origin, int(body.rows),
                         (size, size), 4 * len(names), _layer_fields(names),
                         wire.byte_view(_grid_cells(body, names)))


@functools.lru_cache(maxsize=32)
def _layer_fields(names: tuple[str, ...]) -> tuple[tuple[str, int, int], ...]:
    return tuple((name, 4 * k, FLOAT32) for k, name in enumerate(names))


def _arc(curvature: float) -> list[dict[str, float]]:
    points = []
    for k in range(ARC_POINTS):
        s = ARC_LENGTH * k / (ARC_POINTS - 1)
        if abs(curvature) < 1e-9:
            x, y = s, 0.0
        else:
            x = math.sin(curvature * s) / curvature
            y = (1.0 - math.cos(curvature * s)) / curvature
        points.append({"x": x, "y": y, "z": 0.0})
    return points


@functools.lru_cache(maxsize=4096)
def _arc_json(curvature: float) -> str:
    """An arc's points as JSON: a behaviour votes on the same few curvatures each time."""
    return json.dumps(_arc(curvature), separators=(",", ":"), allow_nan=False)


_LINE_HEAD = json.dumps({"type": _LINE_STRIP, "pose": _IDENTITY_POSE, "thickness": 2.0,
                         "scale_invariant": True}, separators=(",", ":"))[:-1]


def _vote_color(votes: ArcVoteIDL, k: int) -> dict[str, float]:
    if votes.veto[k]:
        return {"r": 1.0, "g": 0.0, "b": 0.0, "a": 1.0}
    vote = float(votes.vote[k])
    return {"r": 1.0 - vote, "g": vote, "b": 0.2, "a": 0.25 + 0.75 * float(votes.certainty[k])}


def _votes_scene(votes: ArcVoteIDL, lines: list[Any]) -> dict[str, Any]:
    entity = {"timestamp": _time(votes.time), "frame_id": VEHICLE_FRAME,
              "id": votes.behaviour or "votes", "lifetime": {"sec": 0, "nsec": 0},
              "frame_locked": True,
              "metadata": [{"key": "behaviour", "value": votes.behaviour}],
              "arrows": [], "cubes": [], "spheres": [], "cylinders": [], "lines": lines,
              "triangles": [], "texts": [], "models": []}
    return {"deletions": [], "entities": [entity]}


def arc_votes(votes: ArcVoteIDL) -> dict[str, Any]:
    """``foxglove.SceneUpdate``: one entity per behaviour (replacing its last one), an arc
    per candidate curvature in the vehicle frame: red when vetoed, else green by vote and
    opaque by certainty."""
    lines = [{"type": _LINE_STRIP, "pose": _IDENTITY_POSE, "thickness": 2.0,
              "scale_invariant": True, "points": _arc(float(curvature)),
              "color": _vote_color(votes, k), "colors": [], "indices": []}
             for k, curvature in enumerate(votes.curvatures)]
    return _votes_scene(votes, lines)


def arc_votes_json(votes: ArcVoteIDL) -> bytes:
    """``dumps(arc_votes(votes))``, the same document (a test compares them) made several
    times faster: each arc's points are encoded once per curvature (a behaviour votes on
    the same curvatures every time), the hottest part of recording the viewer channels
    (an ArcVote every few milliseconds)."""
    vetoes, values, certainties = (votes.veto.tolist(), votes.vote.tolist(),
                                   votes.certainty.tolist())
    if not all(map(math.isfinite, values + certainties)):
        return dumps(arc_votes(votes))  # refuses them, as for any other message
    lines = ",".join(
        f'{_LINE_HEAD},"points":{_arc_json(curvature)},"color":'
        f'{_VETOED if vetoes[k] else _color_json(values[k], certainties[k])}'
        ',"colors":[],"indices":[]}'
        for k, curvature in enumerate(votes.curvatures.tolist()))
    # "lines":[] cannot occur inside a JSON string (its quotes would be escaped)
    return _compact(_votes_scene(votes, [])).replace('"lines":[]', f'"lines":[{lines}]',
                                                     1).encode()


_VETOED = '{"r":1.0,"g":0.0,"b":0.0,"a":1.0}'


def _color_json(vote: float, certainty: float) -> str:
    """:func:`_vote_color` as JSON (json writes a finite float as its repr)."""
    return (f'{{"r":{float(1.0 - vote)!r},"g":{float(vote)!r},"b":0.2,'
            f'"a":{float(0.25 + 0.75 * certainty)!r}}}')


def _compact(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"), allow_nan=False)


_MAP_LAYERS: dict[type, tuple[str, ...]] = {
    MapArrayEventIDL: ("elevation", "maxHeight", "variance"),
    EgoMapArrayEventIDL: ("elevation", "maxHeight", "variance"),
    TravMapArrayEventIDL: ("hazard", "goodness"),
    EtravMapArrayEventIDL: ("hazard", "goodness"),
    PlanMapEventIDL: ("hazard", "goodness", "aPrioriCost", "sensedCost"),
}


_SEQUENCE_FORMS = (Range3dSeqEventIDL, Range3dArrayEventIDL)
_STATIC_FORMS = (Range3dLaserIDL, Range3dStereoEventIDL)


class ViewerConverter:
    """Picks the viewer messages of each event (none for types viewers cannot draw)."""

    def __init__(self) -> None:
        self._sequence_sensors: set[tuple[str, int]] = set()
        self._drawn: dict[tuple[str, str], float] = {}  # (topic, who) -> last stamp drawn
        self._handlers: dict[type, Callable[[str, str, Any], list[ViewerMessage]]] = {
            PoseTransformIDL: self._pose, ArcVoteIDL: self._votes,
            **{cls: self._cloud for cls in _SEQUENCE_FORMS + _STATIC_FORMS},
            **{cls: self._map for cls in _MAP_LAYERS}}

    def convert(self, event_type: str, origin: str, body: IDLModel) -> list[ViewerMessage]:
        handler = self._handlers.get(type(body))
        if handler is None or not self._due(event_type, origin, body):
            return []
        return handler(event_type, origin, body)

    def _due(self, event_type: str, origin: str, body: IDLModel) -> bool:
        """Whether a vote or map is to be drawn now (display rates, module docstring);
        always for the other bodies."""
        if type(body) is ArcVoteIDL:
            key, interval = (event_type, f"{origin}/{body.behaviour}"), VOTE_INTERVAL
        elif type(body) in _MAP_LAYERS:
            key, interval = (event_type, f"{origin}/{type(body).__name__}"), GRID_INTERVAL
        else:
            return True
        stamp = body.time.to_seconds()  # type: ignore[attr-defined]
        last = self._drawn.get(key)
        if last is not None and last <= stamp < last + interval:
            return False
        self._drawn[key] = stamp  # (a stamp going back, a replay's seek: drawn again)
        return True

    def encode(self, event_type: str, origin: str, body: IDLModel
               ) -> list[tuple[str, str, bytes | list[bytes | memoryview]]]:
        """:meth:`convert` encoded, what the recorder writes: the same documents, poses
        and votes as JSON bytes encoded the fast way (``*_json``), point clouds and grids
        as protobuf (:data:`ENCODINGS`), the parts of their bytes."""
        kind = type(body)
        if kind is PoseTransformIDL:
            in_frame, transform = pose_json(body)  # type: ignore[arg-type]
            return [(viewer_topic(event_type), "foxglove.PoseInFrame", in_frame),
                    (TF_TOPIC, "foxglove.FrameTransform", transform)]
        if type(body) is ArcVoteIDL:
            if not self._due(event_type, origin, body):
                return []
            return [(viewer_topic(event_type), "foxglove.SceneUpdate", arc_votes_json(body))]
        if kind in _SEQUENCE_FORMS or kind in _STATIC_FORMS:
            points = self._points(origin, body)
            if points is None:
                return []
            return [(viewer_topic(event_type), "foxglove.PointCloud",
                     point_cloud_protobuf(body.time, body.frame, points))]  # type: ignore[attr-defined]
        if kind in _MAP_LAYERS:
            if not self._due(event_type, origin, body):
                return []
            return [(viewer_topic(event_type), "foxglove.Grid",
                     grid_protobuf(body, _MAP_LAYERS[kind]))]
        return [(topic, schema, dumps(message))
                for topic, schema, message in self.convert(event_type, origin, body)]

    def _points(self, origin: str, body: Any) -> np.ndarray | None:
        """The points to draw of a scan or frame, None when its sequence form is drawn
        already."""
        if type(body) in _SEQUENCE_FORMS:
            self._sequence_sensors.add((origin, body.sensorId))
            return body.points  # type: ignore[no-any-return]
        if (origin, body.sensorId) in self._sequence_sensors:
            return None  # the sequence form of the same scan is drawn already
        return body.valid_points()  # type: ignore[no-any-return]

    def _pose(self, event_type: str, origin: str, pose: PoseTransformIDL
              ) -> list[ViewerMessage]:
        return [(viewer_topic(event_type), "foxglove.PoseInFrame", pose_in_frame(pose)),
                (TF_TOPIC, "foxglove.FrameTransform",
                 frame_transform(WORLD_FRAME, VEHICLE_FRAME, pose.HTransform, pose.time))]

    def _cloud(self, event_type: str, origin: str, body: Any) -> list[ViewerMessage]:
        points = self._points(origin, body)
        if points is None:
            return []
        return [(viewer_topic(event_type), "foxglove.PointCloud",
                 point_cloud(body.time, body.frame, points))]

    def _votes(self, event_type: str, origin: str, votes: ArcVoteIDL) -> list[ViewerMessage]:
        return [(viewer_topic(event_type), "foxglove.SceneUpdate", arc_votes(votes))]

    def _map(self, event_type: str, origin: str, body: Any) -> list[ViewerMessage]:
        return [(viewer_topic(event_type), "foxglove.Grid",
                 grid(body, _MAP_LAYERS[type(body)]))]


def dumps(message: dict[str, Any]) -> bytes:
    """The JSON bytes of a viewer message (finite numbers only, compact)."""
    return json.dumps(message, separators=(",", ":"), allow_nan=False).encode()
