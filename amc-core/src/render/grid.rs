//! A row of source coordinates interpolated from a node grid.
//!
//! Where the output -> source map is not one homography (a distorted lens, a
//! rolling shutter), the warper evaluates it exactly on a grid of nodes every
//! `step` output pixels and fills each output row's coordinate tables by
//! bilinear interpolation between them: the row's value at each node column
//! (interpolated once between the two node rows around it), then along the
//! row, `x(k step + i) = left + (right - left) (k + i / step)`.
//!
//! That fill runs once per output row, frame and plane, as often as the row
//! kernels themselves, and its generic loop (a cell length known only at run
//! time, SSE2 only) cost as much as the luma kernel of a rolling-shutter
//! render. So the two steps the warper uses are compiled with their cell
//! length fixed, and on x86-64 once more for AVX2 (picked at run time; an
//! AVX-512 build of it measured no faster). Every
//! version computes each coordinate with the same two operations in the same
//! order (no fused multiply-add: Rust never contracts), so all give the same
//! bits.

/// The largest grid step supported (a power of two).
pub const MAX_STEP: usize = 16;

/// Fills `xs` and `ys` (the first `min(xs.len(), ys.len())` pixels of output
/// row `v`) from `grid`, `grid_w x grid_h` nodes of `[x, y]` spaced `step`
/// pixels apart (`step` a power of two, at most [`MAX_STEP`]). The last cell
/// extrapolates to the row's end, as the nodes end there. Rows below the last
/// node row extrapolate from the last two.
pub fn interpolate_row(
    grid: &[[f32; 2]],
    grid_w: usize,
    grid_h: usize,
    step: usize,
    v: usize,
    xs: &mut [f32],
    ys: &mut [f32],
) {
    debug_assert!(step.is_power_of_two() && step <= MAX_STEP);
    if grid_w < 2 {
        return;
    }
    let gy = (v / step).min(grid_h.saturating_sub(2));
    let fy = (v - gy * step) as f32 / step as f32;
    let r0 = &grid[gy * grid_w..(gy + 1) * grid_w];
    let r1 = &grid[(gy + 1) * grid_w..(gy + 2) * grid_w];
    let row = NodeRows { r0, r1, fy };
    // The cell length fixed at compile time (the warper's steps) lets the
    // per-pixel loop become straight-line vector code.
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        unsafe {
            match step {
                16 => fill_avx2::<16>(&row, xs, ys),
                8 => fill_avx2::<8>(&row, xs, ys),
                _ => fill(&row, step, xs, ys),
            }
        }
        return;
    }
    match step {
        16 => fill(&row, 16, xs, ys),
        8 => fill(&row, 8, xs, ys),
        _ => fill(&row, step, xs, ys),
    }
}

/// The two node rows around an output row and the row's place between them.
struct NodeRows<'a> {
    r0: &'a [[f32; 2]],
    r1: &'a [[f32; 2]],
    fy: f32,
}

impl NodeRows<'_> {
    /// The row's value at node column `g`: interpolated between the two node
    /// rows once per node, so each pixel costs one interpolation per
    /// coordinate.
    #[inline(always)]
    fn node(&self, g: usize) -> [f32; 2] {
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let (a, b) = (self.r0[g], self.r1[g]);
        [lerp(a[0], b[0], self.fy), lerp(a[1], b[1], self.fy)]
    }
}

/// One cell's pixels (`k` cells past `left`: the last cell extrapolates in
/// whole cells past its node): `left + d (k + i / step)` per coordinate.
#[inline(always)]
fn fill_block(
    left: [f32; 2],
    d: [f32; 2],
    k: f32,
    offsets: &[f32],
    xs: &mut [f32],
    ys: &mut [f32],
) {
    for ((xo, yo), &f) in xs.iter_mut().zip(ys.iter_mut()).zip(offsets) {
        let fx = k + f;
        *xo = left[0] + d[0] * fx;
        *yo = left[1] + d[1] * fx;
    }
}

