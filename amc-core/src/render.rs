//! Rendering frames into the stable view.
//!
//! A pixel `p` of the output (a pinhole camera `K_out` looking along the view
//! `R^view_{0,j}`) shows the scene ray `x_out = K_out^-1 p`. In source frame `i`
//! (orientation `R_hat_{0,i}`) that ray is
//! ```text
//! x_i = R_hat_{0,i}^T R^view_{0,j} x_out = M x_out
//! ```
//! and is sampled at `project_i(x_i)` through the source lens, straight from the
//! original full-resolution frame (one bilinear sample: no intermediate images).
//! For a pinhole source the map is the homography `K_i M K_out^-1`, evaluated
//! exactly and incrementally along each row. For distorted lenses the exact map
//! is evaluated on a grid every [`GRID_STEP`] pixels and interpolated bilinearly
//! in between (the lens map is smooth: the interpolation error is far below a
//! pixel for real lenses, and this is ~20x cheaper than projecting every pixel).
//!
//! Samples are 8-bit fixed point (weights in 1/256), accumulated exactly in
//! integers, so the saccade mode's running sum can add and subtract frames
//! forever without drift.

use crate::camera::CameraModel;
use crate::error::{check_range, AmcError};
use crate::image::FrameRef;
use nalgebra::{Matrix3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Grid spacing (output pixels) of the exact lens map for distorted sources.
pub const GRID_STEP: usize = 8;

/// Parameters of the renderer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderParams {
    /// Frames averaged into each output frame (`N_avg`; paper: 6). Range 1..=64.
    pub n_avg: usize,
    /// Share of the source width/height cropped from each side of the output
    /// (paper: 0.125, i.e. the central 75%). Range 0..=0.45.
    pub margin: f64,
    /// Output width in pixels; default: the cropped source width, rounded to even.
    /// Range 16..=16384.
    pub output_width: Option<usize>,
    /// Output height in pixels; default: keeps the cropped aspect ratio. Range 16..=16384.
    pub output_height: Option<usize>,
}

impl Default for RenderParams {
    fn default() -> Self {
        Self {
            n_avg: 6,
            margin: 0.125,
            output_width: None,
            output_height: None,
        }
    }
}

impl RenderParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<(), AmcError> {
        if !(1..=64).contains(&self.n_avg) {
            return Err(AmcError::invalid("n_avg", self.n_avg, "1..=64 frames"));
        }
        check_range("margin", self.margin, 0.0, 0.45, "0..=0.45 (share of each side)")?;
        for (name, v) in [("output_width", self.output_width), ("output_height", self.output_height)] {
            if let Some(v) = v {
                if !(16..=16384).contains(&v) {
                    return Err(AmcError::invalid(name, v, "16..=16384 pixels"));
                }
            }
        }
        Ok(())
    }

    /// The output camera for a source camera: a pinhole with the source's focal
    /// length (scaled when an explicit output size is asked for), centred.
    pub fn output_camera(&self, src: &CameraModel) -> Result<CameraModel, AmcError> {
        self.validate()?;
        let keep = 1.0 - 2.0 * self.margin;
        let crop_w = src.width as f64 * keep;
        let crop_h = src.height as f64 * keep;
        let even = |x: f64| ((x / 2.0).round() as usize * 2).max(16);
        let (w, h) = match (self.output_width, self.output_height) {
            (None, None) => (even(crop_w), even(crop_h)),
            (Some(w), None) => (w, even(w as f64 * crop_h / crop_w)),
            (None, Some(h)) => (even(h as f64 * crop_w / crop_h), h),
            (Some(w), Some(h)) => (w, h),
        };
        let (sx, sy) = (w as f64 / crop_w, h as f64 / crop_h);
        Ok(CameraModel::pinhole(
            w,
            h,
            src.fx * sx,
            src.fy * sy,
            (w as f64 - 1.0) / 2.0,
            (h as f64 - 1.0) / 2.0,
        ))
    }
}

/// Samples source frames along rotated output rays.
#[derive(Clone, Debug)]
pub struct Warper {
    src: CameraModel,
    out: CameraModel,
    /// Output rays at the grid nodes (distorted sources only).
    grid_rays: Vec<Vector3<f64>>,
    grid_w: usize,
    grid_h: usize,
    grid: Vec<[f32; 2]>,
    row: Vec<[f32; 2]>,
}

