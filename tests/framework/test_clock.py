"""The clocks: virtual time jumps when idle, ordering is deterministic, timeouts fire."""

import asyncio

import pytest

from afa import ETimeOut, VirtualClock, WallClock


async def test_virtual_time_jumps_to_the_next_timer_without_waiting():
    clock = VirtualClock(start=1000.0)
    loop = asyncio.get_running_loop()
    wall = loop.time()
    await clock.sleep(3600.0)
    assert clock.now() == 1000.0 + 3600.0
    assert loop.time() - wall < 5.0  # an hour of virtual time, not of wall time


async def test_timers_fire_in_deadline_then_creation_order():
    clock = VirtualClock(start=0.0)
    fired = []

    async def sleeper(tag, delay):
        await clock.sleep(delay)
        fired.append((tag, clock.now()))

    await asyncio.gather(sleeper("b", 2.0), sleeper("a", 1.0), sleeper("c", 2.0), sleeper("d", 1.0))
    assert fired == [("a", 1.0), ("d", 1.0), ("b", 2.0), ("c", 2.0)]


async def test_a_nan_deadline_is_refused_and_the_timers_keep_their_order():
    clock = VirtualClock(start=0.0)
    fired = []
    clock.call_at(2.0, lambda: fired.append(2.0))
    with pytest.raises(ValueError, match="NaN"):
        clock.call_at(float("nan"), lambda: fired.append("nan"))
    with pytest.raises(ValueError, match="NaN"):
        await clock.sleep_until(float("nan"))
    clock.call_at(1.0, lambda: fired.append(1.0))
    await clock.advance(3.0)
    assert fired == [1.0, 2.0] and clock.monotonic() == 3.0


async def test_time_stands_still_while_work_is_ready():
    clock = VirtualClock(start=0.0)
    seen = []

    async def busy():
        for _ in range(100):
            seen.append(clock.now())
            await asyncio.sleep(0)

    async def sleeper():
        await clock.sleep(0.001)
        seen.append("woke")

    await asyncio.gather(busy(), sleeper())
    assert seen.index("woke") == 100  # the timer waited until the busy task was done
    assert all(t == 0.0 for t in seen[:100])


async def test_periodic_is_drift_free_and_skips_missed_ticks():
    clock = VirtualClock(start=0.0)
    ticks = []
    async for tick in clock.periodic(0.1):
        ticks.append((tick, round(clock.now(), 9)))
        if tick == 2:
            await clock.sleep(0.35)  # fall behind by three periods
        if len(ticks) == 5:
            break
    assert ticks == [(0, 0.0), (1, 0.1), (2, 0.2), (6, 0.6), (7, 0.7)]


async def test_periodic_rejects_a_non_positive_period():
    with pytest.raises(ValueError):
        async for _ in VirtualClock().periodic(0):
            pass


async def test_timeout_raises_etimeout_which_is_a_timeouterror():
    clock = VirtualClock(start=0.0)
    with pytest.raises(TimeoutError) as info:
        async with clock.timeout(2.5, "the test"):
            await clock.sleep(100)
    assert isinstance(info.value, ETimeOut)
    assert "the test" in str(info.value)
    assert clock.now() == 2.5


async def test_timeout_does_not_fire_when_the_body_finishes_in_time():
    clock = VirtualClock(start=0.0)
    async with clock.timeout(5.0):
        await clock.sleep(1.0)
    await clock.sleep(10.0)  # the cancelled deadline must not cancel us later
    assert clock.now() == 11.0
    assert clock.pending == 0


@pytest.mark.parametrize("guard", ["timeout", "watchdog"])
async def test_outer_cancellation_is_not_turned_into_a_timeout(guard):
    clock = VirtualClock(start=0.0)

    async def body():
        async with getattr(clock, guard)(10.0):
            await clock.sleep(100)

    task = asyncio.get_running_loop().create_task(body())
    await clock.advance(1.0)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task


async def test_watchdog_fires_a_fixed_time_after_the_last_feed():
    clock = VirtualClock(start=0.0)
    fed = []
    with pytest.raises(ETimeOut) as info:
        async with clock.watchdog(1.0, "the feed") as dog:
            for delay in (0.5, 0.9, 0.3):  # each gap shorter than the watchdog's second
                await clock.sleep(delay)
                dog.feed()
                fed.append(clock.now())
            await clock.sleep(100)
    assert fed == pytest.approx([0.5, 1.4, 1.7])
    assert clock.now() == pytest.approx(2.7)  # the last feed plus one second
    assert "the feed" in str(info.value)


