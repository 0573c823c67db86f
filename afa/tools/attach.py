"""How a text tool reaches a running system: its own small Zenoh session (no System, no
bridge), connected to the endpoints given (default: ``tcp/127.0.0.1:7447``, where a
process run with ``--bridge`` listens), listening on none, multicast scouting off.

- :meth:`Attachment.infos`: every process's info document (``afa/<Robot>/info/*``);
  :meth:`Attachment.require` raises :class:`Unreachable` when none answers.
- :meth:`Attachment.events`: the events of one name, decoded, as an async iterator
  (bounded buffer, drop-oldest, counted: a slow terminal never slows the vehicle, which
  never waits for a subscriber anyway).
- :meth:`Attachment.call`: one poll by name, typed by the interface the server
  announces; the same afa errors as a local call.

A tool is a peer that only listens and asks: it publishes nothing, serves nothing and
holds no liveliness token, so running one changes nothing in the system it watches
(its calls that would move the vehicle are refused unless the serving process allows
commands from it: ``--as NAME`` and ``Bridge/AllowCommandFrom``).
"""

from __future__ import annotations

import asyncio
import json
import sys
from collections.abc import AsyncIterator
from typing import Any

from afa.bridge import keys
from afa.bridge.info import info_problem
from afa.bridge.link import Inbox, load_zenoh, session_config
from afa.bridge.parameters import DEFAULT_ENDPOINT, BridgeParameters
from afa.bridge.remote import RemoteCall, caller_attachment, find_interface
from afa.errors import AfaError, NameNotFound
from afa.events import Event
from idl import wire
from idl._base import Interface

__all__ = ["Attachment", "Unreachable", "INFO_TIMEOUT"]

#: Seconds to wait for processes to answer an info query.
INFO_TIMEOUT = 3.0
#: Seconds to wait, after opening the session, for a connection to a peer.
CONNECT_GRACE = 1.0


class Unreachable(AfaError, ConnectionError):
    """No afa process answered."""


