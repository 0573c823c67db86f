"""Annex A parameter models, configs/raptor.xml and the geometry files.

The tables below are typed by hand from the seed's Annex A (DRDC Suffield TM 2006-188,
Tables A.1-A.13): parameter name, the default exactly as the seed prints it, and the
Python value it must become. A typo in a model's name or default, a wrong type, or a
value in raptor.xml that drifts from the seed fails here.
"""

from __future__ import annotations

import math
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lxml import etree
from pydantic import ValidationError

from afa.config.loader import load_configuration
from afa.config.parameters import Parameters
from components.arc_arbiter.parameters import ArcArbiterParameters
from components.arcs import ArcSetParameters
from components.find_path.parameters import FindPathParameters
from components.global_map.parameters import GlobalMapParameters
from components.gps_sokkia.parameters import GpsSokkiaParameters
from components.imu.parameters import ImuParameters
from components.model_server.parameters import ModelServerParameters
from components.mpc555.parameters import VehicleControlParameters, WheelOdometryParameters
from components.nodding_laser.parameters import NodLaserParameters
from components.obstacle_avoidance.parameters import ObstacleAvoidanceParameters
from components.obstacle_detection.parameters import ObstacleDetectionParameters
from components.pure_pursuit.parameters import PurePursuitParameters
from components.stereo.parameters import StereoParameters
from components.terrain_map.parameters import TerrainMapParameters
from components.traversability_map.parameters import TraversabilityMapParameters

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
RAPTOR_XML = CONFIGS / "raptor.xml"
ASSEMBLY = CONFIGS / "050917raptor01.XML"

NA = None  # the seed prints "N/A": afa chooses the value

