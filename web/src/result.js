// Shows a finished run: the download, both clips, the plot and the summary.
import { $, state, newUrl } from './state.js';
import { drawPlot } from './plot.js';

export function showResult(blob, mime, telemetry, summary, original) {
  const ext = mime.includes('webm') ? 'webm' : 'mp4';
  const a = $('download');
  a.href = newUrl(blob);
  a.download = (original ? original.name.replace(/\.[^.]+$/, '') : 'clip') + `-stabilized.${ext}`;
  a.textContent = `Download (${ext.toUpperCase()}, ${(blob.size / 1e6).toFixed(1)} MB)`;
  $('stab').src = a.href;
  if (original) $('orig').src = newUrl(original);
  $('orig').hidden = !original;
  $('result').hidden = false;
  state.telemetry = telemetry || null;
  $('summary').textContent = summary ? JSON.stringify(summary, null, 1) : '';
  drawPlot();
}
