// Stabilizes a clip off the main thread: demux (mediabunny), decode every frame
// (WebCodecs), stabilize (amc-wasm), encode (WebCodecs) and mux (mediabunny),
// copying the original's audio packets where the container allows.
import init, { Stabilizer, PassPlan, GyroPass, ClipGyro, simdEnabled } from './pkg/amc_wasm.js';
import { pixelPath, copyOptions, colorSpaceInit } from './pixels.js';
import { readClipGyro, gyroText } from './gyro.js';
import { RenderShare, helperCount } from './render-share.js';
import {
  Input, ALL_FORMATS, BlobSource, VideoSampleSink, EncodedPacketSink, VideoSample,
  Output, Mp4OutputFormat, WebMOutputFormat, BufferTarget, VideoSampleSource,
  EncodedAudioPacketSource, canEncodeVideo,
} from './vendor/mediabunny.mjs';

const ready = init();
let cancelled = false;

/**
 * The browser cannot read the clip (`reason`: `container`, `no-video`,
 * `codec` or `decode`): the page offers the server instead.
 */
class Unreadable extends Error {
  constructor(reason, detail, codec = null) {
    super(detail);
    this.reason = reason;
    this.codec = codec;
  }
}

const message = (e) => String(e && e.message ? e.message : e);

/** A sink's samples, a decoder's failure turned into `Unreadable` (the page offers the server). */
async function* decoded(samples) {
  try {
    for (;;) {
      let r;
      try {
        r = await samples.next();
      } catch (e) {
        throw new Unreadable('decode', message(e));
      }
      if (r.done) return;
      yield r.value;
    }
  } finally {
    // Stopped early (a pass that has its frames): the sink closes its decoder and samples.
    try { await samples.return(); } catch { /* it failed already */ }
  }
}

self.onmessage = async (ev) => {
  const msg = ev.data;
  if (msg.type === 'cancel') { cancelled = true; return; }
  if (msg.type !== 'process') return;
  cancelled = false;
  try {
    await ready;
    await processClip(msg);
  } catch (e) {
    if (e instanceof Unreadable) post('unsupported', { reason: e.reason, codec: e.codec, detail: e.message, fileName: msg.file.name });
    else self.postMessage({ type: 'error', message: message(e) });
  }
};

function post(type, data = {}, transfer = []) {
  self.postMessage({ type, ...data }, transfer);
}

async function pickVideoCodec(format, width, height) {
  const prefs = format === 'webm' ? ['vp9', 'vp8', 'av1'] : ['avc', 'vp9', 'av1'];
  for (const codec of prefs) {
    if (await canEncodeVideo(codec, { width, height, bitrate: 4e6 })) return codec;
  }
  throw new Error(`this browser cannot encode ${format === 'webm' ? 'VP9, VP8 or AV1' : 'H.264, VP9 or AV1'} video`);
}

/** The progress message of each pass the plan makes (see amc-core's plan). */
const PASS_PROGRESS = { lens: 'lens-pass', readout: 'readout-pass', static_zoom: 'zoom-pass' };

/**
 * One pass of `plan` (a PassPlan, or a GyroPass, which takes every frame)
 * over `video`'s frames: each frame decoded into its input buffer and
 * pushed, until the clip ends or `plan.isFull`; progress posted as `kind`.
 */
async function firstPass(plan, video, copyOpts, total, kind) {
  let n = 0, lastT = -Infinity, lastPost = 0;
  for await (const sample of decoded(new VideoSampleSink(video).samples())) {
    if (cancelled) { sample.close(); throw new Error('cancelled'); }
    if (plan.isFull) { sample.close(); break; }
    let t = sample.timestamp;
    if (!(t > lastT)) t = lastT + 1e-6; // as the main pass does
    lastT = t;
    await sample.copyTo(plan.inputBuffer(), copyOpts);
    sample.close();
    plan.pushInput(t);
    n++;
    const now = performance.now();
    if (now - lastPost > 100) {
      lastPost = now;
      post(kind, { done: n, total });
    }
  }
}

/**
 * The first passes the plan asks for (fov auto: the clip's first frames,
 * for the field of view; readout_ms auto: the clip's first frames tracked
 * with the rolling-shutter model; zoom static: every frame through a
 * stabilizer that does not render), each reading the clip from its start
 * and only the frames it takes. Posts the field of view and the readout
 * found; returns `{ fov, lensResult, readoutResult, zoom }` (null where
 * there was no such pass; `fov`: the degrees fov auto found).
 */
