//! The CPU work of a request or job: check the upload, then decode ->
//! stabilize -> encode with the same pipeline as `amc stabilize`. Runs on a
//! blocking thread; a [`RunControl`] cancels it (its ffmpeg children are
//! killed and its partial files removed when the pipeline unwinds).

use super::config::Limits;
use super::jobs::JobFile;
use super::options::JobOptions;
use super::problem::{count, ApiError};
use amc_core::{AmcError, LensSpec};
use amc_engine::{
    self as engine, LensNote, LogReadout, ResolvedLens, RunConfig, RunControl, RunError,
    RunSummary, FALLBACK_FOV_DEG,
};
use amc_video::{self as video, Inspection, VideoError};
use std::path::{Path, PathBuf};

/// What to process.
pub struct WorkSpec {
    pub input: PathBuf,
    pub output: PathBuf,
    pub telemetry: Option<PathBuf>,
    pub lens_text: Option<String>,
    /// The client's gyro log (the `gyro` form field), used instead of the
    /// clip's own track; checked when the upload was taken.
    pub gyro_log: Option<PathBuf>,
    pub options: JobOptions,
    /// Frame size found by the inspection (a `fov` lens needs no second probe).
    pub input_size: (usize, usize),
}

impl WorkSpec {
    /// The work for an accepted upload: output (and telemetry, for jobs) in its scratch folder.
    pub fn for_upload(
        scratch: &super::storage::Scratch,
        upload: super::upload::Upload,
        options: JobOptions,
        inspection: &Inspection,
        with_telemetry: bool,
    ) -> Self {
        Self {
            input: upload.video,
            output: scratch.file(&JobFile::Output.name(options.format)),
            telemetry: with_telemetry
                .then(|| scratch.file(&JobFile::Telemetry.name(options.format))),
            lens_text: upload.lens,
            gyro_log: upload.gyro,
            options,
            input_size: (inspection.info.width, inspection.info.height),
        }
    }
}

/// A control for one run: the per-job time limit, counted in the service's frames.
pub fn control(state: &super::state::AppState) -> std::sync::Arc<RunControl> {
    std::sync::Arc::new(
        RunControl::new(Some(state.limits.job_time_limit))
            .counting_into(state.metrics.frames_processed.clone()),
    )
}

/// Probes an upload and checks it against the limits: 415 if it is not a
/// video, 422 if it is too big or too long.
pub fn inspect(path: &Path, limits: &Limits) -> Result<Inspection, ApiError> {
    let found = video::inspect(path, limits.ffmpeg_timeout).map_err(|e| video_error(e, path))?;
    if found.is_still_image() {
        return Err(ApiError::Unsupported(format!(
            "the upload is a still image ({}), not a video",
            found.format_name
        )));
    }
    let info = &found.info;
    if info.width > limits.max_width || info.height > limits.max_height {
        return Err(ApiError::Unprocessable(format!(
            "the video is {}x{}; the limit is {}x{} (set by --max-width/--max-height)",
            info.width, info.height, limits.max_width, limits.max_height
        )));
    }
    let duration = info
        .duration_s
        .or_else(|| info.frame_count.map(|n| n as f64 / info.fps));
    if let Some(d) = duration.filter(|&d| d > limits.max_duration_s) {
        return Err(ApiError::Unprocessable(format!(
            "the video is {d:.1} s long; the limit is {:.0} s (set by --max-duration)",
            limits.max_duration_s
        )));
    }
    if info.frame_count == Some(1) {
        return Err(ApiError::Unsupported(
            "the upload has a single frame; it is a picture, not a video".into(),
        ));
    }
    Ok(found)
}

/// What a worker thread gives back: the spec, and the run's outcome.
pub type Finished = (WorkSpec, Result<RunSummary, ApiError>);

