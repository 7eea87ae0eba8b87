// Times amc-wasm on raw frames (fetched once, held in memory): the stabilizer
// alone, as the page's worker runs it (inputBuffer + pushInput), for RGBA or
// I420 frames (`fmt`). With `vf` (raw I420 frames of the same clip) it also
// times the page's WebCodecs path without decoder and encoder: I420
// VideoFrames (made up front, as a software decoder gives them) copied into
// the module (`copyTo`: as is for I420, converted by the browser for RGBA),
// stabilized, and each output wrapped in a new VideoFrame (as for the encoder).
import init, { Stabilizer, simdEnabled } from './pkg/amc_wasm.js';

import { copyOptions } from './pixels.js';

const planeLen = (W, H) => W * H + 2 * ((W + 1) >> 1) * ((H + 1) >> 1);

self.onmessage = async (ev) => {
  try {
    await init();
    const { frames, w, h, n, fov, warmup, fmt = 'RGBA', vf } = ev.data;
    const W = Number(w), H = Number(h), N = Number(n), WARM = Number(warmup || 30);
    if (fmt !== 'RGBA' && fmt !== 'I420') throw new Error(`fmt ${fmt}: allowed RGBA or I420`);
    const size = fmt === 'I420' ? planeLen(W, H) : W * H * 4;
    const data = new Uint8Array(await (await fetch(frames)).arrayBuffer());
    const nSrc = Math.floor(data.length / size);
    if (!nSrc) throw new Error(`no ${W}x${H} ${fmt} frame in ${frames}`);
    // Forwards then backwards through the clip: continuous motion (as native_bench).
    const idx = (i, m) => (Math.floor(i / m) % 2 === 0 ? i % m : m - 1 - (i % m));
    const at = (i) => { const k = idx(i, nSrc); return data.subarray(k * size, (k + 1) * size); };
    const run = (count) => {
      const s = new Stabilizer(W, H, '{}', Number(fov || 70), fmt);
      const t0 = performance.now();
      let outs = 0;
      for (let i = 0; i < count; i++) {
        s.inputBuffer().set(at(i));
        if (s.pushInput(i / 30)) outs++;
      }
      const secs = (performance.now() - t0) / 1000;
      s.free();
      return { secs, outs };
    };
    run(WARM); // let the engine tier up
    const { secs, outs } = run(N);
    const result = { width: W, height: H, format: fmt, frames: N, outputs: outs, seconds: secs, fps: N / secs, simd: simdEnabled(), userAgent: navigator.userAgent };

    if (vf) {
      const yuv = new Uint8Array(await (await fetch(vf)).arrayBuffer());
      const ySize = planeLen(W, H), nV = Math.floor(yuv.length / ySize);
      if (!nV) throw new Error(`no ${W}x${H} I420 frame in ${vf}`);
      const sources = [];
      for (let k = 0; k < nV; k++) {
        sources.push(new VideoFrame(yuv.subarray(k * ySize, (k + 1) * ySize), { format: 'I420', codedWidth: W, codedHeight: H, timestamp: k }));
      }
      const copyOpts = copyOptions(fmt, W, H); // as the page's worker
      const runVf = async (count) => {
        const s = new Stabilizer(W, H, '{}', Number(fov || 70), fmt);
        const ow = s.outputWidth, oh = s.outputHeight, of = s.outputFormat;
        let copyMs = 0, stabMs = 0, wrapMs = 0, outs = 0;
        const t0 = performance.now();
        for (let i = 0; i < count; i++) {
          const a = performance.now();
          await sources[idx(i, nV)].copyTo(s.inputBuffer(), copyOpts);
          const b = performance.now();
          const tel = s.pushInput(i / 30);
          const c = performance.now();
          if (tel) {
            const f = new VideoFrame(s.output(), { format: of, codedWidth: ow, codedHeight: oh, timestamp: i });
            f.close();
            outs++;
          }
          const d = performance.now();
          copyMs += b - a; stabMs += c - b; wrapMs += d - c;
        }
        const secs = (performance.now() - t0) / 1000;
        s.free();
        return { secs, outs, copyMs, stabMs, wrapMs };
      };
      await runVf(WARM);
      const r = await runVf(N);
      sources.forEach((f) => f.close());
      Object.assign(result, {
        vf_fps: N / r.secs,
        vf_ms_per_frame: { copyTo: r.copyMs / N, stabilize: r.stabMs / N, output_frame: r.wrapMs / N },
      });
    }
    self.postMessage(result);
  } catch (e) {
    self.postMessage({ error: String(e && e.message || e) });
  }
};
