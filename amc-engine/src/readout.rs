//! Turning a [`ReadoutSpec`] (`--readout-ms MS`, `--readout-ms auto`, the
//! lens file's readout) into the rolling-shutter readout time of a run, once
//! the lens is known ([`resolve_readout`]); [`resolve`] does both.

use super::lens::{resolve_lens, LensNote, ResolvedLens};
use super::RunError;
use amc_core::readout::{ReadoutEstimate, ReadoutEstimator};
use amc_core::{AmcError, Frame, PixelFormat, ReadoutSpec, StabilizerOptions, StabilizerParams};
use amc_video::{self as video, InputOptions};
use std::path::Path;

/// Where a readout time came from, for the caller to tell the user.
#[derive(Clone, Debug, PartialEq)]
pub enum ReadoutNote {
    /// Given by the option, or 0 by default (nothing to say).
    Given,
    /// Stated by the lens file (`readout_ms`, Gyroflow's `frame_readout_time`).
    FromLens,
    /// `auto` estimated it and trusts the estimate.
    Estimated(ReadoutEstimate),
    /// `auto` could not pin it down (too little motion, a fit that explains
    /// too little, too short a clip): a global shutter is assumed.
    FellBack {
        /// The estimate that was not trusted (`None`: too few frames to fit).
        estimate: Option<ReadoutEstimate>,
    },
}

impl ReadoutNote {
    /// The line to show the user, if any (`warning: ...` for a fallback).
    pub fn message(&self, readout_ms: f64) -> Option<String> {
        match self {
            ReadoutNote::Given => None,
            ReadoutNote::FromLens => Some(format!("readout: {readout_ms} ms (from the lens file)")),
            ReadoutNote::Estimated(e) => Some(format!(
                "readout: {:.1} ms (estimated from {} frames; pass --readout-ms to set it)",
                e.readout_ms, e.frames
            )),
            ReadoutNote::FellBack { estimate } => {
                let why = match estimate {
                    Some(e) => format!(
                        "the estimate of {:.1} ms from {} frames is not reliable: {:.3} deg of motion \
                         across a readout, the fit explains {:.0}% of the motion within frames",
                        e.readout_ms,
                        e.frames,
                        e.motion_deg,
                        100.0 * e.explained
                    ),
                    None => "the clip is too short to estimate it".into(),
                };
                Some(format!(
                    "warning: the footage does not pin down the rolling-shutter readout ({why}); \
                     assuming a global shutter (0 ms): set readout_ms (--readout-ms MS) for best results"
                ))
            }
        }
    }

    /// Whether this note is a warning (`auto` fell back to 0).
    pub fn is_warning(&self) -> bool {
        matches!(self, ReadoutNote::FellBack { .. })
    }
}

/// A run's readout time and where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedReadout {
    /// Milliseconds, `0..=100` (0 = global shutter).
    pub readout_ms: f64,
    /// Where it came from.
    pub note: ReadoutNote,
}

impl ResolvedReadout {
    /// The line to show the user, if any.
    pub fn message(&self) -> Option<String> {
        self.note.message(self.readout_ms)
    }
}

/// Resolves `spec` against the lens (`lens.readout_ms`, the file's readout):
/// the option's readout, else the lens file's, else 0; `auto` tracks up to
/// [`READOUT_FRAMES`](amc_core::readout::READOUT_FRAMES) frames of `input` through `lens.camera` and uses the
/// estimate when it is confident, else 0 ([`ReadoutNote::FellBack`]).
pub fn resolve_readout(
    spec: &ReadoutSpec,
    lens: &ResolvedLens,
    input: &Path,
    params: &StabilizerParams,
    opts: &InputOptions,
) -> Result<ResolvedReadout, RunError> {
    if let Some(readout_ms) = spec.given(lens.readout_ms) {
        let from_lens = *spec == ReadoutSpec::FromLens && lens.readout_ms.is_some();
        return Ok(ResolvedReadout {
            readout_ms,
            note: if from_lens {
                ReadoutNote::FromLens
            } else {
                ReadoutNote::Given
            },
        });
    }
    let mut src = video::open_input(input, opts)?;
    let mut buf = Frame::new(0, 0, PixelFormat::Rgb8);
    let mut estimator: Option<ReadoutEstimator> = None;
    while !estimator.as_ref().is_some_and(ReadoutEstimator::is_full) {
        let Some(t) = src.next_frame(&mut buf)? else {
            break;
        };
        let est = match &mut estimator {
            Some(e) => e,
            None => estimator.insert(ReadoutEstimator::new(
                &lens.camera,
                buf.width,
                buf.height,
                params,
            )?),
        };
        est.push(buf.as_ref(), t)?;
    }
    let Some(estimator) = estimator else {
        return Err(RunError::NoFrames {
            path: input.to_path_buf(),
        });
    };
    let fell_back = |estimate| ResolvedReadout {
        readout_ms: 0.0,
        note: ReadoutNote::FellBack { estimate },
    };
    match estimator.finish() {
        Ok(e) if e.confident => Ok(ResolvedReadout {
            readout_ms: e.readout_ms,
            note: ReadoutNote::Estimated(e),
        }),
        Ok(e) => Ok(fell_back(Some(e))),
        Err(AmcError::TooFewFrames { .. }) => Ok(fell_back(None)),
        Err(e) => Err(e.into()),
    }
}

