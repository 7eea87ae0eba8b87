//! `amc serve` given a gyro log beside the clip (the `gyro` part of a
//! `multipart/form-data` upload): used as the CLI's `--gyro FILE`, and refused
//! naming why when it cannot be used (422, or 400 for a broken form). A real server on a loopback
//! port, driven over HTTP like a client (docs/service.md, docs/gyro.md).

use amc_e2e::cluster::wait_finished;
use amc_e2e::server::{delete, post_multipart, Reply, Server};
use amc_e2e::{synth_clip_with_gyro, GYRO_CLIP_OFFSET_S};
use std::path::Path;
use std::time::Duration;

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A clip, its lens file and the given `gyro` parts (file name, bytes).
struct Form {
    video: Vec<u8>,
    lens: Vec<u8>,
}

impl Form {
    fn send(&self, server: &Server, query: &str, gyro: &[(&str, &[u8])]) -> Reply {
        let mut parts: Vec<(&str, &str, &str, &[u8])> = vec![
            ("video", "clip.mp4", "video/mp4", &self.video),
            ("lens", "lens.json", "application/json", &self.lens),
        ];
        parts.extend(
            gyro.iter()
                .map(|&(name, bytes)| ("gyro", name, "text/csv", bytes)),
        );
        post_multipart(&server.url(query), &parts)
    }
}

#[test]
fn a_gyro_log_sent_with_the_clip_is_synchronized_and_fused() {
    let dir = tempfile::tempdir().unwrap();
    let (clip, video) = synth_clip_with_gyro(dir.path(), 2.0);
    let form = Form {
        video: read(&video),
        lens: read(&clip.join("lens.json")),
    };
    let log = read(&clip.join("gyro.gcsv"));
    let server = Server::start(&[]);

    // As a job: its metrics report the log's sync and fusion.
    let r = form.send(&server, "/jobs?metrics=false", &[("flight.gcsv", &log)]);
    assert_eq!(r.status, 202, "{}\n{}", r.text(), server.log());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let v = wait_finished(&server, &id, Duration::from_secs(120));
    assert_eq!(v["state"], "done", "{v}\n{}", server.log());
    let g = &v["metrics"]["gyro"];
    assert!(
        g["source"]
            .as_str()
            .is_some_and(|s| s.contains("amc-synth")),
        "{v}"
    );
    let offset_ms = (g["offset_s"].as_f64().unwrap() - GYRO_CLIP_OFFSET_S) * 1e3;
    eprintln!("offset off by {offset_ms:.3} ms; {g}");
    assert!(
        offset_ms.abs() < 2.0,
        "offset off by {offset_ms:.3} ms: {g}"
    );
    assert!(g["fused_frames"].as_u64().is_some_and(|n| n > 60), "{g}");
    // Done, the job keeps its output; what the client sent is gone.
    let left: Vec<_> = server.scratch_entries();
    assert!(
        left.iter().all(|p| {
            let name = p.file_name().unwrap().to_string_lossy();
            !name.starts_with("gyro") && name != "input"
        }),
        "{left:?}"
    );

    // Synchronously, with `gyro=auto` said outright: the log is used too.
    let r = form.send(
        &server,
        "/stabilize?gyro=auto&metrics=false",
        &[("flight.gcsv", &log)],
    );
    assert_eq!(r.status, 200, "{}", r.text());
    assert!(r.body.len() > 1000);

    // Logs that cannot be used: refused before any work, saying why (422 for
    // a file that is no gyro log or a log with gyro=off, as for an
    // undecodable video; 400 for a broken form).
    let garbage: &[u8] = b"not a log\n1,2\n";
    for (query, gyro, status, says) in [
        (
            "/stabilize",
            garbage,
            422,
            "no gyro log telemetry-parser knows",
        ),
        ("/jobs", &[][..], 400, "is empty"),
        ("/jobs?gyro=off", &log[..], 422, "gyro=off"),
        ("/stabilize?gyro=off", &log[..], 422, "gyro=off"),
    ] {
        let r = form.send(&server, query, &[("flight.gcsv", gyro)]);
        assert_eq!(r.status, status, "{query} {says}: {}", r.text());
        assert_eq!(r.header("content-type"), Some("application/problem+json"));
        let detail = r.json()["detail"].as_str().unwrap_or("").to_string();
        assert!(detail.contains(says), "{query}: {detail}");
        assert!(!detail.contains("req-"), "a scratch path leaked: {detail}");
    }
    // Two logs are a broken form.
    let two = form.send(&server, "/jobs", &[("a.gcsv", &log), ("b.gcsv", &log)]);
    assert_eq!(two.status, 400, "{}", two.text());
    assert!(server.healthy());
    // Nothing is left once the job is removed.
    assert_eq!(delete(&server.url(&format!("/jobs/{id}"))).status, 204);
    server.assert_no_scratch_left(Duration::from_secs(5));
}
