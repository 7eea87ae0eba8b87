// A render helper of render-share.js: a Stabilizer fed every frame of the
// clip that draws its share of the outputs (setRenderShare) and sends their
// pixels, coverage and telemetry back to the worker that started it.
import init, { Stabilizer } from './pkg/amc_wasm.js';

const ready = init();
let stab = null, count = 1, index = 0;

function send(tel) {
  if (!tel || tel.frame % count !== index) return;
  const output = stab.output().slice(), coverage = stab.coverage().slice();
  self.postMessage({ type: 'output', tel, output: output.buffer, coverage: coverage.buffer }, [output.buffer, coverage.buffer]);
}

self.onmessage = async (ev) => {
  const m = ev.data;
  try {
    await ready;
    if (m.type === 'open') {
      ({ count, index } = m);
      stab = new Stabilizer(m.width, m.height, m.paramsJson, m.lens, m.format);
      if (m.staticZoom) stab.setStaticZoom(m.staticZoom);
      // A gyro run: every frame rendered with its fused pose, as in worker.js.
      if (m.poses) stab.setPoses(m.poses);
      stab.setRenderShare(count, index);
      self.postMessage({ type: 'ready' });
    } else if (m.type === 'frame') {
      stab.inputBuffer().set(new Uint8Array(m.data));
      send(stab.pushInput(m.t));
    } else if (m.type === 'finish') {
      for (let tel = stab.finish(); tel; tel = stab.finish()) send(tel);
    }
  } catch (e) {
    self.postMessage({ type: 'error', message: String(e && e.message ? e.message : e) });
  }
};
