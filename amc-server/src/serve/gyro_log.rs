//! A gyro log a client sends as the `gyro` form field: read with the CLI's
//! own reader ([`amc_engine::gyro::read_gyro_log`]: any format
//! telemetry-parser knows, or a plain CSV), once when the upload is taken
//! (so a log that cannot be used is refused at once, 422, before a job is
//! queued) and again by whoever runs the job (this replica, or an
//! `amc worker` that downloaded it beside the clip).

use super::problem::ApiError;
use amc_engine::gyro::{self, GyroLog, GyroLogError};
use std::path::Path;

/// Reads the client's log at `path` (a file in a scratch folder).
pub fn read(path: &Path) -> Result<GyroLog, ApiError> {
    gyro::read_gyro_log(path).map_err(|e| refusal(e, path))
}

/// Reads the log on a blocking thread: telemetry-parser may take a second
/// on a large one, which must not hold up the runtime.
pub async fn check(path: &Path) -> Result<(), ApiError> {
    let path = path.to_path_buf();
    tokio::task::spawn_blocking(move || read(&path).map(|_| ()))
        .await
        .map_err(|e| ApiError::Internal(format!("reading the gyro log failed: {e}")))?
}

/// How a log that cannot be used is answered: what the client sent is at
/// fault (422, as an undecodable video: the request itself is well-formed),
/// except a scratch file this service cannot read back (500).
/// The scratch path means nothing to a client: the message names the field.
fn refusal(e: GyroLogError, path: &Path) -> ApiError {
    let msg = e
        .to_string()
        .replace(&path.display().to_string(), "the `gyro` form field's file");
    match e {
        GyroLogError::Read { .. } => ApiError::Internal(msg),
        GyroLogError::Unknown { .. } | GyroLogError::NoGyro { .. } | GyroLogError::Sync { .. } => {
            ApiError::UnusableGyro(format!("invalid gyro log: {msg}"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_that_is_no_log_is_a_bad_option_naming_the_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("gyro-log.gcsv");
        std::fs::write(&path, "not a log\n1,2\n").unwrap();
        let e = read(&path).unwrap_err();
        assert!(matches!(e, ApiError::UnusableGyro(_)), "{e:?}");
        let msg = e.to_string();
        assert!(msg.contains("the `gyro` form field's file"), "{msg}");
        assert!(msg.contains("telemetry-parser"), "{msg}");
        assert!(!msg.contains(&dir.path().display().to_string()), "{msg}");
    }

    #[test]
    fn a_log_read_from_a_gcsv() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("gyro-log.gcsv");
        let mut text = String::from(
            "GYROFLOW IMU LOG\nversion,1.3\nid,amc_test\norientation,xyz\ntscale,0.001\ngscale,1.0\nt,gx,gy,gz\n",
        );
        for i in 0..200 {
            text.push_str(&format!("{i},0.1,0.2,0.3\n"));
        }
        std::fs::write(&path, text).unwrap();
        let log = read(&path).unwrap();
        assert!(log.samples.t.len() > 100, "{}", log.samples.t.len());
    }
}
