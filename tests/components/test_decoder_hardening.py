"""Every device decoder against hostile byte streams.

- **Linear work.** Whatever the bytes, decoding costs a bounded amount of work per byte
  fed, in any chunking: the work for 8N bytes is at most ~10x the work for N bytes, and
  never more than a per-decoder budget per byte. Work is counted, not timed: every
  ``scan()`` call plus every byte the decoder reads out of its buffer (an instrumented
  ``bytearray`` counts indexing, slicing, ``find`` and iteration; ``struct.unpack_from``
  reads a fixed handful of header bytes and is covered by the count of scan calls).
- **Chunking does not matter.** Feeding a stream in any chunks yields the messages
  feeding it whole yields.
- **A damaged frame never swallows an intact one.** A frame that lost its tail (its
  checksum, its line end), followed by an intact frame: the intact frame decodes.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass
from datetime import date
from typing import Any, ClassVar, SupportsIndex

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from afa.codec import Scan, StreamDecoder
from components.gps_sokkia.codec import (
    BestPos,
    BestVel,
    CommandResponse,
    Gga,
    GpsDecoder,
    GpsDeviceDecoder,
    LogHeader,
    PositionType,
    Rmc,
    SolutionStatus,
    TimeStatus,
    Vtg,
    encode_bestpos_ascii,
    encode_bestpos_binary,
    encode_bestvel_ascii,
    encode_bestvel_binary,
    encode_gga,
    encode_log_command,
    encode_prompt,
    encode_response,
    encode_rmc,
    encode_unlogall_command,
    encode_vtg,
)
from components.imu.codec import (
    CMD_GYRO_STAB_EULER_ACCEL_RATE,
    COMMAND_LENGTHS,
    REPLY_LENGTHS,
    ImuDecoder,
    ImuDeviceDecoder,
    encode_euler_accel_rate_reply,
    encode_euler_angles_reply,
    encode_poll,
    encode_read_eeprom,
    encode_set_continuous,
    encode_temperature_reply,
    encode_write_eeprom,
)
from components.mpc555.codec import (
    CommandAck,
    Mpc555Decoder,
    Mpc555DeviceDecoder,
    PedalBreakpoint,
    SetPedalCalibration,
    SetVelocity,
    SpeedReport,
    StartVehicle,
    WheelDistanceReport,
    encode_command,
    encode_report,
)
from components.nodding_laser.codec import (
    ACK,
    NAK,
    ControllerStatus,
    MeasuredValues,
    NodControllerDecoder,
    NodHostCommandDecoder,
    NodScan,
    SetNodRate,
    SickAck,
    SickTelegramDecoder,
    StartNodding,
    SwitchVariant,
    encode_controller_frame,
    encode_controller_message,
    encode_host_command,
    encode_measured_values,
    encode_mode_reply,
    encode_switch_variant,
    encode_variant_reply,
)

PROPERTY = settings(max_examples=50, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


# --------------------------------------------------------------------------------------
# Counting the work
# --------------------------------------------------------------------------------------

class CountingBuffer(bytearray):
    """A decoder buffer that counts every byte read out of it at Python level."""

    examined: ClassVar[int] = 0

    def __getitem__(self, index: Any) -> Any:
        result = super().__getitem__(index)
        CountingBuffer.examined += len(result) if isinstance(index, slice) else 1
        return result

    def __iter__(self) -> Any:
        for byte in super().__iter__():
            CountingBuffer.examined += 1
            yield byte

    def _span(self, start: SupportsIndex | None, end: SupportsIndex | None) -> tuple[int, int]:
        s, e, _ = slice(start, end).indices(len(self))
        return s, e

    def find(self, sub: Any, start: SupportsIndex | None = None,  # type: ignore[override]
             end: SupportsIndex | None = None) -> int:
        s, e = self._span(start, end)
        position = super().find(sub, s, e)
        width = 1 if isinstance(sub, int) else len(sub)
        CountingBuffer.examined += (position + width - s) if position >= 0 else max(0, e - s)
        return position

    def index(self, sub: Any, start: SupportsIndex | None = None,  # type: ignore[override]
              end: SupportsIndex | None = None) -> int:
        position = self.find(sub, start, end)
        if position < 0:
            raise ValueError("subsection not found")
        return position

    def count(self, sub: Any, start: SupportsIndex | None = None,  # type: ignore[override]
              end: SupportsIndex | None = None) -> int:
        s, e = self._span(start, end)
        CountingBuffer.examined += max(0, e - s)
        return super().count(sub, s, e)

    def startswith(self, prefix: Any, *args: Any) -> bool:  # type: ignore[override]
        CountingBuffer.examined += len(prefix) if isinstance(prefix, bytes | bytearray) else 8
        return super().startswith(prefix, *args)

    def __contains__(self, item: Any) -> bool:
        CountingBuffer.examined += len(self)
        return super().__contains__(item)


SCANS = 0


def instrumented(decoder_type: type[StreamDecoder[Any]]) -> type[StreamDecoder[Any]]:
    """A subclass whose buffer counts bytes read and whose scan() counts calls. A decoder
    that makes helper decoders of its own type (the GPS lookahead) is counted whole."""

    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        decoder_type.__init__(self, *args, **kwargs)
        self._buffer = CountingBuffer()

    def scan(self: Any, buffer: bytearray) -> Scan[Any]:
        global SCANS
        SCANS += 1
        return decoder_type.scan(self, buffer)

    return type(f"Counting{decoder_type.__name__}", (decoder_type,),
                {"__init__": __init__, "scan": scan})


def work(decoder_type: type[StreamDecoder[Any]], data: bytes, chunk: int) -> int:
    """scan() calls plus bytes read out of the buffer, feeding ``data`` in ``chunk``s."""
    global SCANS
    decoder = instrumented(decoder_type)()
    CountingBuffer.examined = 0
    SCANS = 0
    for start in range(0, len(data), chunk):
        decoder.feed(data[start:start + chunk])
    return SCANS + CountingBuffer.examined


# --------------------------------------------------------------------------------------
# The decoders and their frames
# --------------------------------------------------------------------------------------

def _pos_header(name: str) -> LogHeader:
    return LogHeader(name, "COM1", 7, 42.5, TimeStatus.FINESTEERING, 1419, 336208.25)


BESTPOS = BestPos(_pos_header("BESTPOS"), SolutionStatus.SOL_COMPUTED, PositionType.NARROW_INT,
                  45.39821234567, -75.70123456789, 80.5, -34.25, "WGS84", 0.0625, 0.125,
                  0.25, "RAPT", 1.5, 0.0, 9, 8, 8, 7)
BESTVEL = BestVel(_pos_header("BESTVEL"), SolutionStatus.SOL_COMPUTED,
                  PositionType.NARROW_INT, 0.25, 0.5, 3.25, 271.5, -0.125)
GGA = Gga("GP", 45296.5, 45.123456789, -75.5, 4, 12, 0.8, 80.25, -34.25, 2.0, "0042")
RMC = Rmc("GN", 45296.5, True, -33.925, 18.424, 5.5, 359.9, date(2005, 10, 27), -15.5, "D")


def _binary_header(message_id: int, payload_length: int) -> bytes:
    """A NovAtel binary header (no payload, no CRC) for an unknown log of any length."""
    return (b"\xaa\x44\x12\x1c" + message_id.to_bytes(2, "little") + b"\x00\x20"
            + payload_length.to_bytes(2, "little") + bytes(18))


def _controller_header(length: int) -> bytes:
    """A controller frame header with a valid header CRC claiming ``length`` bytes."""
    return encode_controller_frame(0x01, bytes(length))[:10]


_NOT_ACK = bytes(b for b in range(256) if b not in (ACK, NAK))


def _printable(rng: random.Random, n: int, exclude: bytes = b"") -> bytes:
    alphabet = bytes(b for b in range(0x20, 0x7F) if b not in exclude)
    return bytes(rng.choices(alphabet, k=n))


@dataclass(frozen=True)
class Case:
    """One decoder: its frames, its sync bytes and frame heads that claim long frames."""

    decoder: type[StreamDecoder[Any]]
    frames: tuple[bytes, ...]
    sync: tuple[bytes, ...]  # frame starts and their prefixes
    false_heads: Callable[[random.Random], bytes]
    budget: int  # work per byte fed, at most (see test_work_is_linear)

    @property
    def name(self) -> str:
        return self.decoder.__name__


CASES = [
    Case(GpsDecoder,
         (encode_bestpos_ascii(BESTPOS), encode_bestvel_binary(BESTVEL),
          encode_bestpos_binary(BESTPOS), encode_bestvel_ascii(BESTVEL), encode_gga(GGA),
          encode_rmc(RMC), encode_response(), encode_response(False, "Invalid Message ID"),
          encode_prompt()),
         (b"\xaa", b"\xaa\x44", b"\xaa\x44\x12", b"\xaa\x44\x12\x1c", b"#", b"$", b"<", b"[",
          b"\r\n"),
         # a binary header of an unknown log claiming 16 kB, then printable text; an ASCII
         # log, a sentence and a response that never end
         lambda rng: (_binary_header(1111, 16000) + _printable(rng, 300)
                      + b"#BESTPOSA," + _printable(rng, 200, b"*\r\n")
                      + b"$GPGGA," + _printable(rng, 60, b"*\r\n")
                      + b"<ERROR:" + _printable(rng, 60, b"\r\n")),
         budget=24),
    Case(GpsDeviceDecoder,
         (encode_log_command("BESTPOSA"), encode_unlogall_command(), b"\r\n \r\n"),
         (b"\r", b"\n", b" "),
         lambda rng: _printable(rng, 500, b"\r\n"),
         budget=6),
    Case(ImuDecoder,
         (encode_euler_accel_rate_reply(0.1, -0.2, 0.3, (0.5, -0.5, 9.8), (0.01, 0.02, -0.03),
                                        1234),
          encode_euler_angles_reply(0.1, 0.2, -0.3, 99), encode_temperature_reply(25.0, 7)),
         tuple(bytes([c]) for c in REPLY_LENGTHS),
         lambda rng: bytes([CMD_GYRO_STAB_EULER_ACCEL_RATE]) + rng.randbytes(21),
         budget=20),
    Case(ImuDeviceDecoder,
         (encode_poll(CMD_GYRO_STAB_EULER_ACCEL_RATE),
          encode_set_continuous(CMD_GYRO_STAB_EULER_ACCEL_RATE), encode_read_eeprom(230),
          encode_write_eeprom(130, -5)),
         tuple(bytes([c]) for c in COMMAND_LENGTHS) + (b"\x10\x00", b"\x29\x71"),
         lambda rng: b"\x29\x71" + rng.randbytes(4),
         budget=10),
    Case(Mpc555Decoder,
         tuple(encode_report(m, i) for i, m in enumerate(
             [WheelDistanceReport(5, 100, -100), SpeedReport(10, 1500, -300, 2048, 512),
              CommandAck(3, 0x02, 0)])),
         (b"\xa5", b"\xa5\x01", b"\xa5\x01\x0c"),
         lambda rng: b"\xa5\x01\x0c\x81" + rng.randbytes(20),
         budget=16),
    Case(Mpc555DeviceDecoder,
         tuple(encode_command(m, i) for i, m in enumerate(
             [SetVelocity(1500, -250), StartVehicle(),
              SetPedalCalibration(tuple(PedalBreakpoint(v, 2048 + v) for v in
                                        range(-1000, 2000, 400)))])),
         (b"\xa5", b"\xa5\x01", b"\xa5\x01\x21"),
         lambda rng: b"\xa5\x01\x21\x0b" + rng.randbytes(20),
         budget=16),
    Case(SickTelegramDecoder,
         (b"\x06" + encode_mode_reply(0, 0x10),
          b"\x06" + encode_variant_reply(True, 180, 50),
          encode_measured_values(MeasuredValues(tuple(range(1000, 1361)))),
          encode_switch_variant(180, 50), b"\x15"),
         (b"\x02", b"\x06", b"\x15", b"\x02\x80", b"\x02\x00"),
         # heads claiming 812 bytes, and heads with LEN 0, in data without 0x06/0x15
         lambda rng: (b"\x02\x80\x2c\x03" + bytes(rng.choices(_NOT_ACK, k=12))
                      + b"\x02\x00\x00\x00"),
         budget=128),
    Case(NodControllerDecoder,
         (encode_controller_message(ControllerStatus(1, 0, -5, -40, -10, 15, 99, seq=1)),
          encode_controller_message(NodScan(7, 123, -30_000_000, -29_500_000,
                                            MeasuredValues((1000, 1200, 0x1FFF)), seq=9))),
         (b"\xa5", b"\xa5\x4e", b"\xa5\x4e\x01", _controller_header(1024)),
         lambda rng: _controller_header(1024) + rng.randbytes(16),
         budget=128),
    Case(NodHostCommandDecoder,
         (encode_host_command(StartNodding(seq=1)), encode_host_command(SetNodRate(15, seq=2))),
         (b"\xa5", b"\xa5\x4e", b"\xa5\x4e\x01", _controller_header(1024)),
         lambda rng: _controller_header(1024) + rng.randbytes(16),
         budget=128),
]


def _repeat(make: Callable[[random.Random], bytes], size: int, seed: int) -> bytes:
    rng = random.Random(seed)
    out = bytearray()
    while len(out) < size:
        out += make(rng)
    return bytes(out[:size])


def _partial_frames(case: Case) -> Callable[[random.Random], bytes]:
    def make(rng: random.Random) -> bytes:
        frame = rng.choice(case.frames)
        return frame[:rng.randrange(1, len(frame))] if len(frame) > 1 else frame
    return make


HOSTILE: dict[str, Callable[[Case], Callable[[random.Random], bytes]]] = {
    "random": lambda case: lambda rng: rng.randbytes(64),
    "printable": lambda case: lambda rng: _printable(rng, 64),
    "sync": lambda case: lambda rng: b"".join(rng.choices(case.sync, k=32)),
    "false-heads": lambda case: case.false_heads,
    "partial-frames": _partial_frames,
    "frames": lambda case: lambda rng: rng.choice(case.frames),
}

N = 1024
CHUNKS = [1, 7, 64, 4096, None]  # None: the whole stream in one read


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
@pytest.mark.parametrize("kind", list(HOSTILE))
def test_work_is_linear(case: Case, kind: str) -> None:
    """8x more bytes cost at most ~10x the work, and never more than the decoder's budget
    per byte, in every chunking.

    The ratio compares the work of bytes N..9N with that of bytes N..2N (same stream):
    the differences cancel what the start costs and what a frame still pending at the
    end has not cost yet, so a linear decoder gives 8 and a quadratic one ~27. The
    budget is a property of the protocol: a frame head that cannot be checked on its own
    (SICK, the controller's payload CRC) costs a checksum over the length it claims, and
    false heads every k bytes repeat that, so it is about max frame / k.
    """
    stream = _repeat(HOSTILE[kind](case), 9 * N, 1)
    for chunk in CHUNKS:
        w1, w2, w9 = (work(case.decoder, stream[:k * N], chunk or k * N) for k in (1, 2, 9))
        assert w9 - w1 <= 10 * max(w2 - w1, N), (chunk, w1, w2, w9)
        assert w9 <= case.budget * 9 * N, (chunk, w9 / (9 * N))


# --------------------------------------------------------------------------------------
# Chunking does not change the messages
# --------------------------------------------------------------------------------------

def _decode(decoder_type: type[StreamDecoder[Any]], data: bytes, cuts: list[int]) -> list[Any]:
    decoder = decoder_type()
    out: list[Any] = []
    previous = 0
    for cut in sorted({min(c, len(data)) for c in cuts} | {len(data)}):
        out += decoder.feed(data[previous:cut])
        previous = cut
    return out


@st.composite
def streams(draw: st.DrawFn, case: Case) -> bytes:
    pieces = draw(st.lists(st.one_of(
        st.sampled_from(case.frames),
        st.builds(lambda f, k: f[:k], st.sampled_from(case.frames), st.integers(1, 40)),
        st.binary(max_size=24),
        st.lists(st.sampled_from(case.sync), max_size=8).map(b"".join)), max_size=12))
    return b"".join(pieces)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
@PROPERTY
@given(data=st.data())
def test_any_chunking_gives_the_messages_of_one_read(case: Case, data: st.DataObject) -> None:
    stream = data.draw(streams(case))
    cuts = data.draw(st.lists(st.integers(0, max(len(stream), 1)), max_size=16))
    assert _decode(case.decoder, stream, cuts) == _decode(case.decoder, stream, [])


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_byte_by_byte_gives_the_messages_of_one_read(case: Case) -> None:
    stream = _repeat(_partial_frames(case), 3000, 5) + b"".join(case.frames)
    one_read = _decode(case.decoder, stream, [])
    assert _decode(case.decoder, stream, list(range(len(stream)))) == one_read


# --------------------------------------------------------------------------------------
# A damaged frame does not swallow the next one
# --------------------------------------------------------------------------------------

def _cuts(frame: bytes) -> list[int]:
    """Every cut of a short frame; the first and last 16 and 8 more of a long one."""
    if len(frame) <= 40:
        return list(range(1, len(frame)))
    inner = range(16, len(frame) - 16, max(1, (len(frame) - 32) // 8))
    return sorted({*range(1, 16), *inner, *range(len(frame) - 16, len(frame))})


def _contains(out: list[Any], expected: list[Any]) -> bool:
    n = len(expected)
    return any(out[i:i + n] == expected for i in range(len(out) - n + 1))


def _messages(case: Case, frame: bytes) -> list[Any]:
    # After damage a SICK ACK/NAK byte is data until a telegram restores sync (see the
    # SICK tests below); the telegram itself must come through.
    return [m for m in case.decoder().feed(frame) if not isinstance(m, SickAck)]


# The host-to-device command streams have no frame check to tell a cut command from a
# longer one: a GPS command line that lost its CR LF runs into the next line, and the
# 3DM-GX1's "10 00" cut short then "31" *is* "10 00 31". The devices read them so too.
UNCHECKED = (GpsDeviceDecoder, ImuDeviceDecoder)


@pytest.mark.parametrize("case", [c for c in CASES if c.decoder not in UNCHECKED],
                         ids=lambda c: c.name)
def test_a_frame_that_lost_its_tail_does_not_swallow_the_next(case: Case) -> None:
    """Cut any frame anywhere after its first byte and follow it with an intact frame,
    then other frames (a live line goes on; they complete whatever the cut frame's
    head claimed): the intact frame decodes, before those that follow it."""
    for intact in case.frames:
        expected = _messages(case, intact)
        if not expected:
            continue
        others = [f for f in case.frames
                  if not any(m in expected for m in _messages(case, f))]
        longest = max(len(f) for f in case.frames)  # the most a cut head can claim
        filler = b"".join(others) * (1 + 2 * longest // max(1, len(b"".join(others))))
        for damaged in case.frames:
            for cut in _cuts(damaged):
                out = case.decoder().feed(damaged[:cut] + intact + filler)
                assert _contains(out, expected), (damaged[:cut], intact)


def test_gps_error_response_without_line_end_does_not_swallow_the_next_log() -> None:
    log = encode_bestpos_ascii(BESTPOS)
    for intact in (log, encode_bestvel_binary(BESTVEL), encode_gga(GGA), encode_response()):
        expected = GpsDecoder().feed(intact)
        decoder = GpsDecoder()
        out = decoder.feed(b"<ERROR:Invalid Message ID" + intact)
        assert out == expected, intact
        assert not any(isinstance(m, CommandResponse) and not m.ok for m in out)


def test_gps_sentence_without_its_tail_never_absorbs_the_next_sentence() -> None:
    # An 8-bit XOR accepts 1 body in 256; a '$' can never be inside a sentence, so a
    # sentence that lost "*hh CR LF" is dropped at the next '$' whatever its checksum.
    gga, vtg = encode_gga(GGA), encode_vtg(Vtg("GP", 230.5, 229.1, 5.6, 10.4, "A"))
    expected = GpsDecoder().feed(vtg)
    for cut in range(7, gga.index(b"*") + 1):
        for extra in range(95):
            damaged = gga[:cut] + bytes([0x20 + extra % 95])
            assert GpsDecoder().feed(damaged + vtg) == expected, damaged


# --------------------------------------------------------------------------------------
# SICK ACK/NAK only between telegrams
# --------------------------------------------------------------------------------------

def test_sick_noise_yields_no_ack_or_nak() -> None:
    rng = random.Random(8)
    for _ in range(4):
        noise = rng.randbytes(100_000)
        leading = len(noise) - len(noise.lstrip(bytes([ACK, NAK])))
        decoder = SickTelegramDecoder()
        acks = [m for i in range(0, len(noise), 512) for m in decoder.feed(noise[i:i + 512])
                if isinstance(m, SickAck)]
        assert len(acks) == leading  # only a run of ACK/NAK at the very start counts


def test_sick_ack_between_telegrams_is_recognised() -> None:
    reply = encode_variant_reply(True, 180, 50)
    decoder = SickTelegramDecoder()
    assert decoder.feed(b"\x06" + reply + b"\x06" + reply + b"\x15")[0::2] == [
        SickAck(True), SickAck(True), SickAck(False)]


def test_sick_ack_inside_damaged_data_is_not_an_ack() -> None:
    reply = encode_variant_reply(True, 180, 50)
    decoder = SickTelegramDecoder()
    # a telegram that lost its tail, then data bytes that happen to be ACK/NAK
    out = decoder.feed(reply[:5] + b"\x06\x15\x06" + bytes(900) + reply)
    assert [m for m in out if isinstance(m, SickAck)] == []
    assert out[-1:] == SickTelegramDecoder().feed(reply)
    # the telegram re-establishes sync: an ACK after it counts again
    assert decoder.feed(b"\x06") == [SickAck(True)]


def test_sick_command_stream_decodes() -> None:
    stream = encode_switch_variant(180, 50) + b"\x06"
    assert SickTelegramDecoder().feed(stream) == [SwitchVariant(180, 50), SickAck(True)]
