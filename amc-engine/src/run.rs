//! One stabilization run over a whole input: decode -> stabilize -> encode,
//! with telemetry, metrics and progress. Shared by `stabilize`, `eval` and `demo`.

//! One run: decode -> stabilize -> encode, with telemetry, metrics and progress.

use super::control::RunControl;
use super::fusion;
use super::gyro::{GyroLog, GyroReport};
use super::log_readout::MeasureReadout;
use super::measure::MetricsWorker;
use super::passes::{self, On};
use super::stages::{Reader, Writer};
use super::{paths, telemetry, RunError};
use amc_core::metrics::{ClipMetrics, FrameMetrics, MotionAccumulator, MotionSummary};
use amc_core::plan::{LensChoice, LensNote, PassPlan, PlanChoices, ResolvedLens};
use amc_core::{
    CameraModel, Frame, PixelFormat, ReadoutSpec, Stabilizer, StabilizerParams, Telemetry,
};
use amc_video::{self as video, AtomicFile, FrameSource, InputOptions, OutputSpec};
use serde::Serialize;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::{Duration, Instant};

/// What a run needs.
pub struct RunConfig<'a> {
    /// A video, a folder of images or a `.y4m` file.
    pub input: &'a Path,
    /// Where the stabilized video goes (none: measure only).
    pub output: Option<&'a Path>,
    /// The stabilizer's parameters (already validated or not: `run` validates).
    pub params: StabilizerParams,
    /// The camera of the input's frames.
    pub lens: CameraModel,
    /// Where the telemetry CSV goes.
    pub telemetry: Option<&'a Path>,
    /// Other files the caller will write after the run (e.g. `--metrics`),
    /// checked not to clash with the input or the outputs before anything starts.
    pub also_writes: &'a [(&'static str, &'a Path)],
    /// Frame rate for image folders, or to override a video's timestamps.
    pub fps: Option<f64>,
    /// Longest an ffmpeg child may stall.
    pub timeout: Duration,
    /// Encoder quality (x264/VP9 CRF), when not the default.
    pub crf: Option<u8>,
    /// x264's preset for mp4/mkv outputs, when not the default.
    pub preset: Option<amc_video::X264Preset>,
    /// Keep per-frame records (for plots); memory grows with clip length.
    pub keep_per_frame: bool,
    /// Measure the quality metrics (costs about as much as stabilizing at 720p).
    pub measure: bool,
    /// Cancellation, a time limit and a progress counter.
    pub control: Option<&'a RunControl>,
    /// Called after every output frame.
    pub progress: Option<&'a (dyn Fn(Progress) + Sync)>,
    /// A gyro log to synchronize with the clip and fuse with its tracking
    /// (a first pass tracks the whole clip; see `fusion`).
    pub gyro: Option<&'a GyroLog>,
    /// A readout the log records none of: a run with a gyro measures it
    /// against the log, in place of `params`' readout, as
    /// [`LogReadout::measure`](super::LogReadout::measure) says.
    pub measure_readout: Option<MeasureReadout>,
    /// The lens is `--fov auto`'s fallback: with a gyro log whose readout
    /// the run measures, the field of view is estimated again with that
    /// readout (a rolling shutter's frames can hide it from the first,
    /// global-shutter estimate), and the first pass made again with it.
    pub refit_lens: bool,
    /// Threads of the run: 1 decodes, stabilizes and encodes on the caller's
    /// thread; 2 or more decode and encode on threads of their own beside it
    /// (see `stages`) and render each frame's rows on a pool of this many
    /// threads. Same output either way.
    pub threads: usize,
}

/// How far a run is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    /// Output frames written.
    pub done: u64,
    /// Frames the input declares, when it does.
    pub total: Option<u64>,
    /// Seconds since the run started.
    pub elapsed_s: f64,
}

/// One output frame's record.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRecord {
    pub telemetry: Telemetry,
    pub metrics: FrameMetrics,
}

