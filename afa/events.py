"""The event channel: an in-process imitation of the CORBA Notification Service.

A structured :class:`Event` has a *domain* (the robot name, ``Raptor``), a *type* (the
event name, ``Laser11``, ``Pose``), a time stamp from the clock, a per-channel sequence
number and one IDL body. Suppliers publish anonymously; every subscription whose
``(domain, type)`` pattern matches receives the event.

- :meth:`EventChannel.publish` is a plain call: it never waits for consumers. Each
  subscription has a bounded buffer and an :class:`Overflow` policy; a full buffer drops
  (oldest by default, the right choice for sensor data) and counts what it dropped.
- Delivery order is deterministic: subscriptions receive events in publication order,
  and subscriptions are served in the order they were made.
- :meth:`EventChannel.offer` returns a :class:`Publisher` that caches its matching
  subscriptions, so a supplier can ask ``publisher.subscribed`` before building an
  expensive event and publish with no pattern matching on the hot path.
- An event names its *origin* (the publishing component; ``process/component`` once
  several processes share a channel through a bridge), so a bridge never echoes an
  event back where it came from and a log says who said what.
- Events serialise losslessly through the wire codec (:meth:`Event.encode`), for logs,
  the network and the console.
- Anything that watches the whole channel (a digest, a recorder, the console, a bridge)
  is an *observer*: a subscription to ``*`` with its own bounded buffer, so a slow or
  failing observer never slows or fails a publisher, and what it drops is counted
  (:meth:`EventChannel.observe`).
"""

from __future__ import annotations

import asyncio
import math
import struct
from collections import Counter, deque
from collections.abc import AsyncIterator
from dataclasses import dataclass
from enum import StrEnum
from fnmatch import fnmatchcase
from typing import NamedTuple

from afa.clock import Clock, WallClock
from afa.errors import ChannelClosed
from idl import wire
from idl._base import IDLModel

__all__ = ["Event", "EventChannel", "Subscription", "Publisher", "Overflow",
           "SubscriptionStatistics", "peek_envelope"]


_ENVELOPE = struct.Struct("<4sdQHHH")
_EVENT_MAGIC = b"AFE1"


class Event(NamedTuple):
    """One structured event (immutable). ``body`` is an immutable IDL model; ``origin``
    names the component (and process) that published it."""

    domain: str
    type: str
    time: float
    seq: int
    body: IDLModel
    origin: str = ""

    def encode(self) -> bytes:
        """The event as bytes: a small envelope (magic ``AFE1``, time f64, seq u64, the
        lengths of domain, type and origin), those three names in UTF-8, then the body's
        wire frame (:mod:`idl.wire`)."""
        return b"".join(self.encode_parts())

    def encode_parts(self) -> list[bytes | memoryview]:
        """:meth:`encode` as a list of byte strings to write one after the other (the
        arrays' bytes not copied; a recorder writes them straight into its chunk)."""
        names = (self.domain.encode(), self.type.encode(), self.origin.encode())
        head = _ENVELOPE.pack(_EVENT_MAGIC, self.time, self.seq, *map(len, names))
        parts = wire.encode_parts(self.body)
        parts[0] = b"".join((head, *names, parts[0]))
        return parts

    @classmethod
    def decode(cls, data: bytes | bytearray | memoryview) -> Event:
        """Inverse of :meth:`encode`. Raises :class:`idl.wire.WireError` for anything
        that is not a valid event of a known IDL type (a time stamp that is not finite
        included)."""
        view = memoryview(data)
        domain, event_type, time, seq, origin, offset = _envelope(view)
        body: IDLModel = wire.decode(view[offset:])  # arrays: views of ``data`` (bytes)
        return cls(domain, event_type, time, seq, body, origin)


def peek_envelope(data: bytes | bytearray | memoryview) -> tuple[str, str, float, int, str]:
    """``(domain, type, time, seq, origin)`` of an :meth:`Event.encode` frame, without
    decoding the body (a log player schedules and filters by these). Raises
    :class:`idl.wire.WireError` for a frame that is not an event."""
    return _envelope(memoryview(data))[:5]


def _envelope(view: memoryview) -> tuple[str, str, float, int, str, int]:
    """``(domain, type, time, seq, origin, offset of the body)`` of an event frame: the
    one check of an envelope from a peer, a log or a console, whoever reads it. A time
    stamp that is not finite is refused: every event made here has a clock's time."""
    try:
        magic, time, seq, n_domain, n_type, n_origin = _ENVELOPE.unpack_from(view)
    except struct.error:
        raise wire.WireError("truncated event envelope") from None
    if magic != _EVENT_MAGIC:
        raise wire.WireError(f"not an afa event (magic {magic!r})")
    if not math.isfinite(time):
        raise wire.WireError(f"event time {time} is not a finite time stamp")
    offset = _ENVELOPE.size
    try:
        names: list[str] = []
        for n in (n_domain, n_type, n_origin):
            names.append(bytes(view[offset:offset + n]).decode())
            offset += n
    except UnicodeDecodeError as exc:
        raise wire.WireError(f"event names are not UTF-8: {exc}") from None
    return names[0], names[1], time, seq, names[2], offset


