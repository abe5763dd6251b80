// In-page conformance check of the web player's decoder against format-spec/vectors (what
// web/probe/run_vectors.mjs checks under node, here through the page's own dlgs-web API):
// canonical sha256 of every GOP (expected.txt), the error name of every invalid vector
// (expected-errors.txt, random-access reader), and the dynamic frames bit for bit
// (*.frames.f32: t = 0, 0.5, 1.2345, 2, 3.95 s, camera centre (0.3, -0.2, -2.5), language on).
// HEVC vectors must fail with the typed `HevcFeatures` error (the module has no HEVC decoder).
import { initWasm, open_bytes, f32 } from "/target/web/player.js";

const TIMES = [0.0, 0.5, 1.2345, 2.0, 3.95];
const errName = (e) => String(e.message || e).split(":")[0];

export async function runConformance(base = "/format-spec/vectors/") {
  await initWasm();
  const log = [];
  let pass = 0, fail = 0, hevc = 0;
  const get = async (p) => new Uint8Array(await (await fetch(base + p)).arrayBuffer());
  const text = async (p) => (await (await fetch(base + p)).text()).split("\n").filter((l) => l.trim() && !l.startsWith("#"));
  const want = new Map();
  for (const l of await text("expected.txt")) {
    const [name, , sha] = l.trim().split(/\s+/);
    if (!want.has(name)) want.set(name, []);
    want.get(name).push(sha);
  }
  for (const [name, sums] of want) {
    let got;
    try {
      const p = open_bytes(await get(`valid/${name}.dlgs`));
      const n = JSON.parse(p.info()).gop_count;
      got = [];
      for (let g = 0; g < n; g++) got.push(p.gop_digest(g));
      got = got.join(" ");
      p.free();
    } catch (e) { got = String(e.message || e); }
    if (got === sums.join(" ")) { pass++; continue; }
    if (got.startsWith("HevcFeatures:")) { hevc++; log.push(`typed HEVC error: ${name}`); continue; }
    fail++; log.push(`FAIL digests ${name}: ${got.slice(0, 160)}`);
  }
  for (const l of await text("expected-errors.txt")) {
    const [name, err] = l.trim().split(/\s+/);
    let got = "decoded";
    try {
      const p = open_bytes(await get(`invalid/${name}.dlgs`));
      const n = JSON.parse(p.info()).gop_count;
      for (let g = 0; g < n; g++) p.gop_digest(g);
      p.free();
    } catch (e) { got = errName(e); }
    got === err ? pass++ : (fail++, log.push(`FAIL error ${name}: ${got}, want ${err}`));
  }
  const list = await (await fetch(base + "valid/")).text(); // the server's directory listing
  const all = [...new Set([...list.matchAll(/href="([^"]+)\.frames\.f32"/g)].map((m) => decodeURIComponent(m[1])))];
  const names = all.filter((n) => !n.startsWith("scaffold"));
  let framesBitForBit = 0;
  // Scaffold-GS vectors: the neural Gaussians of camera centre (0.4, -0.3, -2.5), language on, at
  // the vector's times (format-spec/vectors/README.md), each frame its child count then per child
  // 26 values (tests/src/vectors/scaffold.rs `push_frame`).
  const scaffoldTimes = (n) => n === "scaffold-tiny-residual" ? [2.0, 2.85, 3.95] : n === "scaffold-tiny-refresh" ? [4.35, 6.0, 7.95] : [0.0, 0.85, 1.95];
  for (const name of all.filter((n) => n.startsWith("scaffold"))) {
    const exp = await get(`valid/${name}.frames.f32`);
    let out;
    try {
      const p = open_bytes(await get(`valid/${name}.dlgs`));
      const parts = scaffoldTimes(name).map((t) => { p.decode_gop(p.gop_at(t)); return p.scaffold_values(t, 0.4, -0.3, -2.5); });
      p.free();
      const total = parts.reduce((a, x) => a + x.length, 0);
      const f = new Float32Array(total);
      let at = 0;
      for (const x of parts) { f.set(x, at); at += x.length; }
      out = new Uint8Array(f.buffer);
    } catch (e) { fail++; log.push(`FAIL scaffold frames ${name}: ${String(e.message || e)}`); continue; }
    const same = out.length === exp.length && out.every((v, i) => v === exp[i]);
    if (same) { pass++; framesBitForBit++; log.push(`ok scaffold frames ${name}: ${out.length / 4} f32 bit for bit`); }
    else { fail++; log.push(`FAIL scaffold frames ${name}: ${out.length} bytes vs ${exp.length}, DIFFER`); }
  }
  for (const name of names) {
    const exp = await get(`valid/${name}.frames.f32`);
    let out;
    try {
      const p = open_bytes(await get(`valid/${name}.dlgs`));
      const info = JSON.parse(p.info());
      const parts = [];
      for (const t of TIMES) {
        p.frame(t, 0.3, -0.2, -2.5, true);
        const rows = p.rows(), ns = info.n_static, nd = rows - ns;
        const stride = p.sh_len() / rows, lw = p.lang_width();
        const lo = p.lang_opacity_len() ? 1 : 0;
        parts.push(f32(p.positions_ptr(), rows * 3).slice(ns * 3), f32(p.log_scales_ptr(), rows * 3).slice(ns * 3),
          f32(p.rotations_ptr(), rows * 4).slice(ns * 4), f32(p.opacity_ptr(), rows).slice(ns),
          f32(p.lang_opacity_ptr(), rows * lo).slice(ns * lo), f32(p.sh_ptr(), rows * stride).slice(ns * stride),
          f32(p.lang_ptr(), rows * lw).slice(ns * lw));
        if (nd < 0) throw new Error("rows < n_static");
      }
      p.free();
      const total = parts.reduce((a, x) => a + x.length, 0);
      out = new Uint8Array(total * 4);
      let at = 0;
      for (const x of parts) { out.set(new Uint8Array(x.buffer, x.byteOffset, x.byteLength), at); at += x.byteLength; }
    } catch (e) {
      const m = String(e.message || e);
      if (m.startsWith("HevcFeatures:")) { hevc++; log.push(`typed HEVC error: frames ${name}`); continue; }
      fail++; log.push(`FAIL frames ${name}: ${m}`); continue;
    }
    const same = out.length === exp.length && out.every((v, i) => v === exp[i]);
    if (same) { pass++; framesBitForBit++; log.push(`ok frames ${name}: ${out.length / 4} f32 bit for bit`); }
    else { fail++; log.push(`FAIL frames ${name}: ${out.length} bytes vs ${exp.length}, DIFFER`); }
  }
  return { pass, fail, hevc, framesBitForBit, log };
}
