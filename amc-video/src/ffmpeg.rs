//! Decoding and encoding through ffmpeg child processes piping raw frames.
//!
//! Decoding: `ffmpeg -i IN -map 0:V -vf showinfo -fps_mode passthrough -f rawvideo
//! -pix_fmt rgb24 pipe:1`, or for [`PixelFormat::Yuv420p`] `-vf
//! showinfo,scale=out_range=tv ... -pix_fmt yuv420p`: ffmpeg does the
//! conversions (10-bit, 4:2:2, 4:4:4 to 8-bit limited-range 4:2:0). 8-bit
//! 4:2:0 video, the usual kind, goes without the scaler (`-vf showinfo`, the
//! decoder's own pixel format); a full-range one (phones, `yuvj420p`) is
//! brought to limited range here, as it is read, with
//! [`amc_core::color::yuv420p_full_to_limited_in_place`]: ffmpeg's scaler
//! took ~8% of a 720p run's CPU for it. Frames are read straight into the
//! caller's buffer.
//! Presentation timestamps come from the `showinfo` filter's log lines on
//! stderr, which ffmpeg writes before the frame itself reaches stdout, so each
//! frame gets its real timestamp (variable frame rate clips exist) without a
//! second pass over the file.
//!
//! Encoding: `ffmpeg -f matroska -i pipe:0 [-i AUDIO_SRC] ... -pix_fmt yuv420p TMP`,
//! renamed onto the output path once ffmpeg has succeeded. The pipe carries
//! raw frames with their timestamps (see `mkv`), as I420 when the spec's
//! [`OutputSpec::pixel_format`] is YUV 4:2:0 (nothing left for ffmpeg to
//! convert), else RGB24 (converted to yuv420p by ffmpeg); frames of the other
//! kind are converted here before they are piped.

use crate::atomic::AtomicFile;
use crate::caps::{caps, prefetch_caps};
use crate::error::VideoError;
use crate::frame::{check_frame, extension, no_frames, shape, FrameSink, FrameSource};
use crate::frame_pipe::FramePipe;
use crate::mkv::RawFormat;
use crate::probe::{probe, probe_device, probe_with, DataTrack, Probe};
use crate::process::Proc;
use crate::spec::{InputOptions, Inspection, OutputSpec, VideoInfo};
use amc_core::image::{Frame, FrameRef, PixelFormat};
use std::ffi::OsString;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, Receiver};
use std::time::Duration;

/// Frames up to this many pixels (1920x1088) are decoded on one ffmpeg
/// thread unless told otherwise. One thread decodes H.264 far faster than a
/// run consumes it (~290 frames/s at 720p on this project's VM, against
/// ~100 for the whole run), while frame threads cost ~40% more CPU for the
/// same frames (2.9 against 2.1 s for 600 720p frames): CPU the stabilizer,
/// on the same cores, needs. Larger frames keep ffmpeg's threads: one thread
/// would decode 4K at about the run's rate.
pub(crate) const ONE_DECODER_THREAD_PIXELS: usize = 1920 * 1088;

/// How long to wait for a frame's `showinfo` line once the frame has arrived.
/// The line is written before the frame, so this only matters if the ffmpeg
/// build prints something else, in which case we fall back to `i / fps`.
const PTS_LINE_WAIT: Duration = Duration::from_secs(2);

fn os_args(args: &[&str]) -> Vec<OsString> {
    args.iter().map(OsString::from).collect()
}

/// Frames decoded by an ffmpeg child.
pub(crate) struct FfmpegSource {
    proc: Proc,
    info: VideoInfo,
    /// `pts_time` of each decoded frame, from the stderr reader.
    pts_rx: Receiver<f64>,
    /// Whether timestamps come from `pts_rx` (false: `i / fps`).
    use_pts: bool,
    fps_override: Option<f64>,
    /// The format frames are decoded to (RGB8 or YUV 4:2:0).
    format: PixelFormat,
    /// Whether ffmpeg gives full-range 4:2:0 frames, brought to limited range
    /// as they are read.
    full_range: bool,
    /// Raw timestamp of the first frame (timestamps are relative to it).
    first_pts: Option<f64>,
    last_t: f64,
    index: u64,
    done: bool,
}

