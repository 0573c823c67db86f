"""The Arc Arbiter's decision (seed §3.4, Tables 25, A.12): weighted arc votes, vetoes,
certainty and maximum speed into one steering and speed command.

Pure Python + numpy: no asyncio, no framework. The component feeds every ``ArcVote``
event to :meth:`VoteArbiter.receive` with the injected clock's time, calls
:meth:`VoteArbiter.decide` (the seed re-decides on every vote), sends the decision's
curvature (as a steering angle) and speed to Vehicle Control's ``setVelocity``, and may
publish the :class:`ArbiterDecision` for displays.

The vote book
-------------
The latest vote of each behaviour (keyed by ``ArcVoteIDL.behaviour``) is kept with the
time it was *received* (the arbiter's own clock: a sender's stamp may come from another
clock or describe old data). A vote is **fresh** while now − received ≤ StaleVoteTime
(``StaleVoteTimeSec + StaleVoteTimeUSec/1e6``, 1.5 s by default); a stale vote is dropped
from the book, so a behaviour that stops voting loses its veto after StaleVoteTime, it is
never frozen in. Its name is remembered to report it as stale.

Weights (Table A.12), by behaviour name:

=====================  =====================
``behaviour``          weight
=====================  =====================
``ObstacleAvoidance``  ``ObsWeight``
``PurePursuit``        ``PursuitWeight``
``FindPath``           ``PlannerWeight``
``ObstacleDetection``  ``LaserSafetyWeight``
anything else          ``unknown_weight`` (0)
=====================  =====================

An unknown behaviour's votes do not steer (weight 0 unless configured), but its vetoes
and speed limits apply: a veto never needs a weight, and a misspelt safety behaviour
must still be able to stop the vehicle. Unknown names are reported in the decision.

The decision
------------
1. Arcs vetoed by any fresh vote are out.
2. Each remaining arc k scores Σ_b w_b · certainty_bk · vote_bk over fresh votes b.
3. The chosen arc has the best score; ties (within 1e-9) go to the straighter arc, then
   to the left one (the straighter arc changes course least; the left one makes the
   choice deterministic for mirrored situations).
4. Speed = min(``TransVelocitySetPoint``, min over fresh votes of maxSpeed[chosen]).

**Fail-safe** (speed 0, steering straight, ``failsafe`` names the cause):
``"no-fresh-vote"`` (nothing fresh), ``"all-vetoed"`` (every arc vetoed by a fresh vote),
``"no-valid-vote"`` (no admissible arc has a positive score: every fresh vote weighs
nothing there, by weight, certainty or vote, so nothing says where to go), and
``"missing-required"`` (a behaviour named in ``required`` has no fresh vote: e.g.
``required={"PurePursuit"}`` stops the vehicle when goal seeking dies, instead of letting
Obstacle Avoidance alone wander on; empty by default, the seed's behaviour). Steering is
straight rather than the last command: the decision stays a function of the vote book
alone, and a stopped vehicle restarts on a predictable course.

A speed of 0 that is not a fail-safe (a behaviour's maxSpeed 0, e.g. Pure Pursuit at its
goal) still reports the best arc's curvature, with ``failsafe`` None.

Votes over another arc set (other count or curvatures) are refused by
:meth:`VoteArbiter.receive` with :class:`~components.arcs.ArcSetMismatchError`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from afa.clock import TIME_TOLERANCE
from components.arc_arbiter.parameters import ArcArbiterParameters
from components.arcs import ArcSet
from idl.planning import ArcVoteIDL

__all__ = [
    "VoteArbiter",
    "ArbiterDecision",
    "BEHAVIOUR_WEIGHTS",
    "Failsafe",
    "weight_for",
]

Failsafe = Literal["no-fresh-vote", "missing-required", "all-vetoed", "no-valid-vote"]

#: Behaviour name (``ArcVoteIDL.behaviour``) → the ArcArbiterParameters weight field.
BEHAVIOUR_WEIGHTS: dict[str, str] = {
    "ObstacleAvoidance": "ObsWeight",
    "PurePursuit": "PursuitWeight",
    "FindPath": "PlannerWeight",
    "ObstacleDetection": "LaserSafetyWeight",
}

#: Scores within this of the best are ties.
SCORE_TIE_TOLERANCE = 1e-9


def weight_for(behaviour: str, parameters: ArcArbiterParameters,
               unknown_weight: float = 0.0) -> float:
    """The weight of a behaviour's votes (module docstring's table)."""
    name = BEHAVIOUR_WEIGHTS.get(behaviour)
    return float(getattr(parameters, name)) if name is not None else unknown_weight


@dataclass(frozen=True, eq=False)
class ArbiterDecision:
    """One decision, for Vehicle Control and for displays.

    ``index``/``curvature``/``steering`` (rad, left positive) the chosen arc (the
    straight arc on a fail-safe); ``speed`` m/s; ``scores`` (n,) the weighted sums
    (vetoed arcs included, for display); ``vetoed`` (n,) the union of fresh vetoes;
    ``fresh`` the behaviours whose votes counted, ``stale`` those seen before whose
    latest vote has gone stale, ``unknown`` fresh behaviours without a configured
    weight; ``failsafe`` the fail-safe cause or None.
    """

    time: float
    index: int
    curvature: float
    steering: float
    speed: float
    scores: NDArray[np.float64]
    vetoed: NDArray[np.bool_]
    fresh: tuple[str, ...]
    stale: tuple[str, ...]
    unknown: tuple[str, ...]
    failsafe: Failsafe | None

    def at(self, time: float) -> ArbiterDecision:
        """This decision, made again at ``time``."""
        return ArbiterDecision(time, self.index, self.curvature, self.steering, self.speed,
                               self.scores, self.vetoed, self.fresh, self.stale, self.unknown,
                               self.failsafe)

    @property
    def stopped(self) -> bool:
        """True when the command is to stand still."""
        return self.speed == 0.0


@dataclass(eq=False, slots=True)
class _Entry:
    """A behaviour's latest vote; ``vote`` and ``received`` move on when a vote repeats
    the arrays of the previous one (the derived arrays stay)."""

    vote: ArcVoteIDL
    received: float
    weighted: NDArray[np.float64]  # weight · certainty · vote, float64
    veto: NDArray[np.bool_]
    max_speed: NDArray[np.float64]
    known: bool


class VoteArbiter:
    """The vote book and the decision rule (module docstring).

    ``required`` names behaviours without whose fresh vote the vehicle must stop.
    Raises ValueError for a negative or non-finite ``unknown_weight``.
    """

    def __init__(self, parameters: ArcArbiterParameters, arcs: ArcSet, *,
                 unknown_weight: float = 0.0, required: Iterable[str] = ()) -> None:
        if not (math.isfinite(unknown_weight) and unknown_weight >= 0.0):
            raise ValueError(f"unknown_weight must be finite and ≥ 0, got {unknown_weight}")
        self.parameters = parameters
        self.arcs = arcs
        self.unknown_weight = float(unknown_weight)
        self.required = frozenset(required)
        self.stale_after = parameters.stale_vote_time
        self._book: dict[str, _Entry] = {}
        self._seen: set[str] = set()
        self._names: tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]] | None = None
        # The book's content changes with ``_version``; the last decision is kept with the
        # version it was made from, so a vote that repeats its behaviour's last one (the
        # safety catch's "clear", every scan) costs no new decision.
        self._version = 0
        self._last: tuple[int, ArbiterDecision] | None = None
        n = len(arcs)
        # Preference among tied arcs: straighter first, then left (positive curvature).
        order = sorted(range(n), key=lambda k: (abs(float(arcs.curvatures[k])),
                                                -float(arcs.curvatures[k])))
        self._preference = np.array(order, dtype=np.intp)
        self._straight = arcs.straight_index
        self._zeros = np.zeros(n)
        self._no_veto = np.zeros(n, dtype=bool)
        self._zeros.flags.writeable = False
        self._no_veto.flags.writeable = False

    def receive(self, vote: ArcVoteIDL, received: float) -> None:
        """Keep ``vote`` as its behaviour's latest, received at ``received`` (s).

        Raises :class:`~components.arcs.ArcSetMismatchError` (a ValueError) if the vote
        is over another arc set, ValueError for a non-finite time.
        """
        if not math.isfinite(received):
            raise ValueError(f"receive time must be finite, got {received!r}")
        previous = self._book.get(vote.behaviour)
        if previous is not None and _same_arrays(previous.vote, vote):
            previous.vote, previous.received = vote, float(received)
            return
        if previous is None or vote.curvatures is not previous.vote.curvatures:
            self.arcs.check(vote.curvatures, f"{vote.behaviour!r} votes")
        known = vote.behaviour in BEHAVIOUR_WEIGHTS
        weight = weight_for(vote.behaviour, self.parameters, self.unknown_weight)
        weighted = weight * vote.certainty.astype(np.float64) * vote.vote.astype(np.float64)
        if previous is None:
            self._names = None
        self._book[vote.behaviour] = _Entry(vote, float(received), weighted, vote.veto,
                                            vote.maxSpeed.astype(np.float64), known)
        self._seen.add(vote.behaviour)
        self._version += 1

    def forget(self, behaviour: str) -> None:
        """Drop a behaviour's vote at once (e.g. the component unsubscribed it)."""
        if self._book.pop(behaviour, None) is not None:
            self._names = None
            self._version += 1

    @property
    def behaviours(self) -> tuple[str, ...]:
        """Behaviours with a vote in the book (fresh as of the last decision)."""
        return tuple(sorted(self._book))

    @property
    def ever_voted(self) -> bool:
        """Whether any behaviour has voted into this book (stale votes included)."""
        return bool(self._seen)

    def latest(self, behaviour: str) -> ArcVoteIDL | None:
        """The kept vote of ``behaviour``, if any."""
        entry = self._book.get(behaviour)
        return entry.vote if entry is not None else None

    def reverse_request(self) -> tuple[str, float, float, float] | None:
        """The latest vote in the book that asks the vehicle to back first
        (``ArcVoteIDL.reverse`` > 0) from a behaviour with a positive weight: its
        behaviour, distance (m), curvature (1/m) and receive time; None when none asks.
        (A behaviour without a say in steering has none in backing either.) Call after
        :meth:`decide`, which drops the stale votes."""
        asks = [(e.received, b, e.vote) for b, e in self._book.items()
                if e.vote.reverse > 0.0
                and weight_for(b, self.parameters, self.unknown_weight) > 0.0]
        if not asks:
            return None
        received, behaviour, vote = max(asks, key=lambda a: (a[0], a[1]))
        return behaviour, float(vote.reverse), float(vote.reverseCurvature), received

    def expires(self) -> float | None:
        """The earliest time (s, the clock of :meth:`receive`) at which :meth:`decide`
        finds a vote of the book stale; None when the book is empty."""
        if not self._book:
            return None
        oldest = min(entry.received for entry in self._book.values())
        return oldest + self.stale_after + 2 * TIME_TOLERANCE

    def decide(self, now: float) -> ArbiterDecision:
        """Drop stale votes and decide at time ``now`` (s, the arbiter's clock).

        Raises ValueError for a non-finite time.
        """
        if not math.isfinite(now):
            raise ValueError(f"time must be finite, got {now!r}")
        limit = self.stale_after + TIME_TOLERANCE
        stale_names = [b for b, e in self._book.items() if now - e.received > limit]
        for name in stale_names:
            del self._book[name]
            self._names = None
            self._version += 1
        if self._last is not None and self._last[0] == self._version:
            return self._last[1].at(now)  # nothing the decision reads changed
        decision = self._decide(now)
        self._last = (self._version, decision)
        return decision

    def _decide(self, now: float) -> ArbiterDecision:
        """The decision over the book as it is (module docstring)."""
        entries = list(self._book.values())
        if self._names is None:  # membership changed: recompute the display names
            self._names = (tuple(sorted(self._book)),
                           tuple(sorted(self._seen - self._book.keys())),
                           tuple(sorted(e.vote.behaviour for e in entries if not e.known)))
        fresh, stale, unknown = self._names
        if not entries:
            return self._stop(now, self._zeros, self._no_veto, fresh, stale, unknown,
                              "no-fresh-vote")
        scores = entries[0].weighted.copy()
        vetoed = entries[0].veto.copy()
        for entry in entries[1:]:
            scores += entry.weighted
            vetoed |= entry.veto
        if self.required and not self.required <= self._book.keys():
            return self._stop(now, scores, vetoed, fresh, stale, unknown, "missing-required")
        if vetoed.all():
            return self._stop(now, scores, vetoed, fresh, stale, unknown, "all-vetoed")
        admissible = np.where(vetoed, -np.inf, scores)
        best = float(admissible.max())
        if not best > 0.0:
            return self._stop(now, scores, vetoed, fresh, stale, unknown, "no-valid-vote")
        tied = admissible[self._preference] >= best - SCORE_TIE_TOLERANCE
        index = int(self._preference[int(np.argmax(tied))])
        speed = float(self.parameters.TransVelocitySetPoint)
        for entry in entries:
            speed = min(speed, float(entry.max_speed[index]))
        curvature = float(self.arcs.curvatures[index])
        return ArbiterDecision(now, index, curvature, self.arcs.steering_angle(index), speed,
                               scores, vetoed, fresh, stale, unknown, None)

    def _stop(self, now: float, scores: NDArray[np.float64], vetoed: NDArray[np.bool_],
              fresh: tuple[str, ...], stale: tuple[str, ...], unknown: tuple[str, ...],
              cause: Failsafe) -> ArbiterDecision:
        return ArbiterDecision(now, self._straight, 0.0, 0.0, 0.0, scores, vetoed, fresh,
                               stale, unknown, cause)


def _same_arrays(kept: ArcVoteIDL, vote: ArcVoteIDL) -> bool:
    """True if ``vote`` carries the very arrays of ``kept`` (a producer re-stamping the
    same votes, :meth:`components.arcs.ArcVotes.to_idl`): event arrays are read-only, so
    the same objects hold the same values and the derived arrays can be kept."""
    return (vote.curvatures is kept.curvatures and vote.veto is kept.veto
            and vote.vote is kept.vote and vote.certainty is kept.certainty
            and vote.maxSpeed is kept.maxSpeed)
