//! What to undo if the process is interrupted: the partial outputs being
//! written and the ffmpeg children running.
//!
//! Dropping a source or sink already kills its children and removes its
//! partial file, but a signal (Ctrl-C, SIGTERM from `timeout` or a service
//! manager) ends the process without running destructors. Every partial
//! output and child registers here while it exists, so a signal handler can
//! call [`interrupt`] and exit without leaving files or processes behind.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// The partial outputs and children alive right now.
pub(crate) struct Registry {
    partials: Vec<PathBuf>,
    children: Vec<u32>,
}

static REGISTRY: Mutex<Registry> = Mutex::new(Registry {
    partials: Vec::new(),
    children: Vec::new(),
});

/// The registry, ignoring poisoning (it holds plain paths and ids).
fn registry() -> MutexGuard<'static, Registry> {
    REGISTRY.lock().unwrap_or_else(|e| e.into_inner())
}

/// Runs `f` with the registry locked, so that a signal handler's [`interrupt`]
/// sees either the state before or after `f`, never half of it (a partial
/// created but not yet recorded, or renamed into place but still recorded).
pub(crate) fn locked<T>(f: impl FnOnce(&mut Registry) -> T) -> T {
    f(&mut registry())
}

impl Registry {
    /// Records a partial output (file or directory) that exists until it is
    /// renamed into place or removed.
    pub(crate) fn add_partial(&mut self, path: &Path) {
        self.partials.push(path.to_path_buf());
    }

    /// Forgets a partial output (it was renamed into place or removed).
    pub(crate) fn remove_partial(&mut self, path: &Path) {
        self.partials.retain(|p| p != path);
    }

    /// Records a running child process.
    pub(crate) fn add_child(&mut self, pid: u32) {
        self.children.push(pid);
    }

    /// Forgets a child process (it was reaped).
    pub(crate) fn remove_child(&mut self, pid: u32) {
        self.children.retain(|&p| p != pid);
    }
}

/// Kills every child still registered (SIGKILL), for a process that is about
/// to exit with threads still blocked on them: a live source's ffmpeg waiting
/// on a network stream that went quiet never notices its reader has gone,
/// and would outlive the process. Returns how many it killed.
pub fn kill_children() -> usize {
    kill_all(&registry().children)
}

/// SIGKILL to each of `children`; returns how many.
fn kill_all(children: &[u32]) -> usize {
    for &pid in children {
        #[cfg(unix)]
        // SAFETY: kill(2) has no memory-safety preconditions; the pid is a
        // child of ours that has not been reaped, so it cannot have been reused.
        unsafe {
            libc::kill(pid as libc::pid_t, libc::SIGKILL);
        }
        #[cfg(not(unix))]
        let _ = pid;
    }
    children.len()
}

/// Kills every registered child and removes every registered partial output,
/// then keeps the registry locked for good, so nothing new starts while the
/// caller exits the process. Call it from a signal handler just before
/// `std::process::exit`. Returns how many children and partials it cleaned up.
pub fn interrupt() -> (usize, usize) {
    let guard = registry();
    let children = kill_all(&guard.children);
    let partials = guard.partials.len();
    for p in &guard.partials {
        if p.is_dir() {
            let _ = std::fs::remove_dir_all(p);
        } else {
            let _ = std::fs::remove_file(p);
        }
    }
    std::mem::forget(guard);
    (children, partials)
}
