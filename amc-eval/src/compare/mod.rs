//! `amc compare`: our modes against the stabilizers people use today
//! (ffmpeg's vid.stab and deshake) on the same clips in the same run, for
//! speed and quality, written as one Markdown report with plots.
//!
//! * [`peers`]: the methods and how each runs as a timed child process;
//! * [`paper`]: the paper's own implementation as a peer (`--peer paper`);
//! * [`measure`]: per-frame measurement of an output against the input;
//! * [`homography`]: the direct homography fit the Liu et al. metrics need;
//! * [`liu`]: cropping, distortion, stability, ITF;
//! * [`synthetic`]: the flapping-wing test sequences;
//! * [`report`]: tables, bars, plots and the frame strip.
//!
//! Per clip: the input is decoded once (luma pyramids kept for the fits);
//! every method runs as a child process writing raw `.y4m` (timed); ours are
//! then re-run in-process (deterministic, same output) to measure them with
//! the renderer's exact coverage mask, peers are measured from their `.y4m`
//! with the validity mask of [`peers`].

mod config;
mod error;
pub mod homography;
pub mod liu;
pub mod measure;
pub mod paper;
pub mod peers;
pub mod report;
mod results;
mod run;
pub mod synthetic;

pub use config::{CompareConfig, MAX_LOOKAHEAD};
pub use error::CompareError;
pub use results::{Clip, ClipResult, MethodResult};
pub use run::run;
