//! End-to-end tests of `amc serve`: a real server on a loopback port, driven
//! over HTTP and WebSocket like a client would.
//!
//! The tests run one at a time (they share two CPU cores and measure rates).

use amc_e2e::fixtures::{
    ffmpeg, ffprobe_frames, ffprobe_video_duration, has_audio, test_clip, test_picture,
};
use amc_e2e::server::{
    delete, get, post, post_multipart, raw_request, wait_until, websocket, Server,
};
use amc_e2e::{data, s};
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tungstenite::Message;

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn read_file(p: &std::path::Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Checks a stabilized karma.mp4: the input's frame count and duration, with audio.
fn assert_like_karma(bytes: &[u8], what: &str) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.mp4");
    std::fs::write(&out, bytes).unwrap();
    let input = data("karma/karma.mp4");
    assert_eq!(
        ffprobe_frames(&out),
        ffprobe_frames(&input),
        "{what}: frame count differs from the input's"
    );
    let (d_out, d_in) = (ffprobe_video_duration(&out), ffprobe_video_duration(&input));
    assert!(
        (d_out - d_in).abs() < 0.05,
        "{what}: duration {d_out} s vs input {d_in} s"
    );
    assert!(has_audio(&out), "{what}: the audio track was lost");
}

#[test]
fn post_stabilize_returns_the_clip_with_metrics() {
    let _g = serial();
    let server = Server::start(&[]);
    let karma = read_file(&data("karma/karma.mp4"));
    let r = post(&server.url("/stabilize?fov=70"), "video/mp4", &karma);
    assert_eq!(r.status, 200, "{}\n{}", r.text(), server.log());
    assert_eq!(r.header("content-type"), Some("video/mp4"));
    assert_eq!(r.header("x-amc-frames"), Some("362"));
    for h in [
        "x-amc-rms-normal-flow",
        "x-amc-rms-frame-change",
        "x-amc-valid-fraction",
        "x-amc-rms-speed-estimate-dps",
        "x-amc-rms-speed-view-dps",
    ] {
        let v: f64 = r
            .header(h)
            .unwrap_or_else(|| panic!("missing {h}"))
            .parse()
            .unwrap();
        assert!(v.is_finite() && v >= 0.0, "{h} = {v}");
    }
    // The view turns slower than the camera: the point of the exercise.
    let est: f64 = r
        .header("x-amc-rms-speed-estimate-dps")
        .unwrap()
        .parse()
        .unwrap();
    let view: f64 = r
        .header("x-amc-rms-speed-view-dps")
        .unwrap()
        .parse()
        .unwrap();
    assert!(view < est, "view {view} deg/s vs camera {est} deg/s");
    assert_like_karma(&r.body, "POST /stabilize");

    // Multipart with a lens file and WebM output, on a short clip.
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("clip.mp4");
    test_clip(&clip, 320, 180, 30, 1.0);
    let lens =
        br#"{"model":"pinhole","width":320,"height":180,"fx":250,"fy":250,"cx":159.5,"cy":89.5}"#;
    let r = post_multipart(
        &server.url("/stabilize?format=webm&mode=saccade&n_avg=4"),
        &[
            ("video", "clip.mp4", "video/mp4", &read_file(&clip)),
            ("lens", "lens.json", "application/json", lens),
        ],
    );
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.header("content-type"), Some("video/webm"));
    let webm = dir.path().join("out.webm");
    std::fs::write(&webm, &r.body).unwrap();
    assert_eq!(ffprobe_frames(&webm), 30);
    assert!(has_audio(&webm));
    server.assert_no_scratch_left(Duration::from_secs(5));
}

