"""Two and three real processes on loopback: events and polls both ways, the same afa
errors and per-call timeouts across the bridge, no echo, a killed peer's names unbound
and its calls in flight failed, remote commands refused unless allowed, and bad input
from a peer (garbage, unknown or wrong types, bad arguments, a flood) counted and
answered, never a crash.

The pytest process is process "b"; the others run ``tests.bridge.parts``. Waits are
bounded waits on conditions, never timing assertions."""

from __future__ import annotations

import asyncio
import json
import struct
from typing import Any

import pytest

from afa import (
    CommandRefused,
    ComponentError,
    EDevIO,
    EOutOfBounds,
    ETimeOut,
    Event,
    InterfaceError,
    NameNotFound,
    System,
    VirtualClock,
    WallClock,
)
from afa.bridge import Bridge, BridgeParameters, keys
from afa.bridge.link import load_zenoh
from afa.bridge.remote import ERROR, RESULT, RemoteServant, parse_reply
from idl import GpsIDL, TimeIDL, VehicleControl, VelocityIDL, wire
from tests.bridge.conftest import Peer
from tests.bridge.parts import (
    Count,
    Counter,
    CounterServer,
    Doubled,
    Doubler,
    Poller,
    endpoint,
    free_port,
)
from tests.waiting import eventually


def peer_a(port: int, *extra: str) -> Peer:
    return Peer(["-m", "tests.bridge.peer", "a", "--process", "a",
                 "--listen", endpoint(port), *extra])


def system_b(*ports: int, allow: list[str] | None = None, **parameters: Any) -> System:
    """Process b, connected to the processes listening on ``ports``."""
    system = System([CounterServer("counterB", served="CounterB", event="CountB"),
                     Doubler("doubler"), Poller("pollerB", served="Counter", period=0.2)],
                    clock=WallClock(), process="b")
    Bridge(BridgeParameters(Listen=[], Connect=[endpoint(port) for port in ports],
                            AllowCommandFrom=allow or [], **parameters)).attach(system)
    return system


def bridge_of(system: System) -> Bridge:
    return next(s for s in system.services if isinstance(s, Bridge))  # type: ignore[misc]


async def test_events_and_polls_cross_both_ways_without_echo(peers: list[Peer]) -> None:
    port = free_port()
    a = peer_a(port)
    peers.append(a)
    a.wait_ready()
    system = system_b(port)
    async with system:
        doubler = system.components["doubler"]
        poller = system.components["pollerB"]
        await eventually(lambda: len(doubler.seen) >= 5 and len(poller.polled) >= 3,
                         what="Count events from a and polls of a's Counter")
        # events a -> b keep their time and say where they came from
        assert {origin for *_, origin in doubler.seen} == {"a/counter"}
        counter = await system.resolve(Counter, "Counter", timeout=5)
        assert await counter.add(2, 3) == 5  # a poll b -> a, typed
        latest = await counter.getCount()
        assert isinstance(latest, Count) and latest.value >= 0
        bridge = bridge_of(system)
        await eventually(lambda: bridge.statistics()["calls_served"] >= 3,
                         what="a's polls of b's CounterB")
        assert isinstance(system.registry.resolve("Raptor/Counter"), RemoteServant)
        await asyncio.sleep(0.5)  # let a receive b's Doubled events
    a.stop()
    result = a.result()
    # events b -> a: the Doubled answers came back, from b's doubler
    assert result["sink.doubled"] and {o for *_, o in result["sink.doubled"]} == {"b/doubler"}
    # polls a -> b: a's poller read b's CounterB
    assert result["poller.polled"]
    # no echo: a's sink saw only its own Count events, never one returned by b
    assert {origin for _, origin in result["sink.counts"]} == {"counter"}
    assert result["events"]["Count"] == len(result["sink.counts"]) or \
        result["events"]["Count"] == len(result["sink.counts"]) + 1  # the last in flight


