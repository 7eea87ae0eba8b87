//! Colour conversions between packed RGB and planar 4:2:0 YUV, for the few
//! places that need RGB from a YUV pipeline or the reverse (PNG folders, the
//! live feed's JPEG, the metrics' per-channel sharpness, RGB sources into a YUV
//! run). BT.601 matrices in 16.16 fixed point, limited range unless told
//! otherwise: the conversion ffmpeg applies by default.

use crate::image::{chroma_size, yuv_planes, yuv_planes_mut};

/// Converts a planar 4:2:0 frame (`width x height`, planes as
/// [`crate::PixelFormat::Yuv420p`] lays them out) to packed pixels of
/// `channels` bytes (3: RGB, 4: RGBA with alpha 255) in `out` (resized).
/// Chroma is taken from the 2x2 block each pixel lies in (nearest).
/// `full_range`: Y 0..=255 instead of 16..=235.
pub fn yuv420p_to_rgb_into(
    width: usize,
    height: usize,
    planes: &[u8],
    full_range: bool,
    channels: usize,
    out: &mut Vec<u8>,
) {
    let (cw, _) = chroma_size(width, height);
    let (luma, cb, cr) = yuv_planes(width, height, planes);
    // Fixed-point (16.16) BT.601 coefficients.
    let (ky, off, kr, kgu, kgv, kb) = if full_range {
        (65536, 0, 91881, 22554, 46802, 116130)
    } else {
        (76309, 16, 104597, 25675, 53279, 132201)
    };
    out.clear();
    out.resize(width * height * channels, 255);
    for y in 0..height {
        let yrow = &luma[y * width..(y + 1) * width];
        let row = &mut out[y * width * channels..(y + 1) * width * channels];
        let crow = (y >> 1) * cw;
        for (x, (px, &l)) in row.chunks_exact_mut(channels).zip(yrow).enumerate() {
            let c = (l as i32 - off) * ky + 32768;
            let d = cb[crow + (x >> 1)] as i32 - 128;
            let e = cr[crow + (x >> 1)] as i32 - 128;
            px[0] = ((c + kr * e) >> 16).clamp(0, 255) as u8;
            px[1] = ((c - kgu * d - kgv * e) >> 16).clamp(0, 255) as u8;
            px[2] = ((c + kb * d) >> 16).clamp(0, 255) as u8;
        }
    }
}

/// Converts packed RGB/RGBA (`channels` bytes per pixel) to planar 4:2:0 YUV
/// in `out` (resized to the [`crate::PixelFormat::Yuv420p`] length), BT.601
/// limited range, chroma from the average colour of each 2x2 block (centred
/// siting).
pub fn rgb_to_yuv420p_into(
    width: usize,
    height: usize,
    channels: usize,
    rgb: &[u8],
    out: &mut Vec<u8>,
) {
    let (cw, ch) = chroma_size(width, height);
    out.clear();
    out.resize(width * height + 2 * cw * ch, 0);
    let (luma, cb, cr) = yuv_planes_mut(width, height, out);
    for (px, yv) in rgb.chunks_exact(channels).zip(luma.iter_mut()) {
        let (r, g, b) = (px[0] as i32, px[1] as i32, px[2] as i32);
        *yv = (((16 << 16) + 16829 * r + 33039 * g + 6416 * b + 32768) >> 16) as u8;
    }
    for cy in 0..ch {
        for cx in 0..cw {
            let (mut r, mut g, mut b, mut n) = (0i32, 0i32, 0i32, 0i32);
            for y in 2 * cy..(2 * cy + 2).min(height) {
                for x in 2 * cx..(2 * cx + 2).min(width) {
                    let i = (y * width + x) * channels;
                    r += rgb[i] as i32;
                    g += rgb[i + 1] as i32;
                    b += rgb[i + 2] as i32;
                    n += 1;
                }
            }
            // Coefficients scaled by 65536 / n fold the averaging in.
            let round = 32768 * n;
            let u = ((128 << 16) * n - 9714 * r - 19071 * g + 28784 * b + round) / (65536 * n);
            let v = ((128 << 16) * n + 28784 * r - 24103 * g - 4681 * b + round) / (65536 * n);
            cb[cy * cw + cx] = u.clamp(0, 255) as u8;
            cr[cy * cw + cx] = v.clamp(0, 255) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_round_trip_is_close() {
        for rgb in [[0u8, 0, 0], [255, 255, 255], [200, 30, 90], [12, 180, 240]] {
            for (w, h) in [(4usize, 4usize), (5, 3)] {
                let img: Vec<u8> = rgb.iter().copied().cycle().take(w * h * 3).collect();
                let mut planes = Vec::new();
                rgb_to_yuv420p_into(w, h, 3, &img, &mut planes);
                let mut back = Vec::new();
                yuv420p_to_rgb_into(w, h, &planes, false, 3, &mut back);
                for (a, b) in img.iter().zip(&back) {
                    assert!((*a as i32 - *b as i32).abs() <= 2, "{rgb:?} -> {back:?}");
                }
                let mut rgba = Vec::new();
                yuv420p_to_rgb_into(w, h, &planes, false, 4, &mut rgba);
                assert!(rgba.chunks_exact(4).all(|p| p[3] == 255));
            }
        }
    }

    #[test]
    fn black_and_grey_are_the_limited_range_codes() {
        let mut planes = Vec::new();
        rgb_to_yuv420p_into(2, 2, 3, &[0; 12], &mut planes);
        assert_eq!(planes, [16, 16, 16, 16, 128, 128]);
    }
}
