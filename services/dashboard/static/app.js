// SkiNet Live dashboard: applies the server's updates (Server-Sent Events) and draws the page.
// Written for this project; no library.  The server sends a snapshot, then updates
// (see services/dashboard/board.py); EventSource reconnects by itself.
"use strict";

const view = {
  system: "", epoch: 0, state: null, verdicts: null, unsafe: null, stateSpace: null, stateSpaceT: null,
  model: { digest: null, lanes: {} }, alive: {}, points: [], violations: [], restarts: [],
  divergences: [], divergencesOlder: 0, pilot: null,
  connected: false, lastMessage: null,
};
const NS = "http://www.w3.org/2000/svg";
const COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22"];
const FILLS = ["#dce8f5", "#fde3c4", "#d5eed5", "#eadcf0", "#eee2d6", "#d9eff2", "#f4f1c9"];
let pending = false;

function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === null || v === undefined) continue;
    if (k === "class") node.className = v; else node.setAttribute(k, v);
  }
  for (const c of children) node.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return node;
}

function svg(tag, attrs, text) {
  const node = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs || {})) node.setAttribute(k, v);
  if (text !== undefined) node.textContent = text;
  return node;
}

function fill(id, ...children) {
  const node = document.getElementById(id);
  node.replaceChildren(...children);
  return node;
}

function clock(t) {
  return t ? new Date(t * 1000).toLocaleTimeString([], { hour12: false }) : "-";
}

function ago(t) {
  if (!t) return "never";
  const s = Math.max(0, Date.now() / 1000 - t);
  return s < 60 ? `${s.toFixed(0)} s ago` : `${(s / 60).toFixed(0)} min ago`;
}

// -- updates ------------------------------------------------------------------------

function apply(u) {
  switch (u.kind) {
    case "snapshot":
      view.system = u.system; view.epoch = u.epoch; view.state = u.state; view.verdicts = u.verdicts;
      view.unsafe = u.unsafe; view.stateSpace = u.state_space; view.stateSpaceT = u.state_space_t;
      view.model = u.model; view.alive = u.alive; view.points = u.points; view.violations = u.violations;
      view.divergences = u.divergences || []; view.divergencesOlder = u.divergences_older || 0;
      view.pilot = u.pilot || null;
      view.lastPointAt = Date.now() / 1000;
      break;
    case "divergences": addDivergences(u.added, u.older); break;
    case "pilot": view.pilot = u.message; break;
    case "state": view.state = u.message; break;
    case "verdicts": view.verdicts = u.message; break;
    case "unsafe": view.unsafe = u.message; break;
    case "state_space": view.stateSpace = u.message; view.stateSpaceT = u.t; break;
    case "model": view.model = u.model; break;
    case "alive": view.alive = u.alive; break;
    case "restart": view.epoch = u.epoch; view.verdicts = null; view.unsafe = null; break;
    case "violation": view.violations[u.violation.n] = u.violation; break;
    case "point": {
      const pts = view.points, p = u.point;
      let k = pts.length - 1;
      while (k >= 0 && pts[k].i > p.i) k--;
      if (k >= 0 && pts[k].i === p.i) pts[k] = p; else pts.splice(k + 1, 0, p);
      if (pts.length > 5000) pts.splice(0, pts.length - 5000);
      view.lastPointAt = Date.now() / 1000;
      break;
    }
  }
  view.lastMessage = Date.now() / 1000;
}

function schedule() {
  if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; render(); }); }
}

// -- panels -------------------------------------------------------------------------

function render() {
  document.body.dataset.seq = view.state ? view.state.seq : -1;
  document.body.dataset.epoch = view.epoch;
  document.getElementById("system").textContent = view.system;
  document.title = `SkiNet Live: ${view.system}`;
  renderHeader();
  renderSkillsets();
  renderProperties();
  renderUnsafe();
  renderSpace();
  renderViolations();
  renderDivergences();
  renderPilot();
  renderTimeline();
}