async function makePasses(plan, video, copyOpts, total) {
  let readoutResult = null, zoom = null, fov = null, lensResult = null;
  while (plan.pass) {
    const budget = plan.frameBudget;
    const wanted = budget === undefined ? total : (total ? Math.min(total, budget) : budget);
    await firstPass(plan, video, copyOpts, wanted, PASS_PROGRESS[plan.pass]);
    const frames = plan.frames;
    const found = plan.finishPass();
    if (found.pass === 'lens') {
      fov = found.hfov_deg;
      lensResult = lensNote(found, frames);
      post('lens', lensResult);
    } else if (found.pass === 'readout') {
      readoutResult = { ...readoutNote(found), estimate: found.estimate };
      post('readout', readoutResult);
    } else if (found.pass === 'static_zoom') {
      zoom = found.zoom;
    }
  }
  return { fov, lensResult, readoutResult, zoom };
}

/** What the page says of the lens pass (fov auto): the field of view found, or a warning when it fell back (the CLI's words). */
function lensNote({ hfov_deg: deg, note }, frames) {
  if (note === 'estimated') return { fov: deg, note: `field of view ${deg.toFixed(1)}° (estimated from ${frames} frames)` };
  return {
    fov: deg,
    warning: true,
    note: 'warning: the footage does not pin down the focal length (translation or little rotation); ' +
      `assuming a ${deg.toFixed(0)}° horizontal field of view: set the field of view (or a lens file) under Advanced for best results`,
  };
}

/** What the page says of the readout pass: the readout used, and a warning when it fell back to 0. */
function readoutNote({ readout_ms, note, estimate: e }) {
  if (note === 'estimated') return { readout_ms, note: `readout ${readout_ms.toFixed(1)} ms (estimated from ${e.frames} frames)` };
  return {
    readout_ms,
    warning: true,
    note: `warning: the clip does not pin down the rolling-shutter readout (estimate ${e.readout_ms.toFixed(1)} ms from ${e.frames} frames, ` +
      'not reliable); assuming a global shutter (0 ms): enter the readout in milliseconds for best results',
  };
}

/**
 * gyro auto with a track found: the gyro's first pass (every frame tracked
 * by a stabilizer made as the main one is, tracking only), then the
 * log synchronized and fused with it, as the CLI does. Returns `{ report,
 * poses, note }` (`poses`: for `Stabilizer.setPoses`) or, when the log does
 * not fit the video, `{ warning: true, note }` (the run goes on from the
 * picture alone).
 */
async function gyroPass(parts, paramsJson, lens, { width, height, path, video, copyOpts, total }) {
  const log = ClipGyro.fromParts(parts.source, parts.videoClock, parts.readoutMs, parts.times, parts.rates);
  let pass;
  try {
    pass = new GyroPass(width, height, paramsJson, lens, path);
    await firstPass(pass, video, copyOpts, total, 'gyro-pass');
    const found = pass.fuse(log);
    if (found.warning) return { warning: true, note: `warning: ${found.warning}` };
    return { report: found.report, poses: found.poses, note: gyroText(found.report), line: found.line };
  } finally {
    if (pass) pass.free();
    log.free();
  }
}

