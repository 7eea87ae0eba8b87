//! The live feed: frames from `--live-source` (anything ffmpeg opens) or
//! from a publisher on `/live/ingest` are stabilized by one processor
//! thread ([`hub`]) and fanned out to `/live` viewers ([`viewer`]).
//!
//! | module | what |
//! |---|---|
//! | `hub` | the source and processor threads, the newest frame, viewers and publisher slots, pausing |
//! | `h264` | the H.264 stream: one shared encoder, access units fanned out |
//! | `jpeg` | JPEG encoding of stabilized frames, decoding of published ones |
//! | `viewer` | `GET /live`: a viewer's WebSocket |
//! | `ingest_h264` | the publisher's H.264, decoded by an ffmpeg child |
//! | `ingest` | `GET /live/ingest`: the publisher's WebSocket |
//! | `telemetry` | the text message after each frame |
//! | `ticket` | `POST /live/ticket`: a browser's single-use ticket for either socket |

mod h264;
mod hub;
mod ingest;
mod ingest_h264;
mod jpeg;
mod telemetry;
mod ticket;
mod viewer;

pub use hub::{LiveConfig, LiveHub};
pub use ingest::ingest;
pub use jpeg::decode_ingest_frame;
pub use ticket::ticket;
pub use viewer::viewer;
