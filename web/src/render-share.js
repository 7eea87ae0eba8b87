// More than one core for the page's stabilizer. A worker has one thread and
// no memory shared with the others (that needs a cross-origin-isolated page
// and a threaded WebAssembly build), so the outputs are shared out instead:
// `count` stabilizers, this thread's and one per helper worker
// (share-worker.js), are each fed every frame, and stabilizer `i` draws
// outputs `j` with `j % count == i` (Stabilizer.setRenderShare). Tracking,
// the view filter and the framing need every frame and run in each; they are
// a small part of the work next to drawing (3% of one worker's time at
// 1280x720, 28% at 320x180), and each output comes out byte for byte as one
// stabilizer draws it.

/** Helpers (besides this thread) the page starts: one per core beyond the first, at most 3. */
export function helperCount(mode) {
  if (mode === 'saccade') return 0; // each output builds on the previous one's frames
  const cores = Number(self.navigator && navigator.hardwareConcurrency) || 1;
  return Math.max(0, Math.min(cores, 4) - 1);
}

/** Outputs queued (drawn or being drawn) before `drawn` waits for the oldest: bounds memory. */
const MAX_QUEUED = 4;

export class RenderShare {
  /**
   * `stab`: this thread's Stabilizer (it draws share 0); `spec`: what made
   * it ({ width, height, paramsJson, lens, format, staticZoom?, poses? }:
   * `poses`, a gyro pass's, for `setPoses`), for the helpers' stabilizers; `helpers`: how many helper workers to start.
   */
  static async open(stab, spec, helpers) {
    const count = helpers + 1;
    const share = new RenderShare(stab, count);
    try {
      await Promise.all(Array.from({ length: helpers }, (_, k) => share.#start(spec, k + 1)));
    } catch (e) {
      share.close();
      throw e;
    }
    stab.setRenderShare(count, 0);
    return share;
  }

  constructor(stab, count) {
    this.stab = stab;
    this.count = count;
    this.workers = [];
    this.waiting = new Map(); // output index -> { resolve, reject } of a helper's output
    this.queue = []; // outputs ready in order: { tel, done, drawn }
    this.failed = null;
  }

  #start(spec, index) {
    const w = new Worker(new URL('./share-worker.js', import.meta.url), { type: 'module' });
    this.workers.push(w);
    return new Promise((resolve, reject) => {
      w.onerror = (e) => this.#fail(new Error(`render helper ${index}: ${e.message || e}`), reject);
      w.onmessage = (ev) => {
        const m = ev.data;
        if (m.type === 'ready') resolve();
        else if (m.type === 'error') this.#fail(new Error(`render helper ${index}: ${m.message}`), reject);
        else if (m.type === 'output') {
          const wait = this.waiting.get(m.tel.frame);
          if (wait) {
            this.waiting.delete(m.tel.frame);
            wait.resolve({ tel: m.tel, output: new Uint8Array(m.output), coverage: new Uint8Array(m.coverage) });
          }
        }
      };
      w.postMessage({ type: 'open', ...spec, count: this.count, index });
    });
  }

  #fail(error, reject) {
    if (!this.failed) this.failed = error;
    for (const wait of this.waiting.values()) wait.reject(error);
    this.waiting.clear();
    if (reject) reject(error);
  }

  /**
   * Pushes the frame in `stab.inputBuffer()` at `t` seconds, to this thread's
   * stabilizer and to each helper (a copy). The output that became ready, if
   * any, is queued: take it with `drawn`.
   */
  push(t) {
    if (this.failed) throw this.failed;
    const input = this.stab.inputBuffer();
    for (const w of this.workers) {
      const copy = input.slice();
      w.postMessage({ type: 'frame', t, data: copy.buffer }, [copy.buffer]);
    }
    this.#ready(this.stab.pushInput(t));
  }

  /** After the last frame: queues the outputs the lookahead held back (take them with `drawn(true)`). */
  finish() {
    if (this.failed) throw this.failed;
    for (const w of this.workers) w.postMessage({ type: 'finish' });
    for (let tel = this.stab.finish(); tel; tel = this.stab.finish()) this.#ready(tel);
  }

  #ready(tel) {
    if (!tel) return;
    const j = tel.frame;
    if (j % this.count === 0) {
      // Copies: the module's views die at the next call into it.
      const value = { tel, output: this.stab.output().slice(), coverage: this.stab.coverage().slice() };
      this.queue.push({ done: value, drawn: Promise.resolve(value) });
      return;
    }
    const entry = { done: null };
    entry.drawn = new Promise((resolve, reject) => this.waiting.set(j, {
      resolve: (v) => { entry.done = v; resolve(v); },
      reject,
    }));
    entry.drawn.catch(() => {}); // a rejection reaches whoever awaits it in `drawn`
    this.queue.push(entry);
  }

  /**
   * The queued outputs, in order, as `{ tel, output, coverage }` (`tel`: the
   * telemetry of the stabilizer that drew it; copies of its pixels and
   * coverage): those already drawn, waiting for the oldest while more than a
   * few are queued; with `all`, every queued one.
   */
  async *drawn(all = false) {
    while (this.queue.length && (all || this.queue[0].done || this.queue.length > MAX_QUEUED)) {
      const entry = this.queue.shift();
      yield entry.done || await entry.drawn;
    }
  }

  close() {
    for (const w of this.workers) w.terminate();
    this.workers = [];
    this.#fail(new Error('render share closed'));
  }
}
