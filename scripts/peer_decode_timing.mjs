// Decode time of a peer file (PlayCanvas SOG or SPZ) with @playcanvas/splat-transform's own
// readers, from memory, the way `decode_timing` measures a .dlgs file: the file is read into
// memory once, then decoded RUNS times into splat-transform's in-memory table (its `readFile`,
// which for SPZ runs the official SPZ WebAssembly library and for SOG decodes the WebP images);
// prints the median and the range in ms. The first decode (wasm and JIT warm-up) is not counted.
// Usage: node scripts/peer_decode_timing.mjs MODULE_DIR FILE [RUNS]
//   MODULE_DIR: a node_modules holding @playcanvas/splat-transform (scripts/peer_decode.sh
//   installs 2.7.1 into target/peer-node).
import { readFileSync } from 'node:fs';
import { basename, join } from 'node:path';
import { pathToFileURL } from 'node:url';

const [moduleDir, file, runsArg] = process.argv.slice(2);
if (!moduleDir || !file) {
    console.error('usage: node peer_decode_timing.mjs MODULE_DIR FILE [RUNS]');
    process.exit(2);
}
const runs = Number(runsArg ?? 5);
const entry = join(moduleDir, '@playcanvas/splat-transform/dist/index.mjs');
const st = await import(pathToFileURL(entry).href);
// Readers report progress through the global logger; keep the timing output clean.
st.logger.setVerbosity('quiet');
// The SPZ WebAssembly library logs every load through console.log; silence it while timing.
console.log = () => {};

const name = basename(file);
const fs = new st.MemoryReadFileSystem();
fs.set(name, new Uint8Array(readFileSync(file)));
const inputFormat = st.getInputFormat(name);

const decode = async () => {
    const t0 = process.hrtime.bigint();
    const tables = await st.readFile({ filename: name, inputFormat, options: {}, params: [], fileSystem: fs });
    const ms = Number(process.hrtime.bigint() - t0) / 1e6;
    return { ms, rows: tables[0].numRows };
};

const warm = await decode();
const times = [];
for (let i = 0; i < runs; i++) {
    times.push((await decode()).ms);
}
times.sort((a, b) => a - b);
const median = times[Math.floor(times.length / 2)];
process.stdout.write(`${name}\t${warm.rows}\t${median.toFixed(1)}\t${times[0].toFixed(1)}\t${times[times.length - 1].toFixed(1)}\n`);
