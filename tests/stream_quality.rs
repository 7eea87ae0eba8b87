//! Decoded quality of the live feed's H.264 against its JPEGs, frame by frame
//! (the same `frame` index): mean Sobel magnitude and PSNR on luma. Shared by
//! `tests/live_h264.rs` and the serve bench.

use std::path::Path;

/// H.264 frames against the JPEG frames of the same index.
#[derive(Clone, Copy, Debug)]
pub struct StreamQuality {
    /// Frames in both streams that were compared.
    pub frames: usize,
    /// Mean over frames of the H.264 frame's sharpness over the JPEG frame's.
    pub sharpness_ratio: f64,
    /// Mean PSNR of the H.264 frames against the JPEG frames, dB.
    pub psnr_db: f64,
}

/// `h264`: access units with their frame index, as a viewer got them from its
/// first (a keyframe); `jpeg`: JPEGs with theirs. Frames `w` x `h`.
pub fn h264_against_jpeg(
    h264: &[(Vec<u8>, u64)],
    jpeg: &[(Vec<u8>, u64)],
    w: usize,
    h: usize,
    dir: &Path,
) -> StreamQuality {
    let units: Vec<u8> = h264.iter().flat_map(|(d, _)| d.iter().copied()).collect();
    let decoded = gray_frames(&units, "h264", w, h, dir);
    assert_eq!(
        decoded.len(),
        h264.len(),
        "ffmpeg decodes every access unit"
    );
    let jpegs: Vec<u8> = jpeg.iter().flat_map(|(d, _)| d.iter().copied()).collect();
    let jpeg_frames = gray_frames(&jpegs, "mjpeg", w, h, dir);
    assert_eq!(jpeg_frames.len(), jpeg.len(), "ffmpeg decodes every JPEG");
    let (mut ratios, mut psnrs) = (Vec::new(), Vec::new());
    for ((_, index), frame) in h264.iter().zip(&decoded) {
        let Some(j) = jpeg.iter().position(|(_, i)| i == index) else {
            continue;
        };
        let jf = &jpeg_frames[j];
        ratios.push(sharpness(frame, w, h) / sharpness(jf, w, h));
        psnrs.push(psnr(frame, jf));
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    StreamQuality {
        frames: ratios.len(),
        sharpness_ratio: mean(&ratios),
        psnr_db: mean(&psnrs),
    }
}

/// Gray frames ffmpeg decodes from `bytes` (`-f h264` or `-f mjpeg`).
pub fn gray_frames(bytes: &[u8], format: &str, w: usize, h: usize, dir: &Path) -> Vec<Vec<u8>> {
    let path = dir.join(format!("stream.{format}"));
    std::fs::write(&path, bytes).unwrap();
    let out = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-f", format, "-i"])
        .arg(&path)
        .args(["-f", "rawvideo", "-pix_fmt", "gray", "-"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout.chunks_exact(w * h).map(<[u8]>::to_vec).collect()
}

/// Mean Sobel magnitude (3x3, / 8, intensities in [0, 1]) inside the border.
pub fn sharpness(g: &[u8], w: usize, h: usize) -> f64 {
    let p = |x: usize, y: usize| g[y * w + x] as f64 / 255.0;
    let mut sum = 0.0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let gx = (p(x + 1, y - 1) + 2.0 * p(x + 1, y) + p(x + 1, y + 1))
                - (p(x - 1, y - 1) + 2.0 * p(x - 1, y) + p(x - 1, y + 1));
            let gy = (p(x - 1, y + 1) + 2.0 * p(x, y + 1) + p(x + 1, y + 1))
                - (p(x - 1, y - 1) + 2.0 * p(x, y - 1) + p(x + 1, y - 1));
            sum += (gx * gx + gy * gy).sqrt() / 8.0;
        }
    }
    sum / ((w - 2) * (h - 2)) as f64
}

/// PSNR of two gray frames, dB.
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (255.0f64.powi(2) / mse.max(1e-9)).log10()
}
