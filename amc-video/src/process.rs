//! ffmpeg/ffprobe child processes: spawning, a stall watchdog, and bounded
//! capture of their error output.
//!
//! The watchdog kills the child when we have been waiting on it (for a frame,
//! for a write to go through, for its exit) longer than the timeout. Waiting
//! that is our own doing (the stabilizer being slow between frames) does not
//! count, so long videos never time out, but a hung ffmpeg does.

use crate::error::VideoError;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use wait_timeout::ChildExt;

/// Error lines kept from a child's stderr (the first ones are the informative ones).
const MAX_STDERR_LINES: usize = 40;
/// Longest stderr line kept, in bytes.
const MAX_LINE_LEN: usize = 400;

/// Locks a mutex, ignoring poisoning: the data guarded here (a child handle,
/// a few strings) stays valid even if a thread panicked holding it.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A running ffmpeg or ffprobe.
pub(crate) struct Proc {
    /// Shared with the watchdog thread, which kills it on a stall.
    child: Arc<Mutex<Child>>,
    /// The child's process id (registered for cleanup until it is reaped).
    pid: u32,
    pub stdin: Option<ChildStdin>,
    pub stdout: Option<ChildStdout>,
    stderr_lines: Arc<Mutex<Vec<String>>>,
    stderr_thread: Option<JoinHandle<()>>,
    watchdog: Watchdog,
    /// Set once the child has been reaped.
    status: Option<ExitStatus>,
    pub tool: &'static str,
    /// The file the child works on, for messages.
    pub path: PathBuf,
    timeout: Duration,
    /// Paths the child knows by another name (a temporary file it writes to),
    /// replaced by the user's in messages: `(hidden, shown)`.
    aliases: Vec<(String, String)>,
}

impl Proc {
    /// Starts `tool args...` with piped stdin if `with_stdin` (an encoder),
    /// else piped stdout (a decoder or probe).
    /// Stderr is read by a thread: `[info]`-tagged `showinfo` frame lines
    /// (when `pts_tx` is given) have their `pts_time` sent through `pts_tx`;
    /// error lines are kept for messages.
    pub fn spawn(
        tool: &'static str,
        args: &[std::ffi::OsString],
        path: &Path,
        timeout: Duration,
        with_stdin: bool,
        pts_tx: Option<Sender<f64>>,
    ) -> Result<Self, VideoError> {
        // An encoder writes to a file; only decoders and probes talk on stdout.
        Self::spawn_piped(tool, args, path, timeout, with_stdin, !with_stdin, pts_tx)
    }

    /// [`Proc::spawn`] with each of stdin and stdout piped or not (a live
    /// encoder takes frames on one and gives its stream on the other).
    pub fn spawn_piped(
        tool: &'static str,
        args: &[std::ffi::OsString],
        path: &Path,
        timeout: Duration,
        with_stdin: bool,
        with_stdout: bool,
        pts_tx: Option<Sender<f64>>,
    ) -> Result<Self, VideoError> {
        let piped = |on: bool| if on { Stdio::piped() } else { Stdio::null() };
        let mut cmd = Command::new(tool);
        cmd.args(args)
            .stdin(piped(with_stdin))
            .stdout(piped(with_stdout))
            .stderr(Stdio::piped());
        // Its own process group keeps a terminal Ctrl-C away from ffmpeg:
        // the program decides what to do (drop sources and sinks, which
        // kills the children and removes partial output).
        #[cfg(unix)]
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        // Recorded in the same critical section as the spawn, so that an
        // interrupting signal never misses a child (see `cleanup`).
        let mut child = crate::cleanup::locked(|registry| {
            let child = cmd.spawn()?;
            registry.add_child(child.id());
            Ok(child)
        })
        .map_err(|e: std::io::Error| {
            if e.kind() == std::io::ErrorKind::NotFound {
                VideoError::ToolMissing {
                    tool,
                    detail: e.to_string(),
                }
            } else {
                VideoError::io(path, "start ffmpeg", e)
            }
        })?;
        let stdin = child.stdin.take();
        let stdout = child.stdout.take();
        let stderr = child.stderr.take();
        let stderr_lines = Arc::new(Mutex::new(Vec::new()));
        let stderr_thread = stderr.map(|err| {
            let lines = Arc::clone(&stderr_lines);
            std::thread::spawn(move || read_stderr(err, &lines, pts_tx))
        });
        let pid = child.id();
        let child = Arc::new(Mutex::new(child));
        let watchdog = Watchdog::start(Arc::clone(&child));
        Ok(Self {
            child,
            stdin,
            stdout,
            stderr_lines,
            stderr_thread,
            watchdog,
            status: None,
            pid,
            tool,
            path: path.to_path_buf(),
            timeout,
            aliases: Vec::new(),
        })
    }

