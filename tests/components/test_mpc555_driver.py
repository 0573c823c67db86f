"""Wheel Odometry and Vehicle Control against the fake MPC555 controller (virtual time).

Expected frames are written out by hand from docs/protocols/mpc555.md (big-endian
fields) and closed with CPython's ``binascii.crc_hqx(frame, 0xFFFF)``, an implementation
of CRC-16/CCITT-FALSE independent of the codec. Expected distances come from plants
whose motion is known in closed form, quantised by hand (0.5062 mm per count).
"""

from __future__ import annotations

import binascii
import json
import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from afa import EDevIO, ETimeOut, SerialSpec, System, VirtualClock
from afa.cli import main as cli_main
from afa.events import Subscription
from afa.testing import until
from components.mpc555 import (
    VehicleControl,
    VehicleControlParameters,
    WheelOdometry,
    WheelOdometryParameters,
)
from components.mpc555.codec import (
    CommandAck,
    ConfigureReports,
    Heartbeat,
    Mode,
    Mpc555Decoder,
    SetJoystickVelocity,
    SetSteerCalibration,
    SetVelocity,
    SetWheelCalibration,
    StatusFlags,
    StatusReport,
    StopVehicle,
)
from components.mpc555.fake import DriveCommand, FakeMpc555, WheelTruth
from idl import Odometry, VelocityDataIDL, VelocityIDL, WheelEventIDL
from idl import VehicleControl as VehicleControlInterface

H = bytes.fromhex
MM_PER_COUNT = 0.5062
HALF_COUNT_M = MM_PER_COUNT / 2 / 1000 + 1e-9


def frame(message_type: int, seq: int, payload: bytes = b"") -> bytes:
    """A frame built by hand: A5 01 LEN TYPE SEQ PAYLOAD CRC (crc_hqx, init 0xFFFF)."""
    body = bytes((0xA5, 0x01, len(payload), message_type, seq)) + payload
    return body + binascii.crc_hqx(body, 0xFFFF).to_bytes(2, "big")


class ConstantPlant:
    """Left front wheel at 0.5 m/s, right at 0.6 m/s from the first call on, whatever
    the command (a truth known in closed form)."""

    def __init__(self) -> None:
        self.t0: float | None = None
        self.commands: list[DriveCommand] = []

    def distances(self, t: float) -> tuple[float, float]:
        assert self.t0 is not None
        return 0.5 * (t - self.t0), 0.6 * (t - self.t0)

    def __call__(self, t: float, command: DriveCommand) -> WheelTruth:
        if self.t0 is None:
            self.t0 = t
        self.commands.append(command)
        left, right = self.distances(t)
        return WheelTruth(t, left, right, 0.5, 0.6, 0.55, 0.0, 0.0)


def drain(subscription: Subscription) -> list[Any]:
    events = []
    while (event := subscription.get_nowait()) is not None:
        events.append(event)
    return events


@asynccontextmanager
async def running(components: list[Any], fakes: dict[str, FakeMpc555],
                  clock: VirtualClock) -> AsyncIterator[System]:
    system = System(components, clock=clock,
                    devices={name: fake.factory() for name, fake in fakes.items()})
    try:
        async with system:
            yield system
    finally:
        for fake in set(fakes.values()):
            await fake.aclose()


def received(fake: FakeMpc555, kind: type, after: float = -math.inf) -> list[Any]:
    return [r for r in fake.received if isinstance(r.command, kind) and r.time >= after]


# --------------------------------------------------------------------------- Wheel Odometry

