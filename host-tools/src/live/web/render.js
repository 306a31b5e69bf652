// The WebGL2 view: the organ surfaces (normals recomputed every frame), the instrument,
// its trocar and the tool force vector, over a floor grid. Raw WebGL2, no library.

import { add, sub, scale, cross, normalize, perpendicular, perspective, lookAt, mat4Mul } from './math.js';

const SOLID_VS = `#version 300 es
layout(location = 0) in vec3 aPos;
layout(location = 1) in vec3 aNormal;
layout(location = 2) in vec3 aColor;
uniform mat4 uViewProj;
out vec3 vPos;
out vec3 vNormal;
out vec3 vColor;
void main() {
  vPos = aPos;
  vNormal = aNormal;
  vColor = aColor;
  gl_Position = uViewProj * vec4(aPos, 1.0);
}`;

const SOLID_FS = `#version 300 es
precision highp float;
in vec3 vPos;
in vec3 vNormal;
in vec3 vColor;
uniform vec3 uEye;
uniform vec3 uKeyDir;
uniform float uAlpha;
uniform float uShininess;
uniform float uSpecular;
out vec4 outColor;
void main() {
  vec3 n = normalize(vNormal);
  vec3 v = normalize(uEye - vPos);
  if (dot(n, v) < 0.0) n = -n;
  vec3 l = normalize(uKeyDir);
  float key = max(dot(n, l), 0.0);
  float head = max(dot(n, v), 0.0);
  vec3 h = normalize(l + v);
  float spec = pow(max(dot(n, h), 0.0), uShininess) * uSpecular;
  float rim = pow(1.0 - head, 3.0) * 0.18;
  vec3 ambient = mix(vec3(0.16, 0.15, 0.17), vec3(0.30, 0.31, 0.34), 0.5 + 0.5 * n.z);
  vec3 c = vColor * (ambient + 0.62 * key + 0.30 * head) + vec3(spec + rim);
  outColor = vec4(pow(c, vec3(0.92)), uAlpha);
}`;

/** A full-screen triangle: a dark slate vignette behind the scene. */
const BACKGROUND_VS = `#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}`;

const BACKGROUND_FS = `#version 300 es
precision mediump float;
uniform vec2 uSize;
out vec4 outColor;
void main() {
  vec2 uv = gl_FragCoord.xy / uSize - vec2(0.42, 0.62);
  uv.x *= uSize.x / uSize.y;
  float r = length(uv);
  vec3 inner = vec3(0.115, 0.150, 0.205);
  vec3 outer = vec3(0.040, 0.055, 0.080);
  outColor = vec4(mix(inner, outer, smoothstep(0.0, 0.95, r)), 1.0);
}`;

const LINE_VS = `#version 300 es
layout(location = 0) in vec3 aPos;
uniform mat4 uViewProj;
void main() { gl_Position = uViewProj * vec4(aPos, 1.0); }`;

const LINE_FS = `#version 300 es
precision mediump float;
uniform vec4 uColor;
out vec4 outColor;
void main() { outColor = uColor; }`;

function compile(gl, type, source) {
  const s = gl.createShader(type);
  gl.shaderSource(s, source);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`shader: ${gl.getShaderInfoLog(s)}`);
  return s;
}

function program(gl, vs, fs) {
  const p = gl.createProgram();
  gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, vs));
  gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(`program: ${gl.getProgramInfoLog(p)}`);
  const uniforms = {};
  const n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < n; i++) {
    const name = gl.getActiveUniform(p, i).name;
    uniforms[name] = gl.getUniformLocation(p, name);
  }
  return { p, u: uniforms };
}

/** A mesh whose vertices (position, normal, colour) and indices are replaced at will. */
class Mesh {
  constructor(gl, withNormals = true) {
    this.gl = gl;
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    this.buffers = (withNormals ? [0, 1, 2] : [0]).map((loc) => {
      const b = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, b);
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
      return b;
    });
    this.index = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.index);
    gl.bindVertexArray(null);
    this.count = 0;
  }

  /** `attributes`: Float32Arrays in location order (null keeps the buffer as it is). */
  setVertices(attributes) {
    const gl = this.gl;
    attributes.forEach((data, i) => {
      if (!data) return;
      gl.bindBuffer(gl.ARRAY_BUFFER, this.buffers[i]);
      gl.bufferData(gl.ARRAY_BUFFER, data, gl.DYNAMIC_DRAW);
    });
  }

  setIndices(indices) {
    const gl = this.gl;
    gl.bindVertexArray(this.vao);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.index);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.DYNAMIC_DRAW);
    gl.bindVertexArray(null);
    this.count = indices.length;
  }

  draw(mode) {
    if (this.count === 0) return;
    const gl = this.gl;
    gl.bindVertexArray(this.vao);
    gl.drawElements(mode, this.count, gl.UNSIGNED_INT, 0);
    gl.bindVertexArray(null);
  }
}