    /// Makes messages name `shown` wherever the child's output names `hidden`
    /// (the full path, or its file name alone).
    pub fn alias(&mut self, hidden: &Path, shown: &Path) {
        self.aliases
            .push((hidden.display().to_string(), shown.display().to_string()));
        if let (Some(h), Some(s)) = (hidden.file_name(), shown.file_name()) {
            self.aliases.push((
                h.to_string_lossy().into_owned(),
                s.to_string_lossy().into_owned(),
            ));
        }
    }

    /// Starts the stall clock before a blocking operation on the child's pipes.
    pub fn arm(&self) {
        self.watchdog.arm(self.timeout);
    }

    /// Stops the stall clock after the operation.
    pub fn disarm(&self) {
        self.watchdog.disarm();
    }

    /// Whether the watchdog killed the child.
    pub fn timed_out(&self) -> bool {
        self.watchdog.fired.load(Ordering::SeqCst)
    }

    /// Closes stdin and waits (at most the timeout) for the child to exit,
    /// then for its stderr to be fully read.
    pub fn wait(&mut self) -> Result<ExitStatus, VideoError> {
        if let Some(status) = self.status {
            return Ok(status);
        }
        drop(self.stdin.take());
        let waited = {
            let mut child = lock(&self.child);
            match child.wait_timeout(self.timeout) {
                Ok(Some(status)) => Ok(status),
                Ok(None) => {
                    let _ = child.kill();
                    let _ = child.wait();
                    self.watchdog.fired.store(true, Ordering::SeqCst);
                    Err(self.timeout_error())
                }
                Err(e) => Err(VideoError::io(&self.path, "wait for ffmpeg", e)),
            }
        };
        // The child is gone, so its stderr is closed and the reader ends.
        if let Some(t) = self.stderr_thread.take() {
            let _ = t.join();
        }
        crate::cleanup::locked(|r| r.remove_child(self.pid));
        let status = waited?;
        self.status = Some(status);
        Ok(status)
    }

    /// Kills the child (if still running) and reaps it.
    /// The error for a write to stdin that failed: ffmpeg stopped taking
    /// input, because it stalled (killed, the timeout's error) or exited (its
    /// status and stderr say why).
    pub fn input_refused(&mut self) -> VideoError {
        if self.timed_out() {
            self.kill();
            return self.timeout_error();
        }
        let status = self.wait().ok();
        self.failure(status)
    }

    pub fn kill(&mut self) {
        if self.status.is_none() {
            let mut child = lock(&self.child);
            let _ = child.kill();
            if let Ok(status) = child.wait() {
                self.status = Some(status);
            }
            crate::cleanup::locked(|r| r.remove_child(self.pid));
        }
    }

    /// The child's error output as one line (its first error line, plus the
    /// last one, which is often the summary), or `fallback` when it said nothing.
    pub fn error_detail(&self, fallback: &str) -> String {
        let lines = lock(&self.stderr_lines);
        // ffmpeg often prefixes messages with the input path, which our own
        // message already names.
        let path_prefix = format!("{}: ", self.path.display());
        let clean = |l: &str| {
            let mut l = l.to_string();
            for (hidden, shown) in &self.aliases {
                if !hidden.is_empty() {
                    l = l.replace(hidden.as_str(), shown);
                }
            }
            l.strip_prefix(path_prefix.as_str())
                .map(str::to_string)
                .unwrap_or(l)
        };
        match (lines.first(), lines.last()) {
            (Some(first), Some(last)) if lines.len() > 1 => {
                format!("{}; {}", clean(first), clean(last))
            }
            (Some(first), _) => clean(first),
            _ => fallback.to_string(),
        }
    }

