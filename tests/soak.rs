//! Soak test of `amc serve` (issue 14, "Hardening"): one real server on a loopback port under
//! a bounded run of mixed traffic, its memory and open file descriptors sampled throughout.
//!
//! ```sh
//! cargo test --release -p amc-e2e --test soak -- --nocapture                     # 45 s
//! AMC_SOAK_SECS=600 cargo test --release -p amc-e2e --test soak -- --nocapture   # 10 minutes
//! ```
//!
//! Traffic, for `AMC_SOAK_SECS` seconds (default 45), one thread per kind, every loop bounded
//! in count and time, 127.0.0.1 only:
//! - good uploads: a 160x90 1 s clip to `POST /stabilize` (raw body, multipart, WebM): 200;
//! - bad requests: random bytes, a truncated MP4, a PNG, text, an empty body, bad options, a
//!   broken form, a clip over the size limit, a declared length over the upload limit, unknown
//!   job ids, wrong methods, a plain GET of `/live`: each its exact 4xx;
//! - jobs: `POST /jobs`, polled to `done`, output and telemetry fetched, then deleted (204);
//! - cancels: `POST /jobs` of a 640x360 10 s clip, `DELETE` after 0-1.5 s (queued or running:
//!   200 `cancelled`; the record then deleted: 204);
//! - two live viewers on `/live` (a looped `--live-source`), each joining, reading 3-40 frames,
//!   then leaving by a close handshake or by dropping the socket;
//! - clients that go away: a partial upload (raw or multipart) closed mid-body, or a whole
//!   clip uploaded and the socket dropped while it is processed;
//! - probes: `/healthz`, `/metrics`, `GET /jobs`, `/openapi.json`.
//!
//! Every `interval` seconds (D/60 clamped to 1..5 s) a sampler records the server's RSS, its
//! open file descriptors (`/proc/PID/fd`), threads and ffmpeg children. Every response's status
//! is counted per kind. The test fails on:
//! - any 5xx, any status other than the one expected, any transport error;
//! - RSS not flat: the max over the last third of the run above the max over the second third
//!   by more than 10% + 20 MB (the first third is warm-up);
//! - fds not flat: the max over the last third above the max over the second third by more than
//!   16, or the idle count after the run above the idle count before it by more than 4;
//! - anything left: a job still listed by `GET /jobs`, a file in the scratch folder, an ffmpeg
//!   child, a live viewer, or an unhealthy server at the end.
//!
//! The report (one row per sample, then the statuses by kind) goes to stdout.

use amc_e2e::fixtures::{silent_test_clip, test_clip, test_picture};
use amc_e2e::server::{
    self, agent_with_timeout, multipart_body, raw_request, rss_kb, websocket, Server, NO_ANSWER,
};
use amc_e2e::{data, s};
use std::collections::BTreeMap;
use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tungstenite::Message;

/// Longest any one request may take before it counts as a failure.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(60);

/// Statuses by kind of traffic, and what went wrong.
#[derive(Default)]
struct Stats {
    counts: Mutex<BTreeMap<(&'static str, u16), u64>>,
    problems: Mutex<Vec<String>>,
}

impl Stats {
    /// Counts `status` under `kind`; a status outside `want` (or any 5xx) is a problem.
    fn record(&self, kind: &'static str, what: &str, status: u16, want: &[u16], body: &str) {
        *self
            .counts
            .lock()
            .unwrap()
            .entry((kind, status))
            .or_default() += 1;
        if !want.contains(&status) || status >= 500 {
            self.problem(format!(
                "{kind}: {what}: status {status}, expected {want:?}: {}",
                body.chars().take(300).collect::<String>()
            ));
        }
    }

    fn problem(&self, p: String) {
        eprintln!("soak problem: {p}");
        let mut ps = self.problems.lock().unwrap();
        if ps.len() < 200 {
            ps.push(p);
        }
    }

