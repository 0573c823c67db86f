"""SICK LMS 2xx telegram codec and nodding-controller framing (components.nodding_laser.codec).

Byte literals come from public captures (cited per literal) or were computed with
independent reference routines (a bitwise CRC-16/CCITT-FALSE, defined below and checked
against the published check value; SICK's CRC checked against the captures).
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from afa.errors import EOutOfBounds
from components.nodding_laser import codec as laser_codec
from components.nodding_laser.codec import (
    AckResult,
    CommandAck,
    ControllerMessage,
    ControllerStatus,
    FrameType,
    GotoAngle,
    HostCommand,
    MeasuredValues,
    NodControllerDecoder,
    NodHostCommandDecoder,
    NodScan,
    OperatingModeReply,
    RangeUnit,
    RequestMeasuredValues,
    RequestStatus,
    SetNodLimits,
    SetNodRate,
    SickAck,
    SickCommand,
    SickMessage,
    SickMode,
    SickReply,
    SickTelegram,
    SickTelegramDecoder,
    StartNodding,
    StopNodding,
    SwitchOperatingMode,
    SwitchVariant,
    VariantReply,
    controller_crc16,
    encode_controller_message,
    encode_host_command,
    encode_measured_values,
    encode_measured_words,
    encode_mode_reply,
    encode_request_measured_values,
    encode_scan_frame,
    encode_sick_message,
    encode_sick_telegram,
    encode_start_continuous,
    encode_stop_continuous,
    encode_switch_mode,
    encode_switch_variant,
    encode_variant_reply,
    nod_scan_to_points,
    parse_sick_telegram,
    scan_bearings_deg,
    scan_line_to_points,
    sick_crc16,
    udeg,
)

PROPERTY = settings(max_examples=200, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace("\n", " "))


# --------------------------------------------------------------------------------------
# Public captures
# --------------------------------------------------------------------------------------

# Host -> LMS commands as hard-coded by public LMS 2xx drivers (each byte string appears
# verbatim in several independent projects found by GitHub code search, e.g. the MRPT-based
# "SickDriver::SickLMS200" (PCLMS_START/STOP/STATUS/B9600/B19200/B38400/RES1..5/SETMODE),
# a Polish "sick_drv" (SICK_CMD_500k) and Qt "lrf_controller.h" (request_data_once)).
CAPTURED_COMMANDS = {
    "start continuous 0x20 0x24": "02 00 02 00 20 24 34 08",
    "stop continuous 0x20 0x25": "02 00 02 00 20 25 35 08",
    "status request 0x31": "02 00 01 00 31 15 12",
    "9600 baud": "02 00 02 00 20 42 52 08",
    "19200 baud": "02 00 02 00 20 41 51 08",
    "38400 baud": "02 00 02 00 20 40 50 08",
    "500000 baud": "02 00 02 00 20 48 58 08",
    "one scan 0x30 0x01": "02 00 02 00 30 01 31 18",
    "installation mode SICK_LMS": "02 00 0a 00 20 00 53 49 43 4b 5f 4c 4d 53 be c5",
    "variant 100/1.00": "02 00 05 00 3b 64 00 64 00 1d 0f",
    "variant 100/0.50": "02 00 05 00 3b 64 00 32 00 b1 59",
    "variant 100/0.25": "02 00 05 00 3b 64 00 19 00 e7 72",
    "variant 180/1.00": "02 00 05 00 3b b4 00 64 00 97 49",
    "variant 180/0.50": "02 00 05 00 3b b4 00 32 00 3b 1f",
}

# LMS -> host replies from the same MRPT-based driver (LMSPC_CMD_ACK, LMSPC_RES1..5_ACK):
# the leading 0x06 is the LMS's ACK byte, then the reply telegram.
CAPTURED_MODE_ACK = "06 02 80 03 00 a0 00 10 16 0a"
CAPTURED_VARIANT_ACKS = {
    (100, 100): "06 02 80 07 00 bb 01 64 00 64 00 10 4f bd",
    (100, 50): "06 02 80 07 00 bb 01 64 00 32 00 10 17 10",
    (100, 25): "06 02 80 07 00 bb 01 64 00 19 00 10 bb 46",
    (180, 100): "06 02 80 07 00 bb 01 b4 00 64 00 10 5b 30",
    (180, 50): "06 02 80 07 00 bb 01 b4 00 32 00 10 03 9d",
}

# A real 361-value 0xB0 telegram (180 deg / 0.5 deg, mm, status 0x10, CRC 0x4764): the
# "sim361" recording in DTU Mobotware's SICK server, usick.cpp USick::receiveSimulatedData
# (C. Andersen, DTU, LGPL). That LMS was configured for measuring mode "fields A, B, C" in
# mm (its 0x77 configuration telegram), so bit 13 is the field A flag.
CAPTURED_SCAN_361 = h("""
02 80 d6 02 b0 69 41 cb 08 cb 08 c2 08 c2 08 c3 08 ba 08 b9 08 b0 08 9e 08 89 08 62 08 44
08 21 08 13 08 f8 07 e9 07 e9 07 e2 07 e7 07 e8 07 e5 07 f0 07 e8 07 e8 07 ea 07 e3 07 e3
07 e5 07 d0 07 c2 07 b8 07 c3 07 44 07 32 07 20 07 1f 07 17 07 01 07 2b 07 55 07 5f 07 57
07 43 07 58 07 15 08 b8 08 c2 08 ab 08 44 08 ed 07 a7 07 5e 07 1c 07 d4 06 86 06 82 06 cb
06 11 09 1b 09 24 09 2d 09 36 09 36 09 3f 09 3f 09 d5 08 34 08 f3 07 07 08 05 08 15 08 1d
08 1a 08 2b 08 15 08 16 08 15 08 09 08 fb 07 d8 07 02 08 ec 07 c7 07 7f 07 90 07 a1 12 75
12 37 10 20 0f e9 0e a5 0e 65 0e 30 0e fc 0d cb 0d 9b 0d 72 0d 3e 0d 11 0d e0 0c b3 0c 93
0c 67 0c 42 0c 25 0c 3d 0c 3e 0c 06 0c ec 0b d9 0b f6 0b f2 0b 0a 0c 17 0c 32 0c 43 0c 5e
0c 79 0c 6d 0c 51 0c 3c 0c 30 0c 31 0c 3f 0c 75 0c cc 0c 0f 0d 1c 0d 89 0d d6 0d 0a 0c c6
0b c9 0d d3 0d cf 0d be 0d a3 0d 93 0d 87 0d 10 0d 6e 0d 92 0d a5 0d ac 0d ac 0d a9 0d 73
0d 6c 0d 60 0d 63 0d 5c 0d 4d 0d 45 0d 36 0d 1c 0d 13 0d d6 0c d5 0c 18 0d 1c 0d 16 0d 1c
0d f1 0c e9 0c e2 0c dc 0c e5 0c d2 0c cd 0c e6 0c d2 0c d8 0c d0 0c db 0c d7 0c e1 0c d5
0c d7 0c dc 0c db 0c d9 0c e4 0c e4 0c e6 0c e2 0c e8 0c e8 0c ec 0c fb 0c ed 0c f1 0c f6
0c fd 0c 03 0d 07 0d 0a 0d 1d 0d 1e 0d 27 0d 36 0d 44 0d 3c 0d 37 0d 41 0d 4a 0d 54 0d 62
0d 5b 0d 62 0d 77 0d 76 0a 71 0a 83 0a 82 0a 81 0a 80 0a 81 0a 82 0a 72 0a 92 0a 98 0d b1
0c bc 0c 26 0c 89 0b 20 0b 3d 0b a8 0b af 0b b4 0b c0 0b c6 0b d0 0b da 0b e2 0b e8 0b ed
0b f8 0b 0a 0c 03 0c 0f 0c 35 0c 41 0c 39 0c 28 0c f2 0b b7 0b 5a 0e cf 0d 92 0b b9 08 45
08 43 08 ab 08 26 0b 4f 0b 83 0b 30 0c 7f 0d 37 11 68 0f 70 0b 41 0b 7a 22 65 22 63 22 58
22 49 22 43 22 3e 22 33 22 2c 22 25 22 1d 22 15 22 15 22 18 22 07 22 05 22 00 22 ff 21 fd
21 f8 21 f1 21 e3 21 e0 21 d9 21 d2 21 d7 21 cb 21 d0 21 da 21 cf 21 cf 21 d0 21 cb 21 ca
21 c2 21 c2 21 b9 21 b9 21 b4 21 b0 21 af 21 9e 21 97 21 98 21 a4 21 a1 21 9c 21 c2 21 c3
21 bf 21 bf 21 c1 21 b4 21 b8 21 bf 21 c3 21 bd 21 c8 21 ca 21 c0 21 d0 21 d1 21 c5 21 ca
21 d1 21 f0 21 32 22 2f 22 2b 22 2f 22 2a 22 2f 22 2f 22 4f 22 5d 22 5e 22 70 22 86 22 b5
22 cc 22 1c 23 3c 05 48 05 d4 21 2f 23 fe 22 c0 22 2b 23 3c 05 3a 05 33 05 33 05 28 05 1e
05 1b 23 b1 22 d7 22 18 05 10 64 47
""")


# Built from the capture's bytes directly, not through the decoder under test.
CAPTURED_VALUES = MeasuredValues(struct.unpack_from("<361H", CAPTURED_SCAN_361, 7))


def ccitt_false_reference(data: bytes) -> int:
    """Bitwise CRC-16/CCITT-FALSE, independent of the code under test (which uses
    binascii.crc_hqx)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