impl FfmpegSource {
    /// Probes `path` and starts decoding it.
    pub fn open(path: &Path, opts: &InputOptions) -> Result<Self, VideoError> {
        prefetch_caps();
        let probed = probe(path, opts.timeout)?;
        // ffmpeg happily decodes a PNG or JPEG (whatever its name) as a
        // one-frame video, which cannot be stabilized: say what it is.
        let found = Inspection {
            info: probed.info.clone(),
            format_name: probed.format_name.clone(),
        };
        if found.is_still_image() {
            return Err(VideoError::StillImage {
                path: path.to_path_buf(),
                format: found.format_name,
            });
        }
        Self::start(path, None, probed, opts)
    }

    /// Probes a live source (without counting its frames) and starts decoding it.
    pub fn open_stream(
        source: &str,
        format: Option<&str>,
        opts: &InputOptions,
    ) -> Result<Self, VideoError> {
        let path = Path::new(source);
        let probed = match format {
            // A device (`-f v4l2 /dev/video0`) is only known once opened with
            // its format; a plain probe would not know how to open it.
            Some(f) => probe_device(path, f, opts.timeout)?,
            None => probe_with(path, opts.timeout, false)?,
        };
        Self::start(path, format, probed, opts)
    }

    fn start(
        path: &Path,
        format: Option<&str>,
        probed: Probe,
        opts: &InputOptions,
    ) -> Result<Self, VideoError> {
        let Probe {
            mut info,
            video_index,
            native_420,
            ..
        } = probed;
        if let Some(fps) = opts.fps_override {
            info.fps = fps;
            info.duration_s = info.frame_count.map(|n| n as f64 / fps);
        }
        let caps = caps();
        let showinfo = if caps.showinfo_checksum {
            "showinfo=checksum=0"
        } else {
            "showinfo"
        };
        let native = native_420.filter(|_| opts.pixel_format == PixelFormat::Yuv420p);
        let (filters, pix_fmt) = match (opts.pixel_format, native) {
            // 8-bit 4:2:0 frames go out as decoded (full range is brought to
            // limited range as they are read). Told an output range, the
            // scaler copies every frame (a tenth of ffmpeg's time at 720p)
            // even when there is nothing to convert.
            (PixelFormat::Yuv420p, Some(n)) => (showinfo.to_string(), n.pix_fmt),
            // Other layouts (10-bit, 4:2:2, 4:4:4) through the scaler, told
            // the range: without it a source tagged full range would keep it.
            (PixelFormat::Yuv420p, None) => (format!("{showinfo},scale=out_range=tv"), "yuv420p"),
            _ => (showinfo.to_string(), "rgb24"),
        };
        let mut args = os_args(&[
            "-hide_banner",
            "-nostdin",
            "-nostats",
            // `level+` tags each line so showinfo's info lines can be told
            // from errors.
            "-loglevel",
            "level+info",
        ]);
        if opts.realtime {
            args.push("-re".into());
        }
        if opts.looped {
            args.extend(os_args(&["-stream_loop", "-1"]));
        }
        if let Some(n) = opts.ffmpeg_threads {
            let n = n.to_string();
            args.extend(os_args(&["-filter_threads", &n, "-threads", &n]));
        } else if info.width * info.height <= ONE_DECODER_THREAD_PIXELS {
            args.extend(os_args(&["-threads", "1"]));
        }
        if let Some(f) = format {
            args.extend(os_args(&["-f", f]));
        }
        args.push("-i".into());
        args.push(path.as_os_str().to_owned());
        args.extend(os_args(&[
            // Only the video stream: files can carry audio and data streams
            // (GoPro telemetry) that rawvideo output cannot take.
            "-map",
            &format!("0:{video_index}"),
            "-vf",
            &filters,
            // One output frame per decoded frame: no duplicates or drops to
            // force a constant rate.
            if caps.fps_mode { "-fps_mode" } else { "-vsync" },
            "passthrough",
            "-f",
            "rawvideo",
            "-pix_fmt",
            pix_fmt,
            "pipe:1",
        ]));
        let (tx, pts_rx) = channel();
        let proc = Proc::spawn("ffmpeg", &args, path, opts.timeout, false, Some(tx))?;
        Ok(Self {
            proc,
            info,
            pts_rx,
            use_pts: opts.fps_override.is_none(),
            fps_override: opts.fps_override,
            format: match opts.pixel_format {
                PixelFormat::Yuv420p => PixelFormat::Yuv420p,
                _ => PixelFormat::Rgb8,
            },
            full_range: native.is_some_and(|n| n.full_range),
            first_pts: None,
            last_t: 0.0,
            index: 0,
            done: false,
        })
    }

