//! Synthetic test clips: a flapping-wing shake trajectory and a renderer that
//! films an equirectangular panorama with any [`CameraModel`], including a
//! rolling shutter.
//!
//! # Shake trajectory
//!
//! Per axis `i in {x, y, z}` the shake angle is a sum of `N = 8` sinusoids
//! ```text
//! theta_i(t) = s * sum_k a_ik sin(2 pi f_ik t + phi_ik)
//! ```
//! with frequencies `f_ik` drawn inside the band `[lo, hi]` (one per equal
//! sub-band, jittered, so no two are nearly equal), phases `phi_ik` uniform in
//! `[0, 2 pi)` and relative amplitudes `a_ik` uniform in `[0.5, 1]`, all from a
//! SplitMix64 generator seeded with `seed` (deterministic on every platform).
//! With an optional constant yaw pan of rate `p` (rad/s) about the world y axis
//! the absolute orientation is
//! ```text
//! A(t) = exp(p t e_y) exp(theta(t))
//! ```
//! and the trajectory reported to callers is relative to the first frame:
//! `R_{0}(t) = A(0)^T A(t)`, so `R_{0}(0) = I` (it is `R_{0,j}` of the frame
//! exposed at `t`). Its body angular velocity (in the current camera's frame) is
//! ```text
//! omega(t) = J_r(theta) theta'(t) + exp(theta)^T (p e_y)
//! J_r(w) = I - (1 - cos|w|)/|w|^2 [w]x + (|w| - sin|w|)/|w|^3 [w]x^2
//! ```
//! The scale `s` is chosen so that the RMS of `|J_r(theta) theta'|` (the shake
//! part, pan excluded) over `t in [0, 10 s)` sampled at 2 kHz equals
//! `shake_dps`: start from the small-angle estimate and apply the fixed-point
//! update `s <- s * target / measured` three times (the map is nearly linear).
//!
//! # Rendering
//!
//! For every output pixel, `n x n` sub-pixel rays (offsets `(i + 0.5)/n - 0.5`)
//! are unprojected once by [`EquirectRenderer::new`]. A frame is rendered with
//! an orientation per row (rolling shutter: row `v` of a frame `H` rows high
//! is exposed at `t + readout * (v / H - 1/2)`, [`crate::shutter::row_fraction`],
//! so the frame's time `t` is its mid-readout time, the pose the telemetry
//! reports; the caller maps that row fraction to an orientation). For a
//! camera ray `d_cam`:
//! ```text
//! d = R_{0}(t_row) d_cam                      (world = camera 0)
//! lon = atan2(d.x, d.z),   lat = atan2(-d.y, sqrt(d.x^2 + d.z^2))   (y is down)
//! u = (lon / (2 pi) + 0.5) W - 0.5,   v = (0.5 - lat / pi) H - 0.5
//! ```
//! and the panorama is sampled bilinearly at `(u, v)` (wrapping horizontally,
//! clamped vertically). The pixel is the mean of its sub-samples; sub-rays the
//! camera cannot unproject contribute black. Because a panorama is usually much
//! finer than the camera, [`downsample_pano`] box-filters it first, by the
//! factor [`pano_downsample_factor`] picks from the camera's angular pixel size
//! at the centre: `floor((W / 2 pi) / fx)`, at least 1.

use crate::camera::CameraModel;
use crate::error::{check_range, AmcError};
use crate::image::{Frame, FrameRef, PixelFormat};
use crate::so3::{self, Rot, Tangent};
use nalgebra::{Matrix3, Vector2, Vector3};
use std::f64::consts::PI;

/// Number of sinusoids per axis.
const COMPONENTS: usize = 8;
/// Length of the window over which the RMS angular speed is calibrated, s.
const CALIBRATION_SECONDS: f64 = 10.0;
/// Sampling rate of the calibration grid, Hz.
const CALIBRATION_RATE_HZ: f64 = 2000.0;

/// SplitMix64: a tiny, well-mixed, deterministic generator (Steele et al. 2014).
#[derive(Clone, Debug)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// Parameters of the flapping-wing shake.
#[derive(Clone, Debug, PartialEq)]
pub struct ShakeParams {
    /// RMS angular speed of the shake, deg/s (`0..=2000`).
    pub shake_dps: f64,
    /// Frequency band of the shake, Hz: `0 < lo < hi <= 1000`.
    pub band_hz: (f64, f64),
    /// Seed of the generator: the same seed gives the same trajectory.
    pub seed: u64,
    /// Constant yaw pan rate, deg/s (positive turns the camera to the right),
    /// `-720..=720`.
    pub pan_dps: f64,
}

impl Default for ShakeParams {
    fn default() -> Self {
        Self {
            shake_dps: 100.0,
            band_hz: (12.0, 20.0),
            seed: 0,
            pan_dps: 0.0,
        }
    }
}

impl ShakeParams {
    /// Checks every parameter's range.
    pub fn validate(&self) -> Result<(), AmcError> {
        check_range(
            "shake angular speed (deg/s)",
            self.shake_dps,
            0.0,
            2000.0,
            "0 to 2000",
        )?;
        let (lo, hi) = self.band_hz;
        let band_ok = lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi && hi <= 1000.0;
        if !band_ok {
            return Err(AmcError::invalid(
                "shake band (Hz)",
                format!("{lo},{hi}"),
                "lo,hi with 0 < lo < hi <= 1000",
            ));
        }
        check_range(
            "pan rate (deg/s)",
            self.pan_dps,
            -720.0,
            720.0,
            "-720 to 720",
        )?;
        Ok(())
    }
}

