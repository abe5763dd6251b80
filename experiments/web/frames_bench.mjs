// Frames/s of the web player's wasm decoder under node (no browser, no drawing):
//   target/wasm/tools/bin/wasm-bindgen --target nodejs --out-dir target/wasm/pkg-bench \
//       target/wasm/wasm32-unknown-unknown/release/dlgs_web.wasm
//   [PKG=/abs/path/dlgs_web.js] node experiments/web/frames_bench.mjs target/web-data/demo.dlgs [frames] [language 0|1]
import { createRequire } from 'module';
import { readFileSync } from 'fs';
const require = createRequire(import.meta.url);
const m = require(process.env.PKG || '../../target/wasm/pkg-bench/dlgs_web.js');
const file = process.argv[2];
const n = Number(process.argv[3] || 20);
const lang = process.argv[4] === '1';
const p = m.open_bytes(readFileSync(file));
const info = JSON.parse(p.info());
let t0 = performance.now();
p.decode_gop(0);
const gopMs = performance.now() - t0;
const fps = info.fps || 30;
p.frame(0.5 / fps, 0, 0, 0, lang); // warm
const times = [];
for (let i = 0; i < n; i++) {
  t0 = performance.now();
  p.frame((i + 0.5) / fps, 0, 0, 0, lang);
  times.push(performance.now() - t0);
}
times.sort((a, b) => a - b);
const med = times[Math.floor(n / 2)];
console.log(`${file}: rows ${p.rows()}, GOP 0 ${gopMs.toFixed(0)} ms, frame median ${med.toFixed(1)} ms (${(1000 / med).toFixed(1)} frames/s), min ${times[0].toFixed(1)} ms, language ${lang}`);
