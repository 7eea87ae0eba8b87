//! The automatic threshold of the ghost-free average (`deghost=auto`): set
//! from the clip's own noise, so that the static scene differs from the
//! newest frame by less than it (and is averaged) while what moves against
//! the rotation model differs by more (and comes from the newest frame).
//!
//! The noise is Immerkaer's estimate (1996, "Fast noise variance
//! estimation"): the 3x3 operator
//! ```text
//!  1 -2  1
//! -2  4 -2      (the difference of two Laplacians; flat and linear
//!  1 -2  1       intensities give 0, white noise of sigma gives 6 sigma RMS)
//! ```
//! on the luma of a frame, with the median of its magnitude instead of the
//! mean, so that the edges and texture of a scene (a minority of its pixels)
//! do not count as noise: `sigma = median |L| / (6 * 0.6745)`. Compressed
//! video has less noise in flat areas than its frames differ by (the codec's
//! own errors change from frame to frame), which the floor of the threshold
//! covers. Rows are sampled every [`ROW_STEP`]: the estimate is a median over
//! hundreds of thousands of pixels either way.
//!
//! Frames are measured while the clip starts ([`FIRST_FRAMES`]) and then every
//! [`EVERY`]th frame; the threshold follows the median of the estimates, and
//! the frame being averaged into the newest one uses the threshold in force
//! when that newest frame arrived, so the output does not depend on how
//! rendering is scheduled.

use super::robust::Deghost;
use crate::image::{FrameRef, PixelFormat};

/// Rows measured: every `ROW_STEP`th.
pub const ROW_STEP: usize = 2;
/// Frames measured at the start of a clip.
pub const FIRST_FRAMES: u64 = 5;
/// After those, one frame in `EVERY`.
pub const EVERY: u64 = 30;
/// Estimates kept (the latest; about 30 s at 30 frames/s).
const KEPT: usize = 32;

/// Threshold, in noise standard deviations of one frame: the difference of
/// two frames' noise has sqrt(2) sigma, less after both are resampled; 3
/// sigma keeps full weight for nearly every static pixel, and none from 6.
pub const SIGMAS: f64 = 3.0;
/// Floor of the threshold, levels of 255: compressed video differs between
/// frames by its codec's errors, which a single frame's noise does not show.
pub const MIN_LEVELS: f64 = 2.0;
/// Ceiling of the threshold, levels: past it, an edge misaligned by a
/// fraction of a pixel or a mover of low contrast would be averaged in.
pub const MAX_LEVELS: f64 = 8.0;

/// The noise standard deviation of `frame`'s luma, levels of 255 (the Y
/// plane's own codes for planar frames); `None` for frames under 3 x 3.
pub fn noise_sigma(frame: &FrameRef<'_>) -> Option<f64> {
    NoiseMeter::default().measure(frame)
}

/// [`noise_sigma`] with its buffers kept: nothing is allocated per frame
/// once they have grown to the frame's width.
#[derive(Clone, Debug, Default)]
pub struct NoiseMeter {
    rows: [Vec<u8>; 3],
    /// Counts of `|L|`, which is at most `16 * 255`.
    hist: Vec<u32>,
}

impl NoiseMeter {
    /// The noise standard deviation of `frame`'s luma (see [`noise_sigma`]).
    pub fn measure(&mut self, frame: &FrameRef<'_>) -> Option<f64> {
        let (w, h) = (frame.width, frame.height);
        if w < 3 || h < 3 {
            return None;
        }
        // Luma rows: the Y plane of planar frames, else (77 R + 150 G + 29 B) / 256.
        let luma_row = |y: usize, out: &mut [u8]| match frame.format {
            PixelFormat::Yuv420p => out.copy_from_slice(&frame.data[y * w..(y + 1) * w]),
            f => {
                let c = f.channels();
                let px = &frame.data[y * w * c..(y + 1) * w * c];
                for (o, p) in out.iter_mut().zip(px.chunks_exact(c)) {
                    *o = ((77 * p[0] as u32 + 150 * p[1] as u32 + 29 * p[2] as u32) >> 8) as u8;
                }
            }
        };
        for row in &mut self.rows {
            row.resize(w, 0);
        }
        self.hist.clear();
        self.hist.resize(16 * 255 + 1, 0);
        let mut n = 0u64;
        let mut y = 1;
        while y + 1 < h {
            for (k, row) in self.rows.iter_mut().enumerate() {
                luma_row(y + k - 1, row);
            }
            let [a, b, c] = &self.rows;
            for x in 1..w - 1 {
                let p = |r: &[u8], i: usize| r[i] as i32;
                let l = p(a, x - 1) - 2 * p(a, x) + p(a, x + 1) - 2 * p(b, x - 1) + 4 * p(b, x)
                    - 2 * p(b, x + 1)
                    + p(c, x - 1)
                    - 2 * p(c, x)
                    + p(c, x + 1);
                self.hist[l.unsigned_abs() as usize] += 1;
            }
            n += (w - 2) as u64;
            y += ROW_STEP;
        }
        if n == 0 {
            return None;
        }
        // The median, interpolated within its bin (|L| is an integer: a clean
        // frame's median of 0 or 1 would otherwise jump).
        let half = n as f64 / 2.0;
        let mut below = 0u64;
        let mut median = 0.0;
        for (v, &count) in self.hist.iter().enumerate() {
            let c = count as u64;
            if (below + c) as f64 >= half {
                let within = if c == 0 {
                    0.0
                } else {
                    (half - below as f64) / c as f64
                };
                median = (v as f64 - 0.5 + within).max(0.0);
                break;
            }
            below += c;
        }
        Some(median / (6.0 * 0.674_489_75))
    }
}

