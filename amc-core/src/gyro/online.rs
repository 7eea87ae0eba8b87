//! Online fusion: each frame's pose as it arrives, from that frame and the
//! ones before it (a live feed; one pass over a clip too long to keep).
//!
//! The same model as [`fuse`](super::fuse), run forward: the gyro's steps
//! chained, the chain held to vision's orientations. Offline, the exact
//! smoother of a random walk does that with the whole clip in view; here its
//! causal twin does, a Kalman filter per axis whose state is the chain's
//! correction and that correction's drift (the bias the sync left, which the
//! offline fusion removes as the whole clip's steady drift). Its noises are
//! measured as offline, over a window of recent frame intervals: the gyro's
//! from the log's own fourth differences, vision's from the two's
//! disagreement. With a `lag` of `L` frames a pose is given once `L` later
//! frames are seen, smoothed backwards over them (Rauch-Tung-Striebel over
//! the window: offline's smoother with a bounded lookahead); 0 is causal.
//! Glitches are judged interval by interval on the same rule
//! (a disagreement far beyond the recent median with a break in the log near
//! it is the gyro's; without one, the picture's), and a frame's readout path
//! is the gyro's own where the log covers its readout.

use super::fuse::{FuseParams, FusedFrom, FusedPose};
use super::glitch::median;
use super::path::{rate_path, PathFit};
use super::samples::VisionPose;
use super::track::GyroTrack;
use crate::error::AmcError;
use crate::shutter::IntraFrame;
use crate::so3::{self, Rot, Tangent};
use std::collections::VecDeque;

/// Online fusion's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct OnlineParams {
    /// When the gyro and the picture disagree (as offline).
    pub glitch: FuseParams,
    /// Recent frame intervals the thresholds and the noises are measured over.
    pub window: usize,
    /// How far the gyro's bias may wander, rad/s per square root of a second
    /// (the drift state's random walk).
    pub bias_walk: f64,
    /// The bias the sync may have left, rad/s (the drift state's prior).
    pub bias_prior: f64,
    /// Frames of lookahead: a pose is given once this many later frames are
    /// seen, smoothed over them (0: causal, as a live feed needs).
    pub lag: usize,
}

impl Default for OnlineParams {
    fn default() -> Self {
        Self {
            glitch: FuseParams::default(),
            window: 240,
            bias_walk: 2e-4,
            bias_prior: 5e-3,
            lag: 0,
        }
    }
}

impl OnlineParams {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), AmcError> {
        self.glitch.validate()?;
        if !(MIN_HISTORY..=100_000).contains(&self.window) {
            return Err(AmcError::invalid(
                "online fusion window",
                self.window.to_string(),
                "10 to 100000 frame intervals",
            ));
        }
        if self.lag > MAX_LAG {
            return Err(AmcError::invalid(
                "online fusion lag",
                self.lag.to_string(),
                "0 to 600 frames",
            ));
        }
        for (name, v) in [
            ("bias walk", self.bias_walk),
            ("bias prior", self.bias_prior),
        ] {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                return Err(AmcError::invalid(name, v.to_string(), "0 to 1 rad/s"));
            }
        }
        Ok(())
    }
}

/// Intervals of history before the measured noises replace the sync's.
const MIN_HISTORY: usize = 10;
/// Most frames of lookahead.
pub const MAX_LAG: usize = 600;
/// Huber's constant, in robust standard deviations of the innovations.
const HUBER: f64 = 2.5;

/// Causal fusion of a synchronized log with frames as they arrive.
#[derive(Clone, Debug)]
pub struct OnlineFusion {
    track: GyroTrack,
    params: OnlineParams,
    readout_s: f64,
    fit: PathFit,
    /// The last frame, and the chain's pose there.
    prev: Option<(VisionPose, Rot)>,
    axes: [DriftFilter; 3],
    /// Frames seen but not given yet (at most `lag + 1`), oldest first.
    pending: VecDeque<Pending>,
    /// Recent disagreements (rad/s, norms) of intervals that were not over the limit.
    rates: VecDeque<f64>,
    /// ... and their size per axis over an interval (rad).
    spread: [VecDeque<f64>; 3],
    /// Recent innovations' norms (rad).
    innovations: VecDeque<f64>,
    /// The previous interval was the gyro's glitch: the next one is bridged too.
    after_glitch: bool,
    glitch_intervals: usize,
    bridged_frames: usize,
}

