//! Stabilization quality metrics, as the paper defines them.
//!
//! All on intensities in `[0, 1]`, counting only valid pixels (pixels that some
//! averaged frame covered; black borders never count). Gradients are the 3x3
//! Sobel operator divided by 8, i.e. a per-pixel derivative, and need all nine
//! neighbours valid.
//! ```text
//! normal flow      n(p) = -I_t(p) grad I(p) / |grad I(p)|^2,   |n| = |I_t| / |grad I|
//!                  over pixels valid in both frames with |grad I| >= 15/255,
//!                  I_t = I_j - I_{j-1} on luma, grad I of the current frame
//! RMS change       sqrt(mean (I_j - I_{j-1})^2)  on luma, pixels valid in both
//! sharpness        sqrt(mean over pixels and R,G,B of |grad C|^2)
//! valid share      share of output pixels covered by every averaged frame
//! angular speed    RMS over frames of |log(R_{j-1}^T R_j)| / dt, in deg/s
//! ```
//! Clip values pool the squares of all frames before the square root.

use crate::color::yuv420p_channel_row_into;
#[cfg(doc)]
use crate::color::yuv420p_to_rgb_into;
use crate::image::{y_to_unit, FrameRef, GrayImage, PixelFormat, LUMA_WEIGHTS};
use crate::lanes::lane_sum;
use crate::stabilizer::Telemetry;
use serde::{Deserialize, Serialize};

/// Gradient magnitude under which normal flow is not measured (paper: 15/255).
pub const NORMAL_FLOW_MIN_GRADIENT: f32 = 15.0 / 255.0;

/// Metrics of one output frame. `None` where undefined (first frame).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameMetrics {
    /// RMS normal flow against the previous output, pixels per frame.
    pub rms_normal_flow: Option<f64>,
    /// RMS luma change against the previous output, intensity units.
    pub rms_change: Option<f64>,
    /// RMS Sobel gradient magnitude over R, G, B.
    pub sharpness: f64,
    /// Share of pixels covered by every averaged frame.
    pub valid_fraction: f64,
}

/// Metrics of a whole clip.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClipMetrics {
    /// Output frames measured.
    pub frames: u64,
    /// RMS normal flow, pixels per frame.
    pub rms_normal_flow: f64,
    /// RMS luma change between consecutive outputs, intensity units `[0, 1]`.
    pub rms_change: f64,
    /// RMS Sobel gradient magnitude over R, G, B.
    pub sharpness: f64,
    /// Mean share of pixels covered by every averaged frame.
    pub valid_fraction: f64,
    /// Lowest per-frame share of fully covered pixels.
    pub min_valid_fraction: f64,
    /// RMS angular speed of the estimated camera orientation, deg/s.
    pub rms_speed_est_dps: f64,
    /// RMS angular speed of the view, deg/s.
    pub rms_speed_view_dps: f64,
    /// Number of saccades (saccade mode).
    pub saccades: u64,
}

/// What the telemetry alone says of a clip: no image work, so always affordable.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MotionSummary {
    /// Output frames counted.
    pub frames: u64,
    /// Mean share of pixels covered by every averaged frame.
    pub valid_fraction: f64,
    /// Lowest per-frame share of fully covered pixels.
    pub min_valid_fraction: f64,
    /// RMS angular speed of the estimated camera orientation, deg/s.
    pub rms_speed_est_dps: f64,
    /// RMS angular speed of the view, deg/s.
    pub rms_speed_view_dps: f64,
    /// Number of saccades (saccade mode).
    pub saccades: u64,
}

/// Accumulates a [`MotionSummary`] over a stream of outputs.
#[derive(Clone, Debug, Default)]
pub struct MotionAccumulator {
    frames: u64,
    valid_sum: f64,
    valid_min: f64,
    est_sq: f64,
    view_sq: f64,
    speed_n: u64,
    saccades: u64,
}

impl MotionAccumulator {
    /// Counts one output frame with its valid share and (if known) telemetry.
    pub fn push(&mut self, valid_fraction: f64, telemetry: Option<&Telemetry>) {
        self.valid_min = if self.frames == 0 {
            valid_fraction
        } else {
            self.valid_min.min(valid_fraction)
        };
        self.frames += 1;
        self.valid_sum += valid_fraction;
        if let Some(t) = telemetry {
            if t.frame > 0 {
                let sq = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>();
                self.est_sq += sq(t.rate_est);
                self.view_sq += sq(t.rate_view);
                self.speed_n += 1;
            }
            self.saccades += t.saccade as u64;
        }
    }

