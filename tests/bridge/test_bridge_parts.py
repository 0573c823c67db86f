"""The bridge's pieces without a network: key expressions, the Bridge section and the
Launcher's process groups, the command guard, the thread-to-loop inbox, loop-time
accounting, and what the tools print."""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path

import pytest

from afa import CommandRefused, ConfigError, Event, System, VirtualClock
from afa.bridge import Bridge, BridgeParameters, bridge_parameters, keys
from afa.bridge.guard import check_command, commands
from afa.bridge.link import Inbox
from afa.bridge.parameters import off_loopback
from afa.bridge.remote import caller_attachment, find_interface, parse_caller
from afa.config.loader import load_configuration
from afa.errors import InterfaceError
from afa.meter import LoopMeter
from afa.tools.commands import parse_arguments, rate_report, render_top
from idl import GlobalMap, Platform, VehicleControl, VehiclePlan, VelocityIDL
from tests.bridge.parts import Count, Counter, CounterServer

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"


def test_key_expressions() -> None:
    assert keys.event("Raptor", "Pose") == "afa/Raptor/event/Pose"
    assert keys.poll("Raptor", "ModelService", "getPose") == "afa/Raptor/poll/ModelService/getPose"
    assert keys.alive_name("Raptor", "Gps", "vehicle", "idl.interfaces.Gps") == \
        "afa/Raptor/alive/name/Gps/vehicle/idl.interfaces.Gps"
    assert keys.parse("afa/Raptor/poll/Gps/getPosition") == ("Raptor", "poll",
                                                             ["Gps", "getPosition"])
    with pytest.raises(ValueError):
        keys.parse("other/Raptor/event/Pose")
    assert keys.chunk_ok("3dmgService") and keys.chunk_ok("idl.interfaces.Gps")
    for bad in ("", "a/b", "a*", "$x", "a b", "a#"):
        assert not keys.chunk_ok(bad), bad


def test_the_bridge_section_per_process_with_overrides() -> None:
    config = load_configuration(RAPTOR)
    assert config.processes() == ["vehicle", "autonomy"]
    main = bridge_parameters(config, None)
    assert not main.Enabled and main.Listen == ["tcp/127.0.0.1:7447"] and not main.MulticastScouting
    vehicle = bridge_parameters(config, "vehicle")
    assert vehicle.AllowCommandFrom == ["autonomy"] and vehicle.TimeMaster == "vehicle"
    autonomy = bridge_parameters(config, "autonomy", Listen=["tcp/127.0.0.1:9999"],
                                 Connect=None)
    assert autonomy.Listen == ["tcp/127.0.0.1:9999"]  # the command line wins
    assert autonomy.Connect == ["tcp/127.0.0.1:7447"]  # None: the file's value
    assert bridge_parameters(None, "x") == BridgeParameters()
    assert off_loopback(BridgeParameters()) == []
    assert off_loopback(BridgeParameters(Listen=["tcp/0.0.0.0:7447"],
                                         Connect=["tcp/localhost:1"])) == ["tcp/0.0.0.0:7447"]


@pytest.mark.parametrize("field, value, message", [
    ("Listen", ["127.0.0.1:7447"], "is not a Zenoh endpoint"),
    ("Export", ["Raptor/Pose"], "no '/'"),
    ("MaxQueries", 0, "greater than or equal to 1"),
    ("Mode", "router", "'peer' or 'client'"),
])
def test_a_bad_bridge_section_names_the_field(tmp_path: Path, field: str, value: object,
                                              message: str) -> None:
    rendered = (f'<parameter name="{field}" value="{value}"/>' if not isinstance(value, list)
                else f'<parameter name="{field}"><parameter value="{value[0]}"/></parameter>')
    path = tmp_path / "bad.xml"
    path.write_text(f"""<config>
  <section name="Robot"><parameter name="Miro::RobotParameters">
    <parameter name="Name" value="Raptor"/></parameter></section>
  <section name="Bridge"><parameter name="Afa::BridgeParameters">
    {rendered}
  </parameter></section>
</config>""")
    with pytest.raises(ConfigError) as caught:
        load_configuration(path)
    assert f"Bridge/{field}" in str(caught.value) and message in str(caught.value)


