//! The paper's own implementation (github.com/prgumd/AMC, Python/JAX) as a
//! peer: where its environment is, how it is run, and the settings at which
//! ours is run beside it.
//!
//! `tools/paper-peer/setup.sh SRC DIR` makes the environment: `DIR/venv`
//! (the Python packages), `DIR/source` (a link to the user's clone; its code
//! is never part of this repository) and `DIR/versions.txt`. The loader that
//! feeds it a clip, `tools/paper-peer/run_paper.py`, is compiled into `amc`
//! and written into the work folder, so it always matches this binary.
//! Without the environment the peer is skipped, never an error: CI has none.
//!
//! Output validity: the paper's renderer averages frames warped with a black
//! border and keeps a mask of the pixels every averaged frame covers; the
//! loader writes that mask (less the one-pixel band the bilinear warp mixes
//! with black) beside the output, one byte per pixel (see run_paper.py).
//!
//! Matched settings: the paper's code fixes its view filter's dt at 1/60 s
//! (and resets its template every 5/60 s) whatever the clip's rate, works on
//! the input downsampled 2x and shows the crop inside a 12.5% margin. "Ours
//! matched" runs at the same smoothing per frame (`--fps 60`, the paper's
//! gains `rate_a` 2 and `rate_b` 40), the same template resets in time
//! (`n_track`: every 3rd frame of a 24-35 frames/s clip, [`paper_reset_frames`]),
//! the same framing (`--zoom none --margin 0.125`) and the same output size
//! as the paper's crop.

use super::error::CompareError;
use super::peers::{best_of, run_timed, Method, Usage};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;
use thiserror::Error;

/// The loader, compiled in (written to the work folder when the peer runs).
const LOADER: &str = include_str!("../../../tools/paper-peer/run_paper.py");

/// Environment variable naming the environment's folder.
pub const ENV_VAR: &str = "AMC_PAPER_PEER";

/// The paper's processing scale (`--downsample 2`) and margin (`--margins 0.125`).
const DOWNSAMPLE: f64 = 2.0;
const MARGIN: f64 = 0.125;
/// The paper's view filter step, seconds per frame (`rot_filt_dt=1/60.0`).
pub const PAPER_DT_S: f64 = 1.0 / 60.0;
/// The paper's view filter gains: `tau = 1/0.5` per second, `beta = 40` per second per radian.
const PAPER_RATE_A: f64 = 2.0;
const PAPER_RATE_B: f64 = 40.0;

/// Why the paper's environment cannot be used (the peer is then skipped).
#[derive(Debug, Error, PartialEq)]
pub enum PaperEnvError {
    #[error("no paper-peer environment at {} (make one with tools/paper-peer/setup.sh SRC DIR, or pass --paper-env DIR)", .0.display())]
    Missing(PathBuf),
    #[error("{}: no Python in the environment's venv (rerun tools/paper-peer/setup.sh)", .0.display())]
    NoPython(PathBuf),
    #[error("{}: not a clone of github.com/prgumd/AMC (no rotation_stabilize.py)", .0.display())]
    NoSource(PathBuf),
    #[error("{}: cannot read: {detail}", path.display())]
    Versions { path: PathBuf, detail: String },
    #[error("versions.txt line {line}: {text:?} is not KEY=VALUE")]
    VersionLine { line: usize, text: String },
    #[error("versions.txt names no {0} (rerun tools/paper-peer/setup.sh)")]
    VersionMissing(&'static str),
}

/// What `versions.txt` states: the paper's commit and the packages it ran with.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Versions {
    pub paper_commit: String,
    pub python: String,
    pub jax: String,
    pub jaxlib: String,
    pub numpy: String,
    pub opencv: String,
    pub scipy: String,
}

