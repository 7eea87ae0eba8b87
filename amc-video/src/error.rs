//! [`VideoError`]: everything that can go wrong reading or writing video.

use crate::spec::IMAGE_EXTENSIONS;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Everything that can go wrong reading or writing video.
///
/// Each message is one line naming the file and what is wrong with it. The
/// path is always the one the user gave (never a hidden temporary sibling).
#[derive(Debug, Error)]
pub enum VideoError {
    /// The input does not exist.
    #[error("{}: no such file or directory", path.display())]
    NotFound {
        /// The missing input.
        path: PathBuf,
    },
    /// An operating-system error on a file (`action` says what we were doing).
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file or directory concerned.
        path: PathBuf,
        /// What we were doing, as a verb phrase (`"open"`, `"write a frame"`).
        action: &'static str,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// ffmpeg/ffprobe cannot read the input, or it has no video stream.
    #[error("{}: not a video ffmpeg can read: {detail}", path.display())]
    NotAVideo {
        /// The input.
        path: PathBuf,
        /// Why (ffprobe's first error line, or our own explanation).
        detail: String,
    },
    /// A still picture (a PNG, a JPEG..., whatever its name) given as a video.
    #[error(
        "{}: this is a still image ({format}), not a video; to stabilize a sequence of pictures, put them in a folder and give the folder",
        path.display()
    )]
    StillImage {
        /// The input.
        path: PathBuf,
        /// ffmpeg's name for its format (`png_pipe`, `jpeg_pipe`, ...).
        format: String,
    },
    /// An empty (0-byte) input file.
    #[error("{}: empty file (0 bytes), not a video", path.display())]
    EmptyFile {
        /// The input.
        path: PathBuf,
    },
    /// A malformed YUV4MPEG2 file.
    #[error("{}: invalid YUV4MPEG2 (.y4m) file: {detail}", path.display())]
    Y4m {
        /// The `.y4m` file.
        path: PathBuf,
        /// What is wrong with it.
        detail: String,
    },
    /// An input directory without image files.
    #[error(
        "{}: no image files ({}) in this directory{}",
        path.display(),
        IMAGE_EXTENSIONS.join(", "),
        subfolder.as_ref().map_or(String::new(), |(dir, n)| format!(
            "; its subfolder {} holds {n}: pass that folder",
            dir.display()
        ))
    )]
    NoImages {
        /// The directory.
        path: PathBuf,
        /// A subfolder that does hold image files, and how many (a recording
        /// laid out as `frames/` beside its `lens.json`, as
        /// `../shared/data/cc9` is).
        subfolder: Option<(PathBuf, usize)>,
    },
    /// An image in an input directory that cannot be decoded, or a PNG that cannot be encoded.
    #[error("{}: {detail}", path.display())]
    Image {
        /// The image file.
        path: PathBuf,
        /// What is wrong with it.
        detail: String,
    },
    /// An image whose size differs from the first image of its directory.
    #[error(
        "{}: image is {width}x{height} but {} is {first_width}x{first_height}; all images in a directory must have the same size",
        path.display(),
        first.display()
    )]
    SizeMismatch {
        /// The image of another size.
        path: PathBuf,
        /// Its width in pixels.
        width: usize,
        /// Its height in pixels.
        height: usize,
        /// The first image of the directory.
        first: PathBuf,
        /// The first image's width in pixels.
        first_width: usize,
        /// The first image's height in pixels.
        first_height: usize,
    },
    /// An output path whose extension names no supported format.
    #[error(
        "{}: unsupported output format \"{ext}\"; use .mp4, .webm, .mkv, .y4m, or a directory (no extension) for PNG frames",
        path.display()
    )]
    UnsupportedOutput {
        /// The output path.
        path: PathBuf,
        /// Its extension, with the dot (`".avi"`).
        ext: String,
    },
    /// A PNG output directory that already holds files.
    #[error(
        "{}: output directory is not empty; choose a new or empty directory so frames are not mixed",
        path.display()
    )]
    OutputDirNotEmpty {
        /// The output directory.
        path: PathBuf,
    },
    /// `ffmpeg` or `ffprobe` is not installed.
    #[error("{tool} is not available ({detail}): install it with apt-get install ffmpeg")]
    ToolMissing {
        /// `"ffmpeg"` or `"ffprobe"`.
        tool: &'static str,
        /// Why it cannot be run.
        detail: String,
    },
    /// An ffmpeg/ffprobe child failed; `detail` is its first error line.
    #[error("{}: {tool} failed: {detail}", path.display())]
    Ffmpeg {
        /// The file the child worked on (the user's path, never a temporary one).
        path: PathBuf,
        /// `"ffmpeg"` or `"ffprobe"`.
        tool: &'static str,
        /// Its first error line (and last, when there are several).
        detail: String,
    },
    /// An ffmpeg/ffprobe child kept us waiting longer than the timeout and was killed.
    #[error(
        "{}: {tool} made no progress for {secs:.0} s and was stopped; raise the timeout if the file is very large",
        path.display()
    )]
    Timeout {
        /// The file the child worked on.
        path: PathBuf,
        /// `"ffmpeg"` or `"ffprobe"`.
        tool: &'static str,
        /// The timeout that ran out, in seconds.
        secs: f64,
    },
    /// A source asked to decode to a pixel format sources do not produce.
    #[error(
        "{}: cannot decode frames as {format:?}; sources decode to Rgb8 or Yuv420p",
        path.display()
    )]
    UnsupportedPixelFormat {
        /// The input.
        path: PathBuf,
        /// The format asked for.
        format: amc_core::PixelFormat,
    },
    /// A frame or output specification that does not fit (wrong size, zero frames, bad fps, bad CRF).
    #[error("{}: {detail}", path.display())]
    BadFrame {
        /// The input or output concerned.
        path: PathBuf,
        /// What does not fit.
        detail: String,
    },
}

impl VideoError {
    /// An [`VideoError::Io`] error on `path` while doing `action`.
    pub fn io(path: &Path, action: &'static str, source: std::io::Error) -> Self {
        VideoError::Io {
            path: path.to_path_buf(),
            action,
            source,
        }
    }
}