async def test_errors_and_timeouts_are_the_same_across_the_bridge(peers: list[Peer]) -> None:
    port = free_port()
    a = peer_a(port)
    peers.append(a)
    a.wait_ready()
    async with system_b(port) as system:
        counter = await system.resolve(Counter, "Counter", timeout=10)
        with pytest.raises(EOutOfBounds, match="negative"):  # the server's own error class
            await counter.check(-1.0)
        assert await counter.check(2.5) == 2.5
        with pytest.raises(InterfaceError):  # refused by the proxy before it leaves
            await counter.add("two", 3)  # type: ignore[arg-type]
        slow = system.proxy(Counter, "Counter", call_timeout=0.3)  # the per-call timeout
        with pytest.raises(ETimeOut):
            await slow.slow(5.0)
        assert await counter.slow(0.05) == 0.05  # the server is fine after a timed-out call
        with pytest.raises(NameNotFound):  # nobody serves it, in any process
            await system.proxy(Counter, "NoSuchCounter").add(1, 1)


async def test_remote_commands_are_refused_unless_the_caller_is_allowed(
        peers: list[Peer]) -> None:
    port, other = free_port(), free_port()
    a = peer_a(port)
    allowing = peer_a(other, "--allow", "b")
    peers += [a, allowing]
    a.wait_ready()
    allowing.wait_ready()
    async with system_b(port) as system:
        vehicle = await system.resolve(VehicleControl, "RaptorMotion", timeout=10)
        with pytest.raises(CommandRefused, match="setVelocity from b refused"):
            await vehicle.setVelocity(VelocityIDL(translation=1.0))
        with pytest.raises(CommandRefused):
            await vehicle.startVehicle()
        with pytest.raises(CommandRefused):
            await vehicle.setArbiter(True)
        await vehicle.stopVehicle()  # stopping is always allowed
        limits = await vehicle.getMinMaxVelocity()  # reading is too
        assert limits.maxTranslation == 1.0
        assert bridge_of(system).statistics()["commands_refused"] == 0  # counted by a
    async with system_b(other) as system:
        vehicle = await system.resolve(VehicleControl, "RaptorMotion", timeout=10)
        await vehicle.setVelocity(VelocityIDL(translation=1.0))  # allowed: --allow b
    a.stop()
    allowing.stop()
    assert a.result()["vehicle.commands"] == ["stopVehicle"]
    assert a.result()["bridge"]["commands_refused"] == 3
    assert allowing.result()["vehicle.commands"] == ["setVelocity 1.0"]


async def test_a_killed_peer_unbinds_its_names_and_fails_calls_in_flight(
        peers: list[Peer]) -> None:
    port = free_port()
    a = peer_a(port)
    peers.append(a)
    a.wait_ready()
    async with system_b(port) as system:
        counter = await system.resolve(Counter, "Counter", timeout=10)
        assert await counter.add(1, 1) == 2
        call = asyncio.ensure_future(counter.slow(30.0))  # in flight when a dies
        await asyncio.sleep(0.2)
        a.kill()
        with pytest.raises(NameNotFound):
            await asyncio.wait_for(call, 10)
        # each name's liveliness token lapses on its own: wait for all of a's names
        await eventually(lambda: system.registry.try_resolve("Raptor/Counter") is None
                         and system.registry.try_resolve("Raptor/RaptorMotion") is None,
                         what="a's names unbound after it was killed")
        with pytest.raises(NameNotFound, match="not running"):
            await counter.add(1, 1)
        assert "a" not in bridge_of(system).peers
        # b itself is unharmed: its servers still run (its poller of a's Counter fails
        # and is restarted by its supervisor, as with a local server that stops)
        health = system.health()
        assert health["counterB"].state.value == "running"
        assert health["doubler"].state.value == "running"


