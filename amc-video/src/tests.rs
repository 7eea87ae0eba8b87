//! Tests of the video module against clips generated with ffmpeg on the fly
//! (and the sample clips under `shared/data` when present). The clips, ffmpeg and
//! ffprobe come from the end-to-end tests' fixtures (`amc_e2e::fixtures`).

use super::*;
use amc_core::image::{Frame, PixelFormat};
use amc_e2e::fixtures::{ffmpeg, ffprobe_stream_types, lavfi, test_clip, test_tone};
use amc_e2e::list_dir;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Whether ffmpeg is installed; tests that need it pass vacuously (with a note) otherwise.
fn have_ffmpeg() -> bool {
    let ok = ffmpeg_available().is_ok();
    if !ok {
        eprintln!("note: ffmpeg/ffprobe not installed, skipping");
    }
    ok
}

/// Decodes a whole input: info, frames and timestamps.
fn read_all(path: &Path, opts: &InputOptions) -> (VideoInfo, Vec<Frame>, Vec<f64>) {
    let mut src = open_input(path, opts).unwrap_or_else(|e| panic!("open {}: {e}", path.display()));
    let info = src.info().clone();
    let (mut frames, mut times) = (Vec::new(), Vec::new());
    let mut buf = Frame::new(1, 1, PixelFormat::Rgb8);
    while let Some(t) = src.next_frame(&mut buf).unwrap() {
        assert_eq!(
            (buf.width, buf.height, buf.format),
            (info.width, info.height, PixelFormat::Rgb8)
        );
        assert_eq!(buf.data.len(), info.width * info.height * 3);
        frames.push(buf.clone());
        times.push(t);
    }
    // End of stream is sticky.
    assert_eq!(src.next_frame(&mut buf).unwrap(), None);
    (info, frames, times)
}

fn assert_timestamps(times: &[f64]) {
    assert_eq!(times.first().copied(), Some(0.0));
    for w in times.windows(2) {
        assert!(w[1] > w[0], "timestamps not increasing: {w:?}");
    }
}

/// Mean absolute difference of the RGB bytes of two frames of the same size
/// (`b` may be larger, e.g. padded; only `a`'s area is compared).
fn mae(a: &Frame, b: &Frame) -> f64 {
    let mut sum = 0u64;
    for y in 0..a.height {
        for x in 0..a.width * 3 {
            let (p, q) = (a.data[y * a.width * 3 + x], b.data[y * b.width * 3 + x]);
            sum += (p as i32 - q as i32).unsigned_abs() as u64;
        }
    }
    sum as f64 / (a.width * a.height * 3) as f64
}

/// Smooth, moving test frames (sharp edges would measure chroma subsampling,
/// not our code).
fn synthetic(width: usize, height: usize, n: usize, format: PixelFormat) -> Vec<Frame> {
    (0..n)
        .map(|i| {
            let mut f = Frame::new(width, height, format);
            let c = format.channels();
            for y in 0..height {
                for x in 0..width {
                    let p = &mut f.data[(y * width + x) * c..][..c];
                    p[0] = (40 + 3 * x + 5 * i).min(255) as u8;
                    p[1] = (30 + 3 * y + 2 * i).min(255) as u8;
                    p[2] = (200 - x - y).clamp(0, 255) as u8;
                    if c == 4 {
                        p[3] = 17; // alpha is ignored
                    }
                }
            }
            f
        })
        .collect()
}

fn write_all(path: &Path, spec: &OutputSpec, frames: &[Frame]) {
    let mut sink =
        create_output(path, spec).unwrap_or_else(|e| panic!("create {}: {e}", path.display()));
    for (i, f) in frames.iter().enumerate() {
        sink.write_frame(&f.as_ref(), i as f64 / spec.fps).unwrap();
    }
    sink.finish().unwrap();
}

/// A 1 s, 64x48, 30 fps H.264 clip with an AAC tone.
fn make_clip(dir: &Path) -> PathBuf {
    let clip = dir.join("clip.mp4");
    test_clip(&clip, 64, 48, 30, 1.0);
    clip
}

