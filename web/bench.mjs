#!/usr/bin/env node
// Speed of amc-wasm in headless Chromium vs native, on the same frames.
//
//   node web/bench.mjs [--clip ../shared/data/karma/karma.mp4] [--n 600] [--n720 150] [--reps 3]
//                      [--formats RGBA,I420] [--workers 1,2]
//
// Decodes the clip with ffmpeg to raw RGBA and raw I420 (`-pix_fmt yuv420p`) at
// 320x180 and 1280x720, serves web/dist and the frames from a throwaway local
// HTTP server, runs web/dist/bench.html in headless Chromium (the stabilizer in
// a Web Worker, one thread) and the same frames through the native
// single-thread example (amc-wasm/examples/native_bench.rs), per format.
// The browser also times the page's WebCodecs path without decoder/encoder
// (`vf_fps`: I420 VideoFrames copyTo'd into the module, as is or converted to
// RGBA, stabilized, each output wrapped in a VideoFrame) and splits its time.
// --workers: the browser runs with one worker and with the page's render
// share (web/src/render-share.js: each output drawn by one of N workers, every
// worker fed every frame); the native example is one thread in every row.
// Each is run --reps times, alternating, and the best run is kept (the machine
// is shared and noisy; the best run is the least disturbed one).
// Needs web/dist (web/build.sh), ffmpeg, /usr/bin/chromium (or $CHROMIUM).
import { chromium } from 'playwright-core';
import { createServer } from 'node:http';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, existsSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, dirname, extname, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const root = resolve(here, '..');
const arg = (name, def) => { const i = process.argv.indexOf(`--${name}`); return i > 0 ? process.argv[i + 1] : def; };
const clip = resolve(arg('clip', join(root, '../shared/data/karma/karma.mp4')));
const reps = Number(arg('reps', 3));
const formats = arg('formats', 'RGBA,I420').split(',').map((f) => f.trim().toUpperCase());
for (const f of formats) if (f !== 'RGBA' && f !== 'I420') throw new Error(`--formats: ${f} (allowed: RGBA, I420)`);
const workerCounts = arg('workers', '1,2').split(',').map(Number);
for (const n of workerCounts) if (!(Number.isInteger(n) && n >= 1 && n <= 16)) throw new Error(`--workers: ${n} (allowed: 1 to 16)`);
const sizes = [
  { w: 320, h: 180, n: Number(arg('n', 600)), src: 120 },
  { w: 1280, h: 720, n: Number(arg('n720', 150)), src: 40 },
];
const dist = join(here, 'dist');
if (!existsSync(join(dist, 'bench.html'))) throw new Error('web/dist missing: run web/build.sh first');

const tmp = mkdtempSync(join(tmpdir(), 'amc-bench-'));
const mime = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.css': 'text/css', '.wasm': 'application/wasm' };
const server = createServer((req, res) => {
  const url = new URL(req.url, 'http://x');
  const file = url.pathname.startsWith('/frames/') ? join(tmp, url.pathname.slice(8)) : join(dist, url.pathname === '/' ? 'index.html' : url.pathname);
  if (!file.startsWith(tmp) && !file.startsWith(dist)) { res.writeHead(403).end(); return; }
  try {
    const body = readFileSync(file);
    res.writeHead(200, { 'Content-Type': mime[extname(file)] || 'application/octet-stream' }).end(body);
  } catch { res.writeHead(404).end(); }
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const base = `http://127.0.0.1:${server.address().port}`;

const cpu = (() => { try { return readFileSync('/proc/cpuinfo', 'utf8').match(/model name\s*:\s*(.*)/)[1]; } catch { return 'unknown CPU'; } })();
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run'],
});
const rows = [];
try {
  for (const s of sizes) {
    // The same frames in both layouts (the I420 ones also feed the VideoFrame path).
    const raw = { RGBA: `${s.w}x${s.h}.rgba`, I420: `${s.w}x${s.h}.yuv` };
    for (const [fmt, pix] of [['RGBA', 'rgba'], ['I420', 'yuv420p']]) {
      execFileSync('ffmpeg', ['-v', 'error', '-y', '-i', clip, '-frames:v', String(s.src), '-vf', `scale=${s.w}:${s.h}`, '-pix_fmt', pix, '-f', 'rawvideo', join(tmp, raw[fmt])]);
    }
    for (const fmt of formats) for (const workers of workerCounts) {
      const name = raw[fmt];
      let web = null, native = null;
      for (let r = 0; r < reps; r++) {
        const page = await browser.newPage();
        await page.goto(`${base}/bench.html?frames=/frames/${name}&w=${s.w}&h=${s.h}&n=${s.n}&fov=70&fmt=${fmt}&vf=/frames/${raw.I420}&workers=${workers}`);
        await page.waitForFunction(() => ['done', 'error'].includes(document.body.dataset.state), null, { timeout: 600000 });
        const wr = await page.evaluate(() => window.benchResult);
        await page.close();
        if (wr.error) throw new Error(`browser: ${wr.error}`);
        const out = execFileSync('cargo', ['run', '-q', '--release', '-p', 'amc-wasm', '--example', 'native_bench', '--', join(tmp, name), String(s.w), String(s.h), '70', String(s.n), fmt.toLowerCase()], { cwd: root, encoding: 'utf8' });
        const nr = JSON.parse(out.trim().split('\n').pop());
        if (!web || wr.fps > web.fps) web = { ...wr, vf_fps: Math.max(wr.vf_fps, web ? web.vf_fps : 0), vf_ms_per_frame: !web || wr.vf_fps > web.vf_fps ? wr.vf_ms_per_frame : web.vf_ms_per_frame };
        else if (wr.vf_fps > web.vf_fps) web = { ...web, vf_fps: wr.vf_fps, vf_ms_per_frame: wr.vf_ms_per_frame };
        if (!native || nr.fps > native.fps) native = nr;
      }
      const ms = web.vf_ms_per_frame;
      rows.push({
        size: `${s.w}x${s.h}`, format: fmt, workers, frames: s.n, browser_fps: +web.fps.toFixed(1), native_fps: +native.fps.toFixed(1),
        ratio: +(native.fps / web.fps).toFixed(2), browser_vf_fps: +web.vf_fps.toFixed(1),
        vf_ms: `copyTo ${ms.copyTo.toFixed(2)} + stab ${ms.stabilize.toFixed(2)} + frame ${ms.output_frame.toFixed(2)}`, simd: web.simd,
      });
    }
  }
} finally {
  await browser.close();
  server.close();
  rmSync(tmp, { recursive: true, force: true });
}
console.log(`clip: ${clip}; CPU: ${cpu}, ${(await import('node:os')).cpus().length} cores; best of ${reps}; load average ${(await import('node:os')).loadavg().map((x) => x.toFixed(1)).join(' ')}`);
console.table(rows);
console.log(JSON.stringify(rows));
