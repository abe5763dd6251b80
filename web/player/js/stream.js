// Streaming a .dlgs through its GOP index (run in the decoder worker): ByteSource fetches byte
// ranges (HTTP Range, whole-file fallback, or a File/Blob), StreamingDecoder feeds them to the
// wasm decoder until a call no longer reports NEED_BYTES.
import { Player } from "./pkg/dlgs_web.js";

export const NEED_BYTES = 1;

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

