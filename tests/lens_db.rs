//! `--lens-db DIR`: a folder of Gyroflow lens profiles, and the one picked
//! for a clip by the camera, lens mode and frame size it records. The
//! profiles are a handful written here (the public collection is never
//! copied into the repository); the clip with a camera is karma.mp4 (a
//! GoPro HERO5 Black, 854x480, ../shared/data/README.md).

use amc_e2e::fixtures::test_clip;
use amc_e2e::*;
use std::path::Path;

/// A Gyroflow profile: `fx = fy`, the centre at the middle, OpenCV
/// fisheye `k`; `extra` is spliced in as more top-level keys.
fn profile(
    brand: &str,
    model: &str,
    lens: &str,
    (w, h): (usize, usize),
    f: f64,
    extra: &str,
) -> String {
    format!(
        r#"{{
  "name": "{brand} {model} {lens} {w}x{h}",
  "note": "NO-EIS",
  "camera_brand": "{brand}", "camera_model": "{model}", "lens_model": "{lens}", "camera_setting": "",
  "calib_dimension": {{"w": {w}, "h": {h}}},
  "orig_dimension": {{"w": {w}, "h": {h}}},
  "output_dimension": {{"w": {w}, "h": {h}}},
  "frame_readout_time": 16.7, "fps": 59.94, "official": true,
  {extra}
  "fisheye_params": {{
    "RMS_error": 0.5,
    "camera_matrix": [[{f}, 0.0, {cx}], [0.0, {f}, {cy}], [0.0, 0.0, 1.0]],
    "distortion_coeffs": [0.04, 0.03, -0.03, 0.01]
  }}
}}"#,
        cx = w as f64 / 2.0,
        cy = h as f64 / 2.0,
    )
}

fn write(dir: &Path, rel: &str, text: &str) {
    let p = dir.join(rel);
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, text).unwrap();
}

/// The database: one profile for karma's camera and aspect ratio (16:9, in
/// a subfolder), one of the same camera at 4:3, one of another camera, one
/// at karma's very size that we cannot model (a distortion model other than
/// OpenCV fisheye: it would be preferred, and is skipped), and a file that
/// is not JSON (counted, skipped).
fn lens_db(dir: &Path) {
    write(
        dir,
        "GoPro/hero5_wide_1080p.json",
        &profile("GoPro", "HERO5 Black", "Wide", (1920, 1080), 900.0, ""),
    );
    write(
        dir,
        "GoPro/hero5_wide_4by3.json",
        &profile("GoPro", "HERO5 Black", "Wide", (2704, 2028), 1300.0, ""),
    );
    write(
        dir,
        "GoPro/hero5_wide_480p_poly.json",
        &profile(
            "GoPro",
            "HERO5 Black",
            "Wide",
            (854, 480),
            400.0,
            r#""distortion_model": "poly3","#,
        ),
    );
    write(
        dir,
        "Sony/a7s3.json",
        &profile("Sony", "ILCE-7SM3", "", (1920, 1080), 1500.0, ""),
    );
    write(dir, "broken.json", "{ this is not JSON");
}

fn karma_run(extra: &[&str], dir: &Path) -> (serde_json::Value, String) {
    let metrics = dir.join("m.json");
    let mut args: Vec<String> = vec![
        "stabilize".into(),
        s(&data("karma/karma.mp4")),
        "-o".into(),
        s(&dir.join("out.y4m")),
        "--mode".into(),
        "none".into(),
        "--gyro".into(),
        "off".into(),
        "--metrics".into(),
        s(&metrics),
    ];
    args.extend(extra.iter().map(|a| a.to_string()));
    let r = amc_ok(&args);
    (read_json(&metrics), r.stderr)
}

