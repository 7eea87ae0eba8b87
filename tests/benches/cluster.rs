//! `cargo bench -p amc-e2e --bench cluster`: how jobs/hour scale with the
//! number of `amc worker`s (docs/service.md, "Scaling out").
//!
//! A real PostgreSQL and SeaweedFS on loopback (the tests' harness: both
//! must be installed), one `amc serve --queue --store` replica, and N short
//! clips (640x360, 30 fps, 4 s, H.264) queued while no worker runs. Then 1,
//! then 2 workers run the whole queue, each limited to one thread
//! (`--threads 1`, which also caps its ffmpeg decoder and encoder at one
//! thread) and confined to a core of its own (`taskset -c i`, its ffmpeg
//! children included: a job's decoder, stabilizer and encoder are three
//! processes, which one thread of ours does not bound); the wall time from the
//! workers' start to the last job done gives jobs/hour. Rounds alternate (1, 2, 1, 2, ...) and the best of each is
//! kept, since the machine is shared. `AMC_BENCH_JOBS` (default 12) and
//! `AMC_BENCH_ROUNDS` (default 2) change the sizes.

use amc_e2e::cluster::{submit, wait_finished, Infra};
use amc_e2e::fixtures::test_clip;
use amc_e2e::server::delete;
use std::time::{Duration, Instant};

fn env_or(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Seconds for `workers` single-threaded workers to run `jobs` queued clips.
fn round(infra: &Infra, clip: &[u8], jobs: usize, workers: usize) -> f64 {
    let api = infra.replica(&[]);
    let ids: Vec<String> = (0..jobs).map(|_| submit(&api, clip, "")).collect();
    let start = Instant::now();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let pool: Vec<_> = (0..workers)
        .map(|i| infra.worker_on_core(i % cores))
        .collect();
    for id in &ids {
        let v = wait_finished(&api, id, Duration::from_secs(1800));
        assert_eq!(v["state"], "done", "{v}");
    }
    let secs = start.elapsed().as_secs_f64();
    drop(pool);
    for id in &ids {
        delete(&api.url(&format!("/jobs/{id}")));
    }
    secs
}

fn main() {
    std::env::set_var("AMC_REQUIRE_SERVICES", "1");
    let infra = Infra::start().expect("PostgreSQL and SeaweedFS are required");
    let jobs = env_or("AMC_BENCH_JOBS", 12);
    let rounds = env_or("AMC_BENCH_ROUNDS", 2);
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("clip.mp4");
    test_clip(&path, 640, 360, 30, 4.0);
    let clip = std::fs::read(&path).expect("clip");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "{jobs} jobs of a 640x360 30 fps 4 s clip, workers with --threads 1 each on a core of its own, {cores} cores"
    );
    let mut best = [f64::INFINITY; 2];
    for r in 0..rounds {
        for (i, workers) in [1usize, 2].into_iter().enumerate() {
            let secs = round(&infra, &clip, jobs, workers);
            println!(
                "round {}: {workers} worker(s): {secs:.1} s, {:.0} jobs/hour",
                r + 1,
                jobs as f64 * 3600.0 / secs
            );
            best[i] = best[i].min(secs);
        }
    }
    let rate = |secs: f64| jobs as f64 * 3600.0 / secs;
    println!(
        "best: 1 worker {:.0} jobs/hour, 2 workers {:.0} jobs/hour: {:.2}x",
        rate(best[0]),
        rate(best[1]),
        best[0] / best[1]
    );
}
