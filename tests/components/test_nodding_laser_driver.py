"""Contract tests of the Nodding Laser driver (components.nodding_laser.NodLaser) against
its fake controller (components.nodding_laser.fake.FakeNodLaser), in virtual time.

Expected geometry is derived by hand in the comments (flat ground z = -h seen by a
scan plane of elevation n: a beam at SICK bearing b meets it at r = h / (sin b sin(-n))),
not taken from the code under test.
"""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import Awaitable, Callable

import numpy as np
import pytest

from afa import EDevIO, ETimeOut, System, VirtualClock, WallClock
from afa.cli import main
from afa.testing import until
from afa.transport import AsyncioByteStream, ByteStream, DeviceSpec
from components.nodding_laser import NodLaser, NodLaserParameters
from components.nodding_laser import fake as fake_module
from components.nodding_laser.codec import (
    RequestStatus,
    SetNodLimits,
    SetNodRate,
    SickCommand,
    SickMode,
    StartNodding,
    StopNodding,
    SwitchOperatingMode,
    SwitchVariant,
)
from components.nodding_laser.component import adaptive_nod_rate, nod_plan
from components.nodding_laser.fake import FakeNodLaser, flat_ground
from idl import Range3dLaserIDL, Range3dSensor, Range3dSeqEventIDL

LEFT = "FrontNoddingSICKLeft:AxleCenterFreeEnd"
RIGHT = "FrontNoddingSICKRight:AxleCenterFreeEnd"
PERIOD = 2 / 75  # 0.5 deg: two interlaced 13.33 ms mirror sweeps (seed: 26.6 ms)
FRAME_BYTES = 10 + 20 + 732 + 2  # NLC header, SCAN prefix, 361-value 0xB0 telegram, CRC


def laser(name: str = "NodLaserService", **overrides: object) -> NodLaser:
    return NodLaser(name, NodLaserParameters(**overrides))  # type: ignore[arg-type]


def seconds(time) -> float:
    return time.sec + time.usec / 1e6


def drain(subscription) -> list:
    events = []
    while (event := subscription.get_nowait()) is not None:
        events.append(event)
    return events


# -- configuration ------------------------------------------------------------------------

async def test_the_driver_configures_controller_and_lms_on_connect():
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock)
    async with System([laser()], clock=clock, devices={"NodLaserService": fake.factory()}):
        await clock.advance(0.2)
    await fake.aclose()
    # Table A.1: 15 deg/s between -40 and -10 deg; LaserOffsetAngle -2 means the encoder
    # reads 2 deg more than the true elevation: commanded -38 .. -8 deg.
    assert [type(c) for c in fake.commands] == [
        SickCommand, StopNodding, SickCommand, SetNodRate, SetNodLimits, StartNodding,
        SickCommand, RequestStatus]
    assert fake.commands[0].command == SwitchOperatingMode(SickMode.MONITOR_REQUEST_VALUES)
    assert fake.commands[2].command == SwitchVariant(180, 50)
    assert fake.commands[3].rate_udeg_per_s == 15_000_000
    assert (fake.commands[4].low_udeg, fake.commands[4].high_udeg) == (-38_000_000, -8_000_000)
    assert fake.commands[6].command == SwitchOperatingMode(SickMode.MONITOR_STREAM_VALUES)
    assert [c.seq for c in fake.commands] == list(range(8))
    assert fake.streaming and (fake.low_deg, fake.high_deg) == (-38.0, -8.0)


