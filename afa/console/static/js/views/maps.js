// Maps (QtMap, seed §4.4.1, Figure 17): the global terrain and traversability maps and the
// Global Map, north up and centred on the vehicle, with the vehicle, its track, the
// waypoints and FindPath's planned path.
//
// Map convention (idl/maps.py): cell [i, j] covers map x in [originX + i g, ...) and y in
// [originY + j g, ...); rows run east, columns north for global maps; mapPose places the
// map frame in the world frame (origin at initialUTM).

import { OBSTACLE, Surface, el, fmt, hazardColour, ramp, rgb, utm, yawOf } from "../util.js";

const LAYERS = {
  traverse: { kind: "map.traverse", label: "traversability" },
  terrain: { kind: "map.terrain", label: "terrain (elevation)" },
  plan: { kind: "map.plan", label: "Global Map (planning cost)" },
};

function layerImage(body, layer) {
  const rows = body.rows, cols = body.cols;
  const image = new ImageData(rows, cols);
  const data = image.data;
  let known = 0, hazards = 0, lo = Infinity, hi = -Infinity;
  if (layer === "terrain") {
    const z = body.elevation;
    for (let k = 0; k < z.length; k++) { const v = z[k]; if (v === v) { if (v < lo) lo = v; if (v > hi) hi = v; } }
  }
  const span = hi - lo > 1e-6 ? hi - lo : 1;
  for (let i = 0; i < rows; i++) {
    for (let j = 0; j < cols; j++) {
      const k = i * cols + j;
      let colour = null;
      if (layer === "traverse") {
        colour = hazardColour(body.hazard[k]);
        if (body.hazard[k] >= 1) hazards++;
      } else if (layer === "terrain") {
        const v = body.elevation[k];
        colour = v === v ? ramp((v - lo) / span) : null;
      } else {
        const sensed = body.goodness[k] > 0;
        const cost = sensed ? body.sensedCost[k] : body.aPrioriCost[k];
        if (cost === Infinity) { colour = OBSTACLE; hazards++; }
        else if (!sensed && cost <= 1) colour = null;
        else colour = hazardColour(Math.min(0.99, Math.log(cost) / Math.log(20)));
      }
      if (!colour) continue;
      known++;
      const p = ((cols - 1 - j) * rows + i) * 4;  // column i (east), row from the north
      data[p] = colour[0]; data[p + 1] = colour[1]; data[p + 2] = colour[2]; data[p + 3] = 255;
    }
  }
  const canvas = document.createElement("canvas");
  canvas.width = rows; canvas.height = cols;
  canvas.getContext("2d").putImageData(image, 0, 0);
  return { canvas, known, hazards, lo, hi };
}