/// What a run produced.
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub frames: u64,
    /// Frames the input's container declares (when it does).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_declared: Option<u64>,
    pub input_size: (usize, usize),
    pub output_size: (usize, usize),
    pub seconds: f64,
    pub frames_per_second: f64,
    /// Quality metrics (absent when not measured).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub metrics: Option<ClipMetrics>,
    /// What the telemetry says of the whole clip (always measured: it is free).
    pub motion: MotionSummary,
    /// The rolling-shutter readout the run used, milliseconds (0 = global shutter).
    pub readout_ms: f64,
    /// The ghost-free average's threshold the run ended with, levels of 255
    /// (`deghost=auto`: set from the clip's noise; 0: the plain average).
    pub deghost_levels: f64,
    /// The gyro log's sync and fusion, when the run was given one that fits.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gyro: Option<GyroReport>,
    /// The field of view (degrees) `--fov auto` found once the gyro log
    /// measured the readout, where the first estimate had fallen back
    /// ([`RunConfig::refit_lens`]); the run used it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit_hfov_deg: Option<f64>,
    /// Warnings for the user about the run (the caller adds them: e.g.
    /// `readout_ms=auto` fell back to a global shutter).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    #[serde(skip)]
    pub per_frame: Vec<FrameRecord>,
}

impl RunSummary {
    /// Whether clearly fewer frames were decoded than the container declares:
    /// the file is truncated or damaged (ffmpeg decodes what it can and
    /// still succeeds).
    pub fn looks_truncated(&self) -> bool {
        self.frames_declared
            .is_some_and(|n| (self.frames as f64) < TRUNCATED_SHARE * n as f64 - 2.0)
    }
}

/// Share of the declared frames under which an input counts as truncated
/// (declared counts can be a few frames off: edit lists, priming frames).
pub const TRUNCATED_SHARE: f64 = 0.95;

/// The pool a run renders on: `threads` threads (1: the rows in order, on it).
/// The live feed renders on one too.
pub fn render_pool(threads: usize) -> Result<rayon::ThreadPool, RunError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .thread_name(|i| format!("amc-render-{i}"))
        .build()
        .map_err(|e| RunError::Threads(e.to_string()))
}

