"""Hostile input files: configuration, geometry model and world files.

Every file afa reads goes through one hardened reader (``afa.config.miro.read_bounded``
and ``parse_xml``) and a validator. Whatever the file holds, loading it either succeeds
or raises :class:`~afa.errors.ConfigError` whose every line starts ``<file>:<line>:``;
never another exception, never unbounded memory or work:

- at most limit + 1 bytes are read from any file: a regular file, a FIFO, ``/dev/zero``;
- world files have ranges for every number and bounds on counts, on the terrain grid
  and on the work of rasterising obstacles (per obstacle and per file);
- mutated copies of the shipped files (attribute values and structure, seeded) load or
  fail with such a ConfigError, and a world that loads builds its terrain.
"""

from __future__ import annotations

import copy
import importlib
import os
import pkgutil
import random
import re
import shutil
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from lxml import etree

import components
from afa.config.loader import load_configuration
from afa.config.miro import MAX_ELEMENTS, MAX_FILE_BYTES, read_bounded
from afa.errors import ConfigError
from afa.sim import Terrain, load_world
from afa.sim.world import (
    MAX_DRIVE_COMMANDS,
    MAX_DRIVE_TIME,
    MAX_OBSTACLE_CELLS,
    MAX_OBSTACLES,
    MAX_RASTER_CELLS,
    MAX_TERRAIN_CELLS,
    MAX_WAYPOINTS,
    MAX_WORLD_BYTES,
    World,
    raster_cells,
)
from components.model_server.geometry import MAX_BODIES, GeometryModel
from components.model_server.geometry import MAX_FILE_BYTES as MAX_GEOMETRY_BYTES

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
WORLDS = sorted((CONFIGS / "worlds").glob("*.xml"))
ASSEMBLY = CONFIGS / "050917raptor01.XML"

# Every parameter model of this tree, so the configuration validates fully (imported
# directly: the installed entry points may name components of another checkout).
for _module in pkgutil.iter_modules(components.__path__):
    if _module.ispkg:
        importlib.import_module(f"components.{_module.name}.parameters")


def _loads_or_config_error(load: Callable[[Path], Any], path: Path,
                           files: tuple[Path, ...] = ()) -> Any:
    """Load ``path``; a ConfigError must name a file and a line on each of its lines."""
    names = "|".join(re.escape(str(p)) for p in (path, *files))
    try:
        return load(path)
    except ConfigError as error:
        assert error.problems, error
        for problem in error.problems:
            assert re.match(rf"({names}):\d+: ", problem), problem
        return error


def _load_error(load: Callable[[Path], Any], path: Path) -> ConfigError:
    result = _loads_or_config_error(load, path)
    assert isinstance(result, ConfigError), f"{path} loaded"
    return result


LOADERS: dict[str, tuple[Callable[[Path], Any], int]] = {
    "configuration": (load_configuration, MAX_FILE_BYTES),
    "geometry": (GeometryModel.load, MAX_GEOMETRY_BYTES),
    "world": (load_world, MAX_WORLD_BYTES),
}


# --------------------------------------------------------------------------------------
# Size: at most limit + 1 bytes read, whatever the file is
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", list(LOADERS))
def test_dev_zero_is_refused_after_the_limit(kind: str) -> None:
    load, limit = LOADERS[kind]
    error = _load_error(load, Path("/dev/zero"))
    assert f"{limit}" in str(error) and "/dev/zero:1:" in str(error)


@pytest.mark.parametrize("kind", list(LOADERS))
def test_endless_fifo_is_refused_after_the_limit(kind: str, tmp_path: Path) -> None:
    load, limit = LOADERS[kind]
    fifo = tmp_path / "endless.xml"
    os.mkfifo(fifo)
    written = [0]
    cap = limit + (8 << 20)  # the writer gives up after this much: a reader ignoring the
                             # limit would otherwise never finish

    def writer() -> None:
        chunk = b"<!-- " + b"x" * 65_000 + b" -->"
        try:
            with open(fifo, "wb") as pipe:
                while written[0] < cap:
                    pipe.write(chunk)
                    written[0] += len(chunk)
        except BrokenPipeError:
            pass  # the reader stopped reading: what we want

    thread = threading.Thread(target=writer, daemon=True)
    thread.start()
    error = _load_error(load, fifo)
    thread.join(timeout=30)
    assert not thread.is_alive()
    assert f"{limit}" in str(error)
    # the reader stopped at the limit: the pipe and the writer's buffer hold the rest
    assert written[0] < limit + (2 << 20), written[0]


