//! Directories of still images as video: input from image files in natural
//! order (`frame-9` before `frame-10`), output as `frame-000000.png`, ...
//!
//! Images decode to RGB; a source asked for YUV 4:2:0 converts each with
//! `amc_core::color::rgb_to_yuv420p_into`, and the PNG sink converts YUV 4:2:0
//! frames back to RGB with `yuv420p_to_rgb_into`.

use crate::atomic::AtomicDir;
use crate::error::VideoError;
use crate::frame::{as_rgb, check_frame, extension, no_frames, FrameSink, FrameSource};
use crate::process::run_capture;
use crate::spec::{
    InputOptions, OutputSpec, VideoInfo, DEFAULT_IMAGE_FPS, FOLDER_META, IMAGE_EXTENSIONS,
};
use amc_core::color::rgb_to_yuv420p_into;
use amc_core::image::{Frame, FrameRef, PixelFormat};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The image files of `dir` (by extension, case-insensitive; hidden files
/// skipped), in natural order (`frame-9` before `frame-10`).
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>, VideoError> {
    let files = image_files(dir)?;
    if files.is_empty() {
        return Err(VideoError::NoImages {
            path: dir.to_path_buf(),
            subfolder: subfolder_with_images(dir),
        });
    }
    Ok(files)
}

/// The first subfolder of `dir` (in natural order) that holds image files,
/// and how many, for the error that `dir` holds none.
fn subfolder_with_images(dir: &Path) -> Option<(PathBuf, usize)> {
    let mut subdirs: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| Some(e.ok()?.path()))
        .filter(|p| p.is_dir())
        .collect();
    subdirs.sort_by(|a, b| natord::compare(&a.to_string_lossy(), &b.to_string_lossy()));
    subdirs.into_iter().find_map(|d| {
        let n = image_files(&d).ok()?.len();
        (n > 0).then_some((d, n))
    })
}

/// The image files of `dir` in natural order; empty when it has none.
fn image_files(dir: &Path) -> Result<Vec<PathBuf>, VideoError> {
    let entries = std::fs::read_dir(dir).map_err(|e| VideoError::io(dir, "list", e))?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| VideoError::io(dir, "list", e))?;
        let path = entry.path();
        let is_image = extension(&path).is_some_and(|ext| IMAGE_EXTENSIONS.contains(&ext.as_str()));
        // Hidden files are editor/OS litter (`._frame.png` on macOS volumes).
        let hidden = entry.file_name().to_string_lossy().starts_with('.');
        if is_image && !hidden && path.is_file() {
            files.push(path);
        }
    }
    files.sort_by(|a, b| {
        let name = |p: &PathBuf| {
            p.file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned()
        };
        natord::compare(&name(a), &name(b))
    });
    Ok(files)
}

/// The frame rate a folder states about itself: `meta.json`'s `fps` (written
/// by `amc synth`), else the spacing of the `t` column of a ground-truth
/// `gt.csv` (`frame,t,...`). `None` when it says nothing usable.
pub fn folder_fps(dir: &Path) -> Option<f64> {
    let valid = |fps: f64| (fps.is_finite() && fps > 0.0 && fps <= 10_000.0).then_some(fps);
    if let Ok(text) = std::fs::read_to_string(dir.join(FOLDER_META)) {
        if let Some(fps) = serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .and_then(|v| v.get("fps").and_then(|f| f.as_f64()))
        {
            return valid(fps);
        }
    }
    let text = std::fs::read_to_string(dir.join("gt.csv")).ok()?;
    let mut lines = text.lines();
    let col = lines.next()?.split(',').position(|c| c.trim() == "t")?;
    let times: Vec<f64> = lines
        .take(2)
        .filter_map(|l| l.split(',').nth(col)?.trim().parse().ok())
        .collect();
    match times[..] {
        [t0, t1] if t1 > t0 => valid(1.0 / (t1 - t0)),
        _ => None,
    }
}

/// Frames read from the image files of a directory.
pub(crate) struct ImageDirSource {
    files: Vec<PathBuf>,
    info: VideoInfo,
    /// The first image, decoded by `open` to learn the size, handed out first.
    first: Option<Vec<u8>>,
    index: usize,
    timeout: std::time::Duration,
    /// The format frames are handed out in (RGB8 or YUV 4:2:0).
    format: PixelFormat,
}

