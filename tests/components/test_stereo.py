"""Stereo Vision (Digiclops): camera backends and the component, in virtual time.

Expected values are derived by hand from the pinhole model (Z = f·B/d, X = (u-cx)·Z/f,
Y = (v-cy)·Z/f) and the ground-plane geometry, never from the code under test. Most
tests use a "simple" camera with round numbers: f = 200 px, B = 0.1 m (f·B = 20 px·m),
principal point (u, v) = (160, 119), looking level at ground 1 m below. Ground seen
by row v then has depth Z = 1 m · 200 / (v - 119).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from afa import EDevIO, ETimeOut, State, System, VirtualClock
from afa.testing import until
from components.stereo import Stereo, StereoParameters
from components.stereo.backends import (
    DIGICLOPS_MODEL,
    CameraModel,
    DisparityFrame,
    EndOfRecording,
    RecordedBackend,
    SyntheticBackend,
    flat_ground,
    read_recording,
    serve_camera,
    write_recording,
)
from idl import Range3dArrayEventIDL, Range3dSensor, Range3dStereoEventIDL

T0 = 1000.0
SIMPLE = CameraModel(width=320, height=240, focal_px=200.0, baseline_m=0.1, cx=160.0, cy=119.0)


def simple_ground(clock: VirtualClock) -> SyntheticBackend:
    """Level camera 1 m above flat ground, no noise."""
    return SyntheticBackend(clock, SIMPLE, flat_ground(SIMPLE, height=1.0, pitch_deg=0.0))


def drain(subscription) -> list:
    events = []
    while (event := subscription.get_nowait()) is not None:
        events.append(event)
    return events


# -- backends, without the component ----------------------------------------------------
def test_synthetic_disparity_is_fb_over_depth_quantised_to_a_sixteenth():
    backend = SyntheticBackend(VirtualClock(), SIMPLE)
    depth = np.full((240, 320), np.nan)
    # f·B = 20: 2 m -> 10 px; 3 m -> 6.667 px -> 107/16 = 6.6875 px; 0.25 m -> 80 px,
    # beyond the 64 px search range; 1000 m -> 0.02 px, below one quantum; NaN -> NaN.
    depth[0, :5] = [2.0, 3.0, 0.25, 1000.0, np.nan]
    d = backend.depth_to_disparity(depth)
    assert d.dtype == np.float32
    assert d[0, 0] == 10.0 and d[0, 1] == 6.6875
    assert np.isnan(d[0, 2:5]).all()


def test_noise_is_seeded_and_stays_on_the_sixteenth_pixel_grid():
    clock = VirtualClock()
    a = SyntheticBackend(clock, SIMPLE, noise_px=0.3, rng=np.random.default_rng(7))
    b = SyntheticBackend(clock, SIMPLE, noise_px=0.3, rng=np.random.default_rng(7))
    depth = np.full((240, 320), 4.0)  # 5 px without noise
    da, db = a.depth_to_disparity(depth), b.depth_to_disparity(depth)
    np.testing.assert_array_equal(da, db)
    assert np.all(da * 16 == np.round(da * 16))
    assert 0.2 < float(np.std(da)) < 0.4 and not np.all(da == 5.0)


def test_default_model_is_the_66_degree_digiclops_estimate():
    # f = 160 / tan(33°) = 246.378 px; principal point at the image centre.
    assert DIGICLOPS_MODEL.focal_px == pytest.approx(246.378, abs=1e-3)
    model = DIGICLOPS_MODEL
    assert (model.cx, model.cy, model.baseline_m) == (159.5, 119.5, 0.1)


async def test_recording_round_trip_and_loop(tmp_path):
    path = tmp_path / "three.npz"
    frames = []
    for k in range(3):
        image = np.full((240, 320), np.nan, dtype=np.float32)
        image[219, 260] = 10.0 / (k + 1)
        frames.append(DisparityFrame(image, 50.0 + 0.5 * k, k))
    write_recording(path, frames, SIMPLE)
    disparity, times, model = read_recording(path)
    assert model == SIMPLE
    assert times.tolist() == [50.0, 50.5, 51.0]
    assert disparity.shape == (3, 240, 320) and disparity[2, 219, 260] == np.float32(10 / 3)
    assert np.isnan(disparity[0, 0, 0])

    backend = RecordedBackend(path, loop=True)
    await backend.open()
    assert [(await backend.capture()).time for _ in range(5)] == [50.0, 50.5, 51.0, 50.0, 50.5]
    stop = RecordedBackend(path)
    await stop.open()
    for _ in range(3):
        await stop.capture()
    with pytest.raises(EndOfRecording):
        await stop.capture()


async def test_recordings_that_are_missing_or_foreign_are_edevio(tmp_path):
    with pytest.raises(EDevIO):
        await RecordedBackend(tmp_path / "absent.npz").open()
    np.savez(tmp_path / "other.npz", disparity=np.zeros((1, 2, 2)))
    with pytest.raises(EDevIO):
        await RecordedBackend(tmp_path / "other.npz").open()


async def test_damaged_recordings_are_edevio(tmp_path):
    """A truncated or bit-flipped archive failed in zipfile or zlib (BadZipFile, not
    EDevIO), so the Stereo component failed to start instead of reporting no camera; so
    did times that run backwards."""
    path = tmp_path / "two.npz"
    frames = [DisparityFrame(np.full((240, 320), 5.0, dtype=np.float32), 50.0 + k, k)
              for k in range(2)]
    write_recording(path, frames, SIMPLE)
    data = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    flipped = bytearray(data)
    for k in range(200, len(flipped), 97):
        flipped[k] ^= 0x5A
    (tmp_path / "flipped.npz").write_bytes(bytes(flipped))
    write_recording(tmp_path / "backwards.npz", frames[::-1], SIMPLE)
    for name in ("cut.npz", "flipped.npz", "backwards.npz"):
        with pytest.raises(EDevIO, match=name):
            await RecordedBackend(tmp_path / name).open()


# -- the component ------------------------------------------------------------------------
async def test_frames_are_published_at_frame_rate_under_the_event_name():
    clock = VirtualClock(start=T0)
    stereo = Stereo("Stereo")
    async with System([stereo], clock=clock,
                      devices={"Stereo": serve_camera(SyntheticBackend(clock))}) as system:
        events = system.channel.subscribe("Raptor", "Stereo", maxsize=1000)
        await clock.settle()
        start = clock.now()
        before = len(drain(events))
        await clock.advance(10.0)
        received = drain(events)
        assert stereo.health().healthy
    assert before <= 1
    assert 19 <= len(received) <= 21  # 2 frames/s (Table A.2) over 10 s
    bodies = [e.body for e in received]
    assert all(isinstance(b, Range3dArrayEventIDL) for b in bodies)
    assert {b.frame for b in bodies} == {"Digiclops:ImagePlane"}
    stamps = [b.time.to_seconds() for b in bodies]
    assert all(b - a == pytest.approx(0.5) for a, b in zip(stamps, stamps[1:], strict=False))
    assert start <= stamps[0] <= start + 0.5


async def test_flat_ground_points_lie_on_the_ground_plane():
    """Default renderer: camera 1.83 m above level ground, pitched 10° down."""
    clock = VirtualClock(start=T0)
    stereo = Stereo("Stereo")
    async with System([stereo], clock=clock,
                      devices={"Stereo": serve_camera(SyntheticBackend(clock))}) as system:
        sensor = await system.resolve(Range3dSensor, "Stereo")
        scan = await sensor.get3dStereoWaitFullScan()
    theta = math.radians(10.0)
    down = np.array([0.0, math.cos(theta), math.sin(theta)])  # gravity in the optical frame
    p = scan.valid_points().astype(np.float64)
    heights = p @ down
    # d = f·B/Z is rounded to 1/16 px, so Z (and the whole point, along its pixel ray)
    # is off by a factor d/d_q with |d - d_q| <= 1/32: |height - h| <= h·(1/32)/d_q.
    d_q = DIGICLOPS_MODEL.fb / p[:, 2]
    assert np.all(np.abs(heights - 1.83) <= 1.83 * (1 / 32) / d_q + 1e-5)
    # Which rows reach the ground within MaxRange 8 m, by hand (f = 246.378, cy = 119.5):
    # row 133: Z = 1.83 / (cos10°·13.5/f + sin10°) = 8.040 m, d = 3.064 -> 49/16 px ->
    #          Z = 8.045 m > 8 m: dropped;
    # row 134: Z = 1.83 / (cos10°·14.5/f + sin10°) = 7.901 m, d = 3.118 -> 50/16 px ->
    #          Z = 7.884 m: kept. So rows 134..239, every column: 106 x 320 points.
    assert scan.count == 106 * 320
    assert not scan.valid[133].any() and scan.valid[134:].all()
    # The nearest ground, bottom row 239: Z = 1.83 / (cos10°·119.5/f + sin10°) = 2.810 m.
    assert scan.points[239, 0, 2] == pytest.approx(2.810, abs=0.01)
    # Columns mirror about the principal point: x(u) = -x(319 - u).
    assert scan.points[200, 0, 0] == pytest.approx(-scan.points[200, 319, 0])


async def test_hand_computed_points_and_max_range_filter():
    clock = VirtualClock(start=T0)
    near = Stereo("Near", StereoParameters(EventName="Near", MaxRange=4000))
    far = Stereo("Far", StereoParameters(EventName="Far"))
    devices = {"Near": serve_camera(simple_ground(clock)),
               "Far": serve_camera(simple_ground(clock))}
    async with System([near, far], clock=clock, devices=devices) as system:
        near_scan = await (await system.resolve(Range3dSensor, "Near")).get3dStereoWaitFullScan()
        far_scan = await (await system.resolve(Range3dSensor, "Far")).get3dStereoWaitFullScan()
        far_seq = await (await system.resolve(Range3dSensor, "Far")).get3dArrayFullScan()
    # Row 219, column 260: Z = 200/100 = 2 m (d = 10 px), X = 100·2/200 = 1 m, Y = 1 m.
    assert far_scan.points[219, 260].tolist() == [1.0, 1.0, 2.0]
    # Row 169, column 160: Z = 200/50 = 4 m (d = 5 px), X = 0, Y = 1 m.
    assert far_scan.points[169, 160].tolist() == [0.0, 1.0, 4.0]
    # MaxRange 8000 mm: row 144 is Z = 200/25 = 8 m exactly (d = 2.5 px) and kept; row
    # 143 is 8.33 m (d = 2.4 -> 38/16 px -> 8.42 m), dropped: rows 144..239 remain.
    assert far_scan.count == 96 * 320 and far_scan.valid[144:].all()
    assert not far_scan.valid[:144].any() and np.isnan(far_scan.points[143, 5]).all()
    # MaxRange 4000 mm: row 169 is 4 m exactly, kept; row 168 (4.08 m -> d 4.9 ->
    # 78/16 px -> 4.10 m) dropped: rows 169..239 remain.
    assert near_scan.count == 71 * 320
    assert near_scan.valid[169:].all() and not near_scan.valid[:169].any()
    assert float(np.nanmax(near_scan.points[..., 2])) == 4.0
    # Level ground 1 m below: y = 1 m for every point, within the 1/16 px quantisation.
    assert np.allclose(far_scan.valid_points()[:, 1], 1.0, atol=8.0 * (1 / 32) / 2.5)
    # The sequence form carries the same valid points, row-major.
    np.testing.assert_array_equal(far_seq.points, far_scan.valid_points())


async def test_polls_get_latest_getwait_next_and_timeout():
    clock = VirtualClock(start=T0)
    backend = simple_ground(clock)
    stereo = Stereo("Stereo")
    async with System([stereo], clock=clock, devices={"Stereo": serve_camera(backend)}) as system:
        events = system.channel.subscribe("Raptor", "Stereo", maxsize=100)
        sensor = await system.resolve(Range3dSensor, "Stereo")
        await clock.advance(1.2)
        last = drain(events)[-1].body
        latest = await sensor.get3dArrayFullScan()
        assert latest == last
        static = await sensor.get3dStereoFullScan()
        assert isinstance(static, Range3dStereoEventIDL)
        assert static.points.shape == (240, 320, 3) and static.time == last.time
        np.testing.assert_array_equal(static.valid_points(), last.points)
        nxt = await sensor.get3dArrayWaitFullScan()
        assert nxt.time.to_seconds() == pytest.approx(last.time.to_seconds() + 0.5)
        for laser in (sensor.get3dLaserFullScan, sensor.get3dLaserWaitFullScan,
                      sensor.get3dSeqFullScan, sensor.get3dSeqWaitFullScan):
            with pytest.raises(EDevIO, match="no laser scans"):
                await laser()
        backend.unplug()
        waited_from = clock.now()
        with pytest.raises(ETimeOut):
            await sensor.get3dStereoWaitFullScan()
        assert clock.now() - waited_from == pytest.approx(Range3dSensor.wait_timeout)
        assert (await sensor.get3dArrayFullScan()) == nxt  # get still answers the latest


async def test_get_before_any_frame_is_edevio_and_no_camera_is_unhealthy():
    clock = VirtualClock(start=T0)
    stereo = Stereo("Stereo")
    async with System([stereo], clock=clock) as system:  # no camera factory installed
        sensor = await system.resolve(Range3dSensor, "Stereo")
        await clock.advance(3.0)
        health = stereo.health()
        with pytest.raises(EDevIO):
            await sensor.get3dArrayFullScan()
        stats = stereo.statistics()
    assert health.state is State.RUNNING and not health.healthy
    assert health.detail.startswith("no camera")
    # backoff 0.5, 1, 2 s: opens tried at 0, 0.5, 1.5 s (and 3.5 s) -> 3 within 3 s
    assert stats["open_failures"] == 3 and stats["frames"] == 0


async def test_a_lost_camera_is_reopened_and_the_other_camera_keeps_running():
    clock = VirtualClock(start=T0)
    flaky, steady = simple_ground(clock), simple_ground(clock)
    a = Stereo("A", StereoParameters(EventName="A"))
    b = Stereo("B", StereoParameters(EventName="B"))
    async with System([a, b], clock=clock,
                      devices={"A": serve_camera(flaky), "B": serve_camera(steady)}) as system:
        ea = system.channel.subscribe("Raptor", "A", maxsize=1000)
        eb = system.channel.subscribe("Raptor", "B", maxsize=1000)
        await clock.advance(2.0)
        assert a.health().healthy
        flaky.unplug()
        await clock.advance(1.0)
        assert not a.health().healthy and "camera" in a.health().detail
        unplugged_at = clock.now()
        await clock.advance(4.0)
        flaky.plug()
        await until(lambda: a.health().healthy, clock, timeout=15.0)
        await clock.advance(2.0)
        stats = a.statistics()
    times_a = [e.body.time.to_seconds() for e in drain(ea)]
    times_b = [e.body.time.to_seconds() for e in drain(eb)]
    assert stats["opens"] == 2 and stats["camera_failures"] == 1
    assert a.state is State.STOPPED and a.failures == 0
    assert any(t > unplugged_at + 4.0 for t in times_a)  # events resumed
    assert not any(unplugged_at <= t <= unplugged_at + 4.0 for t in times_a)
    gaps = [y - x for x, y in zip(times_b, times_b[1:], strict=False)]
    assert max(gaps) == pytest.approx(0.5)  # the other camera never paused


async def test_recorded_backend_replays_frames_then_stops(tmp_path):
    path = tmp_path / "rec.npz"
    frames = []
    for k, d in enumerate([10.0, 5.0, 20.0]):  # Z = 20/d: 2 m, 4 m, 1 m
        image = np.full((240, 320), np.nan, dtype=np.float32)
        image[219, 260] = d
        image[0, 0] = 2.0  # Z = 10 m: beyond MaxRange, dropped
        frames.append(DisparityFrame(image, 7000.25 + k, k))
    write_recording(path, frames, SIMPLE)
    clock = VirtualClock(start=T0)
    stereo = Stereo("Stereo")
    async with System([stereo], clock=clock,
                      devices={"Stereo": serve_camera(RecordedBackend(path))}) as system:
        events = system.channel.subscribe("Raptor", "Stereo", maxsize=100)
        await clock.advance(3.0)
        health = stereo.health()
        received = [e.body for e in drain(events)]
        last = await (await system.resolve(Range3dSensor, "Stereo")).get3dArrayFullScan()
    assert [b.time.to_seconds() for b in received] == [7000.25, 7001.25, 7002.25]
    # pixel (219, 260): X = (260-160)·Z/200 = Z/2, Y = (219-119)·Z/200 = Z/2
    assert [b.points.tolist() for b in received] == [[[1.0, 1.0, 2.0]], [[2.0, 2.0, 4.0]],
                                                     [[0.5, 0.5, 1.0]]]
    assert not health.healthy and health.detail.startswith("end of recording")
    assert last == received[-1]


def test_end_of_recording_is_an_edevio():
    assert issubclass(EndOfRecording, EDevIO)