/// Runs the stabilizer over the whole input.
pub fn run(cfg: &RunConfig<'_>) -> Result<RunSummary, RunError> {
    cfg.params.validate()?;
    let mut outputs: Vec<(&'static str, &Path)> = vec![("input", cfg.input)];
    outputs.extend(cfg.output.map(|p| ("output", p)));
    outputs.extend(cfg.telemetry.map(|p| ("telemetry", p)));
    outputs.extend(cfg.also_writes.iter().copied());
    paths::check_distinct(&outputs)?;

    // Frames stay in the format both ends have without a conversion: planar
    // 4:2:0 from a video to a video, RGB when either end is a folder of images.
    let format = match (
        video::native_format(cfg.input),
        cfg.output.map(video::native_output_format),
    ) {
        (PixelFormat::Yuv420p, None | Some(PixelFormat::Yuv420p)) => PixelFormat::Yuv420p,
        _ => PixelFormat::Rgb8,
    };
    // A run limited to fewer threads than the machine has keeps its ffmpeg
    // children within the same number (a worker of `--threads 1` then uses
    // about one core, so workers scale with cores).
    let ffmpeg_threads = (cfg.threads < super::default_threads()).then_some(cfg.threads);
    let opts = InputOptions {
        pixel_format: format,
        ffmpeg_threads,
        ..super::input_options(cfg.fps, cfg.timeout)
    };
    let pool = render_pool(cfg.threads)?;
    let mut warnings = Vec::new();
    let mut readout_ms = cfg.params.shutter.readout_ms;
    let mut lens = cfg.lens.clone();
    let mut refit_hfov_deg = None;
    let mut fused = match cfg.gyro {
        Some(log) => {
            let first_pass = |lens: &CameraModel, params: &StabilizerParams, measure| {
                fusion::fuse_pass(
                    cfg.input,
                    &opts,
                    lens,
                    params,
                    measure,
                    log,
                    &pool,
                    cfg.control,
                )
            };
            let mut first = first_pass(&lens, &cfg.params, cfg.measure_readout)?;
            if cfg.refit_lens {
                // The readout the first pass used, or the one it measured
                // against the log even where that did not pin it down (a
                // wrong lens hides it too): the lens again with it, and where
                // that finds one, the first pass again with that lens.
                let used = first.readout.as_ref().map(|(ms, _)| *ms);
                let measured = first
                    .fused
                    .as_ref()
                    .ok()
                    .and_then(|f| f.report.readout.as_ref())
                    .map(|r| r.readout_ms);
                let ms = used.filter(|&ms| ms > 0.0).or(measured).unwrap_or(0.0);
                let size = (lens.width, lens.height);
                if ms > 0.0 {
                    if let Some((camera, hfov)) =
                        super::lens::refit_with_readout(cfg.input, &cfg.params, &opts, size, ms)?
                    {
                        first = first_pass(&camera, &cfg.params, cfg.measure_readout)?;
                        lens = camera;
                        refit_hfov_deg = Some(hfov);
                    }
                }
            }
            if let Some((ms, warning)) = first.readout {
                readout_ms = ms;
                warnings.extend(warning);
            }
            match first.fused {
                Ok(fused) => Some(fused),
                Err(warning) => {
                    warnings.push(warning);
                    None
                }
            }
        }
        None => None,
    };
    // The readout the first pass measured, when it did.
    let mut params = cfg.params.clone();
    params.shutter.readout_ms = readout_ms;
    // With fused poses, `zoom = static` frames them (no second tracking pass).
    let static_zoom = match &fused {
        Some(f) => fusion::static_zoom(f, &lens, &params)?,
        None => static_zoom(cfg, &params, &opts, &pool)?,
    };
    let src: Box<dyn FrameSource> = match fused.as_mut().and_then(|f| f.cached.take()) {
        Some(clip) => Box::new(clip),
        None => video::open_input(cfg.input, &opts)?,
    };
    let info = src.info().clone();
    let threaded = cfg.threads > 1;
    let mut stab = Stabilizer::new(&lens, info.width, info.height, params.clone())?;
    if let Some(z) = static_zoom {
        stab.set_static_zoom(z);
    }
    // With threads to spare, track each frame while the previous output renders.
    stab.set_pipelined(cfg.threads > 1);
    let (ow, oh) = stab.output_size();
    let mut sink = match cfg.output {
        Some(path) => {
            let mut spec = OutputSpec::new(ow, oh, cfg.fps.unwrap_or(info.fps));
            spec.audio_from = info.has_audio.then(|| cfg.input.to_path_buf());
            spec.timeout = cfg.timeout;
            spec.crf = cfg.crf;
            spec.preset = cfg.preset;
            spec.pixel_format = format;
            spec.ffmpeg_threads = ffmpeg_threads;
            Some(Writer::new(video::create_output(path, &spec)?, threaded))
        }
        None => None,
    };
    let mut src = Reader::new(src, format, threaded);
    let mut telemetry = match cfg.telemetry {
        Some(p) => {
            let mut w = BufWriter::new(AtomicFile::create(p, "")?);
            writeln!(w, "{}", super::TELEMETRY_HEADER).map_err(|source| RunError::Write {
                path: p.to_path_buf(),
                source,
            })?;
            Some((w, p))
        }
        None => None,
    };
    let mut measure = cfg
        .measure
        .then(|| MetricsWorker::start(cfg.keep_per_frame));
    let mut per_frame = Vec::new();
    let mut motion = MotionAccumulator::default();
    let mut frame = Frame::new(info.width, info.height, format);
    let start = Instant::now();
    let mut frames = 0u64;
    let mut emit = |stab: &Stabilizer, tel: Telemetry| -> Result<(), RunError> {
        if let Some(s) = sink.as_mut() {
            s.write_frame(&stab.output(), tel.t)?;
        }
        if let Some(m) = measure.as_mut() {
            m.push(&stab.output(), stab.output_coverage(), &tel);
        }
        motion.push(tel.valid_fraction, Some(&tel));
        if let Some((w, path)) = telemetry.as_mut() {
            w.write_all(telemetry::row(&tel).as_bytes())
                .map_err(|source| RunError::Write {
                    path: path.to_path_buf(),
                    source,
                })?;
        }
        if cfg.keep_per_frame {
            per_frame.push(FrameRecord {
                telemetry: tel,
                metrics: FrameMetrics::default(),
            });
        }
        frames += 1;
        if let Some(c) = cfg.control {
            c.frame_written();
        }
        if let Some(report) = cfg.progress {
            report(Progress {
                done: frames,
                total: info.frame_count,
                elapsed_s: start.elapsed().as_secs_f64(),
            });
        }
        Ok(())
    };
    let check = || cfg.control.map_or(Ok(()), RunControl::check);
    let mut pushed = 0usize;
    while let Some(t) = src.next_frame(&mut frame)? {
        check()?;
        // With a gyro, the fused poses (the first pass read the same frames;
        // one more would keep the last pose).
        let given = fused
            .as_ref()
            .and_then(|f| f.poses.get(pushed).or(f.poses.last()).copied());
        pushed += 1;
        // On the pool, so that the renderer's row bands use its threads.
        let out = pool.install(|| match given {
            Some(g) => stab.push_posed(frame.as_ref(), t, g),
            None => stab.push(frame.as_ref(), t),
        })?;
        if let Some(tel) = out {
            emit(&stab, tel)?;
        }
    }
    while let Some(tel) = pool.install(|| stab.finish()) {
        check()?;
        emit(&stab, tel)?;
    }
    let metrics = match measure {
        Some(worker) => {
            let (clip, frame_metrics) = worker.finish().ok_or(RunError::MetricsWorker)?;
            for (record, m) in per_frame.iter_mut().zip(frame_metrics) {
                record.metrics = m;
            }
            Some(clip)
        }
        None => None,
    };
    if frames == 0 {
        return Err(RunError::NoFrames {
            path: cfg.input.to_path_buf(),
        });
    }
    let seconds = start.elapsed().as_secs_f64();
    if let Some(s) = sink {
        s.finish()?;
    }
    if let Some((w, path)) = telemetry {
        let file = w.into_inner().map_err(|e| RunError::Write {
            path: path.to_path_buf(),
            source: e.into_error(),
        })?;
        file.persist()?;
    }
    Ok(RunSummary {
        frames,
        frames_declared: info.frame_count,
        input_size: (info.width, info.height),
        output_size: (ow, oh),
        seconds,
        frames_per_second: frames as f64 / seconds.max(1e-9),
        metrics,
        motion: motion.summary(),
        readout_ms: params.shutter.readout_ms,
        deghost_levels: stab.deghost_levels().unwrap_or(0.0),
        gyro: fused.map(|f| f.report),
        refit_hfov_deg,
        warnings,
        per_frame,
    })
}

/// `zoom = static`'s first pass, when the parameters call for one (stabilize
/// and lock modes): the core's pass plan with the run's lens and readout
/// tracks and smooths the whole clip without rendering and returns the
/// highest zoom any output needs (the second pass clamps it to the crop
/// budget and pulls the view where it needs more). Frames are read as the
/// main pass reads them (`opts`).
fn static_zoom(
    cfg: &RunConfig<'_>,
    params: &StabilizerParams,
    opts: &InputOptions,
    pool: &rayon::ThreadPool,
) -> Result<Option<f64>, RunError> {
    let mut plan = PassPlan::new(PlanChoices {
        lens: LensChoice::Known(ResolvedLens {
            camera: cfg.lens.clone(),
            note: LensNote::Given,
            readout_ms: None,
        }),
        readout: ReadoutSpec::Ms(params.shutter.readout_ms),
        params: params.clone(),
        static_zoom: true,
        frame_size: None,
    })?;
    let on = On {
        pool: Some(pool),
        control: cfg.control,
    };
    passes::make(&mut plan, cfg.input, opts, on)?;
    Ok(plan.static_zoom())
}
