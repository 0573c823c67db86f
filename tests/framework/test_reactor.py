"""The Publish Server and Reactor pattern: decoding, resynchronisation, reconnection."""

from typing import Any

import pytest

from afa import (
    Backoff,
    EDevIO,
    Fault,
    PublishServerReactor,
    Scan,
    SerialSpec,
    State,
    StreamDecoder,
    System,
    VirtualClock,
)
from afa.testing import FakeDevice, serve, until
from idl._base import IDLModel, field


class Value(IDLModel):
    n: int = field(0, unit="1")


def checksum(payload: bytes) -> int:
    x = 0
    for b in payload:
        x ^= b
    return x


def frame(n: int) -> bytes:
    payload = f"VAL,{n}".encode()
    return b"$" + payload + b"*%02X\n" % checksum(payload)


class LineDecoder(StreamDecoder[int]):
    """``$VAL,<n>*HH\\n`` with an XOR checksum, NMEA-style."""

    def scan(self, buffer):
        if buffer[0] != ord("$"):
            start = buffer.find(b"$")
            return Scan.skip(len(buffer) if start < 0 else start, Fault.GARBAGE)
        end = buffer.find(b"\n")
        if end < 0:
            return Scan.need_more() if len(buffer) < 64 else Scan.skip(1, Fault.MALFORMED)
        line = bytes(buffer[1:end])
        body, _, check = line.partition(b"*")
        try:
            if int(check, 16) != checksum(body):
                return Scan.skip(1, Fault.CHECKSUM)
            return Scan.frame(end + 1, int(body.split(b",")[1]))
        except (ValueError, IndexError):
            return Scan.skip(1, Fault.MALFORMED)


def test_decoder_skips_garbage_and_corrupt_frames_and_keeps_valid_ones():
    decoder = LineDecoder()
    corrupt = bytearray(frame(2))
    corrupt[5] ^= 0x01
    stream = b"noise" + frame(1) + bytes(corrupt) + frame(3) + b"$VAL,4*"
    assert decoder.feed(stream) == [1, 3]
    assert decoder.stats.checksum_failures == 1
    assert decoder.stats.frames == 2
    assert decoder.feed(b"%02X\n" % checksum(b"VAL,4")) == [4]
    assert decoder.stats.bytes_skipped == len(b"noise") + len(corrupt)


def test_decoder_bounds_its_buffer():
    decoder = LineDecoder(max_buffer=100)
    decoder.feed(b"$" * 500)
    assert decoder.buffered <= 100


class Counter(PublishServerReactor[Any, int]):
    """Publishes every decoded value as a ``Value`` event."""

    backoff = Backoff(initial=0.5, factor=2.0, maximum=2.0)
    stale_after = 1.0

    def __init__(self, name):
        super().__init__(name)
        self.out = self.publishes("Value", Value)

    def device(self):
        return SerialSpec("/dev/ttyTEST", 9600)

    def decoder(self):
        return LineDecoder()

    def handle(self, message: int) -> None:
        self.out.publish(Value(n=message))


class Talker(FakeDevice):
    """Sends ``$VAL,n`` every 0.1 s, counting from ``first``."""

    def __init__(self, clock, first=0):
        super().__init__(clock)
        self.next = first

    async def produce(self, stream):
        while True:
            await stream.write(frame(self.next))
            self.next += 1
            await self.clock.sleep(0.1)


async def test_a_lost_device_is_reconnected_and_the_rest_keeps_running():
    clock = VirtualClock(start=0.0)
    switch, other = Talker(clock), Talker(clock, first=1000)
    counter, bystander = Counter("Counter"), Counter("Bystander")
    system = System([counter, bystander], clock=clock,
                    devices={"Counter": switch.factory(), "Bystander": other.factory()})
    async with system:
        values = system.channel.subscribe("Raptor", "Value", maxsize=10_000)
        await clock.advance(1.0)
        assert counter.health().healthy
        switch.unplug()
        await clock.advance(0.05)
        assert not counter.health().healthy
        assert "device lost" in counter.health().detail
        await clock.advance(3.0)
        assert not counter.health().healthy
        assert "cannot open device" in counter.health().detail
        switch.plug()
        await until(lambda: counter.health().healthy, clock, timeout=5.0)
        await clock.advance(1.0)
        stats = counter.statistics()
        await switch.aclose()
        await other.aclose()
    assert stats["connects"] == 2 and stats["reconnects"] == 1
    assert counter.state is State.STOPPED and counter.failures == 0
    events = []
    while (event := values.get_nowait()) is not None:
        events.append(event)
    mine = [e for e in events if e.body.n < 1000]
    theirs = [e.time for e in events if e.body.n >= 1000]
    assert any(e.time > 4.0 for e in mine)  # events resumed after the reconnect
    gaps = [b - a for a, b in zip(theirs, theirs[1:], strict=False)]
    assert max(gaps) == pytest.approx(0.1)  # the bystander never paused


