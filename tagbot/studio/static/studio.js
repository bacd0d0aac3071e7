// tagbot studio: the page. It draws what the server computes (trajectories, speeds, lognormals,
// fits, variations, brush pictures) and turns pointer input into the JSON API's edit operations;
// no model maths here, only the view's mapping between tag units and screen pixels.

const token = new URLSearchParams(location.search).get("token") || "";
const $ = (id) => document.getElementById(id);
const svg = $("editor");
const NS = "http://www.w3.org/2000/svg";
const PHI_RADIUS = 34; // px from the target to a φ handle
const DT_MIN_LEN = 14; // px: a Δt handle at Δt_min
const DT_MAX_LEN = 74; // px: a Δt handle at Δt_max

const studio = {
  state: null,
  view: { s: 3, ox: 40, oy: 560 }, // screen = (ox + s·x, oy − s·y)
  selected: null, // {kind: "target"|"plan", plan, index}
  activePlan: null, // the plan the Targets tool appends to
  executed: [], // executed trace of the current/last draw, tag units
  live: [],
  stats: { drag: [], dragFrame: [], dragServer: [], dragRender: [], gesture: [], frames: [] },
  busy: false,
  pending: null,
  inflight: new Map(),
  editId: 0,
  ws: null,
  wsReady: false,
  dragCount: 0,
};
window.studio = studio;

// ------------------------------------------------------------------------------------- API

async function api(method, path, body, raw = false) {
  const headers = { "X-Tagbot-Token": token };
  let data = body;
  if (body !== undefined && !raw) {
    headers["Content-Type"] = "application/json";
    data = JSON.stringify(body);
  }
  const response = await fetch(path, { method, headers, body: data });
  const timing = /dur=([0-9.]+)/.exec(response.headers.get("Server-Timing") || "");
  if (timing) studio.stats.serverMs = +timing[1];
  const type = response.headers.get("Content-Type") || "";
  const result = type.includes("json") ? await response.json() : await response.blob();
  if (!response.ok) {
    const message = (result && result.error) || `${response.status} ${response.statusText}`;
    throw new Error(message);
  }
  return result;
}

function say(text, error = false) {
  const status = $("status");
  status.textContent = text;
  status.classList.toggle("error", error);
}

async function call(method, path, body, raw = false) {
  let result;
  try {
    result = await api(method, path, body, raw);
  } catch (e) {
    say(e.message, true);
    return null;
  }
  if (result && result.design) show(result); // a bug here is the page's: let it surface
  return result;
}

// Edits: one request in flight; while it runs only the latest edit waits (a drag sends the
// newest position, never a backlog).
function edit(ops, group = null, started = performance.now()) {
  studio.pending = { ops, group, started };
  pump();
}

// On the WebSocket (when open) up to two edits are in flight, answered in order: a drag's moves
// pipeline instead of waiting a whole round trip each. Otherwise PATCH /api/plan, one at a time.
const MAX_IN_FLIGHT = 2;
function pump() {
  if (!studio.pending) return;
  if (studio.ws && studio.wsReady && !studio.useHttp) { // useHttp, maxInFlight: for comparisons
    if (studio.inflight.size >= (studio.maxInFlight || MAX_IN_FLIGHT)) return;
    const next = studio.pending;
    studio.pending = null;
    const id = ++studio.editId;
    studio.inflight.set(id, next);
    studio.busy = true;
    studio.ws.send(JSON.stringify({ id, ops: opsOf(next), group: next.group }));
  } else if (!studio.busy) flush();
}

// An edit's operations, or the function that makes them when the edit is sent.
function opsOf(next) {
  return typeof next.ops === "function" ? next.ops() : next.ops;
}

function onEditAnswer(msg) {
  const next = studio.inflight.get(msg.id);
  studio.inflight.delete(msg.id);
  studio.busy = studio.inflight.size > 0;
  pump();
  if (msg.type === "error") { say(msg.error, true); return; }
  studio.stats.serverMs = msg.state.server_ms;
  show(msg.state);
  if (next && next.group) recordDrag(next);
}

function recordDrag(next) {
  studio.stats.dragServer.push(studio.stats.serverMs);
  studio.stats.dragRender.push(studio.stats.lastRender);
  studio.stats.drag.push(performance.now() - next.started);
  requestAnimationFrame(() => studio.stats.dragFrame.push(performance.now() - next.started));
}