# (name, seed text, expected Python value)
A1 = [
    ("EventChannelName", "EventChannel", "EventChannel"),
    ("EventName", "Laser11", "Laser11"),
    ("LaserID", "11", 11),
    ("Host", "131.135.74.200", "131.135.74.200"),
    ("Port", "24750", 24750),
    ("Baudrate", "500000", 500000),
    ("Motorrates", "15", 15.0),
    ("LowAngle", "-40", -40.0),
    ("HighAngle", "-10", -10.0),
    ("LaserOffsetAngle", "-2", -2.0),
    ("Laserres", "50", 50),
    ("MountAngle", "-14", -14.0),
    ("MountHeight", "3.0", 3.0),
    ("ScanDistance", "0.2", 0.2),
]
A2 = [
    ("EventChannelName", "EventChannel", "EventChannel"),
    ("EventName", "Stereo", "Stereo"),
    ("MaxRange", "8000", 8000),
    ("frameRate", "2", 2.0),
]
A3 = [
    ("Device", "/dev/ttyUSB0", "/dev/ttyUSB0"),
    ("ChannelName", "EventChannel", "EventChannel"),
    ("Notify", "true", True),
    ("EventName", "Imu", "Imu"),
]
A4 = [
    ("Device", "/dev/ttyUSB0", "/dev/ttyUSB0"),
    ("ChannelName", "EventChannel", "EventChannel"),
    ("Notify", "true", True),
    ("EventName", "Gps", "Gps"),
]
A5 = [
    ("Device", "/dev/ttyS0", "/dev/ttyS0"),
    ("LfdParam", NA, NA),
    ("RfdParam", NA, NA),
    ("SteerParam", NA, NA),
    ("SpeedRepTime", "1000", 1000),
    ("WheelDistRepTime", "200", 200),
    ("RaptorOdometryEvent", "RaptorOdometry", "RaptorOdometry"),
]
A6 = [
    ("EventChannelName", "EventChannel", "EventChannel"),
    ("EventName", "Terrain", "Terrain"),
    ("Depth", "32000", 32000),
    ("Width", "32000", 32000),
    ("Gridsize", "200", 200),
    ("notify", "true", True),
    ("RangeEventName1", "Laser11", "Laser11"),
    ("RangeEventName2", "Laser12", "Laser12"),
    ("RangeEventName3", "Stereo", "Stereo"),
    ("PoseEventName", "Pose", "Pose"),
    ("MapEventInterval", "0.25", 0.25),
    ("MapUpdateTime", "7.0", 7.0),
    ("PlatformEvent", "ModelService", "ModelService"),
    ("GroundFrame", "Raptor: Front-BumperCenter", "Raptor: Front-BumperCenter"),
    ("SickLaserFrame1", "FrontNoddingSICKLeft: AxleCenterFreeEnd",
     "FrontNoddingSICKLeft: AxleCenterFreeEnd"),
    ("SickLaser1_ID", "11", 11),
    ("SickLaserFrame2", "FrontNoddingSICKRight: AxleCenterFreeEnd",
     "FrontNoddingSICKRight: AxleCenterFreeEnd"),
    ("SickLaser2_ID", "12", 12),
    ("DigiclopsFrame", "Digiclops:ImagePlane", "Digiclops:ImagePlane"),
    ("BumperHeight", "-500", -500.0),
    ("MaxVelocity", "6000", 6000.0),
    ("PoseInterval", "0.1", 0.1),
    ("OrientationDevError", "2.0", 2.0),
    ("StereoPeriod", "0.5", 0.5),
]
A7 = [
    ("StepOn", "1", 1),
    ("SlopeOn", "1", 1),
    ("StepPercent", "0", 0),
    ("Stepheight", "300", 300.0),
    ("Maxslope", "20", 20.0),
    ("ChannelName", "EventChannel", "EventChannel"),
    ("GlobalMap", "true", True),
    ("EgoMap", "true", True),
    ("Farfield", "8000", 8000.0),
    ("Farfieldscale", "1.5", 1.5),
    ("Farfieldslopescale", "1.5", 1.5),
    ("MapEventInterval", "1", 1.0),
    ("MapUpdateTime", "7", 7.0),
]
A7_DESCRIPTIONS = {  # nested: Depth, Width, Gridsize, EventName
    "GlobalTravMapDescription": [("Depth", "32000", 32000), ("Width", "32000", 32000),
                                 ("Gridsize", "500", 500), ("EventName", "Traverse", "Traverse")],
    "EgoTravMapDescription": [("Depth", "16000", 16000), ("Width", "16000", 16000),
                              ("Gridsize", "500", 500), ("EventName", "Traverse", "Traverse")],
    "TerrainMapDescription": [("Depth", "32000", 32000), ("Width", "32000", 32000),
                              ("Gridsize", "200", 200), ("EventName", "Terrain", "Terrain")],
    "EgoTerrainMapDescription": [("Depth", "16000", 16000), ("Width", "16000", 16000),
                                 ("Gridsize", "200", 200), ("EventName", "Terrain", "Terrain")],
}
A8 = [
    ("UseRawPose", "true", True),
    ("ModelFileName", "050917raptor01.XML", "050917raptor01.XML"),
    ("UpdatePeriod", "0", 0),
    ("FidgetDelay", "20", 20.0),
    ("FidgetPeriod", "300", 300.0),
]
A8_NAMES = {  # EventChannelDescription: "IDL-type EventName" runs, as printed
    "Subscriptions": "Gps Gps Imu Imu",
    "Publications": "Pose Pose",
    "ResolvedNames": "Imu Imu",
    "OfferedNames": "Platform ModelService",
}
A9 = [
    ("MaxLookahead", "20.0", 20.0),
    ("MinLookahead", "7.0", 7.0),
    ("TrackingTolerance", "30.0", 30.0),
    ("PlanUpdateDelayTime", "5.0", 5.0),
    ("PlanEventInterval", "1.0", 1.0),
]
A10 = [
    ("CurveMakingConst", "0.01", 0.01),
    ("VehicleRadius", "0.5", 0.5),
    ("MaxVelocity", "2.0", 2.0),
    ("MinVelocity", "0.5", 0.5),
    ("NearZone", "0", 0),
    ("FarZone", "39", 39),
    ("DistFactor", "0", 0.0),
    ("MinDistDiscount", "1", 1.0),
    ("MapDepth", "16000", 16000),
    ("MapWidth", "16000", 16000),
    ("MapGridsize", "0.01", 0.01),
    ("DiscountSpeeds", "false", False),
    ("CostUnknownCells", "false", False),
    ("VetoUnknownCells", "false", False),
]
A11 = [
    ("SafetyHeight", "0.3", 0.3),
    ("SafetyDepth", "0.3", 0.3),
    ("SafetyDist", "3", 3.0),
    ("VehicleWidth", "1", 1.0),
    ("DefaultYMax", "3", 3.0),
    ("LaserHeight", "2", 2.0),
    ("NumHitsTolerance", "5", 5),
    ("MaxLaserRange", "8191", 8191),
    ("CheckPosObs", "true", True),
    ("CheckNegObs", "true", True),
    ("ResetCounter", "200", 200),
]
A12 = [
    ("ObsWeight", "1", 1.0),
    ("PursuitWeight", "1", 1.0),
    ("PlannerWeight", "1", 1.0),
    ("LaserSafetyWeight", "1", 1.0),
    ("TransVelocitySetPoint", "0.5", 0.5),
    ("StaleVoteTimeSec", "1", 1),
    ("StaleVoteTimeUSec", "500000", 500000),
]
A13 = [
    ("RaptorMotionEvent", "RaptorMotion", "RaptorMotion"),
    ("Device", "/dev/ttyS0", "/dev/ttyS0"),
    ("MaxSteeringAngle", "30", 30.0),
    ("MaxRotVelocity", "1", 1.0),
    ("MaxTransVelocity", "2000", 2000.0),
    ("RfdParam", NA, NA),
    ("LfdParam", NA, NA),
    ("PedalParam", NA, NA),
    ("SteerParam", NA, NA),
    ("SteerPID", NA, NA),
]

