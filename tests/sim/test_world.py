"""World files: parsing, validation errors with file:line, geodesy, shipped worlds."""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from afa.errors import ConfigError
from afa.sim import (
    DriveCommand,
    Origin,
    Terrain,
    VehicleStart,
    load_world,
    parse_world,
    run_drive,
)

ROOT = Path(__file__).resolve().parents[2]
WORLDS = ROOT / "configs" / "worlds"
SHIPPED = ["open-field", "rock-field", "ditch-crossing", "slalom"]

GOOD = b"""<?xml version="1.0"?>
<world name="test">
  <origin latitude="50.2717" longitude="-111.1766" elevation="750.0"/>
  <terrain width="240" depth="80" resolution="0.2" roughness="0.03" seed="7">
    <slope east="0.02" north="-0.01"/>
  </terrain>
  <obstacle type="box" east="30" north="5" length="2" width="1" height="1.2" heading="45"/>
  <obstacle type="cylinder" east="40" north="-3" radius="0.5" height="0.8"/>
  <obstacle type="ditch" east="-20" north="0" length="6" width="1.5" depth="0.8" heading="90"/>
  <vehicle east="1" north="2" heading="90"/>
  <mission patrol="true">
    <waypoint latitude="50.2717" longitude="-111.1752"/>
    <waypoint east="20" north="-10"/>
  </mission>
  <drive>
    <command time="0" speed="1.5" steering="0"/>
    <command time="20" speed="1.5" steering="-10"/>
    <command time="40" speed="0" steering="0"/>
  </drive>
</world>
"""


def _write(tmp_path: Path, text: str | bytes, name: str = "w.xml") -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def _error(tmp_path: Path, text: str) -> ConfigError:
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_world(path)
    for line in info.value.problems:
        assert line.startswith(f"{path}:"), line
    return info.value


def _line_of(text: str, needle: str) -> int:
    for number, line in enumerate(text.splitlines(), start=1):
        if needle in line:
            return number
    raise AssertionError(needle)


# ------------------------------------------------------------------ parsing
def test_good_world_parses(tmp_path: Path) -> None:
    world = load_world(_write(tmp_path, GOOD))
    assert world.name == "test"
    assert world.origin == Origin(50.2717, -111.1766, 750.0)
    assert (world.terrain.width, world.terrain.depth, world.terrain.resolution) == (240, 80, 0.2)
    assert (world.terrain.slope_east, world.terrain.slope_north) == (0.02, -0.01)
    assert world.terrain.seed == 7 and world.terrain.roughness == 0.03
    box, cylinder, ditch = world.obstacles
    assert (box.type, box.length, box.width, box.height, box.heading) == ("box", 2, 1, 1.2, 45)
    assert (cylinder.type, cylinder.radius, cylinder.height) == ("cylinder", 0.5, 0.8)
    assert (ditch.type, ditch.depth, ditch.heading) == ("ditch", 0.8, 90)
    assert box.line == 7
    assert (world.vehicle.east, world.vehicle.north, world.vehicle.heading) == (1, 2, 90)
    assert world.mission.patrol is True
    assert [c.time for c in world.drive] == [0, 20, 40]
    assert world.command_at(-1) == (0.0, 0.0)
    assert world.command_at(0) == (1.5, 0.0)
    assert world.command_at(25.0) == (1.5, -10.0)
    assert world.command_at(99) == (0.0, 0.0)
    assert world.drive_duration == 40


def test_waypoints_in_both_coordinate_systems(tmp_path: Path) -> None:
    world = load_world(_write(tmp_path, GOOD))
    first, second = world.mission.waypoints
    # 0.0014 deg of longitude at 50.2717 N: (N + h) cos(lat) * dlon, N the prime
    # vertical radius of WGS84, computed here independently of the module.
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    lat = math.radians(50.2717)
    n_radius = a / math.sqrt(1 - e2 * math.sin(lat) ** 2)
    east = (n_radius + 750.0) * math.cos(lat) * math.sin(math.radians(0.0014))
    assert first.east == pytest.approx(east, abs=1e-6)
    assert abs(first.north) < 0.01  # tangent-plane drop-off over 100 m is sub-centimetre
    assert (second.east, second.north) == (20, -10)
    back = world.origin.to_local(second.latitude, second.longitude)
    assert back == pytest.approx((20, -10), abs=1e-6)


