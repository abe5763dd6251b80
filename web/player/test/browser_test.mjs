// Browser tests of the web player (issue 67), run by scripts/web_test.sh: Debian's chromium,
// headless, driven by playwright-core over CDP, pages served on loopback by web/player/serve.py.
//   node browser_test.mjs BASE_URL NORANGE_BASE_URL OUT_DIR [--measure]
// Env: SCENE (dynamic .dlgs, URL path), CAMS (cameras.json path), REF (CPU render PNG path),
//      T (time of the screenshot), PSNR_FLOOR, PLAY_FILE, MEASURE_FILE.
import { createRequire } from "node:module";
import fs from "node:fs";
const require = createRequire(process.env.NODE_MODULES_DIR + "/");
const { chromium } = require("playwright-core");

const [base, baseNoRange, outDir, ...flags] = process.argv.slice(2);
const measure = flags.includes("--measure");
const env = process.env;
const args = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
  "--disable-background-networking", "--disable-component-update", "--disable-sync",
  "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-background-timer-throttling",
  "--disable-renderer-backgrounding"];
const userDataDir = fs.mkdtempSync(outDir + "/chromium-profile-");
const ctx = await chromium.launchPersistentContext(userDataDir, {
  executablePath: "/usr/bin/chromium", headless: true, args, viewport: { width: 1000, height: 900 }, deviceScaleFactor: 1,
});
let failures = 0;
const check = (ok, what) => { console.log(`${ok ? "PASS" : "FAIL"} ${what}`); if (!ok) failures++; };
const page = await ctx.newPage();
page.on("console", (m) => { if (m.type() === "error") console.log("[page]", m.text()); });
page.on("pageerror", (e) => console.log("[page error]", String(e)));
const waitState = async (p, states, ms = 120000) => {
  await p.waitForFunction((s) => window.dlgsStatus && s.includes(window.dlgsStatus.state), states, { timeout: ms, polling: 100 });
  return p.evaluate(() => JSON.parse(JSON.stringify(window.dlgsStatus)));
};

// PSNR of two PNGs (base64), computed in the page: { psnr, maxd, w, h } or { error }.
const pagePsnr = async ([a, b]) => {
  const px = async (b64) => {
    const bmp = await createImageBitmap(await (await fetch("data:image/png;base64," + b64)).blob(), { colorSpaceConversion: "none", premultiplyAlpha: "none" });
    const c = new OffscreenCanvas(bmp.width, bmp.height); const x = c.getContext("2d");
    x.drawImage(bmp, 0, 0); return [bmp.width, bmp.height, x.getImageData(0, 0, bmp.width, bmp.height).data];
  };
  const [w1, h1, p] = await px(a), [w2, h2, q] = await px(b);
  if (w1 !== w2 || h1 !== h2) return { error: `sizes ${w1}x${h1} vs ${w2}x${h2}` };
  let se = 0, n = 0, maxd = 0;
  for (let i = 0; i < p.length; i += 4) for (let c = 0; c < 3; c++) { const d = p[i + c] - q[i + c]; se += d * d; n++; maxd = Math.max(maxd, Math.abs(d)); }
  return { psnr: 10 * Math.log10((255 * 255) / (se / n)), maxd, w: w1, h: h1 };
};

