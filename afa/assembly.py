"""Assembling a System from a configuration file (``System.from_xml``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

from afa import registry
from afa.component import Component, RestartPolicy
from afa.config.loader import load_configuration
from afa.errors import ConfigError

S = TypeVar("S")


def build_system(cls: type[S], path: Path, *, strict: bool = False, **options: Any) -> S:
    """Build ``cls`` (System) with the components ``path``'s Launcher enables."""
    registry.load_all()  # registers every parameter model before validation
    config = load_configuration(path)
    components: list[Component] = []
    delays: dict[str, float] = {}
    notes: list[str] = []
    problems: list[str] = []
    for entry in config.launcher.Components:
        if not entry.Enabled:
            continue
        try:
            component_cls = registry.load_component(entry.Type)
        except ConfigError as exc:
            problems.append(f"{config.path}: Launcher {entry.Name}: {exc}")
            continue
        if not registry.is_implemented(component_cls):
            message = (f"{entry.Name} ({entry.Type}) is configured but not implemented yet "
                       f"({getattr(component_cls, 'plan', '')}); it is not started")
            if strict:
                problems.append(f"{config.path}: Launcher {entry.Name}: {message}")
            else:
                notes.append(message)
            continue
        parameters = config.parameters(entry.Section, entry.Instance) if entry.Section else None
        expected = component_cls.Parameters
        if expected is not None and not isinstance(parameters, expected):
            problems.append(
                f"{config.path}: Launcher {entry.Name}: section {entry.Section!r} holds "
                f"{type(parameters).__name__}, but {entry.Type} needs {expected.__name__}")
            continue
        component = component_cls(entry.Name, parameters)
        if not entry.Restart:
            component.restart_policy = RestartPolicy(restart=False)  # type: ignore[misc]
        components.append(component)
        delays[entry.Name] = entry.Period
    if problems:
        raise ConfigError(problems)
    options.setdefault("robot", config.robot)
    options.setdefault("base_dir", config.path.parent)
    system = cls(components, start_delays=delays, **options)  # type: ignore[call-arg]
    system.notes.extend(notes)  # type: ignore[attr-defined]
    system.configuration = config  # type: ignore[attr-defined]
    return system