# Controller frames computed by hand from the spec in docs/protocols/nodding_laser.md with
# ccitt_false_reference (header CRC over bytes 0-7, frame CRC over all preceding bytes).
FRAME_START_NODDING_SEQ7 = h("a5 4e 01 83 07 00 00 00 82 c8 89 0b")
FRAME_SET_RATE_15DEG_SEQ8 = h("a5 4e 01 81 08 00 04 00 2b 94 c0 e1 e4 00 bb 8d")
FRAME_SET_LIMITS_M40_M10_SEQ9 = h(
    "a5 4e 01 82 09 00 08 00 20 49 00 a6 9d fd 80 69 67 ff 8e fa")
FRAME_ACK_START_SEQ21 = h("a5 4e 01 03 21 00 03 00 d6 af 83 07 00 65 ff")
# 0xB0 with 3 values in mm: 1000 mm; 500 mm + field A (bit 13); 0x1FFF (no return).
SMALL_B0 = h("02 80 0a 00 b0 03 40 e8 03 f4 21 ff 1f 10 63 8a")
SMALL_VALUES = MeasuredValues((1000, 0x2000 | 500, 0x1FFF))
# SCAN frame: counter 42, t = 1 234 567 us, nod -40.0 -> -39.6 deg, SMALL_B0 inside.
FRAME_SCAN_SEQ10 = h("""
a5 4e 01 01 10 00 24 00 79 2e 2a 00 00 00 87 d6 12 00 00 00 00 00 00 a6 9d fd 80 c0 a3 fd
02 80 0a 00 b0 03 40 e8 03 f4 21 ff 1f 10 63 8a e8 2d""")
# cm mode: 250 cm and 0x1FF7 (8183, the smallest no-return code).
SMALL_B0_CM = h("02 80 08 00 b0 02 00 fa 00 f7 1f 10 21 b3")