/// One sinusoid of one axis: `amp * sin(omega t + phase)`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Component {
    amp: f64,
    omega: f64,
    phase: f64,
}

/// A deterministic shake trajectory (see the module header for the equations).
#[derive(Clone, Debug, PartialEq)]
pub struct Shake {
    params: ShakeParams,
    /// Per axis, the sinusoids with the final scale folded into `amp`.
    axes: [[Component; COMPONENTS]; 3],
    /// Pan rate, rad/s.
    pan: f64,
    /// `A(0)^T`.
    r0_inv: Rot,
}

/// Right Jacobian of SO(3): `exp(w + d) ~ exp(w) exp(J_r(w) d)`.
fn right_jacobian(w: &Tangent) -> Matrix3<f64> {
    let a2 = w.norm_squared();
    let a = a2.sqrt();
    let (c1, c2) = if a < 1e-4 {
        (0.5 - a2 / 24.0, 1.0 / 6.0 - a2 / 120.0)
    } else {
        ((1.0 - a.cos()) / a2, (a - a.sin()) / (a2 * a))
    };
    let k = so3::hat(w);
    Matrix3::identity() - k * c1 + k * k * c2
}

impl Shake {
    /// Builds the trajectory; fails when a parameter is out of range.
    pub fn new(params: &ShakeParams) -> Result<Self, AmcError> {
        params.validate()?;
        let (lo, hi) = params.band_hz;
        let mut rng = SplitMix64(params.seed);
        let mut axes = [[Component {
            amp: 0.0,
            omega: 0.0,
            phase: 0.0,
        }; COMPONENTS]; 3];
        let step = (hi - lo) / COMPONENTS as f64;
        for axis in axes.iter_mut() {
            for (k, c) in axis.iter_mut().enumerate() {
                let f = lo + step * (k as f64 + rng.next_f64());
                c.omega = 2.0 * PI * f;
                c.phase = 2.0 * PI * rng.next_f64();
                c.amp = 0.5 + 0.5 * rng.next_f64();
            }
        }
        let mut shake = Shake {
            params: params.clone(),
            axes,
            pan: params.pan_dps.to_radians(),
            r0_inv: Rot::identity(),
        };
        let target = params.shake_dps.to_radians();
        if target > 0.0 {
            // Small-angle estimate: E|theta'|^2 = sum_ik (a_ik w_ik)^2 / 2.
            let ms: f64 = shake
                .axes
                .iter()
                .flatten()
                .map(|c| (c.amp * c.omega).powi(2) / 2.0)
                .sum();
            shake.scale_amplitudes(target / ms.sqrt());
            for _ in 0..3 {
                let measured = shake.calibration_rms();
                if measured > 0.0 && measured.is_finite() {
                    shake.scale_amplitudes(target / measured);
                }
            }
        } else {
            shake.scale_amplitudes(0.0);
        }
        shake.r0_inv = shake.absolute(0.0).inverse();
        Ok(shake)
    }

    /// The parameters this trajectory was built from.
    pub fn params(&self) -> &ShakeParams {
        &self.params
    }

    fn scale_amplitudes(&mut self, s: f64) {
        for c in self.axes.iter_mut().flatten() {
            c.amp *= s;
        }
    }

    /// RMS of the shake part of the body rate on the calibration grid, rad/s.
    fn calibration_rms(&self) -> f64 {
        let n = (CALIBRATION_SECONDS * CALIBRATION_RATE_HZ) as usize;
        let mut sum = 0.0;
        for i in 0..n {
            let t = i as f64 / CALIBRATION_RATE_HZ;
            let (theta, dtheta) = self.theta_and_rate(t);
            sum += (right_jacobian(&theta) * dtheta).norm_squared();
        }
        (sum / n as f64).sqrt()
    }

    /// The shake angle vector `theta(t)` and its time derivative.
    fn theta_and_rate(&self, t: f64) -> (Tangent, Tangent) {
        let mut th = [0.0; 3];
        let mut dth = [0.0; 3];
        for (i, axis) in self.axes.iter().enumerate() {
            for c in axis {
                let (s, co) = (c.omega * t + c.phase).sin_cos();
                th[i] += c.amp * s;
                dth[i] += c.amp * c.omega * co;
            }
        }
        (Tangent::from(th), Tangent::from(dth))
    }

    /// The shake angle vector `theta(t)`, radians (without the pan).
    pub fn theta_at(&self, t: f64) -> Tangent {
        self.theta_and_rate(t).0
    }

    /// `A(t) = exp(p t e_y) exp(theta(t))`, not relative to the first frame.
    fn absolute(&self, t: f64) -> Rot {
        let pan = so3::exp(&Tangent::new(0.0, self.pan * t, 0.0));
        pan * so3::exp(&self.theta_at(t))
    }

    /// `R_{0}(t) = A(0)^T A(t)`: maps camera vectors at time `t` into the
    /// coordinates of the camera at `t = 0` (the world). Identity at `t = 0`.
    pub fn orientation_at(&self, t: f64) -> Rot {
        self.r0_inv * self.absolute(t)
    }

    /// Body angular velocity at `t` (rad/s, in the camera's own frame at `t`),
    /// pan included: `R(t)^T R(t + h) ~ exp(omega h)`.
    pub fn angular_velocity_at(&self, t: f64) -> Vector3<f64> {
        let (theta, dtheta) = self.theta_and_rate(t);
        let shake = right_jacobian(&theta) * dtheta;
        let pan = so3::exp(&theta).inverse() * Tangent::new(0.0, self.pan, 0.0);
        shake + pan
    }
}

