"""Owned tasks: every task afa starts belongs to someone who hears of its failure.

This is the only module that creates asyncio tasks (a test enforces it). Three kinds:

- :class:`TaskGroup`: the long-lived group a :class:`~afa.system.System` owns while it
  runs. Every task of the framework, the fake devices, the simulation and bridges is
  spawned into it with an *owner* name. A task that raises is reported (logged with its
  owner) and handed to the group's failure handler, which fails what the task belongs
  to (a component's task fails the component; a fake device's or the simulation's task
  fails the system). Unlike :class:`asyncio.TaskGroup` it never cancels the task that
  created it, so a notebook can start a system in one cell and stop it in another.
- :class:`Scope`: a structured scope for one life of a component: its tasks end with it,
  and the first failure among them fails it (an :class:`asyncio.TaskGroup` underneath).
- :func:`loop_service`: a task that belongs to the event loop itself, outliving every
  system (the virtual clock's driver).

:func:`spawn` starts a task in the group of the system whose task is calling it (a
context variable carries the group into every task the system starts), so code deep in
a device factory need not be handed the group.
"""

from __future__ import annotations

import asyncio
import contextvars
import logging
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any, TypeVar

from afa.errors import AfaError

if TYPE_CHECKING:
    from afa.meter import LoopMeter

__all__ = ["TaskGroup", "Scope", "spawn", "current_group", "loop_service", "TaskFailure",
           "first_error"]

T = TypeVar("T")
log = logging.getLogger("afa.tasks")

_CURRENT: contextvars.ContextVar[TaskGroup | None] = contextvars.ContextVar(
    "afa_task_group", default=None)

#: ``handler(owner, exception)``: told of a task that ended with an exception.
FailureHandler = Callable[[str, BaseException], None]


class TaskFailure:
    """A task that ended with an exception: who owned it and what it raised."""

    __slots__ = ("owner", "name", "error")

    def __init__(self, owner: str, name: str, error: BaseException) -> None:
        self.owner, self.name, self.error = owner, name, error

    def __repr__(self) -> str:
        return f"<TaskFailure {self.owner} ({self.name}): {self.error!r}>"


class TaskGroup:
    """A long-lived group of owned tasks (see the module docstring).

    ``on_failure(owner, exc)`` decides what a failure fails; without it failures are
    only logged and kept in :attr:`failures`. Use ``async with TaskGroup() as group``
    in tests and tools that run fakes without a System: the body's task then spawns
    into ``group``, and leaving the block cancels what is left and raises the first
    failure.
    """

    def __init__(self, name: str = "afa", *, on_failure: FailureHandler | None = None,
                 meter: LoopMeter | None = None) -> None:
        self.name = name
        self.failures: list[TaskFailure] = []
        self._on_failure = on_failure
        self.meter = meter  # accounts each task's steps to its owner (afa top)
        self._tasks: set[asyncio.Task[Any]] = set()
        self._context = contextvars.copy_context()
        self._context.run(_CURRENT.set, self)
        self._closed = False
        self._token: contextvars.Token[TaskGroup | None] | None = None

    def spawn(self, coroutine: Coroutine[Any, Any, T], *, owner: str,
              name: str | None = None,
              context: contextvars.Context | None = None) -> asyncio.Task[T]:
        """Run ``coroutine`` as a task owned by ``owner`` (in ``context``, a copy of
        :meth:`context`, to give it context variables of its own). Raises RuntimeError
        if the group is closed (the coroutine is closed, never left unawaited)."""
        if self._closed:
            coroutine.close()
            raise RuntimeError(f"task group {self.name} is closed; cannot start {owner}'s task")
        if self.meter is not None:
            coroutine = self.meter.wrap(coroutine, owner)
        task = asyncio.get_running_loop().create_task(
            coroutine, name=name or owner, context=self._context if context is None else context)
        self._tasks.add(task)
        task.add_done_callback(lambda done: self._done(done, owner))
        return task

    def context(self) -> contextvars.Context:
        """A copy of the group's context (its tasks find the group through it)."""
        return self._context.copy()

    def _done(self, task: asyncio.Task[Any], owner: str) -> None:
        self._tasks.discard(task)
        if task.cancelled():
            return
        error = task.exception()
        if error is None:
            return
        failure = TaskFailure(owner, task.get_name(), error)
        self.failures.append(failure)
        # afa's own errors say what happened in their message; anything else is a bug,
        # and its traceback is where to start
        log.error("task %s of %s failed: %s: %s", task.get_name(), owner,
                  type(error).__name__, error,
                  exc_info=None if isinstance(error, AfaError) else error)
        if self._on_failure is not None:
            self._on_failure(owner, error)

    @property
    def tasks(self) -> int:
        """Tasks still running."""
        return len(self._tasks)

    async def aclose(self) -> None:
        """Cancel every task and wait for them; further spawns fail."""
        self._closed = True
        while self._tasks:
            tasks = list(self._tasks)
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    async def __aenter__(self) -> TaskGroup:
        self._token = _CURRENT.set(self)
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        try:
            await self.aclose()
        finally:
            if self._token is not None:
                _CURRENT.reset(self._token)
                self._token = None
        if self.failures and exc_info[0] is None:
            first = self.failures[0]
            raise RuntimeError(f"task {first.name} of {first.owner} failed: "
                               f"{type(first.error).__name__}: {first.error}") from first.error


