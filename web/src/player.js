// Synced playback of the original and the stabilized clip, and the three ways
// to compare them: side by side (two players of the same size), an A/B wipe
// and a difference image. The original (when there is one) leads; the
// stabilized clip follows it. The wipe and the difference draw the original's
// central region at the output's scale (the crop the stabilized view is cut
// from when it does not turn) under the stabilized frame, so both line up.
import { $, state } from './state.js';
import { drawChart, clipPlotSpec } from './plot.js';

const orig = $('orig'), stab = $('stab');
const hasOrig = () => !!orig.src && !orig.hidden && orig.readyState > 0;
const master = () => (hasOrig() ? orig : stab);
const follower = () => (master() === orig ? stab : null);
let mode = 'side';
let lastCursor = null;

function togglePlay() {
  const m = master();
  if (m.paused) {
    if (follower()) follower().currentTime = m.currentTime;
    m.play(); if (follower()) follower().play();
    $('play').textContent = 'Pause';
  } else {
    m.pause(); if (follower()) follower().pause();
    $('play').textContent = 'Play';
  }
}

function seek() {
  const m = master();
  if (!m.duration) return;
  const t = Number($('seek').value) * m.duration;
  m.currentTime = t; if (follower()) follower().currentTime = t;
}

/** Redraws the clip plot (with a cursor at `t` seconds, or none). */
export function drawClipPlot(t = null) {
  const rows = state.plotRows;
  const c = $('plot');
  if (!rows || !rows.length || $('result').hidden) return;
  drawChart(c, clipPlotSpec(rows, t));
  lastCursor = t;
}

/** The compare canvas: the wipe or the difference of the current frames. */
function drawCompare() {
  const c = $('compare-canvas'), g = c.getContext('2d');
  const ow = stab.videoWidth, oh = stab.videoHeight;
  if (!ow || !oh || stab.readyState < 2) return;
  if (c.width !== ow || c.height !== oh) { c.width = ow; c.height = oh; }
  g.globalCompositeOperation = 'source-over';
  if (!hasOrig() || orig.readyState < 2) { g.drawImage(stab, 0, 0, ow, oh); return; }
  // Output pixels have the input's scale (same focal length, centred): the
  // original's central ow x oh pixels (scaled if the original is a resized copy).
  const k = orig.videoWidth / state.inputWidth || 1;
  const cw = Math.min(orig.videoWidth, ow * k), ch = Math.min(orig.videoHeight, oh * k);
  const sx = (orig.videoWidth - cw) / 2, sy = (orig.videoHeight - ch) / 2;
  if (mode === 'wipe') {
    const x = Math.round(Number($('wipe').value) * ow);
    g.drawImage(stab, 0, 0, ow, oh);
    g.save(); g.beginPath(); g.rect(0, 0, x, oh); g.clip();
    g.drawImage(orig, sx, sy, cw, ch, 0, 0, ow, oh);
    g.restore();
    g.fillStyle = '#fff'; g.fillRect(x - 1, 0, 2, oh);
    // Labels about 13 px tall on screen whatever the clip's size.
    const px = Math.max(9, Math.round((13 * ow) / (c.clientWidth || ow))), pad = Math.round(px / 3);
    g.font = `${px}px system-ui, sans-serif`; g.textBaseline = 'top';
    const label = (text, right) => {
      const w = g.measureText(text).width, x = right ? ow - w - 3 * pad : pad;
      g.fillStyle = 'rgba(0,0,0,.55)'; g.fillRect(x, pad, w + 2 * pad, px + 2 * pad);
      g.fillStyle = '#fff'; g.fillText(text, x + pad, 2 * pad);
    };
    label('original', false); label('stabilized', true);
  } else {
    g.drawImage(orig, sx, sy, cw, ch, 0, 0, ow, oh);
    g.globalCompositeOperation = 'difference';
    g.drawImage(stab, 0, 0, ow, oh);
    g.globalCompositeOperation = 'source-over';
  }
  c.dataset.drawn = String(Number(c.dataset.drawn || 0) + 1);
}

function setMode(m) {
  mode = hasOrig() ? m : 'side';
  $('players').hidden = mode !== 'side';
  $('compare').hidden = mode === 'side';
  $('wipe-label').hidden = mode !== 'wipe';
  $('compare-caption').textContent = mode === 'wipe'
    ? 'A/B wipe: the original’s central region (at the output’s scale) left of the line, the stabilized clip right of it. Drag on the image or use the slider.'
    : 'Difference |original − stabilized| (the original’s central region at the output’s scale): bright where they differ, i.e. the motion the view took out, and blur from averaging.';
  document.body.dataset.compare = mode;
}

function tick() {
  const m = master(), f = follower();
  if (m.duration) {
    if (f && !m.paused && Math.abs(f.currentTime - m.currentTime) > 0.06) f.currentTime = m.currentTime;
    $('seek').value = m.currentTime / m.duration;
    $('time').textContent = `${m.currentTime.toFixed(2)} s`;
    if (m.ended) $('play').textContent = 'Play';
    if (m.currentTime !== lastCursor) drawClipPlot(m.currentTime);
    if (mode !== 'side') drawCompare();
  }
  requestAnimationFrame(tick);
}

/** After a new result: back to side by side; the compare modes need an original. */
export function resetCompare() {
  for (const id of ['compare-wipe', 'compare-diff']) $(id).disabled = false;
  $('compare-side').checked = true;
  setMode('side');
  lastCursor = null;
}

/** Whether the compare modes are offered (they need a playable original). */
export function enableCompare(on) {
  for (const id of ['compare-wipe', 'compare-diff']) $(id).disabled = !on;
  if (!on) { $('compare-side').checked = true; setMode('side'); }
}

export function initPlayer() {
  $('play').onclick = togglePlay;
  $('seek').oninput = seek;
  for (const r of document.querySelectorAll('input[name=compare]')) r.onchange = () => { setMode(r.value); drawCompare(); };
  $('wipe').oninput = drawCompare;
  const c = $('compare-canvas');
  const drag = (e) => {
    if (mode !== 'wipe' || !(e.buttons & 1)) return;
    const r = c.getBoundingClientRect();
    $('wipe').value = Math.min(1, Math.max(0, (e.clientX - r.left) / r.width));
    drawCompare();
  };
  c.addEventListener('pointerdown', drag);
  c.addEventListener('pointermove', drag);
  // Both players (and the compare canvas) share one box size: the stabilized clip's aspect ratio.
  stab.addEventListener('loadedmetadata', () => {
    if (stab.videoWidth) $('result').style.setProperty('--ar', `${stab.videoWidth} / ${stab.videoHeight}`);
  });
  orig.addEventListener('loadeddata', () => { if (mode !== 'side') drawCompare(); });
  window.addEventListener('resize', () => drawClipPlot(lastCursor));
  requestAnimationFrame(tick);
}
