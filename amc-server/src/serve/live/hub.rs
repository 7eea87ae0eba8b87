//! The live feed: frames from `--live-source` (anything ffmpeg opens) or
//! from a publisher on `/live/ingest` (JPEG frames over a WebSocket) are
//! stabilized by one processor thread and fanned out to `/live` viewers.
//!
//! ```text
//! source thread --try_send--> [1 slot] --> processor --[1 slot]--> JPEG thread --watch--> viewer tasks
//! ingest socket --try_send-->            (stabilize)              (encode)     (latest frame only)
//!                                                                     |
//!                                      H.264 viewers: [2 slots] --> ffmpeg/x264 --broadcast--> viewer tasks
//! ```
//! The H.264 stage ([`super::h264`]) runs only while someone watches it,
//! and JPEGs are encoded only while someone watches them.
//! The JPEG of frame j is encoded while frame j + 1 is stabilized: on two
//! cores the stabilizer's single-threaded parts (tracking, the view) and the
//! encoder then overlap instead of taking turns (docs/speed.md).
//! With no viewer the feed is paused: the source's ffmpeg child is stopped
//! (and started again, from a file's beginning, for the first viewer) and
//! a publisher's frames are dropped undecoded, so an unwatched feed costs
//! no CPU.
//!
//! Memory is bounded by design: the processor's input holds one frame (a
//! frame arriving while it is full is dropped and counted), and the
//! fan-out is a `watch` channel holding only the newest frame, so a slow
//! viewer skips frames instead of queueing them and never delays the others.

use super::h264::{FrameRate, H264Stage, H264Unit, BROADCAST_UNITS};
use super::ingest_h264::IngestDecoder;
use super::jpeg::{decode_ingest_frame, JpegEncoder};
use super::telemetry::LiveTelemetry;
use crate::poison::lock;
use crate::serve::metrics::Metrics;
use amc_core::view::Mode;
use amc_core::{CameraModel, Frame, PixelFormat, Stabilizer, StabilizerParams};
use amc_video::{self as video, InputOptions};
use bytes::Bytes;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{broadcast, watch};

/// Frames waiting for the processor; more would only add latency.
const INPUT_SLOTS: usize = 1;
/// Wait before reopening a live source that failed or ended.
const REOPEN_DELAY: Duration = Duration::from_secs(2);
/// How often a paused source thread looks for a viewer.
const PAUSED_POLL: Duration = Duration::from_millis(100);

/// How the live feed is stabilized.
#[derive(Clone, Debug)]
pub struct LiveConfig {
    /// `--live-source`: a file, URL or device; `None`: frames come from `/live/ingest`.
    pub source: Option<String>,
    /// ffmpeg `-f` for the source (`v4l2`...).
    pub format: Option<String>,
    /// Replay a file source forever.
    pub looped: bool,
    pub params: StabilizerParams,
    /// A calibrated lens; otherwise a pinhole with `fov_deg`.
    pub lens: Option<CameraModel>,
    pub fov_deg: f64,
    /// JPEG quality of the frames sent to viewers (1..=100).
    pub jpeg_quality: u8,
    /// Kilobits per second of the H.264 stream.
    pub bitrate_kbps: u32,
    pub ffmpeg_timeout: Duration,
}

impl Default for LiveConfig {
    fn default() -> Self {
        let mut params = StabilizerParams::default();
        params.view.mode = Mode::Stabilize;
        Self {
            source: None,
            format: None,
            looped: false,
            params,
            lens: None,
            fov_deg: amc_engine::FALLBACK_FOV_DEG,
            jpeg_quality: 80,
            // 720p60 of stabilized (smooth) video looks clean at 6 Mbit/s,
            // under the 8 that streaming services ask for it.
            bitrate_kbps: 6000,
            ffmpeg_timeout: Duration::from_secs(20),
        }
    }
}

/// One stabilized frame as viewers get it.
#[derive(Debug)]
pub struct LiveFrame {
    pub frame: u64,
    pub jpeg: Bytes,
    /// The JSON telemetry text message.
    pub meta: String,
}

