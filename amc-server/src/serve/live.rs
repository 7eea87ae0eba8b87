//! The live feed: frames from `--live-source` (anything ffmpeg opens) or
//! from a publisher on `/live/ingest` (JPEG frames over a WebSocket) are
//! stabilized by one processor thread and fanned out to `/live` viewers.
//!
//! ```text
//! source thread --try_send--> [1 slot] --> processor thread --watch--> viewer tasks
//! ingest socket --try_send-->            (stabilize, JPEG)    (latest frame only)
//! ```
//! Memory is bounded by design: the processor's input holds one frame (a
//! frame arriving while it is full is dropped and counted), and the
//! fan-out is a `watch` channel holding only the newest frame, so a slow
//! viewer skips frames instead of queueing them and never delays the others.

use super::metrics::Metrics;
use super::problem::ApiError;
use super::AppState;
use amc_core::view::Mode;
use amc_core::{CameraModel, Frame, PixelFormat, Stabilizer, StabilizerParams};
use amc_video::{self as video, InputOptions};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::response::Response;
use bytes::Bytes;
use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::watch;

/// Frames waiting for the processor; more would only add latency.
const INPUT_SLOTS: usize = 1;
/// Wait before reopening a live source that failed or ended.
const REOPEN_DELAY: Duration = Duration::from_secs(2);
/// Frames a viewer may have unread before it is skipped ahead (about 0.2 s
/// at 30 frames/s: enough for a round trip on a slow link, little staleness).
const VIEWER_IN_FLIGHT: u64 = 6;
/// Largest JPEG frame a publisher may send.
pub const MAX_INGEST_FRAME_BYTES: usize = 16 << 20;

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
            fov_deg: crate::engine::FALLBACK_FOV_DEG,
            jpeg_quality: 80,
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

/// The telemetry text message sent after each frame.
#[derive(Serialize)]
struct LiveTelemetry {
    frame: u64,
    t: f64,
    speed_est_dps: f64,
    speed_view_dps: f64,
    valid: f64,
    saccade: bool,
    /// From the frame's arrival (decoded by ffmpeg, or received from the
    /// publisher) to its stabilized JPEG being ready, milliseconds.
    latency_ms: f64,
    width: usize,
    height: usize,
}

enum Input {
    Rgb {
        frame: Frame,
        t: Option<f64>,
        arrived: Instant,
    },
    Jpeg {
        bytes: Bytes,
        arrived: Instant,
    },
}

/// The live feed's shared end: viewers subscribe, sources submit.
pub struct LiveHub {
    latest: watch::Sender<Option<Arc<LiveFrame>>>,
    input: Mutex<Option<SyncSender<Input>>>,
    /// Frame buffers handed back by the processor for the source to reuse.
    spare: Mutex<Vec<Frame>>,
    publisher: AtomicBool,
    stop: AtomicBool,
    pub config: LiveConfig,
    metrics: Arc<Metrics>,
}