/// The row cell by cell; each cell's whole blocks of `step` pixels, then
/// the rest. Inlined where `step` is a constant, whole blocks have a known
/// length, so the per-pixel loop needs no bounds checks or tail.
#[inline(always)]
fn fill(row: &NodeRows<'_>, step: usize, xs: &mut [f32], ys: &mut [f32]) {
    // Each pixel's offset in its cell, `i / step` (exact: `step` is a power
    // of two), from a table: converting the index per pixel is a scalar
    // `usize -> f32` that keeps the loop from vectorizing.
    let inv_step = 1.0 / step as f32;
    let all: [f32; MAX_STEP] = std::array::from_fn(|i| i as f32 * inv_step);
    let offsets = &all[..step.min(MAX_STEP)];
    let n = xs.len().min(ys.len());
    let grid_w = row.r0.len();
    let mut left = row.node(0);
    for gx in 0..grid_w - 1 {
        let start = gx * step;
        if start >= n {
            break;
        }
        let end = if gx + 2 == grid_w {
            n
        } else {
            (start + step).min(n)
        };
        let right = row.node(gx + 1);
        let d = [right[0] - left[0], right[1] - left[1]];
        let mut xb = xs[start..end].chunks_exact_mut(step);
        let mut yb = ys[start..end].chunks_exact_mut(step);
        let mut k = 0.0f32;
        for (xo, yo) in (&mut xb).zip(&mut yb) {
            fill_block(left, d, k, offsets, xo, yo);
            k += 1.0;
        }
        fill_block(
            left,
            d,
            k,
            offsets,
            xb.into_remainder(),
            yb.into_remainder(),
        );
        left = right;
    }
}

/// [`fill`] with a step fixed at compile time, compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fill_avx2<const N: usize>(row: &NodeRows<'_>, xs: &mut [f32], ys: &mut [f32]) {
    fill(row, N, xs, ys)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The previous generic fill, kept as the reference every version must
    /// match bit for bit.
    fn reference(grid: &[[f32; 2]], gw: usize, gh: usize, step: usize, v: usize) -> Vec<[f32; 2]> {
        let gy = (v / step).min(gh.saturating_sub(2));
        let fy = (v - gy * step) as f32 / step as f32;
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let node = |g: usize| {
            let (a, b) = (grid[gy * gw + g], grid[(gy + 1) * gw + g]);
            [lerp(a[0], b[0], fy), lerp(a[1], b[1], fy)]
        };
        let n = (gw - 1) * step + 5;
        let mut out = vec![[0.0f32; 2]; n];
        let inv = 1.0 / step as f32;
        for (u, o) in out.iter_mut().enumerate() {
            let gx = (u / step).min(gw - 2);
            let (l, r) = (node(gx), node(gx + 1));
            let local = u - gx * step;
            let fx = (local / step) as f32 + (local % step) as f32 * inv;
            *o = [l[0] + (r[0] - l[0]) * fx, l[1] + (r[1] - l[1]) * fx];
        }
        out
    }

    #[test]
    fn every_version_matches_the_reference_bit_for_bit() {
        let (gw, gh) = (7, 5);
        // Irregular node values (a lens's curved map), incl. large and tiny ones.
        let grid: Vec<[f32; 2]> = (0..gw * gh)
            .map(|i| {
                let t = i as f32;
                [
                    1.37 * t * t - 0.3 * t + 1e-3,
                    512.25 - 7.1 * t + (t * 0.77).sin(),
                ]
            })
            .collect();
        for step in [8, 16, 4, 2] {
            let n = (gw - 1) * step + 5;
            for v in [0, 1, step - 1, step, 2 * step + 3, (gh - 1) * step + 2] {
                let want = reference(&grid, gw, gh, step, v);
                for len in [n, n - 7, step + 1, 3] {
                    let (mut xs, mut ys) = (vec![0.0; len], vec![0.0; len]);
                    interpolate_row(&grid, gw, gh, step, v, &mut xs, &mut ys);
                    let row = NodeRows {
                        r0: &grid[(v / step).min(gh - 2) * gw..][..gw],
                        r1: &grid[((v / step).min(gh - 2) + 1) * gw..][..gw],
                        fy: (v - (v / step).min(gh - 2) * step) as f32 / step as f32,
                    };
                    let (mut xc, mut yc) = (vec![0.0; len], vec![0.0; len]);
                    fill(&row, step, &mut xc, &mut yc);
                    for u in 0..len {
                        for (got, what) in [(xs[u], "dispatch"), (xc[u], "generic")] {
                            assert_eq!(
                                got.to_bits(),
                                want[u][0].to_bits(),
                                "{what} x: step {step} v {v} u {u}"
                            );
                        }
                        for (got, what) in [(ys[u], "dispatch"), (yc[u], "generic")] {
                            assert_eq!(
                                got.to_bits(),
                                want[u][1].to_bits(),
                                "{what} y: step {step} v {v} u {u}"
                            );
                        }
                    }
                }
            }
        }
    }
}
