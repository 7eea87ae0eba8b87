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
        // The paper's framing (a fixed 12.5% margin), view filter and plain average: its
        // bars, valid share included, are defined for them; the defaults are tested in
        // tests/framing.rs and tests/sharpness.rs.
        "--zoom".into(),
        "none".into(),
        "--rate-b".into(),
        "40".into(),
        "--deghost".into(),
        "off".into(),
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

/// Where a scenario's footage comes from.
enum Input {
    /// A [`SHAKY_CLIP`] rendered by `amc synth`, with these arguments besides.
    ShakyClip(&'static [&'static str]),
    /// Shared real data (a file or a folder of frames).
    Data(&'static str),
}

/// How the stabilizer is told the lens.
enum Lens {
    /// `--lens` with the `lens.json` that `amc synth` wrote next to the clip.
    Synth,
    /// `--lens` with a shared data file.
    File(&'static str),
    /// `--fov` in degrees.
    Fov(&'static str),
}

/// The bars a scenario must meet.
enum Bars {
    /// The paper's: see `check_bars`.
    Paper,
    /// Footage that does not reach the paper's bars (translation-dominated): the paper's bars
    /// are only reported, except NaN and coverage, and the ratios must stay below these levels
    /// (saccade/none normal flow, stabilize/none change) against regressions.
    Regression { flow: f64, change: f64 },
}

/// One scenario: footage, lens, bars, and the extra checks of some rows.
struct Scenario {
    /// Label in the test's output.
    name: &'static str,
    input: Input,
    lens: Lens,
    /// `--fps`, when the input has no rate of its own.
    fps: Option<&'static str>,
    /// Output container of the three runs.
    ext: &'static str,
    bars: Bars,
    /// The saccade mode must fire at least once (telemetry and metrics).
    saccades_fire: bool,
    /// Each output has the input's frame count and an audio stream; also prints what
    /// `--fov auto` finds on the input.
    keeps_frames_and_audio: bool,
}

/// The table: one `#[test]` per row, named by its first column.
macro_rules! scenarios {
    ($($(#[$doc:meta])* $test:ident: $row:expr,)*) => {
        $(
            $(#[$doc])*
            #[test]
            fn $test() {
                run_scenario(&$row);
            }
        )*
    };
}

scenarios! {
    paper_effect_synthetic: Scenario {
        name: "synthetic 100 deg/s + 15 deg/s pan",
        input: Input::ShakyClip(&[
            "--fov",
            "90",
            "--shake-dps",
            "100",
            "--pan-dps",
            "15",
            "--seed",
            "4",
        ]),
        lens: Lens::Synth,
        fps: Some("60"),
        ext: "y4m",
        bars: Bars::Paper,
        saccades_fire: true,
        keeps_frames_and_audio: false,
    },
    /// The paper's bars on real footage whose motion is mostly rotation: cc9
    /// (a phone's hand shake, calibrated lens).
    paper_effect_real_cc9: Scenario {
        name: "cc9",
        input: Input::Data("cc9/frames"),
        lens: Lens::File("cc9/lens.json"),
        fps: Some("30"),
        ext: "y4m",
        bars: Bars::Paper,
        saccades_fire: false,
        keeps_frames_and_audio: false,
    },
    /// cup.mp4 is filmed at close range while the hand moves: translation and
    /// parallax, which no rotation can undo, dominate its image motion, so it does
    /// not reach the paper's bars (measured: stabilize change 0.78x, saccade normal
    /// flow 0.37x). This test guards those levels against regressions and checks the
    /// outputs: same frame count as the input, audio kept, no NaN.
    paper_effect_real_cup: Scenario {
        name: "cup.mp4 --fov 60",
        input: Input::Data("cup/cup.mp4"),
        lens: Lens::Fov("60"),
        fps: None,
        ext: "mp4",
        bars: Bars::Regression { flow: 0.45, change: 0.9 },
        saccades_fire: false,
        keeps_frames_and_audio: true,
    },
}

/// Runs the three modes on one scenario's footage and checks its bars.
fn run_scenario(sc: &Scenario) {
    let tmp = tempfile::tempdir().unwrap();
    let input = match sc.input {
        Input::ShakyClip(args) => {
            let clip = tmp.path().join("clip");
            synth(&clip, &[&SHAKY_CLIP[..], args].concat());
            clip
        }
        Input::Data(rel) => data(rel),
    };
    let tag = sc.name.split([' ', '.']).next().unwrap(); // "cup", "cc9", "synthetic"

    let input_frames = sc.keeps_frames_and_audio.then(|| {
        let input_frames = ffprobe_frames(&input);
        eprintln!("[{tag}] input frames: {input_frames}");

        // What does --fov auto find on this clip?
        let auto_out = tmp.path().join("auto.y4m");
        let r = amc_ok(&[
            "stabilize".to_string(),
            s(&input),
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
        eprintln!("[{tag}] --fov auto: {}", line.trim());
        input_frames
    });

    let mut extra = match sc.lens {
        Lens::Synth => vec!["--lens".to_string(), s(&input.join("lens.json"))],
        Lens::File(rel) => vec!["--lens".to_string(), s(&data(rel))],
        Lens::Fov(deg) => vec!["--fov".to_string(), deg.into()],
    };
    if let Some(fps) = sc.fps {
        extra.extend(["--fps".to_string(), fps.into()]);
    }
    let none = run_mode(&input, tmp.path(), "none", sc.ext, &extra);
    let stab = run_mode(&input, tmp.path(), "stabilize", sc.ext, &extra);
    let sacc = run_mode(&input, tmp.path(), "saccade", sc.ext, &extra);
    let paper = check_bars(sc.name, &none, &stab, &sacc);

    let mut failed = match sc.bars {
        Bars::Paper => paper,
        Bars::Regression { flow, change } => {
            eprintln!("[{tag}] paper bars missed (known, translation-dominated clip): {paper:?}");
            let mut failed: Vec<String> = paper
                .into_iter()
                .filter(|f| f.contains("NaN") || f.contains("valid"))
                .collect();
            let flow_ratio = m(&sacc, "rms_normal_flow") / m(&none, "rms_normal_flow");
            let change_ratio = m(&stab, "rms_change") / m(&none, "rms_change");
            if !(flow_ratio < flow) {
                failed.push(format!(
                    "saccade normal flow ratio {flow_ratio:.4} >= {flow} (regression)"
                ));
            }
            if !(change_ratio < change) {
                failed.push(format!(
                    "stabilize change ratio {change_ratio:.4} >= {change} (regression)"
                ));
            }
            failed
        }
    };

    if sc.saccades_fire {
        let flags = Csv::read(&sacc.telemetry).col("saccade");
        let fired = flags.iter().filter(|&&x| x == 1.0).count();
        eprintln!(
            "[{tag}] telemetry saccade column: {fired} frames with 1 (metrics saccades = {})",
            m(&sacc, "saccades")
        );
        if fired < 1 {
            failed.push("the saccade never fired (telemetry saccade column has no 1)".into());
        }
        if m(&sacc, "saccades") < 1.0 {
            failed.push("metrics report 0 saccades".into());
        }
    }

    if let Some(input_frames) = input_frames {
        for (mode, r) in [("none", &none), ("stabilize", &stab), ("saccade", &sacc)] {
            let frames = ffprobe_frames(&r.output);
            let audio = has_audio(&r.output);
            eprintln!(
                "[{tag}] {mode} output: {frames} frames (input {input_frames}), audio: {audio}"
            );
            if frames != input_frames {
                failed.push(format!(
                    "{mode}: output has {frames} frames, input {input_frames}"
                ));
            }
            if !audio {
                failed.push(format!("{mode}: output mp4 has no audio stream"));
            }
        }
    }
    assert!(failed.is_empty(), "bars failed: {failed:#?}");
}
