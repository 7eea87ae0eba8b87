// The Live tab: the server's stabilized feed over the `/live` WebSocket (a
// JPEG then a JSON telemetry message per frame) and a plot of recent speeds
// (axes with units, a legend beside it). A browser cannot put the API key on
// a WebSocket, so each connection, and each reconnection, first gets a
// one-use ticket (`POST /live/ticket` through authFetch, with the key when the
// server wants one) and opens `/live?ticket=…`; the key itself never goes in
// a URL. A server without tickets (404: older than them) gets a plain `/live`.
import { $, state } from './state.js';
import { drawChart, legend } from './plot.js';
import { authFetch, ApiError, problemDetail } from './auth.js';

// Counts connect/disconnect calls: a late answer of an earlier one compares against it.
let session = 0;
let frames = 0, retryTimer = null, retryDelay = 1;

/** The WebSocket URL for a new connection (a fresh ticket), or null when refused (the status says why). */
async function liveUrl() {
  const base = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/live`;
  const r = await authFetch('/live/ticket', { method: 'POST', what: 'watch the live feed', role: 'view' });
  if (r.status === 404) return base;
  if (!r.ok) throw new Error(`the server gave no ticket: ${(await problemDetail(r)) || `HTTP ${r.status}`}`);
  const { ticket } = await r.json();
  if (typeof ticket !== 'string' || !ticket) throw new Error('the server gave no ticket');
  return `${base}?ticket=${encodeURIComponent(ticket)}`;
}

/** Connects later (after a drop, or the server's Retry-After), with a new ticket. */
function reconnectIn(secs, why, me) {
  clearTimeout(retryTimer);
  $('live-status').textContent = `${why} Reconnecting in ${secs} s…`;
  retryTimer = setTimeout(() => { if (me === session) connect(me); }, 1000 * secs);
}

export function connectLive() {
  if (state.ws || state.liveOn) return;
  state.liveOn = true;
  connect(++session);
}

async function connect(me) {
  $('live-status').textContent = 'Asking the server for a ticket…';
  let url;
  try {
    url = await liveUrl();
  } catch (e) {
    if (me !== session) return;
    if (e instanceof ApiError && e.status === 429) return reconnectIn(e.retryAfter, `Live feed: ${e.message}.`, me);
    // No key given, a role missing, no ticket: shown until the tab is opened again.
    $('live-status').textContent = `Cannot connect to the live feed: ${e.message || e}.`;
    state.liveOn = false;
    return;
  }
  if (me !== session) return;
  const ws = new WebSocket(url);
  state.ws = ws;
  ws.binaryType = 'blob';
  const canvas = $('live-canvas');
  const shown = url.replace(/\?.*/, '');
  let busy = false, got = 0;
  const t0 = performance.now();
  $('live-status').textContent = `Connecting to ${shown}…`;
  ws.onopen = () => { $('live-status').textContent = 'Connected; waiting for frames.'; };
  ws.onclose = () => {
    if (state.ws === ws) state.ws = null;
    if (me !== session) return;
    // Dropped (the server restarted, the network went): again, with a new ticket; slower each time nothing came.
    retryDelay = got > 0 ? 1 : Math.min(2 * retryDelay, 30);
    reconnectIn(retryDelay, got > 0 ? 'Disconnected.' : `Cannot connect to ${shown}.`, me);
  };
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
      frames++; got++;
      canvas.dataset.frames = frames;
      const fps = got / ((performance.now() - t0) / 1000);
      $('live-status').textContent = `Live: ${frames} frames, ${fps.toFixed(1)} frames/s`;
    } catch (e) { /* a bad JPEG: skip */ } finally { busy = false; }
  };
}

export function disconnectLive() {
  session++;
  clearTimeout(retryTimer);
  state.liveOn = false;
  if (state.ws) { const ws = state.ws; state.ws = null; ws.close(); }
  $('live-status').textContent = 'Not connected.';
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