async def test_three_processes_share_events_and_names_once(peers: list[Peer]) -> None:
    port, port_c = free_port(), free_port()
    a = peer_a(port)
    peers.append(a)
    a.wait_ready()
    c = Peer(["-m", "tests.bridge.peer", "c", "--process", "c", "--listen", endpoint(port_c),
              "--connect", endpoint(port)])
    peers.append(c)
    c.wait_ready()
    async with system_b(port) as system:
        doubler = system.components["doubler"]
        await eventually(lambda: len(doubler.seen) >= 5, what="Count from a")
        await eventually(lambda: "c" in bridge_of(system).peers, what="c seen by b")
        await asyncio.sleep(1.0)  # c polls a, receives a's Count and b's Doubled
        c.kill()  # a third process dying unbinds nothing of a's in b
        await eventually(lambda: "c" not in bridge_of(system).peers, what="c gone")
        assert isinstance(system.registry.try_resolve("Raptor/Counter"), RemoteServant)
        counter = await system.resolve(Counter, "Counter")
        assert await counter.add(20, 22) == 42
    a.stop()
    result = a.result()
    # a received each Doubled once, from b only (c never sent a's or b's events on)
    origins = [o for *_, o in result["sink.doubled"]]
    assert origins and set(origins) == {"b/doubler"}
    values = [v for _, v, _ in result["sink.doubled"]]
    assert len(values) == len(set(values))
    assert {origin for _, origin in result["sink.counts"]} == {"counter"}


# -- bad input from a peer --------------------------------------------------------------


class RawPeer:
    """A bare Zenoh session on loopback that says what it likes (a broken peer): it
    listens on ``port`` or connects to the processes listening on ``connect``."""

    def __init__(self, port: int | None = None, *, connect: tuple[int, ...] = ()) -> None:
        self.zenoh = load_zenoh()
        config = self.zenoh.Config()
        config.insert_json5("mode", '"peer"')
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("listen/endpoints", json.dumps([endpoint(port)] if port else []))
        config.insert_json5("connect/endpoints", json.dumps([endpoint(p) for p in connect]))
        self.session = self.zenoh.open(config)

    def put(self, key: str, payload: bytes, attachment: bytes | None = None) -> None:
        self.session.put(key, payload, attachment=attachment)

    def get(self, key: str, payload: bytes, attachment: bytes = b"raw\n") -> list[Any]:
        return [reply for reply in self.session.get(key, payload=payload,
                                                      attachment=attachment, timeout=5)]

    def info(self, process: str) -> dict[str, Any]:
        """The info document of ``process`` (blocking)."""
        replies = [reply.ok for reply in self.get(keys.info("Raptor", process), b"")
                   if reply.ok is not None]
        assert replies, f"process {process} does not answer"
        return json.loads(replies[0].payload.to_bytes())  # type: ignore[no-any-return]

    def processes(self) -> set[str]:
        """The processes whose token it sees: their subscriptions reach it (blocking)."""
        tokens = self.session.liveliness().get(keys.alive_process("Raptor", "*"), timeout=5)
        return {str(reply.ok.key_expr).rpartition("/")[2] for reply in tokens if reply.ok}

    def close(self) -> None:
        self.session.close()


def answer(reply: Any) -> tuple[int, bytes]:
    """(result or error, payload) of a poll's reply (the attachment says which)."""
    assert reply.ok is not None, "afa answers a poll with a sample, errors included"
    kind, _ = parse_reply(reply.ok.attachment.to_bytes())
    return kind, reply.ok.payload.to_bytes()


def raw_event(type_name: str, body: Any, origin: str = "evil/component",
              time: float = 1.0) -> bytes:
    return Event("Raptor", type_name, time, 1, body, origin).encode()


async def test_bad_events_from_a_peer_are_counted_and_never_delivered() -> None:
    port = free_port()
    raw = RawPeer(port)
    try:
        async with system_b(port) as system:
            doubler = system.components["doubler"]
            bridge = bridge_of(system)
            await eventually(lambda: "Raptor/CounterB" in system.registry.list(),
                             what="b up")
            await asyncio.sleep(0.5)  # the subscriptions meet
            good = raw_event("Count", Count(value=7))
            raw.put(keys.event("Raptor", "Count"), good)
            raw.put(keys.event("Raptor", "Count"), b"not an afa event")
            frame = bytearray(good)
            at = frame.index(b"tests.bridge")
            frame[at:at + 5] = b"zzzzz"  # a type name nobody knows
            raw.put(keys.event("Raptor", "Count"), bytes(frame))
            raw.put(keys.event("Raptor", "Count"), raw_event(
                "Count", GpsIDL(time=TimeIDL(sec=1), latitude=1.0, longitude=2.0,
                                elevation=3.0)))  # a type the Count subscribers refuse
            raw.put(keys.event("Raptor", "Count"), raw_event("Pose", Count(value=1)))
            raw.put(keys.event("Raptor", "Count"), good[:20])  # truncated
            for stamp in (float("nan"), float("inf")):  # a time no clock gives
                raw.put(keys.event("Raptor", "Count"), raw_event("Count", Count(value=9),
                                                                 time=stamp))
            await eventually(lambda: sum(bridge.rejected.values()) >= 7,
                             what="seven bad events counted")
            assert bridge.rejected["wrong-type"] == 1 and bridge.rejected["mislabelled"] == 1
            assert bridge.rejected["undecodable"] == 5
            assert [value for _, value, _, _ in doubler.seen] == [7]  # only the good one
            assert system.health()["doubler"].state.value == "running"
    finally:
        raw.close()


