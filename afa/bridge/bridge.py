"""The Zenoh bridge of one process (decision 0012, ``docs/distributed.md``).

Attached to a :class:`~afa.system.System` (``Bridge(parameters).attach(system)``, or
``System.from_xml(..., process=..., bridge=...)``), it runs as a service of the system:
opened before the components start, closed after they stop.

- **Events out**: an observer of the channel (its own bounded buffer: a slow network
  never slows a publisher) puts every event published *in this process* whose name
  matches ``Export`` on ``afa/<Robot>/event/<Name>``, encoded with the wire codec, its
  origin prefixed with the process (``vehicle/GpsSokkiaService``). Events that came from
  another process are never sent on: no echo, whatever the topology.
- **Events in**: one subscriber on ``afa/<Robot>/**`` hands samples from Zenoh's thread
  to the loop (:class:`~afa.bridge.link.Inbox`: bounded, drop-oldest, counted). Each is
  decoded and checked (an unknown type, a damaged frame, a body the local subscribers of
  that name cannot take: counted and dropped, never injected) and injected into the
  local channel with its time and origin kept.
- **Polls out**: every name a local servant binds (``Export``) gets a queryable on
  ``afa/<Robot>/poll/<Name>/*`` and a liveliness token naming its interface. A query is
  decoded, checked by the command guard (:mod:`afa.bridge.guard`), and run through the
  system's poll layer (timeout, statistics, hooks) in a task; the result or the afa
  error goes back in the wire form. At most ``MaxQueries`` are served at once; more are
  answered ``EDevIO`` at once.
- **Polls in**: the liveliness tokens of other processes bind
  :class:`~afa.bridge.remote.RemoteServant` objects under their names (``Import``); a
  token that disappears (a process that stops or dies) unbinds the name and fails calls
  in flight. A local server of the same name always wins.
- **Info**: ``afa/<Robot>/info/<process>`` answers what the text tools need (JSON,
  :mod:`afa.bridge.info`).
- **Time**: under a :class:`~afa.bridge.lockstep.SteppedClock` the process joins the
  others in lock-step virtual time (decision 0011, :mod:`afa.bridge.lockstep`).
"""

from __future__ import annotations

import asyncio
import json
import logging
import struct
from collections import Counter
from fnmatch import fnmatchcase
from typing import Any

from afa.bridge import keys
from afa.bridge.guard import check_command
from afa.bridge.info import process_info
from afa.bridge.link import Inbox, close_session, load_zenoh, open_session, session_config
from afa.bridge.lockstep import Traffic
from afa.bridge.parameters import BridgeParameters, off_loopback
from afa.bridge.remote import (
    ERROR,
    RESULT,
    RemoteServant,
    caller_attachment,
    find_interface,
    parse_caller,
    reply_attachment,
)
from afa.errors import AfaError, ComponentError, EDevIO, NameNotFound
from afa.events import Event
from afa.naming import join_name
from afa.polling import (
    LocalInvoker,
    Servant,
    decode_arguments,
    encode_error,
    encode_result,
    proxy_for,
)
from afa.ports import Direction, interface_name
from idl import wire
from idl._base import Interface

__all__ = ["Bridge"]

log = logging.getLogger("afa.bridge")

_SEQ = struct.Struct("<Q")
#: How many times one kind of bad input is logged before it is only counted.
_LOG_LIMIT = 5
#: Items (events, tokens, queries) handled at a time; the loop turns between parts.
_PART = 64
#: Real seconds an info document answers for: a flood of info queries costs one document
#: a second (names that change make a new one at once).
_INFO_FOR = 1.0


