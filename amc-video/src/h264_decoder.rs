//! A live H.264 decoder: Annex-B access units in (a publisher's stream, as a
//! ground station relays it from a drone), YUV 4:2:0 frames out as soon as
//! each is decoded. ffmpeg runs as a child: the units go to its stdin as a raw
//! `h264` stream, the frames come back on its stdout as YUV4MPEG2 (whose
//! header gives the size the stream turned out to have), one thread reading
//! them. Decoding runs on one thread with `low_delay`: frame threads would
//! hold a frame back per thread.

use crate::error::VideoError;
use crate::process::Proc;
use amc_core::image::{Frame, PixelFormat};
use std::ffi::OsString;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;
use std::thread::JoinHandle;
use std::time::Duration;

/// Whether `bytes` start like an Annex-B H.264 stream (a start code), as
/// opposed to a JPEG (`FF D8`).
pub fn is_annex_b(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0, 0, 0, 1]) || bytes.starts_with(&[0, 0, 1])
}

/// A running decoder; dropping it stops ffmpeg.
pub struct H264Decoder {
    proc: Proc,
    reader: Option<JoinHandle<()>>,
}

/// An access unit delimiter (NAL type 9, any picture type).
const AUD: [u8; 6] = [0, 0, 0, 1, 0x09, 0xf0];

/// Largest frame side the decoder hands out (a stream claiming more stops).
const MAX_SIDE: usize = 8192;

impl H264Decoder {
    /// Starts ffmpeg; each decoded frame goes to `on_frame` (on the reader
    /// thread), which hands back a buffer for the next one.
    pub fn start(
        timeout: Duration,
        mut on_frame: impl FnMut(Frame) -> Frame + Send + 'static,
    ) -> Result<Self, VideoError> {
        let args: Vec<OsString> = [
            "-hide_banner",
            "-nostdin",
            "-nostats",
            "-loglevel",
            "level+error",
            "-probesize",
            "32",
            "-analyzeduration",
            "0",
            "-flags",
            "low_delay",
            "-threads",
            "1",
            "-f",
            "h264",
            "-i",
            "pipe:0",
            "-map",
            "0:v:0",
            "-pix_fmt",
            "yuv420p",
            "-fps_mode",
            "passthrough",
            "-flush_packets",
            "1",
            "-f",
            "yuv4mpegpipe",
            "pipe:1",
        ]
        .map(OsString::from)
        .to_vec();
        let mut proc = Proc::spawn_piped(
            "ffmpeg",
            &args,
            Path::new("live H.264 input"),
            timeout,
            true,
            true,
            None,
        )?;
        let reader = proc.stdout.take().map(|out| {
            std::thread::spawn(move || {
                let mut r = BufReader::with_capacity(1 << 20, out);
                let mut line = Vec::new();
                if r.read_until(b'\n', &mut line).unwrap_or(0) == 0 {
                    return;
                }
                let header = String::from_utf8_lossy(&line).into_owned();
                let side = |tag: char| {
                    header
                        .split_whitespace()
                        .find_map(|t| t.strip_prefix(tag)?.parse::<usize>().ok())
                        .filter(|&v| v > 0 && v <= MAX_SIDE)
                };
                let (Some(w), Some(h)) = (side('W'), side('H')) else {
                    return;
                };
                let mut frame = Frame::new(w, h, PixelFormat::Yuv420p);
                loop {
                    line.clear();
                    if r.read_until(b'\n', &mut line).unwrap_or(0) == 0
                        || !line.starts_with(b"FRAME")
                    {
                        return;
                    }
                    if frame.width != w || frame.height != h || frame.format != PixelFormat::Yuv420p
                    {
                        frame = Frame::new(w, h, PixelFormat::Yuv420p);
                    }
                    if r.read_exact(&mut frame.data).is_err() {
                        return;
                    }
                    frame = on_frame(frame);
                }
            })
        });
        Ok(Self { proc, reader })
    }

    /// Hands one access unit to the decoder (blocking while ffmpeg is busy,
    /// up to the timeout).
    pub fn write(&mut self, unit: &[u8]) -> Result<(), VideoError> {
        self.proc.arm();
        let written = match self.proc.stdin.as_mut() {
            // An access unit delimiter after it: ffmpeg's parser knows the
            // unit is whole at once, instead of at the next unit's first bytes.
            Some(stdin) => stdin
                .write_all(unit)
                .and_then(|()| stdin.write_all(&AUD))
                .and_then(|()| stdin.flush()),
            None => Err(std::io::ErrorKind::BrokenPipe.into()),
        };
        self.proc.disarm();
        written.map_err(|_| self.proc.input_refused())
    }
}

impl Drop for H264Decoder {
    fn drop(&mut self) {
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
    use crate::{H264Encoder, H264Options};
    use std::sync::{Arc, Mutex};

    #[test]
    fn units_from_the_encoder_come_back_as_frames_one_by_one() {
        if crate::ffmpeg_available().is_err() {
            eprintln!("note: ffmpeg not installed, skipping");
            return;
        }
        assert!(is_annex_b(&[0, 0, 0, 1, 0x67]) && !is_annex_b(&[0xff, 0xd8, 0xff]));
        let (w, h, n) = (160, 96, 60);
        let units = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&units);
        let opts = H264Options {
            fps: 30.0,
            ..H264Options::default()
        };
        let mut enc = H264Encoder::start(w, h, PixelFormat::Rgb8, &opts, move |u| {
            sink.lock().unwrap().push(u.unwrap().data);
        })
        .unwrap();
        let mut f = Frame::new(w, h, PixelFormat::Rgb8);
        for i in 0..n {
            f.data
                .iter_mut()
                .enumerate()
                .for_each(|(k, p)| *p = ((k + 3 * i) % 251) as u8);
            enc.write_frame(&f.as_ref(), i as f64 / 30.0).unwrap();
        }
        enc.finish().unwrap();
        let frames = Arc::new(Mutex::new(Vec::new()));
        let got = Arc::clone(&frames);
        let mut dec = H264Decoder::start(Duration::from_secs(20), move |frame| {
            got.lock().unwrap().push((frame.width, frame.height));
            frame
        })
        .unwrap();
        let units = units.lock().unwrap().clone();
        for u in &units {
            assert!(is_annex_b(u));
            dec.write(u).unwrap();
        }
        // Each frame comes out once its unit is in, none held for the next.
        let start = std::time::Instant::now();
        while frames.lock().unwrap().len() < n && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(20));
        }
        let frames = frames.lock().unwrap();
        assert_eq!(frames.len(), n, "decoded {} of {n}", frames.len());
        assert!(frames.iter().all(|&s| s == (w, h)));
    }
}
