//! Comparing estimated orientations with ground truth (`gt.csv` from `amc synth`).
//!
//! Both are `R_{0,j}` (camera j -> camera 0, `R_{0,0} = I`) as rotation vectors.
//! * per-frame error: the angle between the true and estimated frame-to-frame
//!   rotations, `|log((R_{j-1}^T R_j)^T (R^_{j-1}^T R^_j))|`;
//! * orientation error: `|log(R_{0,j}^T R^_{0,j})|`, which includes drift.

use amc_core::so3::{self, Rot, Tangent};
use serde::Serialize;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A ground-truth file that cannot be read.
#[derive(Debug, Error)]
pub enum GtError {
    /// The file cannot be read.
    #[error("{}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a `frame,t,rx,ry,rz` CSV.
    #[error("{}: {detail}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the line.
        detail: String,
    },
}

/// Reads `frame,t,rx,ry,rz` rows (header required; extra columns ignored).
pub fn read_orientations(path: &Path) -> Result<Vec<Rot>, GtError> {
    let text = std::fs::read_to_string(path).map_err(|source| GtError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let mut lines = text.lines();
    let header = lines.next().unwrap_or("");
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let idx = |name: &str| cols.iter().position(|c| *c == name);
    let (Some(ix), Some(iy), Some(iz)) = (idx("rx"), idx("ry"), idx("rz")) else {
        return Err(GtError::Format {
            path: path.to_path_buf(),
            detail: format!("expected a CSV header with columns rx,ry,rz (got '{header}')"),
        });
    };
    let mut out = Vec::new();
    for (n, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        let get = |i: usize| -> Result<f64, GtError> {
            f.get(i)
                .and_then(|s| s.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| GtError::Format {
                    path: path.to_path_buf(),
                    detail: format!("line {}: bad number in column {}", n + 2, i + 1),
                })
        };
        out.push(so3::exp(&Tangent::new(get(ix)?, get(iy)?, get(iz)?)));
    }
    Ok(out)
}

/// The `frame,t,rx,ry,rz` text [`read_orientations`] reads: one row per
/// orientation `R_{0,j}` (as its rotation vector) at time `times[j]`.
pub fn orientations_csv(times: &[f64], rots: &[Rot]) -> String {
    let mut s = String::from("frame,t,rx,ry,rz\n");
    for (j, (t, r)) in times.iter().zip(rots).enumerate() {
        let w = so3::log(r);
        s.push_str(&format!("{j},{t},{},{},{}\n", w.x, w.y, w.z));
    }
    s
}

/// Accuracy of an estimate against ground truth, in degrees.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct GtReport {
    pub frames: usize,
    pub median_frame_error_deg: f64,
    pub mean_frame_error_deg: f64,
    pub p95_frame_error_deg: f64,
    pub max_frame_error_deg: f64,
    pub final_orientation_error_deg: f64,
    pub max_orientation_error_deg: f64,
}

/// Compares estimated `est` with true `gt` orientations (same frames, same order).
pub fn compare(gt: &[Rot], est: &[Rot]) -> GtReport {
    let n = gt.len().min(est.len());
    let mut frame_err = Vec::new();
    let mut max_orient: f64 = 0.0;
    let mut final_orient = 0.0;
    for j in 0..n {
        let e = so3::angle_between(&gt[j], &est[j]).to_degrees();
        max_orient = max_orient.max(e);
        final_orient = e;
        if j > 0 {
            let dg = gt[j - 1].transpose() * gt[j];
            let de = est[j - 1].transpose() * est[j];
            frame_err.push(so3::angle_between(&dg, &de).to_degrees());
        }
    }
    frame_err.sort_by(f64::total_cmp);
    let pick = |q: f64| {
        if frame_err.is_empty() {
            0.0
        } else {
            frame_err[((frame_err.len() - 1) as f64 * q).round() as usize]
        }
    };
    GtReport {
        frames: n,
        median_frame_error_deg: pick(0.5),
        mean_frame_error_deg: frame_err.iter().sum::<f64>() / frame_err.len().max(1) as f64,
        p95_frame_error_deg: pick(0.95),
        max_frame_error_deg: pick(1.0),
        final_orientation_error_deg: final_orient,
        max_orientation_error_deg: max_orient,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orientations_are_read_back_as_written() {
        let rots: Vec<Rot> = (0..5)
            .map(|j| so3::exp(&Tangent::new(0.1 * j as f64, -0.02, 0.3 - 0.05 * j as f64)))
            .collect();
        let times: Vec<f64> = (0..5).map(|j| j as f64 / 60.0).collect();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("o.csv");
        std::fs::write(&path, orientations_csv(&times, &rots)).unwrap();
        let back = read_orientations(&path).unwrap();
        assert_eq!(back.len(), rots.len());
        for (a, b) in rots.iter().zip(&back) {
            assert!(so3::angle_between(a, b) < 1e-12);
        }
    }
}
