// Stabilizes a clip in the browser: checks the settings, starts worker.js,
// relays its progress, shows its result, and offers the server when the
// browser cannot read the clip (a container mediabunny does not demux, a
// codec WebCodecs does not decode, a decoder that fails).
import { $, state, setPageState, showError, reset } from './state.js';
import { settings, lensArg, showFieldErrors, refuseSettings, formReady } from './settings.js';
import { readableList } from './formats.js';
import { showResult, setOriginal, playable } from './result.js';
import { telemetryCsv, rowsFromWorker } from './telemetry.js';
import { localSummary } from './summary.js';

/** What the page says when the browser cannot read `m.fileName` (the worker's `unsupported` message). */
export function unsupportedText(m) {
  const server = 'The server reads every format ffmpeg reads and can stabilize it instead (the clip is uploaded to this page\'s server).';
  if (m.reason === 'codec') {
    const codec = m.codec ? `the ${m.codec.toUpperCase()} video` : 'the video (a codec this page does not know)';
    return `This browser cannot decode ${codec} in ${m.fileName}. ${server}`;
  }
  const detail = String(m.detail || '').replace(/\.+$/, '');
  if (m.reason === 'decode') return `This browser failed to decode ${m.fileName} (${detail}). ${server}`;
  if (m.reason === 'no-video') return `The page finds no video track in ${m.fileName} (it reads ${readableList()}). ${server}`;
  return `${m.fileName} is not a video this page can read in the browser (it reads ${readableList()}): ${detail}. ${server}`;
}

