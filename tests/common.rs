//! Helpers shared by the end-to-end tests of the `amc` command line.
//!
//! Every test drives the RELEASE binary (`target/release/amc`), which [`amc`] builds once per
//! test process. Shared real data lives outside the repository in `../shared/data`. Everything
//! that runs ffmpeg or ffprobe (probing outputs, generated test clips) is in [`fixtures`].

#[path = "cluster_harness.rs"]
pub mod cluster;
pub mod fixtures;
#[path = "rtsp_harness.rs"]
pub mod rtsp;
#[path = "server_harness.rs"]
pub mod server;
pub mod services;
pub mod stream_quality;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::Once;

/// Root of the Cargo workspace.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// Folder of the shared real data (`../shared/data` relative to the workspace root).
pub fn data_dir() -> PathBuf {
    workspace_root().join("..").join("shared").join("data")
}

/// Path of a shared data file; panics with a clear message when it is missing.
pub fn data(rel: &str) -> PathBuf {
    let p = data_dir().join(rel);
    assert!(
        p.exists(),
        "shared test data missing: {} (expected the shared data folder at {}; CI always has it)",
        p.display(),
        data_dir().display()
    );
    p
}

/// The equirectangular panorama used to render synthetic clips.
pub fn pano() -> PathBuf {
    data("pano/pannellum_examplepano.jpg")
}

fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(d) => {
            let d = PathBuf::from(d);
            if d.is_absolute() {
                d
            } else {
                workspace_root().join(d)
            }
        }
        None => workspace_root().join("target"),
    }
}

static BUILD: Once = Once::new();

/// Path of the release `amc` binary, built (once per process) with
/// `cargo build --release -p amc-cli --bin amc`.
pub fn amc() -> PathBuf {
    BUILD.call_once(|| {
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let mut build = Command::new(cargo);
        build.args(["build", "--release", "-p", "amc-cli", "--bin", "amc"]);
        // The variables the cargo running this test set for it (this
        // package's name, version, folder...): a build script that watches
        // them (ring's does) would otherwise see them change, and its crate
        // and every dependant would be rebuilt at each switch between `cargo
        // test` and this build.
        for (key, _) in std::env::vars_os() {
            let key = key.to_string_lossy();
            let set_by_cargo = key.starts_with("CARGO_PKG_")
                || key.starts_with("CARGO_BIN_")
                || [
                    "CARGO_MANIFEST_DIR",
                    "CARGO_MANIFEST_PATH",
                    "CARGO_MANIFEST_LINKS",
                    "CARGO_CRATE_NAME",
                    "CARGO_PRIMARY_PACKAGE",
                    "CARGO_TARGET_TMPDIR",
                    "OUT_DIR",
                ]
                .contains(&key.as_ref());
            if set_by_cargo {
                build.env_remove(key.as_ref());
            }
        }
        let status = build
            .current_dir(workspace_root())
            .stdout(Stdio::inherit())
            .stderr(Stdio::inherit())
            .status()
            .expect("could not run cargo to build the release amc binary");
        assert!(status.success(), "building the release amc binary failed");
    });
    let bin = target_dir()
        .join("release")
        .join(format!("amc{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.exists(),
        "release binary not found at {}",
        bin.display()
    );
    bin
}

/// Captured result of one `amc` run.
pub struct Run {
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
}

impl Run {
    pub fn success(&self) -> bool {
        self.code == Some(0)
    }
}

impl From<Output> for Run {
    fn from(o: Output) -> Self {
        Run {
            code: o.status.code(),
            stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        }
    }
}

fn to_strings<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Vec<String> {
    args.iter()
        .map(|a| a.as_ref().to_string_lossy().into_owned())
        .collect()
}

/// Runs `amc ARGS...` and captures its output (never panics on failure).
pub fn run_amc<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Run {
    let out = Command::new(amc())
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("could not start amc");
    out.into()
}

/// Runs `amc ARGS...` and panics with its output unless it succeeds.
pub fn amc_ok<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Run {
    let t0 = std::time::Instant::now();
    let r = run_amc(args);
    assert!(
        r.success(),
        "amc {:?} failed (exit {:?})\n--- stdout:\n{}\n--- stderr:\n{}",
        to_strings(args),
        r.code,
        r.stdout,
        r.stderr
    );
    assert!(
        !r.stderr.contains("panicked"),
        "amc {:?} panicked:\n{}",
        to_strings(args),
        r.stderr
    );
    eprintln!(
        "  [amc {} ... took {:.1} s]",
        to_strings(args).first().cloned().unwrap_or_default(),
        t0.elapsed().as_secs_f64()
    );
    r
}

/// A CSV file read into a header and rows of strings.
pub struct Csv {
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

impl Csv {
    pub fn read(path: &Path) -> Csv {
        let text = std::fs::read_to_string(path)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        let header = lines
            .next()
            .unwrap_or_else(|| panic!("{} is empty", path.display()))
            .split(',')
            .map(|s| s.trim().to_string())
            .collect::<Vec<_>>();
        let rows = lines
            .map(|l| l.split(',').map(|s| s.trim().to_string()).collect())
            .collect();
        Csv { header, rows }
    }

    pub fn index(&self, name: &str) -> usize {
        self.header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("CSV has no column {name:?}; columns: {:?}", self.header))
    }

    /// A column parsed as numbers.
    pub fn col(&self, name: &str) -> Vec<f64> {
        let i = self.index(name);
        self.rows
            .iter()
            .map(|r| {
                r[i].parse::<f64>()
                    .unwrap_or_else(|e| panic!("column {name}: cannot parse {:?}: {e}", r[i]))
            })
            .collect()
    }
}

/// Rotations of a CSV keyed by its `frame` column, from the rotation-vector columns `x,y,z`.
pub fn rotations(csv: &Csv, x: &str, y: &str, z: &str) -> HashMap<usize, M3> {
    let f = csv.col("frame");
    let (a, b, c) = (csv.col(x), csv.col(y), csv.col(z));
    f.iter()
        .enumerate()
        .map(|(i, &fr)| (fr as usize, exp([a[i], b[i], c[i]])))
        .collect()
}

// ---------------------------------------------------------------- rotations

pub type M3 = [[f64; 3]; 3];

pub const I3: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Rodrigues: rotation vector (radians) to rotation matrix.
pub fn exp(v: [f64; 3]) -> M3 {
    let th = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let k = [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]];
    let k2 = mul(&k, &k);
    let (a, b) = if th < 1e-8 {
        (1.0 - th * th / 6.0, 0.5 - th * th / 24.0)
    } else {
        (th.sin() / th, (1.0 - th.cos()) / (th * th))
    };
    let mut r = I3;
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] += a * k[i][j] + b * k2[i][j];
        }
    }
    r
}

