//! The contract every row kernel shares, below them all: the edge tolerance and
//! frame padding, the row coordinates ([`RowCoords`]), the frame geometry, and the
//! scalar reference sampler ([`Geometry::sample`]): the bilinear or bicubic 8.8
//! fixed-point sample every kernel must match bit for bit, used directly for the
//! pixels the vector kernels leave (row tails, unpadded frames, CPUs without them).
//!
//! Bicubic sampling ([`cubic_weights`]) is Keys' cubic convolution with
//! `a = -1/2` (Catmull-Rom) over the 4 x 4 pixels around the point, its
//! weights found in integers from the same 8-bit fractions `ax`, `ay` as the
//! bilinear weights; taps past the frame's edge repeat the edge pixel. Every
//! product and sum is an exact integer, so any order of summation gives the
//! same bytes: the kernels need only the same weights and the same rounding.
//!
//! A leaf: the kernels (`scalar.rs`, `avx2.rs`, `simd128.rs`) use it and the
//! dispatcher (`mod.rs`) uses them, never the other way round.

use crate::image::FrameRef;

/// How far (pixels) outside a frame a sample point may fall and still sample
/// its edge. An identity warp computes `x = u +- 1e-13` at the borders; without
/// a tolerance that rounding blanks the first or last row or column. 1/512 px
/// is half the bilinear weights' resolution, so the clamp changes no weight.
pub const EDGE_TOLERANCE: f32 = 1.0 / 512.0;

/// Bytes a frame buffer must have past its last pixel for the gathers: the
/// last tap reads a whole dword starting at the last pixel (3 bytes for RGB,
/// 2 past the last pair of a single-channel plane).
pub const FRAME_PADDING: usize = 4;

/// Frame geometry, hoisted out of sampling loops.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry {
    /// Bytes per pixel (3 or 4).
    pub(crate) channels: usize,
    /// Bytes per row.
    pub(crate) stride: usize,
    /// Largest column of a top-left tap (`width - 2`).
    pub(crate) max_x0: usize,
    /// Largest row of a top-left tap (`height - 2`).
    pub(crate) max_y0: usize,
    /// Largest sample x, pixels (`width - 1`).
    pub(crate) max_x: f32,
    /// Largest sample y, pixels (`height - 1`).
    pub(crate) max_y: f32,
    /// Bicubic (4 x 4 taps) instead of bilinear sampling.
    pub(crate) cubic: bool,
}

impl Geometry {
    /// The geometry of an interleaved `frame` (frames narrower or lower than 2
    /// pixels are treated as 2).
    pub(crate) fn of(frame: &FrameRef<'_>) -> Self {
        Self::plane(frame.width, frame.height, frame.format.channels())
    }

    /// The geometry of a packed `width x height` plane of `channels` bytes per
    /// pixel (planes narrower or lower than 2 pixels are treated as 2).
    pub(crate) fn plane(width: usize, height: usize, channels: usize) -> Self {
        let (sw, sh) = (width.max(2), height.max(2));
        Self {
            channels,
            stride: width * channels,
            max_x0: sw - 2,
            max_y0: sh - 2,
            max_x: (sw - 1) as f32,
            max_y: (sh - 1) as f32,
            cubic: false,
        }
    }

    /// This geometry sampled bicubically (`true`) or bilinearly.
    pub(crate) fn with_cubic(self, cubic: bool) -> Self {
        Self { cubic, ..self }
    }

    /// The fixed-point footprint of a point inside the frame (within the
    /// tolerance): the clamped top-left tap `(x0, y0)` of its 2 x 2
    /// neighbourhood and the 8-bit fractions `(ax, ay)` in `0..=256`.
    #[inline(always)]
    fn footprint(&self, sx: f32, sy: f32) -> Option<(usize, usize, u32, u32)> {
        let tol = EDGE_TOLERANCE;
        if !(sx >= -tol && sy >= -tol && sx <= self.max_x + tol && sy <= self.max_y + tol) {
            return None;
        }
        // Points within the tolerance outside the frame sample its edge.
        let (sx, sy) = (sx.max(0.0).min(self.max_x), sy.max(0.0).min(self.max_y));
        let x0 = (sx as usize).min(self.max_x0);
        let y0 = (sy as usize).min(self.max_y0);
        let ax = ((sx - x0 as f32) * 256.0 + 0.5) as u32;
        let ay = ((sy - y0 as f32) * 256.0 + 0.5) as u32;
        Some((x0, y0, ax, ay))
    }

