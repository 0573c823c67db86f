"""Components under supervision: lifecycle, start order and delays, restarts, names."""

import pytest

from afa import (
    Component,
    NameNotFound,
    RestartPolicy,
    StartupError,
    State,
    SubscribePublishServer,
    System,
    VirtualClock,
)
from afa.testing import until
from idl._base import IDLModel, Interface, field


class Tick(IDLModel):
    n: int = field(0, unit="1")


class TickSource(Interface):
    async def getTick(self) -> Tick: ...


class Ticker(SubscribePublishServer):
    """Publishes a Tick every 0.1 s; fails once at tick ``fail_at`` if set."""

    def __init__(self, name, event="Tick", fail_at=None):
        super().__init__(name)
        self.event, self.fail_at, self.n = event, fail_at, 0

    async def setup(self):
        self.out = self.publisher(self.event)
        self.latest = self.slot("tick")
        self.serve(TickSource, self.name)

    async def run(self):
        async for _ in self.clock.periodic(0.1):
            self.n += 1
            body = Tick(n=self.n)
            self.latest.set(body)
            self.out.publish(body)
            if self.n == self.fail_at:
                raise RuntimeError(f"{self.name} broke at {self.n}")

    async def getTick(self):
        return self.latest.get()


class Recorder(SubscribePublishServer):
    def __init__(self, name, pattern="*"):
        super().__init__(name)
        self.pattern, self.events = pattern, []

    async def setup(self):
        self.subscribe(self.pattern, self.events.append, maxsize=1000)


async def test_a_failing_component_is_restarted_while_the_others_keep_publishing(caplog):
    clock = VirtualClock(start=0.0)
    steady = Ticker("Steady", "A")
    flaky = Ticker("Flaky", "B", fail_at=5)
    recorder = Recorder("Recorder")
    policy = RestartPolicy(initial=1.0)
    async with System([recorder, steady, flaky], clock=clock, restart_policy=policy) as system:
        await clock.advance(3.0)
        health = system.health()
    assert health["Flaky"].failures == 1 and health["Flaky"].restarts == 1
    assert health["Flaky"].state is State.RUNNING
    assert "Flaky broke at 5" in health["Flaky"].last_error
    assert health["Steady"].failures == 0
    a_times = [round(e.time, 6) for e in recorder.events if e.type == "A"]
    # Steady never missed a tick while Flaky was failing and restarting.
    assert a_times == [round(0.1 * k, 6) for k in range(0, 31)]
    b_times = [e.time for e in recorder.events if e.type == "B"]
    assert not any(0.45 < t < 1.4 for t in b_times)  # Flaky was down for its backoff
    assert any("component Flaky failed" in r.getMessage() for r in caplog.records)


async def test_names_are_unbound_when_the_server_stops_and_rebound_on_restart():
    clock = VirtualClock(start=0.0)
    ticker = Ticker("Ticker")
    async with System([ticker], clock=clock) as system:
        assert "Raptor/Ticker" in system.registry.list()
        assert "Raptor/EventChannel" in system.registry.list()
        await system.stop_component("Ticker")
        assert ticker.state is State.STOPPED
        with pytest.raises(NameNotFound):
            system.registry.resolve("Raptor/Ticker")
        await system.start_component("Ticker")
        proxy = await system.resolve(TickSource, "Ticker", timeout=1.0)
        await clock.advance(0.5)
        assert (await proxy.getTick()).n >= 1
    assert system.registry.list() == []


async def test_start_order_and_start_delays():
    clock = VirtualClock(start=0.0)
    started = []

    class Noting(Component):
        async def setup(self):
            started.append((self.name, self.clock.now()))

    system = System([Noting("a"), Noting("b"), Noting("c")], clock=clock,
                    start_delays={"a": 3.0, "b": 1.0})
    async with system:
        pass
    assert started == [("a", 0.0), ("b", 3.0), ("c", 4.0)]


async def test_startup_errors_are_gathered_and_name_every_failed_component():
    clock = VirtualClock(start=0.0)

    class Broken(Component):
        async def setup(self):
            raise ValueError(f"{self.name} has no device")

    fine = Ticker("Fine")
    system = System([Broken("x"), fine, Broken("y")], clock=clock)
    with pytest.raises(StartupError) as info:
        async with system:
            pass
    assert set(info.value.failures) == {"x", "y"}
    assert "x: ValueError: x has no device" in str(info.value)
    assert fine.state is State.STOPPED  # started ones were stopped again


async def test_restart_policy_gives_up_after_max_restarts():
    clock = VirtualClock(start=0.0)

    class AlwaysFails(Component):
        async def run(self):
            await self.clock.sleep(1.0)
            raise RuntimeError("again")

    component = AlwaysFails("bad")
    policy = RestartPolicy(initial=0.5, max_restarts=2)
    async with System([component], clock=clock, restart_policy=policy):
        await clock.advance(60.0)
        assert component.state is State.FAILED
        assert component.failures == 3 and component.restarts == 2


async def test_a_handler_exception_fails_its_component_only():
    clock = VirtualClock(start=0.0)

    class Picky(SubscribePublishServer):
        async def setup(self):
            self.subscribe("Tick", self.on_tick)

        def on_tick(self, event):
            if event.body.n == 3:
                raise KeyError("three")

    picky, ticker = Picky("Picky"), Ticker("Ticker", "Tick")
    async with System([picky, ticker], clock=clock) as system:
        await until(lambda: picky.failures == 1, clock, timeout=5.0)
        await until(lambda: picky.state is State.RUNNING, clock, timeout=5.0)
        assert ticker.failures == 0 and ticker.state is State.RUNNING
        assert system.health()["Picky"].last_error == "KeyError('three')"


async def test_component_spawn_outside_its_life_is_an_error():
    from afa import ComponentError

    component = Component("idle")

    async def nothing():
        pass

    with pytest.raises(ComponentError):
        component.spawn(nothing())


async def test_two_runs_with_the_same_inputs_give_identical_event_sequences():
    async def one_run():
        clock = VirtualClock(start=100.0)
        recorder = Recorder("Recorder")
        components = [recorder, Ticker("T1", "A"), Ticker("T2", "B", fail_at=7),
                      Ticker("T3", "C")]
        async with System(components, clock=clock):
            await clock.advance(5.0)
        return [(e.seq, e.type, e.time, e.body.n) for e in recorder.events]

    first, second = await one_run(), await one_run()
    assert len(first) > 100
    assert first == second


async def test_statistics_count_events_per_type():
    clock = VirtualClock(start=0.0)
    async with System([Ticker("T", "A"), Recorder("R", "A")], clock=clock) as system:
        await clock.advance(1.0)
        stats = system.statistics()
    assert stats["events"]["A"] == 11
    assert stats["events_dropped"] == 0
