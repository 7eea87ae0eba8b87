//! The service on shared infrastructure (docs/service.md, "Scaling out"): `amc serve
//! --queue --store` replicas and `amc worker`s over a real PostgreSQL and a
//! real S3-compatible server (SeaweedFS), both started on loopback by the
//! harness ([`amc_e2e::services`], [`amc_e2e::cluster`]). Where they are not installed the tests
//! say so and pass, unless `AMC_REQUIRE_SERVICES=1` (CI sets it).
//!
//! The tests run one at a time (each starts its own database and store, and
//! the machine has two cores).

use amc_e2e::cluster::{metric, submit, wait_finished, Infra};
use amc_e2e::fixtures::{ffprobe_frames, test_clip};
use amc_e2e::server::{delete, get, post_multipart, wait_until, Reply, Server};
use std::collections::HashMap;
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant};

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Waits until the job has rendered some frames (it is being worked on).
fn wait_running(server: &Server, id: &str) -> u64 {
    let start = Instant::now();
    loop {
        let v = get(&server.url(&format!("/jobs/{id}"))).json();
        let f = v["frames_done"].as_u64().unwrap_or(0);
        if v["state"] == "running" && f > 0 {
            return f;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "job {id} never ran: {v}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn download(server: &Server, path: &str, to: &Path) -> Reply {
    let r = get(&server.url(path));
    if r.status == 200 {
        std::fs::write(to, &r.body).unwrap();
    }
    r
}

fn assert_empty(dir: &Path, what: &str) {
    let left: Vec<_> = std::fs::read_dir(dir)
        .map(|rd| rd.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    assert!(left.is_empty(), "{what} left files: {left:?}");
}

#[test]
fn two_replicas_and_two_workers_share_twenty_jobs() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Some(infra) = Infra::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    // Four lengths, so that each output's frame count names its input.
    let clips: Vec<(Vec<u8>, u64)> = [1.0, 1.5, 2.0, 2.5]
        .iter()
        .enumerate()
        .map(|(i, &secs)| {
            let p = dir.path().join(format!("clip{i}.mp4"));
            test_clip(&p, 160, 96, 30, secs);
            let frames = ffprobe_frames(&p);
            (std::fs::read(&p).unwrap(), frames)
        })
        .collect();
    // All four start at once on an empty database: each of the schema's
    // migrations runs once (sqlx holds an advisory lock), and every one starts.
    let (a, b, w1, w2) = std::thread::scope(|s| {
        let a = s.spawn(|| infra.replica(&[]));
        let b = s.spawn(|| infra.replica(&[]));
        let w1 = s.spawn(|| infra.worker(&[]));
        let w2 = s.spawn(|| infra.worker(&[]));
        (
            a.join().unwrap(),
            b.join().unwrap(),
            w1.join().unwrap(),
            w2.join().unwrap(),
        )
    });
    assert_eq!(
        infra
            .pg
            .psql("SELECT count(*) FROM _sqlx_migrations WHERE success"),
        migration_count().to_string()
    );
    let mut expected = HashMap::new();
    for i in 0..20 {
        let (clip, frames) = &clips[i % clips.len()];
        let id = submit(&a, clip, "n_avg=2");
        expected.insert(id, *frames);
    }
    // Replica B lists every one of them.
    let listed = get(&b.url("/jobs?limit=100")).json();
    let listed: Vec<&str> = listed["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["id"].as_str().unwrap())
        .collect();
    for id in expected.keys() {
        assert!(listed.contains(&id.as_str()), "B does not list {id}");
    }
    for (id, frames) in &expected {
        let v = wait_finished(&b, id, Duration::from_secs(240));
        assert_eq!(v["state"], "done", "{v}");
        assert_eq!(v["progress"], 1.0);
        assert_eq!(v["metrics"]["frames"].as_u64(), Some(*frames), "{v}");
        let out = dir.path().join(format!("{id}.mp4"));
        let r = download(&b, &format!("/jobs/{id}/output"), &out);
        assert_eq!(r.status, 200, "{}", r.text());
        assert_eq!(r.header("content-type"), Some("video/mp4"));
        assert_eq!(ffprobe_frames(&out), *frames, "job {id}'s output");
        let t = get(&b.url(&format!("/jobs/{id}/telemetry.csv")));
        assert_eq!(t.status, 200);
        assert!(t.text().starts_with("frame,t,rx,ry,rz,vx,vy,vz"));
        assert_eq!(
            t.text().lines().count() as u64,
            frames + 1,
            "job {id}'s telemetry"
        );
    }
    // Both workers took jobs, and between them ran each once.
    let done = |w: &Server| {
        metric(
            &get(&w.url("/metrics")).text(),
            "amc_jobs_finished_total{state=\"done\"}",
        )
    };
    let (d1, d2) = (done(&w1), done(&w2));
    assert_eq!(d1 + d2, 20.0, "worker 1 ran {d1}, worker 2 ran {d2}");
    assert!(
        d1 >= 1.0 && d2 >= 1.0,
        "worker 1 ran {d1}, worker 2 ran {d2}"
    );
    let m = get(&a.url("/metrics")).text();
    assert_eq!(metric(&m, "amc_jobs{state=\"done\"}"), 20.0, "{m}");
    assert_eq!(metric(&m, "amc_queue_depth"), 0.0);
    for s in [&a, &b, &w1, &w2] {
        assert_eq!(get(&s.url("/healthz")).status, 200);
    }
    // Removed through B, the jobs leave no row and no object.
    for id in expected.keys() {
        assert_eq!(delete(&b.url(&format!("/jobs/{id}"))).status, 204);
        assert_eq!(get(&a.url(&format!("/jobs/{id}"))).status, 404);
    }
    assert_eq!(infra.rows(), 0);
    assert_eq!(infra.s3.object_keys(), Vec::<String>::new());
    a.assert_no_scratch_left(Duration::from_secs(5));
    b.assert_no_scratch_left(Duration::from_secs(5));
    assert_empty(w1.work_parent.path(), "worker 1");
    assert_empty(w2.work_parent.path(), "worker 2");
}

/// A clip long enough to kill or stop its worker mid-run (640x360, 30 s):
/// its worker writes progress twice a second, and an unloaded machine
/// stabilizes 8 s of it (240 frames) in 0.63 s, before a poll had seen the
/// job running.
fn long_clip(dir: &Path) -> (Vec<u8>, u64) {
    let p = dir.join("long.mp4");
    test_clip(&p, 640, 360, 30, 30.0);
    (std::fs::read(&p).unwrap(), ffprobe_frames(&p))
}

#[test]
fn a_killed_workers_job_is_finished_by_another_once() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Some(infra) = Infra::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (clip, frames) = long_clip(dir.path());
    let api = infra.replica(&[]);
    let mut w1 = infra.worker(&["--lease-secs", "3"]);
    let id = submit(&api, &clip, "");
    let seen = wait_running(&api, &id);
    w1.kill();
    let killed = Instant::now();
    // The killed worker could not remove its job's folder.
    assert_eq!(std::fs::read_dir(w1.work_parent.path()).unwrap().count(), 1);
    // A worker started in the same work dir removes it (its process is gone).
    let w2 = infra.worker_in(w1.work_parent.path(), &["--lease-secs", "3"]);
    let v = wait_finished(&api, &id, Duration::from_secs(120));
    assert_eq!(v["state"], "done", "{v}");
    // Not before the dead worker's lease ran out.
    assert!(
        killed.elapsed() >= Duration::from_secs(2),
        "{:?}",
        killed.elapsed()
    );
    assert!(v["frames_done"].as_u64().unwrap() >= seen);
    assert_eq!(infra.attempts(&id), 2);
    // One output, written by the second claim; the first wrote none.
    let objects = infra.objects_of(&id);
    assert_eq!(
        objects
            .iter()
            .filter(|k| k.contains("/output.") || k.ends_with("telemetry.csv"))
            .count(),
        2,
        "{objects:?}"
    );
    assert!(
        objects.iter().all(|k| k.contains(&format!("{id}/2/"))),
        "{objects:?}"
    );
    let out = dir.path().join("out.mp4");
    assert_eq!(
        download(&api, &format!("/jobs/{id}/output"), &out).status,
        200
    );
    assert_eq!(ffprobe_frames(&out), frames);
    let m = get(&w2.url("/metrics")).text();
    assert_eq!(metric(&m, "amc_job_retries"), 1.0, "{m}");
    assert_empty(w1.work_parent.path(), "the shared work dir");
}

#[test]
fn a_worker_stopped_with_sigterm_hands_its_job_back() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Some(infra) = Infra::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (clip, frames) = long_clip(dir.path());
    let api = infra.replica(&[]);
    let mut w1 = infra.worker(&[]);
    let id = submit(&api, &clip, "");
    wait_running(&api, &id);
    let stopped = Instant::now();
    let status = w1
        .terminate(Duration::from_secs(10))
        .expect("worker 1 stops on SIGTERM");
    assert!(status.success(), "{status:?}");
    assert!(
        stopped.elapsed() < Duration::from_secs(5),
        "{:?}",
        stopped.elapsed()
    );
    assert_empty(w1.work_parent.path(), "the stopped worker");
    // Back in the queue at once, the attempt not counted.
    let v = get(&api.url(&format!("/jobs/{id}"))).json();
    assert_eq!(v["state"], "queued", "{v}");
    assert_eq!(infra.attempts(&id), 0);
    let _w2 = infra.worker(&[]);
    let v = wait_finished(&api, &id, Duration::from_secs(120));
    assert_eq!(v["state"], "done", "{v}");
    assert_eq!(infra.attempts(&id), 1);
    let out = dir.path().join("out.mp4");
    assert_eq!(
        download(&api, &format!("/jobs/{id}/output"), &out).status,
        200
    );
    assert_eq!(ffprobe_frames(&out), frames);
}

#[test]
fn a_restarted_api_still_knows_the_job_and_its_progress() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Some(infra) = Infra::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (clip, frames) = long_clip(dir.path());
    let mut api = infra.replica(&[]);
    let _worker = infra.worker(&[]);
    let id = submit(&api, &clip, "");
    let seen = wait_running(&api, &id);
    assert!(api.terminate(Duration::from_secs(20)).is_some());
    let api = infra.replica(&[]);
    let v = get(&api.url(&format!("/jobs/{id}"))).json();
    assert!(
        v["frames_done"].as_u64().unwrap() >= seen,
        "progress lost across the restart: {seen} then {v}"
    );
    let v = wait_finished(&api, &id, Duration::from_secs(120));
    assert_eq!(v["state"], "done", "{v}");
    let out = dir.path().join("out.mp4");
    assert_eq!(
        download(&api, &format!("/jobs/{id}/output"), &out).status,
        200
    );
    assert_eq!(ffprobe_frames(&out), frames);
}

