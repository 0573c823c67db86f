"""The Zenoh bridge on loopback, against in-process delivery (decision 0012).

Two processes on one host, loopback only, multicast scouting off. This script is process
"bench"; it starts process "peer" (``--role peer``) and measures:

- **event latency**, one way: a ``Ping`` event stamped with ``time.monotonic_ns()`` at
  publication (the monotonic clock is system-wide on Linux, so the peer's receive stamp
  is comparable), against the same measure in one process (publish -> subscriber task);
- **throughput**: small events published in bursts as fast as the exporter takes them,
  counted by the peer (events the network or the peer's inbox dropped are reported);
- **poll round trip**: ``add(a, b)`` on the peer through the bridge against the same
  poll of a server in this process (both through the system's poll layer);
- **cost to the exporting process** per event: CPU time of this process per event
  published with the peer subscribed (observer, wire encoding, Zenoh put) against no
  bridge at all;
- **a slow subscriber**: a 100 Hz control loop's lateness here while 2000 events/s go
  to a peer whose handler sleeps 5 ms per event, against no peer;
- **liveliness**: from ``kill -9`` of a peer to its name unbound here;
- **loop-time accounting** (``afa.meter``): in-process dispatch per event, metered or not.

Usage: ``python benchmarks/bridge.py [--samples N] [--json]``. Figures are printed, never
asserted. One run (the machine is shared: medians of one run each).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from afa import SubscribePublishServer, System, WallClock  # noqa: E402
from afa.bridge import Bridge, BridgeParameters  # noqa: E402
from idl import IDLModel, Interface, field  # noqa: E402

#: AFA_BENCH_EXPRESS=1 measures Bridge/Express (each event sent on its own)
EXPRESS = os.environ.get("AFA_BENCH_EXPRESS", "0") == "1"


class Ping(IDLModel):
    sent: int = field(0, unit="ns", description="monotonic_ns at publication")
    seq: int = field(0, unit="1", description="sequence")


class Pong(IDLModel):
    sent: int = field(0, unit="ns", description="the ping's stamp")
    received: int = field(0, unit="ns", description="monotonic_ns at the peer")


class Flood(IDLModel):
    value: int = field(0, unit="1", description="anything")


class Adder(Interface):
    async def add(self, a: int, b: int) -> int: ...
    async def received(self) -> int: ...


class PeerSide(SubscribePublishServer):
    """Answers pings, counts floods (slowly if asked), serves Adder."""

    def __init__(self, name: str, *, served: str = "Adder", slow: float = 0.0,
                 listen: bool = True) -> None:
        super().__init__(name)
        self.slow = slow
        self.pongs = self.publishes("Pong", Pong)
        if listen:
            self.subscribes("Ping", Ping, self._on_ping, maxsize=4096)
            self.subscribes("Flood", Flood, self._on_flood, maxsize=64)
        self.serves(Adder, served)
        self.floods = 0

    def _on_ping(self, event: Any) -> None:
        self.pongs.publish(Pong(sent=event.body.sent, received=time.monotonic_ns()))

    async def _on_flood(self, event: Any) -> None:
        self.floods += 1
        if self.slow:
            await self.clock.sleep(self.slow)

    async def add(self, a: int, b: int) -> int:
        return a + b

    async def received(self) -> int:
        """Flood events that reached this process's channel (through its bridge)."""
        return self.context.channel.counts().get("Flood", 0)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


async def peer(args: argparse.Namespace) -> None:
    system = System([PeerSide("peer", served=args.served, slow=args.slow)], clock=WallClock(),
                    process=args.process)
    Bridge(BridgeParameters(Listen=[], Connect=[args.connect], EventBuffer=1 << 16,
                            ExportBuffer=1 << 16, Express=EXPRESS)).attach(system)
    stop = asyncio.Event()
    asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)
    async with system:
        print("READY", flush=True)
        await stop.wait()


def start_peer(endpoint: str, *extra: str) -> subprocess.Popen[str]:
    process = subprocess.Popen([sys.executable, __file__, "--role", "peer", "--connect",
                                endpoint, *extra], stdout=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert process.stdout is not None
    if process.stdout.readline().strip() != "READY":
        raise RuntimeError("the peer did not start")
    return process


def stop_peer(process: subprocess.Popen[str]) -> None:
    process.terminate()
    process.wait(20)
    if process.stdout is not None:
        process.stdout.close()


def percentiles(values: list[float]) -> dict[str, float]:
    ordered = sorted(values)
    return {"p50": statistics.median(ordered),
            "p99": ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))],
            "n": len(ordered)}


