"""Components under supervision: lifecycle, start order and delays, restarts, names."""

import asyncio
from typing import Any

import pytest

from afa import (
    AfaError,
    Component,
    ComponentError,
    Fault,
    NameNotFound,
    PublishServerReactor,
    RealDeviceForbidden,
    RestartPolicy,
    Scan,
    SerialSpec,
    StartupError,
    State,
    StreamDecoder,
    SubscribePublishServer,
    System,
    TaskFailed,
    VirtualClock,
)
from afa.testing import FakeDevice, memory_pipe, serve, until
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
        self.out = self.publishes(event, Tick)
        self.serves(TickSource, name)

    async def setup(self):
        self.latest = self.slot("tick")

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
        self.subscribes(pattern, Tick, self.events.append, maxsize=1000)


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
        def __init__(self, name):
            super().__init__(name)
            self.subscribes("Tick", Tick, self.on_tick)

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


# -- the wave-2 framework: owned tasks, observers, lifecycle, devices, types --------------


class Poll(Interface):
    async def ping(self) -> Tick: ...


class PollOnly(SubscribePublishServer):
    """Answers polls; has no run body at all."""

    def __init__(self, name):
        super().__init__(name)
        self.serves(Poll, "PollOnly")

    async def ping(self):
        return Tick(n=7)


async def test_a_poll_only_component_stays_up_and_keeps_its_name():
    clock = VirtualClock(start=0.0)
    async with System([PollOnly("PollOnly")], clock=clock) as system:
        await clock.advance(30.0)
        assert system.components["PollOnly"].state is State.RUNNING
        assert "Raptor/PollOnly" in system.registry.list()
        assert (await system.proxy(Poll, "PollOnly").ping()).n == 7


async def test_an_observer_that_raises_never_fails_or_slows_the_publisher(caplog):
    clock = VirtualClock(start=0.0)
    ticker = Ticker("Ticker", "A")
    async with System([ticker], clock=clock) as system:
        def broken(event):
            raise RuntimeError("observer bug")

        observer = system.observe(broken, name="broken", maxsize=4)
        await clock.advance(2.0)
        stats = observer.statistics()
    assert ticker.failures == 0 and ticker.n >= 20
    assert stats["errors"] >= 20 and stats["delivered"] >= 20
    assert any("observer broken failed" in r.getMessage() for r in caplog.records)


async def test_an_observer_whose_callback_raises_cancelled_error_keeps_observing(caplog):
    """A CancelledError the callback raises (nobody cancelled the observer) is one more
    error, counted and logged: it does not end the observer silently."""
    clock = VirtualClock(start=0.0)
    seen = []

    def leaky(event):
        seen.append(event.body.n)
        if len(seen) == 3:
            raise asyncio.CancelledError

    async with System([Ticker("Ticker", "A")], clock=clock) as system:
        observer = system.observe(leaky, name="leaky")
        await clock.advance(2.0)
        stats = observer.statistics()
    assert stats["errors"] == 1 and len(seen) >= 20
    assert any("observer leaky failed" in r.getMessage() for r in caplog.records)


async def test_a_slow_observer_drops_and_counts_instead_of_slowing_anyone():
    clock = VirtualClock(start=0.0)
    ticker, recorder = Ticker("Ticker", "A"), Recorder("Recorder", "A")
    async with System([ticker, recorder], clock=clock) as system:
        async def slow(event):
            await clock.sleep(1.0)  # one event per second, ten arrive

        observer = system.observe(slow, name="slow", maxsize=2)
        await clock.advance(3.0)
        stats = observer.statistics()
    assert stats["dropped"] > 20
    assert len(recorder.events) >= 30  # the fast subscriber saw every tick


class CrashingFake(FakeDevice):
    name = "crasher"

    async def produce(self, stream):
        await self.clock.sleep(0.5)
        raise ZeroDivisionError("bug in the fake")


class Listener(PublishServerReactor[Any, int]):
    def device(self):
        return SerialSpec("/dev/ttyNONE", 9600)

    def decoder(self):
        class Nothing(StreamDecoder[int]):
            def scan(self, buffer):
                return Scan.skip(len(buffer), Fault.GARBAGE)

        return Nothing()

    def handle(self, message):
        pass


async def test_a_fake_device_whose_task_crashes_fails_the_system_with_its_name():
    clock = VirtualClock(start=0.0)
    fake = CrashingFake(clock)
    system = System([Listener("Listener")], clock=clock, devices={"Listener": fake.factory()})
    with pytest.raises(TaskFailed, match="fake crasher failed: ZeroDivisionError") as info:
        async with system:
            await system.run(5.0)
    assert info.value.owner == "fake crasher"
    assert clock.monotonic() == pytest.approx(0.5)  # run() ended at the failure


async def test_a_misspelled_device_key_is_an_error_listing_the_components():
    fake = FakeDevice(VirtualClock())
    with pytest.raises(ComponentError, match=r"'Listenr'.*the components are Listener"):
        System([Listener("Listener")], devices={"Listenr": fake.factory()})