fn assert_503(r: &Reply, what: &str) {
    assert_eq!(r.status, 503, "{what}: {}", r.text());
    assert!(r.header("retry-after").is_some(), "{what}: no Retry-After");
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
}

#[test]
fn an_unreachable_database_or_store_is_503_and_the_service_recovers() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Some(mut infra) = Infra::start() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("clip.mp4");
    test_clip(&p, 160, 96, 30, 1.0);
    let clip = std::fs::read(&p).unwrap();
    let api = infra.replica(&[]);
    let worker = infra.worker(&[]);
    let done = submit(&api, &clip, "");
    assert_eq!(
        wait_finished(&api, &done, Duration::from_secs(60))["state"],
        "done"
    );
    let objects_before = infra.s3.object_keys();

    infra.pg.stop();
    let t = Instant::now();
    assert_503(&get(&api.url(&format!("/jobs/{done}"))), "GET /jobs/{id}");
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    assert_503(&get(&api.url("/jobs")), "GET /jobs");
    assert_503(
        &delete(&api.url(&format!("/jobs/{done}"))),
        "DELETE /jobs/{id}",
    );
    let r = amc_e2e::server::post(&api.url("/jobs"), "video/mp4", &clip);
    assert_503(&r, "POST /jobs");
    assert_eq!(get(&api.url("/healthz")).status, 503);
    assert_eq!(get(&worker.url("/healthz")).status, 503);
    infra.pg.start_again();
    wait_until("the API answers again", Duration::from_secs(20), || {
        get(&api.url(&format!("/jobs/{done}"))).status == 200
    });
    // The refused upload left nothing behind.
    assert_eq!(infra.s3.object_keys(), objects_before);

    infra.s3.stop();
    assert_503(
        &get(&api.url(&format!("/jobs/{done}/output"))),
        "GET output",
    );
    let r = amc_e2e::server::post(&api.url("/jobs"), "video/mp4", &clip);
    assert_503(&r, "POST /jobs");
    assert_eq!(get(&api.url("/healthz")).status, 503);
    assert_eq!(infra.rows(), 1, "a refused upload left a row");
    infra.s3.start_again();
    wait_until("the store answers again", Duration::from_secs(20), || {
        get(&api.url(&format!("/jobs/{done}/output"))).status == 200
    });
    // And the whole path works again.
    let again = submit(&api, &clip, "");
    assert_eq!(
        wait_finished(&api, &again, Duration::from_secs(60))["state"],
        "done"
    );
    assert_eq!(get(&api.url("/healthz")).status, 200);
    for s in [&api, &worker] {
        assert!(!s.log().contains("panic"), "{}", s.log());
    }
    api.assert_no_scratch_left(Duration::from_secs(5));
}

