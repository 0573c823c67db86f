"""Components and a process runner for the bridge's multi-process tests.

``python -m tests.bridge.peer ROLE --process NAME --listen EP --connect EP ...`` runs a
System of the components of ROLE with a bridge, prints ``READY {json}`` once it is up,
and runs until SIGTERM (or ``--duration`` of its clock), then prints ``RESULT {json}``.
The pytest process runs the same components in its own loop, so both sides share the
IDL types and interfaces by module name.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import socket
from typing import Any

from afa import (
    EOutOfBounds,
    SubscribePublishServer,
    System,
    VirtualClock,
    WallClock,
)
from afa.bridge import Bridge, BridgeParameters
from afa.bridge.lockstep import SteppedClock
from idl import IDLModel, Interface, VehicleControl, VelocityIDL, field
from idl.vehicle import MinMaxVelocityIDL


class Count(IDLModel):
    value: int = field(0, unit="1", description="tick number")
    t: float = field(0.0, unit="s", description="clock time of the tick")


class Doubled(IDLModel):
    value: int = field(0, unit="1", description="twice a count")


class Counter(Interface):
    call_timeout = 5.0

    async def getCount(self) -> Count: ...
    async def getWaitCount(self) -> Count: ...
    async def add(self, a: int, b: int) -> int: ...
    async def check(self, value: float) -> float: ...
    async def slow(self, seconds: float) -> float: ...


class CounterServer(SubscribePublishServer):
    """Publishes ``event`` (Count) every ``period`` and serves Counter as ``served``."""

    def __init__(self, name: str, *, served: str = "Counter", event: str = "Count",
                 period: float = 0.1) -> None:
        super().__init__(name)
        self.period = period
        self.output = self.publishes(event, Count)
        self.serves(Counter, served)

    async def setup(self) -> None:
        self.latest = self.slot("count")

    async def run(self) -> None:
        # the first tick one period after the start: nothing at the start-up instant, whose
        # order across processes is not defined
        start = self.clock.monotonic()
        async for tick in self.clock.periodic(self.period, first=start + self.period):
            count = Count(value=tick + 1, t=self.clock.monotonic())
            self.latest.set(count)
            self.output.publish(count)

    async def getCount(self) -> Count:
        return self.latest.get()

    async def getWaitCount(self) -> Count:
        return await self.latest.wait_next(2.0)

    async def add(self, a: int, b: int) -> int:
        return a + b

    async def check(self, value: float) -> float:
        if value < 0:
            raise EOutOfBounds(f"value {value} is negative")
        return value

    async def slow(self, seconds: float) -> float:
        await self.clock.sleep(seconds)
        return seconds


class Doubler(SubscribePublishServer):
    """Answers every Count with a Doubled."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.out = self.publishes("Doubled", Doubled)
        self.subscribes("Count", Count, self._on_count, maxsize=256)
        self.seen: list[tuple[float, int, float, str]] = []

    def _on_count(self, event: Any) -> None:
        self.seen.append((round(self.clock.monotonic(), 6), event.body.value,
                          round(event.time, 6), event.origin))
        self.out.publish(Doubled(value=2 * event.body.value))


class Poller(SubscribePublishServer):
    """Polls ``getWaitCount`` of the Counter served as ``served`` every ``period``."""

    def __init__(self, name: str, *, served: str = "Counter", period: float = 0.35) -> None:
        super().__init__(name)
        self.period = period
        self.counter = self.uses(Counter, served)
        self.polled: list[tuple[float, int]] = []

    async def run(self) -> None:
        await self.bound(self.counter)
        async for _ in self.clock.periodic(self.period):
            count = await self.counter.getWaitCount()
            self.polled.append((round(self.clock.monotonic(), 6), count.value))


