//! Row kernels: bilinear or bicubic sampling of several frames along one output
//! row, summed in 8.8 fixed point.
//!
//! Two operations, each in a plain and a ghost-free form: the sum of the
//! frames' samples (`accumulate_row`), and their sum weighted by agreement with
//! the last frame's (`merge_row`, see [`crate::render::robust`]).
//!
//! `scalar.rs` is the reference; `avx2.rs` (x86-64, chosen at run time when the
//! CPU has AVX2), `avx512.rs` (x86-64 with AVX-512 VBMI: the planes' rows, by
//! byte permutes instead of gathers) and `simd128.rs` (wasm32, chosen at
//! compile time with the `simd128` target feature) are bit-exact with it.
//! [`Kernel`] is the one dispatcher: [`Kernel::detect`] picks the kernel, its
//! methods run it. Bicubic sampling (a geometry's `cubic`) has a vector form in
//! every kernel, for planes and for interleaved frames (AVX-512 runs the
//! AVX2 form of the interleaved ones, as it does for bilinear sampling).
//!
//! Layers: this dispatcher uses the kernels, and they all use `common.rs` (the
//! constants, row coordinates, frame geometry and reference sampler they share);
//! no kernel uses the dispatcher.

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
mod common;
mod scalar;
#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
mod simd128;

use crate::render::robust::Deghost;
#[cfg(test)]
pub(crate) use common::cubic_weights;
pub(crate) use common::{average, Geometry, RowCoords};
pub use common::{EDGE_TOLERANCE, FRAME_PADDING};
pub(crate) use scalar::{merge_row as merge_row_scalar, merge_row_gray as merge_row_gray_scalar};

/// Whether the AVX2 kernel can run on this CPU.
pub fn avx2_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the AVX-512 plane kernel can run on this CPU (AVX-512 F, BW, VL and VBMI).
pub fn avx512_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        avx512::available()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether a vectorized kernel can run here: AVX2 on this x86-64 CPU, or a
/// wasm32 build with the `simd128` target feature.
pub fn vector_kernel_available() -> bool {
    Kernel::detect().is_vectorized()
}

/// A row kernel. The vectorized variants exist only in builds that can run them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// The scalar reference (`scalar.rs`): every target.
    Scalar,
    /// x86-64 AVX2, eight pixels at a time with gathers (`avx2.rs`).
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// x86-64 AVX-512 (F, BW, VL, VBMI): the planes' rows sixteen pixels at a
    /// time, their taps picked by byte permutes (`avx512.rs`), plain and
    /// ghost-free; interleaved rows run the AVX2 kernel, which every such CPU has.
    #[cfg(target_arch = "x86_64")]
    Avx512,
    /// WebAssembly `simd128`, four pixels at a time (`simd128.rs`).
    #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
    Simd128,
}