function renderHeader() {
  const st = document.getElementById("status");
  st.dataset.connected = view.connected;
  st.textContent = view.connected ? "live" : "disconnected, reconnecting\u2026";
  const monitors = view.alive.monitor || [];
  const replay = monitors.length > 0 && monitors.every((id) => id.startsWith("replay-"));  // skinet replay's token
  const services = [["monitor", "monitor"], ["bridge_ros2", "bridge"], ["predictor", "predictors"], ["pilot", "pilot"]].map(([s, label]) => {
    const ids = view.alive[s] || [];
    const up = s === "predictor" ? ids.length : (s === "monitor" && replay ? "replay" : "up");
    // A pilot never heard of was not started (skinet demo --live has none by design): off, not a failure.
    const off = s === "pilot" && !ids.length && !view.pilot;
    return el("span", { class: "service " + (ids.length ? "up" : off ? "off" : "down"), "data-service": s,
      "data-alive": ids.length, title: ids.join(", ") || (off ? "no pilot started: skinet run starts one" : "none alive") },
      `${label}: ${ids.length ? up : off ? "off" : "none"}`);
  });
  fill("services", ...services);
  const s = view.state;
  fill("step", s ? `step ${s.seq} \u00b7 ${s.event || "start"} \u00b7 ${clock(s.stamp)}` : "no monitor message yet");
  // docs/semantics.md §7: a marking the monitor cannot vouch for is said plainly, with since when and why.
  const stale = document.getElementById("stale");
  const sync = s && s.sync ? Object.entries(s.sync) : [];
  const notLive = sync.filter(([, x]) => x.state !== "live");
  stale.hidden = !s || (sync.length > 0 && !notLive.length);
  stale.dataset.state = notLive.some(([, x]) => x.state === "lost") ? "lost" : "syncing";
  stale.textContent = !s ? "" : notLive.length
    ? "STATE NOT LIVE: the marking shown may not be the robot's. " + notLive.map(([n, x]) =>
      `${n} ${x.state.toUpperCase()} since ${clock(x.since)}: ${x.reason}`).join("; ")
    : "STATE NOT VOUCHED FOR: this monitor does not say whether it is synced (older than this dashboard)";
  const div = document.getElementById("divergence");
  div.hidden = !(s && s.divergence);
  div.textContent = s && s.divergence ? `MODEL DIVERGENCE at step ${s.seq}: ${s.divergence}` : "";
  // A missed outcome (LiveState.missed), in the monitor's words (skinet.wire.convert.missed_line).
  const missed = document.getElementById("missed"), ms = (s && s.missed) || [];
  missed.hidden = !ms.length;
  missed.textContent = ms.map((m) => `MISSED OUTCOME at step ${s.seq}: ${m.skillset}:${m.skill} ended without its `
    + `response (${m.gap}): ` + (m.outcome ? `${m.outcome} inferred from the resources`
      : m.candidates.length ? `outcome unknown, the model cannot tell ${m.candidates.join(" from ")}`
        : "outcome unknown, no mode of the model explains the status")).join("; ");
  const notice = document.getElementById("notice");
  const noMonitor = !monitors.length;
  notice.hidden = !(noMonitor || replay);
  notice.dataset.replay = replay;
  notice.textContent = noMonitor ? `No monitor of system '${view.system}' is alive on the network: waiting for one`
    + (view.state ? " (showing the last messages received)." : ".")
    : replay ? "Replay of a recorded run (skinet replay), not the live robot: times are the recording's." : "";
}

function renderSkillsets() {
  const s = view.state;
  if (!s) { fill("skillsets", el("p", { class: "muted" }, "waiting for the monitor\u2026")); return; }
  const cards = Object.entries(s.skillsets).map(([name, ss]) => {
    const rows = Object.entries(ss.resources).map(([r, v]) => el("tr", {}, el("td", {}, r), el("td", { class: "state" }, v)));
    const running = ss.running.length
      ? ss.running.map((k) => el("span", { class: "skill", "data-skill": k }, k))
      : [el("span", { class: "muted" }, "no skill running")];
    const sync = s.sync && s.sync[name];
    const state = sync ? sync.state : "unknown";
    return el("div", { class: "card", "data-skillset": name, "data-sync": state }, el("h3", {}, name,
      state === "live" ? "" : el("span", { class: "sync", title: sync ? sync.reason : "" },
        ` ${state.toUpperCase()}${sync ? " since " + clock(sync.since) : ""}`)),
      el("table", {}, el("tbody", {}, ...rows)), el("div", { class: "running" }, "running: ", ...running));
  });
  fill("skillsets", ...cards);
}

function renderProperties() {
  const v = view.verdicts, u = view.unsafe;
  const rows = (v ? v.properties : []).map((p) => {
    const rec = u ? u.recovery.filter((r) => r.property === p.name)
      .map((r) => `${r.skillset}:${r.transition}${r.controllable ? "" : " (event)"}`) : [];
    return el("tr", { "data-property": p.name, "data-holds": p.holds, class: p.holds ? "holds" : "violated" },
      el("td", {}, p.name), el("td", {}, p.holds ? "holds" : "VIOLATED"),
      el("td", {}, p.holds ? "" : (rec.join(", ") || "none")));
  });
  fill("properties", el("thead", {}, el("tr", {}, el("th", {}, "property"), el("th", {}, "status"), el("th", {}, "recovery"))),
    el("tbody", {}, ...rows));
}

function renderUnsafe() {
  const u = view.unsafe;
  document.getElementById("unsafe-count").textContent = u ? `(${u.unsafe.length}; literal algorithm ${u.literal_count})` : "";
  const p = document.getElementById("prediction");
  p.className = u && !u.prediction_stale ? "fresh" : "stale";
  p.textContent = !u ? "" : (u.prediction_stale
    ? "prediction STALE: explicit and forced constraints only (no predictor answer for this marking yet)"
    : `prediction fresh for step ${u.seq}`) + ` \u00b7 last state-space report ${ago(view.stateSpaceT)}`;
  if (!u) { fill("unsafe"); return; }
  if (!u.unsafe.length) { fill("unsafe", el("p", { class: "muted" }, "no unsafe transition at this marking")); return; }
  const groups = {};
  for (const e of u.unsafe) (groups[e.skillset] = groups[e.skillset] || []).push(e);
  const blocks = Object.entries(groups).map(([ss, entries]) => {
    const rows = entries.map((e) => el("tr", { "data-skillset": e.skillset, "data-transition": e.transition,
      "data-property": e.property, "data-constraint": e.constraint },
      el("td", { class: "mono" }, e.transition), el("td", {}, e.property),
      el("td", {}, el("span", { class: `kind kind-${e.constraint}` }, e.constraint)),
      el("td", {}, e.controllable ? "command" : "uncontrollable"),
      el("td", { class: "num" }, e.steps === null ? "-" : e.steps),
      el("td", { class: "mono witness" }, e.witness.length ? e.witness.join(" \u2192 ") : ""),
      el("td", { class: "reason" }, e.reason || "")));
    return el("div", { class: "group", "data-skillset": ss }, el("h3", {}, ss),
      el("table", {}, el("thead", {}, el("tr", {}, ...["transition", "property", "kind", "control", "steps", "witness", "why"]
        .map((h) => el("th", {}, h)))), el("tbody", {}, ...rows)));
  });
  fill("unsafe", ...blocks);
}

