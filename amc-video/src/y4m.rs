//! YUV4MPEG2 (`.y4m`) reading and writing, done here rather than through
//! ffmpeg: the format is trivial and this keeps uncompressed workflows free of
//! child processes.
//!
//! A file is a header line `YUV4MPEG2 W640 H480 F30000:1001 Ip A1:1 C420jpeg`
//! followed by frames, each a `FRAME` line and the raw planes (Y, then Cb, Cr).
//!
//! Reading as [`PixelFormat::Yuv420p`]: 8-bit limited-range 4:2:0 planes are
//! read straight into the frame, unconverted. Other files are converted here:
//! full range (`XCOLORRANGE=FULL`) is scaled to limited range, 4:2:2 and 4:4:4
//! chroma is averaged down to 4:2:0, mono gets grey chroma. Reading as RGB
//! uses BT.601 matrices, as ffmpeg does by default (limited range unless the
//! header says full): `amc_core::color` for 4:2:0, a local conversion for the
//! other layouts.
//!
//! Writing: YUV 4:2:0 frames are written as they are; RGB frames are
//! converted with `amc_core::color::rgb_to_yuv420p_into`.

use crate::atomic::AtomicFile;
use crate::error::VideoError;
use crate::frame::{
    as_yuv420p, check_frame, fps_rational, no_frames, shape, FrameSink, FrameSource,
};
use crate::spec::{InputOptions, OutputSpec, VideoInfo, DEFAULT_IMAGE_FPS};
use amc_core::color::yuv420p_to_rgb_into;
use amc_core::image::{yuv_planes_mut, Frame, FrameRef, PixelFormat};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// Largest frame side (pixels), the stabilizer's limit.
const MAX_SIDE: usize = 16384;

/// Highest frame rate a header may declare (frames per second), the limit of `--fps`.
const MAX_FPS: f64 = 10_000.0;

/// Longest header or `FRAME` line accepted (real ones are well under 100 bytes).
const MAX_LINE: u64 = 4096;

/// Chroma subsampling of a Y4M file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Chroma {
    /// Half width, half height (`C420jpeg`, `C420paldv`, `C420mpeg2`, `C420`).
    C420,
    /// Half width, full height.
    C422,
    /// Full resolution.
    C444,
    /// Luma only.
    Mono,
}

/// Plane geometry of one frame.
#[derive(Clone, Copy, Debug)]
struct Layout {
    width: usize,
    height: usize,
    chroma: Chroma,
    full_range: bool,
}

impl Layout {
    /// (width, height) of each chroma plane, or `None` for mono.
    fn chroma_size(&self) -> Option<(usize, usize)> {
        let (w, h) = (self.width, self.height);
        match self.chroma {
            Chroma::C420 => Some((w.div_ceil(2), h.div_ceil(2))),
            Chroma::C422 => Some((w.div_ceil(2), h)),
            Chroma::C444 => Some((w, h)),
            Chroma::Mono => None,
        }
    }

    fn frame_bytes(&self) -> usize {
        self.width * self.height + self.chroma_size().map_or(0, |(cw, ch)| 2 * cw * ch)
    }

    /// Whether the planes are laid out as [`PixelFormat::Yuv420p`] says, so
    /// that they can be used without conversion.
    fn is_yuv420p(&self) -> bool {
        self.chroma == Chroma::C420 && !self.full_range
    }
}

/// Frames read from a `.y4m` file.
pub(crate) struct Y4mSource {
    path: PathBuf,
    reader: BufReader<File>,
    layout: Layout,
    info: VideoInfo,
    /// The format frames are handed out in (RGB8 or YUV 4:2:0).
    format: PixelFormat,
    /// Raw planes of the current frame when they need converting (reused;
    /// empty while frames are read straight into the caller's buffer).
    planes: Vec<u8>,
    line: Vec<u8>,
    index: u64,
}

