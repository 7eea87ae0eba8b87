//! A setting outside what it allows: the one error every part's settings
//! (service, access, listener, worker) share, so checking a flag's value
//! depends on nothing else of the crate.

/// A flag's value and what it allows.
#[derive(Debug, thiserror::Error)]
#[error("invalid --{flag}: {detail}")]
pub struct InvalidSetting {
    /// The setting's flag, without dashes.
    pub flag: &'static str,
    /// The value and what is allowed.
    pub detail: String,
}

/// `value` within `lo..=hi`, else an [`InvalidSetting`] naming `--flag`.
pub fn check<T: PartialOrd + std::fmt::Display>(
    flag: &'static str,
    value: T,
    lo: T,
    hi: T,
) -> Result<(), InvalidSetting> {
    if value < lo || value > hi {
        return Err(InvalidSetting {
            flag,
            detail: format!("{value} (allowed: {lo}..={hi})"),
        });
    }
    Ok(())
}
