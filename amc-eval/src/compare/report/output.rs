//! Writing the report's files and naming them.

use crate::compare::error::CompareError;
use std::path::Path;

/// Writes `bytes` to `path` atomically, readable by everyone (0644), like the plots.
pub(super) fn write_public(path: &Path, bytes: &[u8]) -> Result<(), CompareError> {
    amc_video::write_atomic(path, bytes)?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o644))
            .map_err(|e| CompareError::io(path, e))?;
    }
    Ok(())
}

pub(super) fn file_stem(clip: &str) -> String {
    clip.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}
