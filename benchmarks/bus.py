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

from afa import EventChannel, VirtualClock  # noqa: E402
from idl._base import IDLModel, field  # noqa: E402

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
}


def measure(events: int, repeat: int) -> dict[str, dict[str, float]]:
    results: dict[str, dict[str, float]] = {}
    for name, bench in CONTENDERS.items():
        results[name] = {}
        for subscribers in (1, 10):
            samples = []
            for _ in range(repeat):
                gc.collect()
                elapsed = asyncio.run(bench(events, subscribers))
                samples.append(elapsed / events * 1e9)
            results[name][f"{subscribers}_sub_ns_per_event"] = round(statistics.median(samples), 1)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = measure(args.events, args.repeat)
    floor = results["asyncio.Queue (floor)"]
    afa = results["afa EventChannel"]
    ratios = {k: round(afa[k] / floor[k], 2) for k in floor}
    if args.json:
        print(json.dumps({"events": args.events, "repeat": args.repeat, "results": results,
                          "afa_over_queue": ratios}, indent=2))
        return
    print(f"per-event cost, median of {args.repeat} runs of {args.events} events "
          f"(bursts of {BURST}); ns per published event")
    print(f"{'contender':28s} {'1 subscriber':>14s} {'10 subscribers':>16s}")
    for name, row in results.items():
        print(f"{name:28s} {row['1_sub_ns_per_event']:14.0f} {row['10_sub_ns_per_event']:16.0f}")
    print(f"afa / asyncio.Queue: {ratios['1_sub_ns_per_event']}x (1 sub), "
          f"{ratios['10_sub_ns_per_event']}x (10 subs)")


if __name__ == "__main__":
    main()