async def wait_for(condition: Any, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError("benchmark setup did not converge")
        await asyncio.sleep(0.01)


# -- measurements ----------------------------------------------------------------------------
async def in_process_latency(samples: int) -> dict[str, float]:
    system = System([], clock=WallClock())
    async with system:
        subscription = system.channel.subscribe("Raptor", "Ping", maxsize=samples + 1)
        delays: list[float] = []

        async def consume() -> None:
            for _ in range(samples):
                event = await subscription.get()
                delays.append((time.monotonic_ns() - event.body.sent) / 1e6)

        consumer = asyncio.ensure_future(consume())
        for seq in range(samples):
            system.channel.publish("Raptor", "Ping", Ping(sent=time.monotonic_ns(), seq=seq))
            await asyncio.sleep(0.0005)
        await consumer
    return percentiles(delays)


async def bridged(samples: int, flood: int) -> dict[str, Any]:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    system = System([PeerSide("local", served="LocalAdder", listen=False)], clock=WallClock(),
                    process="bench")
    bridge = Bridge(BridgeParameters(Listen=[endpoint], ExportBuffer=1 << 16,
                                     Express=EXPRESS))
    bridge.attach(system)
    results: dict[str, Any] = {}
    async with system:
        peer_process = start_peer(endpoint)
        try:
            await wait_for(lambda: system.registry.try_resolve("Raptor/Adder") is not None)
            await asyncio.sleep(0.5)  # the subscriptions meet
            pongs = system.channel.subscribe("Raptor", "Pong", maxsize=samples + 1)
            one_way: list[float] = []
            round_trip: list[float] = []
            for seq in range(samples):
                system.channel.publish("Raptor", "Ping", Ping(sent=time.monotonic_ns(),
                                                              seq=seq))
                event = await asyncio.wait_for(pongs.get(), 5)
                now = time.monotonic_ns()
                one_way.append((event.body.received - event.body.sent) / 1e6)
                round_trip.append((now - event.body.sent) / 1e6)
            results["event_one_way_ms"] = percentiles(one_way)
            results["event_round_trip_ms"] = percentiles(round_trip)

            remote = system.proxy(Adder, "Adder")
            local = system.proxy(Adder, "LocalAdder")
            for name, proxy in (("poll_remote_ms", remote), ("poll_local_ms", local)):
                times = []
                for k in range(samples):
                    start = time.perf_counter()
                    await proxy.add(k, 1)
                    times.append((time.perf_counter() - start) * 1e3)
                results[name] = percentiles(times)

            before = await remote.received()
            cpu, wall = time.process_time(), time.perf_counter()
            publisher = system.channel.offer("Raptor", "Flood")
            body = Flood(value=1)
            for k in range(flood):
                publisher.publish(body)
                if k % 500 == 499:
                    await asyncio.sleep(0)
            await wait_for(lambda: bridge._observer.subscription.statistics().queued == 0)
            cpu_per_event = (time.process_time() - cpu) / flood
            got, last = 0, -1
            while got != last:  # until the peer's count stops growing
                last = got
                await asyncio.sleep(0.3)
                got = await remote.received() - before
            elapsed = time.perf_counter() - wall - 0.3
            results["throughput"] = {
                "published": flood, "received_by_peer": got,
                "events_per_s": got / elapsed, "seconds": elapsed,
                "export_dropped": bridge.statistics()["export_dropped"]}
            results["export_cpu_us_per_event"] = cpu_per_event * 1e6

            # liveliness: kill -9 a second peer, time until its name is unbound here
            victim = start_peer(endpoint, "--served", "Victim", "--process", "victim")
            await wait_for(lambda: system.registry.try_resolve("Raptor/Victim") is not None)
            start = time.perf_counter()
            victim.kill()
            await wait_for(lambda: system.registry.try_resolve("Raptor/Victim") is None)
            results["killed_peer_unbound_ms"] = (time.perf_counter() - start) * 1e3
            victim.wait()
            if victim.stdout is not None:
                victim.stdout.close()
        finally:
            stop_peer(peer_process)
    return results


async def export_cost_without_bridge(flood: int) -> float:
    system = System([], clock=WallClock())
    async with system:
        sink = system.observe(lambda event: None, name="like-a-recorder-off", maxsize=64)
        del sink
        publisher = system.channel.offer("Raptor", "Flood")
        body = Flood(value=1)
        cpu = time.process_time()
        for k in range(flood):
            publisher.publish(body)
            if k % 500 == 499:
                await asyncio.sleep(0)
        return (time.process_time() - cpu) / flood * 1e6


async def control_loop_lateness(slow_peer: bool, seconds: float = 3.0) -> dict[str, float]:
    """A 100 Hz loop's lateness while 2000 events/s are published (and exported to a
    peer that handles each in 5 ms, when ``slow_peer``)."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    clock = WallClock()
    system = System([], clock=clock, process="bench")
    if slow_peer:
        Bridge(BridgeParameters(Listen=[endpoint])).attach(system)
    lateness: list[float] = []
    async with system:
        peer_process = start_peer(endpoint, "--slow", "0.005") if slow_peer else None
        try:
            if slow_peer:
                await wait_for(lambda: system.registry.try_resolve("Raptor/Adder") is not None)
                await asyncio.sleep(0.5)

            async def control() -> None:
                start = clock.monotonic()
                async for tick in clock.periodic(0.01, first=start):
                    lateness.append((clock.monotonic() - (start + tick * 0.01)) * 1e3)

            async def publish() -> None:
                publisher = system.channel.offer("Raptor", "Flood")
                async for _ in clock.periodic(0.005):
                    for _ in range(10):
                        publisher.publish(Flood(value=1))

            tasks = [asyncio.ensure_future(control()), asyncio.ensure_future(publish())]
            await asyncio.sleep(seconds)
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
        finally:
            if peer_process is not None:
                stop_peer(peer_process)
    return percentiles(lateness)


async def meter_overhead(events: int) -> dict[str, float]:
    results = {}
    for metered in (False, True, False, True):
        system = System([PeerSide("p")], clock=WallClock(), meter=metered)
        async with system:
            publisher = system.channel.offer("Raptor", "Ping")
            component = system.components["p"]
            start = time.perf_counter()
            for k in range(events):
                publisher.publish(Ping(sent=0, seq=k))
                if k % 100 == 99:
                    await asyncio.sleep(0)
            await wait_for(lambda c=component: c.traffic()["in"] >= events * 0.9)
            per = (time.perf_counter() - start) / events * 1e6
        key = "metered_us" if metered else "plain_us"
        results[key] = min(results.get(key, per), per)
    return results


async def main(args: argparse.Namespace) -> None:
    report: dict[str, Any] = {}
    report["event_in_process_ms"] = await in_process_latency(args.samples)
    report.update(await bridged(args.samples, args.flood))
    report["export_cpu_us_per_event_no_bridge"] = await export_cost_without_bridge(args.flood)
    report["control_loop_lateness_ms"] = {"no peer": await control_loop_lateness(False),
                                          "slow peer": await control_loop_lateness(True)}
    report["dispatch_per_event"] = await meter_overhead(20_000)
    if args.json:
        print(json.dumps(report, indent=2))
        return
    p = report
    print(f"event latency, in process:       p50 {p['event_in_process_ms']['p50']:.3f} ms  "
          f"p99 {p['event_in_process_ms']['p99']:.3f} ms")
    print(f"event latency, bridge one way:   p50 {p['event_one_way_ms']['p50']:.3f} ms  "
          f"p99 {p['event_one_way_ms']['p99']:.3f} ms  (round trip p50 "
          f"{p['event_round_trip_ms']['p50']:.3f} ms)")
    print(f"poll round trip, in process:     p50 {p['poll_local_ms']['p50']:.3f} ms  "
          f"p99 {p['poll_local_ms']['p99']:.3f} ms")
    print(f"poll round trip, bridge:         p50 {p['poll_remote_ms']['p50']:.3f} ms  "
          f"p99 {p['poll_remote_ms']['p99']:.3f} ms")
    t = p["throughput"]
    print(f"throughput, bridge:              {t['events_per_s']:,.0f} events/s into the "
          f"peer's channel ({t['received_by_peer']}/{t['published']}; dropped on the way "
          f"{t['published'] - t['received_by_peer']}, by the exporter {t['export_dropped']})")
    print(f"exporting process CPU per event: {p['export_cpu_us_per_event']:.1f} us with the "
          f"bridge, {p['export_cpu_us_per_event_no_bridge']:.1f} us without")
    c = p["control_loop_lateness_ms"]
    print(f"100 Hz loop lateness p99:        {c['no peer']['p99']:.3f} ms alone, "
          f"{c['slow peer']['p99']:.3f} ms exporting 2000 ev/s to a slow peer")
    print(f"killed peer's name unbound in:   {p['killed_peer_unbound_ms']:.1f} ms")
    d = p["dispatch_per_event"]
    print(f"in-process dispatch per event:   {d['plain_us']:.2f} us, metered "
          f"{d['metered_us']:.2f} us (afa.meter)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--role", choices=["bench", "peer"], default="bench")
    parser.add_argument("--connect", default="")
    parser.add_argument("--served", default="Adder")
    parser.add_argument("--process", default="peer")
    parser.add_argument("--slow", type=float, default=0.0)
    parser.add_argument("--samples", type=int, default=2000)
    parser.add_argument("--flood", type=int, default=50_000)
    parser.add_argument("--json", action="store_true")
    arguments = parser.parse_args()
    asyncio.run(peer(arguments) if arguments.role == "peer" else main(arguments))
