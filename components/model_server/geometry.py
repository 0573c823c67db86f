"""ModelServer's geometry database: bodies, frames, constraints and ``getTransformation``.

Seed §3.2.4 describes the database as *Bodies*, *BodyFrames* and *Constraints*: each
constraint binds two ``Body:Frame`` vertices by a time-invariant homogeneous transform,
and the vertices with their constraints form a possibly cyclic directed graph. Table 19
asks it for ``getTransformation(A, B)`` = ^A T_B, ``getBodyList()`` and
``getBodyFrameList()``. The file format (an assembly file naming body files) is afa's own
and is specified in ``docs/geometry.md``; this module reads it.

How a query is answered
    Each ``<frame>`` of a body file is an edge ``Body:reference -> Body:frame``, so a body
    is a star around its reference frame and ^reference T_frame is known directly. The
    assembly's constraints join bodies. Scanning the constraints in file order, the
    first one that joins two not-yet-connected bodies becomes a spanning-tree edge; any
    later constraint whose bodies are already connected closes a cycle and is checked
    against the tree (so the redundant, surveyed constraint written last is the one a
    message blames). A breadth-first walk over the tree edges from each component's root
    (the assembly's ``reference`` frame, or the first body's reference frame) stores
    ^root T_node for every frame, so ``transformation(a, b)`` is one product,
    (^root T_a)^-1 · ^root T_b.

Conventions (docs/geometry.md): metres and degrees; a ``<translation x y z>`` and
``<rotation roll pitch yaw>`` give ^From T_To with t the To origin in From coordinates and
R = Rz(yaw) · Ry(pitch) · Rx(roll), the URDF fixed-axis ``rpy`` order (checked against
urdfdom_headers ``urdf_model/pose.h`` ``Rotation::setFromRPY``, whose quaternion is
q_z(yaw) q_y(pitch) q_x(roll)); with z up, positive pitch tilts x down.

Errors: a bad file is a :class:`~afa.errors.ConfigError` whose lines read
``file:line: message``; an unknown or malformed body or frame name in a query is
:class:`~afa.errors.EOutOfBounds` (Miro's exception), naming the closest existing name.
"""

from __future__ import annotations

import difflib
import math
import re
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lxml import etree

from afa.config.miro import parse_xml, read_bounded
from afa.errors import ConfigError, EOutOfBounds

__all__ = [
    "MAX_ANGLE_DEG",
    "MAX_BODIES",
    "MAX_CONSTRAINTS",
    "MAX_FILE_BYTES",
    "MAX_FRAMES",
    "MAX_MODEL_BYTES",
    "MAX_TRANSLATION_M",
    "ROTATION_TOLERANCE_DEG",
    "TRANSLATION_TOLERANCE_M",
    "Constraint",
    "GeometryModel",
    "homogeneous_transform",
    "invert_transform",
    "normalize_frame_name",
]

#: A loop may miss closing by at most this much translation (docs/geometry.md: 1 mm) ...
TRANSLATION_TOLERANCE_M = 1e-3
#: ... and this much rotation (0.01 degree).
ROTATION_TOLERANCE_DEG = 0.01
#: Geometry files are small; refuse anything larger before parsing it.
MAX_FILE_BYTES = 1 << 20
#: ... and all the files of one model together (the Raptor's: 14 kB).
MAX_MODEL_BYTES = 4 << 20
#: Bodies in an assembly, frames of all its bodies, constraints: the Raptor has 6, 43, 5.
MAX_BODIES = 1000
MAX_FRAMES = 10_000
MAX_CONSTRAINTS = 10_000
#: A translation component (m) and an angle (deg), in absolute value.
MAX_TRANSLATION_M = 10_000.0
MAX_ANGLE_DEG = 360.0

_SCHEMA_VERSION = "1"
_IDENTIFIER = re.compile(r"[^\s:]+")
_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")


# ------------------------------------------------------------------ transforms