async def test_scan_rate_is_one_line_per_26_6_ms():
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock)
    async with System([laser()], clock=clock,
                      devices={"NodLaserService": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Laser11", maxsize=10_000)
        await clock.advance(1.0)
        drain(events)
        await clock.advance(5.0)
        received = drain(events)
    await fake.aclose()
    assert abs(len(received) - 5 / 0.0266) <= 1
    assert all(isinstance(e.body, Range3dSeqEventIDL) for e in received)
    assert {e.body.sensorId for e in received} == {11}
    assert {e.body.frame for e in received} == {LEFT}
    # time stamps are the scans' start times: one scan period apart
    stamps = [seconds(e.body.time) for e in received]
    assert np.allclose(np.diff(stamps), PERIOD, atol=2e-6)
    # ... each one scan period before the frame arrived (no transfer delay in memory)
    assert np.allclose(stamps, [e.time - PERIOD for e in received], atol=2e-6)


# -- geometry -----------------------------------------------------------------------------

async def test_points_of_a_fixed_nod_on_flat_ground_match_hand_computed_values():
    # Nod held at -30 deg (limits 1 micro-degree apart), ground 2 m below the nod axis.
    # Middle beam (index 180, bearing 90): r = 2 / sin 30 = 4.000 m -> x = 4 cos 30 =
    # 3.4641 m, y = 0, z = -2. Bearing 30 (index 60): r = 2 / (0.5 * 0.5) = 8.000 m ->
    # x = 8 * 0.5 * cos 30 = 3.4641, y = -8 cos 30 = -6.9282, z = -2. A beam is seen
    # when r < 8.183 m (8 m mode): sin b >= 2 / (0.5 * 8.183) = 0.48882, b >= 29.26 deg,
    # i.e. bearings 29.5 .. 150.5 deg = indices 59 .. 301 = 243 beams.
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock, source=flat_ground(2.0), offset_deg=-2.0)
    component = laser(LowAngle=-30.0, HighAngle=-29.999999)
    async with System([component], clock=clock,
                      devices={"NodLaserService": fake.factory()}) as system:
        await clock.advance(2.5)  # the mount first travels from 0 to -28 (encoder) at 15 deg/s
        proxy = await system.resolve(Range3dSensor, "Laser11")
        scan = await proxy.get3dLaserWaitFullScan()
    await fake.aclose()
    assert math.degrees(scan.nodAngleStart) == pytest.approx(-30.0, abs=2e-6)
    assert scan.points.shape == (361, 3) and scan.points.dtype == np.float32
    assert scan.count == 243
    assert np.flatnonzero(scan.valid).tolist() == list(range(59, 302))
    assert np.all(np.isnan(scan.points[~scan.valid]))
    assert scan.points[180] == pytest.approx([3.4641016, 0.0, -2.0], abs=6e-4)
    assert scan.points[60] == pytest.approx([3.4641016, -6.9282032, -2.0], abs=6e-4)
    assert scan.points[300] == pytest.approx([3.4641016, 6.9282032, -2.0], abs=6e-4)


async def test_nodding_scan_lines_lie_on_the_ground_plane():
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock, source=flat_ground(2.0), offset_deg=-2.0,
                        waveform="sine")
    async with System([laser()], clock=clock,
                      devices={"NodLaserService": fake.factory()}) as system:
        seq = system.channel.subscribe("Raptor", "Laser11", maxsize=10_000)
        array = system.channel.subscribe("Raptor", "Laser11Array", maxsize=10_000)
        await clock.advance(6.0)  # > one full sweep (2 x 30 deg at 15 deg/s) after arrival
    await fake.aclose()
    lines, statics = drain(seq), drain(array)
    assert len(lines) == len(statics) > 200
    nods = np.degrees([[e.body.nodAngleStart, e.body.nodAngleEnd] for e in lines[90:]])
    # the true elevation sweeps the configured -40 .. -10 deg (encoder -38 .. -8 + offset)
    assert nods.min() == pytest.approx(-40.0, abs=0.05)
    assert nods.max() == pytest.approx(-10.0, abs=0.05)
    for line, static in zip(lines[90:], statics[90:], strict=True):
        z = line.body.points[:, 2]
        # from 2 m the beam ahead reaches the ground within 8.183 m only below -14.14 deg
        if max(line.body.nodAngleStart, line.body.nodAngleEnd) < math.radians(-14.2):
            assert len(z) > 0
        assert np.all(np.abs(z + 2.0) <= 6e-4)  # mm quantisation of the ranges
        assert isinstance(static.body, Range3dLaserIDL)
        assert np.array_equal(static.body.valid_points(), line.body.points)
        # every beam left out would have been beyond 8.183 m (or never hits the ground)
        b = np.radians(np.arange(361) * 0.5)
        n = np.linspace(static.body.nodAngleStart, static.body.nodAngleEnd, 361)
        down = np.sin(b) * np.sin(-n)
        hidden = ~static.body.valid
        assert np.all((down[hidden] <= 0) | (2.0 / np.where(down[hidden] > 0, down[hidden], 1)
                                            >= 8.18))


