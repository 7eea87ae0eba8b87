//! One stabilization run over a whole input: decode -> stabilize -> encode,
//! with telemetry, metrics and progress. Shared by `stabilize`, `eval` and `demo`.

use crate::cli::LensChoice;
use crate::error::CliError;
use crate::measure::MetricsWorker;
use amc_core::metrics::{ClipMetrics, FrameMetrics, MotionAccumulator, MotionSummary};
use amc_core::selfcal;
use amc_core::{CameraModel, Frame, PixelFormat, Stabilizer, StabilizerParams, Telemetry};
use amc_video::{self as video, FrameSource, InputOptions, OutputSpec};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Horizontal field of view assumed when `--fov auto` cannot pin the focal
/// length down: a typical phone / action-camera main lens.
pub const FALLBACK_FOV_DEG: f64 = 70.0;

/// Frames read for `--fov auto` (about 3 s at 30 fps).
pub const AUTO_FOV_FRAMES: usize = 90;

/// Header of the telemetry CSV. The first eight columns are a stable contract.
pub const TELEMETRY_HEADER: &str = "frame,t,rx,ry,rz,vx,vy,vz,est_speed_dps,view_speed_dps,valid_fraction,frames_averaged,saccade,iterations,rms_residual,track_valid_fraction,lost,template_reset";

/// What a run needs.
pub struct RunConfig<'a> {
    pub input: &'a Path,
    pub output: Option<&'a Path>,
    pub params: StabilizerParams,
    pub lens: CameraModel,
    pub telemetry: Option<&'a Path>,
    pub fps: Option<f64>,
    pub timeout: Duration,
    pub crf: Option<u8>,
    pub progress: bool,
    /// Keep per-frame records (for plots); memory grows with clip length.
    pub keep_per_frame: bool,
    /// Measure the quality metrics (costs about as much as stabilizing at 720p).
    pub measure: bool,
    pub label: &'a str,
    /// Cancellation, a time limit and a progress counter, for runs driven by the service.
    pub control: Option<&'a RunControl>,
}

/// Controls a run from another thread: cancel it, bound its time, read its progress.
#[derive(Debug, Default)]
pub struct RunControl {
    cancelled: AtomicBool,
    frames_done: AtomicU64,
    /// When the run must have finished, and the limit it came from (seconds).
    deadline: Option<(Instant, f64)>,
    /// A counter shared by many runs (the service's frames processed).
    shared_frames: Option<Arc<AtomicU64>>,
}

impl RunControl {
    /// A control whose run is stopped once `limit` has passed (if any).
    pub fn new(limit: Option<Duration>) -> Self {
        Self {
            deadline: limit.map(|l| (Instant::now() + l, l.as_secs_f64())),
            ..Self::default()
        }
    }

    /// Also counts this run's frames in `counter`.
    pub fn counting_into(mut self, counter: Arc<AtomicU64>) -> Self {
        self.shared_frames = Some(counter);
        self
    }

    /// Asks the run to stop at its next frame (its children are killed, its partial output removed).
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::SeqCst);
    }

    pub fn is_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::SeqCst)
    }

    /// Output frames written so far.
    pub fn frames_done(&self) -> u64 {
        self.frames_done.load(Ordering::Relaxed)
    }

    fn check(&self) -> Result<(), CliError> {
        if self.is_cancelled() {
            return Err(CliError::Cancelled);
        }
        match self.deadline {
            Some((at, secs)) if Instant::now() > at => Err(CliError::TimeLimit { secs }),
            _ => Ok(()),
        }
    }
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
    #[serde(skip)]
    pub per_frame: Vec<FrameRecord>,
}

fn input_options(fps: Option<f64>, timeout: Duration) -> InputOptions {
    InputOptions {
        fps_override: fps,
        timeout,
        ..InputOptions::default()
    }
}

