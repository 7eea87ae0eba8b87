//! `GET /metrics`: the service's state, in OpenMetrics 1.0 for a scraper
//! that asks for it (Prometheus does) and in Prometheus' classic text format
//! otherwise ([`Metrics::response`]).
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

    /// The exposition in OpenMetrics 1.0 (a counter's family is named
    /// without `_total`, its sample with it; `# EOF` ends it).
    pub fn encode(&self) -> String {
        self.sample();
        let mut out = String::new();
        if prometheus_client::encoding::text::encode(&mut out, &self.registry).is_err() {
            out.clear();
        }
        out
    }

    /// `GET /metrics`' answer, in the format the scraper asks for: OpenMetrics
    /// when its `Accept` prefers `application/openmetrics-text` (Prometheus
    /// does), else Prometheus' classic text format 0.0.4 (curl, a person,
    /// older scrapers). Each with the Content-Type that says which.
    pub fn response(&self, accept: Option<&HeaderValue>) -> Response {
        let openmetrics = accept
            .and_then(|a| a.to_str().ok())
            .is_some_and(prefers_openmetrics);
        let text = self.encode();
        let (body, content_type) = if openmetrics {
            (text, OPENMETRICS)
        } else {
            (classic_text(&text), CLASSIC_TEXT)
        };
        let mut res = body.into_response();
        let h = res.headers_mut();
        h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
        h.insert(header::VARY, HeaderValue::from_static("accept"));
        res
    }
}

/// The Content-Type of OpenMetrics 1.0.
pub const OPENMETRICS: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";
/// The Content-Type of Prometheus' classic text format.
pub const CLASSIC_TEXT: &str = "text/plain; version=0.0.4; charset=utf-8";

/// Whether an `Accept` header ranks `application/openmetrics-text` above
/// (or with) the classic text (`text/plain`, `text/*`, `*/*`).
fn prefers_openmetrics(accept: &str) -> bool {
    let (mut openmetrics, mut text) = (0.0f32, 0.0f32);
    for range in accept.split(',') {
        let mut parts = range.split(';').map(str::trim);
        let media = parts.next().unwrap_or("").to_ascii_lowercase();
        let q = parts
            .find_map(|p| p.strip_prefix("q="))
            .map_or(Some(1.0), |q| q.trim().parse::<f32>().ok())
            .unwrap_or(0.0);
        match media.as_str() {
            "application/openmetrics-text" => openmetrics = openmetrics.max(q),
            "text/plain" | "text/*" | "*/*" => text = text.max(q),
            _ => {}
        }
    }
    openmetrics > 0.0 && openmetrics >= text
}

/// Prometheus' classic text format from the OpenMetrics text: a counter's
/// `# HELP` and `# TYPE` name its samples (`amc_frames_processed_total`), as
/// that format requires; no `# UNIT`, no `# EOF`. Samples are written alike
/// in both.
fn classic_text(openmetrics: &str) -> String {
    let counters: std::collections::HashSet<&str> = openmetrics
        .lines()
        .filter_map(|l| l.strip_prefix("# TYPE ")?.strip_suffix(" counter"))
        .collect();
    let mut out = String::with_capacity(openmetrics.len() + 16 * counters.len());
    for line in openmetrics.lines() {
        if line == "# EOF" || line.starts_with("# UNIT ") {
            continue;
        }
        let meta = ["# HELP ", "# TYPE "]
            .into_iter()
            .find_map(|p| Some((p, line.strip_prefix(p)?)));
        match meta {
            Some((prefix, rest)) => {
                let (name, tail) = match rest.split_once(' ') {
                    Some((name, tail)) => (name, Some(tail)),
                    None => (rest, None),
                };
                out.push_str(prefix);
                out.push_str(name);
                if counters.contains(name) && !name.ends_with("_total") {
                    out.push_str("_total");
                }
                if let Some(tail) = tail {
                    out.push(' ');
                    out.push_str(tail);
                }
            }
            None => out.push_str(line),
        }
        out.push('\n');
    }
    out
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn openmetrics_only_for_a_scraper_that_prefers_it() {
        // Prometheus 2 and 3.
        assert!(prefers_openmetrics(
            "application/openmetrics-text;version=1.0.0,application/openmetrics-text;version=0.0.1;q=0.75,text/plain;version=0.0.4;q=0.5,*/*;q=0.1"
        ));
        assert!(prefers_openmetrics(
            "application/openmetrics-text;version=1.0.0;escaping=allow-utf-8,text/plain;version=1.0.0;q=0.8,*/*;q=0.6"
        ));
        for accept in [
            "*/*",
            "text/plain",
            "text/plain;version=0.0.4",
            "text/plain, application/openmetrics-text;q=0.5",
            "application/openmetrics-text;q=0",
            "application/json",
        ] {
            assert!(!prefers_openmetrics(accept), "{accept}");
        }
    }

    #[test]
    fn the_classic_text_names_counters_as_their_samples() {
        let m = Metrics::new();
        m.reject(400);
        let om = m.encode();
        assert!(om.contains("# TYPE amc_frames_processed counter\n"), "{om}");
        assert!(om.ends_with("# EOF\n"), "{om}");
        let classic = classic_text(&om);
        for name in ["amc_frames_processed", "amc_requests_rejected"] {
            assert!(
                classic.contains(&format!("# TYPE {name}_total counter\n"))
                    && classic.contains(&format!("# HELP {name}_total ")),
                "{classic}"
            );
        }
        assert!(classic.contains("amc_requests_rejected_total{status=\"400\"} 1\n"));
        assert!(
            classic.contains("# TYPE amc_live_viewers gauge\n"),
            "{classic}"
        );
        assert!(!classic.contains("# EOF"), "{classic}");
        // Everything else is as OpenMetrics writes it.
        assert_eq!(
            classic.lines().count() + 1,
            om.lines().count(),
            "{om}\n{classic}"
        );
    }
}
