// Small shared helpers: colours, 4x4 transforms, canvases, formatting.

// --- colours -----------------------------------------------------------------------------
// Hazard 0 (easy) .. 1 (untraversable): dark green -> yellow -> orange; >= 1: obstacle red.
export const OBSTACLE = [235, 40, 40];
export const UNKNOWN = [38, 42, 50];

export function hazardColour(h) {
  if (!(h === h)) return null;               // NaN: unknown
  if (h >= 1) return OBSTACLE;
  const t = Math.max(0, h);
  if (t < 0.5) {
    const u = t / 0.5;
    return [Math.round(40 + u * 170), Math.round(110 + u * 90), Math.round(60 - u * 30)];
  }
  const u = (t - 0.5) / 0.5;
  return [Math.round(210 + u * 30), Math.round(200 - u * 110), Math.round(30)];
}

// A perceptual-ish ramp (dark blue -> teal -> yellow) for elevations and scores.
const RAMP = [[30, 40, 110], [30, 110, 160], [40, 170, 140], [150, 210, 80], [250, 230, 60]];
export function ramp(t) {
  if (!(t === t)) return null;
  const x = Math.min(1, Math.max(0, t)) * (RAMP.length - 1);
  const k = Math.min(RAMP.length - 2, Math.floor(x));
  const u = x - k;
  const a = RAMP[k], b = RAMP[k + 1];
  return [Math.round(a[0] + u * (b[0] - a[0])), Math.round(a[1] + u * (b[1] - a[1])),
          Math.round(a[2] + u * (b[2] - a[2]))];
}

// Arc score colour: low blue -> high cyan/green; the chosen arc is drawn in CHOSEN.
export const CHOSEN = "#ffe14d";
export const VETOED = "#5a5f68";
export function scoreColour(t) {
  const x = Math.min(1, Math.max(0, t));
  const r = Math.round(40 + 40 * x), g = Math.round(90 + 150 * x), b = Math.round(230 - 60 * x);
  return `rgb(${r},${g},${b})`;
}

export const rgb = (c, a = 1) => (a === 1 ? `rgb(${c[0]},${c[1]},${c[2]})`
                                        : `rgba(${c[0]},${c[1]},${c[2]},${a})`);

// --- 4x4 row-major transforms --------------------------------------------------------------
export function mat(values) { return Array.from(values); }
export function mul(a, b) {
  const out = new Array(16).fill(0);
  for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) {
    let s = 0;
    for (let k = 0; k < 4; k++) s += a[i * 4 + k] * b[k * 4 + j];
    out[i * 4 + j] = s;
  }
  return out;
}
// inverse of a rigid transform [R t; 0 1]
export function invRigid(m) {
  const r = [m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10]];  // R^T
  const t = [m[3], m[7], m[11]];
  const ti = [-(r[0] * t[0] + r[1] * t[1] + r[2] * t[2]),
              -(r[3] * t[0] + r[4] * t[1] + r[5] * t[2]),
              -(r[6] * t[0] + r[7] * t[1] + r[8] * t[2])];
  return [r[0], r[1], r[2], ti[0], r[3], r[4], r[5], ti[1], r[6], r[7], r[8], ti[2], 0, 0, 0, 1];
}
export function apply(m, x, y, z) {
  return [m[0] * x + m[1] * y + m[2] * z + m[3], m[4] * x + m[5] * y + m[6] * z + m[7],
          m[8] * x + m[9] * y + m[10] * z + m[11]];
}
export function yawOf(m) { return Math.atan2(m[4], m[0]); }
export function rpyOf(m) {  // R = Rz(yaw) Ry(pitch) Rx(roll)
  const pitch = Math.asin(Math.max(-1, Math.min(1, -m[8])));
  return { roll: Math.atan2(m[9], m[10]), pitch, yaw: Math.atan2(m[4], m[0]) };
}
export const deg = (r) => (r * 180) / Math.PI;

// --- canvases ------------------------------------------------------------------------------
// A canvas that fills its box at the device pixel ratio; `draw(ctx, w, h)` in CSS pixels.
export class Surface {
  constructor(box, probeId, draw) {
    this.canvas = document.createElement("canvas");
    this.canvas.dataset.probe = probeId;
    box.appendChild(this.canvas);
    this.ctx = this.canvas.getContext("2d");
    this.draw = draw;
    this.width = 0; this.height = 0;
    this.dirty = true;
    new ResizeObserver(() => this.invalidate()).observe(box);
  }
  invalidate() { this.dirty = true; }
  render() {
    const rect = this.canvas.getBoundingClientRect();
    if (rect.width < 2 || rect.height < 2) return false;
    const ratio = window.devicePixelRatio || 1;
    const w = Math.round(rect.width * ratio), h = Math.round(rect.height * ratio);
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w; this.canvas.height = h;
    }
    this.width = rect.width; this.height = rect.height;
    const ctx = this.ctx;
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    this.draw(ctx, rect.width, rect.height);
    this.dirty = false;
    return true;
  }
}