    /// The summary of the frames pushed so far (zeros when none).
    pub fn summary(&self) -> MotionSummary {
        let rms = |s: f64| {
            if self.speed_n > 0 {
                (s / self.speed_n as f64).sqrt().to_degrees()
            } else {
                0.0
            }
        };
        MotionSummary {
            frames: self.frames,
            valid_fraction: if self.frames > 0 {
                self.valid_sum / self.frames as f64
            } else {
                0.0
            },
            min_valid_fraction: if self.frames > 0 { self.valid_min } else { 0.0 },
            rms_speed_est_dps: rms(self.est_sq),
            rms_speed_view_dps: rms(self.view_sq),
            saccades: self.saccades,
        }
    }
}

/// Accumulates per-frame and per-clip metrics over a stream of outputs.
#[derive(Clone, Debug, Default)]
pub struct MetricsAccumulator {
    prev: GrayImage,
    cur: GrayImage,
    /// One row of squared gradients (reused).
    row: Vec<f32>,
    /// One row of one RGB channel of a planar frame (reused).
    channel_row: Vec<u8>,
    has_prev: bool,
    nf_sq: f64,
    nf_n: u64,
    ch_sq: f64,
    ch_n: u64,
    sh_sq: f64,
    sh_n: u64,
    motion: MotionAccumulator,
}

/// Luma of `frame` into `dst`, `NaN` where `coverage` is 0.
pub fn masked_luma_into(frame: &FrameRef<'_>, coverage: &[u8], dst: &mut GrayImage) {
    dst.resize(frame.width, frame.height);
    if frame.format == PixelFormat::Yuv420p {
        let (y, _, _) = frame.yuv_planes();
        for ((o, &v), &n) in dst.data.iter_mut().zip(y).zip(coverage) {
            *o = if n == 0 {
                f32::NAN
            } else {
                y_to_unit(v).clamp(0.0, 1.0)
            };
        }
        return;
    }
    let c = frame.format.channels();
    let k = LUMA_WEIGHTS.map(|w| w / 255.0);
    for ((o, px), &n) in dst
        .data
        .iter_mut()
        .zip(frame.data.chunks_exact(c))
        .zip(coverage)
    {
        *o = if n == 0 {
            f32::NAN
        } else {
            k[0] * px[0] as f32 + k[1] * px[1] as f32 + k[2] * px[2] as f32
        };
    }
}

/// `|Sobel / 8|^2` of the interior pixels of one row, from the rows above,
/// at and below it (all of width `w`), into `out` (`w - 2` values; `NaN`
/// where any neighbour is invalid). Written over equal-length slices so the
/// compiler vectorizes it.
fn sobel_sq_row(above: &[f32], row: &[f32], below: &[f32], out: &mut [f32]) {
    let n = out.len();
    let (a0, a1, a2) = (&above[..n], &above[1..n + 1], &above[2..n + 2]);
    let (l, r) = (&row[..n], &row[2..n + 2]);
    let (b0, b1, b2) = (&below[..n], &below[1..n + 1], &below[2..n + 2]);
    for i in 0..n {
        let gx = ((a2[i] + 2.0 * r[i] + b2[i]) - (a0[i] + 2.0 * l[i] + b0[i])) * 0.125;
        let gy = ((b0[i] + 2.0 * b1[i] + b2[i]) - (a0[i] + 2.0 * a1[i] + a2[i])) * 0.125;
        out[i] = gx * gx + gy * gy;
    }
}

/// Sum and count of the finite values of `v` (per row in `f32`, which holds
/// a row's sum to ~1e-7; rows are added in `f64`).
fn finite_sum(v: &[f32]) -> (f64, u64) {
    let (s, n) = lane_sum(v, v, v, |x, _, _| (x, x.is_finite()));
    (s as f64, n as u64)
}

/// Channel `ch` (0 R, 1 G, 2 B) of `frame` in [0, 1] into `chan` (resized),
/// `NaN` where `coverage` is 0. A planar frame is measured in the RGB a
/// player would show ([`yuv420p_to_rgb_into`]'s bytes), converted a row and
/// a channel at a time into `bytes` rather than into a packed copy.
fn channel_into(
    frame: &FrameRef<'_>,
    ch: usize,
    coverage: &[u8],
    chan: &mut GrayImage,
    bytes: &mut Vec<u8>,
) {
    let (w, h) = (frame.width, frame.height);
    chan.resize(w, h);
    let unit = |b: u8, cv: u8| if cv == 0 { f32::NAN } else { b as f32 / 255.0 };
    if frame.format.is_planar() {
        bytes.resize(w, 0);
        for (y, (o, cov)) in chan
            .data
            .chunks_exact_mut(w)
            .zip(coverage.chunks_exact(w))
            .enumerate()
        {
            yuv420p_channel_row_into(w, h, frame.data, ch, y, bytes);
            for ((o, &b), &cv) in o.iter_mut().zip(bytes.iter()).zip(cov) {
                *o = unit(b, cv);
            }
        }
        return;
    }
    let c = frame.format.channels();
    for ((o, px), &cv) in chan
        .data
        .iter_mut()
        .zip(frame.data.chunks_exact(c))
        .zip(coverage)
    {
        *o = unit(px[ch], cv);
    }
}

