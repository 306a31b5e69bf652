// The WebSocket session at /session (docs/live.md): text JSON messages both ways, binary
// surface frames from the server. This module knows the wire; the page only sees
// decoded messages.

/** "PESF": the bytes 'F','S','E','P' read as a little-endian u32. */
export const FRAME_MAGIC = 0x50455346;
export const FRAME_VERSION = 1;
export const FRAME_HEADER_BYTES = 24;
export const KIND_TOPOLOGY = 1;
export const KIND_POSITIONS = 2;
export const KIND_TOOLS = 3;

const LITTLE_ENDIAN = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;

function f32s(view, offset, n) {
  if (LITTLE_ENDIAN) return new Float32Array(view.buffer.slice(view.byteOffset + offset, view.byteOffset + offset + 4 * n));
  const out = new Float32Array(n);
  for (let i = 0; i < n; i++) out[i] = view.getFloat32(offset + 4 * i, true);
  return out;
}

function u32s(view, offset, n) {
  if (LITTLE_ENDIAN) return new Uint32Array(view.buffer.slice(view.byteOffset + offset, view.byteOffset + offset + 4 * n));
  const out = new Uint32Array(n);
  for (let i = 0; i < n; i++) out[i] = view.getUint32(offset + 4 * i, true);
  return out;
}

function need(view, bytes, what) {
  if (view.byteLength < bytes) {
    throw new Error(`${what} frame: ${view.byteLength} bytes, its header asks for ${bytes}`);
  }
}

/**
 * Decodes one binary frame (an ArrayBuffer). Returns
 * { kind: 'topology', seq, time_s, triangles: Uint32Array(3m), reference: Float32Array(3n), body: Uint16Array(n) }
 * { kind: 'positions', seq, time_s, positions: Float32Array(3n) }
 * { kind: 'tools', seq, time_s, poses: [{ orientation: [w,x,y,z], position_m: [x,y,z] }] }
 * or throws an Error naming what is wrong.
 */
export function decodeFrame(buffer) {
  const view = new DataView(buffer);
  need(view, FRAME_HEADER_BYTES, 'a');
  const magic = view.getUint32(0, true);
  if (magic !== FRAME_MAGIC) throw new Error(`frame magic 0x${magic.toString(16)}, expected 0x${FRAME_MAGIC.toString(16)}`);
  const version = view.getUint16(4, true);
  if (version !== FRAME_VERSION) throw new Error(`frame version ${version}, this page reads ${FRAME_VERSION}`);
  const kind = view.getUint16(6, true);
  const seq = view.getUint32(8, true);
  const count = view.getUint32(12, true);
  const time_s = view.getFloat64(16, true);
  let at = FRAME_HEADER_BYTES;
  switch (kind) {
    case KIND_TOPOLOGY: {
      need(view, at + 12 * count + 4, 'TOPOLOGY');
      const triangles = u32s(view, at, 3 * count);
      at += 12 * count;
      const n = view.getUint32(at, true);
      at += 4;
      need(view, at + 14 * n, 'TOPOLOGY');
      const reference = f32s(view, at, 3 * n);
      at += 12 * n;
      const body = new Uint16Array(n);
      for (let i = 0; i < n; i++) body[i] = view.getUint16(at + 2 * i, true);
      for (let i = 0; i < triangles.length; i++) {
        if (triangles[i] >= n) throw new Error(`TOPOLOGY frame: triangle ${Math.floor(i / 3)} names node ${triangles[i]} of ${n}`);
      }
      return { kind: 'topology', seq, time_s, triangles, reference, body };
    }
    case KIND_POSITIONS:
      need(view, at + 12 * count, 'POSITIONS');
      return { kind: 'positions', seq, time_s, positions: f32s(view, at, 3 * count) };
    case KIND_TOOLS: {
      need(view, at + 56 * count, 'TOOLS');
      const poses = [];
      for (let t = 0; t < count; t++, at += 56) {
        const v = [0, 1, 2, 3, 4, 5, 6].map((i) => view.getFloat64(at + 8 * i, true));
        poses.push({ orientation: v.slice(0, 4), position_m: v.slice(4, 7) });
      }
      return { kind: 'tools', seq, time_s, poses };
    }
    default:
      throw new Error(`frame kind ${kind} is not one this page reads`);
  }
}

/**
 * A session with reconnection. `handlers`: onState(state, detail), onText(message),
 * onFrame(frame), onBadMessage(errorText). States: 'connecting', 'open', 'closed'.
 */
export class Session {
  constructor(url, handlers) {
    this.url = url;
    this.handlers = handlers;
    this.ws = null;
    this.state = 'closed';
    this.retryMs = 1000;
    this.bytesReceived = 0;
    this.connect();
  }

  setState(state, detail) {
    this.state = state;
    this.handlers.onState(state, detail);
  }

  connect() {
    this.setState('connecting', this.url);
    let ws;
    try {
      ws = new WebSocket(this.url);
    } catch (e) {
      this.setState('closed', String(e));
      this.retry();
      return;
    }
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    ws.onopen = () => {
      this.retryMs = 1000;
      this.setState('open', this.url);
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data === 'string') {
        this.bytesReceived += ev.data.length;
        let m;
        try {
          m = JSON.parse(ev.data);
        } catch (e) {
          this.handlers.onBadMessage(`unreadable text message (${e.message}): ${ev.data.slice(0, 80)}`);
          return;
        }
        this.handlers.onText(m);
      } else {
        this.bytesReceived += ev.data.byteLength;
        let f;
        try {
          f = decodeFrame(ev.data);
        } catch (e) {
          this.handlers.onBadMessage(e.message);
          return;
        }
        this.handlers.onFrame(f);
      }
    };
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      this.ws = null;
      this.setState('closed', ev.reason || `code ${ev.code}`);
      this.retry();
    };
    ws.onerror = () => {};
  }

  retry() {
    setTimeout(() => this.connect(), this.retryMs);
    this.retryMs = Math.min(this.retryMs * 2, 8000);
  }

  /** Sends a JSON message; false when the session is not open. */
  send(message) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return false;
    this.ws.send(JSON.stringify(message));
    return true;
  }
}
