// The console page: one WebSocket, panes a user can show, hide, reorder (drag a title bar)
// or look at one at a time. Each view says which kinds of data it shows; the page asks the
// server for exactly the kinds of the views on screen (none while the tab is hidden).

import { decodeMessage } from "./wire.js";
import { el, utm } from "./util.js";
import launcher from "./views/launcher.js";
import maps from "./views/maps.js";
import localmap from "./views/localmap.js";
import pose from "./views/pose.js";
import scene3d from "./views/scene3d.js";
import vehicle from "./views/vehicle.js";
import replay from "./views/replay.js";

const VIEWS = [launcher, maps, localmap, pose, scene3d, vehicle, replay];
const LAYOUT_KEY = "afa.console.layout";
const TOKEN_HEADER = "X-Afa-Control-Token";

class App {
  constructor() {
    this.views = {};
    this.panes = {};
    this.hello = null;
    this.state = { status: null, pose: null, poseEvent: null, track: [], geometry: null,
                   truth: null, waypoints: null, vehicle: null, imu: null, decision: null,
                   votes: new Map() };
    this.stats = { messages: 0, bytes: 0, byKind: {}, latency: {}, errors: 0, lastError: null,
                   connected: false, connections: 0 };
    this.ready = false;
    this.token = this._token();
    this.layout = this._urlLayout(this._loadLayout());
    this.ws = null;
    this._frame = null;
  }

  // -- set-up ------------------------------------------------------------------------------
  start() {
    const panes = document.getElementById("panes");
    const toggles = document.getElementById("toggles");
    for (const definition of VIEWS) {
      const pane = el("section", { class: `pane${definition.wide ? " wide" : ""}`,
                                   id: `pane-${definition.id}`, "data-view": definition.id });
      const title = el("h2", { draggable: "true" }, definition.title,
                       el("span", { class: "seed", text: definition.seed || "" }),
                       el("span", { class: "info" }));
      pane.append(title);
      const body = el("div", { class: "body" });
      pane.append(body);
      panes.append(pane);
      this.panes[definition.id] = pane;
      this.views[definition.id] = definition.create(this, body, title.querySelector(".info"));
      this.views[definition.id].definition = definition;
      this._draggable(pane, title);
      const box = el("input", { type: "checkbox", "data-toggle": definition.id });
      box.checked = this.layout.visible[definition.id] !== false;
      box.addEventListener("change", () => {
        this.layout.visible[definition.id] = box.checked; this._applyLayout();
      });
      toggles.append(el("label", {}, box, definition.short || definition.title));
    }
    const select = document.getElementById("layout");
    select.value = this.layout.mode;
    select.addEventListener("change", () => { this.layout.mode = select.value; this._applyLayout(); });
    document.getElementById("stop-vehicle").addEventListener("click", () => this.stopVehicle());
    document.addEventListener("visibilitychange", () => this.subscribe());
    this._applyLayout();
    this.connect();
    this._loop();
  }

  _token() {
    const match = /token=([A-Za-z0-9_-]+)/.exec(location.hash);
    if (match) {
      sessionStorage.setItem("afa.console.token", match[1]);
      history.replaceState(null, "", location.pathname + location.search);  // out of sight
    }
    return sessionStorage.getItem("afa.console.token");
  }

  _loadLayout() {
    const fallback = { mode: "grid", order: VIEWS.map((v) => v.id), visible: {}, active: "launcher" };
    try {
      const saved = JSON.parse(localStorage.getItem(LAYOUT_KEY) || "null");
      if (saved && Array.isArray(saved.order)) {
        const known = new Set(VIEWS.map((v) => v.id));
        const order = saved.order.filter((id) => known.has(id));
        for (const v of VIEWS) if (!order.includes(v.id)) order.push(v.id);
        return { ...fallback, ...saved, order };
      }
    } catch (error) { /* a broken saved layout: start afresh */ }
    return fallback;
  }

  // ?views=maps,localmap shows only those panes; ?layout=tabs one at a time (a bookmark
  // for a particular screen; overrides the saved layout)
  _urlLayout(layout) {
    const params = new URLSearchParams(location.search);
    if (params.get("layout") === "tabs" || params.get("layout") === "grid") layout.mode = params.get("layout");
    if (params.get("views")) {
      const wanted = new Set(params.get("views").split(","));
      for (const v of VIEWS) layout.visible[v.id] = wanted.has(v.id);
    }
    return layout;
  }

