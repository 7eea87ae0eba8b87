//! What `amc serve` (and `amc worker`) tell their users, end to end against
//! the real binary on loopback: every fallback the CLI warns about reaches
//! the client (`X-Amc-Warning`, the job's `warnings`), in memory and in the
//! shared job table; a cancelled or failed job's files are said never to
//! come; a page built after start-up is served, and a missing one is named
//! in the start-up log; one log line per request, none at WARN starting with
//! `warning:`; `/metrics` is what its Content-Type says, for a real
//! Prometheus parser (PyPI's `prometheus_client`).
//!
//! The parser runs in a Python that has `prometheus_client`:
//! `AMC_PROMETHEUS_PYTHON`, else `target/prometheus-venv/bin/python3` (as
//! `.ci/run` installs it), else `python3`. Without one the metrics test says
//! `skipped:` and passes, unless `AMC_REQUIRE_SERVICES=1` (CI), where it
//! fails; so do the shared-table tests without PostgreSQL and SeaweedFS
//! (`amc_e2e::services`).
//!
//! The tests run one at a time (the machine has two cores).

use amc_e2e::cluster::{submit, wait_finished, Infra};
use amc_e2e::fixtures::test_clip;
use amc_e2e::server::{agent, delete, get, post, post_multipart, wait_until, Server};
use amc_e2e::services::REQUIRE_SERVICES;
use amc_e2e::{data, workspace_root};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::{Duration, Instant};

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn read_file(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A 2 s 320x180 clip of ffmpeg's `testsrc2` (a pattern that slides, never
/// turns): `fov=auto` cannot pin its focal length down, nor `readout_ms=auto`
/// its readout, so both fall back (the CLI warns twice on it).
fn fallback_clip(dir: &Path) -> Vec<u8> {
    let clip = dir.join("pattern.mp4");
    test_clip(&clip, 320, 180, 30, 2.0);
    read_file(&clip)
}

fn wait_for_state(server: &Server, id: &str, want: &str) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let j = get(&server.url(&format!("/jobs/{id}"))).json();
        if j["state"] == want {
            return j;
        }
        assert!(
            start.elapsed() < Duration::from_secs(240),
            "job {id} never became {want}: {j}\n{}",
            server.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Checks the two fallbacks' warnings, as the service words them.
fn assert_both_fallbacks(warnings: &[String], what: &str) {
    assert_eq!(warnings.len(), 2, "{what}: {warnings:?}");
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("focal length") && w.contains("70 deg") && w.contains("fov")),
        "{what}: no warning that the field of view fell back to 70 deg: {warnings:?}"
    );
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("rolling-shutter readout") && w.contains("0 ms")),
        "{what}: no warning that the readout fell back to 0: {warnings:?}"
    );
    for w in warnings {
        assert!(
            !w.to_ascii_lowercase().starts_with("warning"),
            "{what}: a warning in a list of warnings says so again: {w:?}"
        );
    }
}

fn job_warnings(job: &serde_json::Value) -> Vec<String> {
    job["metrics"]["warnings"]
        .as_array()
        .unwrap_or_else(|| panic!("no metrics.warnings: {job}"))
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect()
}

/// The text log's lines at WARN whose message starts with "warning:".
fn warn_lines_saying_warning(log: &str) -> Vec<&str> {
    log.lines()
        .filter(|l| {
            l.split_once(" WARN ")
                .and_then(|(_, rest)| rest.split_once(": "))
                .is_some_and(|(_, message)| {
                    message
                        .trim_start()
                        .to_ascii_lowercase()
                        .starts_with("warning")
                })
        })
        .collect()
}