#[test]
fn reads_generated_mp4() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path());
    let (info, frames, times) = read_all(&clip, &InputOptions::default());
    assert_eq!((info.width, info.height), (64, 48));
    assert!((info.fps - 30.0).abs() < 1e-9, "{}", info.fps);
    assert_eq!(info.frame_count, Some(30));
    assert!(info.has_audio);
    assert!((info.duration_s.unwrap() - 1.0).abs() < 0.05);
    assert_eq!(frames.len(), 30);
    assert_timestamps(&times);
    for (i, t) in times.iter().enumerate() {
        assert!((t - i as f64 / 30.0).abs() < 1e-3, "frame {i} at {t}");
    }
    // Frames differ (testsrc2 moves), so they are really decoded in turn.
    assert_ne!(frames[0].data, frames[29].data);

    // Dropping a source mid-stream stops ffmpeg promptly.
    let start = std::time::Instant::now();
    let mut src = open_input(&clip, &InputOptions::default()).unwrap();
    let mut buf = Frame::new(1, 1, PixelFormat::Rgb8);
    assert_eq!(src.next_frame(&mut buf).unwrap(), Some(0.0));
    drop(src);
    assert!(start.elapsed() < Duration::from_secs(10));

    // An fps override gives i / fps timestamps.
    let opts = InputOptions {
        fps_override: Some(10.0),
        ..Default::default()
    };
    let (info, _, times) = read_all(&clip, &opts);
    assert_eq!(info.fps, 10.0);
    assert!((times[3] - 0.3).abs() < 1e-9);
}

#[test]
fn keeps_variable_frame_rate_timestamps() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("vfr.mkv");
    // Frames at 0, 0.1, 0.2, then a gap to 0.5, 0.6, ...
    lavfi(
        &clip,
        &["testsrc=size=32x32:rate=10:duration=1"],
        &[
            "-vf",
            "select='not(between(n,3,4))'",
            "-fps_mode",
            "passthrough",
            "-c:v",
            "libx264",
        ],
    );
    let (_, frames, times) = read_all(&clip, &InputOptions::default());
    assert_eq!(frames.len(), 8);
    assert_timestamps(&times);
    assert!(
        (times[2] - 0.2).abs() < 1e-3 && (times[3] - 0.5).abs() < 1e-3,
        "{times:?}"
    );
}

#[test]
fn round_trips_every_output_format() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let frames = synthetic(64, 48, 6, PixelFormat::Rgb8);
    let spec = OutputSpec::new(64, 48, 30000.0 / 1001.0);
    // (output name, worst mean absolute error allowed)
    for (name, tol) in [
        ("out.mp4", 6.0),
        ("out.MKV", 6.0),
        ("out.webm", 8.0),
        ("out.y4m", 2.0),
        ("pngs", 0.0),
        ("pngs2/", 0.0),
    ] {
        let path = dir.path().join(name);
        write_all(&path, &spec, &frames);
        let (info, back, times) = read_all(&path, &InputOptions::default());
        assert_eq!((info.width, info.height), (64, 48), "{name}");
        assert_eq!(back.len(), frames.len(), "{name}");
        assert_timestamps(&times);
        if !name.starts_with("png") {
            assert!((info.fps - 29.97).abs() < 0.01, "{name}: {}", info.fps);
        }
        for (a, b) in frames.iter().zip(&back) {
            let e = mae(a, b);
            assert!(e <= tol, "{name}: mean error {e}");
        }
    }
    // Only the finished outputs, no temporaries.
    assert_eq!(
        list_dir(dir.path()),
        ["out.MKV", "out.mp4", "out.webm", "out.y4m", "pngs", "pngs2"]
    );
    assert_eq!(list_dir(&dir.path().join("pngs"))[0], "frame-000000.png");
}

