// The trainer page: connects to the session at /session, draws the tissue and the
// instruments live and drives the selected instrument with mouse and keyboard.
//
// window.peLive: the page's state, for tests and the browser console (read it, do not
// write it):
//   state            'connecting' | 'open' | 'closed': the WebSocket session
//   clientId         this page's client id (the hello message's), or null
//   hello            the last hello message, or null
//   bodies           body names by body id (from hello; "body N" when it names none)
//   topology         { triangles: Uint32Array(3m), reference: Float32Array(3n), body: Uint16Array(n) } | null
//   frames           { topology, positions, tools }: binary frames received since the page loaded
//   firstFrameMs, lastFrameMs   performance.now() at the first and the last POSITIONS frame
//   positions        the last POSITIONS frame: Float32Array(3n), m; positionsTime_s, positionsSeq
//   toolPoses        the last TOOLS frame: [{ orientation: [w,x,y,z], position_m: [x,y,z] }] per tool
//   force            { TOOL: { time_s, force_n: [x,y,z] } }: the last force message per tool
//   forceMessages    force messages received
//   forceBarN        the magnitude the force bar shows now (N); forcePeakN: the largest it showed
//   status           the last status message; drivers: { TOOL: client id | null }
//   posesSent        pose messages sent; lastPose: the last one sent (the message object)
//   log              [{ t_ms, kind: 'info' | 'notice' | 'error', message, repeats? }]: the session log
//   webgl            { webgl2: bool, renderer: string, software: bool }; renderedFrames: frames drawn
//   renderScale      the view's resolution scale now (adaptive, 0.4..1); drawCostMs: a drawn frame's cost
//   pinResolution(s) pins the resolution scale to s (1: full; null: adaptive again), e.g. for screenshots
//   selectedTool     the name of the tool the mouse and keys drive
//   project(p)       CSS pixel [x, y] on the canvas of the scene point p (m), or null
//   toolTip(name)    the tip (m) of the tool as drawn (the applied pose, else the commanded one)
//   camera           the view's OrbitCamera (camera.js): target, distance, yaw, pitch

import { add, scale, distance } from './math.js';
import { Session } from './session.js';
import { Instrument } from './instrument.js';
import { OrbitCamera } from './camera.js';
import { Renderer, bodyColor, heatColor } from './render.js';
import { Hud, formatNewtons } from './hud.js';

const POSE_INTERVAL_MS = 1000 / 60;
const INSERT_SPEED_MPS = 0.02;
const ROLL_SPEED_RADPS = Math.PI / 2;
const PIVOT_SPEED_RADPS = Math.PI / 12;
const KEY_TAP_INSERT_M = 0.0005;
const KEY_TAP_ROLL_RAD = Math.PI / 60;
/** Half the height (m) the work-site view shows, and the direction it looks from. */
const WORK_SITE_VIEW_M = 0.06;
const WORK_SITE_YAW_DEG = 110;
const WORK_SITE_PITCH_DEG = 48;
const WHEEL_INSERT_M_PER_PX = 0.00001; // 1 mm per wheel notch (100 px)

const $ = (id) => document.getElementById(id);
const canvas = $('view');
const hud = new Hud();
const camera = new OrbitCamera();

const live = {
  state: 'connecting', clientId: null, hello: null, bodies: [], topology: null,
  frames: { topology: 0, positions: 0, tools: 0 }, firstFrameMs: null, lastFrameMs: null,
  positions: null, positionsTime_s: null, positionsSeq: null, toolPoses: null,
  force: {}, forceMessages: 0, forceBarN: 0, forcePeakN: 0,
  status: null, drivers: {}, posesSent: 0, lastPose: null, log: hud.logEntries,
  webgl: { webgl2: false, renderer: '' }, renderedFrames: 0, selectedTool: null,
  camera,
  project: (p) => (renderer ? renderer.project(p) : null),
  toolTip: (name) => {
    const i = instruments.findIndex((t) => t.name === name);
    return i < 0 ? null : drawnPose(i).tip;
  },
};
window.peLive = live;

