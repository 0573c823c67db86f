"""ModelServer's geometry database: transforms against hand-computed matrices.

Every expected matrix below was worked out by hand (the arithmetic is in the comments),
or follows from the dimensions tabulated in docs/geometry.md, never from the code under
test. The rotation convention is cross-checked against the URDF ``rpy`` quaternion
formula of urdfdom_headers (``Rotation::setFromRPY``), re-derived here independently.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from afa.errors import ConfigError, EOutOfBounds
from components.model_server.geometry import (
    GeometryModel,
    homogeneous_transform,
    normalize_frame_name,
)

REPO = Path(__file__).resolve().parents[2]
RAPTOR = REPO / "configs" / "050917raptor01.XML"

# --------------------------------------------------------------------- small models

# Body "Box": reference Origin, frame Top 1 m up.  Body "Arm": reference Base, frame
# Tip 2 m ahead and turned 90 degrees left.  The assembly puts Arm:Base 1 m ahead of
# Box:Top, turned 90 degrees left.
BOX = """<?xml version="1.0"?>
<body type="Box" version="1" reference="Origin">
  <frame name="Origin"/>
  <frame name="Top"><translation z="1"/></frame>
</body>
"""
ARM = """<?xml version="1.0"?>
<body type="Arm" version="1" reference="Base">
  <frame name="Base"/>
  <frame name="Tip">
    <translation x="2" y="0" z="0"/>
    <rotation roll="0" pitch="0" yaw="90"/>
  </frame>
</body>
"""
MOUNT = """  <constraint name="Mount" from="Box:Top" to="Arm:Base">
    <translation x="1"/>
    <rotation yaw="90"/>
  </constraint>
"""

# ^Box:Origin T_Arm:Tip = [I|(0,0,1)] [Rz90|(1,0,0)] [Rz90|(2,0,0)]
#   R = Rz180;  t = (0,0,1) + (1,0,0) + Rz90 (2,0,0) = (0,0,1) + (1,0,0) + (0,2,0) = (1,2,1)
ORIGIN_T_TIP = np.array([[-1.0, 0.0, 0.0, 1.0],
                         [0.0, -1.0, 0.0, 2.0],
                         [0.0, 0.0, 1.0, 1.0],
                         [0.0, 0.0, 0.0, 1.0]])
# Its inverse: R^T = Rz180, -R^T t = -(-1, -2, 1) = (1, 2, -1)
TIP_T_ORIGIN = np.array([[-1.0, 0.0, 0.0, 1.0],
                         [0.0, -1.0, 0.0, 2.0],
                         [0.0, 0.0, 1.0, -1.0],
                         [0.0, 0.0, 0.0, 1.0]])
# ^Box:Top T_Arm:Base: the Mount constraint itself, Rz90 and (1, 0, 0)
TOP_T_BASE = np.array([[0.0, -1.0, 0.0, 1.0],
                       [1.0, 0.0, 0.0, 0.0],
                       [0.0, 0.0, 1.0, 0.0],
                       [0.0, 0.0, 0.0, 1.0]])


def write_model(tmp_path: Path, constraints: str = MOUNT, *, extra_bodies: str = "",
                header: str = 'name="Test" version="1" reference="Box:Origin"',
                box: str = BOX, arm: str = ARM) -> Path:
    (tmp_path / "bodies").mkdir(exist_ok=True)
    (tmp_path / "bodies" / "box.xml").write_text(box)
    (tmp_path / "bodies" / "arm.xml").write_text(arm)
    assembly = tmp_path / "assembly.xml"
    assembly.write_text(
        '<?xml version="1.0"?>\n'
        f"<assembly {header}>\n"
        '  <body name="Box" file="bodies/box.xml"/>\n'
        '  <body name="Arm" file="bodies/arm.xml"/>\n'
        f"{extra_bodies}{constraints}</assembly>\n")
    return assembly


def line_of(path: Path, needle: str) -> int:
    """1-based line of the first line of ``path`` containing ``needle``."""
    for number, text in enumerate(path.read_text().splitlines(), start=1):
        if needle in text:
            return number
    raise AssertionError(f"{needle!r} not in {path}")


def assert_transform(actual: np.ndarray, expected: np.ndarray) -> None:
    assert actual.shape == (4, 4) and actual.dtype == np.float64
    np.testing.assert_allclose(actual, expected, atol=1e-12)


# --------------------------------------------------------------------- rotation convention


def test_single_axis_rotations_follow_the_documented_signs() -> None:
    # pitch +90: x (forward) tilts down to -z, z turns to +x
    assert_transform(homogeneous_transform(rpy_deg=(0, 90, 0)),
                     np.array([[0, 0, 1, 0], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1.0]]))
    # roll +90: y turns to +z
    assert_transform(homogeneous_transform(rpy_deg=(90, 0, 0)),
                     np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1.0]]))
    # yaw +90: x turns left to +y; translation is the last column
    assert_transform(homogeneous_transform((1, 2, 3), (0, 0, 90)),
                     np.array([[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1.0]]))


def test_roll_is_applied_before_yaw() -> None:
    # Rz90 Rx90 = [[0,-1,0],[1,0,0],[0,0,1]] [[1,0,0],[0,0,-1],[0,1,0]]
    #           = [[0,0,1],[1,0,0],[0,1,0]]  (Rx90 Rz90 would be [[0,-1,0],[0,0,-1],[1,0,0]])
    assert_transform(homogeneous_transform(rpy_deg=(90, 0, 90)),
                     np.array([[0, 0, 1, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1.0]]))


def _urdf_quaternion_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's rpy quaternion (urdfdom_headers setFromRPY's formula) as a rotation matrix."""
    sr, cr = math.sin(roll / 2), math.cos(roll / 2)
    sp, cp = math.sin(pitch / 2), math.cos(pitch / 2)
    sy, cy = math.sin(yaw / 2), math.cos(yaw / 2)
    x = sr * cp * cy - cr * sp * sy
    y = cr * sp * cy + sr * cp * sy
    z = cr * cp * sy - sr * sp * cy
    w = cr * cp * cy + sr * sp * sy
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


