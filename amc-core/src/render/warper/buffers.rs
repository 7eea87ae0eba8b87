//! What a [`Warper`](super::Warper) keeps between renders besides its
//! settings: each frame's row map, the rows' working buffers and the
//! supersampled renders. Defined apart from the files that fill them, so
//! that the warper's files import each other one way.

use crate::render::accumulator::WarpedFrame;
use nalgebra::Matrix3;

/// How one frame's source coordinates are produced along output rows.
#[derive(Clone, Debug, Default)]
pub(super) struct RowMap {
    /// Homography `K_src M K_out^-1` (pinhole sources, global shutter).
    pub(super) h: Matrix3<f32>,
    /// Exact source coordinates at the grid nodes (distorted sources, and any
    /// source through a rolling shutter).
    pub(super) grid: Vec<[f32; 2]>,
    /// Whether this map is the grid (else the homography).
    pub(super) gridded: bool,
}

/// Per-row working buffers: one set per band of rows being rendered.
#[derive(Clone, Debug, Default)]
pub(super) struct RowScratch {
    /// Source coordinates `(xs[f][u], ys[f][u])` of the current row per frame (NaN: none).
    pub(super) xs: Vec<Vec<f32>>,
    pub(super) ys: Vec<Vec<f32>>,
    /// Per-channel sums of the vectorized path (1 or 3 used).
    pub(super) sums: [Vec<u32>; 3],
    /// Frames covering each pixel of the row.
    pub(super) count: Vec<u32>,
    /// Ghost-free averaging: the weights' sum per pixel (`sums` then holds
    /// the weighted sums); `weight_b` the second plane's of a pair (`sums[1]`).
    pub(super) weight: Vec<u32>,
    pub(super) weight_b: Vec<u32>,
}

impl RowScratch {
    /// Sizes the buffers for `frames` frames of rows `width` wide (with the
    /// weights when `merged`).
    pub(super) fn fit(&mut self, frames: usize, width: usize, tables: bool, merged: bool) {
        if tables {
            self.xs.resize_with(frames, Vec::new);
            self.ys.resize_with(frames, Vec::new);
            for t in self.xs.iter_mut().chain(self.ys.iter_mut()) {
                t.resize(width, 0.0);
            }
        }
        for buf in self.sums.iter_mut().chain(std::iter::once(&mut self.count)) {
            buf.resize(width, 0);
        }
        if merged {
            self.weight.resize(width, 0);
            self.weight_b.resize(width, 0);
        }
    }
}

/// The supersampled renders of a warper with `S > 1`, before their `S x S`
/// blocks are averaged into the caller's buffers (kept: a warmed-up render
/// allocates nothing).
#[derive(Clone, Debug, Default)]
pub(super) struct Fine {
    /// Image (interleaved or one plane) and its second plane (U and V pairs).
    pub(super) image: Vec<u8>,
    pub(super) image_b: Vec<u8>,
    /// Covering frames per fine pixel.
    pub(super) coverage: Vec<u8>,
    /// A saccade slot's samples and coverage (interleaved or one plane).
    pub(super) slot: WarpedFrame,
}

impl Fine {
    /// The image, `len` values, and its coverage.
    pub(super) fn image(&mut self, len: usize) -> (&mut [u8], &mut Vec<u8>) {
        self.image.resize(len, 0);
        (&mut self.image, &mut self.coverage)
    }

    /// Both planes of a pair, `len` values each, and their coverage.
    pub(super) fn pair(&mut self, len: usize) -> (&mut [u8], &mut [u8], &mut Vec<u8>) {
        self.image.resize(len, 0);
        self.image_b.resize(len, 0);
        (&mut self.image, &mut self.image_b, &mut self.coverage)
    }

    /// The slot's first `len` values and coverage flags (one plane).
    pub(super) fn plane_slot(&mut self, len: usize) -> (&mut [u16], &mut [u8]) {
        self.slot.value.resize(len, 0);
        self.slot.covered.resize(len, 0);
        (&mut self.slot.value[..len], &mut self.slot.covered[..len])
    }
}