/// Box-filters a panorama by `factor` in both directions (`factor <= 1` copies).
///
/// The output is `round(W / factor) x round(H / factor)` (at least 1x1) and each
/// output pixel is the area-weighted mean of the source pixels under its
/// footprint, so the output still spans the full sphere and the equirectangular
/// mapping is preserved even when `factor` does not divide the size. The output
/// has the input's pixel format.
pub fn downsample_pano(pano: &FrameRef<'_>, factor: usize) -> Frame {
    let ch = pano.format.channels();
    let expected = pano.width * pano.height * ch;
    if factor <= 1 || pano.width == 0 || pano.height == 0 || pano.data.len() != expected {
        return Frame {
            width: pano.width,
            height: pano.height,
            format: pano.format,
            data: pano.data.to_vec(),
        };
    }
    let ow = ((pano.width as f64 / factor as f64).round() as usize).max(1);
    let oh = ((pano.height as f64 / factor as f64).round() as usize).max(1);
    let wx = box_weights(pano.width, ow);
    let wy = box_weights(pano.height, oh);
    // Horizontal pass: pano.height x ow x ch.
    let mut tmp = vec![0f32; pano.height * ow * ch];
    for y in 0..pano.height {
        let src = &pano.data[y * pano.width * ch..(y + 1) * pano.width * ch];
        let dst = &mut tmp[y * ow * ch..(y + 1) * ow * ch];
        for (ox, taps) in wx.iter().enumerate() {
            for &(sx, w) in taps {
                for c in 0..ch {
                    dst[ox * ch + c] += w * src[sx * ch + c] as f32;
                }
            }
        }
    }
    // Vertical pass.
    let mut out = Frame::new(ow, oh, pano.format);
    let mut acc = vec![0f32; ow * ch];
    for (oy, taps) in wy.iter().enumerate() {
        acc.iter_mut().for_each(|a| *a = 0.0);
        for &(sy, w) in taps {
            let row = &tmp[sy * ow * ch..(sy + 1) * ow * ch];
            for (a, &v) in acc.iter_mut().zip(row) {
                *a += w * v;
            }
        }
        let dst = &mut out.data[oy * ow * ch..(oy + 1) * ow * ch];
        for (d, &a) in dst.iter_mut().zip(&acc) {
            *d = a.round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

/// For each of `m` output cells spanning `n` input pixels, the (input index,
/// weight) pairs of the area-weighted box filter; weights sum to 1.
fn box_weights(n: usize, m: usize) -> Vec<Vec<(usize, f32)>> {
    let scale = n as f64 / m as f64;
    (0..m)
        .map(|i| {
            let a = i as f64 * scale;
            let b = (i + 1) as f64 * scale;
            let first = a.floor() as usize;
            let last = ((b.ceil() as usize).min(n)).max(first + 1);
            (first..last)
                .filter_map(|s| {
                    let overlap = (b.min(s as f64 + 1.0) - a.max(s as f64)).max(0.0);
                    (overlap > 1e-12).then(|| (s, (overlap / scale) as f32))
                })
                .collect()
        })
        .collect()
}

/// The box-filter factor that brings a panorama `pano_width` pixels wide
/// (360 degrees) to about the camera's angular resolution at its centre:
/// `floor((pano_width / 2 pi) / fx)`, at least 1.
pub fn pano_downsample_factor(pano_width: usize, camera: &CameraModel) -> usize {
    let pano_px_per_rad = pano_width as f64 / (2.0 * PI);
    let f = camera.fx.abs().max(camera.fy.abs());
    if !(f > 0.0 && f.is_finite()) {
        return 1;
    }
    ((pano_px_per_rad / f).floor() as usize).max(1)
}

/// Renders views of an equirectangular panorama through a fixed camera.
///
/// The camera's sub-pixel rays are unprojected once, in [`EquirectRenderer::new`];
/// each frame then costs one rotation, two `atan2` and one bilinear lookup per
/// sub-sample.
#[derive(Clone, Debug)]
pub struct EquirectRenderer {
    width: usize,
    height: usize,
    supersample: usize,
    /// Unit rays (structure of arrays, so the per-frame loop vectorises),
    /// `supersample^2` per pixel, pixels row-major; NaN where the camera cannot
    /// unproject the sub-pixel.
    rx: Vec<f32>,
    ry: Vec<f32>,
    rz: Vec<f32>,
}

impl EquirectRenderer {
    /// Largest supported supersampling factor (per axis).
    pub const MAX_SUPERSAMPLE: usize = 8;

    /// Precomputes the camera's rays with `supersample x supersample` sub-pixels
    /// per pixel (`1..=8`).
    pub fn new(camera: &CameraModel, supersample: usize) -> Result<Self, AmcError> {
        if supersample == 0 || supersample > Self::MAX_SUPERSAMPLE {
            return Err(AmcError::invalid("supersample", supersample, "1 to 8"));
        }
        let (w, h) = (camera.width, camera.height);
        if w == 0 || h == 0 {
            return Err(AmcError::EmptyFrame {
                width: w,
                height: h,
            });
        }
        let n = w
            .checked_mul(h)
            .and_then(|p| p.checked_mul(supersample * supersample))
            .filter(|&n| n <= 1 << 26)
            .ok_or(AmcError::FrameTooLarge {
                width: w,
                height: h,
            })?;
        let offsets: Vec<f64> = (0..supersample)
            .map(|i| (i as f64 + 0.5) / supersample as f64 - 0.5)
            .collect();
        let mut rx = Vec::with_capacity(n);
        let mut ry = Vec::with_capacity(n);
        let mut rz = Vec::with_capacity(n);
        for v in 0..h {
            for u in 0..w {
                for dy in &offsets {
                    for dx in &offsets {
                        let px = Vector2::new(u as f64 + dx, v as f64 + dy);
                        let ray = camera
                            .unproject(&px)
                            .map(|r| r.normalize())
                            .filter(|r| r.iter().all(|c| c.is_finite()));
                        let r = match ray {
                            Some(r) => [r.x as f32, r.y as f32, r.z as f32],
                            None => [f32::NAN; 3],
                        };
                        rx.push(r[0]);
                        ry.push(r[1]);
                        rz.push(r[2]);
                    }
                }
            }
        }
        Ok(Self {
            width: w,
            height: h,
            supersample,
            rx,
            ry,
            rz,
        })
    }

    /// Output width, pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Output height, pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Sub-pixels per axis.
    pub fn supersample(&self) -> usize {
        self.supersample
    }

    /// Renders with one orientation `R_{0}` (camera to world) for the whole frame.
    pub fn render_into(
        &self,
        pano: &FrameRef<'_>,
        r_world_cam: &Rot,
        out: &mut Frame,
    ) -> Result<(), AmcError> {
        self.render_rolling_into(pano, &|_| *r_world_cam, out)
    }

    /// Renders with a rolling shutter: `orientation(s)` is `R_{0}` at the
    /// exposure of the row at readout fraction `s = v / height - 1/2`
    /// ([`row_fraction`](crate::shutter::row_fraction): `-1/2` for the first
    /// row, `0` for row `height / 2`, `1/2 - 1/height` for the last), so
    /// `orientation(0)` is the frame's mid-readout pose.
    ///
    /// `out` is resized to the camera's size; its pixel format is kept (alpha is
    /// written as 255).
    pub fn render_rolling_into(
        &self,
        pano: &FrameRef<'_>,
        orientation: &dyn Fn(f64) -> Rot,
        out: &mut Frame,
    ) -> Result<(), AmcError> {
        let pano = FrameRef::new(pano.width, pano.height, pano.format, pano.data)?;
        let och = out.format.channels();
        out.width = self.width;
        out.height = self.height;
        out.data.resize(self.width * self.height * och, 0);
        let pch = pano.format.channels();
        let (pw, ph) = (pano.width, pano.height);
        let sampler = Sampler {
            data: pano.data,
            width: pw,
            height: ph,
            channels: pch,
            u_scale: (pw as f64 / (2.0 * PI)) as f32,
            u_offset: (0.5 * pw as f64 - 0.5) as f32,
            v_scale: (ph as f64 / PI) as f32,
            v_offset: (0.5 * ph as f64 - 0.5) as f32,
        };
        let ss2 = self.supersample * self.supersample;
        let norm = 1.0 / ss2 as f32;
        let mut us = vec![0f32; self.width * ss2];
        let mut vs = vec![0f32; self.width * ss2];
        for v in 0..self.height {
            let r = orientation(crate::shutter::row_fraction(v as f64, self.height));
            let m = r.matrix();
            let m: [[f32; 3]; 3] =
                std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)] as f32));
            let row = v * self.width * ss2..(v + 1) * self.width * ss2;
            let (rx, ry, rz) = (&self.rx[row.clone()], &self.ry[row.clone()], &self.rz[row]);
            // Pass 1 (branch-free, vectorisable): panorama coordinates of every sub-ray.
            for ((((&dx, &dy), &dz), u), w) in rx
                .iter()
                .zip(ry)
                .zip(rz)
                .zip(us.iter_mut())
                .zip(vs.iter_mut())
            {
                let x = m[0][0] * dx + m[0][1] * dy + m[0][2] * dz;
                let y = m[1][0] * dx + m[1][1] * dy + m[1][2] * dz;
                let z = m[2][0] * dx + m[2][1] * dy + m[2][2] * dz;
                let lon = atan2_fast(x, z);
                let lat = atan2_fast(-y, (x * x + z * z).sqrt());
                *u = lon * sampler.u_scale + sampler.u_offset;
                *w = sampler.v_offset - lat * sampler.v_scale;
            }
            // Pass 2: bilinear lookups, averaged per pixel.
            let row_out = &mut out.data[v * self.width * och..(v + 1) * self.width * och];
            for (((px_rx, px_u), px_v), px_out) in rx
                .chunks_exact(ss2)
                .zip(us.chunks_exact(ss2))
                .zip(vs.chunks_exact(ss2))
                .zip(row_out.chunks_exact_mut(och))
            {
                let mut acc = [0f32; 3];
                for ((d, &u), &w) in px_rx.iter().zip(px_u).zip(px_v) {
                    if d.is_nan() {
                        continue;
                    }
                    let c = sampler.sample(u, w);
                    acc[0] += c[0];
                    acc[1] += c[1];
                    acc[2] += c[2];
                }
                for c in 0..3 {
                    px_out[c] = (acc[c] * norm + 0.5) as u8; // round; `as` saturates
                }
                if och == 4 {
                    px_out[3] = 255;
                }
            }
        }
        Ok(())
    }
}

