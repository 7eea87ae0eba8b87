//! What a run's gyro log does to its rolling-shutter readout: the readout
//! the camera recorded (GoPro's SROT, Sony, DJI, Insta360, a `.gcsv`'s
//! `frame_readout_time`) answers `readout_ms=auto` better than an estimate
//! and stands in for the unset default where the lens file states none.
//! Where the log records none, `auto` and the unset default (where the lens
//! file states none either) are measured against the log in the gyro run's
//! first pass ([`RunConfig::measure_readout`](super::RunConfig)): a flight
//! controller's log is how its camera's rows are corrected, and assuming a
//! global shutter would leave them bent. One rule for the CLI and the service.

use super::gyro::GyroLog;
use amc_core::plan::{ReadoutNote, ResolvedReadout};
use amc_core::ReadoutSpec;

/// A run's readout as its gyro log shapes it.
#[derive(Clone, Debug, PartialEq)]
pub enum LogReadout {
    /// The log changes nothing: no log, a readout given in milliseconds.
    Keep,
    /// The camera recorded its readout.
    Recorded {
        /// Milliseconds.
        readout_ms: f64,
        /// What read the log.
        source: String,
    },
    /// The log records none: measured against it (`auto`, or the unset
    /// default where the lens file states none either).
    Measure,
}

/// How a gyro run measures the readout against its log, and what it falls
/// back to where the log does not pin it down.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeasureReadout {
    /// `readout_ms=auto`: else the picture's own estimate (the readout
    /// pass's, made in the same first pass), else a global shutter, warned.
    Auto,
    /// Unset: else the run's readout (0: a global shutter), as the default.
    Unset,
}

impl LogReadout {
    /// What `log` does to the readout the user asked for.
    pub fn choose(asked: &ReadoutSpec, log: Option<&GyroLog>) -> Self {
        let Some(log) = log else {
            return LogReadout::Keep;
        };
        match (asked, log.readout_ms) {
            (ReadoutSpec::Ms(_), _) => LogReadout::Keep,
            (_, Some(readout_ms)) => LogReadout::Recorded {
                readout_ms,
                source: log.source.clone(),
            },
            (_, None) => LogReadout::Measure,
        }
    }

    /// The readout to resolve the lens with: a recorded one answers `auto`
    /// without the estimate's pass, and so does a measured one (the gyro
    /// run's first pass makes the estimate the fallback needs).
    pub fn spec(&self, asked: &ReadoutSpec) -> ReadoutSpec {
        match (self, asked) {
            (LogReadout::Recorded { readout_ms, .. }, ReadoutSpec::Auto) => {
                ReadoutSpec::Ms(*readout_ms)
            }
            (LogReadout::Measure, ReadoutSpec::Auto) => ReadoutSpec::FromLens,
            _ => asked.clone(),
        }
    }

    /// Applies a recorded readout to what the lens and the readout pass
    /// resolved (`auto`, or the default where the lens file states none);
    /// the line to show, when it did.
    pub fn apply(&self, asked: &ReadoutSpec, resolved: &mut ResolvedReadout) -> Option<String> {
        let LogReadout::Recorded { readout_ms, source } = self else {
            return None;
        };
        let applies = match asked {
            ReadoutSpec::Auto => true,
            ReadoutSpec::FromLens => resolved.note == ReadoutNote::Given,
            ReadoutSpec::Ms(_) => false,
        };
        if !applies {
            return None;
        }
        resolved.readout_ms = *readout_ms;
        resolved.note = ReadoutNote::Given;
        Some(format!(
            "readout: {readout_ms:.1} ms (recorded by the camera: {source})"
        ))
    }

    /// Whether and how the run measures the readout against the log, once
    /// the lens is resolved (`resolved`: with [`LogReadout::spec`]'s readout).
    pub fn measure(
        &self,
        asked: &ReadoutSpec,
        resolved: &ResolvedReadout,
    ) -> Option<MeasureReadout> {
        if *self != LogReadout::Measure {
            return None;
        }
        match asked {
            ReadoutSpec::Auto => Some(MeasureReadout::Auto),
            // A lens file that states its readout answers the default.
            ReadoutSpec::FromLens if resolved.note == ReadoutNote::Given => {
                Some(MeasureReadout::Unset)
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use amc_core::gyro::GyroSamples;

    fn log(readout_ms: Option<f64>) -> GyroLog {
        GyroLog {
            source: "test.gcsv".into(),
            time_base: "the log's own timestamps",
            samples: GyroSamples {
                t: vec![],
                w: vec![],
            },
            video_clock: false,
            readout_ms,
        }
    }

    #[test]
    fn a_recorded_readout_answers_auto_and_the_unset_default() {
        let l = log(Some(8.5));
        let c = LogReadout::choose(&ReadoutSpec::Auto, Some(&l));
        assert_eq!(c.spec(&ReadoutSpec::Auto), ReadoutSpec::Ms(8.5));
        let mut r = ResolvedReadout {
            readout_ms: 0.0,
            note: ReadoutNote::Given,
        };
        assert!(c.apply(&ReadoutSpec::Auto, &mut r).is_some());
        assert_eq!(r.readout_ms, 8.5);
        // The default with a lens file that states its own keeps the file's.
        let c = LogReadout::choose(&ReadoutSpec::FromLens, Some(&l));
        let mut r = ResolvedReadout {
            readout_ms: 12.0,
            note: ReadoutNote::FromLens,
        };
        assert!(c.apply(&ReadoutSpec::FromLens, &mut r).is_none());
        assert_eq!(r.readout_ms, 12.0);
        // A readout given in milliseconds stands.
        let c = LogReadout::choose(&ReadoutSpec::Ms(3.0), Some(&l));
        assert_eq!(c, LogReadout::Keep);
    }

    #[test]
    fn a_log_that_records_none_measures_auto_and_the_unset_default() {
        let l = log(None);
        let unset = ResolvedReadout {
            readout_ms: 0.0,
            note: ReadoutNote::Given,
        };
        let lens_file = ResolvedReadout {
            readout_ms: 12.0,
            note: ReadoutNote::FromLens,
        };
        let auto = LogReadout::choose(&ReadoutSpec::Auto, Some(&l));
        // The picture's own pass is left to the gyro run's first pass.
        assert_eq!(auto.spec(&ReadoutSpec::Auto), ReadoutSpec::FromLens);
        assert_eq!(
            auto.measure(&ReadoutSpec::Auto, &lens_file),
            Some(MeasureReadout::Auto)
        );
        let default = LogReadout::choose(&ReadoutSpec::FromLens, Some(&l));
        assert_eq!(
            default.measure(&ReadoutSpec::FromLens, &unset),
            Some(MeasureReadout::Unset)
        );
        assert_eq!(default.measure(&ReadoutSpec::FromLens, &lens_file), None);
        let given = LogReadout::choose(&ReadoutSpec::Ms(5.0), Some(&l));
        assert_eq!(given.measure(&ReadoutSpec::Ms(5.0), &unset), None);
        let none = LogReadout::choose(&ReadoutSpec::Auto, None);
        assert_eq!(none.measure(&ReadoutSpec::Auto, &unset), None);
    }
}
