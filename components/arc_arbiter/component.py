"""The Arc Arbiter (seed §3.4, Tables 25, A.12): the one decision-making component.

It keeps the latest ``ArcVote`` of each behaviour and re-decides on every vote
(:mod:`components.arc_arbiter.arbitrate`): arcs vetoed by any fresh vote are out, the
rest are scored by the weighted sum of votes scaled by certainty, and the speed is the
least of the chosen arc's ``maxSpeed`` over the fresh votes and
``TransVelocitySetPoint``. It commands Vehicle Control through the polled
``setVelocity`` (which Vehicle Control obeys only while its arbiter switch is on).

Fail-safe: every arc vetoed, no valid vote, or every vote stale (older than
``StaleVoteTimeSec`` + ``StaleVoteTimeUSec``) means stop. Staleness is checked on each
vote, every ``STALE_CHECK_PERIOD`` and at the moment the oldest vote in the book goes
stale, so a behaviour that stops voting loses its veto (and its say) when its vote goes
stale, and an arbiter whose voters all fell silent commands a stop as its last vote goes
stale. If the arbiter itself falls silent, Vehicle Control's command watchdog stops the
vehicle.

Back-out (afa addition, :mod:`components.arc_arbiter.recovery`): when every arc has been
vetoed for ``RecoverAfter`` seconds (and only then: a stale or missing vote still means
stop), the arbiter reverses ``RecoverDistance`` at ``RecoverSpeed`` on the steering that
turns the vehicle towards the behaviours' preferred arc, checked clear on the latest
global Traversability map, then hands back to the votes. Any other fail-safe during a
back-out stops it at once; a new map that blocks the rest of it stops it too. After
``RecoverLimit`` back-outs in a row (no decision between them let the vehicle drive:
the votes stay vetoed, FindPath has no path at all) it stands, unhealthy, until a
decision lets the vehicle drive again: nothing looks behind the vehicle, and a dead end
that backing out has not opened is not opened by more of it.

Planned reverse (afa addition, decision 0046): a behaviour with a weight may ask in its
vote to back first (``ArcVoteIDL.reverse`` metres on ``reverseCurvature``: FindPath's
drivable path starts by backing, to line up on a gate it is too close to turn into).
The arbiter backs once per request, on the arc nearest that curvature, at most
``RecoverDistance`` at ``RecoverSpeed`` and ``RecoverLimit`` times in a row
(``REVERSE_RESET`` seconds without a request start a new row), and only where the back
is clear on its map, as for a back-out; any fail-safe stops it, as it stops a back-out.
A request voted while backing is not taken: it was planned from somewhere along the way.

Commands go out when the decision changes and at least every ``COMMAND_REFRESH`` seconds
(feeding Vehicle Control's watchdog). Deciding never waits for Vehicle Control: a sender
task makes the ``setVelocity`` calls one at a time, always with the latest decision
(decisions made while a call waits for its ACK are folded into the next call), except
that a **stop** never waits behind an unacknowledged command: it is sent at once, in
its own call. So the safety catch's halt reaches the wire within a frame time of the
vote even when an earlier command's ACK was lost (Vehicle Control waits 50 ms for it).
The decision is published as ``ArcDecision`` (:class:`~idl.planning.ArcDecisionIDL`) for
the console and the logs, when it changes and at least every ``COMMAND_REFRESH`` seconds.
"""

from __future__ import annotations

import asyncio
import math
from typing import Any

import numpy as np

from afa import Event, SubscribePublishServer
from afa.clock import TIME_TOLERANCE
from afa.errors import AfaError
from components.arc_arbiter.arbitrate import ArbiterDecision, VoteArbiter
from components.arc_arbiter.parameters import ArcArbiterParameters
from components.arc_arbiter.recovery import rear_axle, reverse_candidates, reverse_clearance
from components.arcs import ARC_SET_SECTION, ArcSet, ArcSetMismatchError, arc_set_of
from idl import ArcDecisionIDL, ArcVoteIDL, TimeIDL, VehicleControl, VelocityIDL
from idl.maps import TravMapArrayEventIDL

__all__ = ["ArcArbiter", "STALE_CHECK_PERIOD", "COMMAND_REFRESH"]

