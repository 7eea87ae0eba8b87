//! A frame in the stabilizer's ring: the frame and what tracking found.

use crate::image::Frame;
use crate::render::Deghost;
use crate::shutter::{IntraFrame, RollingProjector};
use crate::so3::Rot;
use crate::tracker::TrackInfo;

/// A frame waiting in the ring until every output that averages it is rendered.
pub(super) struct Buffered {
    pub(super) frame: Frame,
    pub(super) index: u64,
    pub(super) t: f64,
    pub(super) r_est: Rot,
    /// Its motion during the readout (zero with a global shutter).
    pub(super) intra: IntraFrame,
    /// Its rows' readout rotations as rendered (`Tracked::rendered`),
    /// tabulated (empty with a global shutter).
    pub(super) rows: RollingProjector,
    pub(super) info: TrackInfo,
    /// Forward-filtered view at this frame.
    pub(super) view_fwd: Rot,
    /// With `deghost=auto`, the ghost-free weights in force when this frame
    /// arrived: those of every output it is the newest frame of.
    pub(super) deghost: Option<Deghost>,
}
