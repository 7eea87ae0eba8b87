//! The rolling-shutter readout time from the footage (`readout_ms = auto`).
//!
//! Above the stabilizer (it tracks with one), as `selfcal` is above the
//! tracker; the model it fits is [`crate::shutter`]'s.
//!
//! With a rolling shutter on, the tracker measures each frame's rotation
//! during its readout, `phi_j`, from the intensities alone, whatever the
//! readout (it is a free parameter per frame). The same motion is also seen
//! *between* frames: the mid-readout orientations `R_{0,j}`. The readout time
//! is the one that makes the two agree: with `r_j(t) = log(R_{0,j}^T R(t))`
//! the orientation relative to frame `j`, interpolated from the frame poses,
//! ```text
//! phi_j ~ r_j(t_j + tau/2) - r_j(t_j - tau/2)
//! tau*  = argmin_tau  sum_j | phi_j - (r_j(t_j + tau/2) - r_j(t_j - tau/2)) |^2
//! ```
//! Shake of 12-20 Hz sampled at 60 frames/s has 3-5 samples per period, where
//! a finite difference of the poses is badly biased (the central difference
//! of a 20 Hz sine at 60 fps is 0.41 of its derivative). A band-limited signal
//! is determined by its samples, though, so `r_j(t)` is interpolated with a
//! Lanczos-windowed sinc over [`LANCZOS_LOBES`] frames on each side.
//!
//! The estimate is trusted ([`ReadoutEstimate::confident`]) when the clip
//! moves enough for the readout to show ([`MIN_MOTION_DEG`] of rotation
//! across a nominal readout) and the fitted model explains at least
//! [`MIN_EXPLAINED`] of the measured intra-frame rotation; otherwise the
//! caller falls back to a global shutter and says so. A global-shutter clip
//! gives `phi_j ~ 0`, hence `tau* ~ 0`.

use crate::camera::CameraModel;
use crate::error::AmcError;
use crate::image::FrameRef;
use crate::minimize::golden_section;
use crate::so3::{self, Rot, Tangent};
use crate::stabilizer::{Stabilizer, StabilizerParams, Telemetry};
use crate::view::Mode;

/// Frames the estimate uses (3 s at 60 frames/s).
pub const READOUT_FRAMES: usize = 180;
/// Frames of the sinc interpolation on each side of a frame.
pub const LANCZOS_LOBES: usize = 6;
/// Least share of the intra-frame rotation the fit must explain.
pub const MIN_EXPLAINED: f64 = 0.5;
/// Least RMS rotation (degrees) between poses a quarter frame period apart
/// (the interpolated path) for the readout to be measurable.
pub const MIN_MOTION_DEG: f64 = 0.02;
/// A global-shutter answer is trusted only when the measured rotation within
/// the frames (RMS) is at most this share of the rotation over a quarter
/// frame period ([`ReadoutEstimate::motion_deg`]): a readout of a quarter
/// frame would show all of it. Measured: 0.52 on a global-shutter synthetic
/// clip (the readout path's estimation noise), 30 on cc9 (parallax and a
/// slow sway, where the path is not seen).
pub const GLOBAL_MAX_SHARE: f64 = 0.75;
/// Estimates under this are a global shutter, milliseconds.
pub const GLOBAL_BELOW_MS: f64 = 0.5;
/// Nominal readout the tracking pass runs with (it only switches the model
/// on: the intra-frame rotation is measured, not derived from it).
pub const NOMINAL_READOUT_MS: f64 = 10.0;

/// One frame's rotation during its readout, as the tracker measured it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredReadout {
    /// Video time of the frame's mid-readout, seconds.
    pub t: f64,
    /// Its rotation from the first row to the last (camera axes, radians).
    pub phi: Tangent,
}

/// Each frame's rotation during its readout from a readout pass's telemetry
/// ([`ReadoutEstimator::finish_with_telemetry`]), lost frames left out.
pub fn measured(telemetry: &[Telemetry]) -> Vec<MeasuredReadout> {
    telemetry
        .iter()
        .filter(|t| !t.track.lost)
        .map(|t| MeasuredReadout {
            t: t.t,
            phi: Tangent::from(t.readout_rotation),
        })
        .collect()
}

/// The readout estimated from a clip.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadoutEstimate {
    /// The estimate, milliseconds (0 below [`GLOBAL_BELOW_MS`]).
    pub readout_ms: f64,
    /// Whether the clip pins it down (see the module's docs); when not, use 0.
    pub confident: bool,
    /// Share of the measured intra-frame rotation the fit explains, 0..=1.
    pub explained: f64,
    /// RMS rotation between poses a quarter frame apart, degrees.
    pub motion_deg: f64,
    /// Frames used in the fit.
    pub frames: usize,
}

