// End to end in headless Chromium against `amc serve` (serving web/dist):
// the page stabilizes cup.mp4 in the browser (and karma.mp4 with its own GoPro
// gyro track); clips it cannot read (HEVC, AVI,
// not a video) are offered to the job API; its settings are the CLI's options;
// the Live tab shows a looped source; against a server with API keys
// (`--auth-keys`) the page asks for a key and watches the feed through
// tickets; no page breaks the server's Content-Security-Policy. Screenshots
// land in web/test-artifacts/.
// Run: node --test --test-concurrency=1 test/e2e.test.mjs   (after ./build.sh)
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { createHash, randomBytes } from 'node:crypto';
import { mkdtempSync, readFileSync, renameSync, rmSync, writeFileSync } from 'node:fs';
import { cpus, tmpdir } from 'node:os';
import { join } from 'node:path';
import { startServer, launch, shot, ffprobeFrames, rmsFrameChange, streamTypes, dataDir, artifacts, root, amcBin } from './helpers.mjs';

const cup = join(dataDir, 'cup', 'cup.mp4');
// A GoPro HERO5's clip with its GPMF track (gyro ~400 Hz): 12 s, 362 frames.
const karma = join(dataDir, 'karma', 'karma.mp4');
let server, browser, tmp;
/** Whether the test gives the pages their Content-Security-Policy (a server that sends none: a build before it did). */
let injectCsp = false;

before(async () => {
  tmp = mkdtempSync(join(tmpdir(), 'amc-e2e-'));
  server = await startServer(['--live-source', cup, '--live-loop']);
  injectCsp = !(await fetch(`${server.url}/`)).headers.get('content-security-policy');
  // A page the test serves (below) has no network address, so Chromium's local
  // network access checks would refuse its WebSocket to 127.0.0.1: off then.
  browser = await launch(injectCsp ? ['--disable-features=LocalNetworkAccessChecks'] : []);
});

