"""Assembling a System from a configuration file (``System.from_xml``)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

from afa import registry
from afa.component import Component, RestartPolicy
from afa.config.loader import MAIN_PROCESS, Configuration, LauncherEntry, load_configuration
from afa.errors import AfaError, ConfigError
from afa.ports import PortInfo

S = TypeVar("S")


def build_components(config: Configuration, *, strict: bool = False,
                     only: Iterable[str] | None = None, process: str | None = None
                     ) -> tuple[list[Component[Any]], dict[str, float], list[str]]:
    """The components ``config``'s Launcher enables (or those named in ``only``, enabled
    or not), their start delays and start-up notes. Imports only their plug-ins.
    ``process`` keeps only the entries of that process group (``main``: those without a
    ``Process``); None keeps every group (the whole system in one process).

    Raises ConfigError naming file and line for a type that cannot be loaded (with the
    optional extra to install when the plug-in declares one).
    """
    wanted = None if only is None else set(only)
    if wanted is not None:
        unknown = wanted - {entry.Name for entry in config.launcher.Components}
        if unknown:
            names = [entry.Name for entry in config.launcher.Components]
            raise ConfigError(f"{config.path}: no Launcher entry named "
                              + ", ".join(f"{name!r}{registry.suggest(name, names)}"
                                          for name in sorted(unknown))
                              + f"; the entries are {', '.join(names)}")
    if process is not None and process not in config.processes():
        raise ConfigError(f"{config.path}: no Launcher entry is in process group {process!r}; "
                          f"the groups are {', '.join(config.processes()) or 'none'}")
    components: list[Component[Any]] = []
    delays: dict[str, float] = {}
    notes: list[str] = []
    problems: list[str] = []
    for index, entry in enumerate(config.launcher.Components):
        if (entry.Name not in wanted) if wanted is not None else not entry.Enabled:
            continue
        if process is not None and entry.group != process:
            continue
        where = f"{config.path}:{_line(config, index)}: Launcher {entry.Name}"
        try:
            component_cls = registry.load_component(entry.Type)
        except AfaError as exc:
            problems.append(f"{where}: {exc}")
            continue
        if not registry.is_implemented(component_cls):
            message = (f"{entry.Name} ({entry.Type}) is configured but not implemented yet "
                       f"({getattr(component_cls, 'plan', '')}); it is not started")
            if strict:
                problems.append(f"{where}: {message}")
            else:
                notes.append(message)
            continue
        component = _build(config, entry, component_cls, where, problems)
        if component is not None:
            components.append(component)
            delays[entry.Name] = entry.Period
    if problems:
        raise ConfigError(problems)
    return components, delays, notes


def _build(config: Configuration, entry: LauncherEntry, cls: type[Component[Any]], where: str,
           problems: list[str]) -> Component[Any] | None:
    parameters = config.parameters(entry.Section, entry.Instance) if entry.Section else None
    expected = cls.parameters_type
    if expected is not None and not isinstance(parameters, expected):
        problems.append(f"{where}: section {entry.Section!r} holds "
                        f"{type(parameters).__name__}, but {entry.Type} needs {expected.__name__}")
        return None
    try:
        component = cls(entry.Name, parameters)
    except AfaError as exc:
        problems.append(f"{where}: {exc}")
        return None
    except (ValueError, ArithmeticError, MemoryError) as exc:  # what its parameters make
        problems.append(f"{where}: section {entry.Section!r} cannot configure {entry.Type}: "
                        f"{type(exc).__name__}: {exc}")
        return None
    component.type_name = entry.Type
    if not entry.Restart:
        component.restart_policy = RestartPolicy(restart=False)  # type: ignore[misc]
    return component


def _line(config: Configuration, index: int) -> int:
    lines = config.launcher_lines
    return lines[index] if index < len(lines) else 0


def build_system(cls: type[S], path: Path, *, strict: bool = False,
                 only: Iterable[str] | None = None, process: str | None = None,
                 bridge: Any = None, **options: Any) -> S:
    """Build ``cls`` (System) with the components ``path``'s Launcher enables (of one
    process group if ``process`` is given).

    ``bridge``: None attaches a Zenoh bridge when the configuration's ``Bridge`` set for
    this process is enabled or a process group is chosen; False never; True always; a
    :class:`~afa.bridge.BridgeParameters` or a dict of overrides (field -> value)
    attaches one with those parameters.
    """
    config = load_configuration(path)
    components, delays, notes = build_components(config, strict=strict, only=only,
                                                 process=process)
    options.setdefault("robot", config.robot)
    options.setdefault("base_dir", config.path.parent)
    options.setdefault("process", process or MAIN_PROCESS)
    ports: list[PortInfo] = []
    if process is not None and only is None:
        everyone, every_delay, _ = build_components(config)
        groups = {entry.Name: entry.group for entry in config.launcher.Components}
        ports = [replace(port, process=groups[c.name]) for c in everyone
                 if groups[c.name] != process for port in c.ports()]
        first, delays = _global_start(everyone, every_delay, [c.name for c in components])
        options.setdefault("start_after", first)
    system = cls(components, start_delays=delays, **options)  # type: ignore[call-arg]
    system.notes.extend(notes)  # type: ignore[attr-defined]
    system.configuration = config  # type: ignore[attr-defined]
    system.peer_ports.extend(ports)  # type: ignore[attr-defined]
    if bridge is not False:
        _attach_bridge(system, config, process, bridge)
    return system


def _global_start(everyone: list[Component[Any]], delays: dict[str, float],
                  local: list[str]) -> tuple[float, dict[str, float]]:
    """When a process group starts its first component, and the delays after each, so
    that every component starts at the clock time the whole Launcher would start it in
    one process, and every group's start ends when the whole Launcher's would (the times
    a split run keeps, decision 0011)."""
    starts: dict[str, float] = {}
    offset = 0.0
    for component in everyone:
        starts[component.name] = offset
        offset += delays[component.name]
    if not local:
        return offset, {}
    mine = {}
    for name, following in zip(local, [*local[1:], None], strict=True):
        mine[name] = (starts[following] if following else offset) - starts[name]
    return starts[local[0]], mine


def _attach_bridge(system: Any, config: Configuration, process: str | None,
                   bridge: Any) -> None:
    from afa.bridge.parameters import BridgeParameters, bridge_parameters

    if isinstance(bridge, BridgeParameters):
        parameters = bridge
    else:
        overrides = bridge if isinstance(bridge, dict) else {}
        parameters = bridge_parameters(config, process, **overrides)
        if not (bridge is True or overrides or parameters.Enabled or process is not None):
            return
    from afa.bridge import Bridge  # imports Zenoh: a clear error when the extra is missing

    Bridge(parameters, configuration=config).attach(system)