#[test]
fn writes_rgba_and_odd_sizes() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let frames = synthetic(33, 25, 3, PixelFormat::Rgba8);
    let rgb = synthetic(33, 25, 3, PixelFormat::Rgb8);
    let spec = OutputSpec::new(33, 25, 25.0);
    for (name, size, tol) in [
        ("odd.mp4", (34, 26), 8.0),
        ("odd.y4m", (33, 25), 2.5),
        ("odd", (33, 25), 0.0),
    ] {
        let path = dir.path().join(name);
        write_all(&path, &spec, &frames);
        let (info, back, _) = read_all(&path, &InputOptions::default());
        assert_eq!((info.width, info.height), size, "{name}");
        assert_eq!(back.len(), 3);
        for (a, b) in rgb.iter().zip(&back) {
            assert!(mae(a, b) <= tol, "{name}: {}", mae(a, b));
        }
    }
}

#[test]
fn copies_audio() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path());
    let (_, frames, _) = read_all(&clip, &InputOptions::default());
    for name in ["with-audio.mp4", "with-audio.mkv", "with-audio.webm"] {
        let out = dir.path().join(name);
        let spec = OutputSpec {
            audio_from: Some(clip.clone()),
            ..OutputSpec::new(64, 48, 30.0)
        };
        write_all(&out, &spec, &frames);
        assert_eq!(ffprobe_stream_types(&out), ["video", "audio"], "{name}");
    }
    // No audio in the source: none in the output, and no error.
    let silent = dir.path().join("silent.y4m");
    write_all(&silent, &OutputSpec::new(64, 48, 30.0), &frames[..2]);
    let out = dir.path().join("silent.mp4");
    let spec = OutputSpec {
        audio_from: Some(silent),
        ..OutputSpec::new(64, 48, 30.0)
    };
    write_all(&out, &spec, &frames[..2]);
    assert_eq!(ffprobe_stream_types(&out), ["video"]);
}

#[test]
fn reads_image_folder_in_natural_order() {
    let dir = tempfile::tempdir().unwrap();
    // Frame number n is a grey of level 10 * n; the names sort wrongly as text.
    for (name, n) in [
        ("frame-10.png", 10u8),
        ("frame-9.PNG", 9),
        ("frame-1.bmp", 1),
        ("frame-2.jpg", 2),
    ] {
        let img = image::RgbImage::from_pixel(8, 6, image::Rgb([n * 10; 3]));
        img.save(dir.path().join(name)).unwrap();
    }
    std::fs::write(dir.path().join("notes.txt"), "not an image").unwrap();
    std::fs::write(dir.path().join("._frame-0.png"), "macOS litter").unwrap();
    let (info, frames, times) = read_all(dir.path(), &InputOptions::default());
    assert_eq!((info.width, info.height, info.frame_count), (8, 6, Some(4)));
    assert_eq!(info.fps, DEFAULT_IMAGE_FPS);
    assert!(!info.has_audio);
    let levels: Vec<u8> = frames.iter().map(|f| f.data[0]).collect();
    assert!(
        levels[0] == 10 && levels[1].abs_diff(20) <= 2 && levels[2] == 90 && levels[3] == 100,
        "{levels:?}"
    );
    assert_timestamps(&times);
    assert!((times[3] - 3.0 / 30.0).abs() < 1e-12);
}

#[test]
fn reads_y4m_written_by_ffmpeg() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (pix_fmt, tol) in [
        ("yuv420p", 4.0),
        ("yuv422p", 4.0),
        ("yuv444p", 1.5),
        ("gray", 1.5),
    ] {
        let y4m = dir.path().join(format!("{pix_fmt}.y4m"));
        let mkv = dir.path().join(format!("{pix_fmt}.mkv"));
        let src = "testsrc2=size=66x50:rate=25";
        lavfi(&y4m, &[src], &["-frames:v", "4", "-pix_fmt", pix_fmt]);
        // The same pictures, losslessly, for ffmpeg's own conversion to RGB.
        ffmpeg(&[
            "-i",
            y4m.to_str().unwrap(),
            "-c:v",
            "ffv1",
            mkv.to_str().unwrap(),
        ]);
        let (info, ours, times) = read_all(&y4m, &InputOptions::default());
        assert_eq!(
            (info.width, info.height, info.fps, info.frame_count),
            (66, 50, 25.0, Some(4))
        );
        assert_timestamps(&times);
        let (_, theirs, _) = read_all(&mkv, &InputOptions::default());
        assert_eq!(ours.len(), 4);
        for (a, b) in ours.iter().zip(&theirs) {
            assert!(mae(a, b) <= tol, "{pix_fmt}: mean error {}", mae(a, b));
        }
    }
}