#[test]
fn the_profile_for_the_clips_camera_and_aspect_is_picked_and_scaled() {
    let tmp = tempfile::tempdir().unwrap();
    let db = tmp.path().join("db");
    lens_db(&db);
    let (m, stderr) = karma_run(&["--lens-db", &s(&db)], tmp.path());
    eprintln!("{stderr}");
    let p = &m["lens_profile"];
    assert!(
        p["file"]
            .as_str()
            .unwrap()
            .ends_with("hero5_wide_1080p.json"),
        "{p}\n{stderr}"
    );
    let line = stderr
        .lines()
        .find(|l| l.starts_with("lens: GoPro HERO5 Black Wide 1920x1080 from "))
        .unwrap_or_else(|| panic!("no lens line:\n{stderr}"));
    assert!(
        line.contains("(camera GoPro HERO5 Black, lens mode Wide, calibrated at 1920x1080, scaled to 854x480)")
            // karma.mp4 records no lens mode (no VFOV): the profile's is an assumption, said.
            && line.contains("the clip records no lens mode"),
        "{line}"
    );
    // The better fit at the clip's own size has a model we cannot use: said, and passed over.
    assert!(
        stderr.contains("hero5_wide_480p_poly.json: unsupported distortion model"),
        "{stderr}"
    );
    assert!(stderr.contains("1 of the 5 .json files"), "{stderr}");
    // Scaled pixel-centre correct from 1920x1080 to 854x480.
    let (sx, sy) = (854.0 / 1920.0, 480.0 / 1080.0);
    let want = [900.0 * sx, 900.0 * sy, 960.5 * sx - 0.5, 540.5 * sy - 0.5];
    for (i, w) in want.iter().enumerate() {
        let got = json_f64(p, &format!("/intrinsics/{i}"));
        assert!((got - w).abs() < 1e-6, "intrinsics[{i}] {got} vs {w}: {p}");
    }
    // A profile states no readout for 854x480 at 29.97: none is taken from it.
    assert!(p["readout_ms"].is_null(), "{p}");
    assert_eq!(m["clip_camera"]["brand"], "GoPro", "{m}");
    // The lens was given: no field-of-view estimate.
    assert!(
        !stderr.contains("estimated horizontal field of view"),
        "{stderr}"
    );
}

#[test]
fn a_clip_naming_its_camera_says_so_without_a_database() {
    let tmp = tempfile::tempdir().unwrap();
    let (m, stderr) = karma_run(&["--fov", "90"], tmp.path());
    assert!(
        stderr.contains("clip: camera GoPro HERO5 Black, no lens mode recorded"),
        "{stderr}"
    );
    assert!(m.get("lens_profile").is_none(), "{m}");
}

#[test]
fn no_camera_falls_back_a_missing_folder_fails_and_flags_conflict() {
    let tmp = tempfile::tempdir().unwrap();
    let db = tmp.path().join("db");
    lens_db(&db);
    let clip = tmp.path().join("clip.mp4");
    test_clip(&clip, 160, 120, 15, 1.0);
    let out = tmp.path().join("out.y4m");
    let metrics = tmp.path().join("m.json");
    let base = |extra: &[&str]| {
        let mut a = vec![
            "stabilize".to_string(),
            s(&clip),
            "-o".into(),
            s(&out),
            "--metrics".into(),
            s(&metrics),
        ];
        a.extend(extra.iter().map(|x| x.to_string()));
        a
    };
    // No camera recorded: said, and the run estimates the lens as without the flag.
    let r = amc_ok(&base(&["--lens-db", &s(&db)]));
    assert!(
        r.stderr.contains("warning: lens: the clip names no camera"),
        "{}",
        r.stderr
    );
    assert!(
        r.stderr.contains("horizontal field of view"),
        "{}",
        r.stderr
    );
    assert!(read_json(&metrics)["lens_profile"].is_null());
    // A folder that is not there: an error naming it, before any work.
    let missing = tmp.path().join("no-such-db");
    let r = run_amc(&base(&["--lens-db", &s(&missing)]));
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    assert!(
        r.stderr.contains("error: --lens-db")
            && r.stderr.contains(&s(&missing))
            && r.stderr.contains("no such folder"),
        "{}",
        r.stderr
    );
    // With a lens or a field of view: refused by the argument parser.
    for other in [["--fov", "70"], ["--lens", "x.json"]] {
        let r = run_amc(&base(&["--lens-db", &s(&db), other[0], other[1]]));
        assert_eq!(r.code, Some(2), "{}", r.stderr);
        assert!(r.stderr.contains("--lens-db"), "{}", r.stderr);
    }
}
