//! Fixtures the integration tests share.

use amc_core::{Frame, PixelFormat};

/// Lattice hash in `[0, 1]` (a few rounds of integer mixing; deterministic everywhere).
pub fn hash(x: u32, y: u32, seed: u32) -> f32 {
    let mut h = x.wrapping_mul(0x8da6_b343) ^ y.wrapping_mul(0xd816_3841) ^ seed;
    h = (h ^ (h >> 16)).wrapping_mul(0x7feb_352d);
    h = (h ^ (h >> 15)).wrapping_mul(0x846c_a68b);
    h ^= h >> 16;
    (h & 0xffff) as f32 / 65535.0
}

/// Value noise with `cell`-pixel lattice cells, smoothstep-interpolated, wrapping
/// horizontally every `width` pixels (so the panorama has no seam).
fn value_noise(x: usize, y: usize, cell: usize, width: usize, seed: u32) -> f32 {
    let cells_x = (width / cell) as u32;
    let (cx, cy) = ((x / cell) as u32, (y / cell) as u32);
    let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
    let fx = smooth((x % cell) as f32 / cell as f32);
    let fy = smooth((y % cell) as f32 / cell as f32);
    let at = |i: u32, j: u32| hash(i % cells_x, j, seed);
    let top = at(cx, cy) + (at(cx + 1, cy) - at(cx, cy)) * fx;
    let bot = at(cx, cy + 1) + (at(cx + 1, cy + 1) - at(cx, cy + 1)) * fx;
    top + (bot - top) * fy
}

/// A procedural 2:1 equirectangular panorama: texture at every scale from 4 to 128
/// pixels (value-noise octaves), so the tracker has gradients at all pyramid levels.
pub fn panorama() -> Frame {
    let (w, h) = (2048usize, 1024usize);
    let mut pano = Frame::new(w, h, PixelFormat::Rgb8);
    let octaves = [128usize, 64, 32, 16, 8, 4];
    for (i, px) in pano.data.chunks_exact_mut(3).enumerate() {
        let (x, y) = (i % w, i / w);
        let noise = |seed: u32| {
            octaves
                .iter()
                .enumerate()
                .map(|(k, &cell)| value_noise(x, y, cell, w, seed + k as u32))
                .sum::<f32>()
                / octaves.len() as f32
        };
        // Octave sums concentrate around 0.5: stretch them to use the byte range.
        let byte = |v: f32| ((v - 0.5) * 3.0 * 255.0 + 127.5).clamp(0.0, 255.0) as u8;
        let (a, b) = (byte(noise(0x1234_5678)), byte(noise(0x9abc_def0)));
        px.copy_from_slice(&[a, ((a as u16 + b as u16) / 2) as u8, 255 - b]);
    }
    pano
}