/// Resolves `--lens`/`--fov` to a camera for frames of `input`.
pub fn resolve_lens(
    choice: &LensChoice,
    input: &Path,
    params: &StabilizerParams,
    fps: Option<f64>,
    timeout: Duration,
    quiet: bool,
) -> Result<CameraModel, CliError> {
    match choice {
        LensChoice::File(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| CliError::io(p, e))?;
            amc_core::lens::parse_lens(&text)
                .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))
        }
        LensChoice::Fov(deg) => {
            let src = video::open_input(input, &input_options(fps, timeout))?;
            let info = src.info();
            Ok(CameraModel::pinhole_hfov(info.width, info.height, *deg)
                .map_err(amc_core::AmcError::from)?)
        }
        LensChoice::Auto => {
            let mut src = video::open_input(input, &input_options(fps, timeout))?;
            let mut frames = Vec::new();
            let mut buf = Frame::new(0, 0, PixelFormat::Rgb8);
            while frames.len() < AUTO_FOV_FRAMES {
                match src.next_frame(&mut buf)? {
                    Some(t) => frames.push((buf.clone(), t)),
                    None => break,
                }
            }
            let refs: Vec<_> = frames.iter().map(|(f, t)| (f.as_ref(), *t)).collect();
            let est = selfcal::estimate_hfov(&refs, params.track_width, &params.tracker)?;
            if !est.confident {
                if !quiet {
                    eprintln!(
                        "warning: the footage does not pin down the focal length (translation or little rotation); \
                         assuming a {FALLBACK_FOV_DEG} deg horizontal field of view: pass --fov DEG or --lens FILE for best results"
                    );
                }
                let (w, h) = (frames[0].0.width, frames[0].0.height);
                return Ok(CameraModel::pinhole_hfov(w, h, FALLBACK_FOV_DEG)
                    .map_err(amc_core::AmcError::from)?);
            }
            if !quiet {
                eprintln!(
                    "estimated horizontal field of view: {:.1} deg (from {} frames; pass --fov or --lens to set it)",
                    est.hfov_deg,
                    frames.len()
                );
            }
            Ok(est.camera)
        }
    }
}

fn progress_bar(total: Option<u64>, enabled: bool, label: &str) -> ProgressBar {
    let pb = match total {
        Some(n) => ProgressBar::new(n),
        None => ProgressBar::new_spinner(),
    };
    if !enabled || !std::io::stderr().is_terminal() {
        pb.set_draw_target(ProgressDrawTarget::hidden());
    }
    let style = ProgressStyle::with_template(
        "{prefix:>10} [{bar:30}] {pos}/{len} frames {per_sec} eta {eta}",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .progress_chars("=> ");
    pb.set_style(style);
    pb.set_prefix(label.to_string());
    pb
}

/// A file written beside its final path and moved there only on success.
struct AtomicFile {
    tmp: tempfile::NamedTempFile,
    path: PathBuf,
}

impl AtomicFile {
    fn create(path: &Path) -> Result<Self, CliError> {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if !dir.is_dir() {
            return Err(CliError::Usage(format!(
                "{}: the directory {} does not exist",
                path.display(),
                dir.display()
            )));
        }
        let tmp = tempfile::Builder::new()
            .prefix(".amc-partial-")
            .tempfile_in(dir)
            // tempfile's error names the temporary file; report the real path.
            .map_err(|e| CliError::io(path, std::io::Error::new(e.kind(), e.kind().to_string())))?;
        Ok(Self {
            tmp,
            path: path.to_path_buf(),
        })
    }

    fn persist(self) -> Result<(), CliError> {
        let path = self.path;
        self.tmp
            .persist(&path)
            .map_err(|e| CliError::io(&path, e.error))?;
        Ok(())
    }
}

/// Writes `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), CliError> {
    let mut f = AtomicFile::create(path)?;
    f.tmp.write_all(bytes).map_err(|e| CliError::io(path, e))?;
    f.persist()
}