def test_world_from_a_fifo_loads(tmp_path: Path) -> None:
    fifo = tmp_path / "world.xml"
    os.mkfifo(fifo)
    data = WORLDS[0].read_bytes()

    def writer() -> None:
        with open(fifo, "wb") as pipe:
            pipe.write(data)

    thread = threading.Thread(target=writer, daemon=True)
    thread.start()
    world = load_world(fifo)
    thread.join(timeout=30)
    assert isinstance(world, World) and world.obstacles


def test_read_bounded_reads_at_most_limit_plus_one(tmp_path: Path) -> None:
    path = tmp_path / "f"
    path.write_bytes(b"a" * 10)
    assert read_bounded(path, 10) == b"a" * 10
    with pytest.raises(ConfigError, match=r"f:1: file is 10 bytes; the limit is 9"):
        read_bounded(path, 9)


# --------------------------------------------------------------------------------------
# World files: ranges, counts and work
# --------------------------------------------------------------------------------------

WORLD = """<?xml version="1.0"?>
<world name="t">
  <origin latitude="50.27" longitude="-111.17" elevation="{elevation}"/>
  <terrain width="{width}" depth="{width}" resolution="{resolution}"/>
{obstacles}
  <vehicle east="0" north="0" heading="{heading}"/>
  <drive><command time="0" speed="1" steering="0"/>
         <command time="{time}" speed="0" steering="0"/></drive>
</world>
"""


def _world(tmp_path: Path, obstacles: str = "", *, elevation: str = "750", width: str = "100",
           resolution: str = "0.5", heading: str = "90", time: str = "10") -> Path:
    path = tmp_path / "w.xml"
    path.write_text(WORLD.format(obstacles=obstacles, elevation=elevation, width=width,
                                 resolution=resolution, heading=heading, time=time))
    return path


def _line(path: Path, needle: str) -> int:
    return next(i for i, text in enumerate(path.read_text().splitlines(), 1) if needle in text)


@pytest.mark.parametrize("obstacle", [
    '<obstacle type="cylinder" east="0" north="0" radius="1e308" height="1"/>',
    '<obstacle type="box" east="0" north="0" length="1e308" width="1" height="1"/>',
    '<obstacle type="ditch" east="0" north="0" length="2" width="1e300" depth="1"/>',
    '<obstacle type="box" east="0" north="0" length="1" width="1" height="1e308"/>',
    '<obstacle type="ditch" east="0" north="0" length="2" width="1" depth="1e308"/>',
    '<obstacle type="box" east="0" north="0" length="1" width="1" height="1" heading="1e308"/>',
    # far off the terrain: reported as such, not rasterised (an OverflowError escaped)
    '<obstacle type="box" east="1e308" north="0" length="1" width="1" height="1"/>',
    '<obstacle type="cylinder" east="0" north="-1e308" radius="1" height="1"/>',
])
def test_obstacle_sizes_have_an_upper_bound(tmp_path: Path, obstacle: str) -> None:
    path = _world(tmp_path, "  " + obstacle)
    error = _load_error(load_world, path)
    assert str(error).startswith(f"{path}:{_line(path, '<obstacle')}: "), error


@pytest.mark.parametrize("attributes", [
    {"elevation": "1e308"}, {"elevation": "-1e6"}, {"heading": "1e308"},
    {"time": "1e300"}, {"time": str(MAX_DRIVE_TIME * 2)},
])
def test_world_numbers_have_ranges(tmp_path: Path, attributes: dict[str, str]) -> None:
    _load_error(load_world, _world(tmp_path, **attributes))


