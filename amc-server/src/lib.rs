//! `amc_server`: everything behind the `amc` command line, as a library.
//!
//! Layers, each depending only on those before it:
//! `amc-core` (the algorithm) <- `amc-video` (video I/O) <- [`engine`] (one
//! run over a clip) <- [`gt`], [`plot`], [`synth`] <- [`eval`], [`demo`],
//! [`compare`], [`serve`] <- the `amc` binary (`src/bin/amc/`: clap, the
//! command line's error type, progress bars, exit codes). See
//! `docs/ARCHITECTURE.md`.

pub mod cluster;
pub mod compare;
pub mod demo;
pub mod engine;
pub mod eval;
pub mod gt;
pub mod plot;
pub mod serve;
pub mod synth;
pub mod worker;
