// How decoded frames enter the module: the pixel path per WebCodecs format and
// the copyTo options writing the module's layout (used by worker.js, the bench
// and the browser tests).

/**
 * The pixel path for a decoded frame: its planar 4:2:0 layout copied as is
 * ('I420', or 'NV12' from hardware decoders, de-interleaved by the module),
 * else 'RGBA' (the browser converts; also for RGBX/BGRA or an opaque format).
 * Planar copies need a visible rectangle on even coordinates (chroma samples).
 */
export function pixelPath(sample) {
  const r = sample.visibleRect;
  const even = r.left % 2 === 0 && r.top % 2 === 0;
  return (sample.format === 'I420' || sample.format === 'NV12') && even ? sample.format : 'RGBA';
}

/**
 * copyTo options writing a frame of `w x h` visible pixels in the module's
 * layout: planes packed one after the other, rows without padding (copyTo
 * would otherwise use the browser's layout, which may pad rows).
 */
export function copyOptions(path, w, h) {
  if (path === 'RGBA') return { format: 'RGBA' }; // converted by the browser, rows packed
  const cw = (w + 1) >> 1, ch = (h + 1) >> 1;
  if (path === 'NV12') return { layout: [{ offset: 0, stride: w }, { offset: w * h, stride: 2 * cw }] };
  return { layout: [{ offset: 0, stride: w }, { offset: w * h, stride: cw }, { offset: w * h + cw * ch, stride: cw }] };
}

/** The VideoColorSpaceInit of a sample's colour space (plain object), or undefined. */
export function colorSpaceInit(sample) {
  const c = sample.colorSpace;
  if (!c) return undefined;
  const init = typeof c.toJSON === 'function' ? c.toJSON() : { primaries: c.primaries, transfer: c.transfer, matrix: c.matrix, fullRange: c.fullRange };
  return Object.fromEntries(Object.entries(init).filter(([, v]) => v !== null && v !== undefined));
}
