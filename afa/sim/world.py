"""World files: the simulated Raptor's terrain, obstacles, start pose, mission and drive script.

A world file is a small XML document (``docs/worlds.md``)::

    <world name="open-field">
      <origin latitude="50.2717" longitude="-111.1766" elevation="750.0"/>
      <terrain width="200" depth="200" resolution="0.1" roughness="0.03" seed="7">
        <slope east="0.02" north="0.0"/>
      </terrain>
      <obstacle type="box" east="30" north="5" length="2" width="2" height="1.2" heading="0"/>
      <vehicle east="0" north="0" heading="90"/>
      <mission patrol="false"> <waypoint east="120" north="40"/> </mission>
      <drive> <command time="0" speed="1.5" steering="0"/> </drive>
    </world>

:func:`load_world` reads it with a hardened lxml parser (no DTD, no entities, no network,
a size limit) into frozen dataclasses, collecting every problem as a ``file:line: message``
line of one :class:`~afa.errors.ConfigError`. A file that loads is bounded in everything
that costs: every number has a range, the counts of obstacles, waypoints and drive
commands have limits, and so have the terrain grid and the work of rasterising the
obstacles into it (per obstacle and per file), so building a world's terrain takes
seconds at most whatever the file says (``docs/worlds.md``, "Limits").

Coordinates: ``east``/``north`` metres in the local tangent plane (ENU) at the origin;
``up`` metres along the origin's vertical above ``origin.elevation``. Headings are degrees
clockwise from north. :class:`Origin` converts exactly between that plane and WGS84
geodetic coordinates (via ECEF), so the conversion error is only floating point.
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from lxml import etree

from afa.config.miro import parse_xml, read_bounded
from afa.errors import ConfigError

__all__ = [
    "World", "Origin", "TerrainSpec", "Obstacle", "ObstacleType", "VehicleStart",
    "Waypoint", "Mission", "DriveCommand", "load_world", "parse_world", "raster_window",
    "raster_cells", "terrain_cells", "MAX_WORLD_BYTES", "MAX_TERRAIN_CELLS", "MAX_OBSTACLES",
    "MAX_OBSTACLE_CELLS", "MAX_RASTER_CELLS", "MAX_WAYPOINTS", "MAX_DRIVE_COMMANDS",
    "MAX_DRIVE_TIME", "LATITUDE_RANGE", "WGS84_A", "WGS84_F",
]

#: World files larger than this are refused (the shipped ones are 2-9 kB).
MAX_WORLD_BYTES = 4 * 1024 * 1024
#: Terrain grid samples, at most 4097 x 4097 (a 400 m square at 0.1 m, 1 km at 0.25 m):
#: building one costs ~2 s and ~0.5 GB (the shipped open field: 4e6 samples, 0.35 s).
MAX_TERRAIN_CELLS = 4097 * 4097
#: Obstacles per world (the obstacle-id grid is int16; each costs ~50 us to rasterise).
MAX_OBSTACLES = 10_000
#: Grid samples one obstacle may cover when rasterised (its footprint's axis-aligned box,
#: :func:`raster_cells`): 2000 x 2000, a 200 m square at 0.1 m.
MAX_OBSTACLE_CELLS = 4_000_000
#: ... and all the obstacles of a world together (the shipped worlds: 17,000 at most).
MAX_RASTER_CELLS = 32_000_000
#: Mission waypoints and drive commands per world.
MAX_WAYPOINTS = 10_000
MAX_DRIVE_COMMANDS = 10_000
#: The last drive command's time, at most (s): one day.
MAX_DRIVE_TIME = 86_400.0
#: Latitudes (deg) of an origin or a waypoint: UTM (the receiver's and the pose's grid)
#: ends at 80 S and 84 N, and the margin keeps a whole terrain (at most 5 km) inside it.
LATITUDE_RANGE = (-79.9, 83.9)
#: Obstacle sizes (m): length, width and diameter; height and depth.
MAX_OBSTACLE_SIZE = 1000.0
MAX_OBSTACLE_HEIGHT = 100.0
#: The origin's ellipsoid height (m): below the Dead Sea shore, above Everest.
ELEVATION_RANGE = (-1000.0, 10_000.0)
#: Problems listed in one ConfigError (a broken file could otherwise list 100,000).
MAX_PROBLEMS = 100

#: WGS84 semi-major axis (m) and flattening (NIMA TR8350.2).
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
_E2 = WGS84_F * (2.0 - WGS84_F)

ObstacleType = Literal["box", "cylinder", "ditch"]


# --------------------------------------------------------------------------- geodesy
def _geodetic_to_ecef(lat_deg: float, lon_deg: float, h: float) -> tuple[float, float, float]:
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    s = math.sin(lat)
    n = WGS84_A / math.sqrt(1.0 - _E2 * s * s)
    return ((n + h) * math.cos(lat) * math.cos(lon),
            (n + h) * math.cos(lat) * math.sin(lon),
            (n * (1.0 - _E2) + h) * s)


def _ecef_to_geodetic(x: float, y: float, z: float) -> tuple[float, float, float]:
    # Fixed-point iteration on latitude; converges to ~1e-12 rad in a few rounds near
    # the surface (we only ever use it within kilometres of the ellipsoid).
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - _E2))
    h = 0.0
    for _ in range(8):
        s = math.sin(lat)
        n = WGS84_A / math.sqrt(1.0 - _E2 * s * s)
        h = p / math.cos(lat) - n
        previous, lat = lat, math.atan2(z, p * (1.0 - _E2 * n / (n + h)))
        if lat == previous:  # a fixed point: the remaining rounds would change nothing
            break
    s = math.sin(lat)
    n = WGS84_A / math.sqrt(1.0 - _E2 * s * s)
    h = p / math.cos(lat) - n
    return math.degrees(lat), math.degrees(lon), h


@dataclass(frozen=True)
class Origin:
    """The world's origin: WGS84 latitude/longitude (degrees) and ellipsoid height (m).

    The local frame is the ENU tangent plane at this point, at height ``elevation``.
    """

    latitude: float
    longitude: float
    elevation: float = 0.0

    @functools.cached_property
    def _enu_basis(self) -> tuple[tuple[float, float, float], tuple[float, float, float],
                                  tuple[float, float, float]]:
        return self._basis()

    @functools.cached_property
    def _ecef(self) -> tuple[float, float, float]:
        return self.ecef()

    def _basis(self) -> tuple[tuple[float, float, float], tuple[float, float, float],
                              tuple[float, float, float]]:
        lat, lon = math.radians(self.latitude), math.radians(self.longitude)
        sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
        east = (-so, co, 0.0)
        north = (-sl * co, -sl * so, cl)
        up = (cl * co, cl * so, sl)
        return east, north, up

    def ecef(self) -> tuple[float, float, float]:
        """The origin in Earth-centred Earth-fixed coordinates (m)."""
        return _geodetic_to_ecef(self.latitude, self.longitude, self.elevation)

    def geodetic_to_enu(self, latitude: float, longitude: float,
                        height: float | None = None) -> tuple[float, float, float]:
        """(east, north, up) in metres of a WGS84 point; ``height`` defaults to the origin's."""
        h = self.elevation if height is None else height
        x, y, z = _geodetic_to_ecef(latitude, longitude, h)
        x0, y0, z0 = self._ecef
        d = (x - x0, y - y0, z - z0)
        e, n, u = self._enu_basis
        return (sum(a * b for a, b in zip(e, d, strict=True)),
                sum(a * b for a, b in zip(n, d, strict=True)),
                sum(a * b for a, b in zip(u, d, strict=True)))

    def enu_to_geodetic(self, east: float, north: float,
                        up: float = 0.0) -> tuple[float, float, float]:
        """(latitude, longitude, ellipsoid height) of a point given in the local ENU frame."""
        e, n, u = self._enu_basis
        x0, y0, z0 = self._ecef
        x = x0 + east * e[0] + north * n[0] + up * u[0]
        y = y0 + east * e[1] + north * n[1] + up * u[1]
        z = z0 + east * e[2] + north * n[2] + up * u[2]
        return _ecef_to_geodetic(x, y, z)

    def to_local(self, latitude: float, longitude: float) -> tuple[float, float]:
        """(east, north) of a ground point given by latitude/longitude (degrees)."""
        e, n, _ = self.geodetic_to_enu(latitude, longitude)
        return e, n

    def to_geodetic(self, east: float, north: float) -> tuple[float, float]:
        """(latitude, longitude) of the point at the origin's height whose tangent-plane
        (east, north) is given: the exact inverse of :meth:`to_local`."""
        up = 0.0
        for _ in range(4):  # the tangent plane leaves the ellipsoid by d^2 / 2R
            lat, lon, h = self.enu_to_geodetic(east, north, up)
            if h == self.elevation:  # on the ellipsoid: further rounds change nothing
                break
            up -= h - self.elevation
        return lat, lon