async function processClip({ file, params, lens, format, readout, gyro = 'auto' }) {
  // gyro auto: the clip's own IMU track, read beside the demuxing (in a worker of its own).
  const gyroRead = gyro === 'off' ? Promise.resolve(null) : readClipGyro(file);
  const input = new Input({ source: new BlobSource(file), formats: ALL_FORMATS });
  let video;
  try {
    video = await input.getPrimaryVideoTrack();
  } catch (e) {
    throw new Unreadable('container', message(e));
  }
  if (!video) throw new Unreadable('no-video', 'no video track');
  const codec = video.codec;
  if (!(await video.canDecode())) throw new Unreadable('codec', `cannot decode ${codec || 'its codec'}`, codec);
  const stats = await video.computePacketStats(Infinity).catch(() => null);
  const total = stats ? stats.packetCount : null;
  // Frames are processed as decoded (coded orientation, visible rectangle); a
  // rotation in the container is carried over to the output's metadata.
  const samples = decoded(new VideoSampleSink(video).samples());
  const first = await samples.next();
  if (first.done) throw new Unreadable('decode', 'no frame decoded from its video track');
  const width = first.value.visibleRect.width, height = first.value.visibleRect.height;
  // Planar frames go through the module as planes (no RGBA round trip); the
  // output is then I420 with the input's colour space.
  const path = pixelPath(first.value);
  const outColorSpace = path === 'RGBA' ? undefined : colorSpaceInit(first.value);
  const copyOpts = copyOptions(path, width, height);
  let stab, plan, readoutResult = null, lensResult = null, staticZoomUsed = null, fov = null, gyroResult = null;
  try {
    const found = await gyroRead;
    const log = found && found.parts;
    if (found && found.note) gyroResult = { note: found.note };
    // The readout the clip records (GoPro's SROT, ...) answers `auto`, and
    // stands in for the unset default where no lens file states one (as the CLI).
    const recorded = log && log.readoutMs != null && (readout === 'auto' || (readout == null && (typeof lens === 'number' || lens === 'auto')));
    if (recorded) readout = log.readoutMs;
    // The first passes (fov auto, readout_ms auto, zoom static), as the core plans them.
    plan = new PassPlan(width, height, JSON.stringify(params), lens, path, readout);
    ({ fov, lensResult, readoutResult, zoom: staticZoomUsed } = await makePasses(plan, video, copyOpts, total));
    if (recorded) {
      readoutResult = { readout_ms: readout, note: `readout ${readout.toFixed(1)} ms (recorded by the camera: ${log.source})` };
      post('readout', readoutResult);
    }
    // fov auto: the stabilizer (and its helpers) get the degrees found.
    if (fov !== null) lens = fov;
    stab = new Stabilizer(width, height, plan.paramsJson(), lens, path);
    if (staticZoomUsed !== null) {
      // One zoom for the whole clip, found by its first pass.
      stab.setStaticZoom(staticZoomUsed);
      post('zoom-pass', { done: total || 0, total, zoom: staticZoomUsed });
    }
    if (log) {
      gyroResult = await gyroPass(log, plan.paramsJson(), lens, { width, height, path, video, copyOpts, total });
      // Each frame rendered with its fused pose, not tracked again.
      if (gyroResult.poses) stab.setPoses(gyroResult.poses);
      post('gyro', { note: gyroResult.note, warning: !!gyroResult.warning, report: gyroResult.report || null });
    } else if (gyroResult) {
      post('gyro', { note: gyroResult.note, warning: false, report: null });
    }
  } catch (e) {
    first.value.close();
    if (stab) stab.free();
    throw e;
  } finally {
    if (plan) plan.free();
  }
  stab.setMetrics(true);
  const ow = stab.outputWidth, oh = stab.outputHeight, outFormat = stab.outputFormat;
  // The other cores draw their share of the outputs (render-share.js).
  let share;
  try {
    // The helpers' stabilizers are made from this one's parameters, as it holds them.
    const paramsJson = stab.paramsJson();
    const mode = JSON.parse(paramsJson).view.mode;
    const spec = { width, height, paramsJson, lens, format: path, staticZoom: staticZoomUsed, poses: gyroResult && gyroResult.poses };
    const helpers = helperCount(mode);
    share = await RenderShare.open(stab, spec, helpers).catch((e) => {
      // Helpers that cannot start (a browser without module workers in
      // workers, say) leave this worker to draw every output.
      if (!helpers) throw e;
      console.warn(`render helpers did not start (${e.message}); stabilizing in one worker`);
      return RenderShare.open(stab, spec, 0);
    });
  } catch (e) {
    first.value.close();
    stab.free();
    throw e;
  }
  try {
    const gyroNote = gyroResult && { note: gyroResult.note, warning: !!gyroResult.warning, report: gyroResult.report || null };
    await stabilizeClip({ format, video, stats, total, width, height, first, samples, path, outColorSpace, copyOpts, codec, stab, share, ow, oh, outFormat, readoutResult, lensResult, gyroNote, fov: typeof lens === 'number' ? lens : null, input });
  } finally {
    share.close();
    stab.free();
  }
}

