//! The methods compared and how each is run as a timed child process.
//!
//! Every method reads the same clip (the original file, or an ffmpeg concat
//! list of the image folder in natural order) and writes raw `.y4m`, so
//! "frames/s" is decode + stabilize + write for all, with no encoder cost.
//! Wall time and peak resident memory are those of the whole child process;
//! vid.stab's two passes are summed (time) and maxed (memory). Peak memory is
//! the kernel's high-water mark `VmHWM` of the child, read from
//! `/proc/PID/status` every 10 ms while it runs (`ru_maxrss` cannot be used:
//! Linux carries the parent's resident size across fork and exec into it).
//!
//! Validity of peer pixels: vid.stab and deshake fill uncovered pixels, so
//! each peer is run a second time (untimed) with a different fill
//! (`vidstabtransform crop=black` vs `crop=keep`, `deshake edge=blank` vs
//! `edge=original`) and the same motion (vid.stab reuses its transforms file;
//! deshake is deterministic and estimates motion on its input, not its
//! output; its `edge=mirror` is not used because it changes interior pixels too). A pixel is valid where the two outputs agree
//! exactly: a fill cannot agree with both black and the other fill except by
//! chance, and pixels interpolated from the border differ, so they count as
//! invalid too.

use super::error::CompareError;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A stabilizer in the comparison.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Ours, `--mode none`: undistorted, cropped input.
    None,
    /// Ours, `--mode stabilize`.
    Stabilize,
    /// Ours, `--mode saccade`.
    Saccade,
    /// Ours, `--mode stabilize --lookahead N`.
    StabilizeLookahead,
    /// ffmpeg vid.stab, two passes, `smoothing=10`.
    VidStab10,
    /// ffmpeg vid.stab, two passes, `smoothing=30`.
    VidStab30,
    /// ffmpeg vid.stab, two passes, `tripod=1` (peer of saccade).
    VidStabTripod,
    /// ffmpeg deshake (one pass, online).
    Deshake,
    /// The paper's own code (github.com/prgumd/AMC), no stabilization: its crop.
    PaperNone,
    /// The paper's own code, `--rotstab2` (its stabilize mode).
    PaperStabilize,
    /// The paper's own code, `--rotstab2 --saccade`.
    PaperSaccade,
    /// Ours, `--mode none` at the paper's framing and output size (see [`super::paper`]).
    MatchedNone,
    /// Ours, `--mode stabilize` at the paper's smoothing, framing and output size.
    MatchedStabilize,
    /// Ours, `--mode saccade` at the paper's framing and output size.
    MatchedSaccade,
    /// The paper's code in its stabilize mode with its tracker's orientations
    /// replaced by ours (those of [`Method::MatchedStabilize`]): its view
    /// filter, renderer and average on our estimates, which separates what its
    /// tracker does to its numbers from what its renderer does.
    PaperFedOurs,
    /// The same fed the clip's true orientations (clips with `gt.csv` only).
    PaperFedTruth,
    /// Its saccade mode fed ours (those of [`Method::MatchedSaccade`]).
    PaperFedOursSaccade,
    /// Its saccade mode fed the truth.
    PaperFedTruthSaccade,
}

/// Whose orientations the paper's renderer is fed instead of its tracker's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fed {
    /// Ours at matched settings, in the same mode.
    Ours,
    /// The clip's ground truth.
    Truth,
}

impl Method {
    pub const ALL: [Method; 8] = [
        Method::None,
        Method::Stabilize,
        Method::Saccade,
        Method::StabilizeLookahead,
        Method::VidStab10,
        Method::VidStab30,
        Method::VidStabTripod,
        Method::Deshake,
    ];

    /// Run besides [`Method::ALL`] with `--peer paper`: the paper's code in its
    /// three modes, ours at matched settings, then the paper's stabilize mode
    /// fed our orientations and (where known) the true ones.
    pub const PAPER: [Method; 10] = [
        Method::PaperNone,
        Method::PaperStabilize,
        Method::PaperSaccade,
        Method::MatchedNone,
        Method::MatchedStabilize,
        Method::MatchedSaccade,
        Method::PaperFedOurs,
        Method::PaperFedTruth,
        Method::PaperFedOursSaccade,
        Method::PaperFedTruthSaccade,
    ];