# --------------------------------------------------------------------------- model
@dataclass(frozen=True)
class TerrainSpec:
    """The heightfield: extent (m), grid resolution (m), roughness (m RMS), seed, slope."""

    width: float
    depth: float
    resolution: float = 0.1
    roughness: float = 0.0
    seed: int = 0
    slope_east: float = 0.0
    slope_north: float = 0.0

    @property
    def east_range(self) -> tuple[float, float]:
        return -self.width / 2.0, self.width / 2.0

    @property
    def north_range(self) -> tuple[float, float]:
        return -self.depth / 2.0, self.depth / 2.0

    def contains(self, east: float, north: float) -> bool:
        """Whether (east, north) lies on the terrain, edges included."""
        return abs(east) <= self.width / 2.0 and abs(north) <= self.depth / 2.0


@dataclass(frozen=True)
class Obstacle:
    """One obstacle. ``length`` runs along ``heading``, ``width`` across it.

    box: ``length``, ``width``, ``height``, ``heading``; cylinder: ``radius``, ``height``;
    ditch: ``length``, ``width``, ``depth``, ``heading``. Unused fields are 0.
    """

    type: ObstacleType
    east: float
    north: float
    length: float = 0.0
    width: float = 0.0
    height: float = 0.0
    depth: float = 0.0
    radius: float = 0.0
    heading: float = 0.0
    line: int = 0

    @property
    def positive(self) -> bool:
        return self.type != "ditch"

    def contains(self, east: float, north: float) -> bool:
        """Whether the ground point (east, north) lies inside the obstacle's footprint."""
        de, dn = east - self.east, north - self.north
        if self.type == "cylinder":
            return de * de + dn * dn <= self.radius * self.radius
        h = math.radians(self.heading)
        along = de * math.sin(h) + dn * math.cos(h)
        across = de * math.cos(h) - dn * math.sin(h)
        return abs(along) <= self.length / 2.0 and abs(across) <= self.width / 2.0

    def bounding_radius(self) -> float:
        if self.type == "cylinder":
            return self.radius
        return math.hypot(self.length, self.width) / 2.0

    def extent(self) -> tuple[float, float]:
        """Half-sizes east and north (m) of the footprint's axis-aligned bounding box."""
        if self.type == "cylinder":
            return self.radius, self.radius
        h = math.radians(self.heading)
        s, c = abs(math.sin(h)), abs(math.cos(h))
        return (self.length * s + self.width * c) / 2.0, (self.length * c + self.width * s) / 2.0


