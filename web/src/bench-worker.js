// Times amc-wasm on raw RGBA frames (fetched once, held in memory): the
// stabilizer alone, as the page's worker runs it (inputBuffer + pushInput).
import init, { Stabilizer, simdEnabled } from './pkg/amc_wasm.js';

self.onmessage = async (ev) => {
  try {
    await init();
    const { frames, w, h, n, fov, warmup } = ev.data;
    const W = Number(w), H = Number(h), N = Number(n), size = W * H * 4;
    const data = new Uint8Array(await (await fetch(frames)).arrayBuffer());
    const nSrc = Math.floor(data.length / size);
    if (!nSrc) throw new Error(`no ${W}x${H} frame in ${frames}`);
    // Forwards then backwards through the clip: continuous motion (as native_bench).
    const at = (i) => { const k = Math.floor(i / nSrc) % 2 === 0 ? i % nSrc : nSrc - 1 - (i % nSrc); return data.subarray(k * size, (k + 1) * size); };
    const run = (count) => {
      const s = new Stabilizer(W, H, '{}', Number(fov || 70));
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
    run(Number(warmup || 30)); // let the engine tier up
    const { secs, outs } = run(N);
    self.postMessage({ width: W, height: H, frames: N, outputs: outs, seconds: secs, fps: N / secs, simd: simdEnabled(), userAgent: navigator.userAgent });
  } catch (e) {
    self.postMessage({ error: String(e && e.message || e) });
  }
};
