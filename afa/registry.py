"""The component registry: component type name -> implementation class.

Implementations are found through the entry-point group ``afa.components`` (afa's own
components are declared in ``pyproject.toml``; a third-party package adds its own the
same way) and through :func:`register` for code that is not installed as a package.

A component type may be *declared* before it is written (:func:`not_implemented`):
its parameter model exists, so configuration files validate, and the system reports it
at start-up as configured but not implemented instead of silently skipping it.
"""

from __future__ import annotations

from functools import cache
from importlib.metadata import entry_points
from typing import Any

from afa.component import Component
from afa.config.parameters import Parameters
from afa.errors import ComponentError, ConfigError

__all__ = ["register", "component_types", "load_component", "not_implemented", "is_implemented",
           "load_all"]

GROUP = "afa.components"
_registered: dict[str, type[Component]] = {}


def register(type_name: str, cls: type[Component]) -> None:
    """Register ``cls`` under ``type_name`` (overrides an entry point of that name)."""
    _registered[type_name] = cls


@cache
def _entry_points() -> dict[str, Any]:
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def component_types() -> list[str]:
    """Every known component type name."""
    return sorted(set(_entry_points()) | set(_registered))


def load_component(type_name: str) -> type[Component]:
    """The class registered as ``type_name``; ConfigError lists the known ones."""
    if type_name in _registered:
        return _registered[type_name]
    ep = _entry_points().get(type_name)
    if ep is None:
        known = ", ".join(component_types()) or "none (is afa installed? pip install -e .)"
        raise ConfigError(f"unknown component type {type_name!r}; known types: {known}")
    try:
        cls = ep.load()
    except Exception as exc:  # a broken plug-in must name itself
        raise ComponentError(f"component type {type_name!r} ({ep.value}) failed to import: "
                             f"{type(exc).__name__}: {exc}") from exc
    if not (isinstance(cls, type) and issubclass(cls, Component)):
        raise ComponentError(f"entry point {type_name!r} ({ep.value}) is not a Component class")
    return cls


def load_all() -> dict[str, type[Component]]:
    """Import every registered component (so every parameter model is registered)."""
    return {name: load_component(name) for name in component_types()}


def not_implemented(type_name: str, parameters: type[Parameters], planned: str) -> type[Component]:
    """Declare a component type whose implementation is not written yet."""

    class Declared(Component):
        Parameters = parameters
        implemented = False
        plan = planned

        async def setup(self) -> None:
            raise ComponentError(f"{type_name} is not implemented yet ({planned})")

    Declared.__name__ = Declared.__qualname__ = type_name
    return Declared


def is_implemented(cls: type[Component]) -> bool:
    return getattr(cls, "implemented", True)
