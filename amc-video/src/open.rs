//! The entry points: [`open_input`], [`open_stream`], [`create_output`] and
//! [`inspect`] choose a format for a path and hand over to its module.

use crate::error::VideoError;
use crate::frame::{check_fps, check_source_format, extension, FrameSink, FrameSource};
use crate::spec::{InputOptions, Inspection, OutputSpec};
use crate::{ffmpeg, images, probe, y4m};
use std::path::Path;
use std::time::Duration;

/// Probes a file (demuxing it to count frames) without decoding it.
pub fn inspect(path: &Path, timeout: Duration) -> Result<Inspection, VideoError> {
    check_not_empty(path, std::fs::metadata(path).ok().as_ref())?;
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
    check_source_format(Path::new(source), opts.pixel_format)?;
    Ok(Box::new(ffmpeg::FfmpegSource::open_stream(
        source, format, opts,
    )?))
}

/// The pixel format `path`'s frames arrive in without a colour conversion:
/// RGB for a directory of images, planar 4:2:0 for `.y4m` files and videos
/// (what decoders produce). A run that keeps to it converts nothing on the way
/// in, and nothing on the way out to a video.
pub fn native_format(path: &Path) -> amc_core::PixelFormat {
    if path.is_dir() {
        amc_core::PixelFormat::Rgb8
    } else {
        amc_core::PixelFormat::Yuv420p
    }
}

/// The pixel format an output at `path` takes without a colour conversion:
/// RGB for a folder of PNGs, planar 4:2:0 for `.y4m` and videos.
pub fn native_output_format(path: &Path) -> amc_core::PixelFormat {
    if is_png_folder(path) {
        amc_core::PixelFormat::Rgb8
    } else {
        amc_core::PixelFormat::Yuv420p
    }
}

/// Whether an output at `path` is a folder of PNGs: a path without an
/// extension, ending in `/`, or an existing directory.
fn is_png_folder(path: &Path) -> bool {
    path.as_os_str().to_string_lossy().ends_with('/') || path.is_dir() || extension(path).is_none()
}

/// Opens `path` for decoding: a directory of images, a `.y4m` file, or any
/// video ffmpeg can read, its frames in `opts.pixel_format`.
pub fn open_input(path: &Path, opts: &InputOptions) -> Result<Box<dyn FrameSource>, VideoError> {
    Ok(match input_kind(path, opts)? {
        InputKind::Images => Box::new(images::ImageDirSource::open(path, opts)?),
        InputKind::Y4m => Box::new(y4m::Y4mSource::open(path, opts)?),
        InputKind::Video => Box::new(ffmpeg::FfmpegSource::open(path, opts)?),
    })
}

/// The size of the frames [`open_input`] would decode from `path`, found
/// without decoding: a video is probed without counting its frames and no
/// ffmpeg is started (that took ~0.4 s of a run's start).
pub fn frame_size(path: &Path, opts: &InputOptions) -> Result<(usize, usize), VideoError> {
    let info = match input_kind(path, opts)? {
        InputKind::Video => probe::probe_with(path, opts.timeout, false)?.info,
        _ => open_input(path, opts)?.info().clone(),
    };
    Ok((info.width, info.height))
}

/// What reads an input.
enum InputKind {
    Images,
    Y4m,
    Video,
}

/// Which reader `path` needs, once the checks every input gets have passed.
fn input_kind(path: &Path, opts: &InputOptions) -> Result<InputKind, VideoError> {
    if let Some(fps) = opts.fps_override {
        check_fps(path, fps)?;
    }
    check_source_format(path, opts.pixel_format)?;
    let meta = std::fs::metadata(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => VideoError::NotFound {
            path: path.to_path_buf(),
        },
        _ => VideoError::io(path, "read", e),
    })?;
    if meta.is_dir() {
        return Ok(InputKind::Images);
    }
    // Checked before probing: ffprobe would say "moov atom not found" or
    // "Invalid data found when processing input".
    check_not_empty(path, Some(&meta))?;
    if extension(path).as_deref() == Some("y4m") {
        return Ok(InputKind::Y4m);
    }
    // Opening it here turns permission problems into a plain I/O error
    // instead of an obscure ffprobe message.
    std::fs::File::open(path).map_err(|e| VideoError::io(path, "open", e))?;
    Ok(InputKind::Video)
}

/// What an output path names, by its extension.
enum OutputKind {
    /// A directory of PNG files: no extension, a trailing `/`, or an existing directory.
    PngFolder,
    /// A `.y4m` file.
    Y4m,
    /// A container ffmpeg writes (`.mp4`, `.webm`, `.mkv`).
    Container(ffmpeg::Container),
}

/// The kind of output `path` names, or [`VideoError::UnsupportedOutput`].
fn output_kind(path: &Path) -> Result<OutputKind, VideoError> {
    if is_png_folder(path) {
        return Ok(OutputKind::PngFolder);
    }
    match extension(path).as_deref() {
        None => Ok(OutputKind::PngFolder),
        Some("y4m") => Ok(OutputKind::Y4m),
        Some(ext) => ffmpeg::Container::from_extension(ext)
            .map(OutputKind::Container)
            .ok_or_else(|| VideoError::UnsupportedOutput {
                path: path.to_path_buf(),
                ext: format!(".{ext}"),
            }),
    }
}

/// Checks, before any work, that an output can be made at `path`: its
/// extension names a format [`create_output`] writes and the directory it
/// goes in exists. The same errors [`create_output`] would give at the end.
pub fn check_output(path: &Path) -> Result<(), VideoError> {
    output_kind(path)?;
    check_parent_dir(path)
}

/// Checks that the directory a file written at `path` goes in exists (a
/// telemetry or metrics file, before any work).
pub fn check_parent_dir(path: &Path) -> Result<(), VideoError> {
    crate::atomic::parent_dir(path).map(|_| ())
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
    Ok(match output_kind(path)? {
        OutputKind::PngFolder => Box::new(images::PngDirSink::create(path, spec)?),
        OutputKind::Y4m => Box::new(y4m::Y4mSink::create(path, spec)?),
        OutputKind::Container(container) => {
            Box::new(ffmpeg::FfmpegSink::create(path, spec, container)?)
        }
    })
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

/// Refuses a 0-byte regular file (`meta` is its metadata, when it could be read).
fn check_not_empty(path: &Path, meta: Option<&std::fs::Metadata>) -> Result<(), VideoError> {
    match meta {
        Some(m) if m.is_file() && m.len() == 0 => Err(VideoError::EmptyFile {
            path: path.to_path_buf(),
        }),
        _ => Ok(()),
    }
}