class Bridge:
    """One process's bridge to the others (see the module docstring).

    Raises :class:`~afa.errors.ComponentError` at construction when Zenoh is not
    installed (``pip install 'afa[zenoh]'``).
    """

    name = "bridge"

    def __init__(self, parameters: BridgeParameters | None = None, *,
                 configuration: Any = None, members: list[str] | None = None) -> None:
        """``configuration`` (a validated Configuration) names the process groups that
        share lock-step time; ``members`` names them without one (the time master first
        unless ``TimeMaster`` says otherwise)."""
        self.parameters = parameters or BridgeParameters()
        self.configuration = configuration
        self.members = members
        self.zenoh = load_zenoh()  # fail at build time, with the extra to install
        self.system: Any = None
        self.session: Any = None
        self.zid = ""
        self.robot = ""
        self.process = ""
        self.attachment = b""
        self.lockstep: Any = None
        self._observer: Any = None
        self._tasks: list[asyncio.Task[Any]] = []
        self._data: Inbox[tuple[str, bytes]] | None = None
        self._alive: Inbox[tuple[str, bool]] | None = None
        self._queries: Inbox[tuple[str, Any]] | None = None
        self._subscribers: list[Any] = []
        self._interests: list[Any] = []  # the other processes' subscriptions, declared here
        self._publishers: dict[str, Any] = {}
        self._matching: dict[str, bool] = {}
        self._listeners: list[Any] = []
        self._served: dict[str, tuple[Any, Any, type[Interface]]] = {}  # name -> (q, token, i)
        self._process_token: Any = None
        self._info_queryable: Any = None
        self._query_callback: Any = None  # set by start(): queries into the inbox
        self._unwatch: Any = None
        # name -> {liveliness token key: (process, interface)}: the other processes' offers
        self._remote: dict[str, dict[str, tuple[str, type[Interface]]]] = {}
        self._users: dict[str, list[type[Interface]]] | None = None  # name -> interfaces used
        self._proxies: dict[tuple[str, type[Interface]], Any] = {}
        self._accepts: dict[tuple[str, type], bool] = {}
        self._subscribers_of: list[Any] | None = None
        self._export_names: dict[str, bool] = {}
        self._import_names: dict[str, bool] = {}
        self.peers: dict[str, str] = {}  # process -> "" (alive)
        self._serving = 0
        self.changed = asyncio.Event()  # any change of activity (lock-step idleness)
        # counters: messages per peer (lock-step consistency) and per name (statistics)
        self.traffic = Traffic()
        self.exported: Counter[str] = Counter()
        self.imported: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()  # reason -> events refused
        self.refused_commands = 0
        self.busy_refusals = 0
        self.served_calls = 0
        self.echoes = 0
        self.unwanted = 0  # events that arrived for which this process has no subscriber
        self._logged: Counter[str] = Counter()
        self._info: bytes | None = None  # the info document while it is current
        self._info_expiry: asyncio.TimerHandle | None = None

    @property
    def clock(self) -> Any:
        return self.system.clock

    def caller(self, time: float | None = None) -> bytes:
        """The attachment of this process's calls (who, and in lock-step when)."""
        return caller_attachment(self.process, self.zid, time)

    def _now(self) -> float | None:
        return self.clock.monotonic() if self.lockstep is not None else None

    # -- wiring ---------------------------------------------------------------------------
    def attach(self, system: Any) -> Bridge:
        """Run this bridge while ``system`` runs (before it starts)."""
        self.system = system
        self.robot = system.robot
        self.process = system.process
        if not keys.chunk_ok(self.robot) or not keys.chunk_ok(self.process):
            raise ComponentError(f"robot {self.robot!r} and process {self.process!r} must be "
                                 "usable as Zenoh key chunks (no / * $ ? # or spaces)")
        system.add_service(self)
        system.enable_meter()
        self._observer = system.observe(self._export, name="bridge",
                                        maxsize=self.parameters.ExportBuffer)
        from afa.bridge.lockstep import SteppedClock, lockstep_for

        if isinstance(system.clock, SteppedClock):
            self.lockstep = lockstep_for(self, system, self.configuration, self.members)
        return self

    # -- the service ------------------------------------------------------------------------
    async def start(self, system: Any) -> None:
        p = self.parameters
        for endpoint in off_loopback(p):
            log.warning("bridge: %s is not a loopback endpoint: other hosts can reach this "
                        "process (see docs/distributed.md for TLS and access control)",
                        endpoint)
        self.session = await open_session(session_config(p, system.base_dir), system.clock)
        try:
            await self._declare(system)
        except BaseException:
            await self.stop()  # a half-open bridge must not keep Zenoh's threads alive
            raise

    async def _declare(self, system: Any) -> None:
        zenoh = self.zenoh
        p = self.parameters
        loop = asyncio.get_running_loop()
        self.zid = str(self.session.zid())
        self._data = Inbox(loop, p.EventBuffer)
        self._alive = Inbox(loop, 1 << 16)
        self._queries = Inbox(loop, p.MaxQueries * 4, drop_oldest=False, refuse=self._refuse)
        data, alive, queries = self._data, self._alive, self._queries
        traffic = self.traffic
        process = self.process
        Callback = zenoh.handlers.Callback

        def on_sample(sample: Any) -> None:  # Zenoh's thread: copy, count, hand over
            attachment = sample.attachment
            extra = attachment.to_bytes() if attachment is not None else None
            if extra is not None and len(extra) > _SEQ.size:
                sender = extra[_SEQ.size:].decode(errors="replace")
                if sender != process:  # counted before it is queued (lock-step)
                    traffic.saw(sender, _SEQ.unpack_from(extra)[0])
            data.push((str(sample.key_expr), sample.payload.to_bytes()))

        name_tokens = f"{keys.ROOT}/{self.robot}/alive/name/"

        def on_alive(sample: Any) -> None:
            key = str(sample.key_expr)
            if key.startswith(name_tokens):  # counted before it is queued (lock-step)
                owner = key[len(name_tokens):].split("/")[1:2]
                if owner and owner[0] != process:
                    traffic.count(traffic.tokens_seen, owner[0])
            alive.push((key, sample.kind == zenoh.SampleKind.PUT))

        def on_query(query: Any) -> None:
            attachment = query.attachment
            caller = parse_caller(attachment.to_bytes() if attachment is not None else None)
            traffic.count(traffic.queries_received, caller[0])
            queries.push(("poll", query))

        def on_info(query: Any) -> None:
            queries.push(("info", query))

        self._query_callback = on_query
        self._subscribers.append(self.session.declare_subscriber(
            keys.everything(self.robot), Callback(on_sample),
            allowed_origin=zenoh.Locality.REMOTE))
        self._subscribers.append(self.session.liveliness().declare_subscriber(
            keys.alive_all(self.robot), Callback(on_alive), history=True))
        self._info_queryable = self.session.declare_queryable(
            keys.info(self.robot, self.process), Callback(on_info), complete=True)
        # what components in the other processes subscribe to counts as subscribed here,
        # so that suppliers build the optional forms they would build in one process
        for port in system.peer_ports:
            if port.direction is Direction.SUBSCRIBES and port.domain in (None, self.robot) \
                    and any(fnmatchcase(port.name, p) for p in self.parameters.Export):
                self._interests.append(system.channel.declare_interest(self.robot, port.name))
        self._unwatch = system.registry.watch(self._on_name)
        for name in system.registry.list(f"{self.robot}/"):
            self._on_name(name, system.registry.try_resolve(name))
        self._spawn(self._receive(), "bridge:events")
        self._spawn(self._liveliness(), "bridge:liveliness")
        self._spawn(self._serve_queries(), "bridge:queries")
        if self.lockstep is not None:
            await self.lockstep.start()
        # the process token last: whoever sees it knows our subscriptions are declared
        self._process_token = self.session.liveliness().declare_token(
            keys.alive_process(self.robot, self.process))
        if self.lockstep is not None:
            await self.lockstep.join()
        log.info("bridge %s/%s up (zid %s) listening on %s, connecting to %s", self.robot,
                 self.process, self.zid, ", ".join(p.Listen) or "nothing",
                 ", ".join(p.Connect) or "nothing")

    async def finish_instant(self) -> None:
        """In lock-step, wait until every process has finished the current instant and
        hold time there (the end of a run; ``System.run``). Otherwise nothing."""
        if self.lockstep is not None:
            await self.lockstep.finish_instant()

    def _spawn(self, coroutine: Any, name: str) -> None:
        self._tasks.append(self.system.tasks.spawn(coroutine, owner="bridge", name=name))

    async def stop(self) -> None:
        if self.lockstep is not None:
            await self.lockstep.stop()
        if self._unwatch is not None:
            self._unwatch()
            self._unwatch = None
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            try:
                await task
            except BaseException:  # noqa: BLE001 - cancelled, or already reported
                pass
        self._tasks.clear()
        for interest in self._interests:
            interest.close()
        self._interests.clear()
        session, self.session = self.session, None
        for name in list(self._remote):
            self._drop_remote(name, None, "this process's bridge stopped")
        for inbox in (self._data, self._alive):
            if inbox is not None:
                inbox.close()
        if self._queries is not None:
            for _, query in self._queries.close():
                self._answer_error(query, EDevIO("the serving process is stopping"))
        self._served.clear()
        self._publishers.clear()
        self._forget_info()
        if session is not None:
            await close_session(session, self.system.clock)

    # -- events out -------------------------------------------------------------------------
    def _exports(self, name: str) -> bool:
        return _selected(name, self._export_names, self.parameters.Export)

    def _imports(self, name: str) -> bool:
        return _selected(name, self._import_names, self.parameters.Import)

    def _publisher(self, name: str) -> Any:
        publisher = self._publishers.get(name)
        if publisher is None:
            zenoh = self.zenoh
            lockstep = self.lockstep is not None
            publisher = self._publishers[name] = self.session.declare_publisher(
                keys.event(self.robot, name), express=self.parameters.Express,
                # lock-step counts every event: never drop one; otherwise never block
                congestion_control=(zenoh.CongestionControl.BLOCK if lockstep
                                    else zenoh.CongestionControl.DROP))
            self._matching[name] = lockstep or publisher.matching_status.matching

            def on_matching(status: Any, name: str = name) -> None:  # Zenoh's thread
                self._matching[name] = lockstep or status.matching

            self._listeners.append(publisher.declare_matching_listener(on_matching))
        return publisher

    def _export(self, event: Event) -> None:
        """The observer: put a locally published event (never one that came in)."""
        if self.session is None or event.domain != self.robot:
            return
        origin = event.origin
        if "/" in origin:  # it came from another process: never send it on
            return
        name = event.type
        if not self._exports(name):
            return
        publisher = self._publisher(name)
        if not self._matching.get(name, True):
            return  # nobody elsewhere wants it: skip the encoding
        try:
            data = event._replace(origin=f"{self.process}/{origin or 'system'}").encode()
        except Exception as exc:  # a body the wire codec cannot carry: counted, not fatal
            self._reject("unencodable", f"event {name} cannot be encoded for export: "
                                        f"{type(exc).__name__}: {exc}")
            return
        traffic = self.traffic
        traffic.exported += 1
        publisher.put(data, attachment=_SEQ.pack(traffic.exported) + self.process.encode())
        self.exported[name] += 1

    # -- events (and time messages) in ----------------------------------------------------------
    async def _receive(self) -> None:
        assert self._data is not None
        while True:
            batch = await self._data.batch(_PART)
            for key, payload in batch:
                try:
                    robot, kind, rest = keys.parse(key)
                except ValueError:
                    continue
                if kind == "event" and len(rest) == 1:
                    self._import(rest[0], payload)
                elif kind == "time" and self.lockstep is not None:
                    self.lockstep.on_message(rest, payload)
            self.changed.set()

    def _reject(self, reason: str, message: str) -> None:
        self.rejected[reason] += 1
        self._logged[reason] += 1
        if self._logged[reason] <= _LOG_LIMIT:
            log.warning("bridge: %s (dropped%s)", message,
                        "; further ones are only counted" if self._logged[reason] == _LOG_LIMIT
                        else "")

    def _import(self, name: str, payload: bytes) -> None:
        if not self._imports(name):
            return
        # any subscription, observers included (a recorder or a digest wants it too);
        # the channel caches the match per name
        if not self.system.channel._match(self.robot, name):
            self.unwanted += 1  # nobody here would receive it: do not even decode it
            return
        try:
            event = Event.decode(payload)
        except wire.WireError as exc:
            self._reject("undecodable", f"event {name} from another process: {exc}")
            return
        except Exception as exc:  # a body whose validators refuse it
            self._reject("invalid", f"event {name} from another process is invalid: "
                                    f"{type(exc).__name__}: {exc}")
            return
        sender, _, _ = event.origin.partition("/")
        if event.domain != self.robot or event.type != name or not sender:
            self._reject("mislabelled", f"event under {name} says it is "
                                        f"{event.domain}/{event.type} from {event.origin!r}")
            return
        if sender == self.process:
            self.echoes += 1
            return
        if not self._accepted(name, type(event.body)):
            self._reject("wrong-type", f"{name} from {event.origin} carries "
                                       f"{type(event.body).__name__}, which a subscriber of "
                                       f"{name} here cannot take")
            return
        self.system.channel.inject(event)
        self.imported[name] += 1

    def _accepted(self, name: str, body_type: type) -> bool:
        """Whether every local subscriber of ``name`` takes ``body_type``."""
        key = (name, body_type)
        found = self._accepts.get(key)
        if found is None:
            if self._subscribers_of is None:
                self._subscribers_of = [
                    p for p in self.system.catalog().by(Direction.SUBSCRIBES)
                    if not p.process and p.domain in (None, self.robot, "*")]
            found = all(issubclass(body_type, port.classes)
                        for port in self._subscribers_of
                        if port.classes and fnmatchcase(name, port.name))
            self._accepts[key] = found
        return found

    # -- names out ----------------------------------------------------------------------------
    def _on_name(self, full: str, obj: Any) -> None:
        """Registry watcher: export local servants, keep remote bindings behind local ones."""
        self._forget_info()  # the names it lists
        try:
            robot, _, name = full.partition("/")
            if robot != self.robot or self.session is None:
                return
            if obj is None:
                self._withdraw(name)
                if name in self._remote:
                    self._bind_remote(name)
                return
            if isinstance(obj, RemoteServant):
                return
            if not isinstance(obj, Servant):
                self._withdraw(name)
                return
            served = self._served.get(name)
            if served is not None and served[2] is obj.interface:
                return
            self._withdraw(name)
            if self._exports(name) and keys.chunk_ok(interface_name(obj.interface)):
                queryable = self.session.declare_queryable(
                    keys.poll_all(self.robot, name),
                    self.zenoh.handlers.Callback(self._query_callback),
                    complete=True)
                token = self.session.liveliness().declare_token(keys.alive_name(
                    self.robot, name, self.process, interface_name(obj.interface)))
                self.traffic.tokens_declared += 1
                self._served[name] = (queryable, token, obj.interface)
        except Exception:  # a watcher must not raise inside bind
            log.exception("bridge: exporting %s failed", full)

    def _withdraw(self, name: str) -> None:
        served = self._served.pop(name, None)
        if served is not None:
            self.traffic.tokens_declared += 1  # its withdrawal is a change the others see
            queryable, token, _ = served
            for entity in (token, queryable):
                try:
                    entity.undeclare()
                except Exception:  # the session may be closing
                    pass

    # -- names in -------------------------------------------------------------------------------
    async def _liveliness(self) -> None:
        assert self._alive is not None
        while True:
            for key, present in await self._alive.batch(_PART):
                try:
                    robot, kind, rest = keys.parse(key)
                except ValueError:
                    continue
                if rest[:1] == ["process"] and len(rest) == 2:
                    self._on_process(rest[1], present)
                elif rest[:1] == ["name"] and len(rest) == 4:
                    self._on_remote_name(key, rest[1], rest[2], rest[3], present)
            self.changed.set()

    def _on_process(self, process: str, present: bool) -> None:
        if process == self.process:
            return
        if present:
            self.peers[process] = ""
            log.info("bridge: process %s joined", process)
        else:
            self.peers.pop(process, None)
            log.info("bridge: process %s left", process)
            for name, offers in list(self._remote.items()):
                self._drop_remote(name, [k for k, (p, _) in offers.items() if p == process],
                                  f"its process {process} went away")
        if self.lockstep is not None:
            self.lockstep.on_process(process, present)

    def _on_remote_name(self, key: str, name: str, process: str, qualified: str,
                        present: bool) -> None:
        """A name token of another process: an offer of ``name``, known by its whole key
        (its DELETE drops that offer and no other)."""
        if process == self.process or not self._imports(name):
            return
        if not present:
            if key in self._remote.get(name, {}):
                self._drop_remote(name, [key], f"its process {process} withdrew it")
                self._recheck(key)
            return
        if key in self._remote.get(name, {}):
            return
        interface = find_interface(qualified)
        if interface is None:
            self._reject("unknown-interface", f"{process} serves {name} as {qualified}, an "
                                              "interface this program does not know")
            return
        if not all(issubclass(interface, used) for used in self._used(name)):
            self._reject("wrong-interface", f"{process} serves {name} as {qualified}, which "
                                            f"a user of {name} here cannot call")
            return
        self._remote.setdefault(name, {})[key] = (process, interface)
        self._bind_remote(name)

    def _used(self, name: str) -> list[type[Interface]]:
        """The interfaces the components of this process use ``name`` as."""
        if self._users is None:
            self._users = {}
            for port in self.system.catalog().by(Direction.USES):
                used = find_interface(port.types[0])
                if not port.process and used is not None:
                    self._users.setdefault(port.name, []).append(used)
        return self._users.get(name, [])

    def _recheck(self, key: str) -> None:
        """Ask Zenoh whether the token ``key`` lives all the same (its DELETE came from a
        spoofing peer, or a glitch): a live one is offered, and bound, again."""
        alive = self._alive
        if self.session is None or alive is None:
            return

        def on_reply(reply: Any) -> None:  # Zenoh's thread
            if reply.ok is not None:
                alive.push((str(reply.ok.key_expr), True))

        self.session.liveliness().get(key, self.zenoh.handlers.Callback(on_reply))

    def _bind_remote(self, name: str) -> None:
        """Bind the first remote offer of ``name`` unless a local server holds it."""
        full = join_name(self.robot, name)
        current = self.system.registry.try_resolve(full)
        if current is not None and not isinstance(current, RemoteServant):
            return
        offers = self._remote.get(name)
        if not offers:
            return
        if isinstance(current, RemoteServant) and \
                (current.process, current.interface) in offers.values():
            return
        process, interface = next(iter(offers.values()))
        self.system.registry.rebind(full, RemoteServant(self, name, interface, process),
                                    owner=self)

    def _drop_remote(self, name: str, tokens: list[str] | None, reason: str) -> None:
        """Drop the offers of ``name`` made by ``tokens`` (None: all); unbind the name if
        the bound one is among them."""
        offers = self._remote.get(name, {})
        dropped = [offers.pop(token) for token in (list(offers) if tokens is None else tokens)
                   if token in offers]
        if not offers:
            self._remote.pop(name, None)
        full = join_name(self.robot, name)
        current = self.system.registry.try_resolve(full)
        if isinstance(current, RemoteServant) and \
                (current.process, current.interface) in dropped:
            current.fail_pending(reason)
            self.system.registry.unbind(full)  # the watcher rebinds another offer, if any

    # -- polls in ---------------------------------------------------------------------------
    def _refuse(self, item: tuple[str, Any]) -> None:
        """A query the full inbox cannot take (Zenoh's thread): answer it at once."""
        self.busy_refusals += 1
        self._answer_error(item[1], EDevIO(f"{self.process} is busy: more than "
                                           f"{self.parameters.MaxQueries} remote calls queued"))

    def _replied(self, query: Any) -> None:
        if not str(query.key_expr).startswith(f"{keys.ROOT}/{self.robot}/poll/"):
            return
        attachment = query.attachment
        caller = parse_caller(attachment.to_bytes() if attachment is not None else None)
        self.traffic.count(self.traffic.replies_sent, caller[0])

    def _answer_error(self, query: Any, error: BaseException) -> None:
        self._replied(query)
        try:
            query.reply(query.key_expr, encode_error(error),
                        attachment=reply_attachment(ERROR, self._now()))
        except Exception:  # the querier is gone
            pass
        finally:
            try:
                query.drop()
            except Exception:
                pass

    async def _serve_queries(self) -> None:
        assert self._queries is not None
        while True:
            for kind, query in await self._queries.batch(_PART):
                if kind == "info":
                    self._answer_info(query)
                elif self._serving >= self.parameters.MaxQueries:
                    self.busy_refusals += 1
                    self._answer_error(query, EDevIO(
                        f"{self.process} is busy: {self._serving} remote calls in progress"))
                else:
                    self._serving += 1
                    self._spawn_query(query)
            # a part of the inbox is taken: a lock-step member waiting to be idle must
            # look again (a call that waits for a later instant sets nothing until it
            # ends, and that instant is granted only once this process reports idle)
            self.changed.set()

    def _spawn_query(self, query: Any) -> None:
        task = self.system.tasks.spawn(self._serve(query), owner="bridge",
                                       name="bridge:call")
        del task  # owned by the system's task group; _serve never raises

    def _answer_info(self, query: Any) -> None:
        try:
            query.reply(query.key_expr, self._info_document(),
                        encoding=self.zenoh.Encoding.APPLICATION_JSON)
        except Exception as exc:
            log.exception("bridge: answering an info query failed")
            self._answer_error(query, ComponentError(f"info failed: {exc}"))
            return
        try:
            query.drop()
        except Exception:
            pass

    def _info_document(self) -> bytes:
        """What ``afa/<Robot>/info/<process>`` answers (:mod:`afa.bridge.info`), made at
        most once every ``_INFO_FOR`` s of real time, and at once after names change."""
        if self._info is None:
            self._info = json.dumps(process_info(self.system, self), default=str).encode()
            self._info_expiry = asyncio.get_running_loop().call_later(_INFO_FOR,
                                                                      self._forget_info)
        return self._info

    def _forget_info(self) -> None:
        self._info = None
        if self._info_expiry is not None:
            self._info_expiry.cancel()
            self._info_expiry = None

    async def _serve(self, query: Any) -> None:
        """One remote call: decode, guard, run through the poll layer, answer."""
        key = str(query.key_expr)
        try:
            try:
                robot, kind, rest = keys.parse(key)
                if kind != "poll" or len(rest) != 2:
                    raise ValueError(key)
            except ValueError:
                raise NameNotFound(f"{key} is not an afa poll") from None
            name, method = rest
            full = join_name(self.robot, name)
            servant = self.system.registry.try_resolve(full)
            if not isinstance(servant, Servant):
                raise NameNotFound(f"{full} is not bound in {self.process}: its server is "
                                   "not running")
            interface = servant.interface
            payload = query.payload
            arguments = decode_arguments(interface, method,
                                         payload.to_bytes() if payload is not None else b"")
            attachment = query.attachment
            caller = parse_caller(attachment.to_bytes() if attachment is not None else None)
            try:
                check_command(interface, method, arguments, caller[:2],
                              self.parameters.AllowCommandFrom, server=full)
            except AfaError:
                self.refused_commands += 1
                raise
            if self.lockstep is not None and caller[2] is not None:
                await self.lockstep.reach(caller[2])  # the grant may still be on its way
            proxy = self._proxy(full, interface)
            result = await getattr(proxy, method)(**arguments)
            data = encode_result(interface, method, result)
        except asyncio.CancelledError:
            self._answer_error(query, EDevIO(f"{self.process} is stopping"))
            raise
        except Exception as exc:  # afa errors travel as themselves, others as ComponentError
            self._answer_error(query, exc)
        else:
            self.served_calls += 1
            self._replied(query)
            try:
                query.reply(key, data, attachment=reply_attachment(RESULT, self._now()))
            except Exception:  # the caller gave up (timeout) or went away
                pass
            finally:
                try:
                    query.drop()
                except Exception:
                    pass
        finally:
            self._serving -= 1
            self.changed.set()

    def _proxy(self, full: str, interface: type[Interface]) -> Any:
        key = (full, interface)
        proxy = self._proxies.get(key)
        if proxy is None:
            proxy = self._proxies[key] = proxy_for(
                interface, LocalInvoker(self.system.registry, full, interface),
                middleware=self.system.polls.middleware)
        return proxy

    # -- accounting ---------------------------------------------------------------------------
    def idle(self) -> bool:
        """Nothing that arrived is waiting for the loop (lock-step): no queued event,
        query or reply. (A call in flight is a counted message, not business.)"""
        return ((self._data is None or self._data.pending() == 0)
                and (self._queries is None or self._queries.pending() == 0)
                and (self._alive is None or self._alive.pending() == 0)
                and self.traffic.replies_unprocessed == 0)

    def statistics(self) -> dict[str, Any]:
        """Counters for ``afa top``, the info document and run summaries."""
        observer = self._observer.statistics() if self._observer is not None else {}
        return {
            "process": self.process,
            "zid": self.zid,
            "peers": sorted(self.peers),
            "exported": dict(self.exported),
            "imported": dict(self.imported),
            "export_dropped": observer.get("dropped", 0),
            "import": self._data.statistics() if self._data is not None else {},
            "rejected": dict(self.rejected),
            "echoes": self.echoes,
            "unwanted": self.unwanted,
            "served": sorted(self._served),
            "remote_names": {name: sorted(p for p, _ in offers.values())
                             for name, offers in self._remote.items()},
            "calls_served": self.served_calls,
            "calls_made": dict(self.traffic.queries_sent),
            "commands_refused": self.refused_commands,
            "busy_refusals": self.busy_refusals,
            "lockstep": self.lockstep.statistics() if self.lockstep is not None else None,
        }


def _selected(name: str, cache: dict[str, bool], patterns: Any) -> bool:
    """Whether ``name`` can be a key chunk and matches one of ``patterns`` (cached)."""
    found = cache.get(name)
    if found is None:
        found = cache[name] = keys.chunk_ok(name) and any(
            fnmatchcase(name, pattern) for pattern in patterns)
    return found
