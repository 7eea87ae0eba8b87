//! The first passes of a run, in one place: which ones a run needs, in what
//! order, how many frames each reads, and what they hand to the main pass.
//!
//! A run may read its clip more than once before it stabilizes it:
//!
//! 1. [`Pass::Lens`] (`fov = auto`): the first [`AUTO_FOV_FRAMES`] frames,
//!    for [`selfcal::estimate_hfov`]; a pinhole of [`FALLBACK_FOV_DEG`]
//!    when the footage does not pin the focal length down.
//! 2. [`Pass::Readout`] (`readout_ms = auto`): the first [`READOUT_FRAMES`]
//!    frames through a [`ReadoutEstimator`] with the lens; a global shutter
//!    (0 ms) when the estimate is not trusted or the clip is too short.
//! 3. [`Pass::StaticZoom`] (`zoom = static` in stabilize or lock mode): the
//!    whole clip through a stabilizer that does not render, with the lens and
//!    the readout; the highest zoom any output needs.
//!
//! Each later pass needs what the earlier ones found, so they run in this
//! order, each reading the clip from its start. A [`PassPlan`] is built from
//! the user's choices ([`PlanChoices`]) and takes the frames of one pass at a
//! time: [`PassPlan::pass`] names the pass to read, [`PassPlan::push`] takes
//! its frames until [`PassPlan::is_full`] (or the clip ends),
//! [`PassPlan::finish_pass`] resolves it; once no pass is left,
//! [`PassPlan::finish`] hands over the lens, the readout, the parameters
//! and the static zoom of the main pass, with notes for the user. The plan
//! reads nothing itself: the engine (`amc-engine`) and the browser's worker
//! (through `amc-wasm`) decode the frames and drive the same plan.

use crate::camera::CameraModel;
use crate::error::AmcError;
use crate::image::{Frame, FrameRef};
use crate::lens::LensFile;
use crate::options::ReadoutSpec;
use crate::readout::{ReadoutEstimate, ReadoutEstimator};
use crate::selfcal;
use crate::stabilizer::{Stabilizer, StabilizerParams};

mod posed;

pub use crate::readout::READOUT_FRAMES;
pub use posed::static_zoom_posed;

/// Frames read for `fov = auto` (about 3 s at 30 fps).
pub const AUTO_FOV_FRAMES: usize = 90;

/// Horizontal field of view assumed when `fov = auto` cannot pin the focal
/// length down: a typical phone / action-camera main lens, degrees.
pub const FALLBACK_FOV_DEG: f64 = 70.0;

/// A pass over the clip before the main one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pass {
    /// `fov = auto`: the focal length from the clip's first frames.
    Lens,
    /// `readout_ms = auto`: the rolling-shutter readout from the clip's first frames.
    Readout,
    /// `zoom = static`: the zoom of the whole clip.
    StaticZoom,
}

impl Pass {
    /// The most frames the pass reads from the clip's start (`None`: all of them).
    pub fn frame_budget(self) -> Option<usize> {
        match self {
            Pass::Lens => Some(AUTO_FOV_FRAMES),
            Pass::Readout => Some(READOUT_FRAMES),
            Pass::StaticZoom => None,
        }
    }

    /// Its name: `lens`, `readout` or `static_zoom`.
    pub fn name(self) -> &'static str {
        match self {
            Pass::Lens => "lens",
            Pass::Readout => "readout",
            Pass::StaticZoom => "static_zoom",
        }
    }
}

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

/// A camera for the clip's frames, and how it was found.
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

impl From<LensFile> for ResolvedLens {
    /// A lens file's camera and readout, given.
    fn from(file: LensFile) -> Self {
        ResolvedLens {
            camera: file.camera,
            note: LensNote::Given,
            readout_ms: file.readout_ms,
        }
    }
}

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

/// What the first passes found: what the main pass needs.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// The camera, and how it was found.
    pub lens: ResolvedLens,
    /// The readout, and where it came from.
    pub readout: ResolvedReadout,
    /// The choices' parameters with the readout set (`shutter.readout_ms`).
    pub params: StabilizerParams,
    /// The zoom [`Pass::StaticZoom`] found, for
    /// [`Stabilizer::set_static_zoom`] (`None`: no such pass was planned).
    pub static_zoom: Option<f64>,
}

