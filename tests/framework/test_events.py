"""The event channel: fan-out, wildcards, bounded buffers, statistics, serialisation."""

import math
from typing import Annotated

import numpy as np
import pydantic
import pytest

from afa import ChannelClosed, Event, EventChannel, Overflow, VirtualClock
from afa.events import peek_envelope
from idl import wire
from idl._base import Array, IDLModel, field


class Sample(IDLModel):
    value: int = field(0, unit="1")


class Cloud(IDLModel):
    points: Annotated[np.ndarray, Array("float32", (None, 3))] = field(unit="m")


def test_publish_fans_out_to_every_matching_subscription_in_order():
    channel = EventChannel(VirtualClock(start=5.0))
    exact = channel.subscribe("Raptor", "Gps")
    any_type = channel.subscribe("Raptor", "*")
    lasers = channel.subscribe("*", "Laser1?")
    other = channel.subscribe("Other", "Gps")
    channel.publish("Raptor", "Gps", Sample(value=1))
    channel.publish("Raptor", "Laser11", Sample(value=2))
    channel.publish("Raptor", "Laser12", Sample(value=3))
    assert [e.body.value for e in _drain(exact)] == [1]
    assert [e.body.value for e in _drain(any_type)] == [1, 2, 3]
    assert [e.type for e in _drain(lasers)] == ["Laser11", "Laser12"]
    assert _drain(other) == []


def test_events_carry_domain_type_clock_time_and_sequence():
    clock = VirtualClock(start=42.0)
    channel = EventChannel(clock)
    sub = channel.subscribe("Raptor", "*")
    first = channel.publish("Raptor", "A", Sample(value=1))
    second = channel.publish("Raptor", "B", Sample(value=2))
    assert (first.domain, first.type, first.time, first.seq) == ("Raptor", "A", 42.0, 1)
    assert second.seq == 2
    assert _drain(sub) == [first, second]


def test_drop_oldest_keeps_the_newest_and_counts_drops():
    channel = EventChannel(VirtualClock())
    sub = channel.subscribe("R", "T", maxsize=3)
    for i in range(10):
        channel.publish("R", "T", Sample(value=i))
    stats = sub.statistics()
    assert (stats.dropped, stats.high_water, stats.queued) == (7, 3, 3)
    assert [e.body.value for e in _drain(sub)] == [7, 8, 9]
    assert sub.statistics().delivered == 3


def test_drop_newest_keeps_what_is_queued():
    channel = EventChannel(VirtualClock())
    sub = channel.subscribe("R", "T", maxsize=2, policy=Overflow.DROP_NEWEST)
    for i in range(5):
        channel.publish("R", "T", Sample(value=i))
    assert [e.body.value for e in _drain(sub)] == [0, 1]
    assert sub.statistics().dropped == 3


def test_offer_knows_whether_anyone_subscribes():
    channel = EventChannel(VirtualClock())
    publisher = channel.offer("Raptor", "Terrain")
    assert not publisher.subscribed and not channel.subscribed("Raptor", "Terrain")
    sub = channel.subscribe("Raptor", "Terr*")
    assert publisher.subscribed and channel.subscribed("Raptor", "Terrain")
    sub.close()
    assert not publisher.subscribed
    assert ("Raptor", "Terrain") in channel.offers()


def test_offer_of_a_pattern_is_refused():
    with pytest.raises(ValueError):
        EventChannel().offer("Raptor", "*")


def test_a_body_must_be_an_idl_model():
    with pytest.raises(TypeError):
        EventChannel().publish("R", "T", {"value": 1})  # type: ignore[arg-type]


async def test_async_iteration_waits_for_events_and_ends_on_close():
    clock = VirtualClock()
    channel = EventChannel(clock)
    sub = channel.subscribe("R", "T")
    received = []

    async def consume():
        async for event in sub:
            received.append(event.body.value)

    import asyncio

    task = asyncio.get_running_loop().create_task(consume())
    await clock.settle()
    channel.publish("R", "T", Sample(value=1))
    await clock.settle()
    channel.publish("R", "T", Sample(value=2))
    sub.close()
    await task
    assert received == [1, 2]
    with pytest.raises(ChannelClosed):
        await sub.get()


