"""Recording (LogNotify): events with stamps, sequence and origin; schemas once; polls;
metadata; patterns; drops counted; flushes that survive a killed process."""

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from afa import EOutOfBounds, SubscribePublishServer, System, VirtualClock
from afa.log import LogReader, PollCallIDL, Recorder, recover
from afa.log import format as fmt
from idl import GpsIDL, Platform, PoseTransformIDL, TimeIDL, type_name, wire

ROOT = Path(__file__).resolve().parents[2]


def test_every_event_is_recorded_with_its_stamp_sequence_and_origin(recorded):
    with LogReader(recorded) as reader:
        assert reader.indexed and not reader.problems
        assert reader.profile == "afa" and reader.library.startswith("afa ")
        events = [reader.decode_event(m) for m in reader.messages(
            channels=[c.id for c in reader.topics(fmt.EVENT)])]
        end = json.loads(reader.metadata["afa.end"]["events"])
    assert len(events) == end > 1000
    seqs = [e.seq for e in events]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)  # publication order
    assert [e.time for e in events] == sorted(e.time for e in events)
    origins = {e.type: e.origin for e in events}
    assert origins["Gps"] == "GpsSokkiaService" and origins["Pose"] == "modelServer"
    poses = [e for e in events if e.type == "Pose"]
    assert all(isinstance(p.body, PoseTransformIDL) for p in poses)
    assert poses[0].time == poses[0].body.time.to_seconds()  # the stamp, exactly


def test_each_type_is_one_schema_from_the_codec_and_each_event_name_one_channel(recorded):
    with LogReader(recorded) as reader:
        names = [name for name, _, _ in reader.schemas.values()]
        assert len(names) == len(set(names))
        gps = next(c for c in reader.topics(fmt.EVENT) if c.event == "Gps")
        assert gps.topic == "/Raptor/Gps" and gps.encoding == "afa-event"
        assert gps.schema == type_name(GpsIDL) == "idl.sensors.GpsIDL@1"
        schema = next(data for name, enc, data in reader.schemas.values() if name == gps.schema)
        assert json.loads(schema) == json.loads(json.dumps(wire.schema(GpsIDL)))
        assert len({c.topic for c in reader.topics(fmt.EVENT)}) == len(reader.topics(fmt.EVENT))


def test_metadata_names_the_configuration_world_seed_version_and_catalog(recorded):
    with LogReader(recorded) as reader:
        afa = reader.metadata["afa"]
        assert afa["world"] == "open-field" and afa["seed"] == "3"
        assert afa["version"] and afa["clock"] == "VirtualClock" and "start_time" in afa
        assert float(afa["clock_origin"]) == VirtualClock().now()
        config = reader.metadata["afa.config"]
        assert config["text"] == (ROOT / "configs" / "raptor.xml").read_text()
        ports = reader.catalog()
        assert {"component": "modelServer", "direction": "serves", "name": "ModelService",
                "types": ["idl.interfaces.Platform"], "domain": None} in ports


def test_the_drive_scripts_polls_are_recorded_with_arguments_and_results(recorded):
    with LogReader(recorded) as reader:
        channel = next(c for c in reader.topics(fmt.POLL) if c.metadata["afa.method"]
                       == "setJoystickVelocity")
        assert channel.topic == "/afa/poll/Raptor/RaptorMotion/setJoystickVelocity"
        record = reader.decode_wire(next(reader.messages(channels=[channel.id])))
    assert isinstance(record, PollCallIDL) and record.caller == ""  # the script, no component
    assert record.server == "Raptor/RaptorMotion" and not record.error_kind


class Geometry(SubscribePublishServer):
    """A Platform server with a failing method, and a component polling it."""

    def __init__(self, name):
        super().__init__(name)
        self.serves(Platform, "ModelService")

    async def getTransformation(self, A, B):
        if A == B:
            return PoseTransformIDL.identity()
        raise EOutOfBounds(f"no frame {B!r}")

    async def getBodyList(self): ...
    async def getBodyFrameList(self, body): ...
    async def getPose(self): ...
    async def getWaitPose(self): ...


class Asker(SubscribePublishServer):
    def __init__(self, name):
        super().__init__(name)
        self.platform = self.uses(Platform, "ModelService")

    async def run(self):
        await self.bound(self.platform)
        await self.platform.getTransformation("A:x", "A:x")
        try:
            await self.platform.getTransformation("A:x", "B:y")
        except EOutOfBounds:
            pass


async def test_polls_are_recorded_with_caller_arguments_results_and_errors(tmp_path):
    clock = VirtualClock(start=100.0)
    system = System([Geometry("geo"), Asker("asker")], clock=clock)
    recorder = Recorder(tmp_path / "polls.mcap").attach(system)
    async with system:
        await clock.advance(0.5)
        await recorder.close()
    with LogReader(tmp_path / "polls.mcap") as reader:
        calls = [reader.decode_wire(m) for m in reader.messages(
            channels=[c.id for c in reader.topics(fmt.POLL)])]
        times = [m.time for m in reader.messages(
            channels=[c.id for c in reader.topics(fmt.POLL)])]
    assert [(c.caller, c.method, c.error_kind) for c in calls] == [
        ("asker", "getTransformation", ""), ("asker", "getTransformation", "EOutOfBounds")]
    assert calls[1].error_message == "no frame 'B:y'" and times == [100.0, 100.0]
    from afa.polling import decode_arguments, decode_result
    assert decode_arguments(Platform, "getTransformation", bytes(calls[1].arguments)) == {
        "A": "A:x", "B": "B:y"}
    assert decode_result(Platform, "getTransformation", bytes(calls[0].result)) == \
        PoseTransformIDL.identity()


