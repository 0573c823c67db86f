"""What an afa recording holds (decision 0010): topics, encodings, records, metadata.

One MCAP file, profile ``afa``:

==================================  ===============  ==========================================
topic                               message encoding  data
==================================  ===============  ==========================================
``/<domain>/<event>``               ``afa-event``    :meth:`afa.events.Event.encode`: envelope
                                                     (time, sequence, domain, type, origin) and
                                                     the body's :mod:`idl.wire` frame
``/afa/poll/<robot>/<server>/<m>``  ``afa-wire``     a :class:`PollCallIDL` frame: caller,
                                                     arguments, result or error, duration
``/afa/dropped``                    ``afa-wire``     a :class:`DroppedIDL` frame: what the
                                                     recorder could not keep, counted
``/afa/statistics``                 ``json``         the Launcher's table once per flush period
                                                     (``afa top --log``): per component its
                                                     state, health, restarts, events in and
                                                     out and loop time; the clock and memory
``/viz/...``                        ``json`` or      Foxglove schemas, for viewers
                                    ``protobuf``     (:mod:`afa.log.viewer`; point clouds
                                                     and grids in protobuf)
==================================  ===============  ==========================================

Event and poll channels have schema encoding ``jsonschema``: the schema's name is the
qualified, versioned IDL type name (``idl.common.PoseTransformIDL@1``) and its data is
:func:`idl.wire.schema` of the type, so a reader knows each channel's type without
decoding a message, and refuses a newer version by name. Channel metadata says what a
channel is (``afa.kind`` = ``event``, ``poll``, ``dropped``, ``statistics`` or
``viewer``). Times are nanoseconds since the Unix epoch (the clock's stamps); the exact
float stamp travels in the event envelope.

Metadata records: ``afa`` (version, start time, clock, clock origin, command, world and
seed in simulation), ``afa.config`` (the configuration file's path and text),
``afa.catalog`` (the recorded system's catalog as JSON: who publishes, subscribes, serves
and uses what) and, when the file is closed, ``afa.end`` (counts and drops).
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from idl._base import Array, IDLModel, field

__all__ = [
    "PROFILE", "EVENT_ENCODING", "WIRE_ENCODING", "SCHEMA_ENCODING", "JSON_ENCODING",
    "KIND", "EVENT", "POLL", "DROPPED", "STATISTICS", "VIEWER", "DROPPED_TOPIC",
    "STATISTICS_TOPIC", "POLL_PREFIX",
    "META_AFA", "META_CONFIG", "META_CATALOG", "META_END", "PollCallIDL", "DroppedIDL",
    "event_topic", "poll_topic", "to_ns", "from_ns",
]

PROFILE = "afa"
EVENT_ENCODING = "afa-event"
WIRE_ENCODING = "afa-wire"
SCHEMA_ENCODING = "jsonschema"
JSON_ENCODING = "json"

#: Channel metadata key saying what a channel carries, and its values.
KIND = "afa.kind"
EVENT = "event"
POLL = "poll"
DROPPED = "dropped"
STATISTICS = "statistics"
VIEWER = "viewer"

DROPPED_TOPIC = "/afa/dropped"
STATISTICS_TOPIC = "/afa/statistics"
POLL_PREFIX = "/afa/poll/"

META_AFA = "afa"
META_CONFIG = "afa.config"
META_CATALOG = "afa.catalog"
META_END = "afa.end"

Bytes = Annotated[np.ndarray, Array("uint8", (None,))]


class PollCallIDL(IDLModel):
    """One finished poll, as the poll layer's recording hook heard it."""

    idl_name = "afa.log.PollCall"
    idl_version = 2  # 2: seq

    caller: str = field("", unit="", description="the calling component ('' outside one)")
    server: str = field(unit="", description="the server's full name, Raptor/ModelService")
    interface: str = field(unit="", description="the interface's qualified name")
    method: str = field(unit="", description="the method called")
    arguments: Bytes = field(unit="", description="wire frame of the arguments model")
    result: Bytes = field(unit="", description="wire frame of the result model (empty on "
                                               "error)")
    error_kind: str = field("", unit="", description="the afa exception class, '' if none")
    error_message: str = field("", unit="", description="the exception's message")
    duration: float = field(0.0, unit="s", description="how long the call took (clock)")
    seq: int = field(-1, unit="1", description="sequence number of the last event published "
                                               "when the call was made (-1: not known)")


class DroppedIDL(IDLModel):
    """What the recorder had to drop so far (cumulative), written whenever it grows."""

    idl_name = "afa.log.Dropped"

    events: int = field(0, unit="1", description="events the recorder's buffer dropped")
    polls: int = field(0, unit="1", description="poll records dropped")
    by_type: dict[str, int] = field({}, unit="1",
                                    description="dropped events per event name (estimated "
                                                "while running, exact at the end)")


def event_topic(domain: str, event_type: str) -> str:
    return f"/{domain}/{event_type}"


def poll_topic(server: str, method: str) -> str:
    """``/afa/poll/Raptor/ModelService/getWaitPose``."""
    return f"{POLL_PREFIX}{server}/{method}"


def to_ns(seconds: float) -> int:
    """A clock stamp as MCAP nanoseconds (never negative)."""
    return max(0, round(seconds * 1e9))


def from_ns(nanoseconds: int) -> float:
    return nanoseconds / 1e9