    /// The timestamp of the frame just read, relative to the first.
    fn timestamp(&mut self) -> f64 {
        let step = 1.0 / self.info.fps;
        if let Some(fps) = self.fps_override {
            return self.index as f64 / fps;
        }
        let mut raw = f64::NAN;
        if self.use_pts {
            match self.pts_rx.recv_timeout(PTS_LINE_WAIT) {
                Ok(t) => raw = t,
                // No line: this ffmpeg logs differently; stop waiting for them.
                Err(_) => self.use_pts = false,
            }
        }
        if self.index == 0 {
            self.first_pts = raw.is_finite().then_some(raw);
            return 0.0;
        }
        let t = match self.first_pts {
            Some(first) if raw.is_finite() => raw - first,
            _ => self.last_t + step,
        };
        // Timestamps must increase for the stabilizer's smoothing; a broken
        // or duplicated stamp becomes one nominal frame after the previous.
        if t > self.last_t {
            t
        } else {
            self.last_t + step
        }
    }

    /// Ends the stream: reaps ffmpeg and reports how it went.
    fn end(&mut self) -> Result<Option<f64>, VideoError> {
        self.done = true;
        let status = self.proc.wait()?;
        if self.proc.timed_out() {
            return Err(self.proc.timeout_error());
        }
        if self.index == 0 {
            // Failing before the first frame means the file is not something
            // ffmpeg can decode, even though ffprobe recognised it.
            return Err(VideoError::NotAVideo {
                path: self.proc.path.clone(),
                detail: self.proc.error_detail(if status.success() {
                    "it decodes to no frames"
                } else {
                    "ffmpeg decoded no frames"
                }),
            });
        }
        if !status.success() {
            return Err(self.proc.failure(Some(status)));
        }
        Ok(None)
    }
}

impl FrameSource for FfmpegSource {
    fn info(&self) -> &VideoInfo {
        &self.info
    }

    fn next_frame(&mut self, buf: &mut Frame) -> Result<Option<f64>, VideoError> {
        if self.done {
            return Ok(None);
        }
        shape(buf, self.info.width, self.info.height, self.format);
        self.proc.arm();
        let read = match self.proc.stdout.as_mut() {
            Some(stdout) => read_full(stdout, &mut buf.data),
            None => Ok(0),
        };
        self.proc.disarm();
        let n = match read {
            Ok(n) => n,
            Err(e) => {
                self.done = true;
                self.proc.kill();
                if self.proc.timed_out() {
                    return Err(self.proc.timeout_error());
                }
                return Err(VideoError::io(&self.proc.path, "read decoded frames", e));
            }
        };
        if n == 0 {
            return self.end();
        }
        if n < buf.data.len() {
            // Only a dying ffmpeg stops mid-frame.
            self.done = true;
            let status = self.proc.wait().ok();
            if status.is_some_and(|s| s.success()) && !self.proc.timed_out() {
                return Err(VideoError::Ffmpeg {
                    path: self.proc.path.clone(),
                    tool: "ffmpeg",
                    detail: format!(
                        "decoded frame {} is {n} bytes instead of {}",
                        self.index,
                        buf.data.len()
                    ),
                });
            }
            return Err(self.proc.failure(status));
        }
        if self.full_range {
            amc_core::color::yuv420p_full_to_limited_in_place(
                self.info.width,
                self.info.height,
                &mut buf.data,
            );
        }
        let t = self.timestamp();
        self.last_t = t;
        self.index += 1;
        Ok(Some(t))
    }
}

