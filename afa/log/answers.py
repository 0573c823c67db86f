"""A recording asked a poll at a chosen time, as its replay would answer it.

``afa poll NAME METHOD --log FILE --at T`` and ``afa sensor3d get NAME --log FILE`` do
not replay a whole system: :class:`RecordedAnswers` builds the replay's own servants
(:func:`afa.log.player.recorded_servants`, one :class:`~afa.log.player.ReplayServant`
per recorded server) and hands them the recorded events and poll results up to ``T``,
in recording order, as :class:`~afa.log.player.Player` does while it replays. So a tool
gets exactly what a component polling the replay at ``T`` would:

- ``get…`` without arguments: the latest recorded event of the method's type that the
  server published, else its latest recorded result;
- any other method: the latest recorded result of that call with the same arguments (a
  command that returns nothing is accepted, as the server did);
- ``get…Wait…``: the next value recorded after ``T``. Time runs on a virtual clock from
  ``T`` message by message, so the interface's ``wait_timeout`` of recorded time applies
  (``ETimeOut``, as in the replay); the end of the recording is an ``EDevIO``. The
  recording is then read up to that value, so the next ``getWait`` gives the one after.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Iterator
from typing import Any

from afa.clock import VirtualClock
from afa.errors import EDevIO, NameNotFound
from afa.log import format as fmt
from afa.log.player import ReplayServant, recorded_servants
from afa.log.reader import LogError, LogMessage, LogReader
from afa.tasks import Scope, first_error

__all__ = ["RecordedAnswers"]


class RecordedAnswers:
    """The recorded servers of ``reader``, answering as of ``at`` seconds after the
    recording's first message (None: its end). Raises LogError for an ``at`` outside
    the recording."""

    def __init__(self, reader: LogReader, at: float | None = None) -> None:
        self.reader = reader
        if at is not None and not 0 <= at <= reader.duration:
            raise LogError(f"--at {at:g} s is outside {reader.path}, which lasts "
                           f"{reader.duration:.3f} s")
        #: nanoseconds: the servants know the recording up to here (the chosen time,
        #: then the value a getWait answered with)
        self.position = reader.end if at is None else reader.start + round(at * 1e9)
        self.robot = reader.metadata.get(fmt.META_AFA, {}).get("robot", "Raptor")
        self.clock = VirtualClock(start=fmt.from_ns(self.position), auto_advance=False)
        self.servants = recorded_servants(reader, self.robot, self.clock, self._body)
        self._listeners: dict[str, list[ReplayServant]] = {}
        for servant in self.servants.values():
            for event_name in servant.topics:
                self._listeners.setdefault(event_name, []).append(servant)
        self._channels = {c.id for c in reader.topics(fmt.POLL)} | {
            c.id for c in reader.topics(fmt.EVENT) if c.event in self._listeners}
        self._fed = False
        self._later: Iterator[LogMessage] | None = None
        self._held: list[LogMessage] | None = None

    @property
    def time(self) -> float:
        """The time answered as of, as a clock stamp."""
        return fmt.from_ns(self.position)

    def servant(self, name: str) -> ReplayServant:
        """The recorded server ``name`` (``ModelService`` or ``Raptor/ModelService``)."""
        for full, servant in self.servants.items():
            if name in (full, full.partition("/")[2]):
                return servant
        raise NameNotFound(f"{self.reader.path} has no recorded server {name!r}; it has "
                           f"{', '.join(sorted(self.servants)) or 'none'}")

    async def call(self, name: str, method: str, arguments: dict[str, Any]) -> Any:
        """``method(**arguments)`` of the recorded server ``name``, answered as of the
        chosen time (see the module docstring)."""
        servant = self.servant(name)
        self._feed_to_position()
        try:
            async with Scope() as scope:
                task = scope.spawn(servant.invoke(method, arguments), f"recorded {method}")
                await self.clock.settle()
                if not task.done():  # a getWait: the messages after the position, in order
                    await self._feed_after_position(task)
                if not task.done():
                    task.cancel()
                    raise EDevIO(f"{servant.name}.{method}: nothing recorded after "
                                 f"t={self.time:.6f} answers it")
        except BaseExceptionGroup as group:  # the servant's error, or the one above
            raise first_error(group) from None
        return task.result()

    def _feed_to_position(self) -> None:
        if self._fed:
            return
        self._fed = True
        for message in self.reader.messages(end=self.position + 1, channels=self._channels):
            self._deliver(message)

    async def _feed_after_position(self, task: asyncio.Task[Any]) -> None:
        if self._later is None:  # one pass over the rest, shared by successive getWaits
            self._later = self.reader.messages(start=self.position + 1,
                                               channels=self._channels)
        held, self._held = self._held, None
        for message in itertools.chain(held or (), self._later):
            await self.clock.advance(max(0.0, message.time - self.clock.now()))
            if task.done():  # the interface's wait_timeout ran out first
                self._held = [message]  # the next call's
                return
            self._deliver(message)
            self.position = message.log_time
            await self.clock.settle()
            if task.done():
                return

    def _deliver(self, message: LogMessage) -> None:
        """One recorded message to the servants, as the replay delivers it."""
        channel = message.channel
        if channel.kind == fmt.EVENT:
            for servant in self._listeners.get(channel.event, ()):
                servant.slot(channel.event).set(message)
            return
        record = self.reader.decode_wire(message)
        if isinstance(record, fmt.PollCallIDL):
            server = self.servants.get(record.server)
            if server is not None:
                server.replay(record)

    def _body(self, message: LogMessage) -> Any:
        event = self.reader.decode_event(message)
        if event is None:
            raise EDevIO(f"{message.channel.topic}: the recorded event cannot be decoded")
        return event.body
