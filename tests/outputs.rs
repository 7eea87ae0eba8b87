//! What `amc stabilize` does with its output paths: they are checked before any
//! work, and an existing output is replaced only once the new one is complete.

use amc_e2e::fixtures::test_clip;
use amc_e2e::*;

/// A bad output fails at once: with a missing input as well, the one error line names
/// the output (the input is not even opened, no field of view is estimated).
#[test]
fn outputs_are_checked_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let missing_input = tmp.path().join("no-such-clip.mp4");
    let cases: [(&[&str], &str, &str); 4] = [
        (
            &["-o", "missing-dir/x.mp4"],
            "missing-dir/x.mp4",
            "does not exist",
        ),
        (
            &["-o", "x.txt"],
            "x.txt",
            "unsupported output format \".txt\"",
        ),
        (
            &["-o", "x.mp4", "--telemetry", "missing-dir/t.csv"],
            "missing-dir/t.csv",
            "does not exist",
        ),
        (
            &["-o", "x.mp4", "--metrics", "missing-dir/m.json"],
            "missing-dir/m.json",
            "does not exist",
        ),
    ];
    for (flags, named, says) in cases {
        let mut argv = vec!["stabilize".to_string(), s(&missing_input)];
        for f in flags {
            argv.push(if f.contains('/') || f.contains('.') {
                s(&tmp.path().join(f))
            } else {
                f.to_string()
            });
        }
        let r = run_amc(&argv);
        eprintln!("[{flags:?}] exit {:?}: {}", r.code, r.stderr.trim());
        assert_eq!(r.code, Some(1), "{flags:?}: {}", r.stderr);
        let lines: Vec<&str> = r.stderr.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(
            lines.len(),
            1,
            "{flags:?}: one line, no warning first: {lines:?}"
        );
        assert!(
            lines[0].starts_with("error:") && lines[0].contains(named) && lines[0].contains(says),
            "{flags:?}: {}",
            lines[0]
        );
        assert!(
            !lines[0].contains("no-such-clip"),
            "{flags:?}: {}",
            lines[0]
        );
    }
}

/// An existing output is replaced, and the run says so; without `-q` only.
#[test]
fn an_existing_output_is_replaced_with_a_note() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("clip.mp4");
    test_clip(&clip, 160, 120, 30, 1.0);
    let out = tmp.path().join("out.y4m");
    std::fs::write(&out, b"old").unwrap();
    let run = |quiet: bool| {
        let mut argv = vec![
            "stabilize".to_string(),
            s(&clip),
            "-o".into(),
            s(&out),
            "--fov".into(),
            "60".into(),
        ];
        if quiet {
            argv.push("-q".into());
        }
        amc_ok(&argv)
    };
    let r = run(false);
    assert!(
        r.stderr
            .contains("exists: it is replaced once the new output is complete"),
        "{}",
        r.stderr
    );
    let bytes = std::fs::read(&out).unwrap();
    assert!(
        bytes.starts_with(b"YUV4MPEG2"),
        "the old file was not replaced"
    );
    let r = run(true);
    assert!(!r.stderr.contains("replaced"), "{}", r.stderr);
}