let renderer = null;
try {
  renderer = new Renderer(canvas);
  live.webgl = { webgl2: true, renderer: renderer.rendererName, software: renderer.software };
} catch (e) {
  hud.log('error', `no 3D view: ${e.message}`);
}

let instruments = [];
let selected = 0;
/** Per tool: whether this page drives it (sent a pose, not released), the last version sent. */
let driving = [];
let sentVersion = [];
let lastSendMs = -Infinity;
/** Per tool: forces received since the last drawn frame (sum and count). */
let forceAcc = {};
let shownForce = {};
let surfaceDirty = false;
let colorByDisplacement = false;
let bodyColors = null;
const frameTimes = [];
let sceneLo = null;
let sceneHi = null;

function log(kind, message) {
  hud.log(kind, message);
}

// ---- session ----------------------------------------------------------------------------

const url = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/session`;
const session = new Session(url, {
  onState(state, detail) {
    live.state = state;
    hud.setConnection(state, detail);
    if (state === 'open') log('info', `connected to ${url}`);
    hud.setBanner(state === 'closed' ? `Session closed (${detail}): reconnecting…` : null);
    if (state === 'closed') {
      log('error', `session closed (${detail}); reconnecting`);
      driving = driving.map(() => false);
    }
  },
  onText: onMessage,
  onFrame,
  onBadMessage: (m) => log('error', `from the server: ${m}`),
});

function onMessage(m) {
  switch (m.type) {
    case 'hello': return onHello(m);
    case 'force': {
      live.forceMessages++;
      live.force[m.tool] = { time_s: m.time_s, force_n: m.force_n };
      const a = forceAcc[m.tool] || (forceAcc[m.tool] = { sum: [0, 0, 0], n: 0 });
      a.sum = add(a.sum, m.force_n);
      a.n++;
      return;
    }
    case 'status':
      live.status = m;
      if (m.drivers) setDrivers({ ...m.drivers });
      hud.setStatus(m, frameRate(), live.hello?.graphics_hz);
      return;
    case 'driver': {
      const was = live.drivers[m.tool];
      setDrivers({ ...live.drivers, [m.tool]: m.client });
      if (was !== m.client) {
        const who = m.client === null ? 'nobody' : m.client === live.clientId ? 'you' : `client ${m.client}`;
        log('info', `${m.tool}: driven by ${who}`);
      }
      return;
    }
    case 'error': return log('error', m.message);
    case 'notice': return log('notice', m.message);
    default: return log('notice', `message of unknown type ${JSON.stringify(m.type)} ignored`);
  }
}

function setDrivers(drivers) {
  live.drivers = drivers;
  instruments.forEach((ins, i) => {
    const d = drivers[ins.name];
    if (driving[i] && d !== undefined && d !== null && d !== live.clientId) driving[i] = false;
  });
  hud.setDrivers(instruments.map((t) => t.name), drivers, live.clientId);
}

function onHello(m) {
  live.hello = m;
  live.clientId = m.client ?? null;
  const names = m.surface?.bodies ?? m.surface?.body_names ?? m.bodies ?? [];
  live.bodies = names;
  instruments = (m.tools || []).map((t) => new Instrument(t));
  driving = instruments.map(() => false);
  sentVersion = instruments.map((t) => t.version);
  selected = Math.min(selected, Math.max(0, instruments.length - 1));
  live.selectedTool = instruments[selected]?.name ?? null;
  hud.setHello(m);
  hud.setTools(instruments.map((t) => t.name), selected, (i) => {
    selected = i;
    live.selectedTool = instruments[i].name;
  });
  setDrivers({});
  log('info', `client ${m.client}: ${m.scene}, ${m.surface?.nodes ?? '?'} surface nodes, `
    + `${instruments.length} tool${instruments.length === 1 ? '' : 's'}, dt ${fmtUs(m.dt_s)}`);
}

const fmtUs = (s) => (Number.isFinite(s) ? `${(s * 1e6).toFixed(1)} µs` : '?');

function onFrame(f) {
  if (f.kind === 'topology') {
    live.frames.topology++;
    const n = f.body.length;
    live.topology = { triangles: f.triangles, reference: f.reference, body: f.body };
    if (live.bodies.length === 0) {
      const ids = Math.max(0, ...f.body) + 1;
      live.bodies = Array.from({ length: ids }, (_, i) => `body ${i}`);
    }
    bodyColors = new Float32Array(3 * n);
    for (let i = 0; i < n; i++) bodyColors.set(bodyColor(live.bodies[f.body[i]], f.body[i]), 3 * i);
    live.positions = f.reference;
    sceneBox(f.reference);
    if (renderer) {
      renderer.setTopology(f.triangles, bodyColors);
      renderer.setGrid(sceneLo, sceneHi, 0.01);
    }
    frameView();
    surfaceDirty = true;
  } else if (f.kind === 'positions') {
    const now = performance.now();
    live.frames.positions++;
    live.firstFrameMs ??= now;
    live.lastFrameMs = now;
    frameTimes.push(now);
    if (live.topology && f.positions.length !== live.topology.reference.length) {
      log('error', `POSITIONS frame ${f.seq}: ${f.positions.length / 3} nodes, the topology has ${live.topology.reference.length / 3}`);
      return;
    }
    live.positions = f.positions;
    live.positionsTime_s = f.time_s;
    live.positionsSeq = f.seq;
    surfaceDirty = true;
  } else if (f.kind === 'tools') {
    live.frames.tools++;
    live.toolPoses = f.poses;
  }
}

function frameRate() {
  const now = performance.now();
  while (frameTimes.length && frameTimes[0] < now - 1000) frameTimes.shift();
  return frameTimes.length;
}

function sceneBox(reference) {
  sceneLo = [Infinity, Infinity, Infinity];
  sceneHi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < reference.length; i += 3) {
    for (let k = 0; k < 3; k++) {
      sceneLo[k] = Math.min(sceneLo[k], reference[i + k]);
      sceneHi[k] = Math.max(sceneHi[k], reference[i + k]);
    }
  }
}

/** Views the work site: the selected instrument's tip and the tissue about it. */
function frameView() {
  const ins = instruments[selected];
  if (!ins) return frameScene();
  camera.target = add(ins.tip0, [0, 0, -0.004]);
  camera.distance = WORK_SITE_VIEW_M / Math.tan(camera.fovy / 2);
  camera.yaw = (WORK_SITE_YAW_DEG * Math.PI) / 180;
  camera.pitch = (WORK_SITE_PITCH_DEG * Math.PI) / 180;
}

/** Views every organ, instrument tip and trocar. */
function frameScene() {
  if (!sceneLo) return;
  const points = [sceneLo, sceneHi];
  for (const ins of instruments) points.push(ins.tip0, ...(ins.trocar ? [ins.trocar] : []));
  camera.frame(points, WORK_SITE_YAW_DEG, WORK_SITE_PITCH_DEG);
}

// ---- the instruments --------------------------------------------------------------------

/** The pose drawn for tool i: the applied pose (TOOLS frame) if known, else the page's. */
function drawnPose(i) {
  const ins = instruments[i];
  const applied = live.toolPoses?.[i];
  if (applied) {
    const probe = new Instrument({ name: ins.name, a_m: ins.tip0, b_m: ins.tail0, radius_m: ins.radius, trocar_m: ins.trocar });
    probe.set(applied.orientation, applied.position_m);
    return { tip: probe.tip(), tail: probe.tail(), axis: probe.axis(), side: probe.side(), applied: true };
  }
  return { tip: ins.tip(), tail: ins.tail(), axis: ins.axis(), side: ins.side(), applied: false };
}

/** Whether the page may move the selected tool now; takes the applied pose on first use. */
function grab() {
  const ins = instruments[selected];
  if (!ins) return null;
  const d = live.drivers[ins.name];
  if (d !== undefined && d !== null && d !== live.clientId) {
    log('notice', `${ins.name} is driven by client ${d}; it must release it first`);
    return null;
  }
  if (!driving[selected]) {
    const applied = live.toolPoses?.[selected];
    if (applied && !ins.adopt(applied)) ins.reset();
    driving[selected] = true;
  }
  return ins;
}

function sendPoses() {
  const now = performance.now();
  if (now - lastSendMs < POSE_INTERVAL_MS - 0.5) return;
  instruments.forEach((ins, i) => {
    if (!driving[i] || ins.version === sentVersion[i]) return;
    const msg = { type: 'pose', tool: ins.name, ...ins.pose() };
    if (session.send(msg)) {
      sentVersion[i] = ins.version;
      lastSendMs = now;
      live.posesSent++;
      live.lastPose = msg;
    }
  });
}
setInterval(sendPoses, 4);

// ---- input ------------------------------------------------------------------------------

let drag = null;
canvas.addEventListener('contextmenu', (e) => e.preventDefault());
canvas.addEventListener('pointerdown', (e) => {
  canvas.focus();
  const mode = e.button === 0 && !e.shiftKey ? 'tool'
    : e.button === 2 && !e.shiftKey ? 'orbit' : 'pan';
  if (mode === 'tool' && !grab()) return;
  drag = { mode, x: e.clientX, y: e.clientY, id: e.pointerId };
  canvas.setPointerCapture(e.pointerId);
  canvas.classList.add('dragging');
  e.preventDefault();
});
canvas.addEventListener('pointermove', (e) => {
  if (!drag || e.pointerId !== drag.id) return;
  const dx = e.clientX - drag.x;
  const dy = e.clientY - drag.y;
  drag.x = e.clientX;
  drag.y = e.clientY;
  if (drag.mode === 'orbit') camera.orbit(dx, dy);
  else if (drag.mode === 'pan') camera.pan(dx, dy, canvas.clientHeight);
  else {
    const ins = instruments[selected];
    const tip = ins.tip();
    ins.pivotToward(add(tip, camera.dragVector(tip, dx, dy, canvas.clientHeight)));
  }
});
const endDrag = (e) => {
  if (!drag || e.pointerId !== drag.id) return;
  drag = null;
  canvas.classList.remove('dragging');
};
canvas.addEventListener('pointerup', endDrag);
canvas.addEventListener('pointercancel', endDrag);
canvas.addEventListener('wheel', (e) => {
  e.preventDefault();
  const px = (e.deltaY || e.deltaX) * (e.deltaMode === 1 ? 33 : e.deltaMode === 2 ? 400 : 1);
  if (e.shiftKey) camera.zoom(Math.exp(px * 0.0015));
  else {
    const ins = grab();
    if (ins) ins.insert(-px * WHEEL_INSERT_M_PER_PX);
  }
}, { passive: false });

const held = new Map();
window.addEventListener('keydown', (e) => {
  if (e.target instanceof HTMLSelectElement || e.target instanceof HTMLInputElement || e.ctrlKey || e.metaKey || e.altKey) return;
  const k = e.key.toLowerCase();
  if (['w', 's', 'q', 'e', 'arrowleft', 'arrowright', 'arrowup', 'arrowdown'].includes(k)) {
    e.preventDefault();
    if (e.repeat || held.has(k)) return;
    held.set(k, performance.now());
    const ins = grab();
    if (!ins) return;
    if (k === 'w') ins.insert(KEY_TAP_INSERT_M);
    if (k === 's') ins.insert(-KEY_TAP_INSERT_M);
    if (k === 'q') ins.roll(-KEY_TAP_ROLL_RAD);
    if (k === 'e') ins.roll(KEY_TAP_ROLL_RAD);
  } else if (k === 'r') resetTool();
  else if (k === 'f') frameView();
  else if (k === 'a') frameScene();
  else if (k === 'c') setColorMode(!colorByDisplacement);
});
window.addEventListener('keyup', (e) => held.delete(e.key.toLowerCase()));
window.addEventListener('blur', () => held.clear());

/** Keys held past a tap move the tool at a steady rate. */
function heldKeys(dt) {
  if (held.size === 0) return;
  const now = performance.now();
  const on = (k) => held.has(k) && now - held.get(k) > 150;
  const ins = instruments[selected];
  if (!ins || !driving[selected]) return;
  if (on('w')) ins.insert(INSERT_SPEED_MPS * dt);
  if (on('s')) ins.insert(-INSERT_SPEED_MPS * dt);
  if (on('q')) ins.roll(-ROLL_SPEED_RADPS * dt);
  if (on('e')) ins.roll(ROLL_SPEED_RADPS * dt);
  const yaw = (held.has('arrowleft') ? 1 : 0) - (held.has('arrowright') ? 1 : 0);
  const pitch = (held.has('arrowup') ? 1 : 0) - (held.has('arrowdown') ? 1 : 0);
  if (yaw || pitch) ins.pivotBy(yaw * PIVOT_SPEED_RADPS * dt, pitch * PIVOT_SPEED_RADPS * dt);
}

function resetTool() {
  const ins = grab();
  if (ins) {
    ins.reset();
    log('info', `${ins.name}: back to the scene's placement`);
  }
}