impl Y4mSource {
    /// Opens `path` and parses its header.
    pub fn open(path: &Path, opts: &InputOptions) -> Result<Self, VideoError> {
        let file = File::open(path).map_err(|e| VideoError::io(path, "open", e))?;
        let file_len = file.metadata().map(|m| m.len()).ok();
        let mut reader = BufReader::with_capacity(1 << 20, file);
        let mut line = Vec::new();
        let n = read_line(&mut reader, &mut line).map_err(|e| VideoError::io(path, "read", e))?;
        let bad = |detail: String| VideoError::Y4m {
            path: path.to_path_buf(),
            detail,
        };
        let header = match n {
            LineRead::Line => String::from_utf8_lossy(&line).into_owned(),
            LineRead::Eof => return Err(bad("the file is empty".into())),
            LineRead::TooLong => return Err(bad("no YUV4MPEG2 header line".into())),
        };
        let (layout, file_fps) = parse_header(&header).map_err(bad)?;
        let fps = opts.fps_override.or(file_fps).unwrap_or(DEFAULT_IMAGE_FPS);
        // With plain `FRAME` lines (the usual case) the count follows from the size.
        let per_frame = 6 + layout.frame_bytes() as u64;
        // A frame buffer is only allocated for a file that can hold one, so a
        // corrupt header cannot make a small file allocate gigabytes.
        let body = file_len.map(|len| len.saturating_sub(header.len() as u64 + 1));
        if let Some(body) = body.filter(|&b| b > 0 && b < per_frame) {
            return Err(bad(format!(
                "the file is shorter than one frame: {body} bytes after the header, and one \
                 {}x{} frame takes {per_frame}",
                layout.width, layout.height
            )));
        }
        let frame_count = file_len
            .map(|len| len.saturating_sub(header.len() as u64 + 1))
            .filter(|body| body % per_frame == 0)
            .map(|body| body / per_frame);
        Ok(Self {
            path: path.to_path_buf(),
            reader,
            layout,
            info: VideoInfo {
                width: layout.width,
                height: layout.height,
                fps,
                frame_count,
                duration_s: frame_count.map(|n| n as f64 / fps),
                has_audio: false,
                fps_assumed: false,
            },
            format: opts.pixel_format,
            planes: Vec::new(),
            line,
            index: 0,
        })
    }

    /// Turns the outcome of reading a frame's planes into ours.
    fn check_read(&self, read: std::io::Result<()>) -> Result<(), VideoError> {
        read.map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                self.bad(format!(
                    "frame {} is truncated (the file ends inside it)",
                    self.index
                ))
            } else {
                VideoError::io(&self.path, "read", e)
            }
        })
    }

    fn bad(&self, detail: String) -> VideoError {
        VideoError::Y4m {
            path: self.path.clone(),
            detail,
        }
    }
}

impl FrameSource for Y4mSource {
    fn info(&self) -> &VideoInfo {
        &self.info
    }

    fn next_frame(&mut self, buf: &mut Frame) -> Result<Option<f64>, VideoError> {
        let read = read_line(&mut self.reader, &mut self.line)
            .map_err(|e| VideoError::io(&self.path, "read", e))?;
        match read {
            LineRead::Eof => return Ok(None),
            LineRead::TooLong => {
                return Err(self.bad(format!("frame {} has no FRAME line", self.index)))
            }
            LineRead::Line if self.line.starts_with(b"FRAME") => {}
            LineRead::Line => {
                return Err(self.bad(format!(
                    "frame {} starts with {:?} instead of FRAME",
                    self.index,
                    String::from_utf8_lossy(&self.line[..self.line.len().min(20)])
                )))
            }
        }
        let (w, h) = (self.layout.width, self.layout.height);
        if self.format == PixelFormat::Yuv420p && self.layout.is_yuv420p() {
            // Already the frame's layout: read the planes straight into it.
            shape(buf, w, h, PixelFormat::Yuv420p);
            let read = self.reader.read_exact(&mut buf.data);
            self.check_read(read)?;
        } else {
            self.planes.resize(self.layout.frame_bytes(), 0);
            let read = self.reader.read_exact(&mut self.planes);
            self.check_read(read)?;
            match self.format {
                PixelFormat::Yuv420p => {
                    shape(buf, w, h, PixelFormat::Yuv420p);
                    to_yuv420p(&self.layout, &self.planes, &mut buf.data);
                }
                _ => {
                    shape(buf, w, h, PixelFormat::Rgb8);
                    to_rgb(&self.layout, &self.planes, &mut buf.data);
                }
            }
        }
        let t = self.index as f64 / self.info.fps;
        self.index += 1;
        Ok(Some(t))
    }
}

