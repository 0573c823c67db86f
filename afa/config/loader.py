"""Validating a Miro configuration document against the parameter models.

:func:`load_configuration` reads the file (:mod:`afa.config.miro`), looks up each
parameter set's model by its Miro type name, validates it, and checks the Launcher's
references. Every problem is collected and reported at once, one line each::

    configs/raptor.xml:57: NodLaserConfig/Laser12/Motorate: unknown parameter
        (did you mean 'Motorrates'?)
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import Field, ValidationError, field_validator

from afa.bridge.parameters import BridgeParameters
from afa.config.miro import ParameterSet, Section, read_document
from afa.config.parameters import Parameters, param
from afa.errors import AfaError, ConfigError

__all__ = [
    "Configuration", "load_configuration", "RobotParameters", "LauncherParameters",
    "LauncherEntry", "DEFAULT_INSTANCE", "MAIN_PROCESS",
]

#: Key of a section's default (unnamed) parameter set in ``Configuration.sections``.
DEFAULT_INSTANCE = "default"
#: The process group of Launcher entries with an empty ``Process``.
MAIN_PROCESS = "main"
_PROCESS_NAME = re.compile(r"[A-Za-z0-9_.-]+")


class RobotParameters(Parameters):
    """Section ``Robot``: read first by every service (Miro::RobotParameters)."""

    namespace = "Miro"
    Name: str = param("Miro", description="The robot's name: naming context and event domain")

    @field_validator("Name")
    @classmethod
    def _one_word(cls, value: str) -> str:
        if not value.strip() or "/" in value or value != value.strip():
            raise ValueError("the robot's name is the first part of every '<Robot>/<Name>': "
                             "not empty, no '/' and no surrounding spaces")
        return value


class LauncherEntry(Parameters):
    """One component the Launcher starts (seed Table 34, Figure 19)."""

    namespace = "Afa"
    Name: str = param(description="Component (process) name, as in the seed's Figure 19")
    Type: str = param(description="Component type: a key of the afa.components registry")
    Section: str = param("", description="Configuration section holding its parameters")
    Instance: str = param("", description="Named instance in that section ('' = default set)")
    Enabled: bool = param(True, description="Component is in the autolaunch group")
    Period: Annotated[float, Field(ge=0.0, le=600.0)] = param(
        0.0, unit="s", description="Delay before launching the next component (dT); at most "
                                   "600 s (start-up waits for it before a run can be stopped)")
    Restart: bool = param(True, description="Restart the component with backoff when it fails")
    Process: str = param("", description="Process group: `afa run CONFIG --process NAME` runs "
                                         "only the entries of group NAME ('' is the group "
                                         "'main') and bridges to the others (afa addition)")

    @field_validator("Process")
    @classmethod
    def _process_name(cls, value: str) -> str:
        if value and not _PROCESS_NAME.fullmatch(value):
            raise ValueError("a process group name is letters, digits, '_', '-' or '.'")
        return value

    @property
    def group(self) -> str:
        """The process group's name (``main`` for an empty ``Process``)."""
        return self.Process or MAIN_PROCESS


class LauncherParameters(Parameters):
    """Section ``Launcher``: which components start, in what order, with what delay."""

    namespace = "Afa"
    Components: list[LauncherEntry] = param([], description="Components in start order")


#: The framework's own sections, always known (the bridge's model imports no network code).
_BUILTIN: dict[str, type[Parameters]] = {
    model.miro_type: model for model in (RobotParameters, LauncherParameters, BridgeParameters)}


@dataclass(frozen=True)
class Configuration:
    """A validated configuration: ``sections[section][instance]`` -> parameters."""

    path: Path
    robot: str
    sections: dict[str, dict[str, Parameters]]
    launcher: LauncherParameters
    launcher_lines: tuple[int, ...] = ()  # the source line of each Launcher entry

    def parameters(self, section: str, instance: str = "") -> Parameters:
        return self.sections[section][instance or DEFAULT_INSTANCE]

    def processes(self) -> list[str]:
        """The Launcher's process groups, in order of first appearance."""
        return list(dict.fromkeys(entry.group for entry in self.launcher.Components))

    def as_dict(self) -> dict[str, dict[str, dict[str, Any]]]:
        """``{section: {instance: {parameter: value}}}`` with every effective value."""
        return {
            section: {instance: p.model_dump(mode="json") for instance, p in sets.items()}
            for section, sets in self.sections.items()
        }

    def to_json(self) -> str:
        return json.dumps(self.as_dict(), indent=2)


