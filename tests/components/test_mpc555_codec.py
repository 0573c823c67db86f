"""MPC555 link codec: byte literals, round trips and stream properties.

The byte literals below were written out by hand from the layouts in
docs/protocols/mpc555.md (big-endian fields); their CRCs were computed with CPython's
``binascii.crc_hqx(frame, 0xFFFF)``, an independent CRC-CCITT implementation, and the
CRC routine itself is checked against the catalogue check value of CRC-16/CCITT-FALSE
(reveng CRC catalogue, CRC-16/IBM-3740: check 0x29B1, residue 0x0000).
"""

from __future__ import annotations

import binascii
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from afa.codec import Fault
from components.mpc555.codec import (
    MAX_FRAME,
    AckResult,
    CommandAck,
    ConfigureReports,
    Faults,
    Heartbeat,
    MessageType,
    Mode,
    Mpc555Decoder,
    Mpc555DeviceDecoder,
    Packet,
    PedalBreakpoint,
    SequenceCounter,
    SetArbiter,
    SetJoystickVelocity,
    SetLimits,
    SetPedalCalibration,
    SetSteerCalibration,
    SetSteerPid,
    SetVelocity,
    SetWheelCalibration,
    SpeedReport,
    StartVehicle,
    StatusFlags,
    StatusReport,
    StopVehicle,
    WheelDistanceReport,
    crc16_ccitt_false,
    crc16_ccitt_false_reference,
    encode_command,
    encode_frame,
    encode_report,
    steering_angle,
    yaw_rate,
)

H = bytes.fromhex

# (frame, sequence number, message): host -> controller.
COMMAND_FRAMES = [
    (H("a5 01 00 01 00 5d ba"), 0x00, Heartbeat()),
    (H("a5 01 04 02 2a 05 dc ff 06 fb 36"), 0x2A, SetVelocity(1500, -250)),
    (H("a5 01 00 04 01 b2 6e"), 0x01, StartVehicle()),
    (H("a5 01 00 05 02 b1 3c"), 0x02, StopVehicle()),
    (H("a5 01 01 06 03 01 87 0e"), 0x03, SetArbiter(True)),
    (H("a5 01 06 07 04 00 c8 03 e8 01 f4 72 b1"), 0x04, ConfigureReports(200, 1000, 500)),
    (H("a5 01 08 08 05 07 d0 03 e8 0b b8 07 6c 60 3d"), 0x05, SetLimits(2000, 1000, 3000, 1900)),
    # LfdParam = RfdParam = 0.5062 mm/count = 506200 nm = 0x0007B958
    (H("a5 01 08 09 06 00 07 b9 58 00 07 b9 58 69 9a"), 0x06, SetWheelCalibration(506200, 506200)),
    # SteerParam Center 512, Gain 0.075 deg = 75000 udeg = 0x000124F8, Min 112, Max 912
    (H("a5 01 0a 0a 07 02 00 00 01 24 f8 00 70 03 90 1a 52"), 0x07,
     SetSteerCalibration(512, 75000, 112, 912)),
    # The default PedalParam table: (-1000, 1250) (0, 2048) (200, 2350) (1000, 2750) (2000, 3250)
    (H("a5 01 15 0b 08 05 fc 18 04 e2 00 00 08 00 00 c8 09 2e 03 e8 0a be 07 d0 0c b2 1f 2b"),
     0x08, SetPedalCalibration((PedalBreakpoint(-1000, 1250), PedalBreakpoint(0, 2048),
                                PedalBreakpoint(200, 2350), PedalBreakpoint(1000, 2750),
                                PedalBreakpoint(2000, 3250)))),
    # SteerPID P 4.0, I 0.5, D 0.1 in thousandths
    (H("a5 01 0c 0c 09 00 00 0f a0 00 00 01 f4 00 00 00 64 85 85"), 0x09,
     SetSteerPid(4000, 500, 100)),
    (H("a5 01 04 03 ff fe 0c 00 00 2d dc"), 0xFF, SetJoystickVelocity(-500, 0)),
]

