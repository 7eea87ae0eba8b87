//! Regressions of what a new user broke (the input overwritten, multipart
//! uploads over 2 MB refused, partial files left by a signal, variable frame
//! rates drifting against their audio, synthetic folders read at the wrong rate).

use amc_e2e::fixtures::{ffmpeg, ffprobe_frame_times, ffprobe_frames};
use amc_e2e::server::{self, post_multipart, Server};
use amc_e2e::*;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn cup() -> std::path::PathBuf {
    data("cup/cup.mp4")
}

/// `amc stabilize cup.mp4 -o OUT --fov 60 ARGS...`; panics unless it succeeds.
fn stabilize_cup(out: &std::path::Path, args: &[&str]) -> Run {
    let cup = s(&cup());
    let out = s(out);
    amc_ok(
        &[
            &["stabilize", cup.as_str(), "-o", out.as_str(), "--fov", "60"][..],
            args,
        ]
        .concat(),
    )
}

#[test]
fn an_output_that_is_the_input_is_refused_and_nothing_is_touched() {
    let d = tempfile::tempdir().unwrap();
    let x = d.path().join("x.mp4");
    std::fs::copy(cup(), &x).unwrap();
    let before = std::fs::read(&x).unwrap();
    let link = d.path().join("link.mp4");
    std::os::unix::fs::symlink(&x, &link).unwrap();
    let hard = d.path().join("hard.mp4");
    std::fs::hard_link(&x, &hard).unwrap();
    let dotted = format!("{}/./x.mp4", d.path().display());
    let out = d.path().join("out.mp4");
    let cases: Vec<Vec<String>> = vec![
        vec!["-o".into(), s(&x)],
        vec!["-o".into(), dotted],
        vec!["-o".into(), s(&link)],
        vec!["-o".into(), s(&hard)],
        vec!["-o".into(), s(&out), "--telemetry".into(), s(&x)],
        vec!["-o".into(), s(&out), "--metrics".into(), s(&x)],
        vec!["-o".into(), s(&out), "--telemetry".into(), s(&out)],
        vec![
            "-o".into(),
            s(&out),
            "--telemetry".into(),
            s(&d.path().join("t.csv")),
            "--metrics".into(),
            s(&d.path().join("t.csv")),
        ],
    ];
    for extra in cases {
        let mut args = vec!["stabilize".to_string(), s(&x), "--fov".into(), "60".into()];
        args.extend(extra.iter().cloned());
        let r = run_amc(&args);
        assert_eq!(r.code, Some(1), "{extra:?}: {}", r.stderr);
        assert!(r.stderr.contains("same file"), "{extra:?}: {}", r.stderr);
        assert_eq!(r.stderr.lines().count(), 1, "{extra:?}: {}", r.stderr);
        assert_eq!(
            std::fs::read(&x).unwrap(),
            before,
            "{extra:?} touched the input"
        );
        assert!(!out.exists(), "{extra:?}");
    }
    let mut names = list_dir(d.path());
    names.sort();
    assert_eq!(names, ["hard.mp4", "link.mp4", "x.mp4"]);
}

#[test]
fn a_signal_stops_the_run_and_leaves_no_partial_file() {
    let d = tempfile::tempdir().unwrap();
    for (sig, code, out) in [
        ("-TERM", 143, "term.mp4"),
        ("-INT", 130, "int.mp4"),
        ("-HUP", 129, "frames"),
    ] {
        let mut child = Command::new(amc())
            .args([
                "stabilize",
                &s(&data("karma/karma.mp4")),
                "--fov",
                "90",
                "-q",
            ])
            .arg("-o")
            .arg(d.path().join(out))
            .arg("--telemetry")
            .arg(d.path().join("t.csv"))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        // Wait until the run is writing its partial output.
        let start = Instant::now();
        while !list_dir(d.path()).iter().any(|n| n.contains("partial")) {
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "no partial output appeared"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        std::thread::sleep(Duration::from_millis(300));
        Command::new("kill")
            .args([sig, &child.id().to_string()])
            .status()
            .unwrap();
        let status = child.wait().unwrap();
        assert_eq!(status.code(), Some(code), "{sig}");
        assert!(
            list_dir(d.path()).is_empty(),
            "{sig}: {:?}",
            list_dir(d.path())
        );
        // No ffmpeg of ours survives (they read the input clip).
        std::thread::sleep(Duration::from_millis(200));
        assert!(
            server::ffmpeg_using(&data("karma/karma.mp4")).is_empty(),
            "{sig}: ffmpeg children left running"
        );
    }
}

#[test]
fn variable_frame_rate_input_keeps_each_frame_time() {
    let d = tempfile::tempdir().unwrap();
    let vfr = d.path().join("karma_vfr.mp4");
    ffmpeg(&[
        "-i",
        &s(&data("karma/karma.mp4")),
        "-t",
        "5",
        "-vf",
        "select='not(mod(n\\,3))+not(mod(n\\,7))',scale=320:-2",
        "-fps_mode",
        "vfr",
        "-c:a",
        "copy",
        &s(&vfr),
    ]);
    let out = d.path().join("out.mp4");
    amc_ok(&["stabilize", &s(&vfr), "-o", &s(&out), "--fov", "90", "-q"]);
    let (a, b) = (ffprobe_frame_times(&vfr), ffprobe_frame_times(&out));
    assert_eq!(a.len(), b.len());
    let (a0, b0) = (a[0], b[0]);
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| ((x - a0) - (y - b0)).abs())
        .fold(0.0, f64::max);
    eprintln!("{} frames, worst drift {:.1} ms", a.len(), worst * 1e3);
    assert!(worst < 0.002, "frames drift by up to {:.1} ms", worst * 1e3);
}