export default {
  id: "maps",
  title: "Maps",
  short: "Maps",
  seed: "QtMap · Global Map",
  kinds: { pose: null, "map.traverse": null, "map.terrain": null, "map.plan": null, path: null,
           waypoints: null, truth: null },
  fps: 5,
  create(app, body, info) {
    body.style.flexDirection = "row";
    const main = el("div", { style: "flex:1;display:flex;flex-direction:column;min-width:0" });
    const tools = el("div", { class: "tools" });
    const layerSelect = el("select", { "data-control": "maps-layer" });
    for (const [key, layer] of Object.entries(LAYERS)) layerSelect.append(el("option", { value: key, text: layer.label }));
    const checks = {};
    for (const name of ["track", "waypoints", "path", "truth"]) {
      checks[name] = el("input", { type: "checkbox", checked: "" });
      checks[name].addEventListener("change", () => { view.dirty = true; });
    }
    const fit = el("button", { type: "button", text: "fit map", onclick: () => { view.fit = true; view.dirty = true; } });
    tools.append(el("label", {}, "layer ", layerSelect), fit,
                 el("label", {}, checks.track, "track"), el("label", {}, checks.waypoints, "waypoints"),
                 el("label", {}, checks.path, "planned path"), el("label", {}, checks.truth, "truth"));
    const box = el("div", { class: "canvas-box" });
    main.append(tools, box);
    const side = el("div", { class: "side" });
    const facts = el("dl", { class: "kv" });
    side.append(el("h3", { text: "map" }), facts,
                el("h3", { text: "legend" }),
                el("div", { class: "legend" },
                   el("span", {}, el("span", { class: "swatch", style: `background:${rgb(OBSTACLE)}` }), "obstacle"),
                   el("span", {}, el("span", { class: "swatch", style: "background:rgb(40,110,60)" }), "easy"),
                   el("span", {}, el("span", { class: "swatch", style: "background:rgb(210,200,30)" }), "hazard"),
                   el("span", {}, el("span", { class: "swatch", style: "background:#ff4fd8" }), "planned path"),
                   el("span", {}, el("span", { class: "swatch", style: "background:#ff9f1c" }), "mission waypoints"),
                   el("span", {}, el("span", { class: "swatch", style: "background:#58a6ff" }), "planner waypoints"),
                   el("span", {}, el("span", { class: "swatch", style: "background:#ffffff" }), "vehicle (estimate)"),
                   el("span", {}, el("span", { class: "swatch", style: "background:#3fb950" }), "vehicle (truth)")));
    body.append(main, side);

    const view = {
      dirty: true, fit: true, mpp: 0.1, layer: "traverse", maps: {}, images: {}, pending: [],
      wanted() {
        return { pose: null, path: null, waypoints: null, truth: null, [LAYERS[this.layer].kind]: null };
      },
      onMessage(message) {
        const kind = message.header.kind;
        if (kind.startsWith("map.")) {
          const key = Object.keys(LAYERS).find((k) => LAYERS[k].kind === kind);
          this.maps[key] = message;
          this.images[key] = null;
          this.pending.push(message);
          this.urgent = true;
        } else if (kind === "path") {
          this.path = message.event;
        }
        this.dirty = true;
      },
      invalidate() { this.dirty = true; surface.invalidate(); },
      center() {
        const pose = app.state.pose;
        if (pose) return [pose[3], pose[7]];
        const map = this.maps[this.layer];
        if (!map) return [0, 0];
        const b = map.event.body;
        return [b.mapPose[3] + b.originX + (b.rows * b.gridsize) / 2,
                b.mapPose[7] + b.originY + (b.cols * b.gridsize) / 2];
      },
      // world (x east, y north) -> CSS pixels of the canvas
      screenOf(x, y) {
        const [vx, vy] = this.center();
        return [surface.width / 2 + (x - vx) / this.mpp, surface.height / 2 - (y - vy) / this.mpp];
      },
      render() { surface.render(); },
    };

    layerSelect.addEventListener("change", () => {
      view.layer = layerSelect.value; view.dirty = true; app.subscribe();
    });

    function toWorld(utm) {
      const origin = app.state.initialUTM;
      return origin ? [utm[0] - origin[0], utm[1] - origin[1]] : null;
    }

    function draw(ctx, w, h) {
      ctx.fillStyle = "#101318"; ctx.fillRect(0, 0, w, h);
      const message = view.maps[view.layer];
      const state = app.state;
      if (message && view.fit) {
        const b = message.event.body;
        view.mpp = Math.max(0.01, Math.max(b.rows * b.gridsize / w, b.cols * b.gridsize / h) * 0.55);
        view.fit = false;
      }
      const mpp = view.mpp;
      // 10 m grid, north up
      const [vx, vy] = view.center();
      ctx.strokeStyle = "#1d232b"; ctx.lineWidth = 1;
      const step = mpp > 0.3 ? 50 : 10;
      for (let gx = Math.floor((vx - (w / 2) * mpp) / step) * step; gx < vx + (w / 2) * mpp; gx += step) {
        const [sx] = view.screenOf(gx, 0); ctx.beginPath(); ctx.moveTo(sx, 0); ctx.lineTo(sx, h); ctx.stroke();
      }
      for (let gy = Math.floor((vy - (h / 2) * mpp) / step) * step; gy < vy + (h / 2) * mpp; gy += step) {
        const [, sy] = view.screenOf(0, gy); ctx.beginPath(); ctx.moveTo(0, sy); ctx.lineTo(w, sy); ctx.stroke();
      }
      const facts = [["layer", LAYERS[view.layer].label]];
      if (message) {
        const b = message.event.body;
        let image = view.images[view.layer];
        if (!image) image = view.images[view.layer] = layerImage(b, view.layer);
        const m = b.mapPose, g = b.gridsize;
        const r00 = m[0], r01 = m[1], r10 = m[4], r11 = m[5], tx = m[3], ty = m[7];
        const top = b.originY + b.cols * g;
        const a = (r00 * g) / mpp, c = (-r01 * g) / mpp, bb = (-r10 * g) / mpp, d = (r11 * g) / mpp;
        const e = w / 2 + (r00 * b.originX + r01 * top + tx - vx) / mpp;
        const f = h / 2 - (r10 * b.originX + r11 * top + ty - vy) / mpp;
        ctx.save();
        ctx.imageSmoothingEnabled = false;
        ctx.transform(a, bb, c, d, e, f);
        ctx.drawImage(image.canvas, 0, 0);
        ctx.restore();
        facts.push(["event", message.event.type], ["from", message.event.origin || "—"],
                   ["grid", `${b.rows} × ${b.cols} × ${fmt(g, 2)} m`],
                   ["known cells", String(image.known)],
                   [view.layer === "terrain" ? "height" : "obstacles",
                    view.layer === "terrain" ? `${fmt(image.lo, 2)} … ${fmt(image.hi, 2)} m` : String(image.hazards)],
                   ["age", `${fmt(message.received ? Date.now() / 1000 - message.received : null, 1)} s`]);
      } else {
        ctx.fillStyle = "#8b94a3"; ctx.font = "13px system-ui, sans-serif";
        ctx.fillText(`no ${LAYERS[view.layer].kind} events yet (published by the map components)`, 12, 22);
      }
      // track
      if (checks.track.checked && state.track.length > 1) {
        ctx.strokeStyle = "rgba(255,255,255,0.55)"; ctx.lineWidth = 1.5; ctx.beginPath();
        state.track.forEach(([x, y], k) => { const [sx, sy] = view.screenOf(x, y); k ? ctx.lineTo(sx, sy) : ctx.moveTo(sx, sy); });
        ctx.stroke();
      }
      // planned path
      if (checks.path.checked && view.path) {
        const p = view.path.body.points;
        const shift = app.state.initialUTM
          ? [view.path.body.initialUTM[0] - app.state.initialUTM[0], view.path.body.initialUTM[1] - app.state.initialUTM[1]]
          : [0, 0];
        ctx.strokeStyle = "#ff4fd8"; ctx.lineWidth = 2.5; ctx.beginPath();
        for (let k = 0; k < p.length / 2; k++) {
          const [sx, sy] = view.screenOf(p[2 * k] + shift[0], p[2 * k + 1] + shift[1]);
          k ? ctx.lineTo(sx, sy) : ctx.moveTo(sx, sy);
        }
        ctx.stroke();
        facts.push(["path", `${p.length / 2} points, cost ${fmt(view.path.body.cost, 1)}`]);
      }
      // waypoints: the mission's (simulation truth) and the planners' lists
      if (checks.waypoints.checked) {
        const truth = state.truth;
        if (truth && truth.waypoints_utm) {
          truth.waypoints_utm.forEach((utm, k) => {
            const world = toWorld(utm); if (!world) return;
            const [sx, sy] = view.screenOf(world[0], world[1]);
            const done = k < truth.waypoints_reached && !truth.patrol;
            ctx.strokeStyle = done ? "#7a5a2a" : "#ff9f1c"; ctx.lineWidth = 2;
            ctx.beginPath(); ctx.arc(sx, sy, 7, 0, 2 * Math.PI); ctx.stroke();
            ctx.fillStyle = "#ff9f1c"; ctx.font = "11px system-ui, sans-serif"; ctx.fillText(String(k + 1), sx + 9, sy - 6);
          });
        }
        const drawn = [];   // the same waypoint in several planners' lists is drawn once
        for (const list of Object.values(state.waypoints || {})) {
          list.waypoints.forEach((wp, k) => {
            const grid = wp.easting === null || wp.northing === null
              ? utm(wp.latitude, wp.longitude) : [wp.easting, wp.northing];
            const world = toWorld(grid); if (!world) return;
            if (drawn.some(([x, y]) => Math.hypot(x - world[0], y - world[1]) < 0.5)) return;
            drawn.push(world);
            const [sx, sy] = view.screenOf(world[0], world[1]);
            ctx.fillStyle = "#58a6ff";
            ctx.beginPath(); ctx.moveTo(sx, sy - 6); ctx.lineTo(sx + 6, sy); ctx.lineTo(sx, sy + 6); ctx.lineTo(sx - 6, sy); ctx.fill();
            ctx.font = "11px system-ui, sans-serif";
            ctx.fillText(String(k + 1), sx + 8, sy + 12);
          });
        }
      }
      // true position (simulation)
      if (checks.truth.checked && state.truth && state.truth.utm) {
        const world = toWorld(state.truth.utm);
        if (world) {
          const [sx, sy] = view.screenOf(world[0], world[1]);
          ctx.strokeStyle = "#3fb950"; ctx.lineWidth = 2; ctx.beginPath(); ctx.arc(sx, sy, 5, 0, 2 * Math.PI); ctx.stroke();
        }
      }
      // the vehicle (estimate): footprint from the rear axle to the front bumper
      if (state.pose) {
        const yaw = yawOf(state.pose);
        const front = bumperOffset(app), rear = -0.5, half = 0.7;
        const corners = [[rear, -half], [front, -half], [front + 0.4, 0], [front, half], [rear, half]];
        ctx.fillStyle = "rgba(255,255,255,0.9)"; ctx.strokeStyle = "#000"; ctx.lineWidth = 1;
        ctx.beginPath();
        corners.forEach(([x, y], k) => {
          const wx = state.pose[3] + Math.cos(yaw) * x - Math.sin(yaw) * y;
          const wy = state.pose[7] + Math.sin(yaw) * x + Math.cos(yaw) * y;
          const [sx, sy] = view.screenOf(wx, wy);
          k ? ctx.lineTo(sx, sy) : ctx.moveTo(sx, sy);
        });
        ctx.closePath(); ctx.fill(); ctx.stroke();
        facts.push(["vehicle", `${fmt(state.pose[3], 1)}, ${fmt(state.pose[7], 1)} m`],
                   ["heading", `${fmt((90 - (yaw * 180) / Math.PI + 360) % 360, 1)}°`]);
      }
      // north arrow and scale bar
      ctx.fillStyle = "#d8dde6"; ctx.font = "12px system-ui, sans-serif";
      ctx.beginPath(); ctx.moveTo(w - 24, 14); ctx.lineTo(w - 30, 30); ctx.lineTo(w - 18, 30); ctx.fill();
      ctx.fillText("N", w - 28, 44);
      const bar = step / mpp;
      ctx.fillRect(12, h - 16, bar, 3); ctx.fillText(`${step} m`, 12, h - 22);
      facts.push(["scale", `${fmt(mpp * 100, 1)} cm/px`]);
      kvFacts(facts);
      info.textContent = message ? `${message.event.type} · ${message.event.body.rows}×${message.event.body.cols}` : "";
      for (const done of view.pending) app.drawn(done);
      view.pending = [];
      view.dirty = false;
    }

    function kvFacts(pairs) {
      facts.replaceChildren();
      for (const [k, v] of pairs) facts.append(el("dt", { text: k }), el("dd", { text: v }));
    }

    const surface = new Surface(box, "maps", draw);
    box.addEventListener("wheel", (e) => {
      e.preventDefault();
      view.mpp = Math.min(5, Math.max(0.01, view.mpp * (e.deltaY > 0 ? 1.2 : 1 / 1.2)));
      view.dirty = true;
    }, { passive: false });
    return view;
  },
};

// x of the front bumper in the vehicle frame, from the geometry model (else 2.9 m)
export function bumperOffset(app) {
  const geometry = app.state.geometry;
  if (geometry) {
    const frame = geometry.frames.find((f) => f.name === "Raptor:Front-BumperCenter");
    if (frame) return frame.transform[3];
  }
  return 2.9;
}
