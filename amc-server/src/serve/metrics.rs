//! `GET /metrics`: the service's state in the Prometheus text format.
//!
//! ```text
//! amc_jobs{state}                      jobs by state (queued, running, done, failed, cancelled)
//! amc_frames_processed_total           output frames of requests, jobs and the live feed
//! amc_processing_frames_per_second     frames processed over the last RATE_WINDOW
//! amc_requests_in_flight               POST /stabilize requests being received or processed
//! amc_requests_rejected_total{status}  requests refused (4xx/503)
//! amc_live_viewers                     WebSocket viewers of /live
//! amc_live_frames_total                frames stabilized by the live feed
//! amc_live_frames_dropped_total        live frames not processed (processor busy) or skipped by a slow viewer
//! amc_disk_used_bytes / amc_disk_limit_bytes   scratch space of uploads and results
//! amc_queue_depth                      jobs waiting for a worker (all replicas, with --queue)
//! amc_job_retries                      claims beyond the first, over the jobs in the table
//! amc_job_duration_seconds             histogram of the runs this process finished
//! amc_jobs_finished_total{state}       runs this process finished, by outcome
//! ```

use axum::http::{header, HeaderValue};
use axum::response::{IntoResponse, Response};
use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{exponential_buckets, Histogram};
use prometheus_client::registry::Registry;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Window of the processing-rate gauge.
pub const RATE_WINDOW: Duration = Duration::from_secs(10);

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct StateLabel {
    pub state: &'static str,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct StatusLabel {
    pub status: u16,
}

pub struct Metrics {
    registry: Registry,
    pub jobs: Family<StateLabel, Gauge>,
    /// Incremented by every run (through `RunControl`) and by the live feed.
    pub frames_processed: Arc<AtomicU64>,
    frames_counter: Counter,
    rate: Gauge<f64, AtomicU64>,
    samples: Mutex<VecDeque<(Instant, u64)>>,
    pub in_flight: Gauge,
    pub rejected: Family<StatusLabel, Counter>,
    pub live_viewers: Gauge,
    pub live_frames: Counter,
    pub live_dropped: Counter,
    pub disk_used: Gauge,
    pub disk_limit: Gauge,
    pub queue_depth: Gauge,
    pub job_retries: Gauge,
    pub job_duration: Histogram,
    pub jobs_finished: Family<StateLabel, Counter>,
}

impl Metrics {
    pub fn new() -> Self {
        let mut registry = Registry::with_prefix("amc");
        let jobs = Family::<StateLabel, Gauge>::default();
        registry.register("jobs", "Jobs by state", jobs.clone());
        let frames_counter = Counter::default();
        registry.register(
            "frames_processed",
            "Output frames of requests, jobs and the live feed",
            frames_counter.clone(),
        );
        let rate = Gauge::<f64, AtomicU64>::default();
        registry.register(
            "processing_frames_per_second",
            "Frames processed per second over the last 10 s",
            rate.clone(),
        );
        let in_flight = Gauge::default();
        registry.register(
            "requests_in_flight",
            "POST /stabilize requests being received or processed",
            in_flight.clone(),
        );
        let rejected = Family::<StatusLabel, Counter>::default();
        registry.register(
            "requests_rejected",
            "Requests refused, by HTTP status",
            rejected.clone(),
        );
        let live_viewers = Gauge::default();
        registry.register(
            "live_viewers",
            "WebSocket viewers of /live",
            live_viewers.clone(),
        );
        let live_frames = Counter::default();
        registry.register(
            "live_frames",
            "Frames stabilized by the live feed",
            live_frames.clone(),
        );
        let live_dropped = Counter::default();
        registry.register(
            "live_frames_dropped",
            "Live frames not processed (processor busy) or skipped by a slow viewer",
            live_dropped.clone(),
        );
        let disk_used = Gauge::default();
        registry.register("disk_used_bytes", "Scratch space in use", disk_used.clone());
        let disk_limit = Gauge::default();
        registry.register(
            "disk_limit_bytes",
            "Scratch space allowed",
            disk_limit.clone(),
        );
        let queue_depth = Gauge::default();
        registry.register(
            "queue_depth",
            "Jobs waiting for a worker",
            queue_depth.clone(),
        );
        let job_retries = Gauge::default();
        registry.register(
            "job_retries",
            "Claims beyond the first (a worker died), summed over the jobs kept",
            job_retries.clone(),
        );
        // 0.5 s to ~35 min.
        let job_duration = Histogram::new(exponential_buckets(0.5, 2.0, 13));
        registry.register(
            "job_duration_seconds",
            "Wall time of the job runs this process finished",
            job_duration.clone(),
        );
        let jobs_finished = Family::<StateLabel, Counter>::default();
        registry.register(
            "jobs_finished",
            "Job runs this process finished, by outcome",
            jobs_finished.clone(),
        );
        Self {
            registry,
            jobs,
            queue_depth,
            job_retries,
            job_duration,
            jobs_finished,
            frames_processed: Arc::new(AtomicU64::new(0)),
            frames_counter,
            rate,
            samples: Mutex::new(VecDeque::new()),
            in_flight,
            rejected,
            live_viewers,
            live_frames,
            live_dropped,
            disk_used,
            disk_limit,
        }
    }

    /// Brings the frame counter and the rate up to date (called every second and on scrape).
    pub fn sample(&self) {
        let now = Instant::now();
        let total = self.frames_processed.load(Ordering::Relaxed);
        let seen = self.frames_counter.get();
        if total > seen {
            self.frames_counter.inc_by(total - seen);
        }
        let mut samples = self.samples.lock().unwrap_or_else(|e| e.into_inner());
        samples.push_back((now, total));
        while samples
            .front()
            .is_some_and(|(t, _)| now.duration_since(*t) > RATE_WINDOW)
        {
            samples.pop_front();
        }
        if let (Some(&(t0, n0)), Some(&(t1, n1))) = (samples.front(), samples.back()) {
            let dt = t1.duration_since(t0).as_secs_f64();
            self.rate
                .set(if dt > 0.0 { (n1 - n0) as f64 / dt } else { 0.0 });
        }
    }

    /// Records a finished job run: its outcome and how long it took.
    pub fn job_finished(&self, state: &'static str, seconds: f64) {
        self.jobs_finished
            .get_or_create(&StateLabel { state })
            .inc();
        self.job_duration.observe(seconds);
    }

    pub fn reject(&self, status: u16) {
        self.rejected.get_or_create(&StatusLabel { status }).inc();
    }

    /// The text exposition.
    pub fn encode(&self) -> String {
        self.sample();
        let mut out = String::new();
        if prometheus_client::encoding::text::encode(&mut out, &self.registry).is_err() {
            out.clear();
        }
        out
    }

    /// `GET /metrics`' answer: [`Metrics::encode`] as Prometheus' text format.
    pub fn response(&self) -> Response {
        let mut res = self.encode().into_response();
        res.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"),
        );
        res
    }
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}
