//! A live H.264 encoder: frames in with their timestamps, access units out
//! (Annex-B, see [`crate::flv`]) as soon as each is encoded. ffmpeg's
//! libx264 runs as a child, as every encoder of the project does: frames go
//! to its stdin as Matroska (each with its own timestamp, see `mkv`), the
//! stream comes back on its stdout as FLV, one tag per picture.
//!
//! Tuned for latency: no B-frames, no lookahead (`-tune zerolatency`), a
//! keyframe every `keyframe_interval_s` of the frames' own time, constant
//! quality (CRF 21) under a rate cap over half a second so the stream fits its
//! link.

use crate::error::VideoError;
use crate::flv::{AccessUnit, FlvError, FlvToAnnexB};
use crate::frame_pipe::FramePipe;
use crate::mkv::RawFormat;
use crate::process::Proc;
use amc_core::image::{FrameRef, PixelFormat};
use std::ffi::OsString;
use std::io::Read;
use std::path::Path;
use std::thread::JoinHandle;
use std::time::Duration;

/// How the live stream is encoded.
#[derive(Clone, Debug)]
pub struct H264Options {
    /// Target and cap, kilobits per second.
    pub bitrate_kbps: u32,
    /// Longest time between keyframes, seconds (a viewer joins at one).
    pub keyframe_interval_s: f64,
    /// x264 preset: speed against bits. `ultrafast` by default: on two
    /// cores beside the stabilizer, 720p60 keeps its rate with it (not with
    /// `superfast`), and the stream stays within the cap (docs/speed.md).
    pub preset: String,
    /// Encoder threads (0: ffmpeg's choice). One by default: more only
    /// contend with the stabilizer for the same cores.
    pub threads: usize,
    /// Frames per second the bit rate is shared over (x264's rate control
    /// budgets per frame; the timestamps alone do not tell it).
    pub fps: f64,
    /// A write that blocks this long (ffmpeg stalled) kills it.
    pub timeout: Duration,
}

impl Default for H264Options {
    fn default() -> Self {
        Self {
            bitrate_kbps: 6000,
            keyframe_interval_s: 1.0,
            preset: "ultrafast".into(),
            threads: 1,
            fps: 30.0,
            timeout: Duration::from_secs(20),
        }
    }
}

/// A running encoder; dropping it stops ffmpeg.
pub struct H264Encoder {
    proc: Proc,
    pipe: FramePipe,
    reader: Option<JoinHandle<()>>,
}

impl H264Encoder {
    /// Starts ffmpeg for `width x height` frames of `format`; every access
    /// unit goes to `on_unit` (on the encoder's reader thread) as soon as it
    /// is read, and the thread ends when the stream does (after an error,
    /// which is handed over too).
    pub fn start(
        width: usize,
        height: usize,
        format: PixelFormat,
        opts: &H264Options,
        mut on_unit: impl FnMut(Result<AccessUnit, FlvError>) + Send + 'static,
    ) -> Result<Self, VideoError> {
        let pipe = FramePipe::new(width, height, format);
        let kbps = opts.bitrate_kbps.max(1);
        let mut args: Vec<String> = [
            "-hide_banner",
            "-nostdin",
            "-nostats",
            "-loglevel",
            "level+error",
            // Start on the first frame: the header says all there is to know.
            "-probesize",
            "32",
            "-analyzeduration",
            "0",
            "-f",
            "matroska",
            "-i",
            "pipe:0",
            "-map",
            "0:v:0",
        ]
        .map(String::from)
        .to_vec();
        if pipe.raw == RawFormat::Rgb24 && pipe.odd() {
            args.extend(["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"].map(String::from));
        }
        args.extend(
            [
                "-c:v",
                "libx264",
                "-preset",
                &opts.preset,
                "-tune",
                "zerolatency",
                "-bf",
                "0",
                // Constant quality, capped: a small or still picture takes
                // the bits it needs, a busy one no more than the link's.
                "-crf",
                "21",
                "-maxrate",
                &format!("{kbps}k"),
                "-bufsize",
                &format!("{}k", (kbps / 2).max(1)),
                // Keyframes by time, not count: the frames' rate is the source's.
                "-g",
                "100000",
                "-x264-params",
                &format!("fps={:.3}", opts.fps.clamp(1.0, 1000.0)),
                "-force_key_frames",
                &format!("expr:gte(t,n_forced*{})", opts.keyframe_interval_s),
                "-threads",
                &opts.threads.to_string(),
                "-pix_fmt",
                "yuv420p",
                "-fps_mode",
                "passthrough",
                "-flush_packets",
                "1",
                "-f",
                "flv",
                "pipe:1",
            ]
            .map(String::from),
        );
        let os: Vec<OsString> = args.into_iter().map(OsString::from).collect();
        let mut proc = Proc::spawn_piped(
            "ffmpeg",
            &os,
            Path::new("live H.264 stream"),
            opts.timeout,
            true,
            true,
            None,
        )?;
        let header = pipe.header();
        if let Some(stdin) = proc.stdin.as_mut() {
            // A failure shows on the first frame, with ffmpeg's own message.
            let _ = std::io::Write::write_all(stdin, &header);
        }
        let reader = proc.stdout.take().map(|mut out| {
            std::thread::spawn(move || {
                let mut flv = FlvToAnnexB::new();
                let mut buf = vec![0u8; 256 * 1024];
                while let Ok(n) = out.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    match flv.push(&buf[..n]) {
                        Ok(units) => units.into_iter().map(Ok).for_each(&mut on_unit),
                        Err(e) => {
                            on_unit(Err(e));
                            break;
                        }
                    }
                }
            })
        });
        Ok(Self { proc, pipe, reader })
    }

    /// Encodes `frame` at `t` seconds (increasing); its access unit reaches
    /// `on_unit` once ffmpeg has encoded it.
    pub fn write_frame(&mut self, frame: &FrameRef<'_>, t: f64) -> Result<(), VideoError> {
        crate::frame::check_frame(
            Path::new("live H.264 stream"),
            self.pipe.width,
            self.pipe.height,
            frame,
        )?;
        self.proc.arm();
        let written = match self.proc.stdin.as_mut() {
            Some(stdin) => self.pipe.write(stdin, frame, t),
            None => Err(std::io::ErrorKind::BrokenPipe.into()),
        };
        self.proc.disarm();
        written.map_err(|_| self.proc.input_refused())
    }
}