    /// Bicubic 8.8 fixed-point sample of the first `C` channels of pixels
    /// `channels` bytes apart at `(sx, sy)`; `None` outside the frame. The taps are
    /// pixels `x0 - 1 ..= x0 + 2` and `y0 - 1 ..= y0 + 2` of the bilinear
    /// footprint, clamped onto the frame; the result, `sum wy (sum wx p)`
    /// (weights in 1/256) rounded to 1/256, is clamped to `0..=255 * 256`
    /// (the cubic overshoots at edges).
    #[inline(always)]
    fn sample_cubic_channels<const C: usize>(
        &self,
        data: &[u8],
        sx: f32,
        sy: f32,
    ) -> Option<[u32; C]> {
        let (x0, y0, ax, ay) = self.footprint(sx, sy)?;
        let (wx, wy) = (cubic_weights(ax as i32), cubic_weights(ay as i32));
        let c = self.channels;
        let (last_x, last_y) = (self.max_x as usize, self.max_y as usize);
        let cols: [usize; 4] = std::array::from_fn(|i| (x0 + i).saturating_sub(1).min(last_x) * c);
        let mut acc = [0i32; C];
        for (j, &w_row) in wy.iter().enumerate() {
            let row = (y0 + j).saturating_sub(1).min(last_y) * self.stride;
            let taps = data.get(row..row + cols[3] + C)?;
            for (ch, a) in acc.iter_mut().enumerate() {
                let along: i32 = (0..4).map(|i| wx[i] * taps[cols[i] + ch] as i32).sum();
                *a += w_row * along;
            }
        }
        Some(acc.map(|a| ((a + 128) >> 8).clamp(0, 255 * 256) as u32))
    }

    /// 8.8 fixed-point sample of a single-channel plane at `(sx, sy)`, bilinear
    /// or bicubic as the geometry says; `None` outside it. The same arithmetic
    /// as [`Geometry::sample`], one channel.
    #[inline(always)]
    pub(crate) fn sample_gray(&self, data: &[u8], sx: f32, sy: f32) -> Option<u32> {
        if self.cubic {
            return self.sample_cubic_channels::<1>(data, sx, sy).map(|[v]| v);
        }
        let (x0, y0, ax, ay) = self.footprint(sx, sy)?;
        let (bx, by) = (256 - ax, 256 - ay);
        let i = y0 * self.stride + x0;
        let s = self.stride;
        let taps = data.get(i..i + s + 2)?;
        let top = taps[0] as u32 * bx + taps[1] as u32 * ax;
        let bot = taps[s] as u32 * bx + taps[s + 1] as u32 * ax;
        Some((top * by + bot * ay + 128) >> 8)
    }

    /// 8.8 fixed-point RGB sample of `data` at `(sx, sy)`, bilinear or
    /// bicubic as the geometry says; `None` outside the frame.
    #[inline(always)]
    pub(crate) fn sample(&self, data: &[u8], sx: f32, sy: f32) -> Option<[u32; 3]> {
        if self.cubic {
            return self.sample_cubic_channels::<3>(data, sx, sy);
        }
        let (x0, y0, ax, ay) = self.footprint(sx, sy)?;
        let (bx, by) = (256 - ax, 256 - ay);
        let c = self.channels;
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

/// Catmull-Rom weights (Keys' cubic convolution kernel, `a = -1/2`) of the
/// taps at `-1, 0, 1, 2` pixels from `x0`, in 1/256, for the 8-bit fraction
/// `a` in `0..=256` (`t = a / 256`):
/// ```text
/// w0 = (-t^3 + 2 t^2 - t) / 2      w2 = (-3 t^3 + 4 t^2 + t) / 2
/// w3 = (t^3 - t^2) / 2             w1 = 1 - w0 - w2 - w3
/// ```
/// `w0`, `w2`, `w3` scaled by 256 and rounded half up in integers
/// (`256 w = P(a) / 2^17`; `|P| < 2^26`, no overflow), `w1` the rest so the
/// weights sum to exactly 256: flat areas stay flat. `a = 0` gives
/// `(0, 256, 0, 0)` (a whole-pixel sample is the pixel), `a = 256` gives
/// `(0, 0, 256, 0)`. The vector kernels compute the same expression lane by lane.
#[inline(always)]
pub(crate) fn cubic_weights(a: i32) -> [i32; 4] {
    let (a2, half) = (a * a, 1 << 16);
    let a3 = a2 * a;
    let w0 = (-a3 + 512 * a2 - 65536 * a + half) >> 17;
    let w2 = (-3 * a3 + 1024 * a2 + 65536 * a + half) >> 17;
    let w3 = (a3 - 256 * a2 + half) >> 17;
    [w0, 256 - w0 - w2 - w3, w2, w3]
}

/// An output pixel from the sum of its frames' 8.8 fixed-point samples:
/// `round(sum / (256 n))`, 0 where `n = 0` (`1 / (256 n)` is inf there and
/// `0 * inf = NaN`, which `as u8` maps to 0). The reference for the kernels'
/// finishing passes.
#[inline(always)]
pub(crate) fn average(sum: u32, n: u32) -> u8 {
    (sum as f32 * (1.0 / (256.0 * n as f32)) + 0.5) as u8
}

/// Where a frame's source coordinates along the row come from.
#[derive(Clone, Copy, Debug)]
pub(crate) enum RowCoords<'a> {
    /// Precomputed `(xs[u], ys[u])` (NaN: no sample).
    Table(&'a [f32], &'a [f32]),
    /// A homography row ([`HomographyRow`]).
    Homography(HomographyRow),
}

/// A homography row: `x = (x0 + dx u) / z`, `y = (y0 + dy u) / z`,
/// `z = z0 + dz u`, NaN where `z <= 1e-6` (exactly the scalar formula).
#[derive(Clone, Copy, Debug)]
pub(crate) struct HomographyRow {
    pub(crate) x0: f32,
    pub(crate) y0: f32,
    pub(crate) z0: f32,
    pub(crate) dx: f32,
    pub(crate) dy: f32,
    pub(crate) dz: f32,
}

impl RowCoords<'_> {
    /// Source coordinates of output pixel `u`: the scalar formula the vector
    /// kernels reproduce (the warper's `fill_row` computes the same for tables).
    #[inline]
    pub(crate) fn at(&self, u: usize) -> (f32, f32) {
        match *self {
            RowCoords::Table(xs, ys) => (xs[u], ys[u]),
            RowCoords::Homography(h) => {
                let uf = u as f32;
                let z = h.z0 + h.dz * uf;
                let iz = if z > 1e-6 { 1.0 / z } else { f32::NAN };
                ((h.x0 + h.dx * uf) * iz, (h.y0 + h.dy * uf) * iz)
            }
        }
    }
}

