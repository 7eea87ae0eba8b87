//! Smaller command-line checks: `amc eval` with a plot, and `amc demo`.

use amc_e2e::fixtures::ffprobe_frames;
use amc_e2e::*;

#[test]
fn eval_plot_and_markdown_table() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("clip");
    synth(
        &clip,
        &["--seconds", "2", "--shake-dps", "100", "--seed", "7"],
    );
    let plot = tmp.path().join("p.png");
    let r = eval_synth_clip(&clip, &["--plot", &s(&plot), "-q"]);
    eprintln!("[eval] stdout:\n{}", r.stdout);
    let bytes = std::fs::read(&plot).expect("eval wrote no plot");
    eprintln!(
        "[eval] plot: {} bytes, magic {:02x?}",
        bytes.len(),
        &bytes[..bytes.len().min(8)]
    );
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "plot is not a PNG");
    assert!(
        r.stdout.contains("| stabilize |"),
        "no `| stabilize |` row in the table:\n{}",
        r.stdout
    );
    // Saccade mode's fixed crop (zoom none) beside the none row in the same framing.
    for mode in [
        "| none |",
        "| saccade (zoom none) |",
        "| none (zoom none) |",
    ] {
        assert!(
            r.stdout.contains(mode),
            "no `{mode}` row in the table:\n{}",
            r.stdout
        );
    }
}

/// `amc eval`'s saccade row is what `amc stabilize --mode saccade` writes at its defaults
/// (the paper's fixed crop, not the stabilize row's per-frame zoom, which made the held view
/// re-centre twice a second on handheld footage), and `--zoom` given to eval still applies.
#[test]
fn eval_frames_each_mode_as_stabilize_does() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("clip");
    synth(
        &clip,
        &["--seconds", "2", "--shake-dps", "100", "--seed", "7"],
    );
    let saccade_row = |extra: &[&str]| {
        let mut args = vec!["--json", "-q"];
        args.extend(extra);
        let r = eval_synth_clip(&clip, &args);
        let v: serde_json::Value = serde_json::from_str(&r.stdout).expect("eval prints JSON");
        let modes = v["modes"].as_array().expect("modes");
        let m = modes
            .iter()
            .find(|m| m["mode"] == "saccade")
            .expect("saccade row");
        m["metrics"].clone()
    };
    let metrics = tmp.path().join("m.json");
    amc_ok(&[
        "stabilize".to_string(),
        s(&clip),
        "--lens".into(),
        s(&clip.join("lens.json")),
        "--fps".into(),
        "60".into(),
        "--mode".into(),
        "saccade".into(),
        "-o".into(),
        s(&tmp.path().join("o.y4m")),
        "--metrics".into(),
        s(&metrics),
        "-q".into(),
    ]);
    let stabilize = read_json(&metrics);
    let (row, auto_row) = (saccade_row(&[]), saccade_row(&["--zoom", "auto"]));
    // Its ratios are to a `none` run in its own framing, a row of the table.
    let table = eval_synth_clip(&clip, &["-q"]).stdout;
    assert!(table.contains("| none (zoom none) |"), "{table}");
    for key in ["rms_change", "sharpness"] {
        let (a, b) = (
            json_f64(&row, &format!("/{key}")),
            json_f64(&stabilize, &format!("/metrics/{key}")),
        );
        eprintln!(
            "[eval saccade] {key}: eval {a}, stabilize --mode saccade {b}, eval --zoom auto {}",
            json_f64(&auto_row, &format!("/{key}"))
        );
        assert!(
            (a - b).abs() <= 1e-9 * b.abs().max(1.0),
            "{key}: eval {a} vs stabilize {b}"
        );
    }
    assert_ne!(
        json_f64(&row, "/sharpness"),
        json_f64(&auto_row, "/sharpness"),
        "--zoom auto given to eval changed nothing in its saccade row"
    );
}

#[test]
fn demo_writes_both_clips() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("demo");
    let r = amc_ok(&["demo", "-o", &s(&dir), "--seconds", "2"]);
    eprintln!(
        "[demo] stdout:\n{}\n[demo] stderr tail: {}",
        r.stdout,
        r.stderr.lines().last().unwrap_or("")
    );
    let files = list_dir(&dir);
    eprintln!("[demo] files: {files:?}");
    for name in ["stabilized.mp4", "shaky.mp4"] {
        let p = dir.join(name);
        assert!(p.exists(), "demo folder lacks {name}: {files:?}");
        let frames = ffprobe_frames(&p);
        eprintln!("[demo] {name}: {frames} frames");
        assert!(frames > 0, "{name} has no frames");
    }
}

/// A one-second 160x90 synthetic clip read out in 8 ms, into `clip`, with
/// `extra` arguments for `amc synth`.
fn small_rolling_clip(clip: &std::path::Path, extra: &[&str]) {
    let mut args = vec![
        "--seconds",
        "1",
        "--width",
        "160",
        "--height",
        "90",
        "--rolling-shutter-ms",
        "8",
    ];
    args.extend_from_slice(extra);
    synth(clip, &args);
}