async function flush() {
  const next = studio.pending;
  if (!next) return;
  studio.pending = null;
  studio.busy = true;
  let result = null;
  try {
    result = await api("PATCH", "/api/plan", { ops: opsOf(next), group: next.group });
  } catch (e) {
    say(e.message, true);
  }
  studio.busy = false;
  pump();
  if (!result) return;
  show(result);
  if (next.group) recordDrag(next);
}

// ------------------------------------------------------------------------------------- view

const sx = (x) => studio.view.ox + studio.view.s * x;
const sy = (y) => studio.view.oy - studio.view.s * y;
function toTag(event) {
  const box = svg.getBoundingClientRect();
  const X = event.clientX - box.left, Y = event.clientY - box.top;
  return [(X - studio.view.ox) / studio.view.s, (studio.view.oy - Y) / studio.view.s];
}

function fitView() {
  const st = studio.state;
  const pts = [];
  if (st) {
    for (const p of st.design.plans) pts.push(...p.targets);
    for (const g of st.design.gestures) pts.push(...g);
    if (st.motion) for (let i = 0; i < st.motion.x.length; i += 7) pts.push([st.motion.x[i], st.motion.y[i]]);
  }
  const box = svg.getBoundingClientRect();
  const W = box.width || 800, H = box.height || 600;
  if (pts.length < 2) {
    studio.view = { s: 3, ox: 40, oy: H - 40 };
    return;
  }
  let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
  for (const [x, y] of pts) {
    x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y);
  }
  const margin = 70;
  const s = Math.min((W - 2 * margin) / Math.max(x1 - x0, 1e-9), (H - 2 * margin) / Math.max(y1 - y0, 1e-9));
  studio.view = { s, ox: W / 2 - s * (x0 + x1) / 2, oy: H / 2 + s * (y0 + y1) / 2 };
}

// Arrays come packed ({dtype, b64}: little-endian bytes): decoding them is much cheaper than
// parsing thousands of JSON numbers on every frame of a drag.
function unpack(p) {
  const bin = atob(p.b64), bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return p.dtype === "|u1" ? bytes : new Float32Array(bytes.buffer);
}

function decodeMotion(m) {
  if (!m || m.x instanceof Float32Array) return m;
  for (const k of ["x", "y", "speed", "pen"]) m[k] = unpack(m[k]);
  m.t = new Float64Array(m.n);
  for (let i = 0; i < m.n; i++) m.t[i] = m.t0 + i * m.dt; // the samples' fixed step
  return m;
}

function decode(state) {
  decodeMotion(state.motion);
  const c = state.strokes;
  if (!c) { state.strokes = []; return; }
  const t = unpack(c.t), v = unpack(c.v), n = c.points;
  state.strokes = c.items.map((s, i) => ({ ...s, t: t.subarray(i * n, (i + 1) * n), v: v.subarray(i * n, (i + 1) * n) }));
}

function show(state) {
  decode(state);
  const first = !studio.state || (!studio.state.tag && state.tag);
  studio.state = state;
  if (first) fitView();
  render();
  syncControls();
  scheduleBrush();
}

// The heavy layers (faded gestures, action plan, trajectory, executed trace) are drawn on a canvas
// under the SVG; the SVG holds only what is picked and dragged (targets and handles).
const layer = $("layer");
const COLORS = { gesture: "rgba(0,0,0,0.14)", chord: "#f28e2b", path: "#1f4e99", selected: "#c2185b", executed: "rgba(214,39,40,0.9)", live: "#d62728" };

function prepareLayer() {
  const box = svg.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
  const W = Math.round(box.width * dpr), H = Math.round(box.height * dpr);
  if (layer.width !== W || layer.height !== H) { layer.width = W; layer.height = H; }
  const g = layer.getContext("2d");
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, box.width, box.height);
  g.lineJoin = "round"; g.lineCap = "round";
  return g;
}

function strokeRuns(g, xs, ys, pens, colour, width, dash = null) {
  g.strokeStyle = colour; g.lineWidth = width; g.setLineDash(dash || []);
  g.beginPath();
  let down = false, runs = 0;
  for (let i = 0; i < xs.length; i++) {
    if (pens && !pens[i]) { down = false; continue; }
    const X = sx(xs[i]), Y = sy(ys[i]);
    if (down) g.lineTo(X, Y); else { g.moveTo(X, Y); runs++; }
    down = true;
  }
  g.stroke();
  g.setLineDash([]);
  return runs;
}

function traceRuns(g, points, colour, width) {
  const xs = points.map((p) => p[0]), ys = points.map((p) => p[1]), pens = points.map((p) => p[2]);
  return strokeRuns(g, xs, ys, pens, colour, width);
}

