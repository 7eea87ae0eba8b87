// The page: picks/drops a clip, hands it to the worker, shows progress, the
// original and stabilized clips side by side in sync, the per-frame plot, the
// download; falls back to the server's job API for codecs the browser cannot
// decode; and shows the server's live feed.
const $ = (id) => document.getElementById(id);
const body = document.body;
const setState = (s) => {
  body.dataset.state = s;
  $('cancel').hidden = s !== 'processing';
};

let worker = null;
let cancelJob = null; // cancels the running work (worker or server job)
let currentFile = null;
let lastTelemetry = null;
let urls = [];

function newUrl(blob) {
  const u = URL.createObjectURL(blob);
  urls.push(u);
  return u;
}

function showError(msg) {
  $('error').textContent = msg;
  $('error').hidden = false;
  $('status-text').textContent = 'Failed.';
  setState('error');
}

function settings() {
  const num = (id) => Number($(id).value);
  return {
    params: {
      view: { mode: $('mode').value, rate_a: num('rate_a'), rate_b: num('rate_b'), lookahead: num('lookahead') },
      render: { n_avg: num('n_avg'), margin: num('margin') },
    },
    fov: num('fov'),
    format: $('format').value,
  };
}

async function lensArg(s) {
  const f = $('lens').files[0];
  return f ? await f.text() : s.fov;
}

function reset() {
  for (const u of urls) URL.revokeObjectURL(u);
  urls = [];
  $('error').hidden = true;
  $('unsupported').hidden = true;
  $('result').hidden = true;
  $('progress').value = 0;
  $('progress').removeAttribute('max');
  $('progress').max = 1;
}

async function start(file) {
  if (!file) return;
  currentFile = file;
  reset();
  $('again').disabled = false;
  setState('processing');
  $('status-text').textContent = `Reading ${file.name}…`;
  if (worker) worker.terminate();
  worker = new Worker('worker.js', { type: 'module' });
  const s = settings();
  const lens = await lensArg(s);
  const t0 = performance.now();
  worker.onerror = (e) => showError(`worker failed: ${e.message || e}`);
  worker.onmessage = (ev) => {
    const m = ev.data;
    if (m.type === 'start') {
      $('status-text').textContent = `${m.width}x${m.height} ${m.codec} → ${m.outWidth}x${m.outHeight} ${m.outCodec}` +
        (m.simd ? ' (WASM SIMD)' : '') + (m.audioNote ? ` · ${m.audioNote}` : '');
      if (m.total) $('progress').max = m.total;
    } else if (m.type === 'progress') {
      if (m.total) { $('progress').max = m.total; $('progress').value = m.done; }
      $('status-text').textContent = `Frame ${m.done}${m.total ? ' / ' + m.total : ''} · ${m.fps.toFixed(0)} frames/s ` +
        `(stabilizer alone ${m.stabFps.toFixed(0)} frames/s; plot metrics ${m.metricsFps.toFixed(0)} frames/s)`;
    } else if (m.type === 'done') {
      const secs = (performance.now() - t0) / 1000;
      $('progress').max = m.frames; $('progress').value = m.frames;
      $('status-text').textContent = `Done: ${m.frames} frames in ${secs.toFixed(1)} s · ${m.fps.toFixed(0)} frames/s end to end ` +
        `(decode + stabilize + measure + encode); stabilizer alone ${m.stabFps.toFixed(0)} frames/s, plot metrics ${m.metricsFps.toFixed(0)} frames/s.`;
      body.dataset.frames = m.frames;
      body.dataset.fps = m.fps.toFixed(1);
      body.dataset.stabFps = m.stabFps.toFixed(1);
      showResult(new Blob([m.buffer], { type: m.mime }), m.mime, m.telemetry, m.summary, file);
      setState('done');
    } else if (m.type === 'unsupported') {
      $('unsupported-text').textContent = `This browser cannot decode the ${m.codec.toUpperCase()} video in ${m.fileName}. ` +
        'The server can stabilize it instead (the clip is uploaded to this page\'s server).';
      $('unsupported').hidden = false;
      $('status-text').textContent = 'Codec not supported by this browser.';
      setState('error');
    } else if (m.type === 'error') {
      showError(m.message);
    }
  };
  const w = worker;
  cancelJob = () => { w.terminate(); if (worker === w) worker = null; showError('Cancelled.'); };
  worker.postMessage({ type: 'process', file, params: s.params, lens, format: s.format });
}

