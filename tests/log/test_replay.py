"""Replay (LogPlayer) and the re-simulation check: ModelServer re-run on the recorded
GPS and IMU reproduces the recorded poses; a changed parameter diverges; recorded servers
answer polls; pause, step, seek and speed."""

import asyncio
import hashlib
from pathlib import Path

import pytest

from afa import ConfigError, EDevIO
from afa.log import Player, check
from idl import Platform, PoseTransformIDL, Range3dSensor, Range3dSeqEventIDL

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"


def _variant(tmp_path, name, old, new):
    text = RAPTOR.read_text()
    assert old in text
    path = RAPTOR.parent / f"_test_{name}_{tmp_path.name}.xml"  # beside its geometry file
    path.write_text(text.replace(old, new))
    return path


@pytest.fixture
def variant(tmp_path):
    made = []

    def make(name, old, new):
        made.append(_variant(tmp_path, name, old, new))
        return made[-1]

    yield make
    for path in made:
        path.unlink()


async def test_a_recorded_simulation_re_runs_identically(recorded):
    report = await check(recorded)
    assert report.identical, report.text()
    # the whole processing stack re-runs: pose filter, maps, behaviours, arbiter
    assert {"modelServer", "TerrainService", "TraverseService", "GlobalMapService",
            "obsAvoid", "purePursuit", "LaserSafetyService", "arcArbiter"} <= set(
        report.components)
    assert {"Gps", "Imu", "Laser11", "Stereo"} <= set(report.replayed)
    assert "Pose" not in report.replayed  # ModelServer makes it again
    assert report.compared["/Raptor/Pose"] > 100
    for topic in ("/Raptor/Terrain", "/Raptor/Traverse", "/Raptor/PlanMap",
                  "/Raptor/ArcVote", "/Raptor/ArcDecision",
                  "Raptor/RaptorMotion.setVelocity"):
        assert report.compared.get(topic, 0) > 0, (topic, report.compared)
    assert "identical:" in report.text()


async def test_a_changed_parameter_reports_where_it_diverges(recorded, variant):
    report = await check(recorded, variant("raw", '"UseRawPose" value="true"',
                                            '"UseRawPose" value="false"'))
    assert not report.identical
    d = report.divergence
    assert d.topic == "/Raptor/Pose" and d.origin == "modelServer"
    assert d.field.startswith("HTransform[") and d.recorded != d.replayed
    assert f"on /Raptor/Pose from modelServer: {d.field}: recorded" in report.text()

    report = await check(recorded, variant("period", '"UpdatePeriod" value="0"',
                                           '"UpdatePeriod" value="100"'))
    assert report.divergence is not None and report.divergence.topic == "/Raptor/Pose"
    assert 0.0 < report.divergence.offset < 12.0


async def test_an_autonomous_recording_re_runs_identically(recorded_autonomous):
    """The control station's commands (waypoints, patrol mode, start, arbiter on) are
    re-issued to the re-run servers, and same-stamp events keep their recorded order,
    so the arbiter's decisions are reproduced score for score."""
    from afa.log.reader import LogReader

    report = await check(recorded_autonomous)
    assert report.identical, report.text()
    assert report.compared["/Raptor/ArcDecision"] >= 5
    assert report.compared["/Raptor/ArcVote"] >= 50
    with LogReader(recorded_autonomous) as reader:  # the decisions weigh real votes
        scores = [reader.decode_event(m).body.scores
                  for m in reader.messages(channels={c.id for c in reader.topics("event")
                                                     if c.event == "ArcDecision"})]
    assert any(len(set(s.round(9).tolist())) > 2 for s in scores)


LONG_AUTONOMOUS_SECONDS = 20.0


async def test_a_long_autonomous_recording_re_runs_identically(tmp_path, record):
    """Past the instants where a GPS fix, the pose made from it and Pure Pursuit's timed
    vote share a stamp (the 6 s recording has none; before decision 0027 a 20 s one
    diverged at 9.47 s): the clock fires one timer at a time and the player holds each
    recorded input until the outputs recorded before it are made, so the order of every
    instant is reproduced. The control station's commands (waypoints, the planning
    boundary) are placed among the events by their recorded sequence."""
    from afa.log.reader import LogReader

    path = tmp_path / "long.mcap"
    await record(path, seconds=LONG_AUTONOMOUS_SECONDS, teleop=False)
    report = await check(path)
    assert report.identical, report.text()
    assert report.compared["/Raptor/ArcDecision"] >= 100
    assert report.compared["/Raptor/PlanMap"] >= 5
    with LogReader(path) as reader:  # instants where a source's input and a re-run
        shared = _shared_instants(reader)  # component's timed output share a stamp
    assert shared >= 10


def test_recorded_polls_stand_among_the_events_they_came_between(recorded_autonomous):
    """A recorded call carries the last event sequence number at its start; the player
    orders each instant by it (a re-issued ``setPlanningBoundary`` after the Traverse
    map it followed, not before every event of its instant)."""
    player = Player(recorded_autonomous, speed=None, check=True)
    try:
        placed = 0
        for _, group in player._instants(player.first):
            last_event = last_poll = -1
            for message, header, record in group:
                if header is not None:  # events in sequence, each after the calls
                    assert header[3] > max(last_event, last_poll)  # made before it
                    last_event = header[3]
                    assert record is None
                    continue
                # a call comes decoded by the feeder (it needed its seq), not twice
                assert record.seq == player.reader.decode_wire(message).seq
                assert record.seq >= max(last_event, last_poll, 0)
                last_poll = record.seq
                if last_event >= 0:  # an event of this instant came before it
                    placed += 1
        assert placed > 10
    finally:
        player.reader.close()


