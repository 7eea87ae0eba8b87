//! What the job endpoints answer: a job's state, its view (`GET
//! /jobs/{id}`), its summary in a listing (`GET /jobs`), and what a finished
//! job measured. The same shapes whether jobs live in this process or in
//! the shared job table (`--queue`).

use crate::serve::options::OutputFormat;
use crate::serve::problem::ApiError;
use amc_engine::RunSummary;
use axum::body::Body;
use axum::http::{header, HeaderValue};
use axum::response::Response;
use serde::{Deserialize, Serialize};
use std::time::SystemTime;

/// Which of a finished job's files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobFile {
    /// The stabilized video.
    Output,
    /// The per-frame telemetry CSV.
    Telemetry,
}

impl JobFile {
    /// Its name among the job's files (`output.mp4`, `telemetry.csv`).
    pub fn name(self, format: OutputFormat) -> String {
        match self {
            JobFile::Output => format!("output.{}", format.extension()),
            JobFile::Telemetry => "telemetry.csv".into(),
        }
    }

    /// What the file is, in a message.
    fn noun(self) -> &'static str {
        match self {
            JobFile::Output => "output",
            JobFile::Telemetry => "telemetry",
        }
    }

    /// The answer (409) for this file of job `id`, which is in `state`, not
    /// done: it comes once the job is done, or (cancelled, failed: `error`)
    /// never.
    pub fn not_there(self, id: &str, state: JobState, error: Option<&str>) -> ApiError {
        let noun = self.noun();
        ApiError::Conflict(match state {
            JobState::Queued | JobState::Running | JobState::Done => format!(
                "job {id} is {}: its {noun} exists once it is done",
                state.name()
            ),
            JobState::Cancelled => format!(
                "job {id} was cancelled: it has no {noun}, and never will (submit the clip again)"
            ),
            JobState::Failed => format!(
                "job {id} failed{}: it has no {noun}, and never will",
                error.map(|e| format!(" ({e})")).unwrap_or_default()
            ),
        })
    }

    fn content_type(self, format: OutputFormat) -> &'static str {
        match self {
            JobFile::Output => format.content_type(),
            JobFile::Telemetry => "text/csv",
        }
    }

    /// The file of job `id` as a download: its type, its length when known,
    /// and a name that says what it is (`stabilized-1a2b3c4d.mp4`).
    pub fn response(
        self,
        id: &str,
        format: OutputFormat,
        body: Body,
        len: Option<u64>,
    ) -> Response {
        let short = &id[..id.len().min(8)];
        let download = match self {
            JobFile::Output => format!("stabilized-{short}.{}", format.extension()),
            JobFile::Telemetry => format!("telemetry-{short}.csv"),
        };
        let mut res = Response::new(body);
        let h = res.headers_mut();
        h.insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static(self.content_type(format)),
        );
        if let Some(len) = len {
            h.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
        }
        if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{download}\"")) {
            h.insert(header::CONTENT_DISPOSITION, v);
        }
        res
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    Queued,
    Running,
    Done,
    Failed,
    Cancelled,
}

impl JobState {
    pub const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Done,
        JobState::Failed,
        JobState::Cancelled,
    ];

    pub fn name(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// The state of a name (as [`JobState::name`] gives it).
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    pub fn finished(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled
        )
    }
}

/// A job as `GET /jobs/{id}` shows it: its line in `GET /jobs`, then the
/// rest.
#[derive(Serialize)]
pub struct JobView {
    #[serde(flatten)]
    pub summary: JobSummary,
    pub format: &'static str,
    pub error: Option<String>,
    /// The clip's measurements, when done.
    pub metrics: Option<JobMetrics>,
    /// The camera's and the view's motion, when done.
    pub motion: Option<JobMotion>,
    pub output: Option<String>,
    pub telemetry: Option<String>,
}

