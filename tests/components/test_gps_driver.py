"""Contract tests of the GPS Sokkia driver (GSR2600, NovAtel OEM4) against its fake.

Everything runs in virtual time over in-memory pipes. Independent oracles:
- GPS time at the default virtual epoch, 2005-09-17 12:00:00 UTC, worked by hand:
  1126958400 - 315964800 (GPS epoch 1980-01-06) + 13 leap seconds = 810993613 s
  = week 1340 (1340 * 604800 = 810432000) + 561613 s (Saturday 12:00:13 GPS time).
- NovAtel CRC-32 as zlib's CRC-32 without the initial/final inversions; NMEA XOR.
- Real receiver captures in tests/data/gps (see SOURCES.md) with values read off the
  file (ASCII) or decoded by hand in test_gps_codec.py (binary).
"""

from __future__ import annotations

import json
import math
import re
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from afa import EDevIO, ETimeOut, SerialSpec, State, System, TransportClosed, VirtualClock
from afa.cli import main as cli_main
from afa.events import Subscription
from afa.testing import memory_pipe, serve, until
from components.gps_sokkia import GpsSokkia, GpsSokkiaParameters
from components.gps_sokkia.codec import (
    BestPos,
    BestUtm,
    BestVel,
    Gga,
    LogCommand,
    LogHeader,
    PositionType,
    SolutionStatus,
    UnlogAllCommand,
    Vtg,
    latlon_to_utm,
)
from components.gps_sokkia.component import EpochCombiner, configuration_commands
from components.gps_sokkia.fake import FakeGps, GpsTruth, gps_time
from idl import Gps

DATA = Path(__file__).resolve().parent.parent / "data" / "gps"
START = 1126958400.0  # 2005-09-17 12:00:00 UTC (afa.clock.DEFAULT_EPOCH)
LAT0, LON0 = 50.2667, -111.1750
EARTH_RADIUS = 6371000.0


def driving(t: float) -> GpsTruth:
    """Driving north-east (track 45 deg) at 5 m/s from (LAT0, LON0) since START."""
    d = 5.0 * (t - START)
    north = east = d * math.sqrt(0.5)
    lat = LAT0 + math.degrees(north / EARTH_RADIUS)
    lon = LON0 + math.degrees(east / (EARTH_RADIUS * math.cos(math.radians(LAT0))))
    return GpsTruth(lat=lat, lon=lon, height=750.0, speed=5.0, track=45.0)


def metres(lat_a: float, lon_a: float, lat_b: float, lon_b: float) -> tuple[float, float]:
    """North and east offsets (m) of a from b, locally flat."""
    north = math.radians(lat_a - lat_b) * EARTH_RADIUS
    east = math.radians(lon_a - lon_b) * EARTH_RADIUS * math.cos(math.radians(lat_b))
    return north, east


def drain(subscription: Subscription) -> list:
    events = []
    while (event := subscription.get_nowait()) is not None:
        events.append(event)
    return events


def crc_oracle(data: bytes) -> int:
    return zlib.crc32(data, 0xFFFFFFFF) ^ 0xFFFFFFFF


def xor_oracle(body: bytes) -> int:
    value = 0
    for byte in body:
        value ^= byte
    return value


def solutions_by_time(fake: FakeGps) -> dict[float, object]:
    return {round(s.unix, 3): s for s in fake.solutions}


# ------------------------------------------------------------------ driver <-> fake


async def test_configures_the_receiver_with_binary_logs_at_4_hz() -> None:
    clock = VirtualClock(start=START)
    host, device = memory_pipe("gps")
    async with System([GpsSokkia("Gps")], clock=clock, devices={"Gps": serve(host)}):
        await clock.settle()
        written = b"".join([await device.read() for _ in range(4)])
    assert written == (b"unlogall thisport\r\n"
                       b"log bestposb ontime 0.25\r\n"
                       b"log bestvelb ontime 0.25\r\n"
                       b"log bestutmb ontime 0.25\r\n")
    assert b"".join(configuration_commands()) == written


