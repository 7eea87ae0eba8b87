// Line charts with real axes: a time axis at the bottom, one or two value
// axes (left, right) with tick labels and units, and the legend as HTML next
// to the canvas (it never covers the curves). Used by the clip's per-frame
// plot (as in the paper's Figure 2) and the Live tab's speed plot.

const FONT = '11px system-ui, sans-serif';
const AXIS = '#aaa', GRID = '#2a2a2a';

/** "Nice" ticks (1, 2, 2.5, 5 x 10^k) covering [min, max]: `{ ticks, step, max }`. */
export function niceTicks(min, max, count = 5) {
  const span = max - min > 0 ? max - min : 1;
  const mag = 10 ** Math.floor(Math.log10(span / count));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => span / s <= count) || 10 * mag;
  const lo = Math.floor(min / step + 1e-9) * step, hi = Math.ceil(max / step - 1e-9) * step;
  const ticks = [];
  for (let v = lo; v <= hi + step / 2; v += step) ticks.push(Math.abs(v) < step * 1e-9 ? 0 : v);
  return { ticks, step, min: lo, max: hi };
}

function tickText(v, step) {
  const d = Math.max(0, Math.ceil(-Math.log10(step) - 1e-9) + (Math.round(step / 10 ** Math.floor(Math.log10(step))) === 2.5 ? 1 : 0));
  return v.toFixed(Math.min(d, 6));
}

/** Sizes the canvas's backing store to its CSS box (crisp text on any screen); returns the CSS size. */
function fit(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth || canvas.width, h = canvas.clientHeight || canvas.height;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const g = canvas.getContext('2d');
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  return { g, w, h };
}

/**
 * Draws a chart. `spec`:
 *   x:      { min, max, label }                     (the label carries the unit)
 *   axes:   [{ label, min?, max, side: 'left'|'right' }]
 *   series: [{ key, label, color, axis: index into axes, points: [[x, y|null], ...] }]
 *   marks:  [x, ...] short ticks at the top (saccades), markLabel
 *   cursor: x or null
 * Series without any finite point are left out (and from the legend: see `legend`).
 */
export function drawChart(canvas, spec) {
  const { g, w, h } = fit(canvas);
  g.clearRect(0, 0, w, h);
  const series = spec.series.filter(hasData);
  canvas.dataset.series = series.map((s) => s.key).join(',');
  const axes = spec.axes.map((a, i) => ({ ...a, used: series.some((s) => s.axis === i) }));
  const left = axes.find((a) => a.side === 'left' && a.used), right = axes.find((a) => a.side === 'right' && a.used);
  // A second right axis (e.g. the zoom) sits outside the first.
  const right2 = axes.find((a) => a.side === 'right2' && a.used);
  const m = { l: 58, r: (right ? 58 : 16) + (right2 ? 58 : 0), t: 12, b: 40 };
  const W = w - m.l - m.r, H = h - m.t - m.b;
  if (W < 20 || H < 20) return;
  g.font = FONT;
  const xt = niceTicks(spec.x.min, spec.x.max > spec.x.min ? spec.x.max : spec.x.min + 1, Math.max(2, Math.floor(W / 90)));
  const x0 = spec.x.min, x1 = spec.x.max > spec.x.min ? spec.x.max : spec.x.min + 1;
  const px = (x) => m.l + (W * (x - x0)) / (x1 - x0);
  axes.forEach((a, i) => {
    let max = a.max || 0;
    for (const s of series) if (s.axis === i) for (const p of s.points) if (Number.isFinite(p[1]) && p[1] > max) max = p[1];
    a.t = niceTicks(a.min || 0, max > (a.min || 0) ? max : (a.min || 0) + 1, Math.max(2, Math.floor(H / 45)));
  });
  const py = (a, y) => m.t + H - (H * (y - a.t.min)) / (a.t.max - a.t.min);
  // Frame, grid and ticks.
  g.strokeStyle = GRID; g.lineWidth = 1;
  const grid = left || right;
  if (grid) for (const v of grid.t.ticks) { const y = Math.round(py(grid, v)) + 0.5; g.beginPath(); g.moveTo(m.l, y); g.lineTo(m.l + W, y); g.stroke(); }
  g.strokeStyle = '#555'; g.strokeRect(m.l + 0.5, m.t + 0.5, W, H);
  g.fillStyle = AXIS; g.textBaseline = 'top'; g.textAlign = 'center';
  for (const v of xt.ticks) {
    if (v < x0 - 1e-9 || v > x1 + 1e-9) continue;
    const x = Math.round(px(v)) + 0.5;
    g.strokeStyle = '#555'; g.beginPath(); g.moveTo(x, m.t + H); g.lineTo(x, m.t + H + 4); g.stroke();
    g.fillText(tickText(v, xt.step), x, m.t + H + 6);
  }
  g.fillText(spec.x.label, m.l + W / 2, m.t + H + 22);
  g.textBaseline = 'middle';
  for (const a of [left, right, right2]) {
    if (!a) continue;
    const isLeft = a === left;
    const shift = a === right2 && right ? 58 : 0;
    g.textAlign = isLeft ? 'right' : 'left';
    for (const v of a.t.ticks) {
      const y = Math.round(py(a, v)) + 0.5, xe = isLeft ? m.l : m.l + W + shift;
      g.strokeStyle = '#555'; g.beginPath(); g.moveTo(xe, y); g.lineTo(xe + (isLeft ? -4 : 4), y); g.stroke();
      g.fillText(tickText(v, a.t.step), xe + (isLeft ? -6 : 6), y);
    }
    g.save();
    g.translate(isLeft ? 12 : (a === right2 || !right2 ? w - 10 : w - 68), m.t + H / 2);
    g.rotate(isLeft ? -Math.PI / 2 : Math.PI / 2);
    g.textAlign = 'center'; g.fillText(a.label, 0, 0);
    g.restore();
  }
  // Curves, clipped to the plot area.
  g.save();
  g.beginPath(); g.rect(m.l, m.t, W, H); g.clip();
  for (const s of series) {
    const a = axes[s.axis];
    g.strokeStyle = s.color; g.lineWidth = 1.4; g.beginPath();
    let on = false;
    for (const [x, y] of s.points) {
      if (y == null || !Number.isFinite(y)) { on = false; continue; }
      if (on) g.lineTo(px(x), py(a, y)); else { g.moveTo(px(x), py(a, y)); on = true; }
    }
    g.stroke();
  }
  g.fillStyle = '#d4a017';
  for (const x of spec.marks || []) g.fillRect(px(x) - 1, m.t, 2, 7);
  if (spec.cursor != null && spec.cursor >= x0 && spec.cursor <= x1) {
    g.strokeStyle = '#fff'; g.lineWidth = 1; g.beginPath(); g.moveTo(px(spec.cursor), m.t); g.lineTo(px(spec.cursor), m.t + H); g.stroke();
  }
  g.restore();
}