# (table, model, Miro type, section in raptor.xml, instance ("" = default set), rows)
TABLES: list[tuple[str, type[Parameters], str, str, str, list[tuple[str, Any, Any]]]] = [
    ("A.1", NodLaserParameters, "Raptor::NodLaserParameters", "NodLaserConfig", "Laser11", A1),
    ("A.2", StereoParameters, "Raptor::StereoParameters", "StereoConfig", "", A2),
    ("A.3", ImuParameters, "Raptor::ImuParameters", "ImuConfig", "", A3),
    ("A.4", GpsSokkiaParameters, "Raptor::GpsSokkiaParameters", "GpsSokkiaConfig", "", A4),
    ("A.5", WheelOdometryParameters, "Raptor::WheelOdometryParameters",
     "WheelOdometryConfig", "", A5),
    ("A.6", TerrainMapParameters, "Raptor::TerrainMapParameters", "MapConfig", "", A6),
    ("A.7", TraversabilityMapParameters, "Raptor::TraversabilityMapParameters",
     "TraverseMap", "", A7),
    ("A.8", ModelServerParameters, "Raptor::ModelServerParameters", "ModelServer", "", A8),
    ("A.9", FindPathParameters, "Raptor::FindPathParameters", "FindPath", "", A9),
    ("A.10", ObstacleAvoidanceParameters, "Raptor::ObstacleAvoidanceParameters",
     "ObsAvoid", "", A10),
    ("A.11", ObstacleDetectionParameters, "Raptor::ObstacleDetectionParameters",
     "ObstacleDetection", "", A11),
    ("A.12", ArcArbiterParameters, "Raptor::ArcArbiterParameters", "ArcArbiter", "", A12),
    ("A.13", VehicleControlParameters, "Raptor::VehicleControlParameters",
     "RaptorCommandConfig", "", A13),
]
# Models without a seed table: every field must be an afa addition.
NO_TABLE: list[tuple[type[Parameters], str, str]] = [
    (GlobalMapParameters, "Raptor::GlobalMapParameters", "GlobalMapConfig"),
    (PurePursuitParameters, "Raptor::PurePursuitParameters", "PurePursuit"),
    (ArcSetParameters, "Raptor::ArcSetParameters", "CandidateArcs"),
]
NESTED_SEED_FIELDS = {
    TraversabilityMapParameters: set(A7_DESCRIPTIONS),
    ModelServerParameters: {"EventChannelDescription"},
}
ALL_MODELS = [t[1] for t in TABLES] + [m for m, _, _ in NO_TABLE]


def seed_names(model: type[Parameters], rows: list[tuple[str, Any, Any]]) -> set[str]:
    return {name for name, _, _ in rows} | NESTED_SEED_FIELDS.get(model, set())


def ids(tables: list[Any]) -> list[str]:
    return [t[0] for t in tables]


# ---------------------------------------------------------------- parameter models


@pytest.mark.parametrize("table", TABLES, ids=ids(TABLES))
def test_every_seed_parameter_exists_with_the_seed_default(table: Any) -> None:
    _, model, _, _, _, rows = table
    defaults = model()
    for name, _, expected in rows:
        assert name in model.model_fields, f"{model.__name__} lacks {name!r}"
        if expected is NA:
            assert "afa's choice" in (model.model_fields[name].description or ""), name
            continue
        value = getattr(defaults, name)
        assert value == expected, f"{name}: {value!r} != seed {expected!r}"
        assert type(value) is type(expected), f"{name}: {type(value).__name__}"


@pytest.mark.parametrize("table", TABLES, ids=ids(TABLES))
def test_miro_type_names(table: Any) -> None:
    _, model, miro_type, _, _, _ = table
    assert model.miro_type == miro_type


