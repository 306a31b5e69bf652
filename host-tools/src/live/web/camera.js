// An orbit camera about a target point, z up (the scenes' vertical).

import { add, sub, scale, dot, cross, normalize, perspective, lookAt, mat4Mul } from './math.js';

export class OrbitCamera {
  constructor() {
    this.fovy = (38 * Math.PI) / 180;
    this.yaw = (-125 * Math.PI) / 180;
    this.pitch = (28 * Math.PI) / 180;
    this.distance = 0.4;
    this.target = [0, 0, 0];
  }

  eye() {
    const c = Math.cos(this.pitch);
    return add(this.target, scale([c * Math.cos(this.yaw), c * Math.sin(this.yaw), Math.sin(this.pitch)], this.distance));
  }

  /** The view's forward, right and up unit vectors. */
  basis() {
    const forward = normalize(sub(this.target, this.eye()));
    const right = normalize(cross(forward, [0, 0, 1]));
    return { forward, right, up: cross(right, forward) };
  }

  matrices(aspect) {
    const eye = this.eye();
    const view = lookAt(eye, this.target, [0, 0, 1]);
    const proj = perspective(this.fovy, aspect, this.distance * 0.02, this.distance * 20);
    return { eye, view, proj, viewProj: mat4Mul(proj, view) };
  }

  /** Frames the points (m): the target at the middle of their box, all in view. */
  frame(points, yawDeg, pitchDeg) {
    if (points.length === 0) return;
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (const p of points) {
      for (let i = 0; i < 3; i++) {
        lo[i] = Math.min(lo[i], p[i]);
        hi[i] = Math.max(hi[i], p[i]);
      }
    }
    this.target = scale(add(lo, hi), 0.5);
    const radius = 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    this.distance = Math.max(0.01, (radius / Math.sin(this.fovy / 2)) * 0.85);
    if (yawDeg !== undefined) this.yaw = (yawDeg * Math.PI) / 180;
    if (pitchDeg !== undefined) this.pitch = (pitchDeg * Math.PI) / 180;
  }

  orbit(dxPx, dyPx) {
    this.yaw -= dxPx * 0.006;
    this.pitch = Math.min(1.5, Math.max(-1.5, this.pitch + dyPx * 0.006));
  }

  zoom(factor) {
    this.distance = Math.min(20, Math.max(0.005, this.distance * factor));
  }

  pan(dxPx, dyPx, heightPx) {
    const { right, up } = this.basis();
    const k = this.worldPerPixel(this.target, heightPx);
    this.target = add(this.target, add(scale(right, -dxPx * k), scale(up, dyPx * k)));
  }

  /** Metres per screen pixel at the depth of `point`, for a viewport `heightPx` tall. */
  worldPerPixel(point, heightPx) {
    const { forward } = this.basis();
    const depth = Math.max(1e-4, dot(sub(point, this.eye()), forward));
    return (2 * depth * Math.tan(this.fovy / 2)) / Math.max(1, heightPx);
  }

  /** The world vector (m) of a screen drag (dx right, dy down, px) at the depth of `point`. */
  dragVector(point, dxPx, dyPx, heightPx) {
    const { right, up } = this.basis();
    const k = this.worldPerPixel(point, heightPx);
    return add(scale(right, dxPx * k), scale(up, -dyPx * k));
  }
}
