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

#[test]
fn ground_truth_100dps_pinhole() {
    let tmp = tempfile::tempdir().unwrap();
    let args = [
        "--width",
        "320",
        "--height",
        "180",
        "--fps",
        "60",
        "--fov",
        "90",
        "--shake-band",
        "12,20",
        "--shake-dps",
        "100",
        "--seconds",
        "10",
        "--seed",
        "1",
    ];
    let e = run_clip(tmp.path(), &args);
    report("100 deg/s pinhole", &e);

    // Cross-check: `amc eval --gt --json` reports the same median per-frame error.
    let clip = tmp.path().join("clip");
    let r = amc_ok(&[
        "eval".to_string(),
        s(&clip),
        "--lens".into(),
        s(&clip.join("lens.json")),
        "--fps".into(),
        "60".into(),
        "--gt".into(),
        s(&clip.join("gt.csv")),
        "--json".into(),
        "-q".into(),
    ]);
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
        "[100 deg/s pinhole] amc eval --gt: median frame error {eval_median:.8} deg (test: {:.8}), \
         final orientation {eval_final:?} deg (test: {:.6})",
        e.median_frame(),
        e.final_orientation()
    );
    assert!(
        (eval_median - e.median_frame()).abs() < 1e-6,
        "amc eval's median frame error {eval_median} differs from the test's {}",
        e.median_frame()
    );

    assert_finite(&e);
    assert!(
        e.median_frame() < 0.03,
        "median per-frame error {} >= 0.03 deg",
        e.median_frame()
    );
    assert!(
        e.final_orientation() < 1.0,
        "final orientation error {} >= 1 deg",
        e.final_orientation()
    );
}

#[test]
fn ground_truth_300dps_no_divergence() {
    let tmp = tempfile::tempdir().unwrap();
    let args = [
        "--width",
        "320",
        "--height",
        "180",
        "--fps",
        "60",
        "--fov",
        "90",
        "--shake-band",
        "12,20",
        "--shake-dps",
        "300",
        "--seconds",
        "10",
        "--seed",
        "2",
    ];
    let e = run_clip(tmp.path(), &args);
    report("300 deg/s pinhole", &e);
    assert_finite(&e);
    assert!(
        e.final_orientation() < 3.0,
        "final orientation error {} >= 3 deg",
        e.final_orientation()
    );
    assert!(
        e.max_orientation() < 3.0,
        "max orientation error {} >= 3 deg (divergence)",
        e.max_orientation()
    );
}

#[test]
fn ground_truth_100dps_fisheye() {
    let tmp = tempfile::tempdir().unwrap();
    let args = [
        "--width",
        "320",
        "--height",
        "180",
        "--fps",
        "60",
        "--fov",
        "150",
        "--fisheye",
        "0.05,-0.01,0.002,-0.0005",
        "--shake-band",
        "12,20",
        "--shake-dps",
        "100",
        "--seconds",
        "10",
        "--seed",
        "3",
    ];
    let e = run_clip(tmp.path(), &args);
    report("100 deg/s fisheye 150 deg", &e);
    assert_finite(&e);
    assert!(
        e.median_frame() < 0.03,
        "median per-frame error {} >= 0.03 deg",
        e.median_frame()
    );
    assert!(
        e.final_orientation() < 1.0,
        "final orientation error {} >= 1 deg",
        e.final_orientation()
    );
}