class Sink(SubscribePublishServer):
    """Records Doubled and Count events (Count too: no echo may reach its source)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.doubled: list[tuple[float, int, str]] = []
        self.counts: list[tuple[int, str]] = []
        self.subscribes("Doubled", Doubled, self._on_doubled, maxsize=256)
        self.subscribes("Count", Count, self._on_count, maxsize=256)

    def _on_doubled(self, event: Any) -> None:
        self.doubled.append((round(self.clock.monotonic(), 6), event.body.value, event.origin))

    def _on_count(self, event: Any) -> None:
        self.counts.append((event.body.value, event.origin))


class FakeVehicle(SubscribePublishServer):
    """Serves VehicleControl as ``RaptorMotion`` and records what it was told."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.serves(VehicleControl, "RaptorMotion")
        self.commands: list[str] = []

    async def setVelocity(self, velocity: VelocityIDL) -> None:
        self.commands.append(f"setVelocity {velocity.translation}")

    async def getTargetVelocity(self) -> VelocityIDL:
        return VelocityIDL()

    async def startVehicle(self) -> None:
        self.commands.append("startVehicle")

    async def stopVehicle(self) -> None:
        self.commands.append("stopVehicle")

    async def setJoystickVelocity(self, velocity: VelocityIDL) -> None:
        self.commands.append("setJoystickVelocity")

    async def setArbiter(self, enabled: bool) -> None:
        self.commands.append(f"setArbiter {enabled}")

    async def getMinMaxVelocity(self) -> MinMaxVelocityIDL:
        return MinMaxVelocityIDL(minTranslation=-1.0, maxTranslation=1.0, minRotation=-1.0,
                                 maxRotation=1.0, maxSteeringAngle=0.5)


ROLES = {
    # the two- and three-process tests (the pytest process is "b")
    "a": lambda: [CounterServer("counter"), FakeVehicle("vehicle"), Sink("sink"),
                  Poller("poller", served="CounterB", period=0.2)],
    "c": lambda: [Sink("sinkC"), Poller("pollerC", served="Counter", period=0.2)],
    # lock-step: the same system in one process ("all") or split in two
    "ls-a": lambda: [CounterServer("counter"), Sink("sink")],
    "ls-b": lambda: [Doubler("doubler"), Poller("poller", period=0.373)],
    "all": lambda: [CounterServer("counter"), Sink("sink"), Doubler("doubler"),
                    Poller("poller", period=0.373)],
}


async def _alone(system: System, args: Any) -> None:
    async with system:
        print("READY " + json.dumps({"process": args.process}), flush=True)
        await system.run(args.duration)
        print("RESULT " + json.dumps(result(system)), flush=True)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def endpoint(port: int) -> str:
    return f"tcp/127.0.0.1:{port}"


def result(system: System) -> dict[str, Any]:
    out: dict[str, Any] = {"t": system.clock.monotonic(), "events": system.channel.counts()}
    for component in system.components.values():
        for attribute in ("seen", "polled", "doubled", "counts", "commands"):
            if hasattr(component, attribute):
                out[f"{component.name}.{attribute}"] = getattr(component, attribute)
    for service in system.services:
        if isinstance(service, Bridge):
            out["bridge"] = service.statistics()
    return out


async def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("role", choices=sorted(ROLES))
    parser.add_argument("--process", required=True)
    parser.add_argument("--listen", action="append", default=[])
    parser.add_argument("--connect", action="append", default=[])
    parser.add_argument("--allow", action="append", default=[])
    parser.add_argument("--clock", choices=["wall", "virtual", "stepped"], default="wall")
    parser.add_argument("--members", default="", help="lock-step members, comma separated")
    parser.add_argument("--duration", type=float)
    parser.add_argument("--join-timeout", type=float, default=20.0)
    args = parser.parse_args(argv)
    clock = {"wall": WallClock, "virtual": lambda: VirtualClock(start=0.0),
             "stepped": lambda: SteppedClock(start=0.0)}[args.clock]()
    system = System(ROLES[args.role](), clock=clock, process=args.process)
    members = [m for m in args.members.split(",") if m] or None
    if args.clock != "stepped" and not args.listen and not args.connect:
        members = None  # a whole system in one process: no bridge
        await _alone(system, args)
        return 0
    Bridge(BridgeParameters(Listen=args.listen, Connect=args.connect,
                            AllowCommandFrom=args.allow,
                            JoinTimeout=args.join_timeout),
           members=members).attach(system)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    async with system:
        print("READY " + json.dumps({"process": args.process}), flush=True)
        running = asyncio.ensure_future(system.run(args.duration))  # or a time master's end
        signalled = asyncio.ensure_future(stop.wait())
        await asyncio.wait([running, signalled], return_when=asyncio.FIRST_COMPLETED)
        signalled.cancel()
        if running.done():
            running.result()
        else:
            running.cancel()
        print("RESULT " + json.dumps(result(system)), flush=True)
    return 0