/** The main pass: every frame decoded, stabilized (its output drawn here or by a helper), encoded and muxed. */
async function stabilizeClip({ format, video, stats, total, width, height, first, samples, path, outColorSpace, copyOpts, codec, stab, share, ow, oh, outFormat, readoutResult, lensResult, gyroNote, fov, input }) {
  const container = format === 'webm' ? new WebMOutputFormat() : new Mp4OutputFormat({ fastStart: 'in-memory' });
  const outCodec = await pickVideoCodec(format, ow, oh);
  const output = new Output({ format: container, target: new BufferTarget() });
  const videoSource = new VideoSampleSource({ codec: outCodec, bitrate: 4e6, keyFrameInterval: 2 });
  output.addVideoTrack(videoSource, {
    frameRate: stats && stats.averagePacketRate ? stats.averagePacketRate : undefined,
    rotation: video.rotation || 0,
  });

  // Audio: copied packet by packet when the output container takes its codec.
  let audio = null, audioNote = null;
  const audioTrack = await input.getPrimaryAudioTrack();
  if (audioTrack) {
    if (audioTrack.codec && container.getSupportedAudioCodecs().includes(audioTrack.codec)) {
      audio = { track: audioTrack, source: new EncodedAudioPacketSource(audioTrack.codec) };
      output.addAudioTrack(audio.source);
    } else {
      audioNote = `audio (${audioTrack.codec}) not copied: ${format.toUpperCase()} cannot hold it`;
    }
  }
  await output.start();

  post('start', { width, height, outWidth: ow, outHeight: oh, total, codec, outCodec, simd: simdEnabled(), workers: share.count,
    pixelFormat: path, decodedFormat: first.value.format,
    params: JSON.parse(stab.paramsJson()), audioNote, readoutNote: readoutResult && readoutResult.note,
    lensNote: lensResult && lensResult.note, gyro: gyroNote, fov });

  const t0 = performance.now();
  const inputMetrics = []; // of frames whose output the lookahead still holds back
  let stabMs = 0, metricsMs = 0, n = 0, out = 0, lastPost = 0, firstT = null, lastT = -Infinity;
  const telemetry = [];
  // An output, drawn here or by a helper, in order: measured, then encoded.
  const emit = async ({ tel, output, coverage }) => {
    const m0 = performance.now();
    tel.metrics = stab.measureOutputOf(output, coverage, tel.valid_fraction);
    tel.input_metrics = inputMetrics.shift();
    metricsMs += performance.now() - m0;
    telemetry.push(tel);
    const frame = new VideoFrame(output, {
      format: outFormat, codedWidth: ow, codedHeight: oh,
      timestamp: Math.round((tel.t - firstT) * 1e6),
      ...(outColorSpace ? { colorSpace: outColorSpace } : {}),
    });
    const sample = new VideoSample(frame);
    await videoSource.add(sample);
    sample.close();
    frame.close();
    out++;
  };
  async function* all() {
    yield first.value;
    for (;;) {
      const r = await samples.next();
      if (r.done) return;
      yield r.value;
    }
  }
  for await (const sample of all()) {
    if (cancelled) { sample.close(); throw new Error('cancelled'); }
    let t = sample.timestamp;
    if (firstT === null) firstT = t;
    if (!(t > lastT)) t = lastT + 1e-6; // duplicate timestamps: keep order
    lastT = t;
    if (path !== 'RGBA' && sample.format !== path) {
      const f = sample.format;
      sample.close();
      throw new Error(`the decoder changed its pixel format within the clip (${path} to ${f}); not supported`);
    }
    const buf = stab.inputBuffer();
    await sample.copyTo(buf, copyOpts);
    sample.close();
    const m0 = performance.now();
    inputMetrics.push(stab.measureInput());
    const s0 = performance.now();
    share.push(t);
    stabMs += performance.now() - s0;
    metricsMs += s0 - m0;
    n++;
    for await (const drawn of share.drawn()) await emit(drawn);
    const now = performance.now();
    if (now - lastPost > 100) {
      lastPost = now;
      post('progress', { done: n, total, fps: n / ((now - t0) / 1000), stabFps: n / (stabMs / 1000), metricsFps: n / (metricsMs / 1000) });
    }
  }
  const s0 = performance.now();
  share.finish();
  stabMs += performance.now() - s0;
  for await (const drawn of share.drawn(true)) await emit(drawn);
  if (audio) {
    const sink = new EncodedPacketSink(audio.track);
    const decoderConfig = await audio.track.getDecoderConfig();
    let first = true;
    for await (const packet of sink.packets()) {
      await audio.source.add(packet, first ? { decoderConfig } : undefined);
      first = false;
    }
  }
  await output.finalize();
  const elapsed = (performance.now() - t0) / 1000;
  const buffer = output.target.buffer;
  const summary = stab.summary();
  post('done', {
    buffer, mime: format === 'webm' ? 'video/webm' : 'video/mp4', frames: n, outFrames: out,
    fps: n / elapsed, stabFps: n / (stabMs / 1000), metricsFps: n / (metricsMs / 1000), telemetry, summary, outCodec,
  }, [buffer]);
}