/// The readout: a synthetic rolling-shutter clip's `lens.json` states it and
/// `stabilize --lens` uses it (and says so); `--readout-ms` overrides it;
/// `auto` estimates it or falls back to 0 with a warning; the telemetry
/// ends with the rotation across the readout.
#[test]
fn readout_from_the_lens_file_the_option_and_auto() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("clip");
    small_rolling_clip(&clip, &[]);
    let lens = clip.join("lens.json");
    let text = std::fs::read_to_string(&lens).unwrap();
    assert!(text.contains("\"readout_ms\": 8"), "{text}");
    let stabilize = |extra: &[&str]| {
        let (out, tel, met) = (
            tmp.path().join("out.y4m"),
            tmp.path().join("t.csv"),
            tmp.path().join("m.json"),
        );
        let mut a = vec![
            "stabilize".to_string(),
            s(&clip),
            "-o".into(),
            s(&out),
            "--lens".into(),
            s(&lens),
            "--telemetry".into(),
            s(&tel),
            "--metrics".into(),
            s(&met),
        ];
        a.extend(extra.iter().map(|x| x.to_string()));
        let r = amc_ok(&a);
        let readout = json_f64(&read_json(&met), "/readout_ms");
        let header = std::fs::read_to_string(&tel)
            .unwrap()
            .lines()
            .next()
            .unwrap()
            .to_string();
        (r.stderr, readout, header)
    };
    let (stderr, readout, header) = stabilize(&[]);
    assert!(
        stderr.contains("readout: 8 ms (from the lens file)"),
        "{stderr}"
    );
    assert_eq!(readout, 8.0);
    assert!(
        header.starts_with("frame,t,rx,ry,rz,vx,vy,vz,")
            && header.ends_with(",zoom,uncovered,readout_rx,readout_ry,readout_rz"),
        "{header}"
    );
    // The option beats the lens file.
    let (stderr, readout, _) = stabilize(&["--readout-ms", "0"]);
    assert_eq!(readout, 0.0);
    assert!(!stderr.contains("readout:"), "{stderr}");
    // auto: an estimate it trusts, or 0 with a warning.
    let (stderr, readout, _) = stabilize(&["--readout-ms", "auto"]);
    if stderr.contains("warning: the footage does not pin down the rolling-shutter readout") {
        assert_eq!(readout, 0.0, "{stderr}");
    } else {
        assert!(stderr.contains("(estimated from 60 frames"), "{stderr}");
        assert!((0.0..=100.0).contains(&readout), "{stderr}");
    }
}

/// An image folder with a lens file of its own (`amc synth` writes one beside
/// the frames, `meta.json` and `gt.csv`): with neither `--lens` nor `--fov`
/// given, `stabilize` uses it (and its readout) and says so; the result is
/// the same as with `--lens DIR/lens.json`, and the same again with the images
/// in `DIR/frames/`. A flag given wins over it, and a broken folder lens is a
/// clear error, not a silent estimate.
#[test]
fn an_image_folders_own_lens_is_used_unless_one_is_given() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("clip");
    small_rolling_clip(&clip, &["--fov", "90"]);
    let lens = clip.join("lens.json");
    let stabilize = |input: &std::path::Path, extra: &[&str]| {
        let (out, tel) = (tmp.path().join("out.y4m"), tmp.path().join("t.csv"));
        let mut a = vec![
            "stabilize".to_string(),
            s(input),
            "-o".into(),
            s(&out),
            "--telemetry".into(),
            s(&tel),
        ];
        a.extend(extra.iter().map(|x| x.to_string()));
        let r = run_amc(&a);
        let telemetry = std::fs::read_to_string(&tel).unwrap_or_default();
        (r, telemetry)
    };
    let (own, own_tel) = stabilize(&clip, &[]);
    assert!(own.success(), "{}", own.stderr);
    assert!(
        own.stderr.contains(&format!("lens: {}", lens.display()))
            && own.stderr.contains("readout: 8 ms (from the lens file)"),
        "{}",
        own.stderr
    );
    let (given, given_tel) = stabilize(&clip, &["--lens", &s(&lens)]);
    assert!(given.success(), "{}", given.stderr);
    assert!(!own_tel.is_empty() && own_tel == given_tel);
    // The same recording laid out with its images in `frames/` (as
    // ../shared/data/cc9 is): its lens and its rate are the folder's.
    let recording = tmp.path().join("recording");
    let frames = recording.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    for name in list_dir(&clip) {
        let to = if name.ends_with(".png") {
            frames.join(&name)
        } else {
            recording.join(&name)
        };
        std::fs::copy(clip.join(&name), to).unwrap();
    }
    let (laid_out, laid_out_tel) = stabilize(&recording, &[]);
    assert!(laid_out.success(), "{}", laid_out.stderr);
    assert!(
        laid_out
            .stderr
            .contains(&format!("lens: {}", recording.join("lens.json").display()))
            && !laid_out.stderr.contains("frame rate"),
        "{}",
        laid_out.stderr
    );
    assert!(laid_out_tel == own_tel);
    // Before, the focal length was estimated (or fell back to 70 deg): what
    // `--fov auto` still asks for.
    for fov in ["90", "auto"] {
        let (r, _) = stabilize(&clip, &["--fov", fov]);
        assert!(r.success(), "{}", r.stderr);
        assert!(
            !r.stderr.contains("lens:") && !r.stderr.contains("readout:"),
            "--fov {fov}: {}",
            r.stderr
        );
    }
    std::fs::write(&lens, "{not json").unwrap();
    let (broken, _) = stabilize(&clip, &[]);
    assert_eq!(broken.code, Some(1), "{}", broken.stderr);
    assert!(
        broken.stderr.contains("lens.json") && !broken.stderr.contains("panicked"),
        "{}",
        broken.stderr
    );
}
