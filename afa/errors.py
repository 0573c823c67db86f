"""The one exception tree of afa.

Every error the framework raises derives from :class:`AfaError` and mixes in the
builtin it behaves like, so callers can catch either::

    AfaError
    ├── ConfigError            (ValueError)    a configuration or world file is invalid
    ├── NamingError            (LookupError)   Naming Service failures
    │   ├── NameNotFound                       resolve() of an unbound name
    │   └── NameAlreadyBound                   bind() of a bound name
    ├── InterfaceError         (TypeError)     a poll violates its IDL interface
    ├── ETimeOut               (TimeoutError)  Miro's ETimeOut: a poll or getWait timed out
    ├── EDevIO                 (OSError)       Miro's EDevIO: a device or transport failed
    │   └── TransportClosed                    the byte stream was closed (EOF)
    ├── EOutOfBounds           (ValueError)    Miro's EOutOfBounds: an argument out of range
    ├── ChannelClosed          (RuntimeError)  a subscription or channel was closed
    ├── ComponentError         (RuntimeError)  a component could not be built or run
    ├── StartupError           (RuntimeError)  one or more components failed to start;
    │                                          ``failures`` maps component name -> error
    ├── TaskFailed             (RuntimeError)  a task of the system (a fake device, the
    │                                          simulation, a bridge) failed; ``owner``
    ├── RealDeviceForbidden    (PermissionError) a real device was opened where real
    │                                          devices are forbidden (tests)
    └── CommandRefused         (PermissionError) a remote call that would move the
                                               vehicle came from a peer not allowed to
                                               command it (the bridge)

Foreign exceptions (pyserial, lxml, pydantic, OSError from sockets) are translated at
the boundary where they enter afa, with ``raise ... from exc`` so the cause is kept.
"""

from __future__ import annotations

from collections.abc import Mapping


class AfaError(Exception):
    """Base of every error raised by afa."""


class ConfigError(AfaError, ValueError):
    """A configuration (or world) file is invalid.

    ``str(error)`` is one line per problem, each ``file:line: section/instance/parameter:
    message``; ``problems`` holds the individual lines.
    """

    def __init__(self, problems: list[str] | str) -> None:
        self.problems = [problems] if isinstance(problems, str) else list(problems)
        super().__init__("\n".join(self.problems))


class NamingError(AfaError, LookupError):
    """A Naming Service operation failed."""


class NameNotFound(NamingError):
    """The name is not bound."""


class NameAlreadyBound(NamingError):
    """The name is already bound (use rebind to replace it)."""


class InterfaceError(AfaError, TypeError):
    """A polled call does not match its interface (unknown method, bad argument or result)."""


class ETimeOut(AfaError, TimeoutError):
    """A poll, a getWait or a device read did not complete before its deadline."""


class EDevIO(AfaError, OSError):
    """A device or transport failed, or has produced no data yet."""


class TransportClosed(EDevIO):
    """The byte stream reached end of file or was closed."""


class EOutOfBounds(AfaError, ValueError):
    """An argument is outside the range the interface accepts (e.g. an unknown frame)."""


class ChannelClosed(AfaError, RuntimeError):
    """The subscription (or the whole event channel) is closed."""


class ComponentError(AfaError, RuntimeError):
    """A component could not be built, started or run."""


class StartupError(AfaError, RuntimeError):
    """One or more components failed to start; ``failures`` maps name -> exception."""

    def __init__(self, failures: Mapping[str, BaseException]) -> None:
        self.failures = dict(failures)
        lines = [f"{len(self.failures)} component(s) failed to start:"]
        lines += [f"  {name}: {type(exc).__name__}: {exc}" for name, exc in self.failures.items()]
        super().__init__("\n".join(lines))


class TaskFailed(AfaError, RuntimeError):
    """A task owned by the system, not by a component, failed (a fake device, the
    simulation's physics, a bridge); ``owner`` names it and ``__cause__`` is the error."""

    def __init__(self, owner: str, error: BaseException) -> None:
        self.owner = owner
        self.error = error
        super().__init__(f"{owner} failed: {type(error).__name__}: {error}")


class RealDeviceForbidden(AfaError, PermissionError):
    """A real serial port or socket was to be opened where real devices are forbidden
    (``System(real_devices=False)`` or ``AFA_FORBID_REAL_DEVICES=1``, as in afa's tests)."""


class CommandRefused(AfaError, PermissionError):
    """A call that would move the vehicle came over the bridge from a peer that the
    serving process's ``Bridge/AllowCommandFrom`` does not name."""