async def test_real_devices_can_be_forbidden():
    system = System([Listener("Listener")], clock=VirtualClock(), real_devices=False)
    with pytest.raises(StartupError, match="real devices are forbidden"):
        async with system:
            pass
    # the suite forbids them for every system (afa's pytest plugin)
    assert System([Listener("Listener")]).real_devices is False
    from afa.transport import DeviceOpener

    with pytest.raises(RealDeviceForbidden, match="/dev/ttyNONE"):
        await DeviceOpener(allow_real=False).open("Listener", SerialSpec("/dev/ttyNONE", 9600))


async def test_a_body_of_the_wrong_type_is_counted_and_fails_the_subscriber():
    clock = VirtualClock(start=0.0)
    recorder = Recorder("Recorder", "A")
    async with System([recorder], clock=clock, restart_policy=RestartPolicy(initial=1.0)) \
            as system:
        system.channel.publish("Raptor", "A", Poll.methods["ping"].result_model(
            result=Tick(n=1)), origin="Impostor")
        await until(lambda: recorder.failures == 1, clock, timeout=1.0)
        assert "carries Poll.ping.result" in repr(recorder.last_error)
        assert "from Impostor" in str(recorder.last_error)
        assert recorder._inputs[0].rejected == 1
        assert recorder.events == []


async def test_a_handler_that_lets_cancelled_error_escape_fails_its_component():
    clock = VirtualClock(start=0.0)

    class Leaky(SubscribePublishServer):
        def __init__(self, name):
            super().__init__(name)
            self.subscribes("A", Tick, self.on_tick)
            self.seen = 0

        async def on_tick(self, event):
            self.seen += 1
            raise asyncio.CancelledError  # e.g. from a helper that was cancelled

    leaky, ticker = Leaky("Leaky"), Ticker("Ticker", "A")
    async with System([leaky, ticker], clock=clock):
        await until(lambda: leaky.failures >= 1, clock, timeout=2.0)
        await until(lambda: leaky.failures >= 2, clock, timeout=5.0)  # restarted, again
    assert "CancelledError without being cancelled" in str(leaky.last_error)


class _Abort(BaseException):
    """Not an Exception: what a handler might raise by mistake (or a library's own)."""


def _self_cancel():
    task = asyncio.current_task()
    assert task is not None
    task.cancel()  # the handler cancels its own delivery task


@pytest.mark.parametrize("ending", ["cancels its own task", "raises a BaseException"])
async def test_a_handler_that_ends_any_other_way_than_returning_fails_its_component(ending):
    """Issue 16, defect 5: the subscription must not die silently with the component
    left RUNNING and healthy; the component fails, is restarted and receives again."""
    clock = VirtualClock(start=0.0)

    class Leaky(SubscribePublishServer):
        def __init__(self, name):
            super().__init__(name)
            self.subscribes("A", Tick, self.on_tick)
            self.seen = 0

        async def on_tick(self, event):
            self.seen += 1
            if self.seen % 3 == 0:  # every third event
                if ending == "cancels its own task":
                    _self_cancel()
                    await asyncio.sleep(0)
                raise _Abort("handler gave up")

    leaky, ticker = Leaky("Leaky"), Ticker("Ticker", "A")
    async with System([leaky, ticker], clock=clock,
                      restart_policy=RestartPolicy(initial=0.1)):
        await until(lambda: leaky.failures >= 2, clock, timeout=5.0)
        assert leaky.restarts >= 1
        await until(lambda: leaky.seen >= 7, clock, timeout=5.0)  # receiving again
    assert isinstance(leaky.last_error, ComponentError)
    assert "the handler of 'A' raised" in str(leaky.last_error)


@pytest.mark.parametrize("where", ["run", "a spawned task"])
async def test_a_cancelled_error_from_the_components_own_code_fails_it(where):
    """Issue 16, defect 5, beyond handlers: run() or a task the component spawned that
    ends with a CancelledError nobody asked for (say, from awaiting a helper's cancelled
    future) fails the component, which is restarted: it is neither left STOPPING for
    good nor left RUNNING and healthy with its task gone."""
    clock = VirtualClock(start=0.0)

    class Quitter(SubscribePublishServer):
        def __init__(self, name):
            super().__init__(name)
            self.lives = 0

        async def run(self):
            self.lives += 1

            async def give_up():
                await self.clock.sleep(0.5)
                raise asyncio.CancelledError  # not cancelled by anyone

            if where == "run":
                await give_up()
            else:
                self.spawn(give_up(), "helper")

    quitter = Quitter("Quitter")
    async with System([quitter], clock=clock,
                      restart_policy=RestartPolicy(initial=0.1)) as system:
        await clock.advance(1.0)
        health = system.health()["Quitter"]
        assert quitter.failures >= 1 and quitter.restarts >= 1, health
        assert quitter.lives >= 2
    assert isinstance(quitter.last_error, ComponentError)
    assert "CancelledError without being cancelled" in str(quitter.last_error)


async def test_a_setup_that_raises_cancelled_error_fails_to_start():
    class Quitter(SubscribePublishServer):
        async def setup(self):
            raise asyncio.CancelledError  # not cancelled by anyone

    with pytest.raises(StartupError, match="raised CancelledError without being cancelled"):
        async with asyncio.timeout(60):  # (before: the start never ended)
            async with System([Quitter("Quitter")], clock=VirtualClock(start=0.0)):
                pass


