"""The Launcher's component table (seed §4.4.3, Figure 19) for one process.

The seed's Launcher showed each process's state, PID, %CPU and memory from ``ps``. Here
every component shares one process and one event loop, so the columns become:

- **state, health, restarts, failures, last error**: :meth:`afa.system.System.health`;
- **dT**: the start delay of the Launcher entry (``System.start_delays``);
- **events in**: events delivered to the component's subscriptions; **events out**:
  events it published, counted by the console's observer from each event's *origin*;
- **loop share**: the fraction of wall time the event loop spent running the
  component's tasks (:class:`LoopProfiler`);
- **memory**: an estimate of what the component holds (:func:`retained_bytes`); the
  process's resident size is shown once, in the status bar.
"""

from __future__ import annotations

import asyncio
import contextvars
import math
import sys
from collections import defaultdict, deque
from collections.abc import Callable, Coroutine, Generator, Iterable
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel

from afa.clock import Clock
from afa.component import Component
from afa.events import EventChannel
from afa.naming import NameRegistry
from afa.polling import Proxy

__all__ = ["LoopProfiler", "retained_bytes", "component_rows", "process_memory",
           "CONSOLE_TASK"]

#: Set in the context of the console's own tasks and of the web server's connection
#: tasks (they inherit it), so the profiler can tell them from anonymous tasks.
CONSOLE_TASK: contextvars.ContextVar[bool] = contextvars.ContextVar("afa_console_task",
                                                                     default=False)
_SUPERVISOR = "afa-supervisor:"


class _TimedCoroutine:
    """Wraps a task's coroutine and times each step (``send``/``throw``) it runs.

    A task runs its coroutine in steps, one per wake-up; the time a step takes is the
    loop time the task used. Awaited coroutines run inside the step, so a poll's servant
    time is charged to the caller's task.
    """

    __slots__ = ("_coro", "_profiler", "_key", "task", "__weakref__")

    def __init__(self, coro: Coroutine[Any, Any, Any], profiler: LoopProfiler) -> None:
        self._coro = coro
        self._profiler = profiler
        self._key: str | None = None
        self.task: asyncio.Task[Any] | None = None

    def send(self, value: Any) -> Any:
        profiler = self._profiler
        start = profiler.now()
        try:
            return self._coro.send(value)
        finally:
            profiler.charge(self._key or self._resolve(), profiler.now() - start)

    def throw(self, *exc_info: Any) -> Any:
        profiler = self._profiler
        start = profiler.now()
        try:
            return self._coro.throw(*exc_info)
        finally:
            profiler.charge(self._key or self._resolve(), profiler.now() - start)

    def close(self) -> None:
        self._coro.close()

    def __await__(self) -> Generator[Any, None, Any]:
        return self._coro.__await__()

    def _resolve(self) -> str:
        name = self.task.get_name() if self.task is not None else ""
        self._key = self._profiler.attribute(name)
        return self._key

    # what asyncio's reprs and debuggers look at
    @property
    def cr_frame(self) -> Any:
        return getattr(self._coro, "cr_frame", None)

    @property
    def cr_code(self) -> Any:
        return getattr(self._coro, "cr_code", None)

    @property
    def cr_running(self) -> bool:
        return bool(getattr(self._coro, "cr_running", False))

    @property
    def cr_await(self) -> Any:
        return getattr(self._coro, "cr_await", None)

    def __repr__(self) -> str:
        return f"<timed {self._coro!r}>"


# asyncio accepts any collections.abc.Coroutine as a task's coroutine
Coroutine.register(_TimedCoroutine)


