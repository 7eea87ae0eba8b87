//! The log as orientations: its samples integrated on SO(3) with the bias
//! removed, so that the camera's pose at any video time is one lookup and
//! one short exponential. Unlike [`GyroIntegral`](super::GyroIntegral)'s
//! summed rotation vectors, this is exact over any span, which fusion needs
//! (a frame's pose relative to the clip's first, a readout's row by row).

use super::glitch;
use super::samples::{GyroSamples, GyroSync};
use crate::so3::{self, Rot, Tangent};
use nalgebra::Vector3;

/// Samples between re-orthonormalizations of the running product.
const RENORMALIZE_EVERY: usize = 256;

/// A synchronized log's camera orientation over time.
#[derive(Clone, Debug)]
pub struct GyroTrack {
    /// Sample times, log clock.
    t: Vec<f64>,
    /// Bias-free rates, IMU axes.
    w: Vec<Vector3<f64>>,
    /// The IMU's orientation at each sample, relative to the first.
    q: Vec<Rot>,
    sync: GyroSync,
    /// The log's mean sample rate, Hz.
    rate_hz: f64,
    /// The log's white noise, rad/s per axis.
    noise_rad_s: f64,
    /// Video times where the log's signal breaks ([`glitch::breaks`]).
    breaks: Vec<f64>,
}

impl GyroTrack {
    /// The orientations of `gyro` (times increasing), with `sync`'s bias
    /// removed and its offset, drift and mounting applied by [`GyroTrack::pose`].
    pub fn new(gyro: &GyroSamples, sync: &GyroSync) -> Self {
        let w: Vec<Vector3<f64>> = gyro.w.iter().map(|w| w - sync.bias).collect();
        let mut q = Vec::with_capacity(w.len());
        let mut acc = Rot::identity();
        for i in 0..w.len() {
            if i > 0 {
                acc *= so3::exp(&segment(&w[i - 1], &w[i], gyro.t[i] - gyro.t[i - 1], 1.0));
                if i % RENORMALIZE_EVERY == 0 {
                    acc = so3::renormalize(&acc);
                }
            }
            q.push(acc);
        }
        let mut track = Self {
            t: gyro.t.clone(),
            w,
            q,
            sync: sync.clone(),
            rate_hz: gyro.rate_hz(),
            noise_rad_s: glitch::noise_rad_s(gyro),
            breaks: Vec::new(),
        };
        track.breaks = glitch::breaks(gyro)
            .into_iter()
            .map(|tau| track.video_time(tau))
            .collect();
        track
    }

    /// The log's white noise, rad/s per axis.
    pub fn noise_rad_s(&self) -> f64 {
        self.noise_rad_s
    }

    /// Video times where the log's signal breaks (spikes, saturation,
    /// dropouts), in order.
    pub fn breaks(&self) -> &[f64] {
        &self.breaks
    }

    /// The sync it was made with.
    pub fn sync(&self) -> &GyroSync {
        &self.sync
    }

    /// Mean sample rate, Hz.
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }

    /// Video time of log time `tau` (the inverse of [`GyroTrack::log_time`]).
    pub fn video_time(&self, tau: f64) -> f64 {
        let d = self.sync.drift_ppm * 1e-6;
        (tau + self.sync.offset_s - d * self.sync.t_first) / (1.0 - d)
    }

    /// Log time of video time `t` (video = log + offset, the offset growing
    /// with the drift from the clip's first frame).
    pub fn log_time(&self, t: f64) -> f64 {
        t - self.sync.offset_s - self.sync.drift_ppm * 1e-6 * (t - self.sync.t_first)
    }

    /// The camera's orientation at video time `t` (camera axes, relative to
    /// an arbitrary fixed frame), `None` outside the log.
    pub fn pose(&self, t: f64) -> Option<Rot> {
        let tau = self.log_time(t);
        let n = self.t.len();
        if n == 0 || !(self.t[0]..=self.t[n - 1]).contains(&tau) {
            return None;
        }
        let i = self.t.partition_point(|&x| x <= tau).saturating_sub(1);
        let q = if i + 1 >= n {
            self.q[n - 1]
        } else {
            let span = self.t[i + 1] - self.t[i];
            let f = (tau - self.t[i]) / span;
            self.q[i] * so3::exp(&segment(&self.w[i], &self.w[i + 1], span, f))
        };
        Some(self.sync.mount * q * self.sync.mount.transpose())
    }

    /// The rotation vector of `pose(a)^T pose(b)`, camera axes of `a`.
    pub fn between(&self, a: f64, b: f64) -> Option<Tangent> {
        Some(so3::log(&(self.pose(a)?.transpose() * self.pose(b)?)))
    }
}

/// The rotation over the first `f` of a sample interval `dt` long whose rate
/// goes linearly from `w0` to `w1` (the trapezoid's integral).
fn segment(w0: &Vector3<f64>, w1: &Vector3<f64>, dt: f64, f: f64) -> Tangent {
    let h = f * dt;
    w0 * h + 0.5 * (w1 - w0) * f * h
}