#[test]
fn every_fallback_the_cli_warns_about_reaches_the_client_and_the_log_once() {
    let _g = serial();
    let server = Server::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let clip = fallback_clip(dir.path());

    // POST /stabilize: one X-Amc-Warning line per warning.
    let r = post(
        &server.url("/stabilize?readout_ms=auto"),
        "video/mp4",
        &clip,
    );
    assert_eq!(r.status, 200, "{}\n{}", r.text(), server.log());
    let headers: Vec<String> = r
        .headers
        .iter()
        .filter(|(k, _)| k.eq_ignore_ascii_case("x-amc-warning"))
        .map(|(_, v)| v.clone())
        .collect();
    assert_both_fallbacks(&headers, "POST /stabilize's X-Amc-Warning");

    // A job: its warnings.
    let r = post(&server.url("/jobs?readout_ms=auto"), "video/mp4", &clip);
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let job = wait_for_state(&server, &id, "done");
    assert_both_fallbacks(&job_warnings(&job), "the job's metrics.warnings");

    // A request carrying secrets (refused: an unknown option).
    let refused = agent()
        .post(&server.url("/stabilize?fov=70&access_key=s3cr3t-in-query"))
        .header("Authorization", "Bearer s3cr3t-in-header")
        .header("Content-Type", "video/mp4")
        .send(&clip[..])
        .unwrap();
    assert_eq!(refused.status(), 400);
    assert_eq!(get(&server.url("/healthz")).status, 200);

    // The log: each request once, with its outcome; no secret; no WARN line
    // that says "warning" twice, and the fallbacks are logged at WARN.
    let log = server.log();
    let lines = |needle: &str| -> Vec<&str> {
        log.lines()
            .filter(|l| l.contains(needle) && l.contains("method=POST"))
            .collect()
    };
    let stabilize = lines("path=/stabilize ");
    assert_eq!(
        stabilize.len(),
        2,
        "POST /stabilize twice (200, 400), one line each:\n{log}"
    );
    assert!(
        stabilize[0].contains("status=200") && stabilize[0].contains(" ms="),
        "{}",
        stabilize[0]
    );
    assert!(
        stabilize[1].contains("status=400") && stabilize[1].contains("access_key"),
        "the refusal's line says why: {}",
        stabilize[1]
    );
    let jobs = lines("path=/jobs ");
    assert_eq!(jobs.len(), 1, "POST /jobs once:\n{log}");
    assert!(jobs[0].contains("status=202"), "{}", jobs[0]);
    assert!(
        log.lines().any(|l| l.contains("method=GET")
            && l.contains("path=/healthz")
            && l.contains("status=200")),
        "GET /healthz is not logged:\n{log}"
    );
    assert!(!log.contains("s3cr3t"), "a secret reached the log:\n{log}");
    assert!(
        !log.to_ascii_lowercase().contains("authorization"),
        "a header reached the log:\n{log}"
    );
    assert_eq!(
        warn_lines_saying_warning(&log),
        Vec::<&str>::new(),
        "WARN lines whose message starts with \"warning:\""
    );
    assert!(
        log.lines()
            .any(|l| l.contains(" WARN ") && l.contains("focal length")),
        "the field of view's fallback is not logged at WARN:\n{log}"
    );
}

