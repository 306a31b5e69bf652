// The trainer page's own modules under Node's test runner (no browser): the instrument's
// motions keep a laparoscopic instrument's constraint, frames decode as docs/live.md lays
// them out, surface normals point outward, and a drag moves the tip with the mouse.
//   node --test tests/browser/
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Instrument } from '../../host-tools/src/live/web/instrument.js';
import { decodeFrame } from '../../host-tools/src/live/web/session.js';
import { vertexNormals } from '../../host-tools/src/live/web/render.js';
import { OrbitCamera } from '../../host-tools/src/live/web/camera.js';
import { transformPoint } from '../../host-tools/src/live/web/math.js';

const sub = (a, b) => a.map((v, i) => v - b[i]);
const norm = (a) => Math.hypot(...a);
const dot = (a, b) => a.reduce((s, v, i) => s + v * b[i], 0);
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];

/** R(q) as a 3x3 matrix from the textbook formula (independent of math.js's quatRotate). */
function rotationMatrix([w, x, y, z]) {
  return [
    [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
  ];
}
const posed = (pose, x) => {
  const R = rotationMatrix(pose.orientation);
  return R.map((row, i) => dot(row, x) + pose.position_m[i]);
};

/** The built-in scene's probe: a 40 mm capsule leaning 30 degrees, its trocar 150 mm up the shaft. */
const lean = [0.5, 0, Math.sqrt(3) / 2];
const tip0 = [0.0015, 0.0963, 0.0052];
const probe = () => new Instrument({
  name: 'probe', a_m: tip0, b_m: tip0.map((v, i) => v + 0.04 * lean[i]), radius_m: 0.0025,
  trocar_m: tip0.map((v, i) => v + 0.15 * lean[i]),
});

/** A seeded generator (the same sequence every run). */
function rng(seed) {
  let s = seed >>> 0;
  return () => ((s = (Math.imul(s, 1664525) + 1013904223) >>> 0) / 2 ** 32);
}

test('the identity pose leaves the tool where the scene places it', () => {
  const p = probe();
  assert.deepEqual(p.pose(), { orientation: [1, 0, 0, 0], position_m: [0, 0, 0] });
  assert.ok(norm(sub(p.tip(), tip0)) === 0);
});

test('every motion keeps the axis through the trocar and the tool rigid', () => {
  const p = probe();
  const T = p.trocar;
  const tail0 = p.tail0;
  const rand = rng(60);
  let moved = 0;
  for (let k = 0; k < 400; k++) {
    const r = rand();
    const before = p.tip();
    if (r < 0.4) p.pivotToward(p.tip().map((v) => v + (rand() - 0.5) * 0.01));
    else if (r < 0.6) p.insert((rand() - 0.5) * 0.01);
    else if (r < 0.8) p.roll((rand() - 0.5) * 0.5);
    else p.pivotBy((rand() - 0.5) * 0.1, (rand() - 0.5) * 0.1);
    moved = Math.max(moved, norm(sub(p.tip(), before)));
    const pose = p.pose();
    assert.ok(Math.abs(norm(pose.orientation) - 1) < 1e-12, `|q| = ${norm(pose.orientation)}`);
    // The tool's points as the pose message moves them (the textbook rotation matrix).
    const tip = posed(pose, tip0);
    const tail = posed(pose, tail0);
    assert.ok(norm(sub(tip, p.tip())) < 1e-12, 'the page draws the pose it sends');
    assert.ok(Math.abs(norm(sub(tip, tail)) - 0.04) < 1e-12, 'the capsule keeps its length');
    const u = sub(tip, tail).map((v) => v / norm(sub(tip, tail)));
    const off = norm(cross(sub(T, tip), u));
    assert.ok(off < 1e-9, `step ${k}: the axis passes ${off} m from the trocar`);
    const depth = dot(sub(tip, T), u);
    assert.ok(depth >= p.minDepth - 1e-12 && depth <= p.maxDepth + 1e-12, `depth ${depth} out of its limits`);
  }
  assert.ok(moved > 1e-3, 'the motions were not trivial');
});

test('a pivot points the tip from the trocar at the target, keeping its distance', () => {
  const p = probe();
  const target = [0.01, 0.09, -0.004];
  const d0 = norm(sub(p.tip(), p.trocar));
  p.pivotToward(target);
  const a = sub(p.tip(), p.trocar);
  const b = sub(target, p.trocar);
  assert.ok(norm(cross(a, b)) / (norm(a) * norm(b)) < 1e-12, 'tip, trocar and target are in line');
  assert.ok(dot(a, b) > 0);
  assert.ok(Math.abs(norm(a) - d0) < 1e-12, 'the tip stays on its sphere about the trocar');
});

test('insertion slides along the axis, within its limits; roll turns about the axis', () => {
  const p = probe();
  const axis = p.axis();
  const tip = p.tip();
  p.insert(0.003);
  assert.ok(norm(sub(sub(p.tip(), tip), axis.map((v) => 0.003 * v))) < 1e-12, 'in 3 mm along the axis');
  p.insert(-1);
  assert.ok(Math.abs(p.depth() - p.minDepth) < 1e-12, 'held at the shallowest depth');
  assert.ok(p.minDepth >= 0.04, 'the capsule stays inside the body wall');
  p.insert(1);
  assert.ok(Math.abs(p.depth() - p.maxDepth) < 1e-12, 'held at the deepest');
  const q = probe();
  const side = q.side();
  const tipBefore = q.tip();
  q.roll(0.3);
  assert.ok(norm(sub(q.tip(), tipBefore)) < 1e-12, 'roll leaves the tip in place');
  assert.ok(norm(sub(q.axis(), axis)) < 1e-12, 'and the axis');
  assert.ok(Math.abs(Math.acos(dot(side, q.side())) - 0.3) < 1e-9, 'the jaw side turns by the angle');
});

test('without a trocar a drag translates the tool', () => {
  const p = new Instrument({ name: 't', a_m: [0, 0, 0], b_m: [0, 0, 0.02], radius_m: 0.002, trocar_m: null });
  p.pivotToward([0.001, -0.002, 0.003]);
  assert.deepEqual(p.pose().orientation, [1, 0, 0, 0]);
  assert.ok(norm(sub(p.pose().position_m, [0.001, -0.002, 0.003])) < 1e-15);
});

test('an applied pose off the trocar is not adopted; one through it is', () => {
  const p = probe();
  assert.equal(p.adopt({ orientation: [1, 0, 0, 0], position_m: [0, 0, -0.0045] }), false, 'a scripted push is not a trocar pose');
  const q = probe();
  q.pivotToward([0.01, 0.1, 0]);
  q.insert(0.002);
  assert.equal(p.adopt(q.pose()), true);
  assert.ok(norm(sub(p.tip(), q.tip())) < 1e-12);
});

/** A frame laid out as docs/live.md says, written here byte by byte. */
function frame(kind, seq, count, time, payload) {
  const head = new DataView(new ArrayBuffer(24));
  head.setUint8(0, 0x46); head.setUint8(1, 0x53); head.setUint8(2, 0x45); head.setUint8(3, 0x50); // 'F','S','E','P'
  head.setUint16(4, 1, true);
  head.setUint16(6, kind, true);
  head.setUint32(8, seq, true);
  head.setUint32(12, count, true);
  head.setFloat64(16, time, true);
  const out = new Uint8Array(24 + payload.byteLength);
  out.set(new Uint8Array(head.buffer), 0);
  out.set(new Uint8Array(payload), 24);
  return out.buffer;
}
function le(kinds) {
  const size = kinds.reduce((s, [t]) => s + ({ u32: 4, f32: 4, f64: 8, u16: 2 })[t], 0);
  const v = new DataView(new ArrayBuffer(Math.ceil(size / 4) * 4));
  let at = 0;
  for (const [t, x] of kinds) {
    if (t === 'u32') v.setUint32(at, x, true);
    if (t === 'f32') v.setFloat32(at, x, true);
    if (t === 'f64') v.setFloat64(at, x, true);
    if (t === 'u16') v.setUint16(at, x, true);
    at += ({ u32: 4, f32: 4, f64: 8, u16: 2 })[t];
  }
  return v.buffer;
}

test('frames decode as documented; a bad one is refused with the reason', () => {
  const tris = [0, 1, 2, 0, 2, 3];
  const ref = [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0.5];
  const topo = decodeFrame(frame(1, 0, 2, 0, le([
    ...tris.map((i) => ['u32', i]), ['u32', 4], ...ref.map((x) => ['f32', x]), ...[3, 3, 7, 3].map((b) => ['u16', b]),
  ])));
  assert.equal(topo.kind, 'topology');
  assert.deepEqual(Array.from(topo.triangles), tris);
  assert.deepEqual(Array.from(topo.reference), ref);
  assert.deepEqual(Array.from(topo.body), [3, 3, 7, 3]);
  const pos = decodeFrame(frame(2, 17, 2, 0.125, le([0.5, -0.25, 1, 2, 3, 4].map((x) => ['f32', x]))));
  assert.deepEqual({ ...pos, positions: Array.from(pos.positions) },
    { kind: 'positions', seq: 17, time_s: 0.125, positions: [0.5, -0.25, 1, 2, 3, 4] });
  const tools = decodeFrame(frame(3, 2, 1, 1.5, le([0.6, 0.8, 0, 0, 0.001, -0.002, 0.003].map((x) => ['f64', x]))));
  assert.deepEqual(tools.poses, [{ orientation: [0.6, 0.8, 0, 0], position_m: [0.001, -0.002, 0.003] }]);

  const bad = frame(2, 0, 1, 0, le([1, 2, 3].map((x) => ['f32', x])));
  new DataView(bad).setUint8(0, 0x47);
  assert.throws(() => decodeFrame(bad), /magic/);
  assert.throws(() => decodeFrame(frame(2, 0, 5, 0, le([1, 2, 3].map((x) => ['f32', x])))), /POSITIONS frame: 36 bytes/);
  assert.throws(() => decodeFrame(frame(1, 0, 1, 0, le([['u32', 0], ['u32', 1], ['u32', 9], ['u32', 2],
    ...[0, 0, 0, 1, 0, 0].map((x) => ['f32', x]), ['u16', 0], ['u16', 0]]))), /names node 9 of 2/);
  assert.throws(() => decodeFrame(frame(9, 0, 0, 0, new ArrayBuffer(0))), /kind 9/);
});

test('vertex normals of a closed surface point outward', () => {
  // A unit cube, each face two triangles counter-clockwise seen from outside.
  const p = new Float32Array([0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1]);
  const quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]];
  const tris = new Uint32Array(quads.flatMap(([a, b, c, d]) => [a, b, c, a, c, d]));
  const n = new Float32Array(24);
  vertexNormals(p, tris, n);
  for (let i = 0; i < 8; i++) {
    const out = [p[3 * i] - 0.5, p[3 * i + 1] - 0.5, p[3 * i + 2] - 0.5];
    const ni = [n[3 * i], n[3 * i + 1], n[3 * i + 2]];
    assert.ok(Math.abs(norm(ni) - 1) < 1e-6, 'unit normals');
    assert.ok(dot(ni, out) / norm(out) > 0.5, `node ${i}: normal ${ni} points inward`);
  }
});

test('a drag moves the tip under the mouse pixel for pixel', () => {
  const cam = new OrbitCamera();
  cam.target = [0.01, 0.09, 0.002];
  cam.distance = 0.15;
  const heightPx = 880;
  const widthPx = 1200;
  const { viewProj } = cam.matrices(widthPx / heightPx);
  const screen = (x) => {
    const c = transformPoint(viewProj, x);
    return [(0.5 + (0.5 * c[0]) / c[3]) * widthPx, (0.5 - (0.5 * c[1]) / c[3]) * heightPx];
  };
  for (const point of [cam.target, [0.02, 0.1, 0.01]]) {
    const v = cam.dragVector(point, 37, -12, heightPx);
    const a = screen(point);
    const b = screen(point.map((x, i) => x + v[i]));
    assert.ok(Math.abs(b[0] - a[0] - 37) < 1e-3 && Math.abs(b[1] - a[1] + 12) < 1e-3, `moved ${b[0] - a[0]}, ${b[1] - a[1]} px`);
  }
});