/// Runs [`stabilize`] on a blocking thread the service tracks (awaited on
/// shutdown). A panic in it comes back as the `JoinError` (the panic hook
/// has logged it with its backtrace); the service itself carries on.
pub async fn stabilize_on_worker(
    state: &super::state::AppState,
    spec: WorkSpec,
    control: std::sync::Arc<RunControl>,
) -> Result<Finished, tokio::task::JoinError> {
    let limits = state.limits.clone();
    let panic_for_test = state.panics_for_test();
    state
        .tasks
        .spawn_blocking(move || {
            if panic_for_test {
                panic!("test-only trigger: a worker panicked");
            }
            let result = stabilize(&spec, &limits, &control);
            (spec, result)
        })
        .await
}

/// Stabilizes `spec.input` into `spec.output`.
pub fn stabilize(
    spec: &WorkSpec,
    limits: &Limits,
    control: &RunControl,
) -> Result<RunSummary, ApiError> {
    let mut params = spec.options.stabilizer.params.clone();
    let opts = engine::input_options(None, limits.ffmpeg_timeout);
    let lens = match &spec.lens_text {
        Some(text) => {
            let file = amc_core::lens::parse_lens_file(text)
                .map_err(|e| ApiError::BadOption(format!("invalid lens file: {e}")))?;
            ResolvedLens {
                camera: file.camera,
                note: LensNote::Given,
                readout_ms: file.readout_ms,
            }
        }
        None => {
            let lens = match &spec.options.stabilizer.lens {
                // A client never names a server path.
                LensSpec::File(_) => &LensSpec::Auto,
                other => other,
            };
            engine::resolve_lens(lens, &spec.input, &params, &opts, Some(spec.input_size))
                .map_err(|e| run_error(e, &spec.input))?
        }
    };
    let gyro = match &spec.gyro_log {
        // The client's log: read again here, where the run is (a worker
        // has only the file); intake refused one that cannot be read.
        Some(path) => Some(super::gyro_log::read(path)?),
        // `gyro=auto`: the clip's own track, when it has one it can read.
        None => spec
            .options
            .gyro
            .then(|| engine::gyro::clip_gyro(&spec.input))
            .flatten(),
    };
    // A readout the log records answers `auto`; `auto` with one that
    // records none is measured against it in the run.
    let asked = &spec.options.stabilizer.readout;
    let log_readout = LogReadout::choose(asked, gyro.as_ref());
    let mut readout =
        engine::resolve_readout(&log_readout.spec(asked), &lens, &spec.input, &params, &opts)
            .map_err(|e| run_error(e, &spec.input))?;
    let recorded = log_readout.apply(asked, &mut readout);
    let mut warnings = Vec::new();
    let input = spec.input.display();
    if let Some(line) = recorded {
        tracing::info!(%input, "{line}");
    }
    match &lens.note {
        LensNote::FellBack => {
            let w = lens_fallback_warning();
            tracing::warn!(%input, "{w}");
            warnings.push(w);
        }
        LensNote::Estimated { hfov_deg, frames } => tracing::info!(
            %input,
            "estimated horizontal field of view: {hfov_deg:.1} deg (from {frames} frames)"
        ),
        LensNote::Given => {}
    }
    match (readout.note.is_warning(), readout.message()) {
        (true, Some(line)) => {
            let w = without_warning_word(&line);
            tracing::warn!(%input, "{w}");
            warnings.push(w);
        }
        (false, Some(line)) => tracing::info!(%input, "{line}"),
        (_, None) => {}
    }
    params.shutter.readout_ms = readout.readout_ms;
    let refit_lens = matches!(lens.note, LensNote::FellBack);
    let lens = lens.camera;
    engine::run(&RunConfig {
        input: &spec.input,
        output: Some(&spec.output),
        params,
        lens,
        telemetry: spec.telemetry.as_deref(),
        also_writes: &[],
        fps: None,
        timeout: limits.ffmpeg_timeout,
        crf: None,
        preset: None,
        keep_per_frame: false,
        measure: spec.options.measure,
        control: Some(control),
        progress: None,
        gyro: gyro.as_ref(),
        measure_readout: log_readout.measure(asked, &readout),
        refit_lens,
        threads: limits.threads,
    })
    .map_err(|e| run_error(e, &spec.input))
    .and_then(|mut summary| {
        if let Some(hfov) = summary.refit_hfov_deg {
            // The gyro's readout let `fov=auto` find the lens after all.
            let fallback = lens_fallback_warning();
            warnings.retain(|w| *w != fallback);
            tracing::info!(%input, "{}", engine::refit_line(hfov));
        }
        summary.warnings.extend(warnings);
        if summary.looks_truncated() {
            return Err(ApiError::Unsupported(format!(
                "the video is truncated or damaged: only {} of the {} it declares could be decoded",
                summary.frames,
                count(summary.frames_declared.unwrap_or(0), "frame", "frames")
            )));
        }
        Ok(summary)
    })
}