function render() {
  const t0 = performance.now();
  const st = studio.state;
  if (!st) return;
  const g = prepareLayer();
  const drawn = { gestures: 0, chords: 0, paths: 0, executed: 0, live: 0 };
  for (const gesture of st.design.gestures) {
    drawn.gestures += strokeRuns(g, gesture.map((p) => p[0]), gesture.map((p) => p[1]), null, COLORS.gesture, 6);
  }
  const plans = st.design.plans;
  plans.forEach((p) => {
    drawn.chords += strokeRuns(g, p.targets.map((t) => t[0]), p.targets.map((t) => t[1]), null, COLORS.chord, 1, [4, 3]);
  });
  // Trajectory: the pen-down runs, one per complete plan (the selected one highlighted).
  const m = st.motion;
  studio.runs = [];
  if (m) {
    const complete = plans.map((p, k) => [k, p.targets.length]).filter(([, n]) => n >= 2).map(([k]) => k);
    let begin = -1;
    for (let i = 0; i <= m.n; i++) {
      const down = i < m.n && m.pen[i];
      if (down && begin < 0) begin = i;
      if (!down && begin >= 0) { studio.runs.push({ plan: complete[studio.runs.length], begin, end: i }); begin = -1; }
    }
    for (const run of studio.runs) {
      const sel = studio.selected && studio.selected.kind === "plan" && studio.selected.plan === run.plan;
      drawn.paths += strokeRuns(g, m.x.subarray(run.begin, run.end), m.y.subarray(run.begin, run.end), null, sel ? COLORS.selected : COLORS.path, 2.2);
    }
  }
  if (studio.executed.length) drawn.executed = traceRuns(g, studio.executed, COLORS.executed, 1.6);
  if (studio.live.length) drawn.live = traceRuns(g, studio.live, COLORS.live, 2.5);
  studio.stats.drawn = drawn;

  // Handles: φ (ΓΛ*: at both ends; ΣΛ*: one per stroke), Δt (strokes after the first).
  const parts = [];
  const sigma = st.design.model === "sigma";
  for (const s of st.strokes) {
    const p = plans[s.plan];
    const [ax, ay] = p.targets[s.stroke], [bx, by] = p.targets[s.stroke + 1];
    const A = [sx(ax), sy(ay)], B = [sx(bx), sy(by)];
    const h1 = [A[0] + PHI_RADIUS * Math.cos(s.theta1), A[1] - PHI_RADIUS * Math.sin(s.theta1)];
    parts.push(`<line class="phi-line" x1="${A[0]}" y1="${A[1]}" x2="${h1[0]}" y2="${h1[1]}"/>`);
    parts.push(`<circle class="phi" r="5.5" cx="${h1[0]}" cy="${h1[1]}" data-kind="phi" data-end="1" data-plan="${s.plan}" data-stroke="${s.stroke}"/>`);
    if (!sigma) {
      const h2 = [B[0] - PHI_RADIUS * Math.cos(s.theta2), B[1] + PHI_RADIUS * Math.sin(s.theta2)];
      parts.push(`<line class="phi-line" x1="${B[0]}" y1="${B[1]}" x2="${h2[0]}" y2="${h2[1]}"/>`);
      parts.push(`<circle class="phi" r="5.5" cx="${h2[0]}" cy="${h2[1]}" data-kind="phi" data-end="2" data-plan="${s.plan}" data-stroke="${s.stroke}"/>`);
    }
    if (s.stroke > 0) {
      const n = dtDirection(s), len = DT_MIN_LEN + s.dt_fraction * (DT_MAX_LEN - DT_MIN_LEN);
      const d = [A[0] + len * n[0], A[1] + len * n[1]];
      parts.push(`<line class="dt-line" x1="${A[0]}" y1="${A[1]}" x2="${d[0]}" y2="${d[1]}"/>`);
      parts.push(`<rect class="dt" x="${d[0] - 5}" y="${d[1] - 5}" width="10" height="10" data-kind="dt" data-plan="${s.plan}" data-stroke="${s.stroke}"/>`);
    }
  }
  plans.forEach((p, k) => {
    p.targets.forEach(([x, y], i) => {
      const sel = studio.selected && studio.selected.kind === "target" && studio.selected.plan === k && studio.selected.index === i;
      parts.push(`<circle class="target${sel ? " selected" : ""}" r="6.5" cx="${sx(x)}" cy="${sy(y)}" data-kind="target" data-plan="${k}" data-index="${i}"/>`);
    });
  });
  parts.push(`<polyline id="live-gesture" class="gesture live-gesture" points=""/>`);
  parts.push(`<circle id="pen" class="pen" r="6" cx="-100" cy="-100"/>`);
  svg.innerHTML = parts.join("");
  drawSpeed();
  studio.stats.lastRender = performance.now() - t0;
}