impl Versions {
    /// Parses `KEY=VALUE` lines (blank lines and `#` comments ignored; unknown keys kept out).
    pub fn parse(text: &str) -> Result<Self, PaperEnvError> {
        let mut pairs = Vec::new();
        for (i, l) in text.lines().enumerate() {
            let l = l.trim();
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let (k, v) = l
                .split_once('=')
                .ok_or_else(|| PaperEnvError::VersionLine {
                    line: i + 1,
                    text: l.to_string(),
                })?;
            pairs.push((k.trim().to_string(), v.trim().to_string()));
        }
        let get = |key: &'static str| {
            pairs
                .iter()
                .find(|(k, _)| k == key)
                .map(|(_, v)| v.clone())
                .ok_or(PaperEnvError::VersionMissing(key))
        };
        Ok(Versions {
            paper_commit: get("paper_commit")?,
            python: get("python")?,
            jax: get("jax")?,
            jaxlib: get("jaxlib")?,
            numpy: get("numpy")?,
            opencv: get("opencv")?,
            scipy: get("scipy")?,
        })
    }

    /// One line for the report.
    pub fn describe(&self) -> String {
        format!(
            "prgumd/AMC commit {}, Python {}, jax {} (jaxlib {}, CPU), numpy {}, OpenCV {}, SciPy {}",
            self.paper_commit,
            self.python,
            self.jax,
            self.jaxlib,
            self.numpy,
            self.opencv,
            self.scipy
        )
    }
}

/// A usable environment made by `tools/paper-peer/setup.sh`.
#[derive(Clone, Debug)]
pub struct PaperEnv {
    pub python: PathBuf,
    pub source: PathBuf,
    pub versions: Versions,
}

/// `$AMC_PAPER_PEER`, else `~/.cache/amc/paper-peer`.
pub fn default_env_dir() -> PathBuf {
    if let Some(d) = std::env::var_os(ENV_VAR).filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    let home = std::env::var_os("HOME").map_or_else(|| PathBuf::from("."), PathBuf::from);
    home.join(".cache/amc/paper-peer")
}

impl PaperEnv {
    /// Checks the environment in `dir`.
    pub fn locate(dir: &Path) -> Result<Self, PaperEnvError> {
        if !dir.is_dir() {
            return Err(PaperEnvError::Missing(dir.to_path_buf()));
        }
        let python = dir.join("venv/bin/python");
        if !python.exists() {
            return Err(PaperEnvError::NoPython(python));
        }
        let source = dir.join("source");
        if !source.join("rotation_stabilize.py").is_file() {
            return Err(PaperEnvError::NoSource(source));
        }
        let vpath = dir.join("versions.txt");
        let text = std::fs::read_to_string(&vpath).map_err(|e| PaperEnvError::Versions {
            path: vpath.clone(),
            detail: e.to_string(),
        })?;
        Ok(PaperEnv {
            python,
            source,
            versions: Versions::parse(&text)?,
        })
    }
}

/// Whether the paper's peer runs in this comparison.
#[derive(Clone, Debug)]
pub enum PaperStatus {
    /// `--peer paper` was not asked for.
    NotRequested,
    /// Asked for, but its environment is missing or broken: skipped.
    Skipped(String),
    Ready(PaperEnv),
}

impl PaperStatus {
    /// The status for `--peer paper` with environment `dir` (None: not asked for).
    pub fn resolve(dir: Option<&Path>) -> Self {
        match dir {
            None => PaperStatus::NotRequested,
            Some(d) => match PaperEnv::locate(d) {
                Ok(env) => PaperStatus::Ready(env),
                Err(e) => PaperStatus::Skipped(e.to_string()),
            },
        }
    }
}

/// The paper's output size for an input of `width` x `height`: its crop
/// rectangle at half resolution, as its code computes it (`int()` truncation).
pub fn crop_size(width: usize, height: usize) -> (usize, usize) {
    let side = |n: usize| {
        let d = (n as f64 / DOWNSAMPLE) as usize;
        d - 2 * (d as f64 * MARGIN) as usize
    };
    (side(width), side(height))
}

