//! Parameters of the renderer and the output camera they define.

use crate::camera::CameraModel;
use crate::error::{check_range, AmcError};
use serde::{Deserialize, Serialize};

/// Parameters of the renderer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderParams {
    /// Frames averaged into each output frame (`N_avg`; paper: 6). Range 1..=64.
    pub n_avg: usize,
    /// Share of the source width/height cropped from each side of the output
    /// with `zoom = none` (paper: 0.125, i.e. the central 75%); `auto` and
    /// `static` zoom instead. Range 0..=0.45.
    pub margin: f64,
    /// Output width in pixels; default: the cropped source width, rounded to even.
    /// Range 16..=16384.
    pub output_width: Option<usize>,
    /// Output height in pixels; default: keeps the cropped aspect ratio. Range 16..=16384.
    pub output_height: Option<usize>,
    /// Ghost-free averaging (default `auto`): see [`DeghostLevel`].
    pub deghost: DeghostLevel,
    /// Anti-aliasing of minified outputs (default `auto`): see [`Antialias`].
    pub antialias: Antialias,
    /// How a source frame is sampled between its pixels (default
    /// `bilinear`): see [`Interpolation`].
    pub interpolation: Interpolation,
}

/// How a source frame is sampled at a point between its pixel centres.
///
/// Bilinear interpolation (2 x 2 taps) is a low-pass filter whose strength
/// depends on the sub-pixel offset: at half a pixel it halves the picture's
/// finest detail, at a whole pixel it passes it. A stabilized view samples
/// every frame at offsets that wander from frame to frame, so on average it
/// costs a real picture some of its sharpness before any averaging (see
/// `docs/core-history.md#render-interpolation`), and the blur breathes with the
/// offset. Bicubic interpolation (4 x 4 taps, Keys' cubic convolution with
/// `a = -1/2`, i.e. Catmull-Rom) keeps nearly all of the passband at every offset: 4
/// x 4 instead of 2 x 2 taps, in the same 8.8 fixed point (see
/// `kernels/common.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    /// 2 x 2 taps (the paper's, and the fastest).
    #[default]
    Bilinear,
    /// 4 x 4 taps, Catmull-Rom: sharper, about twice the sampling work.
    Bicubic,
}

impl std::str::FromStr for Interpolation {
    type Err = AmcError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "bilinear" => Ok(Interpolation::Bilinear),
            "bicubic" => Ok(Interpolation::Bicubic),
            _ => Err(AmcError::invalid("interpolation", s, "bilinear or bicubic")),
        }
    }
}

impl std::fmt::Display for Interpolation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Interpolation::Bilinear => "bilinear",
            Interpolation::Bicubic => "bicubic",
        })
    }
}

/// Anti-aliasing of outputs rendered smaller than the source.
///
/// One bilinear sample per output pixel is a fine resampler while an output
/// pixel covers at most about one source pixel; when it covers more (an output
/// narrower than the input, 4K to 1080p), the samples skip source pixels and
/// alias, and as the view moves the skipped pixels change from frame to frame:
/// the aliasing shimmers. `auto` then renders `S x S` samples per output pixel
/// and averages them (a box prefilter; see [`RenderParams::supersample`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Antialias {
    /// `S = 1` while an output pixel's footprint in the source is at most
    /// [`SUPERSAMPLE_ABOVE`] source pixels (every output of the input's size
    /// and zoom >= 1: bit-identical to `off`), else `S = ceil(footprint)`,
    /// at most [`MAX_SUPERSAMPLE`]: `S^2` times the render work.
    #[default]
    Auto,
    /// One sample per output pixel, whatever the footprint.
    Off,
}

impl std::str::FromStr for Antialias {
    type Err = AmcError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(Antialias::Auto),
            "off" => Ok(Antialias::Off),
            _ => Err(AmcError::invalid("antialias", s, "auto or off")),
        }
    }
}

impl std::fmt::Display for Antialias {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Antialias::Auto => "auto",
            Antialias::Off => "off",
        })
    }
}

/// Footprint (source pixels per output pixel) up to which `antialias = auto`
/// keeps one sample per output pixel: a bilinear sample spaced up to 1.5
/// source pixels from the next still sees every source pixel with some weight.
pub const SUPERSAMPLE_ABOVE: f64 = 1.5;

/// Most samples per axis of a supersampled output pixel (`S^2 = 16` times the
/// render work); larger footprints (beyond 4x minification) stay partly aliased.
pub const MAX_SUPERSAMPLE: usize = 4;

