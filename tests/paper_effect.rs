//! The paper's effect: compared with the unstabilized clip, the saccade mode removes most of
//! the image motion (normal flow) and the stabilize mode reduces the frame-to-frame change,
//! while both keep nearly all of the output covered by real pixels.

use amc_e2e::fixtures::{ffprobe_frames, has_audio};
use amc_e2e::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

struct ModeRun {
    metrics: Value,
    telemetry: PathBuf,
    output: PathBuf,
}

fn run_mode(input: &Path, out_dir: &Path, mode: &str, ext: &str, extra: &[String]) -> ModeRun {
    let metrics = out_dir.join(format!("{mode}.json"));
    let telemetry = out_dir.join(format!("{mode}.csv"));
    let output = out_dir.join(format!("{mode}.{ext}"));
    let mut args = vec![
        "stabilize".to_string(),
        s(input),
        "-o".into(),
        s(&output),
        "--mode".into(),
        mode.into(),
        "--metrics".into(),
        s(&metrics),
        "--telemetry".into(),
        s(&telemetry),
        "-q".into(),
    ];
    args.extend(extra.iter().cloned());
    amc_ok(&args);
    ModeRun {
        metrics: read_json(&metrics),
        telemetry,
        output,
    }
}

fn m(r: &ModeRun, key: &str) -> f64 {
    json_f64(&r.metrics, &format!("/metrics/{key}"))
}

/// Prints the three modes' metrics and returns the bars that failed.
fn check_bars(name: &str, none: &ModeRun, stab: &ModeRun, sacc: &ModeRun) -> Vec<String> {
    for (mode, r) in [("none", none), ("stabilize", stab), ("saccade", sacc)] {
        eprintln!("[{name}] {mode:>9}: {}", r.metrics["metrics"]);
    }
    let flow_ratio = m(sacc, "rms_normal_flow") / m(none, "rms_normal_flow");
    let change_ratio = m(stab, "rms_change") / m(none, "rms_change");
    let stab_valid = m(stab, "valid_fraction");
    let sacc_valid = m(sacc, "valid_fraction");
    eprintln!(
        "[{name}] saccade/none normal flow = {flow_ratio:.4} (bar < 0.3); \
         stabilize/none change = {change_ratio:.4} (bar < 0.7); \
         valid stabilize = {stab_valid:.4} (bar >= 0.99), saccade = {sacc_valid:.4} (bar >= 0.96); \
         saccades = {}",
        m(sacc, "saccades")
    );
    let mut failed = Vec::new();
    for (mode, r) in [("none", none), ("stabilize", stab), ("saccade", sacc)] {
        let tel = Csv::read(&r.telemetry);
        let (x, y, z) = (tel.col("rx"), tel.col("ry"), tel.col("rz"));
        let bad: Vec<usize> = (0..x.len())
            .filter(|&i| !(x[i].is_finite() && y[i].is_finite() && z[i].is_finite()))
            .collect();
        eprintln!(
            "[{name}] {mode}: {} of {} frames have a non-finite estimated rotation{}",
            bad.len(),
            x.len(),
            if bad.is_empty() {
                String::new()
            } else {
                format!(" (first: {:?})", &bad[..bad.len().min(5)])
            }
        );
        if !bad.is_empty() {
            failed.push(format!(
                "{mode}: {} frames with NaN estimated rotations",
                bad.len()
            ));
        }
    }
    if !(flow_ratio < 0.3) {
        failed.push(format!("saccade normal flow ratio {flow_ratio:.4} >= 0.3"));
    }
    if !(change_ratio < 0.7) {
        failed.push(format!("stabilize change ratio {change_ratio:.4} >= 0.7"));
    }
    if !(stab_valid >= 0.99) {
        failed.push(format!("stabilize valid_fraction {stab_valid:.4} < 0.99"));
    }
    if !(sacc_valid >= 0.96) {
        failed.push(format!("saccade valid_fraction {sacc_valid:.4} < 0.96"));
    }
    failed
}