after(async () => {
  if (browser) await browser.close();
  if (server) await server.stop();
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

// The Content-Security-Policy `amc serve` sends with the page (issue "Locked doors").
const CSP = "default-src 'self'; script-src 'self' 'wasm-unsafe-eval'; worker-src 'self' blob:; " +
  "connect-src 'self' ws: wss: blob: data:; img-src 'self' blob: data:; media-src 'self' blob:; style-src 'self'; " +
  "font-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'; form-action 'self'";
/** Every CSP violation of every page of the run (checked by the last test). */
const cspViolations = [];
/** Who set the policy of the pages' files: 'server' (its own header), 'test' (a server without one). */
const cspFrom = new Set();

/**
 * Reports what breaks the page's policy into `sink`: the
 * `securitypolicyviolation` events and Chromium's "Refused to…" console
 * messages (the page's and its workers'). The page's HTML and scripts get the
 * policy as a header from the server or, where the server sends none (a
 * build before it did), from the test: the same header, never a meta tag.
 */
async function watchCsp(page, srv, sink = cspViolations) {
  const origin = new URL(srv.url).origin;
  const note = (v) => sink.push({ page: page.url(), ...v });
  await page.exposeFunction('__amcCspViolation', note);
  await page.addInitScript(() => document.addEventListener('securitypolicyviolation', (e) => window.__amcCspViolation({
    directive: e.violatedDirective, blocked: e.blockedURI, source: `${e.sourceFile}:${e.lineNumber}`, sample: e.sample,
  })));
  const onConsole = (m) => { if (/Content[- ]Security[- ]Policy/i.test(m.text())) note({ console: m.text() }); };
  page.on('console', onConsole);
  page.on('worker', (w) => w.on('console', onConsole));
  if (!injectCsp) { cspFrom.add('server'); return; }
  await page.route((u) => u.origin === origin && (u.pathname === '/' || /\.(html|m?js)$/.test(u.pathname)), async (route) => {
    const res = await route.fetch();
    const headers = res.headers();
    headers['content-security-policy'] = CSP;
    cspFrom.add('test');
    await route.fulfill({ response: res, headers });
  });
}

/** A page of `srv` with its settings form built; `setup(page)` runs before it loads (routes). */
async function newPage(srv = server, setup = null) {
  const page = await browser.newPage({ acceptDownloads: true, viewport: { width: 1280, height: 900 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('response', (r) => { if (r.status() === 404) errors.push(`404 ${r.url()}`); });
  await watchCsp(page, srv);
  if (setup) await setup(page);
  await page.goto(srv.url + '/');
  // The settings form is built from the core's option table once amc-wasm is loaded.
  await page.waitForSelector('#settings[data-ready]', { state: 'attached', timeout: 30000 });
  return { page, errors };
}

/** Opens the Advanced fold (every option of the CLI). */
const openAdvanced = (page) => page.evaluate(() => { document.getElementById('advanced').open = true; });

// amc-server's telemetry CSV header (the page's CSV starts with the same columns).
const TELEMETRY_HEADER = readFileSync(join(root, 'amc-engine/src/telemetry.rs'), 'utf8').match(/TELEMETRY_HEADER: &str = "([^"]+)"/)[1];

/** The summary table as { row label: [original, stabilized, change] }. */
const summaryTable = (page) => page.evaluate(() => Object.fromEntries([...document.querySelectorAll('#summary tbody tr')]
  .map((tr) => [tr.cells[0].textContent, [...tr.cells].slice(1).map((c) => c.textContent)])));

/** Mean brightness (0..255) of a canvas. */
const canvasMean = (page, sel) => page.evaluate((sel) => {
  const c = document.querySelector(sel);
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  let s = 0; for (let i = 0; i < d.length; i += 4) s += d[i] + d[i + 1] + d[i + 2];
  return s / (d.length / 4) / 3;
}, sel);

/** Switches the compare view and waits until its canvas has been drawn again. */
async function compareMode(page, testid) {
  const before = await page.evaluate(() => Number(document.getElementById('compare-canvas').dataset.drawn || 0));
  await page.click(`[data-testid=${testid}]`);
  // A few frames drawn: both videos have their current frame.
  await page.waitForFunction((n) => Number(document.getElementById('compare-canvas').dataset.drawn || 0) > n + 5, before, { timeout: 10000 });
}

const state = (page) => page.evaluate(() => document.body.dataset.state);
const waitState = (page, states, timeout = 300000) =>
  page.waitForFunction((s) => s.includes(document.body.dataset.state), states, { timeout });

/** Mean R, G, B (0..255) over all frames of a video, after cutting `crop` of each side. */
function meanRgb(file, crop = 0) {
  const vf = (crop > 0 ? `crop=iw*${1 - 2 * crop}:ih*${1 - 2 * crop},` : '') + 'scale=1:1:flags=area,format=rgb24';
  const raw = execFileSync('ffmpeg', ['-v', 'error', '-i', file, '-vf', vf, '-f', 'rawvideo', '-'], { maxBuffer: 1 << 26 });
  const n = Math.floor(raw.length / 3), m = [0, 0, 0];
  for (let i = 0; i < 3 * n; i++) m[i % 3] += raw[i] / n;
  return m;
}

async function download(page, name, testid = 'download') {
  const [dl] = await Promise.all([page.waitForEvent('download'), page.click(`[data-testid=${testid}]`)]);
  const file = join(tmp, name);
  await dl.saveAs(file);
  return file;
}

test('drop cup.mp4: every frame stabilized in the browser; the MP4 download has all frames and changes less', async () => {
  const { page, errors } = await newPage();
  assert.equal(await state(page), 'idle');
  assert.match(await page.getAttribute('link[rel=icon]', 'href'), /^data:image\/svg\+xml,/);
  // Every form control has a label.
  const unlabelled = await page.evaluate(() => [...document.querySelectorAll('input, select')]
    .filter((e) => !e.labels?.length && !e.getAttribute('aria-label')).map((e) => e.id || e.name));
  assert.deepEqual(unlabelled, []);
  await shot(page, 'clip-1-idle');
  // A real drop: a DataTransfer holding the file, dispatched on the drop zone.
  const b64 = readFileSync(cup).toString('base64');
  const dt = await page.evaluateHandle((data) => {
    const bin = Uint8Array.from(atob(data), (c) => c.charCodeAt(0));
    const d = new DataTransfer();
    d.items.add(new File([bin], 'cup.mp4', { type: 'video/mp4' }));
    return d;
  }, b64);
  await page.dispatchEvent('#drop', 'drop', { dataTransfer: dt });
  await page.waitForFunction(() => document.body.dataset.state === 'processing' && document.getElementById('progress').value > 0, null, { timeout: 60000 });
  await shot(page, 'clip-2-processing');
  await waitState(page, ['done', 'error']);
  await shot(page, 'clip-3-done');
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  // Chromium's software H.264 decoder gives I420: the frames went through the module as planes.
  assert.equal(await page.evaluate(() => document.body.dataset.pixelFormat), 'I420');
  // Every core at work: the outputs shared out among one worker per core (at most 4).
  assert.equal(await page.evaluate(() => document.body.dataset.workers), String(Math.min(cpus().length, 4)));
  // Speeds the page measured (end to end: decode + stabilize + metrics + encode; the stabilizer alone).
  writeFileSync(join(artifacts, 'clip-speed.json'), JSON.stringify(await page.evaluate(() => ({
    pixelFormat: document.body.dataset.pixelFormat, fps: Number(document.body.dataset.fps), stabFps: Number(document.body.dataset.stabFps),
    status: document.getElementById('status-text').textContent,
  })), null, 1));
  const input = ffprobeFrames(cup);
  assert.equal(Number(await page.evaluate(() => document.body.dataset.frames)), input.frames);
  // fov auto, the CLI's default: a first pass estimated the field of view (or fell back to 70 degrees with a warning).
  const { fov, fovNote } = await page.evaluate(() => ({ fov: Number(document.body.dataset.fov), fovNote: document.body.dataset.fovNote }));
  assert.ok(fov > 0 && fov <= 179, String(fov));
  assert.match(fovNote, /^field of view \d+\.\d° \(estimated from 90 frames\)$|^warning: the footage does not pin down the focal length/);
  if (fovNote.startsWith('warning')) assert.equal(fov, 70);
  const file = await download(page, 'cup-stabilized.mp4');
  const out = ffprobeFrames(file);
  assert.equal(out.codec, 'h264');
  assert.equal(out.frames, input.frames, 'the download has every input frame');
  assert.deepEqual([out.width, out.height], [640, 480], 'zoom auto keeps the input size');
  assert.deepEqual(streamTypes(file).sort(), ['audio', 'video'], "the original's AAC audio is copied");
  // The whole input vs the stabilized output (zoom auto: about the same picture).
  const rin = rmsFrameChange(cup, 0), rout = rmsFrameChange(file);
  writeFileSync(join(artifacts, 'clip-rms.json'), JSON.stringify({ input: rin, output: rout }, null, 1));
  assert.ok(rout.rms < rin.rms, `RMS frame change: output ${rout.rms.toFixed(4)} vs input ${rin.rms.toFixed(4)}`);
  // Colours kept through the planar path (planes in order, same range): mean R, G, B of the clip.
  const cin = meanRgb(cup, 0.025), cout = meanRgb(file);
  assert.ok(cin.every((v, i) => Math.abs(v - cout[i]) < 8), `mean RGB: output ${cout.map((v) => v.toFixed(1))} vs input ${cin.map((v) => v.toFixed(1))}`);
  // The plot and the side-by-side players are there, both players the same size.
  assert.equal(await page.isVisible('#plot'), true);
  assert.ok(await page.evaluate(() => document.getElementById('stab').src.startsWith('blob:')));
  assert.ok(await page.evaluate(() => document.getElementById('orig').src.startsWith('blob:')));
  const [bo, bs] = [await page.locator('#orig').boundingBox(), await page.locator('#stab').boundingBox()];
  assert.ok(Math.abs(bo.width - bs.width) < 1 && Math.abs(bo.height - bs.height) < 1, `original ${bo.width}x${bo.height}, stabilized ${bs.width}x${bs.height}`);
  assert.ok(bo.width > 300, `players ${bo.width} px wide`);
  // The plot: all five series (the zoom on its own axis), a legend outside the canvas naming each.
  assert.equal(await page.getAttribute('#plot', 'data-series'), 'est,view,nf_in,nf_out,zoom');
  const legendText = await page.textContent('[data-testid=plot-legend]');
  for (const k of ['camera (estimate) speed', 'view speed', 'normal flow, input', 'normal flow, output', 'zoom (outer right axis)']) assert.ok(legendText.includes(k), legendText);
  // The summary: a table with units and short numbers; the input's angular speed is the camera's (not 0).
  const sum = await summaryTable(page);
  assert.ok(!(await page.textContent('#summary')).includes('{'), 'no JSON dump');
  assert.doesNotMatch(await page.textContent('#summary'), /\d\.\d{5,}/, 'no long decimals');
  const speed = Object.entries(sum).find(([k]) => k.startsWith('Angular speed'));
  assert.ok(speed && Number(speed[1][0]) > 0 && Number(speed[1][1]) > 0, JSON.stringify(sum));
  assert.ok(Number(speed[1][1]) < Number(speed[1][0]), 'the view turns slower than the camera');
  const nf = sum['RMS normal flow (px/frame)'];
  assert.ok(Number(nf[1]) < Number(nf[0]), JSON.stringify(nf));
  assert.match(sum['Size (pixels)'][1], /^640 × 480$/);
  assert.match(Object.entries(sum).find(([k]) => k.startsWith('Pixels covered'))[1][1], /^\d+\.\d % \(\d+\.\d %\)$/);
  // The telemetry CSV: the CLI's columns in the CLI's order, one row per frame.
  const csv = readFileSync(await download(page, 'cup-telemetry.csv', 'telemetry-download'), 'utf8').trim().split('\n');
  assert.ok(csv[0].startsWith('frame,t,rx,ry,rz,vx,vy,vz,'), csv[0]);
  assert.ok(csv[0].startsWith(TELEMETRY_HEADER + ','), csv[0]);
  assert.equal(csv.length - 1, input.frames);
  assert.deepEqual(csv.slice(1).map((l) => Number(l.split(',')[0])), [...Array(input.frames).keys()]);
  assert.ok(csv.slice(1).every((l) => l.split(',').length === csv[0].split(',').length));
  // The A/B wipe and the difference view: the same frame, original (central crop) vs stabilized.
  await page.evaluate(() => { const s = document.getElementById('seek'); s.value = '0.5'; s.dispatchEvent(new Event('input')); });
  await page.waitForFunction(() => ['orig', 'stab'].every((id) => { const v = document.getElementById(id); return !v.seeking && v.readyState >= 2; }), null, { timeout: 10000 });
  await compareMode(page, 'compare-wipe');
  assert.equal(await page.isVisible('[data-testid=compare-canvas]'), true);
  assert.equal(await page.isVisible('#players'), false);
  assert.deepEqual(await page.evaluate(() => { const c = document.getElementById('compare-canvas'); return [c.width, c.height]; }), [640, 480]);
  const wipeMean = await canvasMean(page, '#compare-canvas');
  assert.ok(wipeMean > 20, `wipe mean ${wipeMean}`);
  await shot(page, 'clip-4-wipe');
  await compareMode(page, 'compare-diff');
  const diffMean = await canvasMean(page, '#compare-canvas');
  assert.ok(diffMean < wipeMean, `difference ${diffMean} vs wipe ${wipeMean}`);
  await shot(page, 'clip-5-difference');
  assert.deepEqual(errors, []);
  await page.close();
});

test('planar VideoFrames in Chromium: I420 and NV12 copied with the page\'s layout (odd and padded sizes) stabilize like the raw planes; I420 output frames', async () => {
  const { page, errors } = await newPage();
  const res = await page.evaluate(async () => {
    const wasm = await import('/pkg/amc_wasm.js');
    await wasm.default();
    const { pixelPath, copyOptions } = await import('/pixels.js');
    const out = [];
    // Visible size, coded size (rows padded, as decoders do), frames.
    for (const [w, h, cwid, chei] of [[160, 90, 160, 90], [161, 91, 176, 96], [320, 180, 320, 192]]) {
      const cw = (w + 1) >> 1, ch = (h + 1) >> 1, ccw = cwid >> 1, cch = chei >> 1;
      const a = new wasm.Stabilizer(w, h, '{}', 70, 'I420');
      const b = new wasm.Stabilizer(w, h, '{}', 70, 'I420');
      const c = new wasm.Stabilizer(w, h, '{}', 70, 'NV12');
      const r = { size: `${w}x${h}`, coded: `${cwid}x${chei}`, paths: [], equal: 0, frames: 0, roundTrip: 0 };
      for (let i = 0; i < 6; i++) {
        // Packed I420 planes of a moving pattern, and the same frame in coded-size I420 and NV12 buffers.
        const val = (x, y, k) => (128 + 60 * Math.sin((x + 2 * i) * 0.21 + k) * Math.cos((y - i) * 0.17)) | 0;
        const packed = new Uint8Array(w * h + 2 * cw * ch);
        const i420 = new Uint8Array(cwid * chei + 2 * ccw * cch), nv12 = new Uint8Array(cwid * chei + 2 * ccw * cch);
        for (let y = 0; y < h; y++) for (let x = 0; x < w; x++) {
          packed[y * w + x] = i420[y * cwid + x] = nv12[y * cwid + x] = val(x, y, 0);
        }
        for (let y = 0; y < ch; y++) for (let x = 0; x < cw; x++) {
          const u = val(2 * x, 2 * y, 1) >> 1, v = 255 - (val(2 * x, 2 * y, 2) >> 1);
          packed[w * h + y * cw + x] = u; packed[w * h + cw * ch + y * cw + x] = v;
          i420[cwid * chei + y * ccw + x] = u; i420[cwid * chei + ccw * cch + y * ccw + x] = v;
          nv12[cwid * chei + y * 2 * ccw + 2 * x] = u; nv12[cwid * chei + y * 2 * ccw + 2 * x + 1] = v;
        }
        const init = { codedWidth: cwid, codedHeight: chei, visibleRect: { x: 0, y: 0, width: w, height: h }, timestamp: i };
        const fi = new VideoFrame(i420, { ...init, format: 'I420' }), fn = new VideoFrame(nv12, { ...init, format: 'NV12' });
        r.paths.push(pixelPath(fi), pixelPath(fn));
        a.push(packed, i / 30);
        await fi.copyTo(b.inputBuffer(), copyOptions('I420', w, h));
        b.pushInput(i / 30);
        await fn.copyTo(c.inputBuffer(), copyOptions('NV12', w, h));
        c.pushInput(i / 30);
        fi.close(); fn.close();
        const oa = a.output(), ob = b.output(), oc = c.output();
        r.frames++;
        if (oa.length && oa.every((x, k) => x === ob[k] && x === oc[k])) r.equal++;
        // The output as the encoder gets it: an I420 VideoFrame of the (possibly odd) output size.
        const copy = oc.slice();
        const of = new VideoFrame(copy, { format: c.outputFormat, codedWidth: c.outputWidth, codedHeight: c.outputHeight, timestamp: i });
        const back = new Uint8Array(copy.length);
        await of.copyTo(back, copyOptions('I420', c.outputWidth, c.outputHeight));
        of.close();
        if (back.every((x, k) => x === copy[k])) r.roundTrip++;
      }
      r.out = `${c.outputWidth}x${c.outputHeight} ${c.outputFormat}`;
      a.free(); b.free(); c.free();
      out.push(r);
    }
    return out;
  });
  for (const r of res) {
    assert.deepEqual([...new Set(r.paths)].sort(), ['I420', 'NV12'], JSON.stringify(r));
    assert.equal(r.equal, r.frames, `copyTo into WASM = raw planes: ${JSON.stringify(r)}`);
    assert.equal(r.roundTrip, r.frames, `I420 output VideoFrame round trip: ${JSON.stringify(r)}`);
  }
  assert.deepEqual(errors, []);
  await page.close();
});

test('WebM download (VP9) with the same frame count', async () => {
  const { page } = await newPage();
  await page.selectOption('#format', 'webm');
  await openAdvanced(page);
  await page.fill('#n_avg', '3');
  await page.selectOption('#mode', 'saccade');
  await page.selectOption('#zoom', 'none'); // the paper's fixed margin
  await page.fill('#margin', ''); // empty: the default, 0.125
  await page.setInputFiles('[data-testid=file-input]', cup);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  const file = await download(page, 'cup-stabilized.webm');
  const out = ffprobeFrames(file);
  assert.ok(['vp9', 'vp8', 'av1'].includes(out.codec), out.codec);
  assert.equal(out.frames, ffprobeFrames(cup).frames);
  assert.deepEqual([out.width, out.height], [480, 360], 'an empty margin is the default 0.125');
  assert.ok('Saccades' in (await summaryTable(page)), 'saccade mode reports its saccades');
  // Saccade mode builds each output on the previous one's: one worker draws them all.
  assert.equal(await page.evaluate(() => document.body.dataset.workers), '1');
  await page.close();
});

test('render helpers that cannot start: the clip is stabilized in one worker', async () => {
  // The helpers' script missing from the server, as in a broken deployment.
  // Hidden on disk, not by a route: the helpers are workers started by the
  // page's worker, and Chromium (156) fetches a nested worker's script where
  // Playwright's routes never see it.
  const script = join(root, 'web', 'dist', 'share-worker.js');
  renameSync(script, `${script}.hidden`);
  try {
    const { page } = await newPage();
    await page.setInputFiles('[data-testid=file-input]', cup);
    await waitState(page, ['done', 'error']);
    assert.equal(await state(page), 'done', await page.textContent('#error'));
    assert.equal(await page.evaluate(() => document.body.dataset.workers), '1');
    assert.equal(Number(await page.evaluate(() => document.body.dataset.frames)), ffprobeFrames(cup).frames);
    await page.close();
  } finally {
    renameSync(`${script}.hidden`, script);
  }
});

test('zoom static: a first pass finds one zoom for the clip, held on every frame, no border', async () => {
  const { page } = await newPage();
  await openAdvanced(page);
  await page.selectOption('#zoom', 'static');
  await page.setInputFiles('[data-testid=file-input]', cup);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  const csv = readFileSync(await download(page, 'cup-static-telemetry.csv', 'telemetry-download'), 'utf8').trim().split('\n');
  const head = csv[0].split(',');
  const col = (name) => csv.slice(1).map((l) => Number(l.split(',')[head.indexOf(name)]));
  const zoom = col('zoom');
  assert.ok(zoom.every((z) => z === zoom[0] && z >= 1 && z <= 1 / 0.85 + 1e-6), `zoom ${zoom[0]}..${Math.max(...zoom)}`);
  assert.ok(col('uncovered').every((u) => u === 0), 'no uncovered pixel');
  await page.close();
});

test('readout: checked as typed; auto makes a first pass and the stabilizer runs with its estimate (or 0 with a warning)', async () => {
  const { page } = await newPage();
  await openAdvanced(page);
  await page.fill('#readout_ms', '150');
  assert.match(await page.textContent('[data-testid=form-error]'), /Readout time \(--readout-ms\): 150 is out of range \(allowed: 0\.\.=100 or auto/);
  await page.fill('#readout_ms', 'auto');
  assert.equal(await page.isVisible('[data-testid=form-error]'), false);
  await page.setInputFiles('[data-testid=file-input]', cup);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  const { note, ms } = await page.evaluate(() => ({ note: document.body.dataset.readoutNote, ms: Number(document.body.dataset.readoutMs) }));
  assert.ok(ms >= 0 && ms <= 100, String(ms));
  if (/^warning:/.test(note)) {
    assert.equal(ms, 0, note);
    assert.match(await page.textContent('#status-text'), /Warning: the clip does not pin down the rolling-shutter readout/);
  } else {
    assert.match(note, /^readout \d+\.\d ms \(estimated from \d+ frames\)$/);
    assert.equal(ms.toFixed(1), note.match(/readout (\d+\.\d)/)[1]);
  }
  // A number goes to the core as it is.
  await page.fill('#readout_ms', '12.5');
  await page.click('#again');
  await waitState(page, ['processing']);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  assert.equal(await page.evaluate(() => document.body.dataset.readoutMs), '12.5');
  await page.close();
});

test("karma.mp4 (a GoPro's GPMF track): gyro auto reads the track in the browser, syncs and fuses it, and the summary says so; gyro off does not", async () => {
  const { page, errors } = await newPage();
  await openAdvanced(page);
  // Its lens given, as the CLI's test of the same track (a gimbal leaves little rotation to estimate it from).
  await page.fill('#fov', '90');
  assert.equal(await page.inputValue('#gyro'), 'auto');
  await page.setInputFiles('[data-testid=file-input]', karma);
  await waitState(page, ['done', 'error'], 600000);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  const g = await page.evaluate(() => ({ gyro: document.body.dataset.gyro, note: document.body.dataset.gyroNote, frames: Number(document.body.dataset.frames) }));
  assert.equal(g.gyro, 'fused', g.note);
  const m = g.note.match(/^gyro: GoPro.*, offset [+-]\d+\.\d{4} s, fused (\d+) frames$/);
  assert.ok(m, g.note);
  const frames = ffprobeFrames(karma).frames;
  assert.equal(g.frames, frames);
  assert.ok(Number(m[1]) > 0.5 * frames, g.note);
  const table = await summaryTable(page);
  assert.match(table.Gyro[1], /^GoPro.*, offset .* s, fused \d+ frames$/);
  await shot(page, 'gyro-karma-fused');
  const out = ffprobeFrames(await download(page, 'karma-gyro.mp4'));
  assert.equal(out.frames, frames);
  // gyro off: the picture alone, no gyro row.
  await page.selectOption('#gyro', 'off');
  await page.click('#again');
  await waitState(page, ['processing']);
  await waitState(page, ['done', 'error'], 600000);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  assert.equal('Gyro' in (await summaryTable(page)), false);
  assert.deepEqual(errors, []);
  await page.close();
});

test('bad settings and a file that is not a video end in the error state with a message', async () => {
  const { page } = await newPage();
  await openAdvanced(page);
  await page.fill('#n_avg', '0');
  // Checked as typed: the field is marked and named with its flag and range.
  assert.match(await page.textContent('[data-testid=form-error]'), /Averaging window \(--n-avg\): 0 is out of range \(allowed: 1\.\.=64, whole numbers; empty: the default, 6\)/);
  assert.equal(await page.getAttribute('#n_avg', 'aria-invalid'), 'true');
  await page.setInputFiles('[data-testid=file-input]', cup);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'error');
  assert.match(await page.textContent('#error'), /Not started: Averaging window \(--n-avg\) out of range/);
  assert.match(await page.textContent('[data-testid=form-error]'), /Averaging window \(--n-avg\): 0 is out of range \(allowed: 1\.\.=64/);
  await page.fill('#margin', '0.6');
  await page.fill('#fov', '180');
  const msg = await page.textContent('[data-testid=form-error]');
  assert.match(msg, /Margin \(--margin\): 0\.6 is out of range \(allowed: 0\.\.=0\.45/);
  assert.match(msg, /Field of view \(--fov\): 180 is out of range \(allowed: 0 < DEG <= 179 or auto/);
  await shot(page, 'error-settings');
  for (const [id, v] of [['margin', '0.125'], ['fov', 'auto']]) await page.fill(`#${id}`, v);
  await page.fill('#n_avg', ''); // empty: the default
  assert.equal(await page.isVisible('[data-testid=form-error]'), false);
  assert.equal(await page.isVisible('#error'), false, 'the refusal goes once the settings are fixed');
  assert.equal(await state(page), 'idle');
  assert.equal(await page.getAttribute('#n_avg', 'aria-invalid'), 'false');
  // Not a video: the page cannot read it, offers the server, and shows the server's refusal.
  const junk = join(tmp, 'junk.mp4');
  writeFileSync(junk, 'this is not a video');
  await page.setInputFiles('[data-testid=file-input]', junk);
  await page.waitForSelector('[data-testid=server-fallback]', { state: 'visible', timeout: 60000 });
  assert.equal(await state(page), 'error');
  assert.match(await page.textContent('#unsupported-text'), /junk\.mp4 is not a video this page can read in the browser/, 'the message names the file');
  await page.click('[data-testid=server-fallback]');
  await page.waitForSelector('#error', { state: 'visible', timeout: 30000 });
  assert.equal(await state(page), 'error');
  assert.match(await page.textContent('#error'), /server refused the job: .*not a video/);
  await shot(page, 'error-state');
  // Cancel while processing.
  await page.setInputFiles('[data-testid=file-input]', cup);
  await page.waitForFunction(() => document.body.dataset.state === 'processing' && document.getElementById('progress').value > 5, null, { timeout: 60000 });
  await page.click('#cancel');
  assert.equal(await state(page), 'error');
  assert.match(await page.textContent('#error'), /Cancelled/);
  await page.waitForTimeout(500);
  assert.equal(await state(page), 'error', 'a cancelled run stays cancelled');
  await page.close();
});

test('HEVC clip: the browser cannot decode it; the page offers the server and gets the result from the job API', async () => {
  const hevc = join(tmp, 'cup-hevc.mp4');
  execFileSync('ffmpeg', ['-v', 'error', '-y', '-i', cup, '-frames:v', '48', '-vf', 'scale=320:240', '-c:v', 'libx265', '-preset', 'ultrafast',
    '-x265-params', 'log-level=error', '-tag:v', 'hvc1', '-an', hevc]);
  const { page } = await newPage();
  await page.setInputFiles('[data-testid=file-input]', hevc);
  await page.waitForSelector('[data-testid=server-fallback]', { state: 'visible', timeout: 60000 });
  assert.match(await page.textContent('#unsupported-text'), /cannot decode the HEVC/i);
  await shot(page, 'hevc-1-unsupported');
  const posted = [];
  page.on('request', (r) => { if (r.method() === 'POST') posted.push(new URL(r.url())); });
  await page.click('[data-testid=server-fallback]');
  await waitState(page, ['processing', 'done', 'error'], 10000);
  await shot(page, 'hevc-2-server-processing');
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  const file = await download(page, 'cup-hevc-stabilized.mp4');
  assert.equal(ffprobeFrames(file).frames, 48);
  // The page's settings went along: all the CLI's defaults, so only the mode and the format
  // (the server's defaults are the same table's: fov auto among them).
  const q = posted[0].searchParams;
  assert.equal(posted[0].pathname, '/jobs');
  assert.equal(q.toString(), 'mode=stabilize&format=mp4');
  // The plot (speeds from the job's telemetry.csv), its CSV and the summary.
  await page.waitForSelector('#plot[data-series="est,view,zoom"]', { timeout: 10000 });
  const csv = readFileSync(await download(page, 'cup-hevc-telemetry.csv', 'telemetry-download'), 'utf8').trim().split('\n');
  assert.ok(csv[0].startsWith('frame,t,rx,ry,rz,vx,vy,vz,est_speed_dps,view_speed_dps,valid_fraction'), csv[0]);
  assert.equal(csv.length - 1, 48);
  const sum = await summaryTable(page);
  assert.equal(sum['Frames'][1], '48');
  assert.ok(Number(Object.entries(sum).find(([k]) => k.startsWith('Angular speed'))[1][0]) > 0, JSON.stringify(sum));
  // The Original slot: Chromium cannot play HEVC, so the server made a playable copy.
  await page.waitForFunction(() => { const o = document.getElementById('orig'); return !o.hidden && o.readyState >= 2 && o.videoWidth === 320; }, null, { timeout: 60000 });
  assert.match(await page.textContent('#orig-caption'), /re-encoded to H\.264 by the server/);
  assert.equal(posted.length, 2);
  assert.equal(posted[1].searchParams.get('mode'), 'none');
  await shot(page, 'hevc-3-done');
  await compareMode(page, 'compare-wipe');
  assert.ok(await canvasMean(page, '#compare-canvas') > 20);
  await shot(page, 'hevc-4-wipe');
  await page.close();
});

test('server fallback sends the smoothing strength as rate_a/rate_b, and shows the server\'s refusal', async () => {
  const hevc = join(tmp, 'cup-hevc-short.mp4');
  execFileSync('ffmpeg', ['-v', 'error', '-y', '-i', cup, '-frames:v', '8', '-vf', 'scale=160:120', '-c:v', 'libx265', '-preset', 'ultrafast',
    '-x265-params', 'log-level=error', '-tag:v', 'hvc1', '-an', hevc]);
  const { page } = await newPage();
  // Strong smoothing: the CLI's gains (2 and 20) halved.
  await page.selectOption('#smoothing', 'strong');
  assert.deepEqual(await page.evaluate(() => [document.getElementById('rate_a').value, document.getElementById('rate_b').value]), ['1', '10']);
  await page.setInputFiles('[data-testid=file-input]', hevc);
  await page.waitForSelector('[data-testid=server-fallback]', { state: 'visible', timeout: 60000 });
  let seen = null;
  await page.route('**/jobs?*', (route) => {
    seen = new URL(route.request().url());
    return route.fulfill({ status: 400, contentType: 'application/problem+json', body: JSON.stringify({ title: 'Bad option', detail: 'unknown option "rate_a" (test)' }) });
  });
  await page.click('[data-testid=server-fallback]');
  await page.waitForSelector('#error', { state: 'visible', timeout: 10000 });
  assert.equal(await state(page), 'error');
  assert.equal(seen.searchParams.get('rate_a'), '1');
  assert.equal(seen.searchParams.get('rate_b'), '10');
  assert.match(await page.textContent('#error'), /server refused the job: unknown option "rate_a" \(test\)/);
  await page.close();
});

test('an AVI clip: the page cannot read it in the browser, offers the server, and the server stabilizes it', async () => {
  const avi = join(tmp, 'testsrc.avi');
  execFileSync('ffmpeg', ['-v', 'error', '-y', '-f', 'lavfi', '-i', 'testsrc=size=320x240:rate=30', '-t', '2', '-c:v', 'mjpeg', avi]);
  const { page, errors } = await newPage();
  // The drop zone names the containers the page reads: the same list as the message.
  const list = await page.textContent('[data-testid=drop-formats]');
  assert.equal(list, 'MP4, MOV, WebM, MKV or MPEG-TS');
  await page.setInputFiles('[data-testid=file-input]', avi);
  await page.waitForSelector('[data-testid=server-fallback]', { state: 'visible', timeout: 60000 });
  assert.equal(await state(page), 'error');
  const text = await page.textContent('#unsupported-text');
  assert.ok(text.includes(`testsrc.avi is not a video this page can read in the browser (it reads ${list})`), text);
  assert.match(text, /The server reads every format ffmpeg reads/);
  assert.equal(await page.isVisible('#error'), false, 'an offer, not an error');
  await shot(page, 'avi-1-unsupported');
  await page.click('[data-testid=server-fallback]');
  await waitState(page, ['processing', 'done', 'error'], 10000);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  const out = ffprobeFrames(await download(page, 'testsrc-stabilized.mp4'));
  assert.equal(out.frames, 60);
  assert.equal(out.codec, 'h264');
  // Chromium cannot play AVI either: the server makes a playable copy for the Original slot.
  await page.waitForFunction(() => { const o = document.getElementById('orig'); return !o.hidden && o.readyState >= 2 && o.videoWidth === 320; }, null, { timeout: 60000 });
  await shot(page, 'avi-2-done');
  assert.deepEqual(errors.filter((e) => !e.startsWith('404')), []);
  await page.close();
});

/** `amc stabilize --help`: { flag: { value, help } } for every option it lists. */
function cliHelp() {
  const text = execFileSync(amcBin(), ['stabilize', '--help'], { encoding: 'utf8' });
  const out = {};
  let cur = null;
  for (const line of text.split('\n')) {
    const m = line.match(/^\s+(?:-\w, )?--([\w-]+)(?: <([^>]+)>)?\s*$/);
    if (m) { cur = out[m[1]] = { value: m[2] || '', help: '' }; continue; }
    if (cur && line.trim()) cur.help = (cur.help ? `${cur.help} ` : '') + line.trim();
    else cur = null;
  }
  return out;
}

test("the settings: a few plain choices first; every CLI option under Advanced with the CLI's flag, help, range and default", async () => {
  const { page } = await newPage();
  const cli = cliHelp();
  // Closed at first: the page leads with mode, smoothing strength, horizon (roll) and output.
  assert.equal(await page.evaluate(() => document.getElementById('advanced').tagName + ':' + document.getElementById('advanced').open), 'DETAILS:false');
  const visible = await page.evaluate(() => [...document.querySelectorAll('#settings input, #settings select')]
    .filter((e) => e.checkVisibility()).map((e) => e.id));
  assert.deepEqual(visible, ['mode', 'smoothing', 'roll', 'format']);
  await shot(page, 'settings-1-basic');
  await openAdvanced(page);
  const fields = await page.evaluate(() => [...document.querySelectorAll('#settings input, #settings select')].map((e) => ({
    id: e.id, tag: e.tagName, type: e.type, value: e.value, min: e.getAttribute('min'), max: e.getAttribute('max'), step: e.getAttribute('step'),
    title: e.title, label: e.labels[0].firstChild.textContent.trim(), advanced: !!e.closest('#advanced'),
    words: e.tagName === 'SELECT' ? [...e.options].map((o) => o.value) : null,
  })));
  await shot(page, 'settings-2-advanced');
  const byId = Object.fromEntries(fields.map((f) => [f.id, f]));
  // Every option of the core's table is a field (checked against the CLI's help, the user's reference).
  const table = await page.evaluate(async () => { const w = await import('/pkg/amc_wasm.js'); await w.default(); return w.options(); });
  assert.ok(table.length >= 20, String(table.length));
  for (const o of table) {
    const f = byId[o.name], c = cli[o.flag];
    assert.ok(f, `a field for ${o.name}`);
    assert.ok(c, `--${o.flag} in amc stabilize --help`);
    assert.equal(c.value, o.value_name, `--${o.flag}'s placeholder`);
    assert.equal(f.advanced, !['mode', 'roll'].includes(o.name), `${o.name} under Advanced`);
    // Named as in the CLI, with its help (range and default) as the tooltip.
    assert.match(f.label, new RegExp(`\\(--${o.flag}\\)$`), f.label);
    assert.equal(f.title, `--${o.flag} ${o.value_name}: ${c.help}`);
    // The CLI's default ("(default 6)"; "(default: the input width)" is no value: empty).
    const def = c.help.match(/\(default ([^;:)\s]+)/);
    if (def) assert.equal(f.value, def[1], `${o.name} starts at the CLI's default`);
    else { assert.match(c.help, /\(default: /); assert.equal(f.value, '', `${o.name} starts empty (the CLI's default)`); }
    if (f.tag === 'SELECT') {
      assert.deepEqual(f.words, o.allowed.words, o.name);
      for (const w of f.words) assert.ok(c.help.includes(w), `${w} in --${o.flag}'s help`);
    } else if (f.type === 'number') {
      // The field's limits: the range in the CLI's help.
      assert.ok(c.help.includes(`${f.min}..=${f.max}`), `${o.name}: ${f.min}..=${f.max} in ${c.help}`);
      assert.equal(f.step, o.allowed.kind === 'integer' ? '1' : 'any', o.name);
    }
  }
  // The ranges the issue names: the server's lookahead (0..=600, not 0..240); the CLI's field of view.
  assert.ok(byId.lookahead.title.includes('0..=600') && !byId.lookahead.title.includes('240'), byId.lookahead.title);
  assert.equal(byId.lookahead.max, '600');
  assert.ok(byId.fov.title.includes('0 < DEG <= 179, or auto') && byId.fov.value === 'auto', byId.fov.title);
  assert.equal(byId.n_avg.label, 'Averaging window (--n-avg)');
  // Untouched, the form reads as the core's defaults: the parameters of new Stabilizer(…, '{}'), fov auto, the lens file's readout.
  const read = await page.evaluate(async () => {
    const { settings } = await import('/settings.js');
    const w = await import('/pkg/amc_wasm.js');
    const st = new w.Stabilizer(64, 48, '{}', 70);
    const core = JSON.parse(st.paramsJson());
    st.free();
    delete core.shutter;
    const s = settings();
    return { params: s.params, fov: s.fov, readout: s.readout, core, errors: s.errors };
  });
  assert.deepEqual(read.errors, []);
  assert.deepEqual(read.params, read.core);
  assert.equal(read.fov, 'auto');
  assert.equal(read.readout, null);
  // Smoothing strength: normal = the CLI's rate_a and rate_b; the menu follows gains typed by hand.
  assert.equal(byId.smoothing.value, 'normal');
  assert.deepEqual([byId.rate_a.value, byId.rate_b.value], ['2', '20']);
  await page.selectOption('#smoothing', 'very-strong');
  assert.deepEqual(await page.evaluate(() => [document.getElementById('rate_a').value, document.getElementById('rate_b').value]), ['0.5', '5']);
  await page.fill('#rate_a', '3');
  assert.equal(await page.inputValue('#smoothing'), 'custom');
  await page.fill('#rate_a', '4');
  await page.fill('#rate_b', '40');
  assert.equal(await page.inputValue('#smoothing'), 'light');
  await page.close();
});

test('Live tab: frames and telemetry from the looped source', async () => {
  const { page } = await newPage();
  const sockets = [];
  page.on('websocket', (ws) => sockets.push(ws.url()));
  await page.click('[data-testid=live-tab]');
  await page.waitForFunction(() => Number(document.querySelector('[data-testid=live-canvas]').dataset.frames) >= 10, null, { timeout: 60000 });
  const telemetry = await page.textContent('#live-telemetry');
  assert.match(telemetry, /frame \d+ .*deg\/s/);
  // The canvas shows an image, not black.
  const lit = await page.evaluate(() => {
    const c = document.querySelector('[data-testid=live-canvas]');
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let s = 0; for (let i = 0; i < d.length; i += 4) s += d[i] + d[i + 1] + d[i + 2];
    return s / (d.length / 4) / 3;
  });
  assert.ok(lit > 20, `mean brightness ${lit}`);
  // The speed plot has its series, axes and a legend beside it.
  await page.waitForFunction(() => document.querySelector('[data-testid=live-plot]').dataset.series === 'est,view', null, { timeout: 10000 });
  const legendText = await page.textContent('[data-testid=live-legend]');
  assert.match(legendText, /camera \(estimate\) speed.*view speed/);
  await shot(page, 'live');
  // Chromium has WebCodecs on localhost: the feed came as H.264, decoded in the page.
  assert.equal(await page.getAttribute('[data-testid=live-canvas]', 'data-codec'), 'h264');
  assert.match(await page.textContent('#live-status'), /H\.264 \(WebCodecs\).*frames\/s.*Mbit\/s/);
  // Through a ticket (a server without keys still gives one), or plain /live where the server has no tickets (404).
  assert.equal(sockets.length, 1, sockets.join(' '));
  assert.match(sockets[0], /^ws:\/\/127\.0\.0\.1:\d+\/live\?(ticket=[0-9a-f]{64}&)?codec=h264$/);
  await page.close();
});

test('Live tab without WebCodecs: JPEGs, and the status says why', async () => {
  const sockets = [];
  const { page } = await newPage(server, async (page) => {
    await page.addInitScript(() => { delete window.VideoDecoder; });
    page.on('websocket', (ws) => sockets.push(ws.url()));
  });
  await page.click('[data-testid=live-tab]');
  await page.waitForFunction(() => Number(document.querySelector('[data-testid=live-canvas]').dataset.frames) >= 10, null, { timeout: 60000 });
  assert.equal(await page.getAttribute('[data-testid=live-canvas]', 'data-codec'), 'jpeg');
  assert.match(await page.textContent('#live-status'), /JPEG \(this browser has no WebCodecs VideoDecoder\)/);
  assert.match(sockets[0], /^ws:\/\/127\.0\.0\.1:\d+\/live(\?ticket=[0-9a-f]{64})?$/);
  await page.close();
});

test('Live tab at 720p60: a 1280x720 60 fps source reaches the canvas as H.264, every picture received drawn', async () => {
  // karma.mp4 (854x480, 29.97 fps) made a 4 s 1280x720 60 fps source, looped.
  const karma = join(dataDir, 'karma', 'karma.mp4');
  const hd = join(tmp, 'karma-720p60.mp4');
  execFileSync('ffmpeg', ['-v', 'error', '-y', '-i', karma, '-t', '4', '-an', '-vf', 'scale=1280:720,fps=60',
    '-c:v', 'libx264', '-preset', 'ultrafast', '-g', '30', hd]);
  const srv = await startServer(['--live-source', hd, '--live-loop', '--live-fov', '94']);
  try {
    const { page } = await newPage(srv);
    await page.click('[data-testid=live-tab]');
    const count = () => page.evaluate(() => {
      const c = document.querySelector('[data-testid=live-canvas]');
      return { drawn: Number(c.dataset.frames || 0), received: Number(c.dataset.received || 0), w: c.width, h: c.height, codec: c.dataset.codec, t: performance.now() };
    });
    await page.waitForFunction(() => Number(document.querySelector('[data-testid=live-canvas]').dataset.frames) >= 30, null, { timeout: 60000 });
    const a = await count();
    await new Promise((r) => setTimeout(r, 5000));
    const b = await count();
    await shot(page, 'live-720p60');
    await page.close();
    const secs = (b.t - a.t) / 1000;
    const drawnRate = (b.drawn - a.drawn) / secs;
    const note = `${JSON.stringify({ a, b, drawnRate: drawnRate.toFixed(1) })}\n${srv.log().slice(-2000)}`;
    assert.equal(b.codec, 'h264', note);
    assert.deepEqual([b.w, b.h], [1280, 720], note);
    // What came is drawn; at most half a second waits in the decoder (the page skips to a
    // keyframe past that).
    assert.ok(b.drawn - a.drawn >= 0.9 * (b.received - a.received), note);
    assert.ok(b.received - b.drawn <= 40, note);
    // The server stabilizes, encodes and sends while Chromium decodes on the same 2 cores,
    // so the rate depends on the VM model (43-44 frames/s drawn on a Zen 4 VM, 18-25.5 on a
    // Zen 3 one): it is measured by the bench (docs/speed.md), not asserted here. This test
    // holds the feed live and whole: pictures keep coming and each one is drawn.
    assert.ok(b.drawn - a.drawn >= 30, note);
    console.log(`720p60 in Chromium: ${drawnRate.toFixed(1)} frames/s drawn over ${secs.toFixed(1)} s`);
  } finally {
    await srv.stop();
  }
});

// --- API keys and tickets ------------------------------------------------------

const sha256 = (text) => createHash('sha256').update(text).digest('hex');
const problemJson = (status, title, detail, headers = {}) => ({
  status, headers, contentType: 'application/problem+json', body: JSON.stringify({ type: 'about:blank', title, status, detail }),
});
const UNAUTHORIZED = (detail) => problemJson(401, 'Unauthorized', detail, { 'WWW-Authenticate': 'Bearer realm="amc"' });

/** A 2 s MJPEG AVI the page cannot read: it goes to the job API. */
function aviClip(name) {
  const avi = join(tmp, name);
  execFileSync('ffmpeg', ['-v', 'error', '-y', '-f', 'lavfi', '-i', 'testsrc=size=320x240:rate=30', '-t', '2', '-c:v', 'mjpeg', avi]);
  return avi;
}

/** Picks `file`, which the page cannot read, and takes the offer of the server. */
async function toServer(page, file) {
  await page.setInputFiles('[data-testid=file-input]', []); // the same file again is no change
  await page.setInputFiles('[data-testid=file-input]', file);
  await page.waitForSelector('[data-testid=server-fallback]', { state: 'visible', timeout: 60000 });
  await page.click('[data-testid=server-fallback]');
}

/** Waits for the key dialog, types `key` and presses OK. */
async function giveKey(page, key) {
  await page.waitForSelector('#key-dialog[open]', { timeout: 30000 });
  await page.fill('[data-testid=key-input]', key);
  await page.click('[data-testid=key-ok]');
}

/** The key as the page holds it: { session, local (every localStorage value) }. */
const keyStore = (page) => page.evaluate(() => ({
  session: sessionStorage.getItem('amc-api-key'),
  local: Object.keys(localStorage).map((k) => `${k}=${localStorage.getItem(k)}`),
}));

test('API key dialog (the job API answering 401, 403 and 429 by route): asked on the first call, a refused key asks again, the key goes on every call and stays in sessionStorage', async () => {
  const avi = aviClip('keyed.avi');
  const { page, errors } = await newPage();
  const KEY = `amc_${randomBytes(16).toString('hex')}`;
  const seen = [], urls = [];
  page.on('request', (r) => urls.push(r.url()));
  let answer = 'check';
  await page.route((u) => u.pathname === '/openapi.json' || u.pathname.startsWith('/jobs'), async (route) => {
    const req = route.request();
    const auth = await req.headerValue('authorization');
    seen.push({ method: req.method(), path: new URL(req.url()).pathname, auth });
    if (answer === 'check' && auth !== `Bearer ${KEY}`) return route.fulfill(UNAUTHORIZED(auth ? 'this key is not valid' : 'an API key is needed'));
    if (answer === '403' && req.method() === 'POST') return route.fulfill(problemJson(403, 'Forbidden', 'this key (tenant "t", roles view) may not use /jobs: it needs the role submit (or admin)'));
    if (answer === '429') return route.fulfill(problemJson(429, 'Too Many Requests', 'too many requests for this key', { 'Retry-After': '7' }));
    return route.continue();
  });
  // No key stored: nothing to forget.
  assert.equal(await page.isVisible('[data-testid=forget-key]'), false);
  await toServer(page, avi);
  // The first API call (a bodiless check before the upload) is answered 401: the page's own dialog asks.
  await page.waitForSelector('#key-dialog[open]', { timeout: 30000 });
  assert.match(await page.textContent('#key-dialog'), /This server needs an API key \(ask its operator; amc keys new\)/);
  assert.equal(await page.getAttribute('[data-testid=key-input]', 'type'), 'password');
  assert.equal(await page.isVisible('[data-testid=key-error]'), false);
  assert.equal(seen.filter((x) => x.method === 'POST').length, 0, 'the clip is not uploaded before there is a key');
  await shot(page, 'key-1-asked');
  // A wrong key: the dialog says so and asks again.
  await giveKey(page, 'not-the-key');
  await page.waitForSelector('[data-testid=key-error]', { state: 'visible', timeout: 10000 });
  assert.match(await page.textContent('[data-testid=key-error]'), /^The server did not accept this key\. Try another/);
  assert.equal(await page.inputValue('[data-testid=key-input]'), '', 'the refused key is not shown again');
  await shot(page, 'key-2-refused');
  await page.fill('[data-testid=key-input]', KEY);
  await page.click('[data-testid=key-ok]');
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  assert.equal(ffprobeFrames(await download(page, 'keyed-stabilized.mp4')).frames, 60);
  // The Original slot's copy (a second job) too.
  await page.waitForFunction(() => { const o = document.getElementById('orig'); return !o.hidden && o.readyState >= 2; }, null, { timeout: 60000 });
  // Once given, the key went on every call: the upload, the polls, the output, the telemetry.
  const after = seen.slice(seen.findIndex((x) => x.auth === `Bearer ${KEY}`));
  assert.ok(after.every((x) => x.auth === `Bearer ${KEY}`), JSON.stringify(after));
  for (const [m, p] of [['POST', /^\/jobs$/], ['GET', /^\/jobs\/[^/]+$/], ['GET', /\/output$/], ['GET', /\/telemetry\.csv$/]]) {
    assert.ok(after.some((x) => x.method === m && p.test(x.path)), `${m} ${p} with the key`);
  }
  assert.equal(after.filter((x) => x.method === 'POST').length, 2, 'each clip uploaded once');
  // Kept for this tab only, never in a URL.
  assert.deepEqual(await keyStore(page), { session: KEY, local: [] });
  assert.deepEqual(urls.filter((u) => u.includes(KEY)), []);
  assert.equal(await page.isVisible('[data-testid=forget-key]'), true);
  // 403: the key lacks a role.
  answer = '403';
  await toServer(page, avi);
  await page.waitForSelector('#error', { state: 'visible', timeout: 30000 });
  assert.equal(await page.textContent('#error'), 'server refused the job: this key may not submit jobs (role submit or admin missing)');
  // 429: too many requests.
  answer = '429';
  await toServer(page, avi);
  await page.waitForFunction(() => /too many/.test(document.getElementById('error').textContent), null, { timeout: 30000 });
  assert.equal(await page.textContent('#error'), 'server refused the job: too many requests, retry in 7 s');
  await shot(page, 'key-3-429');
  // Forget the key: the next call asks again; Cancel ends the job with a message.
  answer = 'check';
  await page.click('[data-testid=forget-key]');
  assert.equal(await page.isVisible('[data-testid=forget-key]'), false);
  assert.deepEqual(await keyStore(page), { session: null, local: [] });
  await toServer(page, avi);
  await page.waitForSelector('#key-dialog[open]', { timeout: 30000 });
  await page.click('[data-testid=key-cancel]');
  await page.waitForFunction(() => /API key/.test(document.getElementById('error').textContent), null, { timeout: 10000 });
  assert.match(await page.textContent('#error'), /^server refused the job: this server needs an API key, and none was given/);
  assert.equal(await page.isVisible('#key-dialog'), false);
  assert.deepEqual(errors.filter((e) => !e.startsWith('404')), []);
  await page.close();
});

test('Live tab (ticket endpoint and socket by route): a ticket, asked with the key, before each connection and each reconnection; the key never in a URL; no ticket endpoint (404): a plain /live', async () => {
  const jpeg = join(tmp, 'live.jpg');
  execFileSync('ffmpeg', ['-v', 'error', '-y', '-f', 'lavfi', '-i', 'testsrc=size=160x120', '-frames:v', '1', '-c:v', 'mjpeg', '-f', 'image2', jpeg]);
  const frame = readFileSync(jpeg);
  const KEY = `amc_${randomBytes(16).toString('hex')}`;
  const tickets = [], sockets = [], urls = [];
  let issued = 0, ticketAnswer = 'check';
  const { page } = await newPage(server, async (page) => {
    // JPEG frames by route: the page's JPEG path (no WebCodecs).
    await page.addInitScript(() => { delete window.VideoDecoder; });
    page.on('request', (r) => urls.push(r.url()));
    await page.route((u) => u.pathname === '/live/ticket', async (route) => {
      const req = route.request();
      const auth = await req.headerValue('authorization');
      tickets.push({ method: req.method(), auth });
      if (ticketAnswer === '404') return route.fulfill(problemJson(404, 'Not Found', 'no such endpoint: /live/ticket'));
      if (auth !== `Bearer ${KEY}`) return route.fulfill(UNAUTHORIZED('an API key is needed'));
      issued++;
      return route.fulfill({ status: 200, contentType: 'application/json', body: JSON.stringify({ ticket: issued.toString(16).padStart(64, 'a'), expires_in_s: 30 }) });
    });
    // The feed: a telemetry message and a frame, then (the first time) the socket drops.
    await page.routeWebSocket((u) => u.pathname === '/live', (ws) => {
      sockets.push(ws.url());
      const n = sockets.length;
      setTimeout(() => {
        ws.send(JSON.stringify({ frame: n, t: n, speed_est_dps: 10, speed_view_dps: 2, valid: 1, saccade: false, latency_ms: 5 }));
        ws.send(frame);
        if (n === 1) setTimeout(() => ws.close({ code: 1001, reason: 'going away' }), 300);
      }, 200);
    });
  });
  await page.click('[data-testid=live-tab]');
  await giveKey(page, KEY);
  await page.waitForFunction(() => Number(document.querySelector('[data-testid=live-canvas]').dataset.frames) >= 2, null, { timeout: 20000 });
  const origin = server.url.replace(/^http/, 'ws');
  assert.deepEqual(sockets, [`${origin}/live?ticket=${'1'.padStart(64, 'a')}`, `${origin}/live?ticket=${'2'.padStart(64, 'a')}`], 'a new ticket for the reconnection');
  assert.deepEqual(tickets.map((t) => `${t.method} ${t.auth}`), ['POST null', `POST Bearer ${KEY}`, `POST Bearer ${KEY}`]);
  assert.deepEqual(urls.concat(sockets).filter((u) => u.includes(KEY)), []);
  assert.deepEqual(await keyStore(page), { session: KEY, local: [] });
  // A server without tickets: the plain /live.
  ticketAnswer = '404';
  await page.click('#tab-clip');
  await page.click('[data-testid=live-tab]');
  await page.waitForFunction(() => Number(document.querySelector('[data-testid=live-canvas]').dataset.frames) >= 3, null, { timeout: 20000 });
  assert.equal(sockets[2], `${origin}/live`);
  await page.close();
});

test('amc serve --auth-keys: the API wants a key, the page asks for it on its first call, a wrong key asks again; the job and the live feed (through tickets) run with it; a key without the role is told so', async () => {
  const keys = { alice: `amc_${randomBytes(32).toString('hex')}`, viewer: `amc_${randomBytes(32).toString('hex')}` };
  const keysFile = join(tmp, 'keys.txt');
  writeFileSync(keysFile, `# test keys\nalice submit,view,publish ${sha256(keys.alice)}\nviewer view ${sha256(keys.viewer)}\n`);
  const srv = await startServer(['--auth-keys', keysFile, '--live-source', cup, '--live-loop']);
  try {
    // The page's files and /healthz are public and the page comes with its policy; the API is not.
    const home = await fetch(`${srv.url}/`);
    assert.equal(home.status, 200);
    assert.match(home.headers.get('content-security-policy') || '', /script-src 'self' 'wasm-unsafe-eval'/, 'the server sends the page its CSP');
    assert.equal((await fetch(`${srv.url}/main.js`)).status, 200);
    const api = await fetch(`${srv.url}/jobs`);
    assert.equal(api.status, 401);
    assert.equal(api.headers.get('www-authenticate'), 'Bearer realm="amc"');
    assert.match(api.headers.get('content-type'), /application\/problem\+json/);

    const avi = aviClip('auth.avi');
    const { page, errors } = await newPage(srv);
    const urls = [], sockets = [], apiCalls = [];
    page.on('request', (r) => {
      urls.push(r.url());
      const path = new URL(r.url()).pathname;
      if (/^\/(jobs|live|openapi\.json)/.test(path)) apiCalls.push(r);
    });
    page.on('websocket', (ws) => sockets.push(ws.url()));
    await toServer(page, avi);
    await page.waitForSelector('#key-dialog[open]', { timeout: 30000 });
    await shot(page, 'auth-1-asked');
    await giveKey(page, `amc_${'0'.repeat(64)}`);
    await page.waitForSelector('[data-testid=key-error]', { state: 'visible', timeout: 10000 });
    assert.match(await page.textContent('[data-testid=key-error]'), /The server did not accept this key/);
    await page.fill('[data-testid=key-input]', keys.alice);
    await page.click('[data-testid=key-ok]');
    await waitState(page, ['done', 'error']);
    assert.equal(await state(page), 'done', await page.textContent('#error'));
    assert.equal(ffprobeFrames(await download(page, 'auth-stabilized.mp4')).frames, 60);
    await page.waitForFunction(() => { const o = document.getElementById('orig'); return !o.hidden && o.readyState >= 2; }, null, { timeout: 60000 });
    // The live feed: a ticket, then the socket with it; again after switching away and back (a new ticket).
    await page.click('[data-testid=live-tab]');
    await page.waitForFunction(() => Number(document.querySelector('[data-testid=live-canvas]').dataset.frames) >= 5, null, { timeout: 60000 });
    await page.click('#tab-clip');
    await page.click('[data-testid=live-tab]');
    await page.waitForFunction(() => Number(document.querySelector('[data-testid=live-canvas]').dataset.frames) >= 10, null, { timeout: 60000 });
    await shot(page, 'auth-2-live');
    assert.equal(sockets.length, 2, sockets.join(' '));
    for (const u of sockets) assert.match(u, /\/live\?ticket=[0-9a-f]{64}&codec=h264$/);
    assert.notEqual(sockets[0], sockets[1], 'a fresh ticket per connection');
    // The key: in sessionStorage and the Authorization header only.
    assert.deepEqual(await keyStore(page), { session: keys.alice, local: [] });
    assert.deepEqual(urls.concat(sockets).filter((u) => u.includes(keys.alice)), []);
    assert.ok(!srv.log().includes(keys.alice), "the key is not in the server's log");
    const withKey = [];
    for (const r of apiCalls) withKey.push(`${r.method()} ${new URL(r.url()).pathname} ${(await r.allHeaders()).authorization === `Bearer ${keys.alice}`}`);
    assert.ok(withKey.some((x) => /^POST \/jobs true$/.test(x)), withKey.join('\n'));
    assert.ok(withKey.some((x) => /^POST \/live\/ticket true$/.test(x)), withKey.join('\n'));
    assert.deepEqual(withKey.filter((x) => / \/jobs\/\S+ false$/.test(x)), [], 'every poll and download with the key');
    assert.deepEqual(errors.filter((e) => !e.startsWith('404')), []);
    await page.close();

    // A key with only the view role: the live feed works, a job is refused, naming the role.
    const { page: viewer } = await newPage(srv);
    await viewer.click('[data-testid=live-tab]');
    await giveKey(viewer, keys.viewer);
    await viewer.waitForFunction(() => Number(document.querySelector('[data-testid=live-canvas]').dataset.frames) >= 3, null, { timeout: 60000 });
    await viewer.click('#tab-clip');
    await toServer(viewer, avi);
    await viewer.waitForSelector('#error', { state: 'visible', timeout: 30000 });
    assert.match(await viewer.textContent('#error'), /^server refused the job: this key may not submit jobs \(role submit\b.*missing\)/);
    assert.equal(await viewer.isVisible('#key-dialog'), false, 'a 403 does not ask for another key');
    await shot(viewer, 'auth-3-forbidden');
    await viewer.close();
  } finally {
    await srv.stop();
  }
});

test('no page of this run broke the Content-Security-Policy (the check itself sees a violation)', async () => {
  writeFileSync(join(artifacts, 'csp.json'), JSON.stringify({ policyFrom: [...cspFrom], violations: cspViolations }, null, 1));
  // The check works: an inline style and an inline script are reported.
  const page = await browser.newPage();
  const probe = [];
  await watchCsp(page, server, probe);
  await page.goto(`${server.url}/`);
  await page.evaluate(() => {
    const d = document.createElement('div');
    d.innerHTML = '<span style="color: red">x</span>';
    document.body.append(d);
    const s = document.createElement('script');
    s.textContent = 'window.inlineRan = true';
    document.body.append(s);
  });
  await new Promise((r) => setTimeout(r, 500));
  assert.equal(await page.evaluate(() => window.inlineRan), undefined, 'the inline script was blocked');
  assert.ok(probe.some((v) => /style-src/.test(v.directive || v.console)), JSON.stringify(probe));
  assert.ok(probe.some((v) => /script-src/.test(v.directive || v.console)), JSON.stringify(probe));
  await page.close();
  assert.ok(cspFrom.size > 0, 'the pages had a policy');
  assert.deepEqual(cspViolations, []);
});
