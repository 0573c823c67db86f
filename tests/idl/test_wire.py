"""The wire codec (idl.wire): lossless, zero-copy arrays, one rule for non-finite numbers,
a schema for every type, a registry that refuses duplicates, and hostile frames refused
with WireError only."""

import base64
import json
import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import idl
from idl import (
    IDLModel,
    PlanPointIDL,
    Range3dArrayEventIDL,
    TimeIDL,
    TypeRegistryError,
    field,
    wire,
)
from tests.idl.test_idl_types import BY_NAME, IDL_TYPES, SAMPLES, T0


@pytest.mark.parametrize("name", IDL_TYPES)
def test_every_type_round_trips_through_the_wire(name):
    sample = SAMPLES[name]()
    frame = wire.encode(sample)
    again = wire.decode(frame)
    assert type(again) is BY_NAME[name] and again == sample
    assert b"".join(bytes(p) for p in wire.encode_parts(sample)) == frame
    for field_name in type(sample).model_fields:
        before, after = getattr(sample, field_name), getattr(again, field_name)
        if isinstance(before, np.ndarray):
            assert after.dtype == before.dtype and after.shape == before.shape
            assert not after.flags.writeable
            if after.nbytes:  # zero copy: the array is a view of the frame
                assert np.shares_memory(after, np.frombuffer(frame, dtype=np.uint8))


def _read_frame(frame):
    """A frame taken apart by the module docstring's layout, by hand: (type name, JSON
    body, buffers), every padding byte checked to be zero."""
    assert frame[:4] == b"AFW1"
    (n,) = struct.unpack_from("<H", frame, 4)
    name = frame[6:6 + n].decode()
    offset = 6 + n
    (m,) = struct.unpack_from("<I", frame, offset)
    body = json.loads(frame[offset + 4:offset + 4 + m])
    offset += 4 + m
    (count,) = struct.unpack_from("<H", frame, offset)
    lengths = struct.unpack_from(f"<{count}Q", frame, offset + 2)
    offset += 2 + 8 * count
    buffers = []
    for length in lengths:
        pad = -offset % 8
        assert frame[offset:offset + pad] == b"\x00" * pad
        offset += pad
        buffers.append(frame[offset:offset + length])
        offset += length
    assert offset == len(frame)
    return name, body, buffers


def _wire_form(value, buffers):
    """The model's JSON form (:meth:`IDLModel.to_json`, arrays in base64) with each
    array's base64 replaced by the wire form's buffer, checked against that buffer."""
    if isinstance(value, dict) and "dtype" in value and "data" in value:
        raw = base64.b64decode(value["data"])
        index = len(buffers["seen"])
        buffers["seen"].append(raw)
        return {"dtype": value["dtype"], "shape": value["shape"], "$array": index}
    if isinstance(value, dict):
        return {k: _wire_form(v, buffers) for k, v in value.items()}
    if isinstance(value, list):
        return [_wire_form(v, buffers) for v in value]
    return value


@pytest.mark.parametrize("name", IDL_TYPES)
def test_every_frame_is_the_json_form_with_arrays_as_raw_buffers(name):
    """Each type's frame, read by hand, holds the model's JSON form with every array's
    base64 turned into an index, its bytes in that buffer (8-aligned, zero padding),
    in field order: what files already written hold, however the encoder is made."""
    sample = SAMPLES[name]()
    type_name, body, buffers = _read_frame(wire.encode(sample))
    assert type_name == idl.type_name(type(sample))
    seen = {"seen": []}
    assert body == _wire_form(json.loads(sample.to_json()), seen)
    assert list(json.loads(sample.to_json())) == list(body)  # the fields' order
    assert buffers == seen["seen"]


def test_the_frame_layout_computed_by_hand():
    frame = wire.encode(TimeIDL(sec=12, usec=250_000))
    name = b"idl.common.TimeIDL@1"
    body = b'{"sec":12,"usec":250000}'
    assert frame == (b"AFW1" + struct.pack("<H", len(name)) + name
                     + struct.pack("<I", len(body)) + body + b"\x00\x00")


def test_arrays_travel_as_aligned_raw_buffers_beside_the_header():
    points = np.array([[1.0, 2.0, -2.0]], dtype=np.float32)
    frame = wire.encode(Range3dArrayEventIDL(time=T0, sensorId=1, frame="D", points=points))
    raw = bytes.fromhex("0000803f00000040000000c0")  # 1.0f, 2.0f, -2.0f little-endian
    assert frame.endswith(raw) and b"base64" not in frame
    assert (len(frame) - len(raw)) % 8 == 0  # the buffer starts 8-aligned
    head = frame[: len(frame) - len(raw)]
    assert b'"points":{"dtype":"<f4","shape":[1,3],"$array":0}' in head
    assert struct.pack("<HQ", 1, len(raw)) in head  # one buffer of 12 bytes


def test_non_finite_numbers_are_strings_a_browser_parses():
    def no_bare_constants(token):
        raise AssertionError(f"bare {token} in JSON (JSON.parse rejects it)")

    point = PlanPointIDL(x=1, y=2, aPrioriCost=math.inf, sensedCost=1.0)
    frame = wire.encode(point)
    body = frame[frame.index(b"{"): frame.rindex(b"}") + 1]
    parsed = json.loads(body, parse_constant=no_bare_constants)
    assert parsed["aPrioriCost"] == "Infinity"
    assert json.loads(point.to_json(), parse_constant=no_bare_constants)["aPrioriCost"] == \
        "Infinity"
    assert wire.decode(frame).aPrioriCost == math.inf

    class Reading(IDLModel):
        value: float = field(unit="1", description="a reading")

    for value, text in ((math.inf, "Infinity"), (-math.inf, "-Infinity"), (math.nan, "NaN")):
        encoded = Reading(value=value).to_json()
        assert encoded == b'{"value":"%s"}' % text.encode()
        again = Reading.from_json(encoded).value
        assert again == value or (math.isnan(again) and math.isnan(value))


