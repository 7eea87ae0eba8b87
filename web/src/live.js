// The Live tab: the server's stabilized feed over the `/live` WebSocket (a
// JPEG then a JSON telemetry message per frame) and a plot of recent speeds
// (axes with units, a legend beside it). A browser cannot put the API key on
// a WebSocket, so each connection, and each reconnection, first gets a
// one-use ticket (`POST /live/ticket` through authFetch, with the key when the
// server wants one) and opens `/live?ticket=…`; the key itself never goes in
// a URL. A server without tickets (404: older than them) gets a plain `/live`.
// Where WebCodecs' `VideoDecoder` exists (a secure context: HTTPS or
// localhost) the feed comes as H.264 (`codec=h264`, about a sixth of the
// JPEGs' bytes), decoded for latency and drawn to the canvas; elsewhere, or if
// the decoder fails, as JPEGs, and the status says which and why.
import { $, state } from './state.js';
import { drawChart, legend } from './plot.js';
import { authFetch, ApiError, problemDetail } from './auth.js';

// Counts connect/disconnect calls: a late answer of an earlier one compares against it.
let session = 0;
let frames = 0, retryTimer = null, retryDelay = 1;

// Access units waiting in the decoder past which it skips to the next keyframe.
const MAX_DECODE_QUEUE = 30;

// Set when H.264 failed in this page: JPEGs from then on.
let h264Failed = null;

/** Why the feed comes as JPEGs, or null when H.264 can be decoded here. */
function noH264() {
  if (h264Failed) return h264Failed;
  if (typeof VideoDecoder !== 'function') {
    return window.isSecureContext ? 'this browser has no WebCodecs VideoDecoder' : 'H.264 needs WebCodecs, which needs HTTPS or localhost';
  }
  return null;
}

/** The WebSocket URL for a new connection (a fresh ticket), or null when refused (the status says why). */
async function liveUrl(codec) {
  const base = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/live`;
  const params = [];
  const r = await authFetch('/live/ticket', { method: 'POST', what: 'watch the live feed', role: 'view' });
  if (r.status !== 404) {
    if (!r.ok) throw new Error(`the server gave no ticket: ${(await problemDetail(r)) || `HTTP ${r.status}`}`);
    const { ticket } = await r.json();
    if (typeof ticket !== 'string' || !ticket) throw new Error('the server gave no ticket');
    params.push(`ticket=${encodeURIComponent(ticket)}`);
  }
  if (codec === 'h264') params.push('codec=h264');
  return params.length ? `${base}?${params.join('&')}` : base;
}

/** `avc1.PPCCLL` from the SPS in an Annex-B access unit (profile, constraints, level), or null. */
function avcCodec(au) {
  for (let i = 0; i + 7 < au.length; i++) {
    if (au[i] === 0 && au[i + 1] === 0 && au[i + 2] === 1 && (au[i + 3] & 0x1f) === 7) {
      return 'avc1.' + [au[i + 4], au[i + 5], au[i + 6]].map((b) => b.toString(16).padStart(2, '0')).join('');
    }
  }
  return null;
}

/** Whether an Annex-B access unit holds an IDR picture. */
function isKey(au) {
  for (let i = 0; i + 3 < au.length; i++) {
    if (au[i] === 0 && au[i + 1] === 0 && au[i + 2] === 1 && (au[i + 3] & 0x1f) === 5) return true;
  }
  return false;
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
  const why = noH264();
  const codec = why ? 'jpeg' : 'h264';
  let url;
  try {
    url = await liveUrl(codec);
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
  ws.binaryType = codec === 'h264' ? 'arraybuffer' : 'blob';
  const canvas = $('live-canvas');
  const shown = url.replace(/\?.*/, '');
  let busy = false, got = 0, bytes = 0, latency = 0, chunks = 0, lagging = false;
  const t0 = performance.now();
  const label = codec === 'h264' ? 'H.264 (WebCodecs)' : `JPEG${why ? ` (${why})` : ''}`;
  const showRate = () => {
    const secs = (performance.now() - t0) / 1000;
    $('live-status').textContent = `Live, ${label}: ${frames} frames, ${(got / secs).toFixed(1)} frames/s, ` +
      `${(bytes * 8 / 1e6 / secs).toFixed(2)} Mbit/s, latency ${latency.toFixed(0)} ms`;
  };
  const drawn = () => {
    frames++; got++;
    canvas.dataset.frames = frames;
    canvas.dataset.codec = codec;
    showRate();
  };
  let decoder = null;
  if (codec === 'h264') {
    decoder = new VideoDecoder({
      output: (frame) => {
        if (canvas.width !== frame.displayWidth || canvas.height !== frame.displayHeight) {
          canvas.width = frame.displayWidth; canvas.height = frame.displayHeight;
        }
        canvas.getContext('2d').drawImage(frame, 0, 0);
        frame.close();
        drawn();
      },
      error: (e) => {
        // A stream this browser cannot decode: JPEGs from now on, saying why.
        if (me !== session) return;
        h264Failed = `the H.264 decoder failed: ${e.message || e}`;
        ws.onclose = null;
        ws.close();
        if (state.ws === ws) state.ws = null;
        connect(me);
      },
    });
  }
  $('live-status').textContent = `Connecting to ${shown}…`;
  ws.onopen = () => { $('live-status').textContent = 'Connected; waiting for frames.'; };
  ws.onclose = () => {
    if (decoder && decoder.state !== 'closed') decoder.close();
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
      latency = +m.latency_ms || 0;
      drawLivePlot();
      return;
    }
    // Pictures the server sent this page, drawn or not (beside data-frames, those drawn).
    canvas.dataset.received = Number(canvas.dataset.received || 0) + 1;
    if (decoder) {
      const au = new Uint8Array(ev.data);
      bytes += au.length;
      if (decoder.state === 'unconfigured') {
        // The server's first message is a keyframe with its SPS: the profile and level are in it.
        const avc = avcCodec(au);
        if (!avc) return;
        decoder.configure({ codec: avc, optimizeForLatency: true });
      }
      if (decoder.state !== 'configured') return;
      const key = isKey(au);
      // A decoder that fell half a second behind (a slow device) waits for the
      // next keyframe rather than showing ever older pictures.
      if (key) lagging = false;
      else if (lagging || decoder.decodeQueueSize > MAX_DECODE_QUEUE) { lagging = true; return; }
      decoder.decode(new EncodedVideoChunk({ type: key ? 'key' : 'delta', timestamp: 1000 * chunks++, data: au }));
      return;
    }
    bytes += ev.data.size || 0;
    if (busy) return; // drop frames rather than queue them
    busy = true;
    try {
      const bmp = await createImageBitmap(ev.data);
      if (canvas.width !== bmp.width || canvas.height !== bmp.height) { canvas.width = bmp.width; canvas.height = bmp.height; }
      canvas.getContext('2d').drawImage(bmp, 0, 0);
      bmp.close();
      drawn();
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