#[test]
fn expired_jobs_leave_no_rows_or_objects() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Some(infra) = Infra::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("clip.mp4");
    test_clip(&p, 160, 96, 30, 1.0);
    let clip = std::fs::read(&p).unwrap();
    let api = infra.replica(&["--job-ttl", "2"]);
    let worker = infra.worker(&["--job-ttl", "2"]);
    let done = submit(&api, &clip, "");
    assert_eq!(
        wait_finished(&api, &done, Duration::from_secs(60))["state"],
        "done"
    );
    assert!(!infra.objects_of(&done).is_empty());
    // A lens file that cannot be read fails the job in the worker, saying why.
    let r = post_multipart(
        &api.url("/jobs"),
        &[
            ("video", "clip.mp4", "video/mp4", &clip),
            ("lens", "l.json", "application/json", b"{not json"),
        ],
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let failed = r.json()["id"].as_str().unwrap().to_string();
    let v = wait_finished(&api, &failed, Duration::from_secs(60));
    assert_eq!(v["state"], "failed", "{v}");
    assert!(v["error"].as_str().unwrap().contains("lens"), "{v}");
    wait_until("expiry", Duration::from_secs(30), || {
        infra.rows() == 0 && infra.s3.object_count() == 0
    });
    assert_eq!(get(&api.url(&format!("/jobs/{done}"))).status, 404);
    assert_eq!(get(&api.url(&format!("/jobs/{failed}"))).status, 404);
    api.assert_no_scratch_left(Duration::from_secs(5));
    assert_empty(worker.work_parent.path(), "the worker");
}

