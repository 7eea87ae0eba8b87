//! The one way outputs are written: into a hidden sibling of the final path
//! (`.NAME.partial-XXXXXX`), renamed onto it only when complete, removed when
//! dropped unfinished, and recorded for [`crate::cleanup::interrupt`] while it
//! exists. Nothing partial is ever left at, or beside, an output path.
//!
//! Outputs get the usual permissions (0666/0777 less the umask), not the
//! private 0600 of temporary files, since they are renamed into place.

use crate::cleanup;
use crate::direct::Staging;
use crate::error::VideoError;
use std::io::Write;
use std::path::{Path, PathBuf};

/// A file being written beside its final path.
pub struct AtomicFile {
    tmp: Option<tempfile::NamedTempFile>,
    path: PathBuf,
    /// Bytes written so far, and how many of them the disk was asked to take.
    written: u64,
    writeback_from: u64,
    /// Staged bytes, when the file is written past the page cache
    /// ([`AtomicFile::write_direct`]).
    direct: Option<Staging>,
}

/// Bytes written between two requests to start their writeback: a large
/// output (a 720p `.y4m` is 1.4 MB a frame) then reaches the disk while the
/// run goes on, instead of all at once in [`AtomicFile::persist`]'s flush.
const WRITEBACK_CHUNK: u64 = 16 << 20;

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
            written: 0,
            writeback_from: 0,
            direct: None,
        })
    }

    /// Writes this file past the page cache where the file system allows
    /// (see `direct.rs`): for large streamed outputs (`.y4m`), whose bytes
    /// nobody reads back during the run. Call before the first write;
    /// elsewhere the file stays buffered.
    pub fn write_direct(&mut self) {
        if let (Some(t), 0) = (self.tmp.as_ref(), self.written) {
            self.direct = Staging::enable(t.as_file());
        }
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
        let Some(mut tmp) = self.tmp.take() else {
            return Ok(());
        };
        let partial = tmp.path().to_path_buf();
        let path = self.path.clone();
        if let Some(staged) = self.direct.as_mut() {
            staged
                .finish(tmp.as_file_mut())
                .map_err(|e| VideoError::io(&path, "write", e))?;
        }
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
        let Some(t) = self.tmp.as_mut() else {
            return Err(std::io::Error::other("the output was already finished"));
        };
        if let Some(staged) = self.direct.as_mut() {
            staged.write(t.as_file_mut(), buf)?;
            self.written += buf.len() as u64;
            return Ok(buf.len());
        }
        let n = t.write(buf)?;
        self.written += n as u64;
        if self.written - self.writeback_from >= WRITEBACK_CHUNK {
            start_writeback(t.as_file(), self.writeback_from, self.written);
            self.writeback_from = self.written;
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.tmp.as_mut().map_or(Ok(()), |t| t.flush())
    }
}

/// Asks the kernel to start writing bytes `from..to` of `file` to disk,
/// without waiting for it (Linux's `sync_file_range`); a hint only, so a
/// failure is ignored: [`AtomicFile::persist`] still flushes everything.
#[cfg(target_os = "linux")]
fn start_writeback(file: &std::fs::File, from: u64, to: u64) {
    use std::os::fd::AsRawFd;
    let (Ok(offset), Ok(len)) = (i64::try_from(from), i64::try_from(to - from)) else {
        return;
    };
    // SAFETY: a plain system call on an open descriptor this file owns; it
    // reads no memory of ours.
    unsafe {
        libc::sync_file_range(file.as_raw_fd(), offset, len, libc::SYNC_FILE_RANGE_WRITE);
    }
}

#[cfg(not(target_os = "linux"))]
fn start_writeback(_file: &std::fs::File, _from: u64, _to: u64) {}

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

#[cfg(test)]
mod tests {
    use super::*;

    /// An output larger than a few writeback chunks, written in odd-sized
    /// pieces, reads back whole once persisted; unfinished, nothing is left.
    #[test]
    fn a_large_output_is_written_whole_with_its_writeback_started_early() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.bin");
        let piece: Vec<u8> = (0..1_000_003u32).map(|i| (i % 251) as u8).collect();
        let pieces = 3 * (WRITEBACK_CHUNK as usize) / piece.len() + 2;
        let mut file = AtomicFile::create(&path, "").unwrap();
        for _ in 0..pieces {
            file.write_all(&piece).unwrap();
        }
        assert!(file.writeback_from >= 3 * WRITEBACK_CHUNK);
        assert!(file.written - file.writeback_from < WRITEBACK_CHUNK);
        file.persist().unwrap();
        let back = std::fs::read(&path).unwrap();
        assert_eq!(back.len(), pieces * piece.len());
        assert!(back.chunks(piece.len()).all(|c| c == piece.as_slice()));

        let unfinished = dir.path().join("unfinished.bin");
        let mut file = AtomicFile::create(&unfinished, "").unwrap();
        for _ in 0..pieces {
            file.write_all(&piece).unwrap();
        }
        drop(file);
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "only the finished output: {left:?}");
    }
}
