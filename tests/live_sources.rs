//! The sources a ground station really offers, from a real ffmpeg publishing
//! on loopback into `amc serve --live-source`: MPEG-TS over UDP and over SRT
//! (SRT's listener on amc's side, the publisher calling it), and RTSP through
//! a relay (the publisher records into an RTSP server, amc plays from it).
//! Each reaches a viewer as stabilized frames, as H.264 and as JPEG.

use amc_e2e::data;
use amc_e2e::rtsp::RtspServer;
use amc_e2e::server::{websocket, Server};
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tungstenite::Message;

static SERIAL: Mutex<()> = Mutex::new(());

/// An ffmpeg publishing cup.mp4 in a loop as H.264 in `format` (a muxer) to
/// `url`, started again while it exits early (an SRT caller before its
/// listener).
struct Publisher {
    url: String,
    format: &'static str,
    child: Child,
}

impl Publisher {
    fn spawn(url: &str, format: &str) -> Child {
        let cup = data("cup/cup.mp4");
        Command::new("ffmpeg")
            .args(["-v", "error", "-re", "-stream_loop", "-1", "-i"])
            .arg(&cup)
            .args([
                "-an",
                "-c:v",
                "libx264",
                "-preset",
                "ultrafast",
                "-tune",
                "zerolatency",
            ])
            .args(["-g", "15", "-f", format, url])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("ffmpeg")
    }

    fn start(url: &str, format: &'static str) -> Publisher {
        Publisher {
            url: url.to_string(),
            format,
            child: Self::spawn(url, format),
        }
    }

    /// Restarts the publisher if it has exited.
    fn keep_alive(&mut self) {
        if let Ok(Some(_)) = self.child.try_wait() {
            self.child = Self::spawn(&self.url, self.format);
        }
    }
}

impl Drop for Publisher {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A viewer of `path` gets `n` frames (binary then telemetry) within 60 s,
/// the publisher kept alive meanwhile; the telemetry of the last.
fn frames_reach(
    server: &Server,
    publisher: &mut Publisher,
    path: &str,
    n: usize,
) -> serde_json::Value {
    let start = Instant::now();
    let mut ws = loop {
        publisher.keep_alive();
        match websocket(&server.addr, path, Duration::from_secs(2)) {
            Ok(ws) => break ws,
            Err(e) => {
                assert!(start.elapsed() < Duration::from_secs(60), "{path}: {e}");
                std::thread::sleep(Duration::from_millis(200));
            }
        }
    };
    let (mut got, mut binary) = (0, false);
    let mut last = serde_json::Value::Null;
    while got < n {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "{path}: {got} of {n} frames in 60 s; server log:\n{}",
            server.log()
        );
        publisher.keep_alive();
        match ws.read() {
            Ok(Message::Binary(_)) => binary = true,
            Ok(Message::Text(t)) if binary => {
                last = serde_json::from_str(&t).unwrap();
                got += 1;
                binary = false;
            }
            Ok(_) => {}
            // The read timeout while the source opens: keep waiting.
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("{path}: {e}"),
        }
    }
    last
}

/// `source` read by amc (with `--live-format` when given) while ffmpeg
/// publishes to `publish_to` as `muxer`.
fn check(source: &str, format: Option<&str>, publish_to: &str, muxer: &'static str) {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let mut args = vec!["--live-source", source, "--live-fov", "70"];
    if let Some(format) = format {
        args.extend(["--live-format", format]);
    }
    let server = Server::start(&args);
    let mut publisher = Publisher::start(publish_to, muxer);
    let meta = frames_reach(&server, &mut publisher, "/live?codec=h264", 40);
    assert_eq!(meta["codec"], "h264", "{meta}");
    assert_eq!(
        (meta["width"].as_u64(), meta["height"].as_u64()),
        (Some(640), Some(480)),
        "{meta}"
    );
    let meta = frames_reach(&server, &mut publisher, "/live", 20);
    assert_eq!(meta["codec"], "jpeg", "{meta}");
}

/// Waits up to 5 s for no process whose command line matches `pattern` (an
/// extended regular expression, `pgrep -f`); panics naming those left.
fn none_left(pattern: &str) {
    let start = Instant::now();
    loop {
        let out = Command::new("pgrep")
            .args(["-af", "--", pattern])
            .output()
            .unwrap();
        let left = String::from_utf8_lossy(&out.stdout).into_owned();
        if left.trim().is_empty() {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "processes left behind after amc serve stopped:\n{left}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn mpeg_ts_over_udp_reaches_viewers() {
    let port = free_udp_port();
    let source = format!("udp://127.0.0.1:{port}?fifo_size=1000000&overrun_nonfatal=1");
    check(
        &source,
        Some("mpegts"),
        &format!("udp://127.0.0.1:{port}?pkt_size=1316"),
        "mpegts",
    );
    // The server stopped while its source's ffmpeg waited on a quiet socket
    // (the publisher gone too): that ffmpeg did not outlive it.
    none_left(&format!("-i udp://127[.]0[.]0[.]1:{port}[?]fifo"));
}

#[test]
fn mpeg_ts_over_srt_reaches_viewers() {
    // Debian's ffmpeg has libsrt; a build without it cannot be asked for SRT.
    let protocols = Command::new("ffmpeg")
        .args(["-hide_banner", "-protocols"])
        .output()
        .unwrap();
    if !String::from_utf8_lossy(&protocols.stdout)
        .lines()
        .any(|l| l.trim() == "srt")
    {
        eprintln!("note: this ffmpeg has no SRT; skipped");
        return;
    }
    let port = free_udp_port();
    check(
        &format!("srt://127.0.0.1:{port}?mode=listener"),
        Some("mpegts"),
        &format!("srt://127.0.0.1:{port}?mode=caller"),
        "mpegts",
    );
}

#[test]
fn rtsp_through_a_relay_reaches_viewers() {
    let Some(relay) = RtspServer::start() else {
        return;
    };
    // The URL alone tells ffmpeg it is RTSP (no --live-format), as a user
    // would pass a camera's or a relay's address.
    check(
        &format!("rtsp://127.0.0.1:{}/drone", relay.client_port),
        None,
        &format!("rtsp://127.0.0.1:{}/drone", relay.source_port),
        "rtsp",
    );
}
