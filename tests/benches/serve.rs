//! `cargo bench -p amc-e2e --bench serve`: the service's speed on this machine.
//!
//! 1. A 1280x720, 30 fps, 20 s H.264 clip with audio (karma.mp4 looped and
//!    scaled) goes through `POST /stabilize` (decode, stabilize, encode,
//!    metrics) on a real server on loopback: wall time vs the clip's 20 s.
//! 2. The same clip as a looped `--live-source`: the per-frame latency the
//!    live feed adds (frame decoded -> stabilized JPEG ready), as reported in
//!    each frame's telemetry, over 300 frames.
//! 3. The clip at 60 frames/s (the paper's FPV camera's rate) as a looped
//!    `--live-source` with two viewers at once: frames/s reaching each viewer
//!    and the added latency (p50/p95/max) over 20 s.
//! 4. The live feed as H.264 (`/live?codec=h264`) beside JPEG: at 320x180
//!    60 fps, 1280x720 60 fps and 1920x1080 30 fps sources, two H.264 viewers
//!    and one JPEG viewer at once: frames/s, Mbit/s and latency for each,
//!    and the H.264 frames' quality against the JPEG frames of the same
//!    index (PSNR, and Sobel sharpness as a ratio).
//!
//! `cargo bench -p amc-e2e --bench serve -- h264` runs part 4 alone.

use amc_e2e::fixtures::ffmpeg;
use amc_e2e::server::{post, websocket, Server};
use amc_e2e::stream_quality::h264_against_jpeg;
use amc_e2e::{data, s};
use std::time::{Duration, Instant};
use tungstenite::Message;

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

/// `ffmpeg INPUT... -c:v libx264 -preset veryfast -crf 20 AUDIO... OUT`: the bench's clips.
fn encode(input: &[&str], audio: &[&str], out: &std::path::Path) {
    let video = ["-c:v", "libx264", "-preset", "veryfast", "-crf", "20"];
    let out = s(out);
    ffmpeg(&[input, &video, audio, &[out.as_str()]].concat());
}

fn main() {
    let only_h264 = std::env::args().any(|a| a == "h264");
    let dir = tempfile::tempdir().expect("temp dir");
    if only_h264 {
        return h264_section(dir.path());
    }
    let clip = dir.path().join("karma-720p30-20s.mp4");
    // karma.mp4 looped and scaled.
    encode(
        &[
            "-stream_loop",
            "1",
            "-i",
            &s(&data("karma/karma.mp4")),
            "-t",
            "20",
            "-map",
            "0:v:0",
            "-map",
            "0:a:0",
            "-vf",
            "scale=1280:720,fps=30",
        ],
        &["-c:a", "aac"],
        &clip,
    );
    let bytes = std::fs::read(&clip).expect("clip");
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    println!(
        "machine: {cores} cores; clip: 1280x720, 30 fps, 20 s, {:.1} MB",
        bytes.len() as f64 / 1e6
    );

    let server = Server::start(&[]);
    println!("\n| POST /stabilize (720p30, 20 s) | wall time | frames/s | x real time |");
    println!("|---|---|---|---|");
    for (label, query) in [
        ("defaults (metrics on)", "fov=70"),
        ("metrics=false", "fov=70&metrics=false"),
    ] {
        let start = Instant::now();
        let r = post(
            &server.url(&format!("/stabilize?{query}")),
            "video/mp4",
            &bytes,
        );
        let secs = start.elapsed().as_secs_f64();
        assert_eq!(r.status, 200, "{}", r.text());
        let frames: f64 = r
            .header("x-amc-frames")
            .and_then(|s| s.parse().ok())
            .unwrap_or(0.0);
        println!(
            "| {label} | {secs:.1} s | {:.1} | {:.2}x |",
            frames / secs,
            20.0 / secs
        );
    }
    drop(server);

    let Viewer {
        rate, lat, skipped, ..
    } = live(&clip, &["/live"], 330, false).remove(0);
    println!("\n| live feed | median | p95 | max | frames/s to a viewer | skipped |");
    println!("|---|---|---|---|---|---|");
    println!(
        "| 720p30 source, 1 viewer: latency added per frame (decoded -> JPEG ready) | {:.1} ms | {:.1} ms | {:.1} ms | {rate:.1} | {skipped} |",
        percentile(&lat, 0.5),
        percentile(&lat, 0.95),
        lat[lat.len() - 1],
    );

    let clip60 = dir.path().join("karma-720p60-20s.mp4");
    encode(&["-i", &s(&clip), "-vf", "fps=60"], &["-an"], &clip60);
    for (
        viewer,
        Viewer {
            rate, lat, skipped, ..
        },
    ) in live(&clip60, &["/live", "/live"], 1230, false)
        .into_iter()
        .enumerate()
    {
        println!(
            "| 720p60 source, viewer {} of 2 | {:.1} ms | {:.1} ms | {:.1} ms | {rate:.1} | {skipped} |",
            viewer + 1,
            percentile(&lat, 0.5),
            percentile(&lat, 0.95),
            lat[lat.len() - 1],
        );
    }
    h264_section(dir.path());
}

