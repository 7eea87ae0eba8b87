//! Media fixtures shared by every test that needs ffmpeg: the one place that runs `ffmpeg` and
//! `ffprobe`, and that makes test clips and pictures from ffmpeg's `lavfi` generators
//! (`testsrc2`, `sine`). Used by the end-to-end tests in `tests/` and by amc-video's and
//! amc-server's own tests (a dev-dependency of both; this crate must never depend on them).

use std::ffi::OsStr;
use std::path::Path;
use std::process::Command;

// ---------------------------------------------------------------- ffmpeg

/// Runs `ffmpeg -hide_banner -nostdin -y -loglevel error ARGS...` (overwriting outputs) and
/// panics with ffmpeg's error output unless it succeeds.
pub fn ffmpeg<S: AsRef<OsStr>>(args: &[S]) {
    let out = Command::new("ffmpeg")
        .args(["-hide_banner", "-nostdin", "-y", "-loglevel", "error"])
        .args(args)
        .output()
        .expect("could not run ffmpeg (is ffmpeg installed?)");
    assert!(
        out.status.success(),
        "ffmpeg {:?} failed: {}",
        args.iter().map(|a| a.as_ref()).collect::<Vec<_>>(),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Writes `out` from ffmpeg `lavfi` generators: `ffmpeg -f lavfi -i SOURCE... ARGS... OUT`, with
/// one `-f lavfi -i` per source (e.g. `testsrc2=size=64x48:rate=30`, `sine=frequency=440`).
pub fn lavfi(out: &Path, sources: &[&str], args: &[&str]) {
    let mut a: Vec<&OsStr> = Vec::new();
    for s in sources {
        a.extend([
            OsStr::new("-f"),
            OsStr::new("lavfi"),
            OsStr::new("-i"),
            OsStr::new(s),
        ]);
    }
    a.extend(args.iter().map(OsStr::new));
    a.push(out.as_os_str());
    ffmpeg(&a);
}

/// Encodes a folder of PNG frames (`frame-%06d.png`, as `amc synth` writes them) at `fps` into
/// `out` as a camera records it: H.264, x264 CRF 30, yuv420p.
pub fn encode_frames(frames: &Path, fps: u32, out: &Path) {
    ffmpeg(&[
        OsStr::new("-framerate"),
        OsStr::new(&fps.to_string()),
        OsStr::new("-i"),
        frames.join("frame-%06d.png").as_os_str(),
        OsStr::new("-c:v"),
        OsStr::new("libx264"),
        OsStr::new("-crf"),
        OsStr::new("30"),
        OsStr::new("-pix_fmt"),
        OsStr::new("yuv420p"),
        out.as_os_str(),
    ]);
}

/// One `width`x`height` picture of ffmpeg's `testsrc2` pattern; the format follows `out`'s
/// extension (`.png`, `.jpg`...).
pub fn test_picture(out: &Path, width: u32, height: u32) {
    lavfi(
        out,
        &[&format!("testsrc2=size={width}x{height}")],
        &["-frames:v", "1"],
    );
}

/// ffmpeg's output arguments of the test clips' video: H.264 (x264's fastest preset), yuv420p.
const H264: [&str; 6] = [
    "-c:v",
    "libx264",
    "-preset",
    "ultrafast",
    "-pix_fmt",
    "yuv420p",
];

/// ffmpeg's moving `testsrc2` pattern at `width`x`height` and `fps` frames/s.
fn moving_pattern(width: u32, height: u32, fps: u32) -> String {
    format!("testsrc2=size={width}x{height}:rate={fps}")
}

/// A test clip with sound, `seconds` long: ffmpeg's moving `testsrc2` pattern at
/// `width`x`height` and `fps` frames/s (H.264, yuv420p), with a 440 Hz tone (AAC, 48 kHz).
/// The container follows `out`'s extension (`.mp4`, `.mkv`...).
pub fn test_clip(out: &Path, width: u32, height: u32, fps: u32, seconds: f64) {
    let seconds = seconds.to_string();
    lavfi(
        out,
        &[
            &moving_pattern(width, height, fps),
            "sine=frequency=440:sample_rate=48000",
        ],
        &[
            &["-t", seconds.as_str()][..],
            &H264,
            &["-c:a", "aac", "-shortest"],
        ]
        .concat(),
    );
}

/// A test clip without sound: [`test_clip`]'s picture alone, then ffmpeg's output arguments
/// `args` (`-movflags +faststart`...).
pub fn silent_test_clip(
    out: &Path,
    width: u32,
    height: u32,
    fps: u32,
    seconds: f64,
    args: &[&str],
) {
    let seconds = seconds.to_string();
    lavfi(
        out,
        &[&moving_pattern(width, height, fps)],
        &[&["-t", seconds.as_str()][..], &H264, args].concat(),
    );
}

/// A sound file with no video: a 440 Hz tone `seconds` long (format by `out`'s extension).
pub fn test_tone(out: &Path, seconds: f64) {
    lavfi(out, &["sine=frequency=440"], &["-t", &seconds.to_string()]);
}

// ---------------------------------------------------------------- ffprobe

fn run_ffprobe(path: &Path, args: &[&str]) -> std::process::Output {
    Command::new("ffprobe")
        .args(["-v", "error"])
        .args(args)
        .arg(path)
        .output()
        .expect("could not run ffprobe (is ffmpeg installed?)")
}

/// Runs `ffprobe -v error ARGS... PATH` and returns its standard output; panics unless it
/// succeeds.
pub fn ffprobe(path: &Path, args: &[&str]) -> String {
    let out = run_ffprobe(path, args);
    assert!(
        out.status.success(),
        "ffprobe failed on {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Number of video frames ffprobe decodes from a file (or image sequence pattern).
pub fn ffprobe_frames(path: &Path) -> u64 {
    let s = ffprobe(
        path,
        &[
            "-count_frames",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=nb_read_frames",
            "-of",
            "csv=p=0",
        ],
    );
    s.trim()
        .trim_end_matches(',')
        .parse()
        .unwrap_or_else(|_| panic!("ffprobe gave no frame count for {}: {s:?}", path.display()))
}

/// Codec types (`video`, `audio`, `data`, ...) of a file's streams, in order.
pub fn ffprobe_stream_types(path: &Path) -> Vec<String> {
    ffprobe(
        path,
        &["-show_entries", "stream=codec_type", "-of", "csv=p=0"],
    )
    .lines()
    .map(|l| l.trim().trim_end_matches(',').to_string())
    .filter(|l| !l.is_empty())
    .collect()
}

/// Presentation times (seconds) of a file's video frames, in order.
pub fn ffprobe_frame_times(path: &Path) -> Vec<f64> {
    ffprobe(
        path,
        &[
            "-select_streams",
            "v:0",
            "-show_entries",
            "frame=pts_time",
            "-of",
            "csv=p=0",
        ],
    )
    .lines()
    .filter_map(|l| l.trim().trim_end_matches(',').parse().ok())
    .collect()
}

/// Whether a file has an audio stream.
pub fn has_audio(path: &Path) -> bool {
    ffprobe_stream_types(path).iter().any(|t| t == "audio")
}

/// ffprobe's values of `entries` (comma-separated stream fields, e.g. `width,height`) for a
/// file's first video stream, comma-separated; empty when ffprobe cannot read the file.
pub fn ffprobe_video_entries(path: &Path, entries: &str) -> String {
    let e = format!("stream={entries}");
    let out = run_ffprobe(
        path,
        &[
            "-select_streams",
            "v:0",
            "-show_entries",
            &e,
            "-of",
            "csv=p=0",
        ],
    );
    String::from_utf8_lossy(&out.stdout)
        .trim()
        .trim_end_matches(',')
        .to_string()
}

/// Width and height of a file's first video stream (0 when unknown).
pub fn ffprobe_size(path: &Path) -> (u32, u32) {
    let s = ffprobe_video_entries(path, "width,height");
    let mut it = s.split(',').map(|x| x.parse::<u32>().unwrap_or(0));
    (it.next().unwrap_or(0), it.next().unwrap_or(0))
}

/// Duration of a file's first video stream, seconds (NaN if unknown).
pub fn ffprobe_video_duration(path: &Path) -> f64 {
    ffprobe_video_entries(path, "duration")
        .parse()
        .unwrap_or(f64::NAN)
}
