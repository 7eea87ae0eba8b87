//! The stabilizer's user-facing options, each defined once.
//!
//! The command line (`--n-avg 4`), the REST API (`?n_avg=4`), `amc compare` and
//! the WASM binding all set the stabilizer through this table and
//! [`StabilizerOptions::set`], so every option has one name, one parser, one
//! default and one allowed range (the range is checked by the parameter
//! structs' `validate()`, which this module calls). The CLI flag of an option is
//! its name in kebab-case.

use crate::error::AmcError;
use crate::framing::Zoom;
use crate::shutter::MAX_READOUT_MS;
use crate::stabilizer::StabilizerParams;
use crate::view::Mode;
use std::path::PathBuf;

/// Largest horizontal field of view of a pinhole lens, degrees (exclusive of 0).
/// A pinhole's focal length goes to zero as the field of view approaches 180 deg.
pub const MAX_PINHOLE_HFOV_DEG: f64 = 179.0;

pub use crate::view::MAX_LOOKAHEAD;

/// One user-facing option: its name and what it accepts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OptionSpec {
    /// The REST / WASM name (snake_case).
    pub name: &'static str,
    /// The command-line flag without its dashes: the name in kebab-case.
    pub flag: &'static str,
    /// Placeholder for the value in help texts.
    pub value_name: &'static str,
    /// What the option does, with its allowed values and default.
    pub help: &'static str,
    /// The values it accepts (checked against the setters by a test; the
    /// service's OpenAPI document gives them as each parameter's schema).
    pub allowed: Allowed,
}

/// The values an option accepts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Allowed {
    /// One of these words.
    Words(&'static [&'static str]),
    /// An integer in `min..=max`.
    Integer {
        /// The least value.
        min: u64,
        /// The greatest value.
        max: u64,
    },
    /// A number in `min..=max` (`min` itself excluded when `above_min`), or one of `words`.
    Number {
        /// The lower bound.
        min: f64,
        /// The greatest value.
        max: f64,
        /// Whether values must be above `min` rather than at least `min`.
        above_min: bool,
        /// Words accepted instead of a number (`auto`).
        words: &'static [&'static str],
    },
}

impl Allowed {
    /// A number in `min..=max`, no words.
    pub const fn range(min: f64, max: f64) -> Self {
        Allowed::Number {
            min,
            max,
            above_min: false,
            words: &[],
        }
    }
}