function renderSpace() {
  const r = view.stateSpace;
  const rows = r ? [["time", r.time < 1 ? `${(r.time * 1000).toFixed(2)} ms` : `${r.time.toFixed(2)} s`],
    ["complete", r.timeout_reached ? "no (budget reached)" : "yes"], ["depth", r.depth],
    ["markings", r.markings], ["edges", r.edges], ["received", ago(view.stateSpaceT)]] : [["report", "none yet"]];
  fill("state-space", el("tbody", {}, ...rows.map(([k, v]) => el("tr", { "data-field": k }, el("th", {}, k), el("td", {}, v)))));
}

function renderViolations() {
  const vs = view.violations.filter(Boolean);
  document.getElementById("violation-count").textContent = `(${vs.length})`;
  const items = vs.map((v) => el("li", { "data-property": v.property, "data-seq": v.seq, "data-event": v.event,
    "data-epoch": v.epoch, "data-joined": v.joined ? "1" : "0" }, el("strong", {}, v.property),
    v.joined ? ` already violated at monitor step ${v.seq}, when this view joined (its onset is not known here)`
      : ` violated at monitor step ${v.seq}`, v.event ? ` by ${v.event}` : "", ` (${clock(v.t)})`));
  fill("violations", ...(items.length ? items : [el("li", { class: "muted none" }, "none")]));
}

// -- divergences and manager restarts (issue 27 item 4): the monitor's list of the run, kept --

const KEPT_DIVERGENCES = 1024;  // as the server's board keeps

function addDivergences(added, older) {
  const have = new Set(view.divergences.map((d) => `${d.monitor}/${d.n}`));
  for (const d of added) if (!have.has(`${d.monitor}/${d.n}`)) view.divergences.push(d);
  if (view.divergences.length > KEPT_DIVERGENCES) view.divergences.splice(0, view.divergences.length - KEPT_DIVERGENCES);
  view.divergencesOlder = older;
}

// What a listed entry is, in the operator's words (kind violation: a property became violated at that step).
function divergenceKind(d) {
  return { restart: "manager restart", violation: "violation" }[d.kind] || "model divergence";
}

function divergenceText(d) {
  const words = d.kind === "restart" ? [d.info, d.reason && `model divergence: ${d.reason}`] : [d.reason, d.info];
  return words.filter(Boolean).join("; ");
}

function renderDivergences() {
  const ds = view.divergences, total = ds.length + view.divergencesOlder;
  document.getElementById("divergence-count").textContent = `(${total})`;
  const items = ds.map((d) => el("li", { "data-kind": d.kind, "data-seq": d.seq, "data-skillset": d.skillset,
    "data-event": d.event, "data-monitor": d.monitor, "data-n": d.n },
    el("strong", {}, divergenceKind(d)),
    ` at monitor step ${d.seq} (${clock(d.stamp)}): `, el("span", { class: "mono" }, d.event), ` \u2014 ${divergenceText(d)}`));
  if (view.divergencesOlder) items.unshift(el("li", { class: "muted older" }, `${view.divergencesOlder} earlier not listed`));
  fill("divergences", ...(items.length ? items : [el("li", { class: "muted none" }, "none")]));
}

// Markers on the timeline: a triangle on top and a dashed line across the lanes, the words in its tooltip.
function drawDivergences(plot, x, v0, v1, top, bottom) {
  for (const d of view.divergences) {
    if (d.stamp < v0 || d.stamp > v1) continue;
    const dx = x(d.stamp);
    const mark = svg("path", { d: `M${dx - 5},${top - 15}L${dx + 5},${top - 15}L${dx},${top - 8}Z`,
      class: `divergence-mark divergence-${d.kind}`, "data-n": d.n, "data-kind": d.kind, "data-seq": d.seq });
    mark.append(svg("title", {}, `${divergenceKind(d)} at step ${d.seq}: `
      + `${d.event} \u2014 ${divergenceText(d)}`));
    plot.append(svg("line", { x1: dx, x2: dx, y1: top - 8, y2: bottom, class: `divergence-line divergence-${d.kind}` }), mark);
  }
}

// -- timeline zoom and pan: the wheel zooms around the pointer, a drag pans, the buttons zoom or show the whole run --

const MIN_SPAN = 2;  // seconds: the narrowest window
const zoom = { span: null, end: null };  // span null: the whole run; end null: the window follows the live edge
let frame = null;  // the last drawing's geometry: {left, plotW, v0, v1, t0, tEnd}

function timelineWindow(t0, tEnd) {
  if (zoom.span === null || zoom.span >= tEnd - t0) return [t0, tEnd];
  const end = zoom.end === null ? tEnd : Math.min(tEnd, Math.max(t0 + zoom.span, zoom.end));
  return [end - zoom.span, end];
}