function setColorMode(on) {
  colorByDisplacement = on;
  $('chk-displacement').checked = on;
  surfaceDirty = true;
  if (!on) hud.setLegend(null);
}

$('btn-reset-tool').onclick = resetTool;
$('btn-reset-view').onclick = frameView;
$('chk-displacement').onchange = (e) => setColorMode(e.target.checked);
$('btn-release').onclick = () => {
  const ins = instruments[selected];
  if (!ins) return;
  session.send({ type: 'release', tool: ins.name });
  driving[selected] = false;
  log('info', `${ins.name}: released`);
};

// ---- drawing ----------------------------------------------------------------------------

function displacementColors() {
  const ref = live.topology.reference;
  const pos = live.positions;
  const n = ref.length / 3;
  const mag = new Float32Array(n);
  let max = 0;
  for (let i = 0; i < n; i++) {
    const d = Math.hypot(pos[3 * i] - ref[3 * i], pos[3 * i + 1] - ref[3 * i + 1], pos[3 * i + 2] - ref[3 * i + 2]);
    mag[i] = d;
    max = Math.max(max, d);
  }
  const top = Math.max(max, 1e-4);
  const out = new Float32Array(3 * n);
  for (let i = 0; i < n; i++) out.set(heatColor(mag[i] / top), 3 * i);
  hud.setLegend(top);
  return out;
}

