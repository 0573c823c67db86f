"""Fake devices keep bounded state however long they run."""

from __future__ import annotations

import pytest

from afa.clock import VirtualClock
from afa.codec import Fault, Scan, StreamDecoder
from afa.fake import FakeDevice, RecentLog
from afa.transport import SerialSpec


class ByteCommands(StreamDecoder[int]):
    """Every byte is one command."""

    def scan(self, buffer: bytearray) -> Scan[int]:
        return Scan.frame(1, buffer[0]) if buffer[0] else Scan.skip(1, Fault.GARBAGE)


class EchoDevice(FakeDevice[int]):
    def command_decoder(self) -> StreamDecoder[int]:
        return ByteCommands()


def test_recent_log_keeps_the_latest_items_and_counts_all() -> None:
    log: RecentLog[int] = RecentLog(3)
    for item in range(10):
        log.append(item)
    assert list(log) == [7, 8, 9] and len(log) == 3 and log.total == 10
    assert log[0] == 7 and log[-1] == 9 and log[:2] == [7, 8] and log[-2:] == [8, 9]
    log.clear()
    assert len(log) == 0 and log.total == 10
    with pytest.raises(ValueError):
        RecentLog(0)


async def test_a_fake_keeps_a_bounded_command_log_and_forgets_ended_connections() -> None:
    clock = VirtualClock()
    fake = EchoDevice(clock)
    factory = fake.factory()
    commands = 0
    for _ in range(40):  # a long run: many reconnections, many commands
        host = await factory(SerialSpec("/dev/ttyFAKE"))
        await host.write(bytes(range(1, 256)) * 4)
        commands += 255 * 4
        await clock.settle()
        await host.close()
        await clock.settle()
    assert fake.commands.total == commands
    assert len(fake.commands) == FakeDevice.command_history < commands
    assert list(fake.commands)[-3:] == [253, 254, 255]
    assert fake._streams == []  # noqa: SLF001 - what a fake retains per connection
    await fake.aclose()