function setWindow(v0, v1) {
  const f = frame;
  if (!f) return;
  const span = Math.max(MIN_SPAN, v1 - v0);
  if (span >= f.tEnd - f.t0) { zoom.span = null; zoom.end = null; schedule(); return; }
  const end = Math.min(f.tEnd, Math.max(f.t0 + span, v0 + span));
  zoom.span = span;
  zoom.end = end >= f.tEnd ? null : end;  // at the live edge: follow it
  schedule();
}

function zoomBy(factor, at) {  // around time ``at``; else around the live edge while following it, or the middle
  const f = frame;
  if (!f) return;
  const centre = at !== undefined ? at : zoom.end === null ? f.v1 : (f.v0 + f.v1) / 2;
  const span = Math.max(MIN_SPAN, (f.v1 - f.v0) * factor);
  const v0 = centre - (centre - f.v0) * span / (f.v1 - f.v0);
  setWindow(v0, v0 + span);
}

function timeAt(event) {
  const f = frame, px = event.clientX - event.currentTarget.getBoundingClientRect().left;
  return f.v0 + (px - f.left) / f.plotW * (f.v1 - f.v0);
}

function initZoom() {
  const box = document.getElementById("timeline");
  box.addEventListener("wheel", (e) => {
    if (!frame) return;
    e.preventDefault();
    zoomBy(e.deltaY > 0 ? 1.25 : 0.8, timeAt(e));
  }, { passive: false });
  let drag = null;
  box.addEventListener("pointerdown", (e) => {
    if (!frame || e.button !== 0) return;
    drag = { x: e.clientX, v0: frame.v0, v1: frame.v1, plotW: frame.plotW };
    box.setPointerCapture(e.pointerId);
    box.classList.add("dragging");
  });
  box.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dt = -(e.clientX - drag.x) / drag.plotW * (drag.v1 - drag.v0);
    if (!dt) return;
    const f = frame, lo = f.t0 - drag.v0, hi = f.tEnd - drag.v1;  // stay within the run
    const shift = Math.min(hi, Math.max(lo, dt));
    setWindow(drag.v0 + shift, drag.v1 + shift);
  });
  const end = () => { drag = null; box.classList.remove("dragging"); };
  box.addEventListener("pointerup", end);
  box.addEventListener("pointercancel", end);
  document.getElementById("zoom-in").addEventListener("click", () => zoomBy(0.5));
  document.getElementById("zoom-out").addEventListener("click", () => zoomBy(2));
  document.getElementById("zoom-all").addEventListener("click", () => { zoom.span = null; zoom.end = null; schedule(); });
}

// -- label widths: lane names are never cut, state names only shown where they fit --

const measurer = document.createElement("canvas").getContext("2d");

function textWidth(text, px) {
  measurer.font = `${px}px system-ui, -apple-system, "Segoe UI", sans-serif`;
  return measurer.measureText(text).width;
}

function fitted(text, px, room) {  // text, or its start and an ellipsis, within room pixels; "" when not even that
  if (textWidth(text, px) <= room) return text;
  for (let n = text.length - 1; n >= 2; n--) {
    const cut = text.slice(0, n) + "\u2026";
    if (textWidth(cut, px) <= room) return cut;
  }
  return "";
}

// -- timeline (paper Fig. 3/4: lanes per resource, skill and property; unsafe count below) --

function lanesOf() {
  const lanes = view.model && view.model.lanes && Object.keys(view.model.lanes).length ? view.model.lanes : {};
  if (Object.keys(lanes).length) return lanes;
  const out = {};
  for (const p of view.points) {
    for (const [ss, s] of Object.entries(p.skillsets)) {
      const o = out[ss] = out[ss] || { resources: {}, skills: [] };
      for (const [r, v] of Object.entries(s.resources)) {
        const states = o.resources[r] = o.resources[r] || [];
        if (!states.includes(v)) states.push(v);
      }
      for (const k of s.running) if (!o.skills.includes(k)) o.skills.push(k);
    }
  }
  return out;
}

