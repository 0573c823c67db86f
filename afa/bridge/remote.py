"""Polls across processes: the servant a bridge binds for a remote name, and the
interface lookup by name.

A :class:`RemoteServant` is bound in the local registry under the remote server's name,
so the poll seam is unchanged (decision 0007): a proxy's ``LocalInvoker`` finds it and
calls :meth:`RemoteServant.invoke`, which sends the call as a Zenoh query
(``afa/<Robot>/poll/<Name>/<method>``, the arguments' wire frame as payload) and turns
the reply back into the result or the same afa exception the server raised. The
proxy's middleware (per-call timeout, statistics, hooks) runs here as for a local call.

While the call is out, the wait is real I/O (``clock.real_io()``, decision 0008): under
a virtual clock, time then runs no faster than real time, so a 5 s timeout is 5 real
seconds. A caller cancelled by its timeout cancels the Zenoh query. A call whose server
process dies is answered at once with :class:`~afa.errors.NameNotFound` (Zenoh ends the
query when the peer's session goes, and the bridge fails calls in flight to a process
whose liveliness token disappears).
"""

from __future__ import annotations

import asyncio
import math
import struct
from collections.abc import Awaitable, Callable
from functools import cache
from typing import TYPE_CHECKING, Any

from afa.bridge import keys
from afa.errors import EOutOfBounds, NameNotFound
from afa.polling import decode_error, decode_result, encode_arguments
from afa.ports import interface_name
from idl._base import Interface

if TYPE_CHECKING:
    from afa.bridge.bridge import Bridge
    from afa.bridge.lockstep import Traffic

__all__ = ["RemoteServant", "RemoteCall", "find_interface", "caller_attachment",
           "parse_caller", "reply_attachment", "parse_reply"]

#: Zenoh's own deadline for a query: a backstop behind the caller's per-call timeout.
QUERY_BACKSTOP = 3600.0


def find_interface(qualified: str) -> type[Interface] | None:
    """The :class:`~idl._base.Interface` subclass already imported under ``qualified``
    (``idl.interfaces.Platform``), or None. A name from the network never imports a
    module: only interfaces this program knows can be called."""
    return _interfaces().get(qualified) or _refresh().get(qualified)


@cache
def _interfaces() -> dict[str, type[Interface]]:
    return _refresh()


def _refresh() -> dict[str, type[Interface]]:
    import idl  # noqa: F401  (the seed's interfaces, always known)

    found: dict[str, type[Interface]] = {}
    stack = list(Interface.__subclasses__())
    while stack:
        cls = stack.pop()
        found[interface_name(cls)] = cls
        stack.extend(cls.__subclasses__())
    _interfaces.cache_clear()
    return found


def caller_attachment(process: str, zid: str, time: float | None = None) -> bytes:
    """Who is calling (``process`` and Zenoh id, for the server's command guard) and, in
    lock-step, at what virtual time (the server answers no earlier)."""
    return f"{process}\n{zid}\n{'' if time is None else repr(time)}".encode()


def parse_caller(attachment: bytes | None) -> tuple[str, str, float | None]:
    """Inverse of :func:`caller_attachment` (empty names and None when absent; a time
    that is not a number is NaN, which a server in lock-step refuses)."""
    if not attachment:
        return "", "", None
    process, _, rest = attachment.decode(errors="replace").partition("\n")
    zid, _, time = rest.partition("\n")
    try:
        return process, zid, float(time) if time else None
    except ValueError:
        return process, zid, math.nan


#: The attachment of a reply: 0 for a result, 1 for an error; the server's virtual time
#: (NaN outside lock-step).
_REPLY = struct.Struct("<Bd")
RESULT, ERROR = 0, 1


def reply_attachment(kind: int, time: float | None) -> bytes:
    return _REPLY.pack(kind, math.nan if time is None else time)


def parse_reply(attachment: bytes | None) -> tuple[int, float | None]:
    if attachment is None or len(attachment) != _REPLY.size:
        return RESULT, None
    kind, time = _REPLY.unpack(attachment)
    return kind, None if math.isnan(time) else time


