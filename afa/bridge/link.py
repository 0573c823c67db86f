"""What afa needs of Zenoh, in one place: importing it (a clear message when the
optional extra is missing), a session configuration from :class:`BridgeParameters`,
opening and closing a session without blocking the loop, and :class:`Inbox`, the hand-off
from Zenoh's threads to the event loop.

Zenoh calls its callbacks on its own threads (one per subscriber or queryable). A
callback must never block there, so it only appends to an :class:`Inbox` (a bounded
deque under a lock) and, when the inbox was empty, schedules one wake-up of the loop
with ``loop.call_soon_threadsafe``. The loop then takes the batch, a part at a time if
it asks (other tasks run between the parts: a flood cannot hold the loop). A full inbox
drops its oldest item (events: the newest matter) or refuses the newest (queries: the
caller is answered at once), and counts it.
"""

from __future__ import annotations

import asyncio
import json
import threading
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any, Generic, TypeVar

from afa.bridge.parameters import BridgeParameters
from afa.clock import Clock
from afa.errors import ComponentError, ConfigError

__all__ = ["load_zenoh", "session_config", "open_session", "close_session", "Inbox",
           "ZENOH_MISSING"]

T = TypeVar("T")

ZENOH_MISSING = ("the Zenoh bridge needs the optional extra 'zenoh' (eclipse-zenoh): "
                 "pip install 'afa[zenoh]'")


def load_zenoh() -> Any:
    """The ``zenoh`` module; raises ComponentError naming the extra when it is missing."""
    try:
        import zenoh
    except ImportError as exc:
        raise ComponentError(f"{ZENOH_MISSING} ({exc})") from exc
    return zenoh


def session_config(parameters: BridgeParameters, base_dir: Path | None = None,
                   *, listen: list[str] | None = None) -> Any:
    """A Zenoh configuration: the ``ZenohConfig`` file if any (TLS, access control...),
    then mode, endpoints and scouting from ``parameters`` (``listen`` overrides the
    listen endpoints: a tool listens on none). Raises ConfigError for a bad file."""
    zenoh = load_zenoh()
    if parameters.ZenohConfig:
        path = Path(parameters.ZenohConfig)
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        try:
            config = zenoh.Config.from_file(str(path))
        except Exception as exc:  # zenoh raises its own ZError
            raise ConfigError(f"{path}: not a usable Zenoh configuration: {exc}") from exc
    else:
        config = zenoh.Config()
    endpoints = parameters.Listen if listen is None else listen
    config.insert_json5("mode", json.dumps(parameters.Mode))
    config.insert_json5("scouting/multicast/enabled", json.dumps(parameters.MulticastScouting))
    config.insert_json5("listen/endpoints", json.dumps(endpoints))
    config.insert_json5("connect/endpoints", json.dumps(parameters.Connect))
    return config


async def open_session(config: Any, clock: Clock) -> Any:
    """Open a Zenoh session in a worker thread (it takes ~10 ms, longer when a peer is
    absent), marked as real I/O so virtual time does not race ahead meanwhile. Raises
    ComponentError when Zenoh refuses (an endpoint in use, a bad TLS file)."""
    zenoh = load_zenoh()
    with clock.real_io():
        try:
            return await asyncio.to_thread(zenoh.open, config)
        except Exception as exc:
            raise ComponentError(f"cannot open the Zenoh session: {exc}") from exc


async def close_session(session: Any, clock: Clock) -> None:
    """Close a session in a worker thread (it flushes and says goodbye to peers)."""
    with clock.real_io():
        await asyncio.to_thread(session.close)


class Inbox(Generic[T]):
    """Items from Zenoh's threads to the loop: bounded, counted, one wake-up per batch.

    ``push`` may be called from any thread and never blocks (beyond a short lock);
    ``batch()`` (loop) waits for and returns everything queued. ``refuse``: with
    ``drop_oldest=False`` a full inbox calls ``refuse(item)`` on the pushing thread
    instead of queueing it (a query is answered "busy" at once).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, maxsize: int, *,
                 drop_oldest: bool = True,
                 refuse: Callable[[T], None] | None = None) -> None:
        self._loop = loop
        self.maxsize = maxsize
        self._drop_oldest = drop_oldest
        self._refuse = refuse
        self._items: deque[T] = deque()
        self._lock = threading.Lock()
        self._scheduled = False
        self._ready = asyncio.Event()
        self._partial = False  # the last batch() left items for the next
        self._closed = False
        self.received = 0  #: items pushed (counted on the pushing thread)
        self.dropped = 0   #: items dropped or refused because the inbox was full
        self.high_water = 0

    def push(self, item: T) -> None:
        """Queue ``item`` (any thread)."""
        refused = False
        with self._lock:
            if self._closed:
                return
            if len(self._items) >= self.maxsize:
                self.dropped += 1
                if self._drop_oldest:
                    self._items.popleft()
                else:
                    refused = True
            if not refused:
                self._items.append(item)
                if len(self._items) > self.high_water:
                    self.high_water = len(self._items)
            self.received += 1
            wake = not refused and not self._scheduled
            if wake:
                self._scheduled = True
        if refused:
            if self._refuse is not None:
                self._refuse(item)
            return
        if wake:
            try:
                self._loop.call_soon_threadsafe(self._ready.set)
            except RuntimeError:  # the loop is closed: the process is ending
                pass

    def pending(self) -> int:
        with self._lock:
            return len(self._items)

    async def batch(self, limit: int | None = None) -> list[T]:
        """Everything queued, or its first ``limit`` items, waiting until there is
        something (loop only). What a limited batch leaves comes with the next call,
        after one turn of the loop: other tasks run between the parts of a flood."""
        if self._partial:
            await asyncio.sleep(0)
        while True:
            await self._ready.wait()
            with self._lock:
                if limit is None or len(self._items) <= limit:
                    items = list(self._items)
                    self._items.clear()
                else:
                    items = [self._items.popleft() for _ in range(limit)]
                self._partial = bool(self._items)
                if not self._partial:
                    self._ready.clear()
                    self._scheduled = False
            if items:
                return items

    def take(self) -> list[T]:
        """Everything queued now, without waiting (loop only)."""
        with self._lock:
            items = list(self._items)
            self._items.clear()
            return items

    def close(self) -> list[T]:
        """Refuse further items; returns what was queued."""
        with self._lock:
            self._closed = True
            items = list(self._items)
            self._items.clear()
        return items

    def statistics(self) -> dict[str, int]:
        with self._lock:
            return {"received": self.received, "dropped": self.dropped,
                    "high_water": self.high_water, "queued": len(self._items)}
