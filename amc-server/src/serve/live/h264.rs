//! The live feed as H.264 (`/live?codec=h264`): one encoder
//! ([`amc_video::H264Encoder`], ffmpeg's libx264) shared by every viewer that
//! asks for it, started for the first and stopped after the last; its access
//! units fan out through a broadcast channel, each with its frame's
//! telemetry. A frame is encoded once, whatever the number of viewers.

use super::telemetry::LiveTelemetry;
use crate::poison::lock;
use amc_core::Frame;
use amc_video::{H264Encoder, H264Options, VideoError};
use bytes::Bytes;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::broadcast;

/// Access units a viewer may fall behind by before it skips to the next
/// keyframe (a second at 60 frames/s).
pub const BROADCAST_UNITS: usize = 64;
/// The encoder's timestamps move on by at least this (FLV counts whole ms).
const MIN_STEP_S: f64 = 0.002;
/// Frames that may wait for the running encoder.
const WAITING_FRAMES: usize = 2;
/// Frames that may wait while ffmpeg starts (a few hundred ms): held, not
/// left out, so a viewer's stream starts with the feed's first frames; the
/// encoder is faster than real time and catches up. At most this many bytes.
const STARTUP_FRAMES: usize = 24;
const STARTUP_BYTES: usize = 64 << 20;

/// One encoded frame as viewers get it.
#[derive(Debug)]
pub struct H264Unit {
    pub frame: u64,
    /// An IDR picture with its SPS and PPS: a viewer can start here.
    pub key: bool,
    /// The access unit, Annex-B.
    pub data: Bytes,
    /// The JSON telemetry text message.
    pub meta: String,
}

type Pending = Arc<Mutex<VecDeque<(LiveTelemetry, Instant)>>>;

/// The feed's frame rate, from the arrival of its last frames: x264's rate
/// control shares the bit rate over it (a live source's or publisher's rate
/// is not known in advance).
#[derive(Default)]
pub(super) struct FrameRate {
    arrivals: VecDeque<Instant>,
}

impl FrameRate {
    /// Frames whose arrival make an estimate.
    const ENOUGH: usize = 8;
    const KEPT: usize = 32;
    const GAP: Duration = Duration::from_secs(1);

    /// A frame arrived. After a gap of over a second (a paused or reopened
    /// feed, not its rate) the estimate starts again.
    pub fn saw(&mut self, arrived: Instant) {
        if self
            .arrivals
            .back()
            .is_some_and(|&l| arrived.saturating_duration_since(l) > Self::GAP)
        {
            self.arrivals.clear();
        }
        if self.arrivals.len() == Self::KEPT {
            self.arrivals.pop_front();
        }
        self.arrivals.push_back(arrived);
    }

    /// Frames per second, once enough frames arrived.
    pub fn fps(&self) -> Option<f64> {
        let (first, last) = (self.arrivals.front()?, self.arrivals.back()?);
        let span = last.saturating_duration_since(*first).as_secs_f64();
        (self.arrivals.len() >= Self::ENOUGH && span > 0.0)
            .then(|| (self.arrivals.len() - 1) as f64 / span)
    }
}

/// A frame on its way to the encoder's writer thread.
struct Job {
    frame: Frame,
    t: f64,
    meta: LiveTelemetry,
    arrived: Instant,
}

/// The running encoder of the feed. Frames go to it through a writer thread
/// (ffmpeg reads a frame only once it has encoded the one before, and the
/// feed's encode thread must not wait for that); a frame arriving while two
/// wait is left out of the H.264 stream (while ffmpeg starts, and until the
/// frames held then are written, up to [`STARTUP_FRAMES`]).
pub(super) struct H264Stage {
    to_writer: SyncSender<Job>,
    /// Frames handed to the writer and not yet taken by it.
    waiting: Arc<AtomicUsize>,
    /// Set once the first access unit came out.
    running: Arc<AtomicBool>,
    /// The writer's used frames, for the next copies.
    spare: Receiver<Frame>,
    size: (usize, usize),
    clock: Option<Instant>,
    last_t: f64,
    /// Set once the frames held while ffmpeg started are written: until
    /// then a frame waits behind them instead of being left out.
    caught_up: bool,
}