/// Bilinear lookup into an equirectangular panorama.
struct Sampler<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    channels: usize,
    u_scale: f32,
    u_offset: f32,
    v_scale: f32,
    v_offset: f32,
}

impl Sampler<'_> {
    #[inline]
    fn sample(&self, u: f32, v: f32) -> [f32; 3] {
        // u is in [-0.5, W - 0.5] for a longitude in [-pi, pi]; wrap anything.
        // (Truncating casts instead of floor: floorf is a libm call on baseline x86-64.)
        let w = self.width;
        let ui = (u + 1.0) as i64 - 1; // floor(u) for u > -1
        let fu = u - ui as f32;
        let u0 = if ui >= 0 && (ui as usize) < w {
            ui as usize
        } else {
            ui.rem_euclid(w as i64) as usize
        };
        let u1 = if u0 + 1 == w { 0 } else { u0 + 1 };
        let vmax = (self.height - 1) as f32;
        let vc = v.clamp(0.0, vmax);
        let v0 = vc as usize; // floor, vc >= 0
        let fv = vc - v0 as f32;
        let v1 = (v0 + 1).min(self.height - 1);
        let ch = self.channels;
        let stride = self.width * ch;
        let (u0, u1) = (u0 * ch, u1 * ch);
        let r0 = &self.data[v0 * stride..v0 * stride + stride];
        let r1 = &self.data[v1 * stride..v1 * stride + stride];
        let w00 = (1.0 - fu) * (1.0 - fv);
        let w01 = fu * (1.0 - fv);
        let w10 = (1.0 - fu) * fv;
        let w11 = fu * fv;
        std::array::from_fn(|c| {
            w00 * r0[u0 + c] as f32
                + w01 * r0[u1 + c] as f32
                + w10 * r1[u0 + c] as f32
                + w11 * r1[u1 + c] as f32
        })
    }
}