async def test_bad_poll_arguments_are_answered_with_the_documented_error() -> None:
    port = free_port()
    raw = RawPeer(port)
    try:
        async with system_b(port) as system:
            await eventually(lambda: "Raptor/CounterB" in system.registry.list(), what="b up")
            await asyncio.sleep(0.5)
            from afa.polling import decode_error, encode_arguments

            # (a blocking get: in a worker thread, so that b's loop can answer it)
            replies = await asyncio.to_thread(raw.get, keys.poll("Raptor", "CounterB", "add"),
                                              b"garbage")
            assert len(replies) == 1
            kind, data = answer(replies[0])
            assert kind == ERROR
            error = decode_error(data)
            assert isinstance(error, InterfaceError) and "bad arguments" in str(error)
            replies = await asyncio.to_thread(raw.get, keys.poll("Raptor", "CounterB", "nosuch"),
                                              b"")
            kind, data = answer(replies[0])
            assert kind == ERROR and isinstance(decode_error(data), InterfaceError)
            payload = encode_arguments(Counter, "add", {"a": 1, "b": 2})
            replies = await asyncio.to_thread(raw.get, keys.poll("Raptor", "CounterB", "add"),
                                              payload)
            kind, data = answer(replies[0])
            from afa.polling import decode_result

            assert kind == RESULT and decode_result(Counter, "add", data) == 3
            # an info query answers JSON the tools read
            info = await asyncio.to_thread(raw.get, keys.info("Raptor", "b"), b"")
            document = json.loads(info[0].ok.payload.to_bytes())
            assert document["process"] == "b" and "counterB" in {
                c["name"] for c in document["components"]}
    finally:
        raw.close()


async def test_a_flood_from_a_peer_is_bounded_and_counted() -> None:
    port = free_port()
    raw = RawPeer(port)
    try:
        async with system_b(port, EventBuffer=64) as system:
            bridge = bridge_of(system)
            await eventually(lambda: "Raptor/CounterB" in system.registry.list(), what="b up")
            await asyncio.sleep(0.5)
            frame = raw_event("Count", Count(value=1))
            sent = 20_000
            await asyncio.to_thread(
                lambda: [raw.put(keys.event("Raptor", "Count"), frame) for _ in range(sent)])
            inbox = bridge.statistics()["import"]
            await eventually(lambda: bridge.statistics()["import"]["received"] >= sent * 0.5,
                             what="the flood arriving")
            inbox = bridge.statistics()["import"]
            assert inbox["high_water"] <= 64  # never more than the bound waiting
            counter = system.proxy(Counter, "CounterB")
            assert await counter.add(1, 2) == 3  # b still answers
            assert system.health()["doubler"].state.value == "running"
    finally:
        raw.close()