impl Resolved {
    /// How the lens was found.
    pub fn lens_note(&self) -> &LensNote {
        &self.lens.note
    }
}

/// How the lens is known, as a plan takes it (a lens file is read and parsed
/// by the caller: the plan does no I/O).
#[derive(Clone, Debug)]
pub enum LensChoice {
    /// Known already: a lens file ([`ResolvedLens::from`]) or a lens an
    /// earlier plan resolved.
    Known(ResolvedLens),
    /// A pinhole with this horizontal field of view, degrees (it needs the
    /// frame size: [`PassPlan::needs_frame_size`]).
    Fov(f64),
    /// Estimated from the clip ([`Pass::Lens`]).
    Auto,
}

/// The choices a plan is made from.
#[derive(Clone, Debug)]
pub struct PlanChoices {
    /// How the lens is known.
    pub lens: LensChoice,
    /// How the readout is known ([`ReadoutSpec::FromLens`] and
    /// [`ReadoutSpec::Ms`] make no pass).
    pub readout: ReadoutSpec,
    /// The stabilizer's parameters (their `framing.zoom` and `view.mode`
    /// decide [`Pass::StaticZoom`]; their `shutter.readout_ms` is replaced
    /// by the resolved readout).
    pub params: StabilizerParams,
    /// Whether to plan [`Pass::StaticZoom`] when the parameters call for it
    /// (`false`: the caller makes that pass itself, as `amc-engine`'s `run`
    /// does after `resolve`).
    pub static_zoom: bool,
    /// The frames' size, when known before the first frame.
    pub frame_size: Option<(usize, usize)>,
}

/// The state of the pass being read.
enum Reading {
    /// No frame yet.
    Idle,
    /// The lens pass's frames, kept for the estimate.
    Lens(Vec<(Frame, f64)>),
    /// The readout pass's estimator.
    Readout(ReadoutEstimator),
    /// The static-zoom pass's stabilizer (not rendering).
    StaticZoom(Stabilizer),
}

/// The first passes of one run (see the module's docs).
pub struct PassPlan {
    params: StabilizerParams,
    lens_choice: LensChoice,
    readout_spec: ReadoutSpec,
    frame_size: Option<(usize, usize)>,
    passes: Vec<Pass>,
    done: usize,
    reading: Reading,
    taken: usize,
    lens: Option<ResolvedLens>,
    readout: Option<ResolvedReadout>,
    static_zoom: Option<f64>,
}

impl PassPlan {
    /// The plan for `choices`: which passes, in order (resolving at once
    /// what needs no frames: a known lens, a field of view of a known size,
    /// a given readout).
    pub fn new(choices: PlanChoices) -> Result<Self, AmcError> {
        let PlanChoices {
            lens,
            readout,
            params,
            static_zoom,
            frame_size,
        } = choices;
        let mut passes = Vec::new();
        if matches!(lens, LensChoice::Auto) {
            passes.push(Pass::Lens);
        }
        if readout == ReadoutSpec::Auto {
            passes.push(Pass::Readout);
        }
        if static_zoom && params.wants_static_zoom() {
            passes.push(Pass::StaticZoom);
        }
        let mut plan = PassPlan {
            params,
            lens_choice: lens,
            readout_spec: readout,
            frame_size,
            passes,
            done: 0,
            reading: Reading::Idle,
            taken: 0,
            lens: None,
            readout: None,
            static_zoom: None,
        };
        plan.resolve_known()?;
        Ok(plan)
    }

    /// Every pass planned, in the order they are made.
    pub fn passes(&self) -> &[Pass] {
        &self.passes
    }

    /// The pass to read now (`None`: all are made; [`PassPlan::finish`]).
    pub fn pass(&self) -> Option<Pass> {
        self.passes.get(self.done).copied()
    }

    /// Whether the lens is a field of view and the frame size is not known
    /// yet: give it ([`PassPlan::set_frame_size`]) before the first pass.
    pub fn needs_frame_size(&self) -> bool {
        self.lens.is_none() && matches!(self.lens_choice, LensChoice::Fov(_))
    }

    /// The frames' size (for a field of view); a pass's first frame gives it
    /// otherwise.
    pub fn set_frame_size(&mut self, width: usize, height: usize) -> Result<(), AmcError> {
        self.frame_size = Some((width, height));
        self.resolve_known()
    }