function meanForces() {
  for (const [tool, a] of Object.entries(forceAcc)) {
    if (a.n > 0) shownForce[tool] = scale(a.sum, 1 / a.n);
    a.sum = [0, 0, 0];
    a.n = 0;
  }
}

/** The panels and the 3D view are redrawn at most this often (the surface comes at ~30 Hz). */
const HUD_INTERVAL_MS = 1000 / 40;
let lastFrameAt = performance.now();
let lastHudAt = -Infinity;
let lastDraw = '';

/** What the 3D view shows, in a string: redraw only when it changes. */
function viewKey() {
  const c = camera;
  return [
    live.positionsSeq, live.frames.tools, live.frames.topology, c.yaw, c.pitch, c.distance, ...c.target,
    canvas.clientWidth, canvas.clientHeight, window.devicePixelRatio, colorByDisplacement, selected,
    ...instruments.map((t, i) => `${t.version}:${driving[i]}`), live.forceBarN,
  ].join(' ');
}

/**
 * Frame cost control: a drawn frame's cost is the time to the next animation frame (with
 * WebGL on the CPU the browser waits there for the drawing). The view is redrawn at most
 * once per twice that cost (and at least every DRAW_INTERVAL_MAX_MS when it changes), so
 * the page keeps time to read the session, and its resolution falls while a frame costs
 * more than FRAME_BUDGET_MS (and rises again when it costs less).
 */