async def test_a_spoofed_name_token_neither_unbinds_nor_takes_over_a_live_name(
        peers: list[Peer]) -> None:
    """A peer that declares a's name under other interfaces and withdraws them leaves
    a's offer bound: an offer is known by its whole token, and one no user here can call
    is never bound. A withdrawal of a's very token while it lives (Zenoh sends none,
    but a lapsed lease or a spoofing router can) is checked with Zenoh: it binds again."""
    port, rogue_port = free_port(), free_port()
    a = peer_a(port)
    peers.append(a)
    a.wait_ready()
    raw = RawPeer(rogue_port)
    try:
        async with system_b(port, rogue_port) as system:
            bridge = bridge_of(system)
            counter = await system.resolve(Counter, "Counter", timeout=10)
            bound = system.registry.resolve("Raptor/Counter")
            assert isinstance(bound, RemoteServant) and bound.process == "a"
            liveliness = raw.session.liveliness()
            claims = [liveliness.declare_token(keys.alive_name("Raptor", "Counter", "a", i))
                      for i in ("bogus", "idl.interfaces.Gps")]
            for claim in claims:
                claim.undeclare()
            marker = liveliness.declare_token(  # comes after the withdrawals
                keys.alive_name("Raptor", "Marker", "rogue", "tests.bridge.parts.Counter"))
            await eventually(lambda: "Marker" in bridge.statistics()["remote_names"],
                             what="the claims and their withdrawals taken")
            assert bridge.rejected["unknown-interface"] == 1
            assert bridge.rejected["wrong-interface"] == 1  # the Poller here uses Counter
            assert system.registry.resolve("Raptor/Counter") is bound  # never unbound
            assert await counter.add(1, 2) == 3
            bindings: list[Any] = []
            system.registry.watch(lambda name, obj: name == "Raptor/Counter"
                                  and bindings.append(obj))
            token = keys.alive_name("Raptor", "Counter", "a", "tests.bridge.parts.Counter")
            bridge._alive.push((token, False))  # as Zenoh's thread hands a withdrawal over
            await eventually(lambda: len(bindings) >= 2, what="Counter bound again")
            assert bindings[0] is None and isinstance(bindings[1], RemoteServant)
            assert bindings[1].process == "a" and await counter.add(2, 3) == 5
            marker.undeclare()
    finally:
        raw.close()


def lockstep_pair() -> tuple[Peer, Peer, int, int]:
    """A lock-step run (master a, follower b) long enough to outlive the test; both
    listen, so that a raw peer reaches each."""
    port_a, port_b = free_port(), free_port()
    common = ["--clock", "stepped", "--members", "a,b"]
    a = Peer(["-m", "tests.bridge.peer", "ls-a", "--process", "a", *common,
              "--listen", endpoint(port_a), "--duration", "100000"])
    b = Peer(["-m", "tests.bridge.peer", "ls-b", "--process", "b", *common,
              "--listen", endpoint(port_b), "--connect", endpoint(port_a)])
    return a, b, port_a, port_b


async def time_moves_on(raw: RawPeer, process: str) -> None:
    """Virtual time in ``process`` (its info document's clock) goes on from now."""
    before = raw.info(process)["clock"]["monotonic"]
    await eventually(lambda: raw.info(process)["clock"]["monotonic"] > before,
                     what=f"virtual time moving on in {process}")


def stop_together(a: Peer, b: Peer) -> None:
    """Stop the lock-step pair at the master; both must end cleanly."""
    a.stop()
    assert a.wait() == 0 and b.wait() == 0, a.errors + b.errors


async def test_malformed_time_messages_are_counted_and_the_run_goes_on(
        peers: list[Peer]) -> None:
    a, b, port_a, port_b = lockstep_pair()
    peers += [a, b]
    a.wait_ready()
    b.wait_ready()
    raw = RawPeer(connect=(port_a, port_b))
    try:
        await eventually(lambda: raw.processes() >= {"a", "b"}, what="a and b seen")
        to_follower = ['{"op":"advance","t":"x"}', '{"op":"advance","t":NaN}',
                       '{"op":"advance","t":1e400}', '{"op":"advance","t":-1.0}',
                       '{"op":"probe","t":0.0}', '{"op":"welcome"}', '{"op":["end"]}',
                       '{"op":"report"}', "[1]", "not json", "[" * 30_000]
        to_master = ['{"op":"report","from":"b","round":1,"t":0.0,"seen":5}',
                     '{"op":"ready"}', '{"op":"bye","from":7}', '{"op":"advance","t":1}']
        for message in to_follower:
            raw.put(keys.time_to("Raptor", "b"), message.encode())
        for message in to_master:
            raw.put(keys.time_to("Raptor", "a"), message.encode())

        def refused(process: str) -> int:
            return int(raw.info(process)["bridge"]["rejected"].get("time-message", 0))

        await eventually(lambda: refused("b") == len(to_follower)
                         and refused("a") == len(to_master),
                         what="every malformed message counted")
        await time_moves_on(raw, "b")
    finally:
        raw.close()
    stop_together(a, b)
    assert a.result()["t"] == b.result()["t"]  # ended together