function renderTimeline() {
  const box = document.getElementById("timeline");
  const pts = view.points;
  const lanes = lanesOf();
  const props = view.verdicts ? view.verdicts.properties.map((p) => p.name)
    : [...new Set(pts.flatMap((p) => Object.keys(p.holds)))];
  const rows = [];
  Object.entries(lanes).forEach(([ss, l], n) => {
    for (const [r, states] of Object.entries(l.resources)) rows.push({ type: "resource", ss, name: r, states, n });
    for (const k of l.skills) rows.push({ type: "skill", ss, name: k, n });
  });
  for (const p of props) rows.push({ type: "property", name: p });
  for (const row of rows) row.label = row.type === "property" ? `property ${row.name}` : `${row.ss}.${row.name}`;
  const laneH = 20, right = 20, top = 60, chartH = 90;
  const width = Math.max(600, box.parentNode.clientWidth - 4);
  // The label column is as wide as the longest lane name (up to 40 % of the width): no name is cut.
  const longest = Math.max(textWidth("unsafe transitions", 11), ...rows.map((row) => textWidth(row.label, 11)));
  const left = Math.ceil(Math.min(width * 0.4, longest + 12));
  const height = top + rows.length * laneH + 20 + chartH + 30;
  box.setAttribute("width", width); box.setAttribute("height", height);
  box.replaceChildren();
  if (!pts.length) { frame = null; box.append(svg("text", { x: 10, y: 20, class: "muted" }, "no step yet")); return; }
  // The right edge is now, measured on the browser's clock from the last step's arrival (no clock skew).
  const t0 = pts[0].t, tEnd = pts[pts.length - 1].t + Math.max(0, Date.now() / 1000 - (view.lastPointAt || 0));
  const [v0, v1] = timelineWindow(t0, Math.max(tEnd, t0 + 1));
  const span = Math.max(1e-3, v1 - v0), plotW = width - left - right;
  frame = { left, plotW, v0, v1, t0, tEnd: Math.max(tEnd, t0 + 1) };
  Object.assign(box.dataset, { t0: v0.toFixed(3), t1: v1.toFixed(3), zoomed: zoom.span !== null });
  const x = (t) => left + plotW * (t - v0) / span;
  const y = (i) => top + i * laneH;
  const cTop = y(rows.length) + 20;
  // Everything drawn against time is clipped to the plot area, so a zoomed window never spills on the names.
  const clip = svg("clipPath", { id: "timeline-plot" });
  clip.append(svg("rect", { x: left, y: 0, width: plotW, height }));
  const defs = svg("defs");
  defs.append(clip);
  const plot = svg("g", { "clip-path": "url(#timeline-plot)" });
  box.append(defs);
  rows.forEach((row, i) => {
    const label = svg("text", { x: left - 6, y: y(i) + 14, class: "lane-label", "text-anchor": "end" }, row.label);
    box.append(label);
    box.append(svg("line", { x1: left, x2: width - right, y1: y(i) + laneH, y2: y(i) + laneH, class: "lane-line" }));
  });
  box.append(plot);
  // One shape per run of equal values (a long mission stays a few hundred shapes).
  const end = (k) => (k + 1 < pts.length ? x(pts[k + 1].t) : x(tEnd));
  rows.forEach((row, i) => {
    const value = (p) => {
      const ss = row.type === "property" ? null : p.skillsets[row.ss];
      if (row.type === "resource") return ss ? ss.resources[row.name] : undefined;
      if (row.type === "skill") return ss ? ss.running.includes(row.name) : undefined;
      return p.holds[row.name];
    };
    let k = 0;
    while (k < pts.length) {
      const v = value(pts[k]);
      let j = k;
      while (j + 1 < pts.length && value(pts[j + 1]) === v && pts[j + 1].epoch === pts[k].epoch) j++;
      const x0 = x(pts[k].t), x1 = end(j), w = Math.max(1, x1 - x0);
      if (x1 < left || x0 > left + plotW) { k = j + 1; continue; }  // outside the window
      if (row.type === "resource" && v !== undefined) {
        const idx = Math.max(0, row.states.indexOf(v));
        const rect = svg("rect", { x: x0, y: y(i) + 2, width: w, height: laneH - 4, fill: FILLS[idx % FILLS.length] });
        rect.append(svg("title", {}, `${row.ss}.${row.name} = ${v} (steps ${pts[k].seq}-${pts[j].seq})`));
        plot.append(rect);
        // The state's name where the shown part of its shape holds it, shortened with an ellipsis, else none.
        const from = Math.max(x0, left), room = Math.min(x1, left + plotW) - from - 4;
        const text = fitted(v, 10, room);
        if (text) {
          const label = svg("text", { x: from + 2, y: y(i) + 14, class: "state-label" }, text);
          label.append(svg("title", {}, v));
          plot.append(label);
        }
      } else if (row.type === "skill" && v === true) {
        plot.append(svg("rect", { x: x0, y: y(i) + 4, width: w, height: laneH - 8, fill: COLOURS[row.n % COLOURS.length],
          class: "skill-bar" }));
      } else if (row.type === "property" && v !== undefined) {
        plot.append(svg("rect", { x: x0, y: y(i) + 2, width: w, height: laneH - 4, class: v ? "holds-bar" : "violated-bar" }));
      }
      k = j + 1;
    }
  });
  // Unsafe transitions per step (operator view, literal algorithm dashed).
  const maxU = Math.max(1, ...pts.map((p) => Math.max(p.unsafe || 0, p.literal || 0)));
  const cy = (n) => cTop + chartH - chartH * n / maxU;
  box.append(svg("text", { x: left - 6, y: cTop + chartH / 2, class: "lane-label", "text-anchor": "end" }, "unsafe transitions"));
  box.append(svg("line", { x1: left, x2: width - right, y1: cTop + chartH, y2: cTop + chartH, class: "axis" }));
  box.append(svg("text", { x: left - 6, y: cTop + 8, class: "tick", "text-anchor": "end" }, String(maxU)));
  for (const [field, cls] of [["literal", "literal-line"], ["unsafe", "unsafe-line"]]) {
    let d = "";
    pts.forEach((p, k) => {
      if (p[field] === null || p[field] === undefined) return;
      const x1 = k + 1 < pts.length ? x(pts[k + 1].t) : x(tEnd);
      d += `${d ? "L" : "M"}${x(p.t).toFixed(1)},${cy(p[field]).toFixed(1)}L${x1.toFixed(1)},${cy(p[field]).toFixed(1)}`;
    });
    if (d) plot.append(svg("path", { d, class: cls }));
  }
  // Events along the top, violations and monitor restarts as vertical lines.
  for (const p of pts) {
    if (!p.event || p.t < v0 || p.t > v1) continue;
    const tick = svg("line", { x1: x(p.t), x2: x(p.t), y1: top - 6, y2: top - 1, class: "event-tick" });
    tick.append(svg("title", {}, `step ${p.seq}: ${p.event}`));
    plot.append(tick);
  }
  view.violations.filter(Boolean).forEach((v, n) => {  // labels on three staggered rows
    const vx = x(v.t), ly = 12 + (n % 3) * 11, text = `${v.property} (step ${v.seq})`;
    const before = vx + 3 + textWidth(text, 11) > left + plotW;  // left of its line at the right edge: never cut
    plot.append(svg("line", { x1: vx, x2: vx, y1: ly + 2, y2: cTop + chartH, class: "violation-line" }));
    plot.append(svg("text", { x: before ? vx - 3 : vx + 3, y: ly, class: "violation-label",
      "text-anchor": before ? "end" : "start" }, text));
  });
  drawDivergences(plot, x, v0, v1, top, cTop + chartH);
  for (let k = 1; k < pts.length; k++) {
    if (pts[k].epoch !== pts[k - 1].epoch) {
      const rx = x(pts[k].t);
      plot.append(svg("line", { x1: rx, x2: rx, y1: top, y2: cTop + chartH, class: "restart-line" }));
      plot.append(svg("text", { x: rx + 3, y: cTop + chartH + 14, class: "tick" }, "monitor restarted"));
    }
  }
  box.append(svg("text", { x: left, y: height - 6, class: "tick" }, clock(v0)));
  box.append(svg("text", { x: width - right, y: height - 6, class: "tick", "text-anchor": "end" },
    `${clock(v1)} (${span.toFixed(0)} s${zoom.span === null ? "" : ` of ${(tEnd - t0).toFixed(0)} s`})`));
}