    /// Totals by status class: 2xx (101 counted here too), 4xx, 5xx, no answer.
    fn classes(&self) -> [u64; 4] {
        let mut c = [0; 4];
        for (&(_, st), &n) in self.counts.lock().unwrap().iter() {
            let i = match st {
                NO_ANSWER => 3,
                500.. => 2,
                400..=499 => 1,
                _ => 0,
            };
            c[i] += n;
        }
        c
    }
}

/// A small xorshift generator: the traffic's jitter, reproducible per thread.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }

    fn pause(&mut self, max_ms: u64) {
        std::thread::sleep(Duration::from_millis(self.below(max_ms)));
    }
}

fn agent() -> ureq::Agent {
    agent_with_timeout(REQUEST_TIMEOUT)
}

/// A reply's status and body, or the transport error as [`NO_ANSWER`] (also the status
/// recorded for a request whose client left).
fn answer(r: Result<ureq::http::Response<ureq::Body>, ureq::Error>) -> (u16, Vec<u8>) {
    server::answer(r, "transport error")
}

fn get(agent: &ureq::Agent, url: &str) -> (u16, Vec<u8>) {
    answer(agent.get(url).call())
}

fn delete(agent: &ureq::Agent, url: &str) -> (u16, Vec<u8>) {
    answer(agent.delete(url).call())
}

fn post(agent: &ureq::Agent, url: &str, ctype: &str, body: &[u8]) -> (u16, Vec<u8>) {
    let mut req = agent.post(url);
    if !ctype.is_empty() {
        req = req.header("Content-Type", ctype);
    }
    answer(req.send(body))
}

/// POSTs a multipart form of (name, filename, content type, bytes) parts.
fn post_form(
    agent: &ureq::Agent,
    url: &str,
    parts: &[(&str, &str, &str, &[u8])],
) -> (u16, Vec<u8>) {
    let (ctype, body) = multipart_body(parts);
    post(agent, url, &ctype, &body)
}

fn text(body: &[u8]) -> String {
    String::from_utf8_lossy(body).into_owned()
}

fn json(body: &[u8]) -> serde_json::Value {
    serde_json::from_slice(body).unwrap_or(serde_json::Value::Null)
}

fn open_fds(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count())
}

fn threads(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("Threads:")?.trim().parse().ok())
        })
        .unwrap_or(0)
}

/// The test's inputs, made once.
struct Clips {
    good: Vec<u8>,
    /// Long enough (300 frames at 640x360) to be cancelled while queued or running.
    long: Vec<u8>,
    /// 1000 pixels wide, over the server's --max-width 900.
    wide: Vec<u8>,
    png: Vec<u8>,
    truncated: Vec<u8>,
    random: Vec<u8>,
}

