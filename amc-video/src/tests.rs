//! Tests of the video module against clips generated with ffmpeg on the fly
//! (and the sample clips under `shared/data` when present). The clips, ffmpeg and
//! ffprobe come from the end-to-end tests' fixtures (`amc_e2e::fixtures`).

use super::*;
use amc_core::image::{Frame, PixelFormat};
use amc_e2e::fixtures::{
    ffmpeg, ffprobe_frame_times, ffprobe_stream_types, lavfi, test_clip, test_tone,
};
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

/// Decodes a whole input: info, frames (in `opts.pixel_format`) and timestamps.
fn read_all(path: &Path, opts: &InputOptions) -> (VideoInfo, Vec<Frame>, Vec<f64>) {
    let mut src = open_input(path, opts).unwrap_or_else(|e| panic!("open {}: {e}", path.display()));
    let info = src.info().clone();
    let (mut frames, mut times) = (Vec::new(), Vec::new());
    let mut buf = Frame::new(1, 1, PixelFormat::Rgb8);
    while let Some(t) = src.next_frame(&mut buf).unwrap() {
        assert_eq!(
            (buf.width, buf.height, buf.format),
            (info.width, info.height, opts.pixel_format)
        );
        let len = opts.pixel_format.buffer_len(info.width, info.height);
        assert_eq!(Some(buf.data.len()), len);
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
fn a_file_rewritten_in_place_is_probed_again() {
    // Probes are remembered per file; one rewritten under the same name (an
    // upload's temporary path reused, a clip re-exported) must not be
    // answered from memory.
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path());
    let first = inspect(&clip, Duration::from_secs(30)).unwrap();
    assert_eq!((first.info.width, first.info.height), (64, 48));
    // Asked again, the same answer (from memory or not).
    assert_eq!(
        inspect(&clip, Duration::from_secs(30)).unwrap().info,
        first.info
    );
    let other = dir.path().join("other.mp4");
    test_clip(&other, 96, 64, 30, 0.5);
    std::fs::rename(&other, &clip).unwrap();
    let second = inspect(&clip, Duration::from_secs(30)).unwrap();
    assert_eq!((second.info.width, second.info.height), (96, 64));
    assert_eq!(second.info.frame_count, Some(15));
    let (w, h) = frame_size(&clip, &InputOptions::default()).unwrap();
    assert_eq!((w, h), (96, 64));
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
    for pixel_format in [PixelFormat::Rgb8, PixelFormat::Yuv420p] {
        let opts = InputOptions {
            pixel_format,
            ..Default::default()
        };
        let (_, frames, times) = read_all(&clip, &opts);
        assert_eq!(frames.len(), 8);
        assert_timestamps(&times);
        assert!(
            (times[2] - 0.2).abs() < 1e-3 && (times[3] - 0.5).abs() < 1e-3,
            "{pixel_format:?}: {times:?}"
        );
    }
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
    let e = open(&empty);
    assert!(
        matches!(
            e,
            VideoError::NoImages {
                subfolder: None,
                ..
            }
        ),
        "{e}"
    );
    // A recording laid out as `frames/` beside its lens file: the error
    // points there.
    let frames = empty.join("frames");
    std::fs::create_dir(&frames).unwrap();
    for name in ["f1.png", "f2.png"] {
        image::RgbImage::new(8, 6).save(frames.join(name)).unwrap();
    }
    let e = open(&empty);
    assert!(matches!(e, VideoError::NoImages { .. }), "{e}");
    let text = e.to_string();
    assert!(
        text.contains(&format!("its subfolder {} holds 2", frames.display())),
        "{text}"
    );

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

// ------------------------------------------------------------- YUV 4:2:0

/// Options asking for YUV 4:2:0 frames.
fn yuv_opts() -> InputOptions {
    InputOptions {
        pixel_format: PixelFormat::Yuv420p,
        ..Default::default()
    }
}

/// The bytes after a `.y4m` file's header line: its frames.
fn y4m_body(path: &Path) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    let start = bytes.iter().position(|&b| b == b'\n').unwrap() + 1;
    bytes[start..].to_vec()
}

/// The frames as ffmpeg itself decodes `path` to `yuv420p`, concatenated.
fn ffmpeg_yuv420p(path: &Path, dir: &Path) -> Vec<u8> {
    let raw = dir.join("ffmpeg.yuv");
    ffmpeg(&[
        "-i",
        path.to_str().unwrap(),
        "-pix_fmt",
        "yuv420p",
        "-f",
        "rawvideo",
        raw.to_str().unwrap(),
    ]);
    std::fs::read(raw).unwrap()
}

/// PSNR (dB) between the first `a.len()` bytes of two sample buffers.
fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let se: f64 = a
        .iter()
        .zip(b)
        .map(|(&p, &q)| (p as f64 - q as f64).powi(2))
        .sum();
    let mse = se / a.len() as f64;
    10.0 * (255.0f64.powi(2) / mse.max(1e-12)).log10()
}

