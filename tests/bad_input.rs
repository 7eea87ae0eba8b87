//! Bad input: every failure exits non-zero with one clear `error:` line (or clap's usage error),
//! never panics, and leaves no partial output behind.

use amc_e2e::fixtures::{ffmpeg, ffprobe_frames, test_picture};
use amc_e2e::*;
use std::path::{Path, PathBuf};

/// What a failing run must look like.
#[derive(Clone, Copy, PartialEq)]
enum Expect {
    /// Our own error: exactly one stderr line, starting with `error:`.
    OneLine,
    /// May be rejected by clap (usage error) or by our own validation.
    ClapOrOneLine,
    /// Either a clean error (as `OneLine`) or success; never a panic.
    ErrorOrSuccess,
}

/// Runs `amc stabilize INPUT -o OUT_DIR/OUT_NAME ARGS...` in a fresh, empty output folder and
/// checks the failure; returns the run.
fn bad(case: &str, input: &Path, out_name: &str, args: &[String], expect: Expect) -> Run {
    let out_dir = tempfile::tempdir().unwrap();
    let out = out_dir.path().join(out_name);
    let mut a = vec![
        "stabilize".to_string(),
        s(input),
        "-o".into(),
        s(&out),
        "-q".into(),
    ];
    a.extend(
        args.iter()
            .map(|x| x.replace("{OUT_DIR}", &s(out_dir.path()))),
    );
    let r = run_amc(&a);
    let lines: Vec<&str> = r.stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    let left = list_dir(out_dir.path());
    eprintln!(
        "[{case}] exit {:?}; stderr ({} lines): {:?}; output dir after: {left:?}",
        r.code,
        lines.len(),
        if lines.len() <= 3 {
            r.stderr.trim().to_string()
        } else {
            format!("{} ...", lines[..3].join(" | "))
        }
    );
    assert!(
        !r.stderr.contains("panicked"),
        "[{case}] amc panicked:\n{}",
        r.stderr
    );
    // Messages name the user's paths, never the hidden temporary output.
    assert!(
        !r.stderr.contains(".partial-"),
        "[{case}] the message names a temporary file:\n{}",
        r.stderr
    );
    if expect == Expect::ErrorOrSuccess && r.success() {
        assert!(
            out.exists(),
            "[{case}] succeeded but wrote no {}",
            out.display()
        );
        return r;
    }
    assert!(
        !r.success(),
        "[{case}] expected a failure, amc exited 0\nstderr:\n{}",
        r.stderr
    );
    assert!(
        !r.stderr.trim().is_empty(),
        "[{case}] failed with an empty stderr"
    );
    let clap_style = r.stderr.contains("Usage:") || r.stderr.contains("For more information");
    if !(expect == Expect::ClapOrOneLine && clap_style) {
        assert_eq!(
            lines.len(),
            1,
            "[{case}] expected exactly one stderr line, got {}:\n{}",
            lines.len(),
            r.stderr
        );
        assert!(
            lines[0].starts_with("error:"),
            "[{case}] stderr does not start with `error:`: {}",
            lines[0]
        );
    }
    assert!(
        !out.exists(),
        "[{case}] partial output left at {}",
        out.display()
    );
    assert!(
        left.is_empty(),
        "[{case}] leftover files in the output folder: {left:?}"
    );
    r
}

fn cup() -> PathBuf {
    data("cup/cup.mp4")
}

fn args(a: &[&str]) -> Vec<String> {
    a.iter().map(|x| x.to_string()).collect()
}

#[test]
fn bad_missing_input_file() {
    let tmp = tempfile::tempdir().unwrap();
    bad(
        "missing input",
        &tmp.path().join("nope.mp4"),
        "out.mp4",
        &[],
        Expect::OneLine,
    );
}

#[test]
fn bad_text_file_named_mp4() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("x.mp4");
    std::fs::write(&p, "this is not a video, just some text\n".repeat(20)).unwrap();
    bad(
        "text as x.mp4",
        &p,
        "out.mp4",
        &args(&["--fov", "60"]),
        Expect::OneLine,
    );
}

#[test]
fn bad_random_bytes_named_mp4() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("x.mp4");
    // Deterministic pseudo-random bytes (xorshift).
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    let bytes: Vec<u8> = (0..200_000)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    std::fs::write(&p, bytes).unwrap();
    bad(
        "random bytes as x.mp4",
        &p,
        "out.mp4",
        &args(&["--fov", "60"]),
        Expect::OneLine,
    );
}