pub fn mul(a: &M3, b: &M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}

pub fn transpose(a: &M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[j][i];
        }
    }
    r
}

/// Rotation angle of a rotation matrix, degrees (robust near 0 via the skew part).
pub fn angle_deg(r: &M3) -> f64 {
    let c = ((r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0).clamp(-1.0, 1.0);
    let s = 0.5
        * ((r[2][1] - r[1][2]).powi(2) + (r[0][2] - r[2][0]).powi(2) + (r[1][0] - r[0][1]).powi(2))
            .sqrt();
    s.atan2(c).to_degrees()
}

/// Angle (degrees) of `a^T b`.
pub fn angle_between_deg(a: &M3, b: &M3) -> f64 {
    angle_deg(&mul(&transpose(a), b))
}

/// Relative rotation `a^T b`.
pub fn rel(a: &M3, b: &M3) -> M3 {
    mul(&transpose(a), b)
}

/// Errors of an estimate against ground truth, both as `R_{0,j}` by frame.
pub struct GtErrors {
    /// Per-frame rotation error (deg) for j = 1..n: angle of (Rgt_{j-1}^T Rgt_j)^T (Rest_{j-1}^T Rest_j).
    pub frame: Vec<f64>,
    /// Orientation error (deg) for j = 0..n: angle of Rgt_j^T Rest_j.
    pub orientation: Vec<f64>,
    /// Frames whose estimated rotation is not finite (NaN/inf in the telemetry); their errors
    /// are NaN in `frame`/`orientation` and left out of the statistics.
    pub nonfinite: Vec<usize>,
}

impl GtErrors {
    pub fn median_frame(&self) -> f64 {
        median(&finite(&self.frame))
    }
    pub fn final_orientation(&self) -> f64 {
        *self.orientation.last().expect("no frames")
    }
    pub fn max_orientation(&self) -> f64 {
        max(&finite(&self.orientation))
    }
}

/// Compares `gt.csv` (frame,t,rx,ry,rz) with a telemetry CSV (frame,...,rx,ry,rz,...).
pub fn gt_errors(gt_csv: &Path, telemetry_csv: &Path) -> GtErrors {
    let gt = rotations(&Csv::read(gt_csv), "rx", "ry", "rz");
    let est = rotations(&Csv::read(telemetry_csv), "rx", "ry", "rz");
    let n = gt.len();
    assert_eq!(
        est.len(),
        n,
        "telemetry has {} frames, gt.csv has {n}",
        est.len()
    );
    let mut frame = Vec::new();
    let mut orientation = Vec::new();
    let nonfinite = (0..n)
        .filter(|j| est[j].iter().flatten().any(|x| !x.is_finite()))
        .collect();
    for j in 0..n {
        let (g, e) = (&gt[&j], &est[&j]);
        orientation.push(angle_between_deg(g, e));
        if j > 0 {
            let dg = rel(&gt[&(j - 1)], g);
            let de = rel(&est[&(j - 1)], e);
            frame.push(angle_between_deg(&dg, &de));
        }
    }
    GtErrors {
        frame,
        orientation,
        nonfinite,
    }
}

// ---------------------------------------------------------------- statistics

/// The finite values of `v`.
pub fn finite(v: &[f64]) -> Vec<f64> {
    v.iter().cloned().filter(|x| x.is_finite()).collect()
}

/// Median (NaN sorts last, so a NaN-free slice gives the usual median).
pub fn median(v: &[f64]) -> f64 {
    assert!(!v.is_empty(), "median of nothing");
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

pub fn max(v: &[f64]) -> f64 {
    v.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
}

// ---------------------------------------------------------------- synth clips

/// Renders a synthetic clip with `amc synth PANO -o dir ARGS...`.
pub fn synth(dir: &Path, args: &[&str]) {
    let mut a: Vec<String> = vec![
        "synth".into(),
        pano().to_string_lossy().into_owned(),
        "-o".into(),
        dir.to_string_lossy().into_owned(),
    ];
    a.extend(args.iter().map(|s| s.to_string()));
    amc_ok(&a);
    assert!(dir.join("gt.csv").exists() && dir.join("lens.json").exists());
}

/// A short clip and the gyro log its camera recorded, as a client uploads them: `amc synth`
/// renders `dir/clip` (320x180, 60 frames/s, `seconds` long, 150 deg/s of shake, its
/// `gyro.gcsv` at 1 kHz starting [`GYRO_CLIP_OFFSET_S`] from the video, and `lens.json`), then
/// the frames are encoded into `dir/clip.mp4`. Returns the folder and the video.
pub fn synth_clip_with_gyro(dir: &Path, seconds: f64) -> (PathBuf, PathBuf) {
    let clip = dir.join("clip");
    let secs = seconds.to_string();
    let offset = GYRO_CLIP_OFFSET_S.to_string();
    synth(
        &clip,
        &[
            "--seconds",
            &secs,
            "--seed",
            "3",
            "--shake-dps",
            "150",
            "--gyro-rate-hz",
            "1000",
            "--gyro-offset-s",
            &offset,
        ],
    );
    let video = dir.join("clip.mp4");
    fixtures::encode_frames(&clip, 60, &video);
    (clip, video)
}

/// Video time of the first sample of [`synth_clip_with_gyro`]'s log, seconds.
pub const GYRO_CLIP_OFFSET_S: f64 = -1.25;

/// `amc synth` arguments of the scenario tests' clips (`ground_truth.rs`, `paper_effect.rs`):
/// 10 s of 320x180 at 60 frames/s, shaking in the 12-20 Hz band (each row adds its speed, its
/// seed, and its lens or pan).
pub const SHAKY_CLIP: [&str; 10] = [
    "--width",
    "320",
    "--height",
    "180",
    "--fps",
    "60",
    "--shake-band",
    "12,20",
    "--seconds",
    "10",
];

/// Runs `amc eval CLIP --lens CLIP/lens.json --fps 60 ARGS...` on a clip rendered by [`synth`]
/// (at 60 frames/s) and panics with its output unless it succeeds.
pub fn eval_synth_clip(clip: &Path, args: &[&str]) -> Run {
    let mut a = vec![
        "eval".to_string(),
        s(clip),
        "--lens".into(),
        s(&clip.join("lens.json")),
        "--fps".into(),
        "60".into(),
    ];
    a.extend(args.iter().map(|s| s.to_string()));
    amc_ok(&a)
}

/// Reads the `metrics` object of a `--metrics` JSON file.
pub fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("bad JSON in {}: {e}", path.display()))
}

/// A number from a JSON value by a `/`-separated pointer, e.g. `/metrics/rms_change`.
pub fn json_f64(v: &serde_json::Value, pointer: &str) -> f64 {
    v.pointer(pointer)
        .and_then(|x| x.as_f64())
        .unwrap_or_else(|| panic!("JSON has no number at {pointer}: {v}"))
}

/// Paths as strings, for argument lists.
pub fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// Names of the entries of a directory (sorted).
pub fn list_dir(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}