/// The `(y, u, v)` planes of a `w x h` YUV frame cropped from a larger one
/// (an encoder pads odd sizes to even ones), concatenated.
fn crop_yuv(f: &Frame, w: usize, h: usize) -> Vec<u8> {
    let (y, u, v) = f.as_ref().yuv_planes();
    let (cw, ch) = amc_core::image::chroma_size(w, h);
    let (fcw, _) = amc_core::image::chroma_size(f.width, f.height);
    let mut out = Vec::new();
    for row in 0..h {
        out.extend_from_slice(&y[row * f.width..][..w]);
    }
    for plane in [u, v] {
        for row in 0..ch {
            out.extend_from_slice(&plane[row * fcw..][..cw]);
        }
    }
    out
}

/// `synthetic` frames as YUV 4:2:0.
fn synthetic_yuv(width: usize, height: usize, n: usize) -> Vec<Frame> {
    synthetic(width, height, n, PixelFormat::Rgb8)
        .into_iter()
        .map(|f| {
            let mut yuv = Frame::new(width, height, PixelFormat::Yuv420p);
            amc_core::color::rgb_to_yuv420p_into(width, height, 3, &f.data, &mut yuv.data);
            yuv
        })
        .collect()
}

#[test]
fn y4m_420_round_trips_byte_for_byte_as_yuv() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (w, h) in [(66, 50), (33, 25)] {
        let src = dir.path().join(format!("in-{w}.y4m"));
        if w % 2 == 0 {
            lavfi(
                &src,
                &[&format!("testsrc2=size={w}x{h}:rate=25")],
                &["-frames:v", "4", "-pix_fmt", "yuv420p"],
            );
        } else {
            // ffmpeg rounds odd 4:2:0 sizes down: write this one by hand.
            let len = PixelFormat::Yuv420p.buffer_len(w, h).unwrap();
            let mut bytes = format!("YUV4MPEG2 W{w} H{h} F25:1 Ip A1:1 C420jpeg\n").into_bytes();
            for i in 0..4 * len {
                if i % len == 0 {
                    bytes.extend_from_slice(b"FRAME\n");
                }
                bytes.push((16 + i * 7 % 220) as u8);
            }
            std::fs::write(&src, bytes).unwrap();
        }
        let (info, frames, _) = read_all(&src, &yuv_opts());
        assert_eq!((info.width, info.height, frames.len()), (w, h, 4));
        // Straight copies of ffmpeg's planes...
        let all: Vec<u8> = frames.iter().flat_map(|f| f.data.clone()).collect();
        assert_eq!(all, ffmpeg_yuv420p(&src, dir.path()), "{w}x{h}");
        // ...written back unchanged.
        let out = dir.path().join(format!("out-{w}.y4m"));
        let spec = OutputSpec {
            pixel_format: PixelFormat::Yuv420p,
            ..OutputSpec::new(info.width, info.height, info.fps)
        };
        write_all(&out, &spec, &frames);
        assert_eq!(y4m_body(&out), y4m_body(&src), "{w}x{h}");
    }
}

#[test]
fn decodes_h264_as_ffmpegs_own_yuv420p() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path());
    let (info, frames, times) = read_all(&clip, &yuv_opts());
    assert_eq!((info.width, info.height, frames.len()), (64, 48, 30));
    assert_timestamps(&times);
    let ours: Vec<u8> = frames.iter().flat_map(|f| f.data.clone()).collect();
    assert!(ours == ffmpeg_yuv420p(&clip, dir.path()), "planes differ");
}

#[test]
fn decodes_full_range_and_10_bit_video_to_limited_yuv420p() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let white = "color=white:size=32x16:rate=10";
    // Full range as `yuvj420p`, as `yuv420p` merely tagged full range, as
    // 10-bit 4:2:2 and 4:4:4: white is Y 235, grey chroma, whatever the source.
    for (name, args) in [
        ("j.mp4", &["-pix_fmt", "yuvj420p", "-c:v", "libx264"][..]),
        (
            "pc.mkv",
            &[
                "-vf",
                "scale=out_range=pc",
                "-pix_fmt",
                "yuv420p",
                "-color_range",
                "pc",
                "-c:v",
                "ffv1",
            ][..],
        ),
        (
            "10bit.mkv",
            &["-pix_fmt", "yuv422p10le", "-c:v", "ffv1"][..],
        ),
        ("444.mkv", &["-pix_fmt", "yuv444p", "-c:v", "ffv1"][..]),
    ] {
        let clip = dir.path().join(name);
        let mut args = args.to_vec();
        args.extend(["-frames:v", "2"]);
        lavfi(&clip, &[white], &args);
        let (_, frames, _) = read_all(&clip, &yuv_opts());
        assert_eq!(frames.len(), 2, "{name}");
        let (y, u, v) = frames[0].as_ref().yuv_planes();
        let near = |p: &[u8], want: u8| p.iter().all(|&s| s.abs_diff(want) <= 1);
        assert!(
            near(y, 235) && near(u, 128) && near(v, 128),
            "{name}: {y:?} {u:?}"
        );
    }
}