    /// Short name used in tables, plots and file names.
    pub fn label(self) -> &'static str {
        match self {
            Method::None => "none",
            Method::Stabilize => "stabilize",
            Method::Saccade => "saccade",
            Method::StabilizeLookahead => "stabilize-lookahead",
            Method::VidStab10 => "vidstab-s10",
            Method::VidStab30 => "vidstab-s30",
            Method::VidStabTripod => "vidstab-tripod",
            Method::Deshake => "deshake",
            Method::PaperNone => "paper-none",
            Method::PaperStabilize => "paper-stabilize",
            Method::PaperSaccade => "paper-saccade",
            Method::MatchedNone => "ours-matched-none",
            Method::MatchedStabilize => "ours-matched-stabilize",
            Method::MatchedSaccade => "ours-matched-saccade",
            Method::PaperFedOurs => "paper-fed-ours-stabilize",
            Method::PaperFedTruth => "paper-fed-truth-stabilize",
            Method::PaperFedOursSaccade => "paper-fed-ours-saccade",
            Method::PaperFedTruthSaccade => "paper-fed-truth-saccade",
        }
    }

    /// One of ours (runs `amc stabilize`).
    pub fn is_ours(self) -> bool {
        matches!(
            self,
            Method::None
                | Method::Stabilize
                | Method::Saccade
                | Method::StabilizeLookahead
                | Method::MatchedNone
                | Method::MatchedStabilize
                | Method::MatchedSaccade
        )
    }

    /// Ours at the paper's settings.
    pub fn is_matched(self) -> bool {
        matches!(
            self,
            Method::MatchedNone | Method::MatchedStabilize | Method::MatchedSaccade
        )
    }

    /// The paper's code in this mode (`run_paper.py --mode`).
    pub fn paper_mode(self) -> Option<&'static str> {
        match self {
            Method::PaperNone => Some("none"),
            Method::PaperStabilize => Some("stabilize"),
            Method::PaperSaccade => Some("saccade"),
            Method::PaperFedOurs | Method::PaperFedTruth => Some("stabilize"),
            Method::PaperFedOursSaccade | Method::PaperFedTruthSaccade => Some("saccade"),
            _ => None,
        }
    }

    /// The paper's code fed other orientations than its tracker's: whose.
    pub fn fed(self) -> Option<Fed> {
        match self {
            Method::PaperFedOurs | Method::PaperFedOursSaccade => Some(Fed::Ours),
            Method::PaperFedTruth | Method::PaperFedTruthSaccade => Some(Fed::Truth),
            _ => None,
        }
    }

    /// Our `--mode` value.
    pub fn our_mode(self) -> Option<&'static str> {
        match self {
            Method::None | Method::MatchedNone => Some("none"),
            Method::Stabilize | Method::StabilizeLookahead | Method::MatchedStabilize => {
                Some("stabilize")
            }
            Method::Saccade | Method::MatchedSaccade => Some("saccade"),
            _ => None,
        }
    }
}

/// How a clip is handed to ffmpeg.
#[derive(Clone, Debug)]
pub enum FfmpegInput {
    /// A file ffmpeg reads directly.
    File(PathBuf),
    /// An image folder: an ffconcat list (natural order, `1/fps` per image).
    Concat(PathBuf),
}

impl FfmpegInput {
    fn args(&self) -> Vec<OsString> {
        match self {
            FfmpegInput::File(p) => vec!["-i".into(), p.into()],
            FfmpegInput::Concat(list) => vec![
                "-f".into(),
                "concat".into(),
                "-safe".into(),
                "0".into(),
                "-i".into(),
                list.into(),
            ],
        }
    }
}

/// Writes an ffconcat list of `images` at `fps` to `list`.
pub fn write_concat_list(list: &Path, images: &[PathBuf], fps: f64) -> Result<(), CompareError> {
    let mut s = String::from("ffconcat version 1.0\n");
    for p in images {
        let abs = std::fs::canonicalize(p).map_err(|e| CompareError::io(p, e))?;
        let quoted = abs.to_string_lossy().replace('\'', "'\\''");
        s += &format!("file '{quoted}'\nduration {:.9}\n", 1.0 / fps);
    }
    std::fs::write(list, s).map_err(|e| CompareError::io(list, e))
}