# -- polls --------------------------------------------------------------------------------

async def test_polls_get_latest_wait_next_and_time_out_when_unplugged():
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock)
    component = laser()
    async with System([component], clock=clock,
                      devices={"NodLaserService": fake.factory()}) as system:
        proxy = await system.resolve(Range3dSensor, "Laser11")
        with pytest.raises(EDevIO):
            await proxy.get3dLaserFullScan()  # no scan yet
        await clock.advance(0.5)
        latest = await proxy.get3dLaserFullScan()
        latest_seq = await proxy.get3dSeqFullScan()
        assert latest.points.shape == (361, 3) and latest.sensorId == 11
        assert latest.frame == LEFT
        assert latest_seq.time == latest.time
        assert np.array_equal(latest_seq.points, latest.valid_points())
        waiting = asyncio.ensure_future(proxy.get3dSeqWaitFullScan())
        waiting_laser = asyncio.ensure_future(proxy.get3dLaserWaitFullScan())
        await clock.advance(0.03)
        following, following_laser = waiting.result(), waiting_laser.result()
        assert seconds(following.time) > seconds(latest.time)
        assert following_laser.time == following.time
        for stereo in (proxy.get3dStereoFullScan, proxy.get3dStereoWaitFullScan,
                       proxy.get3dArrayFullScan, proxy.get3dArrayWaitFullScan):
            with pytest.raises(EDevIO, match="no stereo"):
                await stereo()
        fake.unplug()
        started = clock.now()
        with pytest.raises(ETimeOut):
            await proxy.get3dSeqWaitFullScan()
        assert clock.now() - started == pytest.approx(Range3dSensor.wait_timeout)
        with pytest.raises(ETimeOut):
            await proxy.get3dLaserWaitFullScan()
        last = await proxy.get3dSeqFullScan()  # the last scan before the unplug
        assert seconds(last.time) >= seconds(following.time)
    await fake.aclose()


async def test_the_static_array_form_is_built_only_when_wanted():
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock)
    component = laser()
    async with System([component], clock=clock,
                      devices={"NodLaserService": fake.factory()}) as system:
        await clock.advance(0.5)
        assert component.counters["array_events"] == 0
        assert component.counters["seq_events"] >= 18  # the sequence form is always published
        array = system.channel.subscribe("Raptor", "Laser11Array", maxsize=100)
        await clock.advance(0.5)
        events = drain(array)
    await fake.aclose()
    assert len(events) == component.counters["array_events"] >= 18
    assert all(isinstance(e.body, Range3dLaserIDL) for e in events)


# -- faults -------------------------------------------------------------------------------