/// Every option a user can set on a run, in the order help texts list them.
pub const OPTIONS: &[OptionSpec] = &[
    OptionSpec {
        name: "mode",
        flag: "mode",
        value_name: "stabilize|saccade|lock|none",
        help: "stabilize (smooth view), saccade (fixed view, re-centred when needed), lock (every axis held at the first frame's orientation, a tripod; pulled toward the camera only as far as --max-crop needs) or none (default stabilize)",
        allowed: Allowed::Words(&["stabilize", "saccade", "lock", "none"]),
    },
    OptionSpec {
        name: "roll",
        flag: "roll",
        value_name: "smooth|lock|follow",
        help: "the view's roll in stabilize mode: smooth (with pan and tilt), lock (level with the first frame: the horizon holds its angle) or follow (the camera's roll; only pan and tilt smoothed) (default smooth)",
        allowed: Allowed::Words(&["smooth", "lock", "follow"]),
    },
    OptionSpec {
        name: "fov",
        flag: "fov",
        value_name: "DEG|auto",
        help: "horizontal field of view of a pinhole lens in degrees, 0 < DEG <= 179, or auto to estimate it from the footage (default auto)",
        allowed: Allowed::Number {
            min: 0.0,
            max: MAX_PINHOLE_HFOV_DEG,
            above_min: true,
            words: &["auto"],
        },
    },
    OptionSpec {
        name: "readout_ms",
        flag: "readout-ms",
        value_name: "MS|auto",
        help: "rolling-shutter readout time (first row to last) in milliseconds, 0..=100 (0 = global shutter), or auto to estimate it from the footage (0 with a warning when the clip does not pin it down) (default: the lens file's readout_ms or Gyroflow frame_readout_time, else 0)",
        allowed: Allowed::Number {
            min: 0.0,
            max: MAX_READOUT_MS,
            above_min: false,
            words: &["auto"],
        },
    },
    OptionSpec {
        name: "n_avg",
        flag: "n-avg",
        value_name: "N",
        help: "frames averaged into each output frame, 1..=64 (default 6)",
        allowed: Allowed::Integer { min: 1, max: 64 },
    },
    OptionSpec {
        name: "deghost",
        flag: "deghost",
        value_name: "auto|off|LEVELS",
        help: "ghost-free averaging: an averaged frame's pixel counts fully where it differs from the newest frame's by at most LEVELS (of 255), not at all from twice that, so what moves in the scene (parallax, walkers, cars) is not smeared and edges stay sharp; auto sets LEVELS from the clip's own noise (3 standard deviations, 2..=8); off (or 0) is the paper's plain average; 0..=64 (default auto)",
        allowed: Allowed::Number {
            min: 0.0,
            max: crate::render::MAX_DEGHOST,
            above_min: false,
            words: &["auto", "off"],
        },
    },
    OptionSpec {
        name: "antialias",
        flag: "antialias",
        value_name: "auto|off",
        help: "anti-aliasing of outputs smaller than the input: auto (where an output pixel spans more than 1.5 input pixels, e.g. --output-width below two thirds of the input's, it averages S x S samples, S = that span rounded up, at most 4: S^2 times the render work; outputs of the input's size are unchanged) or off (one sample per pixel) (default auto)",
        allowed: Allowed::Words(&["auto", "off"]),
    },
    OptionSpec {
        name: "interpolation",
        flag: "interpolation",
        value_name: "bilinear|bicubic",
        help: "how frames are sampled between their pixels: bilinear (2x2 taps, the paper's) or bicubic (4x4 taps, Catmull-Rom: keeps the detail bilinear sampling blurs as the view moves by fractions of a pixel; about twice the render work) (default bilinear)",
        allowed: Allowed::Words(&["bilinear", "bicubic"]),
    },
    OptionSpec {
        name: "n_track",
        flag: "n-track",
        value_name: "N",
        help: "template reset period in frames, 1..=1000 (default 5)",
        allowed: Allowed::Integer { min: 1, max: 1000 },
    },
    OptionSpec {
        name: "margin",
        flag: "margin",
        value_name: "FRAC",
        help: "with --zoom none: share cropped from each side of the output, 0..=0.45 (default 0.125)",
        allowed: Allowed::range(0.0, 0.45),
    },
    OptionSpec {
        name: "zoom",
        flag: "zoom",
        value_name: "auto|static|none",
        help: "framing: auto (per frame, the least zoom that shows no border, smoothed, within --max-crop), static (one zoom for the whole clip; files only) or none (crop --margin from each side) (default auto; none in saccade mode: a fixed crop for a fixed view, as the paper frames it)",
        allowed: Allowed::Words(&["auto", "static", "none"]),
    },
    OptionSpec {
        name: "max_crop",
        flag: "max-crop",
        value_name: "FRAC",
        help: "crop budget of --zoom auto|static: the largest share of the width cropped, 0..=0.5 (default 0.15: keeps at least 85%); the view is pulled toward the camera where it would need more",
        allowed: Allowed::range(0.0, 0.5),
    },
    OptionSpec {
        name: "track_width",
        flag: "track-width",
        value_name: "PX",
        help: "width of the grayscale image the tracker works on, 32..=8192 pixels (default 320)",
        allowed: Allowed::Integer { min: 32, max: 8192 },
    },
    OptionSpec {
        name: "lookahead",
        flag: "lookahead",
        value_name: "N",
        help: "future frames used to smooth the view, 0..=600 (default 0 = online); adds N frames of latency",
        allowed: Allowed::Integer { min: 0, max: 600 },
    },
    OptionSpec {
        name: "rate_a",
        flag: "rate-a",
        value_name: "PER_S",
        help: "smoothing: constant part of the view filter's gain, 0..=1000 per second (default 2; lower is smoother)",
        allowed: Allowed::range(0.0, 1000.0),
    },
    OptionSpec {
        name: "rate_b",
        flag: "rate-b",
        value_name: "PER_S_RAD",
        help: "smoothing: gain growing with the view's lag behind the camera, 0..=10000 per second per radian (default 20; the paper's 40 suits --zoom none)",
        allowed: Allowed::range(0.0, 10000.0),
    },
    OptionSpec {
        name: "roll_rate_a",
        flag: "roll-rate-a",
        value_name: "PER_S",
        help: "smoothing of roll alone: constant gain, 0..=1000 per second (default: --rate-a, as pan and tilt)",
        allowed: Allowed::range(0.0, 1000.0),
    },
    OptionSpec {
        name: "roll_rate_b",
        flag: "roll-rate-b",
        value_name: "PER_S_RAD",
        help: "smoothing of roll alone: gain growing with the view's lag, 0..=10000 per second per radian (default: --rate-b)",
        allowed: Allowed::range(0.0, 10000.0),
    },
    OptionSpec {
        name: "output_width",
        flag: "output-width",
        value_name: "PX",
        help: "output width, 16..=16384 pixels (default: the input width; with --zoom none the cropped input width)",
        allowed: Allowed::Integer { min: 16, max: 16384 },
    },
    OptionSpec {
        name: "output_height",
        flag: "output-height",
        value_name: "PX",
        help: "output height, 16..=16384 pixels (default: keeps the aspect ratio)",
        allowed: Allowed::Integer { min: 16, max: 16384 },
    },
];