@pytest.mark.parametrize("name", IDL_TYPES)
def test_every_type_has_a_json_schema_with_arrays_described(name):
    cls = BY_NAME[name]
    document = wire.schema(cls)
    assert document["x-afa-type"] == idl.type_name(cls)
    properties = document["properties"]
    assert set(properties) == set(cls.model_fields)
    for field_name, info in cls.model_fields.items():
        if "ndarray" in str(info.annotation) or "Array(" in repr(info.metadata):
            described = properties[field_name]
            assert described["x-afa-array"]["dtype"] in ("float32", "float64", "int32", "bool")
            assert described["required"] == ["dtype", "shape"]


def test_type_names_are_qualified_and_versioned():
    assert idl.type_name(idl.GpsIDL) == "idl.sensors.GpsIDL@1"
    assert idl.idl_types()["idl.sensors.GpsIDL"] is idl.GpsIDL


def test_the_registry_refuses_a_second_class_with_a_taken_name():
    with pytest.raises(TypeRegistryError, match="idl.sensors.GpsIDL"):
        class Impostor(IDLModel):  # noqa: F841
            idl_name = "idl.sensors.GpsIDL"
            x: int = field(0, unit="1", description="x")
    assert idl.idl_types()["idl.sensors.GpsIDL"] is idl.GpsIDL


def test_a_newer_version_and_an_unknown_type_are_refused_with_the_reason():
    frame = wire.encode(TimeIDL(sec=1))
    newer = frame.replace(b"TimeIDL@1", b"TimeIDL@2")
    with pytest.raises(wire.WireError, match="newer afa"):
        wire.decode(newer)
    unknown = frame.replace(b"idl.common.TimeIDL@1", b"idl.common.TimeIDX@1")
    with pytest.raises(wire.WireError, match="unknown IDL type"):
        wire.decode(unknown)
    with pytest.raises(wire.WireError, match="expected idl.common.TimeIDL"):
        wire.decode(wire.encode(PlanPointIDL(x=1, y=1)), TimeIDL)


def test_a_body_the_model_rejects_is_a_wire_error():
    name = b"idl.common.TimeIDL@1"
    body = b'{"sec":1,"usec":-5}'
    bad = (b"AFW1" + struct.pack("<H", len(name)) + name + struct.pack("<I", len(body)) + body
           + b"\x00\x00")
    with pytest.raises(wire.WireError, match="usec"):
        wire.decode(bad)


def test_an_array_dtype_with_objects_is_refused():
    frame = wire.encode(SAMPLES["Range3dLaserIDL"]())
    bad = frame.replace(b'"dtype":"<f4"', b'"dtype":"|O8"', 1)
    with pytest.raises(wire.WireError):
        wire.decode(bad)


def _with_body(frame, edit):
    """``frame`` rebuilt by the module docstring's layout with its JSON body's text
    passed through ``edit`` (bytes to bytes), the buffers realigned."""
    name, body, buffers = _read_frame(frame)
    encoded = name.encode()
    text = edit(json.dumps(body, separators=(",", ":")).encode())
    out = (b"AFW1" + struct.pack("<H", len(encoded)) + encoded + struct.pack("<I", len(text))
           + text + struct.pack(f"<H{len(buffers)}Q", len(buffers), *map(len, buffers)))
    for buffer in buffers:
        out += b"\x00" * (-len(out) % 8) + buffer
    return out


@pytest.mark.parametrize("old, new", [(b'"shape":[', b'"shape":[Infinity,'),
                                      (b'"shape":[', b'"shape":[1e400,'),
                                      (b'"$array":0', b'"$array":Infinity')])
def test_an_infinite_array_shape_or_index_is_a_wire_error(old, new):
    # JSON lets a peer write Infinity where a count belongs; int() of it overflows
    frame = wire.encode(SAMPLES["Range3dLaserIDL"]())
    assert wire.decode(_with_body(frame, lambda text: text)) == wire.decode(frame)
    bad = _with_body(frame, lambda text: text.replace(old, new, 1))
    with pytest.raises(wire.WireError, match="bad array description"):
        wire.decode(bad)


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_damaged_frames_raise_wire_error_and_nothing_else(data):
    name = data.draw(st.sampled_from(["GpsIDL", "Range3dLaserIDL", "ArcVoteIDL", "PlanPointIDL"]))
    frame = bytearray(wire.encode(SAMPLES[name]()))
    how = data.draw(st.sampled_from(["truncate", "flip", "append"]))
    if how == "truncate":
        del frame[data.draw(st.integers(0, len(frame) - 1)):]
    elif how == "flip":
        index = data.draw(st.integers(0, len(frame) - 1))
        frame[index] ^= data.draw(st.integers(1, 255))
    else:
        frame += data.draw(st.binary(min_size=1, max_size=16))
    try:
        wire.decode(bytes(frame))
    except wire.WireError:
        pass


@given(st.binary(max_size=64))
def test_random_bytes_raise_wire_error(data):
    with pytest.raises(wire.WireError):
        wire.decode(b"AFW1" + data if data[:1] == b"\x00" else data)


def test_empty_arrays_travel_too():
    """A laser scan line with no return has a (0, 3) point array."""
    from idl import Range3dSeqEventIDL

    empty = Range3dSeqEventIDL(time=TimeIDL(sec=1), sensorId=11, frame="L:F",
                               points=np.zeros((0, 3), np.float32))
    again = wire.decode(wire.encode(empty))
    assert again == empty and again.points.shape == (0, 3)
