//! The stabilizer's parameters: one per stage.

use crate::error::AmcError;
use crate::framing::{FramingParams, Zoom};
use crate::render::RenderParams;
use crate::shutter::ShutterParams;
use crate::tracker::TrackerParams;
use crate::view::{Mode, ViewParams};
use serde::{Deserialize, Serialize};

/// All parameters of the stabilizer: one definition shared by the CLI, the REST
/// API and the WASM API.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StabilizerParams {
    /// Width (pixels) of the grayscale image the tracker works on; frames are
    /// box-averaged by `floor(width / track_width)`. Range 32..=8192.
    pub track_width: usize,
    /// Rotation tracker.
    pub tracker: TrackerParams,
    /// View path (smoothing, lookahead, saccades).
    pub view: ViewParams,
    /// Output rendering (averaging, fixed margin, output size).
    pub render: RenderParams,
    /// Framing (zoom and crop budget).
    pub framing: FramingParams,
    /// The camera's shutter (rolling-shutter readout).
    pub shutter: ShutterParams,
}

impl Default for StabilizerParams {
    fn default() -> Self {
        Self {
            track_width: 320,
            tracker: TrackerParams::default(),
            view: ViewParams::default(),
            render: RenderParams::default(),
            framing: FramingParams::default(),
            shutter: ShutterParams::default(),
        }
    }
}

impl StabilizerParams {
    /// Whether these parameters hold the zoom static over the clip, which
    /// takes a first pass to find it (`zoom = static` in stabilize or lock
    /// mode; saccade mode's zoom is fixed anyway).
    pub fn wants_static_zoom(&self) -> bool {
        self.framing.zoom == Zoom::Static && matches!(self.view.mode, Mode::Stabilize | Mode::Lock)
    }

    /// Checks every stage's parameters.
    pub fn validate(&self) -> Result<(), AmcError> {
        if !(32..=8192).contains(&self.track_width) {
            return Err(AmcError::invalid(
                "track_width",
                self.track_width,
                "32..=8192 pixels",
            ));
        }
        self.tracker.validate()?;
        self.view.validate()?;
        self.framing.validate()?;
        self.shutter.validate()?;
        self.render.validate()
    }
}
