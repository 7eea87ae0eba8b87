//! Gyro logs in: a camera's own IMU track (GoPro GPMF, Sony, DJI, Insta360),
//! a flight controller's blackbox, Gyroflow's `.gcsv`, phone-app logs, all
//! read by the `telemetry-parser` crate; a plain CSV of a time and three
//! rates (cc9's `gyro.txt`) by the `csv` crate. Then synchronized with the
//! run's own motion ([`amc_core::gyro::sync`]) and reported.

use amc_core::gyro::{self, GyroSamples, GyroSync, VisionStep};
use nalgebra::Vector3;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use thiserror::Error;

/// Which gyro log a run uses (`--gyro`).
#[derive(Clone, Debug, Default, PartialEq)]
pub enum GyroChoice {
    /// The clip's own log when it has one ([`clip_gyro`]), else none.
    #[default]
    Auto,
    /// None.
    Off,
    /// This log.
    File(PathBuf),
}

impl std::str::FromStr for GyroChoice {
    type Err = std::convert::Infallible;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s.trim() {
            v if v.eq_ignore_ascii_case("auto") => GyroChoice::Auto,
            v if v.eq_ignore_ascii_case("off") => GyroChoice::Off,
            v => GyroChoice::File(PathBuf::from(v)),
        })
    }
}

/// A log read in, with where it came from.
#[derive(Clone, Debug)]
pub struct GyroLog {
    /// What read it: `"GoPro (HERO5 Black)"`, `"gyro.txt (CSV)"`.
    pub source: String,
    /// How its times count: `"the log's first sample"` (telemetry-parser
    /// rebases them) or `"the log's own timestamps"` (a plain CSV).
    pub time_base: &'static str,
    pub samples: GyroSamples,
    /// The log's times are the video's (a camera's per-frame record, such
    /// as GoPro's image orientation): the offset is 0, not searched.
    pub video_clock: bool,
    /// The sensor's readout the clip records (GoPro's SROT, Sony, DJI,
    /// Insta360, a `.gcsv`'s `frame_readout_time`), milliseconds.
    pub readout_ms: Option<f64>,
}

/// Why a gyro log cannot be used.
#[derive(Debug, Error)]
pub enum GyroLogError {
    #[error("cannot read the gyro log {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} is no gyro log telemetry-parser knows (GoPro, Sony, DJI, Insta360, Betaflight, ArduPilot, Gyroflow .gcsv, phone apps) nor a CSV of a time and three rates: {why}")]
    Unknown { path: PathBuf, why: String },
    #[error("{path} holds no gyroscope samples")]
    NoGyro { path: PathBuf },
    #[error("cannot synchronize the gyro log {source_name} with the video: {error}")]
    Sync {
        source_name: String,
        error: gyro::GyroError,
    },
}

/// The clip's own gyro log, if it has one: for a video, its embedded IMU
/// track (GoPro, Sony, DJI, Insta360), else a Gyroflow log beside it with the
/// same name (`clip.gcsv` for `clip.mp4`, as Gyroflow looks for it); for a
/// folder of frames, its `gyro.gcsv` (as `amc synth` writes it). `None`:
/// none, or none that can be read.
pub fn clip_gyro(video: &Path) -> Option<GyroLog> {
    if video.is_dir() {
        let log = video.join(FOLDER_LOG);
        return log.is_file().then(|| read_gyro_log(&log).ok()).flatten();
    }
    if let Some(log) = read_with_telemetry_parser(video).ok().flatten() {
        return Some(log);
    }
    let sidecar = video.with_extension("gcsv");
    (sidecar != video && sidecar.is_file())
        .then(|| read_gyro_log(&sidecar).ok())
        .flatten()
}

/// A folder of frames' gyro log.
pub const FOLDER_LOG: &str = "gyro.gcsv";

/// Reads the log at `path`: any format telemetry-parser knows, else a plain
/// CSV of a time column (the one that increases) and three rates in rad/s.
pub fn read_gyro_log(path: &Path) -> Result<GyroLog, GyroLogError> {
    match read_with_telemetry_parser(path) {
        Ok(Some(log)) => Ok(log),
        Ok(None) => Err(GyroLogError::NoGyro {
            path: path.to_path_buf(),
        }),
        Err(why) => read_plain_csv(path).map_err(|csv| match csv {
            GyroLogError::Unknown { path, why: csv_why } => GyroLogError::Unknown {
                path,
                why: format!("{why}; as a CSV: {csv_why}"),
            },
            e => e,
        }),
    }
}

/// `Ok(None)`: a known format without gyroscope samples; `Err`: not a
/// format it knows (the reason). A parser that panics on a damaged file is
/// an error like any other, not the end of the run.
fn read_with_telemetry_parser(path: &Path) -> Result<Option<GyroLog>, String> {
    std::panic::catch_unwind(|| parse_with_telemetry_parser(path))
        .unwrap_or_else(|_| Err("the telemetry parser failed on this file".into()))
}