    /// Frames the pass being read has taken (the readout pass: those its
    /// estimator has tracked).
    pub fn frames(&self) -> usize {
        match &self.reading {
            Reading::Idle => 0,
            Reading::Lens(frames) => frames.len(),
            Reading::Readout(est) => est.frames(),
            Reading::StaticZoom(_) => self.taken,
        }
    }

    /// Whether the pass being read has the frames it wants: stop decoding.
    /// (A pass of the whole clip is never full; no pass: full.)
    pub fn is_full(&self) -> bool {
        match &self.reading {
            Reading::Idle => self.pass().is_none(),
            Reading::Lens(frames) => frames.len() >= AUTO_FOV_FRAMES,
            Reading::Readout(est) => est.is_full(),
            Reading::StaticZoom(_) => false,
        }
    }

    /// Gives the pass being read the next frame of the clip, `t` seconds in.
    /// A full pass ignores it (it has the frames it wants).
    pub fn push(&mut self, frame: FrameRef<'_>, t: f64) -> Result<(), AmcError> {
        let pass = self.pass().ok_or_else(|| {
            AmcError::invalid("frame", "pushed", "frames only while a pass is planned")
        })?;
        if self.is_full() {
            return Ok(());
        }
        if matches!(self.reading, Reading::Idle) {
            if self.frame_size.is_none() {
                self.frame_size = Some((frame.width, frame.height));
                self.resolve_known()?;
            }
            self.reading = self.start(pass, frame.width, frame.height)?;
        }
        self.taken += 1;
        match &mut self.reading {
            Reading::Idle => unreachable!("a pass is started above"),
            Reading::Lens(frames) => {
                let mut f = Frame::new(0, 0, frame.format);
                f.copy_from(&frame);
                frames.push((f, t));
            }
            Reading::Readout(est) => est.push(frame, t)?,
            Reading::StaticZoom(stab) => {
                stab.push(frame, t)?;
            }
        }
        Ok(())
    }

    /// What a pass starts with, at its first frame (`width x height`).
    fn start(&self, pass: Pass, width: usize, height: usize) -> Result<Reading, AmcError> {
        let lens = || {
            self.lens
                .as_ref()
                .ok_or_else(|| AmcError::invalid("pass", pass.name(), "after the lens is known"))
        };
        Ok(match pass {
            Pass::Lens => Reading::Lens(Vec::with_capacity(AUTO_FOV_FRAMES)),
            Pass::Readout => Reading::Readout(ReadoutEstimator::new(
                &lens()?.camera,
                width,
                height,
                &self.params,
            )?),
            Pass::StaticZoom => {
                if self.readout.is_none() {
                    return Err(AmcError::invalid(
                        "pass",
                        pass.name(),
                        "after the readout is known",
                    ));
                }
                let mut stab =
                    Stabilizer::new(&lens()?.camera, width, height, self.params.clone())?;
                stab.set_rendering(false);
                Reading::StaticZoom(stab)
            }
        })
    }

    /// Resolves the pass being read from the frames it took (at least one)
    /// and moves on to the next; returns the pass resolved.
    ///
    /// - [`Pass::Lens`]: the estimate when the footage pins it down, else a
    ///   pinhole of [`FALLBACK_FOV_DEG`] ([`LensNote::FellBack`]); fewer
    ///   frames than [`selfcal::MIN_FRAMES`] are an error.
    /// - [`Pass::Readout`]: the estimate when it is confident, else 0
    ///   ([`ReadoutNote::FellBack`], also for a clip too short to fit).
    /// - [`Pass::StaticZoom`]: the highest zoom any output needed.
    pub fn finish_pass(&mut self) -> Result<Pass, AmcError> {
        let pass = self.pass().ok_or_else(|| {
            AmcError::invalid("pass", "none", "finish a pass only while one is planned")
        })?;
        match std::mem::replace(&mut self.reading, Reading::Idle) {
            Reading::Idle => {
                return Err(AmcError::invalid(
                    "frames",
                    format!("0 in the {} pass", pass.name()),
                    "at least one frame in each pass",
                ))
            }
            Reading::Lens(frames) => self.lens = Some(self.lens_from(&frames)?),
            Reading::Readout(est) => self.readout = Some(readout_from(est)?),
            Reading::StaticZoom(mut stab) => {
                while stab.finish().is_some() {}
                self.static_zoom = Some(stab.max_zoom_need());
            }
        }
        self.done += 1;
        self.taken = 0;
        self.resolve_known()?;
        Ok(pass)
    }