// The Δt handle points across the stroke's departure (a screen direction: y down).
function dtDirection(s) {
  return [-Math.sin(s.theta1), -Math.cos(s.theta1)];
}

// Which plan's trajectory passes within a few pixels of the pointer (to select or move it).
function pathAt(event) {
  const m = studio.state && studio.state.motion;
  if (!m) return null;
  const box = svg.getBoundingClientRect(), X = event.clientX - box.left, Y = event.clientY - box.top;
  let best = null, bestD = 7;
  for (const run of studio.runs || []) {
    for (let i = run.begin; i < run.end; i++) {
      const d = Math.hypot(sx(m.x[i]) - X, sy(m.y[i]) - Y);
      if (d < bestD) { bestD = d; best = run.plan; }
    }
  }
  return best;
}

// Which plan's action plan (chord polyline) passes near the pointer, and the stroke there.
function chordAt(event) {
  const box = svg.getBoundingClientRect(), P = [event.clientX - box.left, event.clientY - box.top];
  let best = null, bestD = 7;
  studio.state.design.plans.forEach((p, k) => {
    for (let j = 0; j + 1 < p.targets.length; j++) {
      const a = [sx(p.targets[j][0]), sy(p.targets[j][1])], b = [sx(p.targets[j + 1][0]), sy(p.targets[j + 1][1])];
      const d = segmentDistance(P, a, b);
      if (d < bestD) { bestD = d; best = { plan: k, stroke: j }; }
    }
  });
  return best;
}

// ------------------------------------------------------------------------------------- speed plot

function drawSpeed(cursor = null) {
  const canvas = $("speed"), g = canvas.getContext("2d");
  const W = canvas.width, H = canvas.height, L = 36, B = 22;
  g.clearRect(0, 0, W, H);
  const st = studio.state;
  if (!st || !st.motion) {
    g.fillStyle = "#888"; g.fillText("no plan yet", L + 10, H / 2); return;
  }
  const m = st.motion;
  const t0 = m.t[0], t1 = m.t[m.t.length - 1] || t0 + 1;
  let vmax = 1e-9;
  for (const v of m.speed) vmax = Math.max(vmax, v);
  for (const s of st.strokes) for (const v of s.v) vmax = Math.max(vmax, v);
  vmax *= 1.08;
  const X = (t) => L + (W - L - 6) * (t - t0) / Math.max(t1 - t0, 1e-9);
  const Y = (v) => H - B - (H - B - 6) * v / vmax;
  g.fillStyle = "#eee";
  for (let i = 0; i < m.t.length;) {
    if (m.pen[i]) { i++; continue; }
    let j = i; while (j < m.t.length && !m.pen[j]) j++;
    g.fillRect(X(m.t[i]), 6, X(m.t[Math.min(j, m.t.length - 1)]) - X(m.t[i]), H - B - 6);
    i = j;
  }
  g.strokeStyle = "#999"; g.lineWidth = 1;
  g.beginPath(); g.moveTo(L, 6); g.lineTo(L, H - B); g.lineTo(W - 6, H - B); g.stroke();
  g.fillStyle = "#555"; g.font = "11px system-ui";
  g.fillText(`${(t1 - t0).toFixed(2)} s`, W - 46, H - 6);
  g.fillText(`${Math.round(vmax)} ${st.design.units}/s`, 2, 14);
  const colours = ["#4e79a7", "#f28e2b", "#59a14f", "#e15759", "#b07aa1", "#76b7b2", "#edc948"];
  st.strokes.forEach((s, i) => {
    g.strokeStyle = colours[i % colours.length]; g.lineWidth = 1;
    g.beginPath();
    s.t.forEach((t, k) => (k ? g.lineTo(X(t), Y(s.v[k])) : g.moveTo(X(t), Y(s.v[k]))));
    g.stroke();
  });
  g.strokeStyle = "#111"; g.lineWidth = 1.8;
  g.beginPath();
  let down = false;
  for (let i = 0; i < m.t.length; i++) {
    if (!m.pen[i]) { down = false; continue; }
    if (down) g.lineTo(X(m.t[i]), Y(m.speed[i])); else g.moveTo(X(m.t[i]), Y(m.speed[i]));
    down = true;
  }
  g.stroke();
  if (cursor !== null) {
    g.strokeStyle = "#d62728"; g.beginPath(); g.moveTo(X(cursor), 6); g.lineTo(X(cursor), H - B); g.stroke();
  }
}

