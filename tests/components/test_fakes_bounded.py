"""The MPC555 fake keeps bounded state however many commands and connections it sees:
a simulation at 20 commands a second used to keep every one (~0.5 MB per simulated
minute together with the simulation's pose errors)."""

from __future__ import annotations

from afa.clock import VirtualClock
from afa.fake import FakeDevice
from afa.transport import SerialSpec
from components.mpc555.codec import (
    Heartbeat,
    Mpc555Decoder,
    SetVelocity,
    StatusReport,
    encode_command,
)
from components.mpc555.fake import FakeMpc555


async def test_fake_mpc555_retains_a_bounded_number_of_commands_and_connections() -> None:
    clock = VirtualClock()
    fake = FakeMpc555(clock)
    fake.mute_acks = True  # nobody reads the host ends here
    factory = fake.factory()
    sent = 0
    for _ in range(30):
        host = await factory(SerialSpec("/dev/ttyS0"))
        frames = [encode_command(SetVelocity(500, 0) if i % 2 else Heartbeat(), i % 256)
                  for i in range(400)]
        await host.write(b"".join(frames) + b"\xa5\x01\x04\x02\x00garbage")
        sent += len(frames)
        await clock.settle()
        await host.close()
        await clock.settle()
    assert fake.received.total == sent == 12_000
    assert len(fake.received) == fake.received_history < sent
    assert len(fake.commands) == FakeDevice.command_history
    assert fake.received[-1].command == SetVelocity(500, 0)
    # nothing else kept per connection or per command
    assert fake._streams == [] and fake._connections == []  # noqa: SLF001
    # the rx error count still spans every connection (one bad frame each)
    host = await factory(SerialSpec("/dev/ttyS0"))
    await clock.settle()
    fake._send_status()  # noqa: SLF001 - a STATUS now, without waiting for its period
    await clock.settle()
    statuses = [p.message for p in Mpc555Decoder().feed(await host.read(1 << 16))
                if isinstance(p.message, StatusReport)]
    assert statuses and statuses[-1].rx_errors == 30
    await fake.aclose()