class LoopProfiler:
    """Loop time per component, measured by timing every task step (see
    :class:`_TimedCoroutine`), installed as the event loop's task factory while the
    console runs. Tasks are attributed by name: ``afa-supervisor:<name>``,
    ``<name>:<port>`` and ``<name>`` belong to component ``<name>``; the system's
    other tasks (the simulation, observers, fakes) by their owner names; the console's
    own as ``console``. Callbacks that are not task steps (transport reads, timers)
    are not counted: they appear as the rest of the loop's time.

    Cost: two reads of the loop's clock and a dictionary update per task step (about
    half a microsecond).
    """

    def __init__(self, components: Callable[[], Iterable[str]]) -> None:
        self._components = components
        self.totals: dict[str, float] = defaultdict(float)
        self.now: Callable[[], float] = lambda: 0.0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._previous: Any = None
        self._installed = False

    def install(self) -> None:
        """Time every task created from now on in the running loop."""
        if self._installed:
            return
        loop = asyncio.get_running_loop()
        self._loop = loop
        self.now = loop.time
        self._previous = loop.get_task_factory()
        loop.set_task_factory(self._factory)  # type: ignore[arg-type]
        self._installed = True

    def uninstall(self) -> None:
        """Restore the previous task factory (tasks made meanwhile stay timed)."""
        if not self._installed or self._loop is None:
            return
        if self._loop.get_task_factory() == self._factory:
            self._loop.set_task_factory(self._previous)
        self._installed = False

    def _factory(self, loop: asyncio.AbstractEventLoop, coro: Any,
                 **kwargs: Any) -> asyncio.Future[Any]:
        timed = _TimedCoroutine(coro, self)
        if self._previous is not None:
            task = self._previous(loop, timed, **kwargs)
        else:
            task = asyncio.Task(timed, loop=loop, **kwargs)  # type: ignore[arg-type]
        timed.task = task
        return task  # type: ignore[no-any-return]

    def charge(self, key: str, seconds: float) -> None:
        self.totals[key] += seconds

    def attribute(self, task_name: str) -> str:
        """The row a task of this name is charged to."""
        name = task_name[len(_SUPERVISOR):] if task_name.startswith(_SUPERVISOR) else task_name
        head = name.split(":", 1)[0]
        if head in set(self._components()):
            return head
        if CONSOLE_TASK.get() or name.startswith("console"):
            return "console"
        if not name or (name.startswith("Task-") and name[5:].isdigit()):
            return "(unnamed tasks)"
        return head

    def snapshot(self) -> dict[str, float]:
        return dict(self.totals)


class LoopShares:
    """Shares of wall time from snapshots of a :class:`LoopProfiler`, averaged with a
    time constant of ``smoothing`` seconds (as ``ps`` averages %CPU), so one quiet second
    does not blank the table."""

    def __init__(self, profiler: LoopProfiler, clock: Clock, smoothing: float = 5.0) -> None:
        self._profiler = profiler
        self._clock = clock
        self._smoothing = smoothing
        self._last = profiler.snapshot()
        self._last_time = clock.monotonic()
        self.shares: dict[str, float] = {}
        self.busy = 0.0

    def update(self) -> dict[str, float]:
        now = self._clock.monotonic()
        current = self._profiler.snapshot()
        elapsed = now - self._last_time
        if elapsed <= 0:
            return self.shares
        weight = 1.0 - math.exp(-elapsed / self._smoothing) if self.shares else 1.0
        fresh = {key: (value - self._last.get(key, 0.0)) / elapsed
                 for key, value in current.items()}
        self.shares = {key: (1 - weight) * self.shares.get(key, 0.0) + weight * share
                       for key, share in fresh.items()}
        self.busy = sum(self.shares.values())
        self._last, self._last_time = current, now
        return self.shares


# -- memory --------------------------------------------------------------------------------

#: Attributes every component has that belong to the framework (ports, context, logger).
_FRAMEWORK_ATTRIBUTES = frozenset({"_context", "_scope", "_outputs", "_inputs", "_served",
                                   "_used", "_state_changed", "log", "last_error",
                                   "parameters"})
#: Objects the walk never enters: shared machinery, not the component's own data.
_OPAQUE: tuple[type, ...] = (Component, EventChannel, NameRegistry, Clock, Proxy,
                             asyncio.AbstractEventLoop, asyncio.Future, asyncio.Event,
                             asyncio.Lock, asyncio.Condition, type, Path)
_CONTAINERS = (list, tuple, set, frozenset, deque)


def retained_bytes(component: Component[Any], *, limit: int = 5_000, sample: int = 64) -> int:
    """An estimate of the memory ``component`` holds: its own attributes, followed
    through containers, IDL models and objects of the ``components`` and ``afa``
    packages (slots, latest values, reactors and their decoders), with numpy buffers
    counted by their size and each object once. Shared machinery (the channel, registry,
    clock, proxies, other components) is not entered. A container of more than
    ``sample`` items is estimated from ``sample`` of them; at most ``limit`` objects are
    visited. Either way the cost stays around a millisecond, whatever the component holds
    (a planner's search tables are millions of small objects)."""
    seen: set[int] = set()
    # (object, weight): a sampled container's items stand for all of them
    stack: list[tuple[Any, float]] = [(value, 1.0) for key, value in vars(component).items()
                                      if key not in _FRAMEWORK_ATTRIBUTES]
    total = float(sys.getsizeof(component))
    visited = 0
    while stack and visited < limit:
        obj, weight = stack.pop()
        ident = id(obj)
        if ident in seen:
            continue
        seen.add(ident)
        visited += 1
        if isinstance(obj, np.ndarray):
            total += weight * _array_bytes(obj, seen)
            continue
        if isinstance(obj, _OPAQUE) or callable(obj):
            continue
        total += weight * _size(obj)
        if isinstance(obj, (str, bytes, bytearray, int, float, bool, complex)) or obj is None:
            continue
        if isinstance(obj, dict):
            items: list[Any] = _sampled(list(obj.items()), sample)
            share = weight * len(obj) / max(1, len(items))
            for key, value in items:
                stack.append((key, share))
                stack.append((value, share))
        elif isinstance(obj, _CONTAINERS):
            items = _sampled(list(obj), sample)
            share = weight * len(obj) / max(1, len(items))
            stack.extend((item, share) for item in items)
        elif isinstance(obj, BaseModel):
            stack.extend((getattr(obj, name), weight) for name in type(obj).model_fields)
        elif _own(obj):
            if hasattr(obj, "__dict__"):
                stack.extend((value, weight) for value in vars(obj).values())
            for cls in type(obj).__mro__:
                for slot in getattr(cls, "__slots__", ()):
                    if slot not in ("__weakref__", "__dict__") and hasattr(obj, slot):
                        stack.append((getattr(obj, slot), weight))
    return int(total)