/// How the lens of the footage is known.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum LensSpec {
    /// Estimate the focal length of a pinhole from the footage (`fov=auto`).
    #[default]
    Auto,
    /// A pinhole with this horizontal field of view, degrees, in `(0, 179]`.
    Fov(f64),
    /// A lens file (the project's JSON, an OpenCV calibration or a Gyroflow
    /// profile, see [`crate::lens::parse_lens`]) at this path, read by the caller.
    File(PathBuf),
}

impl LensSpec {
    /// Parses a `fov` value: `auto` or degrees in `(0, 179]`.
    pub fn parse_fov(value: &str) -> Result<Self, AmcError> {
        let deg = number_or_auto(
            "fov",
            value,
            |deg| deg > 0.0 && deg <= MAX_PINHOLE_HFOV_DEG,
            "a horizontal field of view in degrees, 0 < DEG <= 179, or auto",
        )?;
        Ok(deg.map_or(LensSpec::Auto, LensSpec::Fov))
    }
}

/// Parses `auto` (`None`) or a finite number `ok` accepts; anything else is
/// an error naming the option `name` and what it `allowed`.
fn number_or_auto(
    name: &'static str,
    value: &str,
    ok: impl Fn(f64) -> bool,
    allowed: &'static str,
) -> Result<Option<f64>, AmcError> {
    let v = value.trim();
    if v.eq_ignore_ascii_case("auto") {
        return Ok(None);
    }
    match v.parse::<f64>() {
        Ok(x) if x.is_finite() && ok(x) => Ok(Some(x)),
        _ => Err(AmcError::invalid(name, format!("{value:?}"), allowed)),
    }
}

/// How the rolling-shutter readout time of the footage is known (`readout_ms`).
#[derive(Clone, Debug, Default, PartialEq)]
pub enum ReadoutSpec {
    /// Not given: the lens file's readout when it states one, else 0 (a
    /// global shutter).
    #[default]
    FromLens,
    /// Estimate it from the footage (`readout_ms=auto`, see
    /// [`crate::readout::ReadoutEstimator`]).
    Auto,
    /// This readout, milliseconds, in `0..=100`.
    Ms(f64),
}

impl ReadoutSpec {
    /// Parses a `readout_ms` value: `auto` or milliseconds in `0..=100`.
    pub fn parse(value: &str) -> Result<Self, AmcError> {
        let ms = number_or_auto(
            "readout_ms",
            value,
            |ms| (0.0..=MAX_READOUT_MS).contains(&ms),
            "a readout time in milliseconds, 0..=100 (0 = global shutter), or auto",
        )?;
        Ok(ms.map_or(ReadoutSpec::Auto, ReadoutSpec::Ms))
    }