async def test_a_server_that_stops_during_a_call_gives_its_caller_an_error():
    """A servant that awaits something its teardown cancels (an acknowledgement, say)
    hands the caller an afa error, not a CancelledError: the caller is not being
    cancelled, so a cancellation would now fail it (and used to end its task silently)."""
    clock = VirtualClock(start=0.0)

    class Slow(SubscribePublishServer):
        def __init__(self, name):
            super().__init__(name)
            self.serves(TickSource, name)
            self.pending: asyncio.Future[Tick] | None = None

        async def getTick(self):
            self.pending = asyncio.get_running_loop().create_future()
            return await self.pending  # answered by a device that never answers

        async def teardown(self):
            if self.pending is not None:
                self.pending.cancel()

    class Caller(SubscribePublishServer):
        def __init__(self, name):
            super().__init__(name)
            self.source = self.uses(TickSource, "Slow")
            self.errors: list[Exception] = []

        async def run(self):
            async def ask():
                await self.bound(self.source)
                try:
                    await self.source.getTick()
                except AfaError as exc:
                    self.errors.append(exc)

            self.spawn(ask(), "ask")

    slow, caller = Slow("Slow"), Caller("Caller")
    async with System([slow, caller], clock=clock) as system:
        await until(lambda: slow.pending is not None, clock, timeout=1.0)
        await system.stop_component("Slow")
        await until(lambda: caller.errors, clock, timeout=1.0)
        assert system.health()["Caller"].healthy and caller.failures == 0
    assert "Slow.getTick" in str(caller.errors[0])


async def test_stopping_a_component_whose_task_it_cancels_itself_is_no_failure():
    """A component may cancel a task it spawned (a helper it no longer needs): that is
    not a failure; neither is stopping the component while its tasks run."""
    clock = VirtualClock(start=0.0)

    class Tidy(SubscribePublishServer):
        async def run(self):
            helper = self.spawn(self.clock.sleep(100.0), "helper")
            await self.clock.sleep(0.5)
            helper.cancel()
            self.spawn(self.clock.sleep(100.0), "another")

    tidy = Tidy("Tidy")
    async with System([tidy], clock=clock) as system:
        await clock.advance(2.0)
        assert system.health()["Tidy"].healthy
        await system.stop_component("Tidy")
    assert tidy.failures == 0 and tidy.state is State.STOPPED


async def test_statistics_after_a_failed_setup_never_raise():
    clock = VirtualClock(start=0.0)

    class BadSetup(PublishServerReactor[Any, int]):
        def device(self):
            return SerialSpec("/dev/null", 9600)

        async def setup(self):
            raise ValueError("no model file")

    component = BadSetup("Bad")
    assert isinstance(component.statistics(), dict)  # before any start
    with pytest.raises(StartupError):
        async with System([component], clock=clock, devices={"Bad": serve(memory_pipe()[0])}):
            pass
    assert isinstance(component.statistics(), dict)


async def test_the_device_base_starts_its_reactor_without_help():
    clock = VirtualClock(start=0.0)
    host, device = memory_pipe("dev")

    class Quiet(Listener):
        async def setup(self):  # does not call super(): nothing to forget any more
            self.set_up = True

    component = Quiet("Quiet")
    async with System([component], clock=clock, devices={"Quiet": serve(host)}):
        device.write_nowait(b"xyz")
        await clock.advance(0.1)
        assert component.reactor is not None
        assert component.statistics()["bytes_in"] == 3


def test_components_are_typed_by_their_parameter_model():
    from components.gps_sokkia import GpsSokkia
    from components.gps_sokkia.parameters import GpsSokkiaParameters

    gps = GpsSokkia("Gps")
    assert GpsSokkia.parameters_type is GpsSokkiaParameters
    assert isinstance(gps.parameters, GpsSokkiaParameters)
    with pytest.raises(ComponentError, match="expected GpsSokkiaParameters"):
        GpsSokkia("Gps", Tick(n=1))  # type: ignore[arg-type]


async def test_a_components_log_messages_name_it_without_a_formatter(caplog):
    """In a notebook with no logging set up, Python prints a warning's message alone:
    a component's messages must say which component they are about (once)."""
    clock = VirtualClock(start=0.0)

    class Chatty(SubscribePublishServer):
        async def run(self):
            self.log.warning("no fix for %d s", 3)
            self.log.warning("%s: already named", self.name)
            self.log.info("the %s component is up", self.name)

    chatty = Chatty("Chatty")
    caplog.set_level("INFO", logger="afa.component.Chatty")
    async with System([chatty], clock=clock):
        await clock.advance(0.1)
    messages = [r.getMessage() for r in caplog.records if r.name == "afa.component.Chatty"]
    assert "Chatty: no fix for 3 s" in messages
    assert "Chatty: already named" in messages
    assert "the Chatty component is up" in messages
    assert all(m.count("Chatty") == 1 for m in messages), messages