async def test_odometry_configures_the_controller_and_publishes_at_wheel_dist_rep_time():
    clock = VirtualClock(start=1000.0)
    plant = ConstantPlant()
    fake = FakeMpc555(clock, plant=plant, record=True)
    odo = WheelOdometry("Odo", WheelOdometryParameters(WheelDistRepTime=250, SpeedRepTime=500))
    async with running([odo], {"Odo": fake}, clock) as system:
        events = system.channel.subscribe("Raptor", "RaptorOdometry", maxsize=1000)
        await clock.advance(1.0)
        assert odo.configured and odo.health().healthy
        drain(events)
        await clock.advance(10.0)
        got = drain(events)
        odometry = await system.resolve(Odometry, "RaptorOdometry")
        latest = await odometry.getWheelData()
        waited = await odometry.getWaitWheelData()
        stats = odo.statistics()
    # Table 9 prints 250 ms: the configured interval reached the controller.
    assert len(got) == 40
    gaps = [b.time - a.time for a, b in zip(got, got[1:], strict=False)]
    assert gaps == pytest.approx([0.25] * 39)
    for event in got:
        body = event.body
        assert isinstance(body, WheelEventIDL)
        left, right = plant.distances(event.time)
        assert abs(body.leftDistance - left) <= HALF_COUNT_M
        assert abs(body.rightDistance - right) <= HALF_COUNT_M
        assert body.leftSpeed == pytest.approx(0.5, abs=2 * HALF_COUNT_M / 0.25)
        assert body.rightSpeed == pytest.approx(0.6, abs=2 * HALF_COUNT_M / 0.25)
        assert body.leftDelta == pytest.approx(0.125, abs=2 * HALF_COUNT_M)
    assert [e.body.sequence for e in got] == list(range(got[0].body.sequence,
                                                        got[0].body.sequence + 40))
    assert waited.time.to_seconds() > latest.time.to_seconds()
    assert stats["checksum_failures"] == stats["malformed"] == stats["lost_reports"] == 0
    # The start-up configuration on the wire, SEQ from 0x80 (Wheel Odometry's range):
    # 250, 500, 500 ms; 0.5062 mm/count = 506200 nm = 00 07 B9 58; SteerParam
    # 512, 0.075 deg = 75000 udeg = 00 01 24 F8, 112, 912.
    assert fake.host_bytes is not None
    wire = bytes(fake.host_bytes)
    assert wire.startswith(frame(0x07, 0x80, H("00FA 01F4 01F4"))
                           + frame(0x09, 0x81, H("0007B958 0007B958"))
                           + frame(0x0A, 0x82, H("0200 000124F8 0070 0390")))


async def test_get_wait_times_out_while_the_controller_is_unplugged_and_odometry_resumes():
    clock = VirtualClock(start=0.0)
    plant = ConstantPlant()
    lost, other = FakeMpc555(clock, plant=plant), FakeMpc555(clock)
    odo, vc = WheelOdometry("Odo"), VehicleControl("VC")
    async with running([odo, vc], {"Odo": lost, "VC": other}, clock) as system:
        motion = system.channel.subscribe("Raptor", "RaptorMotion", maxsize=100)
        odometry = await system.resolve(Odometry, "RaptorOdometry")
        await clock.advance(1.0)
        assert odo.health().healthy and vc.health().healthy
        lost.unplug()
        with pytest.raises(ETimeOut):
            await odometry.getWaitWheelData()
        assert not odo.health().healthy
        assert "device lost" in odo.health().detail or "cannot open" in odo.health().detail
        assert vc.health().healthy
        unplugged_at = clock.now()
        lost.plug()
        await until(lambda: odo.health().healthy and odo.configured, clock, timeout=10.0)
        body = await odometry.getWaitWheelData()
        await clock.advance(2.0)
        stats = odo.statistics()
        velocity_events = drain(motion)
    assert stats["connects"] == 2 and stats["reconnects"] == 1
    # The controller kept counting while the host was away: no restart at zero.
    left, _ = plant.distances(body.time.to_seconds())
    assert abs(body.leftDistance - left) <= HALF_COUNT_M
    assert body.leftDistance > 0.5 * unplugged_at
    # The other controller's component never paused: SPEED every 1 s throughout.
    times = [e.time for e in velocity_events]
    gaps = [b - a for a, b in zip(times, times[1:], strict=False)]
    assert gaps == pytest.approx([1.0] * (len(times) - 1))
    assert times[-1] > unplugged_at + 1.0


async def test_a_corrupt_burst_is_counted_and_the_stream_resynchronises():
    clock = VirtualClock(start=0.0)
    plant = ConstantPlant()
    fake = FakeMpc555(clock, plant=plant)
    odo = WheelOdometry("Odo")
    async with running([odo], {"Odo": fake}, clock) as system:
        events = system.channel.subscribe("Raptor", "RaptorOdometry", maxsize=1000)
        await clock.advance(1.05)
        drain(events)
        # Noise, a false header claiming a long frame, then one report with a bad CRC.
        fake.inject(H("00 ff a5 a5 01 21 81 00 13 37"))
        fake.corrupt_next(1)
        await clock.advance(2.0)
        got = drain(events)
        stats = odo.statistics()
    assert stats["checksum_failures"] == 1
    assert stats["malformed"] == 1  # the false header: LEN 33 is wrong for WHEEL_DISTANCE
    assert stats["resyncs"] >= 2
    assert stats["lost_reports"] == 1  # the corrupted report's SEQ is missing
    assert len(got) == 9  # ten reports in 2 s, one of them corrupted
    for event in got:
        left, _ = plant.distances(event.time)
        assert abs(event.body.leftDistance - left) <= HALF_COUNT_M


