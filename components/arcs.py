"""The candidate arcs: the one set of curvatures every voting behaviour and the Arc Arbiter
share (seed §3.3: "a pre-defined set of candidate arcs").

Pure Python + numpy (and the parameter base class): no asyncio, no components.

Conventions
-----------
- Vehicle frame ``Raptor:RearAxleCenter`` (docs/geometry.md): x forward, y left, z up.
  Every arc starts at the rear axle centre heading along +x; that point is the reference
  of the kinematic bicycle (``afa/sim/vehicle.py``), which drives *exactly* the arc of
  curvature κ = tan(δ)/L for a steering angle δ and wheelbase L.
- Curvature κ in 1/m, **left positive** (as :class:`idl.planning.ArcVoteIDL`), 0 straight.
- Index order: hard left first, hard right last: ``curvatures[0] = +κ_max``,
  ``curvatures[-1] = -κ_max``, ``curvatures[count // 2] = 0.0`` exactly.
- The set is uniform in curvature (as DAMN's arcs): the lateral offset between
  neighbours then has a simple bound (below), the nearest arc of a curvature is one
  division, and a Gaussian in curvature is a Gaussian over the indices.

How dense: threading a gap 5 m ahead
-----------------------------------
An arc's point after arc length s is p(s, κ) = ∫₀ˢ (cos κt, sin κt) dt, so

    ∂p/∂κ = ∫₀ˢ t·(−sin κt, cos κt) dt,   |∂p/∂κ| ≤ ∫₀ˢ t dt = s²/2,

with equality at κ = 0 (where p moves straight sideways). Two neighbouring arcs Δκ apart
are therefore at most Δκ·s²/2 apart after s metres, and exactly that far (sideways) next
to the straight arc, where gaps ahead are threaded. A gap of width W_gap at distance D
leaves the vehicle's centre line a free band W_free = W_gap − W_vehicle wide. If the
arcs cross it at most W_free/2 apart, any such band, wherever it lies, holds at least two
arcs, and the one nearest the band's centre clears each side by at least W_free/4:

    Δκ·D²/2 ≤ W_free/2   ⇔   Δκ ≤ W_free / D².

Design gap (:data:`DESIGN_GAP_DISTANCE`, :data:`DESIGN_GAP_WIDTH`): a 2.0 m gate 5 m
ahead for the Raptor's 1.4 m body gives W_free = 0.6 m and Δκ ≤ 0.024 1/m. With
δ_max = 30° and L = 1.9 m, κ_max = tan 30°/1.9 = 0.3039 1/m; n arcs (n odd, so κ = 0 is
one of them) span 2κ_max in n − 1 steps, so n ≥ 2κ_max/Δκ + 1 = 26.3: **27 arcs**
(Δκ = 0.02337 1/m, 0.292 m apart 5 m ahead). 25 arcs would be 0.317 m apart, too sparse.
:func:`minimum_count` does this arithmetic; a test keeps the default equal to it.

The bound is on arc length. Measured on the line x = 5 m across the heading, arcs cross
it farther apart off to the side (a turning arc meets that line obliquely): 0.293, 0.299
and 0.313 m between the crossings at 0, ±0.29, ±0.59 and ±0.91 m. So a gate square to
the heading is threaded with the full W_free/4 margin while its centre is within ±0.6 m
of the heading, and with a little less beyond.

Votes
-----
:class:`ArcVotes` is what a behaviour computes over the set: per-arc veto, vote 0..1,
certainty 0..1 and maximum speed; :meth:`ArcVotes.to_idl` turns it into the
``ArcVoteIDL`` event body (seed Table 23) a component publishes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, model_validator

from afa.config.parameters import Parameters, param
from components.trusted import trusted
from idl.common import TimeIDL
from idl.planning import ArcVoteIDL

__all__ = [
    "ArcSetParameters",
    "ArcSet",
    "ArcVotes",
    "ArcSetMismatchError",
    "ARC_SET_SECTION",
    "arc_set_of",
    "arc_points",
    "arc_point",
    "curvature_for_steering",
    "steering_for_curvature",
    "max_curvature",
    "required_spacing",
    "minimum_count",
    "DESIGN_GAP_DISTANCE",
    "DESIGN_GAP_WIDTH",
    "DESIGN_VEHICLE_WIDTH",
]

#: Distance (m) ahead of the rear axle at which the design gap must be threadable.
DESIGN_GAP_DISTANCE = 5.0
#: Width (m) of the design gap: a farm gate the Raptor must be able to aim through.
DESIGN_GAP_WIDTH = 2.0
#: The Raptor's body width (m), ``VehicleParameters.body_width`` in afa/sim/vehicle.py.
DESIGN_VEHICLE_WIDTH = 1.4

#: Curvatures within this of a set's own (1/m) are the same arc (JSON round trips are
#: exact; this only absorbs float32 storage or a re-computed set on another machine).
CURVATURE_MATCH_TOLERANCE = 1e-9


class ArcSetMismatchError(ValueError):
    """Votes or curvatures that are not over this arc set (other count or curvatures)."""


def max_curvature(max_steering_deg: float, wheelbase: float) -> float:
    """κ_max = tan(δ_max)/L (1/m) of the bicycle model.

    Raises ValueError unless 0 < δ_max < 89° and L > 0.
    """
    if not (0.0 < max_steering_deg < 89.0) or not wheelbase > 0.0:
        raise ValueError(f"need 0 < max steering < 89 deg and wheelbase > 0, got "
                         f"{max_steering_deg} deg, {wheelbase} m")
    return math.tan(math.radians(max_steering_deg)) / wheelbase


def required_spacing(distance: float = DESIGN_GAP_DISTANCE, gap_width: float = DESIGN_GAP_WIDTH,
                     vehicle_width: float = DESIGN_VEHICLE_WIDTH) -> float:
    """The largest curvature step Δκ (1/m) that threads the gap (module docstring):
    Δκ = (gap_width − vehicle_width) / distance².

    Raises ValueError if the gap is not wider than the vehicle or distance ≤ 0.
    """
    free = gap_width - vehicle_width
    if not free > 0.0 or not distance > 0.0:
        raise ValueError(f"a {gap_width} m gap at {distance} m cannot be threaded by a "
                         f"{vehicle_width} m vehicle")
    return free / distance**2


def minimum_count(max_steering_deg: float, wheelbase: float,
                  spacing: float | None = None) -> int:
    """The smallest odd number of arcs spanning ±κ_max with steps ≤ ``spacing``
    (default :func:`required_spacing` of the design gap).

    Raises ValueError for an invalid steering angle, wheelbase or spacing.
    """
    step = required_spacing() if spacing is None else spacing
    if not step > 0.0:
        raise ValueError(f"spacing must be > 0, got {step}")
    half = math.ceil(max_curvature(max_steering_deg, wheelbase) / step - 1e-12)
    return 2 * max(half, 1) + 1


def curvature_for_steering(steering: float, wheelbase: float) -> float:
    """κ = tan(δ)/L for a steering angle δ (rad, left positive)."""
    return math.tan(steering) / wheelbase


def steering_for_curvature(curvature: float, wheelbase: float) -> float:
    """δ = atan(L·κ) (rad, left positive): the steering angle that drives curvature κ."""
    return math.atan(wheelbase * curvature)


def arc_points(s: ArrayLike, curvature: ArrayLike,
               offset: float = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                             NDArray[np.float64]]:
    """Pose on an arc after the rear axle travelled arc length ``s`` (m) at ``curvature``.

    Returns ``(x, y, heading)`` in the vehicle frame at the arc's start (rear axle,
    x forward, y left), broadcast over ``s`` and ``curvature``. The exact circle, and the
    straight line when κ = 0, from one formula without division by κ:

        x = s·sinc(κs),   y = (κs²/2)·sinc²(κs/2),   heading = κs,

    where sinc(u) = sin(u)/u (so x = sin(κs)/κ and y = (1 − cos κs)/κ, evaluated without
    the cancellation of 1 − cos for small κs). ``offset`` moves the point to a body
    point ``offset`` metres ahead of the rear axle on the vehicle's x axis (e.g. the
    front bumper), which rides rigidly along: p + offset·(cos κs, sin κs).
    """
    s_arr = np.asarray(s, dtype=np.float64)
    k_arr = np.asarray(curvature, dtype=np.float64)
    u = k_arr * s_arr
    x = s_arr * np.sinc(u / np.pi)
    half = np.sinc(u / (2.0 * np.pi))
    y = 0.5 * u * s_arr * half * half
    if offset != 0.0:
        x = x + offset * np.cos(u)
        y = y + offset * np.sin(u)
    return x, y, u


def arc_point(s: float, curvature: float, offset: float = 0.0) -> tuple[float, float, float]:
    """Scalar :func:`arc_points`: ``(x, y, heading)`` after arc length ``s``."""
    x, y, h = arc_points(s, curvature, offset)
    return float(x), float(y), float(h)


class ArcSetParameters(Parameters):
    """The candidate arcs shared by the voting behaviours and the Arc Arbiter (afa
    addition: the seed's set is "pre-defined" but not printed)."""

    section_name: ClassVar[str] = "CandidateArcs"  # ARC_SET_SECTION

    Count: Annotated[int, Field(ge=3)] = param(
        27, unit="1",
        description="afa addition: number of candidate arcs, odd (the straight arc is one "
                    "of them); 27 threads a 2 m gap 5 m ahead with the Raptor's 1.4 m body "
                    "(components/arcs.py)")
    MaxSteeringAngle: Annotated[float, Field(gt=0, lt=89)] = param(
        30.0, unit="deg",
        description="afa addition: steering angle of the hardest arcs (Table A.13's "
                    "MaxSteeringAngle)")
    Wheelbase: Annotated[float, Field(gt=0)] = param(
        1.9, unit="m", description="afa addition: the vehicle's wheelbase (docs/geometry.md)")

    @model_validator(mode="after")
    def _odd(self) -> ArcSetParameters:
        if self.Count % 2 == 0:
            raise ValueError(f"Count ({self.Count}) must be odd so that the straight arc "
                             f"(curvature 0) is a candidate")
        return self


def _read_only(array: NDArray[Any]) -> NDArray[Any]:
    array.setflags(write=False)  # cheaper than array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class ArcSet:
    """The candidate arcs: ``curvatures`` (1/m), hard left (+κ_max) to hard right.

    Build with :meth:`from_parameters`; the constructor checks the invariants
    (symmetric, uniform, κ = 0 exactly at the middle) and raises ValueError otherwise.
    The set is deterministic: equal parameters give bit-identical curvatures.
    """

    parameters: ArcSetParameters
    curvatures: NDArray[np.float64]

    def __post_init__(self) -> None:
        k = np.asarray(self.curvatures, dtype=np.float64)
        n = self.parameters.Count
        if k.shape != (n,):
            raise ValueError(f"ArcSet: {k.shape} curvatures for Count {n}")
        if not np.isfinite(k).all():  # (event bodies carry them unvalidated: to_idl)
            raise ValueError("ArcSet curvatures must be finite")
        if k[n // 2] != 0.0 or not np.array_equal(k, -k[::-1]) or np.any(np.diff(k) >= 0):
            raise ValueError("ArcSet curvatures must be strictly decreasing, symmetric and "
                             "contain 0.0 in the middle")
        object.__setattr__(self, "curvatures", _read_only(k.copy()))

    @classmethod
    def from_parameters(cls, parameters: ArcSetParameters | None = None) -> ArcSet:
        """The uniform set: κ_k = κ_max·(m − k)/m for k = 0..2m (m = Count // 2).

        The left half is computed once and mirrored, so the set is exactly symmetric
        and holds κ = 0.0 exactly.
        """
        p = parameters if parameters is not None else ArcSetParameters()
        m = p.Count // 2
        k_max = max_curvature(p.MaxSteeringAngle, p.Wheelbase)
        left = k_max * (np.arange(m, 0, -1, dtype=np.float64) / m)
        return cls(p, np.concatenate([left, [0.0], -left[::-1]]))

    def __len__(self) -> int:
        return int(self.curvatures.shape[0])

    @property
    def count(self) -> int:
        """Number of arcs."""
        return len(self)

    @property
    def max_curvature(self) -> float:
        """κ_max (1/m), the hardest arcs' curvature."""
        return float(self.curvatures[0])

    @property
    def spacing(self) -> float:
        """Δκ (1/m) between neighbouring arcs."""
        return self.max_curvature / (self.count // 2)

    @property
    def straight_index(self) -> int:
        """Index of the straight arc (κ = 0)."""
        return self.count // 2

    @property
    def wheelbase(self) -> float:
        return self.parameters.Wheelbase

    def steering_angles(self) -> NDArray[np.float64]:
        """(n,) steering angles δ_k = atan(L·κ_k), radians, left positive."""
        return np.arctan(self.parameters.Wheelbase * self.curvatures)

    def steering_angle(self, index: int) -> float:
        """Steering angle (rad) of arc ``index``."""
        return steering_for_curvature(float(self.curvatures[index]), self.parameters.Wheelbase)

    def nearest_index(self, curvature: float) -> int:
        """Index of the arc nearest ``curvature`` (clipped to ±κ_max); a curvature exactly
        half-way between two arcs goes to the straighter one.

        Raises ValueError for a non-finite curvature.
        """
        if not math.isfinite(curvature):
            raise ValueError(f"curvature must be finite, got {curvature!r}")
        position = (self.max_curvature - curvature) / self.spacing
        low = min(max(math.floor(position), 0), self.count - 1)
        high = min(low + 1, self.count - 1)
        d_low = abs(float(self.curvatures[low]) - curvature)
        d_high = abs(float(self.curvatures[high]) - curvature)
        if d_low != d_high:
            return low if d_low < d_high else high
        return low if abs(self.curvatures[low]) <= abs(self.curvatures[high]) else high

    def matches(self, curvatures: ArrayLike) -> bool:
        """True if ``curvatures`` are this set's (same count, each within 1e-9 1/m)."""
        k = np.asarray(curvatures, dtype=np.float64)
        return bool(k.shape == self.curvatures.shape
                    and np.all(np.abs(k - self.curvatures) <= CURVATURE_MATCH_TOLERANCE))

    def check(self, curvatures: ArrayLike, what: str = "votes") -> None:
        """Raise :class:`ArcSetMismatchError` unless ``curvatures`` are this set's."""
        k = np.asarray(curvatures, dtype=np.float64)
        if k.shape != self.curvatures.shape:
            raise ArcSetMismatchError(
                f"{what} are over {k.shape[0] if k.ndim == 1 else k.shape} arcs, the arc "
                f"set has {self.count}: every behaviour and the arbiter must use the one "
                f"ArcSet (components/arcs.py)")
        differ = np.nonzero(~(np.abs(k - self.curvatures) <= CURVATURE_MATCH_TOLERANCE))[0]
        if differ.size:
            i = int(differ[0])
            raise ArcSetMismatchError(
                f"{what} are over other curvatures: arc {i} is {k[i]!r} 1/m, the arc set's "
                f"is {float(self.curvatures[i])!r} 1/m ({differ.size} arcs differ); check "
                f"Count, MaxSteeringAngle and Wheelbase")


@dataclass(frozen=True, eq=False)
class ArcVotes:
    """One behaviour's opinion of every arc (seed Table 23), as float64/bool arrays.

    ``veto`` forbids an arc; ``vote`` 0..1 is its desirability; ``certainty`` 0..1 the
    behaviour's belief in its data; ``max_speed`` (m/s, finite, ≥ 0) the highest speed
    it accepts on the arc. The constructor copies the arrays read-only and raises
    ValueError on mismatched lengths or out-of-range values.
    """

    veto: NDArray[np.bool_]
    vote: NDArray[np.float64]
    certainty: NDArray[np.float64]
    max_speed: NDArray[np.float64]
    #: the last event body built from these votes, with its behaviour and arc set
    #: (see :meth:`to_idl`)
    _published: tuple[str, ArcSet, ArcVoteIDL] | None = field(
        default=None, init=False, repr=False, compare=False)
    #: True when the constructor checked the arrays (not :meth:`unchecked`): their event
    #: body then needs no second validation (see :meth:`to_idl`)
    _checked: bool = field(default=False, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        veto = np.array(self.veto, dtype=bool)
        arrays = {name: np.array(getattr(self, name), dtype=np.float64)
                  for name in ("vote", "certainty", "max_speed")}
        if veto.ndim != 1 or any(a.shape != veto.shape for a in arrays.values()):
            raise ValueError("ArcVotes arrays must be 1-D and of one length, got "
                             f"{[veto.shape] + [a.shape for a in arrays.values()]}")
        for name in ("vote", "certainty"):
            if not np.all((arrays[name] >= 0.0) & (arrays[name] <= 1.0)):
                raise ValueError(f"ArcVotes.{name} must lie in 0..1")
        if not np.all(np.isfinite(arrays["max_speed"]) & (arrays["max_speed"] >= 0.0)):
            raise ValueError("ArcVotes.max_speed must be finite and ≥ 0")
        object.__setattr__(self, "veto", _read_only(veto))
        for name, value in arrays.items():
            object.__setattr__(self, name, _read_only(value))
        object.__setattr__(self, "_checked", True)

    @classmethod
    def unchecked(cls, veto: NDArray[np.bool_], vote: NDArray[np.float64],
                  certainty: NDArray[np.float64], max_speed: NDArray[np.float64]) -> ArcVotes:
        """Wrap arrays without the range checks, for producers whose arrays are in range
        by construction (their tests check it): the checks cost more than scoring a map.
        The arrays are taken over (not copied) and made read-only.
        """
        votes = object.__new__(cls)
        for name, value in (("veto", veto), ("vote", vote), ("certainty", certainty),
                            ("max_speed", max_speed)):
            object.__setattr__(votes, name, _read_only(value))
        return votes

    @classmethod
    def halt(cls, count: int) -> ArcVotes:
        """Every arc vetoed, votes 0, certainty 1, speed 0: a behaviour's "stop now"."""
        return cls(np.ones(count, dtype=bool), np.zeros(count), np.ones(count),
                   np.zeros(count))

    def __len__(self) -> int:
        return int(self.veto.shape[0])

    @property
    def all_vetoed(self) -> bool:
        """True if every arc is vetoed (a halt)."""
        return bool(np.all(self.veto))

    def to_idl(self, *, time: TimeIDL, behaviour: str, arcs: ArcSet) -> ArcVoteIDL:
        """The ``ArcVoteIDL`` event body over ``arcs``.

        Votes are immutable and a behaviour often publishes the same ones scan after
        scan (Obstacle Detection's "clear"): the body is built the first time, and
        later bodies for the same behaviour and arc set are that one with the new time
        stamp (equal to a validated construction; tests/components/test_arcs.py).
        Votes the constructor checked (lengths, ranges) over an arc set (finite, checked
        by :class:`ArcSet`) are put into the body without validating them again
        (:func:`~components.trusted.trusted`); votes built with :meth:`unchecked` are
        validated, so the IDL's checks still catch a producer's out-of-range value.

        Raises :class:`ArcSetMismatchError` if the votes are not one per arc of ``arcs``.
        """
        if len(self) != len(arcs):
            raise ArcSetMismatchError(f"{len(self)} votes for an arc set of {len(arcs)}")
        last = self._published
        if (last is not None and last[0] == behaviour and last[1] is arcs
                and isinstance(time, TimeIDL)):
            return last[2].model_copy(update={"time": time})
        build = (trusted if self._checked and type(time) is TimeIDL and type(behaviour) is str
                 else _validated)
        body = build(ArcVoteIDL, time=time, behaviour=behaviour, curvatures=arcs.curvatures,
                     veto=self.veto, vote=self.vote, certainty=self.certainty,
                     maxSpeed=self.max_speed)
        object.__setattr__(self, "_published", (behaviour, arcs, body))
        return body


def _validated(cls: type[ArcVoteIDL], **values: Any) -> ArcVoteIDL:
    return cls(**values)


#: The configuration section every voting behaviour and the arbiter read the arc set from.
ARC_SET_SECTION = "CandidateArcs"


def arc_set_of(section: object) -> ArcSet:
    """The arc set a configuration declares in section :data:`ARC_SET_SECTION` (pass
    ``component.context.section(ARC_SET_SECTION)``); the defaults when there is none.
    Raises ValueError if the section holds another parameter type."""
    if section is None:
        return ArcSet.from_parameters()
    if not isinstance(section, ArcSetParameters):
        raise ValueError(f"section {ARC_SET_SECTION} holds {type(section).__name__}, "
                         "not ArcSetParameters")
    return ArcSet.from_parameters(section)
