//! The run engine: one stabilization run over a whole input (decode ->
//! track -> view -> render -> encode), with telemetry, metrics and progress.
//!
//! Config in, [`RunSummary`] or a typed [`RunError`] out. It decides nothing
//! about presentation: progress goes to a callback, notes about the lens come
//! back as values, so the command line, `eval`, `demo`, `compare` and the
//! service all drive the same engine.

pub mod clip_camera;
mod control;
mod error;
mod fusion;
pub mod gcsv;
pub mod gyro;
mod lens;
pub mod lens_db;
mod log_readout;
mod measure;
mod passes;
mod paths;
mod readout;
mod run;
mod stages;
mod telemetry;

pub use control::RunControl;
pub use error::RunError;
pub use lens::{
    folder_lens_file, input_options, refit_line, resolve_lens, LensNote, ResolvedLens,
    AUTO_FOV_FRAMES, FALLBACK_FOV_DEG,
};
pub use log_readout::{LogReadout, MeasureReadout};
pub use paths::check_distinct;
pub use readout::{
    resolve, resolve_known, resolve_readout, ReadoutNote, Resolved, ResolvedReadout,
};
pub use run::{render_pool, run, FrameRecord, Progress, RunConfig, RunSummary, TRUNCATED_SHARE};
pub use telemetry::TELEMETRY_HEADER;

/// The default for [`RunConfig::threads`]: every core the process may use.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