// ------------------------------------------------------------------------------------- controls

function syncControls() {
  const st = studio.state, d = st.design;
  for (const name of ["dt_min", "dt_max", "mu", "sigma"]) {
    const input = $(name);
    if (document.activeElement !== input) input.value = +d[name].toFixed(4);
  }
  $("model").value = d.model;
  $("undo").disabled = !st.can_undo;
  $("redo").disabled = !st.can_redo;
  $("save").disabled = !st.save_path;
  $("save").title = st.save_path ? `Write ${st.save_path}` : "Started without a plan file: use Download plan";
  $("download").href = `/api/plan?download=1&token=${encodeURIComponent(token)}`;
  $("machine-port").textContent = st.machine_port ? `port ${st.machine_port}` : "simulated";
  updateExport();
  if (!studio.drawing) drawButtons(st.draw.state);
  if (!st.ready) say("warming up (compiling the kernels)…");
}

function updateExport() {
  const fmt = $("export-format").value, drips = $("drips").checked ? "&drips=1&seed=1" : "";
  $("export").href = `/api/export?format=${fmt}${drips}&token=${encodeURIComponent(token)}`;
}

let brushTimer = null;
function scheduleBrush() {
  clearTimeout(brushTimer);
  brushTimer = setTimeout(refreshBrush, 250);
}

async function refreshBrush() {
  const img = $("brush");
  if (!$("brush-on").checked || !studio.state || !studio.state.tag) { img.removeAttribute("src"); return; }
  if (studio.busy || studio.pending || studio.dragging) { scheduleBrush(); return; }
  studio.brushBusy = true;
  try {
    const dpr = Math.min(window.devicePixelRatio || 1, 2);
    const size = `width=${Math.round(460 * dpr)}&height=${Math.round(300 * dpr)}`;
    const blob = await api("GET", `/api/brush.png?${size}&drips=${$("drips").checked ? 1 : 0}&seed=1&v=${studio.state.version}`);
    const old = img.src;
    img.src = URL.createObjectURL(blob);
    if (old.startsWith("blob:")) URL.revokeObjectURL(old);
  } catch (e) { say(e.message, true); }
  finally { studio.brushBusy = false; }
}

// ------------------------------------------------------------------------------------- pointer

let drag = null;

svg.addEventListener("pointerdown", (event) => {
  if (event.button !== 0) return;
  const el = event.target, kind = el.dataset ? el.dataset.kind : undefined;
  const at = toTag(event);
  svg.setPointerCapture(event.pointerId);
  svg.focus();
  const group = `drag-${++studio.dragCount}`;
  if (kind === "target") {
    const k = +el.dataset.plan, i = +el.dataset.index, [x, y] = studio.state.design.plans[k].targets[i];
    studio.selected = { kind: "target", plan: k, index: i };
    drag = { kind, k, i, group, offset: [x - at[0], y - at[1]], moved: false };
    if (event.altKey) { edit([{ op: "delete", plan: k, index: i }]); drag = null; }
    render();
    return;
  }
  if (kind === "phi") {
    drag = { kind, k: +el.dataset.plan, j: +el.dataset.stroke, end: +el.dataset.end, group };
    return;
  }
  if (kind === "dt") {
    const k = +el.dataset.plan, j = +el.dataset.stroke;
    const s = studio.state.strokes.find((x) => x.plan === k && x.stroke === j);
    drag = { kind, k, j, group, n: dtDirection(s), origin: studio.state.design.plans[k].targets[j] };
    return;
  }
  // On a trajectory: select its plan and move it (with the Gesture tool, hold Shift).
  const onPath = !kind && (tool() === "targets" || event.shiftKey) ? pathAt(event) : null;
  if (onPath !== null) {
    studio.selected = { kind: "plan", plan: onPath };
    drag = { kind: "path", k: onPath, group, start: at, applied: [0, 0] };
    render();
    return;
  }
  if (event.detail === 2 && chordAt(event)) return; // a double click inserts a target
  studio.selected = null;
  if (tool() === "targets") {
    const plans = studio.state.design.plans;
    if (studio.activePlan !== null && studio.activePlan < plans.length) {
      edit([{ op: "append", plan: studio.activePlan, at }]);
    } else {
      studio.activePlan = plans.length;
      edit([{ op: "new_plan", at }]);
    }
    drag = null;
    return;
  }
  const box = svg.getBoundingClientRect();
  drag = { kind: "gesture", points: [], box };
  studio.gesture = [];
  addGesturePoints(event);
});

