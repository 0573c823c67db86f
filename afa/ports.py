"""Typed ports and the catalog: what every component publishes, subscribes, serves and
uses, with types, known from the configuration alone before anything runs.

A component declares its ports in its constructor (see :mod:`afa.component`):

- :class:`Output` (*publishes*): an event name and the IDL type of its bodies;
  ``publish(body)`` refuses a body of another type.
- :class:`Input` (*subscribes*): an event name or pattern, the IDL type(s) it accepts,
  and a handler. A body of another type is counted and fails the component (its error
  path), never a silent drop.
- :class:`Served` (*serves*): a polled interface bound under a name.
- :class:`Used` (*uses*): a polled interface reached by name, through a proxy that
  follows the binding.

:class:`Catalog` lists every port of a set of components (``System.catalog()``), checks
the wiring (a subscription nobody publishes, a used interface nobody serves, one event
name carrying two types, a subscriber that cannot take what is published) and draws the
data-flow graph as text, Mermaid or DOT (``python -m afa graph CONFIG``).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass, field
from enum import StrEnum
from fnmatch import fnmatchcase
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from afa.errors import ComponentError, InterfaceError
from afa.events import Event, Overflow, Publisher, Subscription
from idl._base import IDLModel, Interface, type_name

if TYPE_CHECKING:
    from afa.polling import Proxy

__all__ = ["Direction", "PortInfo", "Output", "Input", "Served", "Used", "Catalog"]

T = TypeVar("T", bound=IDLModel)
Handler = Callable[[Event], Awaitable[None] | None]


class Direction(StrEnum):
    PUBLISHES = "publishes"
    SUBSCRIBES = "subscribes"
    SERVES = "serves"
    USES = "uses"


@dataclass(frozen=True, slots=True)
class PortInfo:
    """One catalog entry. ``name`` is the event name (or pattern) or the server name,
    without the robot; ``types`` are qualified IDL type names, or the interface name."""

    component: str
    direction: Direction
    name: str
    types: tuple[str, ...]
    domain: str | None = None  # None: the system's robot
    #: the IDL classes behind ``types`` (events only), for subtype checks
    classes: tuple[type, ...] = field(default=(), compare=False)
    #: the process group running the component ("": this process)
    process: str = field(default="", compare=False)

    @property
    def label(self) -> str:
        short = " | ".join(t.rpartition(".")[2].partition("@")[0] for t in self.types)
        return f"{self.name}: {short}"


def interface_name(interface: type[Interface]) -> str:
    return f"{interface.__module__}.{interface.__qualname__}"


class Output(Generic[T]):
    """A declared publication. ``publish`` works while the component runs."""

    __slots__ = ("owner", "name", "type", "enabled", "published", "_publisher")

    def __init__(self, owner: str, name: str, type: type[T], enabled: bool = True) -> None:
        self.owner, self.name, self.type, self.enabled = owner, name, type, enabled
        self.published = 0  # events published through this port, every life
        self._publisher: Publisher | None = None

    @property
    def subscribed(self) -> bool:
        """True if anyone would receive a publication now (build expensive bodies only
        then)."""
        return self.enabled and self._publisher is not None and self._publisher.subscribed

    def publish(self, body: T) -> Event | None:
        """Publish ``body`` (never waits). Returns the event, or None when the port is
        disabled (the seed's ``Notify false``). Raises InterfaceError for a body of
        another type and ComponentError while the component is not running."""
        if type(body) is not self.type and not isinstance(body, self.type):
            raise InterfaceError(f"{self.owner} publishes {self.name} as "
                                 f"{self.type.__name__}, not {type(body).__name__}")
        if not self.enabled:
            return None
        publisher = self._publisher
        if publisher is None:
            raise ComponentError(f"{self.owner}: {self.name} published while not running")
        self.published += 1
        return publisher.publish(body, origin=self.owner)

    def info(self) -> PortInfo:
        return PortInfo(self.owner, Direction.PUBLISHES, self.name, (type_name(self.type),),
                        classes=(self.type,))


class Input:
    """A declared subscription (the handler runs in a task of the component)."""

    __slots__ = ("owner", "name", "types", "handler", "domain", "maxsize", "policy",
                 "required", "rejected", "received", "subscription")

    def __init__(self, owner: str, name: str, types: tuple[type[IDLModel], ...],
                 handler: Handler, domain: str | None, maxsize: int, policy: Overflow,
                 required: bool = False) -> None:
        if not types or not all(isinstance(t, type) and issubclass(t, IDLModel)
                                for t in types):
            raise ComponentError(f"{owner}: subscription {name!r} needs IDL model types")
        self.owner, self.name, self.types, self.handler = owner, name, types, handler
        self.domain, self.maxsize, self.policy = domain, maxsize, policy
        self.required = required  # the component is not healthy before it has one
        self.rejected = 0
        self.received = 0
        self.subscription: Subscription | None = None

    def check(self, event: Event) -> None:
        """Raise InterfaceError (and count it) if ``event``'s body is not accepted."""
        if not isinstance(event.body, self.types):
            self.rejected += 1
            wanted = " or ".join(t.__name__ for t in self.types)
            raise InterfaceError(
                f"{self.owner}: event {event.domain}/{event.type} from "
                f"{event.origin or 'an unnamed publisher'} carries "
                f"{type(event.body).__name__}; the subscription {self.name!r} takes {wanted}")

    def statistics(self) -> dict[str, int]:
        counters = {"rejected": self.rejected}
        if self.subscription is not None:
            stats = self.subscription.statistics()
            counters.update(delivered=stats.delivered, dropped=stats.dropped,
                            high_water=stats.high_water)
        return counters

    def info(self) -> PortInfo:
        return PortInfo(self.owner, Direction.SUBSCRIBES, self.name,
                        tuple(type_name(t) for t in self.types), self.domain, self.types)


@dataclass(slots=True)
class Served:
    """A declared served interface; bound while the component runs."""

    owner: str
    interface: type[Interface]
    name: str
    impl: object

    def info(self) -> PortInfo:
        return PortInfo(self.owner, Direction.SERVES, self.name,
                        (interface_name(self.interface),))


@dataclass(slots=True)
class Used:
    """A declared used interface and the proxy that reaches it."""

    owner: str
    interface: type[Interface]
    name: str
    proxy: Proxy

    def info(self) -> PortInfo:
        return PortInfo(self.owner, Direction.USES, self.name, (interface_name(self.interface),))


# -- the catalog ---------------------------------------------------------------------------


def _matches(pattern: str, name: str) -> bool:
    return fnmatchcase(name, pattern)


class Catalog:
    """Every port of a set of components, and what can be said about their wiring."""

    def __init__(self, ports: Iterable[PortInfo], robot: str = "Raptor") -> None:
        self.ports = list(ports)
        self.robot = robot

    def by(self, direction: Direction) -> list[PortInfo]:
        return [p for p in self.ports if p.direction is direction]

    def event_types(self) -> dict[str, set[str]]:
        """Event name -> the IDL types its publishers declare."""
        types: dict[str, set[str]] = defaultdict(set)
        for port in self.by(Direction.PUBLISHES):
            types[port.name].update(port.types)
        return types

    def _foreign(self, subscriber: PortInfo, name: str) -> list[str]:
        """The types published as ``name`` that ``subscriber`` cannot take."""
        foreign: list[str] = []
        for port in self.by(Direction.PUBLISHES):
            if port.name != name:
                continue
            if port.classes and subscriber.classes:
                if not all(issubclass(c, subscriber.classes) for c in port.classes):
                    foreign += port.types
            elif not set(port.types) <= set(subscriber.types):
                foreign += port.types
        return sorted(set(foreign))

    def problems(self) -> list[str]:
        """Wiring warnings, one line each (the configuration may still be right: a log
        player or another process may supply what is missing)."""
        lines = []
        published = self.event_types()
        for name, types in sorted(published.items()):
            if len(types) > 1:
                owners = sorted({p.component for p in self.by(Direction.PUBLISHES)
                                 if p.name == name})
                lines.append(f"event {name!r} carries two types: {', '.join(sorted(types))} "
                             f"(published by {', '.join(owners)})")
        for port in self.by(Direction.SUBSCRIBES):
            if port.domain not in (None, self.robot, "*"):
                continue
            matching = [n for n in published if _matches(port.name, n)]
            if not matching:
                lines.append(f"{port.component} subscribes to {port.name!r}, which nobody "
                             "publishes")
                continue
            for name in matching:
                foreign = self._foreign(port, name)
                if foreign:
                    lines.append(f"{port.component} subscribes to {name!r} taking "
                                 f"{', '.join(port.types)}, but it is published as "
                                 f"{', '.join(foreign)}")
        served = {(p.name, p.types) for p in self.by(Direction.SERVES)}
        served_names = {p.name: p.types for p in self.by(Direction.SERVES)}
        for port in self.by(Direction.USES):
            if (port.name, port.types) in served:
                continue
            if port.name in served_names:
                lines.append(f"{port.component} uses {port.name!r} as {port.types[0]}, but it "
                             f"is served as {served_names[port.name][0]}")
            else:
                lines.append(f"{port.component} uses {port.name!r} ({port.types[0]}), which "
                             "nobody serves")
        return lines

    # -- the graph ---------------------------------------------------------------------------
    def edges(self) -> list[tuple[str, str, str, str]]:
        """(from component, to component, label, kind) with kind ``event`` or ``poll``."""
        edges = []
        for out in self.by(Direction.PUBLISHES):
            for inp in self.by(Direction.SUBSCRIBES):
                if _matches(inp.name, out.name) and inp.component != out.component:
                    edges.append((out.component, inp.component, out.label, "event"))
        for use in self.by(Direction.USES):
            for serve in self.by(Direction.SERVES):
                if serve.name == use.name:
                    label = f"{use.name}: {use.types[0].rpartition('.')[2]}"
                    edges.append((use.component, serve.component, label, "poll"))
        return sorted(set(edges))

    def components(self) -> list[str]:
        seen: dict[str, None] = {}
        for port in self.ports:
            seen.setdefault(port.component)
        return list(seen)

    def text(self) -> str:
        lines = []
        for component in self.components():
            lines.append(component)
            for port in self.ports:
                if port.component == component:
                    lines.append(f"  {port.direction.value:10s} {port.label}")
        lines.append("")
        lines.append("data flow (-> event, => poll):")
        for source, target, label, kind in self.edges():
            arrow = "->" if kind == "event" else "=>"
            lines.append(f"  {source} {arrow} {target}  [{label}]")
        return "\n".join(lines) + "\n"

    def mermaid(self) -> str:
        ids = {name: f"c{index}" for index, name in enumerate(self.components())}
        lines = ["flowchart LR"]
        lines += [f'  {ident}["{name}"]' for name, ident in ids.items()]
        for source, target, label, kind in self.edges():
            arrow = "-->" if kind == "event" else "-.->"
            lines.append(f'  {ids[source]} {arrow}|"{label}"| {ids[target]}')
        return "\n".join(lines) + "\n"

    def dot(self) -> str:
        lines = ["digraph afa {", "  rankdir=LR;", "  node [shape=box];"]
        lines += [f'  "{name}";' for name in self.components()]
        for source, target, label, kind in self.edges():
            style = "solid" if kind == "event" else "dashed"
            lines.append(f'  "{source}" -> "{target}" [label="{label}", style={style}];')
        lines.append("}")
        return "\n".join(lines) + "\n"

    def as_dicts(self) -> list[dict[str, Any]]:
        return [{"component": p.component, "direction": p.direction.value, "name": p.name,
                 "types": list(p.types), "domain": p.domain,
                 **({"process": p.process} if p.process else {})}  # another process's port
                for p in self.ports]
