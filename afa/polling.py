"""Polled interfaces: latest-value slots on the server side, typed proxies on the client.

A server component keeps each polled value in a :class:`LatestSlot`; ``get…`` methods
return :meth:`LatestSlot.get` (the latest value now) and ``getWait…`` methods return
:meth:`LatestSlot.wait_next` (the next new value after the call, or ``ETimeOut``).

The server binds a :class:`Servant` (its implementation plus the interface it serves) in
the name registry. A client resolves the name and receives a :class:`Proxy` built from
the interface class: it has exactly the interface's methods, checks arguments and results
against the IDL annotations, applies a per-call timeout and raises only afa errors.
Every call goes through :meth:`Servant.invoke` with a method name and keyword arguments,
the shape a process boundary needs (see ``docs/decisions/0003-polls.md``).
"""

from __future__ import annotations

import asyncio
import inspect
import logging
from collections.abc import Callable
from functools import cache
from typing import Any, Generic, TypeVar

from pydantic import TypeAdapter, ValidationError

from afa.clock import Clock
from afa.errors import AfaError, ComponentError, EDevIO, InterfaceError
from idl._base import Interface, MethodSpec

__all__ = ["LatestSlot", "Servant", "Proxy", "proxy_for"]

T = TypeVar("T")
InterfaceT = TypeVar("InterfaceT", bound=Interface)


class LatestSlot(Generic[T]):
    """The latest sample of one polled value, with get / getWait semantics."""

    def __init__(self, clock: Clock, what: str = "value") -> None:
        self._clock = clock
        self._what = what
        self._value: T | None = None
        self._version = 0
        self._waiters: list[asyncio.Future[T]] = []

    def set(self, value: T) -> None:
        """Store a new sample and wake every ``wait_next`` caller."""
        self._value = value
        self._version += 1
        waiters, self._waiters = self._waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(value)

    def get(self) -> T:
        """The latest sample; raises :class:`~afa.errors.EDevIO` if there is none yet."""
        if self._version == 0:
            raise EDevIO(f"no {self._what} received yet")
        return self._value  # type: ignore[return-value]

    @property
    def version(self) -> int:
        """How many samples have been stored."""
        return self._version

    async def wait_next(self, timeout: float | None) -> T:
        """The next sample stored after this call; raises ETimeOut after ``timeout``."""
        future: asyncio.Future[T] = asyncio.get_running_loop().create_future()
        self._waiters.append(future)
        try:
            async with self._clock.timeout(timeout, f"waiting for the next {self._what}"):
                return await future
        finally:
            if future in self._waiters:
                self._waiters.remove(future)


class Servant:
    """An implementation object bound to the interface it serves."""

    def __init__(self, interface: type[Interface], impl: object, *, name: str = "",
                 logger: logging.Logger | None = None) -> None:
        missing = [m for m in interface.methods
                   if not inspect.iscoroutinefunction(getattr(impl, m, None))]
        if missing:
            raise ComponentError(
                f"{type(impl).__name__} cannot serve {interface.__name__}: "
                f"missing async method(s) {', '.join(missing)}")
        self.interface = interface
        self.impl = impl
        self.name = name
        self._log = logger or logging.getLogger("afa.polling")

    async def invoke(self, method: str, arguments: dict[str, Any]) -> Any:
        """Run ``method(**arguments)`` on the implementation.

        afa errors pass through unchanged; any other exception is logged with the
        server's name and becomes a :class:`~afa.errors.ComponentError`.
        """
        if method not in self.interface.methods:
            raise InterfaceError(f"{self.interface.__name__} has no method {method!r}")
        try:
            return await getattr(self.impl, method)(**arguments)
        except (AfaError, asyncio.CancelledError):
            raise
        except Exception as exc:
            self._log.exception("%s.%s raised", self.name or self.interface.__name__, method)
            raise ComponentError(f"{self.name}.{method} failed: {exc!r}") from exc


class Proxy:
    """Base of generated client proxies; see :func:`proxy_for`."""

    __slots__ = ("_servant", "_clock", "_timeout", "_name")

    def __init__(self, servant: Servant, clock: Clock, timeout: float | None, name: str) -> None:
        self._servant = servant
        self._clock = clock
        self._timeout = timeout
        self._name = name

    def __repr__(self) -> str:
        return f"<{type(self).__name__} for {self._name}>"


@cache
def _adapter(annotation: Any) -> TypeAdapter[Any]:
    return TypeAdapter(annotation)


def _make_method(spec: MethodSpec, interface: type[Interface]) -> Callable[..., Any]:
    hints = spec.hints()
    parameters = spec.parameters
    returns = hints.get("return", type(None))
    check_return = returns not in (None, type(None))
    label = f"{interface.__name__}.{spec.name}"

    async def call(self: Proxy, *args: Any, **kwargs: Any) -> Any:
        try:
            bound = spec.signature.bind(None, *args, **kwargs)
        except TypeError as exc:
            raise InterfaceError(f"{label}: {exc}") from None
        bound.apply_defaults()
        arguments = {}
        for name in parameters:
            value = bound.arguments[name]
            if name in hints:
                try:
                    value = _adapter(hints[name]).validate_python(value)
                except ValidationError as exc:
                    raise InterfaceError(f"{label}: argument {name!r}: {exc}") from None
            arguments[name] = value
        async with self._clock.timeout(self._timeout, f"{self._name}.{spec.name}"):
            result = await self._servant.invoke(spec.name, arguments)
        if check_return:
            try:
                result = _adapter(returns).validate_python(result)
            except ValidationError as exc:
                raise InterfaceError(f"{label}: bad result from {self._name}: {exc}") from None
        return result

    call.__name__ = spec.name
    call.__qualname__ = f"{interface.__name__}Proxy.{spec.name}"
    call.__doc__ = spec.doc
    return call


@cache
def _proxy_class(interface: type[Interface]) -> type[Proxy]:
    namespace: dict[str, Any] = {"__slots__": (), "interface": interface}
    for spec in interface.methods.values():
        namespace[spec.name] = _make_method(spec, interface)
    return type(f"{interface.__name__}Proxy", (Proxy,), namespace)


def proxy_for(interface: type[InterfaceT], servant: Servant, clock: Clock, *,
              timeout: float | None = None, name: str = "") -> InterfaceT:
    """A client proxy exposing exactly ``interface``'s methods, calling ``servant``.

    ``timeout`` defaults to the interface's ``call_timeout``. Raises InterfaceError if
    the servant serves a different interface.
    """
    if not issubclass(servant.interface, interface):
        raise InterfaceError(
            f"{name or 'object'} serves {servant.interface.__name__}, not {interface.__name__}")
    call_timeout = interface.call_timeout if timeout is None else timeout
    return _proxy_class(interface)(servant, clock, call_timeout, name or servant.name)  # type: ignore[return-value]
