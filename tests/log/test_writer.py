"""afa's MCAP writer against the ``mcap`` package's own readers: what it writes is read
back whole, in order, with every CRC checked, through the index and by a linear scan.
A compressed chunk's CRC is 0 ("not computed"): its zstd or lz4 frame's checksum of the
same records stands for it, and the decompressors check it."""

import io
import struct
import zlib

import lz4.frame
import numpy as np
import pytest
import zstandard
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.records import Chunk, DataEnd, Footer, MessageIndex
from mcap.stream_reader import StreamReader

from afa.log import LogReader
from afa.log.writer import MAGIC, McapWriter


def write_sample(compression: str, chunk_size: int = 600, threaded: bool = False
                 ) -> tuple[bytes, list[tuple], int]:
    """A file of two schemas, three channels (one schemaless, one registered late, one
    in a chunk group of its own),
    messages over several chunks with times out of order within a chunk, metadata
    between chunks; returns its bytes, the messages as (topic, log_time, data, seq) and
    how many of them were written before the explicit flush."""
    stream = io.BytesIO()
    writer = McapWriter(stream, compression=compression, chunk_size=chunk_size,
                        threaded=threaded)
    writer.start(profile="afa", library="test 1")
    first = writer.register_schema("idl.A@1", "jsonschema", b'{"type":"object"}')
    second = writer.register_schema("foxglove.Grid", "jsonschema", b"{}")
    a = writer.register_channel("/Raptor/A", "afa-event", first, {"afa.kind": "event",
                                                                  "k\u00e9y": "v"})
    b = writer.register_channel("/viz/B", "json", second, group=1)
    sent = []
    writer.add_metadata("afa", {"version": "x", "seed": "3"})
    for k in range(40):
        t = 1_000_000_000 * 1126958400 + k * 10_000_000 - (5_000_000 if k % 7 == 3 else 0)
        data = bytes([k % 251]) * (k * 13 % 97)
        channel, topic = (a, "/Raptor/A") if k % 3 else (b, "/viz/B")
        if k % 5 == 1:  # as parts (Event.encode_parts): bytes, an array's memoryview, b""
            cut = len(data) // 3
            values = np.frombuffer(data[cut:], np.uint8).reshape(-1, 1)
            writer.add_message(channel, t, [data[:cut], memoryview(b""),
                                            memoryview(values).cast("B")], t, k)
        else:
            writer.add_message(channel, t, data, t, k)
        sent.append((topic, t, data, k))
        if k == 20:
            c = writer.register_channel("/afa/statistics", "json", 0, {})
        if k > 20 and k % 4 == 0:
            writer.add_message(c, t, b'{"n":%d}' % k, t)
            sent.append(("/afa/statistics", t, b'{"n":%d}' % k, 0))
        if k == 30:
            writer.flush()
            flushed = len(sent)
    writer.add_metadata("afa.end", {"events": "40"})
    writer.finish()
    writer.finish()  # idempotent
    return stream.getvalue(), sent, flushed