#[test]
fn reports_bad_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let open = |p: &Path| {
        open_input(p, &InputOptions::default())
            .err()
            .expect("should fail")
    };

    let e = open(&d.join("missing.mp4"));
    assert!(matches!(e, VideoError::NotFound { .. }), "{e}");
    assert!(e.to_string().contains("missing.mp4"));

    let empty = d.join("empty");
    std::fs::create_dir(&empty).unwrap();
    std::fs::write(empty.join("readme.txt"), "x").unwrap();
    assert!(matches!(open(&empty), VideoError::NoImages { .. }));

    let mixed = d.join("mixed");
    std::fs::create_dir(&mixed).unwrap();
    image::RgbImage::new(8, 6)
        .save(mixed.join("a1.png"))
        .unwrap();
    image::RgbImage::new(8, 7)
        .save(mixed.join("a2.png"))
        .unwrap();
    let mut src = open_input(&mixed, &InputOptions::default()).unwrap();
    let mut buf = Frame::new(1, 1, PixelFormat::Rgb8);
    assert!(src.next_frame(&mut buf).unwrap().is_some());
    let e = src.next_frame(&mut buf).unwrap_err().to_string();
    assert!(
        e.contains("a2.png") && e.contains("8x7") && e.contains("a1.png") && e.contains("8x6"),
        "{e}"
    );

    let broken = d.join("broken");
    std::fs::create_dir(&broken).unwrap();
    std::fs::write(broken.join("f1.png"), "not a png").unwrap();
    let e = open(&broken).to_string();
    assert!(e.contains("f1.png") && e.contains("decode"), "{e}");

    std::fs::write(d.join("bad.y4m"), "YUV4MPEG2 W4 C420\n").unwrap();
    let e = open(&d.join("bad.y4m"));
    assert!(matches!(e, VideoError::Y4m { .. }), "{e}");
    let mut trunc = b"YUV4MPEG2 W4 H2 F25:1\nFRAME\n".to_vec();
    trunc.extend_from_slice(&[16; 12]);
    trunc.extend_from_slice(b"FRAME\n\x10\x10");
    std::fs::write(d.join("trunc.y4m"), &trunc).unwrap();
    let mut src = open_input(&d.join("trunc.y4m"), &InputOptions::default()).unwrap();
    assert_eq!(src.next_frame(&mut buf).unwrap(), Some(0.0));
    let e = src.next_frame(&mut buf).unwrap_err().to_string();
    assert!(e.contains("truncated") && e.contains("trunc.y4m"), "{e}");

    if !have_ffmpeg() {
        return;
    }
    std::fs::write(d.join("text.mp4"), "hello, I am a text file\n").unwrap();
    let e = open(&d.join("text.mp4"));
    assert!(matches!(e, VideoError::NotAVideo { .. }), "{e}");
    assert!(
        e.to_string()
            .starts_with(&format!("{}: not a video", d.join("text.mp4").display())),
        "{e}"
    );

    let noise: Vec<u8> = (0..100_000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    std::fs::write(d.join("noise.mkv"), &noise).unwrap();
    let e = open(&d.join("noise.mkv"));
    assert!(matches!(e, VideoError::NotAVideo { .. }), "{e}");

    // Audio only: no video stream.
    let wav = d.join("tone.wav");
    test_tone(&wav, 0.2);
    let e = open(&wav).to_string();
    assert!(e.contains("no video stream"), "{e}");
}

