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
//!
//! Measured in one pass down the rows, in integers where the definitions
//! allow: `luma.rs` (luma as 16-bit integers with a scale; change and normal
//! flow), `sharpness.rs` (R, G and B a row at a time; exact Sobel sums), both
//! through `sobel.rs`. A row
//! is measured once the rows below it are made, and nothing frame-sized is
//! kept but the previous output's luma and validity.

mod luma;
mod sharpness;
mod sobel;

use crate::image::{y_to_unit, FrameRef, GrayImage, PixelFormat, LUMA_WEIGHTS};
use crate::stabilizer::Telemetry;
pub use luma::NORMAL_FLOW_MIN_GRADIENT;
use luma::{FlowRows, LumaPlane};
use serde::{Deserialize, Serialize};
use sharpness::ChannelRows;

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
    prev: LumaPlane,
    cur: LumaPlane,
    /// The interior pixels of a row with all nine neighbours valid (reused).
    interior: Vec<u8>,
    flow: FlowRows,
    channels: ChannelRows,
    has_prev: bool,
    nf_sq: f64,
    nf_n: u64,
    ch_sq: f64,
    ch_n: u64,
    sh_sq: f64,
    sh_n: u64,
    motion: MotionAccumulator,
}

/// One frame's sums, each with its count of terms: normal flow
/// (`|n|^2` in pixels^2), change (in `L^2`, see [`luma`]) and sharpness (in
/// bytes, see [`sharpness::SCALE`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct FrameSums {
    flow: (f64, u64),
    change: (u64, u64),
    sharpness: (u64, u64),
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