@pytest.mark.parametrize("latitude", ["85", "-85", "84", "-80"])
def test_the_origin_lies_where_utm_does(tmp_path: Path, latitude: str) -> None:
    """The receiver and the pose frame are in UTM, which ends at 84 N and 80 S: a world
    beyond it loaded, and its run then failed in the simulated receiver."""
    path = _world(tmp_path)
    text = re.sub(r'latitude="[^"]*"', f'latitude="{latitude}"', path.read_text(), count=1)
    path.write_text(text)
    error = _load_error(load_world, path)
    assert str(error).startswith(f"{path}:{_line(path, '<origin')}: "), error


@pytest.mark.parametrize("section,name,value,message", [
    ("NodLaserConfig", "Motorrates", "inf",
     "NodLaserConfig/Laser11/Motorrates: Input should be a finite number"),
    ("PurePursuit", "Lookahead", "nan", "PurePursuit/Lookahead: Input should be a finite"),
    ("PurePursuit", "Lookahead", "1e308",
     "Launcher purePursuit: section 'PurePursuit' cannot configure PurePursuit"),
    ("GlobalMapConfig", "Gridsize", "10", "cells, more than 4,194,304"),
    ("Robot", "Name", "", "Robot/Name: the robot's name"),
    ("Launcher", "Period", "1e9", "Period: Input should be less than or equal to 600"),
])
def test_configured_numbers_that_would_break_a_component_are_refused(
        tmp_path: Path, section: str, name: str, value: str, message: str) -> None:
    """Values that used to load and then fail in a constructor with a traceback, allocate
    hundreds of gigabytes (a 1 cm planning grid), or hold start-up for ever (a Launcher
    Period of 1e9 s, which no signal interrupted): each a ConfigError at its line."""
    from afa.assembly import build_components

    lines = (CONFIGS / "raptor.xml").read_text().splitlines(keepends=True)
    first = next(i for i, line in enumerate(lines) if f'<section name="{section}"' in line)
    at = next(i for i in range(first, len(lines)) if f'name="{name}"' in lines[i])
    lines[at] = re.sub(r'value="[^"]*"', f'value="{value}"', lines[at])
    path = tmp_path / "raptor.xml"
    path.write_text("".join(lines))
    shutil.copy(CONFIGS / "050917raptor01.XML", tmp_path)
    shutil.copytree(CONFIGS / "bodies", tmp_path / "bodies")
    with pytest.raises(ConfigError) as caught:
        build_components(load_configuration(path))
    assert message in str(caught.value), caught.value
    assert any(line.startswith(f"{path}:") for line in str(caught.value).splitlines())


def test_too_many_obstacles_is_a_config_error(tmp_path: Path) -> None:
    one = '  <obstacle type="cylinder" east="1" north="1" radius="0.2" height="1"/>\n'
    path = _world(tmp_path, one * (MAX_OBSTACLES + 1))
    error = _load_error(load_world, path)
    assert len(error.problems) == 1
    excess_line = _line(path, "<obstacle") + MAX_OBSTACLES
    assert error.problems[0].startswith(f"{path}:{excess_line}: "), error.problems[0]
    assert f"{MAX_OBSTACLES}" in error.problems[0]


def test_more_obstacles_than_the_id_grid_holds_is_a_config_error(tmp_path: Path) -> None:
    one = '<obstacle type="cylinder" east="1" north="1" radius="0.2" height="1"/>\n'
    _load_error(load_world, _world(tmp_path, one * 32_768))


def test_terrain_grid_is_bounded(tmp_path: Path) -> None:
    side = int((MAX_TERRAIN_CELLS ** 0.5) * 0.1) + 10  # just over the limit at 0.1 m
    error = _load_error(load_world, _world(tmp_path, width=str(side), resolution="0.1"))
    assert "cells" in str(error)


def test_rasterisation_work_per_obstacle_is_bounded(tmp_path: Path) -> None:
    # a valid file whose one obstacle covers the whole of a large grid
    big = '  <obstacle type="cylinder" east="0" north="0" radius="190" height="1"/>'
    path = _world(tmp_path, big, width="400", resolution="0.1")
    error = _load_error(load_world, path)
    assert str(error).startswith(f"{path}:{_line(path, '<obstacle')}: ")
    assert "grid samples" in str(error)


