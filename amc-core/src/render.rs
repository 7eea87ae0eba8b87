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
        check_range(
            "margin",
            self.margin,
            0.0,
            0.45,
            "0..=0.45 (share of each side)",
        )?;
        for (name, v) in [
            ("output_width", self.output_width),
            ("output_height", self.output_height),
        ] {
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
        // One scale for both axes, so rounding a size to even pixels crops
        // (or extends) by a fraction of a pixel instead of stretching the image;
        // only an explicit width *and* height may change the aspect ratio.
        let (sx, sy) = match (self.output_width, self.output_height) {
            (None, None) => (1.0, 1.0),
            (Some(_), None) => (w as f64 / crop_w, w as f64 / crop_w),
            (None, Some(_)) => (h as f64 / crop_h, h as f64 / crop_h),
            (Some(_), Some(_)) => (w as f64 / crop_w, h as f64 / crop_h),
        };
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

/// How one frame's source coordinates are produced along output rows.
#[derive(Clone, Debug, Default)]
struct RowMap {
    /// Homography `K_src M K_out^-1` (pinhole sources).
    h: Matrix3<f32>,
    /// Exact source coordinates at the grid nodes (distorted sources).
    grid: Vec<[f32; 2]>,
    /// Source coordinates `(xs[u], ys[u])` of the current output row (NaN: none).
    xs: Vec<f32>,
    ys: Vec<f32>,
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
    maps: Vec<RowMap>,
    /// Whether a vectorized kernel (AVX2 on this CPU, or wasm `simd128`) is usable.
    avx2: bool,
    /// Per-row accumulators of the vectorized path.
    acc_r: Vec<u32>,
    acc_g: Vec<u32>,
    acc_b: Vec<u32>,
    acc_n: Vec<u32>,
    /// Per-row 8-bit averages, R then G then B (vectorized finalize).
    out8: Vec<u8>,
    /// Output row being rendered (for the kernel's homography rows).
    current_row: usize,
}

/// Most frames one output may average (the range of `n_avg`).
const MAX_FRAMES: usize = 64;

/// Frame geometry, hoisted out of sampling loops.
#[derive(Clone, Copy, Debug)]
struct Geometry {
    channels: usize,
    stride: usize,
    max_x0: usize,
    max_y0: usize,
    max_x: f32,
    max_y: f32,
}

impl Geometry {
    fn of(frame: &FrameRef<'_>) -> Self {
        let (sw, sh) = (frame.width.max(2), frame.height.max(2));
        Self {
            channels: frame.format.channels(),
            stride: frame.stride(),
            max_x0: sw - 2,
            max_y0: sh - 2,
            max_x: (sw - 1) as f32,
            max_y: (sh - 1) as f32,
        }
    }

    /// Bilinear 8.8 fixed-point RGB sample of `data` at `(sx, sy)`; `None`
    /// outside the frame.
    #[inline(always)]
    fn sample(&self, data: &[u8], sx: f32, sy: f32) -> Option<[u32; 3]> {
        let tol = crate::simd::EDGE_TOLERANCE;
        if !(sx >= -tol && sy >= -tol && sx <= self.max_x + tol && sy <= self.max_y + tol) {
            return None;
        }
        // Points within the tolerance outside the frame sample its edge.
        let (sx, sy) = (sx.max(0.0).min(self.max_x), sy.max(0.0).min(self.max_y));
        let c = self.channels;
        let x0 = (sx as usize).min(self.max_x0);
        let y0 = (sy as usize).min(self.max_y0);
        let ax = ((sx - x0 as f32) * 256.0 + 0.5) as u32;
        let ay = ((sy - y0 as f32) * 256.0 + 0.5) as u32;
        let (bx, by) = (256 - ax, 256 - ay);
        let i = y0 * self.stride + x0 * c;
        // One slice covering both rows: a single bounds check for all 12 taps.
        let taps = data.get(i..i + self.stride + c + 3)?;
        let s = self.stride;
        let mut out = [0u32; 3];
        for ch in 0..3 {
            let top = taps[ch] as u32 * bx + taps[c + ch] as u32 * ax;
            let bot = taps[s + ch] as u32 * bx + taps[s + c + ch] as u32 * ax;
            out[ch] = (top * by + bot * ay + 128) >> 8;
        }
        Some(out)
    }
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
            maps: Vec::new(),
            avx2: crate::simd::vector_kernel_available(),
            acc_r: Vec::new(),
            acc_g: Vec::new(),
            acc_b: Vec::new(),
            acc_n: Vec::new(),
            current_row: 0,
            out8: Vec::new(),
        }
    }

    /// Disables the vectorized path (for testing the scalar one against it).
    pub fn set_vectorized(&mut self, on: bool) {
        self.avx2 = on && crate::simd::vector_kernel_available();
    }

    /// Prepares `map` for rotation `m` (output ray -> source ray).
    fn prepare_map(&self, map: &mut RowMap, m: &Matrix3<f64>) {
        map.xs.resize(self.out.width, 0.0);
        map.ys.resize(self.out.width, 0.0);
        if self.src.is_pinhole() {
            let k_out_inv = self
                .out
                .k_matrix()
                .try_inverse()
                .unwrap_or_else(Matrix3::identity);
            map.h = (self.src.k_matrix() * m * k_out_inv).map(|v| v as f32);
        } else {
            map.grid.clear();
            for ray in &self.grid_rays {
                let c = self
                    .src
                    .project(&(m * ray))
                    .map_or([f32::NAN; 2], |p| [p.x as f32, p.y as f32]);
                map.grid.push(c);
            }
        }
    }

    /// Sizes the row accumulators and decides the split of each row: the first
    /// `n8` pixels (a multiple of 8) go to the AVX2 kernel when it is available
    /// and every frame carries the gathers' padding; the rest are scalar.
    /// Returns `(n8, need_tables)`: the kernel evaluates pinhole homographies
    /// itself, so coordinate tables are needed only for distorted sources and
    /// for scalar pixels.
    fn begin_rows(&mut self, padded: bool) -> (usize, bool) {
        let ow = self.out.width;
        let n8 = if self.avx2 && padded { ow / 8 * 8 } else { 0 };
        for buf in [
            &mut self.acc_r,
            &mut self.acc_g,
            &mut self.acc_b,
            &mut self.acc_n,
        ] {
            buf.resize(ow, 0);
        }
        (n8, !self.src.is_pinhole() || n8 < ow)
    }

    /// Vectorized accumulation of the first `n8` pixels of the current row over all frames.
    #[allow(unused_variables)]
    fn accumulate_row_simd(
        &mut self,
        maps: &[RowMap],
        datas: &[&[u8]],
        geom: &Geometry,
        n8: usize,
    ) {
        #[cfg(any(
            target_arch = "x86_64",
            all(target_arch = "wasm32", target_feature = "simd128")
        ))]
        {
            let kg = crate::simd::KernelGeometry {
                channels: geom.channels as i32,
                stride: geom.stride as i32,
                max_x0: geom.max_x0 as i32,
                max_y0: geom.max_y0 as i32,
                max_x: geom.max_x,
                max_y: geom.max_y,
            };
            use crate::simd::RowCoords;
            let mut coords = [RowCoords::Table(&[], &[]); MAX_FRAMES];
            let n = maps.len().min(datas.len());
            let vf = self.current_row as f32;
            for (f, map) in maps.iter().enumerate().take(n) {
                coords[f] = if self.src.is_pinhole() {
                    let h = &map.h;
                    RowCoords::Homography {
                        x0: h[(0, 1)] * vf + h[(0, 2)],
                        y0: h[(1, 1)] * vf + h[(1, 2)],
                        z0: h[(2, 1)] * vf + h[(2, 2)],
                        dx: h[(0, 0)],
                        dy: h[(1, 0)],
                        dz: h[(2, 0)],
                    }
                } else {
                    RowCoords::Table(&map.xs, &map.ys)
                };
            }
            // SAFETY: `self.avx2` is only true when the CPU has AVX2; the caller
            // checked every frame's padding; all row buffers hold `ow >= n8` values.
            #[cfg(target_arch = "x86_64")]
            unsafe {
                crate::simd::accumulate_row_avx2(
                    &datas[..n],
                    kg,
                    &coords[..n],
                    n8,
                    &mut self.acc_r,
                    &mut self.acc_g,
                    &mut self.acc_b,
                    &mut self.acc_n,
                );
            }
            // SAFETY: as above (frames are non-empty: the caller checked the
            // padding, so each holds at least `FRAME_PADDING` bytes).
            #[cfg(target_arch = "wasm32")]
            unsafe {
                crate::simd::accumulate_row_simd128(
                    &datas[..n],
                    kg,
                    &coords[..n],
                    n8,
                    &mut self.acc_r,
                    &mut self.acc_g,
                    &mut self.acc_b,
                    &mut self.acc_n,
                );
            }
        }
    }

    /// Fills `map.xs`/`map.ys` with the source coordinates of output row `v`.
    fn fill_row(&self, map: &mut RowMap, v: usize) {
        if self.src.is_pinhole() {
            let h = &map.h;
            let vf = v as f32;
            let (x0, y0, z0) = (
                h[(0, 1)] * vf + h[(0, 2)],
                h[(1, 1)] * vf + h[(1, 2)],
                h[(2, 1)] * vf + h[(2, 2)],
            );
            let (dx, dy, dz) = (h[(0, 0)], h[(1, 0)], h[(2, 0)]);
            // Branch-free so it vectorizes; rays behind the camera become NaN.
            for (u, (xo, yo)) in map.xs.iter_mut().zip(map.ys.iter_mut()).enumerate() {
                let uf = u as f32;
                let z = z0 + dz * uf;
                let iz = if z > 1e-6 { 1.0 / z } else { f32::NAN };
                *xo = (x0 + dx * uf) * iz;
                *yo = (y0 + dy * uf) * iz;
            }
        } else {
            interpolate_grid_row(
                &map.grid,
                self.grid_w,
                self.grid_h,
                v,
                &mut map.xs,
                &mut map.ys,
            );
        }
    }

    /// Renders the average of frames `frame_at(0..n)` (with `rotations[i]`, the
    /// output->source rotation of frame `i`)
    /// into `out` (interleaved, `channels` 3 or 4) in one pass: per output row
    /// the source coordinates of every frame are computed into small row
    /// buffers, then each pixel samples all frames and is written once.
    /// `coverage` receives the per-pixel count of covering frames. Returns the
    /// share of pixels covered by every frame.
    pub fn average_into<'a, F: Fn(usize) -> FrameRef<'a>>(
        &mut self,
        frame_at: F,
        rotations: &[Matrix3<f64>],
        out: &mut [u8],
        channels: usize,
        coverage: &mut Vec<u8>,
    ) -> f64 {
        let (ow, oh) = (self.out.width, self.out.height);
        coverage.clear();
        coverage.resize(ow * oh, 0);
        let mut maps = std::mem::take(&mut self.maps);
        maps.resize_with(rotations.len(), RowMap::default);
        for (map, m) in maps.iter_mut().zip(rotations) {
            self.prepare_map(map, m);
        }
        let mut inv = [0f32; 65];
        for (k, v) in inv.iter_mut().enumerate().skip(1) {
            *v = 1.0 / (256.0 * k as f32);
        }
        let full = rotations.len() as u8;
        let n_frames = rotations.len().min(MAX_FRAMES);
        // Hoist each frame's pixels out of the per-pixel loop.
        let mut datas: [&[u8]; MAX_FRAMES] = [&[]; MAX_FRAMES];
        let first = frame_at(0);
        let geom = Geometry::of(&first);
        for (f, d) in datas.iter_mut().enumerate().take(n_frames) {
            let fr = frame_at(f);
            if fr.width == first.width && fr.height == first.height && fr.format == first.format {
                *d = fr.data;
            }
        }
        let mut complete = 0usize;
        // Pixels per row the AVX2 kernel handles (multiples of 8), when every
        // frame carries the padding its gathers need.
        let padded = datas[..n_frames]
            .iter()
            .all(|d| d.len() >= geom.stride * (first.height) + crate::simd::FRAME_PADDING);
        let (n8, need_tables) = self.begin_rows(padded);
        self.out8.resize(3 * ow, 0);
        for v in 0..oh {
            self.current_row = v;
            if need_tables {
                for map in maps.iter_mut() {
                    self.fill_row(map, v);
                }
            }
            if n8 > 0 {
                self.accumulate_row_simd(&maps[..n_frames], &datas[..n_frames], &geom, n8);
            }
            let out_row = &mut out[v * ow * channels..(v + 1) * ow * channels];
            let cov_row = &mut coverage[v * ow..(v + 1) * ow];
            // wasm simd128: RGBA rows are finished in one vectorized pass.
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            let finished = channels == 4 && n8 > 0 && {
                // SAFETY: the row sums hold `ow >= n8` values, `out_row` `4 ow` bytes.
                unsafe {
                    crate::simd::finish_row_rgba_simd128(
                        &self.acc_r,
                        &self.acc_g,
                        &self.acc_b,
                        &self.acc_n,
                        out_row,
                        n8,
                    )
                };
                true
            };
            #[cfg(not(all(target_arch = "wasm32", target_feature = "simd128")))]
            let finished = false;
            // Averages in vectorizable passes (SoA), then interleave.
            let (r8, rest) = self.out8.split_at_mut(ow);
            let (g8, rest) = rest.split_at_mut(ow);
            let (b8, _) = rest.split_at_mut(ow);
            for u in 0..if finished { 0 } else { n8 } {
                // 1 / (256 n); n = 0 gives inf and 0 * inf = NaN, which `as u8` maps to 0.
                let k = 1.0 / (256.0 * self.acc_n[u] as f32);
                r8[u] = (self.acc_r[u] as f32 * k + 0.5) as u8;
                g8[u] = (self.acc_g[u] as f32 * k + 0.5) as u8;
                b8[u] = (self.acc_b[u] as f32 * k + 0.5) as u8;
            }
            for u in 0..n8 {
                let n = self.acc_n[u] as u8;
                cov_row[u] = n;
                complete += (n == full) as usize;
            }
            if finished {
            } else if channels == 3 {
                for (u, px) in out_row[..3 * n8].chunks_exact_mut(3).enumerate() {
                    px[0] = r8[u];
                    px[1] = g8[u];
                    px[2] = b8[u];
                }
            } else {
                for (u, px) in out_row[..4 * n8].chunks_exact_mut(4).enumerate() {
                    px[0] = r8[u];
                    px[1] = g8[u];
                    px[2] = b8[u];
                    px[3] = 255;
                }
            }
            for u in n8..ow {
                let mut acc = [0u32; 3];
                let mut n = 0u8;
                for (map, data) in maps.iter().zip(&datas[..n_frames]) {
                    let (sx, sy) = (map.xs[u], map.ys[u]);
                    if let Some(rgb) = geom.sample(data, sx, sy) {
                        acc[0] += rgb[0];
                        acc[1] += rgb[1];
                        acc[2] += rgb[2];
                        n += 1;
                    }
                }
                let k = inv[n as usize];
                let px = &mut out_row[u * channels..u * channels + channels];
                px[0] = (acc[0] as f32 * k + 0.5) as u8;
                px[1] = (acc[1] as f32 * k + 0.5) as u8;
                px[2] = (acc[2] as f32 * k + 0.5) as u8;
                if channels == 4 {
                    px[3] = 255;
                }
                cov_row[u] = n;
                complete += (n == full) as usize;
            }
        }
        self.maps = maps;
        complete as f64 / (ow * oh).max(1) as f64
    }

    /// Output size.
    pub fn output_size(&self) -> (usize, usize) {
        (self.out.width, self.out.height)
    }

    /// Warps `frame` by `m` (output ray -> source ray) and calls
    /// `f(pixel_index, [r, g, b])` with 8.8 fixed-point samples for every output
    /// pixel whose ray lands inside the source frame. Scalar: the reference the
    /// vectorized paths are tested against.
    pub fn warp<F: FnMut(usize, [u32; 3])>(
        &mut self,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        mut f: F,
    ) {
        if frame.width < 2 || frame.height < 2 {
            return;
        }
        let geom = Geometry::of(frame);
        let ow = self.out.width;
        let mut map = RowMap::default();
        self.prepare_map(&mut map, m);
        for v in 0..self.out.height {
            self.fill_row(&mut map, v);
            for (u, (&sx, &sy)) in map.xs.iter().zip(&map.ys).enumerate() {
                if let Some(rgb) = geom.sample(frame.data, sx, sy) {
                    f(v * ow + u, rgb);
                }
            }
        }
    }
}

