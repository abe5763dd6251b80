// dlgs web player: streams a .dlgs file by HTTP Range requests through its GOP index, decodes
// with the GPL-free wasm decoder (dlgs-web) and draws with the WebGL2 splat renderer.
//
//   import { DlgsPlayer } from "./player.js";
//   const p = await DlgsPlayer.create(canvas, { wasmUrl });
//   await p.load(url | File);  p.play();  p.seek(t);  p.setMode("colour" | "language");
import init, { Player, open_bytes } from "./pkg/dlgs_web.js";
import { SplatRenderer } from "./renderer.js";

export const NEED_BYTES = 1;
let wasm = null;
export async function initWasm(url) {
  if (!wasm) wasm = await init(url ? { module_or_path: url } : undefined);
  return wasm;
}
export { Player, open_bytes };

// Float32 view of wasm memory (recreated after every call: memory may grow).
export function f32(ptr, len) { return new Float32Array(wasm.memory.buffer, ptr, len); }

// Where the bytes come from: an HTTP URL (Range requests, whole-file fallback) or a File/Blob.
export class ByteSource {
  constructor(src, stats) { this.src = src; this.stats = stats; this.whole = null; this.total = 0; }
  async start(prefix = 65536) {
    if (typeof this.src !== "string") {
      this.total = this.src.size;
      return [[0, new Uint8Array(await this.src.slice(0, Math.min(prefix, this.total)).arrayBuffer())]];
    }
    const r = await fetch(this.src, { headers: { Range: `bytes=0-${prefix - 1}` } });
    if (!r.ok) throw new Error(`Http: ${r.status} ${r.statusText} for ${this.src}`);
    const body = new Uint8Array(await r.arrayBuffer());
    this.stats.requests++; this.stats.bytes += body.length;
    if (r.status === 206) {
      this.total = Number((r.headers.get("Content-Range") || "").split("/")[1]);
      this.stats.range = true;
      return [[0, body]];
    }
    // The server ignored Range: it sent the whole file.
    this.stats.range = false;
    this.total = body.length;
    this.whole = body;
    return [[0, body]];
  }
  async get(off, len) {
    if (this.whole) return this.whole.subarray(off, off + len);
    if (typeof this.src !== "string") return new Uint8Array(await this.src.slice(off, off + len).arrayBuffer());
    const r = await fetch(this.src, { headers: { Range: `bytes=${off}-${off + len - 1}` } });
    if (r.status !== 206 && r.status !== 200) throw new Error(`Http: ${r.status} for range ${off}+${len}`);
    let body = new Uint8Array(await r.arrayBuffer());
    this.stats.requests++; this.stats.bytes += body.length;
    if (r.status === 200) { this.whole = body; body = body.subarray(off, off + len); }
    return body;
  }
}

// A decoder over a streamed file: call(fn) runs a dlgs-web call, fetching missing bytes until done.
export class StreamingDecoder {
  constructor(src) {
    this.stats = { requests: 0, bytes: 0, range: null };
    this.source = new ByteSource(src, this.stats);
    this.pending = new Map(); // GOP -> Promise of its bytes added
  }
  async open() {
    const first = await this.source.start();
    this.player = new Player(this.source.total);
    for (const [o, b] of first) this.player.add_bytes(o, b);
    if (!this.source.whole && this.source.total > 65536) {
      // The GOP index and TAIL are at the end of the file.
      const n = Math.min(65536, this.source.total - 65536);
      this.player.add_bytes(this.source.total - n, await this.source.get(this.source.total - n, n));
    }
    await this.call(() => this.player.open());
    this.info = JSON.parse(this.player.info());
    return this.info;
  }
  async call(fn) {
    for (let i = 0; i < 10000; i++) {
      if (fn() !== NEED_BYTES) return;
      const off = this.player.need_offset(), len = this.player.need_len();
      // Fetch the whole GOP holding the missing byte if there is one, else at least 64 KiB.
      const g = this.info ? this.info.gops.findIndex(([o, l]) => off >= o && off < o + l) : -1;
      if (g >= 0) { await this.fetchGop(g); continue; }
      const n = Math.min(Math.max(len, 65536), this.source.total - off);
      this.player.add_bytes(off, await this.source.get(off, n));
    }
    throw new Error("Stream: too many fetches");
  }
  fetchGop(g) {
    if (!this.pending.has(g)) {
      const [o, l] = this.info.gops[g];
      this.pending.set(g, this.source.get(o, l).then((b) => { this.player.add_bytes(o, b); }));
    }
    return this.pending.get(g);
  }
  gopReady(g) { return this.pending.has(g); }
}

