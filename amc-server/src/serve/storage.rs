//! Scratch space for uploads and results, bounded by a disk budget.
//!
//! Every request or job gets its own [`Scratch`] folder under the service's
//! work directory. The folder and its share of the budget go away together
//! when the `Scratch` is dropped, so no file outlives its request or job,
//! whatever path (success, error, cancel, disconnect, panic) ends it.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Bytes the service's scratch files may use together (`--max-disk-mb`).
#[derive(Debug)]
pub struct DiskBudget {
    used: AtomicU64,
    max: u64,
}

impl DiskBudget {
    pub fn new(max: u64) -> Self {
        Self {
            used: AtomicU64::new(0),
            max,
        }
    }

    pub fn used(&self) -> u64 {
        self.used.load(Ordering::SeqCst)
    }

    /// Takes `n` bytes if they fit.
    fn try_take(&self, n: u64) -> bool {
        self.used
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |u| {
                u.checked_add(n).filter(|&t| t <= self.max)
            })
            .is_ok()
    }

    /// Takes `n` bytes whether or not they fit (files already written).
    fn take(&self, n: u64) {
        self.used.fetch_add(n, Ordering::SeqCst);
    }

    fn give_back(&self, n: u64) {
        let _ = self
            .used
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |u| {
                Some(u.saturating_sub(n))
            });
    }
}

/// A private folder with the bytes it holds counted against the budget.
#[derive(Debug)]
pub struct Scratch {
    dir: tempfile::TempDir,
    budget: Arc<DiskBudget>,
    bytes: AtomicU64,
}

impl Scratch {
    /// Creates a fresh folder under `root`.
    pub fn new(root: &Path, budget: Arc<DiskBudget>) -> std::io::Result<Self> {
        let dir = tempfile::Builder::new().prefix("req-").tempdir_in(root)?;
        Ok(Self {
            dir,
            budget,
            bytes: AtomicU64::new(0),
        })
    }

    #[cfg(test)]
    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    pub fn file(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// Counts `n` more bytes about to be written; false when the budget is used up.
    pub fn reserve(&self, n: u64) -> bool {
        if self.budget.try_take(n) {
            self.bytes.fetch_add(n, Ordering::SeqCst);
            true
        } else {
            false
        }
    }

    /// Counts a file that was written without a reservation (an output).
    pub fn account(&self, path: &Path) {
        if let Ok(m) = std::fs::metadata(path) {
            self.budget.take(m.len());
            self.bytes.fetch_add(m.len(), Ordering::SeqCst);
        }
    }

    /// Removes a file early (the upload, once processed) and returns its bytes.
    pub fn remove(&self, path: &Path) {
        if let Ok(m) = std::fs::metadata(path) {
            if std::fs::remove_file(path).is_ok() {
                let n = m.len().min(self.bytes.load(Ordering::SeqCst));
                self.bytes.fetch_sub(n, Ordering::SeqCst);
                self.budget.give_back(n);
            }
        }
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        self.budget.give_back(self.bytes.load(Ordering::SeqCst));
        // TempDir removes the folder right after this.
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budget_is_bounded_and_returned() {
        let root = tempfile::tempdir().unwrap();
        let budget = Arc::new(DiskBudget::new(100));
        let a = Scratch::new(root.path(), budget.clone()).unwrap();
        assert!(a.reserve(60));
        let b = Scratch::new(root.path(), budget.clone()).unwrap();
        assert!(!b.reserve(50));
        assert!(b.reserve(40));
        assert_eq!(budget.used(), 100);
        let path = a.path().to_path_buf();
        drop(a);
        assert!(!path.exists());
        assert_eq!(budget.used(), 40);
        drop(b);
        assert_eq!(budget.used(), 0);
    }
}