    /// The error for a stall.
    pub fn timeout_error(&self) -> VideoError {
        VideoError::Timeout {
            path: self.path.clone(),
            tool: self.tool,
            secs: self.timeout.as_secs_f64(),
        }
    }

    /// The error for a child that exited unsuccessfully (or was killed by the watchdog).
    pub fn failure(&self, status: Option<ExitStatus>) -> VideoError {
        if self.timed_out() {
            return self.timeout_error();
        }
        let fallback = match status {
            Some(s) => format!("exited with {s}"),
            None => "stopped unexpectedly".to_string(),
        };
        VideoError::Ffmpeg {
            path: self.path.clone(),
            tool: self.tool,
            detail: self.error_detail(&fallback),
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        // Killing first makes sure nothing keeps writing to a file that the
        // owner is about to delete, and unblocks the stderr reader.
        drop(self.stdin.take());
        drop(self.stdout.take());
        self.kill();
        self.watchdog.stop();
        if let Some(t) = self.stderr_thread.take() {
            let _ = t.join();
        }
    }
}

/// Reads a child's stderr line by line until it closes.
fn read_stderr(
    err: std::process::ChildStderr,
    lines: &Mutex<Vec<String>>,
    pts_tx: Option<Sender<f64>>,
) {
    let mut reader = BufReader::new(err);
    let mut raw = Vec::new();
    // The filtered stream's time base, from showinfo's `config in` line.
    let mut time_base: Option<(u64, u64)> = None;
    loop {
        raw.clear();
        match reader.read_until(b'\n', &mut raw) {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
        let line = String::from_utf8_lossy(&raw);
        let line = line.trim_end();
        match classify(line) {
            Line::FramePts { pts, pts_time } => {
                if let Some(tx) = &pts_tx {
                    let _ = tx.send(frame_time(pts, pts_time, time_base));
                }
            }
            Line::TimeBase(tb) => time_base = Some(tb),
            Line::Noise => {}
            Line::Error(msg) => {
                let mut kept = lock(lines);
                if kept.len() < MAX_STDERR_LINES && !msg.is_empty() {
                    let mut msg = msg.to_string();
                    if msg.len() > MAX_LINE_LEN {
                        let mut cut = MAX_LINE_LEN;
                        while !msg.is_char_boundary(cut) {
                            cut -= 1;
                        }
                        msg.truncate(cut);
                        msg.push_str("...");
                    }
                    kept.push(msg);
                }
            }
        }
    }
}

enum Line<'a> {
    /// A `showinfo` frame line: the frame's integer timestamp (when it has
    /// one) and its `pts_time` (NaN when it has none).
    FramePts {
        /// `pts:`, in the time base of the showinfo's input.
        pts: Option<i64>,
        /// `pts_time:`, printed with six significant digits only.
        pts_time: f64,
    },
    /// showinfo's `config in time_base: NUM/DEN`.
    TimeBase((u64, u64)),
    /// Informational output.
    Noise,
    /// Something worth showing a person.
    Error(&'a str),
}

/// Sorts a stderr line. With `-loglevel level+...` ffmpeg tags each line with
/// its level (`[ctx @ 0x..] [error] msg`); untagged lines come from children
/// run with `-loglevel error` and are errors.
fn classify(line: &str) -> Line<'_> {
    const LEVELS: &[(&str, bool)] = &[
        ("[quiet] ", true),
        ("[panic] ", true),
        ("[fatal] ", true),
        ("[error] ", true),
        ("[warning] ", false),
        ("[info] ", false),
        ("[verbose] ", false),
        ("[debug] ", false),
        ("[trace] ", false),
    ];
    for &(tag, is_error) in LEVELS {
        if let Some(pos) = line.find(tag) {
            let msg = line[pos + tag.len()..].trim();
            if is_error {
                return Line::Error(msg);
            }
            if tag == "[info] " && line.contains("showinfo") {
                if msg.starts_with("n:") {
                    return Line::FramePts {
                        pts: parse_pts(msg),
                        pts_time: parse_pts_time(msg),
                    };
                }
                if let Some(tb) = msg
                    .strip_prefix("config in time_base:")
                    .and_then(parse_time_base)
                {
                    return Line::TimeBase(tb);
                }
            }
            return Line::Noise;
        }
    }
    Line::Error(strip_context(line.trim()))
}

/// Drops ffmpeg's `[mov,mp4 @ 0x55d1] ` context prefix: it means nothing to a person.
fn strip_context(line: &str) -> &str {
    if line.starts_with('[') {
        if let Some(end) = line.find("] ") {
            if line[..end].contains(" @ ") {
                return line[end + 2..].trim_start();
            }
        }
    }
    line
}

/// A frame's time in seconds: its integer timestamp in the stream's time base
/// where both are known (exact: `pts_time` has six significant digits, 16.4333
/// for 493/30, which put frames 33 us off a constant rate), else `pts_time`.
fn frame_time(pts: Option<i64>, pts_time: f64, time_base: Option<(u64, u64)>) -> f64 {
    match (pts, time_base) {
        (Some(pts), Some((num, den))) if pts_time.is_finite() => {
            pts as f64 * num as f64 / den as f64
        }
        _ => pts_time,
    }
}

/// `pts: 3000` (or `pts:1478997` once the number fills its column) from a
/// showinfo line; `None` when absent or `NOPTS`.
fn parse_pts(msg: &str) -> Option<i64> {
    let mut tokens = msg.split_whitespace();
    while let Some(tok) = tokens.next() {
        if let Some(rest) = tok.strip_prefix("pts:") {
            let value = if rest.is_empty() {
                tokens.next()?
            } else {
                rest
            };
            return value.parse().ok();
        }
    }
    None
}

/// ` 1/30, frame_rate: 30/1` after showinfo's `config in time_base:`.
fn parse_time_base(rest: &str) -> Option<(u64, u64)> {
    let tb = rest.split(',').next()?.trim();
    let (num, den) = tb.split_once('/')?;
    let (num, den) = (num.trim().parse().ok()?, den.trim().parse().ok()?);
    (num > 0 && den > 0).then_some((num, den))
}

/// `pts_time:1.234` from a showinfo line; NaN when absent or `NOPTS`.
fn parse_pts_time(msg: &str) -> f64 {
    msg.split_whitespace()
        .find_map(|tok| tok.strip_prefix("pts_time:"))
        .and_then(|v| v.parse::<f64>().ok())
        .filter(|t| t.is_finite())
        .unwrap_or(f64::NAN)
}

/// Kills a child when a blocking operation on it takes longer than allowed.
struct Watchdog {
    shared: Arc<(Mutex<WatchState>, Condvar)>,
    fired: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

#[derive(Default)]
struct WatchState {
    deadline: Option<Instant>,
    stop: bool,
}

impl Watchdog {
    fn start(child: Arc<Mutex<Child>>) -> Self {
        let shared = Arc::new((Mutex::new(WatchState::default()), Condvar::new()));
        let fired = Arc::new(AtomicBool::new(false));
        let thread = {
            let shared = Arc::clone(&shared);
            let fired = Arc::clone(&fired);
            std::thread::spawn(move || {
                let (state, cv) = &*shared;
                let mut st = lock(state);
                loop {
                    if st.stop {
                        return;
                    }
                    match st.deadline {
                        None => st = cv.wait(st).unwrap_or_else(|e| e.into_inner()),
                        Some(d) => {
                            let now = Instant::now();
                            if now >= d {
                                st.deadline = None;
                                fired.store(true, Ordering::SeqCst);
                                // Killing closes the pipes, which unblocks the
                                // reader or writer that armed us.
                                let _ = lock(&child).kill();
                            } else {
                                st = cv
                                    .wait_timeout(st, d - now)
                                    .map(|(g, _)| g)
                                    .unwrap_or_else(|e| e.into_inner().0);
                            }
                        }
                    }
                }
            })
        };
        Self {
            shared,
            fired,
            thread: Some(thread),
        }
    }

