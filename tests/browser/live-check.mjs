// The trainer page in a real browser: Debian's chromium, headless, driven by Playwright
// (playwright-core, no browser download). Run by scripts/live-check.sh against
// `pe live --builtin --level coarse`:
//   node live-check.mjs URL OUT_DIR
// Loads the page, checks it has a WebGL2 context, drags the probe about its trocar and
// inserts it with the mouse wheel (real mouse events on the canvas) so it presses onto the
// right tube, then asserts from window.peLive (documented in host-tools/src/live/web/main.js):
// - the right tube's surface moved in the frames the page received (max displacement over
//   its nodes between the last frame before the drag and the last one after it);
// - the far organs (the uterus and the left tube) moved much less;
// - the force bar rose above a threshold, from near zero before the drag;
// - the page received surface frames at >= 25 Hz over the run.
// Saves OUT_DIR/trainer.png and OUT_DIR/live-check.json; exits 1 with the reasons otherwise.

import { mkdtempSync, writeFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { chromium } from 'playwright-core';

const [url, outDir] = process.argv.slice(2);
if (!url || !outDir) {
  console.error('usage: node live-check.mjs URL OUT_DIR');
  process.exit(2);
}

/** The probe must move the tube this much (m): well above f32 noise and the idle drift. */
const TUBE_MOVED_M = 0.5e-3;
/** The far organs must move less than this fraction of the tube's displacement. */
const FAR_FRACTION = 0.2;
/**
 * The force bar must rise above this (N) after the press, from below IDLE_FORCE_N (no
 * contact: zero). The tube is soft (3 kPa): the scripted push of the same scene (`pe solve
 * --builtin --level coarse`) peaks at 2.9 mN; this press peaked at 1.3 to 2.6 mN over five
 * runs and holds about 0.3 mN.
 */
// The bar's peak over the press: 0.53 to 2.6 mN measured over nine runs (how deep the drag
// lands against the ringing tube varies with the session's timing); idle it reads 0.
const FORCE_N = 0.00025;
const IDLE_FORCE_N = 0.0001;
/** Simulated time (s) the press is held before the state is compared (the scripted push: 0.6 s). */
const HOLD_SIM_S = 0.6;
/** Surface frames the page must receive per second (the issue's graphics rate). */
const FRAME_RATE_HZ = 25;
/** Wheel notches of insertion after the drag (the page inserts 1 mm per 100 px notch). */
const INSERT_NOTCHES = 4;
/**
 * The drag pivots the tip 2.25 mm across the shaft (downward) and the wheel inserts it
 * 4 mm: with the built-in probe's 30 degree lean, 4.7 mm straight down and 0.2 mm aside,
 * about the scripted path's 4.5 mm push onto the tube (1 mm of it the gap above it).
 */
const PIVOT_M = 0.00225;
const PROBE = 'probe';
const RIGHT_TUBE = 'right_oviduct';
const FAR_BODIES = ['body_of_uterus', 'fundus', 'left_oviduct'];

const failures = [];
const check = (ok, what) => {
  console.log(`live-check: ${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) failures.push(what);
};
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function waitFor(page, fn, arg, what, timeoutMs = 60000) {
  try {
    await page.waitForFunction(fn, arg, { timeout: timeoutMs, polling: 100 });
  } catch {
    throw new Error(`timed out after ${timeoutMs / 1000} s waiting for ${what}`);
  }
}

/** Max displacement (m) between two position arrays over the nodes of the named bodies. */
function maxDisplacement(a, b, body, bodies, names) {
  const ids = new Set(names.map((n) => bodies.indexOf(n)).filter((i) => i >= 0));
  let max = 0;
  let count = 0;
  for (let i = 0; i < body.length; i++) {
    if (!ids.has(body[i])) continue;
    count++;
    const d = Math.hypot(a[3 * i] - b[3 * i], a[3 * i + 1] - b[3 * i + 1], a[3 * i + 2] - b[3 * i + 2]);
    max = Math.max(max, d);
  }
  return { max, count };
}

const snapshot = (page) => page.evaluate(() => {
  const l = window.peLive;
  return {
    positions: Array.from(l.positions),
    frames: l.frames.positions,
    nowMs: performance.now(),
    forceBarN: l.forceBarN,
    forcePeakN: l.forcePeakN,
    force: l.force,
  };
});

const userDataDir = mkdtempSync(join(tmpdir(), 'pe-live-chromium-'));
let context;
const results = { url, thresholds: { TUBE_MOVED_M, FAR_FRACTION, FORCE_N, IDLE_FORCE_N, FRAME_RATE_HZ } };
try {
  context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: '/usr/bin/chromium',
    headless: true,
    viewport: { width: 1440, height: 880 },
    args: [
      '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
      '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    ],
  });
  const page = context.pages()[0] ?? (await context.newPage());
  const pageErrors = [];
  page.on('pageerror', (e) => pageErrors.push(`page error: ${e.message}`));
  page.on('console', (m) => { if (m.type() === 'error') pageErrors.push(`console error: ${m.text()}`); });

  const response = await page.goto(url, { waitUntil: 'load' });
  check(response && response.ok(), `GET ${url} answers ${response ? response.status() : 'nothing'}`);
  await waitFor(page, () => window.peLive !== undefined, null, 'the page to set window.peLive');
  const gl = await page.evaluate(() => window.peLive.webgl);
  check(gl.webgl2, `the canvas has a WebGL2 context (${gl.renderer || 'none'})`);
  await waitFor(page, () => window.peLive.state === 'open' && window.peLive.topology && window.peLive.frames.positions > 10
    && window.peLive.renderedFrames > 5, null, 'the session to open and the first surface frames');
  const hello = await page.evaluate(() => window.peLive.hello);
  const bodies = await page.evaluate(() => window.peLive.bodies);
  const body = await page.evaluate(() => Array.from(window.peLive.topology.body));
  results.model = hello.model;
  console.log(`live-check: ${hello.scene}: ${hello.model}; ${body.length} surface nodes; bodies ${bodies.join(', ')}`);
  check(bodies.includes(RIGHT_TUBE), `the hello message names the bodies, ${RIGHT_TUBE} among them`);
  check((hello.tools || []).some((t) => t.name === PROBE && t.trocar_m), `the scene has a tool ${PROBE} with a trocar`);

  // Let the tissue settle, then take the state before the drag.
  await sleep(1500);
  const before = await snapshot(page);
  const first = await page.evaluate(() => ({ atMs: window.peLive.firstFrameMs }));

  // Where the probe's tip is on the screen, and which way on the screen moves it down
  // while pivoting about the trocar (the tip moves on a sphere about the trocar: only the
  // part of "down" across the shaft is a pivot).
  const aim = await page.evaluate(({ probe, pivot }) => {
    const l = window.peLive;
    const tool = l.hello.tools.find((t) => t.name === probe);
    const tip = l.toolTip(probe);
    const T = tool.trocar_m;
    const ax = [0, 1, 2].map((k) => tip[k] - T[k]);
    const n = Math.hypot(...ax);
    const a = ax.map((v) => v / n);
    const down = [0, 0, -1];
    const d = down[0] * a[0] + down[1] * a[1] + down[2] * a[2];
    const t = [0, 1, 2].map((k) => down[k] - d * a[k]);
    const tn = Math.hypot(...t);
    // A pivot of the tip across the shaft, downward, by PIVOT_M.
    const target = [0, 1, 2].map((k) => tip[k] + (pivot * t[k]) / tn);
    const canvas = document.getElementById('view').getBoundingClientRect();
    return { from: l.project(tip), to: l.project(target), canvas: [canvas.left, canvas.top], tip };
  }, { probe: PROBE, pivot: PIVOT_M });
  check(aim.from && aim.to, `the probe's tip is in view (${aim.from && aim.from.map((v) => v.toFixed(0))})`);
  const [cx, cy] = aim.canvas;
  const x0 = cx + aim.from[0];
  const y0 = cy + aim.from[1];
  const x1 = cx + aim.to[0];
  const y1 = cy + aim.to[1];
  console.log(`live-check: drag from (${x0.toFixed(0)}, ${y0.toFixed(0)}) to (${x1.toFixed(0)}, ${y1.toFixed(0)}), then ${INSERT_NOTCHES} wheel notches in`);
  await page.mouse.move(x0, y0);
  await page.mouse.down({ button: 'left' });
  await page.mouse.move(x1, y1, { steps: 25 });
  await page.mouse.up({ button: 'left' });
  for (let i = 0; i < INSERT_NOTCHES; i++) {
    await page.mouse.wheel(0, -100);
    await sleep(120);
  }
  // Hold the press while the tissue responds, in simulated time (a loaded machine runs
  // slower than real time; the session's clock then slips, and the check waits longer).
  const pressedAt = await page.evaluate(() => window.peLive.status.time_s);
  await waitFor(page, ({ t }) => window.peLive.status.time_s >= t, { t: pressedAt + HOLD_SIM_S },
    `${HOLD_SIM_S} s of simulated time after the press`, 180000);
  const after = await snapshot(page);
  const state = await page.evaluate(() => ({
    posesSent: window.peLive.posesSent, lastPose: window.peLive.lastPose, drivers: window.peLive.drivers,
    clientId: window.peLive.clientId, status: window.peLive.status, log: window.peLive.log,
    last: { frames: window.peLive.frames.positions, atMs: window.peLive.lastFrameMs },
  }));
  check(state.posesSent > 0, `the page sent poses (${state.posesSent}; last ${JSON.stringify(state.lastPose)})`);
  check(state.drivers[PROBE] === state.clientId, `the session says this page (client ${state.clientId}) drives ${PROBE} (${JSON.stringify(state.drivers)})`);

  const tube = maxDisplacement(before.positions, after.positions, body, bodies, [RIGHT_TUBE]);
  const far = maxDisplacement(before.positions, after.positions, body, bodies, FAR_BODIES);
  results.tube_max_displacement_m = tube.max;
  results.far_max_displacement_m = far.max;
  check(tube.count > 0 && tube.max > TUBE_MOVED_M,
    `the right tube moved: max displacement ${(tube.max * 1e3).toFixed(3)} mm over its ${tube.count} surface nodes > ${TUBE_MOVED_M * 1e3} mm`);
  check(far.count > 0 && far.max < FAR_FRACTION * tube.max,
    `the far organs moved much less: ${(far.max * 1e3).toFixed(3)} mm over ${far.count} nodes < ${FAR_FRACTION} x the tube's`);

  results.force_before_n = before.forceBarN;
  results.force_peak_n = after.forcePeakN;
  results.force_after_n = after.forceBarN;
  check(before.forcePeakN < IDLE_FORCE_N, `the force bar was near zero before the drag (peak ${before.forcePeakN.toFixed(5)} N < ${IDLE_FORCE_N} N)`);
  check(after.forcePeakN > FORCE_N, `the force bar rose: peak ${after.forcePeakN.toFixed(5)} N > ${FORCE_N} N (${after.forceBarN.toFixed(5)} N at the end)`);

  const overall = (1000 * (state.last.frames - 1)) / (state.last.atMs - first.atMs);
  results.frame_rate_hz = overall;
  check(overall >= FRAME_RATE_HZ, `surface frames received at ${overall.toFixed(1)} Hz over ${((state.last.atMs - first.atMs) / 1000).toFixed(1)} s >= ${FRAME_RATE_HZ} Hz`);
  results.status = state.status;
  console.log(`live-check: status ${JSON.stringify(state.status)}`);
  for (const e of state.log.filter((e) => e.kind !== 'info')) console.log(`live-check: page log ${e.kind}: ${e.message}`);

  // The screenshot at the full resolution (the page lowers it while frames cost too much).
  const drawn = await page.evaluate(() => { window.peLive.pinResolution(1); return window.peLive.renderedFrames; });
  await waitFor(page, (n) => window.peLive.renderedFrames >= n + 2, drawn, 'two frames drawn at full resolution');
  await page.screenshot({ path: join(outDir, 'trainer.png') });
  console.log(`live-check: screenshot ${join(outDir, 'trainer.png')}`);
  // And coloured by displacement (the C key).
  const before2 = await page.evaluate(() => window.peLive.renderedFrames);
  await page.keyboard.press('c');
  await waitFor(page, (n) => window.peLive.renderedFrames >= n + 2, before2, 'two frames drawn in displacement colours');
  await page.screenshot({ path: join(outDir, 'trainer-displacement.png') });
  console.log(`live-check: screenshot ${join(outDir, 'trainer-displacement.png')}`);
  check(pageErrors.length === 0, `no page errors${pageErrors.length ? `: ${pageErrors.join('; ')}` : ''}`);
} catch (e) {
  failures.push(e.message);
  console.error(`live-check: FAIL ${e.message}`);
} finally {
  if (context) await context.close();
  rmSync(userDataDir, { recursive: true, force: true });
}
results.failures = failures;
writeFileSync(join(outDir, 'live-check.json'), `${JSON.stringify(results, null, 2)}\n`);
if (failures.length) {
  console.error(`live-check: ${failures.length} check(s) failed:\n  ${failures.join('\n  ')}`);
  process.exit(1);
}
console.log('live-check: all checks passed');