async def test_a_controller_reset_is_detected_reconfigured_and_odometry_stays_continuous():
    clock = VirtualClock(start=0.0)
    plant = ConstantPlant()
    fake = FakeMpc555(clock, plant=plant)
    odo = WheelOdometry("Odo")
    async with running([odo], {"Odo": fake}, clock) as system:
        odometry = await system.resolve(Odometry, "RaptorOdometry")
        await clock.advance(3.0)
        fake.reset()
        reset_at = clock.now()
        await clock.advance(2.0)
        body = await odometry.getWheelData()
        stats = odo.statistics()
    assert stats["controller_resets"] == 1 and stats["configurations"] == 2
    assert len(received(fake, ConfigureReports, after=reset_at)) == 1
    # Counts restarted at 0 in the controller; the host's distance did not.
    left, right = plant.distances(body.time.to_seconds())
    assert abs(body.leftDistance - left) <= 2 * HALF_COUNT_M
    assert abs(body.rightDistance - right) <= 2 * HALF_COUNT_M


# --------------------------------------------------------------------------- Vehicle Control

async def _started(system: System, vc: VehicleControl, clock: VirtualClock) -> Any:
    control = await system.resolve(VehicleControlInterface, "RaptorMotion")
    await until(lambda: vc.configured, clock, timeout=2.0)
    await control.startVehicle()
    await control.setArbiter(True)
    return control


async def test_set_velocity_drives_the_vehicle_and_stop_vehicle_brakes():
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock)
    vc = VehicleControl("VC")
    async with running([vc], {"VC": fake}, clock) as system:
        motion = system.channel.subscribe("Raptor", "RaptorMotion", maxsize=100)
        control = await _started(system, vc, clock)
        drain(motion)
        for _ in range(100):  # 10 Hz, like the Arc Arbiter, for 10 s
            await control.setVelocity(VelocityIDL(translation=1.0, rotation=0.1))
            await clock.advance(0.1)
        truth = fake.truth
        target = await control.getTargetVelocity()
        events = drain(motion)
        await control.stopVehicle()
        await clock.advance(2.0)
        stopped = fake.truth
        mode, flags = fake.mode, fake.flags
        after_stop = await control.getTargetVelocity()
    assert truth.speed == pytest.approx(1.0, abs=1e-3)
    assert truth.yaw_rate == pytest.approx(0.1, abs=1e-3)
    assert target.translation == 1.0 and target.rotation == 0.1
    assert target.steeringAngle == pytest.approx(math.atan(1.9 * 0.1 / 1.0))
    # VelocityData from every SPEED report (1 s): measured speed and the target.
    assert len(events) == 10
    last = events[-1].body
    assert isinstance(last, VelocityDataIDL)
    assert last.velocity.translation == pytest.approx(1.0, abs=0.01)
    assert last.velocity.rotation == pytest.approx(0.1, abs=0.002)
    assert last.velocity.steeringAngle == pytest.approx(math.atan(0.19), abs=2e-4)
    assert last.target == target and last.vehicleStarted and last.arbiterEnabled
    assert mode is Mode.STOPPED and StatusFlags.BRAKE in flags
    assert abs(stopped.speed) < 0.01
    assert after_stop.translation == 0.0
    assert fake.watchdog_trips == 0