# --------------------------------------------------------------------------------------
# SICK telegrams: byte literals
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(CAPTURED_COMMANDS))
def test_sick_crc_matches_captured_commands(name: str) -> None:
    frame = h(CAPTURED_COMMANDS[name])
    assert sick_crc16(frame[:-2]) == struct.unpack("<H", frame[-2:])[0]


def test_sick_crc_matches_captured_scan() -> None:
    assert len(CAPTURED_SCAN_361) == 732
    assert sick_crc16(CAPTURED_SCAN_361[:-2]) == 0x4764


def test_host_encoders_reproduce_captured_commands() -> None:
    c = CAPTURED_COMMANDS
    assert encode_start_continuous() == h(c["start continuous 0x20 0x24"])
    assert encode_stop_continuous() == h(c["stop continuous 0x20 0x25"])
    assert encode_sick_telegram(0x31) == h(c["status request 0x31"])
    assert encode_switch_mode(SickMode.BAUD_9600) == h(c["9600 baud"])
    assert encode_switch_mode(SickMode.BAUD_19200) == h(c["19200 baud"])
    assert encode_switch_mode(SickMode.BAUD_38400) == h(c["38400 baud"])
    assert encode_switch_mode(SickMode.BAUD_500000) == h(c["500000 baud"])
    assert encode_request_measured_values() == h(c["one scan 0x30 0x01"])
    assert (encode_switch_mode(SickMode.INSTALLATION, b"SICK_LMS")
            == h(c["installation mode SICK_LMS"]))
    assert encode_switch_variant(100, 100) == h(c["variant 100/1.00"])
    assert encode_switch_variant(100, 50) == h(c["variant 100/0.50"])
    assert encode_switch_variant(100, 25) == h(c["variant 100/0.25"])
    assert encode_switch_variant(180, 100) == h(c["variant 180/1.00"])
    assert encode_switch_variant(180, 50) == h(c["variant 180/0.50"])


def test_device_encoders_reproduce_captured_replies() -> None:
    assert b"\x06" + encode_mode_reply(0, 0x10) == h(CAPTURED_MODE_ACK)
    for (angle, resolution), text in CAPTURED_VARIANT_ACKS.items():
        assert b"\x06" + encode_variant_reply(True, angle, resolution, 0x10) == h(text)


def test_captured_scan_decodes() -> None:
    decoder = SickTelegramDecoder()
    [values] = decoder.feed(CAPTURED_SCAN_361)
    assert isinstance(values, MeasuredValues)
    assert values.count == 361
    assert values.unit is RangeUnit.MM
    assert values.status == 0x10 and values.error_class == 0
    assert values.partial_scan_index == 0
    assert (values.scan_angle_deg, values.resolution_cdeg) == (180, 50)
    assert values.start_angle_deg == 0.0
    assert values.raw[:3] == (0x08CB, 0x08CB, 0x08C2)
    assert values.ranges[0] == pytest.approx(2.251)
    assert values.raw[-1] == 0x0518 and values.ranges[-1] == pytest.approx(1.304)
    # 0x227A: bit 13 (field A) set, range 0x027A = 634 mm
    index = values.raw.index(0x227A)
    assert values.range_counts[index] == 634
    assert values.flags[index] == 0b001
    assert values.ranges_array().dtype == np.float32
    assert values.valid_mask().all()
    assert decoder.stats.frames == 1 and decoder.stats.bytes_skipped == 0


def test_device_encoder_reproduces_captured_scan() -> None:
    assert encode_measured_values(CAPTURED_VALUES) == CAPTURED_SCAN_361
    assert parse_sick_telegram(CAPTURED_SCAN_361) == CAPTURED_VALUES


