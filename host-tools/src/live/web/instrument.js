// A laparoscopic instrument driven from the page: a rigid motion (q, p) of the tool from
// where the scene places it, x' = R(q) x + p (the session protocol's pose). With a trocar
// every motion is a rotation about the trocar point or a slide along the instrument's
// axis, so an axis through the trocar at the scene's placement stays through it. Without
// one the instrument translates freely.

import {
  add, sub, scale, dot, normalize, distance, distanceToLine, perpendicular,
  quatIdentity, quatMul, quatNormalize, quatAxisAngle, quatFromTo, quatRotate,
} from './math.js';

/** How close (m) an applied pose's axis must pass to the trocar for the page to adopt it. */
const ADOPT_TOLERANCE_M = 5e-4;

export class Instrument {
  /** `tool`: the hello message's tool {name, a_m, b_m, radius_m, trocar_m}. */
  constructor(tool) {
    this.name = tool.name;
    this.radius = tool.radius_m;
    this.trocar = Array.isArray(tool.trocar_m) ? tool.trocar_m : null;
    const a = tool.a_m;
    const b = tool.b_m;
    // The tip is the end away from the trocar (the capsule's `a` without one).
    const tipIsA = !this.trocar || distance(a, this.trocar) >= distance(b, this.trocar);
    this.tip0 = tipIsA ? a : b;
    this.tail0 = tipIsA ? b : a;
    this.length = distance(a, b);
    this.axis0 = this.length > 0 ? normalize(sub(this.tip0, this.tail0)) : [0, 0, -1];
    this.side0 = perpendicular(this.axis0);
    if (this.trocar) {
      const depth0 = dot(sub(this.tip0, this.trocar), this.axis0);
      this.trocarOnAxis = distanceToLine(this.trocar, this.tip0, this.axis0) < 1e-6 + 1e-3 * this.length;
      // The capsule stays inside the body wall; it may go 8 cm deeper than placed.
      this.minDepth = Math.min(depth0, this.length + this.radius);
      this.maxDepth = depth0 + 0.08;
    }
    this.reset();
  }

  reset() {
    this.q = quatIdentity();
    this.p = [0, 0, 0];
    this.version = (this.version || 0) + 1;
  }

  /** The pose message body for this instrument. */
  pose() {
    return { orientation: this.q.slice(), position_m: this.p.slice() };
  }

  /** A point of the tool at the scene's placement, moved by the current pose. */
  apply(x) {
    return add(quatRotate(this.q, x), this.p);
  }

  tip() { return this.apply(this.tip0); }
  tail() { return this.apply(this.tail0); }
  /** Unit axis, from the tail toward the tip (into the body). */
  axis() { return quatRotate(this.q, this.axis0); }
  /** A unit vector across the axis that turns with the roll (the jaw side). */
  side() { return quatRotate(this.q, this.side0); }
  /** Depth of the tip past the trocar along the axis (m), or null without a trocar. */
  depth() { return this.trocar ? dot(sub(this.tip(), this.trocar), this.axis()) : null; }

  set(q, p) {
    this.q = quatNormalize(q);
    this.p = p.slice();
    this.version++;
  }

  /**
   * Takes `pose` (an applied pose from the server) as the page's own when it keeps the
   * trocar on the axis (a scripted path's translation would not); returns whether it did.
   */
  adopt(pose) {
    const q = quatNormalize(pose.orientation);
    if (this.trocar && this.trocarOnAxis) {
      const tip = add(quatRotate(q, this.tip0), pose.position_m);
      if (distanceToLine(this.trocar, tip, quatRotate(q, this.axis0)) > ADOPT_TOLERANCE_M) return false;
    }
    this.set(q, pose.position_m);
    return true;
  }

  /** Rotation `r` about the point `c`: x'' = r (x' - c) + c. */
  rotateAbout(c, r) {
    this.set(quatMul(r, this.q), add(quatRotate(r, sub(this.p, c)), c));
  }

  translate(v) {
    this.set(this.q, add(this.p, v));
  }

  /**
   * Moves the tip toward `target` (m): with a trocar, pivots about it so the tip's
   * direction from the trocar points at `target` (the tip stays on its sphere); without
   * one, translates by the difference.
   */
  pivotToward(target) {
    const tip = this.tip();
    if (!this.trocar) {
      this.translate(sub(target, tip));
      return;
    }
    const from = normalize(sub(tip, this.trocar));
    const to = normalize(sub(target, this.trocar));
    if (dot(from, to) > 1 - 1e-14) return;
    this.rotateAbout(this.trocar, quatFromTo(from, to));
  }

  /** Yaw about the vertical and pitch about the horizontal across the axis (rad). */
  pivotBy(yaw, pitch) {
    const c = this.trocar || this.tail();
    const across = normalize([this.axis()[1], -this.axis()[0], 0]);
    let r = quatAxisAngle([0, 0, 1], yaw);
    if (Math.hypot(...across) > 0) r = quatMul(quatAxisAngle(across, pitch), r);
    this.rotateAbout(c, r);
  }

  /** Slides the instrument `ds` (m) along its axis, deeper for ds > 0 (held within its limits). */
  insert(ds) {
    let step = ds;
    if (this.trocar) {
      const d = this.depth();
      step = Math.min(Math.max(d + ds, this.minDepth), this.maxDepth) - d;
    }
    if (step !== 0) this.translate(scale(this.axis(), step));
  }

  /** Turns the instrument `angle` (rad) about its own axis. */
  roll(angle) {
    const c = this.trocar && this.trocarOnAxis ? this.trocar : this.tip();
    this.rotateAbout(c, quatAxisAngle(this.axis(), angle));
  }
}
