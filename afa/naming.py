"""The name registry: an in-process imitation of the CORBA Naming Service.

Objects are bound at ``<Robot>/<Name>`` (``Raptor/Gps``, ``Raptor/EventChannel``).
:meth:`NameRegistry.wait_resolve` waits until a name is bound, so components may start
in any order. A binding remembers its owner, and :meth:`NameRegistry.unbind_owner`
removes every name a stopping server bound. :meth:`NameRegistry.watch` tells a watcher
(a bridge exporting names) of every bind and unbind.
"""

from __future__ import annotations

import asyncio
from collections import defaultdict
from collections.abc import Callable
from typing import Any

from afa.clock import Clock, WallClock
from afa.errors import NameAlreadyBound, NameNotFound

__all__ = ["NameRegistry", "join_name", "Watcher"]

#: ``watcher(name, obj)``: ``name`` was bound to ``obj``, or unbound (``obj`` is None).
Watcher = Callable[[str, Any], None]


def join_name(robot: str, name: str) -> str:
    """``join_name("Raptor", "Gps") == "Raptor/Gps"``; absolute names pass through."""
    return name if "/" in name else f"{robot}/{name}"


def _check(name: str) -> str:
    parts = name.split("/")
    if len(parts) != 2 or not all(p.strip() for p in parts):
        raise ValueError(f"a name is '<Robot>/<Name>', got {name!r}")
    return name


class NameRegistry:
    """``<Robot>/<Name>`` -> object, with owners and waiting resolution."""

    def __init__(self, clock: Clock | None = None) -> None:
        self.clock: Clock = clock or WallClock()
        self._objects: dict[str, Any] = {}
        self._owners: dict[str, object] = {}
        self._waiters: defaultdict[str, list[asyncio.Future[Any]]] = defaultdict(list)
        self._watchers: list[Watcher] = []

    def watch(self, watcher: Watcher) -> Callable[[], None]:
        """Call ``watcher(name, obj)`` after every bind or rebind and ``watcher(name,
        None)`` after every unbind; returns a function that stops watching. A watcher
        must not raise (it runs inside bind and unbind)."""
        self._watchers.append(watcher)
        return lambda: self._watchers.remove(watcher) if watcher in self._watchers else None

    def bind(self, name: str, obj: Any, *, owner: object = None) -> None:
        """Bind ``name``; raises NameAlreadyBound if it is bound."""
        if _check(name) in self._objects:
            raise NameAlreadyBound(f"{name} is already bound")
        self._set(name, obj, owner)

    def rebind(self, name: str, obj: Any, *, owner: object = None) -> None:
        """Bind ``name``, replacing a stale binding (what a Miro server does at start)."""
        self._set(_check(name), obj, owner)

    def unbind(self, name: str) -> None:
        """Remove ``name``; raises NameNotFound if it is not bound."""
        if name not in self._objects:
            raise NameNotFound(f"{name} is not bound")
        del self._objects[name]
        self._owners.pop(name, None)
        for watcher in list(self._watchers):
            watcher(name, None)

    def unbind_owner(self, owner: object) -> list[str]:
        """Remove every name bound by ``owner``; returns them."""
        names = [n for n, o in self._owners.items() if o is owner]
        for name in names:
            self.unbind(name)
        return names

    def resolve(self, name: str) -> Any:
        """The object bound at ``name``; raises NameNotFound."""
        try:
            return self._objects[name]
        except KeyError:
            raise NameNotFound(f"{name} is not bound; bound names: {self.list()}") from None

    def try_resolve(self, name: str) -> Any | None:
        """The object bound at ``name``, or None."""
        return self._objects.get(name)

    async def wait_resolve(self, name: str, timeout: float | None = None) -> Any:
        """Wait until ``name`` is bound (at most ``timeout`` clock seconds).

        Raises :class:`~afa.errors.ETimeOut` if it is not bound in time.
        """
        if name in self._objects:
            return self._objects[name]
        future: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._waiters[_check(name)].append(future)
        try:
            async with self.clock.timeout(timeout, f"resolving {name}"):
                return await future
        finally:
            waiters = self._waiters.get(name)
            if waiters and future in waiters:
                waiters.remove(future)
                if not waiters:
                    del self._waiters[name]

    def list(self, prefix: str = "") -> list[str]:
        """Bound names starting with ``prefix``, sorted."""
        return sorted(n for n in self._objects if n.startswith(prefix))

    def owner(self, name: str) -> object:
        return self._owners.get(name)

    def _set(self, name: str, obj: Any, owner: object) -> None:
        self._objects[name] = obj
        if owner is not None:
            self._owners[name] = owner
        else:
            self._owners.pop(name, None)
        for future in self._waiters.pop(name, []):
            if not future.done():
                future.set_result(obj)
        for watcher in list(self._watchers):
            watcher(name, obj)