def test_captured_replies_decode_with_ack_byte() -> None:
    decoder = SickTelegramDecoder()
    assert decoder.feed(h(CAPTURED_MODE_ACK)) == [SickAck(True), OperatingModeReply(0, 0x10)]
    assert decoder.feed(h(CAPTURED_VARIANT_ACKS[(180, 50)])) == [
        SickAck(True), VariantReply(True, 180, 50, 0x10)]
    assert decoder.feed(b"\x15") == [SickAck(False)]


def test_captured_commands_decode_on_the_device_side() -> None:
    c = CAPTURED_COMMANDS
    assert parse_sick_telegram(h(c["start continuous 0x20 0x24"])) == SwitchOperatingMode(0x24)
    assert parse_sick_telegram(h(c["installation mode SICK_LMS"])) == SwitchOperatingMode(
        0x00, b"SICK_LMS")
    assert parse_sick_telegram(h(c["variant 100/0.25"])) == SwitchVariant(100, 25)
    assert parse_sick_telegram(h(c["one scan 0x30 0x01"])) == RequestMeasuredValues(1)
    assert parse_sick_telegram(h(c["status request 0x31"])) == SickTelegram(0x31, b"", 0x00)


def test_small_b0_flags_and_no_return_codes() -> None:
    values = parse_sick_telegram(SMALL_B0)
    assert isinstance(values, MeasuredValues)
    assert values.raw == (1000, 0x2000 | 500, 0x1FFF)
    assert values.unit is RangeUnit.MM
    assert values.range_counts == (1000, 500, 8191)
    assert values.flags == (0, 1, 0)
    assert values.ranges == pytest.approx((1.0, 0.5, 8.191))
    assert values.valid_mask().tolist() == [True, True, False]
    assert values.scan_angle_deg is None  # 3 values are no full-scan variant


def test_cm_mode_unit_and_first_no_return_code() -> None:
    values = parse_sick_telegram(SMALL_B0_CM)
    assert isinstance(values, MeasuredValues)
    assert values.unit is RangeUnit.CM
    assert values.ranges[0] == pytest.approx(2.5)
    assert values.no_return_threshold == 8183
    assert values.valid_mask().tolist() == [True, False]


def test_range_bits_for_other_measuring_modes() -> None:
    # 32 m mode: 15 range bits, so 0x227A is 8826 mm with no flag
    [values] = SickTelegramDecoder(range_bits=15).feed(CAPTURED_SCAN_361)
    assert isinstance(values, MeasuredValues)
    index = values.raw.index(0x227A)
    assert values.range_counts[index] == 0x227A
    assert values.flags[index] == 0


def test_parse_rejects_bad_telegrams() -> None:
    with pytest.raises(EOutOfBounds):
        parse_sick_telegram(SMALL_B0[:-1] + bytes([SMALL_B0[-1] ^ 1]))
    with pytest.raises(EOutOfBounds):
        parse_sick_telegram(SMALL_B0[:-1])
    with pytest.raises(EOutOfBounds):
        parse_sick_telegram(b"\x03" + SMALL_B0[1:])


def test_encoders_reject_bad_arguments() -> None:
    with pytest.raises(EOutOfBounds):
        encode_switch_variant(180, 25)  # 0.25 deg only with the 100 deg field
    with pytest.raises(EOutOfBounds):
        encode_sick_telegram(0x20, b"\x24", address=0x80)  # reply address, no status
    with pytest.raises(EOutOfBounds):
        encode_sick_telegram(0x20, bytes(812))
    with pytest.raises(EOutOfBounds):
        encode_host_command(SetNodLimits(udeg(-10), udeg(-40)))
    with pytest.raises(EOutOfBounds):
        encode_host_command(SetNodRate(0))
    with pytest.raises(EOutOfBounds):
        encode_measured_values(MeasuredValues((0x1_0000,)))


# --------------------------------------------------------------------------------------
# Controller framing: byte literals
# --------------------------------------------------------------------------------------

def test_controller_crc_check_value() -> None:
    # CRC-16/CCITT-FALSE check value from the CRC catalogue (reveng): 0x29B1
    assert ccitt_false_reference(b"123456789") == 0x29B1
    assert controller_crc16(b"123456789") == 0x29B1


def test_host_command_literals() -> None:
    assert encode_host_command(StartNodding(seq=7)) == FRAME_START_NODDING_SEQ7
    assert encode_host_command(SetNodRate(udeg(15.0), seq=8)) == FRAME_SET_RATE_15DEG_SEQ8
    assert (encode_host_command(SetNodLimits(udeg(-40.0), udeg(-10.0), seq=9))
            == FRAME_SET_LIMITS_M40_M10_SEQ9)


def test_host_command_literals_decode_on_the_device_side() -> None:
    decoder = NodHostCommandDecoder()
    stream = FRAME_START_NODDING_SEQ7 + FRAME_SET_RATE_15DEG_SEQ8 + FRAME_SET_LIMITS_M40_M10_SEQ9
    assert decoder.feed(stream) == [
        StartNodding(seq=7), SetNodRate(15_000_000, seq=8),
        SetNodLimits(-40_000_000, -10_000_000, seq=9)]
    assert decoder.stats.frames == 3 and decoder.stats.bytes_skipped == 0


