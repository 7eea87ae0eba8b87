//! The AVX2 kernel's bilinear taps of a plane without gathers: eight output
//! pixels' (left, right) tap pairs picked out of 16-byte windows of the rows
//! they lie on, one window per 128-bit half (`vpshufb` shuffles within a
//! half), as the AVX-512 kernel picks sixteen out of 64-byte windows.
//!
//! Why: AVX2 gathers are slow on some CPUs (on AMD Zen 3 the plane sampler's
//! two gathers a chunk were 62% of a 720p run at the defaults). Under a
//! rotation, four neighbouring output pixels land within a few source
//! columns, on at most two neighbouring rows; a chunk whose taps spread wider
//! (a strong zoom-out, a steep roll, a window past the plane's end) is
//! gathered as before. Both fetch the same bytes, so the choice never changes
//! a result.

use super::common::KernelGeometry;
use std::arch::x86_64::*;

/// Largest offset of a lane's left tap in its half's 16-byte window: its
/// right neighbour is the window's last byte.
const WINDOW_SPAN: i32 = 14;

/// Columns a half's window starts left of its first lane's left tap: the
/// other three may wander left of it (a grid-interpolated row is monotonic
/// only cell by cell), leaving 11 columns for four pixels' run.
const WINDOW_SLACK: i32 = 3;

/// Where a chunk's taps lie in a plane; it depends on the geometry alone,
/// so planes of one geometry share it.
pub(super) struct Window8 {
    /// The first byte of the low and the high half's window (top row).
    start_lo: usize,
    start_hi: usize,
    /// The shuffle: byte 0 of each lane the left tap's offset in its half's
    /// window, byte 2 the right one's; bytes 1 and 3 have their top bit set,
    /// which zeroes them, leaving two 16-bit words.
    index: __m256i,
    /// Lanes whose top tap is on the window's second row (all bits set).
    lower: __m256i,
}

