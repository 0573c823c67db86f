"""StreamDecoder's resume point and stream offset (afa.codec's linear-cost contract)."""

from __future__ import annotations

from afa.codec import Fault, Scan, StreamDecoder


class Lines(StreamDecoder[bytes]):
    """Lines ending in LF; '#' is garbage. Records where each scan started searching."""

    def __init__(self, *, max_buffer: int = 1 << 16) -> None:
        super().__init__(max_buffer=max_buffer)
        self.starts: list[int] = []

    def scan(self, buffer: bytearray) -> Scan[bytes]:
        if buffer[0] == ord("#"):
            return Scan.skip(1, Fault.GARBAGE)
        start = max(0, self.searched)
        self.starts.append(start)
        end = buffer.find(b"\n", start)
        if end < 0:
            return Scan.need_more(searched=len(buffer))
        return Scan.frame(end + 1, bytes(buffer[:end]))


def test_a_scan_resumes_where_the_last_one_stopped_and_starts_over_on_a_new_front() -> None:
    decoder = Lines()
    for byte in b"abcd":
        assert decoder.feed(bytes([byte])) == []
    assert decoder.starts == [0, 1, 2, 3]  # each read searched only the new byte
    assert decoder.feed(b"\nxy") == [b"abcd"]
    assert decoder.starts[-2:] == [4, 0]  # the front after the line is searched from 0
    assert decoder.searched == 2 and decoder.front_position == 5


def test_front_position_counts_consumed_skipped_dropped_and_reset_bytes() -> None:
    decoder = Lines(max_buffer=8)
    decoder.feed(b"##ab\n")
    assert decoder.front_position == 5
    decoder.feed(b"0123456789")  # no line end: 2 bytes dropped beyond max_buffer
    assert decoder.front_position == 7 and decoder.buffered == 8
    assert decoder.searched == 0  # the front moved: no resume point
    decoder.reset()
    assert decoder.front_position == 15 == decoder.stats.bytes_in