/// Sum of squared Sobel magnitudes over R, G, B and the number of terms.
fn sharpness_sums(
    frame: &FrameRef<'_>,
    coverage: &[u8],
    chan: &mut GrayImage,
    row: &mut Vec<f32>,
    bytes: &mut Vec<u8>,
) -> (f64, u64) {
    let (w, h) = (frame.width, frame.height);
    let (mut sum, mut n) = (0f64, 0u64);
    if w < 3 || h < 3 {
        return (sum, n);
    }
    row.resize(w - 2, 0.0);
    for ch in 0..3 {
        channel_into(frame, ch, coverage, chan, bytes);
        for v in 1..h - 1 {
            let d = &chan.data;
            sobel_sq_row(
                &d[(v - 1) * w..v * w],
                &d[v * w..(v + 1) * w],
                &d[(v + 1) * w..(v + 2) * w],
                row,
            );
            let (s, k) = finite_sum(row);
            sum += s;
            n += k;
        }
    }
    (sum, n)
}

impl MetricsAccumulator {
    /// A fresh accumulator.
    pub fn new() -> Self {
        Self::default()
    }

    /// Measures one output frame. `coverage` is the per-pixel count of averaged
    /// frames (0 = not valid); `telemetry` adds angular speeds.
    pub fn push(
        &mut self,
        frame: &FrameRef<'_>,
        coverage: &[u8],
        valid_fraction: f64,
        telemetry: Option<&Telemetry>,
    ) -> FrameMetrics {
        let (w, h) = (frame.width, frame.height);
        masked_luma_into(frame, coverage, &mut self.cur);
        let mut m = FrameMetrics {
            valid_fraction,
            ..Default::default()
        };
        let same_size = self.has_prev && self.prev.width == w && self.prev.height == h;
        if same_size {
            let (mut nf, mut nf_n, mut ch, mut ch_n) = (0f64, 0u64, 0f64, 0u64);
            let (cur, prev) = (&self.cur.data, &self.prev.data);
            let min_g2 = NORMAL_FLOW_MIN_GRADIENT * NORMAL_FLOW_MIN_GRADIENT;
            self.row.resize(w.saturating_sub(2), 0.0);
            for v in 0..h {
                let (c_row, p_row) = (&cur[v * w..(v + 1) * w], &prev[v * w..(v + 1) * w]);
                // Frame change over every pixel valid in both frames.
                let (s, k) = lane_sum(c_row, p_row, p_row, |a, b, _| {
                    let it = a - b;
                    (it * it, it.is_finite())
                });
                ch += s as f64;
                ch_n += k as u64;
                // Normal flow where the gradient (interior pixels, all nine
                // neighbours valid) is strong enough.
                if v == 0 || v + 1 == h || w < 3 {
                    continue;
                }
                sobel_sq_row(
                    &cur[(v - 1) * w..v * w],
                    c_row,
                    &cur[(v + 1) * w..(v + 2) * w],
                    &mut self.row,
                );
                let (c_in, p_in) = (&c_row[1..w - 1], &p_row[1..w - 1]);
                let (s, k) = lane_sum(&self.row, c_in, p_in, |g2, a, b| {
                    let it = a - b;
                    // NaN compares false: invalid pixels drop out here.
                    let ok = g2 >= min_g2 && it.is_finite() && g2.is_finite();
                    (it * it / g2, ok)
                });
                nf += s as f64;
                nf_n += k as u64;
            }
            if nf_n > 0 {
                m.rms_normal_flow = Some((nf / nf_n as f64).sqrt());
                self.nf_sq += nf;
                self.nf_n += nf_n;
            }
            if ch_n > 0 {
                m.rms_change = Some((ch / ch_n as f64).sqrt());
                self.ch_sq += ch;
                self.ch_n += ch_n;
            }
        }
        let mut chan = std::mem::take(&mut self.prev);
        // Sharpness is defined over R, G and B: a planar frame is measured in
        // the RGB a player would show.
        let (s, n) = sharpness_sums(
            frame,
            coverage,
            &mut chan,
            &mut self.row,
            &mut self.channel_row,
        );
        self.prev = chan;
        if n > 0 {
            m.sharpness = (s / n as f64).sqrt();
            self.sh_sq += s;
            self.sh_n += n;
        }
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.has_prev = true;
        self.motion.push(valid_fraction, telemetry);
        m
    }