impl Warper {
    /// A warper from frames of `src` into `out` (a pinhole).
    pub fn new(src: &CameraModel, out: &CameraModel) -> Self {
        let (mut grid_rays, mut grid_w, mut grid_h) = (Vec::new(), 0, 0);
        if !src.is_pinhole() {
            grid_w = out.width.div_ceil(GRID_STEP) + 1;
            grid_h = out.height.div_ceil(GRID_STEP) + 1;
            for gy in 0..grid_h {
                for gx in 0..grid_w {
                    let p = Vector2::new((gx * GRID_STEP) as f64, (gy * GRID_STEP) as f64);
                    grid_rays.push(out.unproject(&p).unwrap_or_else(Vector3::z));
                }
            }
        }
        Self {
            src: src.clone(),
            out: out.clone(),
            grid_rays,
            grid_w,
            grid_h,
            grid: Vec::new(),
            row: vec![[0.0; 2]; out.width],
        }
    }

    /// Output size.
    pub fn output_size(&self) -> (usize, usize) {
        (self.out.width, self.out.height)
    }

    /// Warps `frame` by `m` (output ray -> source ray) and calls
    /// `f(pixel_index, [r, g, b])` with 8.8 fixed-point samples for every output
    /// pixel whose ray lands inside the source frame.
    pub fn warp<F: FnMut(usize, [u32; 3])>(&mut self, frame: &FrameRef<'_>, m: &Matrix3<f64>, mut f: F) {
        let (sw, sh) = (frame.width, frame.height);
        if sw < 2 || sh < 2 {
            return;
        }
        let c = frame.format.channels();
        let stride = frame.stride();
        let data = frame.data;
        let (maxx, maxy) = ((sw - 1) as f32, (sh - 1) as f32);
        let (ow, oh) = (self.out.width, self.out.height);
        let pinhole = self.src.is_pinhole();
        let (hrow, hcol) = if pinhole {
            let k_out_inv = self
                .out
                .k_matrix()
                .try_inverse()
                .unwrap_or_else(Matrix3::identity);
            let h = self.src.k_matrix() * m * k_out_inv;
            (h.map(|v| v as f32), true)
        } else {
            self.fill_grid(m);
            (Matrix3::zeros(), false)
        };
        let _ = hcol;
        for v in 0..oh {
            if pinhole {
                let (mut x, mut y, mut z) = (
                    hrow[(0, 1)] * v as f32 + hrow[(0, 2)],
                    hrow[(1, 1)] * v as f32 + hrow[(1, 2)],
                    hrow[(2, 1)] * v as f32 + hrow[(2, 2)],
                );
                let (dx, dy, dz) = (hrow[(0, 0)], hrow[(1, 0)], hrow[(2, 0)]);
                for r in self.row.iter_mut() {
                    *r = if z > 1e-6 {
                        let iz = 1.0 / z;
                        [x * iz, y * iz]
                    } else {
                        [f32::NAN; 2]
                    };
                    x += dx;
                    y += dy;
                    z += dz;
                }
            } else {
                self.interpolate_row(v);
            }
            let base = v * ow;
            for (u, &[sx, sy]) in self.row.iter().enumerate() {
                if !(sx >= 0.0 && sy >= 0.0 && sx <= maxx && sy <= maxy) {
                    continue;
                }
                let x0 = (sx as usize).min(sw - 2);
                let y0 = (sy as usize).min(sh - 2);
                let ax = ((sx - x0 as f32) * 256.0 + 0.5) as u32;
                let ay = ((sy - y0 as f32) * 256.0 + 0.5) as u32;
                let (bx, by) = (256 - ax, 256 - ay);
                let i = y0 * stride + x0 * c;
                let j = i + stride;
                let p = &data[i..i + c + 3];
                let q = &data[j..j + c + 3];
                let mut out = [0u32; 3];
                for ch in 0..3 {
                    let top = p[ch] as u32 * bx + p[c + ch] as u32 * ax;
                    let bot = q[ch] as u32 * bx + q[c + ch] as u32 * ax;
                    out[ch] = (top * by + bot * ay + 128) >> 8;
                }
                f(base + u, out);
            }
        }
    }

    /// Exact source coordinates at the grid nodes for rotation `m`.
    fn fill_grid(&mut self, m: &Matrix3<f64>) {
        self.grid.clear();
        for ray in &self.grid_rays {
            let c = self
                .src
                .project(&(m * ray))
                .map_or([f32::NAN; 2], |p| [p.x as f32, p.y as f32]);
            self.grid.push(c);
        }
    }