fn wait_for_state(server: &Server, id: &str, want: &[&str], within: Duration) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let j = get(&server.url(&format!("/jobs/{id}"))).json();
        let state = j["state"].as_str().unwrap_or("").to_string();
        if want.contains(&state.as_str()) {
            return j;
        }
        assert!(
            start.elapsed() < within,
            "job {id} still {state} after {within:?}: {j}\n{}",
            server.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn jobs_report_progress_and_cancel_cleanly() {
    let _g = serial();
    let server = Server::start(&[]);
    let karma = read_file(&data("karma/karma.mp4"));
    let r = post(&server.url("/jobs?fov=70"), "video/mp4", &karma);
    assert_eq!(r.status, 202, "{}", r.text());
    let job = r.json();
    let id = job["id"].as_str().unwrap().to_string();
    assert_eq!(r.header("location"), Some(format!("/jobs/{id}").as_str()));
    assert_eq!(job["frames_total"], 362);

    // Progress rises to done.
    let mut seen = Vec::new();
    let start = Instant::now();
    let done = loop {
        let j = get(&server.url(&format!("/jobs/{id}"))).json();
        let state = j["state"].as_str().unwrap().to_string();
        assert!(
            ["queued", "running", "done"].contains(&state.as_str()),
            "unexpected state {state}: {j}"
        );
        seen.push(j["frames_done"].as_u64().unwrap());
        if state == "done" {
            break j;
        }
        assert!(
            start.elapsed() < Duration::from_secs(240),
            "job too slow: {j}"
        );
        std::thread::sleep(Duration::from_millis(150));
    };
    assert!(
        seen.windows(2).all(|w| w[0] <= w[1]),
        "progress went back: {seen:?}"
    );
    assert!(
        seen.iter().any(|&n| n > 0 && n < 362),
        "progress was never seen between 0 and 362: {seen:?}"
    );
    assert_eq!(done["frames_done"], 362);
    assert_eq!(done["progress"], 1.0);
    // One flat metrics object, the motion apart, no value twice.
    for key in [
        "rms_normal_flow",
        "rms_frame_change",
        "sharpness",
        "valid_fraction",
    ] {
        assert!(
            done["metrics"][key].as_f64().is_some(),
            "metrics.{key}: {done}"
        );
    }
    assert!(done["metrics"].get("metrics").is_none(), "{done}");
    // karma.mp4 carries its GoPro gyro track: gyro=auto (the default) used it.
    let gyro = &done["metrics"]["gyro"];
    assert!(
        gyro["source"]
            .as_str()
            .is_some_and(|s| s.starts_with("GoPro")),
        "{done}"
    );
    assert!(
        gyro["fused_frames"].as_u64().is_some_and(|n| n > 300),
        "{done}"
    );
    assert!(
        done["motion"]["rms_speed_est_dps"].as_f64().is_some(),
        "{done}"
    );
    assert!(
        done["created"].as_str().is_some_and(|t| t.ends_with('Z')),
        "{done}"
    );
    // GET /jobs lists it, newest first.
    let list = get(&server.url("/jobs?limit=10"));
    assert_eq!(list.status, 200, "{}", list.text());
    let list = list.json();
    assert_eq!(list["jobs"][0]["id"], id.as_str(), "{list}");
    assert_eq!(list["jobs"][0]["state"], "done", "{list}");

    let out = get(&server.url(&format!("/jobs/{id}/output")));
    assert_eq!(out.status, 200);
    assert_like_karma(&out.body, "job output");
    let csv = get(&server.url(&format!("/jobs/{id}/telemetry.csv")));
    assert_eq!(csv.status, 200);
    let text = csv.text();
    assert!(
        text.starts_with("frame,t,rx,ry,rz,vx,vy,vz"),
        "{}",
        &text[..80.min(text.len())]
    );
    assert_eq!(text.lines().count(), 363);

    // Removing a finished job removes its files.
    assert_eq!(delete(&server.url(&format!("/jobs/{id}"))).status, 204);
    assert_eq!(get(&server.url(&format!("/jobs/{id}"))).status, 404);
    server.assert_no_scratch_left(Duration::from_secs(5));

    // Cancel a running job: no ffmpeg left, no file left.
    let r = post(&server.url("/jobs?fov=70"), "video/mp4", &karma);
    assert_eq!(r.status, 202);
    let id = r.json()["id"].as_str().unwrap().to_string();
    let start = Instant::now();
    loop {
        let j = get(&server.url(&format!("/jobs/{id}"))).json();
        if j["state"] == "running" && j["frames_done"].as_u64().unwrap() > 10 {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "never ran: {j}");
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        !server.ffmpeg_children().is_empty(),
        "expected ffmpeg at work"
    );
    let r = delete(&server.url(&format!("/jobs/{id}")));
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json()["state"], "cancelled");
    assert!(
        server.ffmpeg_children().is_empty(),
        "ffmpeg still running after cancel: {:?}",
        server.ffmpeg_children()
    );
    server.assert_no_scratch_left(Duration::from_secs(1));
    let j = get(&server.url(&format!("/jobs/{id}"))).json();
    assert_eq!(j["state"], "cancelled");
    assert_eq!(get(&server.url(&format!("/jobs/{id}/output"))).status, 409);
    assert!(server.healthy());
}