export async function runLocal(file) {
  if (!file) return;
  await formReady;
  state.file = file;
  const run = reset();
  // What the previous run said of its gyro track is not this run's.
  delete document.body.dataset.gyro;
  delete document.body.dataset.gyroNote;
  $('again').disabled = false;
  if (state.worker) { state.worker.terminate(); state.worker = null; }
  const s = settings();
  if (s.errors.length) return refuseSettings(s.errors);
  showFieldErrors([]);
  setPageState('processing');
  $('status-text').textContent = `Reading ${file.name}…`;
  const worker = new Worker('worker.js', { type: 'module' });
  state.worker = worker;
  const lens = await lensArg(s);
  const t0 = performance.now();
  let start = null, readoutWarning = null, lensWarning = null, gyroWarning = null;
  const current = () => state.run === run && state.worker === worker;
  // The stabilizer's own speed: with helpers, that of this worker's, which tracks every frame and draws 1 output in N.
  const stabilizerSpeed = (fps) => start && start.workers > 1
    ? `this worker's stabilizer ${fps.toFixed(0)} frames/s, drawing 1 output in ${start.workers}`
    : `stabilizer alone ${fps.toFixed(0)} frames/s`;
  worker.onerror = (e) => { if (current()) showError(`worker failed: ${e.message || e}`); };
  worker.onmessage = (ev) => {
    if (!current()) return;
    const m = ev.data;
    if (m.type === 'start') {
      start = m;
      document.body.dataset.pixelFormat = m.pixelFormat;
      document.body.dataset.workers = String(m.workers);
      $('status-text').textContent = `${m.width}x${m.height} ${m.codec} → ${m.outWidth}x${m.outHeight} ${m.outCodec}` +
        ` (${m.pixelFormat}${m.simd ? ', WASM SIMD' : ''}${m.workers > 1 ? `, ${m.workers} workers` : ''})` + (m.audioNote ? ` · ${m.audioNote}` : '') +
        (m.lensNote ? ` · ${m.lensNote}` : '') + (m.readoutNote ? ` · ${m.readoutNote}` : '') + (m.gyro ? ` · ${m.gyro.note}` : '');
      // The field of view the stabilizer runs with (given, or fov auto's estimate; none with a lens file).
      document.body.dataset.fov = m.fov == null ? '' : String(m.fov);
      // The readout the stabilizer runs with (the setting, the lens file's, or auto's estimate).
      document.body.dataset.readoutMs = String(m.params.shutter ? m.params.shutter.readout_ms : 0);
      if (m.total) $('progress').max = m.total;
    } else if (m.type === 'zoom-pass') {
      // zoom static: the first pass (tracking only) that finds the clip's zoom.
      if (m.total) { $('progress').max = m.total; $('progress').value = m.done; }
      $('status-text').textContent = m.zoom
        ? `Static zoom ${m.zoom.toFixed(3)}x (keeps ${(100 / m.zoom).toFixed(1)}% of the width); stabilizing…`
        : `Finding the static zoom (first pass): frame ${m.done}${m.total ? ' / ' + m.total : ''}`;
    } else if (m.type === 'lens-pass') {
      // fov auto: the first pass (tracking only) over the clip's first frames.
      if (m.total) { $('progress').max = m.total; $('progress').value = m.done; }
      $('status-text').textContent = `Estimating the field of view (first pass): frame ${m.done}${m.total ? ' / ' + m.total : ''}`;
    } else if (m.type === 'lens') {
      lensWarning = m.warning ? m.note : null;
      document.body.dataset.fovNote = m.note;
      $('status-text').textContent = `${m.note[0].toUpperCase()}${m.note.slice(1)}; going on…`;
    } else if (m.type === 'readout-pass') {
      // readout_ms auto: the first pass (tracking only) over the clip's first frames.
      if (m.total) { $('progress').max = m.total; $('progress').value = m.done; }
      $('status-text').textContent = `Estimating the readout (first pass): frame ${m.done}${m.total ? ' / ' + m.total : ''}`;
    } else if (m.type === 'readout') {
      readoutWarning = m.warning ? m.note : null;
      document.body.dataset.readoutNote = m.note;
      $('status-text').textContent = `${m.note[0].toUpperCase()}${m.note.slice(1)}; stabilizing…`;
    } else if (m.type === 'gyro-pass') {
      // gyro auto with a track: the first pass (tracking only) over every frame, to sync and fuse the gyro with.
      if (m.total) { $('progress').max = m.total; $('progress').value = m.done; }
      $('status-text').textContent = `Tracking the clip for its gyro track (first pass): frame ${m.done}${m.total ? ' / ' + m.total : ''}`;
    } else if (m.type === 'gyro') {
      gyroWarning = m.warning ? m.note : null;
      // 'fused' (each frame rendered with the gyro's pose), 'warning' (its log did not fit) or 'none' (not read).
      document.body.dataset.gyro = m.report ? 'fused' : (m.warning ? 'warning' : 'none');
      document.body.dataset.gyroNote = m.note;
      $('status-text').textContent = `${m.note[0].toUpperCase()}${m.note.slice(1)}; stabilizing…`;
    } else if (m.type === 'progress') {
      if (m.total) { $('progress').max = m.total; $('progress').value = m.done; }
      $('status-text').textContent = `Frame ${m.done}${m.total ? ' / ' + m.total : ''} · ${m.fps.toFixed(0)} frames/s ` +
        `(${stabilizerSpeed(m.stabFps)}; plot metrics ${m.metricsFps.toFixed(0)} frames/s)`;
    } else if (m.type === 'done') {
      const secs = (performance.now() - t0) / 1000;
      $('progress').max = m.frames; $('progress').value = m.frames;
      $('status-text').textContent = `Done: ${m.frames} frames in ${secs.toFixed(1)} s · ${m.fps.toFixed(0)} frames/s end to end ` +
        `(decode + stabilize + measure + encode); ${stabilizerSpeed(m.stabFps)}, plot metrics ${m.metricsFps.toFixed(0)} frames/s.` +
        (lensWarning ? ` Warning: ${lensWarning.replace(/^warning: /, '')}` : '') +
        (readoutWarning ? ` Warning: ${readoutWarning.replace(/^warning: /, '')}` : '') +
        (gyroWarning ? ` Warning: ${gyroWarning.replace(/^warning: /, '')}` : '');
      document.body.dataset.frames = m.frames;
      document.body.dataset.fps = m.fps.toFixed(1);
      document.body.dataset.stabFps = m.stabFps.toFixed(1);
      worker.terminate();
      state.worker = null;
      showResult({
        blob: new Blob([m.buffer], { type: m.mime }), mime: m.mime, name: file.name,
        original: file, origCaption: 'Original (full frame)',
        rows: rowsFromWorker(m.telemetry),
        csv: new Blob([telemetryCsv(m.telemetry)], { type: 'text/csv' }),
        summary: localSummary(start, m, s.params.view.mode),
        inputWidth: start ? start.width : 0,
      });
      setPageState('done');
      // WebCodecs decoded it, but the <video> element may still not play the container.
      playable(file).then((ok) => {
        if (ok === false && state.run === run) setOriginal(null, `Original: this browser's video player cannot show ${file.name} (it was decoded frame by frame for stabilizing)`);
      });
    } else if (m.type === 'unsupported') {
      worker.terminate();
      state.worker = null;
      $('unsupported-text').textContent = unsupportedText(m);
      $('unsupported').hidden = false;
      $('status-text').textContent = m.reason === 'codec' ? 'Codec not supported by this browser.' : 'This browser cannot read the clip.';
      setPageState('error');
    } else if (m.type === 'error') {
      showError(m.message);
    }
  };
  state.cancel = () => { worker.terminate(); if (state.worker === worker) state.worker = null; showError('Cancelled.'); };
  worker.postMessage({ type: 'process', file, params: s.params, lens, format: s.format, readout: s.readout, gyro: s.gyro });
}
