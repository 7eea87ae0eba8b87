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
    let r = amc_ok(&[
        "eval".to_string(),
        s(&clip),
        "--lens".into(),
        s(&clip.join("lens.json")),
        "--fps".into(),
        "60".into(),
        "--plot".into(),
        s(&plot),
        "-q".into(),
    ]);
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
    for mode in ["| none |", "| saccade |"] {
        assert!(
            r.stdout.contains(mode),
            "no `{mode}` row in the table:\n{}",
            r.stdout
        );
    }
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
