//! What `amc compare` finds: the clips and each method's measurements.

use super::measure::Measured;
use super::peers::Usage;
use crate::gt::GtReport;
use amc_core::image::Frame;
use amc_core::so3;
use amc_core::CameraModel;
use serde::Serialize;
use std::path::PathBuf;

/// A clip ready to compare.
#[derive(Clone, Debug)]
pub struct Clip {
    /// Short name (file stem or folder name).
    pub name: String,
    /// What `amc stabilize` reads: a video file or an image folder.
    pub input: PathBuf,
    pub lens: CameraModel,
    /// Rolling-shutter readout, ms (0: global shutter): a clip folder's
    /// lens.json states it (the synthetic rolling-shutter clips do).
    pub readout_ms: f64,
    /// The same motion filmed through a global shutter (the synthetic
    /// rolling-shutter clips' twins): cropping and distortion are measured
    /// from its frames to the outputs, so undoing the rolling shutter's skew
    /// counts as removing distortion, not as adding it.
    pub reference: Option<PathBuf>,
    /// Frame rate of image folders.
    pub fps: Option<f64>,
    /// Ground-truth orientations (synthetic clips).
    pub gt: Option<Vec<so3::Rot>>,
    /// One line on where the clip comes from.
    pub description: String,
}

/// One method's result on one clip.
#[derive(Serialize)]
pub struct MethodResult {
    pub method: &'static str,
    pub frames: usize,
    pub usage: Usage,
    pub frames_per_second: f64,
    /// The paper's code: input frames per second of its own loop, without the
    /// loader decoding the clip into its recording layout.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub loop_frames_per_second: Option<f64>,
    pub measured: Measured,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<GtReport>,
    /// The middle output frame, for the strip.
    #[serde(skip)]
    pub middle: Option<Frame>,
    #[serde(skip)]
    pub saccades: Vec<bool>,
    /// Ours: output frames with a pixel no averaged frame covers (a border),
    /// counted from the renderer's coverage. Peers fill theirs: not counted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_with_border: Option<usize>,
}

impl MethodResult {
    /// `method`'s result from its run's `usage` over `input_frames` input
    /// frames and its output's measurements (`middle`: the output's middle
    /// frame); what only some methods know (ground truth, saccades, borders,
    /// the paper's own loop) left out.
    pub(super) fn new(
        method: &'static str,
        input_frames: usize,
        usage: Usage,
        measured: Measured,
        middle: Option<Frame>,
    ) -> Self {
        Self {
            method,
            frames: measured.frames.len(),
            frames_per_second: input_frames as f64 / usage.seconds.max(1e-9),
            loop_frames_per_second: None,
            usage,
            measured,
            ground_truth: None,
            middle,
            saccades: Vec::new(),
            frames_with_border: None,
        }
    }
}

/// All methods on one clip.
#[derive(Serialize)]
pub struct ClipResult {
    pub clip: String,
    pub description: String,
    pub input_size: (usize, usize),
    pub frames: usize,
    pub fps: f64,
    pub hfov_deg: f64,
    /// Whether the bars apply (synthetic clips and `cup`).
    pub has_bars: bool,
    pub methods: Vec<MethodResult>,
    /// With `--peer paper`: why the paper's code did not run on this clip.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paper_skipped: Option<String>,
    #[serde(skip)]
    pub input_middle: Option<Frame>,
}