function mat3MulT(a, b) { // a (row-major) * b (row-major)
  const o = new Array(9).fill(0);
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) for (let k = 0; k < 3; k++) o[i * 3 + j] += a[i * 3 + k] * b[k * 3 + j];
  return o;
}

// A 3DGS cameras.json entry -> renderer camera (rotation is camera-to-world, rows).
export function cameraFromJson(c, width, height) {
  const r = c.rotation; const W = width || c.width, H = height || c.height;
  const sx = W / c.width, sy = H / c.height;
  return {
    w2c: [r[0][0], r[1][0], r[2][0], r[0][1], r[1][1], r[2][1], r[0][2], r[1][2], r[2][2]],
    pos: c.position.slice(), fx: c.fx * sx, fy: c.fy * sy, cx: W / 2, cy: H / 2, width: W, height: H,
  };
}

// An orbit camera: yaw/pitch around a centre, up -y (COLMAP scenes), as `dlgs render --orbit`.
export function orbitCamera(center, dist, yaw, pitch, width, height, fovDeg = 50) {
  const cp = Math.cos(pitch), sp = Math.sin(pitch);
  const pos = [center[0] + dist * cp * Math.sin(yaw), center[1] - dist * sp, center[2] - dist * cp * Math.cos(yaw)];
  const f = [center[0] - pos[0], center[1] - pos[1], center[2] - pos[2]];
  const fl = Math.hypot(...f); const z = f.map((v) => v / fl);
  const up = [0, -1, 0];
  let x = [z[1] * up[2] - z[2] * up[1], z[2] * up[0] - z[0] * up[2], z[0] * up[1] - z[1] * up[0]];
  const xl = Math.hypot(...x) || 1; x = x.map((v) => v / xl);
  const y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]];
  const fx = width / (2 * Math.tan((fovDeg * Math.PI) / 360));
  return { w2c: [...x, ...y, ...z], pos, fx, fy: fx, cx: width / 2, cy: height / 2, width, height };
}

