// The Live tab: the server's stabilized feed over the `/live` WebSocket (a
// JPEG then a JSON telemetry message per frame) and a plot of recent speeds.
import { $, state } from './state.js';

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
      state.liveHist.push(m); if (state.liveHist.length > 300) state.liveHist.shift();
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

function drawLivePlot() {
  const c = $('live-plot'), g = c.getContext('2d');
  const hist = state.liveHist;
  g.clearRect(0, 0, c.width, c.height);
  const max = Math.max(1, ...hist.map((m) => Math.max(m.speed_est_dps, m.speed_view_dps)));
  const draw = (k, color) => {
    g.strokeStyle = color; g.beginPath();
    hist.forEach((m, i) => { const x = (c.width * i) / 300, y = c.height - (c.height * m[k]) / max; i ? g.lineTo(x, y) : g.moveTo(x, y); });
    g.stroke();
  };
  draw('speed_est_dps', '#ff7043'); draw('speed_view_dps', '#42a5f5');
}