def in_order(messages):
    """By time, and messages of one time (in chunks of different groups, read in either
    order) by topic and sequence."""
    return sorted(messages, key=lambda m: (m[1], m[0], m[3]))


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_the_mcap_readers_read_back_every_message_with_crcs_checked(compression):
    data, sent, _ = write_sample(compression)
    # compressing in a worker thread writes the same file, byte for byte
    assert write_sample(compression, threaded=True)[0] == data
    assert data.startswith(MAGIC) and data.endswith(MAGIC)
    expected = in_order(sent)

    def read(reader):
        return [(channel.topic, message.log_time, message.data, message.sequence)
                for _, channel, message in reader.iter_messages(log_time_order=True)]

    seeking = SeekingReader(io.BytesIO(data), validate_crcs=True)
    assert in_order(read(seeking)) == expected
    linear = NonSeekingReader(io.BytesIO(data), validate_crcs=True)
    assert in_order(read(linear)) == expected

    summary = seeking.get_summary()
    stats = summary.statistics
    assert stats.message_count == len(sent)
    assert (stats.schema_count, stats.channel_count, stats.metadata_count) == (2, 3, 2)
    assert stats.chunk_count == len(summary.chunk_indexes) > 3
    assert stats.message_start_time == min(m[1] for m in sent)
    assert stats.message_end_time == max(m[1] for m in sent)
    by_topic = {c.topic: c.id for c in summary.channels.values()}
    for topic, cid in by_topic.items():
        assert stats.channel_message_counts[cid] == sum(1 for m in sent if m[0] == topic)
    assert summary.channels[by_topic["/Raptor/A"]].metadata == {"afa.kind": "event",
                                                                "k\u00e9y": "v"}
    assert summary.schemas[summary.channels[by_topic["/viz/B"]].schema_id].name == \
        "foxglove.Grid"
    assert {m.name: m.metadata for m in seeking.iter_metadata()} == {
        "afa": {"version": "x", "seed": "3"}, "afa.end": {"events": "40"}}
    assert seeking.get_header().library == "test 1"

    # each chunk index points at its chunk and at message indexes that point at messages
    records = list(StreamReader(io.BytesIO(data), emit_chunks=True, skip_magic=False).records)
    for index in summary.chunk_indexes:
        assert data[index.chunk_start_offset] == 0x06
        length = struct.unpack_from("<Q", data, index.chunk_start_offset + 1)[0]
        assert index.chunk_length == 9 + length
        assert index.compression == ("" if compression == "none" else compression)
        for channel_id, offset in index.message_index_offsets.items():
            assert data[offset] == 0x07
            assert struct.unpack_from("<H", data, offset + 9)[0] == channel_id
    message_indexes = [r for r in records if isinstance(r, MessageIndex)]
    assert sum(len(r.records) for r in message_indexes) == len(sent)
    # each message index entry is the offset of a message of its channel and time in the
    # uncompressed records of the chunk before it
    content = b""
    for record in records:
        if isinstance(record, Chunk):
            if record.compression == "zstd":
                assert zstandard.get_frame_parameters(record.data).has_checksum
                content = zstandard.decompress(record.data, record.uncompressed_size)
                damaged = bytearray(record.data)
                damaged[-1] ^= 1  # the frame's checksum itself
                with pytest.raises(zstandard.ZstdError, match="checksum"):
                    zstandard.decompress(bytes(damaged), record.uncompressed_size)
            elif record.compression == "lz4":
                content = lz4.frame.decompress(record.data)
                damaged = bytearray(record.data)
                damaged[-1] ^= 1
                with pytest.raises(RuntimeError, match="(?i)checksum"):
                    lz4.frame.decompress(bytes(damaged))
            else:
                content = bytes(record.data)
            # a compressed chunk's records are covered by their frame's checksum
            assert record.uncompressed_crc == (0 if record.compression
                                               else zlib.crc32(content))
        elif isinstance(record, MessageIndex):
            for log_time, offset in record.records:
                opcode, _, channel_id, _, at = struct.unpack_from("<BQHIQ", content, offset)
                assert (opcode, channel_id, at) == (0x05, record.channel_id, log_time)

    # the data end's CRC is the data section's; the footer's the summary's
    [end] = [r for r in records if isinstance(r, DataEnd)]
    [footer] = [r for r in records if isinstance(r, Footer)]
    data_end = data.rindex(b"\x0f" + struct.pack("<Q", 4), 0, footer.summary_start)
    assert end.data_section_crc == zlib.crc32(data[:data_end])
    assert footer.summary_crc == zlib.crc32(data[footer.summary_start:-len(MAGIC) - 4])


def test_afa_reads_it_through_the_index_and_cut_off_up_to_its_last_flush(tmp_path):
    data, sent, flushed = write_sample("zstd", chunk_size=1 << 20,  # chunks at flushes
                                       threaded=True)
    path = tmp_path / "whole.mcap"
    path.write_bytes(data)
    with LogReader(path) as reader:
        assert reader.indexed and not reader.problems
        got = [(m.channel.topic, m.log_time, m.data, m.sequence) for m in reader.messages()]
    assert [m[1] for m in got] == sorted(m[1] for m in got)  # in time order
    assert in_order(got) == in_order(sent)
    # cut inside the first chunk after the flush: the flushed ones (one per group) are
    # read by a scan
    indexes = sorted(SeekingReader(io.BytesIO(data)).get_summary().chunk_indexes,
                     key=lambda i: i.chunk_start_offset)
    assert len(indexes) == 4
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:indexes[2].chunk_start_offset + 50])
    with LogReader(cut) as reader:
        assert not reader.indexed and reader.problems
        got = [(m.channel.topic, m.log_time, m.data, m.sequence) for m in reader.messages()]
    assert [m[1] for m in got] == sorted(m[1] for m in got)
    assert in_order(got) == in_order(sent[:flushed])


def test_a_chunk_holds_the_channels_of_one_group_and_a_reader_skips_the_others(tmp_path):
    data, sent, _ = write_sample("zstd")
    summary = SeekingReader(io.BytesIO(data)).get_summary()
    by_topic = {c.topic: c.id for c in summary.channels.values()}
    viewer = by_topic["/viz/B"]
    groups = [set(i.message_index_offsets) for i in summary.chunk_indexes]
    assert all(g == {viewer} or viewer not in g for g in groups)
    assert {viewer} in groups and any(viewer not in g for g in groups)
    # chunks of the two groups overlap in time: readers merge them
    viewer_chunks = [i for i in summary.chunk_indexes if viewer in i.message_index_offsets]
    other = [i for i in summary.chunk_indexes if viewer not in i.message_index_offsets]
    assert any(v.message_start_time < o.message_end_time and
               o.message_start_time < v.message_end_time for v in viewer_chunks for o in other)
    path = tmp_path / "groups.mcap"
    path.write_bytes(data)
    with LogReader(path) as reader:
        loaded = []
        load = reader._load
        reader._load = lambda ref, wanted=None: loaded.append(ref.offset) or load(ref, wanted)
        got = [(m.channel.topic, m.log_time, m.data, m.sequence)
               for m in reader.messages(channels=[by_topic["/Raptor/A"]])]
    assert got == in_order(m for m in sent if m[0] == "/Raptor/A")
    assert set(loaded) == {i.chunk_start_offset for i in other
                           if by_topic["/Raptor/A"] in i.message_index_offsets}