/// A stabilized frame on its way to the JPEG thread.
struct Stabilized {
    /// A copy of the stabilizer's output.
    frame: Frame,
    /// Its telemetry, `latency_ms` filled in once it is encoded.
    meta: LiveTelemetry,
    arrived: Instant,
}

enum Input {
    Rgb {
        frame: Frame,
        t: Option<f64>,
        arrived: Instant,
        /// Which opening of the source it comes from: a new one (after a
        /// pause or a failure) starts a new stabilizer.
        opening: u64,
    },
    Jpeg {
        bytes: Bytes,
        arrived: Instant,
    },
}

/// The live feed's shared end: viewers subscribe, sources submit.
pub struct LiveHub {
    latest: watch::Sender<Option<Arc<LiveFrame>>>,
    /// The H.264 stream's access units, for its viewers.
    h264: broadcast::Sender<Arc<H264Unit>>,
    /// Viewers of the H.264 stream (the encoder runs while there are any).
    h264_viewers: AtomicUsize,
    input: Mutex<Option<SyncSender<Input>>>,
    /// Frame buffers handed back by the processor for the source to reuse.
    spare: Mutex<Vec<Frame>>,
    publisher: AtomicBool,
    /// The publisher's H.264 decoder, once it sent H.264.
    ingest_h264: Mutex<Option<IngestDecoder>>,
    stop: AtomicBool,
    pub config: LiveConfig,
    metrics: Arc<Metrics>,
    /// Viewers connected to `/live`; none pauses the feed.
    viewers: AtomicUsize,
    /// Why `--live-source` cannot be used right now (for `/healthz`).
    source_error: Mutex<Option<String>>,
    /// Whether the source's ffmpeg child is running.
    source_open: AtomicBool,
    /// Openings of the source so far.
    openings: AtomicU64,
    /// The open source's frame rate as its container states it (f64 bits;
    /// 0: none open, or no plausible rate stated): the H.264 encoder starts
    /// with the first frame instead of measuring the rate over a few.
    source_fps: AtomicU64,
}

/// A viewer's place: counted while it lives (it keeps the feed running).
pub struct Viewing(Arc<LiveHub>);

impl Drop for Viewing {
    fn drop(&mut self) {
        self.0.viewers.fetch_sub(1, Ordering::SeqCst);
        self.0.metrics.live_viewers.dec();
    }
}

/// An H.264 viewer's place (inside a [`Viewing`]): keeps the encoder running.
pub struct H264Viewing(Arc<LiveHub>);

impl Drop for H264Viewing {
    fn drop(&mut self) {
        self.0.h264_viewers.fetch_sub(1, Ordering::SeqCst);
    }
}

/// The single publisher's slot, taken while it lives.
pub struct Publishing(Arc<LiveHub>);

impl Drop for Publishing {
    fn drop(&mut self) {
        // Its decoder (if it sent H.264) stops with it.
        lock(&self.0.ingest_h264).take();
        self.0.publisher.store(false, Ordering::SeqCst);
    }
}

impl LiveHub {
    /// Starts the processor (and the source thread, with `--live-source`).
    pub fn start(config: LiveConfig, metrics: Arc<Metrics>) -> Arc<Self> {
        let (tx, rx) = mpsc::sync_channel(INPUT_SLOTS);
        let hub = Arc::new(Self {
            latest: watch::channel(None).0,
            h264: broadcast::channel(BROADCAST_UNITS).0,
            h264_viewers: AtomicUsize::new(0),
            input: Mutex::new(Some(tx)),
            spare: Mutex::new(Vec::new()),
            publisher: AtomicBool::new(false),
            ingest_h264: Mutex::new(None),
            stop: AtomicBool::new(false),
            config,
            metrics,
            viewers: AtomicUsize::new(0),
            source_error: Mutex::new(None),
            source_open: AtomicBool::new(false),
            openings: AtomicU64::new(0),
            source_fps: AtomicU64::new(0),
        });
        let processor = hub.clone();
        std::thread::Builder::new()
            .name("amc-live".into())
            .spawn(move || processor.process(rx))
            .ok();
        if hub.config.source.is_some() {
            let source = hub.clone();
            std::thread::Builder::new()
                .name("amc-live-source".into())
                .spawn(move || source.read_source())
                .ok();
        }
        hub
    }

