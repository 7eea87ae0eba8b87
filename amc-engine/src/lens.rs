//! Turning a [`LensSpec`] (`--lens FILE`, `--fov DEG`, `--fov auto`) into a
//! camera: the lens file is read here, the rest is the core's pass plan
//! ([`amc_core::plan`]).

use super::passes;
use super::RunError;
use amc_core::plan::{LensChoice, PlanChoices};
use amc_core::{CameraModel, LensSpec, ReadoutSpec, StabilizerParams};
use amc_video::InputOptions;
use std::path::{Path, PathBuf};
use std::time::Duration;

pub use amc_core::plan::{LensNote, ResolvedLens, AUTO_FOV_FRAMES, FALLBACK_FOV_DEG};

/// The lens file an image folder carries, `DIR/lens.json` (as `amc synth`
/// writes beside its frames, `meta.json` and `gt.csv`), if `input` is such a
/// folder. The command line uses it where neither `--lens` nor `--fov` is
/// given, as it takes the folder's frame rate from its `meta.json`.
pub fn folder_lens_file(input: &Path) -> Option<PathBuf> {
    let path = input.join("lens.json");
    (input.is_dir() && path.is_file()).then_some(path)
}

/// The plan's choice for `spec`: a lens file read and parsed, a field of
/// view, or `auto`.
pub(crate) fn lens_choice(spec: &LensSpec) -> Result<LensChoice, RunError> {
    Ok(match spec {
        LensSpec::File(p) => {
            let text = std::fs::read_to_string(p).map_err(|source| RunError::LensRead {
                path: p.clone(),
                source,
            })?;
            let file =
                amc_core::lens::parse_lens_file(&text).map_err(|source| RunError::LensParse {
                    path: p.clone(),
                    source,
                })?;
            LensChoice::Known(file.into())
        }
        LensSpec::Fov(deg) => LensChoice::Fov(*deg),
        LensSpec::Auto => LensChoice::Auto,
    })
}

/// Resolves `spec` to a camera for frames of `input`; `size` is the frame size
/// when the caller already knows it (saves opening the input for a `fov`).
/// `auto` reads the first [`AUTO_FOV_FRAMES`] frames.
pub fn resolve_lens(
    spec: &LensSpec,
    input: &Path,
    params: &StabilizerParams,
    opts: &InputOptions,
    size: Option<(usize, usize)>,
) -> Result<ResolvedLens, RunError> {
    // A plan of the lens alone: a readout from the lens makes no pass.
    let choices = PlanChoices {
        lens: lens_choice(spec)?,
        readout: ReadoutSpec::FromLens,
        params: params.clone(),
        static_zoom: false,
        frame_size: size,
    };
    Ok(passes::estimate(choices, input, opts)?.lens)
}

/// The lens `--fov auto` finds in `input` once its readout is known
/// (`readout_ms`, measured against a gyro log after a first estimate fell
/// back): the estimate's camera and field of view, or `None` where the
/// footage still does not pin it down. `size` is the frame size.
pub(crate) fn refit_with_readout(
    input: &Path,
    params: &StabilizerParams,
    opts: &InputOptions,
    size: (usize, usize),
    readout_ms: f64,
) -> Result<Option<(CameraModel, f64)>, RunError> {
    let choices = PlanChoices {
        lens: LensChoice::Auto,
        readout: ReadoutSpec::Ms(readout_ms),
        params: params.clone(),
        static_zoom: false,
        frame_size: Some(size),
    };
    let lens = passes::estimate(choices, input, opts)?.lens;
    Ok(match lens.note {
        LensNote::Estimated { hfov_deg, .. } => Some((lens.camera, hfov_deg)),
        _ => None,
    })
}

/// What the user is told of a lens [`refit_with_readout`] found.
pub fn refit_line(hfov_deg: f64) -> String {
    format!(
        "estimated horizontal field of view: {hfov_deg:.1} deg (again, with the readout \
         measured against the gyro log; pass --fov or --lens to set it)"
    )
}

/// Options to open an input with: `fps` overrides its timestamps (image folders
/// default to 30 fps), `timeout` bounds each ffmpeg stall.
pub fn input_options(fps: Option<f64>, timeout: Duration) -> InputOptions {
    InputOptions {
        fps_override: fps,
        timeout,
        ..InputOptions::default()
    }
}