/** Triangles gathered on the CPU (the instrument, trocar, arrow: a few thousand vertices). */
class Geometry {
  constructor() {
    this.pos = [];
    this.nrm = [];
    this.col = [];
    this.idx = [];
  }

  get vertexCount() {
    return this.pos.length / 3;
  }

  /**
   * Revolves `profile` ({h, r, nh, nr}: axial offset and radius, the normal's axial and
   * radial parts) about the line from `base` along unit `axis`; `side` is the angle-zero
   * direction. `color(ring, segment)` gives each vertex's colour.
   */
  lathe(base, axis, side, profile, color, segments = 28) {
    const e1 = side;
    const e2 = cross(axis, e1);
    const first = this.vertexCount;
    profile.forEach((ring, i) => {
      for (let j = 0; j <= segments; j++) {
        const t = (2 * Math.PI * j) / segments;
        const radial = add(scale(e1, Math.cos(t)), scale(e2, Math.sin(t)));
        const p = add(add(base, scale(axis, ring.h)), scale(radial, ring.r));
        const n = add(scale(axis, ring.nh), scale(radial, ring.nr));
        this.pos.push(...p);
        this.nrm.push(...n);
        this.col.push(...color(i, j % segments, segments));
      }
    });
    const row = segments + 1;
    for (let i = 0; i + 1 < profile.length; i++) {
      for (let j = 0; j < segments; j++) {
        const a = first + i * row + j;
        const b = a + row;
        this.idx.push(a, b, a + 1, a + 1, b, b + 1);
      }
    }
  }

  upload(mesh) {
    mesh.setVertices([new Float32Array(this.pos), new Float32Array(this.nrm), new Float32Array(this.col)]);
    mesh.setIndices(new Uint32Array(this.idx));
  }
}

const uniform = (c) => () => c;
/** The axes gizmo's size and place (CSS px from the canvas's bottom-right corner). */
const GIZMO_PX = 86;
const GIZMO_RIGHT_PX = 14;
const GIZMO_BOTTOM_PX = 14;

/** A capsule's profile: tip hemisphere bulging to h = -r, cylinder to h = length, end hemisphere. */
function capsuleProfile(r, length, rings = 8) {
  const out = [];
  for (let i = 0; i <= rings; i++) {
    const f = -Math.PI / 2 + (Math.PI / 2) * (i / rings);
    out.push({ h: r * Math.sin(f), r: r * Math.cos(f), nh: Math.sin(f), nr: Math.cos(f) });
  }
  for (let i = 0; i <= rings; i++) {
    const f = (Math.PI / 2) * (i / rings);
    out.push({ h: length + r * Math.sin(f), r: r * Math.cos(f), nh: Math.sin(f), nr: Math.cos(f) });
  }
  return out;
}

function cylinderProfile(r, length) {
  return [
    { h: 0, r: 0, nh: -1, nr: 0 }, { h: 0, r, nh: -1, nr: 0 },
    { h: 0, r, nh: 0, nr: 1 }, { h: length, r, nh: 0, nr: 1 },
    { h: length, r, nh: 1, nr: 0 }, { h: length, r: 0, nh: 1, nr: 0 },
  ];
}

function arrowProfile(length, shaftR, headR, headLength) {
  const shaft = Math.max(0, length - headLength);
  const s = Math.hypot(headR, headLength);
  return [
    { h: 0, r: 0, nh: -1, nr: 0 }, { h: 0, r: shaftR, nh: -1, nr: 0 },
    { h: 0, r: shaftR, nh: 0, nr: 1 }, { h: shaft, r: shaftR, nh: 0, nr: 1 },
    { h: shaft, r: shaftR, nh: -1, nr: 0 }, { h: shaft, r: headR, nh: -1, nr: 0 },
    { h: shaft, r: headR, nh: headR / s, nr: headLength / s }, { h: length, r: 0, nh: headR / s, nr: headLength / s },
  ];
}

