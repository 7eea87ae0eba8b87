// Falls back to the server's job API for clips this browser cannot read or decode:
// POST /jobs with the page's settings, poll GET /jobs/{id}, then fetch the
// output and the job's telemetry.csv (plot, download). When the browser cannot
// play the user's file either, a second job (mode none, no averaging, no
// crop) makes a copy it can play for the Original slot and the compare views.
// Every call goes through authFetch (auth.js): the API key of a server that
// wants one, asked for on its first 401.
import { $, state, setPageState, showError, reset } from './state.js';
import { authFetch, ApiError } from './auth.js';
import { settings, serverQuery, refuseSettings, formReady } from './settings.js';
import { showResult, setOriginal, playable } from './result.js';
import { rowsFromCsv } from './telemetry.js';
import { serverSummary } from './summary.js';

async function problem(res) {
  try { const p = await res.json(); return p.detail || p.title || JSON.stringify(p); } catch { return `HTTP ${res.status}`; }
}

class JobError extends Error {}

// What each call needs of a key (a 403's message names the action and the role).
const SUBMIT = { what: 'submit jobs', role: 'submit' };
const JOBS = { what: 'see jobs', role: 'submit' };
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** Submits a job; returns its URL (`/jobs/{id}`). */
async function submit(file, query, lensFile) {
  let res;
  if (lensFile) {
    const fd = new FormData();
    fd.append('video', file, file.name);
    fd.append('lens', lensFile, lensFile.name);
    res = await authFetch(`/jobs?${query}`, { method: 'POST', body: fd, ...SUBMIT });
  } else {
    res = await authFetch(`/jobs?${query}`, { method: 'POST', body: file, headers: { 'Content-Type': file.type || 'application/octet-stream' }, ...SUBMIT });
  }
  if (res.status !== 202 && !res.ok) throw new JobError(`server refused the job: ${await problem(res)}`);
  const job = await res.json();
  return res.headers.get('Location') || `/jobs/${job.id}`;
}

/** Polls a job until it is done (returns its status) or `stop()` says so (returns null). */
async function waitFor(loc, onStatus, stop) {
  for (;;) {
    await new Promise((r) => setTimeout(r, 300));
    if (stop()) return null;
    let r;
    try {
      r = await authFetch(loc, JOBS);
    } catch (e) {
      // Too many requests: wait as the server asks, then poll again.
      if (!(e instanceof ApiError && e.status === 429)) throw e;
      $('status-text').textContent = `Server: ${e.message}…`;
      await sleep(1000 * e.retryAfter);
      continue;
    }
    if (!r.ok) throw new JobError(`job status: ${await problem(r)}`);
    const st = await r.json();
    if (stop()) return null;
    onStatus(st);
    if (st.state === 'done') return st;
    if (st.state === 'failed' || st.state === 'cancelled') throw new JobError(`server job ${st.state}: ${st.error || ''}`);
  }
}

async function fetchBlob(url, what) {
  const r = await authFetch(url, JOBS);
  if (!r.ok) throw new JobError(`${what}: ${await problem(r)}`);
  return r.blob();
}

export async function runOnServer(file) {
  if (!file) return;
  await formReady;
  const run = reset();
  const s = settings();
  if (s.errors.length) {
    refuseSettings(s.errors);
    $('unsupported').hidden = false;
    return;
  }
  setPageState('processing');
  $('status-text').textContent = `Uploading ${file.name} to the server…`;
  let cancelled = false, loc = null;
  const stop = () => cancelled || state.run !== run;
  const remove = (loc) => authFetch(loc, { method: 'DELETE', what: 'cancel jobs', role: 'submit' }).catch(() => {});
  state.cancel = () => { cancelled = true; if (loc) remove(loc); showError('Cancelled.'); };
  try {
    loc = await submit(file, serverQuery(s), s.lensFile);
    if (stop()) { remove(loc); return; }
    const st = await waitFor(loc, (st) => {
      if (st.frames_total) { $('progress').max = st.frames_total; $('progress').value = st.frames_done; }
      $('status-text').textContent = `Server: ${st.state}, frame ${st.frames_done}${st.frames_total ? ' / ' + st.frames_total : ''}`;
    }, stop);
    if (!st) return;
    const format = st.format || s.format;
    const mime = format === 'webm' ? 'video/webm' : 'video/mp4';
    const blob = await fetchBlob(st.output || `${loc}/output`, 'job output');
    let csv = null, rows = null;
    try {
      const text = await (await fetchBlob(st.telemetry || `${loc}/telemetry.csv`, 'job telemetry')).text();
      csv = new Blob([text], { type: 'text/csv' });
      rows = rowsFromCsv(text);
    } catch { /* no telemetry: no plot, no CSV */ }
    if (stop()) return;
    // What the server warns about (fov auto fell back to 70°, readout auto to 0), as a local run says it.
    const warnings = (st.metrics && st.metrics.warnings) || [];
    $('status-text').textContent = `Done on the server: ${st.frames_done} frames.` +
      warnings.map((w) => ` Warning: ${w.replace(/^warning: /, '')}`).join('');
    document.body.dataset.serverWarnings = String(warnings.length);
    document.body.dataset.frames = st.frames_done;
    showResult({
      blob: new Blob([blob], { type: mime }), mime, name: file.name, original: null,
      origCaption: 'Original: checking whether this browser can play it…',
      rows, csv, summary: serverSummary(st, s.params.view.mode),
      inputWidth: st.metrics && st.metrics.input_size ? st.metrics.input_size[0] : 0,
    });
    setPageState('done');
    state.cancel = null;
    await showOriginal(file, s, run);
  } catch (e) {
    if (stop()) return;
    // A refusal of the key (none given, a role missing, too many requests) is the server's answer to the job.
    if (e instanceof ApiError) showError(`server refused the job: ${e.message}`);
    else showError(e instanceof JobError ? e.message : `server job: ${e.message || e}`);
  }
}

/** Fills the Original slot: the user's file, or a playable copy made by the server. */
async function showOriginal(file, s, run) {
  const stale = () => state.run !== run;
  if (await playable(file)) {
    if (!stale()) setOriginal(file, 'Original (full frame)');
    return;
  }
  if (stale()) return;
  $('orig-caption').textContent = 'Original: this browser cannot play it; the server is making a copy it can play…';
  try {
    const q = new URLSearchParams({ mode: 'none', n_avg: 1, margin: 0, metrics: false, format: 'mp4' });
    // Mode none through a pinhole shows the same picture at any field of
    // view: a number (the one set, else 70) spares the server fov auto's pass.
    if (!s.lensFile) q.set('fov', typeof s.fov === 'number' ? s.fov : 70);
    const loc = await submit(file, q, s.lensFile);
    const st = await waitFor(loc, () => {}, stale);
    if (!st) return;
    const copy = await fetchBlob(st.output || `${loc}/output`, 'copy of the original');
    if (stale()) return;
    setOriginal(new Blob([copy], { type: 'video/mp4' }),
      `Original (full frame; re-encoded to H.264 by the server${s.lensFile ? ' and undistorted' : ''}, since this browser cannot play ${file.name})`);
  } catch (e) {
    if (!stale()) $('orig-caption').textContent = `Original: this browser cannot play ${file.name}, and the server could not make a copy (${e.message || e}).`;
  }
}
