// Times amc-wasm on raw frames (fetched once, held in memory): the stabilizer
// alone, as the page's worker runs it (inputBuffer + pushInput), for RGBA or
// I420 frames (`fmt`). With `vf` (raw I420 frames of the same clip) it also
// times the page's WebCodecs path without decoder and encoder: I420
// VideoFrames (made up front, as a software decoder gives them) copied into
// the module (`copyTo`: as is for I420, converted by the browser for RGBA),
// stabilized, and each output wrapped in a new VideoFrame (as for the encoder).
// With `workers` above 1, both runs share the outputs out among that many
// workers (render-share.js, as the page does on a machine with more cores):
// this one and helpers, each fed every frame; timed until every output is back.
import init, { Stabilizer, simdEnabled } from './pkg/amc_wasm.js';
import { RenderShare } from './render-share.js';

import { copyOptions } from './pixels.js';

const planeLen = (W, H) => W * H + 2 * ((W + 1) >> 1) * ((H + 1) >> 1);

self.onmessage = async (ev) => {
  try {
    await init();
    const { frames, w, h, n, fov, warmup, fmt = 'RGBA', vf, workers = 1 } = ev.data;
    const W = Number(w), H = Number(h), N = Number(n), WARM = Number(warmup || 30), HELPERS = Number(workers) - 1;
    if (!(HELPERS >= 0 && HELPERS < 16)) throw new Error(`workers ${workers}: allowed 1 to 16`);
    if (fmt !== 'RGBA' && fmt !== 'I420') throw new Error(`fmt ${fmt}: allowed RGBA or I420`);
    const size = fmt === 'I420' ? planeLen(W, H) : W * H * 4;
    const data = new Uint8Array(await (await fetch(frames)).arrayBuffer());
    const nSrc = Math.floor(data.length / size);
    if (!nSrc) throw new Error(`no ${W}x${H} ${fmt} frame in ${frames}`);
    // A stabilizer, and its share of the outputs with HELPERS helpers (none: null).
    const open = async () => {
      const s = new Stabilizer(W, H, '{}', Number(fov || 70), fmt);
      if (!HELPERS) return { s, share: null };
      const spec = { width: W, height: H, paramsJson: '{}', lens: Number(fov || 70), format: fmt };
      return { s, share: await RenderShare.open(s, spec, HELPERS) };
    };
    // Pushes the frame in s.inputBuffer(); returns the outputs that are
    // ready (when shared, in order, waiting only while a few are queued).
    const push = async ({ s, share }, t) => {
      if (!share) return s.pushInput(t) ? [s.output()] : [];
      share.push(t);
      const out = [];
      for await (const d of share.drawn()) out.push(d.output);
      return out;
    };
    const drain = async ({ s, share }) => {
      const out = [];
      if (!share) { while (s.finish()) out.push(s.output()); return out; }
      share.finish();
      for await (const d of share.drawn(true)) out.push(d.output);
      share.close();
      return out;
    };
    // Forwards then backwards through the clip: continuous motion (as native_bench).
    const idx = (i, m) => (Math.floor(i / m) % 2 === 0 ? i % m : m - 1 - (i % m));
    const at = (i) => { const k = idx(i, nSrc); return data.subarray(k * size, (k + 1) * size); };
    // Every queued output (between the untimed warm-up and the timed frames).
    const settle = async ({ share }) => { if (share) for await (const _ of share.drawn(true)); };
    // WARM frames to let the engine tier up (in every worker), then `count` timed ones.
    const run = async (count) => {
      const st = await open();
      let outs = 0, t0 = 0;
      for (let i = 0; i < WARM + count; i++) {
        if (i === WARM) { await settle(st); t0 = performance.now(); outs = 0; }
        st.s.inputBuffer().set(at(i));
        outs += (await push(st, i / 30)).length;
      }
      if (st.share) outs += (await drain(st)).length; // every output drawn by then
      const secs = (performance.now() - t0) / 1000;
      st.s.free();
      return { secs, outs };
    };
    const { secs, outs } = await run(N);
    const result = { width: W, height: H, format: fmt, frames: N, workers: HELPERS + 1, outputs: outs, seconds: secs, fps: N / secs, simd: simdEnabled(), userAgent: navigator.userAgent };

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
        const st = await open();
        const s = st.s;
        const ow = s.outputWidth, oh = s.outputHeight, of = s.outputFormat;
        const wrap = (outputs, i) => {
          for (const o of outputs) {
            const f = new VideoFrame(o, { format: of, codedWidth: ow, codedHeight: oh, timestamp: i });
            f.close();
            outs++;
          }
        };
        let copyMs = 0, stabMs = 0, wrapMs = 0, outs = 0, t0 = 0;
        for (let i = 0; i < WARM + count; i++) {
          if (i === WARM) { await settle(st); t0 = performance.now(); copyMs = stabMs = wrapMs = outs = 0; }
          const a = performance.now();
          await sources[idx(i, nV)].copyTo(s.inputBuffer(), copyOpts);
          const b = performance.now();
          const outputs = await push(st, i / 30);
          const c = performance.now();
          wrap(outputs, i);
          const d = performance.now();
          copyMs += b - a; stabMs += c - b; wrapMs += d - c;
        }
        if (st.share) wrap(await drain(st), WARM + count);
        const secs = (performance.now() - t0) / 1000;
        s.free();
        return { secs, outs, copyMs, stabMs, wrapMs };
      };
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