/// Reads until `buf` is full or the stream ends; returns the bytes read.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match r.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

/// The video containers ffmpeg writes for us.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Container {
    /// H.264 + (copied or AAC) audio.
    Mp4,
    /// H.264 + copied audio.
    Mkv,
    /// VP9 + Opus audio.
    Webm,
}

impl Container {
    /// The container for a lower-case extension.
    pub fn from_extension(ext: &str) -> Option<Self> {
        match ext {
            "mp4" => Some(Container::Mp4),
            "mkv" => Some(Container::Mkv),
            "webm" => Some(Container::Webm),
            _ => None,
        }
    }

    fn muxer(self) -> &'static str {
        match self {
            Container::Mp4 => "mp4",
            Container::Mkv => "matroska",
            Container::Webm => "webm",
        }
    }

    fn suffix(self) -> &'static str {
        match self {
            Container::Mp4 => ".mp4",
            Container::Mkv => ".mkv",
            Container::Webm => ".webm",
        }
    }

    /// The highest CRF its encoder takes (x264: 51, VP9: 63; both start at 0).
    pub fn max_crf(self) -> u8 {
        match self {
            Container::Mp4 | Container::Mkv => 51,
            Container::Webm => 63,
        }
    }

    /// The encoder's name, for messages.
    fn encoder(self) -> &'static str {
        match self {
            Container::Mp4 | Container::Mkv => "x264",
            Container::Webm => "VP9",
        }
    }

    /// Checks a requested CRF against the encoder's range.
    fn check_crf(self, path: &Path, crf: Option<u8>) -> Result<(), VideoError> {
        match crf {
            Some(crf) if crf > self.max_crf() => Err(VideoError::BadFrame {
                path: path.to_path_buf(),
                detail: format!(
                    "quality (CRF) {crf} is out of range for {}: {} takes 0..={}",
                    self.suffix(),
                    self.encoder(),
                    self.max_crf()
                ),
            }),
            _ => Ok(()),
        }
    }

    /// Video codec arguments for quality `crf` (codec default when `None`;
    /// checked against [`Container::max_crf`] beforehand).
    fn video_args(self, crf: Option<u8>, preset: Option<crate::X264Preset>) -> Vec<String> {
        let v = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        match self {
            Container::Mp4 | Container::Mkv => {
                let preset = preset.unwrap_or(crate::X264Preset::FILES);
                let mut a = v(&["-c:v", "libx264", "-preset", preset.as_str(), "-crf"]);
                a.push(crf.unwrap_or(20).to_string());
                a
            }
            Container::Webm => {
                // Realtime VP9 at the fastest setting: libvpx is otherwise
                // far slower than the stabilizer.
                let mut a = v(&[
                    "-c:v",
                    "libvpx-vp9",
                    "-deadline",
                    "realtime",
                    "-cpu-used",
                    "8",
                    "-row-mt",
                    "1",
                    "-b:v",
                    "0",
                    "-crf",
                ]);
                a.push(crf.unwrap_or(32).to_string());
                a
            }
        }
    }

    /// Audio arguments for an input audio codec: copy when the container can
    /// hold it, else re-encode.
    fn audio_args(self, codec: &str) -> &'static [&'static str] {
        const COPY: &[&str] = &["-c:a", "copy"];
        match self {
            Container::Mkv => COPY,
            Container::Mp4 => match codec {
                "aac" | "mp3" | "alac" | "ac3" | "eac3" | "opus" | "flac" => COPY,
                _ => &["-c:a", "aac", "-b:a", "192k"],
            },
            Container::Webm => match codec {
                "opus" | "vorbis" => COPY,
                _ => &["-c:a", "libopus", "-b:a", "128k"],
            },
        }
    }
}