# ------------------------------------------------------------------ geodesy
def test_geodetic_to_ecef_matches_pymap3d_test_vector() -> None:
    # geospace-code/pymap3d src/pymap3d/tests/test_geodetic.py: lla0 -> xyz0
    x, y, z = Origin(42, -82, 200).ecef()
    assert (x, y, z) == pytest.approx((660675.2518247, -4700948.68316, 4245737.66222), abs=1e-3)


def test_enu_to_geodetic_matches_pymap3d_aer_test_vector() -> None:
    # pymap3d test_aer_geodetic: az 33, el 77, range 1000 from (42, -82, 200)
    # -> (42.0016981935, -81.99852, 1174.374035). AER -> ENU by hand:
    az, el, rng = math.radians(33), math.radians(77), 1000.0
    e = rng * math.cos(el) * math.sin(az)
    n = rng * math.cos(el) * math.cos(az)
    u = rng * math.sin(el)
    lat, lon, h = Origin(42, -82, 200).enu_to_geodetic(e, n, u)
    assert lat == pytest.approx(42.0016981935, abs=1e-9)
    assert lon == pytest.approx(-81.99852, abs=5e-6)  # published to 5 decimals
    assert h == pytest.approx(1174.374035, abs=1e-5)


def test_local_conversion_is_centimetre_accurate_over_a_kilometre() -> None:
    origin = Origin(50.2717, -111.1766, 750.0)
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    phi = math.radians(50.2717)
    meridian = a * (1 - e2) / (1 - e2 * math.sin(phi) ** 2) ** 1.5
    dphi = 1000.0 / (meridian + 750.0)  # one kilometre north, at the origin's height
    east, north = origin.to_local(50.2717 + math.degrees(dphi), -111.1766)
    assert north == pytest.approx(1000.0, abs=0.01)
    assert east == pytest.approx(0.0, abs=1e-6)
    for e, n in [(1000.0, 0.0), (-700.0, 700.0), (3.25, -999.0)]:
        lat, lon = origin.to_geodetic(e, n)
        assert origin.to_local(lat, lon) == pytest.approx((e, n), abs=1e-6)


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize(("mutation", "needle", "message"), [
    (('<vehicle east="1"', '<vehicle colour="red" east="1"'), "<vehicle",
     "unknown attribute 'colour'"),
    (('<drive>', '<drive><speedbump/>'), "<speedbump", "unknown element <speedbump>"),
    (('length="2" width="1"', 'length="two" width="1"'), 'length="two"', "not a number"),
    (('type="cylinder"', 'type="pyramid"'), 'type="pyramid"', "unknown type 'pyramid'"),
    (('radius="0.5" ', ''), 'type="cylinder"', "missing attribute 'radius'"),
    (('resolution="0.2"', 'resolution="-0.2"'), "<terrain", "must be > 0"),
    (('roughness="0.03"', 'roughness="nan"'), "<terrain", "must be finite"),
    (('time="20"', 'time="0"'), 'time="0" speed="1.5" steering="-10"', "must be later"),
    (('<waypoint east="20" north="-10"/>', '<waypoint east="20" latitude="50"/>'),
     'latitude="50"', "either latitude and longitude or east and north"),
    (('east="40" north="-3"', 'east="400" north="-3"'), 'east="400"', "outside the terrain"),
    (('patrol="true"', 'patrol="maybe"'), "<mission", "expected true or false"),
    (('seed="7"', 'seed="7.5"'), "<terrain", "not an integer"),
])
def test_errors_name_file_and_line(tmp_path: Path, mutation: tuple[str, str], needle: str,
                                   message: str) -> None:
    old, new = mutation
    text = GOOD.decode()
    assert old in text
    text = text.replace(old, new, 1)
    error = _error(tmp_path, text)
    line = _line_of(text, needle)
    assert any(p.startswith(f"{tmp_path / 'w.xml'}:{line}: ") and message in p
               for p in error.problems), error.problems


def test_all_problems_reported_at_once(tmp_path: Path) -> None:
    text = GOOD.decode().replace('height="0.8"', 'height="tall"').replace(
        'heading="90"/>\n  <mission', 'heading="north"/>\n  <mission')
    error = _error(tmp_path, text)
    assert len(error.problems) == 2
    assert "height='tall'" in error.problems[0] and "heading='north'" in error.problems[1]