@dataclass(frozen=True)
class VehicleStart:
    """The start pose of the vehicle reference (rear axle centre): metres and degrees."""

    east: float = 0.0
    north: float = 0.0
    heading: float = 0.0


@dataclass(frozen=True)
class Waypoint:
    """A mission waypoint, held in both local (m) and geodetic (deg) coordinates."""

    east: float
    north: float
    latitude: float
    longitude: float
    line: int = 0


@dataclass(frozen=True)
class Mission:
    """Waypoints to visit in order; ``patrol`` repeats them (Pure Pursuit's patrol mode)."""

    waypoints: tuple[Waypoint, ...] = ()
    patrol: bool = False
    #: seconds the mission may take in a simulated run (None: the simulator's default)
    time_limit: float | None = None


@dataclass(frozen=True)
class DriveCommand:
    """From ``time`` (s) on, command ``speed`` (m/s) and ``steering`` (deg, + = left)."""

    time: float
    speed: float
    steering: float
    line: int = 0


@dataclass(frozen=True)
class World:
    """A loaded world file."""

    name: str
    origin: Origin
    terrain: TerrainSpec
    obstacles: tuple[Obstacle, ...] = ()
    vehicle: VehicleStart = field(default_factory=VehicleStart)
    mission: Mission = field(default_factory=Mission)
    drive: tuple[DriveCommand, ...] = ()
    description: str = ""
    path: Path | None = None

    def command_at(self, time: float) -> tuple[float, float]:
        """(speed m/s, steering deg) the drive script commands at ``time``; (0, 0) before
        the first command and when there is no script. O(log n) in the commands."""
        index = bisect.bisect_right(self.drive, time, key=lambda command: command.time)
        if index == 0:
            return 0.0, 0.0
        command = self.drive[index - 1]
        return command.speed, command.steering

    @property
    def drive_duration(self) -> float:
        """Time of the last drive command (s); 0 without a script."""
        return self.drive[-1].time if self.drive else 0.0


