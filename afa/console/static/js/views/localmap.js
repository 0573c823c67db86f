// Local map (LocalMap, seed §4.4.2, Figure 18; Figure 10's arcs): the egocentric terrain or
// traversability map seen from the front bumper (bumper at the bottom, ahead up), with
// every candidate arc coloured by the Arc Arbiter's combined score (ArcDecision), vetoed
// arcs grey and dashed, the chosen arc highlighted, or by one behaviour's own votes.
//
// Arcs start at the vehicle reference point (the rear axle, where the curvature of an
// Ackermann vehicle is defined); the console sends each ego map with ^Ref T_map, so the
// rear axle is placed in the map frame from the geometry model.

import { CHOSEN, OBSTACLE, Surface, VETOED, el, fmt, hazardColour, invRigid, ramp, rgb, scoreColour } from "../util.js";
import { bumperOffset } from "./maps.js";

const LAYERS = { traverse: "ego.traverse", terrain: "ego.terrain" };

function egoImage(body, layer) {
  const rows = body.rows, cols = body.cols;
  const image = new ImageData(cols, rows);
  const data = image.data;
  let lo = Infinity, hi = -Infinity;
  if (layer === "terrain") {
    for (const v of body.elevation) if (v === v) { if (v < lo) lo = v; if (v > hi) hi = v; }
  }
  const span = hi - lo > 1e-6 ? hi - lo : 1;
  for (let i = 0; i < rows; i++) {
    for (let j = 0; j < cols; j++) {
      const k = i * cols + j;
      const colour = layer === "traverse" ? hazardColour(body.hazard[k])
        : (body.elevation[k] === body.elevation[k] ? ramp((body.elevation[k] - lo) / span) : null);
      if (!colour) continue;
      const p = ((rows - 1 - i) * cols + (cols - 1 - j)) * 4;  // ahead up, left to the left
      data[p] = colour[0]; data[p + 1] = colour[1]; data[p + 2] = colour[2]; data[p + 3] = 255;
    }
  }
  const canvas = document.createElement("canvas");
  canvas.width = cols; canvas.height = rows;
  canvas.getContext("2d").putImageData(image, 0, 0);
  return canvas;
}

// Points of the arc of curvature k from (x0, y0) heading `yaw`, every `ds` m, while inside.
function arcPoints(k, start, inside, ds = 0.1, limit = 60) {
  const [x0, y0, yaw] = start;
  const points = [];
  const sMax = Math.abs(k) > 1e-9 ? Math.min(limit, Math.PI / Math.abs(k)) : limit;
  for (let s = 0; s <= sMax; s += ds) {
    const lx = Math.abs(k) > 1e-9 ? Math.sin(k * s) / k : s;
    const ly = Math.abs(k) > 1e-9 ? (1 - Math.cos(k * s)) / k : 0;
    const x = x0 + Math.cos(yaw) * lx - Math.sin(yaw) * ly;
    const y = y0 + Math.sin(yaw) * lx + Math.cos(yaw) * ly;
    if (!inside(x, y)) { if (s > 0.5) break; else continue; }
    points.push([x, y, s]);
  }
  return points;
}