/// Frames encoded by an ffmpeg child into a temporary sibling of the output.
pub(crate) struct FfmpegSink {
    // Field order matters: `proc` drops (killing ffmpeg) before `temp`
    // deletes the partial file.
    proc: Proc,
    temp: AtomicFile,
    path: PathBuf,
    /// The frames' way into ffmpeg, its pixel layout fixed by the spec.
    pipe: FramePipe,
    frames: u64,
    failed: bool,
}

impl FfmpegSink {
    /// Starts an encoder writing `container` for frames of `spec`.
    pub fn create(
        path: &Path,
        spec: &OutputSpec,
        container: Container,
    ) -> Result<Self, VideoError> {
        container.check_crf(path, spec.crf)?;
        let Carried {
            audio_codec,
            data_tracks,
            timecode,
        } = match &spec.audio_from {
            Some(src) => streams_to_carry(src, container, spec.timeout)?,
            None => Carried::default(),
        };
        let temp = AtomicFile::create(path, container.suffix())?;

        // Frames arrive as Matroska (see `mkv`): each keeps its own timestamp.
        let args: Vec<String> = [
            "-hide_banner",
            "-nostdin",
            "-nostats",
            "-loglevel",
            "level+error",
            "-y",
            "-f",
            "matroska",
            "-i",
            "pipe:0",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let mut os: Vec<OsString> = args.into_iter().map(OsString::from).collect();
        let mut more: Vec<String> = Vec::new();
        more.extend(["-map", "0:v:0"].map(String::from));
        match &spec.audio_from {
            Some(src) if audio_codec.is_some() || !data_tracks.is_empty() => {
                os.push("-i".into());
                os.push(src.as_os_str().to_owned());
                if audio_codec.is_some() {
                    more.extend(["-map", "1:a?"].map(String::from));
                }
                for t in &data_tracks {
                    more.extend(["-map".into(), format!("1:{}", t.index)]);
                }
            }
            _ => {}
        }
        let pipe = FramePipe::new(spec.width, spec.height, spec.pixel_format);
        if pipe.odd() && pipe.raw == RawFormat::Rgb24 {
            // yuv420p needs even sizes: add one black row/column rather than fail.
            // (I420 frames are padded before piping: see `frame_pipe`.)
            more.extend(["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"].map(String::from));
        }
        more.extend(container.video_args(spec.crf, spec.preset));
        if let Some(n) = spec.ffmpeg_threads {
            more.extend(["-threads".into(), n.to_string()]);
            more.extend(["-filter_threads".into(), n.to_string()]);
        }
        // Timestamps pass through unchanged (no frame dropped or duplicated to
        // a constant rate), on a 90 kHz clock: exact for 24/25/30/50/60 and the
        // NTSC /1001 rates.
        more.extend(
            [
                "-pix_fmt",
                "yuv420p",
                "-fps_mode",
                "passthrough",
                "-enc_time_base:v",
                "1:90000",
            ]
            .map(String::from),
        );
        if let Some(codec) = &audio_codec {
            more.extend(container.audio_args(codec).iter().map(|s| s.to_string()));
        }
        if !data_tracks.is_empty() {
            // Copied as they are, under their own tag (`gpmd`), so that
            // telemetry readers (Gyroflow, GPS tools) find them.
            more.extend(["-c:d", "copy"].map(String::from));
            for (i, t) in data_tracks.iter().enumerate() {
                more.extend([format!("-tag:d:{i}"), t.tag.clone()]);
            }
        }
        if let Some(tc) = &timecode {
            // The MP4 muxer writes its own timecode track (`tmcd`) from it.
            more.extend(["-timecode".into(), tc.clone()]);
        }
        if container == Container::Mp4 {
            more.extend(["-video_track_timescale", "90000"].map(String::from));
            // Index at the front so players can start before downloading all.
            more.extend(["-movflags", "+faststart"].map(String::from));
        }
        more.extend(["-f", container.muxer()].map(String::from));
        os.extend(more.into_iter().map(OsString::from));
        os.push(temp.partial_path().as_os_str().to_owned());

        let mut proc = Proc::spawn("ffmpeg", &os, path, spec.timeout, true, None)?;
        // ffmpeg names the file it writes in its errors: that is the hidden
        // temporary sibling, which means nothing to the user.
        proc.alias(temp.partial_path(), path);
        let header = pipe.header();
        if let Some(stdin) = proc.stdin.as_mut() {
            // A failure shows on the first frame, with ffmpeg's own message.
            let _ = stdin.write_all(&header);
        }
        Ok(Self {
            proc,
            temp,
            path: path.to_path_buf(),
            pipe,
            frames: 0,
            failed: false,
        })
    }

    /// The error after ffmpeg stopped taking frames.
    fn died(&mut self) -> VideoError {
        self.failed = true;
        self.proc.input_refused()
    }
}

/// What of the input goes into the output besides the picture.
#[derive(Default)]
struct Carried {
    /// The codec of its audio, when it is a file with audio.
    audio_codec: Option<String>,
    /// The data tracks the container can carry.
    data_tracks: Vec<DataTrack>,
    /// Its start timecode, for the container's own timecode track.
    timecode: Option<String>,
}

/// What of the input `src` goes into the output besides the picture: its
/// audio, and in MP4 its telemetry (GoPro's `gpmd`, which Gyroflow and GPS
/// tools read) and its start timecode. Other data tracks (GoPro's `fdsc`,
/// with no codec ffmpeg knows) and any data track in WebM or Matroska are
/// left out: `docs/cli.md` says so.
fn streams_to_carry(
    src: &Path,
    container: Container,
    timeout: Duration,
) -> Result<Carried, VideoError> {
    if src.is_dir() || extension(src).as_deref() == Some("y4m") {
        return Ok(Carried::default());
    }
    let probed = probe(src, timeout)?;
    if container != Container::Mp4 {
        return Ok(Carried {
            audio_codec: probed.audio_codec,
            ..Carried::default()
        });
    }
    Ok(Carried {
        audio_codec: probed.audio_codec,
        data_tracks: probed
            .data_tracks
            .into_iter()
            .filter(DataTrack::copies_into_mp4)
            .collect(),
        timecode: probed.timecode,
    })
}

impl FrameSink for FfmpegSink {
    fn write_frame(&mut self, frame: &FrameRef<'_>, t: f64) -> Result<(), VideoError> {
        check_frame(&self.path, self.pipe.width, self.pipe.height, frame)?;
        if self.failed {
            return Err(self.proc.failure(None));
        }
        self.proc.arm();
        let written = match self.proc.stdin.as_mut() {
            Some(stdin) => self.pipe.write(stdin, frame, t),
            None => Err(std::io::ErrorKind::BrokenPipe.into()),
        };
        self.proc.disarm();
        match written {
            Ok(()) => {
                self.frames += 1;
                Ok(())
            }
            // A broken pipe means ffmpeg exited: its stderr says why.
            Err(_) => Err(self.died()),
        }
    }

    fn finish(self: Box<Self>) -> Result<(), VideoError> {
        let mut this = *self;
        if this.frames == 0 {
            return Err(no_frames(&this.path));
        }
        if this.failed {
            return Err(this.proc.failure(None));
        }
        let status = this.proc.wait()?;
        if !status.success() {
            return Err(this.proc.failure(Some(status)));
        }
        let FfmpegSink { proc, temp, .. } = this;
        drop(proc);
        temp.persist()
    }
}
