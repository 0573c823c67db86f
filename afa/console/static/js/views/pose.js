// Pose (qtEventPose, seed §4.3, Figure 15): ModelServer's Pose events as they are
// published: position, heading, speed, poseValidFlag, and in simulation the error against
// ground truth.

import { Strip, Surface, deg, el, flag, fmt, kv, rpyOf } from "../util.js";

export default {
  id: "pose",
  title: "Pose",
  short: "Pose",
  seed: "qtEventPose",
  kinds: { pose: null, truth: null, vehicle: null, gps: null },
  fps: 5,
  create(app, body, info) {
    body.style.flexDirection = "column";
    const top = el("div", { class: "grid2" });
    const left = el("dl", { class: "kv" });
    const right = el("dl", { class: "kv" });
    top.append(left, right);
    const box = el("div", { class: "canvas-box", style: "min-height:160px" });
    body.append(top, box);
    const strip = new Strip(60);
    let last = null, anchor = null, speed = null, rate = null;

    const view = {
      dirty: true, pending: [],
      onMessage(message) {
        const { header, event } = message;
        if (header.kind === "pose") {
          const m = event.body.HTransform;
          if (last && event.time > last.time) {
            const dt = event.time - last.time;
            rate = rate === null ? 1 / dt : 0.9 * rate + 0.1 / dt;
          }
          last = { time: event.time, m };
          // speed over at least half a second of poses (a pose's noise over 10 ms is not speed)
          if (!anchor || event.time - anchor.time > 5) anchor = { time: event.time, m };
          if (event.time - anchor.time >= 0.5) {
            speed = Math.hypot(m[3] - anchor.m[3], m[7] - anchor.m[7]) / (event.time - anchor.time);
            anchor = { time: event.time, m };
          }
          const measured = app.state.vehicle ? app.state.vehicle.body.velocity.translation : null;
          strip.push("speed", event.time, measured ?? speed);
          const truth = app.state.truth;
          if (truth && truth.pose_error_m !== null) strip.push("error", event.time, truth.pose_error_m);
          this.pending.push(message);
        }
        this.dirty = true;
      },
      invalidate() { this.dirty = true; surface.invalidate(); },
      render() {
        const event = app.state.poseEvent;
        if (event) {
          const m = event.body.HTransform;
          const utm = event.body.initialUTM;
          const { roll, pitch, yaw } = rpyOf(m);
          const heading = (90 - deg(yaw) + 360) % 360;
          const measured = app.state.vehicle ? app.state.vehicle.body.velocity.translation : null;
          kv(left, [
            ["easting", `${fmt(utm[0] + m[3], 2)} m`], ["northing", `${fmt(utm[1] + m[7], 2)} m`],
            ["elevation", `${fmt(utm[2] + m[11], 2)} m`],
            ["heading", el("span", { class: "big", text: `${fmt(heading, 1)}°` })],
            ["speed", `${fmt(measured ?? speed, 2)} m/s${measured === null ? " (from poses)" : ""}`],
            ["poseValidFlag", event.body.poseValidFlag ? flag("valid", "ok") : flag("questionable", "warn")],
          ]);
          const truth = app.state.truth;
          const gps = app.state.gps;
          kv(right, [
            ["world x, y, z", `${fmt(m[3], 2)}, ${fmt(m[7], 2)}, ${fmt(m[11], 2)} m`],
            ["roll, pitch", `${fmt(deg(roll), 2)}°, ${fmt(deg(pitch), 2)}°`],
            ["initialUTM", `${fmt(utm[0], 1)}, ${fmt(utm[1], 1)}`],
            ["time", new Date(event.time * 1000).toISOString().slice(11, 23)],
            ["rate", `${fmt(rate, 1)} Hz`],
            ["pose error", truth ? (truth.pose_error_m === null ? "—"
              : `${fmt(truth.pose_error_m, 3)} m, ${fmt(truth.heading_error_deg, 2)}°`) : "no ground truth"],
            ["true speed", truth ? `${fmt(truth.speed, 2)} m/s` : "—"],
            ["GPS", gps ? `${gps.body.positionType}, ${gps.body.satellitesUsed} sats` : "—"],
          ]);
          info.textContent = `from ${event.origin || "—"}`;
        } else {
          kv(left, [["Pose", "no Pose events yet (ModelServer publishes them)"]]);
        }
        surface.render();
        for (const done of this.pending) app.drawn(done);
        this.pending = [];
        this.dirty = false;
      },
    };
    const surface = new Surface(box, "pose", (ctx, w, h) => {
      ctx.fillStyle = "#101318"; ctx.fillRect(0, 0, w, h);
      strip.draw(ctx, 4, 4, w - 8, h - 24, { speed: "#58a6ff", error: "#f85149" }, [0, 0.5]);
      ctx.font = "11px system-ui, sans-serif";
      ctx.fillStyle = "#58a6ff"; ctx.fillText("speed m/s", 8, h - 6);
      ctx.fillStyle = "#f85149"; ctx.fillText("pose error m (simulation)", 80, h - 6);
      ctx.fillStyle = "#8b94a3"; ctx.fillText("last 60 s", w - 60, h - 6);
    });
    return view;
  },
};
