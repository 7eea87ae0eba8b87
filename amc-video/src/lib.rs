//! Video input and output.
//!
//! The stabilizer works on decoded RGB frames; this module turns files into
//! frames and frames back into files:
//!
//! * input ([`open_input`]): a directory of images, a `.y4m` file (parsed here),
//!   or anything `ffmpeg` can decode (a child process piping raw RGB);
//! * output ([`create_output`]): `.mp4`, `.webm`, `.mkv` (an `ffmpeg` child
//!   reading raw RGB), `.y4m` (written here), or a directory of PNG files.
//!
//! Outputs are written to a hidden temporary sibling and renamed onto the
//! final path only by [`FrameSink::finish`], so an error or an interruption
//! never leaves a half-written file behind.

pub mod atomic;
pub mod cleanup;
mod ffmpeg;
mod images;
mod mkv;
mod probe;
mod process;
mod y4m;

#[cfg(test)]
mod tests;

use amc_core::image::{Frame, FrameRef};
pub use atomic::{write_atomic, AtomicDir, AtomicFile};
use std::path::{Path, PathBuf};
use std::time::Duration;
use thiserror::Error;

/// Image file extensions read from an input directory (compared case-insensitively).
pub const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "bmp", "tif", "tiff"];

/// The file in an image folder that states its frame rate (`{"fps": 60}`),
/// written by `amc synth`.
pub const FOLDER_META: &str = "meta.json";

pub use images::list_images;

/// Frame rate of an image directory when none is given and it states none.
pub const DEFAULT_IMAGE_FPS: f64 = 30.0;

/// Everything that can go wrong reading or writing video.
///
/// Each message is one line naming the file and what is wrong with it.
#[derive(Debug, Error)]
pub enum VideoError {
    /// The input does not exist.
    #[error("{}: no such file or directory", path.display())]
    NotFound { path: PathBuf },
    /// An operating-system error on a file (`action` says what we were doing).
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    /// ffmpeg/ffprobe cannot read the input, or it has no video stream.
    #[error("{}: not a video ffmpeg can read: {detail}", path.display())]
    NotAVideo { path: PathBuf, detail: String },
    /// A malformed YUV4MPEG2 file.
    #[error("{}: invalid YUV4MPEG2 (.y4m) file: {detail}", path.display())]
    Y4m { path: PathBuf, detail: String },
    /// An input directory without image files.
    #[error(
        "{}: no image files ({}) in this directory",
        path.display(),
        IMAGE_EXTENSIONS.join(", ")
    )]
    NoImages { path: PathBuf },
    /// An image in an input directory that cannot be decoded, or a PNG that cannot be encoded.
    #[error("{}: {detail}", path.display())]
    Image { path: PathBuf, detail: String },
    /// An image whose size differs from the first image of its directory.
    #[error(
        "{}: image is {width}x{height} but {} is {first_width}x{first_height}; all images in a directory must have the same size",
        path.display(),
        first.display()
    )]
    SizeMismatch {
        path: PathBuf,
        width: usize,
        height: usize,
        first: PathBuf,
        first_width: usize,
        first_height: usize,
    },
    /// An output path whose extension names no supported format.
    #[error(
        "{}: unsupported output format \"{ext}\"; use .mp4, .webm, .mkv, .y4m, or a directory (no extension) for PNG frames",
        path.display()
    )]
    UnsupportedOutput { path: PathBuf, ext: String },
    /// A PNG output directory that already holds files.
    #[error(
        "{}: output directory is not empty; choose a new or empty directory so frames are not mixed",
        path.display()
    )]
    OutputDirNotEmpty { path: PathBuf },
    /// `ffmpeg` or `ffprobe` is not installed.
    #[error("{tool} is not available ({detail}): install it with apt-get install ffmpeg")]
    ToolMissing { tool: &'static str, detail: String },
    /// An ffmpeg/ffprobe child failed; `detail` is its first error line.
    #[error("{}: {tool} failed: {detail}", path.display())]
    Ffmpeg {
        path: PathBuf,
        tool: &'static str,
        detail: String,
    },
    /// An ffmpeg/ffprobe child kept us waiting longer than the timeout and was killed.
    #[error(
        "{}: {tool} made no progress for {secs:.0} s and was stopped; raise the timeout if the file is very large",
        path.display()
    )]
    Timeout {
        path: PathBuf,
        tool: &'static str,
        secs: f64,
    },
    /// A frame or output specification that does not fit (wrong size, zero frames, bad fps).
    #[error("{}: {detail}", path.display())]
    BadFrame { path: PathBuf, detail: String },
}