const FRAME_BUDGET_MS = 40;
const SCALE_MIN = 0.4;
let drawCostMs = 0;
let drawnAt = null;
let lastDrawAt = -Infinity;
let pinnedScale = null;

const WARM_UP_DRAWS = 5;
const DRAW_INTERVAL_MAX_MS = 200;

function adaptScale() {
  if (drawnAt === null) return;
  const cost = Math.max(0, performance.now() - drawnAt);
  drawnAt = null;
  if (renderer.frames <= WARM_UP_DRAWS) return; // shaders compile, buffers are made
  drawCostMs = drawCostMs === 0 ? cost : 0.7 * drawCostMs + 0.3 * cost;
  if (!renderer || pinnedScale !== null) return;
  if (drawCostMs > FRAME_BUDGET_MS && renderer.scale > SCALE_MIN) renderer.scale = Math.max(SCALE_MIN, renderer.scale * 0.85);
  else if (drawCostMs < FRAME_BUDGET_MS / 2.5 && renderer.scale < 1) renderer.scale = Math.min(1, renderer.scale * 1.05);
}

function frame(now) {
  const dt = Math.min(0.1, (now - lastFrameAt) / 1000);
  lastFrameAt = now;
  adaptScale();
  heldKeys(dt);
  if (now - lastHudAt >= HUD_INTERVAL_MS) {
    lastHudAt = now;
    meanForces();
    const ins = instruments[selected];
    const force = ins ? shownForce[ins.name] ?? null : null;
    live.forceBarN = hud.setForce(force, now);
    live.forcePeakN = Math.max(live.forcePeakN, live.forceBarN);
    const key = viewKey();
    if (renderer && live.topology && key !== lastDraw
      && now - lastDrawAt >= Math.min(2 * drawCostMs, DRAW_INTERVAL_MAX_MS)) {
      lastDraw = key;
      lastDrawAt = now;
      draw(force);
      drawnAt = performance.now();
    }
  }
  requestAnimationFrame(frame);
}