def load_configuration(path: str | Path) -> Configuration:
    """Read and validate ``path``; raises ConfigError listing every problem.

    Parameter models are imported on demand (only those the file names; see
    :mod:`afa.registry`), and every Launcher ``Type`` must be an installed component
    type (checked without importing it).
    """
    from afa import registry  # plug-ins: imported on demand, never at import time

    document = read_document(path)
    path = document.path
    problems: list[str] = []
    sections: dict[str, dict[str, Parameters]] = {}
    for section in document.sections.values():
        validated = sections[section.name] = {}
        for pset in _sets(section):
            where = _where(section.name, pset.instance)
            try:
                model = _BUILTIN.get(pset.type_name) or registry.load_parameters(pset.type_name)
            except AfaError as exc:
                problems.append(f"{path}:{pset.line}: {where}: {exc}")
                continue
            if model is None:
                hint = _suggest(pset.type_name, registry.parameter_type_names())
                problems.append(f"{path}:{pset.line}: {where}: unknown parameter type "
                                f"{pset.type_name!r}{hint}")
                continue
            try:
                validated[pset.instance or DEFAULT_INSTANCE] = model.model_validate(pset.values)
            except ValidationError as exc:
                problems += _explain(exc, path, where, pset, model)

    robot = "Miro"
    if "Robot" in sections and DEFAULT_INSTANCE in sections["Robot"]:
        robot_params = sections["Robot"][DEFAULT_INSTANCE]
        robot = getattr(robot_params, "Name", robot)
    launcher = LauncherParameters()
    launcher_lines: tuple[int, ...] = ()
    launcher_section = document.sections.get("Launcher")
    if launcher_section is not None and DEFAULT_INSTANCE in sections.get("Launcher", {}):
        launcher = sections["Launcher"][DEFAULT_INSTANCE]  # type: ignore[assignment]
        present = {name: {i or DEFAULT_INSTANCE for i in [*(
            [""] if sec.default is not None else []), *sec.instances]}
            for name, sec in document.sections.items()}
        problems += _check_launcher(path, launcher_section, launcher, present,
                                    registry.component_types())
        default = launcher_section.default
        if default is not None:
            launcher_lines = tuple(default.line_of(("Components", i))
                                   for i in range(len(launcher.Components)))
    if problems:
        raise ConfigError(problems)
    return Configuration(path, robot, sections, launcher, launcher_lines)


def _sets(section: Section) -> list[ParameterSet]:
    sets = [section.default] if section.default is not None else []
    return sets + list(section.instances.values())


def _where(section: str, instance: str) -> str:
    return f"{section}/{instance}" if instance else section


def _suggest(word: str, choices: Any) -> str:
    from afa.registry import suggest

    return suggest(word, choices)


def _explain(exc: ValidationError, path: Path, where: str, pset: ParameterSet,
             model: type[Parameters]) -> list[str]:
    lines = []
    for error in exc.errors(include_url=False):
        loc = tuple(error["loc"])
        line = pset.line_of(loc)
        dotted = ".".join(str(p) for p in loc) or "(set)"
        if error["type"] == "extra_forbidden":
            known = _fields_at(model, loc[:-1])
            lines.append(f"{path}:{line}: {where}/{dotted}: unknown parameter"
                         f"{_suggest(str(loc[-1]), known)}")
        elif error["type"] == "missing":
            lines.append(f"{path}:{line}: {where}/{dotted}: required parameter is missing")
        else:
            message = error["msg"].removeprefix("Value error, ")
            lines.append(f"{path}:{line}: {where}/{dotted}: {message} "
                         f"(got {error.get('input')!r})")
    return lines


def _fields_at(model: type[Parameters], loc: tuple[Any, ...]) -> list[str]:
    """Field names of the (nested) model at ``loc``, for suggestions."""
    current: Any = model
    for part in loc:
        if isinstance(part, int):
            continue
        info = getattr(current, "model_fields", {}).get(part)
        if info is None:
            return []
        annotation = info.annotation
        args = getattr(annotation, "__args__", ())
        current = next((a for a in (annotation, *args)
                        if isinstance(a, type) and issubclass(a, Parameters)), None)
        if current is None:
            return []
    return list(getattr(current, "model_fields", {}))


def _check_launcher(path: Path, section: Section, launcher: LauncherParameters,
                    sections: dict[str, set[str]], types: list[str]) -> list[str]:
    """Launcher references to installed component types, and to sections and instances
    present in the file (a set that is present but invalid has its own message)."""
    problems = []
    pset = section.default
    assert pset is not None
    names: set[str] = set()
    for index, entry in enumerate(launcher.Components):
        line = pset.line_of(("Components", index))
        where = f"Launcher/Components[{index}] {entry.Name}"
        if entry.Name in names:
            problems.append(f"{path}:{line}: {where}: component name used twice")
        names.add(entry.Name)
        if entry.Type not in types:
            type_line = pset.line_of(("Components", index, "Type"))
            problems.append(f"{path}:{type_line}: {where}: unknown component type "
                            f"{entry.Type!r}{_suggest(entry.Type, types)}; installed types: "
                            f"{', '.join(types)}")
        if not entry.Section:
            continue
        if entry.Section not in sections:
            problems.append(f"{path}:{line}: {where}: section {entry.Section!r} is missing"
                            f"{_suggest(entry.Section, sections)}")
        elif (entry.Instance or DEFAULT_INSTANCE) not in sections[entry.Section]:
            have = sorted(sections[entry.Section])
            problems.append(f"{path}:{line}: {where}: instance {entry.Instance or '(default)'!r} "
                            f"is missing from section {entry.Section!r} (it has {have})")
    return problems