/// `atan2(y, x)` in `f32` with an absolute error below `5e-7` rad (3e-5
/// degrees): octant reduction to `a = min/max in [0, 1]`, then the degree-15
/// odd minimax polynomial `atan(a) ~ a P(a^2)` (error 4e-8, cf. Abramowitz &
/// Stegun 4.4.49). Several times faster than `f32::atan2`.
#[inline]
fn atan2_fast(y: f32, x: f32) -> f32 {
    const C: [f32; 8] = [
        0.999_999_34,
        -0.333_298_66,
        0.199_466_15,
        -0.139_088_6,
        0.096_427_51,
        -0.055_919_47,
        0.021_867_664,
        -0.004_055_81,
    ];
    let (ax, ay) = (x.abs(), y.abs());
    // Branch-free (selects only) so loops over it vectorise; 0 at the origin.
    let a = ax.min(ay) / ax.max(ay).max(f32::MIN_POSITIVE);
    let s = a * a;
    let p = C[7];
    let p = p * s + C[6];
    let p = p * s + C[5];
    let p = p * s + C[4];
    let p = p * s + C[3];
    let p = p * s + C[2];
    let p = p * s + C[1];
    let p = p * s + C[0];
    let r = a * p;
    let r = if ay > ax {
        std::f32::consts::FRAC_PI_2 - r
    } else {
        r
    };
    let r = if x < 0.0 { std::f32::consts::PI - r } else { r };
    r.copysign(y)
}

