//! The warper: maps output rows to source coordinates (an exact homography for
//! pinhole sources, an interpolated grid of the exact lens map otherwise) and
//! samples every frame there, through the row kernels.

use super::kernels::{Geometry, Kernel, RowCoords, FRAME_PADDING};
use super::WarpedFrame;
use crate::camera::CameraModel;
use crate::image::FrameRef;
use nalgebra::{Matrix3, Vector2, Vector3};

/// Grid spacing (output pixels) of the exact lens map for distorted sources.
pub const GRID_STEP: usize = 8;

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
    /// The row kernel: a vectorized one (AVX2 on this CPU, or wasm `simd128`)
    /// or the scalar reference, which leaves every pixel to the per-pixel path.
    kernel: Kernel,
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
            kernel: Kernel::detect(),
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
        self.kernel = if on { Kernel::detect() } else { Kernel::Scalar };
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
        let n8 = if self.kernel.is_vectorized() && padded {
            ow / 8 * 8
        } else {
            0
        };
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
    fn accumulate_row_simd(
        &mut self,
        maps: &[RowMap],
        datas: &[&[u8]],
        geom: &Geometry,
        n8: usize,
    ) {
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
        // SAFETY: `self.kernel` comes from `Kernel::detect` (vectorized only when
        // `n8 > 0`, a multiple of 8); the caller checked every frame's padding
        // (so each holds at least `FRAME_PADDING` bytes); all row buffers hold
        // `ow >= n8` values.
        unsafe {
            self.kernel.accumulate_row(
                &datas[..n],
                geom,
                &coords[..n],
                n8,
                &mut self.acc_r,
                &mut self.acc_g,
                &mut self.acc_b,
                &mut self.acc_n,
            );
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
            .all(|d| d.len() >= geom.stride * (first.height) + FRAME_PADDING);
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
            // Kernels with a finishing pass (wasm simd128) finish RGBA rows in one go.
            let finished = channels == 4 && n8 > 0 && {
                // SAFETY: the row sums hold `ow >= n8` values, `out_row` `4 ow` bytes.
                unsafe {
                    self.kernel.finish_row_rgba(
                        &self.acc_r,
                        &self.acc_g,
                        &self.acc_b,
                        &self.acc_n,
                        out_row,
                        n8,
                    )
                }
            };
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
        let padded = frame.data.len() >= geom.stride * frame.height + FRAME_PADDING;
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