#[test]
fn a_cancelled_or_failed_jobs_files_are_said_never_to_come() {
    let _g = serial();
    let server = Server::start(&["--workers", "1"]);
    let karma = read_file(&data("karma/karma.mp4"));
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("clip.mp4");
    test_clip(&clip, 160, 90, 30, 1.0);
    let clip = read_file(&clip);
    let problem = |path: &str| {
        let r = get(&server.url(path));
        assert_eq!(r.status, 409, "GET {path}: {}", r.text());
        assert_eq!(r.header("content-type"), Some("application/problem+json"));
        r.json()["detail"].as_str().unwrap().to_string()
    };

    // One job runs; the next waits for the one worker.
    let r = post(&server.url("/jobs?fov=70"), "video/mp4", &karma);
    assert_eq!(r.status, 202, "{}", r.text());
    let running = r.json()["id"].as_str().unwrap().to_string();
    wait_for_state(&server, &running, "running");
    let r = post(&server.url("/jobs?fov=70"), "video/mp4", &clip);
    assert_eq!(r.status, 202, "{}", r.text());
    let waiting = r.json()["id"].as_str().unwrap().to_string();
    let detail = problem(&format!("/jobs/{waiting}/output"));
    assert!(
        detail.contains("queued") && detail.contains("once it is done"),
        "a queued job's output: {detail}"
    );

    // Cancelled: no output, ever.
    let r = delete(&server.url(&format!("/jobs/{waiting}")));
    assert_eq!(r.json()["state"], "cancelled", "{}", r.text());
    for (file, noun) in [("output", "output"), ("telemetry.csv", "telemetry")] {
        let detail = problem(&format!("/jobs/{waiting}/{file}"));
        assert!(
            detail.contains("cancelled")
                && detail.contains(&format!("no {noun}"))
                && detail.contains("never"),
            "a cancelled job's {file}: {detail}"
        );
        assert!(
            !detail.contains("once it is done"),
            "a cancelled job's {file} is said to come: {detail}"
        );
    }
    let r = delete(&server.url(&format!("/jobs/{running}")));
    assert_eq!(r.json()["state"], "cancelled", "{}", r.text());
    let detail = problem(&format!("/jobs/{running}/output"));
    assert!(detail.contains("cancelled"), "{detail}");

    // Failed (a lens file that is not one): no output, ever, and why.
    let r = post_multipart(
        &server.url("/jobs"),
        &[
            ("video", "clip.mp4", "video/mp4", &clip),
            ("lens", "lens.json", "application/json", b"{not json"),
        ],
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let failed = r.json()["id"].as_str().unwrap().to_string();
    wait_for_state(&server, &failed, "failed");
    let detail = problem(&format!("/jobs/{failed}/output"));
    assert!(
        detail.contains("failed")
            && detail.contains("invalid lens file")
            && detail.contains("no output")
            && !detail.contains("once it is done"),
        "a failed job's output: {detail}"
    );

    // The OpenAPI document says so too.
    let doc = get(&server.url("/openapi.json")).json();
    for path in ["/jobs/{id}/output", "/jobs/{id}/telemetry.csv"] {
        let said = doc["paths"][path]["get"]["responses"]["409"]["description"]
            .as_str()
            .unwrap_or("")
            .to_string();
        assert!(
            said.contains("cancelled") && said.contains("failed"),
            "{path}'s 409 in /openapi.json: {said:?}"
        );
    }
}

#[test]
fn a_page_built_after_start_up_is_served_and_a_missing_one_is_named_in_the_log() {
    let _g = serial();
    let web = tempfile::tempdir().unwrap();
    let dist = web.path().join("dist");
    let server = Server::start(&["--web-dir", dist.to_str().unwrap()]);
    wait_until(
        "the start-up log does not say that the page is not built",
        Duration::from_secs(10),
        || server.log().contains("index.html"),
    );
    let log = server.log();
    let line = log
        .lines()
        .find(|l| l.contains("index.html"))
        .unwrap()
        .to_string();
    assert!(
        line.contains(dist.to_str().unwrap()) && line.contains("bash web/build.sh"),
        "the start-up log names neither the folder nor the command that builds it: {line}"
    );
    let page = get(&server.url("/"));
    assert_eq!(page.status, 200);
    assert!(page.text().contains("not built"), "{}", page.text());

    // Built after start-up: served at once, no restart.
    std::fs::create_dir_all(&dist).unwrap();
    std::fs::write(
        dist.join("index.html"),
        "<!doctype html><title>built later</title>",
    )
    .unwrap();
    std::fs::write(dist.join("main.js"), "export const built = 'later';").unwrap();
    for path in ["/", "/index.html"] {
        let page = get(&server.url(path));
        assert_eq!(page.status, 200, "GET {path}");
        assert!(
            page.text().contains("built later"),
            "GET {path} after the page was built: {}",
            page.text()
        );
    }
    assert!(get(&server.url("/main.js")).text().contains("later"));
    // Unknown paths are still problem+json 404s, whatever the method.
    for r in [
        get(&server.url("/no/such/thing")),
        post(&server.url("/no/such/thing"), "text/plain", b"x"),
    ] {
        assert_eq!(r.status, 404, "{}", r.text());
        assert_eq!(r.header("content-type"), Some("application/problem+json"));
    }
    assert_eq!(get(&server.url("/stabilize")).status, 405);
}

/// A Python that has PyPI's `prometheus_client`; None (skipped, said) where
/// there is none, unless `AMC_REQUIRE_SERVICES=1`.
fn prometheus_python() -> Option<PathBuf> {
    let mut candidates: Vec<PathBuf> = std::env::var_os("AMC_PROMETHEUS_PYTHON")
        .map(PathBuf::from)
        .into_iter()
        .collect();
    candidates.push(workspace_root().join("target/prometheus-venv/bin/python3"));
    candidates.push("python3".into());
    for python in candidates {
        let has = Command::new(&python)
            .args(["-c", "import prometheus_client"])
            .output()
            .is_ok_and(|o| o.status.success());
        if has {
            return Some(python);
        }
    }
    let install = "python3 -m venv target/prometheus-venv && \
                   target/prometheus-venv/bin/pip install prometheus-client";
    if std::env::var(REQUIRE_SERVICES).as_deref() == Ok("1") {
        panic!(
            "PyPI's prometheus_client is required ({REQUIRE_SERVICES}=1) but no Python has it: \
             install it with `{install}` (as .ci/run does) or set AMC_PROMETHEUS_PYTHON"
        );
    }
    eprintln!(
        "skipped: no Python with prometheus_client (install it with `{install}`, \
         or set {REQUIRE_SERVICES}=1 to make this an error)"
    );
    None
}

/// Parses a scrape with `prometheus_client`'s parser for its format and
/// checks what a scraper relies on; prints what is wrong.
const PARSE: &str = r#"
import sys
mode, path = sys.argv[1], sys.argv[2]
text = open(path, encoding="utf-8").read()
if mode == "openmetrics":
    from prometheus_client.openmetrics.parser import text_string_to_metric_families
else:
    from prometheus_client.parser import text_string_to_metric_families
families = {}
for f in text_string_to_metric_families(text):
    if f.name in families:
        sys.exit(f"family {f.name} twice")
    families[f.name] = f
problems = []
for f in families.values():
    if f.type in ("unknown", "untyped"):
        problems.append(f"{f.name}: no type (its samples do not match any TYPE line): {[s.name for s in f.samples]}")
    if f.type == "counter":
        if not f.samples:
            problems.append(f"counter {f.name}: no samples (they were named otherwise)")
        for s in f.samples:
            if s.name not in (f.name + "_total", f.name + "_created"):
                problems.append(f"counter {f.name}: sample {s.name}")
for name in sys.argv[3:]:
    f = families.get(name)
    if f is None or f.type != "counter" or not any(s.name == name + "_total" for s in f.samples):
        problems.append(f"no counter {name} with a sample {name}_total")
if problems:
    sys.exit("\n".join(problems))
print(f"{mode}: {len(families)} families parsed")
"#;

/// What Prometheus sends (its default scrape protocols, most preferred first).
const PROMETHEUS_ACCEPT: &str = "application/openmetrics-text;version=1.0.0,\
    application/openmetrics-text;version=0.0.1;q=0.75,text/plain;version=0.0.4;q=0.5,*/*;q=0.1";

/// Scrapes `url` with `accept` (none: no Accept header) and checks the
/// answer with the real parser its Content-Type names.
fn check_scrape(python: &Path, url: &str, accept: Option<&str>, counters: &[&str]) {
    let mut req = agent().get(url);
    if let Some(a) = accept {
        req = req.header("Accept", a);
    }
    let mut res = req.call().unwrap_or_else(|e| panic!("GET {url}: {e}"));
    assert_eq!(res.status().as_u16(), 200, "GET {url}");
    let ctype = res
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    let text = res.body_mut().read_to_string().unwrap();
    let mode = match ctype.as_str() {
        "application/openmetrics-text; version=1.0.0; charset=utf-8" => {
            assert!(
                text.ends_with("# EOF\n"),
                "OpenMetrics without # EOF:\n{text}"
            );
            "openmetrics"
        }
        "text/plain; version=0.0.4; charset=utf-8" => "classic",
        other => panic!("GET {url} (Accept: {accept:?}): Content-Type {other:?}"),
    };
    if accept.is_some_and(|a| a.starts_with("application/openmetrics-text")) {
        assert_eq!(mode, "openmetrics", "Prometheus asked for OpenMetrics");
    }
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("metrics.txt");
    std::fs::write(&page, &text).unwrap();
    let out = Command::new(python)
        .args(["-c", PARSE, mode])
        .arg(&page)
        .args(counters)
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "GET {url} (Accept: {accept:?}, Content-Type {ctype}) does not parse as {mode}:\n{}{}\n---\n{text}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The scrapes every `/metrics` must pass: what Prometheus asks for, what a
/// person's client gets (no Accept, `*/*`, `text/plain`).
fn check_metrics(python: &Path, url: &str, counters: &[&str]) {
    for accept in [
        Some(PROMETHEUS_ACCEPT),
        Some("application/openmetrics-text; version=1.0.0"),
        None,
        Some("*/*"),
        Some("text/plain;version=0.0.4"),
    ] {
        check_scrape(python, url, accept, counters);
    }
}

#[test]
fn metrics_are_what_their_content_type_says_for_a_real_prometheus_parser() {
    let _g = serial();
    let Some(python) = prometheus_python() else {
        return;
    };
    let server = Server::start(&[]);
    // A refusal, so that the labelled counter has a sample too.
    assert_eq!(
        post(&server.url("/stabilize"), "video/mp4", b"").status,
        400
    );
    check_metrics(
        &python,
        &server.url("/metrics"),
        &[
            "amc_frames_processed",
            "amc_live_frames",
            "amc_live_frames_dropped",
            "amc_requests_rejected",
        ],
    );
}

#[test]
fn the_shared_job_table_carries_warnings_and_says_why_files_never_come() {
    let _g = serial();
    let Some(infra) = Infra::start() else {
        return;
    };
    let python = prometheus_python();
    let replica = infra.replica(&[]);
    let dir = tempfile::tempdir().unwrap();
    let clip = fallback_clip(dir.path());

    // Cancelled while queued (no worker yet): no output, ever.
    let cancelled = submit(&replica, &clip, "fov=70");
    let r = delete(&replica.url(&format!("/jobs/{cancelled}")));
    assert_eq!(r.json()["state"], "cancelled", "{}", r.text());
    let r = get(&replica.url(&format!("/jobs/{cancelled}/output")));
    assert_eq!(r.status, 409, "{}", r.text());
    let detail = r.json()["detail"].as_str().unwrap().to_string();
    assert!(
        detail.contains("cancelled") && detail.contains("no output") && !detail.contains("once"),
        "a cancelled job's output: {detail}"
    );

    // Both fallbacks, in the job's warnings; a failed job says why.
    let warned = submit(&replica, &clip, "readout_ms=auto");
    let r = post_multipart(
        &replica.url("/jobs"),
        &[
            ("video", "clip.mp4", "video/mp4", &clip),
            ("lens", "lens.json", "application/json", b"{not json"),
        ],
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let failed = r.json()["id"].as_str().unwrap().to_string();
    let worker = infra.worker(&[]);
    let job = wait_finished(&replica, &warned, Duration::from_secs(120));
    assert_eq!(job["state"], "done", "{job}");
    assert_both_fallbacks(&job_warnings(&job), "a shared job's metrics.warnings");
    let job = wait_finished(&replica, &failed, Duration::from_secs(120));
    assert_eq!(job["state"], "failed", "{job}");
    let r = get(&replica.url(&format!("/jobs/{failed}/telemetry.csv")));
    assert_eq!(r.status, 409, "{}", r.text());
    let detail = r.json()["detail"].as_str().unwrap().to_string();
    assert!(
        detail.contains("failed")
            && detail.contains("invalid lens file")
            && detail.contains("no telemetry"),
        "a failed job's telemetry: {detail}"
    );

    // The worker's log: its fallback warnings without "warning:" again.
    let log = worker.log();
    assert!(log.contains("focal length"), "{log}");
    assert_eq!(warn_lines_saying_warning(&log), Vec::<&str>::new());

    // /metrics of the replica and of the worker, through the real parser.
    if let Some(python) = python {
        check_metrics(
            &python,
            &replica.url("/metrics"),
            &["amc_frames_processed", "amc_live_frames"],
        );
        check_metrics(
            &python,
            &worker.url("/metrics"),
            &["amc_frames_processed", "amc_jobs_finished"],
        );
    }
}