    pub fn subscribe(&self) -> watch::Receiver<Option<Arc<LiveFrame>>> {
        self.latest.subscribe()
    }

    /// Counts a viewer until the returned guard is dropped; the first one
    /// resumes a paused feed.
    pub fn watch(self: &Arc<Self>) -> Viewing {
        self.viewers.fetch_add(1, Ordering::SeqCst);
        self.metrics.live_viewers.inc();
        Viewing(self.clone())
    }

    /// The H.264 stream: subscribe first, then count the viewer, so that
    /// the encoder's first access unit (a keyframe) is not missed.
    pub fn watch_h264(self: &Arc<Self>) -> (broadcast::Receiver<Arc<H264Unit>>, H264Viewing) {
        let units = self.h264.subscribe();
        self.h264_viewers.fetch_add(1, Ordering::SeqCst);
        (units, H264Viewing(self.clone()))
    }

    fn watched(&self) -> bool {
        self.viewers.load(Ordering::SeqCst) > 0
    }

    /// Takes the single publisher slot, if it is free.
    pub fn publish(self: &Arc<Self>) -> Option<Publishing> {
        (!self.publisher.swap(true, Ordering::SeqCst)).then(|| Publishing(self.clone()))
    }

    /// Why `--live-source` cannot be used, while it cannot.
    pub fn source_error(&self) -> Option<String> {
        lock(&self.source_error).clone()
    }

    /// The feed's state for `/healthz`.
    pub fn status(&self) -> serde_json::Value {
        let viewers = self.viewers.load(Ordering::SeqCst);
        let state = match &self.config.source {
            Some(_) if self.source_error().is_some() => "unavailable",
            Some(_) if self.source_open.load(Ordering::SeqCst) => "running",
            Some(_) => "paused",
            None if self.publisher.load(Ordering::SeqCst) && viewers > 0 => "running",
            None if self.publisher.load(Ordering::SeqCst) => "paused",
            None => "waiting for a publisher",
        };
        serde_json::json!({
            "source": self.config.source.as_deref().unwrap_or("/live/ingest"),
            "state": state,
            "viewers": viewers,
        })
    }

    /// Records (and logs, once per new trouble) why the source cannot be used.
    fn set_source_error(&self, error: Option<String>) {
        let mut slot = lock(&self.source_error);
        match (&error, slot.as_ref()) {
            (Some(e), prev) if prev != Some(e) => tracing::warn!(
                error = %e,
                "the live feed is unavailable (the rest of the API works; /healthz answers 503 until the source can be opened)"
            ),
            (None, Some(_)) => tracing::info!("the live source works again"),
            _ => {}
        }
        *slot = error;
    }

