//! The live feed as H.264 (`/live?codec=h264`) from a real `amc serve` with
//! a looped clip as `--live-source`: every viewer's stream starts at a
//! keyframe with its parameter sets and decodes with ffmpeg frame for frame,
//! a viewer joining later starts at a keyframe too, a stalled viewer skips to
//! a keyframe without holding the others back, and JPEG viewers keep their
//! stream beside them.

use amc_e2e::data;
use amc_e2e::server::{websocket, Server};
use amc_e2e::stream_quality::h264_against_jpeg;
use std::net::TcpStream;
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tungstenite::{Message, WebSocket};

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn start() -> Server {
    let cup = data("cup/cup.mp4");
    Server::start(&[
        "--live-source",
        cup.to_str().unwrap(),
        "--live-loop",
        "--live-fov",
        "70",
    ])
}

/// One frame as a viewer got it: the binary message and its telemetry.
struct Got {
    data: Vec<u8>,
    meta: serde_json::Value,
}

/// Reads `n` frames (binary, then text).
fn read(ws: &mut WebSocket<TcpStream>, n: usize) -> Vec<Got> {
    let mut out = Vec::new();
    let mut data = None;
    while out.len() < n {
        match ws.read().expect("the viewer's socket") {
            Message::Binary(b) => data = Some(b.to_vec()),
            Message::Text(t) => out.push(Got {
                data: data.take().expect("a binary message before its telemetry"),
                meta: serde_json::from_str(&t).unwrap(),
            }),
            _ => {}
        }
    }
    out
}

/// The NAL unit types of an Annex-B access unit.
fn nal_types(au: &[u8]) -> Vec<u8> {
    au.windows(5)
        .filter(|w| w[..4] == [0, 0, 0, 1])
        .map(|w| w[4] & 0x1f)
        .collect()
}

