"""What the console sends and drops: classification by body type, per-view rates, the
drop-oldest outbox and its wait for a fresh entry, and the message framing."""

import math
import struct

import numpy as np
import pytest

from afa.console.frames import MAGIC, decode_frame, encode_frame, event_names_length
from afa.console.streams import FRESH, POLICIES, Outbox, clamp_rate, classify
from afa.events import Event
from idl import (
    ArcVoteIDL,
    EtravMapArrayEventIDL,
    GpsIDL,
    PoseTransformIDL,
    Range3dSeqEventIDL,
    StringSequenceIDL,
    TimeIDL,
    TravMapArrayEventIDL,
    WheelEventIDL,
)

T = TimeIDL(sec=1)


def event(name, body, seq=1, origin="x"):
    return Event("Raptor", name, 1.0, seq, body, origin)


def trav(cls):
    return cls(time=T, frame="World", mapPose=np.eye(4), initialUTM=np.zeros(3), gridsize=0.5,
               originX=0.0, originY=0.0, rows=2, cols=2, hazard=np.zeros((2, 2)),
               goodness=np.ones((2, 2)), vehiclePosition={"x": 0, "y": 0, "z": 0})


def vote(behaviour):
    n = 3
    return ArcVoteIDL(time=T, behaviour=behaviour, curvatures=np.zeros(n), veto=np.zeros(n),
                      vote=np.zeros(n), certainty=np.zeros(n), maxSpeed=np.zeros(n))


def test_the_global_and_the_ego_traversability_maps_share_a_name_but_not_a_stream():
    assert classify(event("Traverse", trav(TravMapArrayEventIDL))) == (
        "map.traverse", "map.traverse/Traverse")
    assert classify(event("Traverse", trav(EtravMapArrayEventIDL))) == (
        "ego.traverse", "ego.traverse/Traverse")


def test_each_behaviours_votes_are_a_stream_and_unknown_bodies_none():
    assert classify(event("ArcVote", vote("PurePursuit")))[1] == "arcs.vote/PurePursuit"
    assert classify(event("ArcVote", vote("FindPath")))[1] == "arcs.vote/FindPath"
    assert classify(event("Names", StringSequenceIDL(values=("a",)))) is None
    pose = PoseTransformIDL.identity()
    assert classify(event("PoseFiltered", pose)) == ("pose", "pose/PoseFiltered")
    # a subclass is classified as its base (WheelEventIDL is a WheelDataIDL)
    wheels = WheelEventIDL(time=T, leftDistance=0, rightDistance=0, leftSpeed=0, rightSpeed=0)
    assert classify(event("RaptorOdometry", wheels))[0] == "odometry"
    assert classify(event("Gps", GpsIDL(time=T)))[0] == "gps"


def test_a_requested_rate_is_clamped_to_the_kinds_maximum_and_nonsense_means_default():
    policy = POLICIES["map.traverse"]
    assert clamp_rate("map.traverse", 1000) == policy.max_rate
    assert clamp_rate("map.traverse", 0.5) == 0.5
    for nonsense in (None, "fast", -1, 0, math.nan, -10**400, [[1]]):
        assert clamp_rate("map.traverse", nonsense) == policy.rate
    assert clamp_rate("map.traverse", 10**400) == policy.max_rate  # beyond any float
    with pytest.raises(KeyError):
        clamp_rate("no.such.kind", 1)


def test_an_outbox_keeps_the_newest_and_counts_what_it_dropped():
    outbox = Outbox("range.laser/Laser11", "range.laser", interval=0.2, depth=3)
    assert outbox.due(0.0) is None
    for k in range(5):
        outbox.push(k, now=0.01 * k)
    assert outbox.stats.dropped == 2 and outbox.stats.offered == 5
    assert outbox.due(0.05) == -math.inf  # never sent: due at once
    assert [entry for _, entry in outbox.take(0.05)] == [2, 3, 4]
    outbox.push(5, now=0.06)
    assert outbox.due(0.06) == pytest.approx(0.25)  # one interval after the last send
    assert outbox.stats.sent == 3


def test_a_latest_value_stream_waits_for_a_fresh_entry_instead_of_sending_a_stale_one():
    # maps arriving 5 times a second, sent once a second
    outbox = Outbox("map.traverse/Traverse", "map.traverse", interval=1.0, depth=1)
    for k in range(6):
        outbox.push(f"map{k}", now=0.2 * k)          # 0.0 .. 1.0
    outbox.take(1.0)                                  # sent map5 at t = 1.0
    outbox.push("map6", now=1.2)
    outbox.push("map7", now=1.8)
    # due at 2.0, but map7 will then be 0.2 s old: wait for the next, expected about
    # one period after it (the outbox keeps a mean of the arrival period)
    assert 0.2 < outbox.period < 0.4
    due = outbox.due(2.0)
    assert due == pytest.approx(1.8 + 1.5 * outbox.period) and due > 2.0
    outbox.push("map8", now=2.0)                      # fresh: goes at once
    assert outbox.due(2.0) == pytest.approx(2.0)
    assert outbox.entries[-1][1] == "map8" and 2.0 - outbox.entries[-1][0] <= FRESH
    # a stream slower than its rate never waits
    slow = Outbox("map.plan/PlanMap", "map.plan", interval=0.5, depth=1)
    slow.push("a", now=0.0)
    slow.push("b", now=3.0)
    assert slow.due(5.0) == -math.inf


def test_a_message_carries_several_events_with_their_bodies_8_aligned():
    lines = [event("Laser11", Range3dSeqEventIDL(
        time=T, sensorId=11, frame="L:F", points=np.full((k + 1, 3), k, dtype=np.float32)),
        seq=k, origin="NodLaserService" + "x" * k) for k in range(3)]
    data = encode_frame({"kind": "range.laser", "stream": "range.laser/Laser11"},
                        [(e.encode(), event_names_length(e)) for e in lines])
    assert data[:4] == MAGIC
    length, count = struct.unpack_from("<II", data, 4)
    assert count == 3
    for k in range(count):
        offset, size = struct.unpack_from("<II", data, 16 + length + 8 * k)
        body = offset + 26 + event_names_length(lines[k])
        assert data[body:body + 4] == b"AFW1" and body % 8 == 0
        assert data[offset:offset + size] == lines[k].encode()
    header, events = decode_frame(data)
    assert header["kind"] == "range.laser" and events == lines


def test_a_header_only_message_and_non_finite_numbers_in_it():
    header, events = decode_frame(encode_frame({"kind": "status", "x": math.inf}))
    assert header == {"kind": "status", "x": None} and events == []
    with pytest.raises(ValueError):
        decode_frame(b"XXXX" + bytes(12))