// A double click on the action plan (the dashed chords) inserts a target into that stroke.
svg.addEventListener("dblclick", (event) => {
  const hit = chordAt(event);
  if (hit) edit([{ op: "insert", plan: hit.plan, index: hit.stroke + 1, at: toTag(event) }]);
});

function segmentDistance(p, a, b) { // screen-free nearest-stroke pick for insertion
  const dx = b[0] - a[0], dy = b[1] - a[1], L = dx * dx + dy * dy || 1;
  const u = Math.max(0, Math.min(1, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / L));
  return Math.hypot(p[0] - a[0] - u * dx, p[1] - a[1] - u * dy);
}

function addGesturePoints(event, d = drag) {
  const events = event.getCoalescedEvents ? event.getCoalescedEvents() : [];
  for (const e of events.length ? events : [event]) {
    const X = e.clientX - d.box.left, Y = e.clientY - d.box.top;
    const [x, y] = [(X - studio.view.ox) / studio.view.s, (studio.view.oy - Y) / studio.view.s];
    const prev = d.points[d.points.length - 1];
    const t = e.timeStamp / 1000;
    if (prev && prev[0] === x && prev[1] === y) continue;
    d.points.push([x, y, prev ? Math.max(t, prev[2]) : t]);
    studio.gesture.push([X.toFixed(1), Y.toFixed(1)]);
  }
}

svg.addEventListener("pointermove", (event) => {
  if (!drag) return;
  const started = performance.now();
  const at = toTag(event);
  if (drag.kind === "gesture") {
    addGesturePoints(event);
    const live = document.getElementById("live-gesture");
    if (live) live.setAttribute("points", studio.gesture.map(([X, Y]) => `${X},${Y}`).join(" "));
    return;
  }
  studio.dragging = true;
  if (drag.kind === "target") {
    drag.moved = true;
    edit([{ op: "move_target", plan: drag.k, index: drag.i, to: [at[0] + drag.offset[0], at[1] + drag.offset[1]] }], drag.group, started);
  } else if (drag.kind === "phi") {
    edit([{ op: "aim", plan: drag.k, stroke: drag.j, end: drag.end, toward: at }], drag.group, started);
  } else if (drag.kind === "dt") {
    const box = svg.getBoundingClientRect();
    const X = event.clientX - box.left - sx(drag.origin[0]), Y = event.clientY - box.top - sy(drag.origin[1]);
    const len = X * drag.n[0] + Y * drag.n[1];
    const fraction = Math.max(0, Math.min(1, (len - DT_MIN_LEN) / (DT_MAX_LEN - DT_MIN_LEN)));
    edit([{ op: "dt_fraction", plan: drag.k, stroke: drag.j, fraction }], drag.group, started);
  } else if (drag.kind === "path") {
    // Moves are relative and only the latest waiting edit is sent: the step is worked out when
    // it is sent, from how far the plan should have moved and how far it was moved already.
    const d = drag;
    d.total = [at[0] - d.start[0], at[1] - d.start[1]];
    edit(() => {
      const by = [d.total[0] - d.applied[0], d.total[1] - d.applied[1]];
      d.applied = [...d.total];
      return [{ op: "move_plan", plan: d.k, by }];
    }, d.group, started);
  }
});

async function endPointer(event) {
  const done = drag;
  drag = null;
  studio.dragging = false;
  if (!done || done.kind !== "gesture") return;
  if (event.type === "pointerup") addGesturePoints(event, done);
  studio.gesture = null;
  if (done.points.length < 2) { render(); return; }
  const t0 = done.points[0][2];
  const points = done.points.map(([x, y, t]) => [x, y, t - t0]);
  studio.stats.lastGesture = points;
  const started = performance.now();
  const result = await call("POST", "/api/gesture", { points });
  if (result) {
    const ms = performance.now() - started;
    requestAnimationFrame(() => studio.stats.gesture.push({ ms, frame: performance.now() - started, fit_ms: result.fit_ms, points: points.length }));
    say(`gesture: ${points.length} points fitted in ${result.fit_ms.toFixed(0)} ms`);
  } else render();
}
svg.addEventListener("pointerup", endPointer);
svg.addEventListener("pointercancel", endPointer);

function tool() { return document.querySelector("input[name=tool]:checked").value; }

// ------------------------------------------------------------------------------------- buttons

