//! What a sync matches: a gyro log's samples, and the video's own motion
//! between consecutive frames.

use crate::so3::{self, Rot, Tangent};
use nalgebra::Vector3;

/// A gyro log: sample times (seconds, the log's clock) and angular
/// velocities (rad/s, the IMU's axes), times increasing.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GyroSamples {
    /// Sample times, seconds (the log's clock).
    pub t: Vec<f64>,
    /// Angular velocities, rad/s, IMU axes.
    pub w: Vec<Vector3<f64>>,
}

impl GyroSamples {
    /// Mean sample rate, Hz (0 with fewer than two samples).
    pub fn rate_hz(&self) -> f64 {
        match (self.t.first(), self.t.last()) {
            (Some(a), Some(b)) if b > a => (self.t.len() - 1) as f64 / (b - a),
            _ => 0.0,
        }
    }
}

/// The video's own motion: the rotation from frame `j - 1` to frame `j`
/// (`log(R_{0,j-1}^T R_{0,j})`, camera axes) over `[t0, t1]`, the frames'
/// (mid-readout) times.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VisionStep {
    /// Time of frame `j - 1`, seconds (video).
    pub t0: f64,
    /// Time of frame `j`, seconds.
    pub t1: f64,
    /// The rotation between them, camera axes, radians.
    pub rotation: Tangent,
}

impl VisionStep {
    /// The steps between consecutive frames of orientations `r` at times `t`.
    pub fn from_orientations(t: &[f64], r: &[Rot]) -> Vec<VisionStep> {
        t.windows(2)
            .zip(r.windows(2))
            .filter(|(t, _)| t[1] > t[0])
            .map(|(t, r)| VisionStep {
                t0: t[0],
                t1: t[1],
                rotation: so3::log(&(r[0].transpose() * r[1])),
            })
            .collect()
    }
}

/// What the sync found.
#[derive(Clone, Debug, PartialEq)]
pub struct GyroSync {
    /// Video time = log time + `offset_s`, at the clip's first frame.
    pub offset_s: f64,
    /// The video time `offset_s` is stated at: the clip's first frame.
    pub t_first: f64,
    /// How much faster the log's clock runs than the video's, parts per
    /// million: the offset grows by `drift_ppm` microseconds per second of video.
    pub drift_ppm: f64,
    /// The rotation taking IMU vectors into the camera frame.
    pub mount: Rot,
    /// The gyro's bias, rad/s, in the IMU's axes.
    pub bias: Vector3<f64>,
    /// Frame intervals where the gyro disagrees with the picture (spikes,
    /// saturation, dropouts) and that the fit left out.
    pub glitches: usize,
    /// RMS disagreement of the other intervals, rad/s.
    pub residual_rad_s: f64,
    /// The correlation of angular speeds at the offset found (1: the same).
    pub correlation: f64,
}

impl GyroSync {
    /// The mounting as a rotation vector, radians.
    pub fn mount_rotvec(&self) -> Tangent {
        so3::log(&self.mount)
    }
}

/// One frame as vision saw it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VisionPose {
    /// Its time (mid-readout), seconds of video.
    pub t: f64,
    /// `R_{0,j}` as the tracker estimated it.
    pub pose: Rot,
    /// True where tracking was lost (the estimate is a guess).
    pub lost: bool,
}