/// Frames ffmpeg decodes from the concatenated units, and its errors.
fn decode(units: &[Got], dir: &Path, name: &str) -> (usize, String) {
    let path = dir.join(name);
    let bytes: Vec<u8> = units.iter().flat_map(|u| u.data.iter().copied()).collect();
    std::fs::write(&path, bytes).unwrap();
    let out = std::process::Command::new("ffprobe")
        .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
        .args(["-show_entries", "stream=nb_read_frames", "-of", "csv=p=0"])
        .arg(&path)
        .output()
        .unwrap();
    let n = String::from_utf8_lossy(&out.stdout)
        .trim()
        .parse()
        .unwrap_or(0);
    (n, String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn h264_viewers_start_at_a_keyframe_and_ffmpeg_decodes_every_frame() {
    let _g = serial();
    let server = start();
    let dir = tempfile::tempdir().unwrap();
    let t = Duration::from_secs(20);
    let mut a = websocket(&server.addr, "/live?codec=h264", t).expect("H.264 viewer a");
    let mut jpeg = websocket(&server.addr, "/live", t).expect("JPEG viewer");
    let first = read(&mut a, 40);
    // The first message decodes alone: an IDR picture with its SPS and PPS.
    let types = nal_types(&first[0].data);
    for want in [7, 8, 5] {
        assert!(
            types.contains(&want),
            "first access unit's NAL types {types:?}"
        );
    }
    // Frames that came while ffmpeg started were held, not left out, and
    // so were those that came while the held ones were written.
    let frames: Vec<u64> = first
        .iter()
        .map(|g| g.meta["frame"].as_u64().unwrap())
        .collect();
    assert!(
        frames[..12].windows(2).all(|w| w[1] == w[0] + 1),
        "the first viewer's frames: {frames:?}"
    );
    // It got every access unit the encoder made, from its first.
    let units =
        |g: &[Got]| -> Vec<u64> { g.iter().map(|g| g.meta["unit"].as_u64().unwrap()).collect() };
    assert!(
        units(&first).iter().copied().eq(0..first.len() as u64),
        "the first viewer's units: {:?}",
        units(&first)
    );
    // A viewer joining later starts at a keyframe too.
    let mut b = websocket(&server.addr, "/live?codec=h264", t).expect("H.264 viewer b");
    let joined = read(&mut b, 40);
    assert!(
        nal_types(&joined[0].data).contains(&5),
        "b's first access unit is no IDR"
    );
    let more = read(&mut a, 40);
    let jpegs = read(&mut jpeg, 10);
    for g in first.iter().chain(&more).chain(&joined) {
        assert_eq!(g.meta["codec"], "h264", "{}", g.meta);
        assert!(
            g.meta["latency_ms"].as_f64().is_some_and(|l| l > 0.0),
            "{}",
            g.meta
        );
    }
    // A is not read while B joins: whatever it skipped, it went on at a keyframe.
    let all: Vec<Got> = first.into_iter().chain(more).collect();
    gaps_end_at_keyframes(&all);
    for g in &jpegs {
        assert_eq!(g.meta["codec"], "jpeg", "{}", g.meta);
        assert_eq!(&g.data[..2], [0xff, 0xd8], "a JPEG");
    }
    eprintln!(
        "sizes: {:?}",
        all.iter().map(|g| g.data.len()).collect::<Vec<_>>()
    );
    let (n, errors) = decode(&all, dir.path(), "a.h264");
    assert_eq!(
        n,
        all.len(),
        "ffmpeg decoded {n} of {} frames: {errors}",
        all.len()
    );
    assert!(errors.trim().is_empty(), "{errors}");
    let (n, errors) = decode(&joined, dir.path(), "b.h264");
    assert_eq!(n, joined.len(), "{errors}");
    // An unknown codec is refused before the upgrade.
    let e = websocket(&server.addr, "/live?codec=vp9", t).err();
    assert_eq!(e.as_deref(), Some("HTTP 400"));
}

#[test]
fn a_stalled_h264_viewer_skips_to_a_keyframe_and_holds_nobody_back() {
    let _g = serial();
    let server = start();
    let dir = tempfile::tempdir().unwrap();
    let t = Duration::from_secs(20);
    let mut a = websocket(&server.addr, "/live?codec=h264", t).expect("viewer a");
    let mut stalled = websocket(&server.addr, "/live?codec=h264", t).expect("stalled viewer");
    read(&mut a, 10);
    let mut got = read(&mut stalled, 10);
    // A reads ~3 s of frames at the source's rate while the other reads nothing.
    let fps = 26.777;
    let start = Instant::now();
    read(&mut a, 80);
    let rate = 80.0 / start.elapsed().as_secs_f64();
    assert!(
        rate > 0.8 * fps,
        "viewer a got {rate:.1} frames/s beside a stalled one"
    );
    // The stalled viewer's stream goes on at a keyframe and still decodes whole.
    got.extend(read(&mut stalled, 60));
    let skipped = gaps_end_at_keyframes(&got);
    assert!(skipped > 0, "the stalled viewer skipped nothing");
    let (n, errors) = decode(&got, dir.path(), "stalled.h264");
    assert_eq!(n, got.len(), "{errors}");
}

/// Access unit numbers rise by one except where the viewer fell behind, and
/// each such gap ends at an IDR picture; the units skipped. (Frame numbers
/// may have gaps of their own: a frame the encoder left out while behind.)
fn gaps_end_at_keyframes(got: &[Got]) -> u64 {
    let frames: Vec<u64> = got
        .iter()
        .map(|g| g.meta["unit"].as_u64().unwrap())
        .collect();
    let mut skipped = 0;
    for (i, w) in frames.windows(2).enumerate() {
        if w[1] != w[0] + 1 {
            assert!(w[1] > w[0], "frames out of order: {frames:?}");
            assert!(
                nal_types(&got[i + 1].data).contains(&5),
                "unit {} after a gap is no IDR: {frames:?}",
                w[1]
            );
            skipped += w[1] - w[0] - 1;
        }
    }
    skipped
}

#[test]
fn h264_frames_keep_the_jpeg_frames_sharpness() {
    let _g = serial();
    let server = start();
    let dir = tempfile::tempdir().unwrap();
    let t = Duration::from_secs(20);
    // Both viewers read at once, each on its own thread.
    let read_from = |path: &'static str| {
        let mut ws = websocket(&server.addr, path, t).expect(path);
        std::thread::spawn(move || read(&mut ws, 90))
    };
    let h264 = read_from("/live?codec=h264");
    let jpeg = read_from("/live");
    let (h264, jpeg) = (h264.join().unwrap(), jpeg.join().unwrap());
    let (w, h) = (
        h264[0].meta["width"].as_u64().unwrap() as usize,
        h264[0].meta["height"].as_u64().unwrap() as usize,
    );
    let pair = |g: &[Got]| -> Vec<(Vec<u8>, u64)> {
        g.iter()
            .map(|g| (g.data.clone(), g.meta["frame"].as_u64().unwrap()))
            .collect()
    };
    let q = h264_against_jpeg(&pair(&h264), &pair(&jpeg), w, h, dir.path());
    assert!(q.frames >= 20, "only {} frames in both streams", q.frames);
    let (ratio, db) = (q.sharpness_ratio, q.psnr_db);
    eprintln!(
        "H.264 against JPEG over {} frames: sharpness {ratio:.3}, PSNR {db:.1} dB",
        q.frames
    );
    assert!(
        ratio >= 0.92,
        "H.264 frames keep {ratio:.3} of the JPEG frames' sharpness"
    );
    assert!(
        db >= 32.0,
        "H.264 frames are {db:.1} dB from the JPEG frames"
    );
}

#[test]
fn h264_from_a_publisher_on_ingest_reaches_viewers() {
    let _g = serial();
    // The drone's stream as a ground station relays it: H.264 access units,
    // Annex-B, each starting with its delimiter (x264's aud=1), one per message.
    let dir = tempfile::tempdir().unwrap();
    let stream = dir.path().join("drone.h264");
    let out = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-i"])
        .arg(data("cup/cup.mp4"))
        .args([
            "-t",
            "4",
            "-an",
            "-c:v",
            "libx264",
            "-preset",
            "ultrafast",
            "-bf",
            "0",
        ])
        .args(["-x264-params", "aud=1", "-f", "h264"])
        .arg(&stream)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = std::fs::read(&stream).unwrap();
    let starts: Vec<usize> = (0..bytes.len().saturating_sub(5))
        .filter(|&i| bytes[i..i + 5] == [0, 0, 0, 1, 9])
        .chain([bytes.len()])
        .collect();
    let units: Vec<Vec<u8>> = starts
        .windows(2)
        .map(|w| bytes[w[0]..w[1]].to_vec())
        .collect();
    assert!(units.len() > 90, "{} access units", units.len());

    let server = Server::start(&["--live-fov", "70"]);
    let t = Duration::from_secs(20);
    let mut viewer = websocket(&server.addr, "/live?codec=h264", t).expect("viewer");
    let mut publisher = websocket(&server.addr, "/live/ingest", t).expect("publisher");
    let sender = std::thread::spawn(move || {
        for u in units {
            if publisher.send(Message::Binary(u.into())).is_err() {
                break;
            }
            std::thread::sleep(Duration::from_millis(33));
        }
        let _ = publisher.close(None);
    });
    let got = read(&mut viewer, 40);
    sender.join().unwrap();
    let first = &got[0].meta;
    assert_eq!(
        (first["width"].as_u64(), first["height"].as_u64()),
        (Some(640), Some(480)),
        "{first}"
    );
    let (n, errors) = decode(&got, dir.path(), "viewer.h264");
    assert_eq!(n, got.len(), "{errors}");
}