/// The lens, the readout and the parameters of a run, from the user's options.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// The camera, and how it was found.
    pub lens: ResolvedLens,
    /// The readout, and where it came from.
    pub readout: ResolvedReadout,
    /// The options' parameters with the readout set (`shutter.readout_ms`).
    pub params: StabilizerParams,
}

impl Resolved {
    /// How the lens was found.
    pub fn lens_note(&self) -> &LensNote {
        &self.lens.note
    }
}

/// Resolves the lens ([`resolve_lens`]), then the readout ([`resolve_readout`]).
pub fn resolve(
    options: &StabilizerOptions,
    input: &Path,
    opts: &InputOptions,
    size: Option<(usize, usize)>,
) -> Result<Resolved, RunError> {
    let lens = resolve_lens(&options.lens, input, &options.params, opts, size)?;
    let readout = resolve_readout(&options.readout, &lens, input, &options.params, opts)?;
    let mut params = options.params.clone();
    params.shutter.readout_ms = readout.readout_ms;
    Ok(Resolved {
        lens,
        readout,
        params,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use amc_core::CameraModel;

    fn lens(readout_ms: Option<f64>) -> ResolvedLens {
        ResolvedLens {
            camera: CameraModel::pinhole_hfov(64, 48, 70.0).unwrap(),
            note: LensNote::Given,
            readout_ms,
        }
    }

    /// The option beats the lens file, which beats 0; neither opens the input.
    #[test]
    fn given_readouts_need_no_input() {
        let params = StabilizerParams::default();
        let none = Path::new("/nonexistent/clip.mp4");
        let opts = InputOptions::default();
        let r = |spec: ReadoutSpec, file: Option<f64>| {
            resolve_readout(&spec, &lens(file), none, &params, &opts).unwrap()
        };
        assert_eq!(r(ReadoutSpec::Ms(7.5), Some(20.0)).readout_ms, 7.5);
        assert_eq!(r(ReadoutSpec::Ms(7.5), Some(20.0)).note, ReadoutNote::Given);
        let from_file = r(ReadoutSpec::FromLens, Some(20.0));
        assert_eq!(from_file.readout_ms, 20.0);
        assert_eq!(from_file.note, ReadoutNote::FromLens);
        assert!(from_file.message().unwrap().contains("20 ms"));
        let default = r(ReadoutSpec::FromLens, None);
        assert_eq!((default.readout_ms, default.message()), (0.0, None));
        // auto opens the input: a missing one is an error, not a panic.
        assert!(resolve_readout(&ReadoutSpec::Auto, &lens(None), none, &params, &opts).is_err());
    }

    #[test]
    fn a_fallback_is_a_warning_that_names_the_option() {
        let note = ReadoutNote::FellBack { estimate: None };
        assert!(note.is_warning());
        let msg = note.message(0.0).unwrap();
        assert!(
            msg.starts_with("warning:") && msg.contains("--readout-ms"),
            "{msg}"
        );
        let est = ReadoutEstimate {
            readout_ms: 14.8,
            confident: true,
            explained: 0.9,
            motion_deg: 0.2,
            frames: 180,
        };
        let msg = ReadoutNote::Estimated(est).message(14.8).unwrap();
        assert!(
            msg.contains("readout: 14.8 ms (estimated from 180 frames"),
            "{msg}"
        );
    }
}