impl H264Stage {
    /// Starts an encoder for frames like `frame` at `fps`, publishing to `units`.
    pub fn start(
        frame: &Frame,
        fps: f64,
        bitrate_kbps: u32,
        timeout: Duration,
        units: broadcast::Sender<Arc<H264Unit>>,
    ) -> Result<Self, VideoError> {
        // Telemetry of the frames written and not yet out, in order (one
        // access unit comes out per frame: no B-frames, no lookahead).
        let pending: Pending = Arc::new(Mutex::new(VecDeque::new()));
        let queue = Arc::clone(&pending);
        let running = Arc::new(AtomicBool::new(false));
        let ran = Arc::clone(&running);
        let mut units_out = 0u64;
        let opts = H264Options {
            bitrate_kbps,
            fps,
            timeout,
            ..H264Options::default()
        };
        let mut encoder = H264Encoder::start(
            frame.width,
            frame.height,
            frame.format,
            &opts,
            move |unit| match unit {
                Ok(unit) => {
                    ran.store(true, Ordering::SeqCst);
                    let Some((mut meta, arrived)) = lock(&queue).pop_front() else {
                        return;
                    };
                    meta.latency_ms = arrived.elapsed().as_secs_f64() * 1e3;
                    meta.codec = "h264";
                    meta.unit = Some(units_out);
                    units_out += 1;
                    let _ = units.send(Arc::new(H264Unit {
                        frame: meta.frame,
                        key: unit.key,
                        data: Bytes::from(unit.data),
                        meta: serde_json::to_string(&meta).unwrap_or_default(),
                    }));
                }
                Err(e) => tracing::warn!(error = %e, "the live H.264 stream cannot be read"),
            },
        )?;
        let held = (STARTUP_BYTES / frame.data.len().max(1)).clamp(WAITING_FRAMES, STARTUP_FRAMES);
        let (to_writer, jobs) = mpsc::sync_channel::<Job>(held);
        let (give_back, spare) = mpsc::channel::<Frame>();
        let waiting = Arc::new(AtomicUsize::new(0));
        let taken = Arc::clone(&waiting);
        std::thread::Builder::new()
            .name("amc-live-h264".into())
            .spawn(move || {
                for job in jobs {
                    taken.fetch_sub(1, Ordering::SeqCst);
                    lock(&pending).push_back((job.meta, job.arrived));
                    if let Err(e) = encoder.write_frame(&job.frame.as_ref(), job.t) {
                        // Returning drops `jobs`: the next `encode` sees it.
                        tracing::warn!(error = %e, "the live H.264 encoder stopped");
                        return;
                    }
                    let _ = give_back.send(job.frame);
                }
                // The feed's encode thread let go: ending here stops ffmpeg.
            })
            .map_err(|e| {
                VideoError::io(
                    std::path::Path::new("live H.264 stream"),
                    "start its writer thread",
                    e,
                )
            })?;
        Ok(Self {
            to_writer,
            waiting,
            running,
            spare,
            size: (frame.width, frame.height),
            clock: None,
            last_t: f64::NEG_INFINITY,
            caught_up: false,
        })
    }

    /// Whether this encoder takes `frame` (same size).
    pub fn fits(&self, frame: &Frame) -> bool {
        self.size == (frame.width, frame.height)
    }

    /// Hands a copy of `frame` to the encoder, stamped with its arrival (the
    /// encoder's keyframe clock runs on the feed's real time); `Err` once
    /// the encoder has stopped.
    pub fn encode(
        &mut self,
        frame: &Frame,
        meta: &LiveTelemetry,
        arrived: Instant,
    ) -> Result<(), &'static str> {
        if self.running.load(Ordering::SeqCst) {
            if self.waiting.load(Ordering::SeqCst) < WAITING_FRAMES {
                self.caught_up = true;
            } else if self.caught_up {
                // Two frames already wait: this one is left out.
                return Ok(());
            }
        }
        let start = *self.clock.get_or_insert(arrived);
        let t = arrived
            .saturating_duration_since(start)
            .as_secs_f64()
            .max(self.last_t + MIN_STEP_S);
        let mut copy = self
            .spare
            .try_recv()
            .unwrap_or_else(|_| Frame::new(0, 0, frame.format));
        copy.copy_from(&frame.as_ref());
        let job = Job {
            frame: copy,
            t,
            meta: meta.clone(),
            arrived,
        };
        self.waiting.fetch_add(1, Ordering::SeqCst);
        match self.to_writer.try_send(job) {
            Ok(()) => {
                self.last_t = t;
                Ok(())
            }
            // As many frames as ffmpeg's start may hold wait: left out.
            Err(TrySendError::Full(_)) => {
                self.waiting.fetch_sub(1, Ordering::SeqCst);
                Ok(())
            }
            Err(TrySendError::Disconnected(_)) => {
                self.waiting.fetch_sub(1, Ordering::SeqCst);
                Err("the encoder stopped")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_is_known_after_a_few_frames() {
        let t0 = Instant::now();
        let mut r = FrameRate::default();
        for i in 0..40u64 {
            assert_eq!(
                r.fps().is_some(),
                i >= FrameRate::ENOUGH as u64,
                "after {i}"
            );
            r.saw(t0 + Duration::from_micros(i * 16_667));
        }
        assert!((r.fps().unwrap() - 60.0).abs() < 0.1, "{:?}", r.fps());
        // A pause of two seconds: the rate is not known again until new frames.
        r.saw(t0 + Duration::from_secs(3));
        assert_eq!(r.fps(), None);
    }
}
