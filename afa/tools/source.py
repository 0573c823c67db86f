"""Where a tool reads from: a running system (:class:`LiveSource`, over the bridge) or a
recording (:class:`LogSource`, ``--log FILE.mcap``), behind one small interface:

- ``events(name)``: the events of ``name`` (a pattern), in order;
- ``names()``: served names with interface, owner and process;
- ``transformation(A, B)``: ModelServer's ``getTransformation`` (live: a poll; a
  recording: the last recorded answer to that poll, else, from the vehicle frame, the
  geometry the recorder wrote for viewers, ``/viz/tf``).

A recording also answers polls as its replay would (:meth:`LogSource.answers`,
:mod:`afa.log.answers`) and holds the Launcher's table once per flush period
(:meth:`LogSource.statistics`, ``afa top --log``).

A recording is read through ``afa.log`` (the record/replay package); a build without it
says so instead of pretending.
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from afa.errors import AfaError, NameNotFound
from afa.events import Event
from afa.tools.attach import Attachment
from idl import Platform

__all__ = ["Source", "LiveSource", "LogSource", "Unavailable"]


class Unavailable(AfaError, RuntimeError):
    """What the tool needs is not available from this source."""


class Source(Protocol):
    def events(self, name: str) -> AsyncIterator[Event]: ...

    async def names(self) -> list[dict[str, Any]]: ...

    async def transformation(self, a: str, b: str) -> np.ndarray: ...


def platform_server(names: list[dict[str, Any]]) -> tuple[str, str]:
    """(robot, name) of the first process serving the Platform interface (ModelServer)."""
    wanted = f"{Platform.__module__}.{Platform.__qualname__}"
    for row in names:
        if row.get("interface") == wanted and not row.get("remote"):
            robot, _, short = row["name"].partition("/")
            return robot, short
    raise NameNotFound("no process serves the Platform interface (ModelServer), which "
                       "transforms range points into the vehicle frame")


class LiveSource:
    """A running system, through an :class:`Attachment`."""

    def __init__(self, attachment: Attachment) -> None:
        self.attachment = attachment
        self._platform: tuple[str, str] | None = None

    def events(self, name: str) -> AsyncIterator[Event]:
        return self.attachment.events(name)

    async def names(self) -> list[dict[str, Any]]:
        return [row for info in await self.attachment.require()
                for row in info.get("names", [])]

    async def transformation(self, a: str, b: str) -> np.ndarray:
        if self._platform is None:
            self._platform = platform_server(await self.names())
        robot, name = self._platform
        pose = await self.attachment.call(robot, name, Platform, "getTransformation",
                                          {"A": a, "B": b})
        return np.asarray(pose.HTransform, dtype=float)


def _reader(path: Path) -> Any:
    try:
        from afa.log.reader import LogReader  # type: ignore[import-not-found, unused-ignore]
    except ImportError as exc:
        raise Unavailable(
            f"reading {path} needs afa's record/replay package (afa.log), which this "
            "installation does not have yet; attach to a running system instead "
            f"({exc})") from exc
    return LogReader(path)


class LogSource:
    """A recording (MCAP, written by ``afa run --record``)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.reader = _reader(path)

    def close(self) -> None:
        self.reader.close()

    async def events(self, name: str) -> AsyncIterator[Event]:  # type: ignore[override]
        channels = [c.id for c in self.reader.topics("event") if fnmatchcase(c.event, name)]
        if not channels:
            known = sorted({c.event for c in self.reader.topics("event")})
            raise NameNotFound(f"{self.path} has no event {name!r}; it has "
                               f"{', '.join(known) or 'none'}")
        for message in self.reader.messages(channels=channels):
            event = self.reader.decode_event(message)
            if event is not None:
                yield event

    async def names(self) -> list[dict[str, Any]]:
        rows = []
        for port in self.reader.catalog():
            if port.get("direction") == "serves":
                rows.append({"name": port["name"], "interface": (port.get("types") or [""])[0],
                             "owner": port.get("component", ""),
                             "process": port.get("process") or "(recorded)",
                             "remote": False})
        return rows

    def answers(self, at: float | None) -> Any:
        """The recorded servers answering as of ``at`` s after the recording's first
        message (None: its end): a :class:`afa.log.answers.RecordedAnswers`."""
        from afa.log.answers import RecordedAnswers

        return RecordedAnswers(self.reader, at)

    def statistics(self) -> list[tuple[float, dict[str, Any]]]:
        """The recorded Launcher tables: (seconds after the recording's first message,
        the table's document), in order. Raises Unavailable if the recording has none."""
        from afa.log import format as fmt

        channels = [c.id for c in self.reader.topics(fmt.STATISTICS)]
        tables = [(fmt.from_ns(m.log_time - self.reader.start), json.loads(m.data))
                  for m in self.reader.messages(channels=channels)]
        if not tables:
            raise Unavailable(f"{self.path} holds no component statistics (recorded by an "
                              "afa before they were written, or shorter than one flush "
                              "period)")
        return tables

    async def transformation(self, a: str, b: str) -> np.ndarray:
        from afa.polling import decode_arguments, decode_result

        channels = [c.id for c in self.reader.topics("poll")
                    if c.topic.endswith("/getTransformation")]
        found = None
        for message in self.reader.messages(channels=channels):
            record = self.reader.decode_wire(message)
            if record is None or getattr(record, "error_kind", None):
                continue
            arguments = decode_arguments(Platform, "getTransformation", bytes(record.arguments))
            if arguments == {"A": a, "B": b}:
                found = decode_result(Platform, "getTransformation", bytes(record.result))
        if found is not None:
            return np.asarray(found.HTransform, dtype=float)
        geometry = self._recorded_geometry(a, b)
        if geometry is None:
            raise Unavailable(f"{self.path} holds no recorded getTransformation({a}, {b}) "
                              "and no recorded geometry of that frame; print the points in "
                              "the sensor frame with --frame sensor")
        return geometry

    def _recorded_geometry(self, a: str, b: str) -> np.ndarray | None:
        """^a T_b from the last static transform the recorder wrote for viewers (it asks
        ModelServer for every frame's place in the vehicle frame), or None."""
        from afa.log.viewer import TF_TOPIC, VEHICLE_FRAME

        channels = [c.id for c in self.reader.topics() if c.topic == TF_TOPIC]
        if a != VEHICLE_FRAME or not channels:
            return None
        found = None
        for message in self.reader.messages(channels=channels):
            transform = json.loads(message.data)
            if (transform.get("parent_frame_id"), transform.get("child_frame_id")) == (a, b):
                found = transform
        return None if found is None else _homogeneous(found["translation"],
                                                       found["rotation"])


def _homogeneous(translation: dict[str, float], rotation: dict[str, float]) -> np.ndarray:
    """The 4x4 transform of a translation and a unit quaternion (x, y, z, w)."""
    x, y, z, w = (rotation[k] for k in "xyzw")
    matrix = np.eye(4)
    matrix[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    matrix[:3, 3] = [translation[k] for k in "xyz"]
    return matrix