/// Bilinear interpolation of a node grid (`grid_w x grid_h`, spacing
/// [`GRID_STEP`]) into the coordinates of output row `v`.
fn interpolate_grid_row(
    grid: &[[f32; 2]],
    grid_w: usize,
    grid_h: usize,
    v: usize,
    xs: &mut [f32],
    ys: &mut [f32],
) {
    let gy = (v / GRID_STEP).min(grid_h.saturating_sub(2));
    let fy = (v - gy * GRID_STEP) as f32 / GRID_STEP as f32;
    let r0 = &grid[gy * grid_w..(gy + 1) * grid_w];
    let r1 = &grid[(gy + 1) * grid_w..(gy + 2) * grid_w];
    let lerp2 =
        |a: [f32; 2], b: [f32; 2], t: f32| [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t];
    for (u, (xo, yo)) in xs.iter_mut().zip(ys.iter_mut()).enumerate() {
        let gx = (u / GRID_STEP).min(grid_w - 2);
        let fx = (u - gx * GRID_STEP) as f32 / GRID_STEP as f32;
        let top = lerp2(r0[gx], r0[gx + 1], fx);
        let bot = lerp2(r1[gx], r1[gx + 1], fx);
        let p = lerp2(top, bot, fy);
        *xo = p[0];
        *yo = p[1];
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
        for ((px, s), &n) in out
            .chunks_exact_mut(channels)
            .zip(self.sum.chunks_exact(3))
            .zip(&self.count)
        {
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

impl Warper {
    /// Warps one frame into a saccade slot: 8.8 fixed-point samples and a
    /// coverage flag per pixel (0 where the frame does not cover it).
    pub fn warp_into_slot(
        &mut self,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        slot: &mut WarpedFrame,
        index: u64,
    ) {
        let (ow, oh) = (self.out.width, self.out.height);
        slot.index = index;
        slot.value.clear();
        slot.value.resize(3 * ow * oh, 0);
        slot.covered.clear();
        slot.covered.resize(ow * oh, 0);
        let geom = Geometry::of(frame);
        let padded = frame.data.len() >= geom.stride * frame.height + crate::simd::FRAME_PADDING;
        let (n8, need_tables) = self.begin_rows(padded);
        let mut maps = std::mem::take(&mut self.maps);
        maps.resize_with(1, RowMap::default);
        self.prepare_map(&mut maps[0], m);
        for v in 0..oh {
            self.current_row = v;
            if need_tables {
                self.fill_row(&mut maps[0], v);
            }
            let vals = &mut slot.value[3 * v * ow..3 * (v + 1) * ow];
            let cov = &mut slot.covered[v * ow..(v + 1) * ow];
            if n8 > 0 {
                self.accumulate_row_simd(&maps[..1], &[frame.data], &geom, n8);
                for u in 0..n8 {
                    vals[3 * u] = self.acc_r[u] as u16;
                    vals[3 * u + 1] = self.acc_g[u] as u16;
                    vals[3 * u + 2] = self.acc_b[u] as u16;
                    cov[u] = self.acc_n[u] as u8;
                }
            }
            for u in n8..ow {
                if let Some(rgb) = geom.sample(frame.data, maps[0].xs[u], maps[0].ys[u]) {
                    vals[3 * u] = rgb[0] as u16;
                    vals[3 * u + 1] = rgb[1] as u16;
                    vals[3 * u + 2] = rgb[2] as u16;
                    cov[u] = 1;
                }
            }
        }
        self.maps = maps;
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
    /// Warps `frame` into this slot (reusing its buffers) with the scalar
    /// sampler: the reference [`Warper::warp_into_slot`] is tested against.
    pub fn fill(
        &mut self,
        warper: &mut Warper,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        index: u64,
    ) {
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

    /// Adds (`add = true`) or removes this slot from an accumulator.
    /// Uncovered pixels hold zeros, so no per-pixel branch is needed.
    pub fn apply(&self, acc: &mut Accumulator, add: bool) {
        if add {
            for (s, &v) in acc.sum.iter_mut().zip(&self.value) {
                *s += v as u32;
            }
            for (n, &c) in acc.count.iter_mut().zip(&self.covered) {
                *n += c;
            }
        } else {
            for (s, &v) in acc.sum.iter_mut().zip(&self.value) {
                *s -= v as u32;
            }
            for (n, &c) in acc.count.iter_mut().zip(&self.covered) {
                *n -= c;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Frame, PixelFormat};
    use crate::so3::{self, Tangent};

    fn noise_frame(w: usize, h: usize, format: PixelFormat, seed: u64) -> Frame {
        let mut f = Frame::new(w, h, format);
        let mut s = seed;
        for b in f.data.iter_mut() {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *b = (s >> 56) as u8;
        }
        f.data.extend_from_slice(&[0; crate::simd::FRAME_PADDING]);
        f
    }

    #[test]
    fn rounding_the_output_size_never_stretches() {
        // 320x180 with 12.5% margins crops 240x135, rounded to 240x136.
        let src = CameraModel::pinhole_hfov(320, 180, 90.0).unwrap();
        let out = RenderParams::default().output_camera(&src).unwrap();
        assert_eq!((out.width, out.height), (240, 136));
        assert_eq!((out.fx, out.fy), (src.fx, src.fy));
        // One explicit dimension scales both axes alike.
        let p = RenderParams {
            output_width: Some(480),
            ..RenderParams::default()
        };
        let out = p.output_camera(&src).unwrap();
        assert_eq!((out.width, out.height), (480, 270));
        assert!((out.fx / src.fx - 2.0).abs() < 1e-12 && (out.fy / src.fy - 2.0).abs() < 1e-12);
    }

    fn render(src: &CameraModel, vectorized: bool, format: PixelFormat) -> (Vec<u8>, Vec<u8>, f64) {
        let out = RenderParams::default().output_camera(src).unwrap();
        let mut warper = Warper::new(src, &out);
        warper.set_vectorized(vectorized);
        let frames: Vec<Frame> = (0..4)
            .map(|i| noise_frame(src.width, src.height, format, i))
            .collect();
        let rots: Vec<Matrix3<f64>> = (0..4)
            .map(|i| *so3::exp(&Tangent::new(0.06 * i as f64, -0.1, 0.05 * i as f64)).matrix())
            .collect();
        let mut img = vec![0u8; out.width * out.height * format.channels()];
        let mut cov = Vec::new();
        let vf = warper.average_into(
            |i| frames[i].as_ref(),
            &rots,
            &mut img,
            format.channels(),
            &mut cov,
        );
        (img, cov, vf)
    }

    /// The AVX2 kernel must be bit-exact with the scalar sampler.
    #[test]
    fn vectorized_matches_scalar() {
        for format in [PixelFormat::Rgb8, PixelFormat::Rgba8] {
            let pinhole = CameraModel::pinhole_hfov(203, 117, 80.0).unwrap();
            let mut fisheye = CameraModel::pinhole_hfov(203, 117, 80.0).unwrap();
            fisheye.distortion = crate::camera::Distortion::Fisheye {
                k1: 0.05,
                k2: -0.01,
                k3: 0.0,
                k4: 0.0,
            };
            for cam in [pinhole, fisheye] {
                let a = render(&cam, false, format);
                let b = render(&cam, true, format);
                if let Some(i) = a.0.iter().zip(&b.0).position(|(x, y)| x != y) {
                    let c = format.channels();
                    panic!(
                        "pixel {} ch {}: scalar {} simd {} (cov {} vs {})",
                        i / c,
                        i % c,
                        a.0[i],
                        b.0[i],
                        a.1[i / c],
                        b.1[i / c]
                    );
                }
                assert_eq!(a.0, b.0);
                assert_eq!(a.1, b.1);
                assert_eq!(a.2, b.2);
                assert!(
                    a.2 < 1.0 && a.2 > 0.5,
                    "rotations should leave some border: {}",
                    a.2
                );
            }
        }
    }

    /// The vectorized saccade slot equals the scalar reference.
    #[test]
    fn slot_matches_scalar_reference() {
        let cam = CameraModel::pinhole_hfov(211, 119, 75.0).unwrap();
        let params = RenderParams {
            output_width: Some(150),
            ..Default::default()
        };
        let out = params.output_camera(&cam).unwrap();
        let f = noise_frame(211, 119, PixelFormat::Rgb8, 3);
        let m = *so3::exp(&Tangent::new(0.05, -0.08, 0.1)).matrix();
        let mut warper = Warper::new(&cam, &out);
        let (mut a, mut b) = (WarpedFrame::default(), WarpedFrame::default());
        warper.warp_into_slot(&f.as_ref(), &m, &mut a, 7);
        b.fill(&mut warper, &f.as_ref(), &m, 7);
        assert_eq!(a.covered, b.covered);
        assert_eq!(a.value, b.value);
        assert!(a.covered.iter().any(|&c| c == 0) && a.covered.iter().any(|&c| c == 1));
    }

    /// Warping by R then by R^T gives the image back (inside the common area).
    #[test]
    fn warp_then_inverse_restores_image() {
        let cam = CameraModel::pinhole_hfov(160, 120, 70.0).unwrap();
        let params = RenderParams {
            margin: 0.0,
            ..Default::default()
        };
        let out = params.output_camera(&cam).unwrap();
        // A smooth image (bilinear resampling is exact on linear ramps).
        let mut f = Frame::new(160, 120, PixelFormat::Rgb8);
        for v in 0..120 {
            for u in 0..160 {
                let i = 3 * (v * 160 + u);
                f.data[i] = (u + v / 2) as u8;
                f.data[i + 1] = (2 * v) as u8;
                f.data[i + 2] = 128;
            }
        }
        f.data.extend_from_slice(&[0; crate::simd::FRAME_PADDING]);
        let r = so3::exp(&Tangent::new(0.02, -0.03, 0.05));
        let mut warper = Warper::new(&cam, &out);
        let mut once = vec![0u8; 160 * 120 * 3];
        let mut cov = Vec::new();
        warper.average_into(|_| f.as_ref(), &[*r.matrix()], &mut once, 3, &mut cov);
        let mut g = Frame {
            width: 160,
            height: 120,
            format: PixelFormat::Rgb8,
            data: once,
        };
        g.data.extend_from_slice(&[0; crate::simd::FRAME_PADDING]);
        let mut back = vec![0u8; 160 * 120 * 3];
        let mut cov2 = Vec::new();
        warper.average_into(
            |_| g.as_ref(),
            &[*r.transpose().matrix()],
            &mut back,
            3,
            &mut cov2,
        );
        let (mut err, mut n) = (0f64, 0);
        for v in 20..100 {
            for u in 25..135 {
                let i = v * 160 + u;
                if cov[i] > 0 && cov2[i] > 0 {
                    for c in 0..3 {
                        err += (back[3 * i + c] as f64 - f.data[3 * i + c] as f64).abs();
                        n += 1;
                    }
                }
            }
        }
        assert!(n > 20000);
        assert!(err / (n as f64) < 1.0, "mean abs error {}", err / n as f64);
    }
}
