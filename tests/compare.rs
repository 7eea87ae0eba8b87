//! `amc compare` end to end on a short synthetic clip: every method runs, the report
//! (Markdown, plots, JSON) is written, and the numbers that have known values are right.

use amc_e2e::*;
use std::path::Path;

/// One method's object from `results.json`.
fn method<'a>(clip: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    clip["methods"]
        .as_array()
        .expect("methods array")
        .iter()
        .find(|m| m["method"] == name)
        .unwrap_or_else(|| panic!("no method {name} in {clip}"))
}

/// Renders a 1 s, 192x108, 60 fps synthetic clip (seed 3) into `dir`,
/// with `extra` options of `amc synth`.
fn short_clip(dir: &Path, extra: &[&str]) {
    let mut args = vec![
        "--width",
        "192",
        "--height",
        "108",
        "--fps",
        "60",
        "--seconds",
        "1",
        "--seed",
        "3",
    ];
    args.extend_from_slice(extra);
    synth(dir, &args);
}

#[test]
fn compare_short_synthetic_clip() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("shaky");
    short_clip(&clip, &["--shake-dps", "100"]);
    let report = tmp.path().join("report");
    let t0 = std::time::Instant::now();
    amc_ok(&["compare", &s(&clip), "--report", &s(&report), "-q"]);
    eprintln!(
        "amc compare on 60 frames took {:.1} s",
        t0.elapsed().as_secs_f64()
    );

    let files = list_dir(&report);
    for f in [
        "README.md",
        "results.json",
        "shaky-motion.png",
        "shaky-strip.png",
    ] {
        assert!(files.contains(&f.to_string()), "{f} missing from {files:?}");
    }
    // No scratch files left behind.
    assert!(files.iter().all(|f| !f.starts_with('.')), "{files:?}");

    let md = std::fs::read_to_string(report.join("README.md")).unwrap();
    for m in [
        "none",
        "stabilize",
        "saccade",
        "stabilize-lookahead",
        "vidstab-s10",
        "vidstab-s30",
        "vidstab-tripod",
        "deshake",
    ] {
        assert!(md.contains(&format!("| {m} |")), "no row for {m}:\n{md}");
    }
    assert!(md.contains("Machine:") && md.contains("Targets:"), "{md}");

    let json = read_json(&report.join("results.json"));
    let c = &json[0];
    assert_eq!(c["frames"], 60);
    for m in c["methods"].as_array().unwrap() {
        let name = m["method"].as_str().unwrap();
        assert_eq!(m["frames"], 60, "{name}");
        assert!(json_f64(m, "/frames_per_second") > 0.0, "{name}");
        assert!(json_f64(m, "/usage/peak_mib") > 1.0, "{name}");
        let valid = json_f64(m, "/measured/paper/valid_fraction");
        assert!(valid > 0.5 && valid <= 1.0, "{name}: valid {valid}");
        let crop = json_f64(m, "/measured/cropping");
        assert!(crop > 0.5 && crop < 1.05, "{name}: cropping {crop}");
        let dist = json_f64(m, "/measured/distortion");
        assert!(dist > 0.8 && dist <= 1.0, "{name}: distortion {dist}");
        let stab = json_f64(m, "/measured/stability/score");
        assert!((0.0..=1.0).contains(&stab), "{name}: stability {stab}");
    }
    // Our "none" is the whole input (a pinhole: zoom 1) without zoom or stretch.
    let none = method(c, "none");
    let crop = json_f64(none, "/measured/cropping");
    assert!((crop - 1.0).abs() < 0.01, "none cropping {crop}");
    // The default framing (zoom auto) never shows a border, and the report says so.
    for m in ["none", "stabilize", "saccade", "stabilize-lookahead"] {
        assert_eq!(method(c, m)["frames_with_border"], 0, "{m}");
    }
    assert!(
        md.contains("stabilize: no output frame with an uncovered pixel")
            && md.contains("stabilize-lookahead >= vidstab-s30 on cropping"),
        "{md}"
    );
    assert!(json_f64(none, "/measured/distortion") > 0.98);
    // The estimate is checked against the ground truth.
    let gt = json_f64(
        method(c, "stabilize"),
        "/ground_truth/median_frame_error_deg",
    );
    assert!(gt < 0.05, "median rotation error {gt} deg");
    // Stabilizing removes image motion: less normal flow than the shaky input.
    let flow = |m: &str| json_f64(method(c, m), "/measured/paper/rms_normal_flow");
    assert!(
        flow("saccade") < 0.5 * flow("none"),
        "{} vs {}",
        flow("saccade"),
        flow("none")
    );
}

#[test]
fn compare_bad_input_is_one_line_error() {
    let tmp = tempfile::tempdir().unwrap();
    let report = tmp.path().join("r");
    let r = run_amc(&["compare", "--report", &s(&report)]);
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    assert!(
        r.stderr.starts_with("error: nothing to compare"),
        "{}",
        r.stderr
    );
    let missing = Path::new("/nonexistent/clip.mp4");
    let r = run_amc(&[
        "compare",
        &s(missing),
        "--fov",
        "70",
        "--report",
        &s(&report),
    ]);
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    assert!(
        r.stderr.contains("clip.mp4") && !r.stderr.contains("panicked"),
        "{}",
        r.stderr
    );
    let r = run_amc(&[
        "compare",
        &s(missing),
        "--lookahead",
        "0",
        "--report",
        &s(&report),
    ]);
    assert_eq!(r.code, Some(1));
    assert!(r.stderr.contains("--lookahead 0"), "{}", r.stderr);
}

/// Through a fisheye our modes render a pinhole of the lens's focal length,
/// and their cropping and distortion are measured against the clip's frames
/// seen the same way: a camera's turn is then a homography, and `none` is
/// the identity. Against the fisheye's own frames the homography fit read the
/// undistortion itself as stretch (`none` 0.96-0.97 on the synthetic fisheye,
/// every frame) while vid.stab's similarities in the fisheye's projection
/// scored 1.
#[test]
fn compare_measures_a_fisheye_in_the_projection_rendered() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("fish");
    short_clip(
        &clip,
        &["--fov", "150", "--fisheye", "0.05,-0.01,0.002,-0.0005"],
    );
    let report = tmp.path().join("report");
    amc_ok(&["compare", &s(&clip), "--report", &s(&report), "-q"]);
    let json = read_json(&report.join("results.json"));
    let c = &json[0];
    let none = method(c, "none");
    let dist = json_f64(none, "/measured/distortion");
    let crop = json_f64(none, "/measured/cropping");
    eprintln!("fisheye: none distortion {dist:.4}, cropping {crop:.4}");
    assert!(dist > 0.99, "none distortion {dist}");
    assert!((crop - 1.0).abs() < 0.02, "none cropping {crop}");
    for m in ["stabilize", "saccade", "vidstab-s10"] {
        let d = json_f64(method(c, m), "/measured/distortion");
        eprintln!("fisheye: {m} distortion {d:.4}");
        assert!(d > 0.9 && d <= 1.0, "{m}: distortion {d}");
    }
}