#[test]
fn paper_effect_synthetic() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("clip");
    synth(
        &clip,
        &[
            "--width",
            "320",
            "--height",
            "180",
            "--fps",
            "60",
            "--fov",
            "90",
            "--shake-dps",
            "100",
            "--shake-band",
            "12,20",
            "--pan-dps",
            "15",
            "--seconds",
            "10",
            "--seed",
            "4",
        ],
    );
    let extra = vec![
        "--lens".to_string(),
        s(&clip.join("lens.json")),
        "--fps".into(),
        "60".into(),
    ];
    let none = run_mode(&clip, tmp.path(), "none", "y4m", &extra);
    let stab = run_mode(&clip, tmp.path(), "stabilize", "y4m", &extra);
    let sacc = run_mode(&clip, tmp.path(), "saccade", "y4m", &extra);
    let mut failed = check_bars("synthetic 100 deg/s + 15 deg/s pan", &none, &stab, &sacc);

    let flags = Csv::read(&sacc.telemetry).col("saccade");
    let fired = flags.iter().filter(|&&x| x == 1.0).count();
    eprintln!(
        "[synthetic] telemetry saccade column: {fired} frames with 1 (metrics saccades = {})",
        m(&sacc, "saccades")
    );
    if fired < 1 {
        failed.push("the saccade never fired (telemetry saccade column has no 1)".into());
    }
    if m(&sacc, "saccades") < 1.0 {
        failed.push("metrics report 0 saccades".into());
    }
    assert!(failed.is_empty(), "bars failed: {failed:#?}");
}

/// The paper's bars on real footage whose motion is mostly rotation: cc9
/// (a phone's hand shake, calibrated lens).
#[test]
fn paper_effect_real_cc9() {
    let frames = data("cc9/frames");
    let tmp = tempfile::tempdir().unwrap();
    let extra = vec![
        "--lens".to_string(),
        s(&data("cc9/lens.json")),
        "--fps".into(),
        "30".into(),
    ];
    let none = run_mode(&frames, tmp.path(), "none", "y4m", &extra);
    let stab = run_mode(&frames, tmp.path(), "stabilize", "y4m", &extra);
    let sacc = run_mode(&frames, tmp.path(), "saccade", "y4m", &extra);
    let failed = check_bars("cc9", &none, &stab, &sacc);
    assert!(failed.is_empty(), "bars failed: {failed:#?}");
}

/// cup.mp4 is filmed at close range while the hand moves: translation and
/// parallax, which no rotation can undo, dominate its image motion, so it does
/// not reach the paper's bars (measured: stabilize change 0.78x, saccade normal
/// flow 0.37x). This test guards those levels against regressions and checks the
/// outputs: same frame count as the input, audio kept, no NaN.
#[test]
fn paper_effect_real_cup() {
    let cup = data("cup/cup.mp4");
    let tmp = tempfile::tempdir().unwrap();
    let input_frames = ffprobe_frames(&cup);
    eprintln!("[cup] input frames: {input_frames}");

    // What does --fov auto find on this clip?
    let auto_out = tmp.path().join("auto.y4m");
    let r = amc_ok(&[
        "stabilize".to_string(),
        s(&cup),
        "-o".into(),
        s(&auto_out),
        "--fov".into(),
        "auto".into(),
    ]);
    let line = r
        .stderr
        .lines()
        .chain(r.stdout.lines())
        .find(|l| l.contains("field of view"))
        .unwrap_or("(no field-of-view line printed)");
    eprintln!("[cup] --fov auto: {}", line.trim());

    let extra = vec!["--fov".to_string(), "60".into()];
    let none = run_mode(&cup, tmp.path(), "none", "mp4", &extra);
    let stab = run_mode(&cup, tmp.path(), "stabilize", "mp4", &extra);
    let sacc = run_mode(&cup, tmp.path(), "saccade", "mp4", &extra);
    let paper = check_bars("cup.mp4 --fov 60", &none, &stab, &sacc);
    eprintln!("[cup] paper bars missed (known, translation-dominated clip): {paper:?}");
    let mut failed: Vec<String> = paper
        .into_iter()
        .filter(|f| f.contains("NaN") || f.contains("valid"))
        .collect();
    let flow_ratio = m(&sacc, "rms_normal_flow") / m(&none, "rms_normal_flow");
    let change_ratio = m(&stab, "rms_change") / m(&none, "rms_change");
    if !(flow_ratio < 0.45) {
        failed.push(format!(
            "saccade normal flow ratio {flow_ratio:.4} >= 0.45 (regression)"
        ));
    }
    if !(change_ratio < 0.9) {
        failed.push(format!(
            "stabilize change ratio {change_ratio:.4} >= 0.9 (regression)"
        ));
    }

    for (mode, r) in [("none", &none), ("stabilize", &stab), ("saccade", &sacc)] {
        let frames = ffprobe_frames(&r.output);
        let audio = has_audio(&r.output);
        eprintln!("[cup] {mode} output: {frames} frames (input {input_frames}), audio: {audio}");
        if frames != input_frames {
            failed.push(format!(
                "{mode}: output has {frames} frames, input {input_frames}"
            ));
        }
        if !audio {
            failed.push(format!("{mode}: output mp4 has no audio stream"));
        }
    }
    assert!(failed.is_empty(), "bars failed: {failed:#?}");
}
