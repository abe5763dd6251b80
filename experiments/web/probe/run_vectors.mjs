// node web/probe/run_vectors.mjs probe.wasm [vectors_dir]
// Checks the wasm decoder against format-spec/vectors: canonical sha256 per GOP (expected.txt,
// random-access and stream decoders) and dynamic frames bit for bit (*.frames.f32).
import fs from "node:fs";
import path from "node:path";
const [wasmPath, dir = new URL("../../../format-spec/vectors", import.meta.url).pathname] = process.argv.slice(2);
let inst;
const text = (p, n) => new TextDecoder().decode(new Uint8Array(inst.exports.memory.buffer, p, n));
const { instance } = await WebAssembly.instantiate(fs.readFileSync(wasmPath), {
  env: { log: (p, n) => console.error("[wasm]", text(p, n)) },
});
inst = instance;
const x = inst.exports;
x.init();
function call(fn, bytes, ...args) {
  const p = x.alloc(bytes.length);
  new Uint8Array(x.memory.buffer, p, bytes.length).set(bytes);
  let rc;
  try { rc = fn(p, bytes.length, ...args); } catch (e) { x.dealloc(p, bytes.length); return { rc: -1, err: String(e) }; }
  x.dealloc(p, bytes.length);
  const out = new Uint8Array(x.memory.buffer, x.out_ptr(), x.out_len()).slice();
  return { rc, out };
}
const want = new Map();
for (const l of fs.readFileSync(path.join(dir, "expected.txt"), "utf8").split("\n")) {
  if (!l.trim() || l.startsWith("#")) continue;
  const [name, , sha] = l.trim().split(/\s+/);
  if (!want.has(name)) want.set(name, []);
  want.get(name).push(sha);
}
let fail = 0, pass = 0, skip = 0;
// Without the `hevc` feature HEVC time features need a key-picture decoder the player supplies.
const noHevc = (s) => s.includes("has no HEVC decoder");
const t0 = performance.now();
for (const [name, sums] of want) {
  const bytes = fs.readFileSync(path.join(dir, "valid", name + ".dlgs"));
  for (const mode of [0, 1]) {
    const r = call(x.digests, bytes, mode);
    const got = r.rc === 0 ? new TextDecoder().decode(r.out) : (r.err ?? new TextDecoder().decode(r.out));
    const ok = got === sums.join(" ");
    if (!ok && noHevc(got)) { skip++; continue; }
    ok ? pass++ : fail++;
    if (!ok) console.log(`FAIL ${name} ${mode ? "stream" : "random"}: ${got.slice(0, 200)}`);
  }
}
// Invalid vectors: the error's name (expected-errors.txt; a third column is the stream reader's).
for (const l of fs.readFileSync(path.join(dir, "expected-errors.txt"), "utf8").split("\n")) {
  if (!l.trim() || l.startsWith("#")) continue;
  const [name, err, streamErr] = l.trim().split(/\s+/);
  const bytes = fs.readFileSync(path.join(dir, "invalid", name + ".dlgs"));
  for (const mode of [0, 1]) {
    if (mode === 1 && name === "x-truncated") continue; // the stream reader may name another
    const want = mode === 1 && streamErr ? streamErr : err;
    const r = call(x.digests, bytes, mode);
    const got = r.rc === 1 ? new TextDecoder().decode(r.out).split(" ")[1] : (r.err ?? "decoded");
    got === want ? pass++ : (fail++, console.log(`FAIL ${name} ${mode ? "stream" : "random"}: ${got}, want ${want}`));
  }
}
for (const f of fs.readdirSync(path.join(dir, "valid")).filter((f) => f.endsWith(".frames.f32") && !f.startsWith("scaffold"))) {
  const name = f.replace(".frames.f32", "");
  const r = call(x.frames, fs.readFileSync(path.join(dir, "valid", name + ".dlgs")));
  if (r.rc !== 0 && noHevc(r.err ?? new TextDecoder().decode(r.out))) { skip++; console.log(`skip frames ${name}: HEVC`); continue; }
  if (r.rc !== 0) { fail++; console.log(`FAIL frames ${name}: ${r.err ?? new TextDecoder().decode(r.out)}`); continue; }
  const exp = fs.readFileSync(path.join(dir, "valid", f));
  const same = Buffer.compare(Buffer.from(r.out), exp) === 0;
  same ? pass++ : fail++;
  console.log(`${same ? "ok  " : "FAIL"} frames ${name}: ${r.out.length / 4} f32 ${same ? "bit for bit" : "DIFFER"}`);
}
console.log(`${pass} passed, ${fail} failed, ${skip} skipped (HEVC), ${(performance.now() - t0).toFixed(0)} ms`);
process.exit(fail ? 1 : 0);
