// The Live tab: the server's stabilized feed over the `/live` WebSocket (a
// JPEG then a JSON telemetry message per frame) and a plot of recent speeds
// (axes with units, a legend beside it).
import { $, state } from './state.js';
import { drawChart, legend } from './plot.js';

export function connectLive() {
  if (state.ws) return;
  const url = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/live`;
  const ws = new WebSocket(url);
  state.ws = ws;
  ws.binaryType = 'blob';
  const canvas = $('live-canvas');
  let frames = 0, busy = false;
  const t0 = performance.now();
  $('live-status').textContent = `Connecting to ${url}…`;
  ws.onopen = () => { $('live-status').textContent = 'Connected; waiting for frames.'; };
  ws.onclose = () => { $('live-status').textContent = 'Disconnected.'; if (state.ws === ws) state.ws = null; };
  ws.onerror = () => { $('live-status').textContent = `Cannot connect to ${url}.`; };
  ws.onmessage = async (ev) => {
    if (typeof ev.data === 'string') {
      let m; try { m = JSON.parse(ev.data); } catch { return; }
      const h = state.liveHist;
      if (h.length && +m.t < +h[h.length - 1].t) h.length = 0; // the source looped: a new time line
      h.push(m); if (state.liveHist.length > 300) state.liveHist.shift();
      $('live-telemetry').textContent = `frame ${m.frame}  t ${(+m.t).toFixed(2)} s  estimate ${(+m.speed_est_dps).toFixed(1)} deg/s  ` +
        `view ${(+m.speed_view_dps).toFixed(1)} deg/s  valid ${(100 * m.valid).toFixed(0)}%  ${m.saccade ? 'SACCADE  ' : ''}latency ${(+m.latency_ms).toFixed(0)} ms`;
      drawLivePlot();
      return;
    }
    if (busy) return; // drop frames rather than queue them
    busy = true;
    try {
      const bmp = await createImageBitmap(ev.data);
      if (canvas.width !== bmp.width || canvas.height !== bmp.height) { canvas.width = bmp.width; canvas.height = bmp.height; }
      canvas.getContext('2d').drawImage(bmp, 0, 0);
      bmp.close();
      frames++;
      canvas.dataset.frames = frames;
      const fps = frames / ((performance.now() - t0) / 1000);
      $('live-status').textContent = `Live: ${frames} frames, ${fps.toFixed(1)} frames/s`;
    } catch (e) { /* a bad JPEG: skip */ } finally { busy = false; }
  };
}

export function disconnectLive() {
  if (state.ws) { state.ws.close(); state.ws = null; }
}

/** The last ~10 s of the feed's angular speeds, with axes and a legend. */
function drawLivePlot() {
  const hist = state.liveHist;
  if (!hist.length) return;
  const tEnd = +hist[hist.length - 1].t;
  const recent = hist.filter((m) => tEnd - m.t <= 10);
  const pts = (k) => recent.map((m) => [m.t - tEnd, +m[k]]);
  const spec = {
    x: { min: -10, max: 0, label: 'time before the latest frame (s)' },
    axes: [{ label: 'angular speed (deg/s)', side: 'left' }],
    series: [
      { key: 'est', label: 'camera (estimate) speed', color: '#ff7043', axis: 0, points: pts('speed_est_dps') },
      { key: 'view', label: 'view speed', color: '#42a5f5', axis: 0, points: pts('speed_view_dps') },
    ],
    marks: recent.filter((m) => m.saccade).map((m) => m.t - tEnd),
    markLabel: 'saccade',
  };
  drawChart($('live-plot'), spec);
  const keys = spec.series.map((x) => x.key).join(',') + (spec.marks.length ? ',marks' : '');
  if ($('live-legend').dataset.keys !== keys) { legend($('live-legend'), spec); $('live-legend').dataset.keys = keys; }
}
