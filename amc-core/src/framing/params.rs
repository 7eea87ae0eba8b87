//! Parameters of the framing stage.

use crate::error::{check_range, AmcError};
use serde::{Deserialize, Serialize};

/// How the output's zoom is chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Zoom {
    /// Per frame: the least zoom that shows no border, smoothed so that it
    /// never pumps, within the crop budget (the output keeps the input's size).
    #[default]
    Auto,
    /// One zoom for the whole clip: the least that shows no border anywhere,
    /// within the crop budget (needs a first pass over the clip).
    Static,
    /// No zoom: the fixed `margin` is cropped from each side (the paper's framing).
    None,
}

impl std::str::FromStr for Zoom {
    type Err = AmcError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(Zoom::Auto),
            "static" => Ok(Zoom::Static),
            "none" => Ok(Zoom::None),
            _ => Err(AmcError::invalid("zoom", s, "auto, static or none")),
        }
    }
}

impl std::fmt::Display for Zoom {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Zoom::Auto => "auto",
            Zoom::Static => "static",
            Zoom::None => "none",
        })
    }
}

/// Parameters of the framing (see the module's docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FramingParams {
    /// How the zoom is chosen (default `auto`).
    pub zoom: Zoom,
    /// Crop budget of `auto` and `static`: the largest share of the width the
    /// output may crop, so at least `1 - max_crop` of it is kept (default 0.15).
    /// The view is pulled toward the camera where it would need more. Range 0..=0.5.
    pub max_crop: f64,
}

impl Default for FramingParams {
    fn default() -> Self {
        Self {
            zoom: Zoom::Auto,
            max_crop: 0.15,
        }
    }
}

impl FramingParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<(), AmcError> {
        check_range(
            "max_crop",
            self.max_crop,
            0.0,
            0.5,
            "0..=0.5 (share of the width)",
        )
    }

    /// The largest zoom the budget allows, `1 / (1 - max_crop)`.
    pub fn max_zoom(&self) -> f64 {
        1.0 / (1.0 - self.max_crop.clamp(0.0, 0.5))
    }
}
