//! Refusing a run whose outputs would overwrite its input or each other.

use super::RunError;
use std::path::{Path, PathBuf};

/// What a path is, for comparisons: the file's identity when it exists
/// (device and inode, so hard links and symlinks are caught), else its
/// canonical parent joined with its name.
#[derive(PartialEq, Eq, Debug)]
enum Identity {
    #[cfg(unix)]
    Inode(u64, u64),
    Path(PathBuf),
}

fn identity(path: &Path) -> Identity {
    if let Ok(meta) = std::fs::metadata(path) {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            return Identity::Inode(meta.dev(), meta.ino());
        }
        #[cfg(not(unix))]
        let _ = meta;
    }
    if let Ok(p) = std::fs::canonicalize(path) {
        return Identity::Path(p);
    }
    // Not there yet: the canonical directory plus the name.
    let name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let dir = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    Identity::Path(dir.join(name))
}

/// Fails if any two of `paths` (labelled `input`, `output`, ...) are the same
/// file. [`run`](super::run) checks its own paths; callers check earlier to
/// refuse before any slow work (such as `--fov auto`).
pub fn check_distinct(paths: &[(&'static str, &Path)]) -> Result<(), RunError> {
    let ids: Vec<Identity> = paths.iter().map(|(_, p)| identity(p)).collect();
    for i in 0..paths.len() {
        for j in i + 1..paths.len() {
            if ids[i] == ids[j] {
                return Err(RunError::SamePath {
                    first: paths[i].0,
                    first_path: paths[i].1.to_path_buf(),
                    second: paths[j].0,
                    second_path: paths[j].1.to_path_buf(),
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_file_by_name_link_or_new_path() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("a.mp4");
        std::fs::write(&a, b"x").unwrap();
        let dotted = d.path().join(".").join("a.mp4");
        assert!(check_distinct(&[("input", &a), ("output", &dotted)]).is_err());
        let hard = d.path().join("hard.mp4");
        std::fs::hard_link(&a, &hard).unwrap();
        assert!(check_distinct(&[("input", &a), ("output", &hard)]).is_err());
        #[cfg(unix)]
        {
            let soft = d.path().join("soft.mp4");
            std::os::unix::fs::symlink(&a, &soft).unwrap();
            assert!(check_distinct(&[("input", &a), ("output", &soft)]).is_err());
        }
        let new = d.path().join("new.csv");
        let new2 = d.path().join("sub").join("..").join("new.csv");
        std::fs::create_dir(d.path().join("sub")).unwrap();
        let e = check_distinct(&[("input", &a), ("telemetry", &new), ("metrics", &new2)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("telemetry") && e.contains("metrics"), "{e}");
        check_distinct(&[("input", &a), ("output", &d.path().join("b.mp4"))]).unwrap();
    }
}