/// Tracks the first frames of a clip with the rolling-shutter model on and
/// estimates the readout from them (push up to [`READOUT_FRAMES`] frames,
/// then [`ReadoutEstimator::finish`]). Memory: one tracker and the poses.
pub struct ReadoutEstimator {
    stab: Stabilizer,
    telemetry: Vec<Telemetry>,
}

impl ReadoutEstimator {
    /// An estimator for `width x height` frames through `lens`, tracked with
    /// `params` (its mode, view and rendering are not used).
    pub fn new(
        lens: &CameraModel,
        width: usize,
        height: usize,
        params: &StabilizerParams,
    ) -> Result<Self, AmcError> {
        let mut p = params.clone();
        p.shutter.readout_ms = NOMINAL_READOUT_MS;
        p.view.mode = Mode::None;
        p.view.lookahead = 0;
        p.render.n_avg = 1;
        let mut stab = Stabilizer::new(lens, width, height, p)?;
        stab.set_rendering(false);
        // The per-frame poses, as measured: a trajectory through them would
        // be fitted with the nominal readout.
        stab.set_trajectory_smoothing(false);
        Ok(Self {
            stab,
            telemetry: Vec::new(),
        })
    }

    /// Frames pushed so far.
    pub fn frames(&self) -> usize {
        self.telemetry.len()
    }

    /// Whether it has the frames it wants.
    pub fn is_full(&self) -> bool {
        self.frames() >= READOUT_FRAMES
    }

    /// Tracks the next frame (`t` seconds into the clip).
    pub fn push(&mut self, frame: FrameRef<'_>, t: f64) -> Result<(), AmcError> {
        if let Some(tel) = self.stab.push(frame, t)? {
            self.telemetry.push(tel);
        }
        Ok(())
    }

    /// The estimate from the frames pushed.
    pub fn finish(self) -> Result<ReadoutEstimate, AmcError> {
        self.finish_with_telemetry().0
    }

    /// [`ReadoutEstimator::finish`], and the telemetry it was fitted to
    /// (each frame's rotation during its readout as measured: what a gyro
    /// log measures the readout against, [`measured`]).
    pub fn finish_with_telemetry(mut self) -> (Result<ReadoutEstimate, AmcError>, Vec<Telemetry>) {
        while let Some(tel) = self.stab.finish() {
            self.telemetry.push(tel);
        }
        (fit_readout(&self.telemetry), self.telemetry)
    }
}

/// Frames needed for one interior sample and a meaningful fit.
pub const MIN_FRAMES: usize = 4 * LANCZOS_LOBES + 1;

/// Lanczos kernel `sinc(x) sinc(x / a)`, 0 outside `|x| < a`.
fn lanczos(x: f64, a: f64) -> f64 {
    if x.abs() >= a {
        return 0.0;
    }
    if x.abs() < 1e-12 {
        return 1.0;
    }
    let px = std::f64::consts::PI * x;
    a * px.sin() * (px / a).sin() / (px * px)
}

/// One frame's sample: its measured intra-frame rotation and its neighbours'
/// orientations relative to it, at times in frame periods from it.
struct Sample {
    phi: Tangent,
    neighbours: Vec<(f64, Tangent)>,
}

impl Sample {
    /// `r(t_j + x dt) - r(t_j - x dt)` by windowed-sinc interpolation.
    fn predicted(&self, x: f64) -> Tangent {
        let a = LANCZOS_LOBES as f64;
        let mut d = Tangent::zeros();
        for &(u, r) in &self.neighbours {
            d += r * (lanczos(x - u, a) - lanczos(-x - u, a));
        }
        d
    }
}

/// The frame period of a pass's telemetry: the median gap between frames
/// (`None` with fewer than two).
pub fn frame_period(telemetry: &[Telemetry]) -> Option<f64> {
    let mut gaps: Vec<f64> = telemetry.windows(2).map(|w| w[1].t - w[0].t).collect();
    gaps.sort_by(f64::total_cmp);
    gaps.get(gaps.len() / 2).copied()
}

