"""The name registry: bind, rebind, unbind, resolve, wait, owners."""

import asyncio

import pytest

from afa import ETimeOut, NameAlreadyBound, NameNotFound, NameRegistry, VirtualClock
from afa.naming import join_name


def test_bind_resolve_unbind():
    registry = NameRegistry()
    registry.bind("Raptor/Gps", "gps")
    assert registry.resolve("Raptor/Gps") == "gps"
    assert registry.try_resolve("Raptor/Imu") is None
    with pytest.raises(NameAlreadyBound):
        registry.bind("Raptor/Gps", "other")
    registry.rebind("Raptor/Gps", "new")
    assert registry.resolve("Raptor/Gps") == "new"
    registry.unbind("Raptor/Gps")
    with pytest.raises(NameNotFound):
        registry.resolve("Raptor/Gps")
    with pytest.raises(LookupError):  # NameNotFound is a LookupError too
        registry.unbind("Raptor/Gps")


def test_names_must_have_robot_and_name():
    registry = NameRegistry()
    for bad in ("Gps", "Raptor/", "/Gps", "a/b/c"):
        with pytest.raises(ValueError):
            registry.bind(bad, 1)
    assert join_name("Raptor", "Gps") == "Raptor/Gps"
    assert join_name("Raptor", "Other/Gps") == "Other/Gps"


def test_list_and_owner_unbinding():
    registry = NameRegistry()
    owner_a, owner_b = object(), object()
    registry.bind("Raptor/Laser11", 1, owner=owner_a)
    registry.bind("Raptor/Laser12", 2, owner=owner_a)
    registry.bind("Raptor/Gps", 3, owner=owner_b)
    registry.bind("Other/Gps", 4)
    assert registry.list("Raptor/") == ["Raptor/Gps", "Raptor/Laser11", "Raptor/Laser12"]
    assert registry.unbind_owner(owner_a) == ["Raptor/Laser11", "Raptor/Laser12"]
    assert registry.list() == ["Other/Gps", "Raptor/Gps"]


async def test_wait_resolve_returns_when_the_name_is_bound_later():
    clock = VirtualClock(start=0.0)
    registry = NameRegistry(clock)

    async def bind_later():
        await clock.sleep(3.0)
        registry.bind("Raptor/ModelServer", "model")

    binder = asyncio.get_running_loop().create_task(bind_later())
    assert await registry.wait_resolve("Raptor/ModelServer", timeout=10.0) == "model"
    assert clock.now() == 3.0
    await binder


async def test_wait_resolve_times_out():
    clock = VirtualClock(start=0.0)
    registry = NameRegistry(clock)
    with pytest.raises(ETimeOut):
        await registry.wait_resolve("Raptor/Nobody", timeout=2.0)
    assert clock.now() == 2.0
    assert registry._waiters == {}  # no leaked waiter
