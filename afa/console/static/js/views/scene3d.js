// Body frames and range points (QtBodyViewer §4.2, QtRange3dSensor §4.1.1, qtEventStereo
// §4.3.1): the geometry model's frames and the laser and stereo points, in the Raptor frame
// (the pose's reference, Raptor:RearAxleCenter; x ahead, y left, z up), rotatable with the
// mouse (drag: rotate, shift-drag: pan, wheel: zoom; click a frame to inspect it).
//
// WebGL through three.js (vendored, static/vendor) when the browser has it; otherwise a
// Canvas 2D projection with the same camera (also forced with ?renderer=2d).

import { Surface, apply, deg, el, fmt, ramp, rpyOf } from "../util.js";

const LASER_LINES = 80;     // scan lines kept per laser (about 2 s at 37.6 lines/s)
const STEREO_POINTS = 25000;  // a stereo frame is thinned to this many points

// -- camera math shared by both renderers ------------------------------------------------------
class Orbit {
  constructor() { this.reset(); }
  reset() { this.target = [2.5, 0, 0.3]; this.distance = 11; this.azimuth = deg2rad(-140); this.elevation = deg2rad(35); }
  eye() {
    const c = Math.cos(this.elevation);
    return [this.target[0] + this.distance * c * Math.cos(this.azimuth),
            this.target[1] + this.distance * c * Math.sin(this.azimuth),
            this.target[2] + this.distance * Math.sin(this.elevation)];
  }
  // camera basis: right, up, forward (z-up world)
  basis() {
    const e = this.eye();
    const f = norm(sub(this.target, e));
    const r = norm(cross(f, [0, 0, 1]));
    const u = cross(r, f);
    return { e, f, r, u };
  }
  // world -> [screen x, screen y, depth] for a w x h viewport, vertical field of view 50°
  projector(w, h) {
    const { e, f, r, u } = this.basis();
    const focal = h / 2 / Math.tan(deg2rad(25));
    return (x, y, z) => {
      const d = [x - e[0], y - e[1], z - e[2]];
      const depth = dot(d, f);
      if (depth < 0.1) return null;
      return [w / 2 + (focal * dot(d, r)) / depth, h / 2 - (focal * dot(d, u)) / depth, depth];
    };
  }
}
const deg2rad = (d) => (d * Math.PI) / 180;
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = (a) => { const n = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / n, a[1] / n, a[2] / n]; };

function pointColour(z, stereo) {
  if (stereo) return [200, 140, 255];
  return ramp((z + 0.6) / 2.4);
}

// -- the point store ---------------------------------------------------------------------------
// Positions and colours are computed once per scan line or frame; a redraw only copies them.
function colourise(points, stereo) {
  const colours = new Float32Array(points.length);
  for (let k = 0; k < points.length; k += 3) {
    const c = pointColour(points[k + 2], stereo);
    colours[k] = c[0] / 255; colours[k + 1] = c[1] / 255; colours[k + 2] = c[2] / 255;
  }
  return colours;
}

class Cloud {
  constructor() { this.lines = new Map(); this.stereo = null; this.version = 0; }
  addLaser(stream, positions) {
    let ring = this.lines.get(stream);
    if (!ring) { ring = []; this.lines.set(stream, ring); }
    ring.push({ positions, colours: colourise(positions, false) });
    if (ring.length > LASER_LINES) ring.shift();
    this.version++;
  }
  setStereo(positions) { this.stereo = { positions, colours: colourise(positions, true) }; this.version++; }
  // every point as flat arrays of positions and colours
  flatten(showLaser, showStereo) {
    const parts = [];
    if (showLaser) for (const ring of this.lines.values()) parts.push(...ring);
    if (showStereo && this.stereo) parts.push(this.stereo);
    const n = parts.reduce((sum, part) => sum + part.positions.length, 0);
    const positions = new Float32Array(n), colours = new Float32Array(n);
    let p = 0;
    for (const part of parts) { positions.set(part.positions, p); colours.set(part.colours, p); p += part.positions.length; }
    return { positions, colours, count: n / 3 };
  }
}