impl VideoError {
    pub fn io(path: &Path, action: &'static str, source: std::io::Error) -> Self {
        VideoError::Io {
            path: path.to_path_buf(),
            action,
            source,
        }
    }
}

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
    /// Frame rate to use instead of the file's: image folders default to
    /// [`DEFAULT_IMAGE_FPS`]; for videos, timestamps become `i / fps`.
    pub fps_override: Option<f64>,
    /// The longest an ffmpeg/ffprobe child may keep us waiting (for probing,
    /// for one frame, or for exiting) before it is killed. This bounds stalls,
    /// not the total decoding time, so long videos are fine.
    pub timeout: Duration,
    /// Read a file at its own frame rate (ffmpeg `-re`), as a live feed would arrive.
    pub realtime: bool,
    /// Replay the file forever (ffmpeg `-stream_loop -1`); timestamps keep increasing.
    pub looped: bool,
}

impl Default for InputOptions {
    fn default() -> Self {
        Self {
            fps_override: None,
            timeout: Duration::from_secs(120),
            realtime: false,
            looped: false,
        }
    }
}

/// What ffprobe says about a file, for checks before decoding it.
#[derive(Clone, Debug)]
pub struct Inspection {
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

/// Probes a file (demuxing it to count frames) without decoding it.
pub fn inspect(path: &Path, timeout: Duration) -> Result<Inspection, VideoError> {
    let p = probe::probe(path, timeout)?;
    Ok(Inspection {
        info: p.info,
        format_name: p.format_name,
    })
}

/// Opens a live source ffmpeg can read (a file, an RTSP/UDP/SRT URL, a V4L2
/// device), with `format` as ffmpeg's `-f` when given. The source is probed
/// without counting its frames, so endless streams open at once.
pub fn open_stream(
    source: &str,
    format: Option<&str>,
    opts: &InputOptions,
) -> Result<Box<dyn FrameSource>, VideoError> {
    Ok(Box::new(ffmpeg::FfmpegSource::open_stream(
        source, format, opts,
    )?))
}

/// A stream of decoded frames.
pub trait FrameSource: Send {
    /// Size, rate and length of the input.
    fn info(&self) -> &VideoInfo;
    /// Decodes the next frame into `buf` (reusing its allocation, as RGB8),
    /// returning its presentation timestamp in seconds relative to the first
    /// frame (strictly increasing, the first is 0), or `None` at end of stream.
    fn next_frame(&mut self, buf: &mut Frame) -> Result<Option<f64>, VideoError>;
}

/// What to write.
#[derive(Clone, Debug)]
pub struct OutputSpec {
    /// Width of every frame given to [`FrameSink::write_frame`].
    pub width: usize,
    /// Height of every frame.
    pub height: usize,
    /// Frame rate of the output: the rate of `.y4m` outputs, which have no
    /// timestamps (video containers keep each frame's own time).
    pub fps: f64,
    /// Copy the audio of this input into the output if it has audio
    /// (ignored for `.y4m` and PNG outputs, which carry no audio).
    pub audio_from: Option<PathBuf>,
    /// The longest the encoder may keep us waiting (for one frame, or for
    /// finishing the file) before it is killed.
    pub timeout: Duration,
    /// Quality for mp4/mkv (x264 CRF, default 20) and webm (VP9 CRF, default 32):
    /// lower is better and larger.
    pub crf: Option<u8>,
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
        }
    }
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