/// Time and memory of a finished child (or of several passes).
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Usage {
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Peak resident set size, MiB (max over passes).
    pub peak_mib: f64,
}

impl Usage {
    fn then(self, other: Usage) -> Usage {
        Usage {
            seconds: self.seconds + other.seconds,
            peak_mib: self.peak_mib.max(other.peak_mib),
        }
    }
}

/// Runs `timed` `repeat` times (at least once): the fastest time, the largest peak
/// memory (on a shared machine the fastest run is the least disturbed one).
pub(super) fn best_of(
    repeat: usize,
    mut timed: impl FnMut() -> Result<Usage, CompareError>,
) -> Result<Usage, CompareError> {
    let mut best = timed()?;
    for _ in 1..repeat {
        let u = timed()?;
        best = Usage {
            seconds: best.seconds.min(u.seconds),
            peak_mib: best.peak_mib.max(u.peak_mib),
        };
    }
    Ok(best)
}

/// Runs `cmd` (stdin and stdout closed, stderr to `log`) and waits at most `limit`,
/// returning its wall time and peak memory.
pub fn run_timed(
    what: &str,
    cmd: &mut Command,
    log: &Path,
    limit: Duration,
) -> Result<Usage, CompareError> {
    let err_file = std::fs::File::create(log).map_err(|e| CompareError::io(log, e))?;
    cmd.stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::from(err_file));
    let start = Instant::now();
    let mut child = cmd.spawn().map_err(|e| CompareError::Spawn {
        what: what.to_string(),
        source: e,
    })?;
    let pid = child.id() as libc::pid_t;
    let status_path = PathBuf::from(format!("/proc/{pid}/status"));
    let mut peak_kib: Option<f64> = None;
    let mut polls = 0u64;
    loop {
        // `spawn` returns after the exec, so this is the child program's own memory.
        if polls == 0 {
            if let Some(kib) = vm_hwm_kib(&status_path) {
                peak_kib = Some(peak_kib.map_or(kib, |p| p.max(kib)));
            }
        }
        // Every 5th pass of the 2 ms loop.
        polls = (polls + 1) % 5;
        let mut status: libc::c_int = 0;
        // SAFETY: `rusage` is plain data that wait4 fills in; `pid` is our own child,
        // reaped only here (std's `Child` is never waited on afterwards).
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        let r = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if r == pid {
            let seconds = start.elapsed().as_secs_f64();
            let exited_ok = libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0;
            if !exited_ok {
                return Err(CompareError::ChildFailed {
                    what: what.to_string(),
                    detail: log_tail(log),
                });
            }
            // Without /proc (not Linux), ru_maxrss (KiB on Linux, an upper bound).
            let kib = peak_kib.unwrap_or(usage.ru_maxrss as f64);
            return Ok(Usage {
                seconds,
                peak_mib: kib / 1024.0,
            });
        }
        if r < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(CompareError::Spawn {
                    what: what.to_string(),
                    source: e,
                });
            }
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            return Err(CompareError::Timeout {
                what: what.to_string(),
                seconds: limit.as_secs(),
            });
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// `VmHWM` (peak resident set, KiB) from a `/proc/PID/status` file.
fn vm_hwm_kib(status: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(status).ok()?;
    text.lines()
        .find(|l| l.starts_with("VmHWM:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

/// The last lines of a child's log, as one line.
fn log_tail(log: &Path) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let tail = &lines[lines.len().saturating_sub(3)..];
    if tail.is_empty() {
        "no message".to_string()
    } else {
        tail.join(" | ")
    }
}

/// Filter prefix converting any decoded format (RGB from PNG frames, full-range JPEG)
/// to the planar 4:2:0 the peers need.
const PLANAR: &str = "format=yuv420p,";

fn ffmpeg() -> Command {
    let mut c = Command::new("ffmpeg");
    c.args(["-nostdin", "-hide_banner", "-v", "error", "-y"]);
    c
}

/// Where a peer's run writes.
pub struct PeerOutputs {
    /// The stabilized clip (timed run).
    pub main: PathBuf,
    /// The same with a different fill (validity run).
    pub alt: PathBuf,
}

/// Runs an ffmpeg peer: the timed run(s), then the untimed validity run.
pub fn run_peer(
    method: Method,
    input: &FfmpegInput,
    work: &Path,
    limit: Duration,
    repeat: usize,
) -> Result<(Usage, PeerOutputs), CompareError> {
    let label = method.label();
    let main = work.join(format!("{label}.y4m"));
    let alt = work.join(format!("{label}-alt.y4m"));
    let log = work.join(format!("{label}.log"));
    // One output frame per input frame, as raw YUV4MPEG2.
    let out_args = |path: &Path| -> Vec<OsString> {
        vec![
            "-an".into(),
            "-fps_mode".into(),
            "passthrough".into(),
            "-f".into(),
            "yuv4mpegpipe".into(),
            path.into(),
        ]
    };
    let usage = match method {
        Method::VidStab10 | Method::VidStab30 | Method::VidStabTripod => {
            let trf = work.join(format!("{label}.trf"));
            let tripod = method == Method::VidStabTripod;
            let detect = format!(
                "{PLANAR}vidstabdetect=result={}{}",
                filter_path(&trf),
                if tripod { ":tripod=1" } else { "" }
            );
            let transform = |crop: &str| {
                let opts = match method {
                    Method::VidStab10 => "smoothing=10".to_string(),
                    Method::VidStab30 => "smoothing=30".to_string(),
                    _ => "tripod=1".to_string(),
                };
                format!(
                    "{PLANAR}vidstabtransform=input={}:{opts}:crop={crop}",
                    filter_path(&trf)
                )
            };
            let usage = best_of(repeat, || {
                let pass1 = run_timed(
                    &format!("{label} (vidstabdetect)"),
                    ffmpeg()
                        .args(input.args())
                        .args(["-an", "-vf", &detect, "-f", "null", "-"]),
                    &log,
                    limit,
                )?;
                let pass2 = run_timed(
                    &format!("{label} (vidstabtransform)"),
                    ffmpeg()
                        .args(input.args())
                        .args(["-vf", &transform("black")])
                        .args(out_args(&main)),
                    &log,
                    limit,
                )?;
                Ok(pass1.then(pass2))
            })?;
            run_timed(
                &format!("{label} (validity run)"),
                ffmpeg()
                    .args(input.args())
                    .args(["-vf", &transform("keep")])
                    .args(out_args(&alt)),
                &log,
                limit,
            )?;
            usage
        }
        Method::Deshake => {
            let f = |edge: &str| format!("{PLANAR}deshake=rx=48:ry=48:edge={edge}");
            let u = best_of(repeat, || {
                run_timed(
                    label,
                    ffmpeg()
                        .args(input.args())
                        .args(["-vf", &f("blank")])
                        .args(out_args(&main)),
                    &log,
                    limit,
                )
            })?;
            run_timed(
                &format!("{label} (validity run)"),
                ffmpeg()
                    .args(input.args())
                    .args(["-vf", &f("original")])
                    .args(out_args(&alt)),
                &log,
                limit,
            )?;
            u
        }
        _ => {
            return Err(CompareError::Internal(format!(
                "{label} is not an ffmpeg peer"
            )))
        }
    };
    Ok((usage, PeerOutputs { main, alt }))
}

/// A path quoted for an ffmpeg filter option (`:` and `\` and `'` escaped).
fn filter_path(p: &Path) -> String {
    let s = p.to_string_lossy();
    let mut out = String::new();
    for c in s.chars() {
        if matches!(c, ':' | '\\' | '\'' | ',' | ';' | '[' | ']' | '=') {
            out.push('\\');
        }
        out.push(c);
    }
    out
}

/// How a matched run (ours at the paper's settings, see `compare::paper`)
/// differs: stabilizer options by name, and the frame rate the clip is read at.
#[derive(Clone, Copy, Debug)]
pub struct MatchedRun<'a> {
    pub options: &'a [(&'static str, String)],
    pub fps: f64,
}