/// What a finished job measured: one flat object, each value once.
#[derive(Serialize, Deserialize)]
pub struct JobMetrics {
    /// Output frames.
    pub frames: u64,
    pub input_size: (usize, usize),
    pub output_size: (usize, usize),
    /// Processing time and rate.
    pub seconds: f64,
    pub frames_per_second: f64,
    /// The paper's image metrics of the output; null with `metrics=false`.
    pub rms_normal_flow: Option<f64>,
    pub rms_frame_change: Option<f64>,
    pub sharpness: Option<f64>,
    /// Share of pixels covered by every averaged frame: mean and lowest.
    pub valid_fraction: f64,
    pub min_valid_fraction: f64,
    /// The rolling-shutter readout used, milliseconds (0 = global shutter).
    #[serde(default)]
    pub readout_ms: f64,
    /// Warnings about the run: each fallback the CLI warns about (`fov=auto`
    /// fell back to 70 deg, `readout_ms=auto` to 0), without its `warning: `.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// With a `gyro` form field's log, or `gyro=auto` and a clip with its
    /// own gyro track: its sync and fusion, as the CLI's `--metrics` reports them.
    #[serde(default)]
    pub gyro: Option<serde_json::Value>,
}

/// The motion a finished job's telemetry shows.
#[derive(Serialize, Deserialize)]
pub struct JobMotion {
    /// RMS angular speed of the camera (estimated) and of the view, deg/s.
    pub rms_speed_est_dps: f64,
    pub rms_speed_view_dps: f64,
    /// Saccades made (saccade mode).
    pub saccades: u64,
}

impl JobMetrics {
    pub fn of(s: &RunSummary) -> Self {
        let image = s.metrics.as_ref();
        Self {
            frames: s.frames,
            input_size: s.input_size,
            output_size: s.output_size,
            seconds: s.seconds,
            frames_per_second: s.frames_per_second,
            rms_normal_flow: image.map(|m| m.rms_normal_flow),
            rms_frame_change: image.map(|m| m.rms_change),
            sharpness: image.map(|m| m.sharpness),
            valid_fraction: s.motion.valid_fraction,
            min_valid_fraction: s.motion.min_valid_fraction,
            readout_ms: s.readout_ms,
            warnings: s.warnings.clone(),
            gyro: s
                .gyro
                .as_ref()
                .map(|g| serde_json::to_value(g).expect("a gyro report is plain data")),
        }
    }
}

impl JobMotion {
    pub fn of(s: &RunSummary) -> Self {
        Self {
            rms_speed_est_dps: s.motion.rms_speed_est_dps,
            rms_speed_view_dps: s.motion.rms_speed_view_dps,
            saccades: s.motion.saccades,
        }
    }
}

/// A job as `GET /jobs` lists it.
#[derive(Serialize)]
pub struct JobSummary {
    pub id: String,
    pub state: JobState,
    /// When the job was accepted, RFC 3339 UTC.
    pub created: String,
    pub frames_done: u64,
    pub frames_total: Option<u64>,
    /// `frames_done / frames_total` in [0, 1], when the total is known.
    pub progress: Option<f64>,
}

/// One page of `GET /jobs`, newest first.
#[derive(Serialize)]
pub struct JobPage {
    pub jobs: Vec<JobSummary>,
    /// Pass as `cursor` for the next (older) page; null on the last page.
    pub next_cursor: Option<String>,
}

/// Whether `id` can name a job: 32 lowercase or uppercase hex digits (128
/// random bits). Anything else is an unknown job, so an id never names a
/// path or reaches a query.
pub fn valid_id(id: &str) -> bool {
    id.len() == 32 && id.bytes().all(|b| b.is_ascii_hexdigit())
}

/// `frames_done / frames_total` in [0, 1] (1 once done), when the total is known.
pub fn progress(state: JobState, frames_done: u64, frames_total: Option<u64>) -> Option<f64> {
    match (state == JobState::Done, frames_total) {
        (true, _) => Some(1.0),
        (false, Some(n)) if n > 0 => Some((frames_done as f64 / n as f64).min(1.0)),
        _ => None,
    }
}

/// Seconds since the Unix epoch as RFC 3339 UTC (`2026-11-29T21:04:05Z`).
pub fn rfc3339(t: SystemTime) -> String {
    let secs = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}
