// WASM-level tests of amc-wasm's exported API, in Node (same module the page loads).
// Run: node --test test/wasm.test.mjs   (after ./build.sh)
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import { initSync, Stabilizer, ReadoutEstimator, PassPlan, GyroPass, ClipGyro, simdEnabled, simdMatchesScalar, options, resolveOptions } from '../dist/pkg/amc_wasm.js';

const wasmPath = fileURLToPath(new URL('../dist/pkg/amc_wasm_bg.wasm', import.meta.url));
initSync({ module: readFileSync(wasmPath) });

// A textured RGBA frame of a scene shifted by (dx, dy) pixels (smooth, so tracking works).
function frame(w, h, dx = 0, dy = 0) {
  const d = new Uint8Array(w * h * 4);
  for (let y = 0; y < h; y++) {
    for (let x = 0; x < w; x++) {
      const u = x + dx, v = y + dy;
      const val = 128 + 60 * Math.sin(u * 0.21) * Math.cos(v * 0.17) + 40 * Math.sin((u + 2 * v) * 0.05);
      const i = 4 * (y * w + x);
      d[i] = val; d[i + 1] = 255 - val; d[i + 2] = (val * 0.5 + 60) | 0; d[i + 3] = 255;
    }
  }
  return d;
}

const W = 160, H = 90;
const throwsMsg = (fn, re) => assert.throws(fn, (e) => e instanceof Error && re.test(e.message), `expected Error matching ${re}`);

test('module is built with the simd128 kernel, bit-exact with the scalar path', () => {
  assert.equal(simdEnabled(), true);
  // 2048x1100 RGBA has byte offsets above 2^23: the kernel's integer offset path.
  for (const [w, h, seed, fisheye] of [[203, 117, 1, false], [203, 117, 2, true], [320, 180, 3, false], [97, 61, 4, true], [64, 48, 5, false], [2048, 1100, 6, false]]) {
    assert.equal(simdMatchesScalar(w, h, seed, fisheye), true, `${w}x${h} seed ${seed} fisheye ${fisheye}`);
  }
});

test('stabilizes a stream: telemetry per frame, RGBA output of the input size (zoom auto)', () => {
  // zoom none: the paper's fixed margin, 0.125 each side: 75% of 160.
  const fixed = new Stabilizer(W, H, '{"framing":{"zoom":"none"}}', 70);
  assert.deepEqual([fixed.outputWidth, fixed.outputHeight], [120, 68]);
  fixed.free();
  // zoom static: a first pass without rendering finds the zoom; a rendering
  // stabilizer refuses frames until it is told.
  const pre = new Stabilizer(W, H, '{"framing":{"zoom":"static"}}', 70);
  pre.setRendering(false);
  for (let i = 0; i < 8; i++) pre.push(frame(W, H, 2 * i, i % 3), i / 30);
  while (pre.finish()) { /* drain */ }
  const need = pre.maxZoomNeed();
  assert.ok(need >= 1 && need < 3, `need ${need}`);
  pre.free();
  const fixedZoom = new Stabilizer(W, H, '{"framing":{"zoom":"static"}}', 70);
  throwsMsg(() => fixedZoom.push(frame(W, H, 0, 0), 0), /invalid zoom: static/);
  fixedZoom.setStaticZoom(need);
  const tel0 = fixedZoom.push(frame(W, H, 0, 0), 0);
  assert.equal(tel0.zoom, Math.min(need, 1 / 0.85));
  fixedZoom.free();
  const s = new Stabilizer(W, H, '{}', 70);
  assert.equal(s.width, W);
  assert.equal(s.outputWidth, W);
  assert.equal(s.outputHeight, H);
  s.setMetrics(true);
  const tels = [];
  for (let i = 0; i < 12; i++) {
    const f = frame(W, H, (i % 3) - 1, ((i * 7) % 3) - 1);
    s.inputBuffer().set(f);
    const inputMetrics = s.measureInput();
    const tel = s.push(f, i / 30);
    assert.ok(tel, `telemetry for frame ${i}`);
    tel.metrics = s.measureOutput();
    tel.input_metrics = inputMetrics;
    throwsMsg(() => s.measureOutput(), /no new output frame/);
    tels.push(tel);
    const out = s.output();
    assert.equal(out.length, s.outputWidth * s.outputHeight * 4);
    assert.equal(out[3], 255);
  }
  assert.deepEqual(tels.map((t) => t.frame), [...Array(12).keys()]);
  assert.ok(tels.every((t) => Number.isFinite(t.speed_est_dps) && t.valid_fraction > 0));
  assert.ok(tels.every((t) => t.uncovered === 0 && t.zoom >= 1 && t.zoom <= 1 / 0.85 + 1e-9), 'zoom auto: no border, within the budget');
  assert.equal(tels[0].metrics.rms_change, null); // no previous frame
  assert.ok(tels[5].metrics && typeof tels[5].metrics.rms_change === 'number');
  assert.ok(tels[5].input_metrics && typeof tels[5].input_metrics.rms_change === 'number');
  assert.equal(s.finish(), undefined);
  const sum = s.summary();
  assert.equal(sum.output.frames, 12);
  // Averaging and stabilizing make consecutive outputs change less than the inputs.
  assert.ok(sum.output.rms_change < sum.input.rms_change, JSON.stringify(sum));
  const p = JSON.parse(s.paramsJson());
  assert.equal(p.render.n_avg, 6);
  s.free();
});

test('inputBuffer/pushInput: decode straight into WASM memory; lookahead drains with finish', () => {
  const s = new Stabilizer(W, H, JSON.stringify({ view: { lookahead: 3 } }), 70);
  let outs = 0;
  for (let i = 0; i < 8; i++) {
    s.inputBuffer().set(frame(W, H, i % 2, 0));
    if (s.pushInput(i / 30)) outs++;
  }
  assert.equal(outs, 5);
  while (s.finish()) outs++;
  assert.equal(outs, 8);
  s.free();
});

test('same frames through push and pushInput give identical output', () => {
  const a = new Stabilizer(W, H, '{}', 60), b = new Stabilizer(W, H, '{}', 60);
  for (let i = 0; i < 5; i++) {
    const f = frame(W, H, i, -i);
    a.push(f, i * 0.04);
    b.inputBuffer().set(f);
    b.pushInput(i * 0.04);
    assert.deepEqual(Array.from(a.output()), Array.from(b.output()));
  }
  a.free(); b.free();
});

