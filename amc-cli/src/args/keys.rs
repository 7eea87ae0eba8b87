//! `amc keys`: API keys for `amc serve --auth-keys`.

use clap::{Args, Subcommand};

/// `amc keys` options.
#[derive(Args, Debug, Clone)]
pub struct KeysArgs {
    #[command(subcommand)]
    pub command: KeysCommand,
}

/// What to do with keys.
#[derive(Subcommand, Debug, Clone)]
pub enum KeysCommand {
    /// Print a fresh random key (shown once: give it to its user) and, on the
    /// next line, its line for the --auth-keys file (it holds only the key's
    /// SHA-256); with --append FILE, append that line and print only the key.
    New {
        /// The tenant the key belongs to (1-64 of A-Z, a-z, 0-9, _ . -);
        /// a tenant sees only its own jobs.
        tenant: String,
        /// A comma list of submit (POST /stabilize, /jobs), view (/live),
        /// publish (/live/ingest), admin (every tenant's jobs, /metrics).
        roles: String,
        /// Append the line to this keys file (created, readable by its owner
        /// only, if missing) instead of printing it.
        #[arg(long, value_name = "FILE")]
        append: Option<std::path::PathBuf>,
    },
}
