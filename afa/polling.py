"""Polled interfaces: latest-value slots, servants, and proxies that hold a *name*.

Server side: a component keeps each polled value in a :class:`LatestSlot`; ``get…``
methods return :meth:`LatestSlot.get` (the latest value now) and ``getWait…`` methods
:meth:`LatestSlot.wait_next` (the next new value after the call, or ``ETimeOut``). It
binds a :class:`Servant` (implementation + interface, signatures checked at bind time)
in the name registry.

Client side (decision 0007)::

    Proxy (the interface's methods; arguments and result checked against the IDL)
      └─ middleware chain: per-call timeout → statistics → recording hooks → ...
           └─ Invoker: interface, name, invoke(method, arguments)
                ├─ LocalInvoker: looks the name up in the registry at every call
                └─ (a bridge's invoker: the same call across a network)

A proxy never keeps the servant it first found: when the binding changes the next call
reaches the new server, and while the name is unbound a call raises
:class:`~afa.errors.NameNotFound` ("its server is not running"), never stale data.
Arguments, results and errors have a wire form (:func:`encode_arguments`,
:func:`encode_result`, :func:`encode_error`): errors come back as the same afa exception
classes.
"""

from __future__ import annotations

import asyncio
import contextvars
import inspect
import logging
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any, Generic, Protocol, TypeVar

from pydantic import TypeAdapter, ValidationError

from afa import errors
from afa.clock import Clock
from afa.errors import AfaError, ComponentError, EDevIO, InterfaceError, NameNotFound
from afa.tasks import cancel_requested
from idl import wire
from idl._base import IDLModel, Interface, MethodSpec
from idl._base import field as idl_field

__all__ = [
    "LatestSlot", "Servant", "Proxy", "Invoker", "LocalInvoker", "Call", "Middleware",
    "PollLayer", "MethodStatistics", "PollRecord", "proxy_for", "check_servant",
    "encode_arguments", "decode_arguments", "encode_result", "decode_result",
    "encode_error", "decode_error", "PollError", "proxy_name", "current_caller",
]

T = TypeVar("T")
InterfaceT = TypeVar("InterfaceT", bound=Interface)
log = logging.getLogger("afa.polling")

#: The component whose task is running (set for every task of a component's life), so a
#: recording hook can say who made a call; "" outside components (tools, notebooks).
current_caller: contextvars.ContextVar[str] = contextvars.ContextVar("afa_caller", default="")


class LatestSlot(Generic[T]):
    """The latest sample of one polled value, with get / getWait semantics."""

    def __init__(self, clock: Clock, what: str = "value") -> None:
        self._clock = clock
        self._what = what
        self._value: T | None = None
        self._make: Callable[[], T] | None = None  # the latest sample, not built yet
        self._version = 0
        self._waiters: list[asyncio.Future[T]] = []

    def set(self, value: T) -> None:
        """Store a new sample and wake every ``wait_next`` caller."""
        self._value = value
        self._make = None
        self._version += 1
        waiters, self._waiters = self._waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(value)

    def set_lazy(self, make: Callable[[], T]) -> None:
        """Store a new sample that ``make()`` builds when it is first read (by
        :meth:`get`), or now if a ``wait_next`` caller is waiting: for a sample that
        arrives far more often than it is asked for. ``make`` must give the same value
        whenever it is called (capture what it needs, such as the receipt time)."""
        if self._waiters:
            self.set(make())
            return
        self._value = None
        self._make = make
        self._version += 1

    def get(self) -> T:
        """The latest sample; raises :class:`~afa.errors.EDevIO` if there is none yet."""
        if self._version == 0:
            raise EDevIO(f"no {self._what} received yet")
        make = self._make
        if make is not None:
            self._value, self._make = make(), None
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


# -- servants ---------------------------------------------------------------------------