/// Frame geometry for the vector kernels, in their 32-bit lanes.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(
    not(any(
        target_arch = "x86_64",
        all(target_arch = "wasm32", target_feature = "simd128")
    )),
    allow(dead_code)
)]
pub(super) struct KernelGeometry {
    pub(super) channels: i32,
    pub(super) stride: i32,
    pub(super) max_x0: i32,
    pub(super) max_y0: i32,
    pub(super) max_x: f32,
    pub(super) max_y: f32,
    pub(super) cubic: bool,
}

#[cfg_attr(
    not(any(
        target_arch = "x86_64",
        all(target_arch = "wasm32", target_feature = "simd128")
    )),
    allow(dead_code)
)]
impl KernelGeometry {
    pub(super) fn of(geom: &Geometry) -> Self {
        Self {
            channels: geom.channels as i32,
            stride: geom.stride as i32,
            max_x0: geom.max_x0 as i32,
            max_y0: geom.max_y0 as i32,
            max_x: geom.max_x,
            max_y: geom.max_y,
            cubic: geom.cubic,
        }
    }

    /// The scalar reference's geometry (for lanes a vector kernel hands to it).
    pub(super) fn scalar(&self) -> Geometry {
        Geometry {
            channels: self.channels as usize,
            stride: self.stride as usize,
            max_x0: self.max_x0 as usize,
            max_y0: self.max_y0 as usize,
            max_x: self.max_x,
            max_y: self.max_y,
            cubic: self.cubic,
        }
    }
}

/// Whether source `y` falls along the row from output pixel `u` on (a roll
/// one way): then the window starts a row above lane 0's. For a homography
/// `y(u) = (y0 + dy u) / (z0 + dz u)`, whose slope has the sign of
/// `dy z0 - dz y0` along the whole row; for a table, from its first and
/// eighth entries (a chunk of the AVX2 kernel, or the first half of
/// the AVX-512 kernel's). Only where the window starts depends on it, never a
/// result: the taps are checked against the window either way.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) fn falls(coord: &RowCoords<'_>, u: usize) -> bool {
    match *coord {
        RowCoords::Homography(HomographyRow { y0, z0, dy, dz, .. }) => dy * z0 < dz * y0,
        RowCoords::Table(_, ys) => ys[u + 7] < ys[u],
    }
}

/// A test row whose source point moves by `(dx, dy)` a pixel from `(x0, y0)`
/// (no perspective): the windows' fixtures.
#[cfg(test)]
pub(super) fn affine_row(x0: f32, y0: f32, dx: f32, dy: f32) -> RowCoords<'static> {
    RowCoords::Homography(HomographyRow {
        x0,
        y0,
        z0: 1.0,
        dx,
        dy,
        dz: 0.0,
    })
}