class RemoteCall:
    """One poll sent as a Zenoh query; :meth:`result` awaits the reply (the result, or
    the afa error the server raised; NameNotFound when no process answered). Zenoh's
    callbacks only count (``traffic``, lock-step) and hand the reply to the loop.

    Raises InterfaceError at construction for arguments the interface refuses.
    """

    def __init__(self, zenoh: Any, session: Any, robot: str, name: str,
                 interface: type[Interface], method: str, arguments: dict[str, Any],
                 attachment: bytes, *, traffic: Traffic | None = None, process: str = "",
                 on_done: Any = None, clock: Any = None,
                 reach: Callable[[float], Awaitable[None]] | None = None) -> None:
        """``clock`` and ``reach``: in lock-step, a reply stamped later than this clock's
        time is handed over when ``reach`` (the lock-step's) says the clock is there: the
        grant of that time may still be on its way. A stamp no grant reaches (a rogue or
        broken server's) answers the call with EOutOfBounds rather than holding it."""
        payload = encode_arguments(interface, method, arguments)  # InterfaceError if bad
        loop = asyncio.get_running_loop()
        #: the reply as (kind, payload, time stamp), or the error of a call nobody answered
        self.future: asyncio.Future[tuple[int, bytes, float | None]] = loop.create_future()
        self._label = f"{robot}/{name}"
        self._decode = (interface, method)
        self._clock = clock
        self._reach = reach
        future = self.future
        replies: list[Any] = []
        label = self._label

        def settle() -> None:
            if traffic is not None:
                traffic.reply_pending(-1)
            if on_done is not None:
                on_done()
            if future.done():
                return
            if not replies:
                where = f" in {process}" if process else ""
                future.set_exception(NameNotFound(
                    f"{label}: no process answered the call (its server{where} is not "
                    "running)"))
                return
            reply = replies[0]
            if reply.ok is None:  # Zenoh's own error (the server's session went away)
                future.set_exception(decode_error(reply.err.payload.to_bytes()))
                return
            attachment = reply.ok.attachment
            kind, when = parse_reply(attachment.to_bytes() if attachment is not None else None)
            future.set_result((kind, reply.ok.payload.to_bytes(), when))

        def on_reply(reply: Any) -> None:  # Zenoh's thread
            if not replies and traffic is not None:
                traffic.count(traffic.replies_received, process)
            replies.append(reply)

        def on_finished() -> None:  # Zenoh's thread: every reply has arrived
            if traffic is not None:
                if not replies:  # nobody received the query: it is not in flight any more
                    traffic.count(traffic.queries_sent, process, -1)
                traffic.reply_pending(+1)  # until the loop has taken it (lock-step)
            try:
                loop.call_soon_threadsafe(settle)
            except RuntimeError:  # the loop is closed
                if traffic is not None:
                    traffic.reply_pending(-1)

        self._token = zenoh.CancellationToken()
        if traffic is not None:
            traffic.count(traffic.queries_sent, process)
        session.get(keys.poll(robot, name, method), zenoh.handlers.Callback(on_reply, on_finished),
                    payload=payload, attachment=attachment, timeout=QUERY_BACKSTOP,
                    cancellation_token=self._token)

    async def result(self) -> Any:
        """The reply; cancelling the wait cancels the query. Raises the afa error the
        server raised, InterfaceError for a reply that does not decode, and in lock-step
        EOutOfBounds for a reply stamped at a time no grant reaches."""
        try:
            kind, data, when = await self.future
        except asyncio.CancelledError:
            self._token.cancel()
            raise
        finally:
            if not self.future.done():
                self.future.cancel()  # whatever arrives later is nobody's business
        if (self._reach is not None and self._clock is not None and when is not None
                and when > self._clock.monotonic()):
            # lock-step: the answer overtook the grant of its time; hand it over then
            try:
                await self._reach(when)
            except EOutOfBounds as exc:
                raise EOutOfBounds(f"{self._label}: the reply is stamped t={when!r} s, a "
                                   f"time no grant reaches ({exc})") from None
        if kind == ERROR:
            raise decode_error(data)
        return decode_result(*self._decode, data)


class RemoteServant:
    """Stands in the local registry for ``name``, served by ``process`` elsewhere."""

    def __init__(self, bridge: Bridge, name: str, interface: type[Interface],
                 process: str) -> None:
        self.bridge = bridge
        self.name = name  # the short name (Gps), bound as <Robot>/<name>
        self.interface = interface
        self.process = process
        self.calls = 0
        self.errors = 0
        self._pending: set[asyncio.Future[Any]] = set()

    def __repr__(self) -> str:
        return f"<RemoteServant {self.name} ({self.interface.__name__}) in {self.process}>"

    async def invoke(self, method: str, arguments: dict[str, Any]) -> Any:
        """Call ``method`` in the serving process; returns its result or raises the afa
        error it raised (NameNotFound if the process goes away meanwhile)."""
        bridge = self.bridge
        lockstep = bridge.lockstep is not None
        call = RemoteCall(bridge.zenoh, bridge.session, bridge.robot, self.name,
                          self.interface, method, arguments,
                          bridge.caller(bridge.clock.monotonic() if lockstep else None),
                          traffic=bridge.traffic, process=self.process,
                          on_done=bridge.changed.set, clock=bridge.clock if lockstep else None,
                          reach=bridge.lockstep.reach if lockstep else None)
        self.calls += 1
        self._pending.add(call.future)
        try:
            with bridge.clock.real_io():
                return await call.result()
        except asyncio.CancelledError:
            raise
        except Exception:
            self.errors += 1
            raise
        finally:
            self._pending.discard(call.future)

    def fail_pending(self, reason: str) -> None:
        """Fail every call in flight (its process went away)."""
        for future in list(self._pending):
            if not future.done():
                future.set_exception(NameNotFound(f"{self.bridge.robot}/{self.name}: {reason}"))