/// Reads `n` frames (binary JPEG + text telemetry) from a viewer; returns
/// the telemetry messages and the seconds it took.
fn read_frames(
    ws: &mut tungstenite::WebSocket<std::net::TcpStream>,
    n: usize,
) -> (Vec<serde_json::Value>, f64) {
    let start = Instant::now();
    let mut metas = Vec::new();
    let mut jpegs = 0;
    while metas.len() < n {
        match ws.read() {
            Ok(Message::Binary(b)) => {
                assert!(b.starts_with(&[0xFF, 0xD8]), "not a JPEG");
                jpegs += 1;
            }
            Ok(Message::Text(t)) => {
                let v: serde_json::Value = serde_json::from_str(&t).expect("telemetry JSON");
                metas.push(v);
            }
            Ok(_) => {}
            Err(e) => panic!("viewer read failed after {} frames: {e}", metas.len()),
        }
    }
    assert!(jpegs >= n, "{jpegs} JPEGs for {n} telemetry messages");
    (metas, start.elapsed().as_secs_f64())
}

#[test]
fn live_source_reaches_viewers_at_its_rate_and_slow_viewers_do_not_hold_it_back() {
    let _g = serial();
    let cup = data("cup/cup.mp4");
    let server = Server::start(&[
        "--live-source",
        cup.to_str().unwrap(),
        "--live-loop",
        "--live-fov",
        "70",
    ]);
    let fps = 26.777;
    let mut a = websocket(&server.addr, "/live", Duration::from_secs(10)).expect("viewer a");
    let mut slow = websocket(&server.addr, "/live", Duration::from_secs(10)).expect("viewer b");
    // Warm up, then measure viewer A over ~3 s while B reads nothing.
    read_frames(&mut a, 10);
    let rss_before = server.rss_kb();
    let (metas, secs) = read_frames(&mut a, 80);
    let rate = 80.0 / secs;
    assert!(
        rate > 0.8 * fps && rate < 1.25 * fps,
        "viewer got {rate:.1} frames/s; the source runs at {fps}"
    );
    for m in &metas {
        for key in [
            "frame",
            "t",
            "speed_est_dps",
            "speed_view_dps",
            "valid",
            "saccade",
            "latency_ms",
        ] {
            assert!(!m[key].is_null(), "telemetry lacks {key}: {m}");
        }
        assert!(m["latency_ms"].as_f64().unwrap() < 500.0, "{m}");
    }
    let frames: Vec<u64> = metas.iter().map(|m| m["frame"].as_u64().unwrap()).collect();
    assert!(
        frames.windows(2).all(|w| w[1] > w[0]),
        "frames out of order"
    );
    // The feed loops past the clip's end (217 frames) without stopping.
    let (metas, _) = read_frames(&mut a, 160);
    assert!(metas.last().unwrap()["frame"].as_u64().unwrap() > 217);
    // B, silent for ~9 s, did not grow the server's memory.
    let rss_after = server.rss_kb();
    assert!(
        rss_after < rss_before + 50_000,
        "server memory grew from {rss_before} kB to {rss_after} kB while a viewer stalled"
    );
    // B still works: after what the sockets buffered while it stalled, it
    // catches up with the live frame, having skipped the ones it missed.
    let newest = metas.last().unwrap()["frame"].as_u64().unwrap();
    let mut frames_b = Vec::new();
    let start = Instant::now();
    while frames_b.last().is_none_or(|&f| f < newest) {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "slow viewer never caught up: {frames_b:?}"
        );
        let (m, _) = read_frames(&mut slow, 1);
        frames_b.push(m[0]["frame"].as_u64().unwrap());
    }
    assert!(
        frames_b.windows(2).any(|w| w[1] > w[0] + 1),
        "the slow viewer skipped nothing: {frames_b:?}"
    );
    assert!(
        (frames_b.len() as u64) < newest,
        "the slow viewer got every frame"
    );
    assert!(
        frames_b.len() < 40,
        "the slow viewer was fed {} stale frames before catching up",
        frames_b.len()
    );
    let m = get(&server.url("/metrics")).text();
    assert!(m.contains("amc_live_viewers 2"), "{m}");
    drop(a);
    drop(slow);
    // Ingest is refused while the feed comes from --live-source.
    let e = websocket(&server.addr, "/live/ingest", Duration::from_secs(5)).err();
    assert_eq!(e.as_deref(), Some("HTTP 409"));
}