/// One-shot convenience: renders a single view with orientation `r_world_cam`
/// (no rolling shutter) into a new RGB8 frame.
pub fn render_equirect(
    pano: &FrameRef<'_>,
    camera: &CameraModel,
    r_world_cam: &Rot,
    supersample: usize,
) -> Result<Frame, AmcError> {
    let renderer = EquirectRenderer::new(camera, supersample)?;
    let mut out = Frame::new(camera.width, camera.height, PixelFormat::Rgb8);
    renderer.render_into(pano, r_world_cam, &mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn finite_difference_rms(shake: &Shake, rate_hz: f64, seconds: f64) -> (Vec<Tangent>, f64) {
        let h = 1.0 / rate_hz;
        let n = (seconds * rate_hz) as usize;
        let mut prev = shake.orientation_at(0.0);
        let mut rates = Vec::with_capacity(n);
        let mut sum = 0.0;
        for i in 1..=n {
            let cur = shake.orientation_at(i as f64 * h);
            let w = so3::body_rate(&prev, &cur, h);
            sum += w.norm_squared();
            rates.push(w);
            prev = cur;
        }
        (rates, (sum / n as f64).sqrt())
    }

    #[test]
    fn fast_atan2_is_accurate() {
        let mut rng = SplitMix64(1);
        let mut worst = 0f64;
        for i in 0..200_000 {
            let (y, x) = if i < 8 {
                [
                    (0.0, 1.0),
                    (1.0, 0.0),
                    (0.0, -1.0),
                    (-1.0, 0.0),
                    (1.0, 1.0),
                    (-1.0, -1.0),
                    (2.0, -1.0),
                    (0.0, 0.0),
                ][i]
            } else {
                (rng.next_f64() * 2.0 - 1.0, rng.next_f64() * 2.0 - 1.0)
            };
            let (yf, xf) = (y as f32, x as f32);
            let exact = (yf as f64).atan2(xf as f64);
            let err = (atan2_fast(yf, xf) as f64 - exact).abs();
            worst = worst.max(err.min(2.0 * PI - err));
        }
        assert!(worst < 5e-7, "worst atan2 error {worst}");
    }

    #[test]
    fn params_validation() {
        assert!(ShakeParams::default().validate().is_ok());
        let bad = [
            ShakeParams {
                shake_dps: -1.0,
                ..Default::default()
            },
            ShakeParams {
                shake_dps: 2000.5,
                ..Default::default()
            },
            ShakeParams {
                shake_dps: f64::NAN,
                ..Default::default()
            },
            ShakeParams {
                band_hz: (0.0, 20.0),
                ..Default::default()
            },
            ShakeParams {
                band_hz: (20.0, 12.0),
                ..Default::default()
            },
            ShakeParams {
                band_hz: (12.0, 1001.0),
                ..Default::default()
            },
            ShakeParams {
                pan_dps: f64::INFINITY,
                ..Default::default()
            },
        ];
        for p in bad {
            assert!(
                matches!(p.validate(), Err(AmcError::InvalidParameter { .. })),
                "{p:?}"
            );
            assert!(Shake::new(&p).is_err());
        }
    }

    #[test]
    fn rms_speed_matches_target() {
        for (dps, band, seed) in [
            (100.0, (12.0, 20.0), 0),
            (400.0, (5.0, 9.0), 7),
            (30.0, (40.0, 60.0), 3),
        ] {
            let shake = Shake::new(&ShakeParams {
                shake_dps: dps,
                band_hz: band,
                seed,
                pan_dps: 0.0,
            })
            .unwrap();
            let (_, rms) = finite_difference_rms(&shake, 1000.0, 10.0);
            let rel = (rms.to_degrees() - dps).abs() / dps;
            assert!(
                rel < 0.03,
                "dps {dps}: measured {} ({rel})",
                rms.to_degrees()
            );
        }
    }

    #[test]
    fn zero_shake_is_identity_and_pan_turns_right() {
        let shake = Shake::new(&ShakeParams {
            shake_dps: 0.0,
            pan_dps: 10.0,
            ..Default::default()
        })
        .unwrap();
        let r = shake.orientation_at(2.0);
        // Camera z (forward) turned toward +x by 20 degrees.
        let fwd = r * Vector3::z();
        assert!((fwd.x.atan2(fwd.z).to_degrees() - 20.0).abs() < 1e-9);
        let w = shake.angular_velocity_at(1.0);
        assert!((w - Vector3::new(0.0, 10f64.to_radians(), 0.0)).norm() < 1e-12);
    }

    #[test]
    fn spectrum_lies_in_band() {
        let (lo, hi) = (12.0, 20.0);
        let shake = Shake::new(&ShakeParams {
            band_hz: (lo, hi),
            seed: 11,
            ..Default::default()
        })
        .unwrap();
        let rate = 1000.0;
        let (rates, _) = finite_difference_rms(&shake, rate, 10.0);
        let win = (rate / lo).round() as usize;
        for axis in 0..3 {
            let x: Vec<f64> = rates.iter().map(|w| w[axis]).collect();
            let ms: f64 = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
            // Moving average over 1/lo seconds removes everything in the band.
            let mut lp = 0.0;
            let mut count = 0;
            let mut s: f64 = x[..win].iter().sum();
            for i in win..x.len() {
                lp += (s / win as f64).powi(2);
                count += 1;
                s += x[i] - x[i - win];
            }
            let ratio = (lp / count as f64 / ms).sqrt();
            assert!(ratio < 0.3, "axis {axis}: low-pass ratio {ratio}");
            // Hann-windowed DFT: nearly all power within [lo - 2, hi + 2] Hz.
            let n = x.len();
            let xw: Vec<f64> = x
                .iter()
                .enumerate()
                .map(|(i, v)| v * (0.5 - 0.5 * (2.0 * PI * i as f64 / n as f64).cos()))
                .collect();
            let total: f64 = xw.iter().map(|v| v * v).sum::<f64>() * n as f64;
            let df = rate / n as f64;
            let k0 = ((lo - 2.0) / df).floor() as usize;
            let k1 = ((hi + 2.0) / df).ceil() as usize;
            let mut band = 0.0;
            for k in k0..=k1 {
                let (mut re, mut im) = (0.0, 0.0);
                for (i, v) in xw.iter().enumerate() {
                    let (s, c) = (2.0 * PI * (k * i) as f64 / n as f64).sin_cos();
                    re += v * c;
                    im -= v * s;
                }
                band += 2.0 * (re * re + im * im);
            }
            let frac = band / total;
            assert!(frac > 0.97, "axis {axis}: in-band power fraction {frac}");
        }
    }

    #[test]
    fn deterministic_and_seed_dependent() {
        let p = ShakeParams {
            seed: 42,
            ..Default::default()
        };
        let a = Shake::new(&p).unwrap();
        let b = Shake::new(&p).unwrap();
        let c = Shake::new(&ShakeParams {
            seed: 43,
            ..p.clone()
        })
        .unwrap();
        for t in [0.1, 1.234, 9.9] {
            assert_eq!(a.orientation_at(t), b.orientation_at(t));
            assert!(so3::angle_between(&a.orientation_at(t), &c.orientation_at(t)) > 1e-6);
        }
    }

    #[test]
    fn first_orientation_is_identity() {
        let shake = Shake::new(&ShakeParams {
            pan_dps: 5.0,
            seed: 9,
            ..Default::default()
        })
        .unwrap();
        assert!(so3::angle_between(&shake.orientation_at(0.0), &Rot::identity()) < 1e-14);
        // Amplitudes are small: a few degrees at most.
        let max = (0..1000)
            .map(|i| shake.theta_at(i as f64 * 0.01).norm().to_degrees())
            .fold(0.0, f64::max);
        assert!(max > 0.1 && max < 10.0, "max shake angle {max} deg");
    }

    #[test]
    fn angular_velocity_matches_finite_differences() {
        let shake = Shake::new(&ShakeParams {
            shake_dps: 800.0,
            pan_dps: 30.0,
            seed: 5,
            ..Default::default()
        })
        .unwrap();
        let h = 1e-6;
        for t in [0.0, 0.37, 2.5, 7.77] {
            let fd = so3::body_rate(
                &shake.orientation_at(t - h),
                &shake.orientation_at(t + h),
                2.0 * h,
            );
            let w = shake.angular_velocity_at(t);
            assert!(
                (fd - w).norm() < 1e-5 * w.norm().max(1.0),
                "t {t}: {fd:?} vs {w:?}"
            );
        }
    }

    /// A 256x128 panorama with red = u and green = 2 v (exact linear ramps, so
    /// bilinear sampling returns the sampled coordinates away from the seam).
    fn coded_pano() -> Frame {
        let (w, h) = (256, 128);
        let mut f = Frame::new(w, h, PixelFormat::Rgb8);
        for v in 0..h {
            for u in 0..w {
                let i = (v * w + u) * 3;
                f.data[i] = u as u8;
                f.data[i + 1] = (2 * v) as u8;
                f.data[i + 2] = 128;
            }
        }
        f
    }

    /// A smooth panorama: red = 128 + 100 sin(lon), green = 128 + 100 sin(lat).
    fn smooth_pano(w: usize, h: usize) -> Frame {
        let mut f = Frame::new(w, h, PixelFormat::Rgb8);
        for v in 0..h {
            let lat = (0.5 - (v as f64 + 0.5) / h as f64) * PI;
            for u in 0..w {
                let lon = ((u as f64 + 0.5) / w as f64 - 0.5) * 2.0 * PI;
                let i = (v * w + u) * 3;
                f.data[i] = (128.0 + 100.0 * lon.sin()).round() as u8;
                f.data[i + 1] = (128.0 + 100.0 * lat.sin()).round() as u8;
                f.data[i + 2] = 50;
            }
        }
        f
    }

    fn decode_lon_lat(px: &[u8]) -> (f64, f64) {
        let lon = (px[0] as f64 - 128.0) / 100.0;
        let lat = (px[1] as f64 - 128.0) / 100.0;
        (lon.asin().to_degrees(), lat.asin().to_degrees())
    }

    #[test]
    fn centre_pixel_looks_forward_and_yaw_turns_right() {
        let pano = smooth_pano(720, 360);
        // Odd size so a pixel sits exactly on the optical axis.
        let cam = CameraModel::pinhole_hfov(33, 21, 60.0).unwrap();
        let ren = EquirectRenderer::new(&cam, 2).unwrap();
        let mut out = Frame::new(1, 1, PixelFormat::Rgb8);
        let centre = (10 * 33 + 16) * 3;

        ren.render_into(&pano.as_ref(), &Rot::identity(), &mut out)
            .unwrap();
        assert_eq!((out.width, out.height), (33, 21));
        let (lon, lat) = decode_lon_lat(&out.data[centre..centre + 3]);
        assert!(lon.abs() < 0.7 && lat.abs() < 0.7, "lon {lon} lat {lat}");

        let yaw = so3::exp(&Tangent::new(0.0, 10f64.to_radians(), 0.0));
        ren.render_into(&pano.as_ref(), &yaw, &mut out).unwrap();
        let (lon, lat) = decode_lon_lat(&out.data[centre..centre + 3]);
        assert!(
            (lon - 10.0).abs() < 0.7 && lat.abs() < 0.7,
            "lon {lon} lat {lat}"
        );

        // Pitch: exp(+a x) turns z toward -y (up), so the centre sees lat +a.
        let pitch = so3::exp(&Tangent::new(8f64.to_radians(), 0.0, 0.0));
        ren.render_into(&pano.as_ref(), &pitch, &mut out).unwrap();
        let (lon, lat) = decode_lon_lat(&out.data[centre..centre + 3]);
        assert!(
            lon.abs() < 0.7 && (lat - 8.0).abs() < 0.7,
            "lon {lon} lat {lat}"
        );

        // Content moves left when the camera turns right: what the centre showed
        // before (lon 0) is now about fx * tan(10 deg) pixels to the left.
        ren.render_into(&pano.as_ref(), &yaw, &mut out).unwrap();
        let u = (16.0 - cam.fx * 10f64.to_radians().tan()).round() as usize;
        let i = (10 * 33 + u) * 3;
        let (lon, _) = decode_lon_lat(&out.data[i..i + 3]);
        assert!(lon.abs() < 1.0, "lon {lon} at u {u}");
    }

    #[test]
    fn coded_pano_pixel_accuracy() {
        // The centre pixel samples exactly the (u, v) of the module equations.
        let pano = coded_pano();
        let cam = CameraModel::pinhole_hfov(31, 31, 40.0).unwrap();
        let ren = EquirectRenderer::new(&cam, 1).unwrap();
        let mut out = Frame::new(31, 31, PixelFormat::Rgb8);
        let i = (15 * 31 + 15) * 3;
        for (yaw, pitch) in [(0.0f64, 0.0f64), (40.0, 0.0), (-70.0, 10.0), (25.0, -33.0)] {
            // Yaw about world y, then pitch about the camera's x.
            let r = so3::exp(&Tangent::new(0.0, yaw.to_radians(), 0.0))
                * so3::exp(&Tangent::new(pitch.to_radians(), 0.0, 0.0));
            ren.render_into(&pano.as_ref(), &r, &mut out).unwrap();
            let u = (yaw / 360.0 + 0.5) * 256.0 - 0.5;
            let v = (0.5 - pitch / 180.0) * 128.0 - 0.5;
            assert!(
                (out.data[i] as f64 - u).abs() <= 0.51,
                "{yaw},{pitch}: red {} vs u {u}",
                out.data[i]
            );
            assert!(
                (out.data[i + 1] as f64 - 2.0 * v).abs() <= 0.51,
                "{yaw},{pitch}: green {} vs 2v {}",
                out.data[i + 1],
                2.0 * v
            );
        }
    }

    #[test]
    fn rolling_shutter_rows_use_their_own_orientation() {
        let pano = smooth_pano(720, 360);
        let cam = CameraModel::pinhole_hfov(21, 11, 30.0).unwrap();
        let ren = EquirectRenderer::new(&cam, 1).unwrap();
        let mut out = Frame::new(1, 1, PixelFormat::Rgba8);
        // Yaw 11 degrees per readout: -5.5 at the first row (s = -1/2),
        // 11 (v / 11 - 1/2) at row v.
        let orient = |s: f64| so3::exp(&Tangent::new(0.0, (11.0 * s).to_radians(), 0.0));
        ren.render_rolling_into(&pano.as_ref(), &orient, &mut out)
            .unwrap();
        assert_eq!(out.data.len(), 21 * 11 * 4);
        let px = |v: usize| &out.data[(v * 21 + 10) * 4..(v * 21 + 10) * 4 + 4];
        let (lon_top, _) = decode_lon_lat(px(0));
        let (lon_mid, _) = decode_lon_lat(px(5));
        let (lon_bot, _) = decode_lon_lat(px(10));
        assert!((lon_top + 5.5).abs() < 0.6, "{lon_top}");
        assert!((lon_mid + 0.5).abs() < 0.6, "{lon_mid}");
        assert!((lon_bot - 4.5).abs() < 0.6, "{lon_bot}");
        assert_eq!(px(0)[3], 255);
    }

    /// The ground truth of a rolling-shutter frame is its mid-readout pose:
    /// row `H / 2` of a frame rendered at `t` is the global-shutter render of
    /// the orientation at `t`, whatever the motion during the readout.
    #[test]
    fn rolling_shutter_middle_row_is_the_global_shutter_render() {
        let pano = smooth_pano(720, 360);
        let cam = CameraModel::pinhole_hfov(24, 16, 40.0).unwrap();
        let ren = EquirectRenderer::new(&cam, 2).unwrap();
        let shake = Shake::new(&ShakeParams {
            shake_dps: 300.0,
            ..ShakeParams::default()
        })
        .unwrap();
        let (t, readout) = (0.37, 0.02);
        let mut rolling = Frame::new(1, 1, PixelFormat::Rgb8);
        ren.render_rolling_into(
            &pano.as_ref(),
            &|s| shake.orientation_at(t + readout * s),
            &mut rolling,
        )
        .unwrap();
        let mut global = Frame::new(1, 1, PixelFormat::Rgb8);
        ren.render_into(&pano.as_ref(), &shake.orientation_at(t), &mut global)
            .unwrap();
        let row = |f: &Frame, v: usize| f.data[v * 24 * 3..(v + 1) * 24 * 3].to_vec();
        assert_eq!(row(&rolling, 8), row(&global, 8));
        // The motion during the readout shows away from the middle.
        assert_ne!(row(&rolling, 0), row(&global, 0));
        assert_ne!(row(&rolling, 15), row(&global, 15));
    }

    #[test]
    fn invalid_rays_are_black_and_bad_inputs_error() {
        let pano = smooth_pano(64, 32);
        let cam = CameraModel::pinhole_hfov(8, 6, 60.0).unwrap();
        assert!(EquirectRenderer::new(&cam, 0).is_err());
        assert!(EquirectRenderer::new(&cam, 9).is_err());
        let mut ren = EquirectRenderer::new(&cam, 1).unwrap();
        ren.rx[0] = f32::NAN;
        let mut out = Frame::new(8, 6, PixelFormat::Rgb8);
        ren.render_into(&pano.as_ref(), &Rot::identity(), &mut out)
            .unwrap();
        assert_eq!(&out.data[..3], &[0, 0, 0]);
        assert!(out.data[3..6].iter().any(|&c| c > 0));
        let short = FrameRef {
            width: 64,
            height: 32,
            format: PixelFormat::Rgb8,
            data: &pano.data[..10],
        };
        assert!(ren.render_into(&short, &Rot::identity(), &mut out).is_err());
    }

    #[test]
    fn downsample_box_filter() {
        // 4x2 RGB, factor 2 -> 2x1, each the mean of a 2x2 block.
        let data: Vec<u8> = (0..24).map(|i| (i * 10) as u8).collect();
        let pano = FrameRef::new(4, 2, PixelFormat::Rgb8, &data).unwrap();
        let d = downsample_pano(&pano, 2);
        assert_eq!((d.width, d.height), (2, 1));
        // Block 0: pixels 0,1 (row 0) and 4,5 (row 1); red = (0+30+120+150)/4 = 75.
        assert_eq!(d.data[0], 75);
        assert_eq!(d.data[3], 135); // (60 + 90 + 180 + 210) / 4
                                    // Non-dividing factor keeps a full-sphere mapping and preserves a constant.
        let flat = vec![77u8; 10 * 5 * 4];
        let p = FrameRef::new(10, 5, PixelFormat::Rgba8, &flat).unwrap();
        let d = downsample_pano(&p, 3);
        assert_eq!((d.width, d.height, d.format), (3, 2, PixelFormat::Rgba8));
        assert!(d.data.iter().all(|&c| c == 77));
        assert_eq!(downsample_pano(&p, 1).data, flat);
        // Factor from the camera: 4096 px / 2 pi = 652 px/rad vs fx = 160 -> 4.
        let cam = CameraModel::pinhole_hfov(320, 180, 90.0).unwrap();
        assert_eq!(pano_downsample_factor(4096, &cam), 4);
        assert_eq!(pano_downsample_factor(100, &cam), 1);
    }
}
