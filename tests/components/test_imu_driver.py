"""The IMU component against its fake 3DM-GX1: a contract test of driver and device.

Expected values are worked out by hand from the protocol document
(docs/protocols/imu_3dmgx1.md), never taken from the code under test. The gain words
used below make the arithmetic exact: AccelGainScale 8192 gives 8192/32768000 g =
1/4000 g per count, GyroGainScale 16384 gives 1/2000 rad/s per count; an angle count
is 360/65536 degrees. All tests but the pseudo-terminal one run in virtual time.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math

import numpy as np
import pytest

from afa import EDevIO, ETimeOut, System, VirtualClock
from afa.cli import main as cli_main
from afa.errors import TransportClosed
from afa.events import Event, Subscription
from afa.testing import serve, until
from afa.transport import ByteStream, PtyDeviceStream, memory_pipe
from components.imu import Imu, ImuParameters
from components.imu.codec import ReadEepromCommand, SetContinuousCommand
from components.imu.fake import FakeImu, ImuNoise, ImuTruth
from idl import Imu as ImuInterface

G = 9.80665
ACCEL_PER_COUNT = G / 4000.0  # m/s^2 per count with AccelGainScale 8192
RATE_PER_COUNT = 1.0 / 2000.0  # rad/s per count with GyroGainScale 16384
ANGLE_PER_COUNT = 2.0 * math.pi / 65536.0
YAW_RATE = 0.1  # rad/s: 200 counts exactly


def turning(t: float) -> ImuTruth:
    """Level, turning left at 0.1 rad/s from yaw 0 at t = 0, with a little tilt."""
    return ImuTruth(roll=math.radians(5.625), pitch=math.radians(-5.625),
                    yaw=math.remainder(YAW_RATE * t, 2.0 * math.pi),
                    accel=(0.5, -0.25, -G), rates=(0.0, 0.0, YAW_RATE))


def make_fake(clock: VirtualClock, **options: object) -> FakeImu:
    options.setdefault("accel_gain", 8192)
    options.setdefault("gyro_gain", 16384)
    return FakeImu(clock, turning, **options)  # type: ignore[arg-type]


def drain(subscription: Subscription) -> list[Event]:
    events = []
    while (event := subscription.get_nowait()) is not None:
        events.append(event)
    return events


# -- the fake on its own: its bytes against hand-computed literals -----------------------


async def test_fake_replies_match_hand_computed_frames():
    clock = VirtualClock(start=0.0)
    fake = FakeImu(clock, lambda t: ImuTruth(math.radians(5.625), math.radians(-5.625),
                                             math.radians(90.0), (0.0, 0.0, -G),
                                             (0.1, -0.05, 0.0)),
                   accel_gain=8192, gyro_gain=16384)
    host, device = memory_pipe("imu")
    serving = asyncio.create_task(fake.serve(device))
    await clock.advance(1.0)  # 1 s / 6.5536 ms = 152.6: TimerTicks 152 = 0x0098
    await host.write(bytes.fromhex("31" "2800E6" "280082" "F0" "F1"))
    await clock.settle()
    device.close_nowait()
    await serving
    received = await read_all(host)
    # 0x31: roll 0x0400, pitch 0xFC00, yaw 0x4000, accel (0, 0, -4000 = 0xF060),
    # rate (200 = 0x00C8, -100 = 0xFF9C, 0), ticks 0x0098; checksum 0x31 + 0x0400 +
    # 0xFC00 + 0x4000 + 0xF060 + 0x00C8 + 0xFF9C + 0x0098 = 0x3318D -> 0x318D
    euler = bytes.fromhex("31 0400 FC00 4000 0000 0000 F060 00C8 FF9C 0000 0098 318D")
    # EEPROM 230 = 8192 = 0x2000: 0x28 + 0x2000 + 0x0098 = 0x20C0
    accel_gain = bytes.fromhex("28 2000 0098 20C0")
    # EEPROM 130 = 16384 = 0x4000: 0x28 + 0x4000 + 0x0098 = 0x40C0
    gyro_gain = bytes.fromhex("28 4000 0098 40C0")
    # firmware 3104 = 0x0C20: 0xF0 + 0x0C20 = 0x0D10; serial 1234 = 0x04D2 -> 0x05C3
    ids = bytes.fromhex("F0 0C20 0D10 F1 04D2 05C3")
    assert received == euler + accel_gain + gyro_gain + ids


def test_fake_replies_follow_gain_words_written_to_its_eeprom():
    """The fake keeps the gains of its EEPROM words until a word changes: a reply
    after a write is scaled by the new gain (0.5 g at gain 8192 is 0.5 * 32768000 / 8192
    = 2000 counts; at 16384, 1000), and a gain word that is not a valid gain fails."""
    clock = VirtualClock(start=0.0)
    fake = FakeImu(clock, lambda t: ImuTruth(0.0, 0.0, 0.0, (0.5 * G, 0.0, 0.0),
                                             (0.0, 0.0, 0.0)),
                   accel_gain=8192, gyro_gain=16384)

    def accel_x_counts() -> int:
        return int.from_bytes(fake.reply(0x31)[7:9], "big", signed=True)

    assert accel_x_counts() == accel_x_counts() == 2000
    fake.eeprom[230] = 16384
    assert accel_x_counts() == 1000
    fake.eeprom[230] = 0x8000  # -32768 as a signed word: not a gain
    with pytest.raises(ValueError):
        fake.reply(0x31)
    fake.eeprom[230] = 8192
    assert accel_x_counts() == 2000


async def test_fake_streams_in_continuous_mode_until_stopped():
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock, period=0.01)
    host, device = memory_pipe("imu")
    serving = asyncio.create_task(fake.serve(device))
    await host.write(bytes.fromhex("100031"))
    await clock.advance(0.5)
    await host.write(bytes.fromhex("100000"))
    await clock.advance(0.5)
    device.close_nowait()
    await serving
    data = await read_all(host)
    # 10 00 31 confirmed at ticks 0: 0x10 + 0x0031 + 0 = 0x0041
    assert data.startswith(bytes.fromhex("10 0031 0000 0041"))
    assert fake.reports == 51  # t = 0.00, 0.01, ..., 0.50 (the stop arrives after 0.50)
    assert len(data) == 7 + 51 * 23 + 7
    # 10 00 00 confirmed at t = 0.5 s: ticks int(76.3) = 76 = 0x004C; 0x10 + 0x004C = 0x005C
    assert data.endswith(bytes.fromhex("10 0000 004C 005C"))


def test_fake_noise_is_seeded_and_a_bias_capture_removes_the_gyro_bias():
    clock = VirtualClock(start=0.0)
    first = FakeImu(clock, rng=np.random.default_rng(7))
    second = FakeImu(clock, rng=np.random.default_rng(7))
    assert [first.reply(0x31) for _ in range(5)] == [second.reply(0x31) for _ in range(5)]
    assert first.gyro_bias != (0.0, 0.0, 0.0)
    quiet = FakeImu(clock, rng=np.random.default_rng(7), noise=ImuNoise(rate=0.0))
    rates = np.array([quiet.measure().rates for _ in range(10)])
    assert np.allclose(rates, quiet.gyro_bias)


async def test_fake_gyro_bias_capture_answers_when_done():
    clock = VirtualClock(start=0.0)
    fake = FakeImu(clock, rng=np.random.default_rng(3), bias_capture_seconds=10.0)
    host, device = memory_pipe("imu")
    serving = asyncio.create_task(fake.serve(device))
    await host.write(b"\x06")
    await clock.advance(9.9)
    assert fake.gyro_bias != (0.0, 0.0, 0.0)
    await clock.advance(0.2)
    # ticks at 10 s: int(10 / 0.0065536) = 1525 = 0x05F5; 0x06 + 0x05F5 = 0x05FB
    assert await host.read() == bytes.fromhex("06 05F5 05FB")
    assert fake.gyro_bias == (0.0, 0.0, 0.0)
    await host.close()
    await serving


# -- the component against the fake ------------------------------------------------------


async def test_the_driver_on_the_wire_against_a_scripted_unit():
    """The test plays the unit by hand: every byte below is a literal."""
    clock = VirtualClock(start=0.0)
    host, unit = memory_pipe("imu")
    frame = bytes.fromhex("31 0400 FC00 4000 0000 0000 F060 00C8 FF9C 0000 0098 318D")
    unit.write_nowait(frame + frame[:10])  # the unit was streaming: a frame and a half
    imu = Imu("Imu")
    async with System([imu], clock=clock, devices={"Imu": serve(host)}) as system:
        await clock.settle()
        assert await unit.read() == bytes.fromhex("100000")  # stop continuous mode
        unit.write_nowait(frame[10:20])  # the tail of the stream, then silence
        await clock.advance(0.1)
        assert await unit.read() == bytes.fromhex("2800E6")  # read AccelGainScale
        unit.write_nowait(bytes.fromhex("28 2000 0000 2028"))  # 8192
        await clock.settle()
        assert await unit.read() == bytes.fromhex("280082")  # read GyroGainScale
        unit.write_nowait(bytes.fromhex("28 4000 0000 4028"))  # 16384
        await clock.settle()
        assert await unit.read() == bytes.fromhex("100031")  # start continuous 0x31
        proxy = await system.resolve(ImuInterface, "Imu")
        waiting = asyncio.create_task(proxy.getWaitImuData())
        await clock.settle()
        unit.write_nowait(bytes.fromhex("10 0031 0000 0041") + frame)
        sample = await waiting
        stats = imu.statistics()
    assert (sample.roll, sample.pitch, sample.yaw) == pytest.approx(
        (math.radians(5.625), math.radians(-5.625), math.pi / 2))
    assert (sample.accelX, sample.accelY, sample.accelZ) == pytest.approx((0.0, 0.0, -G))
    assert (sample.rateX, sample.rateY, sample.rateZ) == pytest.approx((0.1, -0.05, 0.0))
    assert sample.time.to_seconds() == pytest.approx(0.1)
    assert stats["frames"] == 4 and stats["checksum_failures"] == 0  # the old stream was
    assert stats["samples"] == 1  # discarded, not decoded


async def test_start_up_dialogue_reads_the_gains_and_starts_continuous_0x31():
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock)
    imu = Imu("Imu")
    async with System([imu], clock=clock, devices={"Imu": fake.factory()}):
        await clock.advance(0.5)
        stats = imu.statistics()
        await fake.aclose()
    assert fake.commands[:4] == [SetContinuousCommand(0x00), ReadEepromCommand(230),
                                 ReadEepromCommand(130), SetContinuousCommand(0x31)]
    assert stats["gains_from_eeprom"] is True
    assert (stats["accel_gain_scale"], stats["gyro_gain_scale"]) == (8192, 16384)


async def test_events_every_100_ms_with_the_fakes_values():
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock, period=0.01)
    imu = Imu("Imu")
    async with System([imu], clock=clock, devices={"Imu": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Imu", maxsize=1000)
        await clock.advance(11.0)
        received = drain(events)
        stats = imu.statistics()
        await fake.aclose()
    times = [e.body.time.to_seconds() for e in received]
    in_window = [t for t in times if 1.0 <= t < 11.0]
    assert len(in_window) == 100  # 10 s at the seed's 100 ms
    gaps = np.diff(times)
    assert np.allclose(gaps, 0.1, atol=1e-6)
    assert stats["samples"] > 1000  # the unit streams at 100 Hz; events are decimated
    for event in received:
        body, t = event.body, event.body.time.to_seconds()
        truth = turning(t)
        assert body.roll == pytest.approx(1024 * ANGLE_PER_COUNT, abs=1e-12)
        assert body.pitch == pytest.approx(-1024 * ANGLE_PER_COUNT, abs=1e-12)
        assert abs(math.remainder(body.yaw - truth.yaw, 2 * math.pi)) <= ANGLE_PER_COUNT / 2
        # 0.5 m/s^2 = 203.9 counts -> 204; -0.25 -> -102 (-101.97); -g -> -4000 exactly
        assert (body.accelX, body.accelY) == pytest.approx((204 * ACCEL_PER_COUNT,
                                                            -102 * ACCEL_PER_COUNT))
        assert body.accelZ == pytest.approx(-G)
        assert (body.rateX, body.rateY, body.rateZ) == pytest.approx((0.0, 0.0, 0.1))
        assert body.frame == "Imu:SensorCenter"


async def test_polls_get_latest_and_getwait_next_and_timeout_when_unplugged():
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock, period=0.01)
    imu = Imu("Imu")
    async with System([imu], clock=clock, devices={"Imu": fake.factory()}) as system:
        proxy = await system.resolve(ImuInterface, "Imu")
        await clock.advance(1.005)
        latest = await proxy.getImuData()
        assert latest.time.to_seconds() == pytest.approx(1.0)
        assert latest.yaw == pytest.approx(0.1, abs=ANGLE_PER_COUNT)
        called = clock.now()
        following = await proxy.getWaitImuData()
        assert following.time.to_seconds() == pytest.approx(1.01)
        assert following.time.to_seconds() > called
        fake.unplug()
        with pytest.raises(ETimeOut):
            await proxy.getWaitImuData()
        assert clock.now() == pytest.approx(called + 0.005 + ImuInterface.wait_timeout)
        stale = await proxy.getImuData()  # the last sample stays available
        assert stale == following
        await fake.aclose()


async def test_get_before_the_first_sample_is_edevio():
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock)
    fake.unplug()
    async with System([Imu("Imu")], clock=clock, devices={"Imu": fake.factory()}) as system:
        proxy = await system.resolve(ImuInterface, "Imu")
        with pytest.raises(EDevIO):
            await proxy.getImuData()
        await fake.aclose()


async def test_notify_false_publishes_nothing_but_answers_polls():
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock)
    imu = Imu("Imu", ImuParameters(Notify=False, EventName="Orientation"))
    async with System([imu], clock=clock, devices={"Imu": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "*", maxsize=1000)
        proxy = await system.resolve(ImuInterface, "Orientation")
        await clock.advance(2.0)
        sample = await proxy.getWaitImuData()
        assert sample.rateZ == pytest.approx(0.1)
        assert drain(events) == []
        assert imu.statistics()["published"] == 0
        await fake.aclose()


async def test_silent_eeprom_falls_back_to_default_gains_with_a_warning(caplog):
    clock = VirtualClock(start=0.0)
    fake = FakeImu(clock, turning, answers_eeprom=False)  # the unit has the default gains
    imu = Imu("Imu")
    with caplog.at_level(logging.WARNING, logger="afa.component.Imu"):
        async with System([imu], clock=clock, devices={"Imu": fake.factory()}) as system:
            proxy = await system.resolve(ImuInterface, "Imu")
            sample = await proxy.getWaitImuData()
            stats = imu.statistics()
            await fake.aclose()
    assert "default gains" in caplog.text
    assert stats["gains_from_eeprom"] is False
    assert (stats["accel_gain_scale"], stats["gyro_gain_scale"]) == (7000, 8500)
    # 0.1 rad/s with GyroGainScale 8500: 0.1 * 32768000 / 8500 = 385.5 -> 386 counts
    assert sample.rateZ == pytest.approx(386 * 8500 / 32768000)
    assert sample.time.to_seconds() >= 0.5  # it waited out the EEPROM timeout first


async def test_corrupt_frames_and_garbage_are_counted_and_the_stream_resynchronises():
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock, period=0.01)
    imu = Imu("Imu")
    async with System([imu], clock=clock, devices={"Imu": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Imu", maxsize=1000)
        await clock.advance(1.0)
        before = imu.statistics()
        reports_before = fake.reports
        # garbage with false starts (0x31, 0x10, 0x28), then two corrupted reports
        fake.inject(bytes.fromhex("00 FF 31 55 10 AA 28 31 31 00 07"))
        fake.corrupt_next(2)
        await clock.advance(2.0)
        after = imu.statistics()
        reports = fake.reports - reports_before
        received = drain(events)
        await fake.aclose()
    assert before["checksum_failures"] == 0
    assert after["checksum_failures"] >= 2
    assert after["bytes_skipped"] >= 11 + 2 * 23
    assert after["samples"] - before["samples"] == reports - 2  # only the corrupt ones lost
    late = [e for e in received if e.body.time.to_seconds() >= 2.0]
    assert len(late) == 10  # events resumed at the normal rate


async def test_a_lost_imu_reconnects_and_another_is_unaffected():
    clock = VirtualClock(start=0.0)
    fake, other = make_fake(clock), make_fake(clock)
    imu = Imu("Imu")
    bystander = Imu("Imu2", ImuParameters(EventName="Imu2", Device="/dev/ttyUSB1"))
    async with System([imu, bystander], clock=clock,
                      devices={"Imu": fake.factory(), "Imu2": other.factory()}) as system:
        mine = system.channel.subscribe("Raptor", "Imu", maxsize=1000)
        theirs = system.channel.subscribe("Raptor", "Imu2", maxsize=1000)
        await clock.advance(1.0)
        assert imu.health().healthy
        fake.unplug()
        await clock.advance(0.05)
        assert not imu.health().healthy
        await clock.advance(2.0)
        assert not imu.health().healthy
        fake.plug()
        await until(lambda: imu.health().healthy, clock, timeout=10.0)
        await clock.advance(1.0)
        stats = imu.statistics()
        await fake.aclose()
        await other.aclose()
    assert stats["reconnects"] == 1
    # after the reconnect the driver stops the unit (still in continuous mode) and
    # reads its gains again before restarting continuous mode
    assert fake.commands[-4:] == [SetContinuousCommand(0x00), ReadEepromCommand(230),
                                  ReadEepromCommand(130), SetContinuousCommand(0x31)]
    times = [e.body.time.to_seconds() for e in drain(mine)]
    assert any(t > 3.05 for t in times)  # events resumed
    assert not any(1.05 < t < 3.05 for t in times)  # and none while it was lost
    gaps = np.diff([e.body.time.to_seconds() for e in drain(theirs)])
    assert np.allclose(gaps, 0.1, atol=1e-6)  # the bystander never paused


async def test_a_unit_that_falls_silent_is_reopened_and_restarted():
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock)
    imu = Imu("Imu")
    async with System([imu], clock=clock, devices={"Imu": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Imu", maxsize=1000)
        await clock.advance(1.0)
        fake.continuous = 0  # a brown-out reset the unit: back in polled mode, silent
        await clock.advance(1.05)
        assert not imu.health().healthy
        assert "no message for 1 s" in imu.health().detail
        await until(lambda: imu.health().healthy, clock, timeout=5.0)
        await clock.advance(1.0)
        stats = imu.statistics()
        await fake.aclose()
    assert stats["reconnects"] == 1 and fake.continuous == 0x31
    times = [e.body.time.to_seconds() for e in drain(events)]
    assert any(t > 2.0 for t in times)


# -- the decode CLI on a capture the fake produced ---------------------------------------


async def test_decode_cli_on_a_capture_from_the_fake(tmp_path, capsys):
    clock = VirtualClock(start=0.0)
    fake = make_fake(clock, period=0.05)
    host, device = memory_pipe("imu")
    serving = asyncio.create_task(fake.serve(device))
    await host.write(bytes.fromhex("2800E6" "100031"))
    await clock.advance(0.22)  # reports at 0, 0.05, ..., 0.20: five
    device.close_nowait()
    await serving
    capture = await read_all(host)
    garbage = bytes.fromhex("00 FF 55")
    path = tmp_path / "imu.bin"
    path.write_bytes(garbage + capture)
    assert cli_main(["decode", "imu", str(path)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [line.get("type") for line in lines[:-1]] == (
        ["EepromValue", "ContinuousModeSet"] + ["EulerAccelRate"] * 5)
    assert lines[0]["value"] == 8192
    assert lines[1]["command"] == 0x31
    for k, line in enumerate(lines[2:7]):
        # the CLI decodes with the default gains: counts are what to check
        yaw = round(YAW_RATE * 0.05 * k / ANGLE_PER_COUNT)
        assert line["counts"] == [1024, -1024, yaw, 204, -102, -4000, 0, 0, 200]
    assert lines[-1] == {"statistics": {"messages": 7, "checksum_failures": 0, "malformed": 0,
                                        "bytes_skipped": 3, "bytes": 3 + 7 + 7 + 5 * 23}}


async def read_all(host: ByteStream) -> bytes:
    """Everything the device end wrote, once it has closed."""
    data = b""
    try:
        while True:
            data += await host.read()
    except TransportClosed:
        return data


# -- through a real pseudo-terminal and pyserial-asyncio, wall clock ---------------------


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


class RecordingPty(PtyDeviceStream):
    """The device end of a pseudo-terminal that keeps every byte the host wrote."""

    def __init__(self) -> None:
        super().__init__()
        self.received = bytearray()

    async def read(self, max_bytes: int = 4096) -> bytes:
        data = await super().read(max_bytes)
        self.received += data
        return data


async def test_through_a_pseudo_terminal_with_pyserial_asyncio():
    from afa.clock import WallClock

    clock = WallClock()
    fake = FakeImu(clock, turning, accel_gain=8192, gyro_gain=16384)
    stream = RecordingPty()
    serving = asyncio.create_task(fake.serve(stream))
    imu = Imu("Imu", ImuParameters(Device=stream.path, Baudrate=38400))
    try:
        # no device override: the driver opens the pseudo-terminal as a real serial port
        async with System([imu], clock=clock, real_devices=True) as system:
            events = system.channel.subscribe("Raptor", "Imu", maxsize=100)
            first = await asyncio.wait_for(events.get(), 5.0)
            second = await asyncio.wait_for(events.get(), 5.0)
            stats = imu.statistics()
    finally:
        serving.cancel()
        with pytest.raises(asyncio.CancelledError):
            await serving
        await stream.close()
    # the host's bytes on the wire, in order: stop, read 230, read 130, start 0x31
    assert bytes(stream.received[:12]) == bytes.fromhex("100000 2800E6 280082 100031")
    assert stats["gains_from_eeprom"] is True
    for event in (first, second):
        assert event.body.accelZ == pytest.approx(-G)  # -4000 counts at 1/4000 g
        assert event.body.rateZ == pytest.approx(0.1)
    assert second.body.time.to_seconds() > first.body.time.to_seconds()