# --------------------------------------------------------------------------- work
def raster_window(obstacle: Obstacle, terrain: TerrainSpec) -> tuple[int, int, int, int]:
    """Grid index ranges ``(i0, i1, j0, j1)`` (east columns, north rows, ends exclusive)
    that rasterising ``obstacle`` on ``terrain`` touches: its footprint's bounding box and
    one sample more on each side, clipped to the grid. Empty ranges when it is off the
    grid. Raises ValueError/OverflowError for non-finite or absurd sizes (the world
    reader bounds them first)."""
    res = terrain.resolution
    nx = int(round(terrain.width / res)) + 1
    ny = int(round(terrain.depth / res)) + 1
    half_east, half_north = obstacle.extent()
    east0, north0 = -terrain.width / 2.0, -terrain.depth / 2.0
    i0 = max(int(math.floor((obstacle.east - half_east - east0) / res)), 0)
    i1 = min(int(math.ceil((obstacle.east + half_east - east0) / res)) + 1, nx)
    j0 = max(int(math.floor((obstacle.north - half_north - north0) / res)), 0)
    j1 = min(int(math.ceil((obstacle.north + half_north - north0) / res)) + 1, ny)
    return i0, max(i0, i1), j0, max(j0, j1)


def raster_cells(obstacle: Obstacle, terrain: TerrainSpec) -> int:
    """Grid samples rasterising ``obstacle`` touches (:func:`raster_window`): its cost."""
    i0, i1, j0, j1 = raster_window(obstacle, terrain)
    return (i1 - i0) * (j1 - j0)


def terrain_cells(terrain: TerrainSpec) -> float:
    """Samples of the terrain grid (a float: inf for absurd sizes)."""
    return (terrain.width / terrain.resolution + 1) * (terrain.depth / terrain.resolution + 1)


# --------------------------------------------------------------------------- parsing
_SIZE_LIMITS = {"length": MAX_OBSTACLE_SIZE, "width": MAX_OBSTACLE_SIZE,
                "radius": MAX_OBSTACLE_SIZE / 2, "height": MAX_OBSTACLE_HEIGHT,
                "depth": MAX_OBSTACLE_HEIGHT}
_OBSTACLE_FIELDS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    # type: (required attributes, optional attributes) besides "type"
    "box": (("east", "north", "length", "width", "height"), ("heading",)),
    "cylinder": (("east", "north", "radius", "height"), ()),
    "ditch": (("east", "north", "length", "width", "depth"), ("heading",)),
}