def test_closing_the_channel_closes_subscriptions_and_refuses_new_ones():
    channel = EventChannel()
    sub = channel.subscribe("R", "T")
    channel.close()
    assert sub.closed
    with pytest.raises(ChannelClosed):
        channel.subscribe("R", "T")


def test_bodies_are_immutable_so_fan_out_shares_them_safely():
    channel = EventChannel()
    a, b = channel.subscribe("R", "C"), channel.subscribe("R", "C")
    points = np.ones((4, 3), dtype=np.float32)
    channel.publish("R", "C", Cloud(points=points))
    points[:] = 7  # the producer's own buffer stays its own
    event_a, event_b = a.get_nowait(), b.get_nowait()
    assert event_a is event_b
    assert np.all(event_a.body.points == 1)
    with pytest.raises(ValueError):
        event_a.body.points[0, 0] = 3  # read-only
    with pytest.raises(pydantic.ValidationError):
        event_a.body.points = points  # frozen model


def test_events_serialise_losslessly_with_arrays():
    channel = EventChannel(VirtualClock(start=1.5))
    points = np.arange(12, dtype=np.float32).reshape(4, 3) / 7
    event = channel.publish("Raptor", "Laser11", Cloud(points=points), origin="NodLaser")
    back = Event.decode(event.encode())
    assert back == event and back.origin == "NodLaser"
    assert back.body.points.dtype == np.float32
    assert np.array_equal(back.body.points, points)


def test_a_damaged_event_raises_wire_error_only():
    event = EventChannel().publish("Raptor", "T", Sample(value=1))
    data = event.encode()
    for cut in range(len(data)):
        with pytest.raises(wire.WireError):
            Event.decode(data[:cut])


@pytest.mark.parametrize("stamp", [math.nan, math.inf, -math.inf])
def test_an_event_whose_time_is_not_finite_is_refused_by_whoever_reads_it(stamp):
    """A peer, a log or a console frame: a NaN or infinite stamp would reach a component
    as its input's time (a filter fails on it, a log player schedules it nowhere)."""
    data = Event("Raptor", "T", stamp, 1, Sample(value=1), "peer/x").encode()
    with pytest.raises(wire.WireError, match="not a finite time stamp"):
        Event.decode(data)
    with pytest.raises(wire.WireError, match="not a finite time stamp"):
        peek_envelope(data)


def test_an_observer_has_its_own_buffer_and_counts_what_it_drops():
    channel = EventChannel()
    observer = channel.observe(maxsize=2)
    fast = channel.subscribe("R", "T", maxsize=100)
    for i in range(5):
        channel.publish("R", "T", Sample(value=i))
    assert [e.body.value for e in _drain(observer)] == [3, 4]
    assert observer.statistics().dropped == 3
    assert len(_drain(fast)) == 5 and fast.statistics().dropped == 0
    assert channel.counts() == {"T": 5}


def test_injected_events_keep_their_time_and_origin():
    channel = EventChannel(VirtualClock(start=100.0))
    sub = channel.subscribe("Raptor", "Gps")
    remote = Event("Raptor", "Gps", 12.5, 77, Sample(value=3), "other/GpsSokkia")
    delivered = channel.inject(remote)
    assert (delivered.time, delivered.origin, delivered.seq) == (12.5, "other/GpsSokkia", 1)
    assert _drain(sub) == [delivered]


def _drain(sub):
    out = []
    while (event := sub.get_nowait()) is not None:
        out.append(event)
    return out


def test_observers_see_everything_but_ask_for_no_optional_form():
    channel = EventChannel()
    publisher = channel.offer("Raptor", "Laser11Array")
    observer = channel.observe()
    assert not publisher.subscribed and not channel.subscribed("Raptor", "Laser11Array")
    channel.publish("Raptor", "Laser11Array", Sample(value=1))
    assert len(_drain(observer)) == 1  # it still sees what is published
    wanted = channel.subscribe("Raptor", "Laser1*")
    assert publisher.subscribed and channel.subscribed("Raptor", "Laser11Array")
    wanted.close()
    assert not publisher.subscribed