enum LineRead {
    Line,
    Eof,
    TooLong,
}

/// Reads one `\n`-terminated line (without the `\n`) of at most [`MAX_LINE`] bytes.
fn read_line(r: &mut impl BufRead, line: &mut Vec<u8>) -> std::io::Result<LineRead> {
    line.clear();
    let n = r.take(MAX_LINE).read_until(b'\n', line)?;
    if n == 0 {
        return Ok(LineRead::Eof);
    }
    if line.last() != Some(&b'\n') {
        return Ok(LineRead::TooLong);
    }
    line.pop();
    Ok(LineRead::Line)
}

/// Parses a header line into the frame layout and the frame rate (if given).
fn parse_header(header: &str) -> Result<(Layout, Option<f64>), String> {
    let mut tokens = header.split_ascii_whitespace();
    if tokens.next() != Some("YUV4MPEG2") {
        return Err("it does not start with \"YUV4MPEG2\"".into());
    }
    let (mut width, mut height, mut fps) = (None, None, None);
    let mut chroma = Chroma::C420;
    let mut full_range = false;
    for tok in tokens {
        // The key is the token's first character, which need not be ASCII
        // in a corrupt header (so no byte-index split).
        let mut chars = tok.chars();
        let key = chars.next().unwrap_or(' ');
        let val = chars.as_str();
        match key {
            'W' => width = val.parse::<usize>().ok().filter(|&w| w > 0),
            'H' => height = val.parse::<usize>().ok().filter(|&h| h > 0),
            'F' => {
                let rate = val
                    .split_once(':')
                    .and_then(|(n, d)| Some(n.parse::<f64>().ok()? / d.parse::<f64>().ok()?))
                    .filter(|r| r.is_finite() && *r > 0.0 && *r <= MAX_FPS);
                fps = Some(rate.ok_or_else(|| {
                    format!("bad frame rate \"{tok}\" (allowed: N:D above 0 and at most {MAX_FPS} frames per second)")
                }))
            }
            'C' => {
                chroma = match val {
                    "420jpeg" | "420paldv" | "420mpeg2" | "420" => Chroma::C420,
                    "422" => Chroma::C422,
                    "444" => Chroma::C444,
                    "mono" => Chroma::Mono,
                    _ => {
                        return Err(format!(
                    "colour space \"{val}\" is not supported (only 8-bit 420, 422, 444 and mono)"
                ))
                    }
                }
            }
            'X' if val == "COLORRANGE=FULL" => full_range = true,
            // Interlacing, aspect ratio and other extensions do not change the data.
            _ => {}
        }
    }
    let (Some(width), Some(height)) = (width, height) else {
        return Err("the header lacks a valid width (W) or height (H)".into());
    };
    // Guard the allocation against absurd sizes in corrupt headers.
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err(format!(
            "frame size {width}x{height} is too large (allowed: at most {MAX_SIDE} pixels a side)"
        ));
    }
    let fps = fps.transpose()?;
    Ok((
        Layout {
            width,
            height,
            chroma,
            full_range,
        },
        fps,
    ))
}

/// Converts a frame's planes to packed RGB: 4:2:0 with the core's
/// conversion, the other layouts with [`yuv_to_rgb`].
fn to_rgb(layout: &Layout, planes: &[u8], rgb: &mut Vec<u8>) {
    let (w, h) = (layout.width, layout.height);
    if layout.chroma == Chroma::C420 {
        yuv420p_to_rgb_into(w, h, planes, layout.full_range, 3, rgb);
    } else {
        rgb.resize(w * h * 3, 0);
        yuv_to_rgb(layout, planes, rgb);
    }
}