    /// The readout when it needs no estimate: the option's, else the lens
    /// file's (`lens_ms`), else 0; `None` for [`ReadoutSpec::Auto`].
    pub fn given(&self, lens_ms: Option<f64>) -> Option<f64> {
        match self {
            ReadoutSpec::FromLens => Some(lens_ms.unwrap_or(0.0)),
            ReadoutSpec::Auto => None,
            ReadoutSpec::Ms(ms) => Some(*ms),
        }
    }
}

/// The stabilizer's parameters and the lens, as a user sets them option by option.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StabilizerOptions {
    /// The stabilizer's parameters (`shutter.readout_ms` is set by the caller
    /// once [`readout`](Self::readout) is resolved against the lens).
    pub params: StabilizerParams,
    /// How the lens is known.
    pub lens: LensSpec,
    /// How the rolling-shutter readout is known.
    pub readout: ReadoutSpec,
    /// Whether `zoom` was set: if not, saccade mode frames as the paper
    /// does (`zoom = none`), the other modes `zoom = auto`.
    pub zoom_given: bool,
}

impl StabilizerOptions {
    /// The defaults with the view in `mode`.
    pub fn with_mode(mode: Mode) -> Self {
        let mut o = Self::default();
        o.params.view.mode = mode;
        o.mode_framing();
        o
    }

    /// The framing a mode has by default, unless `zoom` was set: a fixed
    /// view re-centred when needed (saccade) keeps a fixed crop, the paper's
    /// (`zoom = none`, `margin` from each side, the uncovered edge shown):
    /// a per-frame zoom would move the held view, and the smaller crop budget
    /// of `zoom = auto` made it re-centre twice a second on handheld footage.
    fn mode_framing(&mut self) {
        if !self.zoom_given {
            self.params.framing.zoom = Self::default_zoom(self.params.view.mode);
        }
    }

    /// The framing of `mode` where no zoom is given (see `mode_framing`): every
    /// caller that switches a mode (eval's rows, the demo, the live feed) frames
    /// it as `amc stabilize --mode` does.
    pub fn default_zoom(mode: Mode) -> Zoom {
        if mode == Mode::Saccade {
            Zoom::None
        } else {
            Zoom::Auto
        }
    }

    /// Sets the option `name` (an [`OPTIONS`] name) from its text `value`.
    /// Ranges are checked by [`validate`](Self::validate), once all options are set.
    pub fn set(&mut self, name: &str, value: &str) -> Result<(), AmcError> {
        let spec =
            OPTIONS
                .iter()
                .find(|o| o.name == name)
                .ok_or_else(|| AmcError::UnknownOption {
                    name: name.to_string(),
                    known: OPTIONS
                        .iter()
                        .map(|o| o.name)
                        .collect::<Vec<_>>()
                        .join(", "),
                })?;
        let p = &mut self.params;
        match spec.name {
            "mode" => {
                p.view.mode = value.trim().parse()?;
                self.mode_framing();
            }
            "roll" => p.view.roll = value.trim().parse()?,
            "fov" => self.lens = LensSpec::parse_fov(value)?,
            "readout_ms" => self.readout = ReadoutSpec::parse(value)?,
            "n_avg" => p.render.n_avg = parse_value(spec, value)?,
            "deghost" => p.render.deghost = value.parse()?,
            "antialias" => p.render.antialias = value.trim().parse()?,
            "interpolation" => p.render.interpolation = value.trim().parse()?,
            "n_track" => p.tracker.n_track = parse_value(spec, value)?,
            "margin" => p.render.margin = parse_value(spec, value)?,
            "zoom" => {
                p.framing.zoom = value.trim().parse()?;
                self.zoom_given = true;
            }
            "max_crop" => p.framing.max_crop = parse_value(spec, value)?,
            "track_width" => p.track_width = parse_value(spec, value)?,
            "lookahead" => p.view.lookahead = parse_value(spec, value)?,
            "rate_a" => p.view.rate_a = parse_value(spec, value)?,
            "rate_b" => p.view.rate_b = parse_value(spec, value)?,
            "roll_rate_a" => p.view.roll_rate_a = Some(parse_value(spec, value)?),
            "roll_rate_b" => p.view.roll_rate_b = Some(parse_value(spec, value)?),
            "output_width" => p.render.output_width = Some(parse_value(spec, value)?),
            "output_height" => p.render.output_height = Some(parse_value(spec, value)?),
            other => unreachable!("option {other} is in OPTIONS but has no setter"),
        }
        Ok(())
    }