const hasData = (s) => s.points.some((p) => p[1] != null && Number.isFinite(p[1]));

/** The legend of the series that have data, as HTML in `el` (outside the canvas). */
export function legend(el, spec, extra = []) {
  el.replaceChildren();
  const side = (a) => (a.side === 'right2' ? 'outer right' : a.side);
  const items = spec.series.filter(hasData).map((s) => ({ color: s.color, text: `${s.label} (${side(spec.axes[s.axis])} axis)` }));
  if ((spec.marks || []).length) items.push({ color: '#d4a017', text: spec.markLabel || 'marks', mark: true });
  for (const it of [...items, ...extra]) {
    const k = document.createElement('span');
    k.className = it.mark ? 'k mark' : 'k';
    k.style.setProperty('--c', it.color);
    k.textContent = it.text;
    el.append(k);
  }
}

/**
 * The clip's per-frame plot from rows `{ t, est, view, nfIn, nfOut, saccade, zoom }`
 * (telemetry.js): angular speed of the estimate and of the view (deg/s, left),
 * RMS normal flow of input and output (px/frame, right), the output's zoom
 * (outer right; 1 / zoom is the kept share of the width); only what was measured.
 */
export function clipPlotSpec(rows, cursor = null) {
  const t0 = rows.length ? rows[0].t : 0, t1 = rows.length ? rows[rows.length - 1].t : 1;
  const pts = (k) => rows.map((r) => [r.t - t0, r[k]]);
  return {
    x: { min: 0, max: t1 - t0, label: 'time (s)' },
    axes: [
      { label: 'angular speed (deg/s)', side: 'left' }, { label: 'RMS normal flow (px/frame)', side: 'right' },
      { label: 'zoom (x)', side: 'right2', min: 1 },
    ],
    series: [
      { key: 'est', label: 'camera (estimate) speed', color: '#ff7043', axis: 0, points: pts('est') },
      { key: 'view', label: 'view speed', color: '#42a5f5', axis: 0, points: pts('view') },
      { key: 'nf_in', label: 'normal flow, input', color: '#9e9e9e', axis: 1, points: pts('nfIn') },
      { key: 'nf_out', label: 'normal flow, output', color: '#66bb6a', axis: 1, points: pts('nfOut') },
      { key: 'zoom', label: 'zoom', color: '#ab47bc', axis: 2, points: pts('zoom') },
    ],
    marks: rows.filter((r) => r.saccade).map((r) => r.t - t0),
    markLabel: 'saccade',
    cursor,
  };
}