async def test_publishes_4_hz_fixes_that_match_the_truth() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock, driving, np.random.default_rng(7))
    gps = GpsSokkia("Gps")
    async with System([gps], clock=clock, devices={"Gps": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Gps", maxsize=1000)
        await clock.advance(1.0)
        drain(events)
        await clock.advance(10.0)
        got = drain(events)
        stats = gps.statistics()
        await fake.aclose()
    assert fake.commands[:4] == [
        UnlogAllCommand("THISPORT"),
        LogCommand(None, "BESTPOSB", "ONTIME", 0.25),
        LogCommand(None, "BESTVELB", "ONTIME", 0.25),
        LogCommand(None, "BESTUTMB", "ONTIME", 0.25)]
    assert 39 <= len(got) <= 41
    times = [e.time for e in got]
    assert all(b - a == pytest.approx(0.25) for a, b in zip(times, times[1:], strict=False))
    solutions = solutions_by_time(fake)
    for event in got:
        body = event.body
        assert body.time.sec + body.time.usec * 1e-6 == pytest.approx(event.time, abs=1e-6)
        # Within the noise of a differential fix (0.3 m horizontal, 0.6 m vertical).
        truth = driving(event.time)
        north, east = metres(body.latitude, body.longitude, truth.lat, truth.lon)
        assert abs(north) < 1.5 and abs(east) < 1.5
        assert abs(body.elevation - 750.0) < 3.0
        assert body.horizontalSpeed == pytest.approx(5.0, abs=0.2)
        assert body.track == pytest.approx(45.0, abs=2.5)
        # Binary logs carry the receiver's doubles exactly.
        solution = solutions[round(event.time, 3)]
        assert (body.latitude, body.longitude) == (solution.lat, solution.lon)
        utm = latlon_to_utm(solution.lat, solution.lon)
        assert (body.utmZone, body.utmZoneLetter) == (12, "U")
        assert body.easting == pytest.approx(utm.easting_m, abs=1e-6)
        assert body.northing == pytest.approx(utm.northing_m, abs=1e-6)
        assert body.solutionStatus == "SOL_COMPUTED" and body.positionType == "PSRDIFF"
        assert body.satellitesTracked == 10 and 7 <= body.satellitesUsed <= 9
        assert body.latitudeStd == pytest.approx(0.3) and body.elevationStd == pytest.approx(0.6)
        assert body.undulation == -16.5 and body.differentialAge == 1.0
        assert body.baseStationId == "0"
    # Noise is there: the errors are not all zero.
    assert any(e.body.latitude != driving(e.time).lat for e in got)
    assert stats["source"] == "novatel" and stats["command_errors"] == 0
    assert stats["checksum_failures"] == stats["malformed"] == 0
    assert stats["incomplete_epochs"] == 0 and stats["late_logs"] == 0


async def test_polls_get_latest_getwait_next_and_timeout_when_unplugged() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock, driving, np.random.default_rng(3))
    gps = GpsSokkia("Gps")
    async with System([gps], clock=clock, devices={"Gps": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Gps", maxsize=100)
        proxy = await system.resolve(Gps, "Gps")
        await clock.advance(1.0)
        latest = await proxy.getPosition()
        assert latest == drain(events)[-1].body
        following = await proxy.getWaitPosition()
        assert following.latitude != latest.latitude
        seconds = (following.time.sec - latest.time.sec) \
            + (following.time.usec - latest.time.usec) * 1e-6
        assert seconds == pytest.approx(0.25)
        assert await proxy.getPosition() == following
        fake.unplug()
        before = clock.now()
        with pytest.raises(ETimeOut):
            await proxy.getWaitPosition()
        assert clock.now() - before == pytest.approx(Gps.wait_timeout)
        assert await proxy.getPosition() == following  # the last fix stays available
        await fake.aclose()


async def test_get_before_any_fix_is_edevio() -> None:
    clock = VirtualClock(start=START)
    silent = FakeGps(clock, obey_commands=False)  # no logs configured, ignores the host
    async with System([GpsSokkia("Gps")], clock=clock,
                      devices={"Gps": silent.factory()}) as system:
        proxy = await system.resolve(Gps, "Gps")
        await clock.advance(0.5)
        with pytest.raises(EDevIO):
            await proxy.getPosition()
        await silent.aclose()


async def test_corrupt_logs_and_line_noise_are_counted_and_the_stream_resynchronises() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock, driving, np.random.default_rng(11))
    gps = GpsSokkia("Gps")
    async with System([gps], clock=clock, devices={"Gps": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Gps", maxsize=1000)
        await clock.advance(1.1)
        drain(events)
        fake.corrupt_next(2)  # BESTPOSB and BESTVELB of the next epoch
        await fake.inject(b"\x00\xff\x13line noise\xaa\x44\x12junk[COM\x01")
        await clock.advance(10.0)
        got = drain(events)
        stats = gps.statistics()
        await fake.aclose()
    assert stats["checksum_failures"] == 2
    assert stats["bytes_skipped"] > 0 and stats["resyncs"] >= 2
    assert stats["dropped_epochs"] == 1  # a BESTUTM alone is not a fix
    assert 38 <= len(got) <= 40  # one epoch lost, the rest on time
    solutions = solutions_by_time(fake)
    for event in got:  # no damaged value ever reached an event
        solution = solutions[round(event.time, 3)]
        assert (event.body.latitude, event.body.longitude) == (solution.lat, solution.lon)


async def test_a_lost_receiver_is_reconnected_and_another_gps_keeps_running() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock, driving, np.random.default_rng(1))
    other = FakeGps(clock, driving, np.random.default_rng(2))
    gps = GpsSokkia("Gps")
    bystander = GpsSokkia("Gps2", GpsSokkiaParameters(Device="/dev/ttyUSB1", EventName="Gps2"))
    system = System([gps, bystander], clock=clock,
                    devices={"Gps": fake.factory(), "Gps2": other.factory()})
    async with system:
        mine = system.channel.subscribe("Raptor", "Gps", maxsize=1000)
        theirs = system.channel.subscribe("Raptor", "Gps2", maxsize=1000)
        await clock.advance(1.0)
        assert gps.health().healthy
        fake.unplug()
        await clock.advance(0.05)
        assert not gps.health().healthy
        assert "device lost" in gps.health().detail
        await clock.advance(3.0)
        assert not gps.health().healthy and "cannot open device" in gps.health().detail
        plugged_at = clock.now()
        fake.plug()
        await until(lambda: gps.health().healthy, clock, timeout=10.0)
        await clock.advance(2.0)
        stats = gps.statistics()
        await fake.aclose()
        await other.aclose()
    assert stats["connects"] == 2 and stats["reconnects"] == 1
    assert gps.state is State.STOPPED and gps.failures == 0
    resumed = [e.time for e in drain(mine) if e.time > plugged_at]
    assert len(resumed) >= 6
    assert all(b - a == pytest.approx(0.25) for a, b in zip(resumed, resumed[1:], strict=False))
    times = [e.time for e in drain(theirs)]
    assert max(b - a for a, b in zip(times, times[1:], strict=False)) == pytest.approx(0.25)
    assert len(times) >= 23  # ~6 s at 4 Hz, never paused


async def test_nmea_only_receiver_is_used_as_a_fallback() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock, driving, np.random.default_rng(5), obey_commands=False,
                   logs={"GPGGA": 0.25, "GPRMC": 0.25, "GPVTG": 0.25})
    gps = GpsSokkia("Gps")
    async with System([gps], clock=clock, devices={"Gps": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Gps", maxsize=1000)
        await clock.advance(1.0)
        drain(events)
        await clock.advance(10.0)
        got = drain(events)
        stats = gps.statistics()
        await fake.aclose()
    assert 39 <= len(got) <= 41
    solutions = solutions_by_time(fake)
    for event in got:
        body, solution = event.body, solutions[round(event.time, 3)]
        # RMC: 7 decimals of a minute (0.2 mm); GGA heights to the centimetre.
        north, east = metres(body.latitude, body.longitude, solution.lat, solution.lon)
        assert abs(north) < 0.001 and abs(east) < 0.001
        assert body.elevation == pytest.approx(solution.height, abs=0.006)
        assert body.undulation == -16.5
        # VTG: km/h to 3 decimals (0.3 mm/s), course to 3 decimals.
        assert body.horizontalSpeed == pytest.approx(solution.speed, abs=1e-3)
        assert body.track == pytest.approx(solution.track, abs=1e-3)
        assert body.positionType == "PSRDIFF"  # GGA quality 2
        assert body.solutionStatus == "SOL_COMPUTED"
        assert body.satellitesUsed == solution.satellites_used
        assert body.utmZone == 12 and body.utmZoneLetter == "U"
    assert stats["source"] == "nmea" and stats["checksum_failures"] == 0


async def test_nmea_is_ignored_while_novatel_logs_arrive_and_fast_logs_are_decimated() -> None:
    # The real swri capture: BESTPOSA, GPGGA, GPRMC at 20 Hz and one TIMEA.
    data = (DATA / "swri_ascii_nmea.log").read_bytes()
    text = data.decode("ascii")
    bestpos = re.findall(r"#BESTPOSA,[^;]*,1957,([0-9.]+),[^;]*;SOL_COMPUTED,SINGLE,"
                         r"([-0-9.]+),([-0-9.]+),([-0-9.]+),([-0-9.]+)", text)
    assert len(bestpos) == 8
    clock = VirtualClock(start=START)
    host, device = memory_pipe("gps")
    device.write_nowait(data)
    gps = GpsSokkia("Gps")
    async with System([gps], clock=clock, devices={"Gps": serve(host)}) as system:
        events = system.channel.subscribe("Raptor", "Gps", maxsize=100)
        proxy = await system.resolve(Gps, "Gps")
        await clock.settle()
        latest = await proxy.getPosition()
        stats = gps.statistics()
    published = [e.body for e in drain(events)]
    # GPS times 339804.750 ... 339805.100 every 50 ms: the 250 ms grid takes .750, .000.
    assert [p.latitude for p in published] == [float(bestpos[0][1]), float(bestpos[5][1])]
    assert stats["fixes"] == 8 and stats["published"] == 2
    assert stats["ignored_nmea"] == 15 and stats["unknown_logs"] == 1  # 8 GGA + 7 RMC; TIMEA
    last = bestpos[-1]
    assert (latest.latitude, latest.longitude, latest.elevation, latest.undulation) == (
        float(last[1]), float(last[2]), float(last[3]), float(last[4]))
    assert latest.positionType == "SINGLE" and latest.satellitesUsed == 8
    assert (latest.utmZone, latest.utmZoneLetter) == (14, "R")


async def test_real_binary_capture_combines_bestpos_and_bestvel_of_each_epoch() -> None:
    # swri capture: prompt, then 3 rounds of PSRDOP2B, BESTPOSB, BESTVELB (10 Hz).
    clock = VirtualClock(start=START)
    host, device = memory_pipe("gps")
    device.write_nowait((DATA / "swri_binary.bin").read_bytes())
    gps = GpsSokkia("Gps")
    async with System([gps], clock=clock, devices={"Gps": serve(host)}) as system:
        events = system.channel.subscribe("Raptor", "Gps", maxsize=100)
        proxy = await system.resolve(Gps, "Gps")
        await clock.settle()
        latest = await proxy.getPosition()
        stats = gps.statistics()
    (first,) = [e.body for e in drain(events)]  # 412623.4; .5 and .6 are inside 250 ms
    # Values decoded by hand from the frames (see test_gps_codec.test_decodes_real_*).
    assert first.latitude == 29.443919376635606 and first.longitude == -98.61475813065091
    assert first.horizontalSpeed == 0.004193245658897487
    assert first.track == 56.3045377218809 and first.verticalSpeed == 0.024802116920758177
    assert first.positionType == "SINGLE" and first.satellitesTracked == 8
    assert (first.utmZone, first.utmZoneLetter) == (14, "R")
    # 98.6148 W is 0.3852 deg east of zone 14's central meridian (99 W): ~37.3 km.
    assert 537_000 < first.easting < 538_000 and 3_257_000 < first.northing < 3_259_000
    assert latest.latitude == 29.443917664970634
    assert latest.horizontalSpeed == 0.07053094815232781
    assert stats["fixes"] == 3 and stats["unknown_logs"] == 3 and stats["incomplete_epochs"] == 1


async def test_notify_false_publishes_nothing_but_answers_polls() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock, driving)
    gps = GpsSokkia("Gps", GpsSokkiaParameters(Notify=False))
    async with System([gps], clock=clock, devices={"Gps": fake.factory()}) as system:
        events = system.channel.subscribe("Raptor", "Gps", maxsize=100)
        proxy = await system.resolve(Gps, "Gps")
        await clock.advance(2.0)
        fix = await proxy.getPosition()
        await fake.aclose()
    assert drain(events) == []
    truth = driving(fix.time.sec + fix.time.usec * 1e-6)
    assert (fix.latitude, fix.longitude) == (truth.lat, truth.lon)  # no noise without rng
    assert fix.horizontalSpeed == 5.0 and fix.track == 45.0


# ------------------------------------------------------------------------ the fake


async def open_fake(fake: FakeGps):
    return await fake.factory()(SerialSpec("/dev/ttyS0", 57600))


async def read_until_closed(stream) -> bytes:
    chunks = []
    try:
        while True:
            chunks.append(await stream.read())
    except TransportClosed:
        return b"".join(chunks)


async def test_fake_bestposb_frame_checked_by_hand() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock)  # standing still at (50.2667, -111.175), 750 m, no noise
    host = await open_fake(fake)
    await host.write(b"log bestposb once\r\n")
    await clock.settle()
    fake.unplug()
    data = await read_until_closed(host)
    assert data.startswith(b"<OK\r\n\r\n[COM1]")
    frame = data[len(b"<OK\r\n\r\n[COM1]"):]
    assert len(frame) == 28 + 72 + 4
    assert frame[:4] == b"\xaa\x44\x12\x1c"
    message_id, message_length = struct.unpack_from("<H", frame, 4)[0], \
        struct.unpack_from("<H", frame, 8)[0]
    week, ms = struct.unpack_from("<HI", frame, 14)
    assert (message_id, message_length) == (42, 72)
    assert (week, ms) == (1340, 561613000)  # worked by hand (module docstring)
    assert struct.unpack_from("<I", frame, 100)[0] == crc_oracle(frame[:100])
    sol, ptype, lat, lon, hgt = struct.unpack_from("<IIddd", frame, 28)
    assert (sol, ptype, lat, lon, hgt) == (0, 17, 50.2667, -111.175, 750.0)  # PSRDIFF = 17
    assert gps_time(START) == (1340, 561613000)
    await fake.aclose()


async def test_fake_gpgga_on_whole_seconds_checked_by_hand() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock)
    host = await open_fake(fake)
    await clock.advance(0.1)
    await host.write(b"log com1 gpgga ontime 1\r\n")
    await clock.advance(1.0)  # up to 12:00:01.1 UTC: one sentence, at 12:00:01.00
    fake.unplug()
    data = await read_until_closed(host)
    # 50.2667 deg = 50 deg 16.0020 min N; 111.175 deg = 111 deg 10.5000 min W.
    body = b"GPGGA,120001.00,5016.0020,N,11110.5000,W,2,09,0.9,750.00,M,-16.50,M,01,0"
    assert data == b"<OK\r\n\r\n[COM1]$" + body + b"*%02X\r\n" % xor_oracle(body)
    await fake.aclose()


async def test_fake_answers_unknown_logs_with_an_error_and_obeys_unlogall() -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock)
    host = await open_fake(fake)
    await host.write(b"log bogusa ontime 1\r\nlog bestposa ontime 0.5\r\nunlogall\r\n")
    await clock.advance(2.0)
    fake.unplug()
    data = await read_until_closed(host)
    assert data == (b"<ERROR:Invalid Message ID\r\n\r\n[COM1]"
                    b"<OK\r\n\r\n[COM1]<OK\r\n\r\n[COM1]")
    assert fake.active == {}
    await fake.aclose()