/// Frames between the paper's template resets on a clip of `clip_fps`: it
/// resets when `frame_i / round(fps)` has advanced by more than 5/60 s since
/// the last reset (`tracker_rotstab_reset_period`), so every 3rd frame at
/// 24-35 frames/s and every 6th at 60.
pub fn paper_reset_frames(clip_fps: f64) -> usize {
    let fps = if clip_fps.is_finite() {
        clip_fps.round().clamp(1.0, 10_000.0) as usize
    } else {
        30
    };
    fps * 5 / 60 + 1
}

/// Our stabilizer options (by name, as `amc_core::options` knows them) at the
/// paper's smoothing, template resets and framing, with its output size, for
/// an input of that size and frame rate.
pub fn matched_options(width: usize, height: usize, clip_fps: f64) -> Vec<(&'static str, String)> {
    let (w, h) = crop_size(width, height);
    vec![
        ("n_track", paper_reset_frames(clip_fps).to_string()),
        ("rate_a", PAPER_RATE_A.to_string()),
        ("rate_b", PAPER_RATE_B.to_string()),
        ("zoom", "none".into()),
        ("margin", MARGIN.to_string()),
        ("output_width", w.to_string()),
        ("output_height", h.to_string()),
    ]
}

/// The frame rate our matched runs read the clip at: one paper filter step per frame.
pub fn matched_fps() -> f64 {
    1.0 / PAPER_DT_S
}

/// Where a run of the paper's code writes.
pub struct PaperOutputs {
    /// The stabilized crop, `.y4m` (4:4:4).
    pub main: PathBuf,
    /// Its validity: one byte per output pixel per frame (non-zero: valid).
    pub valid: PathBuf,
    /// The run's log (its last line times the paper's own loop).
    pub log: PathBuf,
}

/// Runs the paper's code on `input` in `method`'s mode, timed like the other
/// peers; with `rotations` (a CSV with columns `rx,ry,rz`, see
/// [`crate::gt::orientations_csv`]) its renderer takes those orientations
/// instead of its tracker's.
#[allow(clippy::too_many_arguments)]
pub fn run(
    env: &PaperEnv,
    method: Method,
    input: &Path,
    lens_json: &Path,
    rotations: Option<&Path>,
    fps: f64,
    work: &Path,
    limit: Duration,
    repeat: usize,
) -> Result<(Usage, PaperOutputs), CompareError> {
    let mode = method.paper_mode().ok_or_else(|| {
        CompareError::Internal(format!("{} is not the paper's code", method.label()))
    })?;
    let label = method.label();
    let loader = work.join("run_paper.py");
    std::fs::write(&loader, LOADER).map_err(|e| CompareError::io(&loader, e))?;
    let outs = PaperOutputs {
        main: work.join(format!("{label}.y4m")),
        valid: work.join(format!("{label}.valid")),
        log: work.join(format!("{label}.log")),
    };
    let mut cmd = Command::new(&env.python);
    cmd.arg(&loader)
        .arg("--source")
        .arg(&env.source)
        .arg("--input")
        .arg(input)
        .arg("--output")
        .arg(&outs.main)
        .arg("--valid")
        .arg(&outs.valid)
        .args(["--mode", mode, "--fps", &fps.to_string()])
        .arg("--lens")
        .arg(lens_json)
        .arg("--work")
        .arg(work);
    if let Some(r) = rotations {
        cmd.arg("--rotations").arg(r);
    }
    let usage = best_of(repeat, || run_timed(label, &mut cmd, &outs.log, limit))?;
    Ok((usage, outs))
}

/// Seconds the paper's own loop took (without decoding the clip and writing
/// its recording layout), from the loader's `paper-timing` log line.
pub fn loop_seconds(log: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(log).ok()?;
    parse_loop_seconds(&text)
}

fn parse_loop_seconds(text: &str) -> Option<f64> {
    let line = text
        .lines()
        .rev()
        .find(|l| l.starts_with("paper-timing "))?;
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix("stabilize_s="))?
        .parse()
        .ok()
        .filter(|s: &f64| s.is_finite() && *s > 0.0)
}