class Overflow(StrEnum):
    """What a full subscription buffer does with a new event."""

    DROP_OLDEST = "drop-oldest"  # keep the newest: sensor data, maps, poses
    DROP_NEWEST = "drop-newest"  # keep what is queued: ordered logs that prefer a gap at the end


@dataclass(slots=True)
class SubscriptionStatistics:
    delivered: int = 0
    dropped: int = 0
    high_water: int = 0
    queued: int = 0


def _is_pattern(text: str) -> bool:
    return any(c in text for c in "*?[")


class Subscription:
    """A bounded queue of events matching ``(domain, type)``; an async iterator.

    ``async for event in subscription`` yields events until the subscription (or the
    channel) is closed. :meth:`get` raises :class:`~afa.errors.ChannelClosed` then.
    """

    __slots__ = ("domain", "type", "maxsize", "policy", "observer", "_channel", "_queue",
                 "_waiter", "_closed", "_delivered", "_dropped", "_high_water", "_order")

    def __init__(self, channel: EventChannel, domain: str, type: str, maxsize: int,
                 policy: Overflow, order: int) -> None:
        if maxsize < 1:
            raise ValueError(f"maxsize must be at least 1, got {maxsize}")
        self.domain = domain
        self.type = type
        self.maxsize = maxsize
        self.policy = Overflow(policy)
        self.observer = False  # watches everything; asks for nothing (EventChannel.observe)
        self._channel = channel
        self._queue: deque[Event] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._closed = False
        self._delivered = 0
        self._dropped = 0
        self._high_water = 0
        self._order = order

    def matches(self, domain: str, type: str) -> bool:
        return fnmatchcase(domain, self.domain) and fnmatchcase(type, self.type)

    def _push(self, event: Event) -> None:
        queue = self._queue
        if len(queue) >= self.maxsize:
            self._dropped += 1
            if self.policy is Overflow.DROP_NEWEST:
                return
            queue.popleft()
        queue.append(event)
        if len(queue) > self._high_water:
            self._high_water = len(queue)
        waiter = self._waiter
        if waiter is not None:
            self._waiter = None
            if not waiter.done():
                waiter.set_result(None)

    async def get(self) -> Event:
        """The next event; waits if none is queued. Raises ChannelClosed when closed."""
        while not self._queue:
            if self._closed:
                raise ChannelClosed(f"subscription {self.domain}/{self.type} is closed")
            waiter = asyncio.get_running_loop().create_future()
            self._waiter = waiter
            try:
                await waiter
            finally:
                if self._waiter is waiter:
                    self._waiter = None
        self._delivered += 1
        return self._queue.popleft()

    def get_nowait(self) -> Event | None:
        """The next queued event, or None."""
        if not self._queue:
            return None
        self._delivered += 1
        return self._queue.popleft()

    def __aiter__(self) -> AsyncIterator[Event]:
        return self

    async def __anext__(self) -> Event:
        try:
            return await self.get()
        except ChannelClosed:
            raise StopAsyncIteration from None

    def statistics(self) -> SubscriptionStatistics:
        return SubscriptionStatistics(self._delivered, self._dropped, self._high_water,
                                      len(self._queue))

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Stop receiving; queued events can still be read, then iteration ends."""
        if self._closed:
            return
        self._closed = True
        self._channel._remove(self)
        waiter, self._waiter = self._waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def __repr__(self) -> str:
        return f"<Subscription {self.domain}/{self.type} {self.statistics()}>"


class _Interest(Subscription):
    """A subscription that receives nothing (:meth:`EventChannel.declare_interest`)."""

    __slots__ = ()

    def _push(self, event: Event) -> None:
        pass


class Publisher:
    """A supplier's offer of ``(domain, type)``: publish without pattern matching."""

    __slots__ = ("domain", "type", "_channel", "_targets", "_version")

    def __init__(self, channel: EventChannel, domain: str, type: str) -> None:
        self.domain = domain
        self.type = type
        self._channel = channel
        self._targets: tuple[Subscription, ...] = ()
        self._version = -1

    @property
    def subscribed(self) -> bool:
        """True when a subscriber (not merely an observer) would receive this event: a
        supplier builds an optional form (a laser's static array) only for someone who
        asked for it; observers see what is published, they do not ask."""
        return any(not s.observer for s in self._current_targets())

    def _current_targets(self) -> tuple[Subscription, ...]:
        if self._version != self._channel._version:
            self._targets = self._channel._match(self.domain, self.type)
            self._version = self._channel._version
        return self._targets

    def publish(self, body: IDLModel, *, origin: str = "") -> Event:
        """Publish ``body``; never waits. Returns the event that was delivered."""
        channel = self._channel
        if self._version != channel._version:
            self._targets = channel._match(self.domain, self.type)
            self._version = channel._version
        return channel._deliver(self.domain, self.type, body, self._targets, origin)


