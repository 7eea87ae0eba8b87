//! End-to-end tests of `amc serve`'s access control (API keys, tenants, live
//! tickets, limits, TLS), as an attacker would try it: no key, wrong keys, other
//! tenants' jobs, reused and borrowed tickets, foreign origins, floods, slow
//! clients, path tricks, and what reaches the log. A real server on loopback,
//! driven over HTTP, WebSocket and (for TLS and a second client address) curl.
//!
//! The tests run one at a time (they share two CPU cores and count requests).

use amc_e2e::cluster::Infra;
use amc_e2e::fixtures::test_clip;
use amc_e2e::server::{raw_request, request, wait_until, websocket_with, Reply, Server, NO_ANSWER};
use amc_e2e::{amc, amc_ok, data, run_amc};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// A keys file, filled with `amc keys new --append`.
struct Keys {
    _dir: tempfile::TempDir,
    file: PathBuf,
}

impl Keys {
    fn new() -> Keys {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("keys");
        Keys { _dir: dir, file }
    }

    /// A fresh key of `tenant` with `roles` (a comma list).
    fn add(&self, tenant: &str, roles: &str) -> String {
        let r = amc_ok(&["keys", "new", tenant, roles, "--append", self.path()]);
        r.stdout.trim().to_string()
    }

    fn path(&self) -> &str {
        self.file.to_str().expect("UTF-8 path")
    }
}

/// `method url` with `Authorization: Bearer KEY` (none when `key` is empty).
fn call(method: &str, url: &str, key: &str) -> Reply {
    send(method, url, key, b"")
}

/// [`call`] with a body (a clip: `Content-Type: video/mp4`).
fn send(method: &str, url: &str, key: &str, body: &[u8]) -> Reply {
    let auth = format!("Bearer {key}");
    let mut headers = vec![];
    if !key.is_empty() {
        headers.push(("Authorization", auth.as_str()));
    }
    if !body.is_empty() {
        headers.push(("Content-Type", "video/mp4"));
    }
    request(method, url, &headers, body)
}

/// A WebSocket upgrade of `path` with `headers`: `Ok(())` when it opened
/// (101), else `"HTTP 403"` and the like. A 409 (the previous publisher's
/// socket not yet seen closed) is tried again for a few seconds.
fn upgrade(server: &Server, path: &str, headers: &[(&str, &str)]) -> Result<(), String> {
    let start = Instant::now();
    loop {
        match websocket_with(&server.addr, path, headers, Duration::from_secs(10)) {
            Err(e) if e == "HTTP 409" && start.elapsed() < Duration::from_secs(5) => {
                std::thread::sleep(Duration::from_millis(100))
            }
            r => return r.map(drop),
        }
    }
}

fn bearer(key: &str) -> String {
    format!("Bearer {key}")
}

/// A 160x96, 1 s clip (made once per process).
fn tiny_clip() -> Vec<u8> {
    static CLIP: OnceLock<Vec<u8>> = OnceLock::new();
    CLIP.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("tiny.mp4");
        test_clip(&p, 160, 96, 30, 1.0);
        std::fs::read(&p).unwrap()
    })
    .clone()
}

fn job_id(r: &Reply) -> String {
    assert_eq!(r.status, 202, "POST /jobs: {}", r.text());
    r.json()["id"].as_str().expect("job id").to_string()
}

fn listed_ids(r: &Reply) -> Vec<String> {
    assert_eq!(r.status, 200, "GET /jobs: {}", r.text());
    r.json()["jobs"]
        .as_array()
        .expect("jobs array")
        .iter()
        .map(|j| j["id"].as_str().unwrap().to_string())
        .collect()
}

/// A refusal: `status`, problem+json, its detail naming `needle`, and none
/// of `secrets` echoed.
fn assert_problem(r: &Reply, status: u16, needle: &str, secrets: &[&str], what: &str) {
    assert_eq!(r.status, status, "{what}: {}", r.text());
    assert_eq!(
        r.header("content-type"),
        Some("application/problem+json"),
        "{what}"
    );
    let detail = r.json()["detail"].as_str().unwrap_or("").to_string();
    assert!(
        detail.contains(needle),
        "{what}: the detail does not name {needle:?}: {detail}"
    );
    assert_no_secret(&r.text(), secrets, &format!("{what}: the body"));
}

fn assert_no_secret(text: &str, secrets: &[&str], what: &str) {
    for s in secrets {
        assert!(
            !text.contains(s),
            "{what} holds a secret ({}...):\n{text}",
            &s[..s.len().min(10)]
        );
    }
}

/// `Retry-After` in whole seconds, at least 1.
fn retry_after(r: &Reply) -> u64 {
    let secs: u64 = r
        .header("retry-after")
        .unwrap_or_else(|| panic!("status {} without Retry-After", r.status))
        .parse()
        .expect("Retry-After in seconds");
    assert!(secs >= 1, "Retry-After: {secs}");
    secs
}

fn have(tool: &str) -> bool {
    let found = Command::new(tool)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    if !found {
        eprintln!("{tool} is not installed: skipping the part of the test that needs it");
    }
    found
}

/// `curl -s ARGS`: its `%{http_code}` ("000": no HTTP answer) and body.
fn curl(args: &[&str]) -> (String, String) {
    let out = Command::new("curl")
        .args(["-s", "-w", "\n%{http_code}"])
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("could not run curl");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let (body, code) = text.rsplit_once('\n').unwrap_or(("", &text));
    (code.trim().to_string(), body.to_string())
}

/// Reads until the server closes the connection (EOF or reset); how long
/// that took from `since`, or `None` if it was still open after `within`.
fn closed_within(stream: &mut TcpStream, since: Instant, within: Duration) -> Option<Duration> {
    let mut buf = [0u8; 4096];
    loop {
        let left = within.checked_sub(since.elapsed())?;
        stream
            .set_read_timeout(Some(left.max(Duration::from_millis(10))))
            .unwrap();
        match stream.read(&mut buf) {
            Ok(0) => return Some(since.elapsed()),
            Ok(_) => continue, // a 408, say
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return None
            }
            Err(_) => return Some(since.elapsed()),
        }
    }
}

/// The whole answer to a hand-written request (`Connection: close` added).
fn raw_text(addr: &str, request_line: &str) -> String {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10))).ok();
    write!(
        s,
        "{request_line}\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    String::from_utf8_lossy(&out).into_owned()
}