angles = st.floats(min_value=-180, max_value=180, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(angles, angles, angles)
def test_rotation_matches_the_urdf_rpy_quaternion(roll: float, pitch: float, yaw: float) -> None:
    expected = _urdf_quaternion_matrix(*(math.radians(a) for a in (roll, pitch, yaw)))
    np.testing.assert_allclose(homogeneous_transform(rpy_deg=(roll, pitch, yaw))[:3, :3],
                               expected, atol=1e-12)


# --------------------------------------------------------------------- small models


def test_transform_through_a_chain(tmp_path: Path) -> None:
    model = GeometryModel.load(write_model(tmp_path))
    assert_transform(model.transformation("Box:Origin", "Arm:Tip"), ORIGIN_T_TIP)
    assert_transform(model.transformation("Box:Top", "Arm:Base"), TOP_T_BASE)
    # a point 1 m ahead of the tip lies at (1,2,1) + Rz180 (1,0,0) = (0, 2, 1)
    point = model.transformation("Box:Origin", "Arm:Tip") @ np.array([1.0, 0, 0, 1])
    np.testing.assert_allclose(point, [0, 2, 1, 1], atol=1e-12)


def test_edges_traversed_backwards_are_inverted(tmp_path: Path) -> None:
    model = GeometryModel.load(write_model(tmp_path))
    assert_transform(model.transformation("Arm:Tip", "Box:Origin"), TIP_T_ORIGIN)
    # ^Arm:Base T_Box:Top = inverse of TOP_T_BASE: Rz(-90), -Rz(-90)(1,0,0) = (0, 1, 0)
    assert_transform(model.transformation("Arm:Base", "Box:Top"),
                     np.array([[0, 1, 0, 0], [-1, 0, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1.0]]))
    # within one body, from a frame back to its reference: (0, 0, -1)
    assert_transform(model.transformation("Box:Top", "Box:Origin"),
                     np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -1], [0, 0, 0, 1.0]]))