# controller -> host.
REPORT_FRAMES = [
    # t = 123456 ms = 0x0001E240, left 10000 counts, right -3 counts
    (H("a5 01 0c 81 10 00 01 e2 40 00 00 27 10 ff ff ff fd c0 53"), 0x10,
     WheelDistanceReport(123456, 10000, -3)),
    # t = 5000 ms, 1234 mm/s, -15.50 deg (right), pedal 2750, steering sensor 305
    (H("a5 01 0c 82 11 00 00 13 88 04 d2 f9 f2 0a be 01 31 19 5d"), 0x11,
     SpeedReport(5000, 1234, -1550, 2750, 305)),
    # stopped by the watchdog: flags WATCHDOG|BRAKE|CALIBRATED = 0x16, faults 0x0044
    (H("a5 01 0c 83 12 00 00 03 e8 00 16 00 44 02 64 00 03 41 c7"), 0x12,
     StatusReport(1000, Mode.STOPPED,
                  StatusFlags.WATCHDOG | StatusFlags.BRAKE | StatusFlags.CALIBRATED,
                  Faults.STEER_SENSOR | Faults.SUPPLY_LOW, 612, 3)),
    (H("a5 01 03 84 13 2a 02 01 95 01"), 0x13,
     CommandAck(0x2A, MessageType.SET_VELOCITY, AckResult.LIMITED)),
    (H("a5 01 03 84 14 01 04 84 d9 90"), 0x14,
     CommandAck(0x01, MessageType.START_VEHICLE, AckResult.NOT_CALIBRATED)),
]

ALL_COMMANDS = [message for _, _, message in COMMAND_FRAMES]
ALL_REPORTS = [message for _, _, message in REPORT_FRAMES]


# ------------------------------------------------------------------------------ CRC

def test_crc_check_value() -> None:
    assert crc16_ccitt_false(b"123456789") == 0x29B1


def test_crc_is_incremental_and_has_zero_residue() -> None:
    assert crc16_ccitt_false(b"56789", crc16_ccitt_false(b"1234")) == 0x29B1
    for frame, _, _ in COMMAND_FRAMES + REPORT_FRAMES:
        assert crc16_ccitt_false(frame) == 0x0000


@settings(max_examples=200)
@given(st.binary(max_size=64))
def test_crc_matches_the_standard_library(data: bytes) -> None:
    assert crc16_ccitt_false(data) == binascii.crc_hqx(data, 0xFFFF)


@settings(max_examples=200)
@given(st.binary(max_size=64), st.integers(0, 0xFFFF))
def test_crc_equals_the_table_loop(data: bytes, crc: int) -> None:
    assert crc16_ccitt_false(data, crc) == crc16_ccitt_false_reference(data, crc)
    assert crc16_ccitt_false(bytearray(data)) == crc16_ccitt_false_reference(memoryview(data))


# ------------------------------------------------------------------------------ literals

@pytest.mark.parametrize(("frame", "seq", "message"), COMMAND_FRAMES,
                         ids=[type(m).__name__ for m in ALL_COMMANDS])
def test_command_byte_literals(frame: bytes, seq: int, message: object) -> None:
    assert encode_command(message, seq) == frame  # type: ignore[arg-type]
    decoder = Mpc555DeviceDecoder()
    assert decoder.feed(frame) == [Packet(seq, message)]
    assert decoder.stats.frames == 1 and decoder.stats.bytes_skipped == 0


@pytest.mark.parametrize(("frame", "seq", "message"), REPORT_FRAMES,
                         ids=[type(m).__name__ for m in ALL_REPORTS])
def test_report_byte_literals(frame: bytes, seq: int, message: object) -> None:
    assert encode_report(message, seq) == frame  # type: ignore[arg-type]
    decoder = Mpc555Decoder()
    assert decoder.feed(frame) == [Packet(seq, message)]
    assert decoder.stats.frames == 1 and decoder.stats.bytes_skipped == 0


