//! A real `amc serve` (or `amc worker`) on a loopback port, for the service's
//! end-to-end tests and bench.

use super::amc;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A running server; killed (SIGTERM, then SIGKILL) when dropped.
pub struct Server {
    pub child: Child,
    /// `http://127.0.0.1:PORT` (`https://` with `--tls-cert`)
    pub base: String,
    pub addr: String,
    /// The parent given as `--work-dir` (the server makes its own folder inside).
    pub work_parent: tempfile::TempDir,
    stderr_log: PathBuf,
}

impl Server {
    /// Starts `amc serve --addr 127.0.0.1:0 --work-dir TMP ARGS...` and waits until it listens.
    pub fn start(args: &[&str]) -> Server {
        Self::launch("serve", args, None, &[])
    }

    /// [`Server::start`] with extra environment variables (`RUST_LOG`, say).
    pub fn start_with_env(args: &[&str], env: &[(&str, &str)]) -> Server {
        Self::launch("serve", args, None, env)
    }

    /// Starts `amc worker --addr 127.0.0.1:0 --work-dir TMP ARGS...` (its
    /// `/healthz` and `/metrics`) and waits until it listens.
    pub fn worker(args: &[&str]) -> Server {
        Self::launch("worker", args, None, &[])
    }

    /// [`Server::worker`] with `--work-dir DIR` (another worker's, say).
    pub fn worker_in(dir: &Path, args: &[&str]) -> Server {
        let mut all = vec!["--work-dir", dir.to_str().expect("UTF-8 path")];
        all.extend_from_slice(args);
        Self::launch("worker", &all, None, &[])
    }

    /// [`Server::worker`] confined to one CPU core (`taskset -c CORE`), its
    /// ffmpeg children included.
    pub fn worker_on_core(core: usize, args: &[&str]) -> Server {
        Self::launch("worker", args, Some(core), &[])
    }

    fn launch(command: &str, args: &[&str], core: Option<usize>, env: &[(&str, &str)]) -> Server {
        let work_parent = tempfile::tempdir().expect("temp dir");
        let stderr_log = work_parent.path().with_extension("log");
        let log = std::fs::File::create(&stderr_log).expect("log file");
        let mut cmd = match core {
            Some(core) => {
                let mut c = Command::new("taskset");
                c.args(["-c", &core.to_string()]).arg(amc());
                c
            }
            None => Command::new(amc()),
        };
        cmd.arg(command).args(["--addr", "127.0.0.1:0"]);
        // A `--work-dir` in `args` (see `worker_in`) replaces the fresh one.
        if !args.contains(&"--work-dir") {
            cmd.arg("--work-dir").arg(work_parent.path());
        }
        let mut child = cmd
            .args(args)
            .envs(env.iter().copied())
            .current_dir(super::workspace_root())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::from(log))
            .spawn()
            .unwrap_or_else(|e| panic!("could not start amc {command}: {e}"));
        let stdout = child.stdout.take().expect("stdout");
        let mut line = String::new();
        BufReader::new(stdout)
            .read_line(&mut line)
            .unwrap_or_else(|e| panic!("reading amc {command}'s first line: {e}"));
        let base = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| {
                let log = std::fs::read_to_string(&stderr_log).unwrap_or_default();
                panic!("amc {command} did not start: {line:?}\n{log}")
            })
            .to_string();
        // `https://` with `--tls-cert`.
        let addr = base
            .trim_start_matches("http://")
            .trim_start_matches("https://")
            .to_string();
        Server {
            child,
            base,
            addr,
            work_parent,
            stderr_log,
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The server's log so far (for failure messages).
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.stderr_log).unwrap_or_default()
    }

    /// Files and folders left in the server's work directory (its scratch space).
    pub fn scratch_entries(&self) -> Vec<PathBuf> {
        let mut out = Vec::new();
        fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
            if let Ok(rd) = std::fs::read_dir(dir) {
                for e in rd.flatten() {
                    out.push(e.path());
                    if e.path().is_dir() {
                        walk(&e.path(), out);
                    }
                }
            }
        }
        for e in std::fs::read_dir(self.work_parent.path())
            .into_iter()
            .flatten()
            .flatten()
        {
            // The server's own work folder is expected; what is inside is not.
            walk(&e.path(), &mut out);
        }
        out
    }

    /// Waits (up to `within`) until the scratch space is empty; panics listing what is left.
    pub fn assert_no_scratch_left(&self, within: Duration) {
        let start = Instant::now();
        loop {
            let left = self.scratch_entries();
            if left.is_empty() {
                return;
            }
            if start.elapsed() > within {
                panic!("files left in the server's scratch space: {left:?}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// ffmpeg processes started by the server that are still running.
    pub fn ffmpeg_children(&self) -> Vec<u32> {
        children_named(self.pid(), "ffmpeg")
    }

    /// Resident memory of the server, kilobytes.
    pub fn rss_kb(&self) -> u64 {
        rss_kb(self.pid())
    }

    /// Kills the process at once (SIGKILL: no clean-up of its own).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Sends SIGTERM and waits (up to `within`) for the exit status.
    pub fn terminate(&mut self, within: Duration) -> Option<std::process::ExitStatus> {
        let _ = Command::new("kill")
            .args(["-TERM", &self.pid().to_string()])
            .status();
        let start = Instant::now();
        while start.elapsed() < within {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        None
    }

    pub fn healthy(&self) -> bool {
        let agent = agent();
        matches!(agent.get(&self.url("/healthz")).call(), Ok(r) if r.status() == 200)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            if self.terminate(Duration::from_secs(20)).is_none() {
                let _ = self.child.kill();
                let _ = self.child.wait();
            }
        }
        // The server's log stays only for a failed test, to read.
        if std::thread::panicking() {
            eprintln!("amc's log: {}", self.stderr_log.display());
        } else {
            let _ = std::fs::remove_file(&self.stderr_log);
        }
    }
}

/// Direct children of `pid` whose command name is `name`.
pub fn children_named(pid: u32, name: &str) -> Vec<u32> {
    children(pid)
        .into_iter()
        .filter(|(_, comm)| comm == name)
        .map(|(child, _)| child)
        .collect()
}

/// Direct children of `pid`, with their command names.
pub fn children(pid: u32) -> Vec<(u32, String)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(child) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{child}/stat")) else {
            continue;
        };
        // pid (comm) state ppid ...
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let ppid = stat[close + 1..]
            .split_whitespace()
            .nth(1)
            .and_then(|p| p.parse::<u32>().ok());
        if ppid == Some(pid) {
            out.push((child, stat[open + 1..close].to_string()));
        }
    }
    out
}

