"""Writing configuration files in Miro's format (``python -m afa config defaults``)."""

from __future__ import annotations

from typing import Any

from lxml import etree

from afa.config.parameters import Parameters

__all__ = ["defaults_document", "parameter_element"]


def parameter_element(tag: str, name: str | None, value: Any, **attributes: str) -> etree._Element:
    """One ``<parameter>`` (or ``<instance>``) element for ``value``, recursively."""
    element = etree.Element(tag)
    if name is not None:
        element.set("name", name)
    for key, text in attributes.items():
        element.set(key, text)
    if isinstance(value, Parameters):
        for field_name in type(value).model_fields:
            element.append(parameter_element("parameter", field_name, getattr(value, field_name)))
    elif isinstance(value, (list, tuple)):
        for item in value:
            element.append(parameter_element("parameter", None, item))
    elif isinstance(value, bool):
        element.set("value", "true" if value else "false")
    else:
        element.set("value", str(value))
    return element


def defaults_document() -> str:
    """A complete configuration file with every registered parameter model's defaults,
    one section per model (named after the model), in Miro's format."""
    from afa import registry

    root = etree.Element("config")
    root.append(etree.Comment(" every afa parameter model with its defaults "))
    for type_name, model in sorted(registry.load_all_parameters().items()):
        try:
            defaults = model()
        except Exception:  # a model with required fields (e.g. a launcher entry) has no default set
            continue
        section = etree.SubElement(root, "section", name=model.__name__.removesuffix("Parameters"))
        section.append(parameter_element("parameter", type_name, defaults))
    return etree.tostring(root, pretty_print=True, xml_declaration=True,
                          encoding="UTF-8").decode()