/** Pins the view's resolution scale (1: the device's; null: adaptive again), e.g. for a screenshot. */
live.pinResolution = (scale) => {
  pinnedScale = scale;
  if (renderer && scale !== null) renderer.scale = scale;
  lastDraw = '';
};

function draw(force) {
  if (surfaceDirty && live.positions) {
    renderer.setPositions(live.positions, colorByDisplacement ? displacementColors() : bodyColors);
    surfaceDirty = false;
  }
  const drawn = instruments.map((t, i) => {
    const pose = drawnPose(i);
    const ghost = driving[i] && pose.applied && distance(t.tip(), pose.tip) > 2e-4
      ? { tip: t.tip(), tail: t.tail() } : null;
    return {
      ...pose, radius: t.radius, trocar: t.trocar, ghost,
      color: i === selected ? [0.78, 0.80, 0.84] : [0.62, 0.64, 0.68],
      force: shownForce[t.name] ?? null,
      forceScale: 0.03 / (hud.fullScale || 1),
    };
  });
  renderer.draw(camera, { instruments: drawn });
  live.renderedFrames = renderer.frames;
  live.renderScale = renderer.scale;
  live.drawCostMs = drawCostMs;
  const sel = drawn[selected];
  hud.setTipLabel(sel && force ? renderer.project(sel.tip) : null, `${formatNewtons(live.forceBarN)} N`);
  hud.setGizmoLabels(renderer.gizmoLabels());
  hud.setScaleBar(camera.worldPerPixel(camera.target, canvas.clientHeight));
}
requestAnimationFrame(frame);
setInterval(() => hud.setFrameRate(frameRate(), live.hello?.graphics_hz), 500);
