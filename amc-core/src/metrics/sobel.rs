//! The separable 3x3 Sobel operator on integer rows, shared by the luma and
//! the colour metrics: with the column sums `s = above + 2 row + below` and
//! differences `d = below - above`, interior pixel `x` has
//! `gx = s[x + 1] - s[x - 1]` and `gy = d[x - 1] + 2 d[x] + d[x + 1]`.

/// The column sums and differences of three rows of samples (bytes or
/// 12-bit luma: every result fits 16 bits), into `sums` and `diffs`
/// (resized to the rows' width).
#[inline(always)]
pub(super) fn columns_into<T: Copy + Into<i32>>(
    [above, at, below]: [&[T]; 3],
    sums: &mut Vec<i16>,
    diffs: &mut Vec<i16>,
) {
    let w = at.len();
    sums.resize(w, 0);
    diffs.resize(w, 0);
    for ((((s, d), &a), &r), &b) in sums
        .iter_mut()
        .zip(diffs.iter_mut())
        .zip(&above[..w])
        .zip(at)
        .zip(&below[..w])
    {
        let (a, r, b) = (a.into(), r.into(), b.into());
        *s = (a + 2 * r + b) as i16;
        *d = (b - a) as i16;
    }
}

/// `gx^2 + gy^2` of an interior pixel from the sums of the columns left
/// and right of it (`sl`, `sr`) and the differences of its three (`dl`,
/// `dc`, `dr`).
#[inline(always)]
pub(super) fn magnitude_sq(sl: i16, sr: i16, dl: i16, dc: i16, dr: i16) -> i32 {
    let gx = sr - sl;
    let gy = dl + 2 * dc + dr;
    gx as i32 * gx as i32 + gy as i32 * gy as i32
}