async def test_limits_are_clamped_before_the_wire():
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock, record=True)
    vc = VehicleControl("VC", VehicleControlParameters())
    async with running([vc], {"VC": fake}, clock) as system:
        control = await _started(system, vc, clock)
        limits = await control.getMinMaxVelocity()
        await control.setVelocity(VelocityIDL(translation=3.0))
        over_speed = received(fake, SetVelocity)[-1]
        over_speed_target = await control.getTargetVelocity()
        # 2 rad/s at 1 m/s: clamped to 1 rad/s, whose steering angle atan(1.9) = 62 deg
        # is clamped to 30 deg: w = 1.0 * tan(30 deg) / 1.9 = 0.30387 -> 303 mrad/s.
        await control.setVelocity(VelocityIDL(translation=1.0, rotation=2.0))
        too_sharp = received(fake, SetVelocity)[-1]
        await control.setVelocity(VelocityIDL(translation=1.0, steeringAngle=math.radians(45)))
        steered = received(fake, SetVelocity)[-1]
        await control.setVelocity(VelocityIDL(translation=-5.0))
        reverse = received(fake, SetVelocity)[-1]
        stats = vc.statistics()
    assert (limits.minTranslation, limits.maxTranslation) == (-1.0, 2.0)
    assert (limits.minRotation, limits.maxRotation) == (-1.0, 1.0)
    assert limits.maxSteeringAngle == pytest.approx(math.radians(30.0))
    assert over_speed.command == SetVelocity(2000, 0)
    assert frame(0x02, over_speed.seq, H("07D0 0000")) in bytes(fake.host_bytes or b"")
    assert over_speed_target.translation == 2.0
    assert too_sharp.command == SetVelocity(1000, 303)
    assert steered.command == SetVelocity(1000, 303)
    assert reverse.command == SetVelocity(-1000, 0)  # the pedal table ends at -1000 mm/s
    assert stats["limited_commands"] == 4
    # The controller did not have to clamp again: every velocity ACK says OK (00).
    acks = [m.message for m in Mpc555Decoder().feed(bytes(fake.device_bytes or b""))
            if isinstance(m.message, CommandAck) and m.message.acked_type == 0x02]
    assert [a.result for a in acks] == [0, 0, 0, 0]


async def test_host_command_watchdog_puts_a_stop_on_the_wire():
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock)
    vc = VehicleControl("VC")
    async with running([vc], {"VC": fake}, clock) as system:
        control = await _started(system, vc, clock)
        await clock.advance(2.0)  # started but not yet commanded: the watchdog waits
        assert fake.mode is Mode.ARBITER
        await control.setVelocity(VelocityIDL(translation=1.5))
        commanded = received(fake, SetVelocity)[-1].time
        await clock.advance(1.0)
        mode, trips = fake.mode, fake.watchdog_trips
        health = vc.health()
        stats = vc.statistics()
    stops = received(fake, StopVehicle, after=commanded)
    assert stops, "no STOP_VEHICLE after the commands stopped"
    assert stops[0].time - commanded == pytest.approx(0.5, abs=1e-6)
    # Heartbeats kept the link alive meanwhile, so this was the host's watchdog, not the
    # controller's.
    beats = received(fake, Heartbeat, after=commanded)
    assert len([b for b in beats if b.time < stops[0].time]) >= 4
    assert trips == 0 and mode is Mode.STOPPED
    assert stats["watchdog_stops"] == 1
    assert "command watchdog" in health.detail


@pytest.mark.parametrize("last_speed, level", [(1.5, "WARNING"), (0.0, "INFO")])
async def test_the_watchdog_stop_is_a_warning_only_when_the_vehicle_was_told_to_move(
        caplog, last_speed, level):
    """At the end of every scripted drive the last command is 'stand still' and the
    watchdog's stop is routine (info); commands that stop while the vehicle was told to
    move are worth a warning."""
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock)
    vc = VehicleControl("VC")
    caplog.set_level("INFO", logger="afa.component.VC")
    async with running([vc], {"VC": fake}, clock) as system:
        control = await _started(system, vc, clock)
        await control.setVelocity(VelocityIDL(translation=1.0))
        await clock.advance(0.2)
        await control.setVelocity(VelocityIDL(translation=last_speed))
        await clock.advance(1.0)
        stats = vc.statistics()
    assert stats["watchdog_stops"] == 1
    records = [r for r in caplog.records
               if r.getMessage().removeprefix("VC: ").startswith("command watchdog")]
    assert [r.levelname for r in records] == [level]
    assert "t=" not in records[0].getMessage()  # no absolute clock stamp in the message