/// Part 4: H.264 beside JPEG at three sizes.
fn h264_section(dir: &std::path::Path) {
    println!("\n| live source | viewer | frames/s | Mbit/s | latency p50 | p95 | max | skipped | sharpness vs JPEG | PSNR vs JPEG |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (w, h, fps) in [(320, 180, 60), (1280, 720, 60), (1920, 1080, 30)] {
        let clip = dir.join(format!("karma-{h}p{fps}.mp4"));
        encode(
            &[
                "-stream_loop",
                "1",
                "-i",
                &s(&data("karma/karma.mp4")),
                "-t",
                "20",
                "-vf",
                &format!("scale={w}:{h},fps={fps}"),
            ],
            &["-an"],
            &clip,
        );
        // ~12 s of frames for each viewer.
        let frames = 12 * fps as usize;
        // Three JPEG viewers first (before H.264: the baseline of this run),
        // then two H.264 viewers and one JPEG viewer.
        let jpeg_only = ["/live", "/live", "/live"];
        let mixed = ["/live?codec=h264", "/live?codec=h264", "/live"];
        let baseline = live(&clip, &jpeg_only, frames, false);
        let beside = live(&clip, &mixed, frames, true);
        // Each H.264 viewer's decoded frames against the JPEG viewer's of the same index.
        let quality: Vec<String> = beside
            .iter()
            .map(|v| {
                if v.frames
                    .first()
                    .is_none_or(|(d, _)| d.starts_with(&[0xff, 0xd8]))
                {
                    return "-".to_string();
                }
                let q = h264_against_jpeg(&v.frames, &beside[2].frames, w, h, dir);
                format!(
                    "{:.3} ({} frames) | {:.1} dB",
                    q.sharpness_ratio, q.frames, q.psnr_db
                )
            })
            .collect();
        let rows = jpeg_only
            .iter()
            .zip(&baseline)
            .map(|(p, v)| (p, v, "- | -".to_string()))
            .chain(
                mixed
                    .iter()
                    .zip(&beside)
                    .zip(quality)
                    .map(|((p, v), q)| (p, v, if q == "-" { "- | -".to_string() } else { q })),
            );
        for (path, v, q) in rows {
            println!(
                "| {w}x{h} {fps} fps | {path} | {:.1} | {:.2} | {:.1} ms | {:.1} ms | {:.1} ms | {} | {q} |",
                v.rate,
                v.bytes as f64 * 8.0 / 1e6 / ((frames - 30) as f64 / v.rate),
                percentile(&v.lat, 0.5),
                percentile(&v.lat, 0.95),
                v.lat[v.lat.len() - 1],
                v.skipped,
            );
        }
    }
}

/// What one viewer of [`live`] got.
struct Viewer {
    /// Frames/s received after the first 30.
    rate: f64,
    /// The latencies the server reported after the first 30 frames, sorted, ms.
    lat: Vec<f64>,
    /// Frames the viewer was skipped past.
    skipped: u64,
    /// Bytes of its binary messages after the first 30 frames.
    bytes: u64,
    /// Every binary message with its frame index, when kept.
    frames: Vec<(Vec<u8>, u64)>,
}

/// Serves `clip` as a looped live source to one viewer per path at once
/// (`/live`, `/live?codec=h264`), each reading `frames` frames; `keep`: each
/// viewer keeps its binary messages.
fn live(clip: &std::path::Path, paths: &[&str], frames: usize, keep: bool) -> Vec<Viewer> {
    let server = Server::start(&[
        "--live-source",
        clip.to_str().unwrap(),
        "--live-loop",
        "--live-fov",
        "70",
    ]);
    let sockets: Vec<_> = paths
        .iter()
        .map(|p| websocket(&server.addr, p, Duration::from_secs(20)).expect("viewer"))
        .collect();
    let threads: Vec<_> = sockets
        .into_iter()
        .map(|mut ws| {
            std::thread::spawn(move || {
                let mut latencies = Vec::new();
                let mut started: Option<Instant> = None;
                let mut skipped = 0u64;
                let mut last: Option<u64> = None;
                let mut bytes = 0u64;
                let mut kept = Vec::new();
                let mut data = None;
                while latencies.len() < frames {
                    match ws.read() {
                        Ok(Message::Binary(b)) => {
                            if started.is_some() {
                                bytes += b.len() as u64;
                            }
                            if keep {
                                data = Some(b.to_vec());
                            }
                        }
                        Ok(Message::Text(t)) => {
                            let v: serde_json::Value = serde_json::from_str(&t).expect("json");
                            let f = v["frame"].as_u64().unwrap_or(0);
                            if let Some(l) = last {
                                skipped += f.saturating_sub(l + 1);
                            }
                            last = Some(f);
                            if let Some(d) = data.take() {
                                kept.push((d, f));
                            }
                            latencies.push(v["latency_ms"].as_f64().unwrap_or(f64::NAN));
                            // The first frames include the stabilizer's warm-up.
                            if latencies.len() == 30 {
                                started = Some(Instant::now());
                            }
                        }
                        Ok(_) => {}
                        Err(e) => panic!("viewer: {e}"),
                    }
                }
                let secs = started.map_or(f64::NAN, |s| s.elapsed().as_secs_f64());
                let mut lat: Vec<f64> = latencies[30..].to_vec();
                lat.sort_by(|a, b| a.total_cmp(b));
                Viewer {
                    rate: (frames - 30) as f64 / secs,
                    lat,
                    skipped,
                    bytes,
                    frames: kept,
                }
            })
        })
        .collect();
    let out = threads
        .into_iter()
        .map(|t| t.join().expect("viewer thread"))
        .collect();
    drop(server);
    out
}
