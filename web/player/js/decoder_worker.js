// The web player's decoder, in a module Web Worker: fetching (HTTP Range through the GOP
// index), GOP and frame decoding (dlgs-web, wasm) and the per-view depth sort all run here, so
// the page's thread only draws. Messages: {id, op, args} -> {id, value} or {id, error}.
//
//   init(wasmUrl)                      load the wasm module
//   open(src)                          URL or File -> file info (JSON of Player.info)
//   show(t, cam, mode, query)          decode the GOP holding t if needed, the frame at t, sort and
//                                      pack for cam -> {n, splats (transferred), timings, orbit}
//   draw(cam, mode, query, t)          the frame at t again (re-sorted, or decoded again when
//                                      needed) for another camera or mode
//   size(width, height)                the default camera's image size
//   status()                           bytes fetched, requests, language widths
import init from "./pkg/dlgs_web.js";
import { StreamingDecoder } from "./stream.js";
import { orbitCamera } from "./camera.js";

let wasm = null;
let dec = null;
let info = null;
let decoded = -1;
let frameT = null;
let width = 800, height = 600; // the default camera's image size (op size)

function f32(ptr, len) { return new Float32Array(wasm.memory.buffer, ptr, len); }

// Decode GOP g (fetching its bytes), timing the decode alone.
async function ensureGop(g, timings) {
  if (decoded === g) return;
  await dec.fetchGop(g);
  const t = performance.now();
  await dec.call(() => dec.player.decode_gop(g));
  timings.gop = [g, performance.now() - t];
  decoded = g;
  // Bound memory on long files: forget the bytes of GOPs more than one GOP away (fetched again
  // if the player seeks back).
  for (const old of [...dec.pending.keys()]) {
    if (Math.abs(old - g) > 1) { const [o, l] = info.gops[old]; dec.player.drop_bytes(o, l); dec.pending.delete(old); }
  }
  // Read ahead: fetch the next GOP's bytes while this one plays.
  if (g + 1 < info.gop_count) dec.fetchGop(g + 1);
}

// The default view: an orbit around the median of the frame's positions (Scaffold-GS: of the
// anchors at t, as the CLI's orbit cameras; the neural Gaussians depend on the camera).
function defaultOrbit(t) {
  const p = dec.player;
  let pos, n;
  if (info.variant !== "Gaussians3d") { pos = p.anchor_positions(t); n = pos.length / 3; }
  else { n = p.rows(); pos = f32(p.positions_ptr(), n * 3); }
  if (n === 0) return { center: [0, 0, 0], dist: 4, yaw: 0, pitch: 0.3 };
  const xs = [[], [], []];
  for (let i = 0; i < n; i += Math.max(1, (n / 5000) | 0)) for (let a = 0; a < 3; a++) xs[a].push(pos[i * 3 + a]);
  const med = xs.map((v) => v.sort((a, b) => a - b)[v.length >> 1]);
  const q = (v, f) => v[Math.floor(f * (v.length - 1))];
  const rad = Math.max(...xs.map((v) => (q(v, 0.95) - q(v, 0.05)) / 2)) || 1;
  return { center: med, dist: 1.6 * 2 * rad, yaw: 0, pitch: 0.3 };
}

function pack(cam, mode, query, timings) {
  const p = dec.player;
  if (mode === "language" && query) {
    try { p.set_query(query.embedding, query.level); } catch (e) { timings.queryError = String(e.message || e); }
  }
  const t = performance.now();
  const n = p.prepare_draw(new Float32Array(cam.w2c), new Float32Array(cam.pos), mode === "language" ? 1 : 0);
  const splats = f32(p.splats_ptr(), n * 16).slice();
  timings.sort = performance.now() - t;
  return { n, splats };
}

const ops = {
  async init(wasmUrl) { if (!wasm) wasm = await init(wasmUrl ? { module_or_path: wasmUrl } : undefined); return true; },
  async open(src) {
    dec = new StreamingDecoder(src);
    info = await dec.open();
    decoded = -1;
    frameT = null;
    return info;
  },
  async show(t, cam, mode, query) {
    const timings = {};
    const g = dec.player.gop_at(t);
    await ensureGop(g, timings);
    const language = mode === "language";
    const c = cam ? cam.pos : [0, 0, 0];
    const t1 = performance.now();
    await dec.call(() => dec.player.frame(t, c[0], c[1], c[2], language));
    let orbit = null;
    if (!cam) {
      // View-dependent decoders need the camera: decode again from the default one.
      orbit = defaultOrbit(t);
      cam = orbitCamera(orbit.center, orbit.dist, orbit.yaw, orbit.pitch, width, height);
      dec.player.frame(t, cam.pos[0], cam.pos[1], cam.pos[2], language);
    }
    timings.frame = performance.now() - t1;
    frameT = t;
    const { n, splats } = pack(cam, mode, query, timings);
    return { value: { n, splats, timings, orbit, cam, t, stats: dec.stats }, transfer: [splats.buffer] };
  },
  // The frame at t (the one on screen) for another camera or mode: decoded again when the
  // worker's last frame is another one (it decodes one ahead while playing) or the Gaussians
  // depend on the camera (Scaffold-GS).
  async draw(cam, mode, query, t) {
    if (frameT === null) throw new Error("Request: no frame decoded yet");
    const timings = {};
    const at = t ?? frameT;
    if (at !== frameT || info.variant !== "Gaussians3d") {
      const t1 = performance.now();
      await ensureGop(dec.player.gop_at(at), timings);
      await dec.call(() => dec.player.frame(at, cam.pos[0], cam.pos[1], cam.pos[2], mode === "language"));
      timings.frame = performance.now() - t1;
      frameT = at;
    }
    const { n, splats } = pack(cam, mode, query, timings);
    return { value: { n, splats, timings, t: frameT }, transfer: [splats.buffer] };
  },
  async status() {
    const p = dec.player;
    let laed = null;
    try { laed = p.laed_dims(); } catch (e) { laed = null; }
    return { stats: dec.stats, fetched: p.fetched_bytes(), langWidth: p.lang_width(), laedDims: laed };
  },
  async size(w, h) { width = w; height = h; return true; },
};

// One request at a time, in order (the decoder is not re-entrant).
let queue = Promise.resolve();
self.onmessage = (e) => {
  const { id, op, args } = e.data;
  queue = queue.then(async () => {
    try {
      const r = await ops[op](...(args || []));
      if (r && r.transfer) self.postMessage({ id, value: r.value }, r.transfer);
      else self.postMessage({ id, value: r });
    } catch (err) {
      self.postMessage({ id, error: String((err && err.message) || err) });
    }
  });
};