def homogeneous_transform(translation: tuple[float, float, float] = (0.0, 0.0, 0.0),
                          rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """The 4x4 ^A T_B of a translation (metres) and roll, pitch, yaw (degrees).

    R = Rz(yaw) · Ry(pitch) · Rx(roll) (fixed axes x, y, z in that order), t = translation.
    """
    roll, pitch, yaw = (math.radians(angle) for angle in rpy_deg)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    transform = np.eye(4)
    transform[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    transform[:3, 3] = translation
    return transform


def invert_transform(transform: np.ndarray) -> np.ndarray:
    """The inverse of a rigid homogeneous transform: (R, t) -> (R^T, -R^T t)."""
    rotation_t = transform[:3, :3].T
    inverse = np.eye(4)
    inverse[:3, :3] = rotation_t
    inverse[:3, 3] = -rotation_t @ transform[:3, 3]
    return inverse


def _discrepancy(expected: np.ndarray, actual: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation angle (deg) between two transforms of the same pair."""
    translation = float(np.linalg.norm(expected[:3, 3] - actual[:3, 3]))
    relative = expected[:3, :3].T @ actual[:3, :3]
    cosine = max(-1.0, min(1.0, (float(np.trace(relative)) - 1.0) / 2.0))
    return translation, math.degrees(math.acos(cosine))


# ------------------------------------------------------------------ names


def _split_name(text: str) -> tuple[str, str] | str:
    """``(body, frame)`` of a ``Body:Frame`` name, or a message saying what is wrong."""
    parts = text.split(":")
    if len(parts) != 2:
        return f"{text!r} is not a 'Body:Frame' name (it needs exactly one ':')"
    body, frame = parts[0].strip(), parts[1].strip()
    for role, word in (("body", body), ("frame", frame)):
        if not _IDENTIFIER.fullmatch(word):
            return (f"{text!r} is not a 'Body:Frame' name (the {role} name must be non-empty, "
                    "without whitespace or ':')")
    return body, frame


def normalize_frame_name(text: str) -> str:
    """The canonical ``Body:Frame`` spelling of a frame name.

    Whitespace around the colon and at either end is dropped, so
    ``"Raptor: Front-BumperCenter"`` becomes ``"Raptor:Front-BumperCenter"``.
    Raises :class:`~afa.errors.EOutOfBounds` if the text is not of that form.
    """
    split = _split_name(text)
    if isinstance(split, str):
        raise EOutOfBounds(split)
    return f"{split[0]}:{split[1]}"


def _suggest(word: str, choices: list[str]) -> str:
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else ""


# ------------------------------------------------------------------ data


@dataclass(frozen=True, eq=False)
class Constraint:
    """One edge of the model: ``transform`` is ^source T_target (seed: *Constraint*).

    ``file`` and ``line`` locate its declaration: a ``<constraint>`` of the assembly, or a
    ``<frame>`` of a body file (name ``Body:Frame``).
    """

    name: str
    source: str
    target: str
    transform: np.ndarray
    file: Path
    line: int

    @property
    def where(self) -> str:
        """``file:line`` of the declaration."""
        return f"{self.file}:{self.line}"


@dataclass(frozen=True)
class _FrameDecl:
    name: str
    transform: np.ndarray | None  # None for the reference frame
    line: int


@dataclass(frozen=True)
class _BodyFile:
    path: Path
    type: str
    reference: str
    frames: tuple[_FrameDecl, ...]


# ------------------------------------------------------------------ XML reading


class _Budget:
    """What the files of one model may still hold, in bytes (:data:`MAX_MODEL_BYTES`)."""

    def __init__(self) -> None:
        self.left = MAX_MODEL_BYTES

    def spend(self, size: int, where: str) -> None:
        self.left -= size
        if self.left < 0:
            raise ConfigError(f"{where}: the model's files hold more than "
                              f"{MAX_MODEL_BYTES} bytes together (the limit)")


def _read_xml(path: Path, root_tag: str, where: str, budget: _Budget) -> etree._Element:
    """Parse one geometry file safely; ``where`` prefixes messages about reading it."""
    try:
        data = read_bounded(path, MAX_FILE_BYTES)
    except OSError as exc:
        raise ConfigError(f"{where}: cannot read {path}: {exc.strerror or exc}") from exc
    budget.spend(len(data), where)
    root = parse_xml(data, path)
    if root.tag != root_tag:
        raise ConfigError(f"{path}:{root.sourceline}: the root element must be <{root_tag}>, "
                          f"not <{root.tag}>")
    return root


def _check_attributes(path: Path, element: etree._Element, allowed: tuple[str, ...],
                      required: tuple[str, ...] = ()) -> None:
    for name in element.attrib:
        if name not in allowed:
            raise ConfigError(f"{path}:{element.sourceline}: <{element.tag}> has no attribute "
                              f"{name!r}{_suggest(str(name), list(allowed))}")
    for name in required:
        if element.get(name) is None:
            raise ConfigError(f"{path}:{element.sourceline}: <{element.tag}> needs a {name!r} "
                              "attribute")


def _identifier(path: Path, element: etree._Element, attribute: str) -> str:
    value = (element.get(attribute) or "").strip()
    if not _IDENTIFIER.fullmatch(value):
        raise ConfigError(f"{path}:{element.sourceline}: <{element.tag} {attribute}="
                          f"{element.get(attribute)!r}>: a name must be non-empty, without "
                          "whitespace or ':'")
    return value


def _check_version(path: Path, element: etree._Element) -> None:
    version = element.get("version")
    if version is not None and version.strip() != _SCHEMA_VERSION:
        raise ConfigError(f"{path}:{element.sourceline}: schema version {version!r} is not "
                          f"supported (only {_SCHEMA_VERSION!r})")


def _number(path: Path, element: etree._Element, attribute: str, limit: float) -> float:
    """The attribute as a decimal number within ``[-limit, limit]``, 0 if absent."""
    text = element.get(attribute)
    if text is None:
        return 0.0
    shown = text if len(text) <= 40 else text[:37] + "..."
    if not _NUMBER.fullmatch(text.strip()):
        raise ConfigError(f"{path}:{element.sourceline}: <{element.tag} {attribute}={shown!r}>: "
                          "not a decimal number")
    value = float(text)
    if not abs(value) <= limit:
        raise ConfigError(f"{path}:{element.sourceline}: <{element.tag} {attribute}={shown!r}>: "
                          f"must be within ±{limit:g}")
    return value


def _pose(path: Path, element: etree._Element) -> np.ndarray | None:
    """The transform given by ``element``'s <translation>/<rotation> children, if any."""
    translation: tuple[float, float, float] | None = None
    rotation: tuple[float, float, float] | None = None
    for child in element:
        if child.tag == "description":
            continue
        if child.tag == "translation":
            if translation is not None:
                raise ConfigError(f"{path}:{child.sourceline}: a second <translation>")
            _check_attributes(path, child, ("x", "y", "z"))
            translation = (_number(path, child, "x", MAX_TRANSLATION_M),
                           _number(path, child, "y", MAX_TRANSLATION_M),
                           _number(path, child, "z", MAX_TRANSLATION_M))
        elif child.tag == "rotation":
            if rotation is not None:
                raise ConfigError(f"{path}:{child.sourceline}: a second <rotation>")
            _check_attributes(path, child, ("roll", "pitch", "yaw"))
            rotation = (_number(path, child, "roll", MAX_ANGLE_DEG),
                        _number(path, child, "pitch", MAX_ANGLE_DEG),
                        _number(path, child, "yaw", MAX_ANGLE_DEG))
        else:
            hint = _suggest(str(child.tag), ["translation", "rotation", "description"])
            raise ConfigError(f"{path}:{child.sourceline}: unexpected <{child.tag}> in "
                              f"<{element.tag}>{hint}")
    if translation is None and rotation is None:
        return None
    return homogeneous_transform(translation or (0.0, 0.0, 0.0), rotation or (0.0, 0.0, 0.0))


def _read_body_file(path: Path, where: str, budget: _Budget) -> _BodyFile:
    root = _read_xml(path, "body", where, budget)
    _check_attributes(path, root, ("type", "version", "reference"), ("type", "reference"))
    _check_version(path, root)
    reference = _identifier(path, root, "reference")
    frames: dict[str, _FrameDecl] = {}
    for element in root:
        if element.tag == "description":
            continue
        if element.tag != "frame":
            raise ConfigError(f"{path}:{element.sourceline}: expected <frame>, got "
                              f"<{element.tag}>")
        _check_attributes(path, element, ("name",), ("name",))
        name = _identifier(path, element, "name")
        if name in frames:
            raise ConfigError(f"{path}:{element.sourceline}: frame {name!r} is declared twice "
                              f"(first at line {frames[name].line})")
        transform = _pose(path, element)
        line = element.sourceline or 0
        if name == reference:
            if transform is not None:
                raise ConfigError(f"{path}:{line}: frame {name!r} is the body's reference and "
                                  "carries no <translation> or <rotation>")
        else:
            transform = transform if transform is not None else np.eye(4)
        frames[name] = _FrameDecl(name, transform, line)
    if reference not in frames:
        raise ConfigError(f"{path}:{root.sourceline}: the reference frame {reference!r} is not "
                          f"declared{_suggest(reference, list(frames))}")
    return _BodyFile(path, root.get("type", "").strip(), reference, tuple(frames.values()))


# ------------------------------------------------------------------ the model


class GeometryModel:
    """The vehicle's geometry: bodies, their frames, constraints and all transforms.

    Build one with :meth:`load`. Queries are O(1) and return fresh arrays.
    """

    def __init__(self, *, name: str, path: Path, reference: str, ground: str | None,
                 bodies: dict[str, str], frames: dict[str, list[str]],
                 constraints: list[Constraint], to_root: dict[str, np.ndarray],
                 component: dict[str, int]) -> None:
        self.name = name
        self.path = path
        self.reference = reference
        self.ground = ground
        self._body_types = bodies
        self._frames = frames
        self._constraints = constraints
        self._to_root = to_root  # node -> ^root T_node
        self._from_root = {node: invert_transform(t) for node, t in to_root.items()}
        self._component = component

    # ---------------------------------------------------------------- loading

    @classmethod
    def load(cls, assembly_path: str | Path, *, require_connected: bool = True,
             translation_tolerance: float = TRANSLATION_TOLERANCE_M,
             rotation_tolerance_deg: float = ROTATION_TOLERANCE_DEG) -> GeometryModel:
        """Read an assembly file and the body files it names (relative to it).

        Every cycle must close within the tolerances. With ``require_connected`` (the
        default, as docs/geometry.md requires) every frame must be reachable from the
        assembly's reference; without it, disconnected parts load and a query across
        them raises :class:`~afa.errors.EOutOfBounds`.

        Raises :class:`~afa.errors.ConfigError` (``file:line: message``) for an
        unreadable, oversized or malformed file, a DTD or entity, a number out of range
        (translations within ±10 km, angles within ±360 degrees), more bodies, frames or
        constraints than the limits (:data:`MAX_BODIES` ...), an unknown frame, an inconsistent
        cycle (one line per constraint) or, if required, a disconnected model.
        """
        path = Path(assembly_path)
        budget = _Budget()
        root = _read_xml(path, "assembly", f"{path}:0", budget)
        _check_attributes(path, root, ("name", "version", "reference", "ground"))
        _check_version(path, root)

        body_types: dict[str, str] = {}
        frames: dict[str, list[str]] = {}
        edges: list[Constraint] = []
        body_lines: dict[str, int] = {}
        references: dict[str, str] = {}
        cache: dict[Path, _BodyFile] = {}
        constraint_elements: list[etree._Element] = []
        node_count = 0
        for element in root:
            if element.tag == "description":
                continue
            if element.tag == "constraint":
                if len(constraint_elements) == MAX_CONSTRAINTS:
                    raise ConfigError(f"{path}:{element.sourceline}: more than "
                                      f"{MAX_CONSTRAINTS} constraints (the limit)")
                constraint_elements.append(element)
                continue
            if element.tag != "body":
                raise ConfigError(f"{path}:{element.sourceline}: expected <body> or "
                                  f"<constraint>, got <{element.tag}>")
            _check_attributes(path, element, ("name", "file"), ("name", "file"))
            body = _identifier(path, element, "name")
            line = element.sourceline or 0
            if body in body_lines:
                raise ConfigError(f"{path}:{line}: body {body!r} is declared twice (first at "
                                  f"line {body_lines[body]})")
            if len(element) or (element.text or "").strip():
                raise ConfigError(f"{path}:{line}: <body> takes no content")
            body_lines[body] = line
            file = (path.parent / element.get("file", "").strip()).resolve()
            if file not in cache:
                cache[file] = _read_body_file(file, f"{path}:{line}: body {body!r}", budget)
            decl = cache[file]
            node_count += len(decl.frames)
            if len(body_lines) > MAX_BODIES:
                raise ConfigError(f"{path}:{line}: more than {MAX_BODIES} bodies (the limit)")
            if node_count > MAX_FRAMES:
                raise ConfigError(f"{path}:{line}: the bodies so far have more than "
                                  f"{MAX_FRAMES} frames in all (the limit)")
            body_types[body] = decl.type
            references[body] = decl.reference
            frames[body] = [frame.name for frame in decl.frames]
            for frame in decl.frames:
                if frame.transform is not None:
                    edges.append(Constraint(f"{body}:{frame.name}", f"{body}:{decl.reference}",
                                            f"{body}:{frame.name}", frame.transform,
                                            decl.path, frame.line))
        if not body_types:
            raise ConfigError(f"{path}:{root.sourceline}: the assembly declares no <body>")

        def resolve(element: etree._Element, attribute: str) -> str:
            text = element.get(attribute)
            if text is None:
                raise ConfigError(f"{path}:{element.sourceline}: <{element.tag}> needs a "
                                  f"{attribute!r} attribute")
            split = _split_name(text)
            if isinstance(split, str):
                raise ConfigError(f"{path}:{element.sourceline}: {attribute}: {split}")
            problem = cls._unknown(body_types, frames, *split)
            if problem:
                raise ConfigError(f"{path}:{element.sourceline}: {attribute}: {problem}")
            return f"{split[0]}:{split[1]}"

        constraints: list[Constraint] = []
        constraint_lines: dict[str, int] = {}
        for element in constraint_elements:
            _check_attributes(path, element, ("name", "from", "to"), ("name", "from", "to"))
            label = element.get("name", "").strip()
            line = element.sourceline or 0
            if not label:
                raise ConfigError(f"{path}:{line}: <constraint> needs a non-empty name")
            if label in constraint_lines:
                raise ConfigError(f"{path}:{line}: constraint {label!r} is declared twice "
                                  f"(first at line {constraint_lines[label]})")
            constraint_lines[label] = line
            source, target = resolve(element, "from"), resolve(element, "to")
            if source.split(":")[0] == target.split(":")[0]:
                raise ConfigError(f"{path}:{line}: constraint {label!r} joins two frames of "
                                  f"body {source.split(':')[0]!r}; a constraint joins "
                                  "different bodies (declare the frame in the body file)")
            transform = _pose(path, element)
            constraints.append(Constraint(label, source, target,
                                          transform if transform is not None else np.eye(4),
                                          path, line))

        if root.get("reference") is not None:
            reference = resolve(root, "reference")
        else:
            first_body = next(iter(body_types))
            reference = f"{first_body}:{references[first_body]}"
        ground = resolve(root, "ground") if root.get("ground") is not None else None

        to_root, component = _spanning_transforms(
            reference, frames, edges, constraints, translation_tolerance,
            rotation_tolerance_deg)
        if require_connected:
            unreachable = sorted({node.split(":")[0] for node, c in component.items() if c != 0})
            if unreachable:
                raise ConfigError(
                    f"{path}:{root.sourceline}: no constraint connects bod"
                    f"{'y' if len(unreachable) == 1 else 'ies'} "
                    f"{', '.join(repr(b) for b in unreachable)} to the reference {reference!r}")
        return cls(name=(root.get("name") or "").strip(), path=path, reference=reference,
                   ground=ground, bodies=body_types, frames=frames,
                   constraints=edges + constraints, to_root=to_root, component=component)

    @staticmethod
    def _unknown(body_types: dict[str, str], frames: dict[str, list[str]], body: str,
                 frame: str) -> str:
        """A message if ``body:frame`` does not exist, else the empty string."""
        if body not in body_types:
            return f"no body {body!r}{_suggest(body, list(body_types))}"
        if frame not in frames[body]:
            return (f"body {body!r} has no frame {frame!r}"
                    f"{_suggest(frame, frames[body])}")
        return ""

    # ---------------------------------------------------------------- Table 19

    def bodies(self) -> list[str]:
        """All body instance names, in assembly order (``getBodyList``)."""
        return list(self._body_types)

    def frames(self, body: str) -> list[str]:
        """The frame names of ``body``, in declaration order (``getBodyFrameList``).

        Raises :class:`~afa.errors.EOutOfBounds` for an unknown body.
        """
        name = body.strip()
        if name not in self._frames:
            raise EOutOfBounds(f"no body {body!r}{_suggest(name, list(self._frames))}")
        return list(self._frames[name])

    def transformation(self, a: str, b: str) -> np.ndarray:
        """^A T_B as a new 4x4 float64 array: maps coordinates in frame B to frame A.

        Raises :class:`~afa.errors.EOutOfBounds` if a name is malformed or unknown (the
        message names the closest frame), or if no chain of constraints joins A and B.
        """
        node_a, node_b = self._node(a), self._node(b)
        if self._component[node_a] != self._component[node_b]:
            raise EOutOfBounds(f"no chain of constraints joins {node_a!r} and {node_b!r}")
        if node_a == node_b:
            return np.eye(4)
        result: np.ndarray = self._from_root[node_a] @ self._to_root[node_b]
        return result

    getTransformation = transformation
    getBodyList = bodies
    getBodyFrameList = frames

    # ---------------------------------------------------------------- extras

    def body_type(self, body: str) -> str:
        """The ``type`` of the body file ``body`` was built from.

        Raises :class:`~afa.errors.EOutOfBounds` for an unknown body.
        """
        self.frames(body)
        return self._body_types[body.strip()]

    def frame_names(self) -> list[str]:
        """Every vertex as ``Body:Frame``, in declaration order."""
        return [f"{body}:{frame}" for body, names in self._frames.items() for frame in names]

    def constraints(self) -> list[Constraint]:
        """Every edge: body frame declarations first, then the assembly's constraints."""
        return list(self._constraints)

    def _node(self, text: str) -> str:
        split = _split_name(text)
        if isinstance(split, str):
            raise EOutOfBounds(split)
        problem = self._unknown(self._body_types, self._frames, *split)
        if problem:
            raise EOutOfBounds(f"unknown frame {text!r}: {problem}"
                               + ("" if "did you mean" in problem
                                  else _suggest(f"{split[0]}:{split[1]}", self.frame_names())))
        return f"{split[0]}:{split[1]}"


def _spanning_transforms(reference: str, frames: dict[str, list[str]],
                         edges: list[Constraint], constraints: list[Constraint],
                         translation_tolerance: float, rotation_tolerance_deg: float,
                         ) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """^root T_node and a component number (0 = the reference's) for every node.

    Tree edges: every body frame declaration, then the assembly constraints in file
    order that join two still-separate parts. Every other constraint closes a cycle and
    must agree with the tree; all disagreements are reported in one ConfigError.
    """
    nodes = [f"{body}:{frame}" for body, names in frames.items() for frame in names]
    parent = {node: node for node in nodes}

    def find(node: str) -> str:
        while parent[node] != node:
            parent[node] = parent[parent[node]]
            node = parent[node]
        return node

    adjacency: dict[str, list[tuple[str, np.ndarray]]] = {node: [] for node in nodes}
    closing: list[Constraint] = []
    for edge in edges + constraints:
        root_s, root_t = find(edge.source), find(edge.target)
        if root_s == root_t:
            closing.append(edge)
            continue
        parent[root_t] = root_s
        adjacency[edge.source].append((edge.target, edge.transform))
        adjacency[edge.target].append((edge.source, invert_transform(edge.transform)))

    to_root: dict[str, np.ndarray] = {}
    component: dict[str, int] = {}
    number = -1
    for root in [reference] + nodes:
        if root in to_root:
            continue
        number += 1
        to_root[root], component[root] = np.eye(4), number
        queue = deque([root])
        while queue:
            node = queue.popleft()
            for neighbour, transform in adjacency[node]:
                if neighbour not in to_root:
                    to_root[neighbour] = to_root[node] @ transform
                    component[neighbour] = number
                    queue.append(neighbour)

    problems = []
    for edge in closing:
        through_tree = invert_transform(to_root[edge.source]) @ to_root[edge.target]
        translation, rotation = _discrepancy(through_tree, edge.transform)
        if translation > translation_tolerance or rotation > rotation_tolerance_deg:
            problems.append(
                f"{edge.where}: constraint {edge.name!r} ({edge.source} -> {edge.target}) "
                f"disagrees with the chain it closes by {translation * 1000:.3f} mm and "
                f"{rotation:.4f} deg (tolerance {translation_tolerance * 1000:g} mm, "
                f"{rotation_tolerance_deg:g} deg); through the chain t = "
                f"({', '.join(f'{v:.6f}' for v in through_tree[:3, 3])})")
    if problems:
        raise ConfigError(problems)
    return to_root, component
