"""Polled interfaces: typed proxies, errors, per-call timeouts, get/getWait slots."""

import asyncio

import pytest

from afa import (
    ComponentError,
    EDevIO,
    EOutOfBounds,
    ETimeOut,
    InterfaceError,
    LatestSlot,
    LocalInvoker,
    NameNotFound,
    NameRegistry,
    PollLayer,
    Servant,
    SubscribePublishServer,
    System,
    VirtualClock,
    polling,
    proxy_for,
)
from idl._base import IDLModel, Interface, field


class Reading(IDLModel):
    value: float = field(0.0, unit="m")


class Sensor(Interface):
    wait_timeout = 0.5

    async def getReading(self) -> Reading:
        """Latest reading."""

    async def getWaitReading(self) -> Reading:
        """Next reading."""

    async def setGain(self, gain: float) -> bool:
        """Set the gain."""


class Other(Interface):
    async def ping(self) -> None: ...


class SensorServer:
    def __init__(self, clock):
        self.slot = LatestSlot(clock, "reading")
        self.gain = 1.0
        self.hang = False

    async def getReading(self):
        return self.slot.get()

    async def getWaitReading(self):
        return await self.slot.wait_next(Sensor.wait_timeout)

    async def setGain(self, gain):
        if gain <= 0:
            raise EOutOfBounds(f"gain must be positive, got {gain}")
        if self.hang:
            await asyncio.Event().wait()
        if gain > 100:
            return "not a bool"
        if gain == 13:
            raise ZeroDivisionError("bug")
        self.gain = gain
        return True

    async def helper(self):  # not part of the interface
        return 1


def make(clock, **kw):
    """A server bound at Raptor/Sensor and a proxy through the standard middleware."""
    server = SensorServer(clock)
    registry = NameRegistry(clock)
    registry.bind("Raptor/Sensor", Servant(Sensor, server, name="Raptor/Sensor"))
    layer = PollLayer(clock)
    proxy = proxy_for(Sensor, LocalInvoker(registry, "Raptor/Sensor", Sensor),
                      middleware=layer.middleware, **kw)
    return server, proxy


async def test_proxy_exposes_exactly_the_interface_methods():
    _, proxy = make(VirtualClock())
    public = {n for n in dir(proxy) if not n.startswith("_") and n != "interface"}
    assert public == {"getReading", "getWaitReading", "setGain"}
    assert not hasattr(proxy, "helper")


async def test_get_returns_the_latest_and_fails_before_any_sample():
    clock = VirtualClock()
    server, proxy = make(clock)
    with pytest.raises(EDevIO):
        await proxy.getReading()
    server.slot.set(Reading(value=1.0))
    server.slot.set(Reading(value=2.0))
    assert (await proxy.getReading()).value == 2.0


async def test_get_wait_returns_the_next_new_sample_not_the_current_one():
    clock = VirtualClock(start=0.0)
    server, proxy = make(clock)
    server.slot.set(Reading(value=1.0))

    async def produce():
        await clock.sleep(0.2)
        server.slot.set(Reading(value=5.0))

    producer = asyncio.get_running_loop().create_task(produce())
    assert (await proxy.getWaitReading()).value == 5.0
    assert clock.now() == pytest.approx(0.2)
    await producer


async def test_a_lazy_sample_is_built_once_when_read_and_at_once_for_a_waiter():
    clock = VirtualClock(start=0.0)
    server, proxy = make(clock)
    built: list[float] = []

    def sample(value: float):
        def make_it():
            built.append(value)
            return Reading(value=value)
        return make_it

    server.slot.set_lazy(sample(1.0))
    server.slot.set_lazy(sample(2.0))  # replaces the first, which is never built
    assert built == [] and server.slot.version == 2
    assert (await proxy.getReading()).value == 2.0
    assert (await proxy.getReading()).value == 2.0
    assert built == [2.0]  # built once
    server.slot.set(Reading(value=3.0))  # a plain sample after a lazy one
    assert (await proxy.getReading()).value == 3.0

    async def produce():
        await clock.sleep(0.2)
        server.slot.set_lazy(sample(5.0))  # a caller waits: built now

    producer = asyncio.get_running_loop().create_task(produce())
    assert (await proxy.getWaitReading()).value == 5.0
    assert built == [2.0, 5.0]
    await producer


async def test_get_wait_times_out_with_etimeout():
    clock = VirtualClock(start=0.0)
    _, proxy = make(clock)
    with pytest.raises(ETimeOut):
        await proxy.getWaitReading()
    assert clock.now() == pytest.approx(0.5)