export class DlgsPlayer {
  static async create(canvas, opts = {}) {
    await initWasm(opts.wasmUrl);
    return new DlgsPlayer(canvas, opts);
  }
  constructor(canvas, opts) {
    this.renderer = new SplatRenderer(canvas);
    this.mode = "colour";
    this.t = 0;
    this.playing = false;
    this.stats = { shown: 0, dropped: 0, ttff: null, gopDecodeMs: [], frameMs: [], drawMs: [] };
    this.onframe = opts.onframe || (() => {});
    this.width = opts.width || canvas.width || 800;
    this.height = opts.height || canvas.height || 600;
    this.cam = null;
  }
  async load(src, opts = {}) {
    this.t0 = performance.now();
    this.dec = new StreamingDecoder(src);
    this.info = await this.dec.open();
    if (this.info.variant !== "Gaussians3d") throw new Error("Unsupported: Scaffold-GS files need the camera-dependent decoder (not in the web player yet)");
    this.decoded = new Set();
    this.cam = opts.camera || null;
    await this.showFrame(0);
    this.firstFrameAt = performance.now(); // since navigation start
    this.stats.ttff = this.firstFrameAt - this.t0;
    return this.info;
  }
  // Decode GOP g (fetching its bytes), timing the decode alone.
  async ensureGop(g) {
    if (this.decoded.has(g)) return;
    await this.dec.fetchGop(g);
    const t = performance.now();
    await this.dec.call(() => this.dec.player.decode_gop(g));
    this.stats.gopDecodeMs.push([g, performance.now() - t]);
    this.decoded.clear(); // the decoder keeps one GOP
    this.decoded.add(g);
    // Bound memory on long files: forget the bytes of GOPs more than one GOP away (the
    // decoder asks for them again, and they are fetched again, if the player seeks back).
    for (const old of [...this.dec.pending.keys()]) {
      if (Math.abs(old - g) > 1) { const [o, l] = this.info.gops[old]; this.dec.player.drop_bytes(o, l); this.dec.pending.delete(old); }
    }
    // Read ahead: fetch the next GOP's bytes while this one plays.
    if (g + 1 < this.info.gop_count) this.dec.fetchGop(g + 1);
  }
  defaultCamera() {
    const p = this.dec.player, n = p.rows();
    const pos = f32(p.positions_ptr(), n * 3);
    const xs = [[], [], []];
    for (let i = 0; i < n; i += Math.max(1, (n / 5000) | 0)) for (let a = 0; a < 3; a++) xs[a].push(pos[i * 3 + a]);
    const med = xs.map((v) => v.sort((a, b) => a - b)[v.length >> 1]);
    const q = (v, f) => v[Math.floor(f * (v.length - 1))];
    const rad = Math.max(...xs.map((v) => (q(v, 0.95) - q(v, 0.05)) / 2));
    this.orbit = { center: med, dist: 1.6 * 2 * rad, yaw: 0, pitch: 0.3 };
    return orbitCamera(med, this.orbit.dist, 0, 0.3, this.width, this.height);
  }
  async showFrame(t) {
    const g = this.dec.player.gop_at(t);
    await this.ensureGop(g);
    const c = this.cam ? this.cam.pos : [0, 0, 0];
    const t1 = performance.now();
    await this.dec.call(() => this.dec.player.frame(t, c[0], c[1], c[2], this.mode === "language"));
    if (!this.cam) { this.cam = this.defaultCamera(); this.dec.player.frame(t, ...this.cam.pos, this.mode === "language"); }
    const t2 = performance.now();
    this.draw();
    this.stats.frameMs.push(t2 - t1);
    this.stats.drawMs.push(performance.now() - t2);
    this.t = t;
    this.onframe(this);
  }
  draw() {
    const p = this.dec.player;
    if (this.mode === "language" && this.query) { try { p.set_query(this.query.embedding, this.query.level); } catch (e) { this.error = String(e); } this.query = null; }
    const n = p.prepare_draw(new Float32Array(this.cam.w2c), new Float32Array(this.cam.pos), this.mode === "language" ? 1 : 0);
    this.renderer.draw(f32(p.splats_ptr(), n * 16), n, this.cam);
    this.drawn = n;
  }
  setMode(m) { this.mode = m; }
  setQuery(embedding, level = 0) { this.query = { embedding: new Float32Array(embedding), level }; }
  setCamera(cam) { this.cam = cam; }
  frameTime(i) { return Math.min(i / this.info.fps, this.info.duration); }
  // Real-time playback at the file's fps: a frame whose time passed while the previous one was
  // still being decoded or drawn is dropped (counted), never shown late.
  play() {
    if (this.playing) return;
    this.playing = true;
    const fps = this.info.fps, frames = this.info.frame_count;
    const startFrame = Math.round(this.t * fps);
    const start = performance.now();
    let last = startFrame;
    const tick = async () => {
      if (!this.playing) return;
      const want = startFrame + Math.floor(((performance.now() - start) / 1000) * fps);
      if (want >= frames) { this.stats.dropped += Math.max(0, frames - 1 - last); this.playing = false; this.onend && this.onend(); return; }
      try {
        if (want > last) {
          this.stats.dropped += want - last - 1;
          last = want;
          await this.showFrame(this.frameTime(want));
          this.stats.shown++;
        }
      } catch (e) {
        this.playing = false; this.error = String(e.message || e); this.onerror && this.onerror(e); return;
      }
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  }
  pause() { this.playing = false; }
}