fn parse_with_telemetry_parser(path: &Path) -> Result<Option<GyroLog>, String> {
    let mut file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let size = file.metadata().map_err(|e| e.to_string())?.len() as usize;
    let input = telemetry_parser::Input::from_stream(
        &mut file,
        size,
        path,
        |_| {},
        Arc::new(AtomicBool::new(false)),
    )
    .map_err(|e| e.to_string())?;
    let camera = match input.camera_model() {
        Some(model) => format!("{} ({model})", input.camera_type()),
        None => input.camera_type(),
    };
    let readout_ms = input
        .frame_readout_time()
        .filter(|ms| ms.is_finite() && *ms > 0.0 && *ms <= amc_core::shutter::MAX_READOUT_MS);
    // Stabilized in the camera (GoPro's IORI): the picture did not move as
    // the body did; its own orientation is the motion to sync and fuse.
    if let Some(samples) = picture_motion(&input)? {
        return Ok(Some(GyroLog {
            source: format!(
                "{camera}, the picture's orientation (stabilized in the camera: CORI x IORI)"
            ),
            time_base: "the video's frames (the camera's per-frame record)",
            samples,
            video_clock: true,
            readout_ms,
        }));
    }
    let imu = telemetry_parser::util::normalized_imu(&input, None).map_err(|e| e.to_string())?;
    let mut samples = GyroSamples::default();
    for s in &imu {
        let Some(g) = s.gyro else { continue };
        let t = s.timestamp_ms * 1e-3;
        // Repeated or out-of-order times (a log's seams) are dropped.
        if samples.t.last().is_some_and(|&l| t <= l) || !t.is_finite() {
            continue;
        }
        samples.t.push(t);
        // telemetry-parser gives deg/s.
        samples
            .w
            .push(Vector3::new(g[0], g[1], g[2]).map(f64::to_radians));
    }
    if samples.t.is_empty() {
        return Ok(None);
    }
    Ok(Some(GyroLog {
        source: camera,
        time_base: "the log's first sample",
        samples,
        video_clock: false,
        readout_ms,
    }))
}

/// The motion of the picture of a clip stabilized in the camera, where
/// the camera records it (GoPro's IORI, the image's orientation in the body,
/// beside CORI, the body's; telemetry-parser multiplies them per frame): the
/// body rate between consecutive orientations, stamped at their middle.
/// `None`: no in-camera stabilization recorded; an error where it is
/// recorded but the picture's orientation cannot be read (the body's gyro
/// would put back the shake the camera removed).
fn picture_motion(input: &telemetry_parser::Input) -> Result<Option<GyroSamples>, String> {
    use telemetry_parser::tags_impl::{GetWithType, GroupId, TagId, TimeQuaternion};
    let Some(samples) = input.samples.as_ref() else {
        return Ok(None);
    };
    let stabilized = samples.iter().any(|s| {
        s.tag_map
            .as_ref()
            .is_some_and(|m| m.contains_key(&GroupId::ImageOrientation))
    });
    if !stabilized {
        return Ok(None);
    }
    let mut track: Vec<(f64, nalgebra::UnitQuaternion<f64>)> = Vec::new();
    for s in samples {
        let Some(map) = s.tag_map.as_ref().and_then(|m| m.get(&GroupId::Quaternion)) else {
            continue;
        };
        let Some(arr) = map.get_t(TagId::Data) as Option<&Vec<TimeQuaternion<f64>>> else {
            continue;
        };
        for q in arr {
            let t = q.t * 1e-3;
            let v = nalgebra::Quaternion::new(q.v.w, q.v.x, q.v.y, q.v.z);
            if t.is_finite() && v.norm() > 0.5 && track.last().is_none_or(|l| t > l.0) {
                track.push((t, nalgebra::UnitQuaternion::from_quaternion(v)));
            }
        }
    }
    if track.len() < 2 {
        return Err(
            "the clip was stabilized in the camera (IORI) but the picture's orientation \
                    cannot be read from it: its gyro is the body's motion, not the picture's"
                .into(),
        );
    }
    let mut out = GyroSamples::default();
    for pair in track.windows(2) {
        let ((t0, q0), (t1, q1)) = (pair[0], pair[1]);
        out.t.push(0.5 * (t0 + t1));
        out.w.push((q0.inverse() * q1).scaled_axis() / (t1 - t0));
    }
    Ok(Some(out))
}

