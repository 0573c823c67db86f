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
- Events serialise losslessly (:meth:`Event.to_json`), for logs and the network.
"""

from __future__ import annotations

import asyncio
import json
from collections import deque
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from enum import StrEnum
from fnmatch import fnmatchcase
from typing import Any, NamedTuple

from afa.clock import Clock, WallClock
from afa.errors import ChannelClosed
from idl._base import IDLModel, idl_types

__all__ = ["Event", "EventChannel", "Subscription", "Publisher", "Overflow",
           "SubscriptionStatistics"]


class Event(NamedTuple):
    """One structured event (immutable). ``body`` is an immutable IDL model."""

    domain: str
    type: str
    time: float
    seq: int
    body: IDLModel

    def to_json(self) -> bytes:
        """Serialise losslessly; the body's IDL type name travels with it."""
        header = {
            "domain": self.domain,
            "type": self.type,
            "time": self.time,
            "seq": self.seq,
            "body_type": type(self.body).__name__,
        }
        return b'{"header":%s,"body":%s}' % (json.dumps(header).encode(), self.body.to_json())

    @classmethod
    def from_json(cls, data: bytes | str) -> Event:
        """Inverse of :meth:`to_json`; the body type must be a known IDL type."""
        raw = json.loads(data)
        header = raw["header"]
        body_cls = idl_types()[header["body_type"]]
        return cls(header["domain"], header["type"], header["time"], header["seq"],
                   body_cls.model_validate(raw["body"]))


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

    __slots__ = ("domain", "type", "maxsize", "policy", "_channel", "_queue", "_waiter",
                 "_closed", "_delivered", "_dropped", "_high_water", "_order")

    def __init__(self, channel: EventChannel, domain: str, type: str, maxsize: int,
                 policy: Overflow, order: int) -> None:
        if maxsize < 1:
            raise ValueError(f"maxsize must be at least 1, got {maxsize}")
        self.domain = domain
        self.type = type
        self.maxsize = maxsize
        self.policy = Overflow(policy)
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
        """True when at least one subscription would receive this event."""
        return bool(self._current_targets())

    def _current_targets(self) -> tuple[Subscription, ...]:
        if self._version != self._channel._version:
            self._targets = self._channel._match(self.domain, self.type)
            self._version = self._channel._version
        return self._targets

    def publish(self, body: IDLModel) -> Event:
        """Publish ``body``; never waits. Returns the event that was delivered."""
        channel = self._channel
        if self._version != channel._version:
            self._targets = channel._match(self.domain, self.type)
            self._version = channel._version
        return channel._deliver(self.domain, self.type, body, self._targets)


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
        self._taps: list[Callable[[Event], Any]] = []
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

    def add_tap(self, tap: Callable[[Event], Any]) -> Callable[[], None]:
        """Call ``tap(event)`` synchronously for every event (recorders, digests).

        A tap must be fast and must not raise; it sees every event, never drops.
        Returns a function that removes the tap.
        """
        self._taps.append(tap)
        return lambda: self._taps.remove(tap)

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

    def publish(self, domain: str, type: str, body: IDLModel) -> Event:
        """Publish one event; a plain call that never waits for consumers."""
        return self.offer(domain, type).publish(body)

    def subscribed(self, domain: str, type: str) -> bool:
        """Whether anyone subscribes to ``(domain, type)``."""
        return bool(self._match(domain, type))

    def offers(self) -> list[tuple[str, str]]:
        """Every (domain, type) a supplier has offered."""
        return sorted(self._publishers)

    def subscriptions(self) -> list[Subscription]:
        return list(self._subscriptions)

    @property
    def published(self) -> int:
        """Events published so far (the last sequence number)."""
        return self._seq

    def close(self) -> None:
        """Close every subscription; further subscribes fail."""
        self._closed = True
        for subscription in list(self._subscriptions):
            subscription.close()

    # -- internals -------------------------------------------------------------------
    def _deliver(self, domain: str, type: str, body: IDLModel,
                 targets: tuple[Subscription, ...]) -> Event:
        if not isinstance(body, IDLModel):
            raise TypeError(f"event body must be an IDL model, not {type_name(body)}")
        self._seq += 1
        event = Event(domain, type, self._now(), self._seq, body)
        for subscription in targets:
            subscription._push(event)
        if self._taps:
            for tap in self._taps:
                tap(event)
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
