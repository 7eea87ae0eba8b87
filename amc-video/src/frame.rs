//! The [`FrameSource`] and [`FrameSink`] traits every format implements, and
//! the small helpers the formats share (frame shapes, rates, extensions).
//!
//! Frames are packed RGB8/RGBA8 or planar YUV 4:2:0 ([`PixelFormat::Yuv420p`],
//! limited range). A source decodes in the format its caller asked for when
//! opening it ([`InputOptions::pixel_format`](crate::InputOptions::pixel_format));
//! a sink takes any of the three and converts, where its file needs another,
//! with [`as_rgb`] or [`as_yuv420p`] (the `amc_core::color` conversions).

use crate::error::VideoError;
use crate::spec::VideoInfo;
use amc_core::color::rgb_to_yuv420p_into;
use amc_core::image::{Frame, FrameRef, PixelFormat};
use std::path::Path;

/// A stream of decoded frames.
pub trait FrameSource: Send {
    /// Size, rate and length of the input.
    fn info(&self) -> &VideoInfo;
    /// Decodes the next frame into `buf` (reusing its allocation) in the
    /// pixel format asked for by [`InputOptions::pixel_format`](crate::InputOptions::pixel_format)
    /// (RGB8 or planar YUV 4:2:0, limited range), returning its presentation timestamp in seconds relative to the first
    /// frame (strictly increasing, the first is 0), or `None` at end of stream.
    fn next_frame(&mut self, buf: &mut Frame) -> Result<Option<f64>, VideoError>;
}

/// A destination for frames. Nothing appears at the output path until
/// [`finish`](FrameSink::finish) succeeds; dropping a sink without finishing
/// it removes what was written and stops the encoder.
pub trait FrameSink: Send {
    /// Appends one frame (RGB8, RGBA8 with alpha ignored, or YUV 4:2:0; the
    /// buffer may carry tail padding) of the size given in the spec, shown at `t` seconds (non-decreasing; the first frame's time is
    /// the output's start). Video containers keep each frame's time, so a
    /// variable-frame-rate input stays in sync with its audio; `.y4m` and PNG
    /// folders have no timestamps and play at the spec's constant `fps`.
    fn write_frame(&mut self, frame: &FrameRef<'_>, t: f64) -> Result<(), VideoError>;
    /// Completes the file and moves it onto the output path.
    fn finish(self: Box<Self>) -> Result<(), VideoError>;
}

/// The lower-cased extension of `path`, if any.
pub(crate) fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .filter(|e| !e.is_empty())
}

/// Checks a frame rate: finite, above 0 and at most 10000 frames per second.
pub(crate) fn check_fps(path: &Path, fps: f64) -> Result<(), VideoError> {
    if fps.is_finite() && fps > 0.0 && fps <= 10_000.0 {
        Ok(())
    } else {
        Err(VideoError::BadFrame {
            path: path.to_path_buf(),
            detail: format!("frame rate {fps} is not a positive number of frames per second"),
        })
    }
}

/// A rational `(num, den)` close to `fps`, preferring the NTSC-style `/1001`
/// rates so that 29.97 is written as `30000/1001` rather than an approximation.
pub(crate) fn fps_rational(fps: f64) -> (u64, u64) {
    for den in [1u64, 1001] {
        let num = (fps * den as f64).round();
        if num >= 1.0 && (num / den as f64 - fps).abs() <= 1e-6 * fps.max(1.0) {
            return (num as u64, den);
        }
    }
    let den = 1_000_000u64;
    let num = ((fps * den as f64).round() as u64).max(1);
    let g = gcd(num, den);
    (num / g, den / g)
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a.max(1)
}

/// Makes `buf` a `width x height` frame of `format` for a source to fill.
/// Reshaping blackens the whole buffer, wasted work on a frame about to be
/// overwritten, so a buffer already of that shape is left as it is.
pub(crate) fn shape(buf: &mut Frame, width: usize, height: usize, format: PixelFormat) {
    let len = format.buffer_len(width, height);
    if (buf.width, buf.height, buf.format) != (width, height, format) || Some(buf.data.len()) != len
    {
        buf.reshape(width, height, format);
    }
}

/// Checks the pixel format a source was asked to decode to: RGB8 or YUV 4:2:0.
pub(crate) fn check_source_format(path: &Path, format: PixelFormat) -> Result<(), VideoError> {
    match format {
        PixelFormat::Rgb8 | PixelFormat::Yuv420p => Ok(()),
        PixelFormat::Rgba8 => Err(VideoError::UnsupportedPixelFormat {
            path: path.to_path_buf(),
            format,
        }),
    }
}

/// Checks a frame given to a sink against its spec: its size, and a buffer
/// at least as long as its format needs (longer is tail padding, which the
/// core's frames may carry).
pub(crate) fn check_frame(
    path: &Path,
    spec_w: usize,
    spec_h: usize,
    frame: &FrameRef<'_>,
) -> Result<(), VideoError> {
    let expected = frame.format.buffer_len(frame.width, frame.height);
    let fits = expected.is_some_and(|n| frame.data.len() >= n);
    if frame.width != spec_w || frame.height != spec_h || !fits {
        return Err(VideoError::BadFrame {
            path: path.to_path_buf(),
            detail: format!(
                "got a {}x{} {:?} frame ({} bytes) but the output was created for {}x{}",
                frame.width,
                frame.height,
                frame.format,
                frame.data.len(),
                spec_w,
                spec_h
            ),
        });
    }
    Ok(())
}

/// The frame's pixels without tail padding (after [`check_frame`]).
fn pixels<'a>(frame: &FrameRef<'a>) -> &'a [u8] {
    let len = frame.format.buffer_len(frame.width, frame.height);
    &frame.data[..len.unwrap_or(0).min(frame.data.len())]
}

/// The frame as packed RGB: borrowed when it already is, else converted into `scratch`.
pub(crate) fn as_rgb<'a>(frame: &FrameRef<'a>, scratch: &'a mut Vec<u8>) -> &'a [u8] {
    let data = pixels(frame);
    match frame.format {
        PixelFormat::Rgb8 => data,
        PixelFormat::Rgba8 => {
            scratch.clear();
            scratch.reserve(frame.width * frame.height * 3);
            for px in data.chunks_exact(4) {
                scratch.extend_from_slice(&px[..3]);
            }
            scratch
        }
        PixelFormat::Yuv420p => {
            amc_core::color::yuv420p_to_rgb_into(
                frame.width,
                frame.height,
                data,
                false,
                3,
                scratch,
            );
            scratch
        }
    }
}

/// The frame as planar YUV 4:2:0 (limited range): borrowed when it already
/// is, else converted into `scratch`.
pub(crate) fn as_yuv420p<'a>(frame: &FrameRef<'a>, scratch: &'a mut Vec<u8>) -> &'a [u8] {
    let data = pixels(frame);
    match frame.format {
        PixelFormat::Yuv420p => data,
        PixelFormat::Rgb8 | PixelFormat::Rgba8 => {
            let channels = frame.format.channels();
            rgb_to_yuv420p_into(frame.width, frame.height, channels, data, scratch);
            scratch
        }
    }
}

/// The error for a sink finished without any frame.
pub(crate) fn no_frames(path: &Path) -> VideoError {
    VideoError::BadFrame {
        path: path.to_path_buf(),
        detail: "no frames were written, so no output was created".into(),
    }
}
