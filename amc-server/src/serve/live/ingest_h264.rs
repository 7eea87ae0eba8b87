//! H.264 from the publisher on `/live/ingest` (a ground station relaying the
//! drone's stream): each binary message that starts with a start code is one
//! access unit (Annex-B). They go to one decoder ([`amc_video::H264Decoder`],
//! ffmpeg as a child) through a writer thread, so the socket never waits for
//! it; its frames go on to the processor like a `--live-source`'s.

use amc_core::Frame;
use amc_video::H264Decoder;
use bytes::Bytes;
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::time::Duration;

/// Access units that may wait for the decoder; more are dropped (the picture
/// then breaks up until the next keyframe, rather than falling behind).
const WAITING_UNITS: usize = 8;

/// The publisher's decoder, while it sends H.264.
pub(super) struct IngestDecoder {
    to_writer: SyncSender<Bytes>,
}

impl IngestDecoder {
    /// Starts ffmpeg; each decoded frame goes to `on_frame`, which hands a
    /// buffer back.
    pub fn start(
        timeout: Duration,
        on_frame: impl FnMut(Frame) -> Frame + Send + 'static,
    ) -> Result<Self, amc_video::VideoError> {
        let mut decoder = H264Decoder::start(timeout, on_frame)?;
        let (to_writer, units) = mpsc::sync_channel::<Bytes>(WAITING_UNITS);
        std::thread::Builder::new()
            .name("amc-live-ingest-h264".into())
            .spawn(move || {
                for unit in units {
                    if let Err(e) = decoder.write(&unit) {
                        tracing::warn!(error = %e, "the publisher's H.264 cannot be decoded");
                        return;
                    }
                }
                // The publisher left: dropping the decoder stops ffmpeg.
            })
            .map_err(|e| {
                amc_video::VideoError::io(
                    std::path::Path::new("live H.264 input"),
                    "start its writer thread",
                    e,
                )
            })?;
        Ok(Self { to_writer })
    }

    /// Queues one access unit; `false` once the decoder has stopped.
    pub fn push(&self, unit: Bytes) -> bool {
        match self.to_writer.try_send(unit) {
            Ok(()) | Err(TrySendError::Full(_)) => true,
            Err(TrySendError::Disconnected(_)) => false,
        }
    }
}