async def test_a_call_stamped_beyond_every_grant_is_refused_and_holds_nothing(
        peers: list[Peer]) -> None:
    """In lock-step a call says when it was made; a time that is not a time, or later
    than the time master's own, is refused at once: it neither waits forever in one of
    the MaxQueries places nor pulls virtual time after it."""
    from afa.polling import decode_error, encode_arguments

    a, b, port_a, _ = lockstep_pair()
    peers += [a, b]
    a.wait_ready()
    b.wait_ready()
    raw = RawPeer(connect=(port_a,))
    try:
        await eventually(lambda: "a" in raw.processes(), what="a seen")
        call = keys.poll("Raptor", "Counter", "getCount")
        payload = encode_arguments(Counter, "getCount", {})
        stamps = ["nan", "inf", "x"] + ["1e300"] * 70  # more than MaxQueries (64) at once
        pending = [raw.session.get(call, payload=payload, timeout=10,
                                   attachment=f"rogue\nz\n{stamp}".encode())
                   for stamp in stamps]
        errors = []
        for replies in pending:
            kind, data = answer(next(iter(replies)))
            assert kind == ERROR
            errors.append(decode_error(data))
        assert all(isinstance(e, EOutOfBounds) for e in errors[:3]), errors[:3]
        assert all(isinstance(e, EOutOfBounds | EDevIO) for e in errors)  # EDevIO: busy
        # no place stays held: a plain call is served again (bounded, not at once: on
        # the CI machine the first try was once refused, for a reason not recorded)
        refusals: list[BaseException] = []

        def served() -> bool:
            kind, data = answer(raw.get(call, payload)[0])
            if kind != RESULT:
                refusals.append(decode_error(data))
            return kind == RESULT

        await eventually(served, what=lambda: f"a plain call served (refused: {refusals[-3:]})")
        await time_moves_on(raw, "a")
    finally:
        raw.close()
    stop_together(a, b)


async def test_info_answers_share_one_document_until_names_change() -> None:
    """A flood of info queries costs one document a second (of real time), not one per
    query; a name that appears is in the next answer all the same (``afa names`` right
    after a start)."""
    clock = VirtualClock(start=0.0)
    system = System([CounterServer("counter")], clock=clock, process="b")
    bridge = Bridge(BridgeParameters(Listen=[endpoint(free_port())])).attach(system)
    documents: list[dict[str, Any]] = []

    class InfoQuery:  # what Zenoh hands the bridge for afa/Raptor/info/b
        key_expr = keys.info("Raptor", "b")

        def reply(self, key: str, payload: bytes, **options: Any) -> None:
            documents.append(json.loads(payload))

        def drop(self) -> None:
            pass

    async with system:
        await clock.advance(1.0)
        bridge._answer_info(InfoQuery())
        clock.step_wall(60.0)  # (no turn of the loop from here on: no second passes)
        bridge._answer_info(InfoQuery())
        system.registry.bind("Raptor/Extra", object())
        bridge._answer_info(InfoQuery())
    first, second, third = documents
    assert second == first  # the same document: not made again
    assert "Raptor/Extra" in {row["name"] for row in third["names"]}
    assert third["clock"]["now"] == first["clock"]["now"] + 60.0  # made again, now


def test_a_missing_zenoh_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "zenoh", None)
    with pytest.raises(ComponentError, match=r"pip install 'afa\[zenoh\]'"):
        Bridge(BridgeParameters())


def test_attachment_frames_are_what_the_protocol_says() -> None:
    """The attachment of an exported event: its export sequence number and process."""
    attachment = struct.pack("<Q", 7) + b"vehicle"
    assert struct.unpack_from("<Q", attachment)[0] == 7 and attachment[8:] == b"vehicle"
    assert wire.peek_type(wire.encode(Doubled(value=2))).endswith("Doubled@1")