def test_controller_frame_literals() -> None:
    ack = CommandAck(FrameType.START_NODDING, 7, AckResult.OK, seq=0x21)
    assert encode_controller_message(ack) == FRAME_ACK_START_SEQ21
    scan = NodScan(42, 1_234_567, -40_000_000, -39_600_000, SMALL_VALUES, seq=0x10)
    assert encode_controller_message(scan) == FRAME_SCAN_SEQ10


def test_scan_frame_literal_decodes_on_the_host_side() -> None:
    decoder = NodControllerDecoder()
    [scan] = decoder.feed(FRAME_SCAN_SEQ10)
    assert isinstance(scan, NodScan)
    assert (scan.scan_counter, scan.timestamp_us, scan.seq) == (42, 1_234_567, 0x10)
    assert scan.nod_start_deg == pytest.approx(-40.0)
    assert scan.nod_end_deg == pytest.approx(-39.6)
    assert scan.measured.raw == (1000, 0x2000 | 500, 0x1FFF)
    [ack] = decoder.feed(FRAME_ACK_START_SEQ21)
    assert ack == CommandAck(0x83, 7, 0, seq=0x21) and ack.ok


def test_frames_of_the_wrong_direction_are_malformed() -> None:
    host = NodControllerDecoder()
    assert host.feed(FRAME_START_NODDING_SEQ7) == []
    assert host.stats.malformed == 1
    device = NodHostCommandDecoder()
    assert device.feed(FRAME_ACK_START_SEQ21) == []
    assert device.stats.malformed == 1


# --------------------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------------------


CONTROLLER_MESSAGES: list[ControllerMessage] = [
    NodScan(1, 10_000, udeg(-40), udeg(-39.6), CAPTURED_VALUES, seq=1),
    NodScan(0xFFFFFFFF, (1 << 64) - 1, -(1 << 31), (1 << 31) - 1,
            MeasuredValues((0, 0xFFFF), RangeUnit.CM, 0x07, 3), seq=255),
    ControllerStatus(1, 0b0101, udeg(-25.5), udeg(-40), udeg(-10), udeg(15), 99, seq=2),
    CommandAck(FrameType.SET_NOD_LIMITS, 9, AckResult.BUSY, seq=3),
    SickReply(0x06, VariantReply(True, 180, 50, 0x10), seq=4),
    SickReply(0x06, OperatingModeReply(0, 0x10), seq=5),
    SickReply(0x06, SickTelegram(0x92, b"\x01", 0x80, 0x10), seq=6),
    SickReply(0x15, None, seq=7),
]

HOST_COMMANDS: list[HostCommand] = [
    SetNodRate(udeg(15), seq=1),
    SetNodLimits(udeg(-40), udeg(-10), seq=2),
    StartNodding(seq=3),
    StopNodding(seq=4),
    GotoAngle(udeg(-14), seq=5),
    RequestStatus(seq=6),
    SickCommand(SwitchVariant(180, 50), seq=7),
    SickCommand(SwitchOperatingMode(SickMode.MONITOR_STREAM_VALUES), seq=8),
    SickCommand(SwitchOperatingMode(SickMode.INSTALLATION, b"SICK_LMS"), seq=9),
    SickCommand(RequestMeasuredValues(), seq=10),
    SickCommand(SickTelegram(0x31), seq=11),
]


def test_controller_messages_round_trip() -> None:
    stream = b"".join(encode_controller_message(m) for m in CONTROLLER_MESSAGES)
    decoder = NodControllerDecoder()
    assert decoder.feed(stream) == CONTROLLER_MESSAGES
    assert decoder.stats.bytes_skipped == 0


def test_controller_messages_round_trip_byte_by_byte() -> None:
    stream = b"".join(encode_controller_message(m) for m in CONTROLLER_MESSAGES)
    decoder = NodControllerDecoder()
    out = [m for i in range(len(stream)) for m in decoder.feed(stream[i:i + 1])]
    assert out == CONTROLLER_MESSAGES


def test_host_commands_round_trip() -> None:
    stream = b"".join(encode_host_command(c) for c in HOST_COMMANDS)
    decoder = NodHostCommandDecoder()
    assert decoder.feed(stream) == HOST_COMMANDS
    assert decoder.stats.bytes_skipped == 0


def test_sick_messages_round_trip_both_directions() -> None:
    messages: list[SickMessage] = [
        SickAck(True), OperatingModeReply(1, 0x10), SickAck(False),
        VariantReply(False, 100, 25, 0x13), CAPTURED_VALUES,
        MeasuredValues((1, 2, 3), RangeUnit.CM, 0x10, partial_scan_index=2),
        SwitchOperatingMode(0x48), SwitchVariant(100, 50), RequestMeasuredValues(),
        SickTelegram(0x31), SickTelegram(0x92, b"", 0x80, 0x10),
    ]
    stream = b"".join(encode_sick_message(m) for m in messages)
    assert SickTelegramDecoder().feed(stream) == messages


