// Launcher (seed §4.4.3, Figure 19): the component table with start, stop and restart.
// The buttons are disabled unless the console was started with --console-control and
// this page has the control token; the server refuses such requests anyway.

import { bytes, el } from "../util.js";

const COLUMNS = [
  ["#", "n"], ["Name", "name"], ["Type", "type"], ["State", "state"], ["Health", "detail"],
  ["Restarts", "restarts"], ["dT (s)", "start_delay"], ["Events in", "events_in"],
  ["Events out", "events_out"], ["Loop %", "loop_share"], ["Memory ≈", "memory"], ["", "actions"],
];

export default {
  id: "launcher",
  title: "Launcher",
  short: "Launcher",
  seed: "Launcher · qtHealthSafety",
  wide: true,
  kinds: { status: null },
  fps: 2,
  create(app, body, info) {
    body.style.flexDirection = "column";
    const scroll = el("div", { class: "scroll" });
    const table = el("table", { class: "launcher", "data-probe-table": "launcher" });
    const head = el("tr");
    for (const [label, key] of COLUMNS) head.append(el("th", { class: key, text: label }));
    table.append(el("thead", {}, head));
    const tbody = el("tbody");
    table.append(tbody);
    scroll.append(table);
    const details = el("div", { class: "details", text: "select a component for its counters" });
    body.append(scroll, details);
    let selected = null;
    let rows = [];

    const act = async (name, action) => {
      const result = await app.post(`/api/components/${encodeURIComponent(name)}/${action}`);
      return result;
    };

    function cell(row, key, index) {
      const td = el("td", { class: key });
      switch (key) {
        case "n": td.textContent = String(index + 1); break;
        case "state": td.textContent = row.state; break;
        case "detail": td.textContent = row.healthy ? "ok" : (row.detail || row.last_error || "unhealthy"); break;
        case "start_delay": td.textContent = row.start_delay.toFixed(1); break;
        case "loop_share": {
          td.classList.add("bar-cell");
          const share = row.loop_share * 100;
          td.append(el("span", { class: "barfill", style: `width:${Math.min(100, share * 2).toFixed(1)}%` }),
                    el("span", { class: "val", text: share.toFixed(share < 10 ? 2 : 1) }));
          break;
        }
        case "memory": td.textContent = bytes(row.memory); break;
        case "events_in": td.textContent = row.events_in_dropped
          ? `${row.events_in} (−${row.events_in_dropped})` : String(row.events_in); break;
        case "actions": {
          for (const action of ["start", "stop", "restart"]) {
            const running = row.state === "running" || row.state === "starting";
            const pointless = (action === "start" && running) || (action === "stop" && !running);
            td.append(el("button", {
              type: "button", "data-action": action, "data-component": row.name,
              disabled: !app.canControl || pointless ? "" : null,
              title: app.canControl ? `${action} ${row.name}`
                                    : "view only: start the console with --console-control",
              text: action, onclick: (e) => { e.stopPropagation(); act(row.name, action); },
            }));
          }
          break;
        }
        default: td.textContent = String(row[key] ?? "");
      }
      return td;
    }

    function showDetails() {
      const row = rows.find((r) => r.name === selected);
      if (!row) { details.textContent = "select a component for its counters"; return; }
      const lines = [`${row.name} (${row.type}): ${row.state}, ${row.failures} failure(s)` +
                     (row.last_error ? `, last error ${row.last_error}` : "")];
      for (const [key, value] of Object.entries(row.statistics)) {
        lines.push(`  ${key}: ${typeof value === "object" ? JSON.stringify(value) : value}`);
      }
      details.textContent = lines.join("\n");
    }

    return {
      dirty: false,
      onMessage(message) { rows = message.header.components; this.status = message.header; this.dirty = true; },
      render() {
        const status = this.status;
        if (!status) return;
        tbody.replaceChildren();
        rows.forEach((row, index) => {
          const tr = el("tr", { "data-component": row.name,
                                class: `${row.state} ${row.healthy ? "" : "unhealthy"} ${row.name === selected ? "selected" : ""}` });
          for (const [, key] of COLUMNS) tr.append(cell(row, key, index));
          tr.addEventListener("click", () => { selected = row.name; showDetails(); this.dirty = true; });
          tbody.append(tr);
        });
        for (const entry of status.not_started) {
          const tr = el("tr", { class: "inactive", "data-component": entry.name });
          tr.append(el("td", { class: "n", text: "" }), el("td", { class: "name", text: entry.name }),
                    el("td", { class: "type", text: entry.type }),
                    el("td", { class: "state", text: entry.state }),
                    el("td", { class: "detail", text: entry.state === "not implemented"
                      ? "configured; its component is not written yet" : "configured, not in this system" }),
                    el("td"), el("td", { text: entry.start_delay.toFixed(1) }),
                    el("td"), el("td"), el("td"), el("td"), el("td"));
          tbody.append(tr);
        }
        const others = Object.entries(status.loop.others).sort((a, b) => b[1] - a[1])
          .filter(([, share]) => share >= 0.0005)
          .map(([name, share]) => `${name} ${(share * 100).toFixed(1)} %`).join(" · ");
        info.textContent = `${rows.length} components · loop busy ${(status.loop.busy * 100).toFixed(1)} %` +
          (others ? ` (besides components: ${others})` : "");
        showDetails();
        this.dirty = false;
      },
      invalidate() { this.dirty = true; },
    };
  },
};
