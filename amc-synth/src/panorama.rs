//! A panorama brought to a camera's angular resolution: the box filter and
//! its factor.

use amc_core::camera::CameraModel;
use amc_core::image::{Frame, FrameRef};
use std::f64::consts::PI;

/// Box-filters a panorama by `factor` in both directions (`factor <= 1` copies).
///
/// The output is `round(W / factor) x round(H / factor)` (at least 1x1) and each
/// output pixel is the area-weighted mean of the source pixels under its
/// footprint, so the output still spans the full sphere and the equirectangular
/// mapping is preserved even when `factor` does not divide the size. The output
/// has the input's pixel format.
pub fn downsample_pano(pano: &FrameRef<'_>, factor: usize) -> Frame {
    let ch = pano.format.channels();
    let expected = pano.width * pano.height * ch;
    if factor <= 1 || pano.width == 0 || pano.height == 0 || pano.data.len() != expected {
        return Frame {
            width: pano.width,
            height: pano.height,
            format: pano.format,
            data: pano.data.to_vec(),
        };
    }
    let ow = ((pano.width as f64 / factor as f64).round() as usize).max(1);
    let oh = ((pano.height as f64 / factor as f64).round() as usize).max(1);
    let wx = box_weights(pano.width, ow);
    let wy = box_weights(pano.height, oh);
    // Horizontal pass: pano.height x ow x ch.
    let mut tmp = vec![0f32; pano.height * ow * ch];
    for y in 0..pano.height {
        let src = &pano.data[y * pano.width * ch..(y + 1) * pano.width * ch];
        let dst = &mut tmp[y * ow * ch..(y + 1) * ow * ch];
        for (ox, taps) in wx.iter().enumerate() {
            for &(sx, w) in taps {
                for c in 0..ch {
                    dst[ox * ch + c] += w * src[sx * ch + c] as f32;
                }
            }
        }
    }
    // Vertical pass.
    let mut out = Frame::new(ow, oh, pano.format);
    let mut acc = vec![0f32; ow * ch];
    for (oy, taps) in wy.iter().enumerate() {
        acc.iter_mut().for_each(|a| *a = 0.0);
        for &(sy, w) in taps {
            let row = &tmp[sy * ow * ch..(sy + 1) * ow * ch];
            for (a, &v) in acc.iter_mut().zip(row) {
                *a += w * v;
            }
        }
        let dst = &mut out.data[oy * ow * ch..(oy + 1) * ow * ch];
        for (d, &a) in dst.iter_mut().zip(&acc) {
            *d = a.round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

/// For each of `m` output cells spanning `n` input pixels, the (input index,
/// weight) pairs of the area-weighted box filter; weights sum to 1.
fn box_weights(n: usize, m: usize) -> Vec<Vec<(usize, f32)>> {
    let scale = n as f64 / m as f64;
    (0..m)
        .map(|i| {
            let a = i as f64 * scale;
            let b = (i + 1) as f64 * scale;
            let first = a.floor() as usize;
            let last = ((b.ceil() as usize).min(n)).max(first + 1);
            (first..last)
                .filter_map(|s| {
                    let overlap = (b.min(s as f64 + 1.0) - a.max(s as f64)).max(0.0);
                    (overlap > 1e-12).then(|| (s, (overlap / scale) as f32))
                })
                .collect()
        })
        .collect()
}

/// The box-filter factor that brings a panorama `pano_width` pixels wide
/// (360 degrees) to about the camera's angular resolution at its centre:
/// `floor((pano_width / 2 pi) / fx)`, at least 1.
pub fn pano_downsample_factor(pano_width: usize, camera: &CameraModel) -> usize {
    let pano_px_per_rad = pano_width as f64 / (2.0 * PI);
    let f = camera.fx.abs().max(camera.fy.abs());
    if !(f > 0.0 && f.is_finite()) {
        return 1;
    }
    ((pano_px_per_rad / f).floor() as usize).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use amc_core::image::PixelFormat;

    #[test]
    fn downsample_box_filter() {
        // 4x2 RGB, factor 2 -> 2x1, each the mean of a 2x2 block.
        let data: Vec<u8> = (0..24).map(|i| (i * 10) as u8).collect();
        let pano = FrameRef::new(4, 2, PixelFormat::Rgb8, &data).unwrap();
        let d = downsample_pano(&pano, 2);
        assert_eq!((d.width, d.height), (2, 1));
        // Block 0: pixels 0,1 (row 0) and 4,5 (row 1); red = (0+30+120+150)/4 = 75.
        assert_eq!(d.data[0], 75);
        assert_eq!(d.data[3], 135); // (60 + 90 + 180 + 210) / 4
                                    // Non-dividing factor keeps a full-sphere mapping and preserves a constant.
        let flat = vec![77u8; 10 * 5 * 4];
        let p = FrameRef::new(10, 5, PixelFormat::Rgba8, &flat).unwrap();
        let d = downsample_pano(&p, 3);
        assert_eq!((d.width, d.height, d.format), (3, 2, PixelFormat::Rgba8));
        assert!(d.data.iter().all(|&c| c == 77));
        assert_eq!(downsample_pano(&p, 1).data, flat);
        // Factor from the camera: 4096 px / 2 pi = 652 px/rad vs fx = 160 -> 4.
        let cam = CameraModel::pinhole_hfov(320, 180, 90.0).unwrap();
        assert_eq!(pano_downsample_factor(4096, &cam), 4);
        assert_eq!(pano_downsample_factor(100, &cam), 1);
    }
}