def test_models_without_a_table_have_their_miro_type_names() -> None:
    for model, miro_type, _ in NO_TABLE:
        assert model.miro_type == miro_type


@pytest.mark.parametrize("table", TABLES, ids=ids(TABLES))
def test_fields_beyond_the_table_are_marked_afa_additions(table: Any) -> None:
    _, model, _, _, _, rows = table
    for name in set(model.model_fields) - seed_names(model, rows):
        assert "afa addition" in (model.model_fields[name].description or ""), name


@pytest.mark.parametrize("model", [m for m, _, _ in NO_TABLE], ids=lambda m: m.__name__)
def test_models_without_a_table_are_all_afa_additions(model: type[Parameters]) -> None:
    for name, info in model.model_fields.items():
        assert "afa addition" in (info.description or ""), name


def _all_fields(model: type[Parameters]) -> list[tuple[str, Any]]:
    """(dotted name, FieldInfo) for model and every nested Parameters model."""
    out = []
    for name, info in model.model_fields.items():
        out.append((f"{model.__name__}.{name}", info))
        annotation = info.annotation
        for candidate in (annotation, *getattr(annotation, "__args__", ())):
            if isinstance(candidate, type) and issubclass(candidate, Parameters):
                out += _all_fields(candidate)
    return out


@pytest.mark.parametrize("model", ALL_MODELS, ids=lambda m: m.__name__)
def test_every_field_has_a_unit_and_a_description(model: type[Parameters]) -> None:
    for name, info in _all_fields(model):
        assert info.description, f"{name} has no description"
        extra = info.json_schema_extra or {}
        assert isinstance(extra, dict) and extra.get("unit"), f"{name} has no unit"


def test_nested_map_descriptions_of_table_a7() -> None:
    defaults = TraversabilityMapParameters()
    for field, rows in A7_DESCRIPTIONS.items():
        description = getattr(defaults, field)
        for name, _, expected in rows:
            value = getattr(description, name)
            assert value == expected and type(value) is type(expected), f"{field}.{name}"


def test_model_server_name_lists_of_table_a8() -> None:
    names = ModelServerParameters().EventChannelDescription
    for field, seed in A8_NAMES.items():
        words = " ".join(f"{b.Type} {b.Name}" for b in getattr(names, field))
        assert words == seed, field


def test_a_partial_map_description_keeps_that_descriptions_other_defaults() -> None:
    p = TraversabilityMapParameters.model_validate({"EgoTravMapDescription": {"Gridsize": "400"}})
    assert (p.EgoTravMapDescription.Depth, p.EgoTravMapDescription.Width) == (16000, 16000)
    assert p.EgoTravMapDescription.Gridsize == 400


@pytest.mark.parametrize("model", ALL_MODELS, ids=lambda m: m.__name__)
def test_unknown_fields_are_rejected(model: type[Parameters]) -> None:
    with pytest.raises(ValidationError, match="Extra inputs are not permitted"):
        model.model_validate({"NoSuchParameter": "1"})


@pytest.mark.parametrize(("model", "wrong"), [
    (NodLaserParameters, "MotorRates"),        # seed: Motorrates
    (NodLaserParameters, "LaserRes"),          # seed: Laserres
    (StereoParameters, "FrameRate"),           # seed: frameRate
    (TerrainMapParameters, "Notify"),          # seed: notify
    (TerrainMapParameters, "SickLaser1ID"),    # seed: SickLaser1_ID
    (TraversabilityMapParameters, "StepHeight"),   # seed: Stepheight
    (TraversabilityMapParameters, "MaxSlope"),     # seed: Maxslope
    (TraversabilityMapParameters, "FarFieldScale"),  # seed: Farfieldscale
    (ImuParameters, "notify"),                 # seed: Notify
])
def test_names_are_case_sensitive(model: type[Parameters], wrong: str) -> None:
    with pytest.raises(ValidationError):
        model.model_validate({wrong: "1"})


BOOL_FIELDS = [(model, name) for model in ALL_MODELS
               for name, info in model.model_fields.items() if info.annotation is bool]


def test_every_seed_boolean_is_a_bool() -> None:
    seed_bools = {(t[1], name) for t in TABLES for name, text, _ in t[5]
                  if text in ("true", "false")}
    assert seed_bools <= set(BOOL_FIELDS)
    assert len(seed_bools) == 11  # counted by hand in Tables A.3-A.11