def test_a_consistent_cycle_loads_and_agrees(tmp_path: Path) -> None:
    # The shortcut states ORIGIN_T_TIP directly: yaw 180, (1, 2, 1); a 0.4 mm survey
    # error is inside the 1 mm tolerance.
    survey = """  <constraint name="Survey" from="Box:Origin" to="Arm:Tip">
    <translation x="1" y="2.0004" z="1"/>
    <rotation yaw="180"/>
  </constraint>
"""
    model = GeometryModel.load(write_model(tmp_path, MOUNT + survey))
    assert_transform(model.transformation("Box:Origin", "Arm:Tip"), ORIGIN_T_TIP)
    assert_transform(model.transformation("Arm:Tip", "Box:Origin"), TIP_T_ORIGIN)
    assert [c.name for c in model.constraints()][-2:] == ["Mount", "Survey"]


def test_a_cycle_through_a_backwards_constraint(tmp_path: Path) -> None:
    # Written the other way round, Arm:Tip -> Box:Origin with TIP_T_ORIGIN, and before
    # Mount: the loop is still checked and closes.
    survey = """  <constraint name="Survey" from="Arm:Tip" to="Box:Origin">
    <translation x="1" y="2" z="-1"/>
    <rotation yaw="180"/>
  </constraint>
"""
    model = GeometryModel.load(write_model(tmp_path, survey + MOUNT))
    assert_transform(model.transformation("Box:Top", "Arm:Base"), TOP_T_BASE)


@pytest.mark.parametrize("attributes, message", [
    ('<translation x="1" y="2" z="1.01"/><rotation yaw="180"/>', "10.000 mm"),
    ('<translation x="1" y="2" z="1"/><rotation yaw="180.05"/>', "0.0500 deg"),
])
def test_an_inconsistent_cycle_is_rejected_with_file_and_line(
        tmp_path: Path, attributes: str, message: str) -> None:
    survey = (f'  <constraint name="BadSurvey" from="Box:Origin" to="Arm:Tip">\n'
              f"    {attributes}\n  </constraint>\n")
    assembly = write_model(tmp_path, MOUNT + survey)
    with pytest.raises(ConfigError) as caught:
        GeometryModel.load(assembly)
    text = str(caught.value)
    assert text.startswith(f"{assembly}:{line_of(assembly, 'BadSurvey')}: ")
    assert "'BadSurvey'" in text and message in text


def test_every_inconsistent_cycle_is_reported(tmp_path: Path) -> None:
    bad = ('  <constraint name="Bad{0}" from="Box:Origin" to="Arm:Tip">\n'
           '    <translation x="1" y="2" z="{1}"/><rotation yaw="180"/>\n  </constraint>\n')
    assembly = write_model(tmp_path, MOUNT + bad.format(1, 1.1) + bad.format(2, 0.9))
    with pytest.raises(ConfigError) as caught:
        GeometryModel.load(assembly)
    assert [p.split(": ")[0] for p in caught.value.problems] == [
        f"{assembly}:{line_of(assembly, 'Bad1')}", f"{assembly}:{line_of(assembly, 'Bad2')}"]


def test_unknown_names_raise_eoutofbounds_with_a_suggestion(tmp_path: Path) -> None:
    model = GeometryModel.load(write_model(tmp_path))
    with pytest.raises(EOutOfBounds, match="'Top'"):
        model.transformation("Box:Tpo", "Arm:Tip")
    with pytest.raises(EOutOfBounds, match="'Arm'"):
        model.transformation("Box:Top", "Amr:Tip")
    with pytest.raises(EOutOfBounds, match="'Box'"):
        model.frames("Bxo")
    for malformed in ("BoxTop", "Box:Top:Extra", ":Top", "Box:", "Bo x:Top"):
        with pytest.raises(EOutOfBounds):
            model.transformation(malformed, "Arm:Tip")
    assert issubclass(EOutOfBounds, ValueError)


def test_names_ignore_whitespace_around_the_colon(tmp_path: Path) -> None:
    model = GeometryModel.load(write_model(tmp_path))
    assert_transform(model.transformation(" Box : Origin ", "Arm:  Tip"), ORIGIN_T_TIP)
    assert normalize_frame_name("Raptor: Front-BumperCenter") == "Raptor:Front-BumperCenter"
    spaced = MOUNT.replace('from="Box:Top"', 'from="Box: Top"')
    model = GeometryModel.load(write_model(tmp_path, spaced))
    assert_transform(model.transformation("Box:Top", "Arm:Base"), TOP_T_BASE)