class EventChannel:
    """The Notification Service of one process (``<Robot>/EventChannel``)."""

    def __init__(self, clock: Clock | None = None) -> None:
        self.clock: Clock = clock or WallClock()
        self._now = self.clock.now
        self._subscriptions: list[Subscription] = []
        self._cache: dict[tuple[str, str], tuple[Subscription, ...]] = {}
        self._publishers: dict[tuple[str, str], Publisher] = {}
        self._version = 0
        self._seq = 0
        self._order = 0
        self._counts: Counter[str] = Counter()
        self._closed = False

    # -- consumers -------------------------------------------------------------------
    def subscribe(self, domain: str, type: str, *, maxsize: int = 16,
                  policy: Overflow = Overflow.DROP_OLDEST) -> Subscription:
        """Subscribe to ``(domain, type)``; ``*``, ``?`` and ``[...]`` are wildcards."""
        if self._closed:
            raise ChannelClosed("the event channel is closed")
        self._order += 1
        subscription = Subscription(self, domain, type, maxsize, policy, self._order)
        self._subscriptions.append(subscription)
        self._changed()
        return subscription

    def observe(self, domain: str = "*", type: str = "*", *, maxsize: int = 4096,
                policy: Overflow = Overflow.DROP_OLDEST) -> Subscription:
        """A subscription for observers (digests, recorders, the console, bridges), by
        default to every event of every domain: its own bounded buffer, statistics and
        isolation. The observer reads it in its own task; a full buffer drops and
        counts, it never slows the publisher, and it does not make an event
        :meth:`subscribed` (watching must not change what suppliers build)."""
        subscription = self.subscribe(domain, type, maxsize=maxsize, policy=policy)
        subscription.observer = True
        return subscription

    def declare_interest(self, domain: str, type: str) -> Subscription:
        """An *interest*: it makes ``(domain, type)`` :meth:`subscribed` (suppliers build
        their optional forms for it) but receives nothing. A bridge declares the
        subscriptions of components in other processes this way; ``close()`` withdraws
        it."""
        if self._closed:
            raise ChannelClosed("the event channel is closed")
        self._order += 1
        interest = _Interest(self, domain, type, 1, Overflow.DROP_NEWEST, self._order)
        self._subscriptions.append(interest)
        self._changed()
        return interest

    # -- suppliers -------------------------------------------------------------------
    def offer(self, domain: str, type: str) -> Publisher:
        """A :class:`Publisher` for ``(domain, type)`` (one per pair, shared)."""
        if _is_pattern(domain) or _is_pattern(type):
            raise ValueError(f"cannot offer a pattern: {domain}/{type}")
        key = (domain, type)
        publisher = self._publishers.get(key)
        if publisher is None:
            publisher = self._publishers[key] = Publisher(self, domain, type)
        return publisher

    def publish(self, domain: str, type: str, body: IDLModel, *, origin: str = "") -> Event:
        """Publish one event; a plain call that never waits for consumers."""
        return self.offer(domain, type).publish(body, origin=origin)

    def inject(self, event: Event) -> Event:
        """Deliver an event made elsewhere (a bridge, a log player) with its time stamp
        and origin kept; it gets this channel's next sequence number."""
        return self._deliver(event.domain, event.type, event.body,
                             self.offer(event.domain, event.type)._current_targets(),
                             event.origin, event.time)

    def subscribed(self, domain: str, type: str) -> bool:
        """Whether a subscriber (not merely an observer) wants ``(domain, type)``."""
        return any(not s.observer for s in self._match(domain, type))

    def offers(self) -> list[tuple[str, str]]:
        """Every (domain, type) a supplier has offered."""
        return sorted(self._publishers)

    def subscriptions(self) -> list[Subscription]:
        return list(self._subscriptions)

    @property
    def published(self) -> int:
        """Events published so far (the last sequence number)."""
        return self._seq

    def counts(self) -> dict[str, int]:
        """Events published so far per event name (type)."""
        return dict(self._counts)

    def close(self) -> None:
        """Close every subscription; further subscribes fail."""
        self._closed = True
        for subscription in list(self._subscriptions):
            subscription.close()

    # -- internals -------------------------------------------------------------------
    def _deliver(self, domain: str, type: str, body: IDLModel,
                 targets: tuple[Subscription, ...], origin: str,
                 time: float | None = None) -> Event:
        if not isinstance(body, IDLModel):
            raise TypeError(f"event body must be an IDL model, not {type_name(body)}")
        self._seq += 1
        self._counts[type] += 1
        event = Event(domain, type, self._now() if time is None else time, self._seq, body,
                      origin)
        for subscription in targets:
            subscription._push(event)
        return event

    def _match(self, domain: str, type: str) -> tuple[Subscription, ...]:
        key = (domain, type)
        found = self._cache.get(key)
        if found is None:
            found = self._cache[key] = tuple(s for s in self._subscriptions
                                             if s.matches(domain, type))
        return found

    def _remove(self, subscription: Subscription) -> None:
        if subscription in self._subscriptions:
            self._subscriptions.remove(subscription)
            self._changed()

    def _changed(self) -> None:
        self._cache.clear()
        self._version += 1


def type_name(value: object) -> str:
    return type(value).__name__
