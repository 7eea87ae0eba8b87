//! The log's running integral `W(t) = int w dt` (trapezoids between samples):
//! an interval's rotation is `W(b) - W(a)`, interpolated linearly in between,
//! so shifting the interval by a fraction of a sample costs nothing. Summing
//! rotation vectors is exact for a fixed axis and, over one frame interval
//! (a few degrees), off by the second-order term only.

use super::samples::GyroSamples;
use nalgebra::Vector3;

/// The running integral of a gyro log.
#[derive(Clone, Debug)]
pub struct GyroIntegral {
    t: Vec<f64>,
    w: Vec<Vector3<f64>>,
    /// `cum[i] = int_{t_0}^{t_i} w dt`.
    cum: Vec<Vector3<f64>>,
}

impl GyroIntegral {
    /// The integral of `gyro` (times increasing).
    pub fn new(gyro: &GyroSamples) -> Self {
        let mut cum = Vec::with_capacity(gyro.t.len());
        let mut acc = Vector3::zeros();
        for i in 0..gyro.t.len() {
            if i > 0 {
                acc += 0.5 * (gyro.w[i] + gyro.w[i - 1]) * (gyro.t[i] - gyro.t[i - 1]);
            }
            cum.push(acc);
        }
        Self {
            t: gyro.t.clone(),
            w: gyro.w.clone(),
            cum,
        }
    }

    /// First and last sample time.
    pub fn span(&self) -> (f64, f64) {
        (self.t[0], self.t[self.t.len() - 1])
    }

    /// `W(t)`, `None` outside the log.
    pub fn at(&self, t: f64) -> Option<Vector3<f64>> {
        let (a, b) = self.span();
        if !(a..=b).contains(&t) {
            return None;
        }
        // The sample at or before `t`.
        let i = self.t.partition_point(|&x| x <= t).saturating_sub(1);
        if i + 1 >= self.t.len() {
            return Some(self.cum[i]);
        }
        let (t0, t1) = (self.t[i], self.t[i + 1]);
        let h = t - t0;
        // Exact for the trapezoid's linear w between samples.
        let slope = (self.w[i + 1] - self.w[i]) / (t1 - t0);
        Some(self.cum[i] + self.w[i] * h + 0.5 * slope * h * h)
    }

    /// The rotation (IMU axes) over log times `[a, b]`, `None` outside the log.
    pub fn between(&self, a: f64, b: f64) -> Option<Vector3<f64>> {
        Some(self.at(b)? - self.at(a)?)
    }

    /// Mean angular speed over `[a, b]`, rad/s (`|W(b) - W(a)| / (b - a)`).
    pub fn speed(&self, a: f64, b: f64) -> Option<f64> {
        Some(self.between(a, b)?.norm() / (b - a))
    }
}