# --------------------------------------------------------------------------------------
# Properties
# --------------------------------------------------------------------------------------

DECODERS = [NodControllerDecoder, NodHostCommandDecoder, SickTelegramDecoder]
VALID_CONTROLLER = encode_controller_message(
    NodScan(7, 123, udeg(-30), udeg(-29.5), SMALL_VALUES, seq=9))
VALID_CONTROLLER_2 = encode_controller_message(ControllerStatus(0, 0, 1, 2, 3, 4, 5, seq=1))
VALID_COMMAND = encode_host_command(SickCommand(SwitchVariant(180, 50), seq=3))
VALID_SICK = SMALL_B0


@PROPERTY
@given(data=st.binary(max_size=600), cut=st.integers(0, 600))
def test_random_bytes_never_raise(data: bytes, cut: int) -> None:
    for decoder_type in DECODERS:
        decoder = decoder_type()
        decoder.feed(data[:cut])
        decoder.feed(data[cut:])
        assert decoder.stats.bytes_in == len(data)


@PROPERTY
@given(data=st.lists(st.sampled_from([b"\xa5", b"\x4e", b"\xa5\x4e\x01", b"\x02", b"\x80",
                                      b"\x06", b"\x15", b"\x00", b"\xff"]), max_size=80))
def test_sync_heavy_bytes_never_raise(data: list[bytes]) -> None:
    stream = b"".join(data)
    for decoder_type in DECODERS:
        decoder_type().feed(stream)


@PROPERTY
@given(garbage=st.binary(max_size=300))
def test_controller_frame_after_garbage_is_decoded(garbage: bytes) -> None:
    decoder = NodControllerDecoder()
    out = decoder.feed(garbage + VALID_CONTROLLER)
    assert out and out[-1] == NodControllerDecoder().feed(VALID_CONTROLLER)[0]


@PROPERTY
@given(garbage=st.binary(max_size=300))
def test_host_command_after_garbage_is_decoded(garbage: bytes) -> None:
    out = NodHostCommandDecoder().feed(garbage + VALID_COMMAND)
    assert out and out[-1] == SickCommand(SwitchVariant(180, 50), seq=3)


@PROPERTY
@given(garbage=st.binary(max_size=300))
def test_sick_telegram_after_garbage_is_decoded(garbage: bytes) -> None:
    # SICK framing has no header check: a false STX in the garbage may wait for up to
    # MAX_TELEGRAM_LENGTH bytes, which the continuing stream (here zeros) supplies.
    out = SickTelegramDecoder().feed(garbage + VALID_SICK + bytes(1024))
    assert parse_sick_telegram(VALID_SICK) in out


def _flip(frame: bytes, position: int, bit: int) -> bytes:
    corrupted = bytearray(frame)
    corrupted[position] ^= 1 << bit
    return bytes(corrupted)


@PROPERTY
@given(position=st.integers(2, len(VALID_CONTROLLER) - 1), bit=st.integers(0, 7))
def test_controller_bit_flip_is_counted_and_next_frame_decoded(position: int, bit: int) -> None:
    decoder = NodControllerDecoder()
    out = decoder.feed(_flip(VALID_CONTROLLER, position, bit) + VALID_CONTROLLER_2)
    assert out == [ControllerStatus(0, 0, 1, 2, 3, 4, 5, seq=1)]
    assert decoder.stats.checksum_failures >= 1


@PROPERTY
@given(position=st.integers(2, len(VALID_COMMAND) - 1), bit=st.integers(0, 7))
def test_command_bit_flip_is_counted_and_next_frame_decoded(position: int, bit: int) -> None:
    decoder = NodHostCommandDecoder()
    out = decoder.feed(_flip(VALID_COMMAND, position, bit) + FRAME_START_NODDING_SEQ7)
    assert out == [StartNodding(seq=7)]
    assert decoder.stats.checksum_failures >= 1


@PROPERTY
@given(position=st.integers(0, len(VALID_SICK) - 1), bit=st.integers(0, 7))
def test_sick_bit_flip_is_counted_and_next_telegram_decoded(position: int, bit: int) -> None:
    decoder = SickTelegramDecoder()
    out = decoder.feed(_flip(VALID_SICK, position, bit) + VALID_SICK + bytes(1024))
    expected = parse_sick_telegram(VALID_SICK)
    assert out.count(expected) == 1  # the corrupted copy never decodes
    if position == 0:
        assert decoder.stats.bytes_skipped > 0  # STX destroyed: skipped as garbage
    elif position in (2, 3):
        assert decoder.stats.checksum_failures + decoder.stats.malformed >= 1
    else:
        assert decoder.stats.checksum_failures >= 1


@pytest.mark.parametrize("frame", [VALID_CONTROLLER, VALID_COMMAND, VALID_SICK,
                                   CAPTURED_SCAN_361], ids=["scan", "command", "sick", "361"])
