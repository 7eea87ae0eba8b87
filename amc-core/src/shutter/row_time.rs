//! When each pixel of an image derived from the sensor was read out.

use super::motion::row_fraction;
use crate::camera::CameraModel;
use crate::image::GrayImage;
use nalgebra::Vector2;

/// The readout fraction `s` ([`row_fraction`] of the sensor row) of every
/// pixel of an image derived from a rolling-shutter sensor's frames (the
/// tracker's downscaled, undistorted image and its pyramid). A box-downscaled
/// pinhole keeps rows straight, so `s` is affine in the row; an undistorted
/// image of a distorted lens bends them, so `s` is tabulated per pixel.
#[derive(Clone, Debug)]
pub enum RowTime {
    /// `s = a v + b` at pixel row `v` of the image.
    Affine {
        /// Change of `s` per row.
        a: f32,
        /// `s` at row 0.
        b: f32,
    },
    /// `s` per pixel, row-major, `width` wide.
    Table {
        /// Image width, pixels.
        width: usize,
        /// Image height, pixels.
        height: usize,
        /// `s` per pixel (NaN where the pixel's ray leaves the sensor's lens).
        s: Vec<f32>,
    },
}

impl RowTime {
    /// The readout fractions of `image`'s pixels, for an image seeing the
    /// same rays as `sensor` (the camera of the full-resolution frames).
    pub fn new(sensor: &CameraModel, image: &CameraModel) -> Self {
        let row_of = |u: f64, v: f64| {
            image
                .unproject(&Vector2::new(u, v))
                .and_then(|ray| sensor.project(&ray))
                .map(|p| row_fraction(p.y, sensor.height))
        };
        if sensor.is_pinhole() && image.is_pinhole() && sensor.skew == 0.0 && image.skew == 0.0 {
            // Same rays through two pinholes without skew: rows map to rows.
            let cy = image.cy;
            if let (Some(s0), Some(s1)) = (row_of(image.cx, cy), row_of(image.cx, cy + 1.0)) {
                let a = s1 - s0;
                return RowTime::Affine {
                    a: a as f32,
                    b: (s0 - a * cy) as f32,
                };
            }
        }
        let (width, height) = (image.width, image.height);
        let mut s = Vec::with_capacity(width * height);
        for v in 0..height {
            for u in 0..width {
                s.push(row_of(u as f64, v as f64).map_or(f32::NAN, |x| x as f32));
            }
        }
        RowTime::Table { width, height, s }
    }

    /// `s` at pixel `(u, v)` of pyramid level `level` (a 2x2 box halving per
    /// level: level-`l` pixel `u` is at `2^l u + (2^l - 1) / 2` of level 0).
    /// Outside a table, the nearest edge's value.
    #[inline]
    pub fn at(&self, level: usize, u: f32, v: f32) -> f32 {
        let k = (1u32 << level) as f32;
        let off = 0.5 * (k - 1.0);
        match self {
            RowTime::Affine { a, b } => a * (k * v + off) + b,
            RowTime::Table { width, height, s } => {
                let x = (k * u + off).clamp(0.0, (*width - 1) as f32);
                let y = (k * v + off).clamp(0.0, (*height - 1) as f32);
                let (x0, y0) = (
                    (x as usize).min(width.saturating_sub(2)),
                    (y as usize).min(height.saturating_sub(2)),
                );
                let (ax, ay) = (x - x0 as f32, y - y0 as f32);
                let i = y0 * width + x0;
                let (t0, t1) = (s[i], s.get(i + 1).copied().unwrap_or(s[i]));
                let (b0, b1) = (
                    s.get(i + width).copied().unwrap_or(t0),
                    s.get(i + width + 1).copied().unwrap_or(t1),
                );
                let top = t0 + (t1 - t0) * ax;
                let bot = b0 + (b1 - b0) * ax;
                top + (bot - top) * ay
            }
        }
    }

    /// A table's `s` at every pixel of a `width x height` pyramid level
    /// ([`RowTime::at`] there), for sampling bilinearly between pixels as the
    /// level's image is sampled: the tracker's vector kernels gather from it,
    /// where a lookup through [`RowTime::at`] per point (a scalar call with
    /// clamps and bounds checks) kept the whole per-point pass scalar. Between
    /// pixels it interpolates on the level's grid rather than the finest one's;
    /// `s` is smooth, so inside the image the two differ by little (see
    /// `docs/core-history.md#shutter-level-table`). Past the level's edges,
    /// where only a landing's iterates stray, it clamps at the level's last
    /// pixel rather than at the finest level's. `None` for an affine `s`, which
    /// the tracker evaluates directly.
    pub fn level_table(&self, level: usize, width: usize, height: usize) -> Option<GrayImage> {
        if let RowTime::Affine { .. } = self {
            return None;
        }
        let mut table = GrayImage::new(width, height);
        for v in 0..height {
            for u in 0..width {
                table.data[v * width + u] = self.at(level, u as f32, v as f32);
            }
        }
        Some(table)
    }
}
