// Decoding the console's messages (afa/console/frames.py) and afa's wire codec
// (idl/wire.py, afa/events.py) in the browser.
//
// A message: "AFC1", u32 header length, u32 event offset (0: none), u32 reserved,
// the JSON header, padding, then an event: "AFE1" envelope (time f64, seq u64, three u16
// name lengths, names) and the body's "AFW1" frame: type name, JSON body, array buffers
// 8-aligned from the frame start. The console pads each message so the frame starts on a
// multiple of 8: arrays become typed-array *views* of the received buffer, not copies.

const utf8 = new TextDecoder("utf-8");

const DTYPES = {
  f4: Float32Array, f8: Float64Array, i1: Int8Array, i2: Int16Array, i4: Int32Array,
  u1: Uint8Array, u2: Uint16Array, u4: Uint32Array, b1: Uint8Array,
  i8: BigInt64Array, u8: BigUint64Array,
};
const LITTLE = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;

function magic(view, offset) {
  return String.fromCharCode(view.getUint8(offset), view.getUint8(offset + 1),
                             view.getUint8(offset + 2), view.getUint8(offset + 3));
}

// The IDL's one rule for non-finite numbers: "Infinity", "-Infinity", "NaN" strings.
function revive(key, value) {
  if (value === "NaN" || value === "Infinity" || value === "-Infinity") return Number(value);
  return value;
}

function makeArray(buffer, offset, length, dtype, shape) {
  const order = dtype[0];
  const code = dtype.slice(1);
  const Type = DTYPES[code];
  if (!Type) throw new Error(`unsupported dtype ${dtype}`);
  const size = Type.BYTES_PER_ELEMENT;
  const count = length / size;
  let array;
  const native = order === "|" || order === "=" || (order === "<") === LITTLE;
  if (native && offset % size === 0) {
    array = new Type(buffer, offset, count);
  } else {
    // misaligned or foreign byte order: copy through a DataView
    const view = new DataView(buffer, offset, length);
    array = new Type(count);
    const little = order === "<";
    const getter = {
      f4: "getFloat32", f8: "getFloat64", i1: "getInt8", i2: "getInt16", i4: "getInt32",
      u1: "getUint8", b1: "getUint8", u2: "getUint16", u4: "getUint32",
      i8: "getBigInt64", u8: "getBigUint64",
    }[code];
    for (let k = 0; k < count; k++) array[k] = view[getter](k * size, little);
  }
  array.shape = shape;
  array.dtype = dtype;
  return array;
}

function attachArrays(value, arrays) {
  if (Array.isArray(value)) {
    for (let k = 0; k < value.length; k++) value[k] = attachArrays(value[k], arrays);
    return value;
  }
  if (value !== null && typeof value === "object") {
    if ("$array" in value && "dtype" in value && "shape" in value) {
      return arrays[value.$array](value.dtype, value.shape);
    }
    for (const key of Object.keys(value)) value[key] = attachArrays(value[key], arrays);
  }
  return value;
}

// One AFW1 frame at `offset` of `buffer`, `end` its end. Returns {type, body}.
export function decodeWire(buffer, offset, end) {
  const view = new DataView(buffer);
  if (magic(view, offset) !== "AFW1") throw new Error("not an afa wire frame");
  let p = offset + 4;
  const n = view.getUint16(p, true); p += 2;
  const type = utf8.decode(new Uint8Array(buffer, p, n)); p += n;
  const m = view.getUint32(p, true); p += 4;
  const text = utf8.decode(new Uint8Array(buffer, p, m)); p += m;
  const count = view.getUint16(p, true); p += 2;
  const lengths = [];
  for (let k = 0; k < count; k++) { lengths.push(Number(view.getBigUint64(p, true))); p += 8; }
  const starts = [];
  for (let k = 0; k < count; k++) {
    p += (8 - ((p - offset) % 8)) % 8;
    starts.push(p);
    p += lengths[k];
  }
  if (p > end) throw new Error("truncated wire frame");
  const arrays = starts.map((start, k) => (dtype, shape) =>
    makeArray(buffer, start, lengths[k], dtype, shape));
  const body = attachArrays(JSON.parse(text, revive), arrays);
  return { type, body };
}

// An AFE1 event at `offset` ending at `end`. Returns {domain, type, origin, time, seq,
// bodyType, body}.
export function decodeEvent(buffer, offset, end = buffer.byteLength) {
  const view = new DataView(buffer);
  if (magic(view, offset) !== "AFE1") throw new Error("not an afa event");
  const time = view.getFloat64(offset + 4, true);
  const seq = Number(view.getBigUint64(offset + 12, true));
  const lengths = [view.getUint16(offset + 20, true), view.getUint16(offset + 22, true),
                   view.getUint16(offset + 24, true)];
  let p = offset + 26;
  const names = lengths.map((n) => { const s = utf8.decode(new Uint8Array(buffer, p, n)); p += n; return s; });
  const frame = decodeWire(buffer, p, end);
  return { domain: names[0], type: names[1], origin: names[2], time, seq,
           bodyType: frame.type, body: frame.body };
}

// One console message. Returns {header, events, event} (event: the last, or null).
export function decodeMessage(buffer) {
  const view = new DataView(buffer);
  if (buffer.byteLength < 16 || magic(view, 0) !== "AFC1") throw new Error("not a console message");
  const length = view.getUint32(4, true);
  const count = view.getUint32(8, true);
  const header = JSON.parse(utf8.decode(new Uint8Array(buffer, 16, length)));
  const events = [];
  for (let k = 0; k < count; k++) {
    const offset = view.getUint32(16 + length + 8 * k, true);
    const size = view.getUint32(16 + length + 8 * k + 4, true);
    events.push(decodeEvent(buffer, offset, offset + size));
  }
  return { header, events, event: events.length ? events[events.length - 1] : null };
}

// Element [i][j] of a row-major (rows, cols) typed array.
export function at(array, i, j) {
  return array[i * array.shape[1] + j];
}