/// Reads the next frame's validity (`len` bytes) from the loader's mask file.
pub fn read_valid(
    file: &mut impl std::io::Read,
    path: &Path,
    mask: &mut Vec<u8>,
    len: usize,
) -> Result<bool, CompareError> {
    mask.resize(len, 0);
    match file.read_exact(mask) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Ok(false),
        Err(e) => Err(CompareError::io(path, e)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "paper_commit=821f601c\npaper_source=/src\npython=3.11.7\n\
        jax=0.7.1\njaxlib=0.7.1\nnumpy=1.26.4\nopencv=4.11.0.86\nscipy=1.15.3\n";

    #[test]
    fn versions_are_parsed_and_checked() {
        let v = Versions::parse(GOOD).unwrap();
        assert_eq!(v.jax, "0.7.1");
        assert_eq!(v.opencv, "4.11.0.86");
        assert!(v.describe().contains("commit 821f601c"));
        assert_eq!(
            Versions::parse("jax 0.7.1\n"),
            Err(PaperEnvError::VersionLine {
                line: 1,
                text: "jax 0.7.1".into()
            })
        );
        assert_eq!(
            Versions::parse("# comment\n\npaper_commit=x\n"),
            Err(PaperEnvError::VersionMissing("python"))
        );
    }

    #[test]
    fn a_missing_or_broken_environment_is_a_skip_not_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nowhere");
        assert!(matches!(
            PaperStatus::resolve(None),
            PaperStatus::NotRequested
        ));
        let PaperStatus::Skipped(why) = PaperStatus::resolve(Some(&missing)) else {
            panic!("not skipped")
        };
        assert!(why.contains("nowhere") && why.contains("setup.sh"), "{why}");
        // A folder without the venv, then without the source, then with everything.
        let env = dir.path();
        assert!(matches!(
            PaperEnv::locate(env),
            Err(PaperEnvError::NoPython(_))
        ));
        std::fs::create_dir_all(env.join("venv/bin")).unwrap();
        std::fs::write(env.join("venv/bin/python"), "").unwrap();
        assert!(matches!(
            PaperEnv::locate(env),
            Err(PaperEnvError::NoSource(_))
        ));
        std::fs::create_dir_all(env.join("source")).unwrap();
        std::fs::write(env.join("source/rotation_stabilize.py"), "").unwrap();
        assert!(matches!(
            PaperEnv::locate(env),
            Err(PaperEnvError::Versions { .. })
        ));
        std::fs::write(env.join("versions.txt"), GOOD).unwrap();
        let e = PaperEnv::locate(env).unwrap();
        assert_eq!(e.versions.numpy, "1.26.4");
    }

    #[test]
    fn crop_size_is_the_papers() {
        // 640x360 -> 320x180 -> margins int(40), int(22.5)=22.
        assert_eq!(crop_size(640, 360), (240, 136));
        // 854x480 -> int(427) -> 427 - 2*53.
        assert_eq!(crop_size(854, 480), (321, 180));
        let o = matched_options(640, 360, 29.97);
        assert!(o.contains(&("output_width", "240".into())));
        assert!(o.contains(&("n_track", "3".into())));
        assert!(o.contains(&("zoom", "none".into())));
        assert_eq!(matched_fps(), 60.0);
    }

    #[test]
    fn template_resets_follow_the_papers_clock() {
        // k / round(fps) > 5/60: k > 2.25 at 27, 2.5 at 30, 5 at 60.
        assert_eq!(paper_reset_frames(26.78), 3);
        assert_eq!(paper_reset_frames(30.0), 3);
        assert_eq!(paper_reset_frames(60.0), 6);
        assert_eq!(paper_reset_frames(f64::NAN), 3);
    }

    #[test]
    fn the_papers_loop_time_is_read_from_the_log() {
        let log = "100%|####| 90/90\nEncoding stabilized video\npaper-timing frames=90 layout_s=1.686 stabilize_s=23.141\n";
        assert_eq!(parse_loop_seconds(log), Some(23.141));
        assert_eq!(parse_loop_seconds("Traceback ...\n"), None);
    }

    #[test]
    fn the_loader_is_compiled_in() {
        assert!(LOADER.contains("def valid_mask"));
    }
}
