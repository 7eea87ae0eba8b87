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

use crate::image::{FrameRef, GrayImage, LUMA_WEIGHTS};
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

/// Accumulates per-frame and per-clip metrics over a stream of outputs.
#[derive(Clone, Debug, Default)]
pub struct MetricsAccumulator {
    prev: GrayImage,
    cur: GrayImage,
    has_prev: bool,
    frames: u64,
    nf_sq: f64,
    nf_n: u64,
    ch_sq: f64,
    ch_n: u64,
    sh_sq: f64,
    sh_n: u64,
    valid_sum: f64,
    valid_min: f64,
    est_sq: f64,
    view_sq: f64,
    speed_n: u64,
    saccades: u64,
}

/// Sobel x and y of `img` at interior index `i`, divided by 8.
#[inline]
fn sobel(d: &[f32], i: usize, w: usize) -> (f32, f32) {
    let (a, b, c) = (d[i - w - 1], d[i - w], d[i - w + 1]);
    let (l, r) = (d[i - 1], d[i + 1]);
    let (e, f, g) = (d[i + w - 1], d[i + w], d[i + w + 1]);
    let gx = ((c + 2.0 * r + g) - (a + 2.0 * l + e)) * 0.125;
    let gy = ((e + 2.0 * f + g) - (a + 2.0 * b + c)) * 0.125;
    (gx, gy)
}

/// Luma of `frame` into `dst`, `NaN` where `coverage` is 0.
pub fn masked_luma_into(frame: &FrameRef<'_>, coverage: &[u8], dst: &mut GrayImage) {
    dst.resize(frame.width, frame.height);
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

/// Sum of squared Sobel magnitudes over R, G, B and the number of terms.
fn sharpness_sums(frame: &FrameRef<'_>, coverage: &[u8], chan: &mut GrayImage) -> (f64, u64) {
    let (w, h) = (frame.width, frame.height);
    let c = frame.format.channels();
    let (mut sum, mut n) = (0f64, 0u64);
    for ch in 0..3 {
        chan.resize(w, h);
        for ((o, px), &cv) in chan
            .data
            .iter_mut()
            .zip(frame.data.chunks_exact(c))
            .zip(coverage)
        {
            *o = if cv == 0 {
                f32::NAN
            } else {
                px[ch] as f32 / 255.0
            };
        }
        for v in 1..h.saturating_sub(1) {
            for u in 1..w - 1 {
                let (gx, gy) = sobel(&chan.data, v * w + u, w);
                let g2 = gx * gx + gy * gy;
                if g2.is_finite() {
                    sum += g2 as f64;
                    n += 1;
                }
            }
        }
    }
    (sum, n)
}

impl MetricsAccumulator {
    /// A fresh accumulator.
    pub fn new() -> Self {
        Self {
            valid_min: 1.0,
            ..Default::default()
        }
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
            for v in 0..h {
                for u in 0..w {
                    let i = v * w + u;
                    let it = cur[i] - prev[i];
                    if !it.is_finite() {
                        continue;
                    }
                    ch += (it * it) as f64;
                    ch_n += 1;
                    if u == 0 || v == 0 || u == w - 1 || v == h - 1 {
                        continue;
                    }
                    let (gx, gy) = sobel(cur, i, w);
                    let g2 = gx * gx + gy * gy;
                    if g2.is_finite() && g2 >= NORMAL_FLOW_MIN_GRADIENT * NORMAL_FLOW_MIN_GRADIENT {
                        nf += (it * it / g2) as f64;
                        nf_n += 1;
                    }
                }
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
        let (s, n) = sharpness_sums(frame, coverage, &mut chan);
        self.prev = chan;
        if n > 0 {
            m.sharpness = (s / n as f64).sqrt();
            self.sh_sq += s;
            self.sh_n += n;
        }
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.has_prev = true;
        self.frames += 1;
        self.valid_sum += valid_fraction;
        self.valid_min = self.valid_min.min(valid_fraction);
        if let Some(t) = telemetry {
            if t.frame > 0 {
                let sq = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>();
                self.est_sq += sq(t.rate_est);
                self.view_sq += sq(t.rate_view);
                self.speed_n += 1;
            }
            self.saccades += t.saccade as u64;
        }
        m
    }

    /// Metrics of everything pushed so far.
    pub fn summary(&self) -> ClipMetrics {
        let rms = |s: f64, n: u64| if n > 0 { (s / n as f64).sqrt() } else { 0.0 };
        ClipMetrics {
            frames: self.frames,
            rms_normal_flow: rms(self.nf_sq, self.nf_n),
            rms_change: rms(self.ch_sq, self.ch_n),
            sharpness: rms(self.sh_sq, self.sh_n),
            valid_fraction: if self.frames > 0 {
                self.valid_sum / self.frames as f64
            } else {
                0.0
            },
            min_valid_fraction: if self.frames > 0 { self.valid_min } else { 0.0 },
            rms_speed_est_dps: rms(self.est_sq, self.speed_n).to_degrees(),
            rms_speed_view_dps: rms(self.view_sq, self.speed_n).to_degrees(),
            saccades: self.saccades,
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
}