/// `out[x - 1] = 1` where all nine neighbours of interior pixel `x` are
/// valid (`rows`: validity 0 or 1 of the rows above, at and below); returns
/// how many are.
#[inline(always)]
fn interior_valid([above, at, below]: [&[u8]; 3], out: &mut [u8]) -> u64 {
    let n = out.len();
    let ([a0, a1, a2], [r0, r1, r2], [b0, b1, b2]) = [above, at, below]
        .map(|r| [&r[..n], &r[1..n + 1], &r[2..n + 2]])
        .into();
    let mut count = 0u32;
    for i in 0..n {
        out[i] = a0[i] & a1[i] & a2[i] & r0[i] & r1[i] & r2[i] & b0[i] & b1[i] & b2[i];
        count += out[i] as u32;
    }
    count as u64
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
        self.cur.reset(frame);
        let against_prev = self.has_prev
            && (self.prev.width, self.prev.height, self.prev.scale)
                == (self.cur.width, self.cur.height, self.cur.scale);
        let sums = self.measure(frame, coverage, against_prev);
        let mut m = FrameMetrics {
            valid_fraction,
            ..Default::default()
        };
        let (nf, nf_n) = sums.flow;
        if nf_n > 0 {
            m.rms_normal_flow = Some((nf / nf_n as f64).sqrt());
            self.nf_sq += nf;
            self.nf_n += nf_n;
        }
        let (ch, ch_n) = sums.change;
        if ch_n > 0 {
            let ch = ch as f64 / (self.cur.scale as f64).powi(2);
            m.rms_change = Some((ch / ch_n as f64).sqrt());
            self.ch_sq += ch;
            self.ch_n += ch_n;
        }
        let (sh, sh_n) = sums.sharpness;
        if sh_n > 0 {
            let sh = sh as f64 / sharpness::SCALE;
            m.sharpness = (sh / sh_n as f64).sqrt();
            self.sh_sq += sh;
            self.sh_n += sh_n;
        }
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.has_prev = true;
        self.motion.push(valid_fraction, telemetry);
        m
    }

    multiversion! {
        /// The frame's sums, by the widest integer lanes this CPU has: the
        /// same code compiled for AVX-512 (F and BW: 16-bit lanes thirty-two
        /// pixels wide) or AVX2 (sixteen instead of eight). The sums are
        /// integers and the few float operations are not reordered (no fused
        /// multiply-add: Rust never contracts), so the result is the same bits
        /// on every path.
        fn measure(
            [&mut] self,
            frame: &FrameRef<'_>,
            coverage: &[u8],
            against_prev: bool,
        ) -> FrameSums => measure_body {
            measure_avx512: "avx512f,avx512bw" if "avx512bw",
            measure_avx2: "avx2" if "avx2",
        }
    }

    /// One pass down the rows: row `y`'s luma, validity and channels are
    /// made, its change against the previous frame summed, and row `y - 1`,
    /// whose neighbours are now all made, measured for normal flow and
    /// sharpness.
    #[inline(always)]
    fn measure_body(
        &mut self,
        frame: &FrameRef<'_>,
        coverage: &[u8],
        against_prev: bool,
    ) -> FrameSums {
        let (w, h) = (frame.width, frame.height);
        let mut sums = FrameSums::default();
        let interior = w >= 3 && h >= 3;
        self.interior.resize(w.saturating_sub(2), 0);
        for y in 0..h {
            self.cur.fill_row(frame, coverage, y);
            if interior {
                self.channels.fill_row(frame, y);
            }
            if against_prev {
                let (s, k) = luma::change_sum(self.cur.row(y), self.prev.row(y));
                sums.change.0 += s;
                sums.change.1 += k;
            }
            if !interior || y < 2 {
                continue;
            }
            let v = y - 1;
            let (above, at, below) = (self.cur.row(v - 1), self.cur.row(v), self.cur.row(y));
            let valid = interior_valid([above.1, at.1, below.1], &mut self.interior);
            if valid == 0 {
                continue;
            }
            sums.sharpness.0 += self.channels.sum(v, &self.interior);
            sums.sharpness.1 += 3 * valid;
            if against_prev {
                let (s, k) = self.flow.sum(
                    [above.0, at.0, below.0],
                    self.prev.row(v),
                    &self.interior,
                    self.cur.scale,
                );
                sums.flow.0 += s;
                sums.flow.1 += k;
            }
        }
        sums
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

    /// Squared sums and counts of the metrics' definitions, one pixel at a
    /// time in `f64`: `[normal flow, change, sharpness]`.
    fn definitions(prev: (&Frame, &[u8]), cur: (&Frame, &[u8])) -> [(f64, u64); 3] {
        let (w, h) = (cur.0.width, cur.0.height);
        let rgb = |f: &Frame| -> Vec<f64> {
            let mut packed = Vec::new();
            let (bytes, c) = if f.format.is_planar() {
                crate::color::yuv420p_to_rgb_into(w, h, &f.data, false, 3, &mut packed);
                (&packed[..], 3)
            } else {
                (&f.data[..], f.format.channels())
            };
            (0..w * h)
                .flat_map(|i| (0..3).map(move |ch| bytes[i * c + ch] as f64 / 255.0))
                .collect()
        };
        let luma = |f: &Frame| -> Vec<f64> {
            if f.format.is_planar() {
                f.data[..w * h]
                    .iter()
                    .map(|&y| (y.clamp(16, 235) - 16) as f64 / 219.0)
                    .collect()
            } else {
                let c = rgb(f);
                (0..w * h)
                    .map(|i| 0.299 * c[3 * i] + 0.587 * c[3 * i + 1] + 0.114 * c[3 * i + 2])
                    .collect()
            }
        };
        let sobel = |img: &dyn Fn(usize, usize) -> f64, x: usize, y: usize| {
            let p = |dx: usize, dy: usize| img(x + dx - 1, y + dy - 1);
            let gx = (p(2, 0) + 2.0 * p(2, 1) + p(2, 2)) - (p(0, 0) + 2.0 * p(0, 1) + p(0, 2));
            let gy = (p(0, 2) + 2.0 * p(1, 2) + p(2, 2)) - (p(0, 0) + 2.0 * p(1, 0) + p(2, 0));
            (gx / 8.0).powi(2) + (gy / 8.0).powi(2)
        };
        let (lp, lc, c) = (luma(prev.0), luma(cur.0), rgb(cur.0));
        let valid = |cov: &[u8], x: usize, y: usize| cov[y * w + x] != 0;
        let mut out = [(0.0, 0u64); 3];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let both = valid(cur.1, x, y) && valid(prev.1, x, y);
                if both {
                    out[1].0 += (lc[i] - lp[i]).powi(2);
                    out[1].1 += 1;
                }
                let inside = x > 0 && y > 0 && x + 1 < w && y + 1 < h;
                if !inside || !(y - 1..=y + 1).all(|v| (x - 1..=x + 1).all(|u| valid(cur.1, u, v)))
                {
                    continue;
                }
                for ch in 0..3 {
                    out[2].0 += sobel(&|u, v| c[3 * (v * w + u) + ch], x, y);
                    out[2].1 += 1;
                }
                let g2 = sobel(&|u, v| lc[v * w + u], x, y);
                if both && g2 >= (15.0f64 / 255.0).powi(2) {
                    out[0].0 += (lc[i] - lp[i]).powi(2) / g2;
                    out[0].1 += 1;
                }
            }
        }
        out
    }

    /// A frame of smooth ramps (gradients either side of the normal-flow
    /// threshold) with texture and the extreme bytes (the largest Sobel
    /// responses); `shift` moves the pattern.
    fn patterned(w: usize, h: usize, format: PixelFormat, shift: usize) -> Frame {
        let mut f = Frame::new(w, h, format);
        for (i, b) in f.data.iter_mut().enumerate() {
            let i = i + shift;
            *b = match i % 11 {
                0..=2 => 255 * ((i / 3) % 2) as u8,
                3..=6 => (i * 31 + (i * i) % 251) as u8,
                _ => (i / 5 % 200) as u8 + 20,
            };
        }
        f
    }

    /// A coverage with holes (one pixel in 13; `shift` moves them).
    fn holes(w: usize, h: usize, shift: usize) -> Vec<u8> {
        (0..w * h)
            .map(|i| u8::from((i + shift) % 13 != 5) * 3)
            .collect()
    }

    #[test]
    fn sums_are_the_definitions() {
        // Smooth ramps (gradients either side of the normal-flow threshold)
        // with texture, the extreme bytes (the largest Sobel responses),
        // odd sizes, holes in the coverage; planar and packed.
        for (w, h) in [(3usize, 3usize), (37, 21), (1100, 5)] {
            for format in [PixelFormat::Yuv420p, PixelFormat::Rgb8, PixelFormat::Rgba8] {
                let (a, b) = (patterned(w, h, format, 0), patterned(w, h, format, 7));
                let (ca, cb) = (holes(w, h, 0), holes(w, h, 4));
                let mut acc = MetricsAccumulator::new();
                acc.push(&a.as_ref(), &ca, 1.0, None);
                let m = acc.push(&b.as_ref(), &cb, 1.0, None);
                let [nf, ch, sh] = definitions((&a, &ca), (&b, &cb));
                let rms = |(s, n): (f64, u64)| (n > 0).then(|| (s / n as f64).sqrt());
                // Planar luma is exact (normal flow's ratios are taken in
                // `f32`); packed luma is held to 12 bits.
                let tol = if format.is_planar() { 1e-6 } else { 2e-3 };
                let close = |got: Option<f64>, want: Option<f64>| match (got, want) {
                    (Some(g), Some(w)) => (g - w).abs() <= tol * w.max(1e-3),
                    (g, w) => g == w,
                };
                let what = format!("{w}x{h} {format:?}");
                assert!(
                    close(m.rms_change, rms(ch)),
                    "{what}: change {:?} vs {:?}",
                    m.rms_change,
                    rms(ch)
                );
                assert!(
                    close(m.rms_normal_flow, rms(nf)),
                    "{what}: flow {:?} vs {:?}",
                    m.rms_normal_flow,
                    rms(nf)
                );
                assert!(
                    (m.sharpness - rms(sh).unwrap_or(0.0)).abs() <= 1e-9,
                    "{what}: sharpness"
                );
                assert_eq!(acc.summary().frames, 2);
            }
        }
    }

    #[test]
    fn every_instruction_set_gives_the_same_sums() {
        // The vector paths are the scalar body compiled for wider lanes:
        // integer sums and unreordered float operations, so equal bits.
        for (w, h) in [(37usize, 21usize), (1100, 5), (203, 64)] {
            for format in [PixelFormat::Yuv420p, PixelFormat::Rgb8, PixelFormat::Rgba8] {
                let coverage = holes(w, h, 2);
                let (a, b) = (patterned(w, h, format, 0), patterned(w, h, format, 5));
                let mut acc = MetricsAccumulator::new();
                acc.push(&a.as_ref(), &coverage, 1.0, None);
                acc.cur.reset(&b.as_ref());
                let frame = b.as_ref();
                let want = acc.clone().measure_body(&frame, &coverage, true);
                assert!(want.flow.1 > 0 && want.change.1 > 0 && want.sharpness.1 > 0);
                #[cfg_attr(not(target_arch = "x86_64"), allow(unused_mut))] // (pushed to on x86-64)
                let mut got = vec![("dispatch", acc.clone().measure(&frame, &coverage, true))];
                #[cfg(target_arch = "x86_64")]
                {
                    if std::arch::is_x86_feature_detected!("avx2") {
                        // SAFETY: the CPU has AVX2.
                        let s = unsafe { acc.clone().measure_avx2(&frame, &coverage, true) };
                        got.push(("avx2", s));
                    }
                    if std::arch::is_x86_feature_detected!("avx512bw") {
                        // SAFETY: the CPU has AVX-512 F and BW.
                        let s = unsafe { acc.clone().measure_avx512(&frame, &coverage, true) };
                        got.push(("avx512", s));
                    }
                }
                for (path, sums) in got {
                    assert_eq!(sums, want, "{w}x{h} {format:?}: {path}");
                    assert_eq!(sums.flow.0.to_bits(), want.flow.0.to_bits());
                }
            }
        }
    }

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
