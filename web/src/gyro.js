// The clip's own gyro log for worker.js (`gyro: auto`): read in a worker of
// its own (gyro-worker.js), and what the page says of it.

/** Clips larger than this are not read into memory to look for a gyro track. */
export const GYRO_MAX_BYTES = 1 << 30;

/**
 * The gyro log `file` holds, read by gyro-worker.js: `{ parts }` (the
 * arguments of `ClipGyro.fromParts`, with `samples` and `rateHz`), `null`
 * when it holds none, or `{ note }` when it was not read (too large, or the
 * parser failed on it: the run goes on from the picture alone).
 */
export function readClipGyro(file) {
  if (file.size > GYRO_MAX_BYTES) {
    return Promise.resolve({ note: `gyro: not read (the clip is over ${GYRO_MAX_BYTES / 2 ** 30} GiB, more than the page reads into memory to find its track); the output uses the video alone` });
  }
  const w = new Worker(new URL('./gyro-worker.js', import.meta.url), { type: 'module' });
  return new Promise((resolve) => {
    const failed = (why) => resolve({ note: `gyro: the clip's track could not be read (${why}); the output uses the video alone` });
    w.onerror = (e) => failed(e.message || 'the parser stopped');
    w.onmessage = (ev) => {
      const m = ev.data;
      if (m.type === 'log') resolve({ parts: m.parts });
      else if (m.type === 'none') resolve(null);
      else failed(m.message);
    };
    w.postMessage({ file });
  }).finally(() => w.terminate());
}

/** The page's words for a fused run (the report of `GyroPass.fuse`), as the summary shows them. */
export function gyroText(report) {
  return `gyro: ${report.source}, offset ${report.offset_s >= 0 ? '+' : ''}${report.offset_s.toFixed(4)} s, ` +
    `fused ${report.fused_frames} frames`;
}