/// A `.y4m` file of one frame: `header` then `planes`.
fn y4m_file(dir: &Path, name: &str, header: &str, planes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    let mut bytes = format!("YUV4MPEG2 {header}\nFRAME\n").into_bytes();
    bytes.extend_from_slice(planes);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn reads_other_y4m_layouts_as_limited_range_yuv420p() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let one = |path: &Path| read_all(path, &yuv_opts()).1.remove(0).data;
    // Full range: black, white and mid grey luma; extreme chroma.
    let luma = [0u8, 255, 128, 64, 0, 255, 128, 64];
    let full = y4m_file(
        d,
        "full.y4m",
        "W4 H2 F25:1 C420jpeg XCOLORRANGE=FULL",
        &[&luma[..], &[0, 128], &[255, 64]].concat(),
    );
    let y = [16u8, 235, 126, 71, 16, 235, 126, 71];
    assert_eq!(one(&full), [&y[..], &[16, 128], &[240, 72]].concat());
    // The same planes in limited range are taken as they are.
    let limited = y4m_file(
        d,
        "lim.y4m",
        "W4 H2 C420",
        &[&luma[..], &[0, 128], &[255, 64]].concat(),
    );
    assert_eq!(one(&limited), [&luma[..], &[0, 128], &[255, 64]].concat());
    // 4:4:4: each 2x2 block of chroma is averaged (rounded).
    let u444 = [10u8, 20, 30, 41, 50, 60, 70, 80];
    let v444 = [128u8; 8];
    let c444 = y4m_file(
        d,
        "444.y4m",
        "W4 H2 C444",
        &[&luma[..], &u444, &v444].concat(),
    );
    assert_eq!(one(&c444), [&luma[..], &[35, 55], &[128, 128]].concat());
    // 4:2:2: vertical pairs are averaged; odd sizes keep their last row.
    let c422 = y4m_file(
        d,
        "422.y4m",
        "W3 H3 C422",
        &[
            &[100u8; 9][..],
            &[10, 20, 30, 41, 50, 60],
            &[1, 2, 3, 4, 5, 6],
        ]
        .concat(),
    );
    assert_eq!(
        one(&c422),
        [&[100u8; 9][..], &[20, 31, 50, 60], &[2, 3, 5, 6]].concat()
    );
    // Mono: grey chroma.
    let mono = y4m_file(d, "mono.y4m", "W2 H2 Cmono", &[20, 40, 60, 80]);
    assert_eq!(one(&mono), [20, 40, 60, 80, 128, 128]);
    // Full-range 4:4:4 white and black.
    let full444 = y4m_file(
        d,
        "full444.y4m",
        "W2 H2 C444 XCOLORRANGE=FULL",
        &[&[255u8, 0, 255, 0][..], &[0; 4], &[255; 4]].concat(),
    );
    assert_eq!(one(&full444), [235, 16, 235, 16, 16, 240]);
}