@pytest.mark.parametrize(("model", "name"), BOOL_FIELDS,
                         ids=[f"{m.__name__}.{n}" for m, n in BOOL_FIELDS])
def test_booleans_accept_only_true_and_false(model: type[Parameters], name: str) -> None:
    assert getattr(model.model_validate({name: "true"}), name) is True
    assert getattr(model.model_validate({name: "false"}), name) is False
    for bad in ("1", "0", "yes", "True", "TRUE", ""):
        with pytest.raises(ValidationError):
            model.model_validate({name: bad})


def test_integer_switches_of_table_a7_are_not_booleans() -> None:
    assert TraversabilityMapParameters.model_validate({"StepOn": "0"}).StepOn == 0
    for bad in ("2", "-1", "true"):
        with pytest.raises(ValidationError):
            TraversabilityMapParameters.model_validate({"StepOn": bad})


@pytest.mark.parametrize(("model", "values"), [
    (NodLaserParameters, {"Laserres": "30"}),              # SICK: 25, 50 or 100 only
    (NodLaserParameters, {"LowAngle": "-5", "HighAngle": "-10"}),
    (NodLaserParameters, {"Port": "70000"}),
    (TerrainMapParameters, {"Depth": "32100"}),            # not whole 200 mm cells
    (TraversabilityMapParameters, {"GlobalTravMapDescription": {"Gridsize": "300"}}),
    (GlobalMapParameters, {"Gridsize": "300"}),
    (ArcArbiterParameters, {"StaleVoteTimeUSec": "1000000"}),
    (FindPathParameters, {"MinLookahead": "25"}),
    (ObstacleAvoidanceParameters, {"MinDistDiscount": "1.5"}),
    (ObstacleDetectionParameters, {"RangeEventNames": []}),
    (VehicleControlParameters, {"PedalParam": [{"Velocity": "0", "Command": "2048"},
                                               {"Velocity": "-10", "Command": "1900"}]}),
    (VehicleControlParameters, {"SteerParam": {"Center": "950"}}),
])
def test_physically_impossible_values_are_rejected(model: type[Parameters],
                                                   values: dict[str, Any]) -> None:
    with pytest.raises(ValidationError):
        model.model_validate(values)


def test_wheel_distance_calibration_matches_the_wheel() -> None:
    # 2*pi*0.33 m per revolution over 4 * 1024 quadrature counts, in mm
    assert WheelOdometryParameters().LfdParam == pytest.approx(2073.45 / 4096, abs=5e-5)
    assert VehicleControlParameters().RfdParam == WheelOdometryParameters().RfdParam


def test_stale_vote_time_is_one_and_a_half_seconds() -> None:
    assert ArcArbiterParameters().stale_vote_time == 1.5


# ---------------------------------------------------------------- configs/raptor.xml


def _parse(path: Path) -> etree._ElementTree:
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    tree = etree.parse(str(path), parser)
    assert tree.docinfo.internalDTD is None and tree.docinfo.doctype == ""
    return tree


@pytest.fixture(scope="module")
def raptor() -> etree._Element:
    return _parse(RAPTOR_XML).getroot()


def _set(root: etree._Element, section: str, instance: str) -> etree._Element:
    [sec] = root.xpath("section[@name=$s]", s=section)
    if instance:
        [pset] = sec.xpath("instance[@name=$i]", i=instance)
    else:
        [pset] = sec.xpath("parameter")
    return pset


def _child(element: etree._Element, name: str) -> etree._Element:
    found = element.xpath("parameter[@name=$n]", n=name)
    assert len(found) == 1, f"{name!r}: {len(found)} elements under {element.get('name')}"
    return found[0]


def test_raptor_xml_is_miro_format(raptor: etree._Element) -> None:
    assert raptor.tag == "config"
    assert RAPTOR_XML.read_bytes().startswith(b'<?xml version="1.0" encoding="UTF-8"?>')
    robot = _child(_set(raptor, "Robot", ""), "Name")
    assert _set(raptor, "Robot", "").get("name") == "Miro::RobotParameters"
    assert robot.get("value") == "Raptor"