impl Window8 {
    /// The window of the taps whose top-left taps are `(x0, y0)` in the lanes
    /// of `mask`, where `falls` says the row's `y` falls along it (the window
    /// then starts a row above lane 0's); `None` when a lane's taps lie
    /// outside it.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn of(
        g: &KernelGeometry,
        mask: __m256i,
        x0: __m256i,
        y0: __m256i,
        falls: bool,
    ) -> Option<Self> {
        // Lanes 0 and 4 alone place the windows: the other lanes are checked.
        let x_lo = (_mm256_cvtsi256_si32(x0) - WINDOW_SLACK).max(0);
        let x_hi = (_mm256_extract_epi32::<4>(x0) - WINDOW_SLACK).max(0);
        let y_win = (_mm256_cvtsi256_si32(y0) - falls as i32).max(0);
        let off = _mm256_sub_epi32(
            x0,
            _mm256_set_m128i(_mm_set1_epi32(x_hi), _mm_set1_epi32(x_lo)),
        );
        let down = _mm256_sub_epi32(y0, _mm256_set1_epi32(y_win));
        let (zero, one) = (_mm256_setzero_si256(), _mm256_set1_epi32(1));
        let outside = _mm256_or_si256(
            _mm256_or_si256(
                _mm256_cmpgt_epi32(off, _mm256_set1_epi32(WINDOW_SPAN)),
                _mm256_cmpgt_epi32(zero, off),
            ),
            _mm256_or_si256(
                _mm256_cmpgt_epi32(down, one),
                _mm256_cmpgt_epi32(zero, down),
            ),
        );
        if _mm256_testz_si256(outside, mask) == 0 {
            return None;
        }
        let row = y_win as usize * g.stride as usize;
        Some(Self {
            start_lo: row + x_lo as usize,
            start_hi: row + x_hi as usize,
            index: _mm256_or_si256(
                _mm256_or_si256(off, _mm256_slli_epi32::<16>(_mm256_add_epi32(off, one))),
                _mm256_set1_epi32(0x8000_8000u32 as i32),
            ),
            lower: _mm256_cmpeq_epi32(down, one),
        })
    }

    /// The taps' pairs `(left, right)` of the top and bottom rows as 16-bit
    /// words of each 32-bit lane, out of this window of `data` (a plane of
    /// row stride `stride`); `None` where the window's rows would run past
    /// its end. Lanes outside the taps' mask hold anything.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn fetch(&self, data: &[u8], stride: usize) -> Option<(__m256i, __m256i)> {
        if self.start_lo.max(self.start_hi) + 2 * stride + 16 > data.len() {
            return None;
        }
        let p = data.as_ptr();
        // The row below the window, a line ahead: what the next output row's
        // window here will read (as in the AVX-512 kernel: without it those
        // lines come from beyond L2 when first read, and the kernel waits).
        let ahead = p.wrapping_add(self.start_hi + 3 * stride + 64);
        _mm_prefetch::<_MM_HINT_T0>(ahead as *const i8);
        // All three rows are read, whether or not a lane needs the third:
        // as in the AVX-512 kernel, a branch on it costs more than the load.
        let row = |r: usize| {
            let bytes = _mm256_loadu2_m128i(
                p.add(self.start_hi + r * stride) as *const __m128i,
                p.add(self.start_lo + r * stride) as *const __m128i,
            );
            _mm256_shuffle_epi8(bytes, self.index)
        };
        let (first, second, third) = (row(0), row(1), row(2));
        Some((
            _mm256_blendv_epi8(first, second, self.lower),
            _mm256_blendv_epi8(second, third, self.lower),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::super::avx2::{row_coords8, taps8, PlaneTaps8};
    use super::super::common::{affine_row, falls, Geometry, RowCoords};
    use super::*;

    /// The windows and the gathers fetch the same pairs wherever a window
    /// applies, it applies to the rows a rotation makes (so the fast path is
    /// what runs), and it declines runs that do not fit.
    #[test]
    fn window_pairs_match_gathers() {
        if !is_x86_feature_detected!("avx2") {
            eprintln!("skipped: no AVX2 on this CPU");
            return;
        }
        let (w, h) = (203usize, 97usize);
        let plane: Vec<u8> = (0..w * h + 4)
            .map(|i| (i.wrapping_mul(2654435761) >> 7) as u8)
            .collect();
        let g = KernelGeometry::of(&Geometry::plane(w, h, 1));
        let pairs = |coord: RowCoords<'_>, u: usize| -> (Option<[[i32; 8]; 2]>, [[i32; 8]; 2]) {
            // SAFETY: this CPU has AVX2 (checked above); the plane is padded.
            unsafe {
                let t = taps8(&g, row_coords8(&coord, u)).unwrap();
                let mask = t.mask;
                let words = |(a, b): (__m256i, __m256i)| {
                    let (mut x, mut y) = ([0i32; 8], [0i32; 8]);
                    _mm256_storeu_si256(x.as_mut_ptr() as *mut _, _mm256_and_si256(a, mask));
                    _mm256_storeu_si256(y.as_mut_ptr() as *mut _, _mm256_and_si256(b, mask));
                    [x, y]
                };
                let falls = falls(&coord, u);
                let window =
                    Window8::of(&g, t.mask, t.x0, t.y0, falls).and_then(|win| win.fetch(&plane, w));
                let gathered = PlaneTaps8::of(&g, t, falls).gather_pairs(&plane);
                (window.map(words), words(gathered))
            }
        };
        // A slight roll and zoom (either way), a zoom-in: the taps straddle
        // two rows, then one.
        for (coord, u) in [
            (affine_row(10.3, 40.6, 1.13, 0.07), 16),
            (affine_row(3.7, 20.2, 0.93, -0.04), 32),
            (affine_row(3.7, 20.5, 0.6, 0.12), 8),
            (affine_row(-0.4, 0.0, 1.0, 0.0), 0),
        ] {
            let (window, gathered) = pairs(coord, u);
            assert_eq!(window, Some(gathered), "{coord:?} at {u}");
        }
        // Too steep (taps on three rows), too wide (a 5x zoom-out), running
        // backwards past the slack (a mirrored zoom-out), too close to the plane's end for the window's rows: the
        // gathers take over.
        for (coord, u) in [
            (affine_row(10.3, 40.6, 0.9, 0.5), 16),
            (affine_row(1.0, 10.0, 5.0, 0.0), 0),
            (affine_row(150.0, 10.0, -2.0, 0.0), 0),
            (affine_row(180.0, (h - 2) as f32, 1.0, 0.0), 0),
        ] {
            assert_eq!(pairs(coord, u).0, None, "{coord:?} at {u}");
        }
    }
}
