// The panels over the view: connection, model, tool force (number, bar, components,
// history), real-time factor and lag, who drives which tool, and the session log.

const $ = (id) => document.getElementById(id);
const FULL_SCALES_N = [0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500];
const HISTORY_S = 5;
const LOG_KEEP = 200;
const LOG_COALESCE = 6;

const fmt = (v, digits) => (Number.isFinite(v) ? v.toFixed(digits) : '—');

/** A force in newtons with about three significant digits (the scene's forces run from mN up). */
export function formatNewtons(f) {
  const a = Math.abs(f);
  return fmt(f, a >= 1 ? 3 : a >= 0.1 ? 3 : a >= 0.01 ? 4 : 5);
}

export class Hud {
  constructor() {
    this.history = []; // [t_ms, |F| N]
    this.logEntries = [];
    this.t0 = performance.now();
  }

  setConnection(state, detail) {
    const el = $('conn');
    el.className = `pill ${state}`;
    el.textContent = state === 'open' ? 'connected' : state;
    el.title = detail || '';
  }

  setHello(hello) {
    $('scene-name').textContent = hello.scene ?? '—';
    this.setModel(hello.model);
    const lag = Number.isFinite(hello.max_lag_s) ? ` past ${(hello.max_lag_s * 1000).toFixed(0)} ms of lag` : '';
    $('policy').textContent = hello.policy ? `behind real time: no step skipped; the clock slips${lag}` : '';
    $('timing-card').title = hello.policy ? `When the simulation falls behind: ${hello.policy}` : '';
    $('force-rate').textContent = hello.force_hz ? `${hello.force_hz} Hz` : '—';
  }

  setModel(model) {
    if (model !== undefined && model !== null) {
      $('model-name').textContent = model;
      $('model-name').title = model;
    }
  }

  /** Fills the tool selector; `onSelect(index)` when the user picks one. */
  setTools(names, selected, onSelect) {
    const sel = $('tool-select');
    sel.replaceChildren(...names.map((n, i) => new Option(n, String(i), i === selected, i === selected)));
    sel.disabled = names.length < 2;
    sel.onchange = () => onSelect(Number(sel.value));
  }

  /** `drivers`: { tool: client | null }; `me`: this page's client id. */
  setDrivers(names, drivers, me) {
    const items = names.map((n) => {
      const li = document.createElement('li');
      const d = drivers[n];
      const who = document.createElement('span');
      if (d === undefined || d === null) {
        who.className = 'free';
        who.textContent = 'free';
      } else if (d === me) {
        who.className = 'you';
        who.textContent = `you (client ${d})`;
      } else {
        who.className = 'other';
        who.textContent = `client ${d}`;
      }
      const name = document.createElement('span');
      name.textContent = n;
      li.append(name, who);
      return li;
    });
    if (items.length === 0) {
      const li = document.createElement('li');
      li.textContent = 'the scene has no tools';
      items.push(li);
    }
    $('tool-list').replaceChildren(...items);
  }

  /** The selected tool's force (N vector, or null before any); returns the bar's magnitude. */
  setForce(force, nowMs) {
    const f = force ? Math.hypot(force[0], force[1], force[2]) : 0;
    this.history.push([nowMs, f]);
    while (this.history.length && this.history[0][0] < nowMs - HISTORY_S * 1000) this.history.shift();
    const recentMax = this.history.reduce((m, h) => Math.max(m, h[1]), 0);
    this.peak = Math.max(this.peak || 0, f);
    const full = FULL_SCALES_N.find((s) => s >= recentMax * 1.1) ?? FULL_SCALES_N[FULL_SCALES_N.length - 1];
    this.fullScale = full;
    $('force-value').textContent = formatNewtons(f);
    $('fx').textContent = force ? formatNewtons(force[0]) : '—';
    $('fy').textContent = force ? formatNewtons(force[1]) : '—';
    $('fz').textContent = force ? formatNewtons(force[2]) : '—';
    $('force-bar-fill').style.width = `${Math.min(100, (100 * f) / full)}%`;
    $('force-bar-peak').style.left = `${Math.min(99.5, (100 * recentMax) / full)}%`;
    $('force-bar').setAttribute('aria-valuenow', f.toFixed(4));
    $('force-bar').setAttribute('aria-valuemax', String(full));
    $('force-mid').textContent = String(full / 2);
    $('force-full').textContent = `${full} N`;
    $('force-peak').textContent = formatNewtons(this.peak);
    this.drawHistory(nowMs, full);
    return f;
  }

  drawHistory(nowMs, full) {
    const c = $('force-history');
    const dpr = window.devicePixelRatio || 1;
    const w = Math.round(c.clientWidth * dpr);
    const h = Math.round(c.clientHeight * dpr);
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    // A CPU canvas: an accelerated one is read back from the GPU every frame it changes.
    const g = c.getContext('2d', { willReadFrequently: true });
    g.clearRect(0, 0, w, h);
    g.strokeStyle = 'rgba(140,160,185,0.15)';
    g.lineWidth = 1;
    for (const k of [0.25, 0.5, 0.75]) {
      g.beginPath();
      g.moveTo(0, Math.round(h * k) + 0.5);
      g.lineTo(w, Math.round(h * k) + 0.5);
      g.stroke();
    }
    if (this.history.length < 2) return;
    const x = (t) => w * (1 - (nowMs - t) / (HISTORY_S * 1000));
    const y = (f) => h - 2 - (h - 4) * Math.min(1, f / full);
    g.beginPath();
    g.moveTo(x(this.history[0][0]), h);
    for (const [t, f] of this.history) g.lineTo(x(t), y(f));
    g.lineTo(x(this.history[this.history.length - 1][0]), h);
    g.closePath();
    g.fillStyle = 'rgba(255,213,74,0.16)';
    g.fill();
    g.beginPath();
    this.history.forEach(([t, f], i) => (i ? g.lineTo(x(t), y(f)) : g.moveTo(x(t), y(f))));
    g.strokeStyle = '#ffd54a';
    g.lineWidth = 1.5 * dpr;
    g.stroke();
  }