fn sha256_hex(text: &str) -> String {
    let mut child = Command::new("sha256sum")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("sha256sum");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(text.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .next()
        .unwrap()
        .to_string()
}

#[test]
fn keys_new_prints_the_key_once_and_the_file_keeps_only_its_hash() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("keys");
    let f = file.to_str().unwrap();
    let r = amc_ok(&["keys", "new", "alice", "view,submit", "--append", f]);
    assert_eq!(r.stdout.lines().count(), 1, "{}", r.stdout);
    let key = r.stdout.trim().to_string();
    assert!(
        key.len() >= 40 && !key.contains(char::is_whitespace),
        "{key:?}"
    );
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(!text.contains(&key), "the keys file holds the key itself");
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .collect();
    assert_eq!(lines.len(), 1, "{text}");
    let fields: Vec<&str> = lines[0].split_whitespace().collect();
    assert_eq!(fields[..2], ["alice", "submit,view"], "{text}");
    assert_eq!(fields[2], sha256_hex(&key), "{text}");
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(&file).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600, "the keys file is {mode:o}");
    // A second key: another line, another key.
    let second = amc_ok(&["keys", "new", "bob", "admin", "--append", f]);
    assert_ne!(second.stdout.trim(), key);
    assert_eq!(std::fs::read_to_string(&file).unwrap().lines().count(), 2);
    // Without --append: the key, then its line.
    let r = amc_ok(&["keys", "new", "carol", "publish"]);
    let out: Vec<&str> = r.stdout.lines().collect();
    assert_eq!(out.len(), 2, "{}", r.stdout);
    assert_eq!(
        out[1],
        format!("carol publish {}", sha256_hex(out[0])),
        "{}",
        r.stdout
    );
    // Roles and tenants outside the allowed sets are refused.
    for (tenant, roles) in [
        ("alice", "root"),
        ("alice", "Admin"),
        ("../etc", "view"),
        ("a b", "view"),
    ] {
        let r = run_amc(&["keys", "new", tenant, roles, "--append", f]);
        assert!(!r.success(), "keys new {tenant:?} {roles:?} was accepted");
        assert!(r.stdout.trim().is_empty(), "{}", r.stdout);
    }
    assert_eq!(std::fs::read_to_string(&file).unwrap().lines().count(), 2);
}

