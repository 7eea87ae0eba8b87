//! Turning a [`LensSpec`] (`--lens FILE`, `--fov DEG`, `--fov auto`) into a camera.

use super::RunError;
use amc_core::{selfcal, CameraModel, Frame, LensSpec, PixelFormat, StabilizerParams};
use amc_video::{self as video, InputOptions};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Horizontal field of view assumed when `--fov auto` cannot pin the focal
/// length down: a typical phone / action-camera main lens.
pub const FALLBACK_FOV_DEG: f64 = 70.0;

/// Frames read for `--fov auto` (about 3 s at 30 fps).
pub const AUTO_FOV_FRAMES: usize = 90;

/// Where a camera came from, for the caller to tell the user.
#[derive(Clone, Debug, PartialEq)]
pub enum LensNote {
    /// A lens file or a field of view was given.
    Given,
    /// `auto` estimated this horizontal field of view (degrees) from `frames` frames.
    Estimated {
        /// The estimate, degrees.
        hfov_deg: f64,
        /// Frames it was estimated from.
        frames: usize,
    },
    /// `auto` could not pin the focal length down (translation, little
    /// rotation) and fell back to [`FALLBACK_FOV_DEG`].
    FellBack,
}

/// The lens file an image folder carries, `DIR/lens.json` (as `amc synth`
/// writes beside its frames, `meta.json` and `gt.csv`), if `input` is such a
/// folder. The command line uses it where neither `--lens` nor `--fov` is
/// given, as it takes the folder's frame rate from its `meta.json`.
pub fn folder_lens_file(input: &Path) -> Option<PathBuf> {
    let path = input.join("lens.json");
    (input.is_dir() && path.is_file()).then_some(path)
}

/// A camera for the input's frames, and how it was found.
#[derive(Clone, Debug)]
pub struct ResolvedLens {
    /// The camera model.
    pub camera: CameraModel,
    /// How it was found.
    pub note: LensNote,
    /// The rolling-shutter readout the lens file states, milliseconds (none
    /// without a file, or when the file does not say).
    pub readout_ms: Option<f64>,
}

/// Resolves `spec` to a camera for frames of `input`; `size` is the frame size
/// when the caller already knows it (saves opening the input for a `fov`).
pub fn resolve_lens(
    spec: &LensSpec,
    input: &Path,
    params: &StabilizerParams,
    opts: &InputOptions,
    size: Option<(usize, usize)>,
) -> Result<ResolvedLens, RunError> {
    let given = |camera| {
        Ok(ResolvedLens {
            camera,
            note: LensNote::Given,
            readout_ms: None,
        })
    };
    match spec {
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
            Ok(ResolvedLens {
                camera: file.camera,
                note: LensNote::Given,
                readout_ms: file.readout_ms,
            })
        }
        LensSpec::Fov(deg) => {
            let (w, h) = match size {
                Some(s) => s,
                None => video::frame_size(input, opts)?,
            };
            given(CameraModel::pinhole_hfov(w, h, *deg).map_err(amc_core::AmcError::from)?)
        }
        LensSpec::Auto => {
            let mut src = video::open_input(input, opts)?;
            let mut frames = Vec::new();
            let mut buf = Frame::new(0, 0, PixelFormat::Rgb8);
            while frames.len() < AUTO_FOV_FRAMES {
                match src.next_frame(&mut buf)? {
                    Some(t) => frames.push((buf.clone(), t)),
                    None => break,
                }
            }
            if frames.is_empty() {
                return Err(RunError::NoFrames {
                    path: input.to_path_buf(),
                });
            }
            let refs: Vec<_> = frames.iter().map(|(f, t)| (f.as_ref(), *t)).collect();
            let est = selfcal::estimate_hfov(&refs, params.track_width, &params.tracker)?;
            if !est.confident {
                let (w, h) = (frames[0].0.width, frames[0].0.height);
                return Ok(ResolvedLens {
                    camera: CameraModel::pinhole_hfov(w, h, FALLBACK_FOV_DEG)
                        .map_err(amc_core::AmcError::from)?,
                    note: LensNote::FellBack,
                    readout_ms: None,
                });
            }
            Ok(ResolvedLens {
                camera: est.camera,
                note: LensNote::Estimated {
                    hfov_deg: est.hfov_deg,
                    frames: frames.len(),
                },
                readout_ms: None,
            })
        }
    }
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