impl OnlineFusion {
    /// Fusion of `track` (a synchronized log) with frames read out over
    /// `readout_s` (0: a global shutter), none seen yet.
    pub fn new(track: GyroTrack, readout_s: f64, params: OnlineParams) -> Result<Self, AmcError> {
        params.validate()?;
        if !(readout_s.is_finite() && readout_s >= 0.0) {
            return Err(AmcError::invalid(
                "readout",
                readout_s.to_string(),
                "0 s or more",
            ));
        }
        let bias_var = params.bias_prior.powi(2);
        Ok(Self {
            track,
            readout_s,
            fit: PathFit::new(),
            prev: None,
            axes: [DriftFilter::new(bias_var); 3],
            pending: VecDeque::with_capacity(params.lag + 1),
            rates: VecDeque::with_capacity(params.window),
            spread: std::array::from_fn(|_| VecDeque::with_capacity(params.window)),
            innovations: VecDeque::with_capacity(params.window),
            after_glitch: false,
            glitch_intervals: 0,
            bridged_frames: 0,
            params,
        })
    }

    /// Frame intervals where the gyro glitched and the picture bridged it, so far.
    pub fn glitch_intervals(&self) -> usize {
        self.glitch_intervals
    }

    /// Frames whose tracking was lost, or disagreed with a sound log, that
    /// the gyro bridged, so far.
    pub fn bridged_frames(&self) -> usize {
        self.bridged_frames
    }

    /// Takes the next frame (times must increase); gives the pose of the
    /// frame `lag` frames before it, from the frames up to this one, or
    /// `None` while the lookahead fills.
    pub fn push(&mut self, frame: VisionPose) -> Option<FusedPose> {
        self.filter(frame);
        (self.pending.len() > self.params.lag).then(|| self.give())
    }

    /// The frames still held back by the lookahead, one per call, after the
    /// last [`OnlineFusion::push`]; `None` once all are given.
    pub fn finish(&mut self) -> Option<FusedPose> {
        (!self.pending.is_empty()).then(|| self.give())
    }

    /// The oldest pending frame, smoothed backwards over the newer ones.
    fn give(&mut self) -> FusedPose {
        // Rauch-Tung-Striebel from the newest filtered state back to the oldest.
        let mut smooth: [[f64; 2]; 3] =
            std::array::from_fn(|a| self.pending[self.pending.len() - 1].filtered[a].x);
        for i in (0..self.pending.len() - 1).rev() {
            let (old, new) = (&self.pending[i], &self.pending[i + 1]);
            for (a, x) in smooth.iter_mut().enumerate() {
                *x = old.filtered[a].smoothed(&new.predicted[a], new.dt, *x);
            }
        }
        let p = self.pending.pop_front().expect("a pending frame");
        let correction = Tangent::new(smooth[0][0], smooth[1][0], smooth[2][0]);
        let pose = so3::renormalize(&(so3::exp(&correction) * p.chain));
        self.output(p.frame, pose, p.prev, p.glitch)
    }

