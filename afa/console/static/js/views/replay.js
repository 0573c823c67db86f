// Replay controls: play, pause, step, seek and speed, when the source is a recording
// (afa replay FILE --console). Replay controls change only the player's pace and position,
// so they need no control option.

import { el, fmt } from "../util.js";

export default {
  id: "replay",
  title: "Replay",
  short: "Replay",
  seed: "LogPlayer",
  wide: true,
  kinds: { replay: null },
  fps: 5,
  create(app, body, info) {
    body.style.flexDirection = "column";
    const post = (action, value) => app.post(`/api/replay/${action}`, value === undefined ? {} : { value });
    const play = el("button", { type: "button", "data-action": "replay-play", text: "▶ play", onclick: () => post("play") });
    const pause = el("button", { type: "button", "data-action": "replay-pause", text: "⏸ pause", onclick: () => post("pause") });
    const step = el("button", { type: "button", "data-action": "replay-step", text: "⏭ step", onclick: () => post("step") });
    const slider = el("input", { type: "range", min: "0", max: "1000", value: "0", "data-action": "replay-seek" });
    let seeking = false;
    slider.addEventListener("input", () => { seeking = true; });
    slider.addEventListener("change", () => {
      seeking = false;
      const duration = view.status && view.status.duration;
      if (duration) post("seek", (Number(slider.value) / 1000) * duration);
    });
    const speed = el("select", { "data-action": "replay-speed" });
    for (const s of [0.1, 0.25, 0.5, 1, 2, 4, 8, 16]) speed.append(el("option", { value: String(s), text: `×${s}` }));
    speed.append(el("option", { value: "max", text: "as fast as possible" }));
    speed.value = "1";
    speed.addEventListener("change", () => post("speed", speed.value === "max" ? "max" : Number(speed.value)));
    const where = el("span", { class: "big", text: "—" });
    const state = el("span", { class: "muted" });
    body.append(el("div", { class: "replay-controls" }, play, pause, step, slider, el("label", {}, "speed ", speed), where, state));
    const view = {
      dirty: true, status: null,
      onMessage(message) { this.status = message.header.replay; this.dirty = true; },
      invalidate() { this.dirty = true; },
      render() {
        const s = this.status;
        if (s) {
          where.textContent = `${fmt(s.position, 1)} / ${fmt(s.duration, 1)} s`;
          const pace = s.speed === null ? "as fast as possible" : `×${fmt(s.speed, 2)}`;
          state.textContent = `${s.paused ? "paused" : "playing"} at ${pace}${s.label ? " · " + s.label : ""}`;
          if (!seeking && s.duration) slider.value = String(Math.round((s.position / s.duration) * 1000));
          if (document.activeElement !== speed) {
            const option = Array.from(speed.options).find((o) => (s.speed === null ? o.value === "max"
              : Math.abs(Number(o.value) - s.speed) < 1e-9));
            if (option) speed.value = option.value;
          }
          info.textContent = s.label || "";
        }
        this.dirty = false;
      },
    };
    return view;
  },
};