/// Opens `path` for decoding: a directory of images, a `.y4m` file, or any
/// video ffmpeg can read.
pub fn open_input(path: &Path, opts: &InputOptions) -> Result<Box<dyn FrameSource>, VideoError> {
    if let Some(fps) = opts.fps_override {
        check_fps(path, fps)?;
    }
    let meta = std::fs::metadata(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => VideoError::NotFound {
            path: path.to_path_buf(),
        },
        _ => VideoError::io(path, "read", e),
    })?;
    if meta.is_dir() {
        return Ok(Box::new(images::ImageDirSource::open(path, opts)?));
    }
    if extension(path).as_deref() == Some("y4m") {
        return Ok(Box::new(y4m::Y4mSource::open(path, opts)?));
    }
    // Opening it here turns permission problems into a plain I/O error
    // instead of an obscure ffprobe message.
    std::fs::File::open(path).map_err(|e| VideoError::io(path, "open", e))?;
    Ok(Box::new(ffmpeg::FfmpegSource::open(path, opts)?))
}

/// Creates an output at `path`, its format chosen by the extension:
/// `.mp4` (H.264), `.webm` (VP9), `.mkv` (H.264), `.y4m`, or a directory of
/// PNG files when `path` has no extension, ends in `/`, or is an existing directory.
pub fn create_output(path: &Path, spec: &OutputSpec) -> Result<Box<dyn FrameSink>, VideoError> {
    if spec.width == 0 || spec.height == 0 {
        return Err(VideoError::BadFrame {
            path: path.to_path_buf(),
            detail: format!("cannot write {}x{} frames", spec.width, spec.height),
        });
    }
    check_fps(path, spec.fps)?;
    let ends_with_slash = path.as_os_str().to_string_lossy().ends_with('/');
    if ends_with_slash || path.is_dir() {
        return Ok(Box::new(images::PngDirSink::create(path, spec)?));
    }
    match extension(path).as_deref() {
        None => Ok(Box::new(images::PngDirSink::create(path, spec)?)),
        Some("y4m") => Ok(Box::new(y4m::Y4mSink::create(path, spec)?)),
        Some(ext) => match ffmpeg::Container::from_extension(ext) {
            Some(container) => Ok(Box::new(ffmpeg::FfmpegSink::create(path, spec, container)?)),
            None => Err(VideoError::UnsupportedOutput {
                path: path.to_path_buf(),
                ext: format!(".{ext}"),
            }),
        },
    }
}

/// Checks that `ffmpeg` and `ffprobe` can be run.
pub fn ffmpeg_available() -> Result<(), VideoError> {
    for tool in ["ffmpeg", "ffprobe"] {
        match std::process::Command::new(tool)
            .arg("-version")
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .status()
        {
            Ok(status) if status.success() => {}
            Ok(status) => {
                return Err(VideoError::ToolMissing {
                    tool,
                    detail: format!("`{tool} -version` exited with {status}"),
                })
            }
            Err(e) => {
                return Err(VideoError::ToolMissing {
                    tool,
                    detail: e.to_string(),
                })
            }
        }
    }
    Ok(())
}

/// The lower-cased extension of `path`, if any.
fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .filter(|e| !e.is_empty())
}

fn check_fps(path: &Path, fps: f64) -> Result<(), VideoError> {
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
fn fps_rational(fps: f64) -> (u64, u64) {
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
fn shape_rgb(buf: &mut Frame, width: usize, height: usize) {
    buf.width = width;
    buf.height = height;
    buf.format = amc_core::image::PixelFormat::Rgb8;
    buf.data.resize(width * height * 3, 0);
}

/// Checks a frame given to a sink against its spec.
fn check_frame(
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
fn as_rgb<'a>(frame: &'a FrameRef<'_>, scratch: &'a mut Vec<u8>) -> &'a [u8] {
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
    }
}

fn no_frames(path: &Path) -> VideoError {
    VideoError::BadFrame {
        path: path.to_path_buf(),
        detail: "no frames were written, so no output was created".into(),
    }
}