impl ImageDirSource {
    /// Lists the images of `dir` and decodes the first to learn the frame size.
    pub fn open(dir: &Path, opts: &InputOptions) -> Result<Self, VideoError> {
        let files = list_images(dir)?;
        let (width, height, first) = decode(&files[0], opts.timeout)?;
        let own_fps = if opts.fps_override.is_some() {
            None
        } else {
            folder_fps(dir)
        };
        let fps = opts.fps_override.or(own_fps).unwrap_or(DEFAULT_IMAGE_FPS);
        let n = files.len() as u64;
        Ok(Self {
            info: VideoInfo {
                width,
                height,
                fps,
                frame_count: Some(n),
                duration_s: Some(n as f64 / fps),
                has_audio: false,
                fps_assumed: opts.fps_override.is_none() && own_fps.is_none(),
            },
            files,
            first: Some(first),
            index: 0,
            timeout: opts.timeout,
            format: opts.pixel_format,
        })
    }
}

impl FrameSource for ImageDirSource {
    fn info(&self) -> &VideoInfo {
        &self.info
    }

    fn next_frame(&mut self, buf: &mut Frame) -> Result<Option<f64>, VideoError> {
        let Some(path) = self.files.get(self.index) else {
            return Ok(None);
        };
        let (w, h) = (self.info.width, self.info.height);
        let data = match self.first.take() {
            Some(data) => data,
            None => {
                let (width, height, data) = decode(path, self.timeout)?;
                if (width, height) != (w, h) {
                    return Err(VideoError::SizeMismatch {
                        path: path.clone(),
                        width,
                        height,
                        first: self.files[0].clone(),
                        first_width: w,
                        first_height: h,
                    });
                }
                data
            }
        };
        match self.format {
            PixelFormat::Yuv420p => {
                rgb_to_yuv420p_into(w, h, 3, &data, &mut buf.data);
                (buf.width, buf.height, buf.format) = (w, h, PixelFormat::Yuv420p);
            }
            _ => {
                // The decoder hands us a fresh buffer anyway: take it instead of copying.
                buf.data = data;
                (buf.width, buf.height, buf.format) = (w, h, PixelFormat::Rgb8);
            }
        }
        let t = self.index as f64 / self.info.fps;
        self.index += 1;
        Ok(Some(t))
    }
}

/// Decodes an image file to packed RGB8: `(width, height, pixels)`.
fn decode(
    path: &Path,
    timeout: std::time::Duration,
) -> Result<(usize, usize, Vec<u8>), VideoError> {
    let err = |detail: String| VideoError::Image {
        path: path.to_path_buf(),
        detail,
    };
    // Sniffing the content rather than trusting the extension copes with
    // misnamed files (a JPEG called .png).
    let bytes = std::fs::read(path).map_err(|e| VideoError::io(path, "read image", e))?;
    let reader = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| VideoError::io(path, "read image", e))?;
    // The JPEG decoder fills in whatever is missing from a cut-off file
    // (grey or smeared rows) without a word: check that it is complete.
    if reader.format() == Some(image::ImageFormat::Jpeg) && !jpeg_complete(&bytes) {
        return Err(err(
            "truncated JPEG: the file ends before its end-of-image marker (an incomplete copy or download?)"
                .into(),
        ));
    }
    let is_tiff = reader.format() == Some(image::ImageFormat::Tiff)
        || matches!(extension(path).as_deref(), Some("tif" | "tiff"));
    match reader.decode() {
        Ok(img) => {
            let rgb = img.into_rgb8();
            let (w, h) = (rgb.width() as usize, rgb.height() as usize);
            Ok((w, h, rgb.into_raw()))
        }
        // Formats this build of the image crate lacks (TIFF) go through ffmpeg.
        Err(image::ImageError::Unsupported(_)) if is_tiff => decode_with_ffmpeg(path, timeout),
        Err(e) => Err(err(format!("cannot decode image: {e}"))),
    }
}