class Attachment:
    """A tool's session (``async with Attachment(...) as attachment``)."""

    def __init__(self, connect: list[str] | None = None, *, robot: str = "*",
                 identity: str = "tool", zenoh_config: str = "",
                 timeout: float = INFO_TIMEOUT) -> None:
        self.connect = list(connect or [DEFAULT_ENDPOINT])
        self.robot = robot
        self.identity = identity
        self.timeout = timeout
        self.parameters = BridgeParameters(Listen=[], Connect=self.connect,
                                           ZenohConfig=zenoh_config)
        self.zenoh = load_zenoh()
        self.session: Any = None
        self._subscribers: list[Any] = []
        self._infos: list[dict[str, Any]] | None = None
        self._refused: set[str] = set()  # info documents refused, reported once each

    async def __aenter__(self) -> Attachment:
        config = session_config(self.parameters, listen=[])
        try:
            self.session = await asyncio.to_thread(self.zenoh.open, config)
        except Exception as exc:
            raise Unreachable(f"cannot open a Zenoh session to {', '.join(self.connect)}: "
                              f"{exc}") from exc
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the session (blocking a few milliseconds; safe to call twice)."""
        session, self.session = self.session, None
        if session is not None:
            for subscriber in self._subscribers:
                try:
                    subscriber.undeclare()
                except Exception:
                    pass
            session.close()

    @property
    def where(self) -> str:
        return ", ".join(self.connect)

    @property
    def zid(self) -> str:
        return str(self.session.zid()) if self.session is not None else ""

    # -- info ------------------------------------------------------------------------------
    async def infos(self, timeout: float | None = None) -> list[dict[str, Any]]:
        """Every reachable process's info document (sorted by robot and process)."""
        loop = asyncio.get_running_loop()
        done: asyncio.Future[None] = loop.create_future()
        found: list[dict[str, Any]] = []
        refused: list[str] = []

        def on_reply(reply: Any) -> None:  # Zenoh's thread
            if reply.ok is not None:
                try:
                    document = json.loads(reply.ok.payload.to_bytes())
                except (ValueError, RecursionError):
                    document = None
                problem = info_problem(document) if document is not None else "not JSON"
                if problem is None:
                    found.append(document)
                else:
                    refused.append(f"{reply.ok.key_expr}: {problem}")

        def on_done() -> None:
            loop.call_soon_threadsafe(_resolve, done)

        self.session.get(keys.infos(self.robot), self.zenoh.handlers.Callback(on_reply, on_done),
                         timeout=self.timeout if timeout is None else timeout)
        await done
        for line in refused:
            if line not in self._refused:  # once per peer and reason
                self._refused.add(line)
                print(f"warning: ignored an info document from {line}", file=sys.stderr)
        infos = sorted(found, key=lambda info: (info["robot"], info["process"]))
        self._infos = infos
        return infos

    async def require(self, attempts: int = 3) -> list[dict[str, Any]]:
        """:meth:`infos` once a peer is connected (waiting up to the timeout for one),
        retried while a process may still be starting; raises :class:`Unreachable` when
        nothing is connected or no afa process answers."""
        loop = asyncio.get_running_loop()
        # opening the session has tried the endpoints already: a moment's grace
        deadline = loop.time() + min(self.timeout, CONNECT_GRACE)
        while not self._connected():
            if loop.time() >= deadline:
                raise Unreachable(f"no afa system is reachable at {self.where} (nothing "
                                  "accepts a connection there; start one with `afa run "
                                  "CONFIG --bridge`, or give its endpoint with --connect)")
            await asyncio.sleep(0.05)  # a CLI waiting for a connection: real time
        for attempt in range(attempts):
            infos = await self.infos()
            if infos:
                return infos
            if attempt + 1 < attempts:
                await asyncio.sleep(0.5)
        raise Unreachable(f"no afa system is reachable at {self.where} (a Zenoh peer is "
                          "there, but no afa process answers)")

    def _connected(self) -> bool:
        info = self.session.info
        return bool(info.peers_zid() or info.routers_zid())

    def robots(self) -> list[str]:
        return sorted({info["robot"] for info in self._infos or []})

    # -- events ------------------------------------------------------------------------------
    async def events(self, name: str, *, maxsize: int = 1024) -> AsyncIterator[Event]:
        """Events named ``name`` (a pattern with ``*`` for a whole chunk is allowed), as
        they arrive. Undecodable samples are skipped (counted in :attr:`undecodable`)."""
        loop = asyncio.get_running_loop()
        inbox: Inbox[bytes] = Inbox(loop, maxsize)
        self.inbox = inbox
        self.undecodable = 0
        subscriber = self.session.declare_subscriber(
            keys.events(self.robot, name),
            self.zenoh.handlers.Callback(lambda sample: inbox.push(sample.payload.to_bytes())))
        self._subscribers.append(subscriber)
        while True:
            for payload in await inbox.batch():
                try:
                    yield Event.decode(payload)
                except (wire.WireError, ValueError):
                    self.undecodable += 1

    # -- polls -------------------------------------------------------------------------------
    def server(self, name: str) -> tuple[str, str, type[Interface] | None]:
        """(robot, qualified interface name, interface class or None) of the process
        serving ``name`` (NameNotFound with the known names when none does)."""
        known = []
        for info in self._infos or []:
            for row in info.get("names", []):
                if row.get("remote"):
                    continue
                robot, _, short = row["name"].partition("/")
                known.append(short)
                if short == name or row["name"] == name:
                    return robot, row["interface"], find_interface(row["interface"])
        raise NameNotFound(f"no process serves {name!r}; served names: "
                           f"{', '.join(sorted(set(known))) or 'none'}")

    async def call(self, robot: str, name: str, interface: type[Interface], method: str,
                   arguments: dict[str, Any], timeout: float | None = None) -> Any:
        """One poll; raises the server's afa error, ETimeOut-like TimeoutError after
        ``timeout`` (default the interface's call timeout)."""
        call = RemoteCall(self.zenoh, self.session, robot, name, interface, method, arguments,
                          caller_attachment(self.identity, self.zid))
        limit = interface.call_timeout if timeout is None else timeout
        try:
            return await asyncio.wait_for(call.result(), limit)
        except TimeoutError:
            from afa.errors import ETimeOut

            raise ETimeOut(f"{robot}/{name}.{method} timed out after {limit:g} s") from None


def _resolve(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)