async def test_afa_decode_on_a_capture_the_fake_produced(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    clock = VirtualClock(start=START)
    fake = FakeGps(clock, driving, np.random.default_rng(9))
    host = await open_fake(fake)
    await clock.advance(0.1)
    await host.write(b"log bestposb ontime 0.5\r\nlog bestvela ontime 0.5\r\n"
                     b"log gpgga ontime 1\r\nlog bogusa ontime 1\r\n")
    await clock.advance(2.0)  # solutions at +0.5, +1.0, +1.5, +2.0 s
    fake.unplug()
    data = await read_until_closed(host)
    await fake.aclose()
    path = tmp_path / "gps.bin"
    path.write_bytes(data)
    capsys.readouterr()
    assert cli_main(["decode", "gps", str(path)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    records, final = lines[:-1], lines[-1]
    kinds = [r["type"] for r in records]
    assert kinds.count("BestPos") == 4 and kinds.count("BestVel") == 4
    assert kinds.count("Gga") == 2 and kinds.count("Prompt") == 4
    assert [r["ok"] for r in records if r["type"] == "CommandResponse"] == [True] * 3 + [False]
    first = next(r for r in records if r["type"] == "BestPos")
    assert first["header"]["gps_week"] == 1340 and first["header"]["gps_seconds"] == 561613.5
    north, east = metres(first["latitude_deg"], first["longitude_deg"],
                         driving(START + 0.5).lat, driving(START + 0.5).lon)
    assert abs(north) < 1.5 and abs(east) < 1.5
    # bytes_skipped: the CR LF after the last sentence, held by the decoder until a next
    # frame would arrive; the CLI reports it as unconsumed.
    assert data.endswith(b"\r\n")
    assert final == {"statistics": {"messages": len(records), "checksum_failures": 0,
                                    "malformed": 0, "bytes_skipped": 2, "bytes": len(data)}}


def test_afa_decode_on_the_real_swri_capture(capsys: pytest.CaptureFixture[str]) -> None:
    path = DATA / "swri_ascii_nmea.log"
    assert cli_main(["decode", "gps", str(path)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    records, final = lines[:-1], lines[-1]
    # First line of the file: #BESTPOSA,...;SOL_COMPUTED,SINGLE,29.44387747069,-98.61473389841,
    assert records[0]["type"] == "BestPos"
    assert records[0]["latitude_deg"] == 29.44387747069
    assert records[0]["longitude_deg"] == -98.61473389841
    kinds = [r["type"] for r in records]
    assert (kinds.count("BestPos"), kinds.count("Gga"), kinds.count("Rmc"),
            kinds.count("UnknownLog")) == (8, 8, 7, 1)  # 24 lines
    stats = final["statistics"]
    assert stats["messages"] == 24 and stats["bytes"] == 3010
    assert stats["checksum_failures"] == stats["malformed"] == 0


# ---------------------------------------------------------------- epoch combination


def _pos(seconds: float) -> BestPos:
    header = LogHeader("BESTPOS", gps_week=1340, gps_seconds=seconds)
    return BestPos(header, SolutionStatus.SOL_COMPUTED, PositionType.SINGLE, 45.0, -75.0, 80.0,
                   -30.0, "WGS84", 1.0, 1.0, 2.0, "", 0.0, 0.0, 8, 8)


def _vel(seconds: float) -> BestVel:
    header = LogHeader("BESTVEL", gps_week=1340, gps_seconds=seconds)
    return BestVel(header, SolutionStatus.SOL_COMPUTED, PositionType.DOPPLER_VELOCITY,
                   0.0, 0.0, 1.0, 90.0, 0.0)


def test_combiner_stops_waiting_for_a_log_the_receiver_does_not_send() -> None:
    combiner = EpochCombiner({"BESTPOS", "BESTVEL", "BESTUTM"}, {"BESTPOS"})
    assert combiner.add("BESTPOS", 1, _pos(1.0), 10.0) == []
    assert combiner.add("BESTVEL", 1, _vel(1.0), 10.0) == []
    (old,) = combiner.add("BESTPOS", 2, _pos(1.25), 10.25)  # epoch 1 superseded
    assert old.key == 1 and set(old.parts) == {"BESTPOS", "BESTVEL"} and old.time == 10.0
    (new,) = combiner.add("BESTVEL", 2, _vel(1.25), 10.25)  # complete without BESTUTM now
    assert new.key == 2 and combiner.incomplete == 1


def test_combiner_attaches_an_untimed_vtg_to_its_own_epoch() -> None:
    combiner = EpochCombiner({"GGA"}, {"GGA", "RMC"})
    gga = Gga("GP", 1.0, 45.0, -75.0, 1, 8, 1.0, 80.0, -30.0)
    vtg = Vtg("GP", 90.0, 90.0, 1.0, 1.852)
    (first,) = combiner.add("GGA", 1000, gga, 0.0)  # nothing else expected yet
    assert combiner.add("VTG", None, vtg, 0.0) == []  # late part of epoch 1000: learnt
    assert combiner.add("GGA", 2000, gga, 1.0) == []  # now waits for its VTG
    (second,) = combiner.add("VTG", None, vtg, 1.0)
    assert second.key == 2000 and set(second.parts) == {"GGA", "VTG"}
    assert combiner.late == 1


def test_bestutm_eastings_are_used_when_logged() -> None:
    from components.gps_sokkia.component import Epoch, novatel_epoch_to_idl

    header = LogHeader("BESTUTM", gps_week=1340, gps_seconds=1.0)
    utm = BestUtm(header, SolutionStatus.SOL_COMPUTED, PositionType.SINGLE, 18, "T",
                  4984000.5, 421000.25, 80.0, -30.0, "WGS84", 1.0, 1.0, 2.0, "", 0.0, 0.0, 8, 8)
    body = novatel_epoch_to_idl(Epoch(1, 5.0, {"BESTPOS": _pos(1.0), "BESTUTM": utm}))
    assert (body.utmZone, body.utmZoneLetter, body.easting, body.northing) == (
        18, "T", 421000.25, 4984000.5)
    computed = novatel_epoch_to_idl(Epoch(1, 5.0, {"BESTPOS": _pos(1.0)}))
    assert (computed.utmZone, computed.utmZoneLetter) == (18, "T")
    assert computed.horizontalSpeed == 0.0 and computed.time.sec == 5
