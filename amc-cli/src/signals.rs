//! Ctrl-C, SIGTERM (`timeout`, service managers) and SIGHUP (a closed
//! terminal): stop the run, leave nothing behind, exit 128 + the signal.
//!
//! The run is cancelled first, so it unwinds normally (its sources and sinks
//! kill their ffmpeg children and remove their partial files as they drop).
//! If it has not finished within [`GRACE`] (blocked in a probe, say), every
//! child still running is killed and every partial output removed by
//! [`amc_video::cleanup::interrupt`], and the process exits.

use amc_engine::RunControl;
use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// How long a cancelled run may take to unwind before the process exits anyway.
const GRACE: Duration = Duration::from_secs(2);

/// The signal that interrupted the run (0: none).
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// Watches for the signals on a thread of its own.
pub fn on_interrupt(control: Arc<RunControl>) {
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else {
        return;
    };
    std::thread::spawn(move || {
        if let Some(sig) = signals.forever().next() {
            SIGNAL.store(sig, Ordering::SeqCst);
            control.cancel();
            std::thread::sleep(GRACE);
            amc_video::cleanup::interrupt();
            std::process::exit(exit_code().into());
        }
    });
}

/// 128 + the interrupting signal, as shells report it (130 for Ctrl-C, 143 for SIGTERM).
pub fn exit_code() -> u8 {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => 1,
        sig => (128 + sig).clamp(0, 255) as u8,
    }
}