#[test]
fn reports_bad_outputs_and_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spec = OutputSpec::new(16, 8, 30.0);
    let e = create_output(&d.join("out.avi"), &spec)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("\".avi\"") && e.contains(".mp4"), "{e}");
    let e = create_output(&d.join("nodir/out.mp4"), &spec)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("does not exist"), "{e}");
    assert!(create_output(&d.join("x.y4m"), &OutputSpec::new(16, 8, 0.0)).is_err());

    let full = d.join("full");
    std::fs::create_dir(&full).unwrap();
    std::fs::write(full.join("keep.txt"), "x").unwrap();
    let e = create_output(&full, &spec).err().unwrap();
    assert!(matches!(e, VideoError::OutputDirNotEmpty { .. }), "{e}");

    let frame = synthetic(16, 8, 1, PixelFormat::Rgb8).remove(0);
    let wrong = Frame::new(8, 8, PixelFormat::Rgb8);
    let mut names = vec!["out.y4m", "frames"];
    if have_ffmpeg() {
        names.extend(["out.mp4", "out.webm", "out.mkv"]);
    }
    for name in &names {
        let mut sink = create_output(&d.join(name), &spec).unwrap();
        sink.write_frame(&frame.as_ref(), 0.0).unwrap();
        let e = sink
            .write_frame(&wrong.as_ref(), 0.1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("8x8") && e.contains("16x8"), "{e}");
        sink.write_frame(&frame.as_ref(), 0.1).unwrap();
        drop(sink);
        // Finishing with no frames is an error too, and leaves nothing.
        let sink = create_output(&d.join(name), &spec).unwrap();
        assert!(sink.finish().is_err());
    }
    assert_eq!(list_dir(d), ["full"], "left behind");

    // An existing empty directory is replaced.
    let empty = d.join("empty");
    std::fs::create_dir(&empty).unwrap();
    write_all(&empty, &spec, &[frame]);
    assert_eq!(list_dir(&empty), ["frame-000000.png"]);
}

#[test]
fn watchdog_stops_a_stalled_child() {
    use std::io::Read;
    let d = Path::new("sleep");
    let args = [std::ffi::OsString::from("30")];
    let Ok(mut proc) =
        process::Proc::spawn("sleep", &args, d, Duration::from_millis(200), false, None)
    else {
        eprintln!("note: no `sleep` command, skipping");
        return;
    };
    let start = std::time::Instant::now();
    proc.arm();
    let mut out = Vec::new();
    let _ = proc.stdout.as_mut().unwrap().read_to_end(&mut out);
    proc.disarm();
    assert!(proc.timed_out());
    assert!(start.elapsed() < Duration::from_secs(10));
    assert!(proc.timeout_error().to_string().contains("no progress"));
}

/// The sample clips shipped with the project (skipped when absent).
fn sample(rel: &str) -> Option<PathBuf> {
    let p = amc_e2e::data_dir().join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("note: {} not present, skipping", p.display());
        None
    }
}

#[test]
fn reads_cup_sample() {
    let Some(path) = sample("cup/cup.mp4") else {
        return;
    };
    if !have_ffmpeg() {
        return;
    }
    let (info, frames, times) = read_all(&path, &InputOptions::default());
    assert_eq!((info.width, info.height), (640, 480));
    assert!(info.has_audio);
    assert_eq!(info.frame_count, Some(217));
    assert_eq!(frames.len(), 217);
    assert_timestamps(&times);
    let last = *times.last().unwrap();
    assert!((7.5..8.2).contains(&last), "{last}");
}

#[test]
fn reads_karma_sample_video_stream_only() {
    let Some(path) = sample("karma/karma.mp4") else {
        return;
    };
    if !have_ffmpeg() {
        return;
    }
    let (info, frames, times) = read_all(&path, &InputOptions::default());
    assert_eq!((info.width, info.height), (854, 480));
    assert!(info.has_audio);
    assert_eq!(frames.len(), 362);
    assert_timestamps(&times);
    assert!((times[1] - 1001.0 / 30000.0).abs() < 1e-3, "{}", times[1]);
}