try {
  if (!measure) {
    // 1. Conformance vectors decoded in the page, bit for bit.
    await page.goto(`${base}/web/player/test/test.html`);
    await page.waitForFunction(() => window.testReady);
    const gl = await page.evaluate(() => { const c = document.createElement("canvas").getContext("webgl2"); return c ? c.getParameter(c.RENDERER) : "none"; });
    console.log(`WebGL2 renderer: ${gl}`);
    const r = await page.evaluate(() => window.runConformance());
    for (const l of r.log) console.log("  " + l);
    console.log(`conformance in the page: ${r.pass} passed, ${r.fail} failed, ${r.hevc} HEVC vectors refused with the typed HevcFeatures error`);
    check(r.fail === 0 && r.pass >= 55 && r.framesBitForBit >= 11 && r.hevc >= 3,
      `conformance vectors: digests, error names and dynamic frames bit for bit (${r.framesBitForBit} frame vectors, Scaffold-GS ones included)`);

    // 2. Screenshot of a real scene against the CPU renderer (same cameras.json view, size, background).
    const W = 640, H = 480;
    await page.goto(`${base}/target/web/index.html?file=${env.SCENE}&camera=${env.CAMS}&view=0&width=${W}&height=${H}&t=${env.T}`);
    let st = await waitState(page, ["ready", "error"]);
    check(st.state === "ready", `page opened ${env.SCENE} by HTTP Range (${st.error || "ok"})`);
    await page.evaluate(() => { const c = document.getElementById("c"); c.style.position = "fixed"; c.style.left = "0px"; c.style.top = "0px"; c.style.margin = "0"; });
    const shot = await page.screenshot({ path: `${outDir}/screenshot.png`, clip: { x: 0, y: 0, width: W, height: H } });
    const cpu = fs.readFileSync(env.REF);
    const psnr = await page.evaluate(pagePsnr, [shot.toString("base64"), cpu.toString("base64")]);
    const floor = +(env.PSNR_FLOOR || 50);
    console.log(`screenshot ${outDir}/screenshot.png vs CPU renderer ${env.REF}: PSNR ${psnr.psnr?.toFixed(2)} dB (${psnr.w}x${psnr.h}, largest channel difference ${psnr.maxd}) ${psnr.error || ""}`);
    check(psnr.psnr >= floor, `screenshot PSNR >= ${floor} dB against the CPU renderer`);

    // 3. Playback at the file's fps: frames shown and dropped.
    // Small canvas: headless chromium rasterises WebGL2 on the CPU (SwiftShader), seconds per
    // 640x480 frame of 45k splats on 2 cores; the test checks the player's frame accounting.
    await page.goto(`${base}/target/web/index.html?file=${env.PLAY_FILE}&width=160&height=120`);
    st = await waitState(page, ["ready", "error"]);
    check(st.state === "ready", `page opened ${env.PLAY_FILE}`);
    // The page's thread while playing: the longest gap between 10 ms timer ticks (decoding runs
    // in the worker; what is left on this thread is the WebGL2 draw).
    await page.evaluate(() => { window.gap = { last: performance.now(), max: 0 }; window.gapTimer = setInterval(() => { const t = performance.now(); window.gap.max = Math.max(window.gap.max, t - window.gap.last); window.gap.last = t; }, 10); });
    await page.click("#play");
    await page.waitForTimeout(4000);
    st = await page.evaluate(() => { const p = window.dlgsPlayer; p.pause(); clearInterval(window.gapTimer); p.onframe(p); return { ...JSON.parse(JSON.stringify(window.dlgsStatus)), shown: p.stats.shown, dropped: p.stats.dropped, gap: window.gap.max, frameMs: p.stats.frameMs.slice(-20), drawMs: p.stats.drawMs.slice(-20) }; });
    const stats = await page.evaluate(() => document.getElementById("stats").textContent);
    console.log(`playback 4 s: ${stats.replace(/\n/g, " | ")}`);
    const mean = (a) => (a.length ? a.reduce((x, y) => x + y, 0) / a.length : NaN);
    console.log(`page thread while playing: longest gap between 10 ms timer ticks ${st.gap.toFixed(0)} ms (frame decode in the worker ${mean(st.frameMs).toFixed(1)} ms, draw on the page ${mean(st.drawMs).toFixed(1)} ms)`);
    check(st.shown >= 2 && st.shown + st.dropped >= 30, `playback reports frames shown ${st.shown} and dropped ${st.dropped} (4 s at ${st.info.fps} fps)`);

    // Seek to the last GOP (the bytes of GOPs played before are dropped), then back to GOP 0
    // (fetched again by Range).
    const seek = await page.evaluate(async () => {
      const p = window.dlgsPlayer; const r0 = p.dec.stats.requests;
      await p.showFrame(p.info.duration - 0.2); await p.showFrame(0.2);
      const s = await p.status();
      return { t: p.t, requests: s.stats.requests - r0, held: s.fetched };
    });
    check(Math.abs(seek.t - 0.2) < 1e-9 && seek.requests >= 1, `seek to the last GOP and back to GOP 0: ${seek.requests} Range requests, ${seek.held} bytes held`);

    // 4. A server that ignores Range: the player falls back to the whole file.
    await page.goto(`${baseNoRange}/target/web/index.html?file=${env.PLAY_FILE}&width=${W}&height=${H}`);
    st = await waitState(page, ["ready", "error"]);
    const s4 = await page.evaluate(() => document.getElementById("stats").textContent);
    check(st.state === "ready" && s4.includes("whole file"), `server without Range: whole-file fallback (${s4.split("\n")[2]})`);

    // 5. An HEVC file gives the typed error in the page.
    await page.goto(`${base}/target/web/index.html?file=/format-spec/vectors/valid/lod3-dynamic-hevc.dlgs`);
    st = await waitState(page, ["ready", "error"]);
    check(st.state === "error" && st.error.startsWith("HevcFeatures:"), `HEVC file refused in the page: ${st.error}`);

    // 6. Language relevance view renders (the scene's language features against a code).
    await page.goto(`${base}/target/web/index.html?file=${env.SCENE}&width=${W}&height=${H}`);
    st = await waitState(page, ["ready", "error"]);
    const lang = await page.evaluate(async () => {
      const p = window.dlgsPlayer; p.setQuery([1, 0, 0], 0); p.setMode("language"); await p.showFrame(0.5);
      const px = p.renderer.pixels(); let nonWhite = 0;
      for (let i = 0; i < px.length; i += 4) if (px[i] < 250 || px[i + 1] < 250 || px[i + 2] < 250) nonWhite++;
      const s = await p.status();
      return { nonWhite, error: p.error || null, lw: s.langWidth, laed: s.laedDims };
    });
    // 7. A Scaffold-GS file (camera-dependent neural Gaussians) in the page against the CPU
    // renderer, same camera and time.
    await page.goto(`${base}/target/web/index.html?file=${env.SCAFFOLD}&camera=${env.SCAFFOLD_CAMS}&view=0&width=${W}&height=${H}&t=${env.SCAFFOLD_T}`);
    st = await waitState(page, ["ready", "error"]);
    check(st.state === "ready" && st.drawn > 0, `Scaffold-GS file opened and drawn (${st.error || `${st.drawn} neural Gaussians`})`);
    await page.evaluate(() => { const c = document.getElementById("c"); c.style.position = "fixed"; c.style.left = "0px"; c.style.top = "0px"; c.style.margin = "0"; });
    const sshot = await page.screenshot({ path: `${outDir}/scaffold.png`, clip: { x: 0, y: 0, width: W, height: H } });
    const spsnr = await page.evaluate(pagePsnr, [sshot.toString("base64"), fs.readFileSync(env.SCAFFOLD_REF).toString("base64")]);
    console.log(`Scaffold-GS screenshot ${outDir}/scaffold.png vs CPU renderer ${env.SCAFFOLD_REF}: PSNR ${spsnr.psnr?.toFixed(2)} dB (largest channel difference ${spsnr.maxd}) ${spsnr.error || ""}`);
    check(spsnr.psnr >= floor, `Scaffold-GS screenshot PSNR >= ${floor} dB against the CPU renderer`);
    // Without a camera: the default orbit around the anchors (as the CLI's orbit cameras).
    await page.goto(`${base}/target/web/index.html?file=${env.SCAFFOLD}&width=160&height=120`);
    st = await waitState(page, ["ready", "error"]);
    check(st.state === "ready" && st.drawn > 1000, `Scaffold-GS file from the default orbit around its anchors (${st.error || `${st.drawn} neural Gaussians`})`);

    // ... and a query in the LAED decoder's output space (vector tiny-laed: 3 -> 8 -> 16 decoder,
    // two negatives): the reference's relevance score through the cosine table.
    await page.goto(`${base}/web/player/test/test.html`);
    await page.waitForFunction(() => window.testReady);
    const laed = await page.evaluate(async () => {
      const { initWasm, open_bytes, f32 } = window.P; await initWasm();
      const p = open_bytes(new Uint8Array(await (await fetch("/format-spec/vectors/valid/tiny-laed.dlgs")).arrayBuffer()));
      p.frame(0, 0, 0, -3, true);
      const dims = p.laed_dims();
      const e = new Float32Array(dims).map((_, i) => Math.sin(i + 1));
      p.set_query(e, 1);
      const n = p.prepare_draw(new Float32Array([1, 0, 0, 0, 1, 0, 0, 0, 1]), new Float32Array([0, 0, -3]), 1);
      const rgb = Array.from(f32(p.splats_ptr(), n * 16)).filter((_, i) => i % 16 >= 12 && i % 16 < 15);
      return { dims, n, finite: rgb.every(Number.isFinite) };
    });
    console.log(`LAED query on tiny-laed: decoder output ${laed.dims} dims, ${laed.n} Gaussians coloured, finite ${laed.finite}`);
    check(lang.nonWhite > 1000 && !lang.error && laed.dims === 16 && laed.finite, `language relevance view drawn (${lang.nonWhite} non-background pixels; language width ${lang.lw}, LAED output ${lang.laed})`);
  } else {
    // Measurements: decode time per GOP and frames/s in the page, time to first frame throttled.
    await page.goto(`${base}/web/player/test/test.html`);
    await page.waitForFunction(() => window.testReady);
    const m = await page.evaluate(async (file) => {
      const { initWasm, open_bytes } = window.P; await initWasm();
      const bytes = new Uint8Array(await (await fetch(file)).arrayBuffer());
      const p = open_bytes(bytes); const info = JSON.parse(p.info());
      const gop = [];
      for (let round = 0; round < 2; round++) for (let g = 0; g < info.gop_count; g++) {
        const t = performance.now(); p.decode_gop(g); gop.push(performance.now() - t);
      }
      const cam = [0.0, 0.0, -3.0];
      const fps = (lang, n) => {
        p.frame(0, ...cam, lang);
        const t = performance.now();
        for (let i = 0; i < n; i++) p.frame(Math.min((i + 1) / info.fps, 1.99), ...cam, lang);
        return (n * 1000) / (performance.now() - t);
      };
      p.decode_gop(0);
      const colour = fps(false, 59), language = fps(true, 59);
      const w2c = new Float32Array([1, 0, 0, 0, 1, 0, 0, 0, 1]);
      const t = performance.now(); for (let i = 0; i < 10; i++) p.prepare_draw(w2c, new Float32Array(cam), 0);
      const sort = (performance.now() - t) / 10;
      return { info, gop, colour, language, sort, size: bytes.length };
    }, env.MEASURE_FILE);
    const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
    console.log(`MEASURE file ${env.MEASURE_FILE}: ${m.size} B, ${m.info.n_static} static + ${m.info.n_dynamic} dynamic, ${m.info.gop_count} GOPs of ${m.info.gop_length} frames`);
    console.log(`MEASURE wasm decode GOP (canonical + time features + decoders): ${m.gop.map((x) => x.toFixed(0)).join(", ")} ms, median ${med(m.gop).toFixed(0)} ms`);
    console.log(`MEASURE wasm frame_at (merged buffers): ${m.colour.toFixed(1)} frames/s colour, ${m.language.toFixed(1)} with language (1 thread)`);
    console.log(`MEASURE wasm depth sort + pack per frame: ${m.sort.toFixed(1)} ms`);
    // End to end in the page (decode + sort + WebGL2 on SwiftShader, CPU): frames/s while playing.
    await page.goto(`${base}/target/web/index.html?file=${env.MEASURE_FILE}&width=320&height=240`);
    let st = await waitState(page, ["ready", "error"], 300000);
    const e2e = await page.evaluate(async () => {
      const p = window.dlgsPlayer; const n = 5; const t = performance.now();
      for (let i = 1; i <= n; i++) { await p.showFrame(i / p.info.fps); p.renderer.pixels(); }
      return { fps: (n * 1000) / (performance.now() - t), frame: p.stats.frameMs.slice(-n), draw: p.stats.drawMs.slice(-n).map((d, i) => d + p.stats.sortMs.slice(-n)[i]) };
    });
    const avg = (a) => a.reduce((x, y) => x + y, 0) / a.length;
    console.log(`MEASURE page end to end (frame + sort + WebGL2 draw, SwiftShader, each frame read back) at 320x240: ${e2e.fps.toFixed(1)} frames/s (frame ${avg(e2e.frame).toFixed(1)} ms, sort+draw ${avg(e2e.draw).toFixed(1)} ms)`);
    for (const file of (env.TTFF_FILES || "").split(",").filter(Boolean)) {
      const p2 = await ctx.newPage();
      const cdp = await ctx.newCDPSession(p2);
      await cdp.send("Network.enable");
      await cdp.send("Network.setCacheDisabled", { cacheDisabled: true });
      await cdp.send("Network.emulateNetworkConditions", { offline: false, latency: 40, downloadThroughput: 20e6 / 8, uploadThroughput: 20e6 / 8 });
      await p2.goto(`${base}/target/web/index.html?file=${file}&width=640&height=480`);
      const s = await waitState(p2, ["ready", "error"], 600000);
      const fetched = await p2.evaluate(() => document.getElementById("stats").textContent.split("\n")[2]);
      console.log(`MEASURE time to first frame at 20 Mbit/s, 40 ms latency (CDP), ${file}: ${s.firstFrameAt?.toFixed(0)} ms from navigation (page + wasm + header/index + GOP 0 + decode + draw), ${s.ttff?.toFixed(0)} ms from open; ${fetched}`);
      await p2.close();
    }
  }
} catch (e) {
  console.log("FAIL exception:", e.stack || e);
  failures++;
}
await ctx.close();
fs.rmSync(userDataDir, { recursive: true, force: true });
console.log(failures ? `${failures} browser test(s) FAILED` : "all browser tests passed");
process.exit(failures ? 1 : 0);
