"""The Arc Arbiter as a component: ArcVote events in, setVelocity to the real Vehicle
Control (the MPC555 driver) out, over a 115200 baud line to the fake MPC555 whose received
bytes are what the vehicle obeys ("the wire").

Votes are published here as the behaviours would publish them (the behaviours are not
under test). Expected scores, choices and speeds are worked out here from the seed's rule
(weighted sum of certainty × vote, vetoes out, least maxSpeed), not by the arbiter's core.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from vehicle_rig import Cruise, SerialLine, stops_after, wire_commands

from afa import System, VirtualClock
from afa.events import Subscription
from afa.testing import until
from components.arc_arbiter import ArcArbiter
from components.arc_arbiter.component import COMMAND_REFRESH
from components.arc_arbiter.parameters import ArcArbiterParameters
from components.arcs import ArcSet, ArcSetParameters
from components.mpc555 import VehicleControl, VehicleControlParameters
from components.mpc555.codec import Mode, SetVelocity, StopVehicle
from components.mpc555.fake import FakeMpc555
from idl import ArcDecisionIDL, ArcVoteIDL, TimeIDL
from idl import VehicleControl as VehicleControlInterface

ARCS = ArcSet.from_parameters()
N = len(ARCS)
#: SET_VELOCITY on the wire: A5 01 LEN TYPE SEQ, 4 payload bytes, CRC-16 (11 bytes);
#: HEARTBEAT and STOP_VEHICLE have no payload (7 bytes).
SET_VELOCITY_BYTES = 11
SHORT_FRAME_BYTES = 7
SCAN_PERIOD_BOUND = 0.0266


@dataclass
class Rig:
    clock: VirtualClock
    system: System
    fake: FakeMpc555
    line: SerialLine
    arbiter: ArcArbiter
    vc: VehicleControl
    cruise: Cruise | None
    decisions: Subscription
    control: Any

    def publish(self, vote: ArcVoteIDL) -> None:
        self.system.channel.publish("Raptor", "ArcVote", vote, origin="test")

    def publish_at(self, t: float, vote: ArcVoteIDL) -> None:
        self.clock.call_at(t, lambda: self.publish(vote))

    async def until(self, t: float) -> None:
        await self.clock.advance(t - self.clock.monotonic())

    def frames(self, *sizes: int) -> float:
        """Seconds the line takes for frames of these sizes."""
        return sum(sizes) * self.line.byte_time

    def decisions_seen(self) -> list[Any]:
        events = []
        while (event := self.decisions.get_nowait()) is not None:
            events.append(event)
        return events


@asynccontextmanager
async def rig(*, arbiter_on: bool = True, cruise: bool = True,
              parameters: ArcArbiterParameters | None = None) -> AsyncIterator[Rig]:
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock, record=True)
    line = SerialLine(clock)
    arbiter = ArcArbiter("arcArbiter", parameters or ArcArbiterParameters())
    vc = VehicleControl("RaptorService", VehicleControlParameters())
    components: list[Any] = [vc, arbiter]
    driver = Cruise(speed=0.5) if cruise else None
    if driver is not None:
        components.append(driver)
    system = System(components, clock=clock,
                    devices={"RaptorService": line.factory(fake.factory())})
    try:
        async with system:
            decisions = system.channel.subscribe("Raptor", "ArcDecision", maxsize=1 << 14)
            await until(lambda: vc.configured, clock, what="the MPC555 configured")
            control = await system.resolve(VehicleControlInterface, "RaptorMotion")
            await control.startVehicle()
            if arbiter_on:
                await control.setArbiter(True)
            yield Rig(clock, system, fake, line, arbiter, vc, driver, decisions, control)
    finally:
        await fake.aclose()


def vote(behaviour: str, *, veto: Any = False, votes: Any = None, certainty: Any = 1.0,
         speed: Any = 2.0, arcs: ArcSet = ARCS) -> ArcVoteIDL:
    n = len(arcs)
    return ArcVoteIDL(
        time=TimeIDL(sec=0), behaviour=behaviour, curvatures=arcs.curvatures,
        veto=np.broadcast_to(np.asarray(veto, dtype=bool), (n,)).copy(),
        vote=np.broadcast_to(np.asarray(1.0 if votes is None else votes, dtype=np.float32),
                             (n,)).copy(),
        certainty=np.broadcast_to(np.asarray(certainty, dtype=np.float32), (n,)).copy(),
        maxSpeed=np.broadcast_to(np.asarray(speed, dtype=np.float32), (n,)).copy())


def drives(r: Rig, after: float = -math.inf) -> list[Any]:
    return [c for c in wire_commands(r.fake, SetVelocity, after)
            if c.command.translation_mm_s > 0]


# --------------------------------------------------------------------------- the switch

async def test_commands_reach_the_wire_only_while_the_arbiter_switch_is_on():
    async with rig(arbiter_on=False) as r:
        await r.until(3.0)
        assert wire_commands(r.fake, SetVelocity) == []
        ignored = r.vc.statistics()["ignored_velocity_commands"]
        assert ignored > 0  # the arbiter did command: Vehicle Control kept it off the wire
        assert r.fake.mode is Mode.RUNNING
        await r.control.setArbiter(True)
        on = r.clock.monotonic()
        await r.until(5.0)
        moving = drives(r)
        # the arbiter re-sends its decision at least every COMMAND_REFRESH
        assert moving and moving[0].time <= on + COMMAND_REFRESH + r.frames(
            SHORT_FRAME_BYTES, SET_VELOCITY_BYTES)
        assert moving[0].command == SetVelocity(500, 0)
        assert r.fake.mode is Mode.ARBITER and r.fake.target_translation == 0.5
        await r.control.setArbiter(False)
        off = r.clock.monotonic()
        await r.until(7.0)
        assert wire_commands(r.fake, SetVelocity, off) == []


# --------------------------------------------------------------------------- fail-safes

@pytest.mark.parametrize("phase", [0.0, 0.0001, 0.025, 0.05, 0.0999])
async def test_when_every_vote_goes_stale_a_stop_is_on_the_wire_within_100_ms(phase):
    stale_after = ArcArbiterParameters().stale_vote_time
    async with rig(cruise=False) as r:
        first = 2.0 + phase
        times = [first + 0.1 * k for k in range(20)]
        for t in times:
            r.publish_at(t, vote("PurePursuit", speed=0.5))
        last = times[-1]
        gone_stale = last + stale_after
        await r.until(gone_stale + 1.0)
        assert drives(r) and drives(r)[0].time < last
        stops = stops_after(r.fake, drives(r)[0].time)
        assert stops, "no stop after the votes went stale"
        # fresh until last + StaleVoteTime, then a stop within 100 ms
        assert gone_stale <= stops[0].time <= gone_stale + 0.1
        final = r.decisions_seen()[-1].body
        assert final.failsafe == "no-fresh-vote" and final.stale == ("PurePursuit",)


async def test_health_shows_a_stop_for_want_of_votes_and_recovers_with_a_fresh_one():
    """Not "ok" while the vehicle stands because no behaviour votes (a stack without
    inputs); a vetoed stop is the arbiter working, and healthy."""
    stale_after = ArcArbiterParameters().stale_vote_time
    async with rig(cruise=False) as r:
        await r.until(1.0)
        health = r.arbiter.health()
        assert not health.healthy and health.detail == "waiting for ArcVote"
        r.publish(vote("PurePursuit", speed=0.5))
        await r.until(1.05)
        assert r.arbiter.health().healthy
        r.publish(vote("ObstacleAvoidance", veto=True, votes=0.0))
        await r.until(1.1)
        assert r.decisions_seen()[-1].body.failsafe == "all-vetoed"
        assert r.arbiter.health().healthy
        await r.until(1.0 + stale_after + 0.2)
        health = r.arbiter.health()
        assert not health.healthy and "no behaviour has a fresh vote" in health.detail


async def test_every_arc_vetoed_stops_at_once_and_a_silent_vetoer_loses_its_veto():
    stale_after = ArcArbiterParameters().stale_vote_time
    async with rig() as r:
        await r.until(2.0)
        assert r.fake.target_translation == 0.5
        t_veto = 2.0123
        r.publish_at(t_veto, vote("ObstacleAvoidance", veto=True, votes=0.0))
        await r.until(t_veto + 0.5)
        stop = stops_after(r.fake, t_veto)[0]
        assert stop.time - t_veto <= r.frames(SHORT_FRAME_BYTES, SET_VELOCITY_BYTES)
        assert drives(r, t_veto) == []
        # the veto holds while fresh, and is dropped (not frozen) once stale
        await r.until(t_veto + stale_after + 1.0)
        resumed = drives(r, t_veto)
        assert resumed and t_veto + stale_after < resumed[0].time
        assert resumed[0].time <= t_veto + stale_after + 0.1 + COMMAND_REFRESH
        shown = [e.body for e in r.decisions_seen()]
        assert any(d.failsafe == "all-vetoed" for d in shown)
        assert shown[-1].failsafe == "" and "ObstacleAvoidance" in shown[-1].stale


async def test_no_valid_vote_is_a_stop():
    async with rig() as r:
        await r.until(2.0)
        assert r.fake.target_translation == 0.5
        assert r.cruise is not None
        r.cruise.paused = True
        # a vote with nothing to steer by: certainty 0 everywhere (a clear safety vote)
        t = 2.0377
        r.publish_at(t, vote("PurePursuit", certainty=0.0, speed=0.5))
        await r.until(3.0)
        stop = stops_after(r.fake, t)[0]
        assert stop.time - t <= r.frames(SHORT_FRAME_BYTES, SET_VELOCITY_BYTES)
        assert r.decisions_seen()[-1].body.failsafe == "no-valid-vote"
        assert r.fake.target_translation == 0.0


async def test_before_any_vote_the_arbiter_commands_a_stop():
    async with rig(cruise=False) as r:
        await r.until(2.0)
        sent = wire_commands(r.fake, SetVelocity)
        assert sent and all(c.command.translation_mm_s == 0 for c in sent)
        assert r.decisions_seen()[-1].body.failsafe == "no-fresh-vote"


# --------------------------------------------------------------------------- the decision

async def test_the_decision_is_published_with_arc_scores_and_vetoes_and_commanded():
    p = ArcArbiterParameters(ObsWeight=2.0, PursuitWeight=1.0, TransVelocitySetPoint=1.5)
    k = ARCS.curvatures
    # Pure Pursuit wants the left (a ramp towards hard left); Obstacle Avoidance vetoes
    # the three hardest left arcs and prefers the right a little, unsure of it.
    pursuit = np.linspace(1.0, 0.0, N, dtype=np.float32)
    avoid_vote = np.linspace(0.2, 0.6, N, dtype=np.float32)
    avoid_certainty = np.full(N, 0.5, dtype=np.float32)
    avoid_veto = np.zeros(N, dtype=bool)
    avoid_veto[:3] = True
    avoid_speed = np.linspace(0.8, 1.2, N, dtype=np.float32)
    async with rig(cruise=False, parameters=p) as r:
        await r.until(2.0)
        r.publish(vote("PurePursuit", votes=pursuit, speed=1.0))
        r.publish(vote("ObstacleAvoidance", veto=avoid_veto, votes=avoid_vote,
                       certainty=avoid_certainty, speed=avoid_speed))
        await r.until(2.1)
        decision: ArcDecisionIDL = r.decisions_seen()[-1].body
        sent = wire_commands(r.fake, SetVelocity)[-1].command
    scores = 1.0 * pursuit.astype(float) + 2.0 * avoid_certainty * avoid_vote.astype(float)
    best = max((i for i in range(N) if not avoid_veto[i]), key=lambda i: scores[i])
    assert best == 3  # the ramp and the weights were chosen so that this is unambiguous
    speed = min(1.5, 1.0, float(avoid_speed[best]))
    assert decision.curvatures.tolist() == k.tolist()
    assert decision.vetoed.tolist() == avoid_veto.tolist()
    assert decision.scores == pytest.approx(scores, abs=1e-6)
    assert decision.index == best and decision.curvature == pytest.approx(k[best])
    assert decision.speed == pytest.approx(speed, abs=1e-6) and decision.failsafe == ""
    assert decision.fresh == ("ObstacleAvoidance", "PurePursuit")
    assert decision.steeringAngle == pytest.approx(math.atan(k[best] * 1.9), abs=1e-9)
    # on the wire: v in mm/s and w = v·κ in mrad/s (rounded by the driver)
    assert sent.translation_mm_s == round(speed * 1000)
    assert abs(sent.rotation_mrad_s - speed * k[best] * 1000) <= 1.0


async def test_votes_over_another_arc_set_are_refused_and_the_arbiter_shows_unhealthy():
    other = ArcSet.from_parameters(ArcSetParameters(Count=25))
    async with rig() as r:
        await r.until(2.0)
        assert r.arbiter.health().healthy
        r.publish(vote("ObstacleAvoidance", veto=True, arcs=other))
        await r.until(2.5)
        health = r.arbiter.health()
        assert not health.healthy and "ObstacleAvoidance" in health.detail
        assert r.arbiter.statistics()["rejected_votes"] == 1
        assert "ObstacleAvoidance" not in r.decisions_seen()[-1].body.fresh
        assert r.fake.target_translation == 0.5  # the refused veto did not count


# --------------------------------------------------------------------------- silence

async def test_vehicle_controls_watchdog_stops_the_vehicle_when_the_arbiter_falls_silent():
    watchdog = VehicleControlParameters().CommandWatchdog
    async with rig() as r:
        await r.until(2.0)
        assert r.fake.target_translation == 0.5
        await r.system.stop_component("arcArbiter")
        silent = r.clock.monotonic()
        await r.until(silent + 2.0)
        last = wire_commands(r.fake, SetVelocity)[-1]
        assert last.time <= silent + r.frames(SHORT_FRAME_BYTES, SET_VELOCITY_BYTES)
        stop = wire_commands(r.fake, StopVehicle, silent)[0]
        # (Vehicle Control counts from the last command it saw acknowledged: the arbiter's
        # last call may have been cut short by its stop, so the stop may come earlier)
        assert silent < stop.time <= last.time + watchdog + r.frames(
            SHORT_FRAME_BYTES, SHORT_FRAME_BYTES)
        assert r.fake.mode is Mode.STOPPED
        assert "watchdog" in r.vc.health().detail


# --------------------------------------------------------------------------- halts in a busy link

async def test_a_halt_is_not_lost_behind_a_command_in_flight():
    """A halt decided while an earlier command waits for its ACK, followed by an equal
    decision (another behaviour's vote) before the ACK, still goes out at once."""
    async with rig() as r:
        assert r.cruise is not None
        r.cruise.paused = True
        t = 2.0
        r.publish_at(t, vote("PurePursuit", speed=0.4))  # a new command: on the wire
        halt_at = t + r.frames(SET_VELOCITY_BYTES) / 2  # while it is still being sent
        r.publish_at(halt_at, vote("ObstacleDetection", veto=True, votes=0.0, certainty=0.0))
        r.publish_at(halt_at + r.line.byte_time, vote("PurePursuit", speed=0.4))
        await r.until(t + 1.0)
        assert drives(r, t)[0].command.translation_mm_s == 400
        stop = stops_after(r.fake, t)[0]
        assert stop.time - halt_at <= SCAN_PERIOD_BOUND


async def test_a_halt_is_not_held_behind_a_command_awaiting_a_lost_ack():
    """A command whose ACK is lost keeps its caller waiting 50 ms (ACK_TIMEOUT); a halt
    decided meanwhile must not wait for it."""
    async with rig() as r:
        assert r.cruise is not None
        await r.until(1.95)
        assert r.fake.target_translation == 0.5
        r.cruise.paused = True
        t = 2.0
        await r.until(t)
        r.fake.mute_acks = True  # line noise: the controller's ACKs are lost
        r.publish(vote("PurePursuit", speed=0.4))  # a new command, never acknowledged
        halt_at = t + r.frames(SET_VELOCITY_BYTES) * 2
        r.publish_at(halt_at, vote("ObstacleDetection", veto=True, votes=0.0, certainty=0.0))
        await r.until(t + 0.2)
        r.fake.mute_acks = False
        await r.until(t + 1.0)
        stop = stops_after(r.fake, t)[0]
        assert stop.time - halt_at <= SCAN_PERIOD_BOUND
        assert r.arbiter.statistics()["command_errors"] >= 1  # the lost ACKs were noticed
        assert r.fake.target_translation == 0.0