def test_lists(tmp_path: Path) -> None:
    model = GeometryModel.load(write_model(tmp_path))
    assert model.bodies() == ["Box", "Arm"]
    assert model.frames("Box") == ["Origin", "Top"]
    assert model.frames("Arm") == ["Base", "Tip"]
    assert model.body_type("Arm") == "Arm"
    assert model.name == "Test" and model.reference == "Box:Origin" and model.ground is None


def test_disconnected_parts(tmp_path: Path) -> None:
    assembly = write_model(tmp_path, "")
    with pytest.raises(ConfigError, match=r"no constraint connects body 'Arm'"):
        GeometryModel.load(assembly)
    model = GeometryModel.load(assembly, require_connected=False)
    assert_transform(model.transformation("Arm:Base", "Arm:Tip"),
                     np.array([[0, -1, 0, 2], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]))
    with pytest.raises(EOutOfBounds, match="no chain"):
        model.transformation("Box:Origin", "Arm:Tip")


def test_one_body_file_serves_two_instances(tmp_path: Path) -> None:
    second = '  <body name="Arm2" file="bodies/arm.xml"/>\n'
    # Arm2:Base 3 m to the left of Box:Origin, same orientation.
    mount2 = ('  <constraint name="Mount2" from="Box:Origin" to="Arm2:Base">\n'
              '    <translation y="3"/>\n  </constraint>\n')
    model = GeometryModel.load(write_model(tmp_path, MOUNT + mount2, extra_bodies=second))
    assert model.frames("Arm2") == ["Base", "Tip"]
    # ^Box:Origin T_Arm2:Tip: Rz90, (0,3,0) + (2,0,0) = (2,3,0)
    assert_transform(model.transformation("Box:Origin", "Arm2:Tip"),
                     np.array([[0, -1, 0, 2], [1, 0, 0, 3], [0, 0, 1, 0], [0, 0, 0, 1.0]]))


BAD_FILES = [
    # (constraints, box body file, needle on the offending line, which file, message)
    ('  <constraint name="C" from="Box:Top" to="Arm:Nope"/>\n', BOX, 'name="C"', "assembly",
     "has no frame 'Nope'"),
    ('  <constraint name="C" from="Box:Top" to="Box:Origin"/>\n', BOX, 'name="C"', "assembly",
     "different bodies"),
    ('  <constraint name="C" from="BoxTop" to="Arm:Base"/>\n', BOX, 'name="C"', "assembly",
     "exactly one ':'"),
    (MOUNT + MOUNT, BOX, None, "assembly", "declared twice"),
    ('  <constraint name="C" from="Box:Top" to="Arm:Base"><translation x="1,5"/>'
     "</constraint>\n", BOX, 'name="C"', "assembly", "not a decimal number"),
    ('  <constraint name="C" from="Box:Top" to="Arm:Base"><translation q="1"/>'
     "</constraint>\n", BOX, 'name="C"', "assembly", "no attribute 'q'"),
    (MOUNT, BOX.replace('<frame name="Origin"/>', '<frame name="Origin"><translation x="1"/>'
                        "</frame>"), 'name="Origin"', "box", "carries no"),
    (MOUNT, BOX.replace('<frame name="Origin"/>', ""), "<body", "box", "is not declared"),
    (MOUNT, BOX.replace('<frame name="Top">', '<frame name="Origin">'), 'name="Origin"><', "box",
     "declared twice"),
    (MOUNT, BOX.replace("</body>", "<frame name='x'>"), None, "box", "XML syntax error"),
]


@pytest.mark.parametrize("constraints, box, needle, where, message", BAD_FILES)
def test_bad_files_are_config_errors_with_file_and_line(
        tmp_path: Path, constraints: str, box: str, needle: str | None, where: str,
        message: str) -> None:
    assembly = write_model(tmp_path, constraints, box=box)
    file = assembly if where == "assembly" else tmp_path / "bodies" / "box.xml"
    with pytest.raises(ConfigError) as caught:
        GeometryModel.load(assembly)
    text = str(caught.value)
    assert message in text
    prefix = f"{file}:{line_of(file, needle)}: " if needle else f"{file}:"
    resolved = prefix.replace(str(file), str(file.resolve()))
    assert text.startswith(prefix) or text.startswith(resolved)