#[test]
fn a_cancelled_job_stops_its_worker_within_a_second() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Some(infra) = Infra::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (clip, _) = long_clip(dir.path());
    let api = infra.replica(&[]);
    let worker = infra.worker(&[]);
    let id = submit(&api, &clip, "");
    wait_running(&api, &id);
    let t = Instant::now();
    let r = delete(&api.url(&format!("/jobs/{id}")));
    let took = t.elapsed();
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json()["state"], "cancelled");
    // DELETE answers once the worker has let go of the job.
    assert!(took < Duration::from_millis(1500), "{took:?}");
    let m = get(&worker.url("/metrics")).text();
    assert_eq!(
        metric(&m, "amc_jobs_finished_total{state=\"cancelled\"}"),
        1.0,
        "{m}"
    );
    assert_eq!(get(&worker.url("/healthz")).json()["busy"], false);
    assert!(worker.ffmpeg_children().is_empty());
    assert_empty(worker.work_parent.path(), "the worker");
    // Its upload stays until it is removed; then nothing is left.
    assert_eq!(delete(&api.url(&format!("/jobs/{id}"))).status, 204);
    assert_eq!(infra.rows(), 0);
    assert!(infra.objects_of(&id).is_empty());
}

/// A gyro log sent with the clip (the `gyro` form part) goes into the bucket beside the
/// upload, reaches the worker, is used (the job's metrics report its sync and fusion), and
/// leaves the bucket with the upload; one that cannot be read is refused before a job exists.
#[test]
fn a_gyro_log_travels_beside_the_upload_and_leaves_with_it() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Some(infra) = Infra::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (clip, video) = amc_e2e::synth_clip_with_gyro(dir.path(), 2.0);
    let (video, lens, log) = (
        std::fs::read(video).unwrap(),
        std::fs::read(clip.join("lens.json")).unwrap(),
        std::fs::read(clip.join("gyro.gcsv")).unwrap(),
    );
    let api = infra.replica(&[]);
    let form = |log: &[u8]| {
        post_multipart(
            &api.url("/jobs?metrics=false"),
            &[
                ("video", "clip.mp4", "video/mp4", &video),
                ("lens", "lens.json", "application/json", &lens),
                ("gyro", "flight.gcsv", "text/csv", log),
            ],
        )
    };
    // Refused at once: no row, nothing in the bucket.
    let r = form(b"not a log\n1,2\n");
    assert_eq!(r.status, 422, "{}", r.text());
    assert!(
        r.text().contains("no gyro log telemetry-parser knows"),
        "{}",
        r.text()
    );
    assert_eq!(infra.rows(), 0);
    assert_eq!(infra.s3.object_count(), 0);
    // Queued before any worker runs: the log sits beside the upload.
    let r = form(&log);
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let objects = infra.objects_of(&id);
    assert!(
        objects.iter().any(|k| k.ends_with(&format!("{id}/input"))),
        "{objects:?}"
    );
    assert!(
        objects
            .iter()
            .any(|k| k.ends_with(&format!("{id}/gyro.gcsv"))),
        "{objects:?}"
    );
    let worker = infra.worker(&[]);
    let v = wait_finished(&api, &id, Duration::from_secs(120));
    assert_eq!(v["state"], "done", "{v}\n{}", worker.log());
    let g = &v["metrics"]["gyro"];
    assert!(
        g["source"]
            .as_str()
            .is_some_and(|s| s.contains("amc-synth")),
        "{v}"
    );
    let offset_ms = (g["offset_s"].as_f64().unwrap() - amc_e2e::GYRO_CLIP_OFFSET_S) * 1e3;
    assert!(
        offset_ms.abs() < 2.0,
        "offset off by {offset_ms:.3} ms: {g}"
    );
    assert!(g["fused_frames"].as_u64().is_some_and(|n| n > 60), "{g}");
    // Done: the upload and its log have left the bucket; the results stay.
    let objects = infra.objects_of(&id);
    assert!(
        objects
            .iter()
            .all(|k| !k.ends_with("/input") && !k.contains("/gyro")),
        "{objects:?}"
    );
    assert_eq!(delete(&api.url(&format!("/jobs/{id}"))).status, 204);
    assert!(infra.objects_of(&id).is_empty());
    api.assert_no_scratch_left(Duration::from_secs(5));
    assert_empty(worker.work_parent.path(), "the worker");
}

/// How many migrations the server embeds: one file each in amc-server/migrations.
fn migration_count() -> usize {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../amc-server/migrations");
    std::fs::read_dir(dir)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "sql"))
        })
        .count()
}