  _applyLayout() {
    const panes = document.getElementById("panes");
    const tabs = document.getElementById("tabs");
    panes.classList.toggle("tabs-mode", this.layout.mode === "tabs");
    tabs.hidden = this.layout.mode !== "tabs";
    tabs.replaceChildren();
    for (const id of this.layout.order) panes.append(this.panes[id]);
    const available = (id) => id !== "replay" || (this.hello && this.hello.replay);
    const visible = this.layout.order.filter((id) => this.layout.visible[id] !== false && available(id));
    if (!visible.includes(this.layout.active)) this.layout.active = visible[0];
    for (const id of this.layout.order) {
      const shown = visible.includes(id) && (this.layout.mode === "grid" || this.layout.active === id);
      this.panes[id].hidden = !shown;
      const box = document.querySelector(`[data-toggle="${id}"]`);
      if (box) { box.disabled = !available(id); box.parentElement.hidden = !available(id); }
      if (this.layout.mode === "tabs" && visible.includes(id)) {
        const view = VIEWS.find((v) => v.id === id);
        const button = el("button", { class: id === this.layout.active ? "active" : "",
                                      "data-tab": id, text: view.short || view.title,
                                      onclick: () => { this.layout.active = id; this._applyLayout(); } });
        tabs.append(button);
      }
    }
    localStorage.setItem(LAYOUT_KEY, JSON.stringify(this.layout));
    for (const view of Object.values(this.views)) view.invalidate && view.invalidate();
    this.subscribe();
  }

  _draggable(pane, title) {
    title.addEventListener("dragstart", (e) => { e.dataTransfer.setData("text/plain", pane.dataset.view); });
    pane.addEventListener("dragover", (e) => { e.preventDefault(); pane.classList.add("dragover"); });
    pane.addEventListener("dragleave", () => pane.classList.remove("dragover"));
    pane.addEventListener("drop", (e) => {
      e.preventDefault(); pane.classList.remove("dragover");
      const moved = e.dataTransfer.getData("text/plain");
      this.move(moved, pane.dataset.view);
    });
  }

  // Put view `moved` where view `target` is (the page's drag and drop; also for tests).
  move(moved, target) {
    const order = this.layout.order.filter((id) => id !== moved);
    const at = order.indexOf(target);
    if (at < 0 || moved === target) return;
    order.splice(at, 0, moved);
    this.layout.order = order;
    this._applyLayout();
  }

  shown(id) { return !this.panes[id].hidden; }

  // -- data ----------------------------------------------------------------------------------
  connect() {
    const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
    ws.binaryType = "arraybuffer";
    this.ws = ws;
    const link = document.getElementById("link");
    ws.onopen = () => { this.stats.connected = true; this.stats.connections++;
                        link.textContent = "live"; link.className = "pill on"; };
    ws.onclose = () => {
      this.stats.connected = false;
      link.textContent = "disconnected"; link.className = "pill bad";
      setTimeout(() => this.connect(), 1000);
    };
    ws.onmessage = (message) => this.receive(message.data);
  }

