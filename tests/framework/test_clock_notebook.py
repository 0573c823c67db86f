"""Virtual time a person can follow (a notebook, a console): a paused clock starts a
System without deadlock, runs for N seconds and stops, stands still between runs, and a
paced clock keeps to its real-time factor, checked with an injected real-time source
(no sleeps, no timing margins)."""

import asyncio

import pytest

from afa import SubscribePublishServer, System, VirtualClock
from idl._base import IDLModel, field


class Tick(IDLModel):
    n: int = field(0, unit="1")


class Ticker(SubscribePublishServer):
    """Counts (and publishes) a tick every 0.1 s of clock time."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.n = 0
        self.out = self.publishes("Tick", Tick)

    async def run(self) -> None:
        async for _ in self.clock.periodic(0.1):
            self.n += 1
            self.out.publish(Tick(n=self.n))


async def idle_loop(ticks: int = 500) -> None:
    """Leave the event loop idle, as between notebook cells, for a while: another
    virtual clock ticks meanwhile, and the one driver that moves every virtual clock of
    the loop would move a clock that runs by itself between those ticks (round robin)."""
    other = VirtualClock(start=0.0)
    async for tick in other.periodic(0.1):
        if tick >= ticks:
            return


async def test_a_paused_clock_starts_a_system_with_start_delays_and_stays_paused():
    clock = VirtualClock(start=0.0, auto_advance=False)
    first, second = Ticker("First"), Ticker("Second")
    system = System([first, second], clock=clock, start_delays={"First": 2.0},
                    start_after=0.5)
    await system.start()  # used to wait forever: the delays needed time nobody moved
    try:
        assert clock.monotonic() == pytest.approx(2.5) and clock.paused
        await clock.settle()  # what is due at 2.5 runs; time does not move
        ticks = (first.n, second.n)
        assert ticks == (21, 1)  # First ticked from 0.5 s on, Second from 2.5 s
        await idle_loop()
        assert clock.monotonic() == pytest.approx(2.5)  # no free-running between cells
        assert (first.n, second.n) == ticks
    finally:
        await system.stop()
    assert clock.paused


async def test_system_run_runs_n_seconds_then_time_stands_still():
    clock = VirtualClock(start=0.0, auto_advance=False)
    ticker = Ticker("Ticker")
    async with System([ticker], clock=clock) as system:
        await system.run(10.0)
        assert clock.monotonic() == pytest.approx(10.0) and clock.paused
        assert ticker.n == 101  # ticks at 0, 0.1, ... 10.0
        await idle_loop()
        assert clock.monotonic() == pytest.approx(10.0) and ticker.n == 101
        await clock.run_for(1.0)
        assert clock.monotonic() == pytest.approx(11.0) and ticker.n == 111 and clock.paused


async def test_running_blocks_nest_and_overlap_and_the_last_one_out_pauses():
    clock = VirtualClock(start=0.0, auto_advance=False)
    with clock.running():
        assert not clock.paused
        with clock.running():
            await clock.sleep(1.0)
        assert not clock.paused
        await asyncio.gather(clock.run_for(1.0), clock.run_for(2.0))
        assert not clock.paused
    assert clock.paused and clock.monotonic() == pytest.approx(3.0)
    clock.resume()  # running by choice: a running() block leaves it running
    with clock.running():
        await clock.sleep(1.0)
    assert not clock.paused


async def test_a_pause_inside_a_run_holds_it_until_resumed():
    clock = VirtualClock(start=0.0, auto_advance=False)
    run = asyncio.get_running_loop().create_task(clock.run_for(5.0))
    await clock.settle()
    clock.pause()  # the operator's pause button, mid-run
    await idle_loop()
    assert not run.done()
    held = clock.monotonic()
    await idle_loop()
    assert clock.monotonic() == held
    clock.resume()
    await run
    assert clock.monotonic() == pytest.approx(5.0) and not clock.paused


class FakeRealTime:
    """A real-time source the test moves by hand (in binary fractions, so that the
    arithmetic is exact)."""

    def __init__(self) -> None:
        self.now = 64.0

    def __call__(self) -> float:
        return self.now


async def test_a_paced_clock_moves_only_as_far_as_real_time_allows():
    real = FakeRealTime()
    clock = VirtualClock(start=0.0, pace=4.0, real_time=real)
    woke: list[float] = []

    async def sleeper(seconds: float) -> None:
        await clock.sleep(seconds)
        woke.append(clock.monotonic())

    task = asyncio.get_running_loop().create_task(sleeper(1.0))
    await idle_loop()
    assert clock.monotonic() == 0.0 and woke == []  # no real time has passed
    real.now += 0.125  # 0.5 s of virtual time allowed at 4x: short of 1 s
    await idle_loop()
    assert clock.monotonic() == 0.0 and woke == []
    real.now += 0.125  # 0.25 s of real time: 1 s of virtual time
    await task
    assert woke == [1.0]


async def test_a_paced_run_for_in_a_notebook_waits_for_real_time_and_stays_paused_after():
    real = FakeRealTime()
    clock = VirtualClock(start=0.0, auto_advance=False, pace=2.0, real_time=real)
    ticker = Ticker("Ticker")
    async with System([ticker], clock=clock):
        run = asyncio.get_running_loop().create_task(clock.run_for(3.0))
        await idle_loop()
        assert clock.monotonic() == 0.0 and not run.done()
        real.now += 1.0  # 2 s of virtual time at 2x
        await clock.sleep_until(2.0)
        await idle_loop()  # and not a tick further
        assert clock.monotonic() == pytest.approx(2.0) and ticker.n == 21 and not run.done()
        real.now += 0.5
        await run
        assert clock.monotonic() == pytest.approx(3.0) and clock.paused
        real.now += 60.0  # a minute between cells: paused time does not catch up
        await idle_loop()
        assert clock.monotonic() == pytest.approx(3.0) and ticker.n == 31


def test_realtime_factor_gives_afa_run_a_paced_virtual_clock():
    from afa.cli import _parser, run_clock

    args = _parser().parse_args(["run", "configs/raptor.xml", "--sim",
                                 "--realtime-factor", "4"])
    clock = run_clock(args.fast, args.realtime_factor)
    assert isinstance(clock, VirtualClock) and clock.pace == 4.0 and not clock.paused
    fast = run_clock(fast=True)
    assert isinstance(fast, VirtualClock) and fast.pace is None
    assert not isinstance(run_clock(), VirtualClock)


async def test_running_until_stopped_leaves_a_paused_clock_to_its_owner():
    """A replay started paused stays paused under ``system.run()`` (no duration): only
    a bounded run spends time on its own."""
    clock = VirtualClock(start=0.0, auto_advance=False)
    ticker = Ticker("Ticker")
    async with System([ticker], clock=clock) as system:
        runner = asyncio.get_running_loop().create_task(system.run())
        await idle_loop()
        assert clock.monotonic() == 0.0 and clock.paused and not runner.done()
        clock.resume()  # the player's resume
        await clock.sleep(1.0)
        clock.pause()
        system.request_stop()
        await runner
        await clock.settle()  # the rest of the instant: the tick due at 1.0 (decision 0027)
        assert clock.monotonic() == pytest.approx(1.0) and ticker.n == 11