    /// Runs the filter forward over `frame`.
    fn filter(&mut self, frame: VisionPose) {
        let Some((prev, prev_chain)) = self.prev else {
            // The chain starts on the picture.
            self.prev = Some((frame, frame.pose));
            let first_var = self.vision_var(1.0 / 60.0);
            for a in &mut self.axes {
                a.pzz = first_var;
            }
            if frame.lost {
                self.bridged_frames += 1;
            }
            self.pending.push_back(Pending {
                frame,
                prev: None,
                chain: frame.pose,
                glitch: false,
                dt: 0.0,
                predicted: std::array::from_fn(|a| self.axes[a].state()),
                filtered: std::array::from_fn(|a| self.axes[a].state()),
            });
            return;
        };
        let dt = frame.t - prev.t;
        let vision_step = so3::log(&(prev.pose.transpose() * frame.pose));
        let gyro_step = if dt > 0.0 {
            self.track.between(prev.t, frame.t)
        } else {
            None
        };
        let seen = !prev.lost && !frame.lost;
        let mut weight = if frame.lost { 0.0 } else { 1.0 };
        let mut glitch = std::mem::take(&mut self.after_glitch);
        if let (Some(g), true, true) = (gyro_step, seen, dt > 0.0) {
            let d = (g - vision_step) / dt;
            let rate = d.norm();
            let limit = (self.params.glitch.glitch_medians * self.median_rate())
                .max(self.params.glitch.glitch_floor_rad_s);
            if rate > limit {
                let breaks = self.track.breaks();
                let (from, to) = (prev.t - dt, frame.t + dt);
                let first = breaks.partition_point(|&b| b < from);
                if breaks.get(first).is_some_and(|&b| b <= to) {
                    // The gyro's fault: the picture bridges this interval and the next.
                    glitch = true;
                    self.after_glitch = true;
                } else {
                    weight = 0.0;
                }
            } else {
                push_bounded(&mut self.rates, rate, self.params.window);
                for (axis, v) in self.spread.iter_mut().zip(d.iter()) {
                    push_bounded(axis, (v * dt).abs(), self.params.window);
                }
            }
        }
        if glitch {
            self.glitch_intervals += 1;
        }
        if weight == 0.0 {
            self.bridged_frames += 1;
        }
        let step = match gyro_step {
            Some(g) if !glitch => g,
            _ => vision_step,
        };
        let chain = so3::renormalize(&(prev_chain * so3::exp(&step)));
        // The chain's error is the world's (left), as offline.
        let y = so3::log(&(frame.pose * chain.transpose()));
        let gyro_var = self.gyro_var(dt.max(0.0));
        let vision_var = self.vision_var(dt.max(0.0));
        for a in &mut self.axes {
            a.predict(dt.max(0.0), gyro_var, self.params.bias_walk.powi(2));
        }
        let predicted = std::array::from_fn(|a| self.axes[a].state());
        if weight > 0.0 {
            let predicted = Tangent::from(std::array::from_fn::<f64, 3, _>(|i| self.axes[i].z));
            let innovation = (y - predicted).norm();
            if self.innovations.len() >= MIN_HISTORY {
                let limit = HUBER * (1.4826 * median_of(&self.innovations)).max(1e-12);
                if innovation > limit {
                    weight *= limit / innovation;
                }
            }
            push_bounded(&mut self.innovations, innovation, self.params.window);
            for (a, yi) in self.axes.iter_mut().zip(y.iter()) {
                a.update(*yi, vision_var / weight);
            }
        }
        self.prev = Some((frame, chain));
        self.pending.push_back(Pending {
            frame,
            prev: Some(prev),
            chain,
            glitch,
            dt: dt.max(0.0),
            predicted,
            filtered: std::array::from_fn(|a| self.axes[a].state()),
        });
    }

    fn output(
        &self,
        frame: VisionPose,
        pose: Rot,
        prev: Option<VisionPose>,
        glitch: bool,
    ) -> FusedPose {
        let covered = self.track.pose(frame.t).is_some();
        let from = if covered && !glitch {
            FusedFrom::Gyro
        } else {
            FusedFrom::Vision
        };
        let path = if self.readout_s <= 0.0 {
            IntraFrame::ZERO
        } else {
            let from_vision = || {
                prev.map_or(IntraFrame::ZERO, |p| {
                    rate_path(&p, &frame, &frame, self.readout_s)
                })
            };
            if from == FusedFrom::Gyro {
                self.fit
                    .path(&self.track, frame.t, self.readout_s)
                    .unwrap_or_else(from_vision)
            } else {
                from_vision()
            }
        };
        FusedPose { pose, path, from }
    }

    /// The recent median disagreement, rad/s (the sync's residual until
    /// there is history).
    fn median_rate(&self) -> f64 {
        if self.rates.len() < MIN_HISTORY {
            return self.track.sync().residual_rad_s;
        }
        median_of(&self.rates)
    }

    /// The gyro chain's variance per axis over `dt`: its white noise integrated.
    fn gyro_var(&self, dt: f64) -> f64 {
        (self.track.noise_rad_s().powi(2) * dt / self.track.rate_hz().max(1.0))
            .max(f64::MIN_POSITIVE)
    }

    /// Vision's variance per axis: the recent disagreements' spread holds two
    /// poses' vision error and one interval's gyro noise (as offline).
    fn vision_var(&self, dt: f64) -> f64 {
        let spread_var = if self.spread[0].len() < MIN_HISTORY {
            (self.track.sync().residual_rad_s * dt).powi(2) / 3.0
        } else {
            self.spread
                .iter()
                .map(|a| (1.4826 * median_of(a)).powi(2))
                .sum::<f64>()
                / 3.0
        };
        ((spread_var - self.gyro_var(dt)) / 2.0)
            .max(0.01 * spread_var)
            .max(f64::MIN_POSITIVE)
    }
}

