//! Video input and output.
//!
//! The stabilizer works on decoded frames, packed RGB or planar YUV 4:2:0
//! (`amc_core::PixelFormat`); this module turns files into frames and frames
//! back into files:
//!
//! * input ([`open_input`]): a directory of images, a `.y4m` file (parsed here),
//!   or anything `ffmpeg` can decode (a child process piping raw frames), in
//!   the format asked for by [`InputOptions::pixel_format`];
//! * output ([`create_output`]): `.mp4`, `.webm`, `.mkv` (an `ffmpeg` child
//!   reading raw frames with their timestamps as Matroska, YUV 4:2:0 when
//!   [`OutputSpec::pixel_format`] says so, else RGB), `.y4m` (written here),
//!   or a directory of PNG files. Sinks take RGB8, RGBA8 and YUV 4:2:0 frames.
//!
//! Outputs are written to a hidden temporary sibling and renamed onto the
//! final path only by [`FrameSink::finish`], so an error or an interruption
//! never leaves a half-written file behind.

#![deny(missing_docs)]

pub mod atomic;
mod caps;
pub mod cleanup;
mod direct;
mod error;
mod ffmpeg;
mod flv;
mod frame;
mod frame_pipe;
mod h264;
mod h264_decoder;
mod images;
mod mkv;
mod open;
mod preset;
mod probe;
mod process;
mod spec;
mod y4m;

#[cfg(test)]
mod tests;

pub use atomic::{write_atomic, AtomicDir, AtomicFile};
pub use error::VideoError;
pub use flv::{AccessUnit, FlvError, FlvToAnnexB};
pub use frame::{FrameSink, FrameSource};
pub use h264::{H264Encoder, H264Options};
pub use h264_decoder::{is_annex_b, H264Decoder};
pub use images::{folder_fps, list_images};
pub use open::{
    check_output, check_parent_dir, create_output, ffmpeg_available, frame_size, inspect,
    native_format, native_output_format, open_input, open_stream,
};
pub use preset::{X264Preset, X264_PRESETS};
pub use spec::{
    InputOptions, Inspection, OutputSpec, VideoInfo, DEFAULT_IMAGE_FPS, FOLDER_META,
    IMAGE_EXTENSIONS,
};
