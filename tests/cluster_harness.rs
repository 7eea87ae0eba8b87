//! A job table and a bucket on loopback (a real PostgreSQL and SeaweedFS,
//! from [`super::services`]) and `amc serve --queue --store` replicas and
//! `amc worker`s pointed at them, for the scale-out tests and bench.

use super::server::{get, post, Server};
use super::services::{Postgres, SeaweedS3};
use std::time::{Duration, Instant};

/// A database and a bucket, and how to point `amc` at them.
pub struct Infra {
    pub pg: Postgres,
    pub s3: SeaweedS3,
}

impl Infra {
    pub fn start() -> Option<Infra> {
        Some(Infra {
            pg: Postgres::start()?,
            s3: SeaweedS3::start()?,
        })
    }

    /// `--queue`, `--store` and the bucket's endpoint and credentials, then `extra`.
    pub fn args(&self, extra: &[&str]) -> Vec<String> {
        let mut a: Vec<String> = vec![
            "--queue".into(),
            self.pg.url(),
            "--store".into(),
            format!("s3://{}/amc-test", self.s3.bucket()),
            "--s3-endpoint".into(),
            self.s3.endpoint(),
            "--s3-region".into(),
            self.s3.region().into(),
            "--s3-access-key-id".into(),
            self.s3.access_key().into(),
            "--s3-secret-access-key".into(),
            self.s3.secret_key().into(),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    }

    pub fn replica(&self, extra: &[&str]) -> Server {
        let args = self.args(extra);
        Server::start(&args.iter().map(String::as_str).collect::<Vec<_>>())
    }

    pub fn worker(&self, extra: &[&str]) -> Server {
        let mut args = self.args(&["--threads", "1"]);
        args.extend(extra.iter().map(|s| s.to_string()));
        Server::worker(&args.iter().map(String::as_str).collect::<Vec<_>>())
    }

    /// A single-threaded worker in another worker's `--work-dir`.
    pub fn worker_in(&self, dir: &std::path::Path, extra: &[&str]) -> Server {
        let mut args = self.args(&["--threads", "1"]);
        args.extend(extra.iter().map(|s| s.to_string()));
        Server::worker_in(dir, &args.iter().map(String::as_str).collect::<Vec<_>>())
    }

    /// A single-threaded worker confined to one CPU core (with its ffmpeg children).
    pub fn worker_on_core(&self, core: usize) -> Server {
        let args = self.args(&["--threads", "1"]);
        Server::worker_on_core(core, &args.iter().map(String::as_str).collect::<Vec<_>>())
    }

    pub fn rows(&self) -> usize {
        self.pg
            .psql("SELECT count(*) FROM amc_jobs")
            .trim()
            .parse()
            .unwrap()
    }

    /// The job's claims so far.
    pub fn attempts(&self, id: &str) -> i64 {
        self.pg
            .psql(&format!("SELECT attempts FROM amc_jobs WHERE id = '{id}'"))
            .trim()
            .parse()
            .unwrap()
    }

    pub fn objects_of(&self, id: &str) -> Vec<String> {
        self.s3
            .object_keys()
            .into_iter()
            .filter(|k| k.contains(id))
            .collect()
    }
}

pub fn submit(server: &Server, clip: &[u8], query: &str) -> String {
    let r = post(&server.url(&format!("/jobs?{query}")), "video/mp4", clip);
    assert_eq!(r.status, 202, "POST /jobs: {}", r.text());
    r.json()["id"].as_str().unwrap().to_string()
}

/// Polls the job through `server` until it is finished, checking that its
/// progress never goes back; the final view.
pub fn wait_finished(server: &Server, id: &str, within: Duration) -> serde_json::Value {
    let start = Instant::now();
    let (mut frames, mut progress) = (0u64, 0f64);
    loop {
        let r = get(&server.url(&format!("/jobs/{id}")));
        assert_eq!(r.status, 200, "GET /jobs/{id}: {}", r.text());
        let v = r.json();
        let f = v["frames_done"].as_u64().unwrap();
        let p = v["progress"].as_f64().unwrap_or(0.0);
        assert!(
            f >= frames && p >= progress,
            "job {id}'s progress went back: {frames} -> {f} frames, {progress} -> {p}"
        );
        (frames, progress) = (f, p);
        let state = v["state"].as_str().unwrap().to_string();
        if ["done", "failed", "cancelled"].contains(&state.as_str()) {
            return v;
        }
        assert!(
            start.elapsed() < within,
            "job {id} still {state} after {within:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A metric's value in a Prometheus text page (0 when absent).
pub fn metric(page: &str, name: &str) -> f64 {
    page.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
        .unwrap_or(0.0)
}
