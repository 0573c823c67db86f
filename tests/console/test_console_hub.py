"""The console's data side without a web server: sessions get what they show at their
rates, the component table, actions, replay, the loop profiler and memory estimate.

The hub paces itself on the system's virtual clock here (in a real run it paces on the
wall clock), so rates are exact and the tests deterministic."""

import asyncio
import logging

import numpy as np
import pytest
from console_synthetic import FakeVehicleControl, synthetic_system

from afa import Component, SubscribePublishServer, System, VirtualClock
from afa.console.frames import decode_frame
from afa.console.hub import ConsoleHub, HubOptions
from afa.console.launcher import LoopProfiler, retained_bytes
from afa.console.replay import replay_control
from afa.errors import ComponentError
from afa.tasks import TaskGroup
from idl import Range3dLaserIDL, Range3dSeqEventIDL, TimeIDL


class Browser:
    """A session's send: keeps (header, events) of every message."""

    def __init__(self):
        self.messages = []

    async def send(self, data):
        self.messages.append(decode_frame(data))

    def kinds(self):
        return [header["kind"] for header, _ in self.messages]


async def started(system, **options):
    hub = ConsoleHub(system, HubOptions(**options), wall=system.clock)
    await system.start()
    await hub.start()
    return hub


async def test_a_browser_gets_only_the_kinds_it_shows_at_their_rates():
    system = synthetic_system(VirtualClock(start=0.0))
    hub = await started(system)
    browser = Browser()
    session = hub.open_session(browser.send)
    session.subscribe({"map.traverse": 1.0, "arcs.decision": 2.0, "nonsense": 5})
    sender = hub.spawn(session.run(), owner="console sender")
    await system.clock.advance(10.0)
    sender.cancel()
    counts = {kind: browser.kinds().count(kind) for kind in set(browser.kinds())}
    assert set(counts) == {"map.traverse", "arcs.decision"}
    assert 9 <= counts["map.traverse"] <= 11        # 5 maps a second published, 1 sent
    assert 19 <= counts["arcs.decision"] <= 21      # 10 decisions a second published
    header, events = browser.messages[-1]
    assert len(events) == 1 and events[0].type in ("Traverse", "ArcDecision")
    stats = session.statistics()["streams"]["map.traverse/Traverse"]
    assert stats["dropped"] > 30 and stats["rate"] == 1.0
    await hub.aclose()
    await system.stop()


async def test_a_view_shown_later_gets_the_latest_at_once_and_range_events_their_transform():
    system = synthetic_system(VirtualClock(start=0.0))
    hub = await started(system)
    await system.clock.advance(2.0)  # nobody watching
    browser = Browser()
    session = hub.open_session(browser.send)
    sender = hub.spawn(session.run(), owner="console sender")
    session.subscribe({"geometry": None, "range.laser": None, "ego.traverse": None})
    await system.clock.advance(0.001)
    kinds = browser.kinds()
    assert {"geometry", "range.laser", "ego.traverse"} <= set(kinds)
    geometry = next(h for h, _ in browser.messages if h["kind"] == "geometry")
    names = {f["name"] for f in geometry["frames"]}
    assert "Raptor:Front-BumperCenter" in names and geometry["reference"] == "Raptor:RearAxleCenter"
    laser = next(h for h, _ in browser.messages if h["kind"] == "range.laser")
    transform = np.array(laser["transform"]).reshape(4, 4)
    assert np.allclose(transform[3], [0, 0, 0, 1]) and transform[2, 3] > 1.0  # laser mounted high
    sender.cancel()
    await hub.aclose()
    await system.stop()