fn telemetry_row(t: &Telemetry) -> String {
    let speed = |v: [f64; 3]| {
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            .sqrt()
            .to_degrees()
    };
    format!(
        "{},{:.6},{:e},{:e},{:e},{:e},{:e},{:e},{:.4},{:.4},{:.5},{},{},{},{:.6},{:.4},{},{}\n",
        t.frame,
        t.t,
        t.r_est[0],
        t.r_est[1],
        t.r_est[2],
        t.r_view[0],
        t.r_view[1],
        t.r_view[2],
        speed(t.rate_est),
        speed(t.rate_view),
        t.valid_fraction,
        t.frames_averaged,
        t.saccade as u8,
        t.track.iterations,
        t.track.rms_residual,
        t.track.valid_fraction,
        t.track.lost as u8,
        t.track.template_reset as u8,
    )
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

/// Runs the stabilizer over the whole input.
pub fn run(cfg: &RunConfig<'_>) -> Result<RunSummary, CliError> {
    let mut src: Box<dyn FrameSource> =
        video::open_input(cfg.input, &input_options(cfg.fps, cfg.timeout))?;
    let info = src.info().clone();
    let mut stab = Stabilizer::new(&cfg.lens, info.width, info.height, cfg.params.clone())?;
    let (ow, oh) = stab.output_size();
    let mut sink = match cfg.output {
        Some(path) => {
            let mut spec = OutputSpec::new(ow, oh, cfg.fps.unwrap_or(info.fps));
            spec.audio_from = info.has_audio.then(|| cfg.input.to_path_buf());
            spec.timeout = cfg.timeout;
            spec.crf = cfg.crf;
            Some(video::create_output(path, &spec)?)
        }
        None => None,
    };
    let mut telemetry = match cfg.telemetry {
        Some(p) => {
            let f = AtomicFile::create(p)?;
            let mut w = BufWriter::new(f.tmp);
            writeln!(w, "{TELEMETRY_HEADER}").map_err(|e| CliError::io(p, e))?;
            Some((w, f.path))
        }
        None => None,
    };
    let pb = progress_bar(info.frame_count, cfg.progress, cfg.label);
    let mut measure = cfg
        .measure
        .then(|| MetricsWorker::start(cfg.keep_per_frame));
    let mut per_frame = Vec::new();
    let mut motion = MotionAccumulator::default();
    let mut frame = Frame::new(info.width, info.height, PixelFormat::Rgb8);
    let start = Instant::now();
    let mut frames = 0u64;
    let mut emit = |stab: &Stabilizer, tel: Telemetry| -> Result<(), CliError> {
        if let Some(s) = sink.as_mut() {
            s.write_frame(&stab.output())?;
        }
        if let Some(m) = measure.as_mut() {
            m.push(&stab.output(), stab.output_coverage(), &tel);
        }
        motion.push(tel.valid_fraction, Some(&tel));
        if let Some((w, path)) = telemetry.as_mut() {
            w.write_all(telemetry_row(&tel).as_bytes())
                .map_err(|e| CliError::io(&*path, e))?;
        }
        if cfg.keep_per_frame {
            per_frame.push(FrameRecord {
                telemetry: tel,
                metrics: FrameMetrics::default(),
            });
        }
        frames += 1;
        pb.inc(1);
        if let Some(c) = cfg.control {
            c.frames_done.fetch_add(1, Ordering::Relaxed);
            if let Some(shared) = &c.shared_frames {
                shared.fetch_add(1, Ordering::Relaxed);
            }
        }
        Ok(())
    };
    let check = || cfg.control.map_or(Ok(()), RunControl::check);
    while let Some(t) = src.next_frame(&mut frame)? {
        check()?;
        if let Some(tel) = stab.push(frame.as_ref(), t)? {
            emit(&stab, tel)?;
        }
    }
    while let Some(tel) = stab.finish() {
        check()?;
        emit(&stab, tel)?;
    }
    let metrics = match measure {
        Some(worker) => {
            let (clip, frame_metrics) = worker.finish().ok_or_else(|| {
                CliError::Usage("internal error: the metrics worker failed".into())
            })?;
            for (record, m) in per_frame.iter_mut().zip(frame_metrics) {
                record.metrics = m;
            }
            Some(clip)
        }
        None => None,
    };
    pb.finish_and_clear();
    if frames == 0 {
        return Err(CliError::Usage(format!(
            "{}: no frames could be read",
            cfg.input.display()
        )));
    }
    let seconds = start.elapsed().as_secs_f64();
    if let Some(s) = sink {
        s.finish()?;
    }
    if let Some((w, path)) = telemetry {
        let tmp = w
            .into_inner()
            .map_err(|e| CliError::io(&path, e.into_error()))?;
        AtomicFile { tmp, path }.persist()?;
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
        per_frame,
    })
}
