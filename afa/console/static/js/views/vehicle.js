// Vehicle and health (qtRaptor, qtHealthSafety, qtEventImu): commanded and measured velocity
// and steering, the arbiter switch, watchdogs, Obstacle Detection halts, stale votes and
// the IMU's attitude.

import { Strip, Surface, deg, el, flag, fmt, kv } from "../util.js";

export default {
  id: "vehicle",
  title: "Vehicle & health",
  short: "Vehicle",
  seed: "qtRaptor · qtHealthSafety · qtEventImu",
  kinds: { vehicle: null, imu: null, status: null, "arcs.decision": null },
  fps: 5,
  create(app, body, info) {
    body.style.flexDirection = "column";
    const buttons = el("div", { class: "tools" });
    const start = el("button", { type: "button", "data-action": "vehicle-start", text: "start vehicle",
                                 onclick: () => app.post("/api/vehicle/start") });
    const arbOn = el("button", { type: "button", "data-action": "arbiter-on", text: "arbiter on",
                                 onclick: () => app.post("/api/vehicle/arbiter-on") });
    const arbOff = el("button", { type: "button", "data-action": "arbiter-off", text: "arbiter off",
                                  onclick: () => app.post("/api/vehicle/arbiter-off") });
    const stop = el("button", { type: "button", class: "stop", "data-action": "vehicle-stop", text: "stop vehicle",
                                onclick: () => app.stopVehicle() });
    buttons.append(stop, start, arbOn, arbOff);
    const grid = el("div", { class: "grid2" });
    const motion = el("dl", { class: "kv" });
    const health = el("dl", { class: "kv" });
    grid.append(motion, health);
    const box = el("div", { class: "canvas-box", style: "min-height:190px" });
    body.append(buttons, grid, box);
    const speeds = new Strip(60), steering = new Strip(60);

    const view = {
      dirty: true,
      onMessage(message) {
        const { header, event } = message;
        if (header.kind === "vehicle") {
          const v = event.body;
          speeds.push("measured", event.time, v.velocity.translation);
          speeds.push("commanded", event.time, v.target.translation);
          steering.push("measured", event.time, deg(v.velocity.steeringAngle));
          steering.push("commanded", event.time, deg(v.target.steeringAngle));
        }
        this.dirty = true;
      },
      invalidate() { this.dirty = true; surface.invalidate(); },
      render() {
        for (const b of [start, arbOn, arbOff]) {
          b.disabled = !app.canControl;
          b.title = app.canControl ? "" : "view only: start the console with --console-control";
        }
        const event = app.state.vehicle;
        if (event) {
          const v = event.body;
          kv(motion, [
            ["speed measured", `${fmt(v.velocity.translation, 2)} m/s`],
            ["speed commanded", `${fmt(v.target.translation, 2)} m/s`],
            ["steering measured", `${fmt(deg(v.velocity.steeringAngle), 1)}°`],
            ["steering commanded", `${fmt(deg(v.target.steeringAngle), 1)}°`],
            ["yaw rate", `${fmt(v.velocity.rotation, 3)} rad/s`],
            ["vehicle", v.vehicleStarted ? flag("started", "ok") : flag("stopped", "warn")],
            ["arbiter switch", v.arbiterEnabled ? flag("arbiter on", "ok") : flag("arbiter off", "dim")],
          ]);
        } else {
          kv(motion, [["VelocityData", "none yet (Vehicle Control publishes it)"]]);
        }
        const status = app.state.status;
        const rows = [];
        if (status) {
          const unhealthy = status.components.filter((c) => !c.healthy);
          const control = status.components.find((c) => c.name === status.vehicle_control_component);
          rows.push(["Vehicle Control", control ? flag(control.detail || control.state, control.healthy ? "ok" : "bad") : "—"]);
          rows.push(["components", unhealthy.length ? flag(`${unhealthy.length} unhealthy`, "bad") : flag("all healthy", "ok")]);
          for (const c of unhealthy.slice(0, 4)) rows.push([c.name, c.detail || c.last_error || c.state]);
          const od = status.votes.ObstacleDetection;
          rows.push(["Obstacle Detection", od ? (od.halt && !od.stale ? flag(`HALT (${od.halts})`, "bad")
                                                  : flag(`clear, ${od.halts} halt(s)`, "ok")) : flag("no votes", "dim")]);
          const votes = Object.entries(status.votes);
          const stale = votes.filter(([, v]) => v.stale).map(([name]) => name);
          rows.push(["votes", votes.length ? (stale.length ? flag(`stale: ${stale.join(", ")}`, "warn")
                                                          : flag(`${votes.length} fresh`, "ok")) : flag("none", "dim")]);
          for (const [name, v] of votes) rows.push([`  ${name}`, `${fmt(v.age, 1)} s ago${v.halt ? ", halt" : ""}`]);
          const decision = app.state.decision;
          if (decision && decision.body.failsafe) rows.push(["arbiter", flag(`fail-safe: ${decision.body.failsafe}`, "bad")]);
        }
        const imu = app.state.imu;
        if (imu) {
          const b = imu.body;
          rows.push(["IMU roll, pitch", `${fmt(deg(b.roll), 1)}°, ${fmt(deg(b.pitch), 1)}°`],
                    ["IMU yaw", `${fmt(deg(b.yaw), 1)}°`]);
        }
        kv(health, rows);
        surface.render();
        info.textContent = event ? `from ${event.origin}` : "";
        this.dirty = false;
      },
    };

    const surface = new Surface(box, "vehicle", (ctx, w, h) => {
      ctx.fillStyle = "#101318"; ctx.fillRect(0, 0, w, h);
      const horizon = Math.min(h - 8, 170);
      const chartW = Math.max(60, w - horizon - 24);
      speeds.draw(ctx, 4, 4, chartW, h / 2 - 8, { measured: "#58a6ff", commanded: "#ffe14d" }, [0, 0.5]);
      steering.draw(ctx, 4, h / 2 + 2, chartW, h / 2 - 8, { measured: "#58a6ff", commanded: "#ffe14d" }, [-5, 5]);
      ctx.font = "10px system-ui, sans-serif"; ctx.fillStyle = "#8b94a3";
      ctx.fillText("speed m/s (blue measured, yellow commanded)", 8, h / 2 - 8);
      ctx.fillText("steering deg", 8, h - 8);
      // artificial horizon from the IMU
      const imu = app.state.imu;
      const cx = w - horizon / 2 - 8, cy = h / 2, r = horizon / 2 - 4;
      ctx.save();
      ctx.beginPath(); ctx.arc(cx, cy, r, 0, 2 * Math.PI); ctx.clip();
      const roll = imu ? imu.body.roll : 0, pitch = imu ? imu.body.pitch : 0;
      ctx.translate(cx, cy); ctx.rotate(-roll);
      const offset = (deg(pitch) / 30) * r;
      ctx.fillStyle = "#2f6db5"; ctx.fillRect(-2 * r, -2 * r + offset, 4 * r, 2 * r);
      ctx.fillStyle = "#8a5a2b"; ctx.fillRect(-2 * r, offset, 4 * r, 2 * r);
      ctx.strokeStyle = "#fff"; ctx.lineWidth = 1;
      for (let p = -20; p <= 20; p += 10) {
        const y = offset - (p / 30) * r;
        ctx.beginPath(); ctx.moveTo(-r / 4, y); ctx.lineTo(r / 4, y); ctx.stroke();
      }
      ctx.restore();
      ctx.strokeStyle = "#ffe14d"; ctx.lineWidth = 3;
      ctx.beginPath(); ctx.moveTo(cx - r / 2, cy); ctx.lineTo(cx - r / 8, cy); ctx.moveTo(cx + r / 8, cy); ctx.lineTo(cx + r / 2, cy); ctx.stroke();
      ctx.strokeStyle = "#2c323c"; ctx.beginPath(); ctx.arc(cx, cy, r, 0, 2 * Math.PI); ctx.stroke();
      ctx.fillStyle = "#8b94a3"; ctx.fillText(imu ? "IMU attitude" : "no IMU events", cx - r, h - 4);
    });
    return view;
  },
};