    /// Stops the threads (shutdown).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
        lock(&self.input).take();
    }

    fn submit(&self, input: Input) {
        let guard = lock(&self.input);
        let Some(tx) = guard.as_ref() else { return };
        match tx.try_send(input) {
            Ok(()) => {}
            Err(TrySendError::Full(input)) => {
                self.metrics.live_dropped.inc();
                if let Input::Rgb { frame, .. } = input {
                    self.give_back(frame);
                }
            }
            Err(TrySendError::Disconnected(_)) => {}
        }
    }

    fn give_back(&self, frame: Frame) {
        let mut spare = lock(&self.spare);
        if spare.len() < INPUT_SLOTS + 2 {
            spare.push(frame);
        }
    }

    fn take_buffer(&self) -> Frame {
        lock(&self.spare)
            .pop()
            .unwrap_or_else(|| Frame::new(0, 0, PixelFormat::Rgb8))
    }

    /// An H.264 access unit from a publisher (dropped undecoded while nobody
    /// watches; the decoder picks up again at a keyframe).
    pub fn submit_h264(self: &Arc<Self>, unit: Bytes) {
        if !self.watched() {
            return;
        }
        let mut slot = lock(&self.ingest_h264);
        if slot.is_none() {
            // A new stream: a new clock for the processor (see `Input::Rgb`).
            let opening = self.openings.fetch_add(1, Ordering::SeqCst) + 1;
            let hub = Arc::downgrade(self);
            let started = IngestDecoder::start(self.config.ffmpeg_timeout, move |frame| match hub
                .upgrade()
            {
                Some(hub) => {
                    hub.submit(Input::Rgb {
                        frame,
                        t: None,
                        arrived: Instant::now(),
                        opening,
                    });
                    hub.take_buffer()
                }
                None => frame,
            });
            match started {
                Ok(d) => *slot = Some(d),
                Err(e) => {
                    tracing::warn!(error = %e, "cannot start a decoder for the publisher's H.264");
                    return;
                }
            }
        }
        if !slot.as_ref().is_some_and(|d| d.push(unit)) {
            // Stopped (its writer logged why): the next unit starts another.
            *slot = None;
        }
    }

    /// A JPEG frame from a publisher (dropped undecoded while nobody watches).
    pub fn submit_jpeg(&self, bytes: Bytes) {
        if !self.watched() {
            return;
        }
        self.submit(Input::Jpeg {
            bytes,
            arrived: Instant::now(),
        });
    }

    /// The source thread: decode `--live-source` in real time while
    /// someone watches, hand frames on. The source is opened once at start
    /// (so `/healthz` knows whether it works), then again for each viewer
    /// after a pause; one that cannot be opened is retried every
    /// REOPEN_DELAY.
    fn read_source(self: Arc<Self>) {
        let Some(source) = self.config.source.clone() else {
            return;
        };
        let is_file = std::path::Path::new(&source).is_file();
        let opts = InputOptions {
            timeout: self.config.ffmpeg_timeout,
            // A file is replayed at its own rate, as a camera would deliver it.
            realtime: is_file,
            // Decoders' own planes, rendered and JPEG-encoded without a
            // colour conversion.
            pixel_format: PixelFormat::Yuv420p,
            looped: self.config.looped && is_file,
            ..InputOptions::default()
        };
        let stopped = || self.stop.load(Ordering::SeqCst);
        let mut checked = false;
        while !stopped() {
            if checked {
                while !stopped() && !self.watched() {
                    std::thread::sleep(PAUSED_POLL);
                }
                if stopped() {
                    return;
                }
            }
            let mut src = match video::open_stream(&source, self.config.format.as_deref(), &opts) {
                Ok(src) => src,
                Err(e) => {
                    self.set_source_error(Some(format!(
                        "the live source {source} cannot be opened: {e}"
                    )));
                    // Retried whether or not anyone watches, so that
                    // /healthz sees the source come back.
                    checked = false;
                    std::thread::sleep(REOPEN_DELAY);
                    continue;
                }
            };
            checked = true;
            self.set_source_error(None);
            let opening = self.openings.fetch_add(1, Ordering::SeqCst) + 1;
            self.source_open.store(true, Ordering::SeqCst);
            let fps = src.info().fps;
            let stated = if (1.0..=240.0).contains(&fps) {
                fps
            } else {
                0.0
            };
            self.source_fps.store(stated.to_bits(), Ordering::SeqCst);
            tracing::info!(%source, width = src.info().width, height = src.info().height, fps = src.info().fps, "live source open");
            let ended = loop {
                if stopped() {
                    break false;
                }
                if !self.watched() {
                    tracing::info!(%source, "no viewers: live source paused");
                    break false;
                }
                let mut frame = self.take_buffer();
                match src.next_frame(&mut frame) {
                    Ok(Some(t)) => self.submit(Input::Rgb {
                        frame,
                        t: Some(t),
                        arrived: Instant::now(),
                        opening,
                    }),
                    Ok(None) => {
                        tracing::info!(%source, "live source ended");
                        break true;
                    }
                    Err(e) => {
                        self.set_source_error(Some(format!(
                            "the live source {source} failed: {e}"
                        )));
                        // Probed again even with no viewer, as above.
                        checked = false;
                        break true;
                    }
                }
            };
            // Dropping the source kills its ffmpeg child.
            drop(src);
            self.source_open.store(false, Ordering::SeqCst);
            self.source_fps.store(0, Ordering::SeqCst);
            if ended {
                if is_file && !self.config.looped {
                    return;
                }
                std::thread::sleep(REOPEN_DELAY);
            }
        }
    }

    /// The processor thread: stabilize and publish until the input closes.
    fn process(self: Arc<Self>, rx: Receiver<Input>) {
        // Each frame's rows are rendered on every core (no pipelining: it
        // would add a frame of latency).
        let pool = amc_engine::render_pool(amc_engine::default_threads())
            .map_err(|e| tracing::warn!(error = %e, "live frames render on one thread"))
            .ok();
        let mut stab: Option<Stabilizer> = None;
        let mut size = (0, 0);
        let mut rgb = Frame::new(0, 0, PixelFormat::Rgb8);
        // One frame may wait for the JPEG thread while it encodes another.
        let (to_jpeg, frames) = mpsc::sync_channel::<Stabilized>(1);
        let (spare, returned) = mpsc::channel::<Frame>();
        let jpeg_thread = {
            let hub = Arc::clone(&self);
            std::thread::Builder::new()
                .name("amc-live-jpeg".into())
                .spawn(move || hub.encode_and_publish(frames, spare))
        };
        let jpeg_thread = match jpeg_thread {
            Ok(t) => t,
            Err(e) => {
                tracing::error!(error = %e, "cannot start the live feed's JPEG thread");
                return;
            }
        };
        let mut clock: Option<Instant> = None;
        let mut last_t = f64::NEG_INFINITY;
        let mut published = 0u64;
        let mut decode_failures = 0u64;
        let mut last_opening = 0u64;
        while let Ok(input) = rx.recv() {
            let (frame, t, arrived, from_source) = match input {
                Input::Rgb {
                    frame,
                    t,
                    arrived,
                    opening,
                } => {
                    if opening != last_opening {
                        // The source was reopened: its clock starts again.
                        last_opening = opening;
                        size = (0, 0);
                    }
                    (frame, t, arrived, true)
                }
                Input::Jpeg { bytes, arrived } => match decode_ingest_frame(&bytes, &mut rgb) {
                    Ok(()) => (
                        std::mem::replace(&mut rgb, Frame::new(0, 0, PixelFormat::Rgb8)),
                        None,
                        arrived,
                        false,
                    ),
                    Err(e) => {
                        decode_failures += 1;
                        if decode_failures.is_power_of_two() {
                            tracing::warn!(error = %e, failures = decode_failures, "live ingest frame is not a JPEG image");
                        }
                        continue;
                    }
                },
            };
            // A new size (a new publisher, another camera mode) starts a new stabilizer.
            if (frame.width, frame.height) != size {
                size = (frame.width, frame.height);
                stab = match self.stabilizer_for(frame.width, frame.height) {
                    Ok(s) => Some(s),
                    Err(e) => {
                        tracing::warn!(error = %e, width = frame.width, height = frame.height, "live frames cannot be stabilized");
                        None
                    }
                };
                clock = None;
                last_t = f64::NEG_INFINITY;
            }
            let Some(s) = stab.as_mut() else {
                self.recycle(frame, from_source, &mut rgb);
                continue;
            };
            // Source frames carry their own timestamps; ingested ones are
            // stamped on arrival.
            let start = *clock.get_or_insert(arrived);
            let mut t = t.unwrap_or_else(|| arrived.duration_since(start).as_secs_f64());
            if t <= last_t {
                t = last_t + 1e-3;
            }
            last_t = t;
            let pushed = match &pool {
                Some(pool) => pool.install(|| s.push(frame.as_ref(), t)),
                None => s.push(frame.as_ref(), t),
            };
            self.recycle(frame, from_source, &mut rgb);
            let tel = match pushed {
                Ok(Some(tel)) => tel,
                Ok(None) => continue,
                Err(e) => {
                    tracing::warn!(error = %e, "live frame rejected");
                    continue;
                }
            };
            let out = s.output();
            let speed = |v: [f64; 3]| {
                (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
                    .sqrt()
                    .to_degrees()
            };
            let meta = LiveTelemetry {
                frame: published,
                t: tel.t,
                speed_est_dps: speed(tel.rate_est),
                speed_view_dps: speed(tel.rate_view),
                valid: tel.valid_fraction,
                saccade: tel.saccade,
                latency_ms: 0.0,
                width: out.width,
                height: out.height,
                codec: "jpeg",
                unit: None,
            };
            // The JPEG thread hands its buffers back; at most three exist.
            let mut copy = returned
                .try_recv()
                .unwrap_or_else(|_| Frame::new(0, 0, out.format));
            copy.copy_from(&out);
            let sent = to_jpeg.send(Stabilized {
                frame: copy,
                meta,
                arrived,
            });
            if sent.is_err() {
                break;
            }
            published += 1;
        }
        drop(to_jpeg);
        let _ = jpeg_thread.join();
    }

    /// The JPEG thread: encode each stabilized frame and publish it to the
    /// viewers, handing its buffer back to the processor.
    fn encode_and_publish(&self, frames: Receiver<Stabilized>, spare: mpsc::Sender<Frame>) {
        let mut encoder = JpegEncoder::default();
        let mut jpeg = Vec::new();
        let mut h264: Option<H264Stage> = None;
        let mut rate = FrameRate::default();
        while let Ok(Stabilized {
            frame,
            mut meta,
            arrived,
        }) = frames.recv()
        {
            rate.saw(arrived);
            let h264_viewers = self.h264_viewers.load(Ordering::SeqCst);
            if h264_viewers == 0 || h264.as_ref().is_some_and(|h| !h.fits(&frame)) {
                // Dropping the stage stops its ffmpeg.
                h264 = None;
            }
            if h264_viewers > 0 {
                // The encoder starts once the feed's rate is known: as the
                // source states it, else measured over a few frames.
                let stated = f64::from_bits(self.source_fps.load(Ordering::SeqCst));
                let fps = (stated > 0.0).then_some(stated).or_else(|| rate.fps());
                if let (None, Some(fps)) = (&h264, fps) {
                    h264 = H264Stage::start(
                        &frame,
                        fps,
                        self.config.bitrate_kbps,
                        self.config.ffmpeg_timeout,
                        self.h264.clone(),
                    )
                    .map_err(|e| tracing::warn!(error = %e, "cannot start the live H.264 encoder"))
                    .ok();
                }
                if let Some(stage) = h264.as_mut() {
                    if stage.encode(&frame, &meta, arrived).is_err() {
                        // Logged by its writer; the next frame starts a new one.
                        h264 = None;
                    }
                }
            }
            // JPEGs only for those who watch them.
            let jpeg_viewers = self.viewers.load(Ordering::SeqCst) > h264_viewers;
            let encoded = if jpeg_viewers {
                Some(encoder.encode(&frame.as_ref(), self.config.jpeg_quality, &mut jpeg))
            } else {
                None
            };
            let _ = spare.send(frame);
            self.metrics.live_frames.inc();
            self.metrics
                .frames_processed
                .fetch_add(1, Ordering::Relaxed);
            match encoded {
                None => continue,
                Some(Err(e)) => {
                    tracing::warn!(error = %e, "cannot encode a live frame");
                    continue;
                }
                Some(Ok(_)) => {}
            }
            meta.latency_ms = arrived.elapsed().as_secs_f64() * 1e3;
            let number = meta.frame;
            let meta = serde_json::to_string(&meta).unwrap_or_default();
            self.latest.send_replace(Some(Arc::new(LiveFrame {
                frame: number,
                jpeg: Bytes::copy_from_slice(&jpeg),
                meta,
            })));
        }
    }

    /// Returns a source buffer to the pool, or keeps a decoded one for the next JPEG.
    fn recycle(&self, frame: Frame, from_source: bool, rgb: &mut Frame) {
        if from_source {
            self.give_back(frame);
        } else {
            *rgb = frame;
        }
    }

    fn stabilizer_for(
        &self,
        width: usize,
        height: usize,
    ) -> Result<Stabilizer, amc_core::AmcError> {
        let lens = match &self.config.lens {
            Some(l) => l.clone(),
            None => CameraModel::pinhole_hfov(width, height, self.config.fov_deg)?,
        };
        Stabilizer::new(&lens, width, height, self.config.params.clone())
    }
}
