//! What this machine's ffmpeg supports: options that differ between ffmpeg
//! versions, asked once per process (`ffmpeg -h`), as early as possible.

use crate::process::run_capture;
use std::ffi::OsString;
use std::path::Path;
use std::sync::OnceLock;
use std::time::Duration;

/// Options that differ between ffmpeg versions, detected once.
pub(crate) struct Caps {
    /// `-fps_mode` (ffmpeg >= 5.1); older ones only know `-vsync`.
    pub fps_mode: bool,
    /// `showinfo=checksum=0` (ffmpeg >= 5.0) skips hashing every frame.
    pub showinfo_checksum: bool,
}

/// What this machine's ffmpeg supports, once known.
static CAPS: OnceLock<Caps> = OnceLock::new();

pub(crate) fn caps() -> &'static Caps {
    CAPS.get_or_init(|| {
        let help = |topic: &str| -> String {
            let args: Vec<OsString> = ["-hide_banner", "-h", topic]
                .iter()
                .map(OsString::from)
                .collect();
            run_capture(
                "ffmpeg",
                &args,
                Path::new("ffmpeg"),
                Duration::from_secs(20),
            )
            .map(|(_, out, _)| String::from_utf8_lossy(&out).into_owned())
            .unwrap_or_default()
        };
        // Both at once: each ffmpeg takes ~0.2 s just to start.
        let (long, showinfo) = std::thread::scope(|s| {
            let showinfo = s.spawn(|| help("filter=showinfo"));
            (help("long"), showinfo.join().unwrap_or_default())
        });
        Caps {
            fps_mode: long.contains("-fps_mode"),
            showinfo_checksum: showinfo.contains("checksum"),
        }
    })
}

/// Starts asking ffmpeg for its capabilities on a thread, the first time: a
/// video that is probed is about to be decoded, and asking takes ~0.1 s that
/// can overlap ffprobe's instead of following it.
pub(crate) fn prefetch_caps() {
    if CAPS.get().is_none() {
        std::thread::spawn(|| {
            caps();
        });
    }
}
