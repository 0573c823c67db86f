"""Shared rig for the planner component tests: the vehicle end of the chain.

- :class:`SerialLine`: the MPC555's RS-232 link at its baud rate (8N1: ten bit times a
  byte, bytes queued behind the ones before them, each direction on its own wire), put
  between Vehicle Control and the fake controller, so that "on the wire" has a time: a
  frame reaches the fake controller when its last byte would have.
- :class:`Cruise`: a stand-in voting behaviour (not under test) publishing an ArcVote
  every ``period`` seconds: the straight arc preferred, at ``speed``.
- :func:`decode_host_bytes`: the controller's received bytes decoded again, from the
  start, with the MPC555 codec's device-side decoder.
- :func:`wire_commands`: the fake controller's decoded commands of one type after a time.
- :func:`bumper_transformation`: ModelServer's ``getTransformation`` as far as the
  planners ask it (where the ground under the front bumper lies), for stand-ins.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np

from afa import EOutOfBounds, SubscribePublishServer
from afa.clock import Clock
from afa.errors import TransportClosed
from afa.transport import ByteStream, DeviceSpec
from components.arcs import ARC_SET_SECTION, ArcSet, ArcVotes, arc_set_of
from components.mpc555.codec import Command, Mpc555DeviceDecoder, SetVelocity
from components.mpc555.fake import FakeMpc555, ReceivedCommand
from idl import ArcVoteIDL, PoseTransformIDL, TimeIDL

__all__ = ["SerialLine", "Cruise", "decode_host_bytes", "wire_commands", "stops_after",
           "bumper_transformation", "MPC555_BAUD", "BUMPER"]

#: The MPC555 link's rate (Table A.13 ``Baudrate``).
MPC555_BAUD = 115200
#: The ground under the Raptor's front bumper, ahead of the rear axle (m).
BUMPER = 2.45


def bumper_transformation(a: str, b: str, now: float) -> PoseTransformIDL:
    """^A T_B for A the rear axle and B the ground under the front bumper (the one place
    of ModelServer's geometry FindPath and Pure Pursuit ask); EOutOfBounds for any other
    pair, as ModelServer answers for a frame it does not know."""
    if (a, b) != ("Raptor:RearAxleCenter", "Raptor: Front-BumperCenter"):
        raise EOutOfBounds(f"no frame {b!r} in this stand-in's geometry")
    h = np.eye(4)
    h[0, 3] = BUMPER
    return PoseTransformIDL(time=TimeIDL.from_seconds(now), HTransform=h,
                            initialUTM=np.zeros(3))

Factory = Callable[[DeviceSpec], Awaitable[ByteStream]]


class _TimedStream(ByteStream):
    """The host end of a memory pipe, with the line's transmission time added to each
    direction (see :class:`SerialLine`)."""

    def __init__(self, inner: ByteStream, clock: Clock, byte_time: float) -> None:
        self._inner = inner
        self._clock = clock
        self._byte_time = byte_time
        self._tx_free = -math.inf  # when the host-to-device wire is next idle
        self._rx_free = -math.inf

    async def read(self, max_bytes: int = 4096) -> bytes:
        data = await self._inner.read(max_bytes)
        start = max(self._clock.monotonic(), self._rx_free)
        self._rx_free = start + len(data) * self._byte_time
        await self._clock.sleep_until(self._rx_free)
        return data

    async def write(self, data: bytes) -> None:
        if self._inner.closed:
            raise TransportClosed("serial line: write on a closed stream")
        start = max(self._clock.monotonic(), self._tx_free)
        self._tx_free = start + len(data) * self._byte_time
        chunk = bytes(data)
        self._clock.call_at(self._tx_free, lambda: self._deliver(chunk))

    def _deliver(self, data: bytes) -> None:
        try:
            self._inner.write_nowait(data)  # type: ignore[attr-defined]
        except TransportClosed:
            pass  # unplugged while the bytes were on the wire

    async def close(self) -> None:
        await self._inner.close()

    @property
    def closed(self) -> bool:
        return self._inner.closed


class SerialLine:
    """An RS-232 line at ``baudrate`` (8N1) in front of a fake device's factory."""

    def __init__(self, clock: Clock, baudrate: int = MPC555_BAUD) -> None:
        self.clock = clock
        self.byte_time = 10.0 / baudrate

    def factory(self, device: Factory) -> Factory:
        async def open_device(spec: DeviceSpec) -> ByteStream:
            return _TimedStream(await device(spec), self.clock, self.byte_time)

        return open_device


class Cruise(SubscribePublishServer):
    """A voting behaviour standing in for the goal seekers: every ``period`` seconds a
    vote for the straight arc (a linear fall-off to 0 at the hardest turns), certainty 1,
    ``speed`` on every arc. ``paused`` stops the votes (the behaviour falls silent)."""

    def __init__(self, name: str = "cruise", *, behaviour: str = "PurePursuit",
                 speed: float = 0.5, period: float = 0.1, event: str = "ArcVote") -> None:
        super().__init__(name)
        self.behaviour = behaviour
        self.speed = speed
        self.period = period
        self.paused = False
        self.sent = 0
        self.votes = self.publishes(event, ArcVoteIDL)
        self.arcs = ArcSet.from_parameters()

    async def setup(self) -> None:
        self.arcs = arc_set_of(self.context.section(ARC_SET_SECTION))

    async def run(self) -> None:
        async for _ in self.clock.periodic(self.period):
            if not self.paused:
                self.publish()

    def publish(self) -> None:
        n = len(self.arcs)
        curvatures = self.arcs.curvatures
        vote = 1.0 - np.abs(curvatures) / float(np.abs(curvatures).max())
        votes = ArcVotes(np.zeros(n, dtype=bool), vote, np.ones(n), np.full(n, self.speed))
        self.votes.publish(votes.to_idl(time=TimeIDL.from_seconds(self.clock.now()),
                                        behaviour=self.behaviour, arcs=self.arcs))
        self.sent += 1


def decode_host_bytes(fake: FakeMpc555) -> list[Command]:
    """Every command in the bytes the controller received, decoded afresh."""
    assert fake.host_bytes is not None, "make the fake with record=True"
    return [packet.message for packet in Mpc555DeviceDecoder().feed(bytes(fake.host_bytes))]


def wire_commands(fake: FakeMpc555, kind: type[Any], after: float = -math.inf
                  ) -> list[ReceivedCommand]:
    """Commands of type ``kind`` the controller received at or after ``after``."""
    return [r for r in fake.received if isinstance(r.command, kind) and r.time >= after]


def stops_after(fake: FakeMpc555, after: float) -> list[ReceivedCommand]:
    """SET_VELOCITY frames commanding zero speed received at or after ``after``."""
    return [r for r in wire_commands(fake, SetVelocity, after)
            if r.command.translation_mm_s == 0]