function showResult(blob, mime, telemetry, summary, original) {
  const ext = mime.includes('webm') ? 'webm' : 'mp4';
  const a = $('download');
  a.href = newUrl(blob);
  a.download = (original ? original.name.replace(/\.[^.]+$/, '') : 'clip') + `-stabilized.${ext}`;
  a.textContent = `Download (${ext.toUpperCase()}, ${(blob.size / 1e6).toFixed(1)} MB)`;
  $('stab').src = a.href;
  if (original) $('orig').src = newUrl(original);
  $('orig').hidden = !original;
  $('result').hidden = false;
  lastTelemetry = telemetry || null;
  $('summary').textContent = summary ? JSON.stringify(summary, null, 1) : '';
  drawPlot();
}

// --- Side by side, in sync -------------------------------------------------
const orig = $('orig'), stab = $('stab');
function master() { return orig.src && !orig.hidden && orig.readyState > 0 ? orig : stab; }
function follower() { return master() === orig ? stab : null; }
$('play').onclick = () => {
  const m = master();
  if (m.paused) {
    if (follower()) follower().currentTime = m.currentTime;
    m.play(); if (follower()) follower().play();
    $('play').textContent = 'Pause';
  } else {
    m.pause(); if (follower()) follower().pause();
    $('play').textContent = 'Play';
  }
};
$('seek').oninput = () => {
  const m = master();
  if (!m.duration) return;
  const t = Number($('seek').value) * m.duration;
  m.currentTime = t; if (follower()) follower().currentTime = t;
};
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
requestAnimationFrame(tick);