/// Whether a JPEG file runs to its end-of-image marker: walks the marker
/// segments (skipping their payloads, so an EXIF thumbnail's own markers do
/// not count) and the entropy-coded data after each start-of-scan, where a
/// 0xFF byte is always followed by 0x00 (stuffing) or a restart marker.
fn jpeg_complete(data: &[u8]) -> bool {
    const SOI: u8 = 0xD8;
    const EOI: u8 = 0xD9;
    const SOS: u8 = 0xDA;
    if data.len() < 4 || data[0] != 0xFF || data[1] != SOI {
        return false;
    }
    let mut pos = 2;
    loop {
        // A marker: 0xFF (possibly repeated as fill), then its code.
        if data.get(pos) != Some(&0xFF) {
            return false;
        }
        while data.get(pos) == Some(&0xFF) {
            pos += 1;
        }
        let Some(&code) = data.get(pos) else {
            return false;
        };
        pos += 1;
        match code {
            EOI => return true,
            // Markers without a payload.
            0x01 | 0xD0..=0xD7 => continue,
            _ => {}
        }
        let Some(len) = data.get(pos..pos + 2) else {
            return false;
        };
        let len = u16::from_be_bytes([len[0], len[1]]) as usize;
        if len < 2 {
            return false;
        }
        pos += len;
        if pos > data.len() {
            return false;
        }
        if code == SOS {
            // Entropy-coded data up to the next marker that is neither
            // stuffing nor a restart.
            loop {
                match data.get(pos..pos + 2) {
                    None => return false,
                    Some([0xFF, 0x00]) | Some([0xFF, 0xD0..=0xD7]) => pos += 2,
                    Some([0xFF, _]) => break,
                    Some(_) => pos += 1,
                }
            }
        }
    }
}

/// Decodes one image with ffmpeg into a binary PPM on stdout, whose header
/// carries the size.
fn decode_with_ffmpeg(
    path: &Path,
    timeout: std::time::Duration,
) -> Result<(usize, usize, Vec<u8>), VideoError> {
    let err = |detail: String| VideoError::Image {
        path: path.to_path_buf(),
        detail: format!("cannot decode image: {detail}"),
    };
    let mut args: Vec<OsString> = ["-hide_banner", "-nostdin", "-loglevel", "level+error", "-i"]
        .iter()
        .map(OsString::from)
        .collect();
    args.push(path.as_os_str().to_owned());
    args.extend(
        [
            "-frames:v",
            "1",
            "-f",
            "image2pipe",
            "-c:v",
            "ppm",
            "-pix_fmt",
            "rgb24",
            "pipe:1",
        ]
        .iter()
        .map(OsString::from),
    );
    let (_, out, failure) = run_capture("ffmpeg", &args, path, timeout)?;
    if let Some(detail) = failure {
        return Err(err(detail));
    }
    parse_ppm(&out).ok_or_else(|| err("ffmpeg produced no picture".into()))
}

/// Parses a binary 8-bit PPM (`P6 W H 255` + RGB data).
fn parse_ppm(data: &[u8]) -> Option<(usize, usize, Vec<u8>)> {
    let mut fields = Vec::with_capacity(4);
    let mut pos = 0;
    while fields.len() < 4 {
        while data.get(pos)?.is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while !data.get(pos)?.is_ascii_whitespace() {
            pos += 1;
        }
        fields.push(std::str::from_utf8(&data[start..pos]).ok()?);
    }
    pos += 1; // the single whitespace byte before the pixels
    let (w, h): (usize, usize) = (fields[1].parse().ok()?, fields[2].parse().ok()?);
    if fields[0] != "P6" || fields[3] != "255" || w == 0 || h == 0 {
        return None;
    }
    let pixels = data.get(pos..pos + w.checked_mul(h)?.checked_mul(3)?)?;
    Some((w, h, pixels.to_vec()))
}

/// Frames written as PNG files into a temporary directory, renamed onto the
/// output directory by `finish`.
pub(crate) struct PngDirSink {
    path: PathBuf,
    /// Deleted with its contents on drop unless `finish` moves it into place.
    temp: AtomicDir,
    width: usize,
    height: usize,
    scratch: Vec<u8>,
    frames: u64,
}

impl PngDirSink {
    /// Checks that `path` is new or an empty directory and creates the temporary one.
    pub fn create(path: &Path, spec: &OutputSpec) -> Result<Self, VideoError> {
        // `out/` names the directory `out`.
        let path: PathBuf = path.components().collect();
        check_replaceable(&path)?;
        let temp = AtomicDir::create(&path)?;
        Ok(Self {
            path,
            temp,
            width: spec.width,
            height: spec.height,
            scratch: Vec::new(),
            frames: 0,
        })
    }
}

