//! The scalar row kernel: [`accumulate_row`], the per-pixel statement of the row
//! kernels' contract, built on the reference sampler in `common.rs`. Used for
//! every pixel on targets without a vector kernel, and as the reference the vector
//! kernels are tested against.

use super::common::{Geometry, RowCoords};
use crate::render::robust::{Deghost, FULL_WEIGHT};

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

/// The ghost-free contract, pixel by pixel (see [`crate::render::robust`]): for
/// `u in start..n`, with the last frame the reference, `sum_{r,g,b}[u] =
/// sum_f w_f sample_f`, `weight[u] = sum_f w_f` and `count[u]` = frames whose
/// coordinate lies inside the frame; `w_f` is [`Deghost::weight`] of the
/// largest channel difference from the reference's sample (16 for the
/// reference, and for every frame where the reference does not cover the pixel).
#[allow(clippy::too_many_arguments)]
pub(crate) fn merge_row(
    datas: &[&[u8]],
    geom: &Geometry,
    coords: &[RowCoords<'_>],
    deghost: Deghost,
    (start, n): (usize, usize),
    sum: [&mut [u32]; 3],
    weight: &mut [u32],
    count: &mut [u32],
) {
    let [sum_r, sum_g, sum_b] = sum;
    let last = datas.len() - 1;
    for u in start..n {
        let (rx, ry) = coords[last].at(u);
        let reference = geom.sample(datas[last], rx, ry);
        let [r0, g0, b0] = reference.unwrap_or_default();
        let mut acc = [0u32; 3];
        let (mut wsum, mut covered) = (0u32, 0u32);
        for (f, (data, coord)) in datas.iter().zip(coords).enumerate() {
            let (sx, sy) = coord.at(u);
            if let Some([r, g, b]) = geom.sample(data, sx, sy) {
                let w = if f == last || reference.is_none() {
                    FULL_WEIGHT
                } else {
                    deghost.weight(r.abs_diff(r0).max(g.abs_diff(g0)).max(b.abs_diff(b0)))
                };
                acc[0] += w * r;
                acc[1] += w * g;
                acc[2] += w * b;
                wsum += w;
                covered += 1;
            }
        }
        (sum_r[u], sum_g[u], sum_b[u]) = (acc[0], acc[1], acc[2]);
        weight[u] = wsum;
        count[u] = covered;
    }
}

/// The single-channel form of [`merge_row`], for the planes of planar frames.
#[allow(clippy::too_many_arguments)]
pub(crate) fn merge_row_gray(
    datas: &[&[u8]],
    geom: &Geometry,
    coords: &[RowCoords<'_>],
    deghost: Deghost,
    (start, n): (usize, usize),
    sum: &mut [u32],
    weight: &mut [u32],
    count: &mut [u32],
) {
    let last = datas.len() - 1;
    for u in start..n {
        let (rx, ry) = coords[last].at(u);
        let reference = geom.sample_gray(datas[last], rx, ry);
        let v0 = reference.unwrap_or_default();
        let (mut acc, mut wsum, mut covered) = (0u32, 0u32, 0u32);
        for (f, (data, coord)) in datas.iter().zip(coords).enumerate() {
            let (sx, sy) = coord.at(u);
            if let Some(v) = geom.sample_gray(data, sx, sy) {
                let w = if f == last || reference.is_none() {
                    FULL_WEIGHT
                } else {
                    deghost.weight(v.abs_diff(v0))
                };
                acc += w * v;
                wsum += w;
                covered += 1;
            }
        }
        sum[u] = acc;
        weight[u] = wsum;
        count[u] = covered;
    }
}