#[test]
fn bad_empty_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("empty");
    std::fs::create_dir(&d).unwrap();
    bad(
        "empty folder",
        &d,
        "out.mp4",
        &args(&["--fov", "60"]),
        Expect::OneLine,
    );
}

#[test]
fn bad_images_of_different_sizes() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("mixed");
    std::fs::create_dir(&d).unwrap();
    for (name, (w, h)) in [("a-001.png", (64, 48)), ("a-002.png", (80, 60))] {
        test_picture(&d.join(name), w, h);
    }
    bad(
        "images of different sizes",
        &d,
        "out.mp4",
        &args(&["--fov", "60"]),
        Expect::OneLine,
    );
}

#[test]
fn bad_lens_garbage_json() {
    let tmp = tempfile::tempdir().unwrap();
    let lens = tmp.path().join("lens.json");
    std::fs::write(&lens, "{ \"model\": \"pinhole\", fx: [[[ not json").unwrap();
    bad(
        "garbage lens JSON",
        &cup(),
        "out.mp4",
        &args(&["--lens", &s(&lens)]),
        Expect::OneLine,
    );
}

#[test]
fn bad_lens_negative_focal_length() {
    let tmp = tempfile::tempdir().unwrap();
    let lens = tmp.path().join("lens.json");
    std::fs::write(
        &lens,
        r#"{"model":"pinhole","width":640,"height":480,"fx":-5,"fy":500,"cx":319.5,"cy":239.5,"skew":0.0,"dist":[]}"#,
    )
    .unwrap();
    bad(
        "lens with fx -5",
        &cup(),
        "out.mp4",
        &args(&["--lens", &s(&lens)]),
        Expect::OneLine,
    );
}

#[test]
fn bad_option_values() {
    let cases: &[(&str, &[&str])] = &[
        ("--n-avg 0", &["--fov", "60", "--n-avg", "0"]),
        ("--n-avg 1000", &["--fov", "60", "--n-avg", "1000"]),
        ("--margin 0.9", &["--fov", "60", "--margin", "0.9"]),
        ("--fov 500", &["--fov", "500"]),
        ("--fov abc", &["--fov", "abc"]),
        ("--track-width 1", &["--fov", "60", "--track-width", "1"]),
        (
            "--lookahead 100000",
            &["--fov", "60", "--lookahead", "100000"],
        ),
        ("--readout-ms 200", &["--fov", "60", "--readout-ms", "200"]),
        ("--readout-ms -1", &["--fov", "60", "--readout-ms", "-1"]),
        (
            "--readout-ms fast",
            &["--fov", "60", "--readout-ms", "fast"],
        ),
    ];
    for (case, a) in cases {
        bad(case, &cup(), "out.mp4", &args(a), Expect::ClapOrOneLine);
    }
}

/// An out-of-range readout is our own one-line error naming the option and its range.
#[test]
fn bad_readout_names_the_option_and_its_range() {
    let r = bad(
        "--readout-ms 200",
        &cup(),
        "out.mp4",
        &args(&["--fov", "60", "--readout-ms", "200"]),
        Expect::OneLine,
    );
    assert!(
        r.stderr.contains("readout_ms") && r.stderr.contains("0..=100"),
        "{}",
        r.stderr
    );
}

/// A lens file's readout outside 0..=100 ms names the key, the value and the range.
#[test]
fn bad_lens_readout() {
    let tmp = tempfile::tempdir().unwrap();
    let lens = tmp.path().join("lens.json");
    std::fs::write(
        &lens,
        r#"{"model":"pinhole","width":640,"height":360,"fx":500,"fy":500,"cx":319.5,"cy":179.5,"readout_ms":250}"#,
    )
    .unwrap();
    let r = bad(
        "lens readout_ms 250",
        &cup(),
        "out.mp4",
        &args(&["--lens", &s(&lens)]),
        Expect::OneLine,
    );
    assert!(
        r.stderr.contains("readout_ms") && r.stderr.contains("250") && r.stderr.contains("0..=100"),
        "{}",
        r.stderr
    );
}