// Points of a range event in the reference frame (NaN slots of static forms skipped).
function transformed(body, transform, limit = Infinity) {
  const src = body.points;
  const total = src.length / 3;
  const step = total > limit ? Math.ceil(total / limit) : 1;
  const out = [];
  for (let i = 0; i < total; i += step) {
    const x = src[3 * i], y = src[3 * i + 1], z = src[3 * i + 2];
    if (!(x === x && y === y && z === z)) continue;
    const q = apply(transform, x, y, z);
    out.push(q[0], q[1], q[2]);
  }
  return new Float32Array(out);
}

// -- renderers -----------------------------------------------------------------------------------
class FlatRenderer {
  constructor(box, view) {
    this.name = "Canvas 2D projection";
    this.view = view;
    this.surface = new Surface(box, "scene", (ctx, w, h) => this.draw(ctx, w, h));
    this.canvas = this.surface.canvas;
  }
  render() { this.surface.render(); }
  invalidate() { this.surface.invalidate(); }
  projector() { return this.view.orbit.projector(this.surface.width, this.surface.height); }
  draw(ctx, w, h) {
    const view = this.view;
    ctx.fillStyle = "#0e1116"; ctx.fillRect(0, 0, w, h);
    const project = view.orbit.projector(w, h);
    // ground grid, 1 m
    ctx.strokeStyle = "#232a33"; ctx.lineWidth = 1;
    const z = view.groundZ();
    for (let k = -10; k <= 20; k += 1) {
      line(ctx, project, [k, -10, z], [k, 10, z]);
      if (k <= 10) line(ctx, project, [-10, k, z], [20, k, z]);
    }
    if (view.show.points) {
      // points straight into the pixels (2 x 2 device pixels each): fillRect per point is slow
      const { positions, colours, count } = view.points();
      const ratio = this.canvas.width / w;
      const W = this.canvas.width, H = this.canvas.height;
      const image = ctx.getImageData(0, 0, W, H);
      const data = image.data;
      for (let k = 0; k < count; k++) {
        const s = project(positions[3 * k], positions[3 * k + 1], positions[3 * k + 2]);
        if (!s) continue;
        const x0 = Math.round(s[0] * ratio), y0 = Math.round(s[1] * ratio);
        if (x0 < 0 || y0 < 0 || x0 >= W - 1 || y0 >= H - 1) continue;
        const r = colours[3 * k] * 255, g = colours[3 * k + 1] * 255, b = colours[3 * k + 2] * 255;
        for (const [dx, dy] of [[0, 0], [1, 0], [0, 1], [1, 1]]) {
          const q = ((y0 + dy) * W + x0 + dx) * 4;
          data[q] = r; data[q + 1] = g; data[q + 2] = b; data[q + 3] = 255;
        }
      }
      ctx.putImageData(image, 0, 0);
    }
    if (view.show.frames) {
      for (const frame of view.frames) {
        const m = frame.transform;
        const size = frame.name === view.selected ? 0.6 : 0.25;
        const o = apply(m, 0, 0, 0);
        const axes = [[apply(m, size, 0, 0), "#ff4d4d"], [apply(m, 0, size, 0), "#4dff6a"], [apply(m, 0, 0, size), "#4d8dff"]];
        ctx.lineWidth = frame.name === view.selected ? 3 : 1.5;
        for (const [end, colour] of axes) { ctx.strokeStyle = colour; line(ctx, project, o, end); }
      }
    }
    view.afterDraw(ctx, project);
  }
}

function line(ctx, project, a, b) {
  const p = project(a[0], a[1], a[2]), q = project(b[0], b[1], b[2]);
  if (!p || !q) return;
  ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); ctx.stroke();
}

