// Per-frame telemetry: the CSV the CLI and the job API write (same header and
// column order as amc-server's TELEMETRY_HEADER, same number formats), built
// here from the worker's telemetry objects; and the rows the clip plot draws,
// from either source.

/** amc-engine/src/telemetry.rs TELEMETRY_HEADER. */
export const TELEMETRY_HEADER = 'frame,t,rx,ry,rz,vx,vy,vz,est_speed_dps,view_speed_dps,valid_fraction,' +
  'frames_averaged,saccade,iterations,rms_residual,track_valid_fraction,lost,template_reset,zoom,uncovered,' +
  'readout_rx,readout_ry,readout_rz';
/** Columns only the page has (its per-frame image metrics), after the CLI's; empty where undefined. */
export const PAGE_COLUMNS = 'input_rms_normal_flow_px,output_rms_normal_flow_px,input_rms_change,output_rms_change';

/** Rust's `{:e}` (shortest round-trip digits, exponent without `+`). */
const sci = (v) => Number(v).toExponential().replace('e+', 'e');
const fixed = (v, d) => Number(v).toFixed(d);
const opt = (m, k) => (m && m[k] != null && Number.isFinite(m[k]) ? String(m[k]) : '');
const b01 = (v) => (v ? '1' : '0');

/**
 * The telemetry CSV of an in-browser run: the CLI's 23 columns (rotation
 * vectors of the estimate `rx,ry,rz` and of the view `vx,vy,vz`, radians; the
 * rotation across the readout `readout_rx,readout_ry,readout_rz` last), then
 * the page's image metrics.
 */
export function telemetryCsv(telemetry) {
  const lines = [`${TELEMETRY_HEADER},${PAGE_COLUMNS}`];
  for (const r of telemetry) {
    const tr = r.track || {};
    lines.push([
      r.frame, fixed(r.t, 6), ...r.r_est.map(sci), ...r.r_view.map(sci),
      fixed(r.speed_est_dps, 4), fixed(r.speed_view_dps, 4), fixed(r.valid_fraction, 5), r.frames_averaged,
      b01(r.saccade), tr.iterations ?? '', tr.rms_residual != null ? fixed(tr.rms_residual, 6) : '',
      tr.valid_fraction != null ? fixed(tr.valid_fraction, 4) : '', b01(tr.lost), b01(tr.template_reset),
      r.zoom != null ? fixed(r.zoom, 5) : '', r.uncovered ?? '',
      ...(r.readout_rotation ? r.readout_rotation.map(sci) : ['', '', '']),
      opt(r.input_metrics, 'rms_normal_flow'), opt(r.metrics, 'rms_normal_flow'),
      opt(r.input_metrics, 'rms_change'), opt(r.metrics, 'rms_change'),
    ].join(','));
  }
  return lines.join('\n') + '\n';
}

/**
 * Plot rows `{ t, est, view, nfIn, nfOut, saccade, valid, zoom }` (angular speeds in
 * deg/s, normal flow in px/frame; `null` where not measured) of the worker's telemetry.
 */
export function rowsFromWorker(telemetry) {
  const nf = (m) => (m && m.rms_normal_flow != null ? m.rms_normal_flow : null);
  return telemetry.map((r) => ({
    t: r.t, est: r.speed_est_dps, view: r.speed_view_dps, nfIn: nf(r.input_metrics), nfOut: nf(r.metrics),
    saccade: !!r.saccade, valid: r.valid_fraction, zoom: r.zoom ?? null,
  }));
}

/** Plot rows of a telemetry CSV (the job API's `telemetry.csv`), by column name. */
export function rowsFromCsv(text) {
  const lines = text.split(/\r?\n/).filter((l) => l.trim() !== '');
  if (!lines.length) return [];
  const head = lines[0].split(',').map((h) => h.trim());
  const col = (name) => head.indexOf(name);
  const idx = {
    t: col('t'), est: col('est_speed_dps'), view: col('view_speed_dps'), valid: col('valid_fraction'), saccade: col('saccade'),
    nfIn: col('input_rms_normal_flow_px'), nfOut: col('output_rms_normal_flow_px'), zoom: col('zoom'),
  };
  const num = (cells, i) => (i >= 0 && cells[i] !== undefined && cells[i] !== '' ? Number(cells[i]) : null);
  return lines.slice(1).map((l) => {
    const c = l.split(',');
    return {
      t: num(c, idx.t), est: num(c, idx.est), view: num(c, idx.view), nfIn: num(c, idx.nfIn), nfOut: num(c, idx.nfOut),
      saccade: num(c, idx.saccade) === 1, valid: num(c, idx.valid), zoom: num(c, idx.zoom),
    };
  }).filter((r) => r.t != null && Number.isFinite(r.t));
}