impl Kernel {
    /// The fastest kernel for this build and CPU: AVX-512 or else AVX2 when the
    /// x86-64 CPU has it, `simd128` in wasm32 builds with that target feature,
    /// else the scalar one.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if avx512_available() {
                Kernel::Avx512
            } else if avx2_available() {
                Kernel::Avx2
            } else {
                Kernel::Scalar
            }
        }
        #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
        {
            Kernel::Simd128
        }
        #[cfg(not(any(
            target_arch = "x86_64",
            all(target_arch = "wasm32", target_feature = "simd128")
        )))]
        {
            Kernel::Scalar
        }
    }

    /// Every kernel this build can run on this CPU, the scalar reference first
    /// (for tests and benches that compare them).
    pub fn available() -> Vec<Self> {
        #[allow(unused_mut)]
        let mut kernels = vec![Kernel::Scalar];
        #[cfg(target_arch = "x86_64")]
        {
            if avx2_available() {
                kernels.push(Kernel::Avx2);
            }
            if avx512_available() {
                kernels.push(Kernel::Avx512);
            }
        }
        #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
        kernels.push(Kernel::Simd128);
        kernels
    }

    /// True for the vector kernels.
    pub fn is_vectorized(self) -> bool {
        !matches!(self, Kernel::Scalar)
    }

    /// Whether this kernel samples a pair of planes bicubically in one pass
    /// (AVX-512: one window and one set of weights for both); the others
    /// sample one plane, then the other.
    fn pairs_bicubic(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            self == Kernel::Avx512
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    }

    /// Accumulates the samples of several frames along one output row: for
    /// `u in 0..n`, `acc_{r,g,b}[u] = sum_f sample_f(coords[f] at u)` (8.8 fixed
    /// point) and `count[u]` = frames whose coordinate lies inside the frame.
    ///
    /// # Safety
    /// A vectorized kernel must come from [`Kernel::detect`] on this machine, and
    /// then `n` must be a multiple of 8; every `datas[f]` must be non-empty and hold
    /// the whole frame plus [`FRAME_PADDING`] bytes; coordinate tables and the
    /// outputs must have at least `n` elements.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) unsafe fn accumulate_row(
        self,
        datas: &[&[u8]],
        geom: &Geometry,
        coords: &[RowCoords<'_>],
        n: usize,
        acc_r: &mut [u32],
        acc_g: &mut [u32],
        acc_b: &mut [u32],
        count: &mut [u32],
    ) {
        match self {
            Kernel::Scalar => {
                scalar::accumulate_row(datas, geom, coords, n, acc_r, acc_g, acc_b, count)
            }
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 | Kernel::Avx512 => avx2::accumulate_row(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                n,
                acc_r,
                acc_g,
                acc_b,
                count,
            ),
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            Kernel::Simd128 => simd128::accumulate_row(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                n,
                acc_r,
                acc_g,
                acc_b,
                count,
            ),
        }
    }

    /// The single-channel form of [`Kernel::accumulate_row`], for the planes of
    /// planar frames: for `u in 0..n`, `acc[u] = sum_f sample_f(coords[f] at u)`
    /// and `count[u]` = frames whose coordinate lies inside the plane.
    ///
    /// # Safety
    /// As [`Kernel::accumulate_row`], with `datas[f]` a single-channel plane
    /// followed by at least 2 readable bytes.
    #[inline]
    pub(crate) unsafe fn accumulate_row_gray(
        self,
        datas: &[&[u8]],
        geom: &Geometry,
        coords: &[RowCoords<'_>],
        n: usize,
        acc: &mut [u32],
        count: &mut [u32],
    ) {
        debug_assert_eq!(geom.channels, 1);
        match self {
            Kernel::Scalar => scalar::accumulate_row_gray(datas, geom, coords, n, acc, count),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => avx2::accumulate_row_gray(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                n,
                acc,
                count,
            ),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => avx512::accumulate_row_gray(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                n,
                acc,
                count,
            ),
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            Kernel::Simd128 => simd128::accumulate_row_gray(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                n,
                acc,
                count,
            ),
        }
    }

    /// [`Kernel::accumulate_row_gray`] of two planes of one geometry (the U
    /// and V planes of 4:2:0 frames) into `acc_a` and `acc_b`, one `count`.
    /// The vector kernels find each chunk's taps once for both planes (sampled
    /// bicubically, AVX-512 only: see [`Kernel::pairs_bicubic`]); the scalar
    /// reference runs the plane kernel twice.
    ///
    /// # Safety
    /// As [`Kernel::accumulate_row_gray`], for both planes' data.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) unsafe fn accumulate_row_gray_pair(
        self,
        datas_a: &[&[u8]],
        datas_b: &[&[u8]],
        geom: &Geometry,
        coords: &[RowCoords<'_>],
        n: usize,
        acc_a: &mut [u32],
        acc_b: &mut [u32],
        count: &mut [u32],
    ) {
        debug_assert_eq!(geom.channels, 1);
        let (a, b) = (datas_a, datas_b);
        #[cfg(any(
            target_arch = "x86_64",
            all(target_arch = "wasm32", target_feature = "simd128")
        ))]
        let g = common::KernelGeometry::of(geom);
        if geom.cubic && !self.pairs_bicubic() {
            // Bicubic taps are found per plane: one plane, then the other.
            self.accumulate_row_gray(a, geom, coords, n, acc_a, count);
            self.accumulate_row_gray(b, geom, coords, n, acc_b, count);
            return;
        }
        match self {
            Kernel::Scalar => {
                scalar::accumulate_row_gray(a, geom, coords, n, acc_a, count);
                scalar::accumulate_row_gray(b, geom, coords, n, acc_b, count);
            }
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => avx2::accumulate_row_gray_pair(a, b, g, coords, n, acc_a, acc_b, count),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => {
                avx512::accumulate_row_gray_pair(a, b, g, coords, n, acc_a, acc_b, count)
            }
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            Kernel::Simd128 => {
                simd128::accumulate_row_gray_pair(a, b, g, coords, n, acc_a, acc_b, count)
            }
        }
    }

    /// The ghost-free form of [`Kernel::accumulate_row`] (see
    /// [`crate::render::robust`]): for `u in 0..n`, with the last frame the
    /// reference, `sum_{r,g,b}[u] = sum_f w_f sample_f`, `weight[u] = sum_f w_f`
    /// and `count[u]` = frames whose coordinate lies inside the frame.
    ///
    /// # Safety
    /// As [`Kernel::accumulate_row`], and `datas` must not be empty.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) unsafe fn merge_row(
        self,
        datas: &[&[u8]],
        geom: &Geometry,
        coords: &[RowCoords<'_>],
        deghost: Deghost,
        n: usize,
        sum: [&mut [u32]; 3],
        weight: &mut [u32],
        count: &mut [u32],
    ) {
        match self {
            Kernel::Scalar => {
                scalar::merge_row(datas, geom, coords, deghost, (0, n), sum, weight, count)
            }
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 | Kernel::Avx512 => avx2::merge_row(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                deghost,
                n,
                sum,
                weight,
                count,
            ),
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            Kernel::Simd128 => simd128::merge_row(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                deghost,
                n,
                sum,
                weight,
                count,
            ),
        }
    }

    /// The single-channel form of [`Kernel::merge_row`], for the planes of planar frames.
    ///
    /// # Safety
    /// As [`Kernel::accumulate_row_gray`], and `datas` must not be empty.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) unsafe fn merge_row_gray(
        self,
        datas: &[&[u8]],
        geom: &Geometry,
        coords: &[RowCoords<'_>],
        deghost: Deghost,
        n: usize,
        sum: &mut [u32],
        weight: &mut [u32],
        count: &mut [u32],
    ) {
        debug_assert_eq!(geom.channels, 1);
        match self {
            Kernel::Scalar => {
                scalar::merge_row_gray(datas, geom, coords, deghost, (0, n), sum, weight, count)
            }
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => avx512::merge_row_gray(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                deghost,
                n,
                sum,
                weight,
                count,
            ),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => avx2::merge_row_gray(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                deghost,
                n,
                sum,
                weight,
                count,
            ),
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            Kernel::Simd128 => simd128::merge_row_gray(
                datas,
                common::KernelGeometry::of(geom),
                coords,
                deghost,
                n,
                sum,
                weight,
                count,
            ),
        }
    }

    /// Finishes the first `n` pixels of a single-channel output row from
    /// [`Kernel::accumulate_row_gray`]'s sums when this kernel has a finishing
    /// pass (AVX2, AVX-512, `simd128`): `out[u] = round(sum / (256 n))` exactly as the scalar
    /// path rounds, `fill` where no frame covers the pixel, `coverage[u]` the
    /// covering frames. Returns how many pixels `full` frames cover, or `None`
    /// (nothing written) for kernels that leave the row to the caller.
    ///
    /// # Safety
    /// A vectorized kernel must come from [`Kernel::detect`] on this machine and
    /// `n` must be a multiple of 8; every slice must hold at least `n` values.
    #[allow(unused_variables, clippy::too_many_arguments)]
    #[inline]
    pub(crate) unsafe fn finish_row_gray(
        self,
        sum: &[u32],
        count: &[u32],
        out: &mut [u8],
        coverage: &mut [u8],
        n: usize,
        full: u32,
        fill: u8,
    ) -> Option<usize> {
        match self {
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => Some(avx2::finish_row_gray(
                sum, count, out, coverage, n, full, fill,
            )),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => Some(avx512::finish_row_gray(
                sum, count, out, coverage, n, full, fill,
            )),
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            Kernel::Simd128 => Some(simd128::finish_row_gray(
                sum, count, out, coverage, n, full, fill,
            )),
            #[allow(unreachable_patterns)]
            _ => None,
        }
    }

    /// Finishes `n` pixels of an RGBA output row from [`Kernel::accumulate_row`]'s
    /// sums when this kernel has a finishing pass (`simd128`): `round(sum / (256 n))`
    /// per channel, alpha 255, 0 where no frame covers the pixel. Returns whether it
    /// did; the other kernels leave the row to the caller's scalar loop.
    ///
    /// # Safety
    /// The sums must hold at least `n` values and `out` at least `4 * n` bytes;
    /// `n` must be a multiple of 4 when the row is finished.
    #[allow(unused_variables)]
    #[inline]
    pub(crate) unsafe fn finish_row_rgba(
        self,
        acc_r: &[u32],
        acc_g: &[u32],
        acc_b: &[u32],
        count: &[u32],
        out: &mut [u8],
        n: usize,
    ) -> bool {
        match self {
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            Kernel::Simd128 => {
                simd128::finish_row_rgba(acc_r, acc_g, acc_b, count, out, n);
                true
            }
            #[allow(unreachable_patterns)]
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kernel this CPU runs and the scalar reference agree bit for bit, for
    /// tables (with NaN and out-of-frame points) and homography rows, RGB and RGBA,
    /// bilinear and bicubic.
    #[test]
    fn every_kernel_matches_scalar() {
        // 72 pixels: four 16-lane steps and a last one of eight.
        let (w, h, n) = (37usize, 23usize, 72usize);
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut rand = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as u32
        };
        // Bilinear and bicubic sampling.
        for (channels, cubic) in [(3usize, false), (4, false), (3, true), (4, true)] {
            let frames: Vec<Vec<u8>> = (0..4)
                .map(|_| {
                    (0..w * h * channels + FRAME_PADDING)
                        .map(|_| rand() as u8)
                        .collect()
                })
                .collect();
            let datas: Vec<&[u8]> = frames.iter().map(|f| f.as_slice()).collect();
            let geom = Geometry {
                channels,
                stride: w * channels,
                max_x0: w - 2,
                max_y0: h - 2,
                max_x: (w - 1) as f32,
                max_y: (h - 1) as f32,
                cubic,
            };
            let table = |r: &mut dyn FnMut() -> u32, size: usize| -> Vec<f32> {
                (0..n)
                    .map(|_| match r() % 16 {
                        0 => f32::NAN,
                        1 => -EDGE_TOLERANCE * 0.5,
                        2 => (size - 1) as f32 + EDGE_TOLERANCE * 0.5,
                        _ => (r() % 100_000) as f32 / 100_000.0 * (size + 2) as f32 - 1.0,
                    })
                    .collect()
            };
            let (xs, ys) = (table(&mut rand, w), table(&mut rand, h));
            let coords = [
                RowCoords::Table(&xs, &ys),
                RowCoords::Homography {
                    x0: -3.0,
                    y0: 5.5,
                    z0: 0.9,
                    dx: 0.7,
                    dy: 0.11,
                    dz: 0.003,
                },
                RowCoords::Homography {
                    x0: 40.0,
                    y0: -2.0,
                    z0: 1.2,
                    dx: -0.5,
                    dy: 0.4,
                    // Crosses z = 0 inside the row: rays behind the camera.
                    dz: -0.02,
                },
                // A slight roll: sixteen pixels' taps on two or three rows,
                // where the AVX-512 kernel picks them from row windows.
                RowCoords::Homography {
                    x0: 2.3,
                    y0: 7.4,
                    z0: 1.0,
                    dx: 0.97,
                    dy: 0.045,
                    dz: 0.0005,
                },
            ];
            let run = |kernel: Kernel| {
                let mut sums = vec![vec![0u32; n]; 4];
                let [r, g, b, c] = &mut sums[..] else {
                    unreachable!()
                };
                // SAFETY: the kernel comes from `detect` (or is scalar), `n` is a
                // multiple of 8, frames are padded and every buffer holds `n` values.
                unsafe { kernel.accumulate_row(&datas, &geom, &coords, n, r, g, b, c) };
                sums
            };
            let reference = run(Kernel::Scalar);
            // Some pixels are covered by every frame, some by at most one.
            assert!(reference[3].iter().any(|&c| c <= 1) && reference[3].contains(&4));
            for kernel in Kernel::available() {
                assert_eq!(run(kernel), reference, "{kernel:?}");
            }
            // The same frames read as single-channel planes of `channels` times
            // the width: the gray kernel against its scalar reference.
            let gray = Geometry::plane(w * channels, h, 1).with_cubic(cubic);
            let run_gray = |kernel: Kernel| {
                let (mut acc, mut count) = (vec![0u32; n], vec![0u32; n]);
                // SAFETY: as above; each plane has FRAME_PADDING >= 2 bytes past it.
                unsafe {
                    kernel.accumulate_row_gray(&datas, &gray, &coords, n, &mut acc, &mut count)
                };
                (acc, count)
            };
            let reference = run_gray(Kernel::Scalar);
            // Some by every frame, some by at most one of the first three (the
            // fourth, the slight roll, covers the whole row of the wider plane).
            assert!(reference.1.iter().any(|&c| c <= 2) && reference.1.contains(&4));
            for kernel in Kernel::available() {
                assert_eq!(run_gray(kernel), reference, "gray {kernel:?}");
            }
            // Two planes of that geometry at once (the frames in another
            // order for the second): each the gray kernel's sums.
            let mut others = datas.clone();
            others.rotate_left(1);
            let run_other = |kernel: Kernel| {
                let (mut acc, mut count) = (vec![0u32; n], vec![0u32; n]);
                // SAFETY: as above.
                unsafe {
                    kernel.accumulate_row_gray(&others, &gray, &coords, n, &mut acc, &mut count)
                };
                (acc, count)
            };
            let other = run_other(Kernel::Scalar);
            assert_ne!(other.0, reference.0);
            for kernel in Kernel::available() {
                let (mut a, mut b, mut count) = (vec![0u32; n], vec![0u32; n], vec![0u32; n]);
                // SAFETY: as above, for both sets of planes.
                unsafe {
                    kernel.accumulate_row_gray_pair(
                        &datas, &others, &gray, &coords, n, &mut a, &mut b, &mut count,
                    )
                };
                assert_eq!(
                    (&a, &count),
                    (&reference.0, &reference.1),
                    "pair, first {kernel:?}"
                );
                assert_eq!(b, other.0, "pair, second {kernel:?}");
            }
            // And points on the plane's own edges and corners (its right edge
            // is past the tables above): within the tolerance outside, on the
            // last column and row, and just inside them.
            let edge = |r: &mut dyn FnMut() -> u32, size: usize| -> Vec<f32> {
                let last = (size - 1) as f32;
                let near = [
                    -EDGE_TOLERANCE,
                    0.0,
                    last - 1.0 / 1024.0,
                    last - 1.0 / 256.0,
                    last,
                    last + EDGE_TOLERANCE,
                    last + 2.0 * EDGE_TOLERANCE,
                ];
                (0..n).map(|_| near[r() as usize % near.len()]).collect()
            };
            let (ex, ey) = (edge(&mut rand, w * channels), edge(&mut rand, h));
            let edges = [RowCoords::Table(&ex, &ey)];
            let run_edges = |kernel: Kernel| {
                let (mut acc, mut count) = (vec![0u32; n], vec![0u32; n]);
                // SAFETY: as above.
                unsafe {
                    kernel.accumulate_row_gray(&datas[..1], &gray, &edges, n, &mut acc, &mut count)
                };
                (acc, count)
            };
            let reference = run_edges(Kernel::Scalar);
            assert!(reference.1.contains(&0) && reference.1.contains(&1));
            for kernel in Kernel::available() {
                assert_eq!(run_edges(kernel), reference, "gray edges {kernel:?}");
            }
            // Finishing those sums into pixels, where a kernel has a pass for it:
            // as `average` rounds, `fill` where no frame covers the pixel.
            // Every fifth pixel made one that no frame covers (sum 0, as the
            // kernels leave it).
            let uncovered = |i: usize, v: u32| if i % 5 == 0 { 0 } else { v };
            let sums: &Vec<u32> = &reference
                .0
                .iter()
                .enumerate()
                .map(|(i, &s)| uncovered(i, s))
                .collect();
            let counts: &Vec<u32> = &reference
                .1
                .iter()
                .enumerate()
                .map(|(i, &k)| uncovered(i, k))
                .collect();
            let fill = 77u8;
            let expected: Vec<u8> = sums
                .iter()
                .zip(counts)
                .map(|(&s, &k)| if k == 0 { fill } else { average(s, k) })
                .collect();
            for kernel in Kernel::available() {
                let (mut out, mut coverage) = (vec![0u8; n], vec![0u8; n]);
                // SAFETY: as above; `n` is a multiple of 8 and every slice holds `n` values.
                let complete = unsafe {
                    kernel.finish_row_gray(sums, counts, &mut out, &mut coverage, n, 3, fill)
                };
                if let Some(complete) = complete {
                    assert_eq!(out, expected, "finish {kernel:?}");
                    assert!(coverage.iter().zip(counts).all(|(&c, &k)| c as u32 == k));
                    assert_eq!(complete, counts.iter().filter(|&&k| k == 3).count());
                }
            }
            // The ghost-free forms: random frames differ by up to 255 levels, so
            // a threshold of 60 levels gives weights from 0 to 16 (3: mostly 0).
            for levels in [3.0, 60.0] {
                let deghost = Deghost::new(levels).unwrap();
                let run_merge = |kernel: Kernel| {
                    let mut sums = vec![vec![0u32; n]; 5];
                    let [r, g, b, w, c] = &mut sums[..] else {
                        unreachable!()
                    };
                    // SAFETY: as above.
                    unsafe {
                        kernel.merge_row(&datas, &geom, &coords, deghost, n, [r, g, b], w, c)
                    };
                    sums
                };
                let reference = run_merge(Kernel::Scalar);
                if levels > 10.0 {
                    let partial = reference[3].iter().any(|&w| w % 16 != 0);
                    assert!(partial, "{levels}: some partial weights");
                }
                for kernel in Kernel::available() {
                    assert_eq!(run_merge(kernel), reference, "merge {levels} {kernel:?}");
                }
                let run_merge_gray = |kernel: Kernel| {
                    let mut sums = vec![vec![0u32; n]; 3];
                    let [s, w, c] = &mut sums[..] else {
                        unreachable!()
                    };
                    // SAFETY: as above.
                    unsafe { kernel.merge_row_gray(&datas, &gray, &coords, deghost, n, s, w, c) };
                    sums
                };
                let reference = run_merge_gray(Kernel::Scalar);
                for kernel in Kernel::available() {
                    let sums = run_merge_gray(kernel);
                    assert_eq!(sums, reference, "merge gray {levels} {kernel:?}");
                }
            }
        }
    }
}