def test_missing_body_file_names_the_assembly_line(tmp_path: Path) -> None:
    assembly = write_model(tmp_path)
    (tmp_path / "bodies" / "arm.xml").unlink()
    with pytest.raises(ConfigError) as caught:
        GeometryModel.load(assembly)
    line = line_of(assembly, 'name="Arm"')
    assert str(caught.value).startswith(f"{assembly}:{line}: ")
    assert "arm.xml" in str(caught.value)


def test_a_dtd_internal_subset_is_refused(tmp_path: Path) -> None:
    assembly = write_model(tmp_path)
    text = assembly.read_text().replace(
        '<?xml version="1.0"?>\n',
        '<?xml version="1.0"?>\n<!DOCTYPE assembly [<!ENTITY big "Box:Top">]>\n')
    assembly.write_text(text.replace('from="Box:Top"', 'from="&big;"'))
    with pytest.raises(ConfigError, match="DTD"):
        GeometryModel.load(assembly)


def test_an_external_entity_is_not_fetched(tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("Box:Top")
    assembly = write_model(tmp_path)
    text = assembly.read_text().replace(
        '<?xml version="1.0"?>\n',
        f'<?xml version="1.0"?>\n<!DOCTYPE assembly [<!ENTITY s SYSTEM "{secret}">]>\n')
    assembly.write_text(text)
    with pytest.raises(ConfigError):
        GeometryModel.load(assembly)


# --------------------------------------------------------------------- the Raptor


@pytest.fixture(scope="module")
def raptor() -> GeometryModel:
    return GeometryModel.load(RAPTOR)


SEED_FRAMES = ["Raptor: Front-BumperCenter", "FrontNoddingSICKLeft: AxleCenterFreeEnd",
               "FrontNoddingSICKRight: AxleCenterFreeEnd", "Digiclops:ImagePlane"]


def test_raptor_model_loads(raptor: GeometryModel) -> None:
    assert raptor.bodies() == ["Raptor", "FrontNoddingSICKLeft", "FrontNoddingSICKRight",
                               "Digiclops", "GpsAntenna", "Imu"]
    assert raptor.reference == "Raptor:RearAxleCenter" and raptor.ground == "Raptor:Ground"
    assert raptor.frames("FrontNoddingSICKLeft") == ["Base", "AxleCenterFreeEnd",
                                                     "AxleDriveEnd"]


@pytest.mark.parametrize("frame", SEED_FRAMES)
def test_every_frame_the_seed_names_exists(raptor: GeometryModel, frame: str) -> None:
    body, name = (part.strip() for part in frame.split(":"))
    assert name in raptor.frames(body)
    assert_transform(raptor.transformation(frame, frame), np.eye(4))


def test_left_laser_axle_is_two_metres_above_ground(raptor: GeometryModel) -> None:
    # Ground is 0.33 m below the rear axle; LaserMountLeft (2.20, 0.35, 1.555), toe-out
    # yaw +5 deg; AxleCenterFreeEnd 0.115 m above the mount: z = 0.33 + 1.555 + 0.115 = 2.
    c5, s5 = 0.9961946980917455, 0.08715574274765817  # cos 5 deg, sin 5 deg
    expected = np.array([[c5, -s5, 0, 2.20], [s5, c5, 0, 0.35], [0, 0, 1, 2.00], [0, 0, 0, 1]])
    np.testing.assert_allclose(
        raptor.transformation("Raptor:Ground", "FrontNoddingSICKLeft: AxleCenterFreeEnd"),
        expected, atol=1e-12)
    right = raptor.transformation("Raptor:Ground", "FrontNoddingSICKRight:AxleCenterFreeEnd")
    np.testing.assert_allclose(right[:3, 3], [2.20, -0.35, 2.00], atol=1e-12)
    np.testing.assert_allclose(right[:3, 0], [c5, -s5, 0], atol=1e-12)


def test_laser_baseline_matches_the_calibrated_constraint(raptor: GeometryModel) -> None:
    # docs/geometry.md: Rz(-5 deg)(0, -0.70, 0) = (-0.061009, -0.697336, 0), yaw -10 deg
    t = raptor.transformation("FrontNoddingSICKLeft:AxleCenterFreeEnd",
                              "FrontNoddingSICKRight:AxleCenterFreeEnd")
    np.testing.assert_allclose(t[:3, 3], [-0.061009, -0.697336, 0], atol=1e-6)
    np.testing.assert_allclose(t[:2, 0], [math.cos(math.radians(-10)),
                                          math.sin(math.radians(-10))], atol=1e-12)


def test_bumper_gps_camera_and_imu_positions(raptor: GeometryModel) -> None:
    bumper = raptor.transformation("Raptor:Ground", "Raptor: Front-BumperCenter")
    np.testing.assert_allclose(bumper[:3, 3], [2.45, 0, 0.50], atol=1e-12)  # 0.5 m high
    gps = raptor.transformation("Raptor:Ground", "GpsAntenna:PhaseCenter")
    np.testing.assert_allclose(gps[:3, 3], [0.90, 0, 2.08], atol=1e-12)
    # Camera: optical axis (z) forward and 10 deg down, image x to the vehicle's right,
    # image y down-ish; origin CameraMount (2.05, 0, 1.45) + Ry(10)(0.03, -0.05, 0.06)
    #   = (2.05 + 0.03 c10 + 0.06 s10, -0.05, 1.45 - 0.03 s10 + 0.06 c10)
    camera = raptor.transformation("Raptor:RearAxleCenter", "Digiclops:ImagePlane")
    c10, s10 = 0.984807753012208, 0.17364817766693033
    expected = np.array([[0, -s10, c10, 2.05 + 0.03 * c10 + 0.06 * s10],
                         [-1, 0, 0, -0.05],
                         [0, -c10, -s10, 1.45 - 0.03 * s10 + 0.06 * c10],
                         [0, 0, 0, 1]])
    np.testing.assert_allclose(camera, expected, atol=1e-12)
    # IMU: NED-style axes, roll 180: x forward, y right, z down, at (0.95, 0, 0.4125)
    imu = raptor.transformation("Raptor:RearAxleCenter", "Imu:SensorCenter")
    np.testing.assert_allclose(imu, np.array([[1, 0, 0, 0.95], [0, -1, 0, 0],
                                              [0, 0, -1, 0.4125], [0, 0, 0, 1]]), atol=1e-12)


def test_raptor_round_trips_are_identity(raptor: GeometryModel) -> None:
    names = [f"{body}:{frame}" for body in raptor.bodies() for frame in raptor.frames(body)]
    for a, b in itertools.product(names, repeat=2):
        product = raptor.transformation(a, b) @ raptor.transformation(b, a)
        np.testing.assert_allclose(product, np.eye(4), atol=1e-12, err_msg=f"{a} / {b}")
    # composition through a third frame
    a, b, c = "Digiclops:ImagePlane", "Imu:SensorCenter", "FrontNoddingSICKRight:AxleDriveEnd"
    np.testing.assert_allclose(raptor.transformation(a, b) @ raptor.transformation(b, c),
                               raptor.transformation(a, c), atol=1e-12)


def test_raptor_queries_return_fresh_arrays(raptor: GeometryModel) -> None:
    first = raptor.transformation("Raptor:Ground", "Imu:SensorCenter")
    first[:] = 0
    assert raptor.transformation("Raptor:Ground", "Imu:SensorCenter")[3, 3] == 1.0


def test_a_disturbed_raptor_survey_is_rejected(tmp_path: Path) -> None:
    # Copy the shipped model with the GPS survey 5 mm off: the loop through the chassis
    # must no longer close.
    (tmp_path / "bodies").mkdir()
    for body in (RAPTOR.parent / "bodies").glob("*.xml"):
        (tmp_path / "bodies" / body.name).write_bytes(body.read_bytes())
    text = RAPTOR.read_text()
    assert '<translation x="0.90" y="0" z="2.08"/>' in text
    assembly = tmp_path / "raptor.xml"
    assembly.write_text(text.replace('<translation x="0.90" y="0" z="2.08"/>',
                                     '<translation x="0.90" y="0" z="2.085"/>'))
    with pytest.raises(ConfigError) as caught:
        GeometryModel.load(assembly)
    line = line_of(assembly, 'name="GpsAntennaSurvey"')
    assert str(caught.value).startswith(f"{assembly}:{line}: ")
    assert "5.000 mm" in str(caught.value)
