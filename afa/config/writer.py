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


#: The order the Launcher of a defaults file starts the Raptor's component types in
#: (sensors, vehicle control, pose, maps, planners, arbiter: seed Figure 19); types not
#: named here follow in alphabetical order.
START_ORDER = ("NodLaser", "Stereo", "Imu", "GpsSokkia", "WheelOdometry", "VehicleControl",
               "ModelServer", "TerrainMap", "TraversabilityMap", "GlobalMap", "FindPath",
               "ObstacleAvoidance", "PurePursuit", "ObstacleDetection", "ArcArbiter")
#: Types a defaults file lists but does not enable (LogNotify would write a recording).
OFF_BY_DEFAULT = ("LogNotify",)


def defaults_document() -> str:
    """A complete configuration file with every registered parameter model's defaults,
    one section per model (named after the model, or the shared section a model is
    read from, such as ``CandidateArcs``), in Miro's format, and a Launcher that starts
    one component of every installed type (``afa run FILE --sim`` runs it)."""
    from afa import registry
    from afa.config.loader import LauncherEntry, LauncherParameters, RobotParameters

    root = etree.Element("config")
    root.append(etree.Comment(" every afa parameter model with its defaults "))
    robot = etree.SubElement(root, "section", name="Robot")
    robot.append(parameter_element("parameter", RobotParameters.miro_type, RobotParameters()))
    sections: dict[type[Parameters], str] = {}
    for type_name, model in sorted(registry.load_all_parameters().items()):
        try:
            defaults = model()
        except Exception:  # a model with required fields (e.g. a launcher entry) has no default set
            continue
        name = model.section_name or model.__name__.removesuffix("Parameters")
        section = etree.SubElement(root, "section", name=name)
        section.append(parameter_element("parameter", type_name, defaults))
        sections[model] = name
    types = registry.component_types()
    ordered = [t for t in START_ORDER if t in types] + sorted(set(types) - set(START_ORDER))
    entries = []
    for type_name in ordered:
        try:
            cls = registry.load_component(type_name)
        except Exception:  # a plug-in whose optional extra is not installed
            continue
        if not registry.is_implemented(cls):
            continue
        wanted = cls.parameters_type
        if wanted is not None and wanted not in sections:
            continue
        entries.append(LauncherEntry(
            Name=type_name, Type=type_name, Section="" if wanted is None else sections[wanted],
            Enabled=type_name not in OFF_BY_DEFAULT, Period=0.1))
    root.append(etree.Comment(" one component of every installed type, in start order "))
    launcher = etree.SubElement(root, "section", name="Launcher")
    launcher.append(parameter_element("parameter", LauncherParameters.miro_type,
                                      LauncherParameters(Components=entries)))
    return etree.tostring(root, pretty_print=True, xml_declaration=True,
                          encoding="UTF-8").decode()