function undo() { return call("POST", "/api/undo"); }
function redo() { return call("POST", "/api/redo"); }
function deleteSelected() {
  const sel = studio.selected;
  if (!sel) return;
  studio.selected = null;
  if (sel.kind === "target") edit([{ op: "delete", plan: sel.plan, index: sel.index }]);
  else edit([{ op: "delete_plan", plan: sel.plan }]);
}

$("undo").onclick = undo;
$("redo").onclick = redo;
$("delete").onclick = deleteSelected;
$("clear").onclick = () => {
  studio.executed = []; studio.live = []; $("variants").innerHTML = "";
  edit([{ op: "clear" }]);
};
$("fit-view").onclick = () => { fitView(); render(); };
$("new-plan").onclick = () => { studio.activePlan = null; say("next click starts a new plan"); };
$("model").onchange = (e) => edit([{ op: "model", model: e.target.value }]);
for (const name of ["dt_min", "dt_max", "mu", "sigma"]) {
  $(name).onchange = (e) => {
    const value = Number(e.target.value);
    if (e.target.value === "" || !Number.isFinite(value)) { say(`${name}: not a number`, true); return; }
    edit([{ op: "globals", [name]: value }]);
  };
}
document.querySelectorAll("input[name=tool]").forEach((r) => (r.onchange = () => { studio.activePlan = null; }));
$("export-format").onchange = updateExport;
$("drips").onchange = () => { updateExport(); scheduleBrush(); };
$("brush-on").onchange = scheduleBrush;
$("save").onclick = async () => {
  const r = await call("POST", "/api/save");
  if (r) say(`saved ${r.saved}`);
};
$("open").onchange = async (e) => {
  const file = e.target.files[0];
  if (!file) return;
  const r = await call("POST", `/api/open?name=${encodeURIComponent(file.name)}`, file, true);
  e.target.value = "";
  if (r) { fitView(); render(); say(`opened ${file.name}`); }
};

document.addEventListener("keydown", (e) => {
  if (e.target.tagName === "INPUT" || e.target.tagName === "SELECT") return;
  const mod = e.ctrlKey || e.metaKey;
  if (mod && e.key.toLowerCase() === "z") { e.preventDefault(); e.shiftKey ? redo() : undo(); }
  else if (mod && e.key.toLowerCase() === "y") { e.preventDefault(); redo(); }
  else if (e.key === "Delete" || e.key === "Backspace") { e.preventDefault(); deleteSelected(); }
  else if (e.key === "Escape") { studio.activePlan = null; studio.selected = null; render(); }
});

// ------------------------------------------------------------------------------------- animation

$("play").onclick = () => {
  const m = studio.state && studio.state.motion;
  if (!m) return;
  const t0 = m.t[0], begun = performance.now();
  const step = () => {
    const t = t0 + (performance.now() - begun) / 1000;
    let i = Math.min(m.t.length - 1, Math.max(0, Math.round((t - t0) / m.dt)));
    const pen = document.getElementById("pen");
    if (pen) { pen.setAttribute("cx", sx(m.x[i])); pen.setAttribute("cy", sy(m.y[i])); pen.style.opacity = m.pen[i] ? 1 : 0.35; }
    drawSpeed(m.t[i]);
    if (i < m.t.length - 1) requestAnimationFrame(step);
    else setTimeout(() => drawSpeed(), 400);
  };
  requestAnimationFrame(step);
};

// ------------------------------------------------------------------------------------- variations

$("vary").onclick = async () => {
  const result = await call("POST", "/api/variations", { count: 4 });
  if (!result) return;
  const box = $("variants");
  box.innerHTML = `<p class="seed">seed ${result.seed}</p>`;
  result.variants.forEach((v, i) => {
    const m = decodeMotion(v.motion);
    let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
    for (let k = 0; k < m.x.length; k++) { x0 = Math.min(x0, m.x[k]); x1 = Math.max(x1, m.x[k]); y0 = Math.min(y0, m.y[k]); y1 = Math.max(y1, m.y[k]); }
    const runs = [];
    let run = [];
    for (let k = 0; k < m.x.length; k++) {
      if (m.pen[k]) run.push(`${m.x[k].toFixed(2)},${(-m.y[k]).toFixed(2)}`);
      else if (run.length) { runs.push(run); run = []; }
    }
    if (run.length) runs.push(run);
    const pad = 0.06 * Math.max(x1 - x0, y1 - y0);
    const fig = document.createElement("figure");
    fig.innerHTML = `<svg viewBox="${x0 - pad} ${-y1 - pad} ${x1 - x0 + 2 * pad} ${y1 - y0 + 2 * pad}">` +
      runs.map((r) => `<polyline points="${r.join(" ")}" fill="none" stroke="#1f4e99" stroke-width="${(x1 - x0) / 150}"/>`).join("") +
      `</svg><figcaption><span>#${i + 1}</span><button data-index="${i}">Adopt</button></figcaption>`;
    fig.querySelector("button").onclick = async () => {
      if (await call("POST", "/api/variations/adopt", { index: i })) say(`adopted variation #${i + 1}`);
    };
    box.appendChild(fig);
  });
};