#[test]
fn synthetic_folders_are_read_at_their_own_rate() {
    let d = tempfile::tempdir().unwrap();
    let clip = d.path().join("s");
    synth(
        &clip,
        &["--seconds", "0.5", "--width", "64", "--height", "36"],
    );
    assert!(clip.join("meta.json").is_file());
    let stabilize = |out: &str| {
        run_amc(&[
            "stabilize",
            &s(&clip),
            "-o",
            &s(&d.path().join(out)),
            "--lens",
            &s(&clip.join("lens.json")),
        ])
    };
    let r = stabilize("o.y4m");
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(!r.stderr.contains("assuming"), "{}", r.stderr);
    let y4m = std::fs::read(d.path().join("o.y4m")).unwrap();
    assert!(y4m.starts_with(b"YUV4MPEG2 W"), "not a y4m");
    let header = String::from_utf8_lossy(&y4m[..64]).to_string();
    assert!(header.contains("F60:1"), "{header}");
    // A folder that states no rate gets a warning.
    std::fs::remove_file(clip.join("meta.json")).unwrap();
    std::fs::remove_file(clip.join("gt.csv")).unwrap();
    let r = stabilize("p.y4m");
    assert!(r.stderr.contains("assuming 30 frames/s"), "{}", r.stderr);
}

#[test]
fn large_multipart_uploads_are_accepted_in_either_part_order() {
    // Tens of MB in few frames (the upload's size is what is tested, not the clip's length):
    // karma.mp4's first 45 frames with grain, losslessly coded, about 20 MB, with its audio.
    let d = tempfile::tempdir().unwrap();
    let big = d.path().join("big.mp4");
    // From a copy: `a_signal_stops_the_run_and_leaves_no_partial_file`, beside this test,
    // counts every ffmpeg reading karma.mp4 itself as a child left running.
    let karma_copy = d.path().join("karma.mp4");
    std::fs::copy(data("karma/karma.mp4"), &karma_copy).unwrap();
    ffmpeg(&[
        "-i",
        &s(&karma_copy),
        "-frames:v",
        "45",
        "-map",
        "0:v:0",
        "-map",
        "0:a:0",
        "-vf",
        "noise=alls=12:allf=t",
        "-c:v",
        "libx264",
        "-preset",
        "ultrafast",
        "-qp",
        "0",
        "-c:a",
        "copy",
        "-shortest",
        &s(&big),
    ]);
    let karma = std::fs::read(&big).unwrap();
    assert!(karma.len() > 10_000_000, "{} bytes", karma.len());
    let frames = ffprobe_frames(&big).to_string();
    let lens = br#"{"model": "pinhole", "width": 854, "height": 480, "fx": 427, "fy": 427, "cx": 426.5, "cy": 239.5}"#;
    let server = Server::start(&[]);
    for parts in [
        vec![
            ("video", "karma.mp4", "video/mp4", &karma[..]),
            ("lens", "lens.json", "application/json", &lens[..]),
        ],
        vec![
            ("lens", "lens.json", "application/json", &lens[..]),
            ("video", "karma.mp4", "video/mp4", &karma[..]),
        ],
    ] {
        let r = post_multipart(
            &server.url("/stabilize?metrics=false&output_width=320"),
            &parts,
        );
        assert_eq!(r.status, 200, "{}", r.text());
        assert_eq!(r.header("x-amc-frames"), Some(frames.as_str()));
    }
    server.assert_no_scratch_left(Duration::from_secs(10));
}

#[test]
fn every_output_gets_ordinary_file_permissions() {
    use std::os::unix::fs::PermissionsExt;
    let d = tempfile::tempdir().unwrap();
    let (out, tel, met) = (
        d.path().join("o.y4m"),
        d.path().join("t.csv"),
        d.path().join("m.json"),
    );
    // The umask decides, as for any file a program creates (0644 under the usual 022).
    let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let umask_probe = d.path().join("probe");
    std::fs::write(&umask_probe, b"").unwrap();
    let expected = mode(&umask_probe);
    stabilize_cup(
        &out,
        &[
            "--output-width",
            "160",
            "--telemetry",
            &s(&tel),
            "--metrics",
            &s(&met),
            "-q",
        ],
    );
    for p in [&out, &tel, &met] {
        assert_eq!(mode(p), expected, "{}", p.display());
    }
}

#[test]
fn decoding_and_encoding_on_their_own_threads_changes_no_byte() {
    let d = tempfile::tempdir().unwrap();
    let run = |threads: &str| {
        let (out, tel) = (
            d.path().join(format!("o{threads}.y4m")),
            d.path().join(format!("t{threads}.csv")),
        );
        stabilize_cup(&out, &["--telemetry", &s(&tel), "--threads", threads, "-q"]);
        (std::fs::read(out).unwrap(), std::fs::read(tel).unwrap())
    };
    let one = run("1");
    let three = run("3");
    assert!(
        one.0 == three.0,
        "the video differs between --threads 1 and 3"
    );
    assert!(
        one.1 == three.1,
        "the telemetry differs between --threads 1 and 3"
    );
    let r = run_amc(&[
        "stabilize",
        &s(&cup()),
        "-o",
        &s(&d.path().join("x.y4m")),
        "--threads",
        "0",
    ]);
    assert_eq!(r.code, Some(2), "{}", r.stderr);
}
