// Reads a clip's own gyro log (a GoPro's GPMF track, Sony, DJI, Insta360) in
// a worker of its own, for worker.js. The parser runs in this worker's
// WebAssembly instance: a damaged track that makes it panic (in wasm32 a
// panic aborts, a trap that leaves the instance unusable) ends this worker,
// not the run; and the clip's bytes, copied into this instance's memory to
// parse them (WebAssembly memory never shrinks), leave with it.
import init, { ClipGyro } from './pkg/amc_wasm.js';

const ready = init();

self.onmessage = async (ev) => {
  try {
    await ready;
    const { file } = ev.data;
    const bytes = new Uint8Array(await file.arrayBuffer());
    const log = ClipGyro.read(bytes, file.name);
    if (!log) {
      self.postMessage({ type: 'none' });
      return;
    }
    const parts = {
      source: log.source, videoClock: log.videoClock, readoutMs: log.readoutMs ?? null,
      samples: log.samples, rateHz: log.rateHz, times: log.times(), rates: log.rates(),
    };
    log.free();
    self.postMessage({ type: 'log', parts }, [parts.times.buffer, parts.rates.buffer]);
  } catch (e) {
    self.postMessage({ type: 'error', message: String(e && e.message ? e.message : e) });
  }
};