/// Fits the readout to a pass's telemetry (see the module's docs).
pub fn fit_readout(telemetry: &[Telemetry]) -> Result<ReadoutEstimate, AmcError> {
    if telemetry.len() < MIN_FRAMES {
        return Err(AmcError::TooFewFrames {
            needed: MIN_FRAMES,
            got: telemetry.len(),
        });
    }
    let dt = frame_period(telemetry).unwrap_or(f64::NAN);
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(AmcError::invalid("frame period", dt, "positive seconds"));
    }
    let rots: Vec<Rot> = telemetry
        .iter()
        .map(|t| so3::exp(&Tangent::from(t.r_est)))
        .collect();
    let k = LANCZOS_LOBES;
    let mut samples = Vec::new();
    for j in k..telemetry.len() - k {
        let window = &telemetry[j - k..=j + k];
        if window.iter().any(|t| t.track.lost) {
            continue;
        }
        let inv = rots[j].transpose();
        let neighbours = (j - k..=j + k)
            .map(|i| {
                (
                    (telemetry[i].t - telemetry[j].t) / dt,
                    so3::log(&(inv * rots[i])),
                )
            })
            .collect();
        samples.push(Sample {
            phi: Tangent::from(telemetry[j].readout_rotation),
            neighbours,
        });
    }
    if samples.len() < 2 * k {
        return Err(AmcError::TooFewFrames {
            needed: MIN_FRAMES,
            got: samples.len(),
        });
    }
    let sse = |x: f64| -> f64 {
        samples
            .iter()
            .map(|s| (s.phi - s.predicted(x)).norm_squared())
            .sum()
    };
    // x = tau / (2 dt): grid over two frame periods of readout, then golden section.
    let steps = 400;
    let x_max = 1.0;
    let (mut best_x, mut best) = (0.0, sse(0.0));
    for i in 1..=steps {
        let x = x_max * i as f64 / steps as f64;
        let e = sse(x);
        if e < best {
            (best_x, best) = (x, e);
        }
    }
    let (x, best) = refine_minimum(sse, best_x, x_max / steps as f64, 0.0, x_max);
    let total: f64 = samples.iter().map(|s| s.phi.norm_squared()).sum();
    let motion = (samples
        .iter()
        .map(|s| s.predicted(0.125).norm_squared())
        .sum::<f64>()
        / samples.len() as f64)
        .sqrt()
        .to_degrees();
    Ok(ReadoutEstimate::judged(
        2.0 * x * dt * 1000.0,
        Fit {
            sse: best,
            total,
            samples: samples.len(),
        },
        motion,
        telemetry.len(),
    ))
}

/// A readout fit's residual: `sse` of the measured rotations within frames
/// (`total`: their own squared sum) over `samples` frames.
pub(crate) struct Fit {
    pub sse: f64,
    pub total: f64,
    pub samples: usize,
}

impl ReadoutEstimate {
    /// A fitted readout judged as the module's docs say: global below
    /// [`GLOBAL_BELOW_MS`], trusted with [`MIN_MOTION_DEG`] of motion
    /// (`motion_deg`: RMS over a quarter frame period) and, for a rolling
    /// shutter, [`MIN_EXPLAINED`] of the rotation within frames explained.
    pub(crate) fn judged(readout_ms: f64, fit: Fit, motion_deg: f64, frames: usize) -> Self {
        let explained = if fit.total > 0.0 {
            (1.0 - fit.sse / fit.total).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let global = readout_ms < GLOBAL_BELOW_MS;
        // A global shutter measures (almost) no rotation within its frames; a
        // readout the fit cannot explain (parallax, a moving scene, a slow sway
        // the tracker barely sees within a frame) is not evidence of one.
        let rms_phi = (fit.total / fit.samples.max(1) as f64).sqrt().to_degrees();
        let still = rms_phi <= GLOBAL_MAX_SHARE * motion_deg;
        let confident = motion_deg >= MIN_MOTION_DEG
            && if global {
                still
            } else {
                explained >= MIN_EXPLAINED
            };
        Self {
            readout_ms: if global { 0.0 } else { readout_ms },
            confident,
            explained,
            motion_deg,
            frames,
        }
    }
}

/// The minimum of `sse` near `x`, a grid point `step` from its neighbours
/// (within `lo..=hi`): the golden section there, or `x` where that finds
/// nothing lower. The point and its value.
pub(crate) fn refine_minimum(
    sse: impl Fn(f64) -> f64,
    x: f64,
    step: f64,
    lo: f64,
    hi: f64,
) -> (f64, f64) {
    let golden = golden_section(
        |x| Ok::<_, std::convert::Infallible>(sse(x)),
        (x - step).max(lo),
        (x + step).min(hi),
        40,
    )
    .unwrap_or(x);
    let (at_golden, at_grid) = (sse(golden), sse(x));
    if at_golden <= at_grid {
        (golden, at_golden)
    } else {
        (x, at_grid)
    }
}
