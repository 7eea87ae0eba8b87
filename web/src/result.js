// Shows a finished run: the downloads (video, telemetry CSV), both clips at
// the same size, the per-frame plot with its legend, and the summary table.
import { $, state, newUrl } from './state.js';
import { clipPlotSpec, legend } from './plot.js';
import { drawClipPlot, resetCompare, enableCompare } from './player.js';
import { renderSummary } from './summary.js';

const size = (n) => (n >= 1e6 ? `${(n / 1e6).toFixed(1)} MB` : `${Math.max(1, Math.round(n / 1e3))} kB`);
const stem = (name) => (name || 'clip').replace(/\.[^.]+$/, '');

/**
 * `r`: { blob, mime, name (the input's file name), original (a playable Blob or
 * null), origCaption, rows (plot rows), csv (Blob or null), summary (summary.js),
 * inputWidth }
 */
export function showResult(r) {
  const ext = r.mime.includes('webm') ? 'webm' : 'mp4';
  const a = $('download');
  a.href = newUrl(r.blob);
  a.download = `${stem(r.name)}-stabilized.${ext}`;
  a.textContent = `Download the video (${ext.toUpperCase()}, ${size(r.blob.size)})`;
  $('stab').src = a.href;
  $('stab-caption').textContent = 'Stabilized';
  setOriginal(r.original, r.origCaption);
  const csv = $('download-csv');
  csv.hidden = !r.csv;
  if (r.csv) {
    csv.href = newUrl(r.csv);
    csv.download = `${stem(r.name)}-telemetry.csv`;
    csv.textContent = `Telemetry (CSV, ${size(r.csv.size)})`;
  }
  state.inputWidth = r.inputWidth || 0;
  state.plotRows = r.rows && r.rows.length ? r.rows : null;
  $('result').hidden = false;
  resetCompare();
  enableCompare(!!r.original);
  const spec = clipPlotSpec(state.plotRows || [], null);
  legend($('plot-legend'), spec);
  $('plot').closest('figure').hidden = !state.plotRows;
  drawClipPlot(null);
  renderSummary($('summary'), r.summary);
}

/** Puts a playable original (Blob) in the Original slot, or explains why it is empty. */
export function setOriginal(blob, caption) {
  const o = $('orig');
  if (blob) {
    o.src = newUrl(blob);
    o.hidden = false;
  } else {
    o.removeAttribute('src');
    o.load();
    o.hidden = true;
  }
  $('orig-caption').textContent = caption || 'Original';
  enableCompare(!!blob);
}

/** Whether this browser's <video> can show `blob`'s picture: true, false, or null (no answer in time). */
export function playable(blob, timeout = 8000) {
  return new Promise((resolve) => {
    const v = document.createElement('video');
    v.muted = true; v.preload = 'auto';
    const url = URL.createObjectURL(blob);
    let timer = null;
    const done = (ok) => { clearTimeout(timer); v.removeAttribute('src'); v.load(); URL.revokeObjectURL(url); resolve(ok); };
    timer = setTimeout(() => done(null), timeout);
    v.onloadeddata = () => done(v.videoWidth > 0);
    v.onerror = () => done(false);
    v.src = url;
  });
}
