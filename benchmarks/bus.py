"""Event dispatch cost: afa's channel against the asyncio floor and two peers.

Per-event cost of publish -> deliver to 1 and to 10 async consumers, measured the same
way for every contender: a producer task emits events in bursts of ``BURST`` and yields
once per burst; each consumer is a task receiving events one by one. Figures are
wall-clock nanoseconds per event (per delivered copy is ``/ subscribers``).

- ``asyncio.Queue``: the floor for a decoupled hand-off (``put_nowait`` / ``await get``)
- ``loop.call_soon``: the floor for scheduling one callback per event and consumer
- ``afa``: ``Publisher.publish`` -> ``async for event in subscription``
- ``pyee``: ``AsyncIOEventEmitter.emit`` with coroutine handlers (pyee schedules each)
- ``blinker``: ``Signal.send`` with plain receivers (synchronous, not decoupled: it is
  a lower bound for blinker, which has no queueing of its own)
- ``afa component ports``: ``Output.publish`` -> a component's typed ``Input`` handler
  (type check, origin, the component's task), the path components really use

Trials are interleaved: every repeat runs every contender once, in a rotated order, so
drift of a shared, noisy machine lands on all of them alike; the figure is the median.
A second table times one poll: a direct ``await`` of the server's method, the proxy on a
bare invoker, and the proxy through the system's middleware (timeout, statistics).

Usage: ``python benchmarks/bus.py [--events N] [--repeat R] [--json]``
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import statistics
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from afa import (  # noqa: E402
    EventChannel,
    LocalInvoker,
    SubscribePublishServer,
    System,
    VirtualClock,
    proxy_for,
)
from idl._base import IDLModel, Interface, field  # noqa: E402

BURST = 100


class Sample(IDLModel):
    value: int = field(0, unit="1")


BODY = Sample(value=1)


async def bench_queue(n: int, subscribers: int) -> float:
    queues = [asyncio.Queue() for _ in range(subscribers)]

    async def consume(queue: asyncio.Queue) -> None:
        for _ in range(n):
            await queue.get()

    consumers = [asyncio.ensure_future(consume(q)) for q in queues]
    start = time.perf_counter()
    for i in range(0, n, BURST):
        for _ in range(min(BURST, n - i)):
            for queue in queues:
                queue.put_nowait(BODY)
        await asyncio.sleep(0)
    await asyncio.gather(*consumers)
    return time.perf_counter() - start


async def bench_call_soon(n: int, subscribers: int) -> float:
    loop = asyncio.get_running_loop()
    done = loop.create_future()
    remaining = n * subscribers

    def deliver(_body: object) -> None:
        nonlocal remaining
        remaining -= 1
        if remaining == 0:
            done.set_result(None)

    start = time.perf_counter()
    for i in range(0, n, BURST):
        for _ in range(min(BURST, n - i)):
            for _ in range(subscribers):
                loop.call_soon(deliver, BODY)
        await asyncio.sleep(0)
    await done
    return time.perf_counter() - start


async def bench_afa(n: int, subscribers: int) -> float:
    channel = EventChannel(VirtualClock())
    subs = [channel.subscribe("Raptor", "Sample", maxsize=4 * BURST) for _ in range(subscribers)]
    publisher = channel.offer("Raptor", "Sample")

    async def consume(subscription) -> None:
        for _ in range(n):
            await subscription.get()

    consumers = [asyncio.ensure_future(consume(s)) for s in subs]
    start = time.perf_counter()
    for i in range(0, n, BURST):
        for _ in range(min(BURST, n - i)):
            publisher.publish(BODY)
        await asyncio.sleep(0)
    await asyncio.gather(*consumers)
    elapsed = time.perf_counter() - start
    assert all(s.statistics().dropped == 0 for s in subs)
    return elapsed


async def bench_ports(n: int, subscribers: int) -> float:
    """Output.publish -> typed Input handlers of components, in virtual time."""

    class Source(SubscribePublishServer):
        def __init__(self, name: str) -> None:
            super().__init__(name)
            self.out = self.publishes("Sample", Sample)

    class Sink(SubscribePublishServer):
        def __init__(self, name: str) -> None:
            super().__init__(name)
            self.count = 0
            self.subscribes("Sample", Sample, self.on_sample, maxsize=4 * BURST)

        def on_sample(self, event: object) -> None:
            self.count += 1

    source = Source("Source")
    sinks = [Sink(f"Sink{k}") for k in range(subscribers)]
    async with System([source, *sinks], clock=VirtualClock()):
        start = time.perf_counter()
        for i in range(0, n, BURST):
            for _ in range(min(BURST, n - i)):
                source.out.publish(BODY)
            await asyncio.sleep(0)
        while any(sink.count < n for sink in sinks):
            await asyncio.sleep(0)
        elapsed = time.perf_counter() - start
    return elapsed


async def bench_pyee(n: int, subscribers: int) -> float:
    from pyee.asyncio import AsyncIOEventEmitter

    emitter = AsyncIOEventEmitter()
    loop = asyncio.get_running_loop()
    done = loop.create_future()
    remaining = n * subscribers

    def make_handler() -> Callable[[object], Awaitable[None]]:
        async def handler(_body: object) -> None:
            nonlocal remaining
            remaining -= 1
            if remaining == 0:
                done.set_result(None)

        return handler

    for _ in range(subscribers):  # pyee keys listeners by function: one closure each
        emitter.add_listener("sample", make_handler())
    start = time.perf_counter()
    for i in range(0, n, BURST):
        for _ in range(min(BURST, n - i)):
            emitter.emit("sample", BODY)
        await asyncio.sleep(0)
    await done
    return time.perf_counter() - start


async def bench_blinker(n: int, subscribers: int) -> float:
    from blinker import Signal

    signal = Signal()
    received = 0

    def receiver(_sender: object, **_kw: object) -> None:
        nonlocal received
        received += 1

    receivers = [lambda s, **kw: receiver(s, **kw) for _ in range(subscribers)]
    for r in receivers:
        signal.connect(r, weak=False)
    start = time.perf_counter()
    for i in range(0, n, BURST):
        for _ in range(min(BURST, n - i)):
            signal.send(None, body=BODY)
        await asyncio.sleep(0)
    elapsed = time.perf_counter() - start
    assert received == n * subscribers
    return elapsed


CONTENDERS: dict[str, Callable[[int, int], Awaitable[float]]] = {
    "asyncio.Queue (floor)": bench_queue,
    "loop.call_soon (floor)": bench_call_soon,
    "afa EventChannel": bench_afa,
    "pyee AsyncIOEventEmitter": bench_pyee,
    "blinker Signal (sync)": bench_blinker,
    "afa component ports": bench_ports,
}


def measure(events: int, repeat: int) -> dict[str, dict[str, float]]:
    samples: dict[str, dict[int, list[float]]] = {
        name: {1: [], 10: []} for name in CONTENDERS}
    names = list(CONTENDERS)
    for trial in range(repeat):
        order = names[trial % len(names):] + names[:trial % len(names)]  # rotate each trial
        for name in order:
            for subscribers in (1, 10):
                gc.collect()
                elapsed = asyncio.run(CONTENDERS[name](events, subscribers))
                samples[name][subscribers].append(elapsed / events * 1e9)
    return {name: {f"{k}_sub_ns_per_event": round(statistics.median(v), 1)
                   for k, v in by_subs.items()} for name, by_subs in samples.items()}


class Echo(Interface):
    async def echo(self, value: Sample) -> Sample: ...


class EchoServer(SubscribePublishServer):
    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.serves(Echo, "Echo")

    async def echo(self, value: Sample) -> Sample:
        return value


async def bench_polls(calls: int) -> dict[str, float]:
    """Microseconds per call: direct, bare proxy, proxy through the system middleware."""
    server = EchoServer("Echo")
    async with System([server], clock=VirtualClock()) as system:
        bare = proxy_for(Echo, LocalInvoker(system.registry, "Raptor/Echo", Echo))
        full = system.proxy(Echo, "Echo")
        contenders = {"direct await": server.echo, "proxy, bare invoker": bare.echo,
                      "proxy + middleware": full.echo}
        out: dict[str, list[float]] = {name: [] for name in contenders}
        for _ in range(5):
            for name, call in contenders.items():
                start = time.perf_counter()
                for _ in range(calls):
                    await call(BODY)
                out[name].append((time.perf_counter() - start) / calls * 1e6)
    return {name: round(statistics.median(v), 2) for name, v in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    for peer in ("pyee", "blinker"):  # the contenders beside afa's channel
        try:
            __import__(peer)
        except ModuleNotFoundError:
            sys.exit(f"benchmarks/bus.py: {peer} is not installed; the peers come with "
                     "pip install -e '.[dev]'")
    results = measure(args.events, args.repeat)
    polls = asyncio.run(bench_polls(max(1000, args.events // 20)))
    floor = results["asyncio.Queue (floor)"]
    afa = results["afa EventChannel"]
    ratios = {k: round(afa[k] / floor[k], 2) for k in floor}
    if args.json:
        print(json.dumps({"events": args.events, "repeat": args.repeat, "results": results,
                          "afa_over_queue": ratios, "poll_us": polls}, indent=2))
        return
    print(f"per-event cost, median of {args.repeat} runs of {args.events} events "
          f"(bursts of {BURST}); ns per published event")
    print(f"{'contender':28s} {'1 subscriber':>14s} {'10 subscribers':>16s}")
    for name, row in results.items():
        print(f"{name:28s} {row['1_sub_ns_per_event']:14.0f} {row['10_sub_ns_per_event']:16.0f}")
    print(f"afa / asyncio.Queue: {ratios['1_sub_ns_per_event']}x (1 sub), "
          f"{ratios['10_sub_ns_per_event']}x (10 subs)")
    print("\none poll (us per call, median of 5 interleaved runs)")
    for name, value in polls.items():
        print(f"  {name:24s} {value:8.2f}")


if __name__ == "__main__":
    main()