async def test_a_nak_or_a_missing_ack_is_edevio():
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock)
    vc = VehicleControl("VC")
    async with running([vc], {"VC": fake}, clock) as system:
        control = await system.resolve(VehicleControlInterface, "RaptorMotion")
        await until(lambda: vc.configured, clock, timeout=2.0)
        await control.setArbiter(True)
        with pytest.raises(EDevIO, match="NOT_RUNNING"):
            await control.setVelocity(VelocityIDL(translation=1.0))
        fake.estop = True
        with pytest.raises(EDevIO, match="ESTOP"):
            await control.startVehicle()
        fake.estop = False
        fake.mute_acks = True
        before = clock.now()
        with pytest.raises(EDevIO, match="no ACK"):
            await control.stopVehicle()
        stops = received(fake, StopVehicle, after=before)
        stats = vc.statistics()
    # Sent once and retransmitted three times with the same SEQ, 50 ms apart.
    assert len(stops) == 4 and len({s.seq for s in stops}) == 1
    assert [s.time - stops[0].time for s in stops] == pytest.approx([0.0, 0.05, 0.10, 0.15])
    assert stats["naks"] == 2 and stats["ack_timeouts"] == 1 and stats["retransmissions"] == 3


async def test_arbiter_off_ignores_set_velocity_and_obeys_the_joystick():
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock)
    vc = VehicleControl("VC")
    async with running([vc], {"VC": fake}, clock) as system:
        control = await system.resolve(VehicleControlInterface, "RaptorMotion")
        # At once: the call waits for the start-up configuration to finish.
        await control.startVehicle()  # the arbiter is off after start-up
        await control.setVelocity(VelocityIDL(translation=1.0))
        ignored = received(fake, SetVelocity)
        await control.setJoystickVelocity(VelocityIDL(translation=0.5))
        joystick_mode = fake.mode
        await control.setArbiter(True)  # ends the override
        await control.setVelocity(VelocityIDL(translation=0.8))
        arbiter_mode = fake.mode
        stats = vc.statistics()
    assert ignored == []
    assert stats["ignored_velocity_commands"] == 1
    assert [r.command for r in received(fake, SetJoystickVelocity)] == [
        SetJoystickVelocity(500, 0)]
    assert joystick_mode is Mode.JOYSTICK
    assert [r.command for r in received(fake, SetVelocity)] == [SetVelocity(800, 0)]
    assert arbiter_mode is Mode.ARBITER


async def test_after_a_lost_link_the_vehicle_is_stopped_and_needs_start_vehicle():
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock)
    vc = VehicleControl("VC")
    async with running([vc], {"VC": fake}, clock) as system:
        control = await _started(system, vc, clock)
        await control.setVelocity(VelocityIDL(translation=1.0))
        fake.unplug()
        await clock.advance(0.05)
        with pytest.raises(EDevIO, match="link is down"):
            await control.setVelocity(VelocityIDL(translation=1.0))
        assert not vc.health().healthy
        await clock.advance(1.0)
        # No heartbeat gets through: the controller's own watchdog stops the vehicle.
        assert fake.watchdog_trips == 1 and fake.mode is Mode.STOPPED
        fake.plug()
        await until(lambda: vc.health().healthy and vc.configured, clock, timeout=10.0)
        await clock.advance(0.6)  # a STATUS shows the controller stopped
        assert not vc.started
        with pytest.raises(EDevIO, match="NOT_RUNNING"):
            await control.setVelocity(VelocityIDL(translation=1.0))
        await control.startVehicle()
        await control.setVelocity(VelocityIDL(translation=1.0))
        resumed = fake.mode
    assert resumed is Mode.ARBITER
    assert StatusFlags.WATCHDOG not in fake.flags