def test_decoded_values_keep_their_meaning() -> None:
    [packet] = Mpc555Decoder().feed(REPORT_FRAMES[2][0])
    status = packet.message
    assert isinstance(status, StatusReport)
    assert status.mode is Mode.STOPPED and StatusFlags.WATCHDOG in status.flags
    assert StatusFlags.ESTOP not in status.flags
    [packet] = Mpc555Decoder().feed(REPORT_FRAMES[4][0])
    assert isinstance(packet.message, CommandAck) and not packet.message.accepted
    [packet] = Mpc555Decoder().feed(REPORT_FRAMES[3][0])
    assert isinstance(packet.message, CommandAck) and packet.message.accepted


def test_frames_split_byte_by_byte() -> None:
    stream = b"".join(frame for frame, _, _ in REPORT_FRAMES)
    decoder = Mpc555Decoder()
    out = [packet for byte in stream for packet in decoder.feed(bytes((byte,)))]
    assert [p.message for p in out] == ALL_REPORTS
    assert decoder.stats.bytes_skipped == 0


# ------------------------------------------------------------------------------ directions

def test_each_side_drops_the_other_directions_frames() -> None:
    host, device = Mpc555Decoder(), Mpc555DeviceDecoder()
    assert host.feed(COMMAND_FRAMES[1][0]) == []  # e.g. an echo of our own command
    assert host.stats.malformed == 1
    assert device.feed(REPORT_FRAMES[0][0]) == []
    assert device.stats.malformed == 1


def test_encoders_refuse_the_wrong_direction() -> None:
    with pytest.raises(TypeError):
        encode_command(WheelDistanceReport(0, 0, 0), 0)  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        encode_report(Heartbeat(), 0)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", [
    SetVelocity(40000, 0),  # does not fit int16
    ConfigureReports(-1, 1000, 500),
    SetWheelCalibration(1 << 32, 0),
    SetPedalCalibration((PedalBreakpoint(0, 2048),)),  # too few points
    SetPedalCalibration(tuple(PedalBreakpoint(i, 2048) for i in range(9))),  # too many
], ids=["velocity", "interval", "calibration", "pedal-short", "pedal-long"])
def test_out_of_range_fields_raise_value_error(bad: object) -> None:
    with pytest.raises(ValueError):
        encode_command(bad, 0)  # type: ignore[arg-type]


def test_sequence_number_out_of_range_raises() -> None:
    with pytest.raises(ValueError):
        encode_command(Heartbeat(), 256)


def test_sequence_counter_wraps() -> None:
    counter = SequenceCounter(254)
    assert [counter.next() for _ in range(3)] == [254, 255, 0]


# ------------------------------------------------------------------------------ malformed

def _with_crc(body: bytes) -> bytes:
    return body + binascii.crc_hqx(body, 0xFFFF).to_bytes(2, "big")


@pytest.mark.parametrize("frame", [
    _with_crc(H("a5 01 0c 83 00 00 00 00 00 07 00 00 00 00 00 00 00")),  # mode 7
    _with_crc(H("a5 01 03 84 00 05 81 00")),  # ACK naming a report type
    _with_crc(H("a5 01 03 84 00 05 02 42")),  # unknown ACK result
    _with_crc(H("a5 01 03 81 00 00 00 00")),  # WHEEL_DISTANCE with a 3-byte payload
    _with_crc(H("a5 01 00 7f 00")),  # unknown type
], ids=["mode-7", "ack-of-report", "ack-result-0x42", "short-wheel-distance", "type-0x7f"])
def test_malformed_report_frames_are_counted(frame: bytes) -> None:
    decoder = Mpc555Decoder()
    good = REPORT_FRAMES[0][0]
    assert [p.message for p in decoder.feed(frame + good)] == [ALL_REPORTS[0]]
    assert decoder.stats.malformed == 1 and decoder.stats.checksum_failures == 0