export default {
  id: "localmap",
  title: "Local map",
  short: "Local map",
  seed: "LocalMap · arcs",
  kinds: { "ego.traverse": null, "ego.terrain": null, "arcs.vote": null, "arcs.decision": null },
  fps: 5,
  create(app, body, info) {
    body.style.flexDirection = "row";
    const main = el("div", { style: "flex:1;display:flex;flex-direction:column;min-width:0" });
    const layerSelect = el("select", { "data-control": "localmap-layer" },
                           el("option", { value: "traverse", text: "traversability" }),
                           el("option", { value: "terrain", text: "terrain (elevation)" }));
    const voteSelect = el("select", { "data-control": "localmap-votes" },
                          el("option", { value: "", text: "combined (arbiter)" }));
    const tools = el("div", { class: "tools" }, el("label", {}, "map ", layerSelect),
                     el("label", {}, "arcs ", voteSelect));
    const box = el("div", { class: "canvas-box" });
    main.append(tools, box);
    const side = el("div", { class: "side" });
    const decisionFacts = el("dl", { class: "kv" });
    const votesList = el("div");
    side.append(el("h3", { text: "decision" }), decisionFacts, el("h3", { text: "votes" }), votesList,
                el("h3", { text: "legend" }),
                el("div", { class: "legend" },
                   el("span", {}, el("span", { class: "swatch", style: `background:${CHOSEN}` }), "chosen"),
                   el("span", {}, el("span", { class: "swatch", style: `background:${scoreColour(1)}` }), "high score"),
                   el("span", {}, el("span", { class: "swatch", style: `background:${scoreColour(0)}` }), "low score"),
                   el("span", {}, el("span", { class: "swatch", style: `background:${VETOED}` }), "vetoed"),
                   el("span", {}, el("span", { class: "swatch", style: `background:${rgb(OBSTACLE)}` }), "obstacle")));
    body.append(main, side);
    const behaviours = new Set();

    const view = {
      dirty: true, layer: "traverse", behaviour: "", map: null, image: null, pending: [], geometry: null,
      wanted() {
        return { [LAYERS[this.layer]]: null, "arcs.vote": null, "arcs.decision": null };
      },
      onMessage(message) {
        const kind = message.header.kind;
        if (kind === LAYERS[this.layer]) {
          this.map = message; this.image = null; this.pending.push(message); this.urgent = true;
        } else if (kind === "arcs.vote") {
          const name = message.event.body.behaviour;
          if (!behaviours.has(name)) {
            behaviours.add(name);
            voteSelect.append(el("option", { value: name, text: name }));
          }
          if (name === this.behaviour) this.pending.push(message);
        } else if (kind === "arcs.decision" && !this.behaviour) {
          this.pending.push(message);
        }
        this.dirty = true;
      },
      invalidate() { this.dirty = true; surface.invalidate(); },
      // map-frame (x ahead, y left) metres -> CSS pixels; set by draw()
      screenOf(x, y) { return this.geometry ? this.geometry.toScreen(x, y) : null; },
      // the screen position of arc `index` at arc length `s` (tests)
      arcAt(index, s) {
        const arcs = this.arcs || [];
        const arc = arcs[index];
        if (!arc) return null;
        let best = null;
        for (const p of arc.points) if (!best || Math.abs(p[2] - s) < Math.abs(best[2] - s)) best = p;
        return best ? this.screenOf(best[0], best[1]) : null;
      },
      render() { surface.render(); },
    };
    layerSelect.addEventListener("change", () => {
      view.layer = layerSelect.value; view.map = null; view.image = null; view.dirty = true; app.subscribe();
    });
    voteSelect.addEventListener("change", () => { view.behaviour = voteSelect.value; view.dirty = true; });

    function draw(ctx, w, h) {
      ctx.fillStyle = "#101318"; ctx.fillRect(0, 0, w, h);
      const message = view.map;
      const b = message ? message.event.body : null;
      // placement of the rear axle (arc origin) in the map frame
      let start = [-bumperOffset(app), 0, 0];
      if (message && message.header.transform) {
        const mT = invRigid(message.header.transform);   // ^M T_Ref
        start = [mT[3], mT[7], Math.atan2(mT[4], mT[0])];
      }
      const xmin = Math.min(b ? b.originX : 0, start[0] - 0.8);
      const xmax = b ? b.originX + b.rows * b.gridsize : 16;
      const ymid = b ? b.originY + (b.cols * b.gridsize) / 2 : 0;
      const width = b ? b.cols * b.gridsize : 16;
      const margin = 8;
      const mpp = Math.max((xmax - xmin) / (h - 2 * margin), width / (w - 2 * margin));
      const toScreen = (x, y) => [w / 2 - (y - ymid) / mpp, h - margin - (x - xmin) / mpp];
      view.geometry = { toScreen, mpp };
      const inside = (x, y) => x <= xmax && x >= xmin && Math.abs(y - ymid) <= width / 2;
      if (b) {
        if (!view.image) view.image = egoImage(b, view.layer);
        const [sx, sy] = toScreen(b.originX + b.rows * b.gridsize, b.originY + b.cols * b.gridsize);
        ctx.imageSmoothingEnabled = false;
        ctx.drawImage(view.image, sx, sy, (b.cols * b.gridsize) / mpp, (b.rows * b.gridsize) / mpp);
        ctx.strokeStyle = "#2c323c"; ctx.strokeRect(sx, sy, (b.cols * b.gridsize) / mpp, (b.rows * b.gridsize) / mpp);
      } else {
        ctx.fillStyle = "#8b94a3"; ctx.font = "13px system-ui, sans-serif";
        ctx.fillText(`no ${LAYERS[view.layer]} events yet`, 12, 22);
      }
      // metre rings ahead of the bumper
      ctx.strokeStyle = "rgba(255,255,255,0.12)"; ctx.fillStyle = "#8b94a3"; ctx.font = "10px system-ui, sans-serif";
      for (let d = 2; d < xmax; d += 2) {
        const [, sy] = toScreen(d, 0);
        ctx.beginPath(); ctx.moveTo(0, sy); ctx.lineTo(w, sy); ctx.stroke();
        ctx.fillText(`${d} m`, 4, sy - 2);
      }
      // the vehicle outline, rear axle to bumper
      ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 1.5;
      const corners = [[start[0] - 0.5, -0.7], [0, -0.7], [0, 0.7], [start[0] - 0.5, 0.7]];
      ctx.beginPath();
      corners.forEach(([x, y], k) => { const [sx, sy] = toScreen(x, y); k ? ctx.lineTo(sx, sy) : ctx.moveTo(sx, sy); });
      ctx.closePath(); ctx.stroke();

      // the arcs
      const decision = app.state.decision ? app.state.decision.body : null;
      const vote = view.behaviour ? app.state.votes.get(view.behaviour) : null;
      let curvatures = null, values = null, vetoed = null, chosen = -1, caption = "";
      if (view.behaviour && vote) {
        const v = vote.body;
        curvatures = v.curvatures; vetoed = v.veto;
        values = Array.from(v.vote, (x, k) => x * v.certainty[k]);
        caption = `${view.behaviour}: vote × certainty`;
      } else if (!view.behaviour && decision) {
        curvatures = decision.curvatures; vetoed = decision.vetoed; values = Array.from(decision.scores);
        chosen = decision.index; caption = "combined score (ArcDecision)";
      } else {
        const any = app.state.votes.values().next().value;
        if (any) { curvatures = any.body.curvatures; caption = "no ArcDecision yet: arcs only"; }
        else caption = "no arcs yet (ArcVote / ArcDecision events)";
      }
      view.arcs = [];
      if (curvatures) {
        let top = 0;
        if (values) values.forEach((v, k) => { if (!(vetoed && vetoed[k]) && v > top) top = v; });
        // vetoed arcs underneath, then by score, the chosen one on top
        const rank = (k) => (k === chosen ? 2 : vetoed && vetoed[k] ? 0 : 1);
        const order = Array.from(curvatures, (_, k) => k)
          .sort((a, c) => rank(a) - rank(c) || (values ? values[a] - values[c] : 0));
        for (const k of order) view.arcs[k] = { points: arcPoints(curvatures[k], start, inside) };
        for (const k of order) {
          const points = view.arcs[k].points;
          if (points.length < 2) continue;
          const isVetoed = vetoed && vetoed[k];
          ctx.setLineDash(isVetoed ? [5, 4] : []);
          ctx.lineWidth = k === chosen ? 5 : 2;
          ctx.strokeStyle = k === chosen ? CHOSEN : isVetoed ? VETOED
            : values ? scoreColour(top > 0 ? values[k] / top : 0) : "#6e7681";
          ctx.beginPath();
          points.forEach(([x, y], n) => { const [sx, sy] = toScreen(x, y); n ? ctx.lineTo(sx, sy) : ctx.moveTo(sx, sy); });
          ctx.stroke();
          if (isVetoed) {   // a cross at the end of a vetoed arc
            const [ex, ey] = toScreen(points[points.length - 1][0], points[points.length - 1][1]);
            ctx.setLineDash([]); ctx.lineWidth = 1.5; ctx.beginPath();
            ctx.moveTo(ex - 4, ey - 4); ctx.lineTo(ex + 4, ey + 4); ctx.moveTo(ex + 4, ey - 4); ctx.lineTo(ex - 4, ey + 4);
            ctx.stroke();
          }
        }
        ctx.setLineDash([]);
      }
      ctx.fillStyle = "#d8dde6"; ctx.font = "12px system-ui, sans-serif"; ctx.fillText(caption, 12, h - 14);

      // side panel
      const facts = [];
      if (decision) {
        facts.push(["chosen arc", decision.index >= 0 ? `${decision.index} of ${decision.curvatures.length}` : "none"],
                   ["curvature", `${fmt(decision.curvature, 3)} 1/m`],
                   ["steering", `${fmt((decision.steeringAngle * 180) / Math.PI, 1)}°`],
                   ["speed", `${fmt(decision.speed, 2)} m/s`],
                   ["fail-safe", decision.failsafe || "none"],
                   ["fresh", decision.fresh.join(", ") || "—"], ["stale", decision.stale.join(", ") || "—"]);
        if (decision.unknown.length) facts.push(["unknown", decision.unknown.join(", ")]);
      } else facts.push(["arbiter", "no ArcDecision events"]);
      decisionFacts.replaceChildren();
      for (const [k, v] of facts) decisionFacts.append(el("dt", { text: k }), el("dd", { text: v }));
      votesList.replaceChildren();
      for (const [name, event] of app.state.votes) {
        const v = event.body;
        let best = 0;
        for (let k = 1; k < v.vote.length; k++) if (v.vote[k] > v.vote[best]) best = k;
        const vetoes = v.veto.reduce((n, x) => n + (x ? 1 : 0), 0);
        votesList.append(el("div", { text: `${name}: ${vetoes === v.veto.length ? "HALT (all vetoed)" : `best arc ${best}, ${vetoes} vetoed`}` }));
      }
      info.textContent = message ? `${message.event.type} · ${message.header.stream.split("/")[1]} frame ${b.frame}` : "";
      for (const done of view.pending) app.drawn(done);
      view.pending = [];
      view.dirty = false;
    }

    const surface = new Surface(box, "localmap", draw);
    return view;
  },
};