/// Whether the output directory may be (re)placed: it must not exist, or be
/// an empty directory.
fn check_replaceable(path: &Path) -> Result<(), VideoError> {
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(VideoError::io(path, "inspect output", e)),
        Ok(meta) if meta.is_dir() => {
            let mut entries =
                std::fs::read_dir(path).map_err(|e| VideoError::io(path, "list", e))?;
            if entries.next().is_some() {
                Err(VideoError::OutputDirNotEmpty {
                    path: path.to_path_buf(),
                })
            } else {
                Ok(())
            }
        }
        Ok(_) => Err(VideoError::io(
            path,
            "create output directory",
            std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "a file with this name exists (PNG frames need a directory)",
            ),
        )),
    }
}

impl FrameSink for PngDirSink {
    fn write_frame(&mut self, frame: &FrameRef<'_>, _t: f64) -> Result<(), VideoError> {
        use image::ImageEncoder;
        check_frame(&self.path, self.width, self.height, frame)?;
        let rgb = as_rgb(frame, &mut self.scratch);
        let name = format!("frame-{:06}.png", self.frames);
        let file_path = self.temp.partial_path().join(&name);
        let file = std::fs::File::create(&file_path)
            .map_err(|e| VideoError::io(&self.path, "write a frame", e))?;
        // Fast compression: default zlib levels make encoding the bottleneck.
        let encoder = image::codecs::png::PngEncoder::new_with_quality(
            std::io::BufWriter::new(file),
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Adaptive,
        );
        encoder
            .write_image(
                rgb,
                self.width as u32,
                self.height as u32,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(|e| VideoError::Image {
                path: self.path.join(name),
                detail: format!("cannot write PNG: {e}"),
            })?;
        self.frames += 1;
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<(), VideoError> {
        if self.frames == 0 {
            return Err(no_frames(&self.path));
        }
        let PngDirSink { path, temp, .. } = *self;
        // Checked again: something may have appeared there meanwhile.
        check_replaceable(&path)?;
        temp.persist()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_ppm() {
        let mut data = b"P6\n2 1\n255\n".to_vec();
        data.extend_from_slice(&[1, 2, 3, 4, 5, 6]);
        assert_eq!(parse_ppm(&data), Some((2, 1, vec![1, 2, 3, 4, 5, 6])));
        assert_eq!(parse_ppm(&data[..12]), None);
        assert_eq!(parse_ppm(b"P5\n2 1\n255\n\0\0"), None);
    }

    /// A tiny JPEG made by the encoder of the `image` crate.
    fn small_jpeg() -> Vec<u8> {
        let mut out = Vec::new();
        let pixels: Vec<u8> = (0..32 * 24 * 3).map(|i| (i * 7 % 251) as u8).collect();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .encode(&pixels, 32, 24, image::ExtendedColorType::Rgb8)
            .unwrap();
        out
    }

    #[test]
    fn tells_truncated_jpegs() {
        let full = small_jpeg();
        assert!(jpeg_complete(&full));
        // Bytes after the end-of-image marker (camera trailers) are fine.
        let mut trailer = full.clone();
        trailer.extend_from_slice(b"\xff\xda trailing data");
        assert!(jpeg_complete(&trailer));
        for cut in [full.len() - 1, full.len() - 2, full.len() * 2 / 3, 10, 3] {
            assert!(
                !jpeg_complete(&full[..cut]),
                "cut at {cut} of {}",
                full.len()
            );
        }
        assert!(!jpeg_complete(b"not a jpeg"));
    }

    #[test]
    fn refuses_a_truncated_jpeg_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let full = small_jpeg();
        let good = dir.path().join("a.jpg");
        std::fs::write(&good, &full).unwrap();
        let timeout = std::time::Duration::from_secs(30);
        assert_eq!(decode(&good, timeout).unwrap().0, 32);
        let cut = dir.path().join("b.jpg");
        std::fs::write(&cut, &full[..full.len() * 2 / 3]).unwrap();
        let e = decode(&cut, timeout).unwrap_err().to_string();
        assert!(e.contains("b.jpg") && e.contains("truncated JPEG"), "{e}");
    }
}