test('bad sizes and parameters are JS Errors naming the value and the allowed range', () => {
  throwsMsg(() => new Stabilizer(0, 90, '{}', 70), /invalid width: 0 \(allowed: an integer 1\.\.=16384/);
  throwsMsg(() => new Stabilizer(160, -3, '{}', 70), /invalid height: -3/);
  throwsMsg(() => new Stabilizer(160.5, 90, '{}', 70), /invalid width: 160\.5/);
  throwsMsg(() => new Stabilizer(NaN, 90, '{}', 70), /invalid width: NaN/);
  throwsMsg(() => new Stabilizer(1e6, 90, '{}', 70), /invalid width: 1000000/);
  // In range for the core, but more memory than a wasm32 module can have: an Error, not a trap.
  throwsMsg(() => new Stabilizer(16384, 16384, '{}', 70), /16384x16384 with n_avg 6 and lookahead 0 needs about \d+ MiB \(allowed: at most 2048 MiB/);
  throwsMsg(() => new Stabilizer(3840, 2160, '{"view":{"lookahead":600}}', 70), /needs about/);
  throwsMsg(() => new Stabilizer(W, H, '{"render":{"n_avg":0}}', 70), /invalid n_avg: 0 \(allowed: 1\.\.=64/);
  throwsMsg(() => new Stabilizer(W, H, '{"render":{"margin":0.6}}', 70), /invalid margin: 0\.6 \(allowed: 0\.\.=0\.45/);
  throwsMsg(() => new Stabilizer(W, H, '{"bogus":1}', 70), /unknown field `bogus`/);
  throwsMsg(() => new Stabilizer(W, H, '{"view":{"mode":"wobble"}}', 70), /unknown variant `wobble`/);
  throwsMsg(() => new Stabilizer(W, H, '{"view":{"roll":"level"}}', 70), /unknown variant `level`/);
  new Stabilizer(W, H, '{"view":{"roll":"lock"}}', 70).free();
  throwsMsg(() => new Stabilizer(W, H, 'not json', 70), /invalid stabilizer parameters/);
  throwsMsg(() => new Stabilizer(W, H, '{}', 0), /invalid fov: "0" \(allowed: .*0 < DEG <= 179/);
  throwsMsg(() => new Stabilizer(W, H, '{}', 400), /invalid fov: "400"/);
  throwsMsg(() => new Stabilizer(W, H, '{}', undefined), /invalid lens/);
  throwsMsg(() => new Stabilizer(W, H, '{}', '{"nonsense": true}'), /lens file/);
});

test('bad frames are JS Errors, and the stabilizer keeps working after them (no trap)', () => {
  const s = new Stabilizer(W, H, '{}', 70);
  throwsMsg(() => s.measureInput(), /metrics are off/);
  s.setMetrics(true);
  throwsMsg(() => s.measureInput(), /no input frame/);
  throwsMsg(() => s.measureOutput(), /no new output frame/);
  throwsMsg(() => s.push(new Uint8Array(10), 0), /invalid frame buffer length: 10 bytes \(allowed: exactly 57600 = 160x90 RGBA\)/);
  throwsMsg(() => s.push(new Uint8Array(W * H * 3), 0), /43200 bytes/);
  throwsMsg(() => s.push(new Uint8Array(0), 0), /0 bytes/);
  throwsMsg(() => s.push(frame(W, H), NaN), /timestamp NaN is not a finite number/);
  throwsMsg(() => s.push(frame(W, H), Infinity), /not a finite number/);
  assert.ok(s.push(frame(W, H), 1.0));
  throwsMsg(() => s.push(frame(W, H), 1.0), /timestamp 1 s is not after the previous frame's 1 s/);
  throwsMsg(() => s.push(frame(W, H), 0.5), /timestamps must increase/);
  assert.ok(s.push(frame(W, H, 1, 0), 1.04));
  assert.equal(s.output().length, s.outputWidth * s.outputHeight * 4);
  s.free();
});

test('a lens file from text (project JSON) is accepted and rescaled', () => {
  const lens = readFileSync(fileURLToPath(new URL('../../../shared/data/cc9/lens.json', import.meta.url)), 'utf8');
  const cal = JSON.parse(lens);
  const w = cal.width || cal.image_width, h = cal.height || cal.image_height;
  const s = new Stabilizer(w ? w / 4 : 320, h ? h / 4 : 240, '{}', lens);
  assert.ok(s.outputHfovDeg > 10 && s.outputHfovDeg < 170);
  s.free();
});

// --- Planar frames (I420, NV12) ----------------------------------------------

/** RGBA to I420, BT.601 limited range, chroma from the 2x2 block's mean (amc-core's color.rs). */
function toI420(rgba, w, h) {
  const cw = (w + 1) >> 1, ch = (h + 1) >> 1;
  const out = new Uint8Array(w * h + 2 * cw * ch);
  for (let i = 0; i < w * h; i++) {
    const r = rgba[4 * i], g = rgba[4 * i + 1], b = rgba[4 * i + 2];
    out[i] = ((16 << 16) + 16829 * r + 33039 * g + 6416 * b + 32768) >> 16;
  }
  for (let cy = 0; cy < ch; cy++) {
    for (let cx = 0; cx < cw; cx++) {
      let r = 0, g = 0, b = 0, n = 0;
      for (let y = 2 * cy; y < Math.min(2 * cy + 2, h); y++) {
        for (let x = 2 * cx; x < Math.min(2 * cx + 2, w); x++) {
          const i = 4 * (y * w + x);
          r += rgba[i]; g += rgba[i + 1]; b += rgba[i + 2]; n++;
        }
      }
      const u = Math.floor(((128 << 16) * n - 9714 * r - 19071 * g + 28784 * b + 32768 * n) / (65536 * n));
      const v = Math.floor(((128 << 16) * n + 28784 * r - 24103 * g - 4681 * b + 32768 * n) / (65536 * n));
      out[w * h + cy * cw + cx] = Math.min(255, Math.max(0, u));
      out[w * h + cw * ch + cy * cw + cx] = Math.min(255, Math.max(0, v));
    }
  }
  return out;
}

/** I420 to NV12: the Y plane, then U and V interleaved. */
function toNv12(i420, w, h) {
  const n = w * h, nc = ((w + 1) >> 1) * ((h + 1) >> 1);
  const out = new Uint8Array(i420.length);
  out.set(i420.subarray(0, n));
  for (let k = 0; k < nc; k++) { out[n + 2 * k] = i420[n + k]; out[n + 2 * k + 1] = i420[n + nc + k]; }
  return out;
}

const i420Len = (w, h) => w * h + 2 * ((w + 1) >> 1) * ((h + 1) >> 1);

test('I420 frames: I420 output (Y within a few codes of the RGBA run of the same frames), black borders Y16/U=V128', () => {
  // Odd sizes too: chroma planes of ceil(w/2) x ceil(h/2).
  for (const [w, h] of [[W, H], [161, 91]]) {
    const rgba = new Stabilizer(w, h, '{}', 70);
    const yuv = new Stabilizer(w, h, '{}', 70, 'I420');
    assert.equal(rgba.format, 'RGBA');
    assert.equal(rgba.outputFormat, 'RGBA');
    assert.equal(yuv.format, 'I420');
    assert.equal(yuv.outputFormat, 'I420');
    assert.equal(yuv.inputLength, i420Len(w, h));
    assert.equal(yuv.inputBuffer().length, i420Len(w, h));
    const ow = yuv.outputWidth, oh = yuv.outputHeight;
    let worst = 0, sum = 0, count = 0, borders = 0;
    for (let i = 0; i < 10; i++) {
      const f = frame(w, h, 1.5 * i, -0.7 * i);
      const a = rgba.push(f, i / 30);
      yuv.inputBuffer().set(toI420(f, w, h));
      const b = yuv.pushInput(i / 30);
      assert.ok(a && b, `telemetry for frame ${i}`);
      // Same motion estimate from RGBA luma and from the Y plane.
      for (let k = 0; k < 3; k++) assert.ok(Math.abs(a.r_est[k] - b.r_est[k]) < 2e-3, `r_est ${a.r_est} vs ${b.r_est}`);
      const out = yuv.output();
      assert.equal(out.length, i420Len(ow, oh));
      const ref = toI420(rgba.output(), ow, oh);
      const cov = yuv.coverage();
      assert.equal(cov.length, ow * oh);
      for (let p = 0; p < ow * oh; p++) {
        if (cov[p] === 0) {
          assert.equal(out[p], 16, 'black border luma');
          borders++;
          continue;
        }
        const d = Math.abs(out[p] - ref[p]);
        worst = Math.max(worst, d); sum += d; count++;
      }
    }
    assert.ok(count > 0);
    assert.ok(sum / count < 1.0 && worst <= 6, `${w}x${h}: mean |dY| ${sum / count}, max ${worst}`);
    if (borders) {
      // A border pixel's chroma is grey too.
      const cw = (ow + 1) >> 1, cov = yuv.coverage(), out = yuv.output();
      const p = cov.findIndex((c) => c === 0), x = p % ow, y = Math.floor(p / ow);
      const cov4 = [0, 1].every((dy) => [0, 1].every((dx) => (y - (y % 2) + dy >= oh || x - (x % 2) + dx >= ow) || cov[(y - (y % 2) + dy) * ow + x - (x % 2) + dx] === 0));
      if (cov4) {
        const c = (y >> 1) * cw + (x >> 1), nc = cw * ((oh + 1) >> 1);
        assert.equal(out[ow * oh + c], 128);
        assert.equal(out[ow * oh + nc + c], 128);
      }
    }
    rgba.free(); yuv.free();
  }
});

test('NV12 frames give exactly the I420 output of the de-interleaved frames; push and pushInput agree', () => {
  const a = new Stabilizer(W, H, '{}', 70, 'I420'), b = new Stabilizer(W, H, '{}', 70, 'NV12'), c = new Stabilizer(W, H, '{}', 70, 'NV12');
  assert.equal(b.format, 'NV12');
  assert.equal(b.outputFormat, 'I420');
  assert.equal(b.inputBuffer().length, i420Len(W, H));
  for (const s of [a, b, c]) s.setMetrics(true);
  for (let i = 0; i < 8; i++) {
    const f = toI420(frame(W, H, i, (i * 3) % 5), W, H);
    a.inputBuffer().set(f);
    const ma = a.measureInput();
    const ta = a.pushInput(i / 25);
    b.inputBuffer().set(toNv12(f, W, H));
    const mb = b.measureInput();
    const tb = b.pushInput(i / 25);
    const tc = c.push(toNv12(f, W, H), i / 25);
    assert.deepEqual(mb, ma, 'input metrics of NV12 = I420');
    assert.deepEqual(tb.r_est, ta.r_est);
    assert.deepEqual(tc.r_est, ta.r_est);
    assert.deepEqual(b.output(), a.output());
    assert.deepEqual(c.output(), a.output());
    assert.deepEqual(b.measureOutput(), a.measureOutput());
  }
  a.free(); b.free(); c.free();
});

test('I420 metrics: input and output measured on the Y plane, close to the RGBA run', () => {
  const rgba = new Stabilizer(W, H, '{}', 70), yuv = new Stabilizer(W, H, '{}', 70, 'I420');
  rgba.setMetrics(true); yuv.setMetrics(true);
  throwsMsg(() => yuv.measureInput(), /no input frame/);
  for (let i = 0; i < 8; i++) {
    const f = frame(W, H, i, -i);
    rgba.inputBuffer().set(f);
    yuv.inputBuffer().set(toI420(f, W, H));
    const mi = [rgba.measureInput(), yuv.measureInput()];
    rgba.pushInput(i / 30); yuv.pushInput(i / 30);
    const mo = [rgba.measureOutput(), yuv.measureOutput()];
    for (const [x, y] of [mi, mo]) {
      assert.ok(y.sharpness > 0);
      assert.ok(Math.abs(x.sharpness - y.sharpness) < 0.1 * x.sharpness, `sharpness ${x.sharpness} vs ${y.sharpness}`);
      if (i > 0) assert.ok(Math.abs(x.rms_change - y.rms_change) < 0.15 * x.rms_change + 2e-3, `rms_change ${x.rms_change} vs ${y.rms_change}`);
    }
  }
  const sum = yuv.summary();
  assert.equal(sum.output.frames, 8);
  rgba.free(); yuv.free();
});

test('planar formats: bad names and buffer lengths are JS Errors naming the allowed values', () => {
  throwsMsg(() => new Stabilizer(W, H, '{}', 70, 'YUV'), /invalid format: "YUV" \(allowed: "RGBA" \(the default\), "I420" or "NV12"\)/);
  throwsMsg(() => new Stabilizer(W, H, '{}', 70, 'i420'), /invalid format: "i420"/);
  throwsMsg(() => new Stabilizer(W, H, '{}', 70, ''), /invalid format: ""/);
  assert.equal(new Stabilizer(W, H, '{}', 70, undefined).format, 'RGBA');
  assert.equal(new Stabilizer(W, H, '{}', 70, null).format, 'RGBA');
  assert.equal(new Stabilizer(W, H, '{}', 70, 'RGBA').format, 'RGBA');
  const s = new Stabilizer(W, H, '{}', 70, 'I420');
  throwsMsg(() => s.push(new Uint8Array(W * H * 4), 0), /invalid frame buffer length: 57600 bytes \(allowed: exactly 21600 = 160x90 I420\)/);
  throwsMsg(() => s.push(new Uint8Array(W * H), 0), /14400 bytes/);
  const n = new Stabilizer(W, H, '{}', 70, 'NV12');
  throwsMsg(() => n.push(new Uint8Array(7), 0), /invalid frame buffer length: 7 bytes \(allowed: exactly 21600 = 160x90 NV12\)/);
  // Still usable after the errors.
  assert.ok(s.push(toI420(frame(W, H), W, H), 0));
  assert.ok(n.push(toNv12(toI420(frame(W, H), W, H), W, H), 0));
  s.free(); n.free();
});

// --- The page's pure modules on the API's real output ----------------------
const { TELEMETRY_HEADER, telemetryCsv, rowsFromCsv, rowsFromWorker } = await import('../src/telemetry.js');
const { summaryRows, localSummary } = await import('../src/summary.js');
const { serverQuery, checkValue, allowedText, titleOf, labelOf, smoothingRates, smoothingLevel, SMOOTHING } = await import('../src/settings.js');
const { niceTicks } = await import('../src/plot.js');

test("the page's telemetry CSV has the CLI's header, column order and number formats", () => {
  const rust = readFileSync(fileURLToPath(new URL('../../amc-engine/src/telemetry.rs', import.meta.url)), 'utf8');
  assert.equal(TELEMETRY_HEADER, rust.match(/TELEMETRY_HEADER: &str = "([^"]+)"/)[1]);
  const s = new Stabilizer(W, H, '{}', 70);
  s.setMetrics(true);
  const tels = [];
  for (let i = 0; i < 6; i++) {
    s.inputBuffer().set(frame(W, H, i, i % 2));
    const im = s.measureInput();
    const tel = s.pushInput(i / 30);
    tel.metrics = s.measureOutput();
    tel.input_metrics = im;
    tels.push(tel);
  }
  const lines = telemetryCsv(tels).trim().split('\n');
  const head = lines[0].split(',');
  assert.deepEqual(head.slice(0, 8), ['frame', 't', 'rx', 'ry', 'rz', 'vx', 'vy', 'vz']);
  assert.equal(lines[0].slice(0, TELEMETRY_HEADER.length), TELEMETRY_HEADER);
  assert.equal(lines.length, 7);
  for (const [i, line] of lines.slice(1).entries()) {
    const c = line.split(',');
    assert.equal(c.length, head.length);
    const tel = tels[i];
    assert.equal(Number(c[0]), tel.frame);
    assert.equal(c[1], tel.t.toFixed(6));
    // Rotation vectors in radians, Rust's `{:e}` (no `+` in the exponent), exact.
    for (let k = 0; k < 3; k++) {
      assert.equal(Number(c[2 + k]), tel.r_est[k]);
      assert.equal(Number(c[5 + k]), tel.r_view[k]);
      assert.match(c[2 + k], /^-?\d(\.\d+)?e-?\d+$/);
    }
    assert.equal(Number(c[8]), Number(tel.speed_est_dps.toFixed(4)));
    assert.equal(c[12], tel.saccade ? '1' : '0');
    // The framing columns after the tracking diagnostics, as the CLI writes them.
    assert.equal(head[18], 'zoom');
    assert.equal(c[18], tel.zoom.toFixed(5));
    assert.equal(Number(c[19]), tel.uncovered);
    // The rotation across the readout last, radians in Rust's `{:e}`.
    assert.deepEqual(head.slice(20, 23), ['readout_rx', 'readout_ry', 'readout_rz']);
    for (let k = 0; k < 3; k++) assert.equal(Number(c[20 + k]), tel.readout_rotation[k]);
  }
  assert.equal(lines[1].split(',').at(-3), '', 'no normal flow on the first frame');
  // Read back as the plot reads the job API's CSV.
  const rows = rowsFromCsv(telemetryCsv(tels));
  const direct = rowsFromWorker(tels);
  assert.equal(rows.length, 6);
  for (const [i, r] of rows.entries()) {
    assert.ok(Math.abs(r.est - direct[i].est) < 1e-4);
    assert.ok(r.nfOut === null ? direct[i].nfOut === null : Math.abs(r.nfOut - direct[i].nfOut) < 1e-9);
  }
  // The summary table: the input's speed is the camera's (the input accumulator's own is always 0).
  const sum = s.summary();
  assert.equal(sum.input.rms_speed_est_dps, 0);
  const table = summaryRows(localSummary({ width: W, height: H, outWidth: s.outputWidth, outHeight: s.outputHeight },
    { frames: 6, fps: 100, summary: sum }, 'stabilize'));
  const speed = table.find((r) => r[0].startsWith('Angular speed'));
  assert.equal(speed[1], sum.output.rms_speed_est_dps.toFixed(1));
  assert.ok(Number(speed[1]) > 0);
  // zoom auto keeps the input's size; zoom none's fixed margin is named as a crop.
  assert.deepEqual(table.find((r) => r[0] === 'Size (pixels)').slice(1, 3), ['160 × 90', '160 × 90']);
  const cropped = summaryRows(localSummary({ width: W, height: H, outWidth: 120, outHeight: 68 },
    { frames: 6, fps: 100, summary: sum }, 'stabilize'));
  assert.deepEqual(cropped.find((r) => r[0] === 'Size (pixels)').slice(1, 3), ['160 × 90', '120 × 68 (central crop, 1.33× zoom)']);
  assert.ok(!table.some((r) => r[0] === 'Saccades'), 'no saccade row outside saccade mode');
  s.free();
});

test("options(): the core's option table, each default the core's; resolveOptions reads values as the CLI does", () => {
  const table = options();
  const names = table.map((o) => o.name);
  for (const n of ['mode', 'roll', 'fov', 'readout_ms', 'n_avg', 'deghost', 'antialias', 'interpolation', 'n_track', 'margin', 'zoom',
    'max_crop', 'track_width', 'lookahead', 'rate_a', 'rate_b', 'roll_rate_a', 'roll_rate_b', 'output_width', 'output_height']) {
    assert.ok(names.includes(n), n);
  }
  // The table as amc-core/src/options.rs writes it.
  const rust = readFileSync(fileURLToPath(new URL('../../amc-core/src/options.rs', import.meta.url)), 'utf8');
  for (const o of table) {
    assert.equal(o.flag, o.name.replaceAll('_', '-'));
    assert.ok(rust.includes(`help: "${o.help.replaceAll('"', '\\"')}"`), `${o.name}: ${o.help}`);
    assert.ok(rust.includes(`value_name: "${o.value_name}"`), o.value_name);
  }
  const byName = Object.fromEntries(table.map((o) => [o.name, o]));
  assert.deepEqual(byName.lookahead.allowed, { kind: 'integer', min: 0, max: 600 });
  assert.deepEqual(byName.fov.allowed, { kind: 'number', min: 0, max: 179, above_min: true, words: ['auto'] });
  assert.equal(byName.fov.default, 'auto');
  assert.equal(byName.readout_ms.default, null);
  assert.equal(byName.mode.default, 'stabilize');
  // No values: exactly the core's default parameters (the shutter apart), fov auto, the lens file's readout.
  const core = new Stabilizer(64, 48, '{}', 70);
  const def = JSON.parse(core.paramsJson());
  core.free();
  delete def.shutter;
  const r = resolveOptions('{}');
  assert.deepEqual(r.params, def);
  assert.equal(r.fov, 'auto');
  assert.equal(r.readout, null);
  // Each option's default, given as its value, changes nothing.
  const defaults = Object.fromEntries(table.filter((o) => o.default !== null).map((o) => [o.name, String(o.default)]));
  assert.deepEqual(resolveOptions(JSON.stringify(defaults)), r);
  const set = resolveOptions(JSON.stringify({ n_avg: '4', fov: '90', readout_ms: 'auto', roll: 'lock', rate_a: '1.5', output_width: '' }));
  assert.equal(set.params.render.n_avg, 4);
  assert.equal(set.params.view.roll, 'lock');
  assert.equal(set.params.view.rate_a, 1.5);
  assert.equal(set.params.render.output_width, null);
  assert.equal(set.fov, 90);
  assert.equal(set.readout, 'auto');
  throwsMsg(() => resolveOptions('{"n_avg":"0"}'), /invalid n_avg/);
  throwsMsg(() => resolveOptions('{"bogus":"1"}'), /bogus/);
});

test("the page's check of every option is the core's: the same values pass, the message names the flag and the table's range", () => {
  const table = options();
  const core = (name, text) => { try { resolveOptions(JSON.stringify({ [name]: text })); return true; } catch { return false; } };
  for (const o of table) {
    const a = o.allowed;
    const probes = a.kind === 'words'
      ? [...a.words, a.words[0].toUpperCase(), 'wobble']
      : [a.min, a.max, a.min - (a.kind === 'integer' ? 1 : 1e-6), a.max + (a.kind === 'integer' ? 1 : 1e-6 * Math.max(1, a.max)),
        (a.min + a.max) / 2, 'x', 'nan', 'inf', ...(a.words || [])].map(String);
    for (const p of probes) {
      const page = checkValue(o, p);
      assert.equal(!page.error, core(o.name, p), `${o.name}=${p}: page ${JSON.stringify(page)}`);
    }
    // Empty: the default (nothing sent to the core).
    assert.deepEqual(checkValue(o, ''), { value: null });
    assert.ok(titleOf(o).startsWith(`--${o.flag} ${o.value_name}: `) && titleOf(o).endsWith(o.help), titleOf(o));
    assert.match(labelOf(o), new RegExp(` \\(--${o.flag}\\)$`));
    if (a.kind !== 'words') {
      const bad = checkValue(o, String(a.max * 2 + 1));
      assert.match(bad.error, new RegExp(`^.* \\(--${o.flag}\\): .* is out of range \\(allowed: `));
      assert.ok(bad.error.includes(allowedText(o)), bad.error);
      // The range the page names is the one the help gives.
      const range = a.above_min ? `${a.min} < ${o.value_name.split('|')[0]} <= ${a.max}` : `${a.min}..=${a.max}`;
      assert.ok(o.help.includes(range), `${o.name}: ${range} in ${o.help}`);
    }
  }
  const byName = Object.fromEntries(table.map((o) => [o.name, o]));
  assert.match(checkValue(byName.n_avg, '0').error, /^Averaging window \(--n-avg\): 0 is out of range \(allowed: 1\.\.=64, whole numbers; empty: the default, 6\)\.$/);
  assert.match(checkValue(byName.fov, '180').error, /^Field of view \(--fov\): 180 is out of range \(allowed: 0 < DEG <= 179 or auto; empty: the default, auto\)\.$/);
  assert.deepEqual(checkValue(byName.fov, 'Auto'), { value: 'auto' });
  assert.match(checkValue(byName.lookahead, '601').error, /allowed: 0\.\.=600, whole numbers/);
  assert.match(checkValue(byName.readout_ms, '150').error, /allowed: 0\.\.=100 or auto; empty: the default, the lens file's readout_ms or Gyroflow frame_readout_time, else 0\)/);
});

test('smoothing strength: each level is rate_a and rate_b times one factor; normal is exactly the defaults', () => {
  const table = options();
  const def = resolveOptions('{}').params.view;
  assert.deepEqual(smoothingRates(table, 'normal'), { rate_a: def.rate_a, rate_b: def.rate_b });
  assert.deepEqual(smoothingRates(table, 'normal'), { rate_a: 2, rate_b: 20 });
  for (const l of SMOOTHING) {
    const r = smoothingRates(table, l.value);
    assert.deepEqual(r, { rate_a: l.factor * 2, rate_b: l.factor * 20 });
    assert.equal(smoothingLevel(table, r.rate_a, r.rate_b), l.value);
    // The core takes them.
    const v = resolveOptions(JSON.stringify({ rate_a: String(r.rate_a), rate_b: String(r.rate_b) })).params.view;
    assert.deepEqual([v.rate_a, v.rate_b], [r.rate_a, r.rate_b]);
  }
  assert.deepEqual(SMOOTHING.map((l) => l.factor), [2, 1, 0.5, 0.25]);
  assert.equal(smoothingLevel(table, null, null), 'normal');
  assert.equal(smoothingLevel(table, 3, 20), 'custom');
});

test('the server query: the mode and the format, and every other option only where it is not the default', () => {
  const table = options();
  const q = (values, extra = {}) => serverQuery({ values: { mode: 'stabilize', ...values }, format: 'mp4', lensFile: null, ...extra }, table);
  assert.equal(q({}).toString(), 'mode=stabilize&format=mp4');
  // The defaults typed in are not sent either.
  assert.equal(q({ n_avg: '6', fov: 'auto', rate_a: '2', zoom: 'auto', interpolation: 'bilinear' }).toString(), 'mode=stabilize&format=mp4');
  const set = q({ n_avg: '4', rate_a: '1.5', fov: '90', readout_ms: 'auto', deghost: '6', interpolation: 'bicubic', roll: 'lock', zoom: 'static', output_width: '320' }, { format: 'webm' });
  assert.deepEqual(Object.fromEntries(set), {
    mode: 'stabilize', roll: 'lock', fov: '90', readout_ms: 'auto', n_avg: '4', deghost: '6', interpolation: 'bicubic', zoom: 'static',
    rate_a: '1.5', output_width: '320', format: 'webm',
  });
  // A lens file goes instead of the field of view.
  assert.equal(q({ fov: '90' }, { lensFile: {} }).has('fov'), false);
  // Every name the page sends is an option the server knows (the same table).
  for (const k of set.keys()) assert.ok(k === 'format' || table.some((o) => o.name === k), k);
});

test('plot ticks are round numbers covering the range', () => {
  assert.deepEqual(niceTicks(0, 7.2, 5).ticks, [0, 2, 4, 6, 8]);
  assert.deepEqual(niceTicks(0, 0.37, 4).ticks.map((v) => +v.toFixed(3)), [0, 0.1, 0.2, 0.3, 0.4]);
  const t = niceTicks(0, 123, 5);
  assert.ok(t.max >= 123 && t.ticks.length <= 7);
});

test('readout_ms reaches the core: its range, a lens file\'s readout, the page\'s query', () => {
  const readout = (params, lens = 70) => {
    const st = new Stabilizer(64, 48, JSON.stringify(params), lens);
    const ms = JSON.parse(st.paramsJson()).shutter.readout_ms;
    st.free();
    return ms;
  };
  const f = options().find((x) => x.name === 'readout_ms').allowed;
  assert.equal(readout({}), 0);
  assert.equal(readout({ shutter: { readout_ms: f.max } }), f.max);
  assert.equal(readout({ shutter: { readout_ms: 16.5 } }), 16.5);
  throwsMsg(() => new Stabilizer(64, 48, JSON.stringify({ shutter: { readout_ms: f.max + 1e-6 } }), 70), /invalid readout_ms/);
  throwsMsg(() => new Stabilizer(64, 48, JSON.stringify({ shutter: { readout_ms: -1 } }), 70), /invalid readout_ms/);
  // A lens file's readout applies unless the parameters set one.
  const lens = (extra) => JSON.stringify({ model: 'pinhole', width: 64, height: 48, fx: 50, fy: 50, cx: 31.5, cy: 23.5, ...extra });
  assert.equal(readout({}, lens({ readout_ms: 12 })), 12);
  assert.equal(readout({ shutter: { readout_ms: 3 } }, lens({ readout_ms: 12 })), 3);
  assert.equal(readout({}, lens({})), 0);
  throwsMsg(() => new Stabilizer(64, 48, '{}', lens({ readout_ms: 250 })), /readout_ms.*0\.\.=100/);
  // The server gets it only when set: a number or auto.
  const q = (r) => serverQuery({ values: { mode: 'stabilize', readout_ms: r }, format: 'mp4', lensFile: null }, options());
  assert.equal(q(null).has('readout_ms'), false);
  assert.equal(q('14.5').get('readout_ms'), '14.5');
  assert.equal(q('auto').get('readout_ms'), 'auto');
});

test('ReadoutEstimator: frames in, an estimate out (not confident on a sliding test pattern)', () => {
  const est = new ReadoutEstimator(W, H, '{}', 70);
  assert.equal(est.isFull, false);
  for (let i = 0; i < 30; i++) {
    est.inputBuffer().set(frame(W, H, i, 0));
    est.pushInput(i / 30);
  }
  assert.equal(est.frames, 30);
  const e = est.finish();
  for (const k of ['readout_ms', 'explained', 'motion_deg', 'frames']) assert.equal(typeof e[k], 'number', k);
  assert.equal(typeof e.confident, 'boolean');
  assert.ok(e.readout_ms >= 0 && e.readout_ms <= 100, String(e.readout_ms));
  throwsMsg(() => est.finish(), /finished/);
  est.free();
  // Too few frames to fit: an answer, not an error (the page then uses 0).
  const short = new ReadoutEstimator(W, H, '{}', 70);
  short.push(frame(W, H), 0);
  const s = short.finish();
  assert.equal(s.confident, false);
  short.free();
  // Its arguments are checked as the Stabilizer's are.
  throwsMsg(() => new ReadoutEstimator(0, H, '{}', 70), /invalid width/);
  throwsMsg(() => new ReadoutEstimator(W, H, '{}', 70, 'YUYV'), /invalid format/);
});

test('PassPlan: the core plans the first passes, their order, frame budgets and results', () => {
  // Nothing to estimate: no pass; the parameters the main stabilizer takes.
  const none = new PassPlan(W, H, '{}', 70);
  assert.deepEqual(none.passes, []);
  assert.equal(none.pass, undefined);
  assert.equal(none.isFull, true);
  assert.equal(JSON.parse(none.paramsJson()).shutter.readout_ms, 0);
  none.free();
  // readout auto, then zoom static, in that order; the readout pass takes the core's budget.
  const json = '{"framing":{"zoom":"static"}}';
  const plan = new PassPlan(W, H, json, 70, undefined, 'auto');
  assert.deepEqual(plan.passes, ['readout', 'static_zoom']);
  assert.equal(plan.pass, 'readout');
  assert.equal(plan.frameBudget, 180);
  for (let i = 0; i < 30; i++) {
    plan.inputBuffer().set(frame(W, H, i, 0));
    plan.pushInput(i / 30);
  }
  assert.equal(plan.frames, 30);
  throwsMsg(() => plan.paramsJson(), /readout/);
  const r = plan.finishPass();
  assert.equal(r.pass, 'readout');
  assert.ok(['estimated', 'fell_back'].includes(r.note), r.note);
  assert.equal(r.readout_ms, r.note === 'estimated' ? r.estimate.readout_ms : 0);
  assert.equal(r.estimate.frames, 30);
  // The zoom pass reads the whole clip with the readout found.
  assert.equal(plan.pass, 'static_zoom');
  assert.equal(plan.frameBudget, undefined);
  const params = plan.paramsJson();
  assert.equal(JSON.parse(params).shutter.readout_ms, r.readout_ms);
  for (let i = 0; i < 20; i++) plan.push(frame(W, H, i, 0), i / 30);
  assert.equal(plan.isFull, false);
  const z = plan.finishPass();
  assert.equal(z.pass, 'static_zoom');
  assert.equal(plan.staticZoom, z.zoom);
  assert.equal(plan.pass, undefined);
  plan.free();
  // The same zoom as a stabilizer that does not render, by hand.
  const pre = new Stabilizer(W, H, params, 70);
  pre.setRendering(false);
  for (let i = 0; i < 20; i++) pre.push(frame(W, H, i, 0), i / 30);
  while (pre.finish()) { /* drain */ }
  assert.equal(pre.maxZoomNeed(), z.zoom);
  pre.free();
  // Saccade mode holds no static zoom: no pass. A readout given is no pass either.
  const passes = (j, readout) => { const p = new PassPlan(W, H, j, 70, undefined, readout); const v = p.passes; p.free(); return v; };
  assert.deepEqual(passes('{"framing":{"zoom":"static"},"view":{"mode":"saccade"}}'), []);
  assert.deepEqual(passes('{}', 12.5), []);
  const given = new PassPlan(W, H, '{}', 70, undefined, 12.5);
  assert.equal(JSON.parse(given.paramsJson()).shutter.readout_ms, 12.5);
  given.free();
  throwsMsg(() => new PassPlan(W, H, '{}', 70, undefined, 'fast'), /invalid readout_ms/);
  throwsMsg(() => new PassPlan(0, H, '{}', 70), /invalid width/);
  const ended = new PassPlan(W, H, '{}', 70, undefined, 'auto');
  throwsMsg(() => ended.finishPass(), /at least one frame/);
  ended.free();
});

test('PassPlan with lens "auto" (fov auto): a lens pass over the first frames gives the degrees the stabilizer takes', () => {
  const plan = new PassPlan(W, H, '{"framing":{"zoom":"static"}}', 'auto', 'RGBA', 'auto');
  assert.deepEqual(plan.passes, ['lens', 'readout', 'static_zoom']);
  assert.equal(plan.pass, 'lens');
  assert.equal(plan.frameBudget, 90);
  for (let i = 0; i < 30; i++) plan.push(frame(W, H, 2 * i, i % 3), i / 30);
  assert.equal(plan.frames, 30);
  const l = plan.finishPass();
  assert.equal(l.pass, 'lens');
  assert.ok(['estimated', 'fell_back'].includes(l.note), l.note);
  assert.ok(l.hfov_deg > 0 && l.hfov_deg <= 179, String(l.hfov_deg));
  if (l.note === 'fell_back') assert.equal(l.hfov_deg, 70);
  assert.equal(plan.pass, 'readout');
  plan.free();
  // No other pass: the lens pass alone, then the parameters.
  const only = new PassPlan(W, H, '{}', 'AUTO');
  assert.deepEqual(only.passes, ['lens']);
  for (let i = 0; i < 12; i++) only.push(frame(W, H, i, 0), i / 30);
  const found = only.finishPass();
  assert.equal(only.pass, undefined);
  assert.equal(JSON.parse(only.paramsJson()).shutter.readout_ms, 0);
  only.free();
  // The stabilizer takes the degrees found; "auto" itself is the plan's.
  new Stabilizer(W, H, '{}', found.hfov_deg).free();
  throwsMsg(() => new Stabilizer(W, H, '{}', 'auto'), /invalid lens: "auto".*PassPlan/);
  throwsMsg(() => new ReadoutEstimator(W, H, '{}', 'auto'), /invalid lens: "auto"/);
  // Too few frames to estimate: an error naming them.
  const short = new PassPlan(W, H, '{}', 'auto');
  short.push(frame(W, H), 0);
  throwsMsg(() => short.finishPass(), /frames/);
  short.free();
  // The pass keeps its frames: sizes whose 90 frames would not fit in WebAssembly memory are refused up front.
  throwsMsg(() => new PassPlan(4096, 2160, '{}', 'auto'), /fov auto keeps the clip's first 90 frames.*give the field of view in degrees/);
  new PassPlan(4096, 2160, '{}', 70).free();
});

test('render share: two stabilizers fed every frame draw each output once, byte for byte the single one\'s; measureOutputOf measures them in order', () => {
  for (const format of ['RGBA', 'I420']) {
    const make = () => new Stabilizer(W, H, '{"view":{"lookahead":3}}', 70, format);
    const one = make(), shares = [make(), make()];
    one.setMetrics(true);
    shares[0].setMetrics(true); // the page's worker: it measures every output, wherever drawn
    shares.forEach((s, i) => s.setRenderShare(2, i));
    const oneOut = [], drawn = [], measured = [];
    const take = (tel, s, list) => { if (tel) list.push({ tel, output: s.output().slice(), coverage: s.coverage().slice() }); };
    const step = (push) => {
      take(push(one), one, oneOut);
      if (oneOut.length > measured.length) measured.push(one.measureOutput());
      shares.forEach((s, i) => { const tel = push(s); if (tel && tel.frame % 2 === i) take(tel, s, drawn); });
    };
    for (let i = 0; i < 12; i++) {
      const f = format === 'RGBA' ? frame(W, H, 1.5 * i, -i) : toI420(frame(W, H, 1.5 * i, -i), W, H);
      step((s) => { s.inputBuffer().set(f); return s.pushInput(i / 30); });
    }
    for (let k = 0; k < 4; k++) step((s) => s.finish());
    assert.equal(oneOut.length, 12);
    assert.deepEqual(drawn.map((d) => d.tel.frame), [...Array(12).keys()]);
    for (const [j, d] of drawn.entries()) {
      assert.deepEqual(d.output, oneOut[j].output, `${format} output ${j}`);
      assert.deepEqual(d.coverage, oneOut[j].coverage, `${format} coverage ${j}`);
      assert.equal(d.tel.valid_fraction, oneOut[j].tel.valid_fraction);
      // Measured in order from the copies: the metrics of measuring each output as it came.
      assert.deepEqual(shares[0].measureOutputOf(d.output, d.coverage, d.tel.valid_fraction), measured[j], `${format} metrics ${j}`);
    }
    throwsMsg(() => shares[0].measureOutputOf(drawn[0].output, drawn[0].coverage, 1), /no output frame left/);
    throwsMsg(() => shares[0].measureOutputOf(drawn[0].output, drawn[0].coverage.subarray(1), 1), /coverage: .* expected/);
    assert.deepEqual(shares[0].summary().output, one.summary().output);
    one.free(); shares.forEach((s) => s.free());
  }
  const s = new Stabilizer(W, H, '{}', 70);
  throwsMsg(() => s.setRenderShare(0, 0), /1 to 16/);
  throwsMsg(() => s.setRenderShare(2, 2), /count - 1/);
  const saccade = new Stabilizer(W, H, '{"view":{"mode":"saccade"}}', 70);
  throwsMsg(() => saccade.setRenderShare(2, 0), /saccade/);
  s.free(); saccade.free();
});

const sharedData = (rel) => fileURLToPath(new URL(`../../../shared/data/${rel}`, import.meta.url));

test("ClipGyro reads karma.mp4's GPMF track (a GoPro HERO5): its gyro samples, ~400 Hz; a clip without one, or garbage, is null", () => {
  const karma = readFileSync(sharedData('karma/karma.mp4'));
  const log = ClipGyro.read(karma, 'karma.mp4');
  assert.ok(log, 'a track');
  assert.match(log.source, /^GoPro/);
  // 12 s at ~400 Hz (the CLI's test of the same track: over 4000 samples).
  assert.ok(log.samples > 4000, String(log.samples));
  assert.ok(Math.abs(log.rateHz - 400) < 20, String(log.rateHz));
  assert.equal(log.videoClock, false);
  const times = log.times(), rates = log.rates();
  assert.equal(times.length, log.samples);
  assert.equal(rates.length, 3 * log.samples);
  assert.ok(times.every((t, i) => i === 0 || t > times[i - 1]), 'times increase');
  assert.ok(rates.every(Number.isFinite) && rates.some((w) => Math.abs(w) > 0.01), 'rates in rad/s, some motion');
  // Made again from its parts (the page parses in a worker of its own).
  const again = ClipGyro.fromParts(log.source, log.videoClock, log.readoutMs, times, rates);
  assert.deepEqual([again.source, again.samples, again.rateHz, again.readoutMs], [log.source, log.samples, log.rateHz, log.readoutMs]);
  assert.deepEqual(again.rates(), rates);
  throwsMsg(() => ClipGyro.fromParts('x', false, undefined, times, rates.subarray(1)), /three per time/);
  log.free(); again.free();
  // No track: a phone's MP4, garbage, nothing.
  assert.equal(ClipGyro.read(readFileSync(sharedData('cup/cup.mp4')), 'cup.mp4'), undefined);
  assert.equal(ClipGyro.read(new Uint8Array(4096).map((_, i) => (i * 7919) & 255), 'junk.mp4'), undefined);
  assert.equal(ClipGyro.read(new Uint8Array(0), 'empty.mp4'), undefined);
  // Cut short (no moov at its end): telemetry-parser would panic, which aborts a wasm32
  // instance; refused before it is called, and the module goes on.
  for (const len of [1 << 20, karma.length - 1000]) assert.equal(ClipGyro.read(karma.subarray(0, len), 'karma.mp4'), undefined);
  const after = ClipGyro.read(karma, 'karma.mp4');
  assert.ok(after && after.samples > 4000);
  after.free();
});

test('GyroPass: a first pass synchronized and fused with a matching log gives every frame its pose; the main stabilizer renders with them; a log of another clip is a warning', () => {
  // The camera pans and tilts (the scene shifts by x(t), y(t) pixels); the
  // log is that motion as rates (rad/s, a pinhole of 70 degrees).
  const fps = 30, n = 90, f = W / 2 / Math.tan((35 * Math.PI) / 180);
  const x = (t) => 20 * Math.sin(7.5 * t), y = (t) => 10 * Math.sin(5.1 * t + 1);
  const dx = (t) => 150 * Math.cos(7.5 * t), dy = (t) => 51 * Math.cos(5.1 * t + 1);
  const times = [], rates = [];
  for (let t = -0.5; t < n / fps + 0.5; t += 1 / 200) {
    times.push(t);
    rates.push(dy(t) / f, -dx(t) / f, 0);
  }
  const log = ClipGyro.fromParts('test log', false, undefined, new Float64Array(times), new Float64Array(rates));
  const frames = Array.from({ length: n }, (_, i) => frame(W, H, x(i / fps), y(i / fps)));
  const pass = new GyroPass(W, H, '{}', 70);
  frames.forEach((d, i) => pass.push(d, i / fps));
  const found = pass.fuse(log);
  pass.free();
  assert.equal(found.warning, undefined, found.warning);
  assert.match(found.line, /^gyro: test log \(\d+ samples, 200 Hz\): offset /);
  assert.equal(found.report.source, 'test log');
  assert.ok(found.report.correlation > 0.9, JSON.stringify(found.report));
  assert.ok(Math.abs(found.report.offset_s) < 0.01, JSON.stringify(found.report));
  assert.ok(found.report.fused_frames > 0.8 * n, JSON.stringify(found.report));
  const poses = JSON.parse(found.poses);
  assert.equal(poses.length, n);
  // The main pass: every frame rendered with its pose, none beyond them.
  const s = new Stabilizer(W, H, '{}', 70);
  s.setPoses(found.poses);
  let out = 0;
  frames.forEach((d, i) => { if (s.push(d, i / fps)) out++; });
  while (s.finish()) out++;
  assert.equal(out, n);
  throwsMsg(() => s.push(frames[0], 99), /more frames than the gyro pass gave poses for/);
  throwsMsg(() => s.setPoses('{"not": "poses"}'), /poses: not a gyro pass's poses/);
  s.free();
  // Another clip's log (no motion where this one moves): the run goes on from the picture alone.
  const still = ClipGyro.fromParts('still', false, undefined, new Float64Array(times), new Float64Array(rates.length));
  const other = new GyroPass(W, H, '{}', 70);
  frames.forEach((d, i) => other.push(d, i / fps));
  const warned = other.fuse(still);
  assert.match(warned.warning, /^cannot synchronize the gyro log still with the video: .*; the output uses the video alone$/);
  assert.equal(warned.poses, undefined);
  other.free(); still.free(); log.free();
});