/// Running ffmpeg processes whose command line mentions `path` (orphans included).
pub fn ffmpeg_using(path: &Path) -> Vec<u32> {
    let needle = path.to_string_lossy().into_owned();
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmd) = std::fs::read(format!("/proc/{pid}/cmdline")) else {
            continue;
        };
        let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
        if cmd.starts_with("ffmpeg") && cmd.contains(&needle) {
            out.push(pid);
        }
    }
    out
}

/// Resident memory of a process, kilobytes (0 if it is gone).
pub fn rss_kb(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

/// An HTTP client that returns 4xx/5xx responses instead of errors, 300 s per request.
pub fn agent() -> ureq::Agent {
    agent_with_timeout(Duration::from_secs(300))
}

/// An HTTP client that returns 4xx/5xx responses instead of errors, `timeout` per request.
pub fn agent_with_timeout(timeout: Duration) -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(timeout))
        .build()
        .into()
}

/// The status [`answer`] and [`raw_request`] give a request that got no answer.
pub const NO_ANSWER: u16 = 0;

/// Status and body of a finished request; [`NO_ANSWER`] with `"{what}: {error}"` as the
/// body when there was no answer (a transport error).
pub fn answer(
    result: Result<ureq::http::Response<ureq::Body>, ureq::Error>,
    what: &str,
) -> (u16, Vec<u8>) {
    match result {
        Ok(mut res) => (res.status().as_u16(), body(&mut res)),
        Err(e) => (NO_ANSWER, format!("{what}: {e}").into_bytes()),
    }
}

/// The whole body of a response (empty if it cannot be read).
fn body(res: &mut ureq::http::Response<ureq::Body>) -> Vec<u8> {
    res.body_mut()
        .with_config()
        .limit(u64::MAX)
        .read_to_vec()
        .unwrap_or_default()
}

/// A finished HTTP exchange.
pub struct Reply {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Reply {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "status {}: body is not JSON ({e}): {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }

    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

fn reply(mut res: ureq::http::Response<ureq::Body>) -> Reply {
    let status = res.status().as_u16();
    let headers = res
        .headers()
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_str().unwrap_or("").to_string()))
        .collect();
    Reply {
        status,
        headers,
        body: body(&mut res),
    }
}

pub fn get(url: &str) -> Reply {
    reply(
        agent()
            .get(url)
            .call()
            .unwrap_or_else(|e| panic!("GET {url}: {e}")),
    )
}

pub fn delete(url: &str) -> Reply {
    reply(
        agent()
            .delete(url)
            .call()
            .unwrap_or_else(|e| panic!("DELETE {url}: {e}")),
    )
}

/// POSTs `body` with `content_type` (no Content-Type header when empty).
pub fn post(url: &str, content_type: &str, body: &[u8]) -> Reply {
    let mut req = agent().post(url);
    if !content_type.is_empty() {
        req = req.header("Content-Type", content_type);
    }
    reply(req.send(body).unwrap_or_else(|e| panic!("POST {url}: {e}")))
}