def test_a_process_group_name_must_be_a_plain_word(tmp_path: Path) -> None:
    text = RAPTOR.read_text().replace('name="Process" value="vehicle"',
                                      'name="Process" value="my vehicle"', 1)
    path = tmp_path / "bad.xml"
    path.write_text(text.replace('value="050917raptor01.XML"',
                                 f'value="{RAPTOR.parent / "050917raptor01.XML"}"'))
    with pytest.raises(ConfigError, match="Process: a process group name is"):
        load_configuration(path)


def test_a_group_runs_only_its_launcher_entries() -> None:
    whole = System.from_xml(RAPTOR, real_devices=False)
    vehicle = System.from_xml(RAPTOR, process="vehicle", bridge=False, real_devices=False)
    autonomy = System.from_xml(RAPTOR, process="autonomy", bridge=False, real_devices=False)
    assert set(vehicle.components) | set(autonomy.components) == set(whole.components)
    assert not set(vehicle.components) & set(autonomy.components)
    assert {"modelServer", "RaptorService", "GpsSokkiaService"} <= set(vehicle.components)
    assert vehicle.process == "vehicle" and whole.process == "main"
    assert vehicle.start_after == 0.0 and autonomy.start_after > 0.0
    with pytest.raises(ConfigError, match="no Launcher entry is in process group 'nope'"):
        System.from_xml(RAPTOR, process="nope", bridge=False)


@pytest.mark.parametrize("interface, method, arguments, moves", [
    (VehicleControl, "setVelocity", {"velocity": VelocityIDL()}, True),
    (VehicleControl, "setJoystickVelocity", {"velocity": VelocityIDL()}, True),
    (VehicleControl, "startVehicle", {}, True),
    (VehicleControl, "setArbiter", {"enabled": False}, True),
    (VehicleControl, "stopVehicle", {}, False),
    (VehicleControl, "getTargetVelocity", {}, False),
    (VehiclePlan, "setWaypointList", {"waypoints": None}, True),
    (VehiclePlan, "setHalt", {"halt": False}, True),
    (VehiclePlan, "setHalt", {"halt": True}, False),
    (GlobalMap, "setWaypointList", {"waypoints": None}, True),
    (Platform, "getTransformation", {"A": "a", "B": "b"}, False),
])
def test_which_calls_command_the_vehicle(interface: type, method: str,
                                         arguments: dict[str, object], moves: bool) -> None:
    assert commands(interface, method, arguments) is moves


def test_the_guard_refuses_unless_the_caller_is_named() -> None:
    velocity = {"velocity": VelocityIDL(translation=1.0)}
    with pytest.raises(CommandRefused, match="setVelocity from console refused"):
        check_command(VehicleControl, "setVelocity", velocity, ("console", "z1"), [],
                      server="Raptor/RaptorMotion")
    check_command(VehicleControl, "setVelocity", velocity, ("autonomy", "z2"), ["autonomy"],
                  server="Raptor/RaptorMotion")
    check_command(VehicleControl, "setVelocity", velocity, ("x", "z3"), ["z3"],
                  server="Raptor/RaptorMotion")  # by Zenoh id
    check_command(VehicleControl, "setVelocity", velocity, ("", ""), ["*"],
                  server="Raptor/RaptorMotion")
    check_command(VehicleControl, "stopVehicle", {}, ("", ""), [], server="Raptor/RaptorMotion")
    assert issubclass(CommandRefused, PermissionError)


def test_who_calls_travels_with_the_call() -> None:
    assert parse_caller(caller_attachment("autonomy", "abc")) == ("autonomy", "abc", None)
    assert parse_caller(caller_attachment("a", "z", 1.25)) == ("a", "z", 1.25)
    assert parse_caller(None) == ("", "", None)
    assert find_interface("idl.interfaces.Platform") is Platform
    assert find_interface("tests.bridge.parts.Counter") is Counter
    assert find_interface("os.system") is None  # a name never imports anything


