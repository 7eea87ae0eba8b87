//! Row kernels: bilinear sampling of several frames along one output row, summed
//! in 8.8 fixed point.
//!
//! Two operations, each in a plain and a ghost-free form: the sum of the
//! frames' samples (`accumulate_row`), and their sum weighted by agreement with
//! the last frame's (`merge_row`, see [`crate::render::robust`]).
//!
//! `scalar.rs` is the reference; `avx2.rs` (x86-64, chosen at run time when the
//! CPU has AVX2) and `simd128.rs` (wasm32, chosen at compile time with the
//! `simd128` target feature) are bit-exact with it. [`Kernel`] is the one
//! dispatcher: [`Kernel::detect`] picks the kernel, its methods run it.
//!
//! Layers: this dispatcher uses the kernels, and they all use `common.rs` (the
//! constants, row coordinates, frame geometry and reference sampler they share);
//! no kernel uses the dispatcher.

#[cfg(target_arch = "x86_64")]
mod avx2;
mod common;
mod scalar;
#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
mod simd128;

use crate::render::robust::Deghost;
pub(crate) use common::{Geometry, RowCoords};
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
    /// WebAssembly `simd128`, four pixels at a time (`simd128.rs`).
    #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
    Simd128,
}

impl Kernel {
    /// The fastest kernel for this build and CPU: AVX2 when the x86-64 CPU has it,
    /// `simd128` in wasm32 builds with that target feature, else the scalar one.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if avx2_available() {
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

    /// True for the vector kernels.
    pub fn is_vectorized(self) -> bool {
        !matches!(self, Kernel::Scalar)
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
            Kernel::Avx2 => avx2::accumulate_row(
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
            Kernel::Avx2 => avx2::merge_row(
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

    /// The detected kernel and the scalar reference agree bit for bit, for tables
    /// (with NaN and out-of-frame points) and homography rows, RGB and RGBA.
    #[test]
    fn detected_kernel_matches_scalar() {
        let (w, h, n) = (37usize, 23usize, 64usize);
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut rand = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as u32
        };
        for channels in [3usize, 4] {
            let frames: Vec<Vec<u8>> = (0..3)
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
            assert!(reference[3].iter().any(|&c| c <= 1) && reference[3].contains(&3));
            assert_eq!(run(Kernel::detect()), reference, "{:?}", Kernel::detect());
            // The same frames read as single-channel planes of `channels` times
            // the width: the gray kernel against its scalar reference.
            let gray = Geometry::plane(w * channels, h, 1);
            let run_gray = |kernel: Kernel| {
                let (mut acc, mut count) = (vec![0u32; n], vec![0u32; n]);
                // SAFETY: as above; each plane has FRAME_PADDING >= 2 bytes past it.
                unsafe {
                    kernel.accumulate_row_gray(&datas, &gray, &coords, n, &mut acc, &mut count)
                };
                (acc, count)
            };
            let reference = run_gray(Kernel::Scalar);
            assert!(reference.1.iter().any(|&c| c <= 1) && reference.1.contains(&3));
            assert_eq!(
                run_gray(Kernel::detect()),
                reference,
                "gray {:?}",
                Kernel::detect()
            );
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
                assert_eq!(run_merge(Kernel::detect()), reference, "merge {levels}");
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
                assert_eq!(
                    run_merge_gray(Kernel::detect()),
                    reference,
                    "merge gray {levels}"
                );
            }
        }
    }
}
