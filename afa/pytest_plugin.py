"""afa's pytest plugin (loaded automatically once afa is installed: entry point
``pytest11``). For test suites that use afa's components, fakes and clocks:

- every ``async def`` test runs inside an :class:`afa.tasks.TaskGroup` (fixture
  ``afa_tasks``), so fake devices used without a System have an owner, and a fake whose
  task fails fails the test at teardown instead of vanishing into a log line;
- real devices are forbidden (``AFA_FORBID_REAL_DEVICES=1``) unless pytest runs with
  ``--afa-real-devices`` (hardware-in-the-loop runs): a mistyped device key then raises
  instead of writing to ``/dev/tty*``;
- fixture ``virtual_clock``: a :class:`~afa.clock.VirtualClock` (``monotonic()`` from 0,
  stamps from 2005-09-17);
- fixture ``afa_system``: a factory, ``afa_system(config, only=[...], devices={...})``,
  of systems built from a configuration file on ``virtual_clock`` (not started: the test
  starts it with ``async with``); real devices are off, so every device component
  needs a fake under its component name in ``devices``.

The user's guide is docs/testing.md (asyncio mode, fakes, device keys, configured
parameters).
"""

from __future__ import annotations

import inspect
import os
from collections.abc import AsyncIterator, Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import pytest

from afa.clock import VirtualClock
from afa.system import FORBID_REAL_DEVICES, System
from afa.tasks import TaskGroup
from afa.transport import DeviceFactory


def pytest_addoption(parser: Any) -> None:
    parser.addoption("--afa-real-devices", action="store_true", default=False,
                     help="allow afa systems to open real serial ports and sockets")


def pytest_configure(config: Any) -> None:
    if not config.getoption("--afa-real-devices", default=False):
        os.environ[FORBID_REAL_DEVICES] = "1"


def pytest_collection_modifyitems(items: list[Any]) -> None:
    for item in items:
        function = getattr(item, "function", None)
        if function is not None and inspect.iscoroutinefunction(function):
            fixtures = getattr(item, "fixturenames", None)
            if fixtures is not None and "afa_tasks" not in fixtures:
                fixtures.insert(0, "afa_tasks")


@pytest.fixture
async def afa_tasks() -> AsyncIterator[TaskGroup]:
    """A task group for the test; its failures fail the test."""
    async with TaskGroup("test") as group:
        yield group


@pytest.fixture
def virtual_clock() -> VirtualClock:
    """Virtual time: deterministic, instant; ``monotonic()`` from 0, time stamps from
    afa's default epoch (2005-09-17, a date every fake can encode: GPS time begins in
    1980)."""
    return VirtualClock()


#: What the ``afa_system`` fixture returns: ``make(config, *, only=None, devices=None,
#: **options)`` -> System.
SystemFactory = Callable[..., System]


@pytest.fixture
def afa_system(virtual_clock: VirtualClock) -> SystemFactory:
    """Build a :class:`~afa.system.System` from a Miro XML configuration on the test's
    ``virtual_clock``: ``afa_system(config, only=["GpsSokkiaService"],
    devices={"GpsSokkiaService": fake.factory()})``. ``only`` keeps the named Launcher
    entries, with their configured parameters; ``devices`` maps component names to fake
    device factories; other ``options`` go to :meth:`System.from_xml`. Real devices
    are off unless ``real_devices=True`` is passed."""

    def make(config: str | Path, *, only: Iterable[str] | None = None,
             devices: Mapping[str, DeviceFactory] | None = None, **options: Any) -> System:
        options.setdefault("clock", virtual_clock)
        options.setdefault("real_devices", False)
        return System.from_xml(config, only=None if only is None else list(only),
                               devices=devices, **options)

    return make
