//! Ground truth: rotation-only clips rendered from the panorama with `amc synth`, whose exact
//! orientations are in gt.csv, compared with the estimator's telemetry.

use amc_e2e::*;
use std::path::Path;

/// Renders a clip into `dir/clip`, stabilizes it and returns the errors against gt.csv.
fn run_clip(dir: &Path, synth_args: &[&str]) -> GtErrors {
    let clip = dir.join("clip");
    synth(&clip, synth_args);
    let tel = dir.join("telemetry.csv");
    amc_ok(&[
        "stabilize".to_string(),
        s(&clip),
        "-o".into(),
        s(&dir.join("out.y4m")),
        "--lens".into(),
        s(&clip.join("lens.json")),
        "--fps".into(),
        "60".into(),
        "--telemetry".into(),
        s(&tel),
        "-q".into(),
    ]);
    gt_errors(&clip.join("gt.csv"), &tel)
}

fn report(name: &str, e: &GtErrors) {
    eprintln!(
        "[{name}] frames {}: per-frame error median {:.5} deg, mean {:.5} deg, max {:.5} deg; \
         orientation error final {:.4} deg, max {:.4} deg; non-finite estimates: {} frames {:?}",
        e.orientation.len(),
        e.median_frame(),
        mean(&finite(&e.frame)),
        max(&finite(&e.frame)),
        e.final_orientation(),
        e.max_orientation(),
        e.nonfinite.len(),
        &e.nonfinite[..e.nonfinite.len().min(10)]
    );
}

/// Every frame's estimate must be a finite rotation.
fn assert_finite(e: &GtErrors) {
    assert!(
        e.nonfinite.is_empty(),
        "{} frames have non-finite (NaN) estimated rotations in the telemetry, first: {:?}",
        e.nonfinite.len(),
        &e.nonfinite[..e.nonfinite.len().min(10)]
    );
}

/// One ground-truth scenario: a clip rendered by `amc synth`, the bars its estimate must meet.
struct Scenario {
    /// Label in the test's output.
    name: &'static str,
    /// `amc synth` arguments besides [`SHAKY_CLIP`]'s and the lens: shake speed, seed.
    synth: &'static [&'static str],
    /// `amc synth`'s lens arguments (the stabilizer reads the clip's lens.json).
    lens: &'static [&'static str],
    /// Bars, in degrees: median per-frame error, final and maximum orientation error.
    median_frame: Option<f64>,
    final_orientation: Option<f64>,
    max_orientation: Option<f64>,
    /// Also check that `amc eval --gt --json` reports the test's median per-frame error.
    cross_check_eval: bool,
}

/// A [`SHAKY_CLIP`] shaking at `$dps` deg/s.
macro_rules! shake {
    ($dps:literal, seed $seed:literal) => {
        &["--shake-dps", $dps, "--seed", $seed]
    };
}

/// The table: one `#[test]` per row, named by its first column.
macro_rules! scenarios {
    ($($test:ident: $row:expr,)*) => {
        $(
            #[test]
            fn $test() {
                run_scenario(&$row);
            }
        )*
    };
}

scenarios! {
    ground_truth_100dps_pinhole: Scenario {
        name: "100 deg/s pinhole",
        synth: shake!("100", seed "1"),
        lens: &["--fov", "90"],
        median_frame: Some(0.03),
        final_orientation: Some(1.0),
        max_orientation: None,
        cross_check_eval: true,
    },
    ground_truth_300dps_no_divergence: Scenario {
        name: "300 deg/s pinhole",
        synth: shake!("300", seed "2"),
        lens: &["--fov", "90"],
        median_frame: None,
        final_orientation: Some(3.0),
        max_orientation: Some(3.0),
        cross_check_eval: false,
    },
    ground_truth_100dps_fisheye: Scenario {
        name: "100 deg/s fisheye 150 deg",
        synth: shake!("100", seed "3"),
        lens: &["--fov", "150", "--fisheye", "0.05,-0.01,0.002,-0.0005"],
        median_frame: Some(0.03),
        final_orientation: Some(1.0),
        max_orientation: None,
        cross_check_eval: false,
    },
}