async def test_the_inbox_bounds_and_counts_what_other_threads_hand_over() -> None:
    inbox: Inbox[int] = Inbox(asyncio.get_running_loop(), 100)

    def flood() -> None:
        for value in range(10_000):
            inbox.push(value)

    threads = [threading.Thread(target=flood) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    batch = await inbox.batch()
    stats = inbox.statistics()
    assert len(batch) == 100 and stats["received"] == 40_000 and stats["dropped"] == 39_900
    assert stats["high_water"] == 100 and stats["queued"] == 0
    refused: list[int] = []
    strict: Inbox[int] = Inbox(asyncio.get_running_loop(), 2, drop_oldest=False,
                               refuse=refused.append)
    for value in range(5):
        strict.push(value)
    assert await strict.batch() == [0, 1] and refused == [2, 3, 4]
    strict.close()
    strict.push(9)
    assert strict.take() == []


async def test_a_flood_is_taken_in_parts_and_the_loop_turns_between_them() -> None:
    """What a peer floods a process with (events here; tokens and queries alike) is
    handled a part at a time, and every other task gets its turn between the parts: a
    control loop is late by one part at most, not by the whole flood."""
    system = System([], clock=VirtualClock(start=0.0), process="b")
    bridge = Bridge(BridgeParameters()).attach(system)  # not started: no network
    received = system.channel.subscribe("Raptor", "Count", maxsize=1000)
    bridge._data = Inbox(asyncio.get_running_loop(), 1000)
    frame = Event("Raptor", "Count", 1.0, 1, Count(value=1), "a/counter").encode()
    for _ in range(300):
        bridge._data.push((keys.event("Raptor", "Count"), frame))
    seen: list[int] = []  # events delivered so far, at each turn of another task

    async def other_task() -> None:
        while True:
            seen.append(received.statistics().queued)
            await asyncio.sleep(0)

    tasks = [asyncio.ensure_future(bridge._receive()), asyncio.ensure_future(other_task())]
    try:
        while received.statistics().queued < 300:
            # none taken and not yet delivered: a lock-step member's idle() sees the rest
            assert bridge._data.pending() + received.statistics().queued == 300
            await asyncio.sleep(0)
    finally:
        for task in tasks:
            task.cancel()
    assert bridge.imported["Count"] == 300
    assert len({n for n in seen if 0 < n < 300}) >= 2  # it ran while the flood was taken


async def test_the_meter_gives_each_component_its_share_of_the_loop() -> None:
    # a timer that moves 1 µs each time it is read: each step of a task costs exactly
    # 1 µs, so every account must hold its own steps' time and nothing else (on the real
    # clock a descheduled step of the idle component could outweigh 500 short ones)
    reads = [0]

    def timer() -> float:
        reads[0] += 1
        return reads[0] * 1e-6

    clock = VirtualClock(start=0.0)
    system = System([CounterServer("busy", period=0.01), CounterServer("idle", served="Other",
                                                                       event="Other",
                                                                       period=1.0)],
                    clock=clock)
    meter = system.enable_meter(LoopMeter(timer=timer))
    async with system:
        await clock.advance(5.0)
        snapshot = meter.snapshot()
    accounts = snapshot["accounts"]
    assert accounts["busy"]["steps"] > 10 * accounts["idle"]["steps"] > 0
    for name in ("busy", "idle"):
        assert accounts[name]["busy_s"] == pytest.approx(accounts[name]["steps"] * 1e-6)
    assert accounts["busy"]["busy_s"] > accounts["idle"]["busy_s"] > 0
    assert 0 < accounts["busy"]["share"] < 1
    assert system.components["busy"].traffic() == {"in": 0, "out": 500}


def test_the_meter_reports_and_survives_failures() -> None:
    meter = LoopMeter()

    async def boom() -> None:
        raise ValueError("x")

    async def main() -> None:
        with pytest.raises(ValueError):
            await asyncio.get_running_loop().create_task(meter.wrap(boom(), "b"))

    asyncio.run(main())
    assert meter.snapshot()["accounts"]["b"]["steps"] == 1


def test_the_meter_keeps_each_owners_longest_step() -> None:
    """The longest step is the longest an owner held the loop: a coroutine that never
    suspends has one step, its whole time; one that suspends between two halves of
    work held the loop for less than its total."""
    meter = LoopMeter()

    def work() -> int:
        return sum(k * k for k in range(20_000))

    async def whole() -> None:
        work()
        work()

    async def halves() -> None:
        work()
        await asyncio.sleep(0)
        work()

    async def main() -> None:
        loop = asyncio.get_running_loop()
        await loop.create_task(meter.wrap(whole(), "whole"))
        await loop.create_task(meter.wrap(halves(), "halves"))

    asyncio.run(main())
    accounts = meter.snapshot()["accounts"]
    assert accounts["whole"]["steps"] == 1
    assert accounts["whole"]["longest_s"] == accounts["whole"]["busy_s"] > 0
    assert accounts["halves"]["steps"] == 2
    assert 0 < accounts["halves"]["longest_s"] < accounts["halves"]["busy_s"]


def test_poll_arguments_are_parsed_by_the_interface() -> None:
    spec = Counter.methods["add"]
    assert parse_arguments(spec, ["2", "3"], "Counter.add") == {"a": 2, "b": 3}
    assert parse_arguments(spec, ["b=3", "a=2"], "Counter.add") == {"a": 2, "b": 3}
    with pytest.raises(InterfaceError, match=r"the call is Counter.add\(a: int, b: int\)"):
        parse_arguments(spec, ["2"], "Counter.add")
    with pytest.raises(InterfaceError, match="argument a='two'"):
        parse_arguments(spec, ["two", "3"], "Counter.add")
    with pytest.raises(InterfaceError, match="too many arguments"):
        parse_arguments(spec, ["1", "2", "3"], "Counter.add")
    velocity = parse_arguments(VehicleControl.methods["setVelocity"],
                               ['{"translation": 0.5}'], "RaptorMotion.setVelocity")
    assert velocity["velocity"] == VelocityIDL(translation=0.5)
    frames = parse_arguments(Platform.methods["getTransformation"], ["Raptor:A", "B=L:F"], "x")
    assert frames == {"A": "Raptor:A", "B": "L:F"}  # strings stay strings
    flag = parse_arguments(VehiclePlan.methods["setHalt"], ["true"], "x")
    assert flag == {"halt": True}


def test_rate_report_counts_gaps() -> None:
    stamps = [0.1 * k for k in range(11)] + [1.5, 1.6]
    report = rate_report("Imu", stamps)
    assert report.startswith("Imu: ") and "gaps 1" in report and "window 13" in report
    assert rate_report("Imu", [1.0]) == "Imu: 1 event(s), no rate yet"


def test_top_renders_the_launcher_table() -> None:
    info = {"robot": "Raptor", "process": "vehicle", "pid": 42, "host": "h",
            "clock": {"kind": "VirtualClock", "monotonic": 12.5, "now": 0.0},
            "memory": {"rss_bytes": 80_000_000, "peak_rss_bytes": 90_000_000},
            "loop": {"wall_s": 10.0},
            "bridge": {"peers": ["autonomy"], "exported": {"Gps": 5}, "imported": {},
                       "export_dropped": 0, "import": {"dropped": 0}, "rejected": {},
                       "calls_served": 3, "commands_refused": 1},
            "components": [{"name": "gps", "type": "GpsSokkia", "state": "running",
                            "healthy": True, "detail": "", "restarts": 0, "events_in": 0,
                            "events_out": 5, "loop_busy_s": 1.0,
                            "loop_longest_s": 0.0125}]}
    from afa.tools.commands import _Shares

    text = render_top([info], _Shares())
    assert "Raptor/vehicle  pid 42 on h  VirtualClock t=12.5 s  memory 80.0 MB" in text
    assert "peers autonomy; events out 5" in text and "refused commands 1" in text
    assert text.splitlines()[-1].split() == ["gps", "GpsSokkia", "running", "ok", "0", "0", "5",
                                             "10.0%", "12.5", "ms"]


def test_an_interest_makes_an_event_subscribed_and_receives_nothing() -> None:
    from afa import EventChannel
    from tests.bridge.parts import Count

    channel = EventChannel()
    publisher = channel.offer("Raptor", "Laser11Array")
    watcher = channel.observe()
    assert not publisher.subscribed  # observers do not ask for optional forms
    interest = channel.declare_interest("Raptor", "Laser11*")  # another process's subscriber
    assert publisher.subscribed and channel.subscribed("Raptor", "Laser11Array")
    publisher.publish(Count(value=1))
    assert interest.get_nowait() is None and interest.statistics().dropped == 0
    assert watcher.get_nowait() is not None
    interest.close()
    assert not publisher.subscribed