@pytest.mark.parametrize("frame", [
    _with_crc(H("a5 01 01 06 00 02")),  # SET_ARBITER with 2
    _with_crc(H("a5 01 09 0b 00 03 00 00 08 00 00 c8 09 2e")),  # count 3, two points
    _with_crc(H("a5 01 05 0b 00 01 00 00 08 00")),  # one point only
], ids=["arbiter-2", "pedal-count-mismatch", "pedal-one-point"])
def test_malformed_command_frames_are_counted(frame: bytes) -> None:
    decoder = Mpc555DeviceDecoder()
    assert [p.message for p in decoder.feed(frame + COMMAND_FRAMES[0][0])] == [Heartbeat()]
    assert decoder.stats.malformed == 1


def test_wrong_version_is_skipped_as_garbage() -> None:
    frame = bytearray(COMMAND_FRAMES[0][0])
    frame[1] = 0x02
    decoder = Mpc555DeviceDecoder()
    assert decoder.feed(bytes(frame)) == []
    assert decoder.stats.malformed == 0 and decoder.stats.checksum_failures == 0
    assert decoder.stats.bytes_skipped == len(frame)


def test_checksum_failure_then_recovery() -> None:
    bad = bytearray(REPORT_FRAMES[0][0])
    bad[-1] ^= 0x01
    decoder = Mpc555Decoder()
    out = decoder.feed(bytes(bad) + REPORT_FRAMES[1][0])
    assert [p.message for p in out] == [ALL_REPORTS[1]]
    assert decoder.stats.checksum_failures == 1


# ------------------------------------------------------------------------------ kinematics

def test_steering_from_rotation_uses_the_wheelbase() -> None:
    # tan(delta) = L * w / v = 1.9 m * 0.5 rad/s / 0.95 m/s = 1 -> 45 deg left
    assert steering_angle(950, 500, 1900) == pytest.approx(math.pi / 4)
    # reversing while turning left (w > 0) needs the wheels to the right
    assert steering_angle(-950, 500, 1900) == pytest.approx(-math.pi / 4)
    assert steering_angle(0, 500, 1900) is None
    assert steering_angle(1000, 0, 1900) == 0.0
    assert yaw_rate(950, math.pi / 4, 1900) == pytest.approx(0.5)


# ------------------------------------------------------------------------------ round trips

velocity = st.integers(-32768, 32767)
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFFFFFF)
i32 = st.integers(-(1 << 31), (1 << 31) - 1)
seqs = st.integers(0, 255)

commands = st.one_of(
    st.just(Heartbeat()), st.just(StartVehicle()), st.just(StopVehicle()),
    st.builds(SetVelocity, velocity, velocity),
    st.builds(SetJoystickVelocity, velocity, velocity),
    st.builds(SetArbiter, st.booleans()),
    st.builds(ConfigureReports, u16, u16, u16),
    st.builds(SetLimits, u16, u16, u16, u16),
    st.builds(SetWheelCalibration, u32, u32),
    st.builds(SetSteerCalibration, u16, u32, u16, u16),
    st.builds(SetPedalCalibration, st.lists(
        st.builds(PedalBreakpoint, velocity, u16), min_size=2, max_size=8).map(tuple)),
    st.builds(SetSteerPid, u32, u32, u32),
)
reports = st.one_of(
    st.builds(WheelDistanceReport, u32, i32, i32),
    st.builds(SpeedReport, u32, velocity, velocity, u16, u16),
    st.builds(StatusReport, u32, st.sampled_from(Mode),
              st.integers(0, 0xFF).map(StatusFlags), u16.map(Faults), u16, u16),
    st.builds(CommandAck, seqs,
              st.sampled_from([t for t in MessageType if not t.is_report]),
              st.sampled_from(AckResult)),
)


@settings(max_examples=200)
@given(st.lists(st.tuples(seqs, commands), min_size=1, max_size=5))
def test_host_encode_device_decode_round_trip(items: list) -> None:
    stream = b"".join(encode_command(message, seq) for seq, message in items)
    assert len(stream) <= len(items) * MAX_FRAME
    decoder = Mpc555DeviceDecoder()
    assert decoder.feed(stream) == [Packet(seq, message) for seq, message in items]
    assert decoder.buffered == 0


