//! What a new user ran into: each mistake is a one-line error naming the
//! user's own path (never a hidden temporary one).

use amc_core::image::{Frame, FrameRef, PixelFormat};
use amc_video::{create_output, open_input, InputOptions, OutputSpec, VideoError};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data")
        .join(rel)
}

fn have_ffmpeg() -> bool {
    amc_video::ffmpeg_available().is_ok()
}

fn opts() -> InputOptions {
    InputOptions {
        timeout: Duration::from_secs(60),
        ..InputOptions::default()
    }
}

/// A small PNG written by the `image` crate.
fn write_png(path: &Path) {
    let pixels: Vec<u8> = (0..64 * 48 * 3).map(|i| (i % 253) as u8).collect();
    image::save_buffer_with_format(
        path,
        &pixels,
        64,
        48,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .unwrap();
}

#[test]
fn a_png_named_mp4_is_a_still_image() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("holiday.mp4");
    write_png(&p);
    let e = open_input(&p, &opts())
        .err()
        .expect("a still image must be refused");
    assert!(matches!(e, VideoError::StillImage { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("holiday.mp4") && msg.contains("still image") && msg.contains("folder"),
        "{msg}"
    );
}

#[test]
fn an_empty_file_says_so() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["empty.mp4", "empty.y4m", "empty.mov"] {
        let p = dir.path().join(name);
        std::fs::write(&p, b"").unwrap();
        let e = open_input(&p, &opts())
            .err()
            .expect("an empty file must be refused");
        let msg = e.to_string();
        assert!(
            msg.contains(name) && msg.contains("empty file") && !msg.contains("moov"),
            "{msg}"
        );
        let e = amc_video::inspect(&p, Duration::from_secs(30)).unwrap_err();
        assert!(e.to_string().contains("empty file"), "{e}");
    }
}

#[test]
fn a_truncated_jpeg_in_a_folder_is_named() {
    let src = data("cc9/frames");
    if !src.is_dir() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut names: Vec<_> = std::fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .collect();
    names.sort();
    for (i, p) in names.iter().take(3).enumerate() {
        let bytes = std::fs::read(p).unwrap();
        let bytes = if i == 2 {
            bytes[..bytes.len() / 2].to_vec()
        } else {
            bytes
        };
        std::fs::write(dir.path().join(format!("f{i}.jpg")), bytes).unwrap();
    }
    let mut src = open_input(dir.path(), &opts()).unwrap();
    let mut buf = Frame::new(0, 0, PixelFormat::Rgb8);
    assert!(src.next_frame(&mut buf).unwrap().is_some());
    assert!(src.next_frame(&mut buf).unwrap().is_some());
    let e = src.next_frame(&mut buf).unwrap_err().to_string();
    assert!(e.contains("f2.jpg") && e.contains("truncated JPEG"), "{e}");
}

#[test]
fn crf_beyond_the_format_range_is_an_error() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let spec = |crf| OutputSpec {
        crf: Some(crf),
        ..OutputSpec::new(16, 16, 30.0)
    };
    for (name, bad, good) in [("o.mp4", 52, 51), ("o.mkv", 60, 0), ("o.webm", 64, 63)] {
        let p = dir.path().join(name);
        let e = create_output(&p, &spec(bad))
            .err()
            .unwrap_or_else(|| panic!("{name}: CRF {bad} accepted"))
            .to_string();
        let max = if name.ends_with(".webm") { 63 } else { 51 };
        assert!(
            e.contains(name) && e.contains(&bad.to_string()) && e.contains(&format!("0..={max}")),
            "{e}"
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "{name}");
        // The largest value the encoder takes is fine.
        let sink = create_output(&p, &spec(good)).unwrap();
        drop(sink);
    }
    // Formats without a CRF ignore it.
    drop(create_output(&dir.path().join("o.y4m"), &spec(63)).unwrap());
}

#[test]
fn encoder_errors_name_the_output_not_its_temporary_file() {
    if !have_ffmpeg() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("result.mp4");
    let mut sink = create_output(&out, &OutputSpec::new(32, 32, 30.0)).unwrap();
    // Make the encoder's own file unwritable: a directory where it expects the file.
    let partial: Vec<PathBuf> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(partial.len(), 1, "{partial:?}");
    std::fs::remove_file(&partial[0]).unwrap();
    std::fs::create_dir(&partial[0]).unwrap();
    let pixels = vec![128u8; 32 * 32 * 3];
    let frame = FrameRef {
        width: 32,
        height: 32,
        format: PixelFormat::Rgb8,
        data: &pixels,
    };
    let mut err = None;
    for i in 0..30 {
        if let Err(e) = sink.write_frame(&frame, i as f64 / 30.0) {
            err = Some(e);
            break;
        }
    }
    let e = match err {
        Some(e) => e,
        None => sink.finish().unwrap_err(),
    }
    .to_string();
    let hidden = partial[0]
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    assert!(!e.contains(&hidden) && !e.contains("partial"), "{e}");
    assert!(e.contains("result.mp4"), "{e}");
}