#: The Raptor's configuration departs from the seed's defaults here, each for a reason
#: stated in docs/configuration.md ("Where raptor.xml departs from the seed"); the
#: parameter models keep the seed's defaults. (section, parameter) -> written value.
DEVIATIONS = {
    # Table A.10 draws the vehicle as a 0.5 m disc: the Raptor's body is 1.4 m wide
    ("ObsAvoid", "VehicleRadius"): "0.7",
    # Table A.11's 1 m corridor misses an obstacle before a 1.4 m wide vehicle's wheel
    ("ObstacleDetection", "VehicleWidth"): "1.4",
    # Tables A.3 and A.4 put the IMU (38400 baud) and the GPS (57600) on one port
    ("GpsSokkiaConfig", "Device"): "/dev/ttyUSB1",
    # Pure Pursuit's map-blind pull outvoted FindPath's detours (decision 0035)
    ("ArcArbiter", "PursuitWeight"): "0.25",
}


@pytest.mark.parametrize("table", TABLES, ids=ids(TABLES))
def test_every_seed_parameter_is_written_with_the_seed_default(
        raptor: etree._Element, table: Any) -> None:
    _, _, miro_type, section, instance, rows = table
    pset = _set(raptor, section, instance)
    assert (pset.get("type") if instance else pset.get("name")) == miro_type
    for name, text, _ in rows:
        element = _child(pset, name)
        if text is not NA:
            assert element.get("value") == DEVIATIONS.get((section, name), text), name


def test_each_deviation_is_a_seed_parameter_and_documented(raptor: etree._Element) -> None:
    documented = (ROOT / "docs" / "configuration.md").read_text()
    seed = {(t[3], name): text for t in TABLES for name, text, _ in t[5]}
    for (section, name), value in DEVIATIONS.items():
        assert (section, name) in seed, (section, name)
        assert seed[(section, name)] != value, (section, name)
        assert f"`{section}` `{name}`" in documented, (section, name)


def test_second_laser_instance(raptor: etree._Element) -> None:
    pset = _set(raptor, "NodLaserConfig", "Laser12")
    assert pset.get("type") == "Raptor::NodLaserParameters"
    overrides = {"EventName": "Laser12", "LaserID": "12"}
    for name, text, _ in A1:
        if name == "Host":
            continue  # the second laser has its own address
        assert _child(pset, name).get("value") == overrides.get(name, text), name


def test_nested_descriptions_are_written_with_the_seed_defaults(raptor: etree._Element) -> None:
    pset = _set(raptor, "TraverseMap", "")
    for field, rows in A7_DESCRIPTIONS.items():
        struct = _child(pset, field)
        for name, text, _ in rows:
            assert _child(struct, name).get("value") == text, f"{field}.{name}"
    names = _child(_set(raptor, "ModelServer", ""), "EventChannelDescription")
    for field, seed in A8_NAMES.items():
        vector = _child(names, field)
        assert all(item.get("name") is None for item in vector), field  # a vector
        words = " ".join(leaf.get("value") for leaf in vector.iter("parameter")
                         if leaf.get("value") is not None)
        assert words == seed, field


SETS = [(t[1], t[3], t[4]) for t in TABLES] + [(m, s, "") for m, _, s in NO_TABLE]


@pytest.mark.parametrize(("model", "section", "instance"), SETS,
                         ids=[t[0] for t in TABLES] + [s for _, _, s in NO_TABLE])
def test_every_model_field_is_written_out(raptor: etree._Element, model: type[Parameters],
                                          section: str, instance: str) -> None:
    pset = _set(raptor, section, instance)
    written = {child.get("name") for child in pset}
    assert written == set(model.model_fields)


def test_raptor_xml_loads_and_equals_the_model_defaults() -> None:
    config = load_configuration(RAPTOR_XML)
    assert config.robot == "Raptor"
    for model, section, instance in SETS:
        deviations = {name: value for (where, name), value in DEVIATIONS.items()
                      if where == section}
        expected = model.model_validate({**model().model_dump(), **deviations})
        assert config.parameters(section, instance) == expected, section
    laser12 = config.parameters("NodLaserConfig", "Laser12")
    assert isinstance(laser12, NodLaserParameters)
    assert (laser12.EventName, laser12.LaserID) == ("Laser12", 12)