async def test_corrupt_frames_and_garbage_are_counted_and_the_stream_resynchronises():
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock)
    component = laser()
    async with System([component], clock=clock,
                      devices={"NodLaserService": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Laser11", maxsize=10_000)
        await clock.advance(1.0)
        drain(events)
        before, sent = component.statistics(), fake.scans_sent
        await fake.inject(b"\x00\x11\x22" * 40)  # 120 bytes with no sync byte
        fake.corrupt_scans(2)
        await clock.advance(1.0)
        after, received = component.statistics(), drain(events)
        healthy = component.health().healthy
    await fake.aclose()
    assert healthy  # corrupt frames are line noise, not a lost device
    assert after["checksum_failures"] - before["checksum_failures"] == 2
    assert after["bytes_skipped"] - before["bytes_skipped"] == 120 + 2 * FRAME_BYTES
    assert after["scans_lost"] - before["scans_lost"] == 2  # gaps in the scan counter
    assert len(received) == fake.scans_sent - sent - 2  # every other scan got through
    assert received[-1].time > clock.now() - 2 * PERIOD  # still streaming at the end


async def test_a_lost_controller_is_reconnected_and_the_other_laser_keeps_running():
    clock = VirtualClock(start=0.0)
    left, right = FakeNodLaser(clock), FakeNodLaser(clock)
    laser11 = laser()
    laser12 = laser("NodLaserService12", EventName="Laser12", LaserID=12)
    async with System([laser11, laser12], clock=clock,
                      devices={"NodLaserService": left.factory(),
                               "NodLaserService12": right.factory()}) as system:
        events11 = system.channel.subscribe("Raptor", "Laser11", maxsize=10_000)
        events12 = system.channel.subscribe("Raptor", "Laser12", maxsize=10_000)
        await clock.advance(1.0)
        left.unplug()
        await clock.advance(0.05)
        assert not laser11.health().healthy and "device lost" in laser11.health().detail
        await clock.advance(2.0)
        assert not laser11.health().healthy and laser12.health().healthy
        plugged = clock.now()
        left.plug()
        await until(lambda: laser11.health().healthy, clock, timeout=10.0)
        await clock.advance(1.0)
        stats = laser11.statistics()
    await left.aclose()
    await right.aclose()
    assert stats["connects"] == 2 and stats["reconnects"] == 1
    assert len(left.commands) == 16  # the whole configuration again after reconnecting
    mine = drain(events11)
    assert sum(e.time > plugged for e in mine) >= 30  # events resumed
    theirs = [e.time for e in drain(events12)]
    assert max(np.diff(theirs)) == pytest.approx(PERIOD)  # Laser12 never paused


async def test_two_lasers_side_by_side_with_their_own_names_ids_and_frames():
    clock = VirtualClock(start=0.0)
    left = FakeNodLaser(clock, source=flat_ground(2.0), offset_deg=-2.0)
    right = FakeNodLaser(clock, source=flat_ground(1.5), offset_deg=-2.0)
    laser11 = laser()
    laser12 = laser("NodLaserService12", EventName="Laser12", LaserID=12)
    async with System([laser11, laser12], clock=clock,
                      devices={"NodLaserService": left.factory(),
                               "NodLaserService12": right.factory()}) as system:
        await clock.advance(2.5)
        p11 = await system.resolve(Range3dSensor, "Laser11")
        p12 = await system.resolve(Range3dSensor, "Laser12")
        s11, s12 = await p11.get3dSeqWaitFullScan(), await p12.get3dSeqFullScan()
    await left.aclose()
    await right.aclose()
    assert (s11.sensorId, s11.frame) == (11, LEFT)
    assert (s12.sensorId, s12.frame) == (12, RIGHT)
    assert np.all(np.abs(s11.points[:, 2] + 2.0) <= 6e-4)
    assert np.all(np.abs(s12.points[:, 2] + 1.5) <= 6e-4)


# -- adaptive nodding ---------------------------------------------------------------------

def test_adaptive_nodding_rule_hand_computed():
    p = NodLaserParameters()
    fixed = nod_plan(p)
    assert (fixed.low_deg, fixed.high_deg, fixed.rate_deg_s) == (-40.0, -10.0, 15.0)
    assert (fixed.command_low_deg, fixed.command_high_deg) == (-38.0, -8.0)
    # MountAngle -14 lies inside -40..-10: the sweep tops out there. Rate: 0.2 m spacing
    # at -14 deg from 3.0 m with 1/37.5 s per scan: w = 0.2 sin^2(14) / (3.0 * 0.026667)
    # = 0.2 * 0.0585262 / 0.08 = 0.146316 rad/s = 8.3833 deg/s.
    adaptive = nod_plan(p, adaptive=True)
    assert (adaptive.low_deg, adaptive.high_deg) == (-40.0, -14.0)
    assert adaptive.rate_deg_s == pytest.approx(8.3833, abs=1e-4)
    assert (adaptive.command_low_deg, adaptive.command_high_deg) == (-38.0, -12.0)
    # exact (not linearised) ground spacing of two lines one scan apart at -14 deg
    step = math.radians(adaptive.rate_deg_s) * PERIOD
    a = math.radians(14.0)
    spacing = 3.0 / math.tan(a - step) - 3.0 / math.tan(a)
    assert spacing == pytest.approx(0.2, rel=0.03)
    # a mount angle outside the range leaves the limits; at or above level: no limit
    outside = nod_plan(p.model_copy(update={"MountAngle": -50.0}), adaptive=True)
    assert outside.high_deg == -10.0
    assert outside.rate_deg_s == pytest.approx(
        math.degrees(0.2 * math.sin(math.radians(10)) ** 2 / (3.0 * PERIOD)))
    assert adaptive_nod_rate(0.0, 3.0, 0.2, PERIOD, 15.0) == 15.0
    assert adaptive_nod_rate(-60.0, 1.0, 0.2, PERIOD, 15.0) == 15.0  # capped


async def test_adaptive_nodding_is_commanded_when_switched_on():
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock, offset_deg=-2.0)
    component = NodLaser("NodLaserService", NodLaserParameters(), adaptive_nodding=True)
    async with System([component], clock=clock,
                      devices={"NodLaserService": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Laser11", maxsize=10_000)
        await clock.advance(12.0)
    await fake.aclose()
    rate = next(c for c in fake.commands if isinstance(c, SetNodRate))
    limits = next(c for c in fake.commands if isinstance(c, SetNodLimits))
    assert rate.rate_udeg_per_s == pytest.approx(8_383_300, abs=100)
    assert (limits.low_udeg, limits.high_udeg) == (-38_000_000, -12_000_000)
    nods = np.degrees([e.body.nodAngleEnd for e in drain(events)[200:]])
    step = 8.3833 * PERIOD  # 0.22 deg between samples: the turnaround falls between two
    assert -14.0 - step <= nods.max() <= -14.0 + 1e-6
    assert -40.0 - 1e-6 <= nods.min() <= -40.0 + step


# -- tools and real sockets ------------------------------------------------------------------

class TeeStream(ByteStream):
    """Records every byte the driver reads (a capture of what the device sent)."""

    def __init__(self, inner: ByteStream, capture: bytearray) -> None:
        self.inner, self.capture = inner, capture

    async def read(self, max_bytes: int = 4096) -> bytes:
        data = await self.inner.read(max_bytes)
        self.capture += data
        return data

    async def write(self, data: bytes) -> None:
        await self.inner.write(data)

    async def close(self) -> None:
        await self.inner.close()

    @property
    def closed(self) -> bool:
        return self.inner.closed


def tee(factory: Callable[[DeviceSpec], Awaitable[ByteStream]],
        capture: bytearray) -> Callable[[DeviceSpec], Awaitable[ByteStream]]:
    async def open_device(spec: DeviceSpec) -> ByteStream:
        return TeeStream(await factory(spec), capture)

    return open_device


async def test_afa_decode_sick_reads_a_capture_of_the_fake(tmp_path, capsys):
    clock = VirtualClock(start=0.0)
    fake = FakeNodLaser(clock)
    capture = bytearray()
    component = laser()
    async with System([component], clock=clock,
                      devices={"NodLaserService": tee(fake.factory(), capture)}) as system:
        system.channel.subscribe("Raptor", "Laser11", maxsize=1000)
        await clock.advance(0.2)
        fake.corrupt_scans(1)
        await clock.advance(0.2)
    await fake.aclose()
    scans = component.counters["scans"]
    assert scans >= 12
    path = tmp_path / "laser11.bin"
    path.write_bytes(bytes(capture))
    assert main(["decode", "sick", str(path)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    records, summary = lines[:-1], lines[-1]["statistics"]
    kinds = [r["type"] for r in records]
    assert kinds.count("NodScan") == scans
    assert kinds.count("CommandAck") == 8  # one per configuration command
    assert kinds.count("SickReply") == 3  # stop streaming, variant, start streaming
    assert kinds.count("ControllerStatus") >= 1
    assert all(r["result"] == 0 for r in records if r["type"] == "CommandAck")
    first_scan = next(r for r in records if r["type"] == "NodScan")
    assert len(first_scan["measured"]["raw"]) == 361
    assert summary["messages"] == len(records)
    assert summary["checksum_failures"] == 1
    assert summary["bytes"] == len(capture)
    assert summary["bytes_skipped"] == FRAME_BYTES


async def test_the_driver_talks_to_the_fake_through_a_real_tcp_socket():
    clock = WallClock()
    # resting at -28 deg (encoder), -30 deg true: the first scan already sees the ground
    fake = FakeNodLaser(clock, source=flat_ground(2.0), offset_deg=-2.0,
                        initial_angle_deg=-28.0)
    served = asyncio.Event()

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            await fake.serve(AsyncioByteStream(reader, writer, "fake-controller"))
        finally:
            served.set()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    component = laser(Host="127.0.0.1", Port=port)
    try:
        # a loopback socket made for the test: the real TCP transport, on purpose
        async with System([component], clock=clock, real_devices=True) as system:
            proxy = await system.resolve(Range3dSensor, "Laser11")
            async with asyncio.timeout(10):
                scan = await proxy.get3dSeqWaitFullScan()
        async with asyncio.timeout(10):
            await served.wait()  # the fake saw the driver hang up
    finally:
        server.close()
        await server.wait_closed()
    assert scan.sensorId == 11 and scan.frame == LEFT
    assert len(scan.points) > 0 and np.all(np.abs(scan.points[:, 2] + 2.0) <= 6e-4)
    assert component.statistics()["connects"] == 1
    assert [type(c) for c in fake.commands][:2] == [SickCommand, StopNodding]


@pytest.mark.skipif(fake_module._words_kernel() is None,
                    reason="no compiled kernel (numba missing, or AFA_KERNELS=numpy)")
@pytest.mark.parametrize("noise_m", [0.0, 0.01])
def test_the_fakes_compiled_value_words_are_the_numpy_ones(noise_m, monkeypatch):
    # ranges at and around every boundary: no return (NaN, inf), negative, zero, half a
    # millimetre (rounded half to even), the first no-return count, beyond
    special = np.array([np.nan, np.inf, -np.inf, -1.0, 0.0, 0.0005, 0.0015, 0.0025, 0.001,
                        8.1815, 8.1825, 8.1835, 8.183, 8.2, 100.0])
    rng = np.random.default_rng(2)

    def source(t, nod_deg, bearings_deg):
        ranges = rng.uniform(-0.5, 9.0, bearings_deg.size)
        ranges[:special.size] = special
        return ranges

    def words(kernel):
        clock = VirtualClock(start=0.0)
        fake = FakeNodLaser(clock, source=source, noise_m=noise_m,
                            rng=np.random.default_rng(5))
        if not kernel:
            monkeypatch.setattr(fake_module, "_words_kernel", lambda: None)
        try:
            return [fake._measure(0.1 * k, 0.1 * k + 0.0266)[1] for k in range(30)]
        finally:
            monkeypatch.undo()

    state = rng.bit_generator.state
    compiled = words(True)
    rng.bit_generator.state = state
    reference = words(False)
    for a, b in zip(compiled, reference, strict=True):
        assert a.dtype == b.dtype == np.uint16
        np.testing.assert_array_equal(a, b)
    assert (np.concatenate(compiled) == fake_module.NO_RETURN_WORD).sum() > 100
