// The clip's summary as a table (original vs stabilized, with units), from an
// in-browser run (the worker's amc-wasm summary) or a server job (RunSummary).
// Rows whose values were not measured are left out; a cell that has no value
// for one side shows "—".

const f = (v, d) => (v == null || !Number.isFinite(v) ? null : v.toFixed(d));
const pct = (v, d = 1) => (v == null || !Number.isFinite(v) ? null : `${(100 * v).toFixed(d)} %`);
const change = (a, b) => (a > 0 && Number.isFinite(b) ? `${b < a ? '−' : '+'}${Math.abs(100 * (b - a) / a).toFixed(0)} %` : null);

/**
 * Summary rows `[label, original, stabilized, change]` (strings or null).
 * `s`: { frames, inSize: [w, h], outSize: [w, h], margin?, fps?, seconds?,
 *        input?: ClipMetrics, output?: ClipMetrics, motion?: MotionSummary, mode,
 *        gyro?: { note, warning, report } }
 * The input's angular speed is the camera's, as estimated (the output's
 * `rms_speed_est_dps`); the input accumulator has no telemetry, so its own
 * speed fields are always 0 and are not shown.
 */
export function summaryRows(s) {
  const rows = [];
  const out = s.output || null, inp = s.input || null;
  const motion = s.motion || out || null;
  rows.push(['Frames', String(s.frames ?? '—'), String((out && out.frames) || (motion && motion.frames) || s.frames || '—'), null]);
  if (s.inSize && s.outSize) {
    const [iw, ih] = s.inSize, [ow, oh] = s.outSize;
    const zoom = ow > 0 ? iw / ow : null;
    rows.push(['Size (pixels)', `${iw} × ${ih}`, `${ow} × ${oh}` + (zoom && Math.abs(zoom - 1) > 0.005 ? ` (central crop, ${zoom.toFixed(2)}× zoom)` : ''), null]);
  }
  if (motion && Number.isFinite(motion.rms_speed_est_dps) && motion.frames > 1) {
    rows.push(['Angular speed, RMS (deg/s): camera (estimated) → view', f(motion.rms_speed_est_dps, 1), f(motion.rms_speed_view_dps, 1),
      change(motion.rms_speed_est_dps, motion.rms_speed_view_dps)]);
  }
  if (out) {
    rows.push(['RMS normal flow (px/frame)', inp ? f(inp.rms_normal_flow, 3) : null, f(out.rms_normal_flow, 3),
      inp ? change(inp.rms_normal_flow, out.rms_normal_flow) : null]);
    rows.push(['RMS frame change (luma, % of full scale)', inp ? f(100 * inp.rms_change, 2) : null, f(100 * out.rms_change, 2),
      inp ? change(inp.rms_change, out.rms_change) : null]);
    rows.push(['Sharpness (RMS gradient, % of full scale per px)', inp ? f(100 * inp.sharpness, 2) : null, f(100 * out.sharpness, 2),
      inp ? change(inp.sharpness, out.sharpness) : null]);
  }
  if (motion && Number.isFinite(motion.valid_fraction) && motion.frames > 0) {
    rows.push(['Pixels covered by every averaged frame: mean (lowest)', null,
      `${pct(motion.valid_fraction)} (${pct(motion.min_valid_fraction)})`, null]);
  }
  if (s.mode === 'saccade' || (motion && motion.saccades > 0)) rows.push(['Saccades', null, String(motion ? motion.saccades : 0), null]);
  // The clip's gyro track: fused, or why not (a warning, or not read).
  if (s.gyro) rows.push(['Gyro', null, s.gyro.note.replace(/^gyro: /, ''), null]);
  if (Number.isFinite(s.fps)) rows.push([s.where === 'server' ? 'Processing on the server (frames/s)' : 'Processing in this browser (frames/s)', null, f(s.fps, 1), null]);
  return rows;
}

/** Fills `table` with the rows of `s` (see summaryRows). */
export function renderSummary(table, s) {
  table.replaceChildren();
  if (!s) { table.hidden = true; return; }
  table.hidden = false;
  const cap = table.createCaption();
  cap.textContent = s.where === 'server' ? 'Summary (computed by the server)' : 'Summary (computed in this browser)';
  const head = table.createTHead().insertRow();
  for (const h of ['', 'Original', 'Stabilized', 'Change']) {
    const th = document.createElement('th'); th.scope = 'col'; th.textContent = h; head.append(th);
  }
  const body = table.createTBody();
  for (const [label, a, b, c] of summaryRows(s)) {
    const tr = body.insertRow();
    const th = document.createElement('th'); th.scope = 'row'; th.textContent = label; tr.append(th);
    for (const v of [a, b, c]) { const td = tr.insertCell(); td.textContent = v ?? '—'; }
  }
}

/** Summary of an in-browser run: the worker's `start` and `done` messages. */
export function localSummary(start, done, mode) {
  const sum = done.summary || {};
  return {
    where: 'browser', mode, frames: done.frames, fps: done.fps,
    inSize: start ? [start.width, start.height] : null, outSize: start ? [start.outWidth, start.outHeight] : null,
    input: sum.input || null, output: sum.output || null, motion: sum.output || null,
    gyro: (start && start.gyro) || null,
  };
}

/** Summary of a server job (`GET /jobs/{id}`: its flat `metrics` and its `motion`). */
export function serverSummary(job, mode) {
  const m = job && job.metrics;
  if (!m) return null;
  const mo = job.motion || {};
  return {
    where: 'server', mode, frames: m.frames, fps: m.frames_per_second, inSize: m.input_size, outSize: m.output_size,
    input: null,
    output: m.rms_normal_flow == null ? null : { frames: m.frames, rms_normal_flow: m.rms_normal_flow, rms_change: m.rms_frame_change, sharpness: m.sharpness },
    motion: { frames: m.frames, valid_fraction: m.valid_fraction, min_valid_fraction: m.min_valid_fraction,
              rms_speed_est_dps: mo.rms_speed_est_dps, rms_speed_view_dps: mo.rms_speed_view_dps, saccades: mo.saccades ?? 0 },
  };
}