class Burst(SubscribePublishServer):
    def __init__(self, name, count):
        super().__init__(name)
        self.out = self.publishes("Fix", GpsIDL)
        self.other = self.publishes("Other", GpsIDL)
        self.count = count

    async def run(self):
        for k in range(self.count):  # no await: faster than any observer can keep up
            self.out.publish(GpsIDL(time=TimeIDL(sec=k)))
            self.other.publish(GpsIDL(time=TimeIDL(sec=k)))


async def test_patterns_choose_events_and_what_the_buffer_drops_is_counted_in_the_file(tmp_path):
    clock = VirtualClock(start=0.0)
    system = System([Burst("burst", 50)], clock=clock)
    recorder = Recorder(tmp_path / "drops.mcap", events=["Fi*"], maxsize=10).attach(system)
    async with system:
        await clock.advance(2.0)
        await recorder.close()
    assert recorder.statistics()["events_dropped"] == 90  # 100 published, 10 kept
    with LogReader(tmp_path / "drops.mcap") as reader:
        assert {c.event for c in reader.topics(fmt.EVENT)} == {"Fix"}
        dropped = [reader.decode_wire(m) for m in reader.messages(
            channels=[c.id for c in reader.topics(fmt.DROPPED)])]
        assert json.loads(reader.metadata["afa.end"]["events_dropped"]) == 90
    assert dropped[-1].events == 90 and dropped[-1].by_type == {"Fix": 45}


class Ticker(SubscribePublishServer):
    """A fix every 10 ms of clock time."""

    def __init__(self, name):
        super().__init__(name)
        self.out = self.publishes("Fix", GpsIDL)

    async def run(self):
        k = 0
        async for _ in self.clock.periodic(0.01):
            self.out.publish(GpsIDL(time=TimeIDL(sec=k)))
            k += 1


async def test_events_are_recorded_in_batches_and_none_is_lost_at_a_flush_or_the_end(
        tmp_path):
    """The recorder lets events wait up to its batch period: a flush records what waits
    before writing (what was published before it is on disk after it), and finish()
    records what still waits, so every published event is in the file."""
    clock = VirtualClock(start=0.0)
    system = System([Ticker("ticker")], clock=clock)
    on_disk = []
    recorder = Recorder(tmp_path / "batches.mcap", batch_period=0.25,
                        on_flush=on_disk.append).attach(system)
    async with system:
        await clock.advance(1.13)
        waiting = recorder._observer.subscription.statistics().queued
        published = system.channel.counts()["Fix"]
        assert 0 < waiting < published  # batches: some recorded, the latest waiting
        assert recorder.events_written == published - waiting
        recorder.flush()
        assert recorder.events_written == recorder.events_flushed == published
        await clock.advance(0.3)
        published = system.channel.counts()["Fix"]
        recorder.finish()  # not close(): nothing awaited
    with LogReader(tmp_path / "batches.mcap") as reader:
        fixes = [reader.decode_event(m).body.time.sec for m in reader.messages()
                 if m.channel.kind == fmt.EVENT]
        assert json.loads(reader.metadata["afa.end"]["events_dropped"]) == 0
    assert fixes == list(range(published))
    assert on_disk and on_disk[-1] <= published


CHILD = textwrap.dedent("""
    import asyncio, sys
    from afa import SubscribePublishServer, System, VirtualClock
    from afa.log import Recorder
    from idl import GpsIDL, TimeIDL

    class Counter(SubscribePublishServer):
        def __init__(self, name):
            super().__init__(name)
            self.out = self.publishes("Fix", GpsIDL)

        async def run(self):
            k = 0
            async for _ in self.clock.periodic(0.1):
                self.out.publish(GpsIDL(time=TimeIDL(sec=k), latitude=k * 1e-3))
                k += 1

    def flushed(count):
        print(count, flush=True)
        if count >= 25:  # the parent kills us; meanwhile write what will never be flushed
            recorder.flush_period = 1e9
            recorder.on_flush = None
            import time
            while True:
                recorder._writer.add_message(1, 0, b"x" * 1000, 0)
                time.sleep(0.01)

    async def main():
        global recorder
        clock = VirtualClock(start=0.0)
        system = System([Counter("counter")], clock=clock)
        recorder = Recorder(sys.argv[1], on_flush=flushed, chunk_size=1 << 30).attach(system)
        async with system:
            await system.run()

    asyncio.run(main())
""")


def test_a_recording_killed_mid_write_reads_back_up_to_its_last_flush(tmp_path):
    path = tmp_path / "killed.mcap"
    flushed = 0
    with subprocess.Popen([sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE,
                          text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}) as child:
        for line in child.stdout:
            flushed = int(line)
            if flushed >= 25:
                break
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
    with LogReader(path) as reader:
        assert not reader.indexed
        assert any("no index" in p for p in reader.problems)
        fixes = [reader.decode_event(m) for m in reader.messages()
                 if m.channel.kind == fmt.EVENT]
    assert len(fixes) == flushed == 30  # flushed every second: 10 fixes a second
    assert [f.body.time.sec for f in fixes] == list(range(30))  # all there, in order
    assert recover(path, tmp_path / "whole.mcap") >= 30
    with LogReader(tmp_path / "whole.mcap") as whole:
        assert whole.indexed and not whole.problems
        assert whole.metadata["afa.recovered"]["messages"] == str(sum(whole.counts.values()))
        assert np.isclose(whole.duration, 3.0)  # the last fix, 2.9 s; the table at 3 s
