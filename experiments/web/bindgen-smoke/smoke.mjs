// node web/bindgen-smoke/smoke.mjs PKG_DIR  (PKG_DIR from `wasm-bindgen --target nodejs`)
import fs from "node:fs";
import { createRequire } from "node:module";
const require = createRequire(import.meta.url);
const pkg = require(process.argv[2] + "/dlgs_bindgen_smoke.js");
const dir = new URL("../../../format-spec/vectors/", import.meta.url).pathname;
const bytes = fs.readFileSync(dir + "valid/tiny-3gop-zstd.dlgs");
const got = pkg.gop_digests(bytes);
const want = fs.readFileSync(dir + "expected.txt", "utf8").split("\n")
  .filter((l) => l.startsWith("tiny-3gop-zstd ")).map((l) => l.split(/\s+/)[2]).join(" ");
console.log(got === want ? "ok   tiny-3gop-zstd digests" : `FAIL ${got}`);
const pos = pkg.positions_at(fs.readFileSync(dir + "valid/lod3-dynamic.dlgs"), 1.2345);
console.log(`ok   lod3-dynamic positions_at(1.2345): ${pos.length / 3} Gaussians, first ${Array.from(pos.slice(0, 3)).map((v) => v.toFixed(4))}`);
try { pkg.gop_digests(fs.readFileSync(dir + "invalid/x-bad-magic.dlgs")); console.log("FAIL no error"); }
catch (e) { console.log(`ok   x-bad-magic throws: ${e.message}`); }
process.exit(got === want ? 0 : 1);
