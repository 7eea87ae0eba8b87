//! `amc_eval`: measuring the stabilizer. Ground-truth files ([`gt`]), plots
//! ([`plot`]), synthetic clips with known motion ([`synth`]), a clip's metrics
//! report ([`eval`]), the quick-start [`demo`], and [`compare`] against peers
//! (vid.stab, deshake, the paper's code). Every run goes through `amc-engine`.
//!
//! Layers: [`gt`], [`plot`], [`synth`] <- [`eval`], [`demo`], [`compare`].
//! See `docs/ARCHITECTURE.md`.

pub mod compare;
pub mod demo;
pub mod eval;
pub mod gt;
pub mod plot;
pub mod synth;
pub mod synth_gyro;