    /// Bilinear interpolation of the grid into `self.row` for output row `v`.
    fn interpolate_row(&mut self, v: usize) {
        let gy = (v / GRID_STEP).min(self.grid_h.saturating_sub(2));
        let fy = (v - gy * GRID_STEP) as f32 / GRID_STEP as f32;
        let r0 = &self.grid[gy * self.grid_w..(gy + 1) * self.grid_w];
        let r1 = &self.grid[(gy + 1) * self.grid_w..(gy + 2) * self.grid_w];
        for (u, out) in self.row.iter_mut().enumerate() {
            let gx = (u / GRID_STEP).min(self.grid_w - 2);
            let fx = (u - gx * GRID_STEP) as f32 / GRID_STEP as f32;
            let lerp2 = |a: [f32; 2], b: [f32; 2], t: f32| [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t];
            let top = lerp2(r0[gx], r0[gx + 1], fx);
            let bot = lerp2(r1[gx], r1[gx + 1], fx);
            *out = lerp2(top, bot, fy);
        }
    }
}

/// Per-pixel sums of warped frames: the averaging buffer.
#[derive(Clone, Debug, Default)]
pub struct Accumulator {
    /// 8.8 fixed-point channel sums, 3 per pixel.
    pub sum: Vec<u32>,
    /// Frames that covered each pixel.
    pub count: Vec<u8>,
}

impl Accumulator {
    /// Zeroes the buffer for `n` pixels.
    pub fn reset(&mut self, n: usize) {
        self.sum.clear();
        self.sum.resize(3 * n, 0);
        self.count.clear();
        self.count.resize(n, 0);
    }

    /// Writes the average into an interleaved frame buffer (`channels` 3 or 4);
    /// uncovered pixels are black. Returns the share of pixels covered by `full` frames.
    pub fn finish_into(&self, out: &mut [u8], channels: usize, full: u8) -> f64 {
        let mut inv = [0f32; 256];
        for (k, v) in inv.iter_mut().enumerate().skip(1) {
            *v = 1.0 / (256.0 * k as f32);
        }
        let mut complete = 0usize;
        for ((px, s), &n) in out.chunks_exact_mut(channels).zip(self.sum.chunks_exact(3)).zip(&self.count) {
            let k = inv[n as usize];
            px[0] = (s[0] as f32 * k + 0.5) as u8;
            px[1] = (s[1] as f32 * k + 0.5) as u8;
            px[2] = (s[2] as f32 * k + 0.5) as u8;
            if channels == 4 {
                px[3] = 255;
            }
            complete += (n >= full) as usize;
        }
        complete as f64 / self.count.len().max(1) as f64
    }
}

/// One frame warped into the (fixed) saccade view, kept to subtract it later.
#[derive(Clone, Debug, Default)]
pub struct WarpedFrame {
    /// Source frame index this slot holds.
    pub index: u64,
    /// 8.8 fixed-point samples (3 per pixel) of covered pixels.
    pub value: Vec<u16>,
    /// 1 where the frame covered the pixel.
    pub covered: Vec<u8>,
}

impl WarpedFrame {
    /// Warps `frame` into this slot (reusing its buffers).
    pub fn fill(&mut self, warper: &mut Warper, frame: &FrameRef<'_>, m: &Matrix3<f64>, index: u64) {
        let (w, h) = warper.output_size();
        self.index = index;
        self.value.clear();
        self.value.resize(3 * w * h, 0);
        self.covered.clear();
        self.covered.resize(w * h, 0);
        let (value, covered) = (&mut self.value, &mut self.covered);
        warper.warp(frame, m, |i, rgb| {
            value[3 * i] = rgb[0] as u16;
            value[3 * i + 1] = rgb[1] as u16;
            value[3 * i + 2] = rgb[2] as u16;
            covered[i] = 1;
        });
    }

    /// Adds (`sign = true`) or removes this slot from an accumulator.
    pub fn apply(&self, acc: &mut Accumulator, add: bool) {
        for (i, &c) in self.covered.iter().enumerate() {
            if c == 0 {
                continue;
            }
            let s = &mut acc.sum[3 * i..3 * i + 3];
            let v = &self.value[3 * i..3 * i + 3];
            if add {
                s[0] += v[0] as u32;
                s[1] += v[1] as u32;
                s[2] += v[2] as u32;
                acc.count[i] += 1;
            } else {
                s[0] -= v[0] as u32;
                s[1] -= v[1] as u32;
                s[2] -= v[2] as u32;
                acc.count[i] -= 1;
            }
        }
    }
}