#[test]
fn bad_unsupported_output_extension() {
    bad(
        "out.xyz",
        &cup(),
        "out.xyz",
        &args(&["--fov", "60"]),
        Expect::OneLine,
    );
}

#[test]
fn bad_telemetry_in_missing_directory() {
    bad(
        "telemetry in a missing folder",
        &cup(),
        "out.mp4",
        &args(&["--fov", "60", "--telemetry", "{OUT_DIR}/no/such/dir/t.csv"]),
        Expect::OneLine,
    );
}

#[test]
fn bad_truncated_mp4() {
    let tmp = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(cup()).unwrap();
    let p = tmp.path().join("truncated.mp4");
    std::fs::write(&p, &bytes[..bytes.len() * 3 / 10]).unwrap();
    let out_dir = tempfile::tempdir().unwrap();
    let out = out_dir.path().join("out.y4m");
    let r = bad(
        "truncated mp4 (30%)",
        &p,
        "out.mp4",
        &args(&["--fov", "60"]),
        Expect::ErrorOrSuccess,
    );
    if r.success() {
        // Same run again to a file we keep, to report how many frames it recovered.
        amc_ok(&[
            "stabilize".to_string(),
            s(&p),
            "-o".into(),
            s(&out),
            "--fov".into(),
            "60".into(),
            "-q".into(),
        ]);
        eprintln!(
            "[truncated mp4 (30%)] outcome: success, {} frames written (full clip: 217)",
            ffprobe_frames(&out)
        );
    } else {
        eprintln!("[truncated mp4 (30%)] outcome: clean error");
    }
}

/// Copies the first `n` JPEG frames of the cc9 sample into `dir` (sorted by name).
fn copy_jpegs(dir: &Path, n: usize) -> Vec<PathBuf> {
    let mut src: Vec<PathBuf> = std::fs::read_dir(data("cc9/frames"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .collect();
    src.sort();
    std::fs::create_dir_all(dir).unwrap();
    src.iter()
        .take(n)
        .enumerate()
        .map(|(i, p)| {
            let to = dir.join(format!("f-{i:03}.jpg"));
            std::fs::copy(p, &to).unwrap();
            to
        })
        .collect()
}

#[test]
fn bad_still_image_named_mp4() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("photo.mp4");
    // A PNG picture under a video's name.
    ffmpeg(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=64x48",
        "-frames:v",
        "1",
        "-f",
        "image2",
        "-c:v",
        "png",
        &s(&p),
    ]);
    let r = bad(
        "PNG named photo.mp4",
        &p,
        "out.mp4",
        &args(&["--fov", "60"]),
        Expect::OneLine,
    );
    assert!(
        r.stderr.contains("photo.mp4")
            && r.stderr.contains("still image")
            && r.stderr.contains("folder"),
        "{}",
        r.stderr
    );
}

#[test]
fn bad_truncated_jpeg_in_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("frames");
    let files = copy_jpegs(&d, 6);
    let victim = &files[3];
    let bytes = std::fs::read(victim).unwrap();
    std::fs::write(victim, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let r = bad(
        "truncated JPEG in a folder",
        &d,
        "out.mp4",
        &args(&["--fov", "60"]),
        Expect::OneLine,
    );
    assert!(
        r.stderr.contains("f-003.jpg") && r.stderr.contains("truncated"),
        "{}",
        r.stderr
    );
}

#[test]
fn bad_empty_file() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("empty.mp4");
    std::fs::write(&p, b"").unwrap();
    let r = bad(
        "empty file",
        &p,
        "out.mp4",
        &args(&["--fov", "60"]),
        Expect::OneLine,
    );
    assert!(
        r.stderr.contains("empty.mp4") && r.stderr.contains("empty file"),
        "{}",
        r.stderr
    );
    assert!(!r.stderr.contains("moov"), "{}", r.stderr);
}

#[test]
fn bad_crf_beyond_the_format_range() {
    for (out, crf, range) in [("out.mp4", "52", "0..=51"), ("out.mkv", "63", "0..=51")] {
        let r = bad(
            &format!("--crf {crf} for {out}"),
            &cup(),
            out,
            &args(&["--fov", "60", "--crf", crf]),
            Expect::OneLine,
        );
        assert!(
            r.stderr.contains(out) && r.stderr.contains(crf) && r.stderr.contains(range),
            "{}",
            r.stderr
        );
    }
}