fn make_clips(dir: &std::path::Path) -> Clips {
    let good = dir.join("good.mp4");
    test_clip(&good, 160, 90, 30, 1.0);
    let long = dir.join("long.mp4");
    test_clip(&long, 640, 360, 30, 10.0);
    let wide = dir.join("wide.mp4");
    test_clip(&wide, 1000, 200, 10, 1.0);
    let png = dir.join("still.png");
    test_picture(&png, 160, 90);
    // 3 s with the index (moov) first, so its first half decodes to 45 of the 90 frames
    // it declares.
    let whole = dir.join("whole.mp4");
    silent_test_clip(&whole, 160, 90, 30, 3.0, &["-movflags", "+faststart"]);
    let whole = std::fs::read(&whole).unwrap();
    Clips {
        good: std::fs::read(&good).unwrap(),
        long: std::fs::read(&long).unwrap(),
        wide: std::fs::read(&wide).unwrap(),
        png: std::fs::read(&png).unwrap(),
        truncated: whole[..whole.len() / 2].to_vec(),
        random: (0..200_000u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect(),
    }
}

/// One kind of traffic: a loop run on its own thread until the deadline, with its seed.
type Client = fn(&Ctx, u64);

/// What one traffic thread needs.
struct Ctx {
    base: String,
    addr: String,
    deadline: Instant,
    stats: Arc<Stats>,
    clips: Arc<Clips>,
}

impl Ctx {
    fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    fn running(&self) -> bool {
        Instant::now() < self.deadline
    }
}

/// Good clips through `POST /stabilize`: raw, multipart, WebM.
fn good_uploads(c: &Ctx, seed: u64) {
    let (agent, mut rng) = (agent(), Rng(seed));
    for i in 0..100_000u64 {
        if !c.running() {
            break;
        }
        let (what, r) = match i % 4 {
            0 | 1 => (
                "raw mp4",
                post(
                    &agent,
                    &c.url("/stabilize?fov=70"),
                    "video/mp4",
                    &c.clips.good,
                ),
            ),
            2 => (
                "multipart + lens",
                post_form(
                    &agent,
                    &c.url("/stabilize?mode=saccade&n_avg=4"),
                    &[
                        ("video", "good.mp4", "video/mp4", &c.clips.good),
                        (
                            "lens",
                            "lens.json",
                            "application/json",
                            br#"{"model":"pinhole","width":160,"height":90,"fx":125,"fy":125,"cx":79.5,"cy":44.5}"#,
                        ),
                    ],
                ),
            ),
            _ => (
                "webm, no metrics",
                post(
                    &agent,
                    &c.url("/stabilize?fov=70&format=webm&metrics=false"),
                    "video/mp4",
                    &c.clips.good,
                ),
            ),
        };
        let (status, body) = r;
        let shown = if status == 200 {
            String::new()
        } else {
            text(&body)
        };
        c.stats
            .record("stabilize good", what, status, &[200], &shown);
        if status == 200 && body.len() < 1000 {
            c.stats
                .problem(format!("stabilize good: {what}: {} byte video", body.len()));
        }
        rng.pause(300);
    }
}

/// Requests that must be refused, each with its exact status.
fn bad_requests(c: &Ctx, seed: u64) {
    let mut rng = Rng(seed);
    let k = &c.clips;
    let unknown = "0123456789abcdef0123456789abcdef";
    for i in 0..100_000u64 {
        if !c.running() {
            break;
        }
        // A fresh client each time: connections come and go.
        let agent = agent();
        let (what, (status, body), want): (&str, (u16, Vec<u8>), u16) = match i % 20 {
            0 => (
                "empty body",
                post(&agent, &c.url("/stabilize"), "video/mp4", b""),
                400,
            ),
            1 => (
                "random bytes",
                post(&agent, &c.url("/stabilize"), "video/mp4", &k.random),
                415,
            ),
            2 => (
                "random bytes as a job",
                post(
                    &agent,
                    &c.url("/jobs"),
                    "application/octet-stream",
                    &k.random,
                ),
                415,
            ),
            3 => (
                "truncated mp4",
                post(&agent, &c.url("/stabilize"), "video/mp4", &k.truncated),
                415,
            ),
            4 => (
                "png as video",
                post(&agent, &c.url("/stabilize"), "video/mp4", &k.png),
                415,
            ),
            5 => (
                "text",
                post(&agent, &c.url("/jobs"), "text/plain", b"hello"),
                415,
            ),
            6 => (
                "n_avg 0",
                post(&agent, &c.url("/stabilize?n_avg=0"), "video/mp4", &k.good),
                400,
            ),
            7 => (
                "fov text",
                post(&agent, &c.url("/jobs?fov=wide"), "video/mp4", &k.good),
                400,
            ),
            8 => (
                "format gif",
                post(
                    &agent,
                    &c.url("/stabilize?format=gif"),
                    "video/mp4",
                    &k.good,
                ),
                400,
            ),
            9 => (
                "unknown option",
                post(&agent, &c.url("/stabilize?speed=11"), "video/mp4", &k.good),
                400,
            ),
            10 => (
                "broken lens",
                post_form(
                    &agent,
                    &c.url("/stabilize"),
                    &[
                        ("video", "good.mp4", "video/mp4", &k.good),
                        ("lens", "l.json", "application/json", b"{not json"),
                    ],
                ),
                400,
            ),
            11 => (
                "form without video",
                post_form(
                    &agent,
                    &c.url("/jobs"),
                    &[("clip", "good.mp4", "video/mp4", &k.good)],
                ),
                400,
            ),
            12 => (
                "too wide",
                post(&agent, &c.url("/stabilize"), "video/mp4", &k.wide),
                422,
            ),
            13 => (
                "unknown job",
                get(&agent, &c.url(&format!("/jobs/{unknown}"))),
                404,
            ),
            14 => (
                "path-like job id",
                get(&agent, &c.url("/jobs/..%2F..%2Fetc%2Fpasswd/output")),
                404,
            ),
            15 => (
                "delete unknown job",
                delete(&agent, &c.url(&format!("/jobs/{unknown}"))),
                404,
            ),
            16 => ("GET /stabilize", get(&agent, &c.url("/stabilize")), 405),
            17 => ("plain GET /live", get(&agent, &c.url("/live")), 426),
            18 => ("no such path", get(&agent, &c.url("/no/such/thing")), 404),
            _ => {
                // A declared length over --max-upload-mb, refused before the upload.
                let head = "POST /stabilize HTTP/1.1\r\nHost: x\r\nContent-Type: video/mp4\r\nContent-Length: 80000000\r\nConnection: close";
                (
                    "declared length over the limit",
                    (raw_request(&c.addr, head, b"", false), Vec::new()),
                    413,
                )
            }
        };
        c.stats
            .record("bad request", what, status, &[want], &text(&body));
        rng.pause(150);
    }
}

/// Polls a job until it is in one of `want` (or `within` passes); its last view.
fn poll(
    c: &Ctx,
    agent: &ureq::Agent,
    id: &str,
    want: &[&str],
    within: Duration,
) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let (status, body) = get(agent, &c.url(&format!("/jobs/{id}")));
        c.stats.record("job poll", id, status, &[200], &text(&body));
        let j = json(&body);
        if status != 200 || want.contains(&j["state"].as_str().unwrap_or("")) {
            return j;
        }
        if start.elapsed() > within {
            c.stats
                .problem(format!("job {id} not {want:?} after {within:?}: {j}"));
            return j;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Jobs submitted, followed to `done`, their results fetched, then deleted.
fn jobs(c: &Ctx, seed: u64) {
    let (agent, mut rng) = (agent(), Rng(seed));
    for _ in 0..100_000u64 {
        if !c.running() {
            break;
        }
        let (status, body) = post(&agent, &c.url("/jobs?fov=70"), "video/mp4", &c.clips.good);
        c.stats
            .record("job submit", "good clip", status, &[202], &text(&body));
        let Some(id) = json(&body)["id"].as_str().map(str::to_string) else {
            rng.pause(500);
            continue;
        };
        let j = poll(
            c,
            &agent,
            &id,
            &["done", "failed", "cancelled"],
            REQUEST_TIMEOUT,
        );
        if j["state"] != "done" {
            c.stats.problem(format!("job {id} ended {j}"));
        }
        for (what, path) in [("output", "output"), ("telemetry", "telemetry.csv")] {
            let (status, body) = get(&agent, &c.url(&format!("/jobs/{id}/{path}")));
            c.stats.record(
                "job result",
                what,
                status,
                &[200],
                &if status == 200 {
                    String::new()
                } else {
                    text(&body)
                },
            );
        }
        let (status, body) = delete(&agent, &c.url(&format!("/jobs/{id}")));
        c.stats
            .record("job delete", "done job", status, &[204], &text(&body));
        rng.pause(300);
    }
}

/// Jobs cancelled while queued or running, then removed.
fn cancels(c: &Ctx, seed: u64) {
    let (agent, mut rng) = (agent(), Rng(seed));
    for _ in 0..100_000u64 {
        if !c.running() {
            break;
        }
        let (status, body) = post(&agent, &c.url("/jobs?fov=70"), "video/mp4", &c.clips.long);
        c.stats
            .record("job submit", "long clip", status, &[202], &text(&body));
        let Some(id) = json(&body)["id"].as_str().map(str::to_string) else {
            rng.pause(500);
            continue;
        };
        rng.pause(1500);
        let url = c.url(&format!("/jobs/{id}"));
        let (status, body) = delete(&agent, &url);
        // 200 cancelled; 204 if it finished first.
        c.stats.record(
            "job cancel",
            "queued or running",
            status,
            &[200, 204],
            &text(&body),
        );
        if status == 200 {
            let j = json(&body);
            if j["state"] != "cancelled" {
                c.stats.problem(format!("cancel of {id} answered {j}"));
            }
            let (status, body) = get(&agent, &c.url(&format!("/jobs/{id}/output")));
            c.stats.record(
                "job result",
                "output of a cancelled job",
                status,
                &[409],
                &text(&body),
            );
            let (status, body) = delete(&agent, &url);
            c.stats
                .record("job delete", "cancelled job", status, &[204], &text(&body));
        }
        rng.pause(500);
    }
}

/// A live viewer joining, reading a few frames, leaving.
fn viewers(c: &Ctx, seed: u64) {
    let mut rng = Rng(seed);
    for i in 0..100_000u64 {
        if !c.running() {
            break;
        }
        let mut ws = match websocket(&c.addr, "/live", Duration::from_secs(15)) {
            Ok(ws) => ws,
            Err(e) => {
                let status = e
                    .strip_prefix("HTTP ")
                    .and_then(|s| s.parse().ok())
                    .unwrap_or(NO_ANSWER);
                c.stats.record("live viewer", "join", status, &[101], &e);
                rng.pause(1000);
                continue;
            }
        };
        c.stats.record("live viewer", "join", 101, &[101], "");
        let want = 3 + rng.below(38);
        let (mut metas, mut jpegs) = (0, 0);
        let start = Instant::now();
        while metas < want && start.elapsed() < Duration::from_secs(30) {
            match ws.read() {
                Ok(Message::Binary(b)) => {
                    if !b.starts_with(&[0xFF, 0xD8]) {
                        c.stats
                            .problem("live viewer: a frame that is not a JPEG".into());
                    }
                    jpegs += 1;
                }
                Ok(Message::Text(_)) => metas += 1,
                Ok(_) => {}
                Err(e) => {
                    c.stats.problem(format!(
                        "live viewer: read failed after {metas} frames ({jpegs} JPEGs): {e}"
                    ));
                    break;
                }
            }
        }
        if metas < want {
            c.stats
                .problem(format!("live viewer: {metas} of {want} frames in 30 s"));
        }
        if i % 2 == 0 {
            // A polite leave: close handshake, then read until the server's close.
            let _ = ws.close(None);
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(5) {
                match ws.read() {
                    Ok(_) => {}
                    Err(_) => break,
                }
            }
        }
        // Otherwise the socket is simply dropped.
        drop(ws);
        rng.pause(2000);
    }
}

/// Clients that leave mid-upload or while their clip is processed.
fn quitters(c: &Ctx, seed: u64) {
    let mut rng = Rng(seed);
    let k = &c.clips;
    for i in 0..100_000u64 {
        if !c.running() {
            break;
        }
        match i % 3 {
            0 => {
                let path = if rng.below(2) == 0 {
                    "/stabilize"
                } else {
                    "/jobs"
                };
                let head = format!(
                    "POST {path} HTTP/1.1\r\nHost: x\r\nContent-Type: video/mp4\r\nContent-Length: 2000000"
                );
                let part = 1 + rng.below(k.long.len() as u64 / 2) as usize;
                raw_request(&c.addr, &head, &k.long[..part], true);
                c.stats.record(
                    "client left",
                    "mid-upload, raw",
                    NO_ANSWER,
                    &[NO_ANSWER],
                    "",
                );
            }
            1 => {
                let (ctype, body) = multipart_body(&[("video", "long.mp4", "video/mp4", &k.long)]);
                let head = format!(
                    "POST /stabilize HTTP/1.1\r\nHost: x\r\nContent-Type: {ctype}\r\nContent-Length: {}",
                    body.len()
                );
                let part = 1 + rng.below(body.len() as u64 - 1) as usize;
                raw_request(&c.addr, &head, &body[..part], true);
                c.stats.record(
                    "client left",
                    "mid-upload, multipart",
                    NO_ANSWER,
                    &[NO_ANSWER],
                    "",
                );
            }
            _ => {
                // The whole clip sent, then the client goes away while it is processed.
                match std::net::TcpStream::connect(&c.addr) {
                    Ok(mut s) => {
                        let _ = write!(
                            s,
                            "POST /stabilize?fov=70 HTTP/1.1\r\nHost: x\r\nContent-Type: video/mp4\r\nContent-Length: {}\r\n\r\n",
                            k.long.len()
                        );
                        let _ = s.write_all(&k.long);
                        rng.pause(1500);
                        drop(s);
                        c.stats.record(
                            "client left",
                            "while processing",
                            NO_ANSWER,
                            &[NO_ANSWER],
                            "",
                        );
                    }
                    Err(e) => c.stats.problem(format!("connect: {e}")),
                }
            }
        }
        rng.pause(700);
    }
}

/// The cheap endpoints a monitor would hit.
fn probes(c: &Ctx, seed: u64) {
    let (agent, mut rng) = (agent(), Rng(seed));
    for i in 0..100_000u64 {
        if !c.running() {
            break;
        }
        let path = ["/healthz", "/metrics", "/jobs?limit=5", "/openapi.json"][i as usize % 4];
        let (status, body) = get(&agent, &c.url(path));
        c.stats.record("probe", path, status, &[200], &text(&body));
        rng.pause(1000);
    }
}

#[derive(Clone, Copy)]
struct Sample {
    t: f64,
    rss_kb: u64,
    fds: usize,
    threads: u64,
    ffmpeg: usize,
    classes: [u64; 4],
}

fn sample(server: &Server, stats: &Stats, t0: Instant) -> Sample {
    let pid = server.pid();
    Sample {
        t: t0.elapsed().as_secs_f64(),
        rss_kb: rss_kb(pid),
        fds: open_fds(pid),
        threads: threads(pid),
        ffmpeg: server.ffmpeg_children().len(),
        classes: stats.classes(),
    }
}

fn max_of<T: Ord + Copy>(s: &[Sample], f: impl Fn(&Sample) -> T) -> T {
    s.iter().map(f).max().expect("samples")
}

fn mb(kb: u64) -> f64 {
    kb as f64 / 1024.0
}

#[test]
fn soak_mixed_traffic_keeps_memory_and_descriptors_flat() {
    let secs: u64 = std::env::var("AMC_SOAK_SECS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(45)
        .clamp(15, 3600);
    let interval = Duration::from_secs((secs / 60).clamp(1, 5));
    let dir = tempfile::tempdir().unwrap();
    let clips = Arc::new(make_clips(dir.path()));
    let cup = data("cup/cup.mp4");
    let server = Server::start(&[
        "--workers",
        "2",
        "--max-queued",
        "8",
        "--max-upload-mb",
        "50",
        "--max-width",
        "900",
        "--max-height",
        "900",
        "--live-source",
        &s(&cup),
        "--live-loop",
        "--live-fov",
        "70",
        "--live-width",
        "320",
    ]);
    // Idle baseline: the live source opened once and paused again.
    let settle = Instant::now();
    while !server.ffmpeg_children().is_empty() && settle.elapsed() < Duration::from_secs(15) {
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(500));
    let (idle_rss_before, idle_fds_before) = (server.rss_kb(), open_fds(server.pid()));

    let stats = Arc::new(Stats::default());
    let t0 = Instant::now();
    let deadline = t0 + Duration::from_secs(secs);
    let workers: [(&str, Client); 8] = [
        ("good uploads", good_uploads),
        ("bad requests", bad_requests),
        ("jobs", jobs),
        ("cancels", cancels),
        ("viewer 1", viewers),
        ("viewer 2", viewers),
        ("quitters", quitters),
        ("probes", probes),
    ];
    let handles: Vec<_> = workers
        .iter()
        .enumerate()
        .map(|(i, &(name, f))| {
            let c = Ctx {
                base: server.base.clone(),
                addr: server.addr.clone(),
                deadline,
                stats: stats.clone(),
                clips: clips.clone(),
            };
            std::thread::Builder::new()
                .name(name.into())
                .spawn(move || f(&c, 0x9E37_79B9_7F4A_7C15 ^ ((i as u64 + 1) * 7919)))
                .unwrap()
        })
        .collect();

    let mut samples = Vec::new();
    while Instant::now() < deadline {
        samples.push(sample(&server, &stats, t0));
        std::thread::sleep(interval.min(deadline.saturating_duration_since(Instant::now())));
    }
    samples.push(sample(&server, &stats, t0));
    let traffic_samples = samples.len();
    // Every thread stops by itself: no new iteration after the deadline, each request
    // bounded by REQUEST_TIMEOUT.
    for (h, (name, _)) in handles.into_iter().zip(workers.iter()) {
        if h.join().is_err() {
            stats.problem(format!("thread {name} panicked"));
        }
    }
    let drain_s = t0.elapsed().as_secs_f64() - secs as f64;

    // Quiet again: no job listed, no viewer, no ffmpeg, nothing on disk.
    let agent = agent();
    let (status, body) = get(&agent, &server.url("/jobs?limit=100"));
    let listed = json(&body)["jobs"].as_array().map_or(0, |a| a.len());
    if status != 200 || listed != 0 {
        stats.problem(format!(
            "GET /jobs after the run: {status}, {listed} jobs listed: {}",
            text(&body)
        ));
    }
    let quiet = Instant::now();
    while (!server.ffmpeg_children().is_empty()
        || json(&get(&agent, &server.url("/healthz")).1)["live"]["viewers"] != 0)
        && quiet.elapsed() < Duration::from_secs(15)
    {
        std::thread::sleep(Duration::from_millis(200));
    }
    if !server.ffmpeg_children().is_empty() {
        stats.problem(format!(
            "ffmpeg children after the run: {:?}",
            server.ffmpeg_children()
        ));
    }
    let health = get(&agent, &server.url("/healthz"));
    if health.0 != 200 || json(&health.1)["live"]["viewers"] != 0 {
        stats.problem(format!(
            "/healthz after the run: {} {}",
            health.0,
            text(&health.1)
        ));
    }
    let scratch = {
        let start = Instant::now();
        loop {
            let left = server.scratch_entries();
            if left.is_empty() || start.elapsed() > Duration::from_secs(10) {
                break left;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    };
    // Our keep-alive connection closed, so that it is not counted as the server's fd.
    drop(agent);
    std::thread::sleep(Duration::from_millis(500));
    let end = sample(&server, &stats, t0);
    let (idle_rss_after, idle_fds_after) = (server.rss_kb(), open_fds(server.pid()));
    samples.push(end);

    // The report.
    println!(
        "\nsoak: {secs} s of mixed traffic, sampled every {} s; threads drained {drain_s:.1} s after the deadline",
        interval.as_secs()
    );
    println!(
        "{:>7} {:>8} {:>5} {:>8} {:>7} {:>7} {:>5} {:>5} {:>9}",
        "t (s)", "RSS MB", "fds", "threads", "ffmpeg", "2xx/101", "4xx", "5xx", "no answer"
    );
    for (i, sm) in samples.iter().enumerate() {
        let tag = if i + 1 == samples.len() {
            " (idle, after)"
        } else {
            ""
        };
        println!(
            "{:>7.1} {:>8.1} {:>5} {:>8} {:>7} {:>7} {:>5} {:>5} {:>9}{tag}",
            sm.t,
            mb(sm.rss_kb),
            sm.fds,
            sm.threads,
            sm.ffmpeg,
            sm.classes[0],
            sm.classes[1],
            sm.classes[2],
            sm.classes[3]
        );
    }
    println!("\n{:<16} {:>6} {:>6}", "kind", "status", "count");
    let counts = stats.counts.lock().unwrap().clone();
    for ((kind, status), n) in &counts {
        let st = if *status == NO_ANSWER {
            "-".to_string()
        } else {
            status.to_string()
        };
        println!("{kind:<16} {st:>6} {n:>6}");
    }
    let total: u64 = counts.values().sum();
    let during = &samples[..traffic_samples];
    let third = during.len() / 3;
    let (mid, last) = (&during[third..2 * third], &during[2 * third..]);
    let (rss_mid, rss_last) = (max_of(mid, |s| s.rss_kb), max_of(last, |s| s.rss_kb));
    let (fds_mid, fds_last) = (max_of(mid, |s| s.fds), max_of(last, |s| s.fds));
    println!(
        "\n{total} requests; RSS idle before {:.1} MB, max warm-up {:.1} MB, max 2nd third {:.1} MB, max last third {:.1} MB, idle after {:.1} MB",
        mb(idle_rss_before),
        mb(max_of(&during[..third], |s| s.rss_kb)),
        mb(rss_mid),
        mb(rss_last),
        mb(idle_rss_after)
    );
    println!(
        "fds idle before {idle_fds_before}, max 2nd third {fds_mid}, max last third {fds_last}, idle after {idle_fds_after}; scratch entries left: {}",
        scratch.len()
    );

    // The verdict.
    let mut failures: Vec<String> = stats.problems.lock().unwrap().clone();
    let five = counts
        .iter()
        .filter(|((_, st), _)| *st >= 500)
        .map(|(k, n)| format!("{k:?} x{n}"))
        .collect::<Vec<_>>();
    if !five.is_empty() {
        failures.push(format!("5xx answers: {five:?}"));
    }
    if third < 2 {
        failures.push(format!("too few samples ({}) to judge", during.len()));
    }
    if rss_last as f64 > rss_mid as f64 * 1.10 + 20.0 * 1024.0 {
        failures.push(format!(
            "RSS grew: max {:.1} MB in the last third vs {:.1} MB in the second (allowed: +10% + 20 MB)",
            mb(rss_last),
            mb(rss_mid)
        ));
    }
    if fds_last > fds_mid + 16 {
        failures.push(format!(
            "open fds grew: max {fds_last} in the last third vs {fds_mid} in the second (allowed: +16)"
        ));
    }
    if idle_fds_after > idle_fds_before + 4 {
        failures.push(format!(
            "open fds when idle: {idle_fds_before} before the run, {idle_fds_after} after (allowed: +4)"
        ));
    }
    if !scratch.is_empty() {
        failures.push(format!("left in the scratch folder: {scratch:?}"));
    }
    if !server.healthy() {
        failures.push("the server is not healthy after the run".into());
    }
    for kind in [
        "stabilize good",
        "bad request",
        "job submit",
        "job cancel",
        "live viewer",
        "client left",
    ] {
        if !counts.keys().any(|(k, _)| *k == kind) {
            failures.push(format!("no {kind} traffic at all"));
        }
    }
    assert!(
        failures.is_empty(),
        "soak failed:\n{}\n--- server log (tail) ---\n{}",
        failures.join("\n"),
        server
            .log()
            .lines()
            .rev()
            .take(60)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect::<Vec<_>>()
            .join("\n")
    );
}
