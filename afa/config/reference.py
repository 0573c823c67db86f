"""The parameter reference (``docs/parameters.md``), generated from the parameter models.

Annex A regenerated: one table per model with each parameter's name, type, default,
unit and description. ``python -m afa config reference`` prints it; a test fails when
the committed file is stale.
"""

from __future__ import annotations

import json
from typing import Any

from afa.config import loader as _framework_models  # noqa: F401  (Robot, Launcher models)
from afa.config.parameters import Parameters, parameter_types

__all__ = ["reference_markdown"]


def _type_name(annotation: Any) -> str:
    text = getattr(annotation, "__name__", None) or str(annotation)
    return text.replace("typing.", "")


def _default(model: type[Parameters], name: str) -> str:
    info = model.model_fields[name]
    if info.is_required():
        return "(required)"
    value = info.get_default(call_default_factory=True)
    if isinstance(value, Parameters):
        return json.dumps(value.model_dump(mode="json"))
    if isinstance(value, list):
        if value and isinstance(value[0], Parameters):
            return json.dumps([v.model_dump(mode="json") for v in value])
        return json.dumps(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def reference_markdown() -> str:
    """The whole reference document as Markdown."""
    from afa import registry
    from afa.config import loader

    framework = {model.__module__ for model in loader._BUILTIN.values()}  # Robot, Bridge, ...
    modules = framework | {m.__module__ for m in registry.load_all_parameters().values()}
    # every model of those modules: the plug-ins' own and the structs nested in them
    models = {name: model for name, model in parameter_types().items()
              if model.__module__ in modules}
    lines = [
        "# Parameter reference",
        "",
        "Generated from the parameter models by `python -m afa config reference`; do not",
        "edit by hand (`tests/config/test_reference.py` fails when this file is stale).",
        "Names and defaults of the seed's Annex A tables are kept exactly; parameters",
        "marked *afa addition* are not in the seed. Booleans are written `true`/`false`.",
        "",
    ]
    for type_name, model in sorted(models.items(), key=lambda kv: kv[1].__module__ + kv[0]):
        doc = (model.__doc__ or "").strip().splitlines()[0] if model.__doc__ else ""
        lines += [f"## `{type_name}`", "", f"{doc}  ", f"Module: `{model.__module__}`", "",
                  "| parameter | type | default | unit | description |",
                  "|---|---|---|---|---|"]
        for name, info in model.model_fields.items():
            extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
            unit = str(extra.get("unit", ""))
            lines.append(f"| `{name}` | {_cell(_type_name(info.annotation))} | "
                         f"{_cell(_default(model, name))} | {_cell(unit)} | "
                         f"{_cell(info.description or '')} |")
        lines.append("")
    return "\n".join(lines)