@settings(max_examples=200)
@given(st.lists(st.tuples(seqs, reports), min_size=1, max_size=5))
def test_device_encode_host_decode_round_trip(items: list) -> None:
    stream = b"".join(encode_report(message, seq) for seq, message in items)
    decoder = Mpc555Decoder()
    assert decoder.feed(stream) == [Packet(seq, message) for seq, message in items]
    assert decoder.buffered == 0


# ------------------------------------------------------------------------------ properties

@settings(max_examples=200)
@given(st.binary(max_size=512), st.lists(st.integers(1, 64), max_size=8))
def test_random_bytes_never_raise(data: bytes, cuts: list[int]) -> None:
    for decoder in (Mpc555Decoder(), Mpc555DeviceDecoder()):
        start = 0
        for cut in cuts:
            decoder.feed(data[start:start + cut])
            start += cut
        decoder.feed(data[start:])
        assert decoder.buffered < MAX_FRAME


@settings(max_examples=200)
@given(st.binary(max_size=200), seqs, reports)
def test_valid_frame_after_garbage_is_decoded(garbage: bytes, seq: int, report: object) -> None:
    # A false header at the end of the garbage can hold a frame back until at most
    # MAX_FRAME further bytes arrive; the zero padding stands for later traffic.
    decoder = Mpc555Decoder()
    out = decoder.feed(garbage + encode_report(report, seq) + bytes(MAX_FRAME))  # type: ignore[arg-type]
    assert Packet(seq, report) in out


@settings(max_examples=200)
@given(seqs, commands, seqs, commands, st.data())
def test_bit_flip_is_counted_and_next_frame_decoded(
        seq: int, command: object, next_seq: int, following: object, data: st.DataObject) -> None:
    frame = bytearray(encode_command(command, seq))  # type: ignore[arg-type]
    # From the SEQ byte on, a flip can only be caught by the CRC (which catches every
    # single-bit error); flips in SYNC, VERSION, LEN or TYPE fail the header checks.
    position = data.draw(st.integers(0, len(frame) - 1))
    frame[position] ^= 1 << data.draw(st.integers(0, 7))
    decoder = Mpc555DeviceDecoder()
    good = encode_command(following, next_seq)  # type: ignore[arg-type]
    out = decoder.feed(bytes(frame) + good + bytes(MAX_FRAME))
    assert out == [Packet(next_seq, following)]
    if position >= 4:
        assert decoder.stats.checksum_failures >= 1
    else:
        assert decoder.stats.resyncs >= 1


@settings(max_examples=200)
@given(seqs, reports, st.data())
def test_truncated_frame_needs_more_and_yields_nothing(
        seq: int, report: object, data: st.DataObject) -> None:
    frame = encode_report(report, seq)  # type: ignore[arg-type]
    cut = data.draw(st.integers(0, len(frame) - 1))
    decoder = Mpc555Decoder()
    assert decoder.feed(frame[:cut]) == []
    assert decoder.buffered == cut and decoder.stats.bytes_skipped == 0
    assert decoder.feed(frame[cut:]) == [Packet(seq, report)]


def test_scan_reports_each_fault_kind() -> None:
    decoder = Mpc555Decoder()
    assert decoder.scan(bytearray(b"\x00\xa5")).fault is Fault.GARBAGE
    assert decoder.scan(bytearray(b"\xa5")).consumed == 0
    assert decoder.scan(bytearray(REPORT_FRAMES[0][0][:10])).consumed == 0
    corrupted = bytearray(REPORT_FRAMES[0][0])
    corrupted[8] ^= 0x80
    assert decoder.scan(corrupted).fault is Fault.CHECKSUM
    frame = encode_frame(0x7F, 0, b"")
    assert decoder.scan(bytearray(frame)).fault is Fault.MALFORMED