impl LiveHub {
    /// Starts the processor (and the source thread, with `--live-source`).
    pub fn start(config: LiveConfig, metrics: Arc<Metrics>) -> Arc<Self> {
        let (tx, rx) = mpsc::sync_channel(INPUT_SLOTS);
        let hub = Arc::new(Self {
            latest: watch::channel(None).0,
            input: Mutex::new(Some(tx)),
            spare: Mutex::new(Vec::new()),
            publisher: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            config,
            metrics,
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

    /// Stops the threads (shutdown).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
        self.input.lock().unwrap_or_else(|e| e.into_inner()).take();
    }

    fn submit(&self, input: Input) {
        let guard = self.input.lock().unwrap_or_else(|e| e.into_inner());
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
        let mut spare = self.spare.lock().unwrap_or_else(|e| e.into_inner());
        if spare.len() < INPUT_SLOTS + 2 {
            spare.push(frame);
        }
    }

    fn take_buffer(&self) -> Frame {
        self.spare
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .pop()
            .unwrap_or_else(|| Frame::new(0, 0, PixelFormat::Rgb8))
    }

    /// A JPEG frame from a publisher.
    pub fn submit_jpeg(&self, bytes: Bytes) {
        self.submit(Input::Jpeg {
            bytes,
            arrived: Instant::now(),
        });
    }

    /// The source thread: decode `--live-source` in real time, hand frames on.
    fn read_source(self: Arc<Self>) {
        let Some(source) = self.config.source.clone() else {
            return;
        };
        let is_file = std::path::Path::new(&source).is_file();
        let opts = InputOptions {
            timeout: self.config.ffmpeg_timeout,
            // A file is replayed at its own rate, as a camera would deliver it.
            realtime: is_file,
            looped: self.config.looped && is_file,
            ..InputOptions::default()
        };
        while !self.stop.load(Ordering::SeqCst) {
            match video::open_stream(&source, self.config.format.as_deref(), &opts) {
                Ok(mut src) => {
                    tracing::info!(%source, width = src.info().width, height = src.info().height, fps = src.info().fps, "live source open");
                    loop {
                        if self.stop.load(Ordering::SeqCst) {
                            return;
                        }
                        let mut frame = self.take_buffer();
                        match src.next_frame(&mut frame) {
                            Ok(Some(t)) => self.submit(Input::Rgb {
                                frame,
                                t: Some(t),
                                arrived: Instant::now(),
                            }),
                            Ok(None) => {
                                tracing::info!(%source, "live source ended");
                                break;
                            }
                            Err(e) => {
                                tracing::warn!(%source, error = %e, "live source failed");
                                break;
                            }
                        }
                    }
                }
                Err(e) => tracing::warn!(%source, error = %e, "cannot open the live source"),
            }
            if is_file && !self.config.looped {
                return;
            }
            std::thread::sleep(REOPEN_DELAY);
        }
    }

    /// The processor thread: stabilize and publish until the input closes.
    fn process(self: Arc<Self>, rx: Receiver<Input>) {
        let mut stab: Option<Stabilizer> = None;
        let mut size = (0, 0);
        let mut rgb = Frame::new(0, 0, PixelFormat::Rgb8);
        let mut jpeg = Vec::new();
        let mut clock: Option<Instant> = None;
        let mut last_t = f64::NEG_INFINITY;
        let mut published = 0u64;
        let mut decode_failures = 0u64;
        while let Ok(input) = rx.recv() {
            let (frame, t, arrived, from_source) = match input {
                Input::Rgb { frame, t, arrived } => (frame, t, arrived, true),
                Input::Jpeg { bytes, arrived } => match decode_jpeg(&bytes, &mut rgb) {
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
            let pushed = s.push(frame.as_ref(), t);
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
            jpeg.clear();
            let encoded = encode_jpeg(&out, self.config.jpeg_quality, &mut jpeg);
            if let Err(e) = encoded {
                tracing::warn!(error = %e, "cannot encode a live frame");
                continue;
            }
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
                latency_ms: arrived.elapsed().as_secs_f64() * 1e3,
                width: out.width,
                height: out.height,
            };
            let meta = serde_json::to_string(&meta).unwrap_or_default();
            self.latest.send_replace(Some(Arc::new(LiveFrame {
                frame: published,
                jpeg: Bytes::copy_from_slice(&jpeg),
                meta,
            })));
            published += 1;
            self.metrics.live_frames.inc();
            self.metrics
                .frames_processed
                .fetch_add(1, Ordering::Relaxed);
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

/// Encodes a stabilized frame for viewers (jpeg-encoder's SIMD path: a
/// few milliseconds at 960x540, several times faster than `image`'s encoder).
fn encode_jpeg(
    frame: &amc_core::FrameRef<'_>,
    quality: u8,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let (Ok(w), Ok(h)) = (u16::try_from(frame.width), u16::try_from(frame.height)) else {
        return Err(format!(
            "{}x{} is too large for JPEG",
            frame.width, frame.height
        ));
    };
    let color = match frame.format {
        PixelFormat::Rgb8 => jpeg_encoder::ColorType::Rgb,
        PixelFormat::Rgba8 => jpeg_encoder::ColorType::Rgba,
    };
    jpeg_encoder::Encoder::new(out, quality)
        .encode(frame.data, w, h, color)
        .map_err(|e| e.to_string())
}

fn decode_jpeg(bytes: &[u8], into: &mut Frame) -> Result<(), image::ImageError> {
    let img = image::load_from_memory_with_format(bytes, image::ImageFormat::Jpeg)?.into_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    into.width = w;
    into.height = h;
    into.format = PixelFormat::Rgb8;
    into.data = img.into_raw();
    Ok(())
}

/// Resolves once the service starts shutting down.
async fn until_shutdown(rx: &mut watch::Receiver<bool>) {
    let _ = rx.wait_for(|s| *s).await;
}

/// Decrements the viewer gauge when a viewer's task ends.
struct ViewerGuard(Arc<Metrics>);

impl Drop for ViewerGuard {
    fn drop(&mut self) {
        self.0.live_viewers.dec();
    }
}

/// `GET /live`: a viewer's WebSocket.
pub async fn viewer(ws: WebSocketUpgrade, State(state): State<Arc<AppState>>) -> Response {
    ws.on_upgrade(move |socket| serve_viewer(socket, state))
}

async fn serve_viewer(mut socket: WebSocket, state: Arc<AppState>) {
    state.metrics.live_viewers.inc();
    let _guard = ViewerGuard(state.metrics.clone());
    let mut frames = state.live.subscribe();
    let mut shutdown = state.shutdown.subscribe();
    let mut last: Option<u64> = None;
    // Flow control: each frame is followed by a ping carrying its number;
    // the viewer's pong says it has read that far. A viewer that has not
    // read the last VIEWER_IN_FLIGHT frames gets none until it has, so
    // what it sees is never more than that many frames old.
    let mut sent = 0u64;
    let mut acked = 0u64;
    loop {
        tokio::select! {
            changed = frames.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(frame) = frames.borrow_and_update().clone() else { continue };
                if sent - acked >= VIEWER_IN_FLIGHT {
                    continue;
                }
                if let Some(prev) = last {
                    if frame.frame > prev + 1 {
                        state.metrics.live_dropped.inc_by(frame.frame - prev - 1);
                    }
                }
                last = Some(frame.frame);
                if socket.send(Message::Binary(frame.jpeg.clone())).await.is_err()
                    || socket.send(Message::Text(frame.meta.clone().into())).await.is_err()
                    || socket.send(Message::Ping(Bytes::copy_from_slice(&sent.to_be_bytes()))).await.is_err()
                {
                    break;
                }
                sent += 1;
            }
            msg = socket.recv() => match msg {
                Some(Ok(Message::Pong(payload))) => {
                    if let Ok(n) = <[u8; 8]>::try_from(payload.as_ref()) {
                        acked = acked.max(u64::from_be_bytes(n) + 1).min(sent);
                    }
                }
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                Some(Ok(_)) => {}
            },
            _ = until_shutdown(&mut shutdown) => {
                let _ = socket.send(Message::Close(None)).await;
                break;
            }
        }
    }
}

/// Marks the single publisher slot as taken while it lives.
struct PublisherSlot(Arc<AppState>);

impl Drop for PublisherSlot {
    fn drop(&mut self) {
        self.0.live.publisher.store(false, Ordering::SeqCst);
    }
}

/// `GET /live/ingest`: a publisher's WebSocket; each binary message is one JPEG frame.
pub async fn ingest(
    ws: WebSocketUpgrade,
    State(state): State<Arc<AppState>>,
) -> Result<Response, ApiError> {
    if let Some(source) = &state.live.config.source {
        return Err(ApiError::Conflict(format!(
            "the live feed comes from --live-source {source}; ingest is for a server started without it"
        )));
    }
    if state.live.publisher.swap(true, Ordering::SeqCst) {
        return Err(ApiError::Conflict(
            "another publisher is connected to /live/ingest; one at a time".into(),
        ));
    }
    let slot = PublisherSlot(state.clone());
    Ok(ws
        .max_message_size(MAX_INGEST_FRAME_BYTES)
        .on_upgrade(move |socket| serve_publisher(socket, slot)))
}

async fn serve_publisher(mut socket: WebSocket, slot: PublisherSlot) {
    let state = slot.0.clone();
    let mut shutdown = state.shutdown.subscribe();
    tracing::info!("live publisher connected");
    loop {
        tokio::select! {
            msg = socket.recv() => match msg {
                Some(Ok(Message::Binary(bytes))) => state.live.submit_jpeg(bytes),
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                Some(Ok(_)) => {}
            },
            _ = until_shutdown(&mut shutdown) => {
                let _ = socket.send(Message::Close(None)).await;
                break;
            }
        }
    }
    tracing::info!("live publisher disconnected");
    drop(slot);
}