// --- formatting ----------------------------------------------------------------------------
export function fmt(value, digits = 2, unit = "") {
  if (value === null || value === undefined || !(value === value)) return "—";
  return `${Number(value).toFixed(digits)}${unit ? " " + unit : ""}`;
}
export function bytes(n) {
  if (n === null || n === undefined) return "—";
  if (n < 1024) return `${n} B`;
  if (n < 1024 * 1024) return `${(n / 1024).toFixed(1)} KiB`;
  if (n < 1024 ** 3) return `${(n / 1024 / 1024).toFixed(1)} MiB`;
  return `${(n / 1024 ** 3).toFixed(2)} GiB`;
}
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (key === "class") node.className = value;
    else if (key === "style") node.style.cssText = value;   // CSSOM: allowed by the page's CSP
    else if (key === "text") node.textContent = value;
    else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
    else if (value !== undefined && value !== null && value !== false) node.setAttribute(key, value);
  }
  for (const child of children) if (child !== null && child !== undefined) node.append(child);
  return node;
}
export function kv(target, pairs) {
  target.replaceChildren();
  for (const [k, v] of pairs) {
    target.append(el("dt", { text: k }));
    const dd = el("dd");
    if (v instanceof Node) dd.append(v); else dd.textContent = v;
    target.append(dd);
  }
}
export function flag(text, level) { return el("span", { class: `flag ${level}`, text }); }

// Strip chart of several series over the last `span` seconds.
export class Strip {
  constructor(span = 60, capacity = 2000) { this.span = span; this.capacity = capacity; this.series = new Map(); }
  push(name, t, value) {
    let s = this.series.get(name);
    if (!s) { s = []; this.series.set(name, s); }
    s.push([t, value]);
    if (s.length > this.capacity) s.splice(0, s.length - this.capacity);
  }
  draw(ctx, x, y, w, h, styles, range = null) {
    ctx.strokeStyle = "#2c323c"; ctx.lineWidth = 1; ctx.strokeRect(x + 0.5, y + 0.5, w - 1, h - 1);
    let tmax = -Infinity, lo = Infinity, hi = -Infinity;
    for (const s of this.series.values()) for (const [t, v] of s) {
      if (t > tmax) tmax = t;
      if (v === null || !(v === v)) continue;
      if (v < lo) lo = v; if (v > hi) hi = v;
    }
    if (!(tmax > -Infinity)) return;
    if (range) { lo = range[0]; hi = Math.max(range[1], hi); }
    if (hi - lo < 1e-6) { hi = lo + 1; }
    const tmin = tmax - this.span;
    ctx.fillStyle = "#8b94a3"; ctx.font = "10px system-ui, sans-serif";
    ctx.fillText(hi.toFixed(2), x + 3, y + 11); ctx.fillText(lo.toFixed(2), x + 3, y + h - 3);
    for (const [name, s] of this.series) {
      const style = styles[name] || "#d8dde6";
      ctx.strokeStyle = style; ctx.lineWidth = 1.5; ctx.beginPath();
      let pen = false;
      for (const [t, v] of s) {
        if (t < tmin || v === null || !(v === v)) { pen = false; continue; }
        const px = x + ((t - tmin) / this.span) * w, py = y + h - ((v - lo) / (hi - lo)) * h;
        if (pen) ctx.lineTo(px, py); else { ctx.moveTo(px, py); pen = true; }
      }
      ctx.stroke();
    }
  }
}

// --- geodesy -------------------------------------------------------------------------------
// WGS84 latitude/longitude (deg) to UTM [easting, northing, zone] in the zone of the
// longitude (Norway and Svalbard exceptions ignored): the transverse Mercator series in n
// to the fourth order (Krüger), millimetres within a zone. For waypoints that carry no UTM.
const WGS84_A = 6378137.0, WGS84_F = 1 / 298.257223563, K0 = 0.9996;
export function utm(latitude, longitude, zone = null) {
  const n = WGS84_F / (2 - WGS84_F), n2 = n * n, n3 = n2 * n, n4 = n3 * n;
  const A = (WGS84_A / (1 + n)) * (1 + n2 / 4 + n4 / 64);
  const alpha = [n / 2 - (2 * n2) / 3 + (5 * n3) / 16 + (41 * n4) / 180,
                 (13 * n2) / 48 - (3 * n3) / 5 + (557 * n4) / 1440,
                 (61 * n3) / 240 - (103 * n4) / 140,
                 (49561 * n4) / 161280];
  const z = zone || Math.floor((longitude + 180) / 6) + 1;
  const phi = (latitude * Math.PI) / 180;
  const dl = ((longitude - (z * 6 - 183)) * Math.PI) / 180;
  const c = (2 * Math.sqrt(n)) / (1 + n);
  const t = Math.sinh(Math.atanh(Math.sin(phi)) - c * Math.atanh(c * Math.sin(phi)));
  const xi = Math.atan2(t, Math.cos(dl));
  const eta = Math.atanh(Math.sin(dl) / Math.sqrt(1 + t * t));
  let x = eta, y = xi;
  for (let j = 1; j <= 4; j++) {
    x += alpha[j - 1] * Math.cos(2 * j * xi) * Math.sinh(2 * j * eta);
    y += alpha[j - 1] * Math.sin(2 * j * xi) * Math.cosh(2 * j * eta);
  }
  return [500000 + K0 * A * x, (latitude < 0 ? 10000000 : 0) + K0 * A * y, z];
}
