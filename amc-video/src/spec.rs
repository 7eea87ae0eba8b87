//! Plain descriptions of inputs and outputs: what is known about an input
//! ([`VideoInfo`], [`Inspection`]), how to open one ([`InputOptions`]), what to
//! write ([`OutputSpec`]), and the constants they refer to.

use amc_core::PixelFormat;
use std::path::PathBuf;
use std::time::Duration;

/// Image file extensions read from an input directory (compared case-insensitively).
pub const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "bmp", "tif", "tiff"];

/// The file in an image folder that states its frame rate (`{"fps": 60}`),
/// written by `amc synth`.
pub const FOLDER_META: &str = "meta.json";

/// Frame rate of an image directory when none is given and it states none (frames per second).
pub const DEFAULT_IMAGE_FPS: f64 = 30.0;

/// What is known about an input before decoding it.
#[derive(Clone, Debug, PartialEq)]
pub struct VideoInfo {
    /// Frame width in pixels (after the rotation ffmpeg applies on decode).
    pub width: usize,
    /// Frame height in pixels.
    pub height: usize,
    /// Average frame rate (frames per second).
    pub fps: f64,
    /// Number of frames, when the container says (or counting packets is possible).
    pub frame_count: Option<u64>,
    /// Duration in seconds, when known.
    pub duration_s: Option<f64>,
    /// Whether the input has an audio stream (never for image folders and `.y4m`).
    pub has_audio: bool,
    /// Whether `fps` is [`DEFAULT_IMAGE_FPS`] assumed for an image folder that
    /// states no rate (no `--fps`, no `meta.json` or `gt.csv`): worth a warning.
    pub fps_assumed: bool,
}

/// How to open an input.
#[derive(Clone, Debug)]
pub struct InputOptions {
    /// Frame rate to use instead of the file's (frames per second, above 0 and
    /// at most 10000): image folders default to [`DEFAULT_IMAGE_FPS`]; for
    /// videos, timestamps become `i / fps`.
    pub fps_override: Option<f64>,
    /// The longest an ffmpeg/ffprobe child may keep us waiting (for probing,
    /// for one frame, or for exiting) before it is killed. This bounds stalls,
    /// not the total decoding time, so long videos are fine.
    pub timeout: Duration,
    /// Read a file at its own frame rate (ffmpeg `-re`), as a live feed would arrive.
    pub realtime: bool,
    /// Replay the file forever (ffmpeg `-stream_loop -1`); timestamps keep increasing.
    pub looped: bool,
    /// The format [`FrameSource::next_frame`](crate::FrameSource::next_frame)
    /// fills frames in: [`PixelFormat::Rgb8`] (the default) or
    /// [`PixelFormat::Yuv420p`] (limited range; what video decoders deliver, so
    /// videos and 4:2:0 `.y4m` files need no colour conversion). Other inputs
    /// are converted: 10-bit, 4:2:2, 4:4:4 and full-range videos by ffmpeg,
    /// `.y4m` and image folders here (full-range 8-bit 4:2:0 too).
    /// [`PixelFormat::Rgba8`] is refused with
    /// [`VideoError::UnsupportedPixelFormat`](crate::VideoError::UnsupportedPixelFormat).
    pub pixel_format: PixelFormat,
    /// Threads the ffmpeg decoder and its filters may use (`-threads N
    /// -filter_threads N`); `None`: one decoder thread for frames up to
    /// 1920x1088 (it keeps up, and frame threads cost CPU the run needs),
    /// ffmpeg's own choice (about every core) above. A run limited to N
    /// threads sets it so that it stays within N cores.
    pub ffmpeg_threads: Option<usize>,
}

impl Default for InputOptions {
    fn default() -> Self {
        Self {
            fps_override: None,
            timeout: Duration::from_secs(120),
            realtime: false,
            looped: false,
            pixel_format: PixelFormat::Rgb8,
            ffmpeg_threads: None,
        }
    }
}

/// What ffprobe says about a file, for checks before decoding it.
#[derive(Clone, Debug)]
pub struct Inspection {
    /// Size, rate and length of the file's video stream.
    pub info: VideoInfo,
    /// ffmpeg's name for the container, e.g. `mov,mp4,m4a,3gp,3g2,mj2` or `png_pipe`.
    pub format_name: String,
}

impl Inspection {
    /// Whether the file is a still picture (a PNG, a JPEG...) rather than a video.
    pub fn is_still_image(&self) -> bool {
        let f = self.format_name.as_str();
        f.ends_with("_pipe") || f == "image2" || f == "gif" && self.info.frame_count == Some(1)
    }
}

/// What to write.
#[derive(Clone, Debug)]
pub struct OutputSpec {
    /// Width in pixels of every frame given to [`FrameSink::write_frame`](crate::FrameSink::write_frame).
    pub width: usize,
    /// Height in pixels of every frame.
    pub height: usize,
    /// Frame rate of the output (frames per second): the rate of `.y4m`
    /// outputs, which have no timestamps (video containers keep each frame's
    /// own time).
    pub fps: f64,
    /// Copy the audio of this input into the output if it has audio
    /// (ignored for `.y4m` and PNG outputs, which carry no audio).
    pub audio_from: Option<PathBuf>,
    /// The longest the encoder may keep us waiting (for one frame, or for
    /// finishing the file) before it is killed.
    pub timeout: Duration,
    /// Quality for mp4/mkv (x264 CRF 0..=51, default 20) and webm (VP9 CRF
    /// 0..=63, default 32): lower is better and larger. A value outside the
    /// format's range is an error.
    pub crf: Option<u8>,
    /// x264's preset for mp4/mkv (default [`X264Preset::FILES`]); other
    /// formats ignore it.
    pub preset: Option<crate::X264Preset>,
    /// The format of the frames the caller will give (default
    /// [`PixelFormat::Rgb8`]). It fixes the pixel format of the pipe to an
    /// ffmpeg encoder: [`PixelFormat::Yuv420p`] frames then reach it as they
    /// are (and the encoder's `yuv420p` needs no conversion), other formats go
    /// as RGB24. A frame of another format is still accepted, converted. `.y4m`
    /// and PNG outputs ignore it (they convert each frame as needed).
    pub pixel_format: PixelFormat,
    /// Threads the ffmpeg encoder and its filters may use (`-threads N
    /// -filter_threads N`); `None`: ffmpeg's own choice.
    pub ffmpeg_threads: Option<usize>,
}

impl OutputSpec {
    /// A spec with no audio, the default timeout and default quality.
    pub fn new(width: usize, height: usize, fps: f64) -> Self {
        Self {
            width,
            height,
            fps,
            audio_from: None,
            timeout: InputOptions::default().timeout,
            crf: None,
            preset: None,
            pixel_format: PixelFormat::Rgb8,
            ffmpeg_threads: None,
        }
    }
}