async def test_arguments_and_results_are_checked_against_the_idl():
    clock = VirtualClock()
    server, proxy = make(clock)
    assert await proxy.setGain(2) is True and server.gain == 2.0  # int coerced to float
    with pytest.raises(InterfaceError):
        await proxy.setGain("loud")
    with pytest.raises(InterfaceError):
        await proxy.setGain()
    with pytest.raises(InterfaceError):
        await proxy.setGain(1.0, 2.0)
    with pytest.raises(InterfaceError, match="bad result"):
        await proxy.setGain(200.0)


async def test_server_errors_reach_the_client_as_afa_errors():
    clock = VirtualClock()
    _, proxy = make(clock)
    with pytest.raises(EOutOfBounds):
        await proxy.setGain(-1.0)
    with pytest.raises(ComponentError) as info:
        await proxy.setGain(13.0)
    assert isinstance(info.value.__cause__, ZeroDivisionError)


async def test_per_call_timeout():
    clock = VirtualClock(start=0.0)
    server, proxy = make(clock, timeout=3.0)
    server.hang = True
    with pytest.raises(ETimeOut, match="Raptor/Sensor.setGain"):
        await proxy.setGain(1.0)
    assert clock.now() == pytest.approx(3.0)


def test_a_servant_must_implement_every_method():
    with pytest.raises(ComponentError, match="getWaitReading"):
        class Half:
            async def getReading(self):
                return Reading()

            async def setGain(self, gain):
                return True

        Servant(Sensor, Half())


async def test_a_proxy_for_the_wrong_interface_is_refused():
    clock = VirtualClock()
    registry = NameRegistry(clock)
    registry.bind("Raptor/Sensor", Servant(Sensor, SensorServer(clock)))
    with pytest.raises(InterfaceError):
        proxy_for(Other, LocalInvoker(registry, "Raptor/Sensor", Sensor))
    proxy = proxy_for(Other, LocalInvoker(registry, "Raptor/Sensor", Other))
    with pytest.raises(InterfaceError, match="serves Sensor, not Other"):
        await proxy.ping()


# -- polls ready for a network (the invoker seam, names, middleware, wire form) -----------


class SensorComponent(SubscribePublishServer):
    def __init__(self, name):
        super().__init__(name)
        self.serves(Sensor, "Sensor")
        self.reading = 0.0

    async def setup(self):
        self.latest = self.slot("reading")
        self.latest.set(Reading(value=self.reading))

    async def getReading(self):
        return self.latest.get()

    async def getWaitReading(self):
        return await self.latest.wait_next(Sensor.wait_timeout)

    async def setGain(self, gain):
        return True


async def test_an_old_proxy_never_returns_a_stopped_servers_data_and_follows_a_restart():
    clock = VirtualClock(start=0.0)
    server = SensorComponent("SensorServer")
    server.reading = 1.0
    async with System([server], clock=clock) as system:
        proxy = await system.resolve(Sensor, "Sensor")
        assert (await proxy.getReading()).value == 1.0
        await system.stop_component("SensorServer")
        with pytest.raises(NameNotFound, match="not running"):
            await proxy.getReading()
        server.reading = 2.0
        await system.start_component("SensorServer")
        assert (await proxy.getReading()).value == 2.0  # the same proxy, the new servant


def test_binding_checks_every_signature_and_names_the_mismatch():
    class Misnamed:
        async def getReading(self):
            return Reading()

        async def getWaitReading(self):
            return Reading()

        async def setGain(self, level):  # the interface says gain
            return True

    with pytest.raises(ComponentError, match=r"setGain\(level\) does not match .*setGain\(gain\)"):
        Servant(Sensor, Misnamed())

    class NotAsync(Misnamed):
        def setGain(self, gain):  # type: ignore[override]
            return True

    with pytest.raises(ComponentError, match="setGain is not an async method"):
        Servant(Sensor, NotAsync())

    class ExtraRequired(Misnamed):
        async def setGain(self, gain, why):  # type: ignore[override]
            return True

    with pytest.raises(ComponentError, match="setGain"):
        Servant(Sensor, ExtraRequired())

    class Wrong(SubscribePublishServer):
        def __init__(self, name):
            super().__init__(name)
            self.serves(Sensor, "Sensor")  # checked at declaration, before anything runs

        async def getReading(self, which):
            return Reading()

    with pytest.raises(ComponentError, match="getReading"):
        Wrong("W")