/// The value of a counter or gauge in a `/metrics` scrape.
fn metric(server: &Server, name: &str) -> f64 {
    let text = get(&server.url("/metrics")).text();
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
        .unwrap_or_else(|| panic!("/metrics lacks {name}:\n{text}"))
}

#[test]
fn live_feed_pauses_without_viewers_and_resumes_for_the_first() {
    let _g = serial();
    let karma = data("karma/karma.mp4");
    let server = Server::start(&[
        "--live-source",
        karma.to_str().unwrap(),
        "--live-loop",
        "--live-fov",
        "70",
    ]);
    // Opened once at start (so /healthz can tell it works), then paused:
    // no ffmpeg and no frames while nobody watches.
    wait_until(
        "the live source's ffmpeg still runs with no viewer",
        Duration::from_secs(15),
        || server.ffmpeg_children().is_empty(),
    );
    let health = get(&server.url("/healthz"));
    assert_eq!(health.status, 200, "{}", health.text());
    assert_eq!(
        health.json()["live"]["state"],
        "paused",
        "{}",
        health.text()
    );
    let before = metric(&server, "amc_live_frames_total");
    let processed = metric(&server, "amc_frames_processed_total");
    std::thread::sleep(Duration::from_secs(3));
    assert_eq!(metric(&server, "amc_live_frames_total"), before);
    assert_eq!(metric(&server, "amc_frames_processed_total"), processed);
    assert!(server.ffmpeg_children().is_empty());

    // The first viewer resumes it within a few seconds.
    let start = Instant::now();
    let mut viewer = websocket(&server.addr, "/live", Duration::from_secs(10)).expect("viewer");
    read_frames(&mut viewer, 10);
    assert!(
        start.elapsed() < Duration::from_secs(5),
        "the first frames took {:?}",
        start.elapsed()
    );
    assert!(
        !server.ffmpeg_children().is_empty(),
        "no ffmpeg while watched"
    );
    assert!(metric(&server, "amc_live_frames_total") >= before + 10.0);
    assert_eq!(
        get(&server.url("/healthz")).json()["live"]["state"],
        "running"
    );

    // The last viewer leaving pauses it again.
    drop(viewer);
    wait_until(
        "the live source's ffmpeg outlived the last viewer",
        Duration::from_secs(5),
        || server.ffmpeg_children().is_empty(),
    );
    std::thread::sleep(Duration::from_millis(500));
    let paused = metric(&server, "amc_live_frames_total");
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(metric(&server, "amc_live_frames_total"), paused);
}