#: How often staleness is checked without a vote (s).
STALE_CHECK_PERIOD = 0.1
#: A command (and a decision event) goes out at least this often (s): below Vehicle
#: Control's 0.5 s command watchdog.
COMMAND_REFRESH = 0.2
#: Planned reverses (decision 0046) count in a row, up to ``RecoverLimit``, until one is
#: asked for this long (s) after the last one ended.
REVERSE_RESET = 15.0


class ArcArbiter(SubscribePublishServer[ArcArbiterParameters]):
    """The Arc Arbiter (module docstring)."""

    def __init__(self, name: str, parameters: ArcArbiterParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self.subscribes(p.VoteEventName, ArcVoteIDL, self._on_vote, maxsize=64, required=True)
        self.decisions = self.publishes(p.DecisionEventName, ArcDecisionIDL)
        if p.RecoverAfter > 0:
            self.subscribes(p.TraverseEventName, TravMapArrayEventIDL, self._on_map, maxsize=2)
        self._map: TravMapArrayEventIDL | None = None
        self._apron: tuple[float, float, float, float, float, float] | None = None
        self._vetoed_since: float | None = None  # every arc vetoed since then
        self._backing: tuple[int, float] | None = None  # arc index, reverse until
        self._backouts_in_row = 0  # since the last decision that let the vehicle drive
        self._reverse_seen = -math.inf  # receive time of the last reverse request handled
        self._reverse_ended = -math.inf  # when the last back (of either kind) ended
        self._reverses_in_row = 0
        self.control = self.uses(VehicleControl, p.VehicleControlName)
        self.arcs = ArcSet.from_parameters()
        self.book = VoteArbiter(p, self.arcs, required=p.RequiredBehaviours)
        self.decision: ArbiterDecision | None = None
        self._sent: tuple[int, float, float] | None = None  # index, speed, steering
        self._sent_at = -1e9
        self._published: tuple[int, float, str] | None = None
        self._published_at = -1e9
        self._queued: ArbiterDecision | None = None  # the latest decision to command
        self._wake = asyncio.Event()
        self._busy = False  # the sender's call is waiting for Vehicle Control
        self.counters = {"votes": 0, "decisions": 0, "commands": 0, "command_errors": 0,
                         "failsafe_stops": 0, "rejected_votes": 0, "backouts": 0,
                         "backouts_blocked": 0, "backouts_refused": 0, "reverses": 0,
                         "reverses_blocked": 0, "reverses_refused": 0}

    async def setup(self) -> None:
        self.arcs = arc_set_of(self.context.section(ARC_SET_SECTION))
        self.book = VoteArbiter(self.parameters, self.arcs,
                                required=self.parameters.RequiredBehaviours)
        self._sent = self._published = self._queued = None
        self._wake = asyncio.Event()
        self._busy = False
        self._map = None
        self._apron = None
        self._vetoed_since = self._backing = None
        self._backouts_in_row = self._reverses_in_row = 0
        self._reverse_seen = self._reverse_ended = -math.inf

    async def run(self) -> None:
        self.spawn(self._sender(), f"{self.name}:sender")
        tick = self.clock.monotonic()
        while True:
            expiry = self.book.expires()
            await self.clock.sleep_until(tick if expiry is None else min(tick, expiry))
            now = self.clock.monotonic()
            if now >= tick:  # the periodic check (drift-free; missed ticks skipped)
                tick += STALE_CHECK_PERIOD * (1 + int((now - tick) / STALE_CHECK_PERIOD))
            self._decide()

    def _on_vote(self, event: Event) -> None:
        vote: ArcVoteIDL = event.body  # type: ignore[assignment]
        try:
            self.book.receive(vote, self.clock.monotonic())
        except ArcSetMismatchError as exc:
            self.counters["rejected_votes"] += 1
            self.set_health(False, f"vote from {vote.behaviour} refused: {exc}")
            return
        self.counters["votes"] += 1
        self._decide()

    def _on_map(self, event: Event) -> None:
        self._map = event.body  # type: ignore[assignment]
        p = self.parameters
        if self._apron is None and p.StartApron > 0:
            try:
                x, y, heading = rear_axle(self._map, p.MapFrameOffset)
            except (ValueError, TypeError, AttributeError):  # a map without a vehicle pose
                pass
            else:
                # StartApron behind the rear axle and either side of the centre line (at
                # least a disc's radius beyond the body's discs), the body's length ahead
                self._apron = (x, y, heading, p.StartApron, max(p.DiscOffsets, default=0.0)
                               + 2.0 * p.VehicleRadius,
                               max(p.StartApron, 2.0 * p.VehicleRadius))
        if self._backing is not None and not self._reverse_clear(
                self._backing[0], (self._backing[1] - self.clock.monotonic())
                * self.parameters.RecoverSpeed):
            self._backing = None  # the rest of the back-out is blocked: stand
            self.counters["backouts_blocked"] += 1
            self._decide()

    def _reverse_clear(self, index: int, distance: float) -> bool:
        p = self.parameters
        if self._map is None:
            return False
        if distance <= 0:
            return True
        try:
            return reverse_clearance(self._map, float(self.arcs.curvatures[index]), distance,
                                     radius=p.VehicleRadius + p.RecoverMargin,
                                     offsets=p.DiscOffsets,
                                     map_offset=p.MapFrameOffset, apron=self._apron)
        except (ValueError, TypeError):  # a map without the layers it should hold
            return False

    def _back_out(self, decision: ArbiterDecision, now: float) -> ArbiterDecision:
        """The decision, or a reverse when every arc has been vetoed too long
        (module docstring)."""
        p = self.parameters
        if p.RecoverAfter <= 0:
            return decision
        self._planned_reverse(decision, now)
        if decision.failsafe is None and self._backouts_in_row:
            self._backouts_in_row = 0  # the votes let the vehicle drive again
            if self._health_detail.startswith("standing:"):
                self.set_health(True, "commanding")
        if decision.failsafe != "all-vetoed":
            if decision.failsafe is not None:
                self._backing = None  # stale or missing votes: stop, whatever else
            self._vetoed_since = None
            if self._backing is None:
                return decision
        elif self._vetoed_since is None:
            self._vetoed_since = now
        if self._backing is not None and now >= self._backing[1] - TIME_TOLERANCE:
            self._backing = None
            # a request voted while backing was planned from somewhere along the way
            self._reverse_seen = self._reverse_ended = now
            self._vetoed_since = None if decision.failsafe is None else now
        if self._backing is None and self._vetoed_since is not None \
                and now - self._vetoed_since >= p.RecoverAfter - TIME_TOLERANCE:
            self._vetoed_since = now  # the next try, if this one finds no way
            preferred = float(self.arcs.curvatures[int(np.argmax(decision.scores))])
            candidates = reverse_candidates(self.arcs.curvatures, preferred)
            if p.RecoverLimit and self._backouts_in_row >= p.RecoverLimit:
                candidates = []
                self.counters["backouts_refused"] += 1
                self.set_health(False, f"standing: every arc still vetoed after "
                                       f"{self._backouts_in_row} back-outs in a row "
                                       "(RecoverLimit)")
            for index in candidates:
                if self._reverse_clear(index, p.RecoverDistance):
                    self._backing = (index, now + p.RecoverDistance / p.RecoverSpeed)
                    self._backouts_in_row += 1
                    self.counters["backouts"] += 1
                    self.log.info("every arc vetoed for %.1f s: backing out %.1f m on "
                                  "curvature %.3f", p.RecoverAfter, p.RecoverDistance,
                                  float(self.arcs.curvatures[index]))
                    break
            else:
                if candidates:
                    self.counters["backouts_blocked"] += 1
        if self._backing is None:
            return decision
        index = self._backing[0]
        return ArbiterDecision(now, index, float(self.arcs.curvatures[index]),
                               self.arcs.steering_angle(index), -p.RecoverSpeed,
                               decision.scores, decision.vetoed, decision.fresh,
                               decision.stale, decision.unknown, None)

    def _planned_reverse(self, decision: ArbiterDecision, now: float) -> None:
        """Start the back a behaviour's fresh vote asks for (``ArcVoteIDL.reverse``,
        decision 0046: FindPath's way on starts by backing), once per request, on the
        arc nearest its curvature, at most ``RecoverDistance`` and ``RecoverLimit`` in
        a row, and only where it is clear on the map, as for a back-out."""
        p = self.parameters
        if self._backing is not None or decision.failsafe not in (None, "all-vetoed"):
            return
        request = self.book.reverse_request()
        if request is None or request[3] <= self._reverse_seen:
            return
        behaviour, distance, curvature, self._reverse_seen = request
        if now - self._reverse_ended > REVERSE_RESET:
            self._reverses_in_row = 0
        if p.RecoverLimit and self._reverses_in_row >= p.RecoverLimit:
            self.counters["reverses_refused"] += 1
            return
        index = int(np.argmin(np.abs(self.arcs.curvatures - curvature)))
        distance = min(distance, p.RecoverDistance)
        if not self._reverse_clear(index, distance):
            self.counters["reverses_blocked"] += 1
            return
        self._backing = (index, now + distance / p.RecoverSpeed)
        self._reverses_in_row += 1
        self.counters["reverses"] += 1
        self.log.info("%s asks to back %.1f m on curvature %.3f: backing",
                      behaviour, distance, float(self.arcs.curvatures[index]))

    def _decide(self) -> None:
        now = self.clock.monotonic()
        decision = self._back_out(self.book.decide(now), now)
        self.decision = decision
        self.counters["decisions"] += 1
        self._note_inputs(decision)
        key = (decision.index, decision.speed, decision.steering)
        if key != self._sent or now - self._sent_at >= COMMAND_REFRESH - TIME_TOLERANCE:
            if decision.failsafe is not None and (self._sent is None or self._sent[1] != 0):
                self.counters["failsafe_stops"] += 1
            self._sent, self._sent_at = key, now
            self._dispatch(decision)
        shown = (decision.index, decision.speed, decision.failsafe or "")
        if shown != self._published or now - self._published_at >= COMMAND_REFRESH - TIME_TOLERANCE:
            self._published, self._published_at = shown, now
            self._publish(decision)

    def _note_inputs(self, decision: ArbiterDecision) -> None:
        """Unhealthy while the vehicle is stopped for want of votes (every behaviour
        silent or stale, or a required one); a stop the votes decide (every arc vetoed,
        the mission finished) is the arbiter working. A failed command says more and
        stays until a command goes through."""
        if self._health_detail.startswith("setVelocity"):
            return
        if decision.failsafe == "no-fresh-vote" and self.book.ever_voted:  # (before
            # the first vote the required input says "waiting for")
            self.set_health(False, "stopped: no behaviour has a fresh vote")
        elif decision.failsafe == "missing-required":
            missing = sorted(self.book.required - set(decision.fresh))
            self.set_health(False, "stopped: no fresh vote from required "
                                   f"{', '.join(missing) or 'behaviours'}")
        elif self._health_detail.startswith("stopped:"):
            self.set_health(True, "commanding")

    def _dispatch(self, decision: ArbiterDecision) -> None:
        """Hand ``decision`` to the sender; a stop while the sender waits goes at once."""
        if decision.stopped and self._busy:
            self._queued = None  # anything queued is older than this stop
            self.spawn(self._command(decision), f"{self.name}:stop")
            return
        self._queued = decision
        self._wake.set()

    async def _sender(self) -> None:
        """One setVelocity at a time, always the latest decision queued."""
        while True:
            await self._wake.wait()
            self._wake.clear()
            decision, self._queued = self._queued, None
            if decision is None:
                continue
            self._busy = True
            try:
                await self._command(decision)
            finally:
                self._busy = False

    async def _command(self, decision: ArbiterDecision) -> None:
        velocity = VelocityIDL(translation=decision.speed,
                               rotation=decision.speed * decision.curvature,
                               steeringAngle=decision.steering)
        try:
            await self.control.setVelocity(velocity)
        except AfaError as exc:  # the link is down, or Vehicle Control is restarting
            self.counters["command_errors"] += 1
            self.set_health(False, f"setVelocity failed: {exc}")
            return
        self.counters["commands"] += 1
        if not self.health().healthy and self._health_detail.startswith("setVelocity"):
            self.set_health(True, "commanding")

    def _publish(self, decision: ArbiterDecision) -> None:
        self.decisions.publish(ArcDecisionIDL(
            time=TimeIDL.from_seconds(self.clock.now()), curvatures=self.arcs.curvatures,
            scores=decision.scores, vetoed=decision.vetoed, index=decision.index,
            curvature=decision.curvature, steeringAngle=decision.steering,
            speed=decision.speed, fresh=decision.fresh, stale=decision.stale,
            unknown=decision.unknown, failsafe=decision.failsafe or ""))

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        if self.decision is not None:
            stats["failsafe"] = self.decision.failsafe
            stats["speed"] = self.decision.speed
        return stats