class ThreeRenderer {
  constructor(THREE, box, view) {
    this.THREE = THREE;
    this.name = `WebGL (three.js r${THREE.REVISION})`;
    this.view = view;
    this.canvas = document.createElement("canvas");
    this.canvas.dataset.probe = "scene";
    box.appendChild(this.canvas);
    this.overlay = document.createElement("canvas");   // labels, drawn in 2-D on top
    this.overlay.style.pointerEvents = "none";
    box.appendChild(this.overlay);
    this.renderer = new THREE.WebGLRenderer({ canvas: this.canvas, antialias: false,
                                              preserveDrawingBuffer: true });
    this.renderer.setClearColor(0x0e1116, 1);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(50, 1, 0.1, 500);
    this.camera.up.set(0, 0, 1);
    const grid = new THREE.GridHelper(30, 30, 0x2e3640, 0x232a33);
    grid.rotation.x = Math.PI / 2;
    grid.position.set(5, 0, view.groundZ());
    this.grid = grid;
    this.scene.add(grid);
    this.framesGroup = new THREE.Group();
    this.scene.add(this.framesGroup);
    this.geometry = new THREE.BufferGeometry();
    this.material = new THREE.PointsMaterial({ size: 2.5, sizeAttenuation: false, vertexColors: true });
    this.points = new THREE.Points(this.geometry, this.material);
    this.points.frustumCulled = false;
    this.scene.add(this.points);
    this.framesVersion = -1;
    this.cloudVersion = -1;
    this.box = box;
    new ResizeObserver(() => view.invalidate()).observe(box);
  }
  invalidate() {}
  projector() {
    const THREE = this.THREE, camera = this.camera, rect = this.canvas.getBoundingClientRect();
    return (x, y, z) => {
      const v = new THREE.Vector3(x, y, z).project(camera);
      if (v.z > 1) return null;
      return [((v.x + 1) / 2) * rect.width, ((1 - v.y) / 2) * rect.height, v.z];
    };
  }
  buildFrames() {
    const THREE = this.THREE, view = this.view;
    this.framesGroup.clear();
    for (const frame of view.frames) {
      const size = frame.name === view.selected ? 0.6 : 0.25;
      const axes = new THREE.AxesHelper(size);
      const m = new THREE.Matrix4();
      m.set(...frame.transform);
      axes.matrixAutoUpdate = false;
      axes.matrix.copy(m);
      this.framesGroup.add(axes);
    }
    this.framesVersion = view.framesVersion;
  }
  render() {
    const THREE = this.THREE, view = this.view;
    const rect = this.canvas.getBoundingClientRect();
    if (rect.width < 2 || rect.height < 2) return;
    const ratio = window.devicePixelRatio || 1;
    this.renderer.setPixelRatio(ratio);
    this.renderer.setSize(rect.width, rect.height, false);
    this.camera.aspect = rect.width / rect.height;
    this.camera.updateProjectionMatrix();
    const eye = view.orbit.eye();
    this.camera.position.set(eye[0], eye[1], eye[2]);
    this.camera.lookAt(new THREE.Vector3(...view.orbit.target));
    this.grid.position.z = view.groundZ();
    if (this.framesVersion !== view.framesVersion) this.buildFrames();
    this.framesGroup.visible = view.show.frames;
    if (this.cloudVersion !== view.cloudVersion()) {
      const { positions, colours, count } = view.points();
      this.geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
      this.geometry.setAttribute("color", new THREE.BufferAttribute(colours, 3));
      this.geometry.setDrawRange(0, count);
      this.cloudVersion = view.cloudVersion();
    }
    this.points.visible = view.show.points;
    this.renderer.render(this.scene, this.camera);
    // labels
    this.overlay.width = Math.round(rect.width * ratio); this.overlay.height = Math.round(rect.height * ratio);
    this.overlay.style.position = "absolute"; this.overlay.style.inset = "0";
    this.overlay.style.width = "100%"; this.overlay.style.height = "100%";
    const ctx = this.overlay.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.clearRect(0, 0, rect.width, rect.height);
    view.afterDraw(ctx, this.projector());
  }
}

