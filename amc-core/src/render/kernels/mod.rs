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
//! AVX2 form of the interleaved ones, as it does for bilinear sampling). The
//! ghost-free forms of the x86-64 kernels are in `avx2_merge.rs` and
//! `avx512_merge.rs`, beside the plain ones whose samplers they use; both merge
//! U and V as a pair (`merge_row_gray_pair`), finding each chunk's taps once.
//!
//! Layers: this dispatcher uses the kernels, and they all use `common.rs` (the
//! constants, row coordinates, frame geometry and reference sampler they share);
//! no kernel uses the dispatcher.

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx2_merge;
#[cfg(target_arch = "x86_64")]
mod avx2_window;
#[cfg(target_arch = "x86_64")]
mod avx512;
#[cfg(target_arch = "x86_64")]
mod avx512_merge;
mod common;
mod scalar;
#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
mod simd128;

use crate::render::robust::Deghost;
#[cfg(test)]
pub(crate) use common::cubic_weights;
pub(crate) use common::{average, Geometry, HomographyRow, RowCoords};
pub use common::{EDGE_TOLERANCE, FRAME_PADDING};
pub(crate) use scalar::{merge_row as merge_row_scalar, merge_row_gray as merge_row_gray_scalar};

/// Runs one operation on the kernel `$kernel` is: `$call` with `k` the
/// kernel's module (`avx2`, `simd128`, or for AVX-512 the module `avx512:`
/// names: its own, or AVX2's for the interleaved rows, which it runs with
/// AVX2's code) and, with `g = geom`, `g` the frames' geometry as that kernel
/// takes it ([`common::KernelGeometry`] in 32-bit lanes, the scalar
/// reference's [`Geometry`] as it is). `Scalar` runs `scalar:`, by default
/// `$call` with the scalar module.
macro_rules! dispatch {
    ($kernel:expr, |$k:ident $(, $g:ident = $geom:ident)?| $call:block, avx512: $avx512:ident $(,)?) => {
        dispatch!($kernel, |$k $(, $g = $geom)?| $call, avx512: $avx512, scalar: {
            use self::scalar as $k;
            $(let $g = $geom;)?
            $call
        })
    };
    ($kernel:expr, |$k:ident $(, $g:ident = $geom:ident)?| $call:block, avx512: $avx512:ident,
     scalar: $scalar:expr $(,)?) => {
        match $kernel {
            Kernel::Scalar => $scalar,
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => {
                use self::avx2 as $k;
                $(let $g = common::KernelGeometry::of($geom);)?
                $call
            }
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => {
                use self::$avx512 as $k;
                $(let $g = common::KernelGeometry::of($geom);)?
                $call
            }
            #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
            Kernel::Simd128 => {
                use self::simd128 as $k;
                $(let $g = common::KernelGeometry::of($geom);)?
                $call
            }
        }
    };
}

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
        dispatch!(self, |k, g = geom| {
            k::accumulate_row(datas, g, coords, n, acc_r, acc_g, acc_b, count)
        }, avx512: avx2)
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
        dispatch!(self, |k, g = geom| {
            k::accumulate_row_gray(datas, g, coords, n, acc, count)
        }, avx512: avx512)
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
        if geom.cubic && !self.pairs_bicubic() {
            // Bicubic taps are found per plane: one plane, then the other.
            self.accumulate_row_gray(a, geom, coords, n, acc_a, count);
            self.accumulate_row_gray(b, geom, coords, n, acc_b, count);
            return;
        }
        dispatch!(self, |k, g = geom| {
            k::accumulate_row_gray_pair(a, b, g, coords, n, acc_a, acc_b, count)
        }, avx512: avx512, scalar: {
            scalar::accumulate_row_gray(a, geom, coords, n, acc_a, count);
            scalar::accumulate_row_gray(b, geom, coords, n, acc_b, count);
        })
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
        dispatch!(self, |k, g = geom| {
            k::merge_row(datas, g, coords, deghost, n, sum, weight, count)
        }, avx512: avx2, scalar: {
            scalar::merge_row(datas, geom, coords, deghost, (0, n), sum, weight, count)
        })
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
        dispatch!(self, |k, g = geom| {
            k::merge_row_gray(datas, g, coords, deghost, n, sum, weight, count)
        }, avx512: avx512, scalar: {
            scalar::merge_row_gray(datas, geom, coords, deghost, (0, n), sum, weight, count)
        })
    }

    /// [`Kernel::merge_row_gray`] of two planes of one geometry (the U and V
    /// planes of 4:2:0 frames), each weighted by its own agreement with its last
    /// frame: `sums.0`/`weights.0` from `datas.0`, `sums.1`/`weights.1` from
    /// `datas.1`, one `count`. AVX2 and AVX-512 find each chunk's taps once for
    /// both planes (bicubic: AVX-512 only); the others run the plane kernel twice.
    ///
    /// # Safety
    /// As [`Kernel::merge_row_gray`], for both planes' data.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) unsafe fn merge_row_gray_pair(
        self,
        datas: (&[&[u8]], &[&[u8]]),
        geom: &Geometry,
        coords: &[RowCoords<'_>],
        deghost: Deghost,
        n: usize,
        sums: (&mut [u32], &mut [u32]),
        weights: (&mut [u32], &mut [u32]),
        count: &mut [u32],
    ) {
        debug_assert_eq!(geom.channels, 1);
        match self {
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => {
                let g = common::KernelGeometry::of(geom);
                avx512::merge_row_gray_pair(datas, g, coords, deghost, n, sums, weights, count)
            }
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 if !geom.cubic => {
                let g = common::KernelGeometry::of(geom);
                avx2::merge_row_gray_pair(datas, g, coords, deghost, n, sums, weights, count)
            }
            _ => {
                let (a, b) = datas;
                self.merge_row_gray(a, geom, coords, deghost, n, sums.0, weights.0, count);
                self.merge_row_gray(b, geom, coords, deghost, n, sums.1, weights.1, count);
            }
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
        dispatch!(self, |k| {
            Some(k::finish_row_gray(sum, count, out, coverage, n, full, fill))
        }, avx512: avx512, scalar: None)
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
mod tests;