def test_truncation_needs_more_and_yields_nothing(frame: bytes) -> None:
    decoder_type = (SickTelegramDecoder if frame[0] == 0x02 else
                    NodControllerDecoder if frame is VALID_CONTROLLER else NodHostCommandDecoder)
    for cut in range(1, len(frame)):
        decoder = decoder_type()
        assert decoder.feed(frame[:cut]) == []
        assert decoder.buffered == cut
        assert decoder.stats.bytes_skipped == 0 and decoder.stats.frames == 0


@PROPERTY
@given(raw=st.lists(st.integers(0, 0xFFFF), max_size=401), unit=st.sampled_from(RangeUnit),
       status=st.integers(0, 255), partial=st.integers(0, 3),
       counter=st.integers(0, 0xFFFFFFFF), stamp=st.integers(0, (1 << 64) - 1),
       start=st.integers(-(1 << 31), (1 << 31) - 1), seq=st.integers(0, 255))
def test_any_scan_round_trips(raw: list[int], unit: RangeUnit, status: int, partial: int,
                              counter: int, stamp: int, start: int, seq: int) -> None:
    scan = NodScan(counter, stamp, start, -start - 1,
                   MeasuredValues(tuple(raw), unit, status, partial), seq)
    assert NodControllerDecoder().feed(encode_controller_message(scan)) == [scan]


# --------------------------------------------------------------------------------------
# Scan line -> 3-D points (hand-computed)
# --------------------------------------------------------------------------------------

def test_bearings_of_the_variants() -> None:
    bearings = scan_bearings_deg(361, 180, 50)
    assert bearings[[0, 1, 180, 360]].tolist() == [0.0, 0.5, 90.0, 180.0]
    bearings = scan_bearings_deg(101, 100, 100)
    assert (bearings[0], bearings[50], bearings[-1]) == (40.0, 90.0, 140.0)
    with pytest.raises(EOutOfBounds):
        scan_bearings_deg(721, 180, 25)


def test_points_hand_computed() -> None:
    s2 = math.sqrt(2.0)
    points = scan_line_to_points([2.0, 1.0, 1.0, s2], [90.0, 0.0, 180.0, 45.0], -30.0)
    expected = [
        [2 * math.cos(math.radians(30)), 0.0, -1.0],  # ahead, 30 deg down: (1.732, 0, -1)
        [0.0, -1.0, 0.0],  # bearing 0 = right, on the nod axis
        [0.0, 1.0, 0.0],  # bearing 180 = left
        [math.cos(math.radians(30)), -1.0, -0.5],  # 45 deg right of ahead, 1 m forward
    ]
    np.testing.assert_allclose(points, expected, atol=1e-12)
    points = scan_line_to_points([s2], [135.0], -45.0)
    np.testing.assert_allclose(points, [[math.sqrt(0.5), 1.0, -math.sqrt(0.5)]], atol=1e-12)


def test_points_interpolate_nod_and_drop_invalid() -> None:
    points = scan_line_to_points([1.0, 1.0, 1.0, 0.0, float("nan")], [90.0] * 5,
                                 (-40.0, -20.0))
    # five beams, nod -40, -35, -30, -25, -20; the last two have no range
    np.testing.assert_allclose(points[:, 2], [-math.sin(math.radians(a))
                                              for a in (40, 35, 30)], atol=1e-12)
    points = scan_line_to_points([1.0, 1.0], [90.0, 90.0], 0.0, valid=[False, True])
    np.testing.assert_allclose(points, [[1.0, 0.0, 0.0]], atol=1e-12)


def test_nod_scan_to_points_excludes_no_return_codes() -> None:
    raw = [0] * 181
    raw[90] = 2000  # 2 m straight ahead
    raw[0] = 8183  # no-return code at bearing 0
    raw[180] = 1000 | 0x2000  # field A flag, 1 m to the left
    scan = NodScan(1, 0, udeg(-12), udeg(-8), MeasuredValues(tuple(raw)))
    points = nod_scan_to_points(scan, offset_deg=-2.0)
    # beam 90 of 181 is halfway: nod (-14 + -10) / 2 = -12 deg after the offset
    np.testing.assert_allclose(points, [
        [2 * math.cos(math.radians(12)), 0.0, -2 * math.sin(math.radians(12))],
        [0.0, 1.0, 0.0],
    ], atol=1e-6)
    with pytest.raises(EOutOfBounds):
        nod_scan_to_points(NodScan(1, 0, 0, 0, MeasuredValues((1000, 1000))))
    assert nod_scan_to_points(NodScan(1, 0, 0, 0, MeasuredValues((1000, 1000))),
                              variant=(100, 100)).shape == (2, 3)


@settings(max_examples=200)
@given(st.binary(max_size=1100))
def test_the_table_driven_crc_equals_the_manuals_byte_by_byte_routine(data):
    from components.nodding_laser.codec import sick_crc16_reference

    assert sick_crc16(data) == sick_crc16_reference(data)


