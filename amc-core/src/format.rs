//! Pixel formats: how a frame's bytes are laid out. A leaf below the images
//! and the errors that name formats.

use serde::{Deserialize, Serialize};

/// Channel layout of an interleaved 8-bit colour frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PixelFormat {
    /// 3 bytes per pixel: R, G, B.
    Rgb8,
    /// 4 bytes per pixel: R, G, B, A (alpha is ignored on input, 255 on output).
    Rgba8,
    /// Planar 4:2:0 YUV (`yuv420p`, `I420`): the Y plane (`width x height`
    /// bytes), then the U and V planes (`ceil(width/2) x ceil(height/2)` each),
    /// rows packed without padding. Limited ("video") range: Y 16..=235 is
    /// black..white, U = V = 128 is grey; chroma sits at the centre of each 2x2
    /// block of luma pixels. Black borders are Y 16, U = V 128.
    Yuv420p,
}

impl PixelFormat {
    /// Bytes per pixel of the interleaved formats; 1 for [`PixelFormat::Yuv420p`]
    /// (bytes per sample of each plane: use [`PixelFormat::buffer_len`] for sizes).
    pub const fn channels(self) -> usize {
        match self {
            PixelFormat::Rgb8 => 3,
            PixelFormat::Rgba8 => 4,
            PixelFormat::Yuv420p => 1,
        }
    }

    /// True for the planar formats.
    pub const fn is_planar(self) -> bool {
        matches!(self, PixelFormat::Yuv420p)
    }

    /// Bytes of a `width x height` frame, `None` on overflow.
    pub fn buffer_len(self, width: usize, height: usize) -> Option<usize> {
        match self {
            PixelFormat::Rgb8 | PixelFormat::Rgba8 => width
                .checked_mul(height)
                .and_then(|n| n.checked_mul(self.channels())),
            PixelFormat::Yuv420p => {
                let (cw, ch) = chroma_size(width, height);
                width
                    .checked_mul(height)
                    .and_then(|n| n.checked_add(cw.checked_mul(ch)?.checked_mul(2)?))
            }
        }
    }
}

/// Size of a 4:2:0 chroma plane for a `width x height` frame: `ceil` of halves.
pub const fn chroma_size(width: usize, height: usize) -> (usize, usize) {
    (width.div_ceil(2), height.div_ceil(2))
}

/// Where the U and V planes of a `width x height` [`PixelFormat::Yuv420p`]
/// buffer start (the Y plane starts at 0), bytes.
pub const fn yuv_plane_offsets(width: usize, height: usize) -> (usize, usize) {
    let (cw, ch) = chroma_size(width, height);
    (width * height, width * height + cw * ch)
}
