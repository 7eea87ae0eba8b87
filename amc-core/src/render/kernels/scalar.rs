//! The scalar row kernel: [`accumulate_row`], the per-pixel statement of the row
//! kernels' contract, built on the reference sampler in `common.rs`. Used for
//! every pixel on targets without a vector kernel, and as the reference the vector
//! kernels are tested against.

use super::common::{Geometry, RowCoords};

/// The row kernels' contract, pixel by pixel: for `u in 0..n`,
/// `acc_{r,g,b}[u] = sum_f sample_f(coords[f] at u)` and `count[u]` = frames whose
/// coordinate lies inside the frame.
#[allow(clippy::too_many_arguments)]
pub(crate) fn accumulate_row(
    datas: &[&[u8]],
    geom: &Geometry,
    coords: &[RowCoords<'_>],
    n: usize,
    acc_r: &mut [u32],
    acc_g: &mut [u32],
    acc_b: &mut [u32],
    count: &mut [u32],
) {
    for u in 0..n {
        let (mut sum, mut covered) = ([0u32; 3], 0u32);
        for (data, coord) in datas.iter().zip(coords) {
            let (sx, sy) = coord.at(u);
            if let Some(rgb) = geom.sample(data, sx, sy) {
                sum[0] += rgb[0];
                sum[1] += rgb[1];
                sum[2] += rgb[2];
                covered += 1;
            }
        }
        acc_r[u] = sum[0];
        acc_g[u] = sum[1];
        acc_b[u] = sum[2];
        count[u] = covered;
    }
}

/// The single-channel contract, pixel by pixel: for `u in 0..n`,
/// `acc[u] = sum_f sample_f(coords[f] at u)` and `count[u]` = frames whose
/// coordinate lies inside the plane.
pub(crate) fn accumulate_row_gray(
    datas: &[&[u8]],
    geom: &Geometry,
    coords: &[RowCoords<'_>],
    n: usize,
    acc: &mut [u32],
    count: &mut [u32],
) {
    for u in 0..n {
        let (mut sum, mut covered) = (0u32, 0u32);
        for (data, coord) in datas.iter().zip(coords) {
            let (sx, sy) = coord.at(u);
            if let Some(v) = geom.sample_gray(data, sx, sy) {
                sum += v;
                covered += 1;
            }
        }
        acc[u] = sum;
        count[u] = covered;
    }
}
