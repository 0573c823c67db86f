"""Lock-step virtual time across processes (decision 0011): a split system sees every
event and every poll at the virtual time one process would, the split ends cleanly and
together, and a member that is missing or dies stops the run loudly."""

from __future__ import annotations

import asyncio
import math

import pytest

from afa import EOutOfBounds, System
from afa.assembly import _global_start
from afa.bridge import Bridge, BridgeParameters
from afa.bridge.lockstep import SteppedClock, TimeFollower, TimeMaster
from afa.errors import ComponentError
from tests.bridge.conftest import Peer
from tests.bridge.parts import endpoint, free_port


async def test_a_stepped_clock_moves_only_when_granted() -> None:
    clock = SteppedClock(start=100.0)
    fired: list[tuple[str, float]] = []
    clock.call_at(2.0, lambda: fired.append(("b", clock.monotonic())))
    clock.call_at(1.0, lambda: fired.append(("a", clock.monotonic())))
    clock.call_at(1.0, lambda: fired.append(("a2", clock.monotonic())))
    await clock.settle()
    assert clock.monotonic() == 0.0 and fired == []  # idle is not a reason to move
    assert clock.next_deadline() == 1.0
    clock.grant(1.0)
    assert clock.now() == 101.0
    await clock.settle()  # the instant's timers fire one at a time (decision 0027)
    assert fired == [("a", 1.0), ("a2", 1.0)] and clock.now() == 101.0
    clock.grant(1.5)  # nothing due: time moves all the same
    assert clock.monotonic() == 1.5 and clock.next_deadline() == 2.0
    with pytest.raises(ComponentError, match="cannot go back"):
        clock.grant(1.0)
    with pytest.raises(ComponentError, match="cannot be resumed"):
        clock.resume()


async def test_a_call_made_ahead_of_a_follower_waits_for_its_grant_and_no_later() -> None:
    """A member's call can overtake the grant of its time (decision 0011). The follower
    waits for that grant without asking for the time (a timer would: every clock would
    be pulled to whatever a caller stamped), and refuses a call from beyond the time the
    next probe says the master has reached."""
    clock = SteppedClock(start=0.0)
    system = System([], clock=clock, process="b")
    follower = TimeFollower(Bridge(BridgeParameters()), system, "a")  # it sends nothing
    done: list[tuple[float, object]] = []

    async def call(moment: float) -> None:
        try:
            await follower.reach(moment)
            done.append((moment, clock.monotonic()))
        except EOutOfBounds as exc:
            done.append((moment, str(exc)))

    calls = [asyncio.ensure_future(call(t)) for t in (0.5, 1e300)]
    await clock.settle()
    assert done == [] and clock.next_deadline() is None  # no time asked for
    follower.handle({"op": "advance", "t": 0.5})
    await clock.settle()
    assert done == [(0.5, 0.5)]  # at the instant it was made at
    async with system:  # its task group runs the report
        follower.handle({"op": "probe", "round": 1, "t": 0.5})
        await asyncio.gather(*calls)
    assert done[1][0] == 1e300 and "granted more than t=0.5 s" in str(done[1][1])
    for moment in (math.nan, math.inf):
        with pytest.raises(EOutOfBounds):
            await follower.reach(moment)


async def test_the_master_refuses_a_call_made_later_than_its_own_time() -> None:
    """The master grants itself each instant before any member hears of it: a call
    stamped later than its clock was made at a time nobody was granted."""
    clock = SteppedClock(start=0.0)
    system = System([], clock=clock, process="a")
    master = TimeMaster(Bridge(BridgeParameters()), system, ["b"])
    clock.grant(2.0)
    await master.reach(1.5)
    await master.reach(2.0)
    for moment in (2.5, 1e300, math.inf, math.nan):
        with pytest.raises(EOutOfBounds, match="no process has been granted more than t=2.0"):
            await master.reach(moment)
    assert clock.next_deadline() is None


async def test_a_reply_stamped_beyond_every_grant_is_refused_not_held() -> None:
    """A reply may overtake the grant of the time it was made at, and then waits for it;
    a reply stamped at a time nobody was granted (a rogue or broken server) answers the
    call with EOutOfBounds instead of holding it until that virtual time."""
    import zenoh

    from afa.bridge import keys
    from afa.bridge.link import session_config
    from afa.bridge.remote import RESULT, RemoteCall, caller_attachment, reply_attachment
    from afa.polling import encode_result
    from idl import GlobalMap, PlanPointIDL

    clock = SteppedClock(start=0.0)
    master = TimeMaster(Bridge(BridgeParameters()), System([], clock=clock, process="a"),
                        ["b"])
    clock.grant(2.0)
    key = keys.poll("Raptor", "GlobalMap", "valid")
    stamp = [0.0]

    def reply(query: zenoh.Query) -> None:
        query.reply(key, encode_result(GlobalMap, "valid", True),
                    attachment=reply_attachment(RESULT, stamp[0]))

    with zenoh.open(session_config(BridgeParameters(), listen=[endpoint(free_port())])
                    ) as session:
        rogue = session.declare_queryable(key, reply)
        try:
            async def call() -> object:
                remote = RemoteCall(zenoh, session, "Raptor", "GlobalMap", GlobalMap,
                                    "valid", {"p": PlanPointIDL(x=1, y=2)},
                                    caller_attachment("a", "zid", clock.monotonic()),
                                    clock=clock, reach=master.reach)
                return await asyncio.wait_for(remote.result(), 30.0)

            for stamp[0] in (1.5, 2.0):  # made at a granted time: answered at once
                assert await call() is True
            for stamp[0] in (2.5, 1e300):
                with pytest.raises(EOutOfBounds, match="the reply is stamped t="):
                    await call()
        finally:
            rogue.undeclare()
    assert clock.next_deadline() is None  # nobody's time was asked for