async def test_the_launcher_table_counts_events_by_origin_and_lists_what_did_not_start():
    system = synthetic_system(VirtualClock(start=0.0))
    hub = await started(system)
    await system.clock.advance(3.0)
    status = hub.status()
    rows = {row["name"]: row for row in status["components"]}
    assert set(rows) == {"modelServer", "synthetic", "RaptorService"}
    assert rows["synthetic"]["state"] == "running" and rows["synthetic"]["events_out"] > 100
    assert rows["RaptorService"]["events_out"] >= 14  # VelocityData, 5 a second
    assert rows["modelServer"]["start_delay"] == pytest.approx(0.2)  # the Launcher's dT
    not_started = {entry["name"]: entry["state"] for entry in status["not_started"]}
    assert not_started["NodLaserService"] == "not started"  # excluded by only=[...]
    assert set(status["votes"]) == {"ObstacleAvoidance", "PurePursuit", "FindPath",
                                    "ObstacleDetection"}
    assert not any(v["stale"] for v in status["votes"].values())
    assert status["vehicle_control"] == "RaptorMotion"
    assert status["vehicle_control_component"] == "RaptorService"
    # the stack stops voting: after the stale time every vote is stale
    await hub.component_action("synthetic", "stop")
    await system.clock.advance(2.0)
    assert all(v["stale"] for v in hub.status()["votes"].values())
    await hub.aclose()
    await system.stop()


async def test_launcher_actions_and_the_vehicle_commands():
    system = synthetic_system(VirtualClock(start=0.0))
    hub = await started(system)
    control = system.components["RaptorService"]
    assert isinstance(control, FakeVehicleControl)
    assert await hub.component_action("synthetic", "restart") == "running"
    assert await hub.component_action("synthetic", "stop") == "stopped"
    assert await hub.component_action("synthetic", "start") == "running"
    with pytest.raises(KeyError):
        await hub.component_action("nobody", "restart")
    with pytest.raises(ValueError):
        await hub.component_action("synthetic", "explode")
    assert await hub.vehicle_action("stop") == "RaptorMotion"
    await hub.vehicle_action("start")
    await hub.vehicle_action("arbiter-on")
    assert control.calls == ["stopVehicle", "startVehicle", "setArbiter(True)"]
    assert [a["action"] for a in hub.status()["actions"]] == [
        "restart", "stop", "start", "vehicle stop", "vehicle start", "vehicle arbiter-on"]
    await hub.aclose()
    await system.stop()


async def test_stop_vehicle_says_so_when_nobody_serves_vehicle_control():
    system = System([], clock=VirtualClock(start=0.0))
    hub = await started(system)
    with pytest.raises(ComponentError, match="no component serves VehicleControl"):
        await hub.vehicle_action("stop")
    await hub.aclose()
    await system.stop()


class Player:
    """A log player with other verbs than the protocol's (resume, a speed attribute)."""

    def __init__(self):
        self.calls = []
        self.position, self.duration, self.speed, self.paused = 0.0, 60.0, 1.0, True

    def resume(self):
        self.calls.append("resume")
        self.paused = False

    async def pause(self):
        self.calls.append("pause")
        self.paused = True

    def step(self):
        self.calls.append("step")
        self.position += 0.1

    def seek(self, position):
        self.calls.append(f"seek {position}")
        self.position = position


async def test_replay_controls_drive_a_player_through_the_adapter():
    player = Player()
    system = System([], clock=VirtualClock(start=0.0))
    hub = ConsoleHub(system, wall=system.clock, replay=replay_control(player))
    await system.start()
    await hub.start()
    await hub.replay_action("play")
    await hub.replay_action("pause")
    await hub.replay_action("step")
    status = await hub.replay_action("seek", 12.5)
    assert status["position"] == 12.5 and status["paused"] is True
    status = await hub.replay_action("speed", 4)
    assert player.speed == 4.0 and status["speed"] == 4.0
    assert player.calls == ["resume", "pause", "step", "seek 12.5"]
    for action, value in (("speed", 0), ("speed", "fast"), ("seek", -1), ("rewind", None)):
        with pytest.raises(ValueError):
            await hub.replay_action(action, value)
    await hub.aclose()
    await system.stop()
    live = ConsoleHub(System([], clock=VirtualClock()))
    with pytest.raises(ComponentError, match="not a recording"):
        await live.replay_action("play")


