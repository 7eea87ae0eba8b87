//! An RTSP server on loopback, as a ground station's relay (MediaMTX and the like) offers
//! a drone's feed: Debian's `rtsp-server-perl` (RTSP::Server). A publisher ANNOUNCEs and
//! RECORDs a stream on the source port; clients DESCRIBE and PLAY it on the client port,
//! over RTP/UDP. Stopped when dropped.
//!
//! Not installed: skipped (None), or a panic with `AMC_REQUIRE_SERVICES=1` (CI).

use crate::services::{not_installed, PortLease};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BINARY: &str = "/usr/bin/rtsp-server-perl";

pub struct RtspServer {
    child: Child,
    /// Where clients read: rtsp://127.0.0.1:{client_port}/NAME.
    pub client_port: u16,
    /// Where a publisher records: rtsp://127.0.0.1:{source_port}/NAME.
    pub source_port: u16,
    _ports: PortLease,
}

impl RtspServer {
    pub fn start() -> Option<RtspServer> {
        if !std::path::Path::new(BINARY).is_file() {
            return not_installed(
                "rtsp-server-perl",
                "the RTSP source test needs an RTSP server",
                "apt-get install rtsp-server-perl",
            );
        }
        // Two TCP ports, and a base for the RTP/RTCP UDP pairs it hands to clients.
        let ports = PortLease::reserve(3, false);
        let (client_port, source_port, rtp_port) = (ports.ports[0], ports.ports[1], ports.ports[2]);
        let child = Command::new(BINARY)
            .args(["--clientport", &client_port.to_string()])
            .args(["--serverport", &source_port.to_string()])
            .args(["--client_listen_address", "127.0.0.1"])
            .args(["--source_listen_address", "127.0.0.1"])
            .args(["--rtp_start_port", &rtp_port.to_string()])
            .args(["--loglevel", "1"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("rtsp-server-perl");
        let server = RtspServer {
            child,
            client_port,
            source_port,
            _ports: ports,
        };
        let start = Instant::now();
        while [client_port, source_port]
            .iter()
            .any(|p| TcpStream::connect(("127.0.0.1", *p)).is_err())
        {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "rtsp-server-perl did not listen on {client_port} and {source_port} within 20 s"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        Some(server)
    }
}

impl Drop for RtspServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
