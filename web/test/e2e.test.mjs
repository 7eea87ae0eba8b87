// End to end in headless Chromium against `amc serve` (serving web/dist):
// the page stabilizes cup.mp4 in the browser; an HEVC clip goes to the job API;
// the Live tab shows a looped source. Screenshots land in web/test-artifacts/.
// Run: node --test --test-concurrency=1 test/e2e.test.mjs   (after ./build.sh)
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { startServer, launch, shot, ffprobeFrames, rmsFrameChange, streamTypes, dataDir, artifacts } from './helpers.mjs';

const cup = join(dataDir, 'cup', 'cup.mp4');
let server, browser, tmp;

before(async () => {
  tmp = mkdtempSync(join(tmpdir(), 'amc-e2e-'));
  server = await startServer(['--live-source', cup, '--live-loop']);
  browser = await launch();
});

after(async () => {
  if (browser) await browser.close();
  if (server) await server.stop();
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

async function newPage() {
  const page = await browser.newPage({ acceptDownloads: true, viewport: { width: 1280, height: 900 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  await page.goto(server.url + '/');
  return { page, errors };
}

const state = (page) => page.evaluate(() => document.body.dataset.state);
const waitState = (page, states, timeout = 300000) =>
  page.waitForFunction((s) => s.includes(document.body.dataset.state), states, { timeout });

async function download(page, name) {
  const [dl] = await Promise.all([page.waitForEvent('download'), page.click('[data-testid=download]')]);
  const file = join(tmp, name);
  await dl.saveAs(file);
  return file;
}

test('drop cup.mp4: every frame stabilized in the browser; the MP4 download has all frames and changes less', async () => {
  const { page, errors } = await newPage();
  assert.equal(await state(page), 'idle');
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
  const input = ffprobeFrames(cup);
  assert.equal(Number(await page.evaluate(() => document.body.dataset.frames)), input.frames);
  const file = await download(page, 'cup-stabilized.mp4');
  const out = ffprobeFrames(file);
  assert.equal(out.codec, 'h264');
  assert.equal(out.frames, input.frames, 'the download has every input frame');
  assert.deepEqual([out.width, out.height], [480, 360]);
  assert.deepEqual(streamTypes(file).sort(), ['audio', 'video'], "the original's AAC audio is copied");
  // The same central 75% of the input (margin 0.125) vs the stabilized output.
  const rin = rmsFrameChange(cup, 0.125), rout = rmsFrameChange(file);
  writeFileSync(join(artifacts, 'clip-rms.json'), JSON.stringify({ input: rin, output: rout }, null, 1));
  assert.ok(rout.rms < rin.rms, `RMS frame change: output ${rout.rms.toFixed(4)} vs input ${rin.rms.toFixed(4)}`);
  // The plot and the side-by-side players are there.
  assert.equal(await page.isVisible('#plot'), true);
  assert.ok(await page.evaluate(() => document.getElementById('stab').src.startsWith('blob:')));
  assert.deepEqual(errors, []);
  await page.close();
});

test('WebM download (VP9) with the same frame count', async () => {
  const { page } = await newPage();
  await page.selectOption('#format', 'webm');
  await page.fill('#n_avg', '3');
  await page.selectOption('#mode', 'saccade');
  await page.setInputFiles('[data-testid=file-input]', cup);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  const file = await download(page, 'cup-stabilized.webm');
  const out = ffprobeFrames(file);
  assert.ok(['vp9', 'vp8', 'av1'].includes(out.codec), out.codec);
  assert.equal(out.frames, ffprobeFrames(cup).frames);
  await page.close();
});

test('bad settings and a file that is not a video end in the error state with a message', async () => {
  const { page } = await newPage();
  await page.fill('#n_avg', '0');
  await page.setInputFiles('[data-testid=file-input]', cup);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'error');
  assert.match(await page.textContent('#error'), /n_avg: 0 \(allowed: 1\.\.=64/);
  const junk = join(tmp, 'junk.mp4');
  writeFileSync(junk, 'this is not a video');
  await page.fill('#n_avg', '6');
  await page.setInputFiles('[data-testid=file-input]', junk);
  await waitState(page, ['done', 'error']);
  assert.equal(await state(page), 'error');
  assert.ok((await page.textContent('#error')).length > 5);
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
  await page.click('[data-testid=server-fallback]');
  await waitState(page, ['processing', 'done', 'error'], 10000);
  await shot(page, 'hevc-2-server-processing');
  await waitState(page, ['done', 'error']);
  await shot(page, 'hevc-3-done');
  assert.equal(await state(page), 'done', await page.textContent('#error'));
  const file = await download(page, 'cup-hevc-stabilized.mp4');
  assert.equal(ffprobeFrames(file).frames, 48);
  await page.close();
});

test('Live tab: frames and telemetry from the looped source', async () => {
  const { page } = await newPage();
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
  await shot(page, 'live');
  await page.close();
});