  setStatus(s, frameRateHz, graphicsHz) {
    const rtf = s.real_time_factor;
    const el = $('rtf-value');
    el.textContent = fmt(rtf, 2);
    el.parentElement.className = `rtf ${rtf >= 0.98 ? 'ok' : rtf >= 0.8 ? 'warn' : 'bad'}`;
    $('lag').textContent = Number.isFinite(s.lag_s) ? `${(s.lag_s * 1000).toFixed(1)} ms` : '—';
    $('slips').textContent = Number.isFinite(s.slips)
      ? `${s.slips}${Number.isFinite(s.slipped_s) ? ` · ${s.slipped_s.toFixed(2)} s` : ''}` : '—';
    $('sim-time').textContent = Number.isFinite(s.time_s) ? `${s.time_s.toFixed(3)} s` : '—';
    $('step-dt').textContent = Number.isFinite(s.step)
      ? `${s.step} · ${Number.isFinite(s.dt_s) ? `${(s.dt_s * 1e6).toFixed(1)} µs` : '—'}` : '—';
    $('clients').textContent = s.clients ?? '—';
    $('dropped').textContent = s.surface_frames_dropped ?? '—';
    const l = s.latency_ms;
    $('latency').textContent = l && l.samples > 0 ? `${l.p50.toFixed(2)} / ${l.p99.toFixed(2)} ms` : '—';
    this.setFrameRate(frameRateHz, graphicsHz);
    this.setModel(s.model);
  }

  setFrameRate(frameRateHz, graphicsHz) {
    $('frame-rate').textContent = `${frameRateHz.toFixed(1)} Hz${graphicsHz ? ` / ${graphicsHz}` : ''}`;
  }

  setLegend(maxM) {
    $('legend').hidden = maxM === null;
    if (maxM !== null) $('legend-max').textContent = `0 … ${(maxM * 1000).toFixed(2)} mm`;
  }

  /** The force label beside the tool tip, at CSS pixel `at` (or hidden with null). */
  setTipLabel(at, text) {
    const el = $('tip-label');
    el.hidden = !at;
    if (at) {
      el.style.left = `${at[0]}px`;
      el.style.top = `${at[1]}px`;
      el.textContent = text;
    }
  }

  /** Places the axes gizmo's x, y, z labels at CSS pixels `points`. */
  setGizmoLabels(points) {
    const spans = $('gizmo-labels').children;
    points.forEach((p, i) => {
      spans[i].style.left = `${p[0]}px`;
      spans[i].style.top = `${p[1]}px`;
    });
  }

  /** A scale bar of a round length near 100 px, at `metresPerPixel` (at the view's target). */
  setScaleBar(metresPerPixel) {
    const lengths = [0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1];
    const m = lengths.find((l) => l / metresPerPixel >= 70) ?? lengths[lengths.length - 1];
    $('scale-bar').firstElementChild.style.width = `${Math.round(m / metresPerPixel)}px`;
    $('scale-text').textContent = m < 1 ? `${Math.round(m * 1000)} mm` : `${m} m`;
  }

  /** A message across the view (null: none). */
  setBanner(text) {
    const el = $('banner');
    el.hidden = !text;
    if (text) el.textContent = text;
  }

  /** Adds a line to the session log (a repeat of the last line counts on it); returns the entry. */
  log(kind, message) {
    const t_ms = performance.now();
    const list = $('log-list');
    // A message among the last few lines counts on its line, which moves to the end.
    const k = this.logEntries.slice(-LOG_COALESCE).findIndex((e) => e.kind === kind && e.message === message);
    if (k >= 0) {
      const at = this.logEntries.length - Math.min(LOG_COALESCE, this.logEntries.length) + k;
      const entry = this.logEntries.splice(at, 1)[0];
      this.logEntries.push(entry);
      entry.repeats = (entry.repeats || 1) + 1;
      entry.t_ms = t_ms;
      const li = list.children[at];
      li.querySelector('.t').textContent = this.stamp(t_ms);
      li.querySelector('.n').textContent = ` ×${entry.repeats}`;
      list.append(li);
      list.scrollTop = list.scrollHeight;
      return entry;
    }
    const entry = { t_ms, kind, message };
    this.logEntries.push(entry);
    if (this.logEntries.length > LOG_KEEP) this.logEntries.shift();
    const li = document.createElement('li');
    li.className = kind;
    const t = document.createElement('span');
    t.className = 't';
    t.textContent = this.stamp(t_ms);
    const n = document.createElement('span');
    n.className = 'n';
    li.append(t, document.createTextNode(message), n);
    li.title = message;
    list.append(li);
    while (list.children.length > LOG_KEEP) list.firstChild.remove();
    list.scrollTop = list.scrollHeight;
    return entry;
  }

  stamp(t_ms) {
    return `${((t_ms - this.t0) / 1000).toFixed(1).padStart(6)} s`;
  }
}
