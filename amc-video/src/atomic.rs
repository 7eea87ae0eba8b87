//! The one way outputs are written: into a hidden sibling of the final path
//! (`.NAME.partial-XXXXXX`), renamed onto it only when complete, removed when
//! dropped unfinished, and recorded for [`crate::cleanup::interrupt`] while it
//! exists. Nothing partial is ever left at, or beside, an output path.
//!
//! Outputs get the usual permissions (0666/0777 less the umask), not the
//! private 0600 of temporary files, since they are renamed into place.

use crate::cleanup;
use crate::error::VideoError;
use std::io::Write;
use std::path::{Path, PathBuf};

/// A file being written beside its final path.
pub struct AtomicFile {
    tmp: Option<tempfile::NamedTempFile>,
    path: PathBuf,
}

impl AtomicFile {
    /// Creates the hidden sibling of `path`; `suffix` keeps an extension that a
    /// child process may need to pick the format (`.mp4`). The directory of
    /// `path` must exist.
    pub fn create(path: &Path, suffix: &str) -> Result<Self, VideoError> {
        let dir = parent_dir(path)?;
        let prefix = partial_prefix(path);
        let tmp = cleanup::locked(|registry| {
            let tmp = builder(&prefix, suffix, false).tempfile_in(&dir)?;
            registry.add_partial(tmp.path());
            Ok(tmp)
        })
        // tempfile's error names the temporary file; name the output instead.
        .map_err(|e: std::io::Error| VideoError::io(path, "create output", e))?;
        Ok(Self {
            tmp: Some(tmp),
            path: path.to_path_buf(),
        })
    }

    /// The final path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Where the bytes are being written now (for a child process that writes them).
    pub fn partial_path(&self) -> &Path {
        self.tmp.as_ref().map_or(self.path.as_path(), |t| t.path())
    }

    /// Flushes to disk and renames the file onto its final path.
    pub fn persist(mut self) -> Result<(), VideoError> {
        let Some(tmp) = self.tmp.take() else {
            return Ok(());
        };
        let partial = tmp.path().to_path_buf();
        let path = self.path.clone();
        tmp.as_file()
            .sync_all()
            .map_err(|e| VideoError::io(&path, "write", e))?;
        cleanup::locked(|registry| {
            let result = tmp.persist(&path).map(|_| ());
            registry.remove_partial(&partial);
            result
        })
        .map_err(|e| VideoError::io(&path, "move the finished output into place", e.error))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self.tmp.as_mut() {
            Some(t) => t.write(buf),
            None => Err(std::io::Error::other("the output was already finished")),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.tmp.as_mut().map_or(Ok(()), |t| t.flush())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if let Some(tmp) = self.tmp.take() {
            let partial = tmp.path().to_path_buf();
            drop(tmp); // removes the file
            cleanup::locked(|registry| registry.remove_partial(&partial));
        }
    }
}

/// A directory being filled beside its final path.
pub struct AtomicDir {
    tmp: Option<tempfile::TempDir>,
    path: PathBuf,
}

impl AtomicDir {
    /// Creates the hidden sibling directory of `path`, whose parent must exist.
    pub fn create(path: &Path) -> Result<Self, VideoError> {
        let dir = parent_dir(path)?;
        let prefix = partial_prefix(path);
        let tmp = cleanup::locked(|registry| {
            let tmp = builder(&prefix, "", true).tempdir_in(&dir)?;
            registry.add_partial(tmp.path());
            Ok(tmp)
        })
        .map_err(|e: std::io::Error| VideoError::io(path, "create output directory", e))?;
        Ok(Self {
            tmp: Some(tmp),
            path: path.to_path_buf(),
        })
    }

    /// The directory being filled.
    pub fn partial_path(&self) -> &Path {
        self.tmp.as_ref().map_or(self.path.as_path(), |t| t.path())
    }

    /// Renames the directory onto its final path, which must not exist (or be
    /// an empty directory, which is replaced).
    pub fn persist(mut self) -> Result<(), VideoError> {
        let Some(tmp) = self.tmp.take() else {
            return Ok(());
        };
        let path = self.path.clone();
        if path.is_dir() {
            std::fs::remove_dir(&path).map_err(|e| VideoError::io(&path, "replace", e))?;
        }
        let partial = tmp.path().to_path_buf();
        cleanup::locked(|registry| {
            let result = std::fs::rename(&partial, &path);
            if result.is_ok() {
                // The directory now lives at `path`: stop `TempDir` from deleting it.
                let _ = tmp.keep();
                registry.remove_partial(&partial);
            }
            result
        })
        .map_err(|e| VideoError::io(&path, "move the finished output into place", e))
    }
}

impl Drop for AtomicDir {
    fn drop(&mut self) {
        if let Some(tmp) = self.tmp.take() {
            let partial = tmp.path().to_path_buf();
            drop(tmp); // removes the directory and its files
            cleanup::locked(|registry| registry.remove_partial(&partial));
        }
    }
}

/// Writes `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), VideoError> {
    let mut f = AtomicFile::create(path, "")?;
    f.write_all(bytes)
        .map_err(|e| VideoError::io(path, "write", e))?;
    f.persist()
}

/// The directory a sibling of `path` goes in; it must exist.
pub(crate) fn parent_dir(path: &Path) -> Result<PathBuf, VideoError> {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !parent.is_dir() {
        return Err(VideoError::io(
            path,
            "create output",
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("directory {} does not exist", parent.display()),
            ),
        ));
    }
    Ok(parent)
}

/// `.NAME.partial-` prefix for the hidden sibling of `path`.
fn partial_prefix(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    format!(".{name}.partial-")
}

/// A `tempfile` builder for the hidden sibling, with an output's permissions.
fn builder<'a>(prefix: &'a str, suffix: &'a str, is_dir: bool) -> tempfile::Builder<'a, 'a> {
    let mut b = tempfile::Builder::new();
    b.prefix(prefix).suffix(suffix);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        b.permissions(std::fs::Permissions::from_mode(if is_dir {
            0o777
        } else {
            0o666
        }));
    }
    #[cfg(not(unix))]
    let _ = is_dir;
    b
}