    /// Metrics of everything pushed so far.
    pub fn summary(&self) -> ClipMetrics {
        let rms = |s: f64, n: u64| if n > 0 { (s / n as f64).sqrt() } else { 0.0 };
        let motion = self.motion.summary();
        ClipMetrics {
            frames: motion.frames,
            rms_normal_flow: rms(self.nf_sq, self.nf_n),
            rms_change: rms(self.ch_sq, self.ch_n),
            sharpness: rms(self.sh_sq, self.sh_n),
            valid_fraction: motion.valid_fraction,
            min_valid_fraction: motion.min_valid_fraction,
            rms_speed_est_dps: motion.rms_speed_est_dps,
            rms_speed_view_dps: motion.rms_speed_view_dps,
            saccades: motion.saccades,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Frame, PixelFormat};

    /// A horizontal ramp `I(u) = a u` shifted by `d` pixels has `I_t = -a d` and
    /// `|grad I| = a`: normal flow exactly `d`.
    #[test]
    fn pure_shift_has_known_normal_flow() {
        // Slope 20/255 per pixel: above the 15/255 gradient threshold.
        let (w, h) = (12, 16);
        let ramp = |shift: f32| {
            let mut f = Frame::new(w, h, PixelFormat::Rgb8);
            for v in 0..h {
                for u in 0..w {
                    let val = (20.0 * (u as f32 - shift) + 30.0).round() as u8;
                    f.data[3 * (v * w + u)..3 * (v * w + u) + 3].fill(val);
                }
            }
            f
        };
        let cov = vec![1u8; w * h];
        let mut acc = MetricsAccumulator::new();
        acc.push(&ramp(0.0).as_ref(), &cov, 1.0, None);
        let m = acc.push(&ramp(1.0).as_ref(), &cov, 1.0, None);
        let nf = m.rms_normal_flow.unwrap();
        assert!((nf - 1.0).abs() < 0.02, "normal flow {nf}");
        // Change: 20 levels of 255 per pixel, everywhere.
        assert!((m.rms_change.unwrap() - 20.0 / 255.0).abs() < 1e-4);
        // Sharpness: per-pixel derivative of 20/255 in x on all channels.
        assert!((m.sharpness - 20.0 / 255.0).abs() < 1e-4);
    }

    #[test]
    fn black_borders_never_count() {
        let (w, h) = (32, 32);
        let mut a = Frame::new(w, h, PixelFormat::Rgb8);
        let mut b = Frame::new(w, h, PixelFormat::Rgb8);
        a.data.fill(100);
        b.data.fill(100);
        let mut cov = vec![1u8; w * h];
        // A "border" that differs wildly but is marked invalid.
        for v in 0..h {
            for u in 0..4 {
                cov[v * w + u] = 0;
                b.data[3 * (v * w + u)..3 * (v * w + u) + 3].fill(255);
            }
        }
        let mut acc = MetricsAccumulator::new();
        acc.push(&a.as_ref(), &cov, 1.0, None);
        let m = acc.push(&b.as_ref(), &cov, 1.0, None);
        assert_eq!(m.rms_change, Some(0.0));
        assert_eq!(m.sharpness, 0.0);
        assert_eq!(m.rms_normal_flow, None);
    }

    #[test]
    fn a_planar_frame_is_as_sharp_as_its_rgb() {
        // Sharpness is defined on the RGB a player shows: measuring the
        // planes directly must give exactly what their conversion gives.
        let (w, h) = (37, 21);
        let n = PixelFormat::Yuv420p.buffer_len(w, h).unwrap();
        let planes: Vec<u8> = (0..n).map(|i| (i * 31 + (i * i) % 251) as u8).collect();
        let mut rgb = Vec::new();
        crate::color::yuv420p_to_rgb_into(w, h, &planes, false, 3, &mut rgb);
        let yuv = Frame {
            width: w,
            height: h,
            format: PixelFormat::Yuv420p,
            data: planes,
        };
        let rgb = Frame {
            width: w,
            height: h,
            format: PixelFormat::Rgb8,
            data: rgb,
        };
        let mut cov = vec![1u8; w * h];
        cov[5 * w + 9] = 0;
        let a = MetricsAccumulator::new().push(&yuv.as_ref(), &cov, 1.0, None);
        let b = MetricsAccumulator::new().push(&rgb.as_ref(), &cov, 1.0, None);
        assert!(a.sharpness > 0.0);
        assert_eq!(a.sharpness, b.sharpness);
    }
}
