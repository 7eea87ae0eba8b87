//! The [`FrameSource`] and [`FrameSink`] traits every format implements, and
//! the small helpers the formats share (frame shapes, rates, extensions).

use crate::error::VideoError;
use crate::spec::VideoInfo;
use amc_core::image::{Frame, FrameRef};
use std::path::Path;

/// A stream of decoded frames.
pub trait FrameSource: Send {
    /// Size, rate and length of the input.
    fn info(&self) -> &VideoInfo;
    /// Decodes the next frame into `buf` (reusing its allocation, as RGB8),
    /// returning its presentation timestamp in seconds relative to the first
    /// frame (strictly increasing, the first is 0), or `None` at end of stream.
    fn next_frame(&mut self, buf: &mut Frame) -> Result<Option<f64>, VideoError>;
}

/// A destination for frames. Nothing appears at the output path until
/// [`finish`](FrameSink::finish) succeeds; dropping a sink without finishing
/// it removes what was written and stops the encoder.
pub trait FrameSink: Send {
    /// Appends one frame (RGB8 or RGBA8, alpha ignored) of the size given in
    /// the spec, shown at `t` seconds (non-decreasing; the first frame's time is
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

/// Makes frame buffers the right shape for a source, reusing their allocation.
pub(crate) fn shape_rgb(buf: &mut Frame, width: usize, height: usize) {
    buf.width = width;
    buf.height = height;
    buf.format = amc_core::image::PixelFormat::Rgb8;
    buf.data.resize(width * height * 3, 0);
}

/// Checks a frame given to a sink against its spec.
pub(crate) fn check_frame(
    path: &Path,
    spec_w: usize,
    spec_h: usize,
    frame: &FrameRef<'_>,
) -> Result<(), VideoError> {
    let expected = frame.width * frame.height * frame.format.channels();
    if frame.width != spec_w || frame.height != spec_h || frame.data.len() != expected {
        return Err(VideoError::BadFrame {
            path: path.to_path_buf(),
            detail: format!(
                "got a {}x{} frame ({} bytes) but the output was created for {}x{}",
                frame.width,
                frame.height,
                frame.data.len(),
                spec_w,
                spec_h
            ),
        });
    }
    Ok(())
}

/// The frame as packed RGB: borrowed when it already is, else converted into `scratch`.
pub(crate) fn as_rgb<'a>(frame: &'a FrameRef<'_>, scratch: &'a mut Vec<u8>) -> &'a [u8] {
    match frame.format {
        amc_core::image::PixelFormat::Rgb8 => frame.data,
        amc_core::image::PixelFormat::Rgba8 => {
            scratch.clear();
            scratch.reserve(frame.width * frame.height * 3);
            for px in frame.data.chunks_exact(4) {
                scratch.extend_from_slice(&px[..3]);
            }
            scratch
        }
        amc_core::image::PixelFormat::Yuv420p => {
            amc_core::color::yuv420p_to_rgb_into(
                frame.width,
                frame.height,
                frame.data,
                false,
                3,
                scratch,
            );
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