def test_quiescence_needs_every_message_received() -> None:
    master = TimeMaster.__new__(TimeMaster)
    master.bridge = type("B", (), {"process": "m"})()  # type: ignore[assignment]

    def report(exported: int, seen: dict[str, int], qsent: dict[str, int] | None = None,
               qrecv: dict[str, int] | None = None) -> dict[str, object]:
        return {"exported": exported, "seen": seen, "qsent": qsent or {},
                "qrecv": qrecv or {}, "rsent": {}, "rrecv": {}}

    mine = report(5, {"f": 3})
    assert master._consistent(mine, {"f": report(3, {"m": 5})})
    assert not master._consistent(mine, {"f": report(3, {"m": 4})})  # an event in flight
    assert not master._consistent(mine, {"f": report(4, {"m": 5})})  # the other way
    asking = report(5, {"f": 3}, qsent={"f": 1})
    assert not master._consistent(asking, {"f": report(3, {"m": 5})})  # a call in flight
    assert master._consistent(asking, {"f": report(3, {"m": 5}, qrecv={"m": 1})})


def test_each_group_starts_its_components_when_the_whole_launcher_would() -> None:
    class C:
        def __init__(self, name: str) -> None:
            self.name = name

    everyone = [C(n) for n in ("gps", "imu", "model", "plan", "arbiter")]
    delays = {"gps": 0.5, "imu": 0.1, "model": 0.2, "plan": 0.0, "arbiter": 0.3}
    first, mine = _global_start(everyone, delays, ["imu", "arbiter"])  # type: ignore[arg-type]
    assert first == 0.5  # imu starts after gps's dT
    # imu -> arbiter: imu's, model's and plan's dT; arbiter waits to the whole Launcher's end
    assert mine == pytest.approx({"imu": 0.3, "arbiter": 0.3})
    assert first + sum(mine.values()) == pytest.approx(sum(delays.values()))


def run(role: str, process: str, *extra: str) -> Peer:
    return Peer(["-m", "tests.bridge.peer", role, "--process", process, *extra])


def test_a_split_system_sees_everything_when_one_process_would(peers: list[Peer]) -> None:
    one = run("all", "main", "--clock", "virtual", "--duration", "6")
    peers.append(one)
    port = free_port()
    a = run("ls-a", "a", "--clock", "stepped", "--members", "a,b", "--listen", endpoint(port),
            "--duration", "6")
    b = run("ls-b", "b", "--clock", "stepped", "--members", "a,b", "--connect", endpoint(port))
    peers += [a, b]
    assert one.wait() == 0 and a.wait() == 0 and b.wait() == 0, a.errors + b.errors
    alone, master, follower = one.result(), a.result(), b.result()
    # the same virtual times, values and order, whichever process each part ran in
    assert follower["doubler.seen"] == [[t, v, s, "a/counter"] for t, v, s, _ in
                                        alone["doubler.seen"]]
    assert follower["poller.polled"] == alone["poller.polled"]  # getWait polls across
    assert master["sink.doubled"] == [[t, v, "b/doubler"] for t, v, _ in
                                      alone["sink.doubled"]]
    assert master["t"] == follower["t"] == alone["t"] == 6.0  # ended together, at 6 s
    stats = master["bridge"]["lockstep"]
    assert stats["role"] == "master" and stats["grants"] > 0


def test_a_missing_member_fails_the_start_with_a_message(peers: list[Peer]) -> None:
    a = run("ls-a", "a", "--clock", "stepped", "--members", "a,b", "--listen",
            endpoint(free_port()), "--duration", "5", "--join-timeout", "1")
    peers.append(a)
    assert a.wait() != 0
    assert any("did not join within 1 s" in line for line in a.errors), a.errors


def test_a_member_that_dies_stops_the_run_loudly(peers: list[Peer]) -> None:
    port = free_port()
    a = run("ls-a", "a", "--clock", "stepped", "--members", "a,b", "--listen", endpoint(port),
            "--duration", "100000")
    b = run("ls-b", "b", "--clock", "stepped", "--members", "a,b", "--connect", endpoint(port))
    peers += [a, b]
    a.wait_ready()
    b.wait_ready()
    b.kill()
    assert a.wait() != 0
    assert any("process b went away" in line for line in a.errors), a.errors


async def test_a_call_taken_off_the_inbox_wakes_a_process_waiting_to_be_idle() -> None:
    """A query that arrives just after a member's idleness check is served by a call that
    may wait for a later instant (``getWait…``); taking it off the inbox must wake the
    member, or it never reports idle, that instant is never granted, and the split run
    stalls (what hung the test above under load)."""
    from afa.bridge.link import Inbox

    bridge = Bridge(BridgeParameters())
    bridge._queries = Inbox(asyncio.get_running_loop(), 8)
    served: list[object] = []
    bridge._spawn_query = served.append  # type: ignore[method-assign]  # the call runs on
    serving = asyncio.ensure_future(bridge._serve_queries())
    try:
        await asyncio.sleep(0)  # the server waits for its inbox
        bridge.changed.clear()
        bridge._queries.push(("poll", "a getWait call"))
        assert not bridge.idle()  # waiting in the inbox
        for _ in range(3):  # the wake-up, then the server's turn
            await asyncio.sleep(0)
        assert served == ["a getWait call"] and bridge.idle()
        assert bridge.changed.is_set()
    finally:
        serving.cancel()