    /// Checks every parameter against its range.
    pub fn validate(&self) -> Result<(), AmcError> {
        self.params.validate()
    }
}

/// Parses one option's text as a `T`; the error names the option and what it accepts.
fn parse_value<T: std::str::FromStr>(spec: &OptionSpec, value: &str) -> Result<T, AmcError> {
    value
        .trim()
        .parse::<T>()
        .map_err(|_| AmcError::InvalidParameter {
            name: spec.name,
            value: format!("{value:?}"),
            allowed: spec.help,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `allowed` is what the setters and `validate` accept: its bounds and
    /// words pass, values just outside fail, and the help text names the bounds.
    #[test]
    fn allowed_values_are_what_the_setters_accept() {
        let accepts = |name: &str, value: &str| {
            let mut o = StabilizerOptions::default();
            o.set(name, value).and_then(|()| o.validate()).is_ok()
        };
        for spec in OPTIONS {
            let n = spec.name;
            match spec.allowed {
                Allowed::Words(words) => {
                    for w in words {
                        assert!(accepts(n, w), "{n}={w}");
                    }
                    assert!(!accepts(n, "wobble"), "{n}");
                }
                Allowed::Integer { min, max } => {
                    assert!(accepts(n, &min.to_string()), "{n}={min}");
                    assert!(accepts(n, &max.to_string()), "{n}={max}");
                    assert!(!accepts(n, &(max + 1).to_string()), "{n}={}", max + 1);
                    if min > 0 {
                        assert!(!accepts(n, &(min - 1).to_string()), "{n}={}", min - 1);
                    }
                    assert!(!accepts(n, "1.5"), "{n}=1.5");
                    assert!(
                        spec.help.contains(&format!("{min}..={max}")),
                        "{n}: {}",
                        spec.help
                    );
                }
                Allowed::Number {
                    min,
                    max,
                    above_min,
                    words,
                } => {
                    assert_eq!(accepts(n, &min.to_string()), !above_min, "{n}={min}");
                    assert!(accepts(n, &(min + 1e-6).to_string()), "{n}");
                    assert!(accepts(n, &max.to_string()), "{n}={max}");
                    assert!(!accepts(n, &(max + 1e-6 * max.max(1.0)).to_string()), "{n}");
                    assert!(!accepts(n, &(min - 1e-6).to_string()), "{n}");
                    for bad in ["nan", "inf", "x"] {
                        assert!(!accepts(n, bad), "{n}={bad}");
                    }
                    for w in words {
                        assert!(accepts(n, w), "{n}={w}");
                    }
                    assert!(spec.help.contains(&format!("{max}")), "{n}: {}", spec.help);
                }
            }
        }
    }

    /// A word option's placeholder in `--help` names every word it takes (`--mode` once
    /// showed `stabilize|saccade|none` without `lock`).
    #[test]
    fn word_placeholders_name_every_allowed_word() {
        for o in OPTIONS {
            if let Allowed::Words(words) = o.allowed {
                assert_eq!(o.value_name, words.join("|"), "--{}", o.flag);
            }
        }
    }

    #[test]
    fn every_option_has_a_setter_and_a_flag() {
        for spec in OPTIONS {
            let value = match spec.name {
                "mode" => "saccade",
                "roll" => "lock",
                "zoom" => "static",
                "antialias" => "off",
                "interpolation" => "bicubic",
                "max_crop" => "0.3",
                "rate_b" => "30",
                "fov" => "90",
                _ => "20",
            };
            let mut o = StabilizerOptions::default();
            o.set(spec.name, value).unwrap();
            assert_ne!(
                o,
                StabilizerOptions::default(),
                "{} changed nothing",
                spec.name
            );
            assert_eq!(spec.flag, spec.name.replace('_', "-"));
        }
    }

    #[test]
    fn values_land_in_their_fields() {
        let mut o = StabilizerOptions::default();
        for (k, v) in [
            ("mode", "saccade"),
            ("n_avg", "4"),
            ("margin", "0.1"),
            ("fov", "90"),
            ("readout_ms", "14.5"),
            ("lookahead", "3"),
            ("rate_a", "0.5"),
            ("rate_b", "10"),
            ("antialias", "off"),
            ("interpolation", "Bicubic"),
        ] {
            o.set(k, v).unwrap();
        }
        assert_eq!(o.params.render.antialias, crate::render::Antialias::Off);
        assert_eq!(
            o.params.render.interpolation,
            crate::render::Interpolation::Bicubic
        );
        assert_eq!(o.readout, ReadoutSpec::Ms(14.5));
        o.validate().unwrap();
        assert_eq!(o.params.view.mode, Mode::Saccade);
        assert_eq!(o.params.render.n_avg, 4);
        assert_eq!(o.params.view.lookahead, 3);
        assert_eq!(o.params.view.rate_a, 0.5);
        assert_eq!(o.params.view.rate_b, 10.0);
        assert_eq!(o.lens, LensSpec::Fov(90.0));
    }

    #[test]
    fn bad_values_name_the_option_and_its_range() {
        for (k, v) in [
            ("n_avg", "0"),
            ("n_avg", "abc"),
            ("margin", "0.9"),
            ("fov", "500"),
            ("fov", "0"),
            ("fov", "nan"),
            ("readout_ms", "200"),
            ("readout_ms", "-1"),
            ("readout_ms", "abc"),
            ("readout_ms", "inf"),
            ("mode", "wobble"),
            ("lookahead", "100000"),
            ("n_track", "-3"),
            ("rate_a", "-1"),
        ] {
            let mut o = StabilizerOptions::default();
            let msg = match o.set(k, v) {
                Err(e) => e.to_string(),
                Ok(()) => o.validate().unwrap_err().to_string(),
            };
            assert!(msg.contains(k), "{k}={v}: {msg}");
            assert!(msg.contains("allowed"), "{k}={v}: {msg}");
        }
        let e = StabilizerOptions::default().set("bogus", "1").unwrap_err();
        assert!(e.to_string().contains("n_avg"), "{e}");
    }

    #[test]
    fn fov_range_is_the_pinhole_cameras() {
        assert_eq!(LensSpec::parse_fov("AUTO").unwrap(), LensSpec::Auto);
        assert_eq!(LensSpec::parse_fov("179").unwrap(), LensSpec::Fov(179.0));
        assert_eq!(LensSpec::parse_fov("0.5").unwrap(), LensSpec::Fov(0.5));
        assert!(LensSpec::parse_fov("179.5").is_err());
        for deg in [0.5, 179.0] {
            crate::CameraModel::pinhole_hfov(64, 48, deg).unwrap();
        }
    }

    #[test]
    fn readout_is_a_number_or_auto_and_defaults_to_the_lens() {
        assert_eq!(StabilizerOptions::default().readout, ReadoutSpec::FromLens);
        assert_eq!(ReadoutSpec::parse(" Auto ").unwrap(), ReadoutSpec::Auto);
        assert_eq!(ReadoutSpec::parse("0").unwrap(), ReadoutSpec::Ms(0.0));
        assert_eq!(ReadoutSpec::parse("100").unwrap(), ReadoutSpec::Ms(100.0));
        for bad in ["100.5", "-0.1", "nan", "", "fast"] {
            let e = ReadoutSpec::parse(bad).unwrap_err();
            assert!(
                matches!(
                    e,
                    AmcError::InvalidParameter {
                        name: "readout_ms",
                        ..
                    }
                ),
                "{bad}: {e}"
            );
            assert!(e.to_string().contains("0..=100"), "{e}");
        }
        // An explicit option beats the lens file, which beats 0.
        assert_eq!(ReadoutSpec::Ms(5.0).given(Some(12.0)), Some(5.0));
        assert_eq!(ReadoutSpec::FromLens.given(Some(12.0)), Some(12.0));
        assert_eq!(ReadoutSpec::FromLens.given(None), Some(0.0));
        assert_eq!(ReadoutSpec::Auto.given(Some(12.0)), None);
    }
}