  subscribe() {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN || !this.hello) return;
    const kinds = { status: null };
    if (!document.hidden) {
      for (const [id, view] of Object.entries(this.views)) {
        if (!this.shown(id)) continue;
        const wanted = view.wanted ? view.wanted() : view.definition.kinds;
        for (const [kind, rate] of Object.entries(wanted)) {
          // null: the server's default rate for the kind (afa/console/streams.py)
          const chosen = rate || (this.hello.policies[kind] ? this.hello.policies[kind].rate : 1);
          kinds[kind] = Math.max(kinds[kind] || 0, chosen);
        }
      }
    } else {
      kinds.status = 0.2;   // a hidden tab: the header only, rarely
    }
    this.subscribed = kinds;
    this.ws.send(JSON.stringify({ op: "subscribe", kinds }));
  }

  receive(buffer) {
    let message;
    try {
      message = decodeMessage(buffer);
    } catch (error) {
      this.stats.errors++; this.stats.lastError = String(error); return;
    }
    const { header } = message;
    message.received = Date.now() / 1000;
    this.stats.messages++;
    this.stats.bytes += buffer.byteLength;
    this.stats.byKind[header.kind] = (this.stats.byKind[header.kind] || 0) + 1;
    if (header.kind === "hello") { this.onHello(header); return; }
    this._share(message);
    for (const [id, view] of Object.entries(this.views)) {
      if (view.definition.kinds[header.kind] !== undefined && this.shown(id)) {
        try { view.onMessage(message); } catch (error) {
          this.stats.errors++; this.stats.lastError = `${id}: ${error}`; console.error(error);
        }
      }
    }
  }

  onHello(hello) {
    this.hello = hello;
    document.getElementById("robot").textContent = hello.robot;
    const control = document.getElementById("control");
    control.textContent = hello.control ? "control on" : "view only";
    control.className = `pill ${hello.control ? "on" : ""}`;
    control.title = hello.control
      ? (this.token ? "this console may start, stop and restart components and command the vehicle"
                    : "control is on, but this page has no token: open the URL the console printed")
      : "start the console with --console-control to allow commands ('stop vehicle' always works)";
    this._applyLayout();
    for (const view of Object.values(this.views)) view.onHello && view.onHello(hello);
  }

  get canControl() { return Boolean(this.hello && this.hello.control && this.token); }

  _share(message) {
    const { header, event } = message;
    const state = this.state;
    switch (header.kind) {
      case "status":
        state.status = header; this.ready = true; this._statusBar(header); break;
      case "pose": {
        state.pose = event.body.HTransform; state.poseEvent = event;
        state.initialUTM = event.body.initialUTM;
        for (const pose of message.events) {
          const x = pose.body.HTransform[3], y = pose.body.HTransform[7];
          const last = state.track[state.track.length - 1];
          if (!last || Math.hypot(x - last[0], y - last[1]) > 0.1) state.track.push([x, y]);
        }
        if (state.track.length > 10000) state.track.splice(0, 1000);
        break;
      }
      case "geometry": state.geometry = header; break;
      case "truth": state.truth = header.truth; break;
      case "waypoints": state.waypoints = header.lists; break;
      case "vehicle": state.vehicle = event; break;
      case "imu": state.imu = event; break;
      case "gps": state.gps = event; break;
      case "arcs.decision": state.decision = event; break;
      case "arcs.vote": state.votes.set(event.body.behaviour, event); break;
      default: break;
    }
  }

  // A view drew `message`: keep how long it took from the event to the screen.
  drawn(message) {
    if (!message || !message.event || message.counted) return;
    message.counted = true;
    const now = Date.now() / 1000;
    const kind = message.header.kind;
    const samples = this.stats.latency[kind] || (this.stats.latency[kind] = []);
    const fromEvent = this.state.status && this.state.status.clock === "wall"
      ? (now - message.event.time) * 1000 : null;
    const waited = message.header.waited ? message.header.waited[message.header.waited.length - 1] : 0;
    samples.push({ intake_ms: (now - message.header.wall + waited) * 1000,
                   event_ms: fromEvent, receive_ms: (now - message.received) * 1000 });
    if (samples.length > 500) samples.splice(0, samples.length - 500);
  }

  _statusBar(status) {
    const running = status.running ? "running" : "stopped";
    const rtf = status.realtime_factor === null || status.paused ? "" : `×${status.realtime_factor.toFixed(2)}`;
    const busy = `${(status.loop.busy * 100).toFixed(1)} %`;
    const rss = status.rss ? `${(status.rss / 1048576).toFixed(0)} MiB` : "—";
    const clock = status.clock === "virtual" ? (status.paused ? "virtual time, paused" : "virtual time")
                                             : "wall time";
    document.getElementById("clock").textContent =
      `${new Date(status.now * 1000).toISOString().replace("T", " ").slice(0, 19)} UTC · ${clock} ${rtf}`;
    const observer = status.console.observer;
    document.getElementById("status-text").textContent =
      `system ${running} · loop busy ${busy} · RSS ${rss} · events dropped ${status.events_dropped}` +
      ` · console observer ${observer.delivered} in / ${observer.dropped} dropped · ${location.host}`;
  }

  // -- actions -------------------------------------------------------------------------------
  async post(path, body = {}) {
    const headers = { "Content-Type": "application/json" };
    if (this.token) headers[TOKEN_HEADER] = this.token;
    let result;
    try {
      const response = await fetch(path, { method: "POST", headers, body: JSON.stringify(body) });
      result = await response.json();
      result.status = response.status;
    } catch (error) {
      result = { ok: false, error: String(error), status: 0 };
    }
    this.say(result.ok ? `${path.split("/").slice(2).join(" ")}: done` : `${result.error}`, result.ok);
    return result;
  }

  stopVehicle() { return this.post("/api/vehicle/stop"); }

  say(text, ok = true) {
    const node = document.getElementById("message");
    node.textContent = text; node.className = `message ${ok ? "ok" : "bad"}`;
  }

  // -- drawing ---------------------------------------------------------------------------------
  // Each view redraws when its data changed, at most `fps` times a second (default 10):
  // a browser on the vehicle's machine must not take the CPU the vehicle needs.
  _loop() {
    const last = {};
    const tick = (now) => {
      for (const [id, view] of Object.entries(this.views)) {
        if (!this.shown(id) || !view.dirty) continue;
        // a new map or decision is drawn at once (they come a few times a second at most);
        // a view that is merely busy (poses at 10 Hz) waits for its frame rate
        const interval = view.urgent ? 30 : 1000 / (view.definition.fps || 10);
        if (last[id] !== undefined && now - last[id] < interval) continue;
        view.urgent = false;
        last[id] = now;
        try { view.render(); } catch (error) {
          this.stats.errors++; this.stats.lastError = `${id}: ${error}`; console.error(error);
        }
      }
      this._frame = requestAnimationFrame(tick);
    };
    this._frame = requestAnimationFrame(tick);
  }

  // -- test hooks --------------------------------------------------------------------------------
  // Pixel statistics of the canvas with data-probe=`id` (drawn into a 2-D canvas, so a WebGL
  // canvas is read too): size, mean and variance of luminance, and how many pixels match
  // `match` ([r, g, b, tolerance]) if given.
  probe(id, match = null, region = null) {
    const canvas = document.querySelector(`canvas[data-probe="${id}"]`);
    if (!canvas || !canvas.width || !canvas.height) return null;
    const copy = document.createElement("canvas");
    copy.width = canvas.width; copy.height = canvas.height;
    const ctx = copy.getContext("2d", { willReadFrequently: true });
    ctx.drawImage(canvas, 0, 0);
    const [x, y, w, h] = region || [0, 0, canvas.width, canvas.height];
    const data = ctx.getImageData(x, y, w, h).data;
    let sum = 0, sum2 = 0, matches = 0;
    const n = data.length / 4;
    for (let k = 0; k < data.length; k += 4) {
      const l = 0.299 * data[k] + 0.587 * data[k + 1] + 0.114 * data[k + 2];
      sum += l; sum2 += l * l;
      if (match && Math.abs(data[k] - match[0]) <= match[3] && Math.abs(data[k + 1] - match[1]) <= match[3]
          && Math.abs(data[k + 2] - match[2]) <= match[3]) matches++;
    }
    const mean = sum / n;
    return { width: canvas.width, height: canvas.height, mean, variance: sum2 / n - mean * mean, matches,
             ratio: window.devicePixelRatio || 1 };
  }

  // RGBA of one CSS pixel of a probe canvas.
  pixel(id, x, y) {
    const canvas = document.querySelector(`canvas[data-probe="${id}"]`);
    const ratio = canvas.width / canvas.getBoundingClientRect().width;
    const copy = document.createElement("canvas");
    copy.width = canvas.width; copy.height = canvas.height;
    const ctx = copy.getContext("2d", { willReadFrequently: true });
    ctx.drawImage(canvas, 0, 0);
    return Array.from(ctx.getImageData(Math.round(x * ratio), Math.round(y * ratio), 1, 1).data);
  }
}

const app = new App();
app.utm = utm;   // for tests and the browser's developer console
window.afaConsole = app;
app.start();