@pytest.mark.parametrize("form", ["compiled", "numpy"])
def test_both_crc_forms_equal_the_manuals_routine(form: str, monkeypatch) -> None:
    """The compiled loop (decision 0021) and the numpy table give the listing's CRC, on
    the captured scan, a bytearray and random telegram-sized data."""
    from components.nodding_laser import codec

    if form == "compiled":
        pytest.importorskip("numba")
        if codec._crc_kernel() is None:
            pytest.skip("numba cannot compile here (or AFA_KERNELS=numpy)")
    else:
        monkeypatch.setattr(codec, "_crc_kernel", lambda: None)
    rng = np.random.default_rng(7)
    samples = [b"", b"\x02", CAPTURED_SCAN_361[:-2], bytearray(CAPTURED_SCAN_361[:-2])]
    samples += [rng.bytes(int(n)) for n in rng.integers(1, 1100, 40)]
    for data in samples:
        assert codec.sick_crc16(data) == codec.sick_crc16_reference(data)
    assert codec.sick_crc16(CAPTURED_SCAN_361[:-2]) == 0x4764


# -- value words from an array (the emulator's path, decision 0030) ---------------------------

@PROPERTY
@given(words=st.lists(st.integers(0, 0xFFFF), max_size=0x3FF),
       status=st.integers(0, 0xFF), counter=st.integers(0, 0xFFFFFFFF),
       stamp=st.integers(0, (1 << 64) - 1), start=st.integers(-(1 << 31), (1 << 31) - 1),
       end=st.integers(-(1 << 31), (1 << 31) - 1), seq=st.integers(0, 0xFF),
       dtype=st.sampled_from([np.int64, np.uint16, np.int32, np.uint32]))
def test_words_from_an_array_encode_as_the_tuple_does(words: list[int], status: int,
                                                     counter: int, stamp: int, start: int,
                                                     end: int, seq: int, dtype: type) -> None:
    array = np.array(words, dtype=dtype)
    values = MeasuredValues(tuple(words), RangeUnit.MM, status)
    assert encode_measured_words(array, status=status) == encode_measured_values(values)
    scan = NodScan(counter, stamp, start, end, values, seq)
    assert encode_scan_frame(counter, stamp, start, end, array, seq=seq, status=status) \
        == encode_controller_message(scan)


def test_words_from_an_array_are_refused_as_the_tuple_is() -> None:
    for words in ([0x10000], [-1], [5, 0x1FFFF]):
        with pytest.raises(EOutOfBounds):
            encode_measured_values(MeasuredValues(tuple(words)))
        with pytest.raises(EOutOfBounds):
            encode_measured_words(np.array(words, dtype=np.int64))
    with pytest.raises(EOutOfBounds):
        encode_measured_words(np.zeros(0x400, dtype=np.uint16))
    with pytest.raises(EOutOfBounds):  # not integers
        encode_measured_words(np.array([1.5, 2.0]))
    with pytest.raises(EOutOfBounds):
        encode_scan_frame(1 << 32, 0, 0, 0, np.zeros(3, dtype=np.uint16))


# -- the driver's scan line, compiled and numpy (decision 0030) --------------------------------

def _numpy_scan_line(geometry, measured, nod, monkeypatch):
    monkeypatch.setattr(laser_codec, "_points_kernel", lambda: None)
    try:
        return geometry.scan_line(measured, nod)
    finally:
        monkeypatch.undo()


@pytest.mark.skipif(laser_codec._points_kernel() is None,
                    reason="no compiled kernel (numba missing, or AFA_KERNELS=numpy)")
@pytest.mark.parametrize("count, variant", [(361, (180, 50)), (181, (180, 100)),
                                            (401, (100, 25))])
def test_compiled_scan_line_is_bit_for_bit_the_numpy_one(count, variant, monkeypatch):
    geometry = laser_codec.ScanLineGeometry(scan_bearings_deg(count, *variant))
    rng = np.random.default_rng(count)
    for trial in range(40):
        range_bits = (13, 14, 16)[trial % 3]
        unit = (RangeUnit.MM, RangeUnit.CM)[trial % 2]
        words = rng.integers(0, 1 << 16, count)  # flags above the range field too
        words[rng.random(count) < 0.2] = 0
        threshold = (1 << range_bits) - laser_codec.NO_RETURN_CODES
        words[rng.random(count) < 0.2] = threshold + rng.integers(0, laser_codec.NO_RETURN_CODES)
        measured = MeasuredValues(tuple(int(w) for w in words), unit, range_bits=range_bits)
        nod = (rng.uniform(-40, 10), rng.uniform(-40, 10))
        points, valid = geometry.scan_line(measured, nod)
        expected_points, expected_valid = _numpy_scan_line(geometry, measured, nod,
                                                           monkeypatch)
        assert points.dtype == np.float32 and points.shape == (count, 3)
        assert points.tobytes() == expected_points.tobytes()  # NaNs and signed zeros too
        np.testing.assert_array_equal(valid, expected_valid)
        assert valid.dtype == np.bool_ and 0 < valid.sum() < count


def test_scan_line_of_the_wrong_count_is_refused():
    geometry = laser_codec.ScanLineGeometry(scan_bearings_deg(361, 180, 50))
    with pytest.raises(EOutOfBounds):
        geometry.scan_line(MeasuredValues((1000,) * 181), (0.0, 0.0))