impl H264Encoder {
    /// Ends the stream: ffmpeg encodes what it holds, and every access unit
    /// has reached `on_unit` when this returns.
    pub fn finish(mut self) -> Result<(), VideoError> {
        self.proc.stdin.take();
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
        let status = self.proc.wait()?;
        if status.success() {
            Ok(())
        } else {
            Err(self.proc.failure(Some(status)))
        }
    }
}

impl Drop for H264Encoder {
    fn drop(&mut self) {
        // Closing stdin ends the stream; killing makes sure.
        self.proc.stdin.take();
        self.proc.kill();
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use amc_core::image::Frame;
    use std::sync::{Arc, Mutex};

    /// A moving gradient, `n` frames at 60 fps.
    fn frames(width: usize, height: usize, n: usize) -> Vec<Frame> {
        (0..n)
            .map(|i| {
                let mut f = Frame::new(width, height, PixelFormat::Rgb8);
                for y in 0..height {
                    for x in 0..width {
                        let p = &mut f.data[(y * width + x) * 3..][..3];
                        p[0] = ((x + 4 * i) % 256) as u8;
                        p[1] = ((y * 2 + i) % 256) as u8;
                        p[2] = ((x ^ y) % 256) as u8;
                    }
                }
                f
            })
            .collect()
    }

    #[test]
    fn the_bit_rate_cap_holds_for_a_picture_that_wants_more() {
        if crate::ffmpeg_available().is_err() {
            eprintln!("note: ffmpeg not installed, skipping");
            return;
        }
        // Noise: at constant quality it would take tens of Mbit/s.
        let (w, h, n) = (320, 180, 120);
        let bytes = Arc::new(Mutex::new(0usize));
        let sum = Arc::clone(&bytes);
        let opts = H264Options {
            fps: 60.0,
            bitrate_kbps: 1000,
            ..H264Options::default()
        };
        let mut enc = H264Encoder::start(w, h, PixelFormat::Rgb8, &opts, move |u| {
            *sum.lock().unwrap() += u.unwrap().data.len();
        })
        .unwrap();
        let mut seed = 12345u32;
        let mut f = Frame::new(w, h, PixelFormat::Rgb8);
        for i in 0..n {
            for p in f.data.iter_mut() {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *p = (seed >> 24) as u8;
            }
            enc.write_frame(&f.as_ref(), i as f64 / 60.0).unwrap();
        }
        enc.finish().unwrap();
        // 2 s of frames: at most the cap, plus the half-second buffer.
        let mbps = *bytes.lock().unwrap() as f64 * 8.0 / 2.0 / 1e6;
        assert!(
            mbps > 0.5 && mbps <= 1.0 + 0.5 / 2.0 + 0.1,
            "{mbps:.2} Mbit/s"
        );
    }

    #[test]
    fn every_frame_is_one_access_unit_and_the_stream_decodes_from_its_first_byte() {
        if crate::ffmpeg_available().is_err() {
            eprintln!("note: ffmpeg not installed, skipping");
            return;
        }
        let (w, h, n) = (160, 90, 150);
        let units = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&units);
        let opts = H264Options {
            fps: 60.0,
            ..H264Options::default()
        };
        let mut enc = H264Encoder::start(w, h, PixelFormat::Rgb8, &opts, move |u| {
            sink.lock().unwrap().push(u.expect("a readable stream"));
        })
        .unwrap();
        for (i, f) in frames(w, h, n).iter().enumerate() {
            enc.write_frame(&f.as_ref(), i as f64 / 60.0).unwrap();
        }
        enc.finish().unwrap();
        let units = units.lock().unwrap();
        assert!(units[0].key, "the stream starts at a keyframe");
        assert!(
            units[0].data.windows(5).any(|w| w == [0, 0, 0, 1, 0x67]),
            "SPS first"
        );
        // A keyframe each second of the frames' time: at 0, 1 and 2 s.
        let keys: Vec<usize> = (0..n).filter(|&i| units[i].key).collect();
        assert_eq!(keys, [0, 60, 120], "keyframes at");
        assert_eq!(units[60].pts_ms, 1000);
        // Concatenated, and from the second keyframe on: streams ffmpeg decodes whole.
        let dir = tempfile::tempdir().unwrap();
        for (name, from) in [("all.h264", 0), ("joined.h264", 60)] {
            let path = dir.path().join(name);
            let bytes: Vec<u8> = units[from..].iter().flat_map(|u| u.data.clone()).collect();
            std::fs::write(&path, bytes).unwrap();
            let out = std::process::Command::new("ffprobe")
                .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
                .args(["-show_entries", "stream=nb_read_frames", "-of", "csv=p=0"])
                .arg(&path)
                .output()
                .unwrap();
            let text = String::from_utf8_lossy(&out.stdout);
            assert_eq!(text.trim(), (n - from).to_string(), "{name}: {text}");
        }
    }
}
