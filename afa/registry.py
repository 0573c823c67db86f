"""Plug-ins: component types, parameter models, decoders, emulators, simulators.

Everything is found through entry points (afa's own in ``pyproject.toml``; a third-party
package declares its own the same way) and imported only when a configuration or a
command needs it, so a plug-in whose optional extra is missing breaks only the
configurations that use it, with a message naming the extra to install:

==================  ======================================  ==================================
group               name                                    value
==================  ======================================  ==================================
afa.components      component type (Launcher ``Type``)      ``pkg.module:Class [extra]``
afa.parameters      Miro parameter type (``Raptor::X``)     ``pkg.module:XParameters``
afa.decoders        device name for ``afa decode``          ``pkg.codec:Decoder``
afa.emulators       component type it emulates              ``pkg.emulator:function``
afa.simulators      simulation name                         ``pkg.module:Simulation``
==================  ======================================  ==================================

Parameter modules import nothing but :mod:`afa.config`, so validating a file never
imports a component. :func:`register` adds a component class that is not installed as a
package (tests, notebooks).
"""

from __future__ import annotations

import difflib
from functools import cache
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from afa.component import Component
from afa.config.parameters import Parameters, parameter_types
from afa.errors import ComponentError, ConfigError

__all__ = ["register", "component_types", "load_component", "not_implemented", "is_implemented",
           "load_parameters", "load_all_parameters", "decoders", "load_decoder", "emulator_for",
           "simulators", "suggest"]

COMPONENTS = "afa.components"
PARAMETERS = "afa.parameters"
DECODERS = "afa.decoders"
EMULATORS = "afa.emulators"
SIMULATORS = "afa.simulators"

_registered: dict[str, type[Component[Any]]] = {}


def register(type_name: str, cls: type[Component[Any]]) -> None:
    """Register ``cls`` under ``type_name`` (overrides an entry point of that name)."""
    _registered[type_name] = cls


@cache
def _group(group: str) -> dict[str, EntryPoint]:
    return {ep.name: ep for ep in entry_points(group=group)}


def suggest(word: str, choices: Any) -> str:
    """`` (did you mean 'X'?)`` for the closest of ``choices``, or ``""``.

    A candidate that resembles ``word`` only through a shared prefix or suffix
    (``ImuConfig`` and ``MapConfig`` share ``Config``) is not suggested: what differs
    between them must still look like a typo (a character or two, or mostly alike)."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    if not close or not _typo_of(word, close[0]):
        return ""
    return f" (did you mean {close[0]!r}?)"


def _typo_of(word: str, candidate: str) -> bool:
    a, b = word.lower(), candidate.lower()
    start = 0
    while start < min(len(a), len(b)) and a[start] == b[start]:
        start += 1
    end = 0
    while end < min(len(a), len(b)) - start and a[-1 - end] == b[-1 - end]:
        end += 1
    a, b = a[start:len(a) - end], b[start:len(b) - end]
    if max(len(a), len(b)) <= 2:
        return True  # a character or two added, dropped, swapped or changed
    return difflib.SequenceMatcher(None, a, b).ratio() >= 0.5


def _load(ep: EntryPoint, what: str) -> Any:
    """Import an entry point; a missing optional extra or a broken plug-in is named."""
    try:
        return ep.load()
    except ImportError as exc:
        if ep.extras:
            extra = ep.extras[0]
            raise ComponentError(
                f"{what} {ep.name!r} needs the optional extra {extra!r}: "
                f"pip install 'afa[{extra}]' ({type(exc).__name__}: {exc})") from exc
        raise ComponentError(f"{what} {ep.name!r} ({ep.value}) failed to import: "
                             f"{type(exc).__name__}: {exc}") from exc
    except Exception as exc:  # a broken plug-in must name itself
        raise ComponentError(f"{what} {ep.name!r} ({ep.value}) failed to import: "
                             f"{type(exc).__name__}: {exc}") from exc


# -- components ----------------------------------------------------------------------------


def component_types() -> list[str]:
    """Every known component type name (nothing is imported)."""
    return sorted(set(_group(COMPONENTS)) | set(_registered))


def load_component(type_name: str) -> type[Component[Any]]:
    """The class registered as ``type_name``.

    Raises :class:`~afa.errors.ConfigError` for an unknown type (with the closest known
    one) and :class:`~afa.errors.ComponentError` for a plug-in that cannot be imported
    (naming the extra to install when it declares one).
    """
    if type_name in _registered:
        return _registered[type_name]
    ep = _group(COMPONENTS).get(type_name)
    if ep is None:
        known = ", ".join(component_types()) or "none (is afa installed? pip install -e .)"
        raise ConfigError(f"unknown component type {type_name!r}"
                          f"{suggest(type_name, component_types())}; known types: {known}")
    cls = _load(ep, "component type")
    if not (isinstance(cls, type) and issubclass(cls, Component)):
        raise ComponentError(f"entry point {type_name!r} ({ep.value}) is not a Component class")
    return cls


def not_implemented(type_name: str, parameters: type[Parameters],
                    planned: str) -> type[Component[Any]]:
    """Declare a component type whose implementation is not written yet."""

    class Declared(Component[Any]):
        parameters_type = parameters
        implemented = False
        plan = planned

        async def setup(self) -> None:
            raise ComponentError(f"{type_name} is not implemented yet ({planned})")

    Declared.__name__ = Declared.__qualname__ = type_name
    return Declared


def is_implemented(cls: type[Component[Any]]) -> bool:
    return getattr(cls, "implemented", True)


# -- parameter models ----------------------------------------------------------------------


def load_parameters(miro_type: str) -> type[Parameters] | None:
    """The parameter model registered as ``miro_type``, importing its plug-in's
    parameter module if needed; None if no installed package provides it. Raises
    ComponentError for a parameter module that cannot be imported."""
    model = parameter_types().get(miro_type)
    if model is not None:
        return model
    ep = _group(PARAMETERS).get(miro_type)
    if ep is None:
        return None
    loaded = _load(ep, "parameter type")
    if not (isinstance(loaded, type) and issubclass(loaded, Parameters)):
        raise ComponentError(f"entry point {miro_type!r} ({ep.value}) is not a Parameters model")
    return loaded


def load_all_parameters() -> dict[str, type[Parameters]]:
    """Every installed plug-in's parameter models by Miro type (imports parameter
    modules only), for the parameter reference and ``config defaults``."""
    models = {}
    for miro_type in _group(PARAMETERS):
        model = load_parameters(miro_type)
        if model is not None:
            models[miro_type] = model
    return models


def parameter_type_names() -> list[str]:
    """Every parameter type known (imported or declared), for suggestions."""
    return sorted(set(parameter_types()) | set(_group(PARAMETERS)))


# -- decoders, emulators, simulators -------------------------------------------------------


def decoders() -> list[str]:
    """Device names ``afa decode`` knows."""
    return sorted(_group(DECODERS))


def load_decoder(device: str) -> Any:
    """The decoder class registered for ``device`` (ConfigError if unknown)."""
    ep = _group(DECODERS).get(device)
    if ep is None:
        raise ConfigError(f"no decoder for {device!r}{suggest(device, decoders())}; "
                          f"known: {', '.join(decoders())}")
    return _load(ep, "decoder")


def emulator_for(type_name: str) -> Any | None:
    """The emulator function registered for component type ``type_name``, or None."""
    ep = _group(EMULATORS).get(type_name)
    return None if ep is None else _load(ep, "emulator")


def simulators() -> dict[str, EntryPoint]:
    return dict(_group(SIMULATORS))
