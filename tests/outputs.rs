//! What `amc stabilize` does with its output paths: they are checked before any
//! work, and an existing output is replaced only once the new one is complete.

use amc_e2e::fixtures::test_clip;
use amc_e2e::*;
use std::path::Path;

/// `amc stabilize INPUT -o OUT --fov 60 EXTRA...`'s arguments.
fn stabilize_args(input: &Path, out: &Path, extra: &[&str]) -> Vec<String> {
    let mut argv = vec![
        "stabilize".to_string(),
        s(input),
        "-o".into(),
        s(out),
        "--fov".into(),
        "60".into(),
    ];
    argv.extend(extra.iter().map(|a| a.to_string()));
    argv
}

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
        amc_ok(&stabilize_args(
            &clip,
            &out,
            if quiet { &["-q"] } else { &[] },
        ))
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

/// The GoPro clip's telemetry track (`gpmd`) and its start timecode reach the stabilized
/// MP4 unchanged, so Gyroflow and GPS tools still read them; its `fdsc` track, with no
/// codec ffmpeg can write, is left out (docs/cli.md says so).
#[test]
fn mp4_keeps_the_clips_telemetry_and_timecode() {
    use amc_e2e::fixtures::ffprobe;
    let tmp = tempfile::tempdir().unwrap();
    let karma = data("karma/karma.mp4");
    let out = tmp.path().join("karma.mp4");
    amc_ok(&stabilize_args(&karma, &out, &["-q"]));
    let tracks = |p: &std::path::Path| {
        ffprobe(
            p,
            &[
                "-show_entries",
                "stream=codec_type,codec_tag_string:stream_tags=timecode",
                "-of",
                "csv=p=0",
            ],
        )
    };
    let (before, after) = (tracks(&karma), tracks(&out));
    eprintln!("[karma] input tracks:\n{before}\noutput tracks:\n{after}");
    assert!(after.contains("data,gpmd"), "no telemetry track:\n{after}");
    assert!(
        after.contains("video,avc1,19:26:48:04"),
        "no timecode:\n{after}"
    );
    let payload = |p: &std::path::Path, stream: &str| {
        let o = std::process::Command::new("ffmpeg")
            .args(["-v", "error", "-i"])
            .arg(p)
            .args(["-map", stream, "-c", "copy", "-f", "data", "-"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        o.stdout
    };
    let (gpmd_in, gpmd_out) = (payload(&karma, "0:3"), payload(&out, "0:d:0"));
    assert!(!gpmd_in.is_empty());
    assert_eq!(gpmd_in, gpmd_out, "the telemetry changed on the way");
}

/// A constant-rate clip keeps its rate: frame times are read exactly (from each frame's
/// timestamp and its stream's time base), not from ffmpeg's six-digit `pts_time`, which
/// made a 496-frame 30 fps AVI come out at 4960000/165333 frames/s.
#[test]
fn a_constant_rate_clip_keeps_its_rate() {
    use amc_e2e::fixtures::{ffprobe, lavfi};
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("clip.avi");
    lavfi(
        &clip,
        &["testsrc=size=160x120:rate=30"],
        &["-frames:v", "496", "-c:v", "mpeg4"],
    );
    let out = tmp.path().join("out.mp4");
    amc_ok(&stabilize_args(&clip, &out, &["-q"]));
    let rates = ffprobe(
        &out,
        &[
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=avg_frame_rate,nb_frames",
            "-of",
            "default=nw=1",
        ],
    );
    eprintln!(
        "[avi 30 fps, 496 frames] output: {}",
        rates.replace('\n', " ")
    );
    assert!(rates.contains("avg_frame_rate=30/1"), "{rates}");
    assert!(rates.contains("nb_frames=496"), "{rates}");
}