class TwoForms(SubscribePublishServer):
    """A laser publishing each scan line in both forms, as the Nodding Laser does."""

    def __init__(self):
        super().__init__("laser")
        self.seq = self.publishes("Laser11", Range3dSeqEventIDL)
        self.array = self.publishes("Laser11Array", Range3dLaserIDL)

    async def run(self):
        points = np.ones((2, 3), dtype=np.float32)
        line = Range3dLaserIDL(time=TimeIDL(sec=0), sensorId=11, frame="L:F", points=points,
                               valid=np.ones(2, dtype=bool))
        async for _ in self.clock.periodic(0.1):
            self.seq.publish(line.to_seq())
            self.array.publish(line)


async def test_a_laser_published_in_both_forms_is_shown_once():
    system = System([TwoForms()], clock=VirtualClock(start=0.0))
    hub = await started(system)
    await system.clock.advance(1.0)
    streams = [stream for stream, (kind, _) in hub._latest.items() if kind == "range.laser"]
    assert streams == ["range.laser/Laser11"]
    await hub.aclose()
    await system.stop()


async def test_a_failing_encoding_skips_one_message_not_the_stream(caplog):
    system = synthetic_system(VirtualClock(start=0.0))
    hub = await started(system)
    browser = Browser()
    session = hub.open_session(browser.send)
    session.subscribe({"arcs.decision": 10.0})
    original, calls = hub.frame_for, []

    def flaky(*args):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("boom")
        return original(*args)

    hub.frame_for = flaky
    sender = hub.spawn(session.run(), owner="console sender")
    with caplog.at_level(logging.ERROR, logger="afa.console"):
        await system.clock.advance(1.0)
    assert session.failed == 1 and len(browser.messages) >= 8
    assert "cannot encode arcs.decision" in caplog.text
    sender.cancel()
    await hub.aclose()
    await system.stop()


async def test_the_profiler_times_task_steps_by_component_and_restores_the_factory():
    loop = asyncio.get_running_loop()
    previous = loop.get_task_factory()
    profiler = LoopProfiler(lambda: ["modelServer", "synthetic"])
    profiler.install()
    try:
        async def busy(n):
            total = 0
            for _ in range(3):
                total += sum(range(n))
                await asyncio.sleep(0)
            return total

        async def fails():
            raise ValueError("inside")

        async with TaskGroup("t") as group:
            done = group.spawn(busy(200_000), owner="synthetic", name="synthetic:handler")
            supervisor = group.spawn(busy(10), owner="x", name="afa-supervisor:modelServer")
            assert await done == 3 * sum(range(200_000)) and await supervisor == 3 * sum(range(10))
        with pytest.raises(ValueError, match="inside"):
            await loop.create_task(fails())
    finally:
        profiler.uninstall()
    assert loop.get_task_factory() is previous
    totals = profiler.snapshot()
    assert totals["synthetic"] > totals["modelServer"] > 0
    assert profiler.attribute("observer simulation") == "observer simulation"
    assert profiler.attribute("Task-17") == "(unnamed tasks)"
    assert profiler.attribute("console sender") == "console"


class Holder(Component):
    def __init__(self):
        super().__init__("holder")
        self.grid = np.zeros((512, 512), dtype=np.float32)   # 1 MiB
        self.view = self.grid[:10]                           # counted once
        self.history = [np.zeros(1000) for _ in range(10)]   # 80 kB


def test_the_memory_estimate_counts_what_a_component_holds_once():
    holder = Holder()
    System([holder])
    size = retained_bytes(holder)
    assert 1_048_576 + 80_000 <= size < 1_048_576 + 80_000 + 50_000


class Planner(Component):
    def __init__(self):
        super().__init__("planner")
        self.table = {(i, i + 1): (float(i), i) for i in range(20_000)}  # many small objects


def test_a_large_table_is_estimated_from_a_sample_quickly():
    import sys

    planner = Planner()
    exact = sys.getsizeof(planner.table) + sum(
        sys.getsizeof(k) + sum(sys.getsizeof(x) for x in k)
        + sys.getsizeof(v) + sum(sys.getsizeof(x) for x in v) for k, v in planner.table.items())
    estimate = retained_bytes(planner)
    assert 0.7 * exact < estimate < 1.3 * exact