async def test_another_transport_sits_under_the_same_proxy():
    """An invoker that carries the call through the wire form, as a bridge would."""
    clock = VirtualClock()
    server = SensorServer(clock)
    servant = Servant(Sensor, server)
    frames = []

    class WireInvoker:
        interface, name = Sensor, "remote/Sensor"

        async def invoke(self, method, arguments):
            request = polling.encode_arguments(Sensor, method, arguments)
            frames.append(request)
            try:
                result = await servant.invoke(method, polling.decode_arguments(
                    Sensor, method, request))
            except Exception as exc:
                raise polling.decode_error(polling.encode_error(exc)) from None
            return polling.decode_result(Sensor, method,
                                         polling.encode_result(Sensor, method, result))

    proxy = proxy_for(Sensor, WireInvoker())
    assert await proxy.setGain(3) is True and server.gain == 3.0
    assert frames and frames[0].startswith(b"AFW1")
    server.slot.set(Reading(value=4.5))
    assert await proxy.getReading() == Reading(value=4.5)
    with pytest.raises(EOutOfBounds, match="gain must be positive"):  # the same class back
        await proxy.setGain(-1.0)
    with pytest.raises(ComponentError, match="ZeroDivisionError"):
        await proxy.setGain(13.0)


def test_errors_travel_as_their_own_afa_class_and_nothing_else_is_instantiated():
    for error in (EOutOfBounds("x"), ETimeOut("y"), EDevIO("z"), NameNotFound("n")):
        again = polling.decode_error(polling.encode_error(error))
        assert type(again) is type(error) and str(again) == str(error)
    assert type(polling.decode_error(polling.encode_error(KeyError("k")))) is ComponentError
    forged = polling.encode_error(EDevIO("x")).replace(b'"EDevIO"', b'"SystemExit"')
    assert type(polling.decode_error(forged)) is ComponentError
    with pytest.raises(InterfaceError):
        polling.decode_arguments(Sensor, "setGain", polling.encode_arguments(
            Sensor, "getReading", {}))


async def test_middleware_counts_calls_errors_and_latency_and_hooks_record_calls():
    clock = VirtualClock(start=0.0)
    server = SensorServer(clock)
    registry = NameRegistry(clock)
    registry.bind("Raptor/Sensor", Servant(Sensor, server))
    layer = PollLayer(clock)
    records = []
    layer.add_hook(records.append)
    layer.add_hook(lambda record: 1 / 0)  # a broken hook never fails the call
    proxy = proxy_for(Sensor, LocalInvoker(registry, "Raptor/Sensor", Sensor),
                      middleware=layer.middleware)

    async def produce():
        await clock.sleep(0.25)
        server.slot.set(Reading(value=1.0))

    producer = asyncio.get_running_loop().create_task(produce())
    await proxy.getWaitReading()
    await producer
    await proxy.setGain(2.0)
    with pytest.raises(EOutOfBounds):
        await proxy.setGain(-2.0)
    stats = layer.statistics
    assert stats[("Raptor/Sensor", "getWaitReading")].as_dict() == {
        "calls": 1, "errors": 0, "mean_s": pytest.approx(0.25), "max_s": pytest.approx(0.25)}
    assert stats[("Raptor/Sensor", "setGain")].calls == 2
    assert stats[("Raptor/Sensor", "setGain")].errors == 1
    assert [(r.method, r.arguments, r.result) for r in records[:2]] == [
        ("getWaitReading", {}, Reading(value=1.0)), ("setGain", {"gain": 2.0}, True)]
    assert isinstance(records[2].error, EOutOfBounds)


class SensorHost(SubscribePublishServer):
    """A component serving a SensorServer's Sensor interface under "Sensor"."""

    def __init__(self, name, server):
        super().__init__(name)
        self.serves(Sensor, "Sensor", impl=server)


async def test_a_recording_hook_hears_which_component_made_the_call():
    class Poller(SubscribePublishServer):
        def __init__(self, name):
            super().__init__(name)
            self.sensor = self.uses(Sensor, "Sensor")

        async def run(self):
            await self.bound(self.sensor)
            await self.sensor.setGain(2.0)

    clock = VirtualClock(start=0.0)
    server = SensorServer(clock)

    system = System([SensorHost("Host", server), Poller("A"), Poller("B")], clock=clock)
    records = []
    system.polls.add_hook(records.append)
    async with system:
        await clock.advance(0.1)
        await system.proxy(Sensor, "Sensor").setGain(3.0)  # outside any component
    assert sorted(r.caller for r in records) == ["", "A", "B"]


async def test_a_poll_record_carries_the_last_event_sequence_when_the_call_was_made():
    """Where a call stands among the events of its instant (decision 0027): the event
    channel's last sequence number at the call's start."""
    clock = VirtualClock(start=0.0)
    server = SensorServer(clock)

    system = System([SensorHost("Host", server)], clock=clock)
    records = []
    system.polls.add_hook(records.append)
    async with system:
        proxy = system.proxy(Sensor, "Sensor")
        before = system.channel.published
        await proxy.setGain(1.0)
        for _ in range(3):
            system.channel.publish("Robot", "Reading", Reading(value=1.0))
        await proxy.setGain(2.0)
    assert [r.seq for r in records] == [before, before + 3]
    assert PollLayer(clock).sequence is None  # a bare layer: no channel, seq -1