/// The threshold (levels of 255) for a noise of `sigma`.
pub fn levels_for_noise(sigma: f64) -> f64 {
    (SIGMAS * sigma).clamp(MIN_LEVELS, MAX_LEVELS)
}

/// The running estimate of `deghost=auto`: frames in, the threshold in force.
#[derive(Clone, Debug, Default)]
pub struct AutoDeghost {
    meter: NoiseMeter,
    /// The latest estimates (at most [`KEPT`]), oldest first.
    estimates: Vec<f64>,
    /// Their copy, sorted for the median (kept to reuse its buffer).
    sorted: Vec<f64>,
    levels: Option<f64>,
}

impl AutoDeghost {
    /// Frame `index` of the clip arrived: measured when it is one of the
    /// first or an [`EVERY`]th; returns the threshold in force from it on.
    pub fn observe(&mut self, index: u64, frame: &FrameRef<'_>) -> Option<Deghost> {
        if index < FIRST_FRAMES || index.is_multiple_of(EVERY) {
            if let Some(sigma) = self.meter.measure(frame) {
                if self.estimates.len() == KEPT {
                    self.estimates.remove(0);
                }
                self.estimates.reserve_exact(KEPT - self.estimates.len());
                self.estimates.push(sigma);
                self.sorted.clear();
                self.sorted.reserve_exact(KEPT);
                self.sorted.extend_from_slice(&self.estimates);
                self.sorted.sort_unstable_by(f64::total_cmp);
                self.levels = Some(levels_for_noise(self.sorted[self.sorted.len() / 2]));
            }
        }
        self.deghost()
    }

    /// The threshold in force, levels of 255 (`None` before any frame).
    pub fn levels(&self) -> Option<f64> {
        self.levels
    }

    /// The weights of the threshold in force.
    pub fn deghost(&self) -> Option<Deghost> {
        Deghost::new(self.levels.unwrap_or(MIN_LEVELS))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Frame;

    /// A gray ramp with a few hard edges plus white noise of `sigma` (a
    /// fixed-seed generator), as a planar frame.
    fn noisy(w: usize, h: usize, sigma: f64, seed: u64) -> Frame {
        let mut f = Frame::new(w, h, PixelFormat::Yuv420p);
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
        let mut uniform = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        for y in 0..h {
            for x in 0..w {
                // Box-Muller.
                let g =
                    (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
                let base =
                    60.0 + 100.0 * x as f64 / w as f64 + if (x / 40) % 2 == 0 { 0.0 } else { 40.0 };
                f.data[y * w + x] = (base + sigma * g).round().clamp(0.0, 255.0) as u8;
            }
        }
        f
    }

    #[test]
    fn white_noise_is_measured_within_ten_percent() {
        for sigma in [2.0, 4.0, 8.0] {
            let f = noisy(320, 180, sigma, 7);
            let got = noise_sigma(&f.as_ref()).unwrap();
            assert!(
                (got / sigma - 1.0).abs() < 0.1,
                "sigma {sigma}: measured {got:.3}"
            );
        }
    }

    #[test]
    fn a_clean_frame_with_edges_has_almost_no_noise_and_the_floor_threshold() {
        let f = noisy(320, 180, 0.0, 1);
        let got = noise_sigma(&f.as_ref()).unwrap();
        assert!(got < 0.2, "{got}");
        assert_eq!(levels_for_noise(got), MIN_LEVELS);
    }

    #[test]
    fn the_threshold_follows_the_median_estimate_and_its_range() {
        let mut auto = AutoDeghost::default();
        assert_eq!(auto.levels(), None);
        let f = noisy(160, 90, 2.0, 3);
        auto.observe(0, &f.as_ref());
        let l = auto.levels().unwrap();
        assert!((l - 6.0).abs() < 0.6, "{l}");
        // Frames between the measured ones keep the threshold.
        let loud = noisy(160, 90, 20.0, 4);
        for i in FIRST_FRAMES..EVERY {
            auto.observe(i, &loud.as_ref());
        }
        assert_eq!(auto.levels(), Some(l));
        assert_eq!(levels_for_noise(100.0), MAX_LEVELS);
    }
}
