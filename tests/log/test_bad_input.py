"""Bad input: a clear message naming the file and what is wrong, and everything that can
be read is read. Nothing in a log makes the reader import or run anything."""

import json
import sys

import pytest

from afa.log import LogError, LogReader
from afa.log import format as fmt


def test_a_file_that_is_not_mcap_is_refused_by_name(tmp_path):
    text = tmp_path / "notes.mcap"
    text.write_text("hello, I am not a recording\n")
    with pytest.raises(LogError, match=r"notes\.mcap: not an MCAP file"):
        LogReader(text)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(LogError, match=r"empty\.mcap: the file is empty"):
        LogReader(empty)
    with pytest.raises(LogError, match="cannot open"):
        LogReader(tmp_path / "missing.mcap")


def test_a_truncated_file_is_read_up_to_its_last_complete_chunk(recorded, tmp_path):
    data = recorded.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with LogReader(recorded) as whole, LogReader(cut) as reader:
        assert not reader.indexed
        assert any("cut.mcap: the file ends at byte" in p for p in reader.problems)
        got = [(m.channel.topic, m.log_time, m.data) for m in reader.messages()]
        expected = [(m.channel.topic, m.log_time, m.data) for m in whole.messages(
            end=reader.end + 1)]
    assert 0 < len(got) and got == expected[: len(got)]


def test_a_corrupted_chunk_is_skipped_and_named_and_the_others_are_read(recorded, tmp_path):
    with LogReader(recorded) as reader:
        chunk = reader.chunks[len(reader.chunks) // 2]
        total = sum(1 for _ in reader.messages())
    data = bytearray(recorded.read_bytes())
    middle = chunk.offset + chunk.length // 2
    data[middle:middle + 64] = bytes(64)  # zeros inside the compressed data
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with LogReader(bad) as reader:
        read = sum(1 for _ in reader.messages())
        assert any(f"bad.mcap: the chunk at byte {chunk.offset}" in p and "damaged" in p
                   for p in reader.problems), reader.problems
    assert 0 < read < total


def _damage_record(data: bytearray, opcode: int, change) -> int:
    """Apply ``change(data, content_start, length)`` to the first record of ``opcode``
    (walking the records from the magic); its offset."""
    at = len(b"\x89MCAP0\r\n")
    while True:
        op, length = data[at], int.from_bytes(data[at + 1:at + 9], "little")
        if op == opcode:
            change(data, at + 9, length)
            return at
        at += 9 + length


@pytest.mark.parametrize("damage", ["chunk length", "zeroed index entry"])
def test_a_damaged_chunk_length_or_index_entry_costs_one_chunk(recorded, tmp_path, damage):
    """A chunk record claiming 2^64 - 1 bytes, or a chunk index entry zeroed (pointing at
    the magic, which then reads as a record of 7e16 bytes), made every reading tool fail
    with OverflowError or MemoryError: the index entry is checked against the record it
    names, and a mismatch costs that chunk, named, and nothing else."""
    with LogReader(recorded) as reader:
        chunks, total = len(reader.chunks), sum(1 for _ in reader.messages())
    data = bytearray(recorded.read_bytes())
    if damage == "chunk length":
        def change(d, start, length):
            d[start - 8:start] = (2**64 - 1).to_bytes(8, "little")
        _damage_record(data, 6, change)
    else:
        def change(d, start, length):
            d[start:start + length] = bytes(length)
        _damage_record(data, 8, change)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with LogReader(bad) as reader:
        assert reader.indexed and len(reader.chunks) == chunks - 1
        assert any("does not match the record there" in p and "not read" in p
                   for p in reader.problems), reader.problems
        read = sum(1 for _ in reader.messages())
        assert 0 < read < total and reader.duration > 0


def _rewrite(source, target, change):
    """Copy a recording, changing schemas/channels/messages through ``change``."""
    from mcap.writer import Writer

    with LogReader(source) as reader, open(target, "wb") as out:
        writer = Writer(out)
        writer.start("afa", "test")
        ids = {}
        for message in reader.messages():
            channel = message.channel
            schema, data = change(channel, message.data)
            if channel.id not in ids:
                sid = writer.register_schema(schema, "jsonschema", b"{}")
                ids[channel.id] = writer.register_channel(channel.topic, channel.encoding, sid,
                                                          channel.metadata)
            writer.add_message(ids[channel.id], message.log_time, data, message.log_time)
        writer.finish()


def test_a_type_from_a_newer_afa_or_unknown_is_named_and_the_rest_is_read(recorded, tmp_path):
    def change(channel, data):
        if channel.event == "Gps":
            data = data.replace(b"idl.sensors.GpsIDL@1", b"idl.sensors.GpsIDL@9")
            return "idl.sensors.GpsIDL@9", data
        if channel.event == "Imu":
            data = data.replace(b"idl.sensors.ImuIDL@1", b"idl.sensors.ZzzIDL@1")
            return "idl.sensors.ZzzIDL@1", data
        return channel.schema, data

    odd = tmp_path / "odd.mcap"
    _rewrite(recorded, odd, change)
    with LogReader(odd) as reader:
        events = [reader.decode_event(m) for m in reader.messages()
                  if m.channel.kind == fmt.EVENT]
        problems = "\n".join(reader.problems)
    assert "odd.mcap: topic /Raptor/Gps (idl.sensors.GpsIDL@9) cannot be read" in problems
    assert "newer afa" in problems and "unknown IDL type 'idl.sensors.ZzzIDL'" in problems
    kinds = {e.type for e in events if e is not None}
    assert "Pose" in kinds and not {"Gps", "Imu"} & kinds
    assert problems.count("/Raptor/Gps") == 1  # once per topic, not per message


def test_nothing_in_a_log_imports_a_module(recorded, tmp_path):
    from afa.log.player import known_interfaces

    def change(channel, data):
        return channel.schema, data.replace(b"idl.interfaces.VehicleControl",
                                            b"antigravity.Interface")
    forged = tmp_path / "forged.mcap"
    _rewrite(recorded, forged, change)
    with LogReader(forged) as reader:
        for message in reader.messages():
            if message.channel.kind == fmt.POLL:
                reader.decode_wire(message)
    assert "antigravity" not in sys.modules
    assert "antigravity.Interface" not in known_interfaces()
    assert json.dumps  # the reader decodes through idl.wire and json only
