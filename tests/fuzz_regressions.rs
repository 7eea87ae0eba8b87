//! Replays, on stable, what the fuzzers found: every file in
//! `fuzz/regressions/TARGET/` goes through the same target body that libFuzzer
//! runs (`fuzz/src/lib.rs`, included here), plus the seeds in `fuzz/seeds/`,
//! and the named cases below check the answer each crash now gets.

#[path = "../fuzz/src/lib.rs"]
#[allow(dead_code)]
mod targets;

use std::path::{Path, PathBuf};

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz")
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

/// Every regression and seed input through its target; a panic fails the test
/// and names the file.
#[test]
fn every_found_crash_and_seed_passes_its_target() {
    let mut ran = 0;
    for (name, body) in targets::TARGETS {
        for kind in ["regressions", "seeds"] {
            for file in files(&fuzz_dir().join(kind).join(name)) {
                let data = std::fs::read(&file).unwrap();
                let outcome = std::panic::catch_unwind(|| body(&data));
                assert!(outcome.is_ok(), "{name}: {} panics", file.display());
                ran += 1;
            }
        }
    }
    assert!(ran >= 20, "only {ran} inputs replayed");
    std::fs::remove_dir_all(targets::scratch_root()).unwrap();
}

fn y4m_error(bytes: &[u8]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.y4m");
    std::fs::write(&path, bytes).unwrap();
    match amc_video::open_input(&path, &amc_video::InputOptions::default()) {
        Ok(_) => panic!("{:?} opened", String::from_utf8_lossy(bytes)),
        Err(e) => e.to_string(),
    }
}

/// Found while writing the `y4m` target (reading the parser it drives): a
/// header token starting with a non-ASCII character was split inside the
/// character (a panic); now it is ignored like any unknown tag.
#[test]
fn y4m_header_with_non_ascii_token() {
    let e = y4m_error(
        &std::fs::read(fuzz_dir().join("regressions/y4m/non-ascii-header-key.y4m")).unwrap(),
    );
    assert!(e.contains("shorter than one frame"), "{e}");
}

/// A header claiming a huge frame in a tiny file is refused before a frame
/// buffer is allocated, naming the sizes.
#[test]
fn y4m_huge_header_in_a_tiny_file() {
    let e = y4m_error(b"YUV4MPEG2 W16384 H16384 F30:1 C444\nFRAME\n0123");
    assert!(
        e.contains("shorter than one frame") && e.contains("16384x16384"),
        "{e}"
    );
    let e = y4m_error(b"YUV4MPEG2 W16385 H8 F30:1\nFRAME\n0123");
    assert!(e.contains("at most 16384"), "{e}");
    let e = y4m_error(b"YUV4MPEG2 W8 H8 F100000:1\nFRAME\n0123");
    assert!(e.contains("at most 10000"), "{e}");
}