def check_servant(interface: type[Interface], impl: object) -> None:
    """Raise :class:`~afa.errors.ComponentError` naming every method of ``interface``
    that ``impl`` lacks, does not make ``async``, or declares with other parameters."""
    problems = []
    for name, spec in interface.methods.items():
        method = getattr(impl, name, None)
        if method is None:
            problems.append(f"{name} is missing")
            continue
        if not inspect.iscoroutinefunction(method):
            problems.append(f"{name} is not an async method")
            continue
        wanted = [(p.name, p.kind) for p in spec.signature.parameters.values()
                  if p.name != "self"]
        given = list(inspect.signature(method).parameters.values())
        required_extra = [p for p in given[len(wanted):]
                          if p.default is inspect.Parameter.empty
                          and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
        if [(p.name, p.kind) for p in given[:len(wanted)]] != wanted or required_extra:
            problems.append(f"{name}({', '.join(p.name for p in given)}) does not match the "
                            f"interface's {name}({', '.join(n for n, _ in wanted)})")
    if problems:
        raise ComponentError(f"{type(impl).__name__} cannot serve {interface.__name__}: "
                             + "; ".join(problems))


class Servant:
    """An implementation object bound to the interface it serves (signatures checked)."""

    def __init__(self, interface: type[Interface], impl: object, *, name: str = "",
                 logger: logging.Logger | None = None) -> None:
        check_servant(interface, impl)
        self.interface = interface
        self.impl = impl
        self.name = name
        self._log = logger or log

    async def invoke(self, method: str, arguments: dict[str, Any]) -> Any:
        """Run ``method(**arguments)`` on the implementation.

        afa errors pass through unchanged; any other exception is logged with the
        server's name and becomes a :class:`~afa.errors.ComponentError`, and so does a
        CancelledError the caller did not ask for (the server stopped during the call
        and cancelled what the method awaited).
        """
        if method not in self.interface.methods:
            raise InterfaceError(f"{self.interface.__name__} has no method {method!r}")
        try:
            return await getattr(self.impl, method)(**arguments)
        except AfaError:
            raise
        except asyncio.CancelledError:
            if cancel_requested():
                raise  # the caller is being cancelled (or timed out)
            raise ComponentError(f"{self.name or self.interface.__name__}.{method}: "
                                 "cancelled by the server (stopping or restarting)") from None
        except Exception as exc:
            self._log.exception("%s.%s raised", self.name or self.interface.__name__, method)
            raise ComponentError(f"{self.name}.{method} failed: {exc!r}") from exc


# -- the call path ------------------------------------------------------------------------


class Invoker(Protocol):
    """Where a proxy's calls go: a server named ``name`` serving ``interface``."""

    interface: type[Interface]
    name: str

    async def invoke(self, method: str, arguments: dict[str, Any]) -> Any:
        """Call ``method`` with validated keyword ``arguments``; return its result or
        raise an afa error."""
        ...


class _Registry(Protocol):
    def try_resolve(self, name: str) -> Any: ...


class LocalInvoker:
    """Calls whatever serves ``name`` in the registry *now* (a dictionary look-up per
    call): a proxy follows restarts and rebinds, and fails while nothing serves."""

    __slots__ = ("interface", "name", "_registry")

    def __init__(self, registry: _Registry, name: str, interface: type[Interface]) -> None:
        self.interface = interface
        self.name = name
        self._registry = registry

    async def invoke(self, method: str, arguments: dict[str, Any]) -> Any:
        servant = self._registry.try_resolve(self.name)
        if servant is None:
            raise NameNotFound(f"{self.name} is not bound: its server is not running")
        served = getattr(servant, "interface", None)
        if not (isinstance(served, type) and issubclass(served, self.interface)):
            raise InterfaceError(f"{self.name} serves {getattr(served, '__name__', served)}, "
                                 f"not {self.interface.__name__}")
        return await servant.invoke(method, arguments)


@dataclass(slots=True)
class Call:
    """One poll on its way through the middleware chain."""

    name: str
    interface: type[Interface]
    method: str
    arguments: dict[str, Any]
    timeout: float | None


#: ``async def middleware(call, call_next) -> result``: wraps every call of a proxy.
Middleware = Callable[[Call, Callable[[Call], Awaitable[Any]]], Awaitable[Any]]


@dataclass(slots=True)
class MethodStatistics:
    """Per server and method: calls, errors and latency (clock seconds)."""

    calls: int = 0
    errors: int = 0
    total: float = 0.0
    maximum: float = 0.0

    @property
    def mean(self) -> float:
        return self.total / self.calls if self.calls else 0.0

    def as_dict(self) -> dict[str, float]:
        return {"calls": self.calls, "errors": self.errors, "mean_s": self.mean,
                "max_s": self.maximum}


@dataclass(frozen=True, slots=True)
class PollRecord:
    """What a recording hook hears of one finished call."""

    time: float  #: clock stamp when the call was made
    name: str
    interface: type[Interface]
    method: str
    arguments: dict[str, Any]
    result: Any = None
    error: BaseException | None = None
    duration: float = 0.0
    caller: str = ""  #: the calling component ("" outside components)
    #: the sequence number of the last event published when the call was made (-1: the
    #: layer has no event channel): where the call stands among events of one instant
    seq: int = -1


class PollLayer:
    """The standard middleware of a system: per-call timeout (the interface's
    ``call_timeout`` unless given), per-method statistics, and recording hooks (a hook
    that raises is logged and never fails the call)."""

    def __init__(self, clock: Clock, sequence: Callable[[], int] | None = None) -> None:
        self.clock = clock
        self.statistics: dict[tuple[str, str], MethodStatistics] = {}
        self._hooks: list[Callable[[PollRecord], None]] = []
        #: the event channel's last sequence number (a System passes its channel's), so
        #: that a recording can place a call among the events of its instant
        self.sequence = sequence

    def add_hook(self, hook: Callable[[PollRecord], None]) -> Callable[[], None]:
        """Call ``hook(record)`` after every call; returns a function removing it."""
        self._hooks.append(hook)
        return lambda: self._hooks.remove(hook) if hook in self._hooks else None

    @property
    def middleware(self) -> list[Middleware]:
        return [self._measure, self._timeout]

    async def _timeout(self, call: Call, call_next: Callable[[Call], Awaitable[Any]]) -> Any:
        async with self.clock.timeout(call.timeout, f"{call.name}.{call.method}"):
            return await call_next(call)

    async def _measure(self, call: Call, call_next: Callable[[Call], Awaitable[Any]]) -> Any:
        clock = self.clock
        stamp, start = clock.now(), clock.monotonic()
        seq = -1 if self.sequence is None else self.sequence()
        key = (call.name, call.method)
        stats = self.statistics.get(key)
        if stats is None:
            stats = self.statistics[key] = MethodStatistics()
        stats.calls += 1
        result: Any = None
        error: BaseException | None = None
        try:
            result = await call_next(call)
            return result
        except BaseException as exc:
            error = exc
            stats.errors += 1
            raise
        finally:
            duration = clock.monotonic() - start
            stats.total += duration
            if duration > stats.maximum:
                stats.maximum = duration
            if self._hooks:
                record = PollRecord(stamp, call.name, call.interface, call.method,
                                    call.arguments, result, error, duration,
                                    current_caller.get(), seq)
                for hook in list(self._hooks):
                    try:
                        hook(record)
                    except Exception:
                        log.exception("poll hook %r failed (ignored)", hook)


class Proxy:
    """Base of generated client proxies; see :func:`proxy_for`."""

    __slots__ = ("_invoker", "_chain", "_timeout")

    def __init__(self, invoker: Invoker, chain: Callable[[Call], Awaitable[Any]],
                 timeout: float | None) -> None:
        self._invoker = invoker
        self._chain = chain
        self._timeout = timeout

    def __repr__(self) -> str:
        return f"<{type(self).__name__} for {self._invoker.name}>"


def proxy_name(proxy: object) -> str:
    """The server name a proxy calls."""
    if not isinstance(proxy, Proxy):
        raise TypeError(f"not an afa proxy: {proxy!r}")
    return proxy._invoker.name


@cache
def _adapter(annotation: Any) -> TypeAdapter[Any]:
    return TypeAdapter(annotation)


def _make_method(spec: MethodSpec, interface: type[Interface]) -> Callable[..., Any]:
    hints = spec.hints()
    parameters = spec.parameters
    returns = hints.get("return", type(None))
    check_return = returns not in (None, type(None))
    label = f"{interface.__name__}.{spec.name}"

    count = len(parameters)

    async def call(self: Proxy, *args: Any, **kwargs: Any) -> Any:
        if not kwargs and len(args) == count:  # the common case, without inspect
            given = dict(zip(parameters, args, strict=True))
        else:
            try:
                bound = spec.signature.bind(None, *args, **kwargs)
            except TypeError as exc:
                raise InterfaceError(f"{label}: {exc}") from None
            bound.apply_defaults()
            given = bound.arguments
        arguments = {}
        for name in parameters:
            value = given[name]
            if name in hints:
                try:
                    value = _adapter(hints[name]).validate_python(value)
                except ValidationError as exc:
                    raise InterfaceError(f"{label}: argument {name!r}: {exc}") from None
            arguments[name] = value
        invoker = self._invoker
        result = await self._chain(Call(invoker.name, interface, spec.name, arguments,
                                        self._timeout))
        if check_return:
            try:
                result = _adapter(returns).validate_python(result)
            except ValidationError as exc:
                raise InterfaceError(f"{label}: bad result from {invoker.name}: {exc}") from None
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


def proxy_for(interface: type[InterfaceT], invoker: Invoker, *,
              middleware: Sequence[Middleware] = (), timeout: float | None = None) -> InterfaceT:
    """A client proxy with exactly ``interface``'s methods, calling through
    ``middleware`` (outermost first) to ``invoker``. ``timeout`` (per call, used by a
    timeout middleware) defaults to the interface's ``call_timeout``."""
    if not issubclass(invoker.interface, interface):
        raise InterfaceError(f"{invoker.name} is reached as {invoker.interface.__name__}, "
                             f"not {interface.__name__}")

    async def innermost(call: Call) -> Any:
        return await invoker.invoke(call.method, call.arguments)

    chain: Callable[[Call], Awaitable[Any]] = innermost
    for layer in reversed(middleware):
        chain = _wrap(layer, chain)
    call_timeout = interface.call_timeout if timeout is None else timeout
    return _proxy_class(interface)(invoker, chain, call_timeout)  # type: ignore[arg-type, return-value]


def _wrap(layer: Middleware, inner: Callable[[Call], Awaitable[Any]]
          ) -> Callable[[Call], Awaitable[Any]]:
    async def wrapped(call: Call) -> Any:
        return await layer(call, inner)
    return wrapped


# -- the wire form of calls ---------------------------------------------------------------


class PollError(IDLModel):
    """An error a poll raised, as it travels back to the caller."""

    idl_name = "afa.PollError"

    kind: str = idl_field(unit="", description="the afa exception class name")
    message: str = idl_field(unit="", description="the exception's message")


def _spec(interface: type[Interface], method: str) -> MethodSpec:
    spec = interface.methods.get(method)
    if spec is None:
        raise InterfaceError(f"{interface.__name__} has no method {method!r}")
    return spec


def encode_arguments(interface: type[Interface], method: str, arguments: dict[str, Any]) -> bytes:
    """The wire frame of a call's keyword arguments."""
    return wire.encode(_spec(interface, method).arguments_model(**arguments))


def decode_arguments(interface: type[Interface], method: str, data: bytes) -> dict[str, Any]:
    """Inverse of :func:`encode_arguments`; raises InterfaceError for bad arguments."""
    model = _spec(interface, method).arguments_model
    try:
        decoded = wire.decode(data, model)
    except wire.WireError as exc:
        raise InterfaceError(f"{interface.__name__}.{method}: bad arguments: {exc}") from None
    return {name: getattr(decoded, name) for name in model.model_fields}


def encode_result(interface: type[Interface], method: str, value: Any) -> bytes:
    """The wire frame of a call's result."""
    return wire.encode(_spec(interface, method).result_model.model_validate({"result": value}))


def decode_result(interface: type[Interface], method: str, data: bytes) -> Any:
    """Inverse of :func:`encode_result`; raises InterfaceError for a bad result."""
    try:
        return wire.decode(data, _spec(interface, method).result_model).result  # type: ignore[attr-defined]
    except wire.WireError as exc:
        raise InterfaceError(f"{interface.__name__}.{method}: bad result: {exc}") from None


_ERRORS: dict[str, type[AfaError]] = {
    name: cls for name, cls in vars(errors).items()
    if isinstance(cls, type) and issubclass(cls, AfaError) and name != "StartupError"}


def encode_error(error: BaseException) -> bytes:
    """The wire frame of an error a call raised; non-afa errors travel as
    :class:`~afa.errors.ComponentError`."""
    kind = type(error).__name__ if type(error).__name__ in _ERRORS else "ComponentError"
    return wire.encode(PollError(kind=kind, message=str(error)))


def decode_error(data: bytes) -> AfaError:
    """The afa exception a :func:`encode_error` frame describes (only afa's own
    exception classes are ever instantiated)."""
    try:
        frame = wire.decode(data, PollError)
    except wire.WireError as exc:
        return ComponentError(f"undecodable error from a server: {exc}")
    cls = _ERRORS.get(frame.kind, ComponentError)
    if cls is errors.ConfigError:
        return errors.ConfigError(frame.message)
    return cls(frame.message)