/** Colours of the bodies by name (tissue tones), then a palette. */
export function bodyColor(name, index) {
  const n = (name || '').toLowerCase();
  if (n.includes('ovary')) return [0.93, 0.80, 0.62];
  if (n.includes('oviduct') || n.includes('tube')) return [0.95, 0.55, 0.52];
  if (n.includes('fundus')) return [0.80, 0.38, 0.42];
  if (n.includes('uter') || n.includes('body')) return [0.76, 0.33, 0.38];
  if (n.includes('liver')) return [0.55, 0.22, 0.20];
  const palette = [[0.78, 0.36, 0.40], [0.93, 0.60, 0.55], [0.90, 0.78, 0.60], [0.70, 0.45, 0.55], [0.85, 0.50, 0.35]];
  return palette[index % palette.length];
}

/** A blue-to-yellow-to-red map of t in [0, 1]. */
export function heatColor(t) {
  const x = Math.min(1, Math.max(0, t));
  const stops = [[0.18, 0.24, 0.52], [0.16, 0.55, 0.75], [0.45, 0.80, 0.55], [0.98, 0.85, 0.30], [0.92, 0.30, 0.20]];
  const f = x * (stops.length - 1);
  const i = Math.min(stops.length - 2, Math.floor(f));
  const u = f - i;
  return [0, 1, 2].map((k) => stops[i][k] * (1 - u) + stops[i + 1][k] * u);
}

/** Area-weighted vertex normals of `triangles` over `positions` (3n floats) into `out`. */
export function vertexNormals(positions, triangles, out) {
  out.fill(0);
  for (let t = 0; t < triangles.length; t += 3) {
    const a = 3 * triangles[t];
    const b = 3 * triangles[t + 1];
    const c = 3 * triangles[t + 2];
    const ux = positions[b] - positions[a];
    const uy = positions[b + 1] - positions[a + 1];
    const uz = positions[b + 2] - positions[a + 2];
    const vx = positions[c] - positions[a];
    const vy = positions[c + 1] - positions[a + 1];
    const vz = positions[c + 2] - positions[a + 2];
    const nx = uy * vz - uz * vy;
    const ny = uz * vx - ux * vz;
    const nz = ux * vy - uy * vx;
    for (const k of [a, b, c]) {
      out[k] += nx;
      out[k + 1] += ny;
      out[k + 2] += nz;
    }
  }
  for (let k = 0; k < out.length; k += 3) {
    const l = Math.hypot(out[k], out[k + 1], out[k + 2]) || 1;
    out[k] /= l;
    out[k + 1] /= l;
    out[k + 2] /= l;
  }
}

