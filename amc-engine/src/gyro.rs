//! Gyro logs in from files: a camera's own IMU track (GoPro GPMF, Sony, DJI,
//! Insta360), a flight controller's blackbox, Gyroflow's `.gcsv`, phone-app
//! logs, all read by the `telemetry-parser` crate through [`amc_gyrolog`]
//! (shared with the page, which reads a clip's bytes); a plain CSV of a time
//! and three rates (cc9's `gyro.txt`) by the `csv` crate. Then synchronized
//! with the run's own motion ([`sync_log`]) and reported.

use amc_core::gyro::GyroSamples;
pub use amc_gyrolog::{sync_log, GyroLog, GyroLogError, GyroReport};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

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
/// format it knows (the reason), a panic of the parser included.
fn read_with_telemetry_parser(path: &Path) -> Result<Option<GyroLog>, String> {
    let mut file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let size = file.metadata().map_err(|e| e.to_string())?.len() as usize;
    amc_gyrolog::read_gyro_stream(&mut file, size, path).map_err(|e| e.to_string())
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
