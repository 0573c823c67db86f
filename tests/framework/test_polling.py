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
    Servant,
    VirtualClock,
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
    server = SensorServer(clock)
    proxy = proxy_for(Sensor, Servant(Sensor, server, name="Raptor/Sensor"), clock, **kw)
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


def test_a_proxy_for_the_wrong_interface_is_refused():
    clock = VirtualClock()
    servant = Servant(Sensor, SensorServer(clock))
    with pytest.raises(InterfaceError):
        proxy_for(Other, servant, clock)