export default {
  id: "scene",
  title: "Body frames & range points",
  short: "3-D",
  seed: "QtBodyViewer · QtRange3dSensor · qtEventStereo",
  kinds: { geometry: null, "range.laser": null, "range.stereo": null },
  fps: 5,
  create(app, body, info) {
    body.style.flexDirection = "row";
    const main = el("div", { style: "flex:1;display:flex;flex-direction:column;min-width:0" });
    const show = { frames: true, points: true, laser: true, stereo: true, labels: true };
    const tools = el("div", { class: "tools" });
    for (const name of ["frames", "laser", "stereo", "labels"]) {
      const box = el("input", { type: "checkbox", checked: "", "data-control": `scene-${name}` });
      box.addEventListener("change", () => { show[name] = box.checked; view.cloudDirty = true; view.dirty = true; });
      tools.append(el("label", {}, box, name));
    }
    tools.append(el("button", { type: "button", text: "reset view",
                                onclick: () => { view.orbit.reset(); view.dirty = true; } }));
    const box = el("div", { class: "canvas-box" });
    main.append(tools, box);
    const side = el("div", { class: "side" });
    const frameFacts = el("dl", { class: "kv" });
    const frameList = el("ul", { class: "frames-list" });
    const counts = el("dl", { class: "kv" });
    side.append(el("h3", { text: "points" }), counts, el("h3", { text: "selected frame" }), frameFacts,
                el("h3", { text: "frames (click to inspect)" }), frameList);
    body.append(main, side);
    const cloud = new Cloud();

    const view = {
      dirty: true, orbit: new Orbit(), frames: [], framesVersion: 0, selected: null, renderer: null,
      show, pending: [], cloudDirty: true, cached: null,
      groundZ() {
        const ground = this.frames.find((f) => f.name === "Raptor:Ground");
        return ground ? ground.transform[11] : -0.35;
      },
      cloudVersion() { return cloud.version * 4 + (show.laser ? 1 : 0) + (show.stereo ? 2 : 0); },
      points() {
        if (!this.cached || this.cached.version !== this.cloudVersion()) {
          this.cached = { version: this.cloudVersion(), ...cloud.flatten(show.laser, show.stereo) };
        }
        return this.cached;
      },
      onMessage(message) {
        const { header, event } = message;
        if (header.kind === "geometry") {
          this.frames = header.frames; this.framesVersion++;
          frameList.replaceChildren(...this.frames.map((f) => {
            const item = el("li", { "data-frame": f.name, text: f.name, onclick: () => this.select(f.name) });
            return item;
          }));
        } else if (header.kind === "range.laser") {
          for (const line of message.events) cloud.addLaser(header.stream, transformed(line.body, header.transform));
          this.pending.push(message);
        } else if (header.kind === "range.stereo") {
          cloud.setStereo(transformed(event.body, header.transform, STEREO_POINTS));
          this.pending.push(message);
        }
        this.dirty = true;
      },
      select(name) {
        this.selected = name; this.framesVersion++; this.dirty = true;
        for (const item of frameList.children) item.classList.toggle("selected", item.dataset.frame === name);
      },
      invalidate() { this.dirty = true; this.renderer && this.renderer.invalidate(); },
      afterDraw(ctx, project) {
        ctx.font = "11px system-ui, sans-serif";
        if (show.labels) {
          for (const frame of this.frames) {
            if (frame.name !== this.selected && !frame.frame.match(/^(RearAxleCenter|Front-BumperCenter|SensorCenter|ImagePlane|PhaseCenter|AxleCenterFreeEnd)$/)) continue;
            const p = project(frame.transform[3], frame.transform[7], frame.transform[11]);
            if (!p) continue;
            ctx.fillStyle = frame.name === this.selected ? "#ffe14d" : "rgba(216,221,230,0.8)";
            ctx.fillText(frame.name, p[0] + 5, p[1] - 4);
          }
        }
        ctx.fillStyle = "#8b94a3";
        ctx.fillText(`${this.renderer.name} · reference ${app.hello ? app.hello.reference : ""}`, 8, 14);
      },
      render() {
        if (!this.renderer) return;
        this.renderer.render();
        const facts = [];
        for (const [stream, ring] of cloud.lines) facts.push([stream.split("/")[1], `${ring.reduce((n, l) => n + l.positions.length / 3, 0)} pts, ${ring.length} lines`]);
        if (cloud.stereo) facts.push(["Stereo", `${cloud.stereo.positions.length / 3} pts`]);
        if (!facts.length) facts.push(["range events", "none yet"]);
        counts.replaceChildren(...facts.flatMap(([k, v]) => [el("dt", { text: k }), el("dd", { text: v })]));
        const frame = this.frames.find((f) => f.name === this.selected);
        frameFacts.replaceChildren();
        if (frame) {
          const m = frame.transform, r = rpyOf(m);
          const pairs = [["body", frame.body], ["frame", frame.frame],
                         ["x, y, z", `${fmt(m[3], 3)}, ${fmt(m[7], 3)}, ${fmt(m[11], 3)} m`],
                         ["roll, pitch, yaw", `${fmt(deg(r.roll), 1)}°, ${fmt(deg(r.pitch), 1)}°, ${fmt(deg(r.yaw), 1)}°`]];
          for (const [k, v] of pairs) frameFacts.append(el("dt", { text: k }), el("dd", { text: v }));
        }
        info.textContent = `${this.frames.length} frames · ${this.renderer.name}`;
        for (const done of this.pending) app.drawn(done);
        this.pending = [];
        this.dirty = false;
      },
    };

    // mouse: drag rotates, shift-drag pans, wheel zooms, click picks a frame
    let drag = null;
    box.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, moved: false, shift: e.shiftKey }; box.setPointerCapture(e.pointerId); });
    box.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
      drag.x = e.clientX; drag.y = e.clientY;
      const o = view.orbit;
      if (drag.shift) {
        const { r, u } = o.basis();
        const k = o.distance / 600;
        o.target = [o.target[0] - (r[0] * dx - u[0] * dy) * k, o.target[1] - (r[1] * dx - u[1] * dy) * k,
                    o.target[2] - (r[2] * dx - u[2] * dy) * k];
      } else {
        o.azimuth -= dx * 0.008;
        o.elevation = Math.max(-1.4, Math.min(1.5, o.elevation + dy * 0.008));
      }
      view.dirty = true;
    });
    box.addEventListener("pointerup", (e) => {
      if (drag && !drag.moved && view.renderer) {
        const rect = box.getBoundingClientRect();
        const x = e.clientX - rect.left, y = e.clientY - rect.top;
        const project = view.renderer.projector();
        let best = null, bestD = 12;
        for (const f of view.frames) {
          const p = project(f.transform[3], f.transform[7], f.transform[11]);
          if (!p) continue;
          const d = Math.hypot(p[0] - x, p[1] - y);
          if (d < bestD) { bestD = d; best = f.name; }
        }
        if (best) view.select(best);
      }
      drag = null;
    });
    box.addEventListener("wheel", (e) => {
      e.preventDefault();
      view.orbit.distance = Math.min(200, Math.max(1, view.orbit.distance * (e.deltaY > 0 ? 1.15 : 1 / 1.15)));
      view.dirty = true;
    }, { passive: false });

    (async () => {
      const forced2d = new URLSearchParams(location.search).get("renderer") === "2d";
      let webgl = false;
      if (!forced2d) {
        const test = document.createElement("canvas");
        webgl = Boolean(test.getContext("webgl2") || test.getContext("webgl"));
      }
      if (webgl) {
        try {
          const THREE = await import("../../vendor/three.module.js");
          view.renderer = new ThreeRenderer(THREE, box, view);
        } catch (error) {
          console.error("three.js failed, using the 2-D projection", error);
          view.renderer = new FlatRenderer(box, view);
        }
      } else {
        view.renderer = new FlatRenderer(box, view);
      }
      view.dirty = true;
    })();
    return view;
  },
};
