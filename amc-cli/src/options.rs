//! The stabilizer's flags, generated from the one definition of each option
//! in [`amc_core::options::OPTIONS`] (`--n-avg` is the REST API's `n_avg`).

use amc_core::options::OPTIONS;
use amc_core::{LensSpec, Mode, StabilizerOptions};
use clap::{Arg, ArgMatches, Args, Command, FromArgMatches};
use std::path::PathBuf;

/// The stabilizer options given on the command line, as text, in table order.
#[derive(Clone, Debug, Default)]
pub struct StabilizerFlags {
    values: Vec<(&'static str, String)>,
}

impl StabilizerFlags {
    /// The options for `mode` (unless `--mode` overrides it), with the lens
    /// from `--lens FILE` when given.
    pub fn options(
        &self,
        mode: Mode,
        lens_file: Option<&PathBuf>,
    ) -> Result<StabilizerOptions, amc_core::AmcError> {
        let mut o = StabilizerOptions::with_mode(mode);
        for (name, value) in &self.values {
            o.set(name, value)?;
        }
        if let Some(p) = lens_file {
            o.lens = LensSpec::File(p.clone());
        }
        o.validate()?;
        Ok(o)
    }

    /// Whether the option `name` (as in [`OPTIONS`]) was given.
    pub fn has(&self, name: &str) -> bool {
        self.values.iter().any(|(n, _)| *n == name)
    }
}

impl FromArgMatches for StabilizerFlags {
    fn from_arg_matches(m: &ArgMatches) -> Result<Self, clap::Error> {
        let values = OPTIONS
            .iter()
            .filter_map(|o| m.get_one::<String>(o.name).map(|v| (o.name, v.clone())))
            .collect();
        Ok(Self { values })
    }

    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(m)?;
        Ok(())
    }
}

impl Args for StabilizerFlags {
    fn augment_args(cmd: Command) -> Command {
        OPTIONS.iter().fold(cmd, |cmd, o| {
            cmd.arg(
                Arg::new(o.name)
                    .long(o.flag)
                    .value_name(o.value_name)
                    .help(o.help)
                    .allow_negative_numbers(true),
            )
        })
    }

    fn augment_args_for_update(cmd: Command) -> Command {
        Self::augment_args(cmd)
    }
}
