//! What the clip says about its camera, and the lens `--lens-db DIR` picks
//! for it, told to the user: one line each, before the run.

use crate::error::CliError;
use amc_engine::clip_camera::{clip_camera, ClipCamera};
use amc_engine::lens_db::{select, LensDb, LensPick};
use amc_video::InputOptions;
use std::path::Path;

/// What the clip names, and the profile picked for it.
pub struct ClipLens {
    /// The camera the clip names, if any.
    pub camera: Option<ClipCamera>,
    /// The profile `--lens-db` picked (`None` without it, or with no match).
    pub pick: Option<LensPick>,
}

/// Reads the camera `input` names; with `db_dir`, loads the profiles (a
/// missing folder is an error, before any work) and picks one for the
/// clip's size and rate. Says which, or that none matched (a warning, shown
/// even with `quiet`: the run then estimates the lens as without the flag).
pub fn clip_lens(
    input: &Path,
    db_dir: Option<&Path>,
    opts: &InputOptions,
    quiet: bool,
) -> Result<ClipLens, CliError> {
    let db = db_dir.map(LensDb::load).transpose()?;
    let camera = clip_camera(input);
    let Some(db) = db else {
        if let (Some(c), false) = (&camera, quiet) {
            eprintln!("clip: {} (from its metadata)", c.describe());
        }
        return Ok(ClipLens { camera, pick: None });
    };
    let info = amc_video::open_input(input, opts)?.info().clone();
    let selection = select(
        &db,
        camera.as_ref(),
        (info.width, info.height),
        Some(info.fps),
    );
    if !quiet {
        for (path, why) in &selection.skipped {
            eprintln!("lens: skipped {}: {why}", path.display());
        }
        if db.unreadable > 0 {
            eprintln!(
                "lens: {} of the {} .json files in {} skipped (unreadable, or no Gyroflow lens profile)",
                db.unreadable,
                db.unreadable + db.profiles.len(),
                db.dir.display()
            );
        }
    }
    let line = selection.line(camera.as_ref(), &db);
    if selection.pick.is_none() || !quiet {
        eprintln!("{line}");
    }
    Ok(ClipLens {
        camera,
        pick: selection.pick,
    })
}
