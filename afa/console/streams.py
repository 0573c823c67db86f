"""What the console sends, how often, and what it drops: stream kinds, rate limits and
drop-oldest buffers.

Every event the console's observer sees is *classified* by the type of its body into a
**kind** (``map.traverse``, ``arcs.vote``, ``range.laser`` ...) and a **stream**, the kind
plus a name that keeps sources apart (``range.laser/Laser11``, ``arcs.vote/PurePursuit``):
event names are not enough, since the Raptor publishes the global and the egocentric
traversability maps under one name (``Traverse``), told apart only by their types.

Each browser connection subscribes to kinds (the views it shows) at a rate. For each
stream it gets an :class:`Outbox`: a bounded buffer that drops the oldest entry when full,
sent at most ``rate`` times a second. A map keeps only its latest frame (depth 1); laser
scan lines keep a few dozen, sent together, so the point cloud has no gaps at moderate
rates and simply thins out when the browser cannot keep up. Nothing here ever waits: a
slow or hidden browser tab costs the vehicle a deque append per event.

Rates are in wall-clock seconds whatever the system's clock (decision 0013): they pace a
browser and a socket, which live in real time.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

from afa.events import Event
from idl import (
    ArcDecisionIDL,
    ArcVoteIDL,
    EgoMapArrayEventIDL,
    EtravMapArrayEventIDL,
    GpsIDL,
    ImuIDL,
    MapArrayEventIDL,
    PlanMapEventIDL,
    PlannedPathIDL,
    PoseTransformIDL,
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
    TravMapArrayEventIDL,
    VelocityDataIDL,
    WheelDataIDL,
)
from idl._base import IDLModel

__all__ = ["StreamPolicy", "POLICIES", "classify", "Outbox", "StreamStatistics",
           "JSON_KINDS", "clamp_rate", "FRESH"]


@dataclass(frozen=True)
class StreamPolicy:
    """How one kind of stream is sent: ``rate`` (messages per second by default),
    ``max_rate`` (the most a browser may ask for) and ``depth`` (entries kept per stream;
    each send empties the buffer, so depth > 1 sends a burst of the latest entries)."""

    rate: float
    max_rate: float
    depth: int = 1
    description: str = ""


#: Default policy per kind. Event kinds first, then the console's own JSON kinds.
POLICIES: dict[str, StreamPolicy] = {
    "pose": StreamPolicy(10.0, 50.0, 2, "Pose (PoseTransformIDL); the track is drawn from them"),
    "map.terrain": StreamPolicy(1.0, 5.0, 1, "global terrain map (MapArrayEventIDL)"),
    "map.traverse": StreamPolicy(1.0, 5.0, 1, "global traversability (TravMapArrayEventIDL)"),
    "map.plan": StreamPolicy(0.5, 2.0, 1, "the Global Map (PlanMapEventIDL)"),
    "ego.terrain": StreamPolicy(4.0, 10.0, 1, "egocentric terrain (EgoMapArrayEventIDL)"),
    "ego.traverse": StreamPolicy(4.0, 10.0, 1, "egocentric traversability "
                                              "(EtravMapArrayEventIDL)"),
    "arcs.vote": StreamPolicy(5.0, 20.0, 1, "ArcVote per behaviour (ArcVoteIDL)"),
    "arcs.decision": StreamPolicy(5.0, 20.0, 1, "the arbiter's ArcDecision"),
    "path": StreamPolicy(2.0, 5.0, 1, "FindPath's PlannedPath"),
    "range.laser": StreamPolicy(5.0, 30.0, 12, "laser scan lines (Range3dSeqEventIDL)"),
    "range.stereo": StreamPolicy(1.0, 4.0, 1, "stereo points (Range3dArrayEventIDL)"),
    "vehicle": StreamPolicy(10.0, 20.0, 1, "VelocityData (VelocityDataIDL)"),
    "imu": StreamPolicy(10.0, 30.0, 1, "IMU attitude (ImuIDL)"),
    "gps": StreamPolicy(2.0, 10.0, 1, "GPS fixes (GpsIDL)"),
    "odometry": StreamPolicy(5.0, 20.0, 1, "wheel odometry (WheelDataIDL)"),
    # the console's own messages (JSON headers, no event)
    "status": StreamPolicy(1.0, 5.0, 1, "component table, health, statistics"),
    "truth": StreamPolicy(5.0, 10.0, 1, "simulation ground truth and pose error"),
    "waypoints": StreamPolicy(0.5, 2.0, 1, "waypoint lists polled from the planners"),
    "geometry": StreamPolicy(1.0, 1.0, 1, "the geometry model's frames"),
    "replay": StreamPolicy(4.0, 10.0, 1, "replay position and state"),
}

JSON_KINDS = frozenset({"status", "truth", "waypoints", "geometry", "replay"})

# Order matters: subclasses before their bases (WheelEventIDL is a WheelDataIDL).
_BY_TYPE: tuple[tuple[type[IDLModel], str], ...] = (
    (PoseTransformIDL, "pose"),
    (PlanMapEventIDL, "map.plan"),
    (TravMapArrayEventIDL, "map.traverse"),
    (EtravMapArrayEventIDL, "ego.traverse"),
    (MapArrayEventIDL, "map.terrain"),
    (EgoMapArrayEventIDL, "ego.terrain"),
    (ArcVoteIDL, "arcs.vote"),
    (ArcDecisionIDL, "arcs.decision"),
    (PlannedPathIDL, "path"),
    (Range3dSeqEventIDL, "range.laser"),
    (Range3dLaserIDL, "range.laser"),
    (Range3dArrayEventIDL, "range.stereo"),
    (Range3dStereoEventIDL, "range.stereo"),
    (VelocityDataIDL, "vehicle"),
    (ImuIDL, "imu"),
    (GpsIDL, "gps"),
    (WheelDataIDL, "odometry"),
)
_CACHE: dict[type, str | None] = {}


def _kind_of(body_type: type) -> str | None:
    try:
        return _CACHE[body_type]
    except KeyError:
        pass
    kind = next((k for t, k in _BY_TYPE if issubclass(body_type, t)), None)
    _CACHE[body_type] = kind
    return kind


_STREAMS: dict[tuple[str, str], str] = {}


def classify(event: Event) -> tuple[str, str] | None:
    """``(kind, stream)`` of an event, or None for an event no view shows.

    A Pose event that is not named ``Pose`` is still a pose (a second filter, a replay).
    The transforms ModelServer returns to polls are PoseTransformIDL too, but polls are
    not events, so they never get here. Called for every event: cached lookups only.
    """
    body_type = type(event.body)
    kind = _CACHE[body_type] if body_type in _CACHE else _kind_of(body_type)
    if kind is None:
        return None
    name = event.body.behaviour if kind == "arcs.vote" else event.type  # type: ignore[attr-defined]
    key = (kind, name)
    stream = _STREAMS.get(key)
    if stream is None:
        stream = _STREAMS[key] = f"{kind}/{name}"
    return kind, stream


def clamp_rate(kind: str, rate: Any) -> float:
    """A browser's requested rate for ``kind``, within (0, max_rate]; the default rate for
    anything that is not a positive number. Raises KeyError for an unknown kind."""
    policy = POLICIES[kind]
    try:
        value = float(rate)
    except OverflowError:  # an integer beyond any float, of either sign
        value = math.inf if rate > 0 else 0.0
    except (TypeError, ValueError):
        return policy.rate
    if not value > 0.0 or value != value:  # also NaN
        return policy.rate
    return min(value, policy.max_rate)


@dataclass(slots=True)
class StreamStatistics:
    offered: int = 0
    sent: int = 0
    dropped: int = 0


#: An entry this young is fresh: a due outbox sends it at once.
FRESH = 0.05
#: Streams that arrive more often than this (s) are worth waiting for (see Outbox.due).
_WAIT_FOR_FRESH = 0.5


class Outbox:
    """A drop-oldest buffer for one stream of one browser, sent at most every
    ``interval`` seconds (wall time). Plain data: the sender task asks :meth:`due`.

    Latest-value streams (depth 1) that arrive faster than they may be sent wait, when
    due, for the next arrival rather than sending an entry that is already most of a
    period old: the frames that do get sent are fresh (a map reaches the page within
    a few milliseconds of its event, not up to a period later), and never more than
    ``1 / interval`` a second.
    """

    __slots__ = ("stream", "kind", "interval", "entries", "last_sent", "stats", "period",
                 "_last_arrival")

    def __init__(self, stream: str, kind: str, interval: float, depth: int) -> None:
        self.stream = stream
        self.kind = kind
        self.interval = interval
        self.entries: deque[tuple[float, Any]] = deque(maxlen=max(1, depth))
        self.last_sent = float("-inf")
        self.stats = StreamStatistics()
        self.period: float | None = None  # mean time between arrivals (EWMA)
        self._last_arrival: float | None = None

    def push(self, entry: Any, now: float) -> None:
        """Queue ``entry`` arrived at ``now``; a full buffer drops its oldest (counted)."""
        entries = self.entries
        if len(entries) == entries.maxlen:
            self.stats.dropped += 1
        entries.append((now, entry))
        self.stats.offered += 1
        if self._last_arrival is not None:
            gap = now - self._last_arrival
            self.period = gap if self.period is None else 0.8 * self.period + 0.2 * gap
        self._last_arrival = now

    def due(self, now: float) -> float | None:
        """When this outbox may send next (None while it is empty)."""
        if not self.entries:
            return None
        ready = self.last_sent + self.interval
        period = self.period
        if (self.entries.maxlen != 1 or period is None or period >= self.interval
                or period > _WAIT_FOR_FRESH):
            return ready
        arrival = self.entries[-1][0]
        if max(now, ready) - arrival <= FRESH:
            return ready
        # a newer entry should arrive within a period: send that one (or this one, late)
        return max(ready, arrival + 1.5 * period)

    def take(self, now: float) -> list[tuple[float, Any]]:
        """Everything queued as (arrival, entry), oldest first; marks the outbox sent at
        ``now``."""
        entries = list(self.entries)
        self.entries.clear()
        self.last_sent = now
        self.stats.sent += len(entries)
        return entries