/// `amc ARGS` with its output in files: the exit status and stderr, or
/// `None` (killed) if it was still running after `within`.
fn exits_within(args: &[&str], within: Duration) -> Option<(std::process::ExitStatus, String)> {
    let dir = tempfile::tempdir().unwrap();
    let err = dir.path().join("stderr");
    let mut child = Command::new(amc())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&err).unwrap())
        .spawn()
        .expect("could not start amc");
    let start = Instant::now();
    while start.elapsed() < within {
        if let Some(status) = child.try_wait().unwrap() {
            return Some((status, std::fs::read_to_string(&err).unwrap_or_default()));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

/// `amc serve --addr ADDR --work-dir DIR ARGS...` must stop at start with a
/// non-zero status (within 20 s); its stderr.
fn refused_at_start(addr: &str, dir: &Path, args: &[&str], what: &str) -> String {
    let mut all = vec!["serve", "--addr", addr, "--work-dir", dir.to_str().unwrap()];
    all.extend_from_slice(args);
    let (status, stderr) = exits_within(&all, Duration::from_secs(20))
        .unwrap_or_else(|| panic!("amc serve {what} started"));
    assert!(!status.success(), "amc serve {what}: {stderr}");
    stderr
}

#[test]
fn a_public_address_without_keys_is_refused_at_start() {
    let _g = serial();
    let work = tempfile::tempdir().unwrap();
    let w = work.path().to_str().unwrap();
    let stderr = refused_at_start("0.0.0.0:0", work.path(), &[], "on 0.0.0.0 without keys");
    assert!(
        stderr.contains("--auth-keys") && stderr.contains("--insecure-no-auth"),
        "the refusal does not say what to do: {stderr}"
    );
    // Keys and the escape hatch together are a contradiction.
    let keys = Keys::new();
    keys.add("alice", "submit");
    refused_at_start(
        "127.0.0.1:0",
        work.path(),
        &["--auth-keys", keys.path(), "--insecure-no-auth"],
        "with --auth-keys and --insecure-no-auth",
    );
    // A keys file that is missing stops it.
    let missing = work.path().join("no-such-keys");
    let stderr = refused_at_start(
        "127.0.0.1:0",
        work.path(),
        &["--auth-keys", missing.to_str().unwrap()],
        "with a missing keys file",
    );
    assert!(stderr.contains("no-such-keys"), "{stderr}");

    // With --insecure-no-auth it serves, without keys.
    let mut child = Command::new(amc())
        .args([
            "serve",
            "--addr",
            "0.0.0.0:0",
            "--insecure-no-auth",
            "--work-dir",
            w,
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let port = line
        .trim()
        .strip_prefix("listening on http://0.0.0.0:")
        .map(str::to_string);
    let jobs = port
        .as_deref()
        .map(|p| call("GET", &format!("http://127.0.0.1:{p}/jobs"), "").status);
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let _ = child.wait();
    assert!(port.is_some(), "--insecure-no-auth did not start: {line:?}");
    assert_eq!(jobs, Some(200));
}

/// Moves the file's modification time `secs` ahead (the server reads its
/// keys file again when that time changes; some filesystems keep whole seconds).
fn touch_ahead(path: &Path, secs: u64) {
    std::fs::File::options()
        .write(true)
        .open(path)
        .unwrap()
        .set_modified(std::time::SystemTime::now() + Duration::from_secs(secs))
        .unwrap();
}

#[test]
fn a_key_removed_from_the_keys_file_is_refused_without_a_restart() {
    let _g = serial();
    let keys = Keys::new();
    let alice = keys.add("alice", "submit");
    let bob = keys.add("bob", "submit");
    let server = Server::start(&["--auth-keys", keys.path()]);
    let jobs = server.url("/jobs");
    assert_eq!(call("GET", &jobs, &alice).status, 200);
    // Revoke Alice: her line goes.
    let text = std::fs::read_to_string(&keys.file).unwrap();
    let kept: Vec<&str> = text.lines().filter(|l| !l.starts_with("alice ")).collect();
    assert_eq!(kept.len(), 1, "{text}");
    std::fs::write(&keys.file, format!("{}\n", kept.join("\n"))).unwrap();
    touch_ahead(&keys.file, 10);
    wait_until(
        "a revoked key is still served",
        Duration::from_secs(5),
        || call("GET", &jobs, &alice).status == 401,
    );
    assert_eq!(call("GET", &jobs, &bob).status, 200);
    // A key added meanwhile is served.
    let carol = keys.add("carol", "submit");
    touch_ahead(&keys.file, 20);
    wait_until("a new key is not served", Duration::from_secs(5), || {
        call("GET", &jobs, &carol).status == 200
    });
    assert_no_secret(&server.log(), &[&alice, &bob, &carol], "the log");
}

#[test]
fn a_key_pasted_into_the_keys_file_is_refused_without_printing_it() {
    let _g = serial();
    // An operator pastes a key where its hash goes: the server must not
    // take it, and what it says about it (the service's log) must not hold
    // the key. At start, and in the file of a running server.
    let key = amc_ok(&["keys", "new", "alice", "submit"])
        .stdout
        .lines()
        .next()
        .unwrap()
        .to_string();
    let work = tempfile::tempdir().unwrap();
    let pasted = work.path().join("pasted-keys");
    std::fs::write(&pasted, format!("alice submit {key}\n")).unwrap();
    let at_start = refused_at_start(
        "127.0.0.1:0",
        work.path(),
        &["--auth-keys", pasted.to_str().unwrap()],
        "with a key pasted in its keys file",
    );
    assert!(at_start.contains("pasted-keys:1"), "{at_start}");

    let keys = Keys::new();
    let bob = keys.add("bob", "submit");
    let server = Server::start(&["--auth-keys", keys.path()]);
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&keys.file)
        .unwrap();
    writeln!(f, "alice submit {key}").unwrap();
    drop(f);
    touch_ahead(&keys.file, 10);
    wait_until(
        "the changed keys file was not read again",
        Duration::from_secs(5),
        || server.log().contains("cannot be used"),
    );
    // The previous keys stay in force; the pasted key opens nothing.
    assert_eq!(call("GET", &server.url("/jobs"), &bob).status, 200);
    assert_eq!(call("GET", &server.url("/jobs"), &key).status, 401);
    assert_no_secret(&at_start, &[&key], "amc serve's error at start");
    assert_no_secret(&server.log(), &[&key], "the running server's log");
}

/// The protected endpoints (method, path), for an unknown job id.
fn protected() -> Vec<(&'static str, String)> {
    let id = "0123456789abcdef0123456789abcdef";
    vec![
        ("GET", "/jobs".into()),
        ("GET", "/jobs?limit=100".into()),
        ("POST", "/jobs".into()),
        ("POST", "/stabilize".into()),
        ("GET", format!("/jobs/{id}")),
        ("GET", format!("/jobs/{id}/output")),
        ("GET", format!("/jobs/{id}/telemetry")),
        ("GET", format!("/jobs/{id}/telemetry.csv")),
        ("DELETE", format!("/jobs/{id}")),
        ("GET", "/jobs/".into()),
        ("GET", "/live".into()),
        ("GET", "/live/ingest".into()),
        ("POST", "/live/ticket".into()),
        ("GET", "/metrics".into()),
        ("HEAD", "/metrics".into()),
        ("GET", "/openapi.json".into()),
    ]
}

#[test]
fn anonymous_and_wrong_keys_get_401_everywhere_but_healthz() {
    let _g = serial();
    let keys = Keys::new();
    let admin = keys.add("ops", "submit,view,publish,admin");
    let viewer = keys.add("alice", "view");
    let server = Server::start(&["--auth-keys", keys.path(), "--auth-failures", "1000"]);
    let clip = tiny_clip();
    // What a stolen copy of the keys file holds is no key.
    let file = std::fs::read_to_string(&keys.file).unwrap();
    let hash = file
        .lines()
        .next()
        .unwrap()
        .split_whitespace()
        .nth(2)
        .unwrap();
    let wrong = format!("amc_{}", "0".repeat(64));
    let truncated = &admin[..admin.len() - 1];
    let longer = format!("{admin}0");
    let basic = format!("Basic {admin}");
    let token = format!("Token {admin}");
    let credentials: Vec<Option<String>> = vec![
        None,
        Some(bearer(&wrong)),
        Some(bearer(hash)),
        Some(bearer(truncated)),
        Some(bearer(&longer)),
        Some(basic),
        Some(token),
        Some("Bearer".into()),
        Some(bearer("")),
        Some(admin.clone()),
    ];
    for (method, path) in protected() {
        for cred in &credentials {
            let mut headers = vec![];
            if let Some(c) = cred {
                headers.push(("Authorization", c.as_str()));
            }
            let body: &[u8] = if method == "POST" { &clip } else { b"" };
            if !body.is_empty() {
                headers.push(("Content-Type", "video/mp4"));
            }
            let r = request(method, &server.url(&path), &headers, body);
            let what = format!(
                "{method} {path} with {:?}",
                cred.as_ref().map(|c| &c[..c.len().min(12)])
            );
            assert_eq!(r.status, 401, "{what}: {}", r.text());
            assert!(
                r.header("www-authenticate")
                    .is_some_and(|h| h.starts_with("Bearer")),
                "{what}: WWW-Authenticate {:?}",
                r.header("www-authenticate")
            );
            if method != "HEAD" {
                assert_problem(&r, 401, "", &[&admin, &wrong, hash], &what);
            }
        }
    }
    // Public: the health check and the page, with or without a key.
    for cred in ["", &wrong] {
        assert_eq!(call("GET", &server.url("/healthz"), cred).status, 200);
        let page = call("GET", &server.url("/"), cred);
        assert_eq!(page.status, 200);
        assert!(page
            .header("content-type")
            .unwrap()
            .starts_with("text/html"));
    }
    // Any valid key reads the API's description; the scheme's case does not matter.
    assert_eq!(
        call("GET", &server.url("/openapi.json"), &viewer).status,
        200
    );
    let lower = format!("bearer {admin}");
    let r = request(
        "GET",
        &server.url("/jobs"),
        &[("Authorization", &lower)],
        b"",
    );
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(call("GET", &server.url("/metrics"), &admin).status, 200);
    assert_no_secret(&server.log(), &[&admin, &viewer, &wrong, hash], "the log");
}

#[test]
fn each_endpoint_needs_its_role_and_a_missing_one_is_named_in_a_403() {
    let _g = serial();
    let keys = Keys::new();
    let submit = keys.add("alice", "submit");
    let view = keys.add("alice", "view");
    let publish = keys.add("alice", "publish");
    let admin = keys.add("ops", "admin");
    let server = Server::start(&["--auth-keys", keys.path()]);
    let clip = tiny_clip();
    let id = "0123456789abcdef0123456789abcdef";
    let secrets = [
        submit.as_str(),
        view.as_str(),
        publish.as_str(),
        admin.as_str(),
    ];
    // (key, method, path, status, the role a 403 names). A 400 (empty
    // upload), 404 (no such job) or 426 (not an upgrade) passed the check.
    let (submit_k, view_k, publish_k, admin_k) = (
        submit.as_str(),
        view.as_str(),
        publish.as_str(),
        admin.as_str(),
    );
    let cases: Vec<(&str, &str, &str, String, u16, &str)> = vec![
        ("submit", submit_k, "GET", "/jobs".into(), 200, ""),
        ("submit", submit_k, "POST", "/stabilize".into(), 400, ""),
        ("submit", submit_k, "GET", format!("/jobs/{id}"), 404, ""),
        ("submit", submit_k, "GET", "/metrics".into(), 403, "admin"),
        ("submit", submit_k, "GET", "/live".into(), 403, "view"),
        (
            "submit",
            submit_k,
            "GET",
            "/live/ingest".into(),
            403,
            "publish",
        ),
        (
            "submit",
            submit_k,
            "POST",
            "/live/ticket".into(),
            403,
            "view or publish",
        ),
        ("submit", submit_k, "GET", "/openapi.json".into(), 200, ""),
        ("view", view_k, "GET", "/jobs".into(), 403, "submit"),
        ("view", view_k, "POST", "/jobs".into(), 403, "submit"),
        ("view", view_k, "POST", "/stabilize".into(), 403, "submit"),
        (
            "view",
            view_k,
            "GET",
            format!("/jobs/{id}/output"),
            403,
            "submit",
        ),
        (
            "view",
            view_k,
            "DELETE",
            format!("/jobs/{id}"),
            403,
            "submit",
        ),
        ("view", view_k, "GET", "/metrics".into(), 403, "admin"),
        ("view", view_k, "GET", "/live".into(), 426, ""),
        ("view", view_k, "GET", "/live/ingest".into(), 403, "publish"),
        ("view", view_k, "POST", "/live/ticket".into(), 200, ""),
        ("publish", publish_k, "GET", "/jobs".into(), 403, "submit"),
        ("publish", publish_k, "GET", "/live".into(), 403, "view"),
        ("publish", publish_k, "GET", "/live/ingest".into(), 426, ""),
        ("publish", publish_k, "POST", "/live/ticket".into(), 200, ""),
        ("publish", publish_k, "GET", "/metrics".into(), 403, "admin"),
        ("admin", admin_k, "GET", "/jobs".into(), 200, ""),
        ("admin", admin_k, "POST", "/stabilize".into(), 400, ""),
        ("admin", admin_k, "GET", "/metrics".into(), 200, ""),
        ("admin", admin_k, "GET", "/live".into(), 403, "view"),
        (
            "admin",
            admin_k,
            "GET",
            "/live/ingest".into(),
            403,
            "publish",
        ),
        (
            "admin",
            admin_k,
            "POST",
            "/live/ticket".into(),
            403,
            "view or publish",
        ),
    ];
    for (who, key, method, path, status, role) in cases {
        let what = format!("{method} {path} with the {who} key");
        // A clip to the upload endpoints, except where an empty one shows the check passed.
        let body = if method == "POST" && status == 403 && path != "/live/ticket" {
            clip.clone()
        } else {
            vec![]
        };
        let r = send(method, &server.url(&path), key, &body);
        if status == 403 {
            assert_problem(&r, 403, role, &secrets, &what);
            assert!(
                r.json()["detail"]
                    .as_str()
                    .unwrap()
                    .contains(&format!("needs the role {role}")),
                "{what}: {}",
                r.text()
            );
        } else {
            assert_eq!(r.status, status, "{what}: {}", r.text());
        }
    }
    // The sockets themselves.
    let (v, p, a) = (bearer(&view), bearer(&publish), bearer(&admin));
    assert_eq!(upgrade(&server, "/live", &[("Authorization", &v)]), Ok(()));
    assert_eq!(
        upgrade(&server, "/live/ingest", &[("Authorization", &p)]),
        Ok(())
    );
    for (path, auth) in [
        ("/live/ingest", &v),
        ("/live", &p),
        ("/live", &a),
        ("/live/ingest", &a),
    ] {
        assert_eq!(
            upgrade(&server, path, &[("Authorization", auth)]),
            Err("HTTP 403".into()),
            "{path}"
        );
    }
    assert_no_secret(&server.log(), &secrets, "the log");
}

/// Polls the job with `key` until it has finished.
fn wait_done(server: &Server, id: &str, key: &str) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let r = call("GET", &server.url(&format!("/jobs/{id}")), key);
        assert_eq!(r.status, 200, "GET /jobs/{id}: {}", r.text());
        let v = r.json();
        if ["done", "failed", "cancelled"].contains(&v["state"].as_str().unwrap_or("")) {
            return v;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "job {id} never finished: {v}\n{}",
            server.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Asks for another tenant's job every way there is: each is a 404 that
/// reads like one for a job that never existed.
fn assert_hidden(server: &Server, id: &str, key: &str, who: &str) {
    let unknown = "fedcba9876543210fedcba9876543210";
    for (method, suffix) in [
        ("GET", ""),
        ("GET", "/output"),
        ("GET", "/telemetry"),
        ("GET", "/telemetry.csv"),
        ("DELETE", ""),
    ] {
        let r = call(method, &server.url(&format!("/jobs/{id}{suffix}")), key);
        let what = format!("{who}: {method} /jobs/{{other tenant's job}}{suffix}");
        assert_eq!(r.status, 404, "{what}: {}", r.text());
        let never = call(
            method,
            &server.url(&format!("/jobs/{unknown}{suffix}")),
            key,
        );
        assert_eq!(never.status, 404, "{what}");
        assert_eq!(
            r.json()["detail"].as_str().unwrap().replace(id, "ID"),
            never.json()["detail"]
                .as_str()
                .unwrap()
                .replace(unknown, "ID"),
            "{what}: the answer tells an existing job from none"
        );
    }
    let listed = listed_ids(&call("GET", &server.url("/jobs?limit=100"), key));
    assert!(
        !listed.contains(&id.to_string()),
        "{who} lists another tenant's job"
    );
}

#[test]
fn tenants_see_only_their_own_jobs_and_admin_sees_all() {
    let _g = serial();
    let keys = Keys::new();
    let alice = keys.add("alice", "submit");
    let bob = keys.add("bob", "submit");
    let admin = keys.add("ops", "admin");
    let server = Server::start(&["--auth-keys", keys.path()]);
    let clip = tiny_clip();
    let a = job_id(&send("POST", &server.url("/jobs?n_avg=2"), &alice, &clip));
    let b = job_id(&send("POST", &server.url("/jobs?n_avg=2"), &bob, &clip));
    // While queued or running, and once done.
    assert_hidden(&server, &a, &bob, "bob");
    assert_hidden(&server, &b, &alice, "alice");
    assert_eq!(
        listed_ids(&call("GET", &server.url("/jobs"), &alice)),
        [a.clone()]
    );
    let all = listed_ids(&call("GET", &server.url("/jobs?limit=100"), &admin));
    assert!(all.contains(&a) && all.contains(&b), "admin lists {all:?}");
    assert_eq!(wait_done(&server, &a, &alice)["state"], "done");
    assert_eq!(wait_done(&server, &b, &bob)["state"], "done");
    assert_hidden(&server, &a, &bob, "bob");
    // Paging does not leak either: bob's pages of one job each hold only his.
    let mut cursor = String::new();
    let mut pages = vec![];
    for _ in 0..3 {
        let r = call("GET", &server.url(&format!("/jobs?limit=1{cursor}")), &bob);
        pages.extend(listed_ids(&r));
        match r.json()["next_cursor"].as_u64() {
            Some(c) => cursor = format!("&cursor={c}"),
            None => break,
        }
    }
    assert_eq!(pages, [b.clone()], "bob's pages");
    let out = call("GET", &server.url(&format!("/jobs/{a}/output")), &alice);
    assert_eq!(out.status, 200, "{}", out.text());
    assert!(out.body.len() > 1000);
    // Bob's DELETE removed nothing; admin's does. In this order:
    for (method, path, key, status) in [
        ("GET", "/telemetry.csv", &alice, 200),
        ("GET", "", &alice, 200),
        ("GET", "", &admin, 200),
        ("GET", "/output", &admin, 200),
        ("DELETE", "", &admin, 204),
        ("GET", "", &alice, 404),
    ] {
        let url = server.url(&format!("/jobs/{a}{path}"));
        assert_eq!(call(method, &url, key).status, status, "{method} {url}");
    }
    // The synchronous endpoint serves a key of its own tenant too.
    let r = send("POST", &server.url("/stabilize?n_avg=2"), &bob, &clip);
    assert_eq!(r.status, 200, "{}", r.text());
    assert_no_secret(&server.log(), &[&alice, &bob, &admin], "the log");
}

/// A live ticket for `key` (`POST /live/ticket`).
fn ticket(server: &Server, key: &str) -> String {
    let r = call("POST", &server.url("/live/ticket"), key);
    assert_eq!(r.status, 200, "POST /live/ticket: {}", r.text());
    assert_eq!(r.header("cache-control"), Some("no-store"));
    let v = r.json();
    assert_eq!(v["expires_in_s"], 30, "{v}");
    let t = v["ticket"].as_str().expect("ticket").to_string();
    assert!(t.len() >= 32, "{t}");
    t
}

#[test]
fn tickets_open_the_live_sockets_once_and_carry_their_keys_roles() {
    let _g = serial();
    let keys = Keys::new();
    let viewer = keys.add("alice", "view");
    let publisher = keys.add("alice", "publish");
    let submitter = keys.add("alice", "submit");
    let server = Server::start(&["--auth-keys", keys.path()]);
    // Issued first, redeemed last: past its 30 s.
    let stale = ticket(&server, &viewer);
    let issued = Instant::now();
    let mut tickets = vec![stale.clone()];
    let live = |t: &str| upgrade(&server, &format!("/live?ticket={t}"), &[]);
    let ingest = |t: &str| upgrade(&server, &format!("/live/ingest?ticket={t}"), &[]);

    // Single use.
    let t = ticket(&server, &viewer);
    tickets.push(t.clone());
    assert_ne!(t, stale);
    assert_eq!(live(&t), Ok(()));
    assert_eq!(
        live(&t),
        Err("HTTP 401".into()),
        "a ticket opened /live twice"
    );
    // It carries its key's roles: a viewer's ticket publishes nothing, a
    // publisher's watches nothing.
    let t = ticket(&server, &viewer);
    tickets.push(t.clone());
    assert_eq!(ingest(&t), Err("HTTP 403".into()));
    let t = ticket(&server, &publisher);
    tickets.push(t.clone());
    assert_eq!(live(&t), Err("HTTP 403".into()));
    let t = ticket(&server, &publisher);
    tickets.push(t.clone());
    assert_eq!(ingest(&t), Ok(()));
    // Only a key with a socket's role gets one.
    let r = call("POST", &server.url("/live/ticket"), &submitter);
    assert_problem(
        &r,
        403,
        "view or publish",
        &[&submitter],
        "a ticket for a submit key",
    );
    // A ticket opens the sockets only: not the API, not another ticket, and
    // it is not a key. None of these uses it up.
    let t = ticket(&server, &viewer);
    tickets.push(t.clone());
    for (method, path) in [
        ("GET", "/jobs"),
        ("GET", "/metrics"),
        ("GET", "/openapi.json"),
        ("POST", "/live/ticket"),
    ] {
        let r = call(method, &server.url(&format!("{path}?ticket={t}")), "");
        assert_problem(&r, 401, "", &[&t], &format!("{method} {path}?ticket="));
    }
    let as_key = bearer(&t);
    for path in ["/live", "/jobs"] {
        assert_eq!(
            request("GET", &server.url(path), &[("Authorization", &as_key)], b"").status,
            401,
            "a ticket as a bearer key on {path}"
        );
    }
    assert_eq!(live(&t), Ok(()));
    // Forged ones.
    for forged in [
        "0".repeat(64),
        "f".repeat(64),
        "x".into(),
        String::new(),
        t.to_uppercase(),
    ] {
        assert_eq!(
            live(&forged),
            Err("HTTP 401".into()),
            "a forged ticket {forged:?}"
        );
    }
    // Expiry: the first ticket, never used, is refused after 30 s.
    let ttl = Duration::from_secs(31);
    if let Some(wait) = ttl.checked_sub(issued.elapsed()) {
        std::thread::sleep(wait);
    }
    assert_eq!(
        live(&stale),
        Err("HTTP 401".into()),
        "a ticket older than 30 s opened /live"
    );
    let log = server.log();
    let mut secrets: Vec<&str> = tickets.iter().map(String::as_str).collect();
    secrets.extend([viewer.as_str(), publisher.as_str(), submitter.as_str()]);
    assert_no_secret(&log, &secrets, "the log");
}

#[test]
fn websocket_upgrades_from_a_foreign_origin_are_refused() {
    let _g = serial();
    let keys = Keys::new();
    let viewer = keys.add("alice", "view,publish");
    let server = Server::start(&["--auth-keys", keys.path()]);
    let auth = bearer(&viewer);
    let own = format!("http://{}", server.addr);
    let own_https = format!("https://{}", server.addr);
    let lookalike = format!("http://{}.evil.example", server.addr);
    let in_path = format!("http://evil.example/{}", server.addr);
    let userinfo = format!("http://{}@evil.example", server.addr);
    for path in ["/live", "/live/ingest"] {
        for origin in [
            "https://evil.example",
            "null",
            lookalike.as_str(),
            in_path.as_str(),
            userinfo.as_str(),
        ] {
            let headers = [("Authorization", auth.as_str()), ("Origin", origin)];
            assert_eq!(
                upgrade(&server, path, &headers),
                Err("HTTP 403".into()),
                "{path} from origin {origin}"
            );
            // A ticket does not help a foreign page either.
            let t = ticket(&server, &viewer);
            assert_eq!(
                upgrade(
                    &server,
                    &format!("{path}?ticket={t}"),
                    &[("Origin", origin)]
                ),
                Err("HTTP 403".into()),
                "{path}?ticket= from origin {origin}"
            );
        }
        for origin in [own.as_str(), own_https.as_str()] {
            let headers = [("Authorization", auth.as_str()), ("Origin", origin)];
            assert_eq!(
                upgrade(&server, path, &headers),
                Ok(()),
                "{path} from {origin}"
            );
        }
        // Tools send no Origin.
        assert_eq!(upgrade(&server, path, &[("Authorization", &auth)]), Ok(()));
    }
    // Without keys (loopback) the origin is checked all the same, and
    // --cors-origin lets a named site in.
    let open = Server::start(&["--cors-origin", "https://app.example"]);
    let evil = [("Origin", "https://evil.example")];
    assert_eq!(upgrade(&open, "/live", &evil), Err("HTTP 403".into()));
    assert_eq!(
        upgrade(&open, "/live", &[("Origin", "https://app.example")]),
        Ok(())
    );
    assert_eq!(upgrade(&open, "/live", &[]), Ok(()));
    assert_no_secret(&server.log(), &[&viewer], "the log");
}

#[test]
fn wrong_keys_from_one_address_get_429_but_the_right_key_still_works() {
    let _g = serial();
    let keys = Keys::new();
    let alice = keys.add("alice", "submit,view");
    let server = Server::start(&["--auth-keys", keys.path(), "--auth-failures", "5"]);
    let jobs = server.url("/jobs");
    for i in 0..5 {
        let wrong = format!("amc_{i:064}");
        assert_eq!(call("GET", &jobs, &wrong).status, 401, "wrong key {i}");
    }
    let r = call("GET", &jobs, &format!("amc_{:064}", 5));
    assert_problem(&r, 429, "--auth-failures", &[], "the 6th wrong key");
    let wait = retry_after(&r);
    assert!(wait <= 60, "Retry-After {wait}");
    // Wrong keys and wrong tickets stay refused while it waits...
    for i in 6..9 {
        assert_eq!(call("GET", &jobs, &format!("amc_{i:064}")).status, 429);
    }
    let forged = "0".repeat(64);
    assert_eq!(
        raw_request(
            &server.addr,
            &format!("GET /live?ticket={forged} HTTP/1.1\r\nHost: x\r\nConnection: close"),
            b"",
            false
        ),
        429
    );
    // ...and the right key is served from the same address.
    assert_eq!(call("GET", &jobs, &alice).status, 200);
    // Another address has its own budget.
    if have("curl") {
        let wrong = format!("Authorization: Bearer amc_{:064}", 99);
        let (code, _) = curl(&["--interface", "127.0.0.2", "-H", &wrong, &jobs]);
        assert_eq!(code, "401", "a wrong key from 127.0.0.2");
        let right = format!("Authorization: Bearer {alice}");
        let (code, body) = curl(&["--interface", "127.0.0.2", "-H", &right, &jobs]);
        assert_eq!(code, "200", "{body}");
    }
    assert_no_secret(&server.log(), &[&alice], "the log");
}

#[test]
fn a_key_over_its_rate_gets_429_and_other_keys_do_not() {
    let _g = serial();
    let keys = Keys::new();
    let alice = keys.add("alice", "submit");
    let bob = keys.add("bob", "submit");
    let server = Server::start(&["--auth-keys", keys.path(), "--key-rate", "5"]);
    let jobs = server.url("/jobs");
    let start = Instant::now();
    let mut ok = 0;
    let mut limited = vec![];
    for _ in 0..40 {
        let r = call("GET", &jobs, &alice);
        match r.status {
            200 => ok += 1,
            429 => limited.push(r),
            other => panic!("status {other}: {}", r.text()),
        }
    }
    let secs = start.elapsed().as_secs_f64();
    // A burst of 10, then 5 a second.
    let allowed = 10 + (5.0 * secs).ceil() as usize + 1;
    assert!(
        ok >= 10 && ok <= allowed,
        "{ok} of 40 requests served in {secs:.2} s at --key-rate 5"
    );
    assert!(!limited.is_empty());
    for r in &limited {
        assert_problem(r, 429, "--key-rate", &[&alice], "over the key's rate");
        assert!(retry_after(r) <= 2);
    }
    // Bob's key is not held back by Alice's.
    assert_eq!(call("GET", &jobs, &bob).status, 200);
    // Alice is served again once she has waited.
    std::thread::sleep(Duration::from_millis(1100));
    assert_eq!(call("GET", &jobs, &alice).status, 200);
}

#[test]
fn a_tenant_gets_429_beyond_its_jobs_at_once_and_others_are_still_served() {
    let _g = serial();
    let keys = Keys::new();
    let alice = keys.add("alice", "submit");
    let bob = keys.add("bob", "submit");
    let server = Server::start(&[
        "--auth-keys",
        keys.path(),
        "--max-jobs-per-tenant",
        "2",
        "--workers",
        "1",
    ]);
    let karma = std::fs::read(data("karma/karma.mp4")).unwrap();
    let clip = tiny_clip();
    let first = job_id(&send("POST", &server.url("/jobs?fov=70"), &alice, &karma));
    let second = job_id(&send("POST", &server.url("/jobs?fov=70"), &alice, &karma));
    let r = send("POST", &server.url("/jobs"), &alice, &clip);
    assert_problem(
        &r,
        429,
        "--max-jobs-per-tenant",
        &[&alice],
        "alice's third job",
    );
    retry_after(&r);
    let r = send("POST", &server.url("/stabilize"), &alice, &clip);
    assert_problem(
        &r,
        429,
        "--max-jobs-per-tenant",
        &[&alice],
        "alice's upload to /stabilize",
    );
    // The two are still at work: the refusal was the limit's.
    let state = call("GET", &server.url(&format!("/jobs/{second}")), &alice).json();
    assert_eq!(state["state"], "queued", "{state}");
    // Bob has his own.
    job_id(&send("POST", &server.url("/jobs"), &bob, &clip));
    // Cancelling one frees its place.
    let r = call("DELETE", &server.url(&format!("/jobs/{first}")), &alice);
    assert_eq!(r.status, 200, "{}", r.text());
    let start = Instant::now();
    loop {
        let r = send("POST", &server.url("/jobs"), &alice, &clip);
        if r.status == 202 {
            break;
        }
        assert_eq!(r.status, 429, "{}", r.text());
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "a cancelled job still counts against its tenant"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn slow_clients_are_capped_per_address_and_cut_after_the_header_timeout() {
    let _g = serial();
    let server = Server::start(&["--max-connections-per-ip", "4", "--header-timeout", "2"]);
    let opened = Instant::now();
    // Three send half a request line, one sends nothing.
    let mut slow: Vec<TcpStream> = (0..4)
        .map(|i| {
            let mut s = TcpStream::connect(&server.addr).unwrap();
            if i < 3 {
                s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
                    .unwrap();
            }
            s
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    // A fifth from the same address is closed at once, unanswered.
    let t = Instant::now();
    let head = "GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close";
    assert_eq!(raw_request(&server.addr, head, b"", false), NO_ANSWER);
    assert!(
        t.elapsed() < Duration::from_secs(1),
        "the fifth connection was held"
    );
    // Another address is served meanwhile.
    if have("curl") {
        let (code, _) = curl(&[
            "--max-time",
            "5",
            "--interface",
            "127.0.0.2",
            &server.url("/healthz"),
        ]);
        assert_eq!(
            code, "200",
            "/healthz from 127.0.0.2 while 127.0.0.1 holds its connections"
        );
    }
    // The slow ones are cut after --header-timeout.
    for (i, s) in slow.iter_mut().enumerate() {
        let after = closed_within(s, opened, Duration::from_secs(5))
            .unwrap_or_else(|| panic!("slow connection {i} still open 5 s after it opened"));
        assert!(
            after >= Duration::from_millis(1500),
            "slow connection {i} was cut after {after:?}, before the header timeout"
        );
    }
    // Their places are free again.
    let t = Instant::now();
    loop {
        let status = raw_request(&server.addr, head, b"", false);
        if status == 200 {
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(3),
            "no place freed: {status}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // A keep-alive connection left idle after its answer is cut too.
    let mut idle = TcpStream::connect(&server.addr).unwrap();
    idle.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        .unwrap();
    idle.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut buf = [0u8; 4096];
    let n = idle.read(&mut buf).unwrap();
    assert!(
        buf[..n].starts_with(b"HTTP/1.1 200"),
        "{}",
        String::from_utf8_lossy(&buf[..n])
    );
    let answered = Instant::now();
    closed_within(&mut idle, answered, Duration::from_secs(5))
        .expect("an idle keep-alive connection still open 5 s after its answer");
    assert!(server.healthy());
}

#[test]
fn protected_endpoints_cannot_be_reached_by_path_tricks() {
    let _g = serial();
    let keys = Keys::new();
    let admin = keys.add("ops", "submit,view,publish,admin");
    let web = tempfile::tempdir().unwrap();
    let www = web.path().join("www");
    std::fs::create_dir(&www).unwrap();
    std::fs::write(www.join("index.html"), "<!doctype html><title>amc</title>").unwrap();
    let marker = "amc-secret-next-to-the-page";
    std::fs::write(web.path().join("secret.txt"), marker).unwrap();
    let server = Server::start(&[
        "--auth-keys",
        keys.path(),
        "--web-dir",
        www.to_str().unwrap(),
    ]);
    // Each spelling of a protected endpoint: refused or unknown, never served.
    let addr = server.addr.clone();
    let absolute = |p: &str| format!("GET http://{addr}{p} HTTP/1.1");
    let mut lines: Vec<String> = [
        "/jobs",
        "//jobs",
        "/jobs/",
        "/Jobs",
        "/%6Aobs",
        "/jobs;x",
        "/./jobs",
        "/x/../jobs",
        "/healthz/../jobs",
        "/healthz/%2e%2e/jobs",
        "/metrics",
        "//metrics",
        "/metrics/",
        "/METRICS",
        "/%6Detrics",
        "/./metrics",
        "/healthz/../metrics",
        "/openapi.json/",
        "/live/ticket/",
        "/jobs%2f0123456789abcdef0123456789abcdef",
    ]
    .iter()
    .map(|p| format!("GET {p} HTTP/1.1"))
    .collect();
    lines.push(absolute("/jobs"));
    lines.push(absolute("/metrics"));
    lines.push("POST /live/ticket HTTP/1.1".into());
    lines.push("HEAD /jobs HTTP/1.1".into());
    lines.push("OPTIONS /jobs HTTP/1.1".into());
    for line in &lines {
        let text = raw_text(&server.addr, line);
        let status: u16 = text
            .split_whitespace()
            .nth(1)
            .and_then(|c| c.parse().ok())
            .unwrap_or(NO_ANSWER);
        assert!(
            [400, 401, 404, 405].contains(&status),
            "{line}: {status}\n{text}"
        );
        assert!(!text.contains("\"jobs\""), "{line} listed jobs:\n{text}");
        assert!(
            !text.contains("amc_jobs"),
            "{line} served the metrics:\n{text}"
        );
        assert!(
            !text.contains("\"ticket\""),
            "{line} issued a ticket:\n{text}"
        );
    }
    // The page's folder holds the page's files only.
    for p in [
        "/../secret.txt",
        "/%2e%2e/secret.txt",
        "/..%2fsecret.txt",
        "/%2e%2e%2fsecret.txt",
        "/.%2e/secret.txt",
        "//../secret.txt",
        "/..\\secret.txt",
    ] {
        let text = raw_text(&server.addr, &format!("GET {p} HTTP/1.1"));
        assert!(
            !text.contains(marker),
            "GET {p} served a file outside --web-dir:\n{text}"
        );
    }
    assert!(raw_text(&server.addr, "GET / HTTP/1.1").starts_with("HTTP/1.1 200"));
    assert_eq!(call("GET", &server.url("/jobs"), &admin).status, 200);
}

#[test]
fn keys_and_tickets_never_reach_the_log_even_at_trace_level() {
    let _g = serial();
    let keys = Keys::new();
    let alice = keys.add("alice", "submit,view,publish");
    let admin = keys.add("ops", "admin");
    let server = Server::start_with_env(&["--auth-keys", keys.path()], &[("RUST_LOG", "trace")]);
    let clip = tiny_clip();
    let wrong = format!("amc_{}", "7".repeat(64));
    let query_secret = "amc_query_secret_5ca1ab1e";
    let mut bodies = vec![];
    let id = job_id(&send("POST", &server.url("/jobs?n_avg=2"), &alice, &clip));
    bodies.push(call("GET", &server.url(&format!("/jobs/{id}")), &alice));
    bodies.push(send(
        "POST",
        &server.url("/stabilize?n_avg=2"),
        &alice,
        &clip,
    ));
    bodies.push(call("GET", &server.url("/jobs"), &wrong));
    bodies.push(call("GET", &server.url("/metrics"), &alice));
    bodies.push(call("GET", &server.url("/jobs"), &admin));
    bodies.push(request(
        "GET",
        &server.url("/jobs"),
        &[("Authorization", &format!("Basic {alice}"))],
        b"",
    ));
    bodies.push(call(
        "GET",
        &server.url(&format!("/jobs?key={query_secret}")),
        &alice,
    ));
    bodies.push(call(
        "GET",
        &server.url(&format!("/jobs?api_key={query_secret}")),
        "",
    ));
    let t = ticket(&server, &alice);
    assert_eq!(upgrade(&server, &format!("/live?ticket={t}"), &[]), Ok(()));
    assert_eq!(
        upgrade(&server, &format!("/live?ticket={t}"), &[]),
        Err("HTTP 401".into())
    );
    let t2 = ticket(&server, &alice);
    assert_eq!(
        upgrade(&server, &format!("/live/ingest?ticket={t2}"), &[]),
        Ok(())
    );
    let auth = bearer(&alice);
    assert_eq!(
        upgrade(&server, "/live", &[("Authorization", &auth)]),
        Ok(())
    );
    let wrong_auth = bearer(&wrong);
    assert_eq!(
        upgrade(&server, "/live", &[("Authorization", &wrong_auth)]),
        Err("HTTP 401".into())
    );
    wait_done(&server, &id, &alice);
    let secrets = [
        alice.as_str(),
        admin.as_str(),
        wrong.as_str(),
        query_secret,
        &t,
        &t2,
    ];
    for r in &bodies {
        assert_no_secret(&r.text(), &secrets, &format!("a {} answer", r.status));
    }
    // Let the last lines be written.
    std::thread::sleep(Duration::from_millis(300));
    let log = server.log();
    assert!(
        log.contains("/stabilize"),
        "no access log at trace level?\n{log}"
    );
    assert_no_secret(&log, &secrets, "the log at RUST_LOG=trace");
}

/// `openssl req` for a self-signed certificate of localhost and 127.0.0.1.
fn self_signed(dir: &Path) -> (PathBuf, PathBuf) {
    let (cert, key) = (dir.join("cert.pem"), dir.join("key.pem"));
    let status = Command::new("openssl")
        .args([
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:prime256v1",
            "-nodes",
            "-keyout",
        ])
        .arg(&key)
        .arg("-out")
        .arg(&cert)
        .args([
            "-days",
            "2",
            "-subj",
            "/CN=localhost",
            "-addext",
            "subjectAltName=DNS:localhost,IP:127.0.0.1",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("openssl");
    assert!(status.success(), "openssl could not make a certificate");
    (cert, key)
}

#[test]
fn https_and_wss_serve_with_a_certificate_and_keys_still_apply() {
    let _g = serial();
    if !have("openssl") || !have("curl") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (cert, tls_key) = self_signed(dir.path());
    let keys = Keys::new();
    let alice = keys.add("alice", "submit,view");
    let server = Server::start(&[
        "--auth-keys",
        keys.path(),
        "--tls-cert",
        cert.to_str().unwrap(),
        "--tls-key",
        tls_key.to_str().unwrap(),
        "--header-timeout",
        "2",
    ]);
    assert!(server.base.starts_with("https://"), "{}", server.base);
    let ca = cert.to_str().unwrap();
    let auth = format!("Authorization: Bearer {alice}");
    let (code, body) = curl(&["--cacert", ca, &server.url("/healthz")]);
    assert_eq!(code, "200", "{body}\n{}", server.log());
    let (code, _) = curl(&["--cacert", ca, &server.url("/jobs")]);
    assert_eq!(code, "401");
    let (code, body) = curl(&["--cacert", ca, "-H", &auth, &server.url("/jobs")]);
    assert_eq!(code, "200", "{body}");
    assert!(body.contains("\"jobs\""), "{body}");
    // WSS.
    let ws = |extra: &[&str]| {
        let mut args = vec![
            "--cacert",
            ca,
            "--http1.1",
            "--max-time",
            "2",
            "-o",
            "/dev/null",
            "-H",
            "Connection: Upgrade",
            "-H",
            "Upgrade: websocket",
            "-H",
            "Sec-WebSocket-Version: 13",
            "-H",
            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
        ];
        args.extend_from_slice(extra);
        let url = server.url("/live");
        args.push(&url);
        curl(&args).0
    };
    assert_eq!(ws(&["-H", &auth]), "101");
    assert_eq!(ws(&[]), "401");
    // Only TLS on this port; the certificate must be trusted.
    let plain = format!("http://{}/healthz", server.addr);
    assert_eq!(curl(&["--max-time", "5", &plain]).0, "000");
    assert_eq!(curl(&["--max-time", "5", &server.url("/healthz")]).0, "000");
    // A client that never starts its handshake is cut after --header-timeout.
    let opened = Instant::now();
    let mut silent = TcpStream::connect(&server.addr).unwrap();
    closed_within(&mut silent, opened, Duration::from_secs(5))
        .expect("a connection without a TLS handshake still open after 5 s");
    assert_eq!(curl(&["--cacert", ca, &server.url("/healthz")]).0, "200");
    assert_no_secret(&server.log(), &[&alice], "the log");
}

/// On shared infrastructure (a real PostgreSQL and SeaweedFS, as in
/// tests/cluster.rs: skipped where they are not installed, unless
/// `AMC_REQUIRE_SERVICES=1`).
#[test]
fn tenants_and_tickets_hold_across_replicas() {
    let _g = serial();
    let Some(infra) = Infra::start() else { return };
    let keys = Keys::new();
    let alice = keys.add("alice", "submit");
    let bob = keys.add("bob", "submit");
    let admin = keys.add("ops", "admin");
    let viewer = keys.add("alice", "view");
    let limits = ["--auth-keys", keys.path(), "--max-jobs-per-tenant", "1"];
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| infra.replica(&limits));
        let b = s.spawn(|| infra.replica(&limits));
        (a.join().unwrap(), b.join().unwrap())
    });
    let clip = tiny_clip();
    // No worker yet: the job waits in the table.
    let id = job_id(&send("POST", &a.url("/jobs?n_avg=2"), &alice, &clip));
    // The tenant's limit counts its jobs on every replica.
    let r = send("POST", &b.url("/jobs"), &alice, &clip);
    assert_problem(
        &r,
        429,
        "--max-jobs-per-tenant",
        &[&alice],
        "alice's second job, on b",
    );
    // Bob, on the other replica, cannot see, fetch or cancel it.
    assert_hidden(&b, &id, &bob, "bob on replica b");
    let all = listed_ids(&call("GET", &b.url("/jobs?limit=100"), &admin));
    assert!(all.contains(&id), "admin on b lists {all:?}");
    let own = job_id(&send("POST", &b.url("/jobs"), &bob, &clip));
    assert!(matches!(
        call("DELETE", &b.url(&format!("/jobs/{own}")), &bob).status,
        200 | 204
    ));
    // A ticket from one replica opens the other's socket, once, and is
    // kept only as its hash.
    let t = ticket(&a, &viewer);
    let stored = |sql: &str| infra.pg.psql(sql).trim().to_string();
    assert_eq!(stored("SELECT count(*) FROM amc_tickets"), "1");
    assert_eq!(
        stored(&format!("SELECT count(*) FROM amc_tickets WHERE encode(hash, 'hex') = '{t}' OR tenant = '{t}' OR roles = '{t}'")),
        "0"
    );
    assert_eq!(upgrade(&b, &format!("/live?ticket={t}"), &[]), Ok(()));
    assert_eq!(
        upgrade(&a, &format!("/live?ticket={t}"), &[]),
        Err("HTTP 401".into())
    );
    assert_eq!(
        upgrade(&b, &format!("/live?ticket={t}"), &[]),
        Err("HTTP 401".into())
    );
    // A worker with the same keys: its metrics are admin's.
    let worker = infra.worker(&["--auth-keys", keys.path()]);
    assert_eq!(call("GET", &worker.url("/healthz"), "").status, 200);
    assert_eq!(call("GET", &worker.url("/metrics"), "").status, 401);
    assert_eq!(call("GET", &worker.url("/metrics"), &alice).status, 403);
    assert_eq!(call("GET", &worker.url("/metrics"), &admin).status, 200);
    let done = wait_done(&b, &id, &alice);
    assert_eq!(done["state"], "done", "{done}");
    let out = call("GET", &b.url(&format!("/jobs/{id}/output")), &alice);
    assert_eq!(out.status, 200, "{}", out.text());
    assert!(out.body.len() > 1000);
    assert_hidden(&b, &id, &bob, "bob on replica b, once done");
    assert_hidden(&a, &id, &bob, "bob on replica a, once done");
    // Its objects sit under its tenant's prefix.
    let row = stored(&format!(
        "SELECT tenant || ' ' || input_key FROM amc_jobs WHERE id = '{id}'"
    ));
    assert!(
        row.starts_with("alice ") && row.contains(&format!("tenants/alice/jobs/{id}/")),
        "{row}"
    );
    let objects = infra.objects_of(&id);
    assert!(!objects.is_empty());
    for k in &objects {
        assert!(
            k.contains(&format!("tenants/alice/jobs/{id}/")),
            "object {k}"
        );
    }
    assert_eq!(
        call("DELETE", &a.url(&format!("/jobs/{id}")), &alice).status,
        204
    );
    for (name, s) in [("a", &a), ("b", &b), ("worker", &worker)] {
        assert_no_secret(
            &s.log(),
            &[&alice, &bob, &admin, &viewer, &t],
            &format!("{name}'s log"),
        );
    }
}

#[test]
fn a_public_healthz_names_no_source_url_host_or_path() {
    let _g = serial();
    // /healthz is open to strangers; a live source's URL can carry its
    // credentials (rtsp://user:pass@, srt's passphrase), and errors name hosts
    // and paths. With keys it says only which part is broken; the log has why.
    let keys = Keys::new();
    keys.add("ops", "admin");
    let source = "rtsp://pilot:hunter2secret@127.0.0.1:9/cam";
    let server = Server::start(&["--auth-keys", keys.path(), "--live-source", source]);
    let mut health = None;
    wait_until(
        "/healthz never reported the live source",
        Duration::from_secs(20),
        || {
            let h = call("GET", &server.url("/healthz"), "");
            let bad = h.status == 503;
            health = Some(h);
            bad
        },
    );
    let h = health.unwrap();
    let text = h.text();
    let j = h.json();
    assert_eq!(j["status"], "unavailable", "{j}");
    assert_eq!(j["live"]["state"], "unavailable", "{j}");
    assert!(
        j["detail"].as_str().unwrap().contains("the live source"),
        "{j}"
    );
    for secret in ["hunter2secret", "pilot", "127.0.0.1:9", "rtsp"] {
        assert!(!text.contains(secret), "/healthz shows {secret:?}: {text}");
    }
    wait_until(
        "the log never said why the source failed",
        Duration::from_secs(5),
        || server.log().contains("the live source"),
    );
}