/// Renders, stabilizes and checks one scenario.
fn run_scenario(sc: &Scenario) {
    let tmp = tempfile::tempdir().unwrap();
    let args: Vec<&str> = SHAKY_CLIP
        .iter()
        .chain(sc.synth)
        .chain(sc.lens)
        .copied()
        .collect();
    let e = run_clip(tmp.path(), &args);
    let name = sc.name;
    report(name, &e);

    if sc.cross_check_eval {
        // Cross-check: `amc eval --gt --json` reports the same median per-frame error.
        let clip = tmp.path().join("clip");
        let r = eval_synth_clip(&clip, &["--gt", &s(&clip.join("gt.csv")), "--json", "-q"]);
        let v: serde_json::Value = serde_json::from_str(r.stdout.trim())
            .unwrap_or_else(|e| panic!("eval --json printed no JSON ({e}):\n{}", r.stdout));
        let modes = v["modes"].as_array().expect("eval JSON has no modes array");
        let row = modes
            .iter()
            .find(|m| m["mode"] == "stabilize")
            .expect("eval JSON has no stabilize row");
        let eval_median = json_f64(row, "/ground_truth/median_frame_error_deg");
        let eval_final = row
            .pointer("/ground_truth/final_orientation_error_deg")
            .and_then(|x| x.as_f64());
        eprintln!(
            "[{name}] amc eval --gt: median frame error {eval_median:.8} deg (test: {:.8}), \
             final orientation {eval_final:?} deg (test: {:.6})",
            e.median_frame(),
            e.final_orientation()
        );
        assert!(
            (eval_median - e.median_frame()).abs() < 1e-6,
            "amc eval's median frame error {eval_median} differs from the test's {}",
            e.median_frame()
        );
    }

    assert_finite(&e);
    if let Some(bar) = sc.median_frame {
        assert!(
            e.median_frame() < bar,
            "median per-frame error {} >= {bar} deg",
            e.median_frame()
        );
    }
    if let Some(bar) = sc.final_orientation {
        assert!(
            e.final_orientation() < bar,
            "final orientation error {} >= {bar} deg",
            e.final_orientation()
        );
    }
    if let Some(bar) = sc.max_orientation {
        assert!(
            e.max_orientation() < bar,
            "max orientation error {} >= {bar} deg (divergence)",
            e.max_orientation()
        );
    }
}

/// `--fov auto` on a rolling-shutter clip with its readout given: the focal
/// length is fitted with the readout's model, so a clip whose frames a global
/// shutter cannot explain (250 deg/s over a 12 ms readout, where the global
/// fit falls back to 70 deg) still gives its own field of view, and the
/// tracking with it is as accurate as with the lens file.
#[test]
fn fov_auto_with_a_given_readout_finds_a_rolling_shutter_clip_s_lens() {
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("clip");
    synth(
        &clip,
        &[
            "--width",
            "640",
            "--height",
            "360",
            "--seconds",
            "3",
            "--seed",
            "22",
            "--shake-dps",
            "250",
            "--rolling-shutter-ms",
            "12",
            "--fov",
            "100",
        ],
    );
    let video = dir.path().join("clip.mp4");
    amc_e2e::fixtures::encode_frames(&clip, 60, &video);
    let tel = dir.path().join("telemetry.csv");
    let r = amc_ok(&[
        "stabilize".to_string(),
        s(&video),
        "-o".into(),
        s(&dir.path().join("out.y4m")),
        "--readout-ms".into(),
        "12".into(),
        "--telemetry".into(),
        s(&tel),
    ]);
    let hfov: f64 = r
        .stderr
        .split("estimated horizontal field of view: ")
        .nth(1)
        .and_then(|rest| rest.split(" deg").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no estimate: {}", r.stderr));
    let e = gt_errors(&clip.join("gt.csv"), &tel);
    report("fov auto, 12 ms readout given", &e);
    assert!((hfov - 100.0).abs() < 2.0, "estimated {hfov} deg, true 100");
    assert_finite(&e);
    assert!(
        e.median_frame() < 0.03,
        "median per-frame error {}",
        e.median_frame()
    );
}