def _sampled(items: list[Any], sample: int) -> list[Any]:
    if len(items) <= sample:
        return items
    step = len(items) / sample
    return [items[int(k * step)] for k in range(sample)]


def _array_bytes(array: np.ndarray, seen: set[int]) -> int:
    """The bytes behind ``array``, once per underlying buffer."""
    base = array
    while isinstance(base.base, np.ndarray):
        base = base.base
    if id(base) in seen and base is not array:
        return 0
    seen.add(id(base))
    owner = base.base
    if owner is None or isinstance(owner, np.ndarray):
        return int(base.nbytes)
    if id(owner) in seen:
        return 0
    seen.add(id(owner))
    return int(getattr(owner, "nbytes", None) or _size(owner))


def _size(obj: Any) -> int:
    try:
        return sys.getsizeof(obj)
    except TypeError:
        return 0


def _own(obj: Any) -> bool:
    module = type(obj).__module__ or ""
    return module.startswith(("components", "afa.", "idl")) or module == "__main__" or (
        not module.startswith(("builtins", "asyncio", "logging", "numpy", "pydantic",
                               "aiohttp", "serial", "collections")))


def process_memory() -> int | None:
    """The process's resident set size in bytes (Linux ``/proc``), or None."""
    try:
        with open("/proc/self/statm") as statm:
            pages = int(statm.read().split()[1])
    except (OSError, ValueError, IndexError):
        return None
    import os

    return pages * os.sysconf("SC_PAGE_SIZE")


# -- the table -----------------------------------------------------------------------------


def _events_in(statistics: dict[str, Any]) -> tuple[int, int]:
    delivered = dropped = 0
    for value in statistics.values():
        if isinstance(value, dict) and "delivered" in value:
            delivered += int(value.get("delivered", 0))
            dropped += int(value.get("dropped", 0))
    return delivered, dropped


def _scalars(statistics: dict[str, Any]) -> dict[str, Any]:
    """The component's own counters (not its subscriptions'), for the row's details."""
    out: dict[str, Any] = {}
    for key, value in statistics.items():
        if isinstance(value, bool) or isinstance(value, (int, float, str)) or value is None:
            out[str(key)] = value if not isinstance(value, float) or value == value else None
        elif isinstance(value, dict) and "delivered" in value:
            out[f"in:{key}"] = {k: v for k, v in value.items() if isinstance(v, (int, float))}
    return out


def component_rows(system: Any, events_out: dict[str, int], shares: dict[str, float],
                   memory: dict[str, int]) -> list[dict[str, Any]]:
    """One row per component, in start order, as JSON-ready dictionaries."""
    rows = []
    health = system.health()
    for name, component in system.components.items():
        h = health[name]
        try:
            statistics = component.statistics()
        except Exception as exc:  # a broken statistics() must not break the table
            statistics = {"statistics_error": f"{type(exc).__name__}: {exc}"}
        delivered, dropped = _events_in(statistics)
        rows.append({
            "name": name,
            "type": component.type_name,
            "state": h.state.value,
            "healthy": h.healthy,
            "detail": h.detail,
            "restarts": h.restarts,
            "failures": h.failures,
            "last_error": h.last_error,
            "start_delay": float(system.start_delays.get(name, 0.0)),
            "events_in": delivered,
            "events_in_dropped": dropped,
            "events_out": int(events_out.get(name, 0)),
            "loop_share": round(shares.get(name, 0.0), 6),
            "memory": memory.get(name),
            "implemented": bool(getattr(type(component), "implemented", True)),
            "statistics": _scalars(statistics),
        })
    return rows