/// Runs one of our modes as `amc stabilize` (the current executable), timed;
/// `matched` for the matched methods.
#[allow(clippy::too_many_arguments)]
pub fn run_ours(
    method: Method,
    input: &Path,
    lens_json: &Path,
    fps: Option<f64>,
    lookahead: usize,
    matched: Option<MatchedRun<'_>>,
    work: &Path,
    limit: Duration,
    repeat: usize,
) -> Result<(Usage, PathBuf), CompareError> {
    let label = method.label();
    let out = work.join(format!("{label}.y4m"));
    let log = work.join(format!("{label}.log"));
    let exe = std::env::current_exe().map_err(|e| CompareError::Spawn {
        what: "amc (current executable)".into(),
        source: e,
    })?;
    let mut cmd = Command::new(exe);
    cmd.arg("stabilize")
        .arg(input)
        .arg("-o")
        .arg(&out)
        .args(["--mode", method.our_mode().unwrap_or("stabilize"), "-q"])
        .arg("--lens")
        .arg(lens_json);
    if method == Method::StabilizeLookahead {
        cmd.args(["--lookahead", &lookahead.to_string()]);
    }
    if let Some(run) = matched {
        for (name, value) in run.options {
            let flag = amc_core::options::OPTIONS
                .iter()
                .find(|o| o.name == *name)
                .ok_or_else(|| CompareError::Internal(format!("no stabilizer option {name}")))?
                .flag;
            cmd.arg(format!("--{flag}")).arg(value);
        }
        cmd.args(["--fps", &run.fps.to_string()]);
    } else if let Some(f) = fps {
        cmd.args(["--fps", &f.to_string()]);
    }
    let usage = best_of(repeat, || run_timed(label, &mut cmd, &log, limit))?;
    Ok((usage, out))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_is_fed_our_estimates_after_they_are_made() {
        // compare_clip runs the methods in this order and hands the paper's
        // renderer the orientations of our matched stabilize run.
        let at = |m: Method| Method::PAPER.iter().position(|&x| x == m).unwrap();
        for fed in Method::PAPER.into_iter().filter(|m| m.fed().is_some()) {
            let mode = fed.paper_mode().unwrap();
            let ours = Method::PAPER
                .into_iter()
                .find(|m| m.is_matched() && m.our_mode() == Some(mode))
                .unwrap();
            assert!(
                at(ours) < at(fed),
                "{} before {}",
                ours.label(),
                fed.label()
            );
            assert!(!fed.is_ours() && !fed.is_matched());
            assert!(fed.label().ends_with(mode));
        }
        let labels: std::collections::HashSet<_> = Method::ALL
            .iter()
            .chain(&Method::PAPER)
            .map(|m| m.label())
            .collect();
        assert_eq!(labels.len(), Method::ALL.len() + Method::PAPER.len());
    }

    #[test]
    fn filter_paths_are_escaped() {
        assert_eq!(filter_path(Path::new("/a:b/c'd")), "/a\\:b/c\\'d");
    }

    #[test]
    fn timed_child_reports_time_memory_and_failure() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("log");
        let u = run_timed(
            "sleep",
            Command::new("sh").args(["-c", "sleep 0.2"]),
            &log,
            Duration::from_secs(10),
        )
        .unwrap();
        assert!(u.seconds >= 0.19 && u.seconds < 5.0, "{u:?}");
        assert!(u.peak_mib > 0.0);
        // A child that allocates 200 MiB (touching it) peaks above that, one that
        // does not stays far below, whatever this (test) process holds.
        let big = vec![1u8; 300 << 20];
        let small = run_timed(
            "sleep",
            Command::new("sh").args(["-c", "sleep 0.1"]),
            &log,
            Duration::from_secs(10),
        )
        .unwrap();
        assert!(
            small.peak_mib < 50.0,
            "{small:?} (parent holds {} MiB)",
            big.len() >> 20
        );
        drop(big);
        let e = run_timed(
            "false",
            Command::new("sh").args(["-c", "echo boom >&2; exit 3"]),
            &log,
            Duration::from_secs(10),
        )
        .unwrap_err();
        assert!(e.to_string().contains("boom"), "{e}");
        let e = run_timed(
            "slow",
            Command::new("sh").args(["-c", "sleep 5"]),
            &log,
            Duration::from_millis(200),
        )
        .unwrap_err();
        assert!(matches!(e, CompareError::Timeout { .. }), "{e}");
    }
}