// -- command check ------------------------------------------------------------------

async function check(event) {
  event.preventDefault();
  const command = document.getElementById("check-command").value.trim();
  const out = document.getElementById("check-result");
  out.textContent = "asking the monitor\u2026";
  try {
    const r = await (await fetch(`/api/check?command=${encodeURIComponent(command)}`)).json();
    if (!r.ok) {
      out.replaceChildren(el("p", { class: "error" }, r.error),
        r.candidates && r.candidates.length ? el("p", {}, "did you mean: " + r.candidates.join(", ")) : "");
      return;
    }
    const reasons = r.reasons.map((x) => el("li", {}, `${x.property ? x.property + ": " : ""}${x.constraint} (${x.action})`,
      x.steps ? `, within ${x.steps} steps` : "", x.witness.length ? ` via ${x.witness.join(" \u2192 ")}` : "",
      x.reason ? ` \u2014 ${x.reason}` : ""));
    // As skinet check answers: a command that cannot fire now is no allow, whatever its decision.
    out.replaceChildren(el("p", { class: `decision decision-${r.decision}`, "data-decision": r.decision,
      "data-enabled": r.enabled }, `${r.skillset}:${r.transition}: ` + (r.enabled ? r.decision.toUpperCase()
        : `NOT FIRABLE (not enabled at the live marking; if it were: ${r.decision.toUpperCase()})`)),
      el("ul", {}, ...reasons));
  } catch (e) {
    out.textContent = `check failed: ${e}`;
  }
}

function updateNames() {
  const lanes = lanesOf(), list = document.getElementById("check-names");
  const names = [];
  for (const e of (view.unsafe ? view.unsafe.unsafe : [])) names.push(`${e.skillset}:${e.transition}`);
  for (const [ss, l] of Object.entries(lanes)) for (const k of l.skills) names.push(`${ss}:${k}.start`);
  list.replaceChildren(...[...new Set(names)].map((n) => el("option", { value: n })));
  examples(lanes);
}

// The goal box's and the check's placeholders name the loaded system's skillsets, never another robot's.
function examples(lanes) {
  const [ss, l] = Object.entries(lanes).find(([, x]) => x.skills.length) || Object.entries(lanes)[0] || [];
  if (!ss) return;
  const skill = l.skills[0], [, states] = Object.entries(l.resources)[0] || [];
  const goals = [states && states.length ? `reach ${ss}:${states[states.length - 1]}` : null,
    skill ? `run ${ss}:${skill}` : null].filter(Boolean);
  document.getElementById("goal-text").placeholder = goals.join("\n");
  document.getElementById("check-command").placeholder =
    `skillset:transition${skill ? `, e.g. ${ss}:${skill}.start` : ""}`;
  const inputs = Object.values(lanes).flatMap((x) => Object.entries(x.inputs || {}))[0];
  document.getElementById("goal-inputs").placeholder =
    inputs ? `${inputs[0]}.${inputs[1][0]} = ...` : "no skill of this system takes inputs";
}

// -- the pilot: goal box, status, plan (docs/semantics.md §8) ---------------------------------------

const ACTIVE = ["planning", "guiding", "driving", "waiting for outcome", "paused", "waiting for monitor"];
const plan = { goal: 0, steps: [], answer: null, moves: null, at: -1 };  // the plan shown and its next step (flat index)

function tomlValue(v) {  // inputs as TOML writes them inline, as skinet plan and skinet goal print them
  if (Array.isArray(v)) return `[${v.map(tomlValue).join(", ")}]`;
  if (v && typeof v === "object") return `{${Object.entries(v).map(([k, x]) => `${k} = ${tomlValue(x)}`).join(", ")}}`;
  return typeof v === "string" ? JSON.stringify(v) : String(v);
}

