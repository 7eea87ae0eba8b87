//! Query options of `POST /stabilize` and `POST /jobs`, named like the
//! command line's flags (`n_avg` for `--n-avg`). They fill the same
//! [`StabilizerParams`] the CLI and the WASM API use, and are checked by its
//! `validate()`, so every range is stated once.

use super::problem::ApiError;
use crate::cli::LensChoice;
use amc_core::view::Mode;
use amc_core::StabilizerParams;

/// Container of the stabilized video.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// H.264 in MP4 (the input's audio copied, or AAC).
    Mp4,
    /// VP9 in WebM (Opus audio).
    Webm,
}

impl OutputFormat {
    pub fn extension(self) -> &'static str {
        match self {
            OutputFormat::Mp4 => "mp4",
            OutputFormat::Webm => "webm",
        }
    }

    pub fn content_type(self) -> &'static str {
        match self {
            OutputFormat::Mp4 => "video/mp4",
            OutputFormat::Webm => "video/webm",
        }
    }
}

/// Everything a request may set.
#[derive(Clone, Debug)]
pub struct JobOptions {
    pub params: StabilizerParams,
    /// `fov=DEG|auto`; a `lens` form field overrides it.
    pub lens: LensChoice,
    pub format: OutputFormat,
    /// Measure the paper's image metrics (normal flow, frame change, sharpness).
    pub measure: bool,
}

/// The options a request may carry, with their allowed values (also used in the OpenAPI document).
pub const OPTIONS: &[(&str, &str)] = &[
    ("mode", "stabilize, saccade or none (default stabilize)"),
    (
        "n_avg",
        "frames averaged into each output frame, 1..=64 (default 6)",
    ),
    (
        "n_track",
        "template reset period in frames, 1..=1000 (default 5)",
    ),
    (
        "margin",
        "share cropped from each side, 0..=0.45 (default 0.125)",
    ),
    (
        "fov",
        "horizontal field of view in degrees, 1 < DEG < 179, or auto (default auto)",
    ),
    (
        "lookahead",
        "future frames used to smooth the view, 0..=240 (default 0)",
    ),
    (
        "track_width",
        "width of the tracking image in pixels, 32..=8192 (default 320)",
    ),
    (
        "output_width",
        "output width in pixels (default: the cropped input width)",
    ),
    (
        "output_height",
        "output height in pixels (default: keeps the aspect ratio)",
    ),
    ("format", "mp4 or webm (default mp4)"),
    (
        "metrics",
        "true or false: measure normal flow, frame change and sharpness (default true)",
    ),
];

fn parse_num<T: std::str::FromStr>(name: &str, value: &str) -> Result<T, ApiError> {
    value.trim().parse::<T>().map_err(|_| {
        let allowed = OPTIONS
            .iter()
            .find(|(n, _)| *n == name)
            .map_or("", |(_, a)| *a);
        ApiError::BadOption(format!("invalid {name}: {value:?} (allowed: {allowed})"))
    })
}

impl JobOptions {
    /// Parses a raw query string (`None` or empty: all defaults).
    pub fn from_query(query: Option<&str>) -> Result<Self, ApiError> {
        let mut params = StabilizerParams::default();
        let mut lens = LensChoice::Auto;
        let mut format = OutputFormat::Mp4;
        let mut measure = true;
        for (key, value) in form_urlencoded::parse(query.unwrap_or("").as_bytes()) {
            let value = value.as_ref();
            match key.as_ref() {
                "mode" => {
                    params.view.mode = value
                        .parse::<Mode>()
                        .map_err(|e| ApiError::BadOption(e.to_string()))?
                }
                "n_avg" => params.render.n_avg = parse_num("n_avg", value)?,
                "n_track" => params.tracker.n_track = parse_num("n_track", value)?,
                "margin" => params.render.margin = parse_num("margin", value)?,
                "lookahead" => params.view.lookahead = parse_num("lookahead", value)?,
                "track_width" => params.track_width = parse_num("track_width", value)?,
                "output_width" => {
                    params.render.output_width = Some(parse_num("output_width", value)?)
                }
                "output_height" => {
                    params.render.output_height = Some(parse_num("output_height", value)?)
                }
                "fov" => {
                    lens = if value.eq_ignore_ascii_case("auto") {
                        LensChoice::Auto
                    } else {
                        match value.trim().parse::<f64>() {
                            Ok(v) if v.is_finite() && v > 1.0 && v < 179.0 => LensChoice::Fov(v),
                            _ => {
                                return Err(ApiError::BadOption(format!(
                                    "invalid fov: {value:?} (allowed: a horizontal field of view in degrees, 1 < DEG < 179, or auto)"
                                )))
                            }
                        }
                    }
                }
                "format" => {
                    format = match value.to_ascii_lowercase().as_str() {
                        "mp4" => OutputFormat::Mp4,
                        "webm" => OutputFormat::Webm,
                        _ => {
                            return Err(ApiError::BadOption(format!(
                                "invalid format: {value:?} (allowed: mp4 or webm)"
                            )))
                        }
                    }
                }
                "metrics" => measure = parse_num::<bool>("metrics", value)?,
                other => {
                    let names: Vec<_> = OPTIONS.iter().map(|(n, _)| *n).collect();
                    return Err(ApiError::BadOption(format!(
                        "unknown option {other:?} (known: {})",
                        names.join(", ")
                    )));
                }
            }
        }
        if params.view.lookahead > 240 {
            return Err(ApiError::BadOption(format!(
                "invalid lookahead: {} (allowed: 0..=240 frames)",
                params.view.lookahead
            )));
        }
        params
            .validate()
            .map_err(|e| ApiError::BadOption(e.to_string()))?;
        Ok(Self {
            params,
            lens,
            format,
            measure,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_values() {
        let o = JobOptions::from_query(None).unwrap();
        assert_eq!(o.params, StabilizerParams::default());
        assert_eq!(o.lens, LensChoice::Auto);
        assert_eq!(o.format, OutputFormat::Mp4);
        let o = JobOptions::from_query(Some(
            "mode=saccade&n_avg=4&margin=0.1&fov=90&lookahead=3&format=webm&metrics=false",
        ))
        .unwrap();
        assert_eq!(o.params.view.mode, Mode::Saccade);
        assert_eq!(o.params.render.n_avg, 4);
        assert_eq!(o.params.view.lookahead, 3);
        assert_eq!(o.lens, LensChoice::Fov(90.0));
        assert_eq!(o.format, OutputFormat::Webm);
        assert!(!o.measure);
    }

    #[test]
    fn bad_options_name_the_option_and_range() {
        for (q, needle) in [
            ("n_avg=0", "n_avg"),
            ("n_avg=abc", "n_avg"),
            ("margin=0.9", "margin"),
            ("fov=500", "fov"),
            ("fov=nan", "fov"),
            ("mode=wobble", "mode"),
            ("format=gif", "format"),
            ("lookahead=100000", "lookahead"),
            ("bogus=1", "unknown option"),
            ("n_track=-3", "n_track"),
        ] {
            let e = JobOptions::from_query(Some(q)).unwrap_err();
            assert!(matches!(e, ApiError::BadOption(_)), "{q}");
            let msg = e.to_string();
            assert!(msg.contains(needle), "{q}: {msg}");
            assert!(
                msg.contains("allowed") || msg.contains("known"),
                "{q}: {msg}"
            );
        }
    }
}