/// What a client is told when `fov=auto` could not pin the focal length
/// down: the CLI's warning, in the service's terms.
fn lens_fallback_warning() -> String {
    format!(
        "the footage does not pin down the focal length (translation or little rotation); \
         assuming a {FALLBACK_FOV_DEG} deg horizontal field of view: pass fov=DEG (or send a \
         lens file) for best results"
    )
}

/// A warning as the service carries it: in a list of warnings (the job's
/// `warnings`, `X-Amc-Warning`, a WARN log line), without the CLI's
/// leading `warning: `.
fn without_warning_word(line: &str) -> String {
    line.strip_prefix("warning: ").unwrap_or(line).to_string()
}

/// How a failed run is answered, by variant: problems with the upload are
/// the client's (415/422), anything else is the server's.
pub fn run_error(e: RunError, input: &Path) -> ApiError {
    match e {
        RunError::Video(v) => video_error(v, input),
        RunError::Core(c) => core_error(c),
        RunError::NoFrames { .. } => {
            ApiError::Unsupported("the upload has no frames that can be decoded".into())
        }
        RunError::LensRead { .. } | RunError::LensParse { .. } => ApiError::BadOption(format!(
            "invalid lens file: {}",
            strip_path(&e.to_string(), input)
        )),
        RunError::Cancelled => ApiError::Conflict("the job was cancelled".into()),
        RunError::TimeLimit { secs } => ApiError::Unprocessable(format!(
            "processing took longer than the limit of {secs:.0} s (set by --job-time-limit)"
        )),
        // Out of threads is the machine being busy: try again later.
        RunError::Threads(_) => ApiError::Saturated(e.to_string()),
        RunError::SamePath { .. }
        | RunError::Write { .. }
        | RunError::MetricsWorker
        | RunError::ThreadFailed { .. } => ApiError::Internal(e.to_string()),
    }
}

fn core_error(e: AmcError) -> ApiError {
    match e {
        AmcError::Lens(_) | AmcError::Camera(_) | AmcError::LensAspectMismatch { .. } => {
            ApiError::BadOption(format!("the lens does not fit this video: {e}"))
        }
        AmcError::InvalidParameter { .. } => ApiError::BadOption(e.to_string()),
        _ => ApiError::Unprocessable(format!("the video cannot be stabilized: {e}")),
    }
}

fn video_error(e: VideoError, input: &Path) -> ApiError {
    let msg = strip_path(&e.to_string(), input);
    match &e {
        VideoError::NotAVideo { .. }
        | VideoError::StillImage { .. }
        | VideoError::EmptyFile { .. }
        | VideoError::Y4m { .. }
        | VideoError::Image { .. } => ApiError::Unsupported(msg),
        VideoError::BadFrame { .. } | VideoError::SizeMismatch { .. } => {
            ApiError::Unprocessable(msg)
        }
        // A decoder failing on the upload is the upload's fault; the encoder
        // failing is ours.
        VideoError::Ffmpeg { path, .. } | VideoError::Timeout { path, .. } if path == input => {
            ApiError::Unsupported(format!("the video cannot be decoded: {msg}"))
        }
        VideoError::ToolMissing { .. } => ApiError::Internal(msg),
        _ => ApiError::Internal(msg),
    }
}

/// Messages name the upload's scratch path, which means nothing to a client.
fn strip_path(msg: &str, input: &Path) -> String {
    let p = input.display().to_string();
    msg.replace(&format!("{p}: "), "").replace(&p, "the upload")
}
