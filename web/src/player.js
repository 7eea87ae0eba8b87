// The original and the stabilized clip side by side, played in sync: the
// original (when shown) leads, the stabilized clip follows it.
import { $ } from './state.js';
import { drawPlot } from './plot.js';

const orig = $('orig'), stab = $('stab');
const master = () => (orig.src && !orig.hidden && orig.readyState > 0 ? orig : stab);
const follower = () => (master() === orig ? stab : null);

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

function tick() {
  const m = master(), f = follower();
  if (m.duration) {
    if (f && !m.paused && Math.abs(f.currentTime - m.currentTime) > 0.06) f.currentTime = m.currentTime;
    $('seek').value = m.currentTime / m.duration;
    $('time').textContent = `${m.currentTime.toFixed(2)} s`;
    if (m.ended) $('play').textContent = 'Play';
    drawPlot(m.currentTime);
  }
  requestAnimationFrame(tick);
}

export function initPlayer() {
  $('play').onclick = togglePlay;
  $('seek').oninput = seek;
  requestAnimationFrame(tick);
}
