//! Rendering views of an equirectangular panorama through any camera model,
//! with a rolling shutter (see the crate's docs for the mapping).

use amc_core::camera::CameraModel;
use amc_core::error::AmcError;
use amc_core::image::{Frame, FrameRef, PixelFormat};
use amc_core::so3::Rot;
use nalgebra::Vector2;
use std::f64::consts::PI;

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
    /// ([`row_fraction`](amc_core::shutter::row_fraction): `-1/2` for the first
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
            let r = orientation(amc_core::shutter::row_fraction(v as f64, self.height));
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
    use crate::rng::SplitMix64;
    use crate::shake::{Shake, ShakeParams};
    use amc_core::so3::{self, Tangent};

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
}