async def test_watchdog_leaves_no_timer_and_needs_a_positive_time():
    clock = VirtualClock(start=0.0)
    async with clock.watchdog(5.0) as dog:
        await clock.sleep(1.0)
        dog.feed()
    assert clock.pending == 0
    with pytest.raises(ValueError):
        async with clock.watchdog(0.0):
            pass


async def test_manual_advance_without_auto_advance():
    clock = VirtualClock(start=0.0, auto_advance=False)
    woke = []

    async def sleeper():
        await clock.sleep(5.0)
        woke.append(clock.now())

    task = asyncio.get_running_loop().create_task(sleeper())
    await clock.advance(4.0)
    assert woke == [] and clock.now() == 4.0
    await clock.advance(1.0)
    assert woke == [5.0]
    await task


async def test_wall_clock_sleeps_in_real_time_order():
    clock = WallClock()
    before = clock.now()
    await clock.sleep(0.01)
    assert clock.now() >= before
    with pytest.raises(ETimeOut):
        async with clock.timeout(0.01):
            await asyncio.Event().wait()


async def test_two_virtual_clocks_can_share_one_loop():
    first, second = VirtualClock(start=0.0), VirtualClock(start=100.0)
    await asyncio.gather(first.sleep(5.0), second.sleep(7.0))
    assert (first.now(), second.now()) == (5.0, 107.0)


async def test_settle_runs_ready_work_without_moving_time():
    clock = VirtualClock(start=0.0)
    done = []

    async def chain(n):
        for _ in range(n):
            await asyncio.sleep(0)
        done.append(n)

    asyncio.get_running_loop().create_task(chain(50))
    asyncio.get_running_loop().create_task(clock.sleep(10.0))
    await clock.settle()
    assert done == [50]
    assert clock.now() == 0.0


# -- stamps and intervals, pacing, real I/O, the scaled clock (decision 0006) -------------


async def test_a_wall_clock_step_fires_no_watchdog_and_no_timer():
    clock = VirtualClock(start=1000.0)
    fired = []
    clock.call_later(5.0, lambda: fired.append(clock.monotonic()))
    stamps = []

    async def fed_watchdog():
        async with clock.watchdog(0.5, "feed") as dog:
            for _ in range(20):
                await clock.sleep(0.1)
                stamps.append(clock.now())
                if len(stamps) == 5:
                    clock.step_wall(3600.0)  # NTP or GPS corrects the wall clock
                if len(stamps) == 10:
                    clock.step_wall(-7200.0)
                dog.feed()

    await fed_watchdog()  # never fired, though the stamps jumped an hour each way
    assert stamps[5] - stamps[4] == pytest.approx(3600.1)
    assert stamps[10] - stamps[9] == pytest.approx(-7199.9)
    await clock.advance(5.0)
    assert fired == [pytest.approx(5.0)]  # the timer kept its interval


async def test_the_wall_clock_takes_stamps_from_its_source_and_intervals_elsewhere():
    stamp = [1e9]
    clock = WallClock(time_source=lambda: stamp[0])
    before = clock.monotonic()
    stamp[0] += 3600.0
    assert clock.now() == 1e9 + 3600.0
    assert clock.monotonic() - before < 60.0  # the step did not move the interval base