function commandText(c) {
  const inputs = c.inputs && Object.keys(c.inputs).length ? ` with ${tomlValue(c.inputs)}` : "";
  return `${c.skillset}:${c.transition}${inputs}`;
}

function flatSteps(steps, out) {  // depth first, as the plan lists them: each step, then its branches' routes
  for (const s of steps) { out.push(s); for (const b of s.branches || []) flatSteps(b.steps || [], out); }
  return out;
}

// The step the pilot is at: the one whose command is `next` (or, waiting for an outcome, the wait for a skill the
// live state shows running, else the next wait), searched from the one highlighted before, so the highlight moves
// on along the plan (and back on a retry).  Statuses are rendered once per frame: the short one that names the
// command just sent may never be drawn, so a wait is found by its running skill, not by the step before it.
function nextStep(p, flat) {
  if (!ACTIVE.includes(p.state)) return -1;
  const waiting = !p.next && ["waiting for outcome", "guiding", "driving"].includes(p.state);
  if (!p.next && !waiting) return plan.at;  // planning, paused: where it was
  const from = Math.max(0, plan.at);
  const find = (same) => {
    for (let k = from; k < flat.length; k++) if (same(flat[k])) return k;
    for (let k = 0; k < from; k++) if (same(flat[k])) return k;
    return -1;
  };
  if (waiting) {
    const running = new Set(Object.entries((view.state && view.state.skillsets) || {})
      .flatMap(([ss, s]) => (s.running || []).map((k) => `${ss}:${k}`)));
    const k = find((s) => s.action === "wait" && running.has(`${s.skillset}:${(s.expect || "").split(".")[0]}`));
    if (k >= 0) return k;
  }
  return find((s) => (p.next ? s.skillset === p.next.skillset && s.action === p.next.transition : s.action === "wait"));
}

function stepNodes(steps, flat) {
  return steps.map((s) => {
    const k = flat.indexOf(s);
    const label = s.action === "wait" ? `${s.number}. wait for ${s.skillset}:${s.expect}`
      : `${s.number}. ${s.skillset}:${s.action}${s.inputs ? " with " + tomlValue(s.inputs) : ""}`;
    const branches = (s.branches || []).map((b) => {
      const head = `if ${b.skillset}:${b.transition}`;
      if (b.then === "retry") return el("li", { class: "branch", "data-then": b.then }, `${head}: retry from step ${b.step}`);
      if (b.then === "continue") return el("li", { class: "branch", "data-then": b.then }, `${head}: continue at step ${b.step}`);
      if (b.then === "reached") return el("li", { class: "branch", "data-then": b.then }, `${head}: the goal is reached`);
      return el("li", { class: "branch", "data-then": b.then }, `${head}:`, el("ol", {}, ...stepNodes(b.steps || [], flat)),
        b.step ? `then continue at step ${b.step}` : "");
    });
    return el("li", { class: "step" + (k === plan.at ? " next" : ""), "data-number": s.number, "data-action": s.action,
      "data-skillset": s.skillset, "data-next": k === plan.at }, el("span", { class: "label" }, label),
      branches.length ? el("ul", { class: "branches" }, ...branches) : "");
  });
}

function renderPilot() {
  const p = view.pilot, alive = (view.alive.pilot || []).length;
  // With no pilot at all (alive or heard of), the panel is one line: nothing to send goals to.
  document.getElementById("pilot-panel").dataset.pilot = alive ? "alive" : p ? "gone" : "none";
  document.getElementById("pilot-service").textContent = alive ? ""
    : "(no pilot alive: skinet run starts one, or python -m services.pilot)";
  const active = p && ACTIVE.includes(p.state);
  document.getElementById("goal-pause").disabled = !active || p.state === "paused";
  document.getElementById("goal-resume").disabled = !(p && p.state === "paused");
  document.getElementById("goal-cancel").disabled = !active;
  // A skill that ended unseen, its outcome unknown: the pilot waits for the operator's answer.
  const unknown = p && active ? p.unknown : null;
  document.getElementById("goal-unknown").hidden = !unknown;
  document.getElementById("goal-unknown-text").textContent = unknown
    ? `How did ${unknown.skillset}:${unknown.skill} end (${unknown.gap})?` : "";
  if (active && !modeClicked) for (const r of document.querySelectorAll("input[name=goal-mode]")) r.checked = r.value === p.mode;
  if (!p) { fill("pilot-status", el("span", { class: "muted" }, "no pilot status yet")); fill("plan"); return; }
  if (p.goal_id > plan.goal) Object.assign(plan, { goal: p.goal_id, steps: [], answer: null, moves: null, at: -1 });
  const mine = p.goal_id === plan.goal;  // else the status is of a goal older than the reply just shown
  if (mine && p.steps && p.steps.length) plan.steps = p.steps;
  if (mine && p.answer) { plan.answer = p.answer; plan.moves = p.moves_left; }
  const flat = flatSteps(plan.steps, []);
  if (mine) plan.at = nextStep(p, flat);
  const facts = [];
  const fact = (name, ...text) => facts.push(el("span", { "data-fact": name }, ...text));
  if (p.goal_id) fact("goal", `goal ${p.goal_id}` + (p.client ? ` of ${p.client}` : ""));
  if (p.goals.length) fact("goals", p.goals.length > 1 ? `${p.index + 1}/${p.goals.length}: ${p.goals[p.index] || ""}` : p.goals[0]);
  fact("mode", `${p.mode} mode`);
  if (p.next) fact("next", "next ", el("strong", { class: "mono" }, commandText(p.next)));
  if (p.moves_left !== null && active) fact("moves", `${p.moves_left} move${p.moves_left === 1 ? "" : "s"} left`);
  const retries = Object.entries(p.retries || {});
  if (retries.length) fact("retries", "retries " + retries.map(([k, n]) => `${k} ${n}`).join(", "));
  fact("commands", `${p.commands} command${p.commands === 1 ? "" : "s"} sent`);
  if ((p.notes || []).length) fact("note", p.notes[p.notes.length - 1]);
  if (p.denied) facts.push(el("span", { "data-fact": "denied", class: "denied" }, `${p.denied} denied by the check`));
  fill("pilot-status", el("span", { class: "pilot-state", "data-state": p.state, "data-goal": p.goal_id },
    p.state + (p.reason ? `: ${p.reason}` : "")), el("span", { class: "facts" }, ...facts));
  document.getElementById("plan-answer").textContent = plan.answer
    ? `(${plan.answer}${plan.moves !== null && active ? `, ${plan.moves} move${plan.moves === 1 ? "" : "s"} from here` : ""})`
    : "";
  fill("plan", ...stepNodes(plan.steps, flat));
}