async def test_the_fake_controllers_own_watchdog_stops_a_silent_host():
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock, record=True)
    try:
        host = await fake.factory()(SerialSpec("/dev/ttyS0", 115200))
        await host.write(frame(0x09, 1, H("0007B958 0007B958"))
                         + frame(0x0A, 2, H("0200 000124F8 0070 0390"))
                         + frame(0x0B, 3, H("05 FC18 04E2 0000 0800 00C8 092E 03E8 0ABE"
                                            " 07D0 0CB2"))
                         + frame(0x0C, 4, H("00000FA0 000001F4 00000064"))
                         + frame(0x04, 5)  # START_VEHICLE
                         + frame(0x02, 6, H("03E8 0000")))  # 1000 mm/s straight
        await clock.advance(0.4)
        running_mode = fake.mode
        last_frame = fake.received[-1].time
        await clock.advance(0.4)
        await host.close()
    finally:
        await fake.aclose()
    assert running_mode is Mode.RUNNING
    assert fake.mode is Mode.STOPPED and fake.watchdog_trips == 1
    packets = Mpc555Decoder().feed(bytes(fake.device_bytes or b""))
    acks = [(p.message.acked_seq, p.message.result) for p in packets
            if isinstance(p.message, CommandAck)]
    assert acks == [(1, 0), (2, 0), (3, 0), (4, 0), (5, 0), (6, 0)]
    tripped = [p.message for p in packets if isinstance(p.message, StatusReport)
               and StatusFlags.WATCHDOG in p.message.flags]
    assert tripped[0].mode is Mode.STOPPED and StatusFlags.BRAKE in tripped[0].flags
    assert tripped[0].time_ms == round((last_frame + 0.5) * 1000)  # sent at once
    assert tripped[0].command_age_ms == 500


async def test_both_components_share_one_controller():
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock)
    odo, vc = WheelOdometry("Odo"), VehicleControl("VC")
    async with running([odo, vc], {"Odo": fake, "VC": fake}, clock) as system:
        odometry = await system.resolve(Odometry, "RaptorOdometry")
        motion = system.channel.subscribe("Raptor", "RaptorMotion", maxsize=100)
        control = await _started(system, vc, clock)
        await until(lambda: odo.configured, clock, timeout=2.0)
        for _ in range(50):
            await control.setVelocity(VelocityIDL(translation=1.2))
            await clock.advance(0.1)
        wheel = await odometry.getWaitWheelData()
        truth = fake.last_wheel_truth
        odo_stats, vc_stats = odo.statistics(), vc.statistics()
        velocity = drain(motion)
    assert fake.opens == 2
    assert truth is not None
    assert abs(wheel.leftDistance - truth.left_distance) <= HALF_COUNT_M
    assert abs(wheel.rightDistance - truth.right_distance) <= HALF_COUNT_M
    assert wheel.leftDistance > 4.0  # about 5 s at up to 1.2 m/s
    assert wheel.speed == pytest.approx(1.2, abs=0.01)
    assert velocity and velocity[-1].body.velocity.translation == pytest.approx(1.2, abs=0.01)
    for stats in (odo_stats, vc_stats):
        # Each sees the other's reports and ACKs: ignored, never counted as errors.
        assert stats["malformed"] == stats["checksum_failures"] == stats["lost_reports"] == 0
        assert stats["unmatched_acks"] > 0
    kinds = {type(r.command) for r in fake.received}
    assert {ConfigureReports, SetWheelCalibration, SetSteerCalibration} <= kinds


async def test_decode_cli_reads_a_capture_of_the_fake(tmp_path, capsys):
    clock = VirtualClock(start=0.0)
    fake = FakeMpc555(clock, plant=ConstantPlant(), record=True)
    odo = WheelOdometry("Odo")
    async with running([odo], {"Odo": fake}, clock):
        await clock.advance(1.5)
        fake.inject(b"\x00\x01\x02")
        await clock.advance(1.5)
    capture = tmp_path / "mpc555.bin"
    capture.write_bytes(bytes(fake.device_bytes or b""))
    assert cli_main(["decode", "mpc555", str(capture)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    *records, summary = lines
    wheel = [r["message"] for r in records if "left_counts" in r["message"]]
    speed = [r["message"] for r in records if "speed_mm_s" in r["message"]]
    status = [r["message"] for r in records if "rx_errors" in r["message"]]
    acks = [r["message"] for r in records if "acked_seq" in r["message"]]
    # 3 s: WHEEL_DISTANCE every 0.2 s, SPEED every 1 s, STATUS at power-on and every
    # 0.5 s, and one ACK for each of the three configuration commands.
    assert (len(wheel), len(speed), len(status), len(acks)) == (15, 3, 7, 3)
    # At 3.000 s the left wheel has rolled 1.5 m: 1500 / 0.5062 = 2963.3 -> 2963 counts.
    assert wheel[-1] == {"time_ms": 3000, "left_counts": 2963, "right_counts": 3556}
    assert [r["seq"] for r in records] == list(range(len(records)))
    assert summary == {"statistics": {"messages": 28, "checksum_failures": 0, "malformed": 0,
                                      "bytes_skipped": 3, "bytes": capture.stat().st_size}}