#[test]
fn refuses_to_decode_as_rgba() {
    let dir = tempfile::tempdir().unwrap();
    let path = y4m_file(dir.path(), "a.y4m", "W2 H2 Cmono", &[0; 4]);
    let opts = InputOptions {
        pixel_format: PixelFormat::Rgba8,
        ..Default::default()
    };
    let e = open_input(&path, &opts).err().unwrap();
    assert!(
        matches!(
            e,
            VideoError::UnsupportedPixelFormat {
                format: PixelFormat::Rgba8,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("Rgba8"), "{e}");
}

#[test]
fn encodes_yuv420p_frames_through_ffmpeg() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (w, h) in [(64, 48), (33, 25)] {
        let frames = synthetic_yuv(w, h, 6);
        let spec = OutputSpec {
            pixel_format: PixelFormat::Yuv420p,
            ..OutputSpec::new(w, h, 30.0)
        };
        // Lossless x264 (CRF 0) gives the planes back exactly.
        let mkv = dir.path().join(format!("lossless-{w}.mkv"));
        write_all(
            &mkv,
            &OutputSpec {
                crf: Some(0),
                ..spec.clone()
            },
            &frames,
        );
        let (_, back, _) = read_all(&mkv, &yuv_opts());
        assert_eq!(back.len(), frames.len());
        for (a, b) in frames.iter().zip(&back) {
            // The odd size comes back padded to 34x26 (the last column and
            // row repeated); the frame's own area is exact.
            assert_eq!(
                (b.width, b.height),
                (w.next_multiple_of(2), h.next_multiple_of(2))
            );
            assert!(
                a.data == crop_yuv(b, w, h),
                "{w}x{h}: lossless planes differ"
            );
        }
        // Lossy mp4 and webm at their default quality.
        for name in ["lossy.mp4", "lossy.webm"] {
            let path = dir.path().join(format!("{w}-{name}"));
            write_all(&path, &spec, &frames);
            let (_, back, _) = read_all(&path, &yuv_opts());
            assert_eq!(back.len(), frames.len());
            for (a, b) in frames.iter().zip(&back) {
                let db = psnr(&a.data, &crop_yuv(b, w, h));
                eprintln!("{w}x{h} {name}: PSNR {db:.1} dB");
                assert!(db > 45.0, "{w}x{h} {name}: PSNR {db:.1} dB");
            }
        }
    }
}

#[test]
fn ffmpeg_sink_converts_frames_of_the_other_format() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let yuv = synthetic_yuv(32, 16, 2);
    let rgb = synthetic(32, 16, 2, PixelFormat::Rgb8);
    // RGB frames into a YUV pipe, YUV frames into an RGB pipe: both lossless
    // encodes decode close to the frames given.
    for (pipe, given) in [(PixelFormat::Yuv420p, &rgb), (PixelFormat::Rgb8, &yuv)] {
        let path = dir.path().join(format!("{pipe:?}.mkv"));
        let spec = OutputSpec {
            pixel_format: pipe,
            crf: Some(0),
            ..OutputSpec::new(32, 16, 30.0)
        };
        write_all(&path, &spec, given);
        let (_, back, _) = read_all(&path, &yuv_opts());
        for (a, b) in yuv.iter().zip(&back) {
            let db = psnr(&a.data, &b.data);
            assert!(db > 40.0, "{pipe:?} pipe: PSNR {db:.1} dB");
        }
    }
}

#[test]
fn yuv420p_output_keeps_variable_frame_rate_timestamps() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let frames = synthetic_yuv(32, 32, 6);
    let times = [0.0, 0.1, 0.2, 0.5, 0.6, 0.7];
    let spec = OutputSpec {
        pixel_format: PixelFormat::Yuv420p,
        ..OutputSpec::new(32, 32, 10.0)
    };
    for name in ["vfr.mp4", "vfr.mkv", "vfr.webm"] {
        let path = dir.path().join(name);
        let mut sink = create_output(&path, &spec).unwrap();
        for (f, &t) in frames.iter().zip(&times) {
            sink.write_frame(&f.as_ref(), t).unwrap();
        }
        sink.finish().unwrap();
        let probed = ffprobe_frame_times(&path);
        assert_eq!(probed.len(), times.len(), "{name}: {probed:?}");
        let t0 = probed[0];
        for (p, t) in probed.iter().zip(&times) {
            assert!((p - t0 - t).abs() < 2e-3, "{name}: {probed:?}");
        }
        let (_, _, read) = read_all(&path, &yuv_opts());
        for (r, t) in read.iter().zip(&times) {
            assert!((r - t).abs() < 2e-3, "{name}: {read:?}");
        }
    }
}

#[test]
fn yuv420p_frames_reach_pngs_and_images_become_yuv420p() {
    let dir = tempfile::tempdir().unwrap();
    let colour = [200u8, 30, 90];
    let rgb: Vec<u8> = colour.iter().copied().cycle().take(6 * 4 * 3).collect();
    let mut frame = Frame::new(6, 4, PixelFormat::Yuv420p);
    amc_core::color::rgb_to_yuv420p_into(6, 4, 3, &rgb, &mut frame.data);
    // Tail padding, as the core's frames may carry, is not written.
    let mut padded = frame.clone();
    padded.data.extend_from_slice(&[0; 16]);
    let pngs = dir.path().join("pngs");
    write_all(
        &pngs,
        &OutputSpec::new(6, 4, 30.0),
        &[frame.clone(), padded],
    );
    let (_, back, _) = read_all(&pngs, &InputOptions::default());
    for f in &back {
        for px in f.data.chunks_exact(3) {
            for (a, b) in px.iter().zip(&colour) {
                assert!(a.abs_diff(*b) <= 2, "{px:?} vs {colour:?}");
            }
        }
    }
    // Read back as YUV: the core's conversion of the PNG's RGB.
    let (_, yuv, _) = read_all(&pngs, &yuv_opts());
    let mut want = Vec::new();
    amc_core::color::rgb_to_yuv420p_into(6, 4, 3, &back[0].data, &mut want);
    assert_eq!(yuv[0].data, want);
}
