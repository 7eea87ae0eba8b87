// Falls back to the server's job API (POST /jobs, polled at GET /jobs/{id})
// for clips this browser cannot decode.
import { $, state, setPageState, showError } from './state.js';
import { settings } from './settings.js';
import { showResult } from './result.js';

async function problem(res) {
  try { const p = await res.json(); return p.detail || p.title || JSON.stringify(p); } catch { return `HTTP ${res.status}`; }
}

export async function runOnServer(file) {
  if (!file) return;
  const s = settings();
  $('unsupported').hidden = true;
  $('error').hidden = true;
  setPageState('processing');
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
  state.cancel = () => { cancelled = true; fetch(loc, { method: 'DELETE' }).catch(() => {}); showError('Cancelled.'); };
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
      document.body.dataset.frames = st.frames_done;
      showResult(new Blob([blob], { type: mime }), mime, null, st.metrics, null);
      $('download').download = file.name.replace(/\.[^.]+$/, '') + `-stabilized.${s.format}`;
      setPageState('done');
      return;
    }
    if (st.state === 'failed' || st.state === 'cancelled') return showError(`server job ${st.state}: ${st.error || ''}`);
  }
}
