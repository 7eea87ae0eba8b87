//! Query options of `POST /stabilize` and `POST /jobs`, named like the
//! command line's flags (`n_avg` for `--n-avg`). The stabilizer's options are
//! set through [`amc_core::options`], the one definition the CLI and the WASM
//! API use too; only `format` and `metrics` are the service's own.

use super::problem::ApiError;
use amc_core::options::{Allowed, OPTIONS as STABILIZER_OPTIONS};
use amc_core::StabilizerOptions;

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

    /// The format of an extension (`mp4`, `webm`).
    pub fn from_extension(ext: &str) -> Option<Self> {
        [OutputFormat::Mp4, OutputFormat::Webm]
            .into_iter()
            .find(|f| f.extension() == ext)
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
    /// The stabilizer's parameters and the lens (`fov=DEG|auto`; a `lens`
    /// form field overrides it).
    pub stabilizer: StabilizerOptions,
    /// The container of the result.
    pub format: OutputFormat,
    /// Measure the paper's image metrics (normal flow, frame change, sharpness).
    pub measure: bool,
    /// `gyro=auto` (the default): use the clip's own IMU track (GoPro, Sony,
    /// DJI, Insta360) when it has one, synchronized and fused as the CLI's
    /// `--gyro auto` does, or the `gyro` form field's log when one is sent;
    /// `gyro=off`: the picture alone (and a `gyro` form field is refused).
    pub gyro: bool,
}

/// The service's own options: name, help, allowed values.
pub const SERVICE_OPTIONS: &[(&str, &str, Allowed)] = &[
    (
        "format",
        "mp4 or webm (default mp4)",
        Allowed::Words(&["mp4", "webm"]),
    ),
    (
        "metrics",
        "true or false: measure normal flow, frame change and sharpness (default true)",
        Allowed::Words(&["true", "false"]),
    ),
    (
        "gyro",
        "auto or off: use the clip's own gyro track (GoPro, Sony, DJI, Insta360), synchronized from the video and fused with it, as the CLI's --gyro auto (default auto); a `gyro` form field (a log file) is used instead of the track, and cannot go with off",
        Allowed::Words(&["auto", "off"]),
    ),
];

/// Every option a request may carry, with its allowed values (for the OpenAPI document).
pub fn all_options() -> Vec<(&'static str, &'static str, Allowed)> {
    STABILIZER_OPTIONS
        .iter()
        .map(|o| (o.name, o.help, o.allowed))
        .chain(SERVICE_OPTIONS.iter().copied())
        .collect()
}

impl JobOptions {
    /// Parses a raw query string (`None` or empty: all defaults).
    pub fn from_query(query: Option<&str>) -> Result<Self, ApiError> {
        let mut stabilizer = StabilizerOptions::default();
        let mut format = OutputFormat::Mp4;
        let mut measure = true;
        let mut gyro = true;
        for (key, value) in form_urlencoded::parse(query.unwrap_or("").as_bytes()) {
            let value = value.as_ref();
            match key.as_ref() {
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
                "metrics" => {
                    measure = value.trim().parse::<bool>().map_err(|_| {
                        ApiError::BadOption(format!(
                            "invalid metrics: {value:?} (allowed: true or false)"
                        ))
                    })?
                }
                "gyro" => {
                    gyro = match value.trim().to_ascii_lowercase().as_str() {
                        "auto" => true,
                        "off" => false,
                        _ => {
                            return Err(ApiError::BadOption(format!(
                                "invalid gyro: {value:?} (allowed: auto or off)"
                            )))
                        }
                    }
                }
                name if STABILIZER_OPTIONS.iter().any(|o| o.name == name) => stabilizer
                    .set(name, value)
                    .map_err(|e| ApiError::BadOption(e.to_string()))?,
                other => {
                    let names: Vec<_> = all_options().iter().map(|(n, ..)| *n).collect();
                    return Err(ApiError::BadOption(format!(
                        "unknown option {other:?} (known: {})",
                        names.join(", ")
                    )));
                }
            }
        }
        stabilizer
            .validate()
            .map_err(|e| ApiError::BadOption(e.to_string()))?;
        Ok(Self {
            stabilizer,
            format,
            measure,
            gyro,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use amc_core::LensSpec;

    #[test]
    fn defaults_and_values() {
        let o = JobOptions::from_query(None).unwrap();
        assert_eq!(o.stabilizer, StabilizerOptions::default());
        assert_eq!(o.format, OutputFormat::Mp4);
        let o = JobOptions::from_query(Some(
            "mode=saccade&n_avg=4&margin=0.1&fov=90&lookahead=3&format=webm&metrics=false&rate_a=0.5",
        ))
        .unwrap();
        assert_eq!(o.stabilizer.params.view.mode, amc_core::Mode::Saccade);
        assert_eq!(o.stabilizer.params.render.n_avg, 4);
        assert_eq!(o.stabilizer.params.view.lookahead, 3);
        assert_eq!(o.stabilizer.lens, LensSpec::Fov(90.0));
        assert_eq!(o.format, OutputFormat::Webm);
        assert!(!o.measure);
        assert!(o.gyro);
        assert!(!JobOptions::from_query(Some("gyro=off")).unwrap().gyro);
        assert_eq!(o.stabilizer.readout, amc_core::ReadoutSpec::FromLens);
        for (q, want) in [
            ("readout_ms=auto", amc_core::ReadoutSpec::Auto),
            ("readout_ms=16.7", amc_core::ReadoutSpec::Ms(16.7)),
        ] {
            assert_eq!(
                JobOptions::from_query(Some(q)).unwrap().stabilizer.readout,
                want
            );
        }
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
            ("readout_ms=abc", "readout_ms"),
            ("readout_ms=100.5", "readout_ms"),
            ("gyro=maybe", "gyro"),
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