def test_rasterisation_work_per_file_is_bounded(tmp_path: Path) -> None:
    # each obstacle within its own bound, but together more than a file may ask for
    side = 2 * int((MAX_OBSTACLE_CELLS ** 0.5) * 0.1 / 2) - 2  # square footprint, in m
    one = (f'  <obstacle type="box" east="0" north="0" length="{side}" width="{side}" '
           'height="1"/>\n')
    count = MAX_RASTER_CELLS // MAX_OBSTACLE_CELLS + 2
    path = _world(tmp_path, one * count, width="400", resolution="0.1")
    error = _load_error(load_world, path)
    assert "grid samples" in str(error) and len(error.problems) == 1


def test_the_largest_allowed_world_loads_within_its_work_bound(tmp_path: Path) -> None:
    # the most obstacles a file may hold, each about as large as the per-file budget allows
    radius = ((MAX_RASTER_CELLS / MAX_OBSTACLES) ** 0.5 - 3) * 0.5 / 2 * 0.95
    rng = random.Random(3)
    lines = [f'  <obstacle type="cylinder" east="{rng.uniform(-90, 90):.1f}" '
             f'north="{rng.uniform(-90, 90):.1f}" radius="{radius:.2f}" height="1"/>\n'
             for _ in range(MAX_OBSTACLES)]
    world = load_world(_world(tmp_path, "".join(lines), width="200", resolution="0.5"))
    assert len(world.obstacles) == MAX_OBSTACLES
    assert sum(raster_cells(o, world.terrain) for o in world.obstacles) <= MAX_RASTER_CELLS


def test_counts_of_waypoints_and_drive_commands_are_bounded(tmp_path: Path) -> None:
    text = WORLD.format(obstacles="", elevation="0", width="100", resolution="1",
                        heading="0", time="1")
    waypoints = "<mission>" + '<waypoint east="1" north="1"/>' * (MAX_WAYPOINTS + 1) + "</mission>"
    path = tmp_path / "w.xml"
    path.write_text(text.replace("<drive>", waypoints + "<drive>", 1))
    _load_error(load_world, path)
    commands = "".join(f'<command time="{i}" speed="0" steering="0"/>'
                       for i in range(MAX_DRIVE_COMMANDS + 1))
    path.write_text(re.sub(r"<drive>.*</drive>", f"<drive>{commands}</drive>", text,
                           flags=re.DOTALL))
    _load_error(load_world, path)


# --------------------------------------------------------------------------------------
# Mutating the shipped files
# --------------------------------------------------------------------------------------

NASTY_VALUES = [
    "1e308", "-1e308", "1e999", "-1e999", "1e-320", "nan", "NaN", "inf", "-inf", "", " ",
    "0", "-0", "-1", "0.0000001", "9" * 400, "1" * 5000, "0x10", "1_000", "+5", " 7 ",
    "3.5", "-90", "360", "720", "32768", "65536", "4294967296", "-2147483649", "true",
    "yes", "\u00e9t\u00e9", "a:b", "Raptor:Nowhere", "../../etc/passwd", "x" * 300,
]


def _random_value(rng: random.Random) -> str:
    choice = rng.random()
    if choice < 0.5:
        return rng.choice(NASTY_VALUES)
    if choice < 0.75:
        return repr(rng.uniform(-1e4, 1e4) * 10.0 ** rng.randint(-6, 6))
    return str(rng.randint(-10 ** rng.randint(1, 12), 10 ** rng.randint(1, 12)))


def _mutate_tree(root: etree._Element, rng: random.Random) -> None:
    """One mutation in place: half of them a new value for an existing attribute."""
    elements = [e for e in root.iter() if isinstance(e.tag, str)]
    names = sorted({name for e in elements for name in e.attrib}) or ["value"]
    tags = sorted({e.tag for e in elements})
    action = rng.randrange(12)
    element = rng.choice(elements)
    if action < 6:  # a new value for an attribute
        element = rng.choice([e for e in elements if e.attrib] or elements)
        element.set(rng.choice(list(element.attrib) or names), _random_value(rng))
    elif action == 6 and element.attrib:  # an attribute removed
        del element.attrib[rng.choice(list(element.attrib))]
    elif action == 7:  # an attribute of another element, or an unknown one, added
        element.set(rng.choice(names + ["colour"]), _random_value(rng))
    elif action == 8 and element is not root:  # an element removed
        element.getparent().remove(element)
    elif action == 9 and element is not root:  # an element repeated
        for _ in range(rng.randint(1, 4)):
            element.addnext(copy.deepcopy(element))
    elif action == 10:  # an element renamed
        element.tag = rng.choice(tags + ["bogus"])
    else:  # an element moved into another, or given text
        target = rng.choice(elements)
        if element is not root and target is not element \
                and element not in target.iterancestors():
            target.append(element)
        else:
            element.text = rng.choice(["text", "12", "\n"])


