// Shared helpers of the browser tests: start `amc serve`, launch Chromium,
// decode videos with ffmpeg, save screenshots.
import { spawn, execFileSync } from 'node:child_process';
import { mkdirSync, existsSync } from 'node:fs';
import { createServer } from 'node:net';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

export const webDir = resolve(dirname(fileURLToPath(import.meta.url)), '..');
export const root = resolve(webDir, '..');
export const dataDir = resolve(root, '../shared/data');
export const artifacts = join(webDir, 'test-artifacts');
mkdirSync(artifacts, { recursive: true });

const freePort = () => new Promise((res, rej) => {
  const s = createServer();
  s.on('error', rej);
  s.listen(0, '127.0.0.1', () => { const { port } = s.address(); s.close(() => res(port)); });
});

/** The `amc` binary the tests run: $AMC_BIN, else target/release/amc. */
export const amcBin = () => process.env.AMC_BIN || join(root, 'target', 'release', 'amc');

/** Starts `amc serve` on a free port serving web/dist (built by web/build.sh). */
export async function startServer(extraArgs = []) {
  // Development only: point the tests at an already running server.
  if (process.env.AMC_E2E_URL) return { url: process.env.AMC_E2E_URL, log: () => '', stop: async () => {} };
  if (!existsSync(join(webDir, 'dist', 'index.html'))) throw new Error('web/dist missing: run web/build.sh first');
  const bin = amcBin();
  // The `amc` binary is amc-cli's (it serves through amc-server).
  if (!process.env.AMC_BIN) execFileSync('cargo', ['build', '--release', '-q', '-p', 'amc-cli'], { cwd: root, stdio: 'inherit' });
  const port = await freePort();
  const args = ['serve', '--addr', `127.0.0.1:${port}`, '--web-dir', join(webDir, 'dist'), ...extraArgs];
  const proc = spawn(bin, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  proc.stdout.on('data', (d) => { log += d; });
  proc.stderr.on('data', (d) => { log += d; });
  const url = `http://127.0.0.1:${port}`;
  const deadline = Date.now() + 30000;
  for (;;) {
    if (proc.exitCode !== null) throw new Error(`amc serve exited (${proc.exitCode}):\n${log}`);
    try { const r = await fetch(`${url}/`); if (r.ok) break; } catch { /* not up yet */ }
    if (Date.now() > deadline) { proc.kill(); throw new Error(`amc serve did not answer on ${url}:\n${log}`); }
    await new Promise((r) => setTimeout(r, 100));
  }
  return { url, proc, log: () => log, stop: () => new Promise((r) => { if (proc.exitCode !== null) return r(); proc.once('exit', r); proc.kill('SIGTERM'); }) };
}

/** Headless Chromium (Debian's, or $CHROMIUM), with `extraArgs`. */
export async function launch(extraArgs = []) {
  return chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update', '--disable-sync', '--no-first-run', ...extraArgs],
  });
}

export async function shot(page, name) {
  await page.screenshot({ path: join(artifacts, `${name}.png`), fullPage: true });
}

/** Number of video frames ffprobe counts (decoding every frame). */
export function ffprobeFrames(file) {
  const out = execFileSync('ffprobe', ['-v', 'error', '-count_frames', '-select_streams', 'v:0', '-show_entries', 'stream=nb_read_frames,width,height,codec_name', '-of', 'json', file], { encoding: 'utf8' });
  const s = JSON.parse(out).streams[0];
  return { frames: Number(s.nb_read_frames), width: s.width, height: s.height, codec: s.codec_name };
}

/**
 * RMS frame change on luma in [0, 1]: sqrt of the mean squared difference of
 * consecutive frames over all pixels and frame pairs (amc-core's `rms_change`
 * without masks). `crop` = share of each side to cut first.
 */
export function rmsFrameChange(file, crop = 0) {
  const { width, height } = ffprobeFrames(file);
  const w = Math.round(width * (1 - 2 * crop)) & ~1, h = Math.round(height * (1 - 2 * crop)) & ~1;
  const vf = crop > 0 ? `crop=${w}:${h},format=gray` : 'format=gray';
  const raw = execFileSync('ffmpeg', ['-v', 'error', '-i', file, '-vf', vf, '-f', 'rawvideo', '-pix_fmt', 'gray', '-'], { maxBuffer: 1 << 30 });
  const size = w * h, n = Math.floor(raw.length / size);
  let sum = 0, count = 0;
  for (let f = 1; f < n; f++) {
    const a = (f - 1) * size, b = f * size;
    for (let i = 0; i < size; i++) { const d = (raw[b + i] - raw[a + i]) / 255; sum += d * d; }
    count += size;
  }
  return { rms: Math.sqrt(sum / count), frames: n, width: w, height: h };
}

/** Codec types of a file's streams, e.g. ['video', 'audio']. */
export function streamTypes(file) {
  const out = execFileSync('ffprobe', ['-v', 'error', '-show_entries', 'stream=codec_type', '-of', 'csv=p=0', file], { encoding: 'utf8' });
  return out.split('\n').map((l) => l.trim()).filter(Boolean);
}