// ------------------------------------------------------------------------------------- drawing

function drawButtons(state) {
  const going = state === "running" || state === "paused" || state === "preparing" || state === "stopping";
  $("draw").disabled = going;
  $("pause").disabled = state !== "running";
  $("resume").disabled = state !== "paused";
  $("stop").disabled = !(state === "running" || state === "paused");
}

$("draw").onclick = async () => {
  studio.executed = []; studio.live = [];
  drawButtons("preparing");
  try {
    const [device, profile] = $("device").value.split(":");  // a serial arm: its profile
    const r = await api("POST", "/api/draw", profile ? { device, profile } : { device });
    $("draw-status").textContent = `drawing into ${r.folder}`;
    drawButtons(r.state);
  } catch (e) {
    say(e.message, true);
    $("draw-status").textContent = `refused: ${e.message}`;
    drawButtons("idle");
  }
};
for (const name of ["pause", "resume", "stop"]) {
  $(name).onclick = async () => {
    try { const r = await api("POST", `/api/draw/${name}`); drawButtons(r.state); }
    catch (e) { say(e.message, true); }
  };
}

function onDrawEvent(msg) {
  studio.stats.drawEvents = (studio.stats.drawEvents || 0) + 1;
  if (msg.points) studio.stats.livePoints = (studio.stats.livePoints || 0) + msg.points.length;
  if (msg.points && msg.points.length) {
    const from = Math.max(0, studio.live.length - 1);
    studio.live.push(...msg.points);
    traceRuns(layer.getContext("2d"), studio.live.slice(from), COLORS.live, 2.5); // only what is new
  }
  $("draw-progress").max = msg.total || 1;
  $("draw-progress").value = msg.done || 0;
  drawButtons(msg.state);
  const where = msg.folder ? ` — ${msg.folder}` : "";
  if (msg.state === "running" || msg.state === "paused") {
    $("draw-status").textContent = `${msg.state}: ${msg.done}/${msg.total}${where}`;
  } else if (msg.state === "done") {
    const s = msg.summary || {};
    const dev = s.path_deviation_mean_mm !== undefined ? `; deviation ${s.path_deviation_mean_mm.toFixed(3)} mm mean` : "";
    $("draw-status").textContent = `done${where}${dev}`;
  } else if (msg.state === "stopped" || msg.state === "failed") {
    $("draw-status").textContent = `${msg.state}: ${msg.error || ""}${where}`;
  }
  if (msg.executed) { studio.executed = msg.executed; studio.live = []; render(); }
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws?token=${encodeURIComponent(token)}`);
  studio.ws = ws;
  ws.onmessage = (e) => {
    const msg = JSON.parse(e.data);
    if (msg.type === "draw") onDrawEvent(msg);
    else if (msg.type === "state" || msg.type === "error") onEditAnswer(msg);
    else if (msg.type === "hello") { studio.wsReady = true; drawButtons(msg.draw.state); }
  };
  ws.onclose = () => {
    studio.wsReady = false;
    studio.inflight.clear(); // their answers are lost: the next edit goes by HTTP meanwhile
    studio.busy = false;
    pump();
    setTimeout(connect, 1000);
  };
}

// Long frames while the page runs (for the benchmark: none should exceed 100 ms during a draw).
let lastFrame = performance.now();
function watchFrames() {
  const now = performance.now();
  if (studio.stats.recordFrames) studio.stats.frames.push(now - lastFrame);
  lastFrame = now;
  requestAnimationFrame(watchFrames);
}

async function start() {
  connect();
  requestAnimationFrame(watchFrames);
  await call("GET", "/api/state");
  while (studio.state && !studio.state.ready) {
    await new Promise((r) => setTimeout(r, 300));
    await call("GET", "/api/state");
  }
  if (studio.state && !$("status").classList.contains("error")) {
    say("ready: draw a gesture (Shift-drag a trajectory to move it), or pick Targets and click");
  }
  studio.ready = true;
}
window.addEventListener("resize", () => { if (studio.state) render(); });
start();