async def test_a_silent_device_is_stale_and_reopened():
    clock = VirtualClock(start=0.0)
    opened = []

    async def silent(spec):
        from afa.transport import memory_pipe

        host, device = memory_pipe("silent")
        opened.append(device)
        return host

    counter = Counter("Counter")
    async with System([counter], clock=clock, devices={"Counter": silent}):
        await clock.advance(1.2)
        assert not counter.health().healthy
        assert "no message for 1 s" in counter.health().detail
        await clock.advance(2.0)
    assert len(opened) >= 2


async def test_a_device_sending_only_noise_is_stale_and_reopened():
    """Bytes that never decode (a wrong baud rate looks like this) are no sign of life."""
    clock = VirtualClock(start=0.0)
    opened = []

    class Babbler(FakeDevice):
        async def produce(self, stream):
            while True:
                await stream.write(b"\x00garbage\xff")
                await self.clock.sleep(0.05)

    babbler = Babbler(clock)
    factory = babbler.factory()

    async def counted(spec):
        opened.append(spec)
        return await factory(spec)

    counter = Counter("Counter")
    async with System([counter], clock=clock, devices={"Counter": counted}):
        await clock.advance(1.2)
        assert not counter.health().healthy
        assert "no message for 1 s" in counter.health().detail
        await clock.advance(2.0)
        stats = counter.statistics()
        await babbler.aclose()
    assert len(opened) >= 2
    assert stats["bytes_skipped"] > 0


async def test_corrupt_frames_are_counted_in_component_statistics():
    clock = VirtualClock(start=0.0)
    from afa.transport import memory_pipe

    host, device = memory_pipe("counter")
    bad = bytearray(frame(7))
    bad[2] ^= 0x40
    device.write_nowait(frame(1) + bytes(bad) + b"\x00\xff" + frame(2))
    counter = Counter("Counter")
    async with System([counter], clock=clock, devices={"Counter": serve(host)}) as system:
        values = system.channel.subscribe("Raptor", "Value")
        await clock.settle()
        device.write_nowait(frame(3))
        await clock.settle()
        stats = counter.statistics()
    received = []
    while (event := values.get_nowait()) is not None:
        received.append(event.body.n)
    assert received == [1, 2, 3]  # the corrupt frame and the noise never reached handle()
    assert stats["frames"] == 3 and stats["checksum_failures"] == 1
    assert stats["bytes_skipped"] == len(bad) + 2


async def test_send_while_disconnected_is_edevio():
    clock = VirtualClock(start=0.0)

    async def absent(spec):
        raise EDevIO("no such port")

    counter = Counter("Counter")
    async with System([counter], clock=clock, devices={"Counter": absent}):
        await clock.settle()
        with pytest.raises(EDevIO):
            await counter.send(b"hello")
        assert counter.state is State.RUNNING and not counter.health().healthy


async def test_a_device_that_connects_but_never_answers_is_never_healthy():
    """Connected is not alive: a port that opens (a cable, a wrong baud rate) but yields
    no decoded message keeps the component unhealthy, and the run says it never came up."""
    clock = VirtualClock(start=0.0)
    silent = FakeDevice(clock)  # accepts the connection, sends nothing
    counter = Counter("Counter")
    async with System([counter], clock=clock, devices={"Counter": silent.factory()}):
        await clock.advance(0.5)
        health = counter.health()
        assert not health.healthy and health.detail == "connected, no message from the device yet"
        await clock.advance(5.0)  # stale after 1 s: reconnects, and is still not healthy
        health = counter.health()
        assert not health.healthy and not health.ever_healthy
        await silent.aclose()


async def test_a_device_that_answers_once_has_been_healthy():
    clock = VirtualClock(start=0.0)
    talker = Talker(clock)
    counter = Counter("Counter")
    async with System([counter], clock=clock, devices={"Counter": talker.factory()}):
        await clock.advance(0.5)
        assert counter.health().healthy and counter.health().detail == "receiving"
        assert counter.health().ever_healthy
        await talker.aclose()