class _Reader:
    """Collects problems while reading, so one error lists all of them."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.problems: list[str] = []
        self.omitted = 0
        self._omitted_line = 0

    def problem(self, element: etree._Element | None, message: str) -> None:
        line = element.sourceline if element is not None and element.sourceline else 1
        if len(self.problems) < MAX_PROBLEMS:
            self.problems.append(f"{self.path}:{line}: {message}")
        else:
            self.omitted += 1
            self._omitted_line = self._omitted_line or line

    @property
    def count(self) -> int:
        """Problems found so far, listed or not."""
        return len(self.problems) + self.omitted

    def all_problems(self) -> list[str]:
        """The problems, with a last line counting those beyond :data:`MAX_PROBLEMS`."""
        if not self.omitted:
            return self.problems
        return self.problems + [f"{self.path}:{self._omitted_line}: ... and {self.omitted} "
                                "more problems (only the first 100 are listed)"]

    def limited(self, elements: list[etree._Element], limit: int, what: str
                ) -> list[etree._Element]:
        """The first ``limit`` elements; one problem at the first one beyond."""
        if len(elements) > limit:
            self.problem(elements[limit], f"more than {limit} {what} (the limit)")
        return elements[:limit]

    def check_attributes(self, element: etree._Element, required: tuple[str, ...],
                         optional: tuple[str, ...] = ()) -> bool:
        ok = True
        for name in element.attrib:
            if name not in required and name not in optional:
                allowed = ", ".join(required + optional) or "none"
                self.problem(element, f"<{element.tag}>: unknown attribute {name!r} "
                                      f"(allowed: {allowed})")
                ok = False
        for name in required:
            if name not in element.attrib:
                self.problem(element, f"<{element.tag}>: missing attribute {name!r}")
                ok = False
        return ok

    def number(self, element: etree._Element, name: str, default: float | None = None, *,
               minimum: float | None = None, positive: bool = False,
               maximum: float | None = None) -> float:
        """The attribute as a finite float in range, or NaN after reporting why not (a
        missing required attribute is reported by :meth:`check_attributes`)."""
        raw = element.get(name)
        if raw is None:
            return math.nan if default is None else default
        shown = raw if len(raw) <= 40 else raw[:37] + "..."
        try:
            value = float(raw)
        except ValueError:
            self.problem(element, f"<{element.tag}> {name}={shown!r}: not a number")
            return math.nan
        if not math.isfinite(value):
            problem = "must be finite"
        elif positive and value <= 0:
            problem = "must be > 0"
        elif minimum is not None and value < minimum:
            problem = f"must be >= {minimum:g}"
        elif maximum is not None and value > maximum:
            problem = f"must be <= {maximum:g}"
        else:
            return value
        self.problem(element, f"<{element.tag}> {name}={shown!r}: {problem}")
        return math.nan

    def integer(self, element: etree._Element, name: str, default: int, *,
                maximum: int = 2 ** 63 - 1) -> int:
        """The attribute as an integer in 0..maximum, or ``default`` after reporting."""
        raw = element.get(name)
        if raw is None:
            return default
        shown = raw if len(raw) <= 40 else raw[:37] + "..."
        try:
            value = int(raw) if len(raw) <= 40 else None
        except ValueError:
            value = None
        if value is None:
            self.problem(element, f"<{element.tag}> {name}={shown!r}: not an integer")
            return default
        if not 0 <= value <= maximum:
            self.problem(element, f"<{element.tag}> {name}={shown!r}: must be in 0..{maximum}")
            return default
        return value

    def boolean(self, element: etree._Element, name: str, default: bool) -> bool:
        raw = element.get(name)
        if raw is None:
            return default
        text = raw.strip().lower()
        if text in ("true", "1", "yes"):
            return True
        if text in ("false", "0", "no"):
            return False
        self.problem(element, f"<{element.tag}> {name}={raw!r}: expected true or false")
        return default

    def no_children(self, element: etree._Element) -> None:
        for child in element:
            self.problem(child, f"<{element.tag}> takes no child elements, got <{child.tag}>")
        if element.text and element.text.strip():
            self.problem(element, f"<{element.tag}> takes no text")


def load_world(path: str | Path) -> World:
    """Read and validate a world file.

    Raises :class:`~afa.errors.ConfigError` with one ``file:line: message`` line per
    problem: unreadable, oversized or malformed file, DTD or entity, unknown element or
    attribute, bad number, unknown obstacle type, an object outside the terrain.
    """
    path = Path(path)
    try:
        data = read_bounded(path, MAX_WORLD_BYTES)
    except OSError as exc:
        raise ConfigError(f"{path}:0: cannot read world file: {exc.strerror or exc}") from exc
    return parse_world(data, path)


def parse_world(data: bytes, path: str | Path = "<world>") -> World:
    """Parse world-file bytes (``path`` is used in messages). Raises ConfigError."""
    path = Path(path)
    if len(data) > MAX_WORLD_BYTES:
        raise ConfigError(f"{path}:1: world is {len(data)} bytes; the limit is {MAX_WORLD_BYTES}")
    root = parse_xml(data, path)
    reader = _Reader(path)
    world = _read_world(reader, root)
    if reader.problems or world is None:
        raise ConfigError(reader.all_problems() or [f"{path}:1: invalid world"])
    return world


def _read_world(r: _Reader, root: etree._Element) -> World | None:
    if root.tag != "world":
        r.problem(root, f"the root element must be <world>, not <{root.tag}>")
        return None
    r.check_attributes(root, ("name",))
    name = root.get("name", "")
    singles: dict[str, etree._Element] = {}
    obstacles: list[etree._Element] = []
    description = ""
    for child in root:
        if child.tag == "obstacle":
            obstacles.append(child)
        elif child.tag in ("origin", "terrain", "vehicle", "mission", "drive", "description"):
            if child.tag in singles:
                r.problem(child, f"<{child.tag}> appears twice (first at line "
                                 f"{singles[child.tag].sourceline})")
                continue
            singles[child.tag] = child
            if child.tag == "description":
                description = " ".join((child.text or "").split())
        else:
            r.problem(child, f"unknown element <{child.tag}> in <world> (expected origin, "
                             "terrain, obstacle, vehicle, mission, drive, description)")
    for required in ("origin", "terrain"):
        if required not in singles:
            r.problem(root, f"<world> needs an <{required}> element")
    if "origin" not in singles or "terrain" not in singles:
        return None

    origin = _read_origin(r, singles["origin"])
    terrain = _read_terrain(r, singles["terrain"])
    obstacles = r.limited(obstacles, MAX_OBSTACLES, "obstacles")
    items = tuple(o for o in (_read_obstacle(r, e, terrain) for e in obstacles) if o is not None)
    _check_raster_work(r, items, obstacles, terrain)
    vehicle = _read_vehicle(r, singles.get("vehicle"), terrain)
    mission = _read_mission(r, singles.get("mission"), origin, terrain)
    drive = _read_drive(r, singles.get("drive"))
    return World(name=name, origin=origin, terrain=terrain, obstacles=items, vehicle=vehicle,
                 mission=mission, drive=drive, description=description, path=r.path)


def _sized(terrain: TerrainSpec) -> bool:
    # a terrain whose size did not parse has been reported; do not pile up more errors
    return math.isfinite(terrain.width + terrain.depth)


def _on_terrain(terrain: TerrainSpec, east: float, north: float) -> bool:
    return math.isfinite(east) and math.isfinite(north) and terrain.contains(east, north)


def _check_raster_work(r: _Reader, items: tuple[Obstacle, ...],
                       elements: list[etree._Element], terrain: TerrainSpec) -> None:
    """Bound the work of rasterising the obstacles: per obstacle and per file."""
    cells = terrain_cells(terrain) if _sized(terrain) else math.inf
    if not (math.isfinite(cells) and cells <= MAX_TERRAIN_CELLS
            and math.isfinite(terrain.resolution) and terrain.resolution > 0):
        return  # the terrain is reported already; its windows mean nothing
    by_line = {e.sourceline: e for e in elements}
    total = 0
    for obstacle in items:
        if not _on_terrain(terrain, obstacle.east, obstacle.north):
            continue  # reported already ("must be on the terrain"); no window to bound
        element = by_line.get(obstacle.line)
        count = raster_cells(obstacle, terrain)
        if count > MAX_OBSTACLE_CELLS:
            r.problem(element, f"<obstacle> covers {count} grid samples at resolution "
                               f"{terrain.resolution:g} m; the limit is {MAX_OBSTACLE_CELLS} "
                               "per obstacle (make it smaller or the terrain coarser)")
            continue
        total += count
        if total > MAX_RASTER_CELLS:
            r.problem(element, f"the obstacles up to this one cover {total} grid samples "
                               f"at resolution {terrain.resolution:g} m; the limit is "
                               f"{MAX_RASTER_CELLS} cells per world")
            return


def _read_origin(r: _Reader, e: etree._Element) -> Origin:
    r.check_attributes(e, ("latitude", "longitude"), ("elevation",))
    r.no_children(e)
    low, high = LATITUDE_RANGE
    return Origin(latitude=r.number(e, "latitude", minimum=low, maximum=high),
                  longitude=r.number(e, "longitude", minimum=-180.0, maximum=180.0),
                  elevation=r.number(e, "elevation", 0.0, minimum=ELEVATION_RANGE[0],
                                     maximum=ELEVATION_RANGE[1]))


def _read_terrain(r: _Reader, e: etree._Element) -> TerrainSpec:
    r.check_attributes(e, ("width", "depth"), ("resolution", "roughness", "seed"))
    width = r.number(e, "width", positive=True, maximum=5000.0)
    depth = r.number(e, "depth", positive=True, maximum=5000.0)
    resolution = r.number(e, "resolution", 0.1, positive=True, maximum=10.0)
    if math.isfinite(width * depth * resolution) and resolution > 0:
        cells = (width / resolution + 1) * (depth / resolution + 1)
        if cells > MAX_TERRAIN_CELLS:
            r.problem(e, f"<terrain> {width:g} x {depth:g} m at {resolution:g} m is "
                         f"{cells:.3g} cells; the limit is {MAX_TERRAIN_CELLS} (4097 x 4097; "
                         "use a coarser resolution)")
    roughness = r.number(e, "roughness", 0.0, minimum=0.0, maximum=5.0)
    seed = r.integer(e, "seed", 0)
    slope_east = slope_north = 0.0
    seen = False
    for child in e:
        if child.tag != "slope":
            r.problem(child, f"unknown element <{child.tag}> in <terrain> (expected slope)")
            continue
        if seen:
            r.problem(child, "<slope> appears twice")
        seen = True
        r.check_attributes(child, (), ("east", "north"))
        r.no_children(child)
        slope_east = r.number(child, "east", 0.0, minimum=-1.0, maximum=1.0)
        slope_north = r.number(child, "north", 0.0, minimum=-1.0, maximum=1.0)
    return TerrainSpec(width=width, depth=depth, resolution=resolution, roughness=roughness,
                       seed=seed, slope_east=slope_east, slope_north=slope_north)


def _read_obstacle(r: _Reader, e: etree._Element, terrain: TerrainSpec) -> Obstacle | None:
    kind = e.get("type")
    if kind is None:
        r.problem(e, "<obstacle>: missing attribute 'type' (box, cylinder or ditch)")
        return None
    if kind not in _OBSTACLE_FIELDS:
        r.problem(e, f"<obstacle>: unknown type {kind!r} (expected box, cylinder or ditch)")
        return None
    required, optional = _OBSTACLE_FIELDS[kind]
    ok = r.check_attributes(e, ("type",) + required, optional)
    r.no_children(e)
    before = r.count
    values = {"east": r.number(e, "east"), "north": r.number(e, "north")}
    for name in required[2:] + optional:
        if name == "heading":
            values[name] = r.number(e, name, 0.0, minimum=-360.0, maximum=360.0)
        else:
            values[name] = r.number(e, name, positive=True, maximum=_SIZE_LIMITS[name])
    if not ok or r.count > before or any(math.isnan(v) for v in values.values()):
        return None
    obstacle = Obstacle(type=kind, line=e.sourceline or 0, **values)  # type: ignore[arg-type]
    if _sized(terrain) and not _on_terrain(terrain, obstacle.east, obstacle.north):
        r.problem(e, f"<obstacle> at east={obstacle.east:g} north={obstacle.north:g} is "
                     f"outside the terrain (±{terrain.width / 2:g}, ±{terrain.depth / 2:g} m)")
    return obstacle


def _read_vehicle(r: _Reader, e: etree._Element | None, terrain: TerrainSpec) -> VehicleStart:
    if e is None:
        return VehicleStart()
    r.check_attributes(e, ("east", "north"), ("heading",))
    r.no_children(e)
    start = VehicleStart(east=r.number(e, "east"), north=r.number(e, "north"),
                         heading=r.number(e, "heading", 0.0, minimum=-360.0, maximum=360.0))
    if (_sized(terrain) and not math.isnan(start.east) and not math.isnan(start.north)
            and not _on_terrain(terrain, start.east, start.north)):
        r.problem(e, "<vehicle> start is outside the terrain")
    return start


def _read_mission(r: _Reader, e: etree._Element | None, origin: Origin,
                  terrain: TerrainSpec) -> Mission:
    if e is None:
        return Mission()
    r.check_attributes(e, (), ("patrol", "time-limit"))
    patrol = r.boolean(e, "patrol", False)
    time_limit = (r.number(e, "time-limit", minimum=1.0) if "time-limit" in e.attrib
                  else None)
    waypoints: list[Waypoint] = []
    for child in r.limited(list(e), MAX_WAYPOINTS, "mission elements"):
        if child.tag != "waypoint":
            r.problem(child, f"unknown element <{child.tag}> in <mission> (expected waypoint)")
            continue
        r.no_children(child)
        keys = set(child.attrib)
        if keys == {"latitude", "longitude"}:
            lat = r.number(child, "latitude", minimum=LATITUDE_RANGE[0],
                           maximum=LATITUDE_RANGE[1])
            lon = r.number(child, "longitude", minimum=-180.0, maximum=180.0)
            if math.isnan(lat + lon + origin.latitude + origin.longitude + origin.elevation):
                continue
            east, north = origin.to_local(lat, lon)
        elif keys == {"east", "north"}:
            east, north = r.number(child, "east"), r.number(child, "north")
            if math.isnan(east + north + origin.latitude + origin.longitude + origin.elevation):
                continue
            if _sized(terrain) and not _on_terrain(terrain, east, north):
                r.problem(child, f"<waypoint> at east={east:g} north={north:g} is outside "
                                 "the terrain")
                continue
            lat, lon = origin.to_geodetic(east, north)
        else:
            r.problem(child, "<waypoint> takes either latitude and longitude or east and "
                             f"north, got {', '.join(sorted(keys)) or 'no attributes'}")
            continue
        if _sized(terrain) and not _on_terrain(terrain, east, north):
            r.problem(child, f"<waypoint> at east={east:.1f} north={north:.1f} is outside "
                             "the terrain")
        waypoints.append(Waypoint(east, north, lat, lon, child.sourceline or 0))
    if time_limit is not None and not math.isfinite(time_limit):
        time_limit = None
    return Mission(waypoints=tuple(waypoints), patrol=patrol, time_limit=time_limit)


def _read_drive(r: _Reader, e: etree._Element | None) -> tuple[DriveCommand, ...]:
    if e is None:
        return ()
    r.check_attributes(e, ())
    commands: list[DriveCommand] = []
    for child in r.limited(list(e), MAX_DRIVE_COMMANDS, "drive elements"):
        if child.tag != "command":
            r.problem(child, f"unknown element <{child.tag}> in <drive> (expected command)")
            continue
        if not r.check_attributes(child, ("time", "speed", "steering")):
            continue
        r.no_children(child)
        before = r.count
        command = DriveCommand(time=r.number(child, "time", minimum=0.0,
                                             maximum=MAX_DRIVE_TIME),
                               speed=r.number(child, "speed", minimum=-10.0, maximum=10.0),
                               steering=r.number(child, "steering", minimum=-90.0, maximum=90.0),
                               line=child.sourceline or 0)
        if r.count > before:
            continue
        if commands and command.time <= commands[-1].time:
            r.problem(child, f"<command> time={command.time:g} must be later than the "
                             f"previous command's ({commands[-1].time:g})")
            continue
        commands.append(command)
    return tuple(commands)