class Scope:
    """The tasks of one component life: ``async with Scope() as scope``; the first task
    that fails cancels the others and the body, and its exception leaves the block
    (wrapped in an exception group, as :class:`asyncio.TaskGroup` does)."""

    def __init__(self, meter: LoopMeter | None = None, account: str = "") -> None:
        self._group = asyncio.TaskGroup()
        self._meter = meter
        self._account = account
        #: True once the block's body has ended (returned, raised or was cancelled):
        #: a task cancelled from then on is being stopped, not ending by its own hand
        self.closing = False

    async def __aenter__(self) -> Scope:
        await self._group.__aenter__()
        return self

    async def __aexit__(self, *exc_info: Any) -> None:
        self.closing = True
        await self._group.__aexit__(*exc_info)

    def spawn(self, coroutine: Coroutine[Any, Any, T], name: str) -> asyncio.Task[T]:
        if self._meter is not None:
            coroutine = self._meter.wrap(coroutine, self._account or name)
        return self._group.create_task(coroutine, name=name)


def cancel_requested() -> bool:
    """Whether the running task was asked to stop (``task.cancel()``), as opposed to
    meeting a CancelledError that some code raised or let escape (a cancelled future
    it awaited, say)."""
    task = asyncio.current_task()
    return task is None or task.cancelling() > 0


def first_error(group: BaseExceptionGroup) -> BaseException:
    """The exception that ended a scope, unwrapped from its exception group (the first
    that is not a cancellation; the group itself if there is none)."""
    for exc in group.exceptions:
        if isinstance(exc, BaseExceptionGroup):
            return first_error(exc)
        if not isinstance(exc, asyncio.CancelledError):
            return exc
    return group


def current_group() -> TaskGroup | None:
    """The task group of the system whose task is running, if any."""
    return _CURRENT.get()


def spawn(coroutine: Coroutine[Any, Any, T], *, owner: str,
          name: str | None = None) -> asyncio.Task[T]:
    """Start ``coroutine`` in the current system's task group (see the module docstring).

    Raises RuntimeError outside a system or a ``TaskGroup`` block.
    """
    group = _CURRENT.get()
    if group is None:
        coroutine.close()
        raise RuntimeError(
            f"{owner}: no afa task group here; run inside a System, or in tests "
            "`async with afa.tasks.TaskGroup():`")
    return group.spawn(coroutine, owner=owner, name=name)


def loop_service(coroutine: Coroutine[Any, Any, None], name: str) -> asyncio.Task[None]:
    """A task that serves the whole event loop (the virtual clock's driver). A failure
    is logged: such a task is written never to raise."""
    task = asyncio.get_running_loop().create_task(coroutine, name=name,
                                                  context=contextvars.Context())
    task.add_done_callback(_report_service)
    return task


def _report_service(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("loop service %s failed", task.get_name(), exc_info=task.exception())