    fn arm(&self, timeout: Duration) {
        let (state, cv) = &*self.shared;
        lock(state).deadline = Some(Instant::now() + timeout);
        cv.notify_one();
    }

    fn disarm(&self) {
        // No need to wake the thread: it finds no deadline when it wakes.
        lock(&self.shared.0).deadline = None;
    }

    fn stop(&mut self) {
        let (state, cv) = &*self.shared;
        lock(state).stop = true;
        cv.notify_one();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Runs a child to completion (each stall bounded by the timeout) and returns
/// its exit status, its stdout and, when it failed, its first error line.
pub(crate) fn run_capture(
    tool: &'static str,
    args: &[std::ffi::OsString],
    path: &Path,
    timeout: Duration,
) -> Result<(ExitStatus, Vec<u8>, Option<String>), VideoError> {
    use std::io::Read;
    let mut proc = Proc::spawn(tool, args, path, timeout, false, None)?;
    let mut out = Vec::new();
    proc.arm();
    let read = match proc.stdout.as_mut() {
        Some(s) => s.read_to_end(&mut out),
        None => Ok(0),
    };
    proc.disarm();
    if proc.timed_out() {
        return Err(proc.timeout_error());
    }
    read.map_err(|e| VideoError::io(path, "read ffmpeg output", e))?;
    let status = proc.wait()?;
    let err = if status.success() {
        None
    } else {
        Some(proc.error_detail(&format!("exited with {status}")))
    };
    Ok((status, out, err))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classifies_stderr_lines() {
        let l = "[Parsed_showinfo_0 @ 0x55f5] [info] n:   3 pts:   3000 pts_time:0.112036 pos: 1 fmt:yuv420p";
        assert!(
            matches!(classify(l), Line::FramePts { pts: Some(3000), pts_time } if (pts_time - 0.112036).abs() < 1e-9)
        );
        let l = "[Parsed_showinfo_0 @ 0x55f5] [info] n: 493 pts:1478997 pts_time:16.4333 pos: 1";
        assert!(matches!(
            classify(l),
            Line::FramePts {
                pts: Some(1478997),
                ..
            }
        ));
        let l = "[Parsed_showinfo_0 @ 0x55f5] [info] n:   3 pts:NOPTS pts_time:NOPTS";
        assert!(matches!(classify(l), Line::FramePts { pts: None, pts_time } if pts_time.is_nan()));
        let l = "[Parsed_showinfo_0 @ 0x55f5] [info] config in time_base: 1/26777, frame_rate: 0/0";
        assert!(matches!(classify(l), Line::TimeBase((1, 26777))));
        let l = "[Parsed_showinfo_0 @ 0x55f5] [info] config out time_base: 0/0, frame_rate: 0/0";
        assert!(matches!(classify(l), Line::Noise));
        let l = "[mov,mp4 @ 0x1] [error] moov atom not found";
        assert!(matches!(classify(l), Line::Error("moov atom not found")));
        let l = "[warning] deprecated pixel format";
        assert!(matches!(classify(l), Line::Noise));
        assert!(matches!(
            classify("x.mp4: Invalid data"),
            Line::Error("x.mp4: Invalid data")
        ));
        let l = "[mov,mp4,m4a @ 0x55cf64af04c0] moov atom not found";
        assert!(matches!(classify(l), Line::Error("moov atom not found")));
    }

    /// Frame 493 of a 30 fps clip is at 493/30 s exactly, not at showinfo's 16.4333.
    #[test]
    fn frame_times_come_from_the_integer_timestamp() {
        let t = frame_time(Some(493), 16.4333, Some((1, 30)));
        assert_eq!(t, 493.0 / 30.0);
        assert_eq!(frame_time(Some(493), 16.4333, None), 16.4333);
        assert!(frame_time(None, f64::NAN, Some((1, 30))).is_nan());
    }
}
