// dlgs web player: streams a .dlgs file by HTTP Range requests through its GOP index, decodes
// it in a Web Worker with the GPL-free wasm decoder (dlgs-web; decoder_worker.js) and draws with
// the WebGL2 splat renderer on the page's thread.
//
//   import { DlgsPlayer } from "./player.js";
//   const p = await DlgsPlayer.create(canvas, { wasmUrl });
//   await p.load(url | File);  p.play();  await p.seek(t);  p.setMode("colour" | "language");
import init, { Player, open_bytes } from "./pkg/dlgs_web.js";
import { SplatRenderer } from "./renderer.js";
import { orbitCamera, cameraFromJson } from "./camera.js";

export { orbitCamera, cameraFromJson };
export const NEED_BYTES = 1;

// The wasm module on the page's thread (the conformance tests call the decoder directly).
let wasm = null;
export async function initWasm(url) {
  if (!wasm) wasm = await init(url ? { module_or_path: url } : undefined);
  return wasm;
}
export { Player, open_bytes };

// Float32 view of the page's wasm memory (recreated after every call: memory may grow).
export function f32(ptr, len) { return new Float32Array(wasm.memory.buffer, ptr, len); }

// The decoder worker, one request at a time: call(op, ...args) -> Promise of its value.
export class DecoderWorker {
  constructor() {
    this.worker = new Worker(new URL("./decoder_worker.js", import.meta.url), { type: "module" });
    this.next = 1;
    this.waiting = new Map();
    this.worker.onmessage = (e) => {
      const { id, value, error } = e.data;
      const w = this.waiting.get(id);
      if (!w) return; // already failed by onerror
      this.waiting.delete(id);
      if (error !== undefined) w.reject(new Error(error)); else w.resolve(value);
    };
    this.worker.onerror = (e) => { for (const w of this.waiting.values()) w.reject(new Error(`Worker: ${e.message}`)); this.waiting.clear(); };
  }
  call(op, ...args) {
    const id = this.next++;
    return new Promise((resolve, reject) => {
      this.waiting.set(id, { resolve, reject });
      this.worker.postMessage({ id, op, args });
    });
  }
  terminate() { this.worker.terminate(); }
}

export class DlgsPlayer {
  static async create(canvas, opts = {}) {
    const p = new DlgsPlayer(canvas, opts);
    await p.worker.call("init", opts.wasmUrl ? new URL(opts.wasmUrl, location.href).href : undefined);
    await p.worker.call("size", p.width, p.height);
    return p;
  }
  constructor(canvas, opts) {
    this.renderer = new SplatRenderer(canvas);
    this.worker = new DecoderWorker();
    this.mode = "colour";
    this.t = 0;
    this.playing = false;
    this.stats = { shown: 0, dropped: 0, ttff: null, gopDecodeMs: [], frameMs: [], sortMs: [], drawMs: [] };
    this.onframe = opts.onframe || (() => {});
    this.width = opts.width || canvas.width || 800;
    this.height = opts.height || canvas.height || 600;
    this.cam = null;
    this.query = null;
    this.dec = { stats: { requests: 0, bytes: 0, range: null } };
  }
  async load(src, opts = {}) {
    this.t0 = performance.now();
    // A File is structured-cloned to the worker; a URL is resolved against the page.
    this.info = await this.worker.call("open", typeof src === "string" ? new URL(src, location.href).href : src);
    this.cam = opts.camera || null;
    await this.showFrame(0);
    this.firstFrameAt = performance.now(); // since navigation start
    this.stats.ttff = this.firstFrameAt - this.t0;
    return this.info;
  }
  // Bytes fetched, requests, language widths (from the worker).
  async status() {
    const s = await this.worker.call("status");
    this.dec.stats = s.stats;
    return s;
  }
  // The frame at t decoded, sorted and packed by the worker (a query is sent once: the worker's
  // decoder keeps it).
  request(t) {
    const q = this.mode === "language" ? this.query : null;
    if (q) this.query = null;
    return this.worker.call("show", t, this.cam, this.mode, q);
  }
  // Draw a frame the worker decoded and packed; record its timings.
  present(r) {
    if (r.orbit) { this.orbit = r.orbit; this.cam = r.cam; }
    if (r.stats) this.dec.stats = r.stats;
    const tm = r.timings;
    if (tm.gop) this.stats.gopDecodeMs.push(tm.gop);
    if (tm.frame !== undefined) this.stats.frameMs.push(tm.frame);
    this.stats.sortMs.push(tm.sort);
    if (tm.queryError) this.error = tm.queryError;
    const t = performance.now();
    this.renderer.draw(r.splats, r.n, this.cam);
    this.stats.drawMs.push(performance.now() - t);
    this.drawn = r.n;
    this.t = r.t;
    this.onframe(this);
  }
  async showFrame(t) {
    this.present(await this.request(t));
  }
  // The current frame again, for another camera (orbit drag) or mode.
  async draw() {
    const q = this.mode === "language" ? this.query : null;
    if (q) this.query = null;
    this.present(await this.worker.call("draw", this.cam, this.mode, q, this.t));
  }
  seek(t) { return this.showFrame(t); }
  setMode(m) { this.mode = m; }
  setQuery(embedding, level = 0) { this.query = { embedding: new Float32Array(embedding), level }; }
  setCamera(cam) { this.cam = cam; }
  frameTime(i) { return Math.min(i / this.info.fps, this.info.duration); }
  // Real-time playback at the file's fps: a frame whose time passed while the previous one was
  // still being decoded or drawn is dropped (counted), never shown late. The worker decodes the
  // next frame while this thread draws the current one.
  play() {
    if (this.playing) return;
    this.playing = true;
    const token = (this.playToken = (this.playToken || 0) + 1); // one loop at a time
    const fps = this.info.fps, frames = this.info.frame_count;
    const startFrame = Math.round(this.t * fps);
    const start = performance.now();
    const due = (ms) => startFrame + Math.floor(((ms - start) / 1000) * fps);
    let shownIdx = startFrame;
    let ahead = null; // [frame index, Promise, camera]: requested before the previous draw
    let period = 1000 / fps;
    const live = () => this.playing && token === this.playToken;
    const tick = async () => {
      if (!live()) return;
      const want = due(performance.now());
      if (want >= frames) { this.stats.dropped += Math.max(0, frames - 1 - shownIdx); this.playing = false; this.onend && this.onend(); return; }
      try {
        if (want > shownIdx && !(ahead && ahead[0] > want && ahead[2] === this.cam)) {
          const began = performance.now();
          let r;
          // A frame asked ahead is used if it is the one due and was sorted for this camera.
          if (ahead && ahead[0] === want && ahead[2] === this.cam) r = await ahead[1];
          else { if (ahead) await ahead[1].catch(() => {}); r = await this.request(this.frameTime(want)); }
          ahead = null;
          if (!live()) return;
          this.stats.dropped += want - shownIdx - 1;
          // Ask for the frame that will be due once this one is drawn.
          const next = Math.max(want + 1, due(performance.now() + period));
          if (next < frames) {
            const p = this.request(this.frameTime(next));
            p.catch(() => {}); // a pause or an error may leave it unused
            ahead = [next, p, this.cam];
          }
          this.present(r);
          shownIdx = want;
          this.stats.shown++;
          period = performance.now() - began;
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