// Errors point into the box: the message, the line with a caret under the column, and the cursor put there.
function showGoalError(body) {
  const box = document.getElementById("goal-error");
  for (const id of ["goal-text", "goal-inputs"]) document.getElementById(id).classList.remove("invalid");
  if (!body) { box.hidden = true; box.replaceChildren(); return; }
  box.hidden = false;
  Object.assign(box.dataset, { field: body.field || "", line: body.line || "", column: body.column || "",
    rejected: !!body.rejected });
  const where = body.field && body.line
    ? `${body.field === "inputs" ? "skill inputs" : "goal"} line ${body.line}, column ${body.column}: ` : "";
  const parts = [el("div", { class: "message", title: body.error }, where + (body.detail || body.error))];
  if (body.field && body.line) {
    const input = document.getElementById(body.field === "inputs" ? "goal-inputs" : "goal-text");
    const lines = input.value.split("\n"), text = lines[body.line - 1] || "";
    parts.push(el("pre", { class: "excerpt" }, `${text}\n${" ".repeat(Math.max(0, body.column - 1))}^`));
    input.classList.add("invalid");
    const offset = lines.slice(0, body.line - 1).reduce((n, l) => n + l.length + 1, 0) + body.column - 1;
    input.focus();
    input.setSelectionRange(offset, offset + 1);
  }
  box.replaceChildren(...parts);
}

async function askPilot(form) {
  try {
    const r = await fetch("/api/goal", { method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify(form) });
    const body = await r.json();
    showGoalError(body.ok ? null : body);
    if (body.ok && form.op === "goal") {
      const reply = body.reply;
      Object.assign(plan, { goal: reply.goal_id, steps: reply.steps, answer: reply.answer, moves: reply.moves, at: -1 });
      schedule();
    }
    return body.ok;
  } catch (e) {
    showGoalError({ error: `the dashboard did not answer: ${e}` });
    return false;
  }
}

let modeClicked = false;  // a mode change on its way to the pilot: the radios keep the operator's choice meanwhile

function chosenMode() {
  return document.querySelector("input[name=goal-mode]:checked").value;
}

function initGoalBox() {
  document.getElementById("goal-form").addEventListener("submit", (e) => {
    e.preventDefault();
    askPilot({ op: "goal", goals: document.getElementById("goal-text").value,
      inputs: document.getElementById("goal-inputs").value, mode: chosenMode(),
      replace: document.getElementById("goal-replace").checked });
  });
  for (const id of ["goal-pause", "goal-resume", "goal-cancel"]) {
    const button = document.getElementById(id);
    button.addEventListener("click", () => askPilot({ op: button.dataset.op, mode: chosenMode() }));
  }
  for (const button of document.querySelectorAll(".goal-answer")) {
    button.addEventListener("click", () => askPilot({ op: "confirm", answer: button.dataset.answer, mode: chosenMode() }));
  }
  for (const radio of document.querySelectorAll("input[name=goal-mode]")) {
    radio.addEventListener("change", async () => {  // a goal that runs switches at once; else the next goal's mode
      if (!(view.pilot && ACTIVE.includes(view.pilot.state))) return;
      modeClicked = true;
      await askPilot({ op: "mode", mode: chosenMode() });
      modeClicked = false;
      schedule();
    });
  }
  for (const id of ["goal-text", "goal-inputs"]) {
    document.getElementById(id).addEventListener("input", () => showGoalError(null));
  }
}

// -- connection ---------------------------------------------------------------------

function connect() {
  const source = new EventSource("/events");
  source.onopen = () => { view.connected = true; schedule(); };
  source.onerror = () => { view.connected = false; schedule(); };  // EventSource retries by itself
  source.onmessage = (m) => {
    const u = JSON.parse(m.data);
    apply(u);
    if (u.kind === "snapshot" || u.kind === "model") updateNames();
    schedule();
  };
}

document.getElementById("check-form").addEventListener("submit", check);
initGoalBox();
initZoom();
window.addEventListener("resize", schedule);
setInterval(schedule, 1000);  // ages and the timeline's right edge move on
connect();