/// The footprint of an output pixel in the source, source pixels per output
/// pixel: the largest singular value of the Jacobian of the map output pixel
/// -> source pixel at the output's principal point under the identity rotation
/// (central differences over +-0.5 output pixels), i.e. the longest side of
/// the ellipse an output pixel covers there. For pinhole cameras this is the
/// ratio of focal lengths `f_src / f_out`; distorted lenses have their
/// centre's scale (fisheye and barrel lenses compress the periphery, so an
/// output pixel covers fewer source pixels there than at the centre). Zoom
/// (`>= 1`) only shrinks it, so the framing's zoom is left out. Returns 1 when
/// the centre does not project (a degenerate pair of cameras).
pub fn footprint(src: &CameraModel, out: &CameraModel) -> f64 {
    let map = |dx: f64, dy: f64| {
        let p = nalgebra::Vector2::new(out.cx + dx, out.cy + dy);
        out.unproject(&p).and_then(|ray| src.project(&ray))
    };
    let h = 0.5;
    let (Some(xp), Some(xm), Some(yp), Some(ym)) =
        (map(h, 0.0), map(-h, 0.0), map(0.0, h), map(0.0, -h))
    else {
        return 1.0;
    };
    // Columns of the Jacobian: d(src)/du and d(src)/dv.
    let (a, c) = ((xp.x - xm.x) / (2.0 * h), (xp.y - xm.y) / (2.0 * h));
    let (b, d) = ((yp.x - ym.x) / (2.0 * h), (yp.y - ym.y) / (2.0 * h));
    // Largest singular value of [[a, b], [c, d]]: sigma^2 is the larger
    // eigenvalue of J^T J, (t + sqrt(t^2 - 4 det^2)) / 2 with t = |J|_F^2.
    let t = a * a + b * b + c * c + d * d;
    let det = a * d - b * c;
    let s = ((t + (t * t - 4.0 * det * det).max(0.0).sqrt()) / 2.0).sqrt();
    if s.is_finite() {
        s
    } else {
        1.0
    }
}

impl Default for RenderParams {
    fn default() -> Self {
        Self {
            n_avg: 6,
            margin: 0.125,
            output_width: None,
            output_height: None,
            deghost: DeghostLevel::Auto,
            antialias: Antialias::Auto,
            interpolation: Interpolation::Bilinear,
        }
    }
}

/// The ghost-free average's threshold (`deghost`): each averaged frame's
/// pixel counts fully where it differs from the newest frame's by at most the
/// threshold, not at all from twice it, so whatever moves against the
/// rotation model (parallax, walkers, cars, edges a rolling shutter bends)
/// comes from the newest frame only and is not smeared (see
/// [`super::robust`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum DeghostLevel {
    /// Set from the clip's own noise (see [`super::noise`]): 3 standard
    /// deviations, within 2..=8 levels.
    #[default]
    Auto,
    /// This threshold, intensity levels of 255, `0..=64`; 0 (`off`): the
    /// plain average of the paper, which smears what moves.
    Levels(f64),
}

impl DeghostLevel {
    /// The fixed weights; `None` for the plain average and for `auto` (the
    /// stabilizer sets those as it measures the clip).
    pub fn fixed(self) -> Option<super::Deghost> {
        match self {
            DeghostLevel::Auto => None,
            DeghostLevel::Levels(l) => super::Deghost::new(l),
        }
    }
}

impl std::str::FromStr for DeghostLevel {
    type Err = AmcError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let v = s.trim();
        if v.eq_ignore_ascii_case("auto") {
            return Ok(DeghostLevel::Auto);
        }
        if v.eq_ignore_ascii_case("off") {
            return Ok(DeghostLevel::Levels(0.0));
        }
        // The range is checked by `RenderParams::validate`, as every option's.
        match v.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(DeghostLevel::Levels(x)),
            _ => Err(AmcError::invalid(
                "deghost",
                format!("{s:?}"),
                DEGHOST_ALLOWED,
            )),
        }
    }
}

/// What `deghost` takes, for errors.
const DEGHOST_ALLOWED: &str = "auto, off, or 0..=64 intensity levels (0 = the plain average)";

impl std::fmt::Display for DeghostLevel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DeghostLevel::Auto => f.write_str("auto"),
            DeghostLevel::Levels(l) => write!(f, "{l}"),
        }
    }
}

// As the option is written: "auto" or a number.
impl Serialize for DeghostLevel {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            DeghostLevel::Auto => s.serialize_str("auto"),
            DeghostLevel::Levels(l) => s.serialize_f64(*l),
        }
    }
}