// --- Per-frame plot (as in the paper's Figure 2) ---------------------------
function drawPlot(cursorT) {
  const c = $('plot'), g = c.getContext('2d');
  const T = lastTelemetry;
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

// --- Input: pick or drop ---------------------------------------------------
$('file').onchange = () => start($('file').files[0]);
$('again').onclick = () => start(currentFile);
const drop = $('drop');
for (const ev of ['dragenter', 'dragover']) drop.addEventListener(ev, (e) => { e.preventDefault(); drop.classList.add('over'); });
for (const ev of ['dragleave', 'drop']) drop.addEventListener(ev, () => drop.classList.remove('over'));
drop.addEventListener('drop', (e) => { e.preventDefault(); start(e.dataTransfer.files[0]); });
document.addEventListener('dragover', (e) => e.preventDefault());
document.addEventListener('drop', (e) => { e.preventDefault(); if (e.target !== drop) start(e.dataTransfer.files[0]); });

$('cancel').onclick = () => { if (cancelJob) cancelJob(); cancelJob = null; };

// --- Server fallback (job API) ---------------------------------------------
$('server-btn').onclick = () => serverJob(currentFile);
async function problem(res) {
  try { const p = await res.json(); return p.detail || p.title || JSON.stringify(p); } catch { return `HTTP ${res.status}`; }
}
async function serverJob(file) {
  if (!file) return;
  const s = settings();
  $('unsupported').hidden = true;
  $('error').hidden = true;
  setState('processing');
  $('status-text').textContent = 'Uploading to the server…';
  const q = new URLSearchParams({
    mode: s.params.view.mode, n_avg: s.params.render.n_avg, margin: s.params.render.margin,
    fov: s.fov, lookahead: s.params.view.lookahead, format: s.format,
  });
  let res;
  const lensFile = $('lens').files[0];
  if (lensFile) {
    const fd = new FormData();
    fd.append('video', file, file.name);
    fd.append('lens', lensFile, lensFile.name);
    q.delete('fov');
    res = await fetch(`/jobs?${q}`, { method: 'POST', body: fd });
  } else {
    res = await fetch(`/jobs?${q}`, { method: 'POST', body: file, headers: { 'Content-Type': file.type || 'application/octet-stream' } });
  }
  if (res.status !== 202 && !res.ok) return showError(`server refused the job: ${await problem(res)}`);
  const job = await res.json();
  const loc = res.headers.get('Location') || `/jobs/${job.id}`;
  let cancelled = false;
  cancelJob = () => { cancelled = true; fetch(loc, { method: 'DELETE' }).catch(() => {}); showError('Cancelled.'); };
  for (;;) {
    if (cancelled) return;
    await new Promise((r) => setTimeout(r, 300));
    const r = await fetch(loc);
    if (!r.ok) return showError(`job status: ${await problem(r)}`);
    const st = await r.json();
    if (cancelled) return;
    if (st.frames_total) { $('progress').max = st.frames_total; $('progress').value = st.frames_done; }
    $('status-text').textContent = `Server: ${st.state}, frame ${st.frames_done}${st.frames_total ? ' / ' + st.frames_total : ''}`;
    if (st.state === 'done') {
      const out = await fetch(`${loc}/output`);
      if (!out.ok) return showError(`job output: ${await problem(out)}`);
      const blob = await out.blob();
      const mime = s.format === 'webm' ? 'video/webm' : 'video/mp4';
      $('status-text').textContent = `Done on the server: ${st.frames_done} frames.`;
      body.dataset.frames = st.frames_done;
      showResult(new Blob([blob], { type: mime }), mime, null, st.metrics, null);
      $('download').download = file.name.replace(/\.[^.]+$/, '') + `-stabilized.${s.format}`;
      setState('done');
      return;
    }
    if (st.state === 'failed' || st.state === 'cancelled') return showError(`server job ${st.state}: ${st.error || ''}`);
  }
}

// --- Tabs and the live feed -------------------------------------------------
let ws = null;
for (const b of document.querySelectorAll('.tab')) {
  b.onclick = () => {
    for (const o of document.querySelectorAll('.tab')) o.classList.toggle('active', o === b);
    $('panel-clip').hidden = b.dataset.tab !== 'clip';
    $('panel-live').hidden = b.dataset.tab !== 'live';
    if (b.dataset.tab === 'live') connectLive(); else disconnectLive();
  };
}
const liveHist = [];
function connectLive() {
  if (ws) return;
  const url = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/live`;
  ws = new WebSocket(url);
  ws.binaryType = 'blob';
  const canvas = $('live-canvas');
  let frames = 0, t0 = performance.now(), busy = false;
  $('live-status').textContent = `Connecting to ${url}…`;
  ws.onopen = () => { $('live-status').textContent = 'Connected; waiting for frames.'; };
  ws.onclose = () => { $('live-status').textContent = 'Disconnected.'; ws = null; };
  ws.onerror = () => { $('live-status').textContent = `Cannot connect to ${url}.`; };
  ws.onmessage = async (ev) => {
    if (typeof ev.data === 'string') {
      let m; try { m = JSON.parse(ev.data); } catch { return; }
      liveHist.push(m); if (liveHist.length > 300) liveHist.shift();
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
function disconnectLive() { if (ws) { ws.close(); ws = null; } }
function drawLivePlot() {
  const c = $('live-plot'), g = c.getContext('2d');
  g.clearRect(0, 0, c.width, c.height);
  const max = Math.max(1, ...liveHist.map((m) => Math.max(m.speed_est_dps, m.speed_view_dps)));
  const draw = (k, color) => {
    g.strokeStyle = color; g.beginPath();
    liveHist.forEach((m, i) => { const x = (c.width * i) / 300, y = c.height - (c.height * m[k]) / max; i ? g.lineTo(x, y) : g.moveTo(x, y); });
    g.stroke();
  };
  draw('speed_est_dps', '#ff7043'); draw('speed_view_dps', '#42a5f5');
}
if (location.hash === '#live') $('tab-live').click();
