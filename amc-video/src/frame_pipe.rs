//! The encoder child's stdin: frames converted to the Matroska track's
//! layout (RGB24, or I420 with an odd side padded to even) and written one
//! cluster each (see `mkv`), reusing its buffers. The file encoder
//! (`FfmpegSink`) and the live H.264 encoder share it.

use crate::frame::{as_rgb, as_yuv420p};
use crate::mkv::RawFormat;
use amc_core::image::{FrameRef, PixelFormat};
use std::io::{self, Write};

/// Frames of one size into one raw Matroska track.
pub(crate) struct FramePipe {
    pub width: usize,
    pub height: usize,
    /// The track's pixel layout.
    pub raw: RawFormat,
    scratch: Vec<u8>,
    /// An odd-sized I420 frame padded to even sizes, reused.
    padded: Vec<u8>,
    /// A frame's Matroska cluster header, reused.
    block_header: Vec<u8>,
}

impl FramePipe {
    /// Frames of `format` go in as RGB24 (packed formats) or I420 (planar).
    pub fn new(width: usize, height: usize, format: PixelFormat) -> Self {
        let raw = match format {
            PixelFormat::Yuv420p => RawFormat::I420,
            PixelFormat::Rgb8 | PixelFormat::Rgba8 => RawFormat::Rgb24,
        };
        Self {
            width,
            height,
            raw,
            scratch: Vec::new(),
            padded: Vec::new(),
            block_header: Vec::new(),
        }
    }

    /// Whether a side is odd (RGB24 is then padded by ffmpeg's `pad` filter,
    /// I420 here, see [`pad_to_even`]).
    pub fn odd(&self) -> bool {
        self.width % 2 == 1 || self.height % 2 == 1
    }

    /// The stream's header, written before the first frame.
    pub fn header(&self) -> Vec<u8> {
        let (w, h) = match self.raw {
            RawFormat::I420 => (
                self.width.next_multiple_of(2),
                self.height.next_multiple_of(2),
            ),
            RawFormat::Rgb24 => (self.width, self.height),
        };
        crate::mkv::header(w, h, self.raw)
    }

    /// Writes `frame` (of this pipe's size) at `t` seconds to `out`.
    pub fn write(&mut self, out: &mut impl Write, frame: &FrameRef<'_>, t: f64) -> io::Result<()> {
        let odd = self.odd();
        let pixels = match self.raw {
            RawFormat::Rgb24 => as_rgb(frame, &mut self.scratch),
            RawFormat::I420 => {
                let planes = as_yuv420p(frame, &mut self.scratch);
                if odd {
                    pad_to_even(self.width, self.height, planes, &mut self.padded);
                    &self.padded
                } else {
                    planes
                }
            }
        };
        crate::mkv::write_frame(out, t, pixels, &mut self.block_header)
    }
}

/// Pads a `width x height` YUV 4:2:0 frame with an odd side to the next even
/// size by repeating its last luma column and row: the encoder's `yuv420p`
/// needs even sizes, and ffmpeg's `pad` filter would drop that column and row
/// (it rounds a 4:2:0 input's size down to the chroma grid). The chroma planes
/// already cover the added pixels (they are `ceil(side / 2)` samples), so the
/// copies keep the colour of the pixels they repeat.
fn pad_to_even(width: usize, height: usize, planes: &[u8], out: &mut Vec<u8>) {
    let (ew, eh) = (width.next_multiple_of(2), height.next_multiple_of(2));
    let (y, u, v) = amc_core::image::yuv_planes(width, height, planes);
    out.clear();
    for row in (0..height).chain((height < eh).then_some(height - 1)) {
        let line = &y[row * width..][..width];
        out.extend_from_slice(line);
        out.extend(line.last().filter(|_| width < ew));
    }
    out.extend_from_slice(u);
    out.extend_from_slice(v);
    debug_assert_eq!(Some(out.len()), PixelFormat::Yuv420p.buffer_len(ew, eh));
}