impl<'de> Deserialize<'de> for DeghostLevel {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Form {
            Number(f64),
            Word(String),
        }
        match Form::deserialize(d)? {
            Form::Number(x) => Ok(DeghostLevel::Levels(x)),
            Form::Word(w) => w.parse().map_err(serde::de::Error::custom),
        }
    }
}

/// A threshold that suits compressed 8-bit video: about 1-2 standard
/// deviations of the difference of two frames' noise, so the static scene
/// keeps most of the averaging's noise reduction.
pub const SUGGESTED_DEGHOST: f64 = 6.0;

impl RenderParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<(), AmcError> {
        if !(1..=64).contains(&self.n_avg) {
            return Err(AmcError::invalid("n_avg", self.n_avg, "1..=64 frames"));
        }
        check_range(
            "margin",
            self.margin,
            0.0,
            0.45,
            "0..=0.45 (share of each side)",
        )?;
        if let DeghostLevel::Levels(l) = self.deghost {
            check_range(
                "deghost",
                l,
                0.0,
                super::robust::MAX_DEGHOST,
                DEGHOST_ALLOWED,
            )?;
        }
        for (name, v) in [
            ("output_width", self.output_width),
            ("output_height", self.output_height),
        ] {
            if let Some(v) = v {
                if !(16..=16384).contains(&v) {
                    return Err(AmcError::invalid(name, v, "16..=16384 pixels"));
                }
            }
        }
        Ok(())
    }

    /// The fixed ghost-free averaging weights; `None` for the plain average
    /// and for `auto` (see [`DeghostLevel::fixed`]).
    pub fn deghost(&self) -> Option<super::Deghost> {
        self.deghost.fixed()
    }

    /// Samples per axis of each output pixel from `src` into `out` (see
    /// [`Antialias`]): 1 with `off` or while the [`footprint`] is at most
    /// [`SUPERSAMPLE_ABOVE`], else its ceiling, at most [`MAX_SUPERSAMPLE`].
    /// A footprint within 1% above a whole number counts as that number (an
    /// output rounded to even pixels is a hair smaller than exactly half).
    pub fn supersample(&self, src: &CameraModel, out: &CameraModel) -> usize {
        let f = footprint(src, out);
        if self.antialias == Antialias::Off || f <= SUPERSAMPLE_ABOVE {
            1
        } else {
            ((f - 0.01).ceil() as usize).clamp(2, MAX_SUPERSAMPLE)
        }
    }

    /// The output camera for a source camera: a pinhole with the source's focal
    /// length (scaled when an explicit output size is asked for), centred,
    /// cropped by `margin`.
    pub fn output_camera(&self, src: &CameraModel) -> Result<CameraModel, AmcError> {
        self.output_camera_with_margin(src, self.margin)
    }

    /// [`RenderParams::output_camera`] cropped by `margin` (0..=0.45) instead
    /// of `self.margin`: the zoomed framings size the output at margin 0.
    pub fn output_camera_with_margin(
        &self,
        src: &CameraModel,
        margin: f64,
    ) -> Result<CameraModel, AmcError> {
        self.validate()?;
        let keep = 1.0 - 2.0 * margin.clamp(0.0, 0.45);
        let crop_w = src.width as f64 * keep;
        let crop_h = src.height as f64 * keep;
        let even = |x: f64| ((x / 2.0).round() as usize * 2).max(16);
        let (w, h) = match (self.output_width, self.output_height) {
            (None, None) => (even(crop_w), even(crop_h)),
            (Some(w), None) => (w, even(w as f64 * crop_h / crop_w)),
            (None, Some(h)) => (even(h as f64 * crop_w / crop_h), h),
            (Some(w), Some(h)) => (w, h),
        };
        // One scale for both axes, so rounding a size to even pixels crops
        // (or extends) by a fraction of a pixel instead of stretching the image;
        // only an explicit width *and* height may change the aspect ratio.
        let (sx, sy) = match (self.output_width, self.output_height) {
            (None, None) => (1.0, 1.0),
            (Some(_), None) => (w as f64 / crop_w, w as f64 / crop_w),
            (None, Some(_)) => (h as f64 / crop_h, h as f64 / crop_h),
            (Some(_), Some(_)) => (w as f64 / crop_w, h as f64 / crop_h),
        };
        Ok(CameraModel::pinhole(
            w,
            h,
            src.fx * sx,
            src.fy * sy,
            (w as f64 - 1.0) / 2.0,
            (h as f64 - 1.0) / 2.0,
        ))
    }
}