#[test]
fn a_live_source_that_cannot_be_opened_is_reported_and_the_api_still_works() {
    let _g = serial();
    let missing = "/nonexistent/amc-test/flight.mp4";
    let server = Server::start(&["--live-source", missing, "--log-json"]);
    let mut health = None;
    wait_until(
        "/healthz never reported the live source",
        Duration::from_secs(15),
        || {
            let h = get(&server.url("/healthz"));
            let bad = h.status == 503;
            health = Some(h);
            bad
        },
    );
    let h = health.unwrap();
    assert_eq!(h.status, 503);
    let j = h.json();
    assert_eq!(j["status"], "unavailable", "{j}");
    assert!(j["detail"].as_str().unwrap().contains(missing), "{j}");
    assert_eq!(j["live"]["state"], "unavailable", "{j}");
    // The rest of the API works.
    assert_eq!(get(&server.url("/openapi.json")).status, 200);
    assert_eq!(get(&server.url("/jobs")).status, 200);
    // A plain GET of the WebSocket endpoint is a problem+json 426.
    let plain = get(&server.url("/live"));
    assert_eq!(plain.status, 426, "{}", plain.text());
    assert_eq!(
        plain.header("content-type"),
        Some("application/problem+json")
    );
    assert!(plain.json()["detail"]
        .as_str()
        .unwrap()
        .contains("WebSocket"));
    // The log says it, as JSON lines without colours.
    let log = server.log();
    assert!(
        log.contains(missing),
        "the log does not name the source:\n{log}"
    );
    assert!(!log.contains('\x1b'), "ANSI escapes in the log:\n{log}");
    for line in log.lines().filter(|l| !l.trim().is_empty()) {
        assert!(
            serde_json::from_str::<serde_json::Value>(line).is_ok(),
            "not a JSON log line: {line}"
        );
    }
}