def test_missing_origin_and_wrong_root(tmp_path: Path) -> None:
    error = _error(tmp_path, '<world name="x">\n<terrain width="10" depth="10"/>\n</world>')
    assert error.problems == [f"{tmp_path / 'w.xml'}:1: <world> needs an <origin> element"]
    error = _error(tmp_path, "<config/>")
    assert "root element must be <world>" in str(error)


def test_syntax_error_line(tmp_path: Path) -> None:
    error = _error(tmp_path, '<world name="x">\n<origin latitude="1" longitude="2">\n</world>')
    # reported where the cause is: <origin> on line 2 is never closed (</world> on line 3
    # is only where the parser noticed)
    assert re.match(rf"{re.escape(str(tmp_path / 'w.xml'))}:2: XML syntax error", str(error))
    assert "<origin>" in str(error) and "line 3" in str(error)


def test_dtd_and_entities_refused(tmp_path: Path) -> None:
    text = ('<?xml version="1.0"?>\n<!DOCTYPE world [<!ENTITY big "0.5">]>\n'
            '<world name="x"><origin latitude="1" longitude="&big;"/>'
            '<terrain width="10" depth="10"/></world>')
    error = _error(tmp_path, text)
    assert "DTD" in str(error)
    external = ('<?xml version="1.0"?>\n<!DOCTYPE world SYSTEM "file:///etc/passwd">\n'
                '<world name="x"><origin latitude="1" longitude="&xxe;"/></world>')
    _error(tmp_path, external)


def test_missing_and_oversized_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.xml:0: cannot read"):
        load_world(tmp_path / "nope.xml")
    with pytest.raises(ConfigError, match="limit"):
        parse_world(b" " * (4 * 1024 * 1024 + 1), "big.xml")


# ------------------------------------------------------------------ shipped worlds
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_world_loads_and_drive_script_is_collision_free(name: str) -> None:
    world = load_world(WORLDS / f"{name}.xml")
    assert world.name == name
    assert world.mission.waypoints and world.drive
    terrain = Terrain.from_spec(world.terrain, world.obstacles)
    result = run_drive(world, terrain)
    assert result.collision is None, result.collision
    course = result.states[-1].distance
    assert 100.0 <= course <= 150.0
    assert result.states[-1].speed == 0.0
    track = result.track
    for waypoint in world.mission.waypoints:  # the script visits the mission
        gap = np.hypot(track[:, 0] - waypoint.east, track[:, 1] - waypoint.north).min()
        assert gap < 0.5, (waypoint, gap)


def test_ditch_crossing_direct_route_is_blocked() -> None:
    world = load_world(WORLDS / "ditch-crossing.xml")
    straight = replace(world, drive=(DriveCommand(0.0, 1.5, 0.0),))
    result = run_drive(straight, duration=80.0)
    assert result.collision is not None
    assert result.collision.kind == "ditch"
    assert world.obstacles[result.collision.obstacle].type == "ditch"
    assert all(w.east > world.obstacles[0].east for w in world.mission.waypoints)


def test_slalom_gates_straddle_the_drive() -> None:
    world = load_world(WORLDS / "slalom.xml")
    track = run_drive(world).track
    posts = [o for o in world.obstacles if o.type == "cylinder"]
    assert len(posts) >= 10
    # a straight drive along the course's centre line hits a post
    centre = (max(o.north for o in posts) + min(o.north for o in posts)) / 2
    straight = replace(world, vehicle=VehicleStart(world.vehicle.east, centre, 90.0),
                       drive=(DriveCommand(0.0, 1.5, 0.0),))
    blocked = run_drive(straight, duration=60.0)
    assert blocked.collision is not None and blocked.collision.kind == "obstacle"
    assert track[:, 1].max() - track[:, 1].min() > 4.0


# ------------------------------------------------------------------ docs
def test_docs_examples_run() -> None:
    text = (ROOT / "docs" / "worlds.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks
    for block in blocks:
        namespace: dict[str, object] = {"__name__": "docs_example", "ROOT": ROOT}
        exec(compile(block, "<docs/worlds.md>", "exec"), namespace)
