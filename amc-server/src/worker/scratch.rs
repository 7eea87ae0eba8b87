//! A job's local folder under `--work-dir`, named for the process that owns
//! it (`amc-job-HOST-PID-RANDOM`). A worker killed with SIGKILL cannot
//! remove its folder; the next worker started on the same host (and work
//! dir) removes every folder whose process is gone. Folders of other hosts
//! (a work dir shared between containers) and of live processes are left.

use std::path::{Path, PathBuf};

/// This host's name, as it goes into names (letters, digits, '-' and '.').
pub fn host() -> String {
    let host: String = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .unwrap_or_default()
        .trim()
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || *c == '-' || *c == '.')
        .collect();
    if host.is_empty() {
        "worker".into()
    } else {
        host
    }
}

/// The start of the names of this host's job folders.
fn host_prefix(host: &str) -> String {
    format!("amc-job-{host}-")
}

/// A new job folder of this process in `work_dir`, removed when dropped.
pub fn create(work_dir: &Path, host: &str) -> std::io::Result<tempfile::TempDir> {
    tempfile::Builder::new()
        .prefix(&format!("{}{}-", host_prefix(host), std::process::id()))
        .tempdir_in(work_dir)
}

/// Whether process `pid` exists on this host.
fn alive(pid: i32) -> bool {
    // Signal 0 checks existence and permission only; EPERM means it exists.
    // SAFETY: kill(2) with signal 0 sends nothing.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

/// Removes the job folders of this host's processes that are gone; returns them.
pub fn remove_stale(work_dir: &Path, host: &str) -> Vec<PathBuf> {
    let prefix = host_prefix(host);
    let mut removed = Vec::new();
    for entry in std::fs::read_dir(work_dir).into_iter().flatten().flatten() {
        let name = entry.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(&prefix)) else {
            continue;
        };
        let Some(pid) = rest
            .split('-')
            .next()
            .and_then(|p| p.parse::<i32>().ok())
            .filter(|&p| p > 0)
        else {
            continue;
        };
        if pid as u32 == std::process::id() || alive(pid) {
            continue;
        }
        let path = entry.path();
        if std::fs::remove_dir_all(&path).is_ok() {
            removed.push(path);
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_folders_of_gone_processes_of_this_host_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let host = host();
        // A process that has exited.
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let gone = child.id();
        child.wait().unwrap();
        let stale = dir.path().join(format!("amc-job-{host}-{gone}-abc"));
        std::fs::create_dir_all(stale.join("sub")).unwrap();
        std::fs::write(stale.join("sub/input"), b"x").unwrap();
        let mine = create(dir.path(), &host).unwrap();
        let other_host = dir.path().join(format!("amc-job-elsewhere-{gone}-abc"));
        std::fs::create_dir(&other_host).unwrap();
        let unrelated = dir.path().join("amc-job-notes");
        std::fs::create_dir(&unrelated).unwrap();
        let removed = remove_stale(dir.path(), &host);
        assert_eq!(removed, vec![stale.clone()]);
        assert!(!stale.exists());
        assert!(mine.path().exists() && other_host.exists() && unrelated.exists());
    }
}