#[test]
fn ingest_publisher_feeds_viewers() {
    let _g = serial();
    let server = Server::start(&["--live-fov", "70"]);
    // JPEG frames of the first 3 s of cup.mp4.
    let dir = tempfile::tempdir().unwrap();
    let (cup, jpgs) = (s(&data("cup/cup.mp4")), s(&dir.path().join("%04d.jpg")));
    ffmpeg(&["-i", &cup, "-t", "3", "-q:v", "4", &jpgs]);
    let mut jpegs: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    jpegs.sort();
    assert!(jpegs.len() > 60);
    let mut viewer = websocket(&server.addr, "/live", Duration::from_secs(10)).expect("viewer");
    let mut publisher =
        websocket(&server.addr, "/live/ingest", Duration::from_secs(10)).expect("publisher");
    // One publisher at a time.
    let second = websocket(&server.addr, "/live/ingest", Duration::from_secs(5)).err();
    assert_eq!(second.as_deref(), Some("HTTP 409"));
    let frames = jpegs.clone();
    let sender = std::thread::spawn(move || {
        let start = Instant::now();
        for (i, p) in frames.iter().enumerate() {
            let due = Duration::from_secs_f64(i as f64 / 30.0);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
            publisher
                .send(Message::Binary(std::fs::read(p).unwrap().into()))
                .expect("publish");
        }
        publisher
    });
    let (metas, secs) = read_frames(&mut viewer, 60);
    let publisher = sender.join().unwrap();
    let rate = 60.0 / secs;
    assert!(
        rate > 20.0,
        "viewer got {rate:.1} frames/s from a 30 frames/s publisher"
    );
    assert!(
        metas
            .iter()
            .all(|m| m["width"] == 640 && m["height"] == 480),
        "{}",
        metas[0]
    );
    drop(publisher);
    // Once the publisher has gone, another may connect.
    let start = Instant::now();
    loop {
        match websocket(&server.addr, "/live/ingest", Duration::from_secs(5)) {
            Ok(_) => break,
            Err(e) => {
                assert!(
                    start.elapsed() < Duration::from_secs(5),
                    "ingest still busy: {e}"
                );
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}

#[test]
fn bad_inputs_get_clear_statuses_and_leave_the_server_healthy() {
    let _g = serial();
    let server = Server::start(&[
        "--max-upload-mb",
        "3",
        "--max-width",
        "900",
        "--max-height",
        "900",
        "--max-duration",
        "10",
    ]);
    let dir = tempfile::tempdir().unwrap();
    let cup = read_file(&data("cup/cup.mp4"));
    let karma = read_file(&data("karma/karma.mp4"));
    let wide = dir.path().join("wide.mp4");
    test_clip(&wide, 1000, 200, 10, 1.0);
    let long = dir.path().join("long.mp4");
    test_clip(&long, 64, 64, 5, 12.0);
    let png = dir.path().join("still.png");
    test_picture(&png, 320, 180);
    let png = read_file(&png);
    let random: Vec<u8> = (0..200_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    // The first half of an MP4 whose index (moov) is at the end.
    let truncated = &cup[..cup.len() / 2];

    let cases: Vec<(&str, &str, &str, Vec<u8>, u16)> = vec![
        ("empty body", "/stabilize", "video/mp4", vec![], 400),
        (
            "random bytes",
            "/stabilize",
            "video/mp4",
            random.clone(),
            415,
        ),
        (
            "random bytes as a job",
            "/jobs",
            "application/octet-stream",
            random,
            415,
        ),
        (
            "truncated mp4",
            "/stabilize",
            "video/mp4",
            truncated.to_vec(),
            415,
        ),
        ("png as video", "/stabilize", "video/mp4", png.clone(), 415),
        ("png as image", "/stabilize", "image/png", png, 415),
        ("text", "/stabilize", "text/plain", b"hello".to_vec(), 415),
        (
            "over the upload limit",
            "/stabilize",
            "video/mp4",
            karma,
            413,
        ),
        ("too wide", "/stabilize", "video/mp4", read_file(&wide), 422),
        ("too long", "/jobs", "video/mp4", read_file(&long), 422),
        (
            "n_avg 0",
            "/stabilize?n_avg=0",
            "video/mp4",
            cup.clone(),
            400,
        ),
        (
            "n_avg huge",
            "/jobs?n_avg=100000",
            "video/mp4",
            cup.clone(),
            400,
        ),
        (
            "margin negative",
            "/stabilize?margin=-1",
            "video/mp4",
            cup.clone(),
            400,
        ),
        ("fov 0", "/stabilize?fov=0", "video/mp4", cup.clone(), 400),
        (
            "fov text",
            "/stabilize?fov=wide",
            "video/mp4",
            cup.clone(),
            400,
        ),
        (
            "format gif",
            "/stabilize?format=gif",
            "video/mp4",
            cup.clone(),
            400,
        ),
        (
            "mode bogus",
            "/stabilize?mode=wobble",
            "video/mp4",
            cup.clone(),
            400,
        ),
        (
            "unknown option",
            "/stabilize?speed=11",
            "video/mp4",
            cup.clone(),
            400,
        ),
        (
            "track_width tiny",
            "/jobs?track_width=2",
            "video/mp4",
            cup.clone(),
            400,
        ),
        (
            "readout_ms text",
            "/stabilize?readout_ms=abc",
            "video/mp4",
            cup.clone(),
            400,
        ),
        (
            "readout_ms too long",
            "/jobs?readout_ms=200",
            "video/mp4",
            cup.clone(),
            400,
        ),
    ];
    for (what, path, ctype, body, want) in cases {
        eprintln!("bad input: {what}");
        let r = post(&server.url(path), ctype, &body);
        assert_eq!(r.status, want, "{what}: {}", r.text());
        assert_eq!(
            r.header("content-type"),
            Some("application/problem+json"),
            "{what}"
        );
        let p = r.json();
        assert_eq!(p["status"], want, "{what}");
        let detail = p["detail"].as_str().unwrap_or("");
        assert!(detail.len() > 10, "{what}: unhelpful detail {detail:?}");
        if want == 400 && path.contains('=') {
            let option = path.split('?').nth(1).unwrap().split('=').next().unwrap();
            assert!(
                detail.contains(option),
                "{what}: {detail:?} does not name {option}"
            );
            assert!(
                detail.contains("allowed") || detail.contains("known"),
                "{what}: {detail}"
            );
        }
        assert!(
            server.healthy(),
            "{what}: server unhealthy afterwards\n{}",
            server.log()
        );
    }
    // A lens that does not fit, and a bad multipart form.
    let r = post_multipart(
        &server.url("/stabilize"),
        &[
            ("video", "cup.mp4", "video/mp4", &cup),
            ("lens", "l.json", "application/json", b"{not json"),
        ],
    );
    assert_eq!(r.status, 400, "{}", r.text());
    let r = post_multipart(
        &server.url("/stabilize"),
        &[("clip", "cup.mp4", "video/mp4", &cup)],
    );
    assert_eq!(r.status, 400, "{}", r.text());

    // Unknown and path-like job ids.
    for id in [
        "0123456789abcdef0123456789abcdef",
        "nope",
        "..%2F..%2Fetc%2Fpasswd",
        "%2e%2e",
        "..",
        "0123456789abcdef0123456789abcdeg",
    ] {
        for suffix in ["", "/output", "/telemetry.csv"] {
            let r = get(&server.url(&format!("/jobs/{id}{suffix}")));
            assert_eq!(r.status, 404, "GET /jobs/{id}{suffix}: {}", r.text());
        }
        assert_eq!(delete(&server.url(&format!("/jobs/{id}"))).status, 404);
    }
    let r = get(&server.url("/no/such/thing"));
    assert_eq!(r.status, 404);
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    assert_eq!(get(&server.url("/stabilize")).status, 405);

    // A client that disconnects mid-upload.
    for path in ["/stabilize", "/jobs"] {
        let head = format!(
            "POST {path} HTTP/1.1\r\nHost: x\r\nContent-Type: video/mp4\r\nContent-Length: 2000000"
        );
        raw_request(&server.addr, &head, &cup[..300_000], true);
    }
    // A client that disconnects while its clip is being processed: the work
    // is cancelled, its ffmpeg children killed, its files removed.
    {
        use std::io::Write;
        let mut c = std::net::TcpStream::connect(&server.addr).unwrap();
        write!(
            c,
            "POST /stabilize?fov=70 HTTP/1.1\r\nHost: x\r\nContent-Type: video/mp4\r\nContent-Length: {}\r\n\r\n",
            cup.len()
        )
        .unwrap();
        c.write_all(&cup).unwrap();
        let start = Instant::now();
        while server.ffmpeg_children().is_empty() {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "processing never started"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        drop(c);
        let start = Instant::now();
        while !server.ffmpeg_children().is_empty() {
            assert!(
                start.elapsed() < Duration::from_secs(5),
                "ffmpeg still running after the client left"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    // A declared length over the limit is refused before the upload.
    let head = "POST /stabilize HTTP/1.1\r\nHost: x\r\nContent-Type: video/mp4\r\nContent-Length: 50000000\r\nConnection: close";
    assert_eq!(raw_request(&server.addr, head, b"", false), 413);
    assert!(server.healthy());
    server.assert_no_scratch_left(Duration::from_secs(5));
    assert!(server.ffmpeg_children().is_empty());
    // Text logs written to a file carry no colour codes.
    let log = server.log();
    assert!(!log.contains('\x1b'), "ANSI escapes in the log:\n{log}");
}

#[test]
fn bounded_load_every_request_succeeds_or_gets_503() {
    let _g = serial();
    let server = Server::start(&["--workers", "2", "--max-queued", "4"]);
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("short.mp4");
    test_clip(&clip, 320, 180, 30, 1.0);
    let clip = std::sync::Arc::new(read_file(&clip));
    let url = server.url("/stabilize?fov=70");
    let pid = server.pid();
    let peak = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let sampler = {
        let (peak, stop) = (peak.clone(), stop.clone());
        std::thread::spawn(move || {
            while !stop.load(std::sync::atomic::Ordering::SeqCst) {
                peak.fetch_max(
                    amc_e2e::server::rss_kb(pid),
                    std::sync::atomic::Ordering::SeqCst,
                );
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };
    let clients: Vec<_> = (0..40)
        .map(|_| {
            let (clip, url) = (clip.clone(), url.clone());
            std::thread::spawn(move || {
                let r = post(&url, "video/mp4", &clip);
                (
                    r.status,
                    r.header("retry-after").map(str::to_string),
                    r.body.len(),
                )
            })
        })
        .collect();
    let results: Vec<_> = clients.into_iter().map(|c| c.join().unwrap()).collect();
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    sampler.join().unwrap();
    let ok = results.iter().filter(|r| r.0 == 200).count();
    let busy = results.iter().filter(|r| r.0 == 503).count();
    for (status, retry, len) in &results {
        match status {
            200 => assert!(*len > 1000),
            503 => assert!(retry.as_deref().is_some_and(|s| s.parse::<u64>().is_ok())),
            other => panic!("status {other} under load\n{}", server.log()),
        }
    }
    assert!(ok >= 6, "only {ok} of 40 succeeded ({busy} got 503)");
    let peak_mb = peak.load(std::sync::atomic::Ordering::SeqCst) / 1024;
    assert!(peak_mb < 600, "server peaked at {peak_mb} MB under load");
    eprintln!("load: {ok} ok, {busy} busy (503), peak RSS {peak_mb} MB");
    server.assert_no_scratch_left(Duration::from_secs(5));
    let m = get(&server.url("/metrics")).text();
    assert!(
        m.contains("amc_requests_rejected_total{status=\"503\"}"),
        "{m}"
    );
    assert!(server.healthy());
}

#[test]
fn service_documents_itself_and_shuts_down_cleanly() {
    let _g = serial();
    let mut server = Server::start(&[]);
    let api = get(&server.url("/openapi.json"));
    assert_eq!(api.status, 200);
    let doc = api.json();
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    // Every operation has an operationId, unique in the document.
    let mut ids = std::collections::BTreeSet::new();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let id = op["operationId"].as_str();
            assert!(id.is_some(), "{method} {path} has no operationId");
            assert!(
                ids.insert(id.unwrap().to_string()),
                "operationId {id:?} twice"
            );
        }
    }
    assert!(
        doc["paths"]["/jobs"]["get"].is_object(),
        "GET /jobs is not documented"
    );
    for path in [
        "/stabilize",
        "/jobs",
        "/jobs/{id}",
        "/jobs/{id}/output",
        "/jobs/{id}/telemetry.csv",
        "/live",
        "/live/ingest",
        "/healthz",
        "/metrics",
        "/openapi.json",
    ] {
        assert!(doc["paths"][path].is_object(), "{path} is not documented");
    }
    let m = get(&server.url("/metrics"));
    assert!(m.header("content-type").unwrap().starts_with("text/plain"));
    for name in [
        "amc_jobs{state=\"queued\"}",
        "amc_frames_processed_total",
        "amc_processing_frames_per_second",
        "amc_live_viewers",
        "amc_live_frames_dropped_total",
    ] {
        assert!(m.text().contains(name), "/metrics lacks {name}");
    }
    let page = get(&server.url("/"));
    assert_eq!(page.status, 200);
    assert!(page
        .header("content-type")
        .unwrap()
        .starts_with("text/html"));

    // SIGTERM while a job runs: it is cancelled, ffmpeg is gone, nothing is left on disk.
    let karma = read_file(&data("karma/karma.mp4"));
    let r = post(&server.url("/jobs?fov=70"), "video/mp4", &karma);
    assert_eq!(r.status, 202);
    let id = r.json()["id"].as_str().unwrap().to_string();
    wait_for_state(&server, &id, &["running"], Duration::from_secs(60));
    let pid = server.pid();
    let status = server
        .terminate(Duration::from_secs(30))
        .expect("server did not stop within 30 s of SIGTERM");
    assert!(status.success(), "server exited with {status}");
    assert!(amc_e2e::server::children_named(pid, "ffmpeg").is_empty());
    let orphans = amc_e2e::server::ffmpeg_using(server.work_parent.path());
    assert!(
        orphans.is_empty(),
        "ffmpeg still running after shutdown: {orphans:?}"
    );
    let left: Vec<_> = std::fs::read_dir(server.work_parent.path())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    assert!(left.is_empty(), "left on disk after shutdown: {left:?}");
}