def _shared_instants(reader) -> int:
    """Stamps at which a GPS fix and a Pure Pursuit vote were both recorded."""
    from afa.events import peek_envelope

    stamps: dict[float, set[str]] = {}
    channels = {c.id for c in reader.topics("event") if c.event in ("Gps", "ArcVote")}
    for message in reader.messages(channels=channels):
        _, kind, stamp, _, origin = peek_envelope(message.data)
        stamps.setdefault(stamp, set()).add(kind if kind == "Gps" else origin)
    return sum(1 for names in stamps.values() if {"Gps", "purePursuit"} <= names)


async def test_a_changed_arbiter_weight_diverges_on_the_decision(recorded_autonomous,
                                                                 variant):
    report = await check(recorded_autonomous, variant(
        "weight", '"PursuitWeight" value="0.25"', '"PursuitWeight" value="2"'))
    d = report.divergence
    assert d is not None and d.topic == "/Raptor/ArcDecision" and d.origin == "arcArbiter"
    assert d.field.startswith("scores[") and d.recorded != d.replayed
    assert 1.0 < d.offset < 6.0
    assert f"on /Raptor/ArcDecision from arcArbiter: {d.field}: recorded" in report.text()


async def test_replay_at_max_speed_is_deterministic(recorded):
    async def digest():
        player = Player(recorded, speed=None)
        poses = player.system.channel.subscribe("Raptor", "Pose", maxsize=1 << 16)
        h = hashlib.sha256()
        async with player:
            await player.run()
        while (event := poses.get_nowait()) is not None:
            h.update(f"{event.time!r}".encode() + event.body.fingerprint())
        return h.hexdigest(), player.published

    assert await digest() == await digest()


async def test_recorded_servers_answer_polls_during_replay(recorded):
    player = Player(recorded, speed=None, paused=True, skip=["modelServer"])
    async with player:
        assert "Raptor/ModelService" in player.servants  # modelServer does not re-run
        laser = player.system.proxy(Range3dSensor, "Laser11")
        platform = player.system.proxy(Platform, "ModelService")
        with pytest.raises(EDevIO, match="no .* yet|not in the recording"):
            await platform.getPose()
        await player.step_time(3.0)
        scan = await laser.get3dSeqFullScan()
        assert isinstance(scan, Range3dSeqEventIDL) and scan.sensorId == 11
        with pytest.raises(EDevIO):
            await laser.get3dStereoFullScan()  # nothing recorded of that type
        with pytest.raises(EDevIO):  # the array form is built only for a subscriber
            await laser.get3dLaserFullScan()
        pose = await platform.getPose()
        assert isinstance(pose, PoseTransformIDL)
        player.resume()
        waited = await platform.getWaitPose()  # the next recorded pose, in replay time
        assert waited.time.to_seconds() > pose.time.to_seconds()
        assert waited.time.to_seconds() <= player.position


async def test_pause_step_seek_and_speed(recorded):
    player = Player(recorded, speed=4.0, paused=True)
    gps = player.system.channel.subscribe("Raptor", "Gps", maxsize=1 << 12)
    async with player:
        assert player.paused and player.speed == 4.0
        await player.step()
        first_step = player.delivered
        await player.step()
        assert 1 <= first_step < player.delivered
        await player.step_time(1.0)
        assert 1.0 <= player.elapsed <= 1.1
        fixes_before = []
        while (event := gps.get_nowait()) is not None:
            fixes_before.append(event)
        await player.seek(6.0)  # forward: the latest fix before 6 s comes first
        first = gps.get_nowait()
        assert first is not None and first.time < player.position
        assert player.elapsed == pytest.approx(6.0)
        await player.seek(2.0)  # and back
        again = gps.get_nowait()
        assert again is not None and again.time < first.time
        player.speed = None
        player.resume()
        await player.run()
        assert player.elapsed > 11.0


async def test_a_loop_starts_the_re_run_components_afresh(recorded):
    """Going back to ``--start`` (or seeking back) must not feed the re-run components
    the earlier stretch on top of what they made of the later one: a pose buffer ahead
    of every scan dropped the scans ("older than the pose buffer"), a terrain map kept
    from the end stamped the Traversability Map's next map in the future, and the
    Global Map refused it, on every pass."""
    # passes of 11 s: the maps publish once they have filled again (MapUpdateTime 7 s)
    player = Player(recorded, speed=None, start=0.5, end=11.5, loop=True)
    async with player:
        runner = asyncio.ensure_future(player.run())
        await player.clock.sleep(28.0)  # two and a half passes
        terrain = player.system.components["TerrainService"]
        scans = terrain.counters["scans"]
        await player.seek(1.0)  # and back by hand, mid-pass
        await player.clock.sleep(9.0)
        runner.cancel()
        await asyncio.gather(runner, return_exceptions=True)
        assert terrain.counters["scans"] > scans  # scans were fused after every wrap
        assert terrain.counters["too_old"] == 0 and terrain.counters["future_dropped"] == 0
        maps = player.system.components["TraverseService"]
        assert maps.counters["maps_published"] > 0 and maps.counters["future_maps"] == 0
        assert player.system.components["GlobalMapService"].counters["future_maps"] == 0


def test_only_and_skip_name_components_or_topics(recorded):
    player = Player(recorded, only=["modelServer", "Gps", "Imu"])
    try:
        assert [c.name for c in player.rerun] == ["modelServer"]
        assert {c.event for c in player.replayed.values()} == {"Gps", "Imu"}
    finally:
        player.reader.close()
    with pytest.raises(ConfigError, match="'Nothing' names no recorded topic"):
        Player(recorded, skip=["Nothing"])