LAUNCH_ORDER = [  # (Name, Type, Section, Instance)
    ("NodLaserService", "NodLaser", "NodLaserConfig", "Laser11"),
    ("NodLaserService12", "NodLaser", "NodLaserConfig", "Laser12"),
    ("StereoService", "Stereo", "StereoConfig", ""),
    ("3dmgService", "Imu", "ImuConfig", ""),
    ("GpsSokkiaService", "GpsSokkia", "GpsSokkiaConfig", ""),
    ("RaptorOdometryService", "WheelOdometry", "WheelOdometryConfig", ""),
    ("RaptorService", "VehicleControl", "RaptorCommandConfig", ""),
    ("modelServer", "ModelServer", "ModelServer", ""),
    ("TerrainService", "TerrainMap", "MapConfig", ""),
    ("TraverseService", "TraversabilityMap", "TraverseMap", ""),
    ("GlobalMapService", "GlobalMap", "GlobalMapConfig", ""),
    ("FindPathService", "FindPath", "FindPath", ""),
    ("obsAvoid", "ObstacleAvoidance", "ObsAvoid", ""),
    ("purePursuit", "PurePursuit", "PurePursuit", ""),
    ("LaserSafetyService", "ObstacleDetection", "ObstacleDetection", ""),
    ("arcArbiter", "ArcArbiter", "ArcArbiter", ""),
]


def test_launcher_starts_every_component_in_dependency_order(raptor: etree._Element) -> None:
    pset = _set(raptor, "Launcher", "")
    assert pset.get("name") == "Afa::LauncherParameters"
    entries = []
    for entry in _child(pset, "Components"):
        fields = {child.get("name"): child.get("value") for child in entry}
        entries.append((fields["Name"], fields["Type"], fields["Section"], fields["Instance"]))
        assert fields["Enabled"] == "true"
        assert 0.0 <= float(fields["Period"]) <= 0.5
    assert entries == LAUNCH_ORDER


# ---------------------------------------------------------------- geometry files


def _name(text: str) -> tuple[str, str]:
    """'Body : Frame' -> ('Body', 'Frame'), whitespace around ':' ignored."""
    body, frame = text.split(":")
    return body.strip(), frame.strip()


def _transform(element: etree._Element) -> np.ndarray:
    t = element.find("translation")
    r = element.find("rotation")
    x, y, z = ((float(t.get(k, "0")) for k in "xyz") if t is not None else (0.0, 0.0, 0.0))
    roll, pitch, yaw = ((math.radians(float(r.get(k, "0"))) for k in ("roll", "pitch", "yaw"))
                        if r is not None else (0.0, 0.0, 0.0))
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch),
                              math.sin(pitch), math.cos(yaw), math.sin(yaw))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    out = np.eye(4)
    out[:3, :3] = rz @ ry @ rx
    out[:3, 3] = (x, y, z)
    return out


class Model:
    """A test-side reading of the geometry files: edges and path composition."""

    def __init__(self, assembly: Path) -> None:
        root = _parse(assembly).getroot()
        assert root.tag == "assembly" and root.get("version") == "1"
        self.root = root
        self.frames: set[tuple[str, str]] = set()
        self.edges: list[tuple[tuple[str, str], tuple[str, str], np.ndarray, str]] = []
        for body in root.findall("body"):
            name = body.get("name")
            broot = _parse(assembly.parent / body.get("file")).getroot()
            assert broot.tag == "body" and broot.get("version") == "1"
            reference = broot.get("reference")
            declared = [f.get("name") for f in broot.findall("frame")]
            assert reference in declared and len(declared) == len(set(declared))
            for frame in broot.findall("frame"):
                self.frames.add((name, frame.get("name")))
                if frame.get("name") == reference:
                    assert frame.find("translation") is None and frame.find("rotation") is None
                    continue
                self.edges.append(((name, reference), (name, frame.get("name")),
                                   _transform(frame), f"{name} frame {frame.get('name')}"))
        for constraint in root.findall("constraint"):
            a, b = _name(constraint.get("from")), _name(constraint.get("to"))
            assert a in self.frames and b in self.frames, constraint.get("name")
            assert a[0] != b[0], "a constraint joins two bodies"
            self.edges.append((a, b, _transform(constraint), constraint.get("name")))

    def transform(self, a: str, b: str, skip: str = "") -> np.ndarray:
        """^A T_B by breadth-first search, optionally without one edge."""
        start, goal = _name(a), _name(b)
        adjacent: dict[tuple[str, str], list[tuple[tuple[str, str], np.ndarray]]] = {}
        for frm, to, t, label in self.edges:
            if label == skip:
                continue
            adjacent.setdefault(frm, []).append((to, t))
            adjacent.setdefault(to, []).append((frm, np.linalg.inv(t)))
        seen = {start: np.eye(4)}
        queue = deque([start])
        while queue:
            node = queue.popleft()
            for nxt, t in adjacent.get(node, []):
                if nxt not in seen:
                    seen[nxt] = seen[node] @ t
                    queue.append(nxt)
        assert goal in seen, f"{b} is not connected to {a}"
        return seen[goal]