/// A frame held back by the lookahead.
#[derive(Clone, Debug)]
struct Pending {
    frame: VisionPose,
    prev: Option<VisionPose>,
    /// The gyro chain's pose at it.
    chain: Rot,
    /// Its interval from the previous frame was the gyro's glitch.
    glitch: bool,
    /// Seconds from the previous frame.
    dt: f64,
    /// Each axis's state before and after vision's update.
    predicted: [Gauss2; 3],
    filtered: [Gauss2; 3],
}

/// A correction and its drift, `x = [z, d]`, with covariance `[[a, b], [b, c]]`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Gauss2 {
    x: [f64; 2],
    p: [f64; 3],
}

impl Gauss2 {
    /// The smoothed state here, from the next frame's `predicted` state
    /// (`dt` later) and its `smoothed` mean: `x + C (x_s' - x_p')`,
    /// `C = P F^T P_p'^-1`.
    fn smoothed(&self, predicted: &Gauss2, dt: f64, next: [f64; 2]) -> [f64; 2] {
        let [a, b, c] = self.p;
        // P F^T, F = [[1, dt], [0, 1]].
        let pf = [[a + b * dt, b], [b + c * dt, c]];
        let [pa, pb, pc] = predicted.p;
        let det = pa * pc - pb * pb;
        if !(det > 0.0 && det.is_finite()) {
            return self.x;
        }
        let inv = [[pc / det, -pb / det], [-pb / det, pa / det]];
        let r = [next[0] - predicted.x[0], next[1] - predicted.x[1]];
        let mut out = self.x;
        for (i, o) in out.iter_mut().enumerate() {
            let c0 = pf[i][0] * inv[0][0] + pf[i][1] * inv[1][0];
            let c1 = pf[i][0] * inv[0][1] + pf[i][1] * inv[1][1];
            *o += c0 * r[0] + c1 * r[1];
        }
        out
    }
}

/// The median of a window of recent values.
fn median_of(q: &VecDeque<f64>) -> f64 {
    median(&mut q.iter().copied().collect::<Vec<f64>>())
}

fn push_bounded(q: &mut VecDeque<f64>, v: f64, cap: usize) {
    if q.len() == cap {
        q.pop_front();
    }
    q.push_back(v);
}

/// One axis of the chain's correction `z` and its drift `d` (rad/s): a
/// random walk (the gyro's integrated noise) whose drift wanders slowly (the
/// bias), seen through vision's white noise.
#[derive(Clone, Copy, Debug)]
struct DriftFilter {
    z: f64,
    d: f64,
    pzz: f64,
    pzd: f64,
    pdd: f64,
}

impl DriftFilter {
    fn new(bias_var: f64) -> Self {
        Self {
            z: 0.0,
            d: 0.0,
            pzz: 0.0,
            pzd: 0.0,
            pdd: bias_var,
        }
    }

    fn state(&self) -> Gauss2 {
        Gauss2 {
            x: [self.z, self.d],
            p: [self.pzz, self.pzd, self.pdd],
        }
    }

    /// Over `dt`: the correction grows by the drift; the chain's noise `q_z`
    /// and the bias's walk `q_d` per second add their variance.
    fn predict(&mut self, dt: f64, q_z: f64, q_d: f64) {
        self.z += self.d * dt;
        self.pzz += 2.0 * dt * self.pzd + dt * dt * self.pdd + q_z;
        self.pzd += dt * self.pdd;
        self.pdd += q_d * dt;
    }

    /// Vision sees `y` with variance `r`.
    fn update(&mut self, y: f64, r: f64) {
        let s = self.pzz + r;
        if !(s > 0.0 && s.is_finite()) {
            return;
        }
        let (kz, kd) = (self.pzz / s, self.pzd / s);
        let nu = y - self.z;
        self.z += kz * nu;
        self.d += kd * nu;
        let (pzz, pzd) = (self.pzz, self.pzd);
        self.pzz = (1.0 - kz) * pzz;
        self.pzd = (1.0 - kz) * pzd;
        self.pdd -= kd * pzd;
    }
}