def mutated(source: bytes, rng: random.Random, prepare: Callable[[etree._Element], None]
            | None = None) -> bytes:
    """A mutated copy of an XML file: 1-3 tree mutations, sometimes a damaged byte or a
    truncation on top."""
    root = etree.fromstring(source)
    if prepare is not None:
        prepare(root)
    for _ in range(rng.randint(1, 3)):
        _mutate_tree(root, rng)
    data = bytearray(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
    if rng.random() < 0.1:
        data[rng.randrange(len(data))] = rng.randrange(256)
    if rng.random() < 0.05:
        del data[rng.randrange(len(data)):]
    return bytes(data)


def _coarse(root: etree._Element) -> None:
    """Shipped worlds at 1 m resolution, so that building each mutant's terrain is quick."""
    for terrain in root.iter("terrain"):
        terrain.set("resolution", "1.0")


@pytest.mark.parametrize("source", WORLDS, ids=lambda p: p.stem)
def test_mutated_worlds_load_or_fail_with_file_and_line(source: Path, tmp_path: Path) -> None:
    rng = random.Random(source.stem)
    path = tmp_path / source.name
    loaded = 0
    for _ in range(200):
        path.write_bytes(mutated(source.read_bytes(), rng, _coarse))
        world = _loads_or_config_error(load_world, path)
        if isinstance(world, ConfigError):
            continue
        loaded += 1
        # the loader's bounds hold for whatever loaded ...
        terrain = world.terrain
        cells = (terrain.width / terrain.resolution + 1) * (terrain.depth / terrain.resolution + 1)
        assert cells <= MAX_TERRAIN_CELLS
        assert sum(raster_cells(o, terrain) for o in world.obstacles) <= MAX_RASTER_CELLS
        assert len(world.obstacles) <= MAX_OBSTACLES
        assert world.drive_duration <= MAX_DRIVE_TIME
        # ... and the terrain builds (kept small enough to do it every time)
        if cells <= 250_000:
            built = Terrain.from_spec(world.terrain, world.obstacles)
            assert built.surface.shape == (built.ny, built.nx)
    assert loaded >= 10  # the mutator does not only produce broken files


def test_mutated_configurations_load_or_fail_with_file_and_line(tmp_path: Path) -> None:
    source = (CONFIGS / "raptor.xml").read_bytes()
    rng = random.Random("raptor.xml")
    path = tmp_path / "raptor.xml"
    loaded = 0
    for _ in range(300):
        path.write_bytes(mutated(source, rng))
        if not isinstance(_loads_or_config_error(load_configuration, path), ConfigError):
            loaded += 1
    assert loaded >= 10


def test_mutated_geometry_files_load_or_fail_with_file_and_line(tmp_path: Path) -> None:
    model = tmp_path / "model"
    shutil.copytree(CONFIGS / "bodies", model / "bodies")
    assembly = model / ASSEMBLY.name
    originals = {assembly: ASSEMBLY.read_bytes()}
    originals |= {model / "bodies" / p.name: p.read_bytes()
                  for p in (CONFIGS / "bodies").glob("*.xml")}
    files = tuple(originals)
    rng = random.Random("geometry")
    loaded = 0
    for path, data in originals.items():
        path.write_bytes(data)
    for _ in range(300):
        victim = rng.choice(files)
        victim.write_bytes(mutated(originals[victim], rng))
        result = _loads_or_config_error(GeometryModel.load, assembly, files)
        if not isinstance(result, ConfigError):
            loaded += 1
            for name in result.frame_names()[:3]:
                transform = result.transformation(result.frame_names()[0], name)
                assert transform.shape == (4, 4) and bool((abs(transform) < 1e9).all())
        victim.write_bytes(originals[victim])
    assert loaded >= 10


def _model(tmp_path: Path) -> Path:
    model = tmp_path / "model"
    shutil.copytree(CONFIGS / "bodies", model / "bodies")
    shutil.copy(ASSEMBLY, model / ASSEMBLY.name)
    return model / ASSEMBLY.name


@pytest.mark.parametrize(("old", "new"), [
    ('yaw="5"', 'yaw="1e300"'), ('yaw="5"', 'yaw="nan"'), ('x="0"', 'x="1e999"'),
    ('x="0"', 'x="1e308"'),
])
def test_geometry_numbers_must_be_finite_and_in_range(tmp_path: Path, old: str,
                                                       new: str) -> None:
    assembly = _model(tmp_path)
    text = assembly.read_text()
    assert old in text
    assembly.write_text(text.replace(old, new, 1))
    error = _load_error(GeometryModel.load, assembly)
    assert str(error).startswith(f"{assembly}:{_line(assembly, new)}: "), error


def test_geometry_counts_are_bounded(tmp_path: Path) -> None:
    assembly = _model(tmp_path)
    bodies = "".join(f'<body name="Extra{i}" file="bodies/gps_antenna.xml"/>\n'
                     for i in range(MAX_BODIES + 1))
    assembly.write_text(assembly.read_text().replace("<constraint ", bodies + "<constraint ", 1))
    error = _load_error(GeometryModel.load, assembly)
    assert f"more than {MAX_BODIES} bodies" in str(error)


def test_configuration_element_count_is_bounded(tmp_path: Path) -> None:
    # each element may cost a validation error with a spelling suggestion: bound them
    source = (CONFIGS / "raptor.xml").read_text()
    start = source.index('<instance name="Laser11"')
    start = source.index(">", start) + 1
    extra = "".join(f'\n<parameter name="Unknown{i}" value="1"/>' for i in range(MAX_ELEMENTS))
    path = tmp_path / "raptor.xml"
    path.write_text(source[:start] + extra + source[start:])
    error = _load_error(load_configuration, path)
    parser = etree.XMLParser(remove_comments=True)  # as the reader does
    first_excess = list(etree.parse(path, parser).getroot().iter())[MAX_ELEMENTS]
    assert error.problems == [f"{path}:{first_excess.sourceline}: more than {MAX_ELEMENTS} "
                              "elements (the limit; the Raptor's configuration has 400)"]


def test_a_world_lists_at_most_a_hundred_problems(tmp_path: Path) -> None:
    bad = '  <obstacle type="cylinder" east="x" north="0" radius="1" height="1"/>\n'
    path = _world(tmp_path, bad * 500)
    error = _load_error(load_world, path)
    assert len(error.problems) == 101
    first_omitted = _line(path, "<obstacle") + 100
    assert error.problems[-1] == (f"{path}:{first_omitted}: ... and 400 more problems (only "
                                  "the first 100 are listed)")


@pytest.mark.parametrize("geometry", ["/dev/zero", "missing.XML"])
def test_a_bad_geometry_file_is_a_file_line_message_without_a_traceback(geometry, tmp_path):
    """The vehicle geometry file ModelServer reads is an input file like the others: a
    bad one fails the run with its ``file:line:`` message, never a traceback (which the
    log of the failing component used to print)."""
    root = Path(__file__).resolve().parents[2]
    config = tmp_path / "raptor.xml"
    config.write_text((root / "configs" / "raptor.xml").read_text().replace(
        'value="050917raptor01.XML"', f'value="{geometry}"'))
    result = subprocess.run(
        [sys.executable, "-m", "afa", "run", str(config), "--sim", "--fast", "--duration",
         "1"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 1, result.stderr
    shown = geometry if geometry.startswith("/") else str(tmp_path / geometry)
    assert f"modelServer: ConfigError: {shown}:" in result.stderr, result.stderr
    assert "Traceback" not in result.stderr, result.stderr