/// Converts planar 4:2:2, 4:4:4 or mono YUV to packed RGB (chroma upsampled
/// by nearest neighbour), for the layouts the core's 4:2:0 conversion does
/// not take.
fn yuv_to_rgb(layout: &Layout, planes: &[u8], rgb: &mut [u8]) {
    let (w, h) = (layout.width, layout.height);
    let (luma, chroma) = planes.split_at(w * h);
    // Fixed-point (16.16) BT.601 coefficients.
    let (ky, off, kr, kgu, kgv, kb) = if layout.full_range {
        (65536, 0, 91881, 22554, 46802, 116130)
    } else {
        (76309, 16, 104597, 25675, 53279, 132201)
    };
    let sub = layout.chroma_size();
    let (sx, sy) = match layout.chroma {
        Chroma::C420 => (1, 1),
        Chroma::C422 => (1, 0),
        _ => (0, 0),
    };
    for y in 0..h {
        let yrow = &luma[y * w..(y + 1) * w];
        let out = &mut rgb[y * w * 3..(y + 1) * w * 3];
        match sub {
            None => {
                for (px, &l) in out.chunks_exact_mut(3).zip(yrow) {
                    let c = ((l as i32 - off) * ky + 32768) >> 16;
                    px.fill(c.clamp(0, 255) as u8);
                }
            }
            Some((cw, ch)) => {
                let (cb, cr) = chroma.split_at(cw * ch);
                let crow = (y >> sy) * cw;
                for (x, (px, &l)) in out.chunks_exact_mut(3).zip(yrow).enumerate() {
                    let c = (l as i32 - off) * ky + 32768;
                    let d = cb[crow + (x >> sx)] as i32 - 128;
                    let e = cr[crow + (x >> sx)] as i32 - 128;
                    px[0] = ((c + kr * e) >> 16).clamp(0, 255) as u8;
                    px[1] = ((c - kgu * d - kgv * e) >> 16).clamp(0, 255) as u8;
                    px[2] = ((c + kb * d) >> 16).clamp(0, 255) as u8;
                }
            }
        }
    }
}

/// Converts a frame's planes to limited-range 4:2:0 (`out` already has the
/// [`PixelFormat::Yuv420p`] length): chroma subsampled, then the range scaled.
fn to_yuv420p(layout: &Layout, planes: &[u8], out: &mut [u8]) {
    let (w, h) = (layout.width, layout.height);
    let (y_out, u_out, v_out) = yuv_planes_mut(w, h, out);
    let (luma, chroma) = planes.split_at(w * h);
    y_out.copy_from_slice(luma);
    match layout.chroma_size() {
        // No colour: grey.
        None => {
            u_out.fill(128);
            v_out.fill(128);
        }
        Some((cw, ch)) => {
            let (cb, cr) = chroma.split_at(cw * ch);
            subsample_420(cb, cw, ch, w, h, u_out);
            subsample_420(cr, cw, ch, w, h, v_out);
        }
    }
    if layout.full_range {
        let (y_lut, c_lut) = (range_lut(0.0, 16.0, 219.0), range_lut(128.0, 128.0, 224.0));
        y_out.iter_mut().for_each(|v| *v = y_lut[*v as usize]);
        u_out.iter_mut().for_each(|v| *v = c_lut[*v as usize]);
        v_out.iter_mut().for_each(|v| *v = c_lut[*v as usize]);
    }
}

/// Reduces a chroma plane of `cw x ch` samples (for a `width x height` frame:
/// 4:2:0, 4:2:2 or 4:4:4) to the 4:2:0 plane `out`, each sample the rounded
/// mean of the samples covering its 2x2 block of pixels.
fn subsample_420(plane: &[u8], cw: usize, ch: usize, width: usize, height: usize, out: &mut [u8]) {
    let (ow, oh) = amc_core::image::chroma_size(width, height);
    // Source samples per output sample: 2 where the plane has full resolution.
    let fx = if cw == ow { 1 } else { 2 };
    let fy = if ch == oh { 1 } else { 2 };
    for oy in 0..oh {
        for ox in 0..ow {
            let (mut sum, mut n) = (0u32, 0u32);
            for y in fy * oy..(fy * oy + fy).min(ch) {
                for x in fx * ox..(fx * ox + fx).min(cw) {
                    sum += plane[y * cw + x] as u32;
                    n += 1;
                }
            }
            out[oy * ow + ox] = ((sum + n / 2) / n) as u8;
        }
    }
}

/// A table mapping full-range samples (0..=255) to limited range:
/// `to + (v - from) * span / 255`, rounded (luma: from 0 to 16, span 219;
/// chroma: from 128 to 128, span 224).
fn range_lut(from: f64, to: f64, span: f64) -> [u8; 256] {
    std::array::from_fn(|v| (to + (v as f64 - from) * span / 255.0).round() as u8)
}