    /// The lens `fov = auto` finds from `frames`.
    fn lens_from(&self, frames: &[(Frame, f64)]) -> Result<ResolvedLens, AmcError> {
        let refs: Vec<_> = frames.iter().map(|(f, t)| (f.as_ref(), *t)).collect();
        let readout_s = self.readout_spec.given(None).unwrap_or(0.0) * 1e-3;
        let est = selfcal::estimate_hfov(
            &refs,
            self.params.track_width,
            &self.params.tracker,
            readout_s,
        )?;
        if !est.confident {
            let (w, h) = (frames[0].0.width, frames[0].0.height);
            return Ok(ResolvedLens {
                camera: CameraModel::pinhole_hfov(w, h, FALLBACK_FOV_DEG)?,
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

    /// Resolves what needs no (more) frames: a field of view once the size
    /// is known, a given readout once the lens is.
    fn resolve_known(&mut self) -> Result<(), AmcError> {
        if self.lens.is_none() {
            match &self.lens_choice {
                LensChoice::Known(lens) => self.lens = Some(lens.clone()),
                LensChoice::Fov(deg) => {
                    if let Some((w, h)) = self.frame_size {
                        self.lens = Some(ResolvedLens {
                            camera: CameraModel::pinhole_hfov(w, h, *deg)?,
                            note: LensNote::Given,
                            readout_ms: None,
                        });
                    }
                }
                LensChoice::Auto => {}
            }
        }
        if let (None, Some(lens)) = (&self.readout, &self.lens) {
            if let Some(readout_ms) = self.readout_spec.given(lens.readout_ms) {
                let from_lens =
                    self.readout_spec == ReadoutSpec::FromLens && lens.readout_ms.is_some();
                self.readout = Some(ResolvedReadout {
                    readout_ms,
                    note: if from_lens {
                        ReadoutNote::FromLens
                    } else {
                        ReadoutNote::Given
                    },
                });
            }
        }
        if let Some(r) = &self.readout {
            self.params.shutter.readout_ms = r.readout_ms;
        }
        Ok(())
    }

    /// The lens, once known.
    pub fn lens(&self) -> Option<&ResolvedLens> {
        self.lens.as_ref()
    }

    /// The readout, once known.
    pub fn readout(&self) -> Option<&ResolvedReadout> {
        self.readout.as_ref()
    }

    /// The zoom [`Pass::StaticZoom`] found, once made.
    pub fn static_zoom(&self) -> Option<f64> {
        self.static_zoom
    }

    /// The parameters, with the readout set once it is known.
    pub fn params(&self) -> &StabilizerParams {
        &self.params
    }

    /// What the main pass needs, once every pass is made.
    pub fn finish(self) -> Result<Resolved, AmcError> {
        if let Some(pass) = self.pass() {
            return Err(AmcError::invalid(
                "plan",
                format!("the {} pass is not made", pass.name()),
                "finish once every pass is made",
            ));
        }
        let (Some(lens), Some(readout)) = (self.lens, self.readout) else {
            return Err(AmcError::invalid(
                "plan",
                "the frame size is not known",
                "a field of view needs the frame size (set_frame_size)",
            ));
        };
        Ok(Resolved {
            lens,
            readout,
            params: self.params,
            static_zoom: self.static_zoom,
        })
    }
}

/// The readout `readout_ms = auto` finds with `est`: the estimate when it is
/// confident, else 0 (also when the clip is too short to fit).
fn readout_from(est: ReadoutEstimator) -> Result<ResolvedReadout, AmcError> {
    let fell_back = |estimate| ResolvedReadout {
        readout_ms: 0.0,
        note: ReadoutNote::FellBack { estimate },
    };
    match est.finish() {
        Ok(e) if e.confident => Ok(ResolvedReadout {
            readout_ms: e.readout_ms,
            note: ReadoutNote::Estimated(e),
        }),
        Ok(e) => Ok(fell_back(Some(e))),
        Err(AmcError::TooFewFrames { .. }) => Ok(fell_back(None)),
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests;