async def test_a_virtual_timeout_around_a_socket_that_answers_does_not_fire():
    """Pending real I/O is not idleness: virtual time waits for the socket (paced at
    real time) instead of jumping to the 5 s deadline."""
    from afa.transport import open_tcp

    async def answer(reader, writer):
        await reader.read(1)
        await asyncio.sleep(0.05)  # the server's own latency (real time, test side)
        writer.write(b"pong")
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(answer, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    clock = VirtualClock(start=0.0)
    try:
        stream = await open_tcp("127.0.0.1", port, clock=clock)
        await stream.write(b"p")
        async with clock.timeout(5.0, "pong"):
            reply = await stream.read()
        assert reply == b"pong"
        assert clock.monotonic() < 5.0  # the deadline was not reached
        await stream.close()
    finally:
        server.close()


async def test_a_paced_clock_runs_no_faster_than_its_real_time_factor():
    loop = asyncio.get_running_loop()
    clock = VirtualClock(start=0.0, pace=20.0)
    wall = loop.time()
    await clock.sleep(2.0)  # 2 virtual seconds at 20x: at least 0.1 s of real time
    assert loop.time() - wall >= 0.09
    assert clock.monotonic() == pytest.approx(2.0)


async def test_pause_resume_and_step():
    clock = VirtualClock(start=0.0)
    ticks = []

    async def ticker():
        async for tick in clock.periodic(1.0):
            ticks.append(tick)

    task = asyncio.get_running_loop().create_task(ticker())
    await clock.advance(2.5)
    assert ticks == [0, 1, 2]
    clock.pause()
    for _ in range(50):
        await asyncio.sleep(0)  # the loop is idle, yet paused time does not move
    assert clock.monotonic() == 2.5 and ticks == [0, 1, 2]
    await clock.run_for(1.0)  # a step while paused
    assert clock.monotonic() == 3.5 and ticks == [0, 1, 2, 3]
    assert clock.paused
    clock.resume()
    await clock.sleep(1.0)
    assert ticks == [0, 1, 2, 3, 4]
    task.cancel()


async def test_the_scaled_clock_changes_speed_and_starts_paused_on_request():
    from afa import ScaledClock

    clock = ScaledClock(start=0.0, speed=None, paused=True)
    assert clock.paused and clock.pace is None
    await clock.advance(3.0)  # a step of three seconds
    assert clock.monotonic() == 3.0
    clock.pace = 50.0
    clock.resume()
    loop = asyncio.get_running_loop()
    wall = loop.time()
    await clock.sleep(1.0)
    assert loop.time() - wall >= 0.015  # at most 50x real time


# -- one instant, one timer at a time (decision 0027) --------------------------------------


async def test_timers_of_one_instant_fire_one_at_a_time_with_their_consequences():
    """Two timers due at the same instant: what the first wakes runs to completion
    (however many awaits it takes) before the second fires, so the order within an
    instant is the timers' order, not the await counts'."""
    clock = VirtualClock(start=0.0)
    order = []

    async def long_chain():  # a source: its timer first, then twenty awaits of work
        await clock.sleep_until(1.0)
        for _ in range(20):
            await asyncio.sleep(0)
        order.append("fix processed")

    async def tick():  # a periodic task's tick at the same instant, scheduled later
        await clock.sleep_until(1.0)
        order.append("tick")

    await asyncio.gather(long_chain(), tick())
    assert order == ["fix processed", "tick"]
    assert clock.monotonic() == 1.0


async def test_call_when_idle_runs_between_the_timers_of_one_instant():
    clock = VirtualClock(start=0.0)
    seen = []

    def idle():
        seen.append(("idle", list(fired)))
        if len(seen) < 3:
            clock.call_when_idle(idle)  # again at the next idle point

    fired = []
    for name in ("a", "b", "c"):
        clock.call_at(2.0, lambda name=name: fired.append(name))
    clock.call_at(1.0, lambda: clock.call_when_idle(idle))
    await clock.sleep(3.0)
    # registered while the first timer ran: once that settled, then after each timer
    assert seen == [("idle", []), ("idle", ["a"]), ("idle", ["a", "b"])]
    assert fired == ["a", "b", "c"]


async def test_a_paused_clock_finishes_the_instant_it_is_in():
    """Pausing stops time, not the rest of an instant: timers due at the current time
    still fire (one at a time) when the loop is idle; later ones wait."""
    clock = VirtualClock(start=0.0)
    fired = []
    clock.call_at(1.0, lambda: (fired.append("first"), clock.pause()))
    clock.call_at(1.0, lambda: fired.append("second"))
    clock.call_at(2.0, lambda: fired.append("later"))
    await clock.sleep_until(1.0)  # the last timer of the instant: it fires paused too
    assert fired == ["first", "second"] and clock.paused and clock.monotonic() == 1.0
    await clock.settle()
    assert fired == ["first", "second"]
    await clock.advance(1.0)
    assert fired == ["first", "second", "later"]