/// Frames written to a `.y4m` file (limited-range 4:2:0, `C420jpeg`).
pub(crate) struct Y4mSink {
    path: PathBuf,
    /// Deleted on drop unless persisted by `finish`.
    out: BufWriter<AtomicFile>,
    width: usize,
    height: usize,
    planes: Vec<u8>,
    frames: u64,
}

impl Y4mSink {
    /// Creates the temporary file and writes the header.
    pub fn create(path: &Path, spec: &OutputSpec) -> Result<Self, VideoError> {
        let mut temp = AtomicFile::create(path, ".y4m")?;
        temp.write_direct();
        let mut out = BufWriter::with_capacity(1 << 20, temp);
        let (num, den) = fps_rational(spec.fps);
        writeln!(
            out,
            "YUV4MPEG2 W{} H{} F{num}:{den} Ip A1:1 C420jpeg",
            spec.width, spec.height
        )
        .map_err(|e| VideoError::io(path, "write", e))?;
        Ok(Self {
            path: path.to_path_buf(),
            out,
            width: spec.width,
            height: spec.height,
            planes: Vec::new(),
            frames: 0,
        })
    }
}

impl FrameSink for Y4mSink {
    fn write_frame(&mut self, frame: &FrameRef<'_>, _t: f64) -> Result<(), VideoError> {
        check_frame(&self.path, self.width, self.height, frame)?;
        let planes = as_yuv420p(frame, &mut self.planes);
        self.out
            .write_all(b"FRAME\n")
            .and_then(|()| self.out.write_all(planes))
            .map_err(|e| VideoError::io(&self.path, "write", e))?;
        self.frames += 1;
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<(), VideoError> {
        if self.frames == 0 {
            return Err(no_frames(&self.path));
        }
        let path = self.path;
        let temp = self
            .out
            .into_inner()
            .map_err(|e| VideoError::io(&path, "write", e.into_error()))?;
        temp.persist()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_headers() {
        let (l, fps) =
            parse_header("YUV4MPEG2 W64 H48 F30000:1001 Ip A1:1 C420mpeg2 XYSCSS=420MPEG2")
                .unwrap();
        assert_eq!((l.width, l.height, l.chroma), (64, 48, Chroma::C420));
        assert!((fps.unwrap() - 29.97).abs() < 0.01);
        let (l, fps) = parse_header("YUV4MPEG2 W3 H3 Cmono").unwrap();
        assert_eq!((l.chroma, fps, l.frame_bytes()), (Chroma::Mono, None, 9));
        let (l, _) = parse_header("YUV4MPEG2 W5 H3 F25:1 C420").unwrap();
        assert_eq!(l.frame_bytes(), 15 + 2 * 3 * 2);
        for bad in [
            "YUV4MPEG W64 H48",
            "YUV4MPEG2 H48",
            "YUV4MPEG2 W64 H48 C420p10",
            "YUV4MPEG2 W64 H48 F0:0",
            "YUV4MPEG2 W99999999 H99999999",
        ] {
            assert!(parse_header(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn non_420_colour_matches_the_core_conversion() {
        // A flat colour as 4:4:4 converts like the same colour as 4:2:0.
        let (w, h) = (4, 2);
        let planes444: Vec<u8> = [[90u8; 8], [60; 8], [200; 8]].concat();
        let layout = |chroma| Layout {
            width: w,
            height: h,
            chroma,
            full_range: false,
        };
        let mut ours = Vec::new();
        to_rgb(&layout(Chroma::C444), &planes444, &mut ours);
        let mut planes420 = vec![0; 12];
        to_yuv420p(&layout(Chroma::C444), &planes444, &mut planes420);
        assert_eq!(
            planes420,
            [[90u8; 8].as_slice(), &[60; 2], &[200; 2]].concat()
        );
        let mut core = Vec::new();
        to_rgb(&layout(Chroma::C420), &planes420, &mut core);
        assert_eq!(ours, core);
    }

    #[test]
    fn full_range_maps_to_limited() {
        let y = range_lut(0.0, 16.0, 219.0);
        let c = range_lut(128.0, 128.0, 224.0);
        assert_eq!((y[0], y[128], y[255]), (16, 126, 235));
        assert_eq!((c[0], c[128], c[255]), (16, 128, 240));
    }
}
