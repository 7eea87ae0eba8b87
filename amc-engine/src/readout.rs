//! Turning a [`ReadoutSpec`] (`--readout-ms MS`, `--readout-ms auto`, the
//! lens file's readout) into the rolling-shutter readout time of a run, once
//! the lens is known ([`resolve_readout`]); [`resolve`] does both. The passes
//! are the core's pass plan ([`amc_core::plan`]).

use super::lens::{lens_choice, ResolvedLens};
use super::passes;
use super::RunError;
use amc_core::plan::{LensChoice, PlanChoices};
use amc_core::{ReadoutSpec, StabilizerOptions, StabilizerParams};
use amc_video::InputOptions;
use std::path::Path;

pub use amc_core::plan::{ReadoutNote, Resolved, ResolvedReadout};

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
    let choices = PlanChoices {
        lens: LensChoice::Known(lens.clone()),
        readout: spec.clone(),
        params: params.clone(),
        static_zoom: false,
        frame_size: None,
    };
    Ok(passes::estimate(choices, input, opts)?.readout)
}

/// Resolves the lens ([`resolve_lens`](super::resolve_lens)), then the
/// readout ([`resolve_readout`]), each pass reading `input` once. `zoom =
/// static`'s pass is left to [`run`](super::run), which reads the frames in
/// its own pixel format (so [`Resolved::static_zoom`] is `None`).
pub fn resolve(
    options: &StabilizerOptions,
    input: &Path,
    opts: &InputOptions,
    size: Option<(usize, usize)>,
) -> Result<Resolved, RunError> {
    resolve_choice(lens_choice(&options.lens)?, options, input, opts, size)
}

/// [`resolve`] with a lens known already (a profile `--lens-db` picked)
/// in place of `options.lens`; the readout as `options` says.
pub fn resolve_known(
    options: &StabilizerOptions,
    lens: ResolvedLens,
    input: &Path,
    opts: &InputOptions,
) -> Result<Resolved, RunError> {
    let size = (lens.camera.width, lens.camera.height);
    resolve_choice(LensChoice::Known(lens), options, input, opts, Some(size))
}

fn resolve_choice(
    lens: LensChoice,
    options: &StabilizerOptions,
    input: &Path,
    opts: &InputOptions,
    size: Option<(usize, usize)>,
) -> Result<Resolved, RunError> {
    let choices = PlanChoices {
        lens,
        readout: options.readout.clone(),
        params: options.params.clone(),
        static_zoom: false,
        frame_size: size,
    };
    passes::estimate(choices, input, opts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LensNote;
    use amc_core::readout::ReadoutEstimate;
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