/// `method url` with extra headers (`Authorization`, say); `body` is sent
/// only with POST and PUT.
pub fn request(method: &str, url: &str, headers: &[(&str, &str)], body: &[u8]) -> Reply {
    let agent = agent();
    macro_rules! with_headers {
        ($req:expr) => {{
            let mut req = $req;
            for (k, v) in headers {
                req = req.header(*k, *v);
            }
            req
        }};
    }
    let result = match method {
        "GET" => with_headers!(agent.get(url)).call(),
        "HEAD" => with_headers!(agent.head(url)).call(),
        "DELETE" => with_headers!(agent.delete(url)).call(),
        "OPTIONS" => with_headers!(agent.options(url)).call(),
        "POST" => with_headers!(agent.post(url)).send(body),
        "PUT" => with_headers!(agent.put(url)).send(body),
        other => panic!("request: unsupported method {other}"),
    };
    reply(result.unwrap_or_else(|e| panic!("{method} {url}: {e}")))
}

/// A multipart form of (name, filename, content type, bytes) parts: its
/// Content-Type (with the boundary) and its body.
pub fn multipart_body(parts: &[(&str, &str, &str, &[u8])]) -> (String, Vec<u8>) {
    let boundary = "amc-test-boundary-7d41c2";
    let mut body = Vec::new();
    for (name, filename, ctype, bytes) in parts {
        write!(
            body,
            "--{boundary}\r\nContent-Disposition: form-data; name=\"{name}\"; filename=\"{filename}\"\r\nContent-Type: {ctype}\r\n\r\n"
        )
        .unwrap();
        body.extend_from_slice(bytes);
        body.extend_from_slice(b"\r\n");
    }
    write!(body, "--{boundary}--\r\n").unwrap();
    (format!("multipart/form-data; boundary={boundary}"), body)
}

/// POSTs a multipart form with (name, filename, content type, bytes) parts.
pub fn post_multipart(url: &str, parts: &[(&str, &str, &str, &[u8])]) -> Reply {
    let (content_type, body) = multipart_body(parts);
    post(url, &content_type, &body)
}

/// Sends a request by hand: `head` (request line and headers, without the
/// final blank line) then `body`, then reads whatever comes back ([`NO_ANSWER`] if nothing).
pub fn raw_request(addr: &str, head: &str, body: &[u8], close_early: bool) -> u16 {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(30))).ok();
    let _ = s.write_all(format!("{head}\r\n\r\n").as_bytes());
    let _ = s.write_all(body);
    if close_early {
        // The client goes away mid-upload.
        let _ = s.shutdown(std::net::Shutdown::Both);
        return NO_ANSWER;
    }
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    let text = String::from_utf8_lossy(&out);
    text.split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(NO_ANSWER)
}

/// A WebSocket client on `path` with a read timeout.
pub fn websocket(
    addr: &str,
    path: &str,
    read_timeout: Duration,
) -> Result<tungstenite::WebSocket<TcpStream>, String> {
    websocket_with(addr, path, &[], read_timeout)
}

/// [`websocket`] with extra headers on the upgrade request (`Authorization`, `Origin`).
pub fn websocket_with(
    addr: &str,
    path: &str,
    headers: &[(&str, &str)],
    read_timeout: Duration,
) -> Result<tungstenite::WebSocket<TcpStream>, String> {
    use tungstenite::client::IntoClientRequest;
    use tungstenite::http::{HeaderName, HeaderValue};
    let mut req = format!("ws://{addr}{path}")
        .into_client_request()
        .map_err(|e| e.to_string())?;
    for (k, v) in headers {
        req.headers_mut().insert(
            HeaderName::from_bytes(k.as_bytes()).map_err(|e| e.to_string())?,
            HeaderValue::from_str(v).map_err(|e| e.to_string())?,
        );
    }
    let stream = TcpStream::connect(addr).map_err(|e| e.to_string())?;
    stream.set_read_timeout(Some(read_timeout)).ok();
    stream.set_nodelay(true).ok();
    match tungstenite::client(req, stream) {
        Ok((ws, _)) => Ok(ws),
        Err(tungstenite::HandshakeError::Failure(tungstenite::Error::Http(res))) => {
            Err(format!("HTTP {}", res.status().as_u16()))
        }
        Err(e) => Err(e.to_string()),
    }
}

/// Polls `ok` every 100 ms until it holds; fails the test naming `what`
/// once `within` has passed.
pub fn wait_until(what: &str, within: Duration, mut ok: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ok() {
        assert!(start.elapsed() < within, "{what}: not within {within:?}");
        std::thread::sleep(Duration::from_millis(100));
    }
}