/// A CSV of four numeric columns (an optional header line): the one that
/// increases throughout is the time in seconds, the others the x, y and z
/// rates in rad/s, in their order.
fn read_plain_csv(path: &Path) -> Result<GyroLog, GyroLogError> {
    let unknown = |why: String| GyroLogError::Unknown {
        path: path.to_path_buf(),
        why,
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(false)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| unknown(e.to_string()))?;
    let mut rows: Vec<[f64; 4]> = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let record = record.map_err(|e| unknown(e.to_string()))?;
        let values: Option<Vec<f64>> = record.iter().map(|v| v.parse().ok()).collect();
        match values {
            Some(v) if v.len() == 4 => rows.push([v[0], v[1], v[2], v[3]]),
            // A header line.
            None if i == 0 => continue,
            _ => return Err(unknown(format!("line {} is not four numbers", i + 1))),
        }
    }
    let time = (0..4)
        .find(|&c| rows.len() > 1 && rows.windows(2).all(|w| w[1][c] > w[0][c]))
        .ok_or_else(|| unknown("no column increases throughout (a time)".into()))?;
    let rates: Vec<usize> = (0..4).filter(|&c| c != time).collect();
    let samples = GyroSamples {
        t: rows.iter().map(|r| r[time]).collect(),
        w: rows
            .iter()
            .map(|r| Vector3::new(r[rates[0]], r[rates[1]], r[rates[2]]))
            .collect(),
    };
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    Ok(GyroLog {
        source: format!("{name} (CSV)"),
        time_base: "the log's own timestamps",
        samples,
        video_clock: false,
        readout_ms: None,
    })
}

/// The sync as `--metrics` reports it (`"gyro": {...}`).
#[derive(Clone, Debug, Serialize)]
pub struct GyroReport {
    pub source: String,
    pub samples: usize,
    pub rate_hz: f64,
    /// Video time = log time + `offset_s`, at the clip's first frame.
    pub offset_s: f64,
    /// What log time counts from.
    pub log_time: &'static str,
    pub drift_ppm: f64,
    /// Radians: the rotation taking IMU vectors into the camera frame.
    pub mount_rotvec: [f64; 3],
    /// Rad/s, IMU axes.
    pub bias_rad_s: [f64; 3],
    pub glitches: usize,
    /// RMS disagreement with the video, frame intervals other than glitches, rad/s.
    pub residual_rad_s: f64,
    /// Correlation of the log's and the video's angular speeds at the offset.
    pub correlation: f64,
    /// Frames whose pose and readout path came from the gyro, held to the
    /// picture (0 when the log was only synchronized, not fused).
    pub fused_frames: usize,
    /// Frame intervals where the gyro glitched and the picture bridged it.
    pub glitch_intervals_bridged: usize,
    /// Frames where tracking was lost, or disagreed with a sound log, that
    /// the gyro bridged.
    pub frames_bridged: usize,
}

impl GyroReport {
    /// One line for the terminal.
    pub fn line(&self) -> String {
        let m = self.mount_rotvec;
        let angle = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
            .sqrt()
            .to_degrees();
        format!(
            "gyro: {} ({} samples, {:.0} Hz): offset {:+.4} s (video = log + offset, log time from {}), drift {:+.0} ppm, mounting {angle:.1} deg (rotvec {:.4} {:.4} {:.4} rad), bias {:.4} {:.4} {:.4} rad/s, {} glitches, residual {:.3} rad/s; fused {} frames ({} glitch intervals bridged by the picture, {} frames by the gyro)",
            self.source,
            self.samples,
            self.rate_hz,
            self.offset_s,
            self.log_time,
            self.drift_ppm,
            m[0],
            m[1],
            m[2],
            self.bias_rad_s[0],
            self.bias_rad_s[1],
            self.bias_rad_s[2],
            self.glitches,
            self.residual_rad_s,
            self.fused_frames,
            self.glitch_intervals_bridged,
            self.frames_bridged,
        )
    }
}

/// Synchronizes `log` with a run's frames (their times and estimated
/// orientations `R_{0,j}`).
pub fn sync_log(
    log: &GyroLog,
    t: &[f64],
    rots: &[amc_core::so3::Rot],
) -> Result<(GyroSync, GyroReport), GyroLogError> {
    let steps = VisionStep::from_orientations(t, rots);
    let synced = if log.video_clock {
        gyro::sync_at(&log.samples, &steps, 0.0)
    } else {
        gyro::sync(&log.samples, &steps)
    };
    let s: GyroSync = synced.map_err(|error| GyroLogError::Sync {
        source_name: log.source.clone(),
        error,
    })?;
    let m = s.mount_rotvec();
    let report = GyroReport {
        source: log.source.clone(),
        samples: log.samples.t.len(),
        rate_hz: log.samples.rate_hz(),
        offset_s: s.offset_s,
        log_time: log.time_base,
        drift_ppm: s.drift_ppm,
        mount_rotvec: [m.x, m.y, m.z],
        bias_rad_s: [s.bias.x, s.bias.y, s.bias.z],
        glitches: s.glitches,
        residual_rad_s: s.residual_rad_s,
        correlation: s.correlation,
        fused_frames: 0,
        glitch_intervals_bridged: 0,
        frames_bridged: 0,
    };
    Ok((s, report))
}