/** The name of the WebGL2 renderer of a context (the real GPU's where the browser tells it). */
function rendererName(gl) {
  const dbg = gl.getExtension('WEBGL_debug_renderer_info');
  return String(gl.getParameter(dbg ? dbg.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
}

/** Whether WebGL runs on the CPU (no GPU): then no multisampling, it costs too much. */
function softwareRenderer() {
  const probe = document.createElement('canvas').getContext('webgl2');
  if (!probe) return false;
  const software = /swiftshader|llvmpipe|softpipe|software/i.test(rendererName(probe));
  probe.getExtension('WEBGL_lose_context')?.loseContext();
  return software;
}

export class Renderer {
  constructor(canvas) {
    this.software = softwareRenderer();
    const gl = canvas.getContext('webgl2', { antialias: !this.software, alpha: false, preserveDrawingBuffer: false });
    if (!gl) throw new Error('this browser gives no WebGL2 context');
    this.gl = gl;
    this.canvas = canvas;
    this.rendererName = rendererName(gl);
    /** Backing pixels per CSS pixel, relative to the device's (lowered when frames cost too much). */
    this.scale = 1;
    this.background = program(gl, BACKGROUND_VS, BACKGROUND_FS);
    this.solid = program(gl, SOLID_VS, SOLID_FS);
    this.line = program(gl, LINE_VS, LINE_FS);
    this.surface = new Mesh(gl);
    this.opaque = new Mesh(gl);
    this.clear = new Mesh(gl);
    this.overlay = new Mesh(gl);
    this.grid = new Mesh(gl, false);
    this.gizmo = new Mesh(gl);
    const g = new Geometry();
    const axes = [[[1, 0, 0], [0.90, 0.33, 0.30]], [[0, 1, 0], [0.40, 0.80, 0.38]], [[0, 0, 1], [0.35, 0.55, 0.95]]];
    for (const [axis, color] of axes) g.lathe([0, 0, 0], axis, perpendicular(axis), arrowProfile(1, 0.05, 0.13, 0.32), uniform(color), 12);
    g.upload(this.gizmo);
    this.normals = null;
    this.colors = null;
  }

  /** The surface's triangles and per-vertex body colours (once per topology). */
  setTopology(triangles, bodyColors) {
    this.surface.setIndices(triangles);
    this.triangles = triangles;
    this.normals = new Float32Array(bodyColors.length);
    this.colors = bodyColors;
    this.surface.setVertices([null, null, bodyColors]);
  }

  /** New surface positions (3n f32): normals recomputed; `colors` replaces the colours if given. */
  setPositions(positions, colors) {
    vertexNormals(positions, this.triangles, this.normals);
    this.surface.setVertices([positions, this.normals, colors || null]);
  }

  /** A floor grid of `step` (m) under the box lo..hi. */
  setGrid(lo, hi, step) {
    const z = lo[2] - 0.01;
    const pad = 4 * step;
    const x0 = Math.floor((lo[0] - pad) / step) * step;
    const x1 = Math.ceil((hi[0] + pad) / step) * step;
    const y0 = Math.floor((lo[1] - pad) / step) * step;
    const y1 = Math.ceil((hi[1] + pad) / step) * step;
    const pos = [];
    for (let x = x0; x <= x1 + 1e-9; x += step) pos.push(x, y0, z, x, y1, z);
    for (let y = y0; y <= y1 + 1e-9; y += step) pos.push(x0, y, z, x1, y, z);
    this.grid.setVertices([new Float32Array(pos)]);
    this.grid.setIndices(new Uint32Array(pos.length / 3).map((_, i) => i));
  }

  /**
   * Draws a frame. `scene`: { instruments: [{ tip, tail, axis, side, radius, trocar, color,
   * ghost: {tip, tail} | null, force: [x,y,z] | null, forceScale (m per N) }] }.
   */
  draw(camera, scene) {
    const gl = this.gl;
    const ratio = (window.devicePixelRatio || 1) * this.scale;
    this.ratio = ratio;
    const w = Math.max(1, Math.round(this.canvas.clientWidth * ratio));
    const h = Math.max(1, Math.round(this.canvas.clientHeight * ratio));
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w;
      this.canvas.height = h;
    }
    gl.viewport(0, 0, w, h);
    gl.clear(gl.DEPTH_BUFFER_BIT);
    gl.disable(gl.DEPTH_TEST);
    gl.disable(gl.BLEND);
    gl.useProgram(this.background.p);
    gl.uniform2f(this.background.u.uSize, w, h);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    const m = camera.matrices(w / h);
    this.lastViewProj = m.viewProj;

    gl.enable(gl.DEPTH_TEST);
    gl.enable(gl.BLEND);
    gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);

    gl.useProgram(this.line.p);
    gl.uniformMatrix4fv(this.line.u.uViewProj, false, m.viewProj);
    gl.uniform4f(this.line.u.uColor, 0.55, 0.62, 0.72, 0.09);
    gl.depthMask(false);
    this.grid.draw(gl.LINES);
    gl.depthMask(true);

    const opaque = new Geometry();
    const clear = new Geometry();
    const overlay = new Geometry();
    for (const ins of scene.instruments) this.instrumentGeometry(ins, opaque, clear, overlay);
    opaque.upload(this.opaque);
    clear.upload(this.clear);
    overlay.upload(this.overlay);

    const s = this.solid;
    gl.useProgram(s.p);
    gl.uniformMatrix4fv(s.u.uViewProj, false, m.viewProj);
    gl.uniform3fv(s.u.uEye, m.eye);
    const { right, up, forward } = camera.basis();
    gl.uniform3fv(s.u.uKeyDir, add(add(scale(up, 0.9), scale(right, -0.35)), scale(forward, -0.5)));
    gl.uniform1f(s.u.uAlpha, 1);
    gl.uniform1f(s.u.uShininess, 40);
    gl.uniform1f(s.u.uSpecular, 0.22);
    this.surface.draw(gl.TRIANGLES);
    gl.uniform1f(s.u.uShininess, 90);
    gl.uniform1f(s.u.uSpecular, 0.55);
    this.opaque.draw(gl.TRIANGLES);
    gl.depthMask(false);
    gl.uniform1f(s.u.uAlpha, 0.35);
    this.clear.draw(gl.TRIANGLES);
    gl.disable(gl.DEPTH_TEST);
    gl.uniform1f(s.u.uAlpha, 0.95);
    gl.uniform1f(s.u.uSpecular, 0.2);
    this.overlay.draw(gl.TRIANGLES);
    gl.depthMask(true);
    this.drawGizmo(camera, w, h);
    this.frames = (this.frames || 0) + 1;
  }

  /** The scene's axes (x red, y green, z blue) turned as the view, in a corner. */
  drawGizmo(camera, w, h) {
    const gl = this.gl;
    const dpr = this.ratio;
    const size = Math.round(GIZMO_PX * dpr);
    const { forward } = camera.basis();
    const eye = scale(forward, -4);
    const viewProj = mat4Mul(perspective(0.5, 1, 0.5, 10), lookAt(eye, [0, 0, 0], [0, 0, 1]));
    this.gizmoViewProj = viewProj;
    gl.viewport(w - size - Math.round(GIZMO_RIGHT_PX * dpr), Math.round(GIZMO_BOTTOM_PX * dpr), size, size);
    gl.enable(gl.DEPTH_TEST);
    gl.clear(gl.DEPTH_BUFFER_BIT);
    const s = this.solid;
    gl.uniformMatrix4fv(s.u.uViewProj, false, viewProj);
    gl.uniform3fv(s.u.uEye, eye);
    gl.uniform1f(s.u.uAlpha, 1);
    this.gizmo.draw(gl.TRIANGLES);
    gl.viewport(0, 0, w, h);
  }

  /** CSS-pixel positions, in the canvas, of the gizmo's axis ends (x, y, z). */
  gizmoLabels() {
    if (!this.gizmoViewProj) return [];
    const m = this.gizmoViewProj;
    const cw = this.canvas.clientWidth;
    const ch = this.canvas.clientHeight;
    return [[1.35, 0, 0], [0, 1.35, 0], [0, 0, 1.35]].map((p) => {
      const x = m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12];
      const y = m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13];
      const ww = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
      return [cw - GIZMO_RIGHT_PX - GIZMO_PX + (0.5 + (0.5 * x) / ww) * GIZMO_PX,
        ch - GIZMO_BOTTOM_PX - (0.5 + (0.5 * y) / ww) * GIZMO_PX];
    });
  }

  instrumentGeometry(ins, opaque, clear, overlay) {
    const r = ins.radius;
    const axisOut = normalize(sub(ins.tail, ins.tip));
    const length = Math.hypot(...sub(ins.tail, ins.tip));
    const side = ins.side;
    // The modelled capsule (the part that touches tissue), a stripe showing the roll.
    const steel = ins.color;
    const stripe = [0.95, 0.62, 0.18];
    opaque.lathe(ins.tip, axisOut, side, capsuleProfile(r, length), (_, j) => (j < 2 ? stripe : steel));
    // The shaft beyond it, up through the trocar and 6 cm out of the body.
    const shaftEnd = ins.trocar
      ? Math.max(length, Math.hypot(...sub(ins.trocar, ins.tip)) + 0.06)
      : length + 0.1;
    opaque.lathe(add(ins.tip, scale(axisOut, length)), axisOut, side,
      cylinderProfile(r * 0.92, shaftEnd - length), uniform([0.30, 0.32, 0.36]));
    if (ins.trocar) {
      // The trocar's sleeve, pivoting with the shaft, and its pivot point.
      const sleeve = 0.03;
      clear.lathe(add(ins.trocar, scale(axisOut, -sleeve / 2)), axisOut, side,
        cylinderProfile(r * 2.4, sleeve), uniform([0.35, 0.75, 0.85]));
      opaque.lathe(add(ins.trocar, scale(axisOut, -r * 0.6)), axisOut, side,
        capsuleProfile(r * 0.6, 0), uniform([0.35, 0.85, 0.95]), 16);
    }
    if (ins.ghost) {
      const gOut = normalize(sub(ins.ghost.tail, ins.ghost.tip));
      clear.lathe(ins.ghost.tip, gOut, perpendicular(gOut),
        capsuleProfile(r * 1.02, Math.hypot(...sub(ins.ghost.tail, ins.ghost.tip))), uniform([0.55, 0.85, 1.0]));
    }
    if (ins.force) {
      const f = Math.hypot(...ins.force);
      const len = Math.min(f * ins.forceScale, 0.08);
      if (len > 1e-4) {
        const dir = scale(ins.force, 1 / f);
        const head = Math.min(len * 0.4, 0.007);
        overlay.lathe(ins.tip, dir, perpendicular(dir), arrowProfile(len, 0.0007, 0.0019, head), uniform([1.0, 0.86, 0.25]), 16);
      }
    }
  }

  /** CSS-pixel position of the point p in the last frame drawn (null if behind the eye). */
  project(p) {
    if (!this.lastViewProj) return null;
    const m = this.lastViewProj;
    const x = m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12];
    const y = m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13];
    const w = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
    if (w <= 0) return null;
    return [(0.5 + (0.5 * x) / w) * this.canvas.clientWidth, (0.5 - (0.5 * y) / w) * this.canvas.clientHeight];
  }
}
