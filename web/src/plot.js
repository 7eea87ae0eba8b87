// The per-frame plot of a clip (as in the paper's Figure 2): angular speed of
// the estimate and of the view, RMS normal flow of input and output.
import { $, state } from './state.js';

export function drawPlot(cursorT) {
  const c = $('plot'), g = c.getContext('2d');
  const T = state.telemetry;
  g.clearRect(0, 0, c.width, c.height);
  if (!T || !T.length) return;
  const pad = 40, W = c.width - 2 * pad, H = c.height - 30;
  const t0 = T[0].t, t1 = T[T.length - 1].t || t0 + 1;
  const x = (t) => pad + (W * (t - t0)) / Math.max(1e-9, t1 - t0);
  const maxS = Math.max(1, ...T.map((r) => Math.max(r.speed_est_dps, r.speed_view_dps)));
  const nf = (r, k) => (r[k] && r[k].rms_normal_flow != null ? r[k].rms_normal_flow : null);
  const maxF = Math.max(0.1, ...T.map((r) => Math.max(nf(r, 'metrics') || 0, nf(r, 'input_metrics') || 0)));
  g.strokeStyle = '#333'; g.strokeRect(pad, 5, W, H);
  g.fillStyle = '#888'; g.font = '11px sans-serif';
  g.fillText(`${maxS.toFixed(0)} deg/s`, 2, 14); g.fillText(`${maxF.toFixed(1)} px`, c.width - pad + 2, 14);
  g.fillText(`${t0.toFixed(1)} s`, pad, H + 20); g.fillText(`${t1.toFixed(1)} s`, pad + W - 30, H + 20);
  const line = (color, val, max) => {
    g.strokeStyle = color; g.lineWidth = 1.2; g.beginPath();
    let started = false;
    for (const r of T) {
      const v = val(r);
      if (v == null || !isFinite(v)) { started = false; continue; }
      const px = x(r.t), py = 5 + H - (H * v) / max;
      if (started) g.lineTo(px, py); else { g.moveTo(px, py); started = true; }
    }
    g.stroke();
  };
  line('#9e9e9e', (r) => nf(r, 'input_metrics'), maxF);
  line('#66bb6a', (r) => nf(r, 'metrics'), maxF);
  line('#ff7043', (r) => r.speed_est_dps, maxS);
  line('#42a5f5', (r) => r.speed_view_dps, maxS);
  for (const r of T) if (r.saccade) { g.fillStyle = '#d4a017'; g.fillRect(x(r.t) - 1, 5, 2, 6); }
  if (cursorT != null) {
    g.strokeStyle = '#fff'; g.beginPath(); g.moveTo(x(t0 + cursorT), 5); g.lineTo(x(t0 + cursorT), 5 + H); g.stroke();
  }
}