@pytest.fixture(scope="module")
def model() -> Model:
    return Model(ASSEMBLY)


def test_model_server_names_the_assembly_file() -> None:
    assert (RAPTOR_XML.parent / ModelServerParameters().ModelFileName) == ASSEMBLY
    assert ASSEMBLY.is_file()


def test_every_frame_the_seed_names_exists(model: Model) -> None:
    terrain = TerrainMapParameters()
    for text in (terrain.GroundFrame, terrain.SickLaserFrame1, terrain.SickLaserFrame2,
                 terrain.DigiclopsFrame, "Raptor:RearAxleCenter", "Raptor:FrontAxleCenter",
                 "Raptor:Ground", "GpsAntenna:PhaseCenter", "Imu:SensorCenter"):
        assert _name(text) in model.frames, text
    assert _name(model.root.get("reference")) == ("Raptor", "RearAxleCenter")
    assert _name(model.root.get("ground")) == ("Raptor", "Ground")


def test_whole_model_is_connected(model: Model) -> None:
    for body, frame in model.frames:
        model.transform("Raptor:RearAxleCenter", f"{body}:{frame}")


def _position(model: Model, frame: str, reference: str = "Raptor:Ground") -> np.ndarray:
    return model.transform(reference, frame)[:3, 3]


def test_vehicle_dimensions(model: Model) -> None:
    assert _position(model, "Raptor:FrontAxleCenter", "Raptor:RearAxleCenter") == \
        pytest.approx([1.9, 0, 0])
    track = _position(model, "Raptor:FrontRightWheelCenter", "Raptor:FrontLeftWheelCenter")
    assert track == pytest.approx([0, -1.3, 0])
    for wheel in ("FrontLeft", "FrontRight", "RearLeft", "RearRight"):
        assert _position(model, f"Raptor:{wheel}WheelCenter")[2] == pytest.approx(0.33)


def test_bumper_is_half_a_metre_above_ground_as_bumper_height_says(model: Model) -> None:
    ground_in_bumper = _position(model, "Raptor:Ground", "Raptor: Front-BumperCenter")
    assert ground_in_bumper[2] * 1000 == pytest.approx(TerrainMapParameters().BumperHeight)


def test_laser_axles_are_at_laser_height(model: Model) -> None:
    for side in ("Left", "Right"):
        p = _position(model, f"FrontNoddingSICK{side}: AxleCenterFreeEnd")
        assert p[2] == pytest.approx(ObstacleDetectionParameters().LaserHeight)
        assert p[0] == pytest.approx(2.20)  # ahead of the front axle, behind the bumper
        assert p[1] == pytest.approx(0.35 if side == "Left" else -0.35)


def test_camera_optical_axis_looks_forward_and_down(model: Model) -> None:
    t = model.transform("Raptor:RearAxleCenter", "Digiclops:ImagePlane")
    optical_axis = t[:3, 2]  # camera z in vehicle coordinates
    assert optical_axis == pytest.approx([math.cos(math.radians(10)), 0,
                                          -math.sin(math.radians(10))], abs=1e-9)
    image_right = t[:3, 0]
    assert image_right == pytest.approx([0, -1, 0], abs=1e-9)


def test_imu_axes_point_forward_right_down(model: Model) -> None:
    r = model.transform("Raptor:RearAxleCenter", "Imu:SensorCenter")[:3, :3]
    assert r == pytest.approx(np.diag([1.0, -1.0, -1.0]), abs=1e-12)


@pytest.mark.parametrize("closing", ["GpsAntennaSurvey", "LaserBaseline"])
def test_redundant_constraints_close_their_cycles(model: Model, closing: str) -> None:
    [(frm, to, direct, _)] = [e for e in model.edges if e[3] == closing]
    around = model.transform(":".join(frm), ":".join(to), skip=closing)
    assert np.abs(around[:3, 3] - direct[:3, 3]).max() < 1e-6
    assert np.abs(around[:3, :3] - direct[:3, :3]).max() < 1e-9


def test_an_inconsistent_redundant_constraint_would_be_detected(model: Model) -> None:
    """The cycle check above can fail: a 1 cm survey error shows up."""
    [(frm, to, direct, _)] = [e for e in model.edges if e[3] == "GpsAntennaSurvey"]
    around = model.transform(":".join(frm), ":".join(to), skip="GpsAntennaSurvey")
    wrong = direct.copy()
    wrong[2, 3] += 0.01
    assert np.abs(around[:3, 3] - wrong[:3, 3]).max() > 1e-3
