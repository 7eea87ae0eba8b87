//! `--lens-db DIR`: a folder of Gyroflow lens profiles (such as the public
//! gyroflow/lens_profiles collection, never shipped with us) and the pick of
//! the one that fits a clip: the camera's brand and model and its lens mode
//! as the clip records them ([`ClipCamera`]), and the clip's frame size.
//!
//! Gyroflow calibrates each camera, mode and resolution; a profile of the
//! same aspect ratio at another size is the same optics sampled differently,
//! so its camera matrix is scaled to the clip. A profile of another aspect
//! ratio is a different crop of the sensor, and is never used.

use crate::clip_camera::ClipCamera;
use amc_core::lens::parse_lens_file;
use amc_core::plan::{LensNote, ResolvedLens};
use amc_core::CameraModel;
use serde::Serialize;
use serde_json::Value;
use std::cmp::Reverse;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a lens database cannot be read at all (a profile that cannot be
/// read is skipped and counted, not an error).
#[derive(Debug, Error)]
pub enum LensDbError {
    /// The folder does not exist.
    #[error("--lens-db {}: no such folder (give a folder of Gyroflow lens profiles, e.g. a clone of github.com/gyroflow/lens_profiles)", .dir.display())]
    Missing {
        /// The folder given.
        dir: PathBuf,
    },
    /// The path is not a folder.
    #[error("--lens-db {}: not a folder (give a folder of Gyroflow lens profiles; for one profile use --lens FILE)", .dir.display())]
    NotAFolder {
        /// The path given.
        dir: PathBuf,
    },
    /// The folder cannot be listed.
    #[error("--lens-db {}: cannot list it: {source}", .dir.display())]
    List {
        /// The folder that could not be listed.
        dir: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// One profile's metadata, as read from its JSON (its camera is parsed
/// only when it is a candidate: the public collection has ~10 000 files).
#[derive(Clone, Debug)]
pub struct Profile {
    /// The file.
    pub path: PathBuf,
    /// Its `name`, else the file's stem.
    pub name: String,
    /// `camera_brand`.
    pub brand: String,
    /// `camera_model`.
    pub model: String,
    /// `lens_model` (Gyroflow's name for the lens mode: "Wide", "Linear").
    pub lens_model: String,
    /// `camera_setting`.
    pub setting: String,
    /// `note` and `name` together, where the EIS setting is written.
    pub note: String,
    /// `calib_dimension`.
    pub calib: (usize, usize),
    /// Frame sizes, rates and readouts it is stated to fit:
    /// `compatible_settings` and its own (`calib_dimension`, `fps`,
    /// `frame_readout_time`).
    pub settings: Vec<Setting>,
    /// `official`.
    pub official: bool,
}

/// A size (and rate) a profile fits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setting {
    /// Frame width, pixels.
    pub width: usize,
    /// Frame height, pixels.
    pub height: usize,
    /// Frames per second, where stated.
    pub fps: Option<f64>,
    /// Readout at that size and rate, milliseconds, where stated.
    pub readout_ms: Option<f64>,
}

/// The profiles under a folder.
#[derive(Clone, Debug, Default)]
pub struct LensDb {
    /// The folder.
    pub dir: PathBuf,
    /// The profiles read.
    pub profiles: Vec<Profile>,
    /// `.json` files skipped: unreadable, not JSON, or no Gyroflow profile.
    pub unreadable: usize,
}

impl LensDb {
    /// Reads every `.json` under `dir`, recursively, in name order.
    pub fn load(dir: &Path) -> Result<Self, LensDbError> {
        if !dir.exists() {
            return Err(LensDbError::Missing {
                dir: dir.to_path_buf(),
            });
        }
        if !dir.is_dir() {
            return Err(LensDbError::NotAFolder {
                dir: dir.to_path_buf(),
            });
        }
        let mut files = Vec::new();
        list_json(dir, 0, &mut files).map_err(|source| LensDbError::List {
            dir: dir.to_path_buf(),
            source,
        })?;
        files.sort();
        let mut db = LensDb {
            dir: dir.to_path_buf(),
            ..Self::default()
        };
        for path in files {
            match read_profile(&path) {
                Some(p) => db.profiles.push(p),
                None => db.unreadable += 1,
            }
        }
        Ok(db)
    }
}

/// Deepest folder nesting followed (the collection is two levels deep; a
/// link loop must end).
const MAX_DEPTH: usize = 8;

fn list_json(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let Ok(entry) = entry else { continue };
        let path = entry.path();
        let hidden = entry.file_name().to_string_lossy().starts_with('.');
        if path.is_dir() {
            // A clone's .git holds no profiles; an unlistable subfolder is skipped.
            if !hidden && depth < MAX_DEPTH {
                let _ = list_json(&path, depth + 1, out);
            }
        } else if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"))
        {
            out.push(path);
        }
    }
    Ok(())
}

fn read_profile(path: &Path) -> Option<Profile> {
    let text = std::fs::read_to_string(path).ok()?;
    let v: Value = serde_json::from_str(text.trim_start_matches('\u{feff}')).ok()?;
    let s = |k: &str| {
        v.get(k)
            .and_then(Value::as_str)
            .unwrap_or("")
            .trim()
            .to_string()
    };
    let size = |d: &Value| -> Option<(usize, usize)> {
        let w = d.get("w").and_then(Value::as_u64)? as usize;
        let h = d.get("h").and_then(Value::as_u64)? as usize;
        (w > 0 && h > 0).then_some((w, h))
    };
    let calib = size(v.get("calib_dimension")?)?;
    let positive = |x: Option<&Value>| x.and_then(Value::as_f64).filter(|f| *f > 0.0);
    let mut settings = vec![Setting {
        width: calib.0,
        height: calib.1,
        fps: positive(v.get("fps")),
        readout_ms: positive(v.get("frame_readout_time")),
    }];
    for c in v
        .get("compatible_settings")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        let dim = |k: &str| c.get(k).and_then(Value::as_u64).map(|n| n as usize);
        if let (Some(width), Some(height)) = (dim("width"), dim("height")) {
            settings.push(Setting {
                width,
                height,
                fps: positive(c.get("fps")),
                readout_ms: positive(c.get("frame_readout_time")),
            });
        }
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
    let name = Some(s("name"))
        .filter(|n| !n.is_empty())
        .or(stem)
        .unwrap_or_default();
    Some(Profile {
        path: path.to_path_buf(),
        note: format!("{} {name}", s("note")),
        name,
        brand: s("camera_brand"),
        model: s("camera_model"),
        lens_model: s("lens_model"),
        setting: s("camera_setting"),
        calib,
        settings,
        official: v.get("official").and_then(Value::as_bool).unwrap_or(false),
    })
}

/// The profile picked for a clip.
#[derive(Clone, Debug, Serialize)]
pub struct LensPick {
    /// The profile's name.
    pub name: String,
    /// Its file.
    pub file: PathBuf,
    /// The camera it names (brand and model).
    pub camera: String,
    /// The lens mode it names (`lens_model`, else `camera_setting`), if any.
    pub lens_mode: Option<String>,
    /// The size it was calibrated at.
    pub calib_size: (usize, usize),
    /// The clip's size, which its camera was scaled to.
    pub size: (usize, usize),
    /// The readout it states for the clip's size and rate, milliseconds.
    pub readout_ms: Option<f64>,
    /// `[fx, fy, cx, cy]` at the clip's size, pixels.
    pub intrinsics: [f64; 4],
    /// The lens it gives, at the clip's size.
    #[serde(skip)]
    pub camera_model: CameraModel,
}

impl LensPick {
    /// The lens for a run: given (not estimated), with the profile's readout.
    pub fn lens(&self) -> ResolvedLens {
        ResolvedLens {
            camera: self.camera_model.clone(),
            note: LensNote::Given,
            readout_ms: self.readout_ms,
        }
    }

    /// `"lens: NAME from FILE (camera X, lens mode Y, WxH)"`.
    pub fn line(&self) -> String {
        let (cw, ch) = self.calib_size;
        let (w, h) = self.size;
        let size = if (cw, ch) == (w, h) {
            format!("{w}x{h}")
        } else {
            format!("calibrated at {cw}x{ch}, scaled to {w}x{h}")
        };
        let mode = self.lens_mode.as_ref().map_or_else(
            || "no lens mode stated".to_string(),
            |m| format!("lens mode {m}"),
        );
        format!(
            "lens: {} from {} (camera {}, {mode}, {size})",
            self.name,
            self.file.display(),
            self.camera
        )
    }
}

/// What the database gave for a clip.
#[derive(Clone, Debug)]
pub struct Selection {
    /// The profile picked, if one fits.
    pub pick: Option<LensPick>,
    /// Profiles that fit better but whose lens we cannot use: file, why.
    pub skipped: Vec<(PathBuf, String)>,
    /// Why none fits (empty with a pick).
    pub why_none: String,
}

impl Selection {
    /// The line that says what happened: [`LensPick::line`], or which
    /// camera the clip names and that no profile matched (a warning).
    pub fn line(&self, clip: Option<&ClipCamera>, db: &LensDb) -> String {
        match (&self.pick, clip) {
            // The clip does not say which mode: the profile's is an assumption.
            (Some(p), Some(c)) if c.lens_mode.is_none() && p.lens_mode.is_some() => format!(
                "{}; the clip records no lens mode, so the profile's is assumed",
                p.line()
            ),
            (Some(p), _) => p.line(),
            (None, Some(c)) => format!(
                "warning: lens: the clip names {}; no profile in {} matched ({}): estimating the field of view as without --lens-db",
                c.describe(),
                db.dir.display(),
                self.why_none
            ),
            (None, None) => format!(
                "warning: lens: the clip names no camera, so no profile in {} can be picked for it: estimating the field of view as without --lens-db",
                db.dir.display()
            ),
        }
    }
}

/// Lower case letters and digits only: "HERO8 Black", "Hero8-black" and
/// "hero 8 black" are one name.
fn norm(s: &str) -> String {
    s.chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// How well two normalized names agree: 2 equal, 1 one extends the other by
/// a word ("hero8" and "hero8black", "super" and "superview"), 0 not
/// ("hero1" does not extend to "hero10": the next character is a digit).
fn agree(a: &str, b: &str) -> u8 {
    if a.is_empty() || b.is_empty() {
        return 0;
    }
    if a == b {
        return 2;
    }
    let (short, long) = if a.len() < b.len() { (a, b) } else { (b, a) };
    let extends =
        long.starts_with(short) && !long[short.len()..].starts_with(|c: char| c.is_ascii_digit());
    u8::from(extends)
}

/// Whether `a`x`b` has the aspect ratio of `w`x`h` (within 1%: 854x480 is 16:9).
fn same_aspect((a, b): (usize, usize), (w, h): (usize, usize)) -> bool {
    let (l, r) = ((a * h) as f64, (b * w) as f64);
    (l - r).abs() <= 0.01 * l.max(r)
}

/// Picks the profile for a clip of `size` at `fps` frames/s that names
/// `clip`: brand equal, model equal or extended by a word, the lens mode
/// where both the clip and the profile state one, the same aspect ratio;
/// then the best by how exactly model and lens mode agree (a GoPro that
/// records none: Wide, its default, first), then size and EIS, the official
/// before the user-contributed. A better profile whose lens we
/// cannot use (another distortion model, an anamorphic stretch) is skipped
/// with its reason.
pub fn select(
    db: &LensDb,
    clip: Option<&ClipCamera>,
    size: (usize, usize),
    fps: Option<f64>,
) -> Selection {
    let none = |why: String| Selection {
        pick: None,
        skipped: Vec::new(),
        why_none: why,
    };
    let Some(clip) = clip else {
        return none("the clip names no camera".into());
    };
    let Some(model) = clip.model.as_deref() else {
        return none(format!("the clip names {} but no model", clip.brand));
    };
    let (brand, model) = (norm(&clip.brand), norm(model));
    let mode = clip.lens_mode.as_deref().map(norm);
    let eis = clip.eis.as_deref().map(norm);
    // A GoPro that records no mode (a HERO5 has no VFOV tag) was most
    // likely in its default, Wide: among equals, that profile first.
    let default_mode = (mode.is_none() && brand == "gopro").then_some("wide");
    let (mut of_camera, mut of_mode) = (0usize, 0usize);
    let mut ranked = Vec::new();
    for p in &db.profiles {
        if agree(&brand, &norm(&p.brand)) != 2 {
            continue;
        }
        // Some profiles repeat the brand in the model ("GoPro HERO5 Black").
        let model_fit = agree(&model, &norm(&p.model).replacen(&brand, "", 1));
        if model_fit == 0 {
            continue;
        }
        of_camera += 1;
        let stated = [&p.lens_model, &p.setting]
            .into_iter()
            .map(|s| norm(s))
            .find(|s| !s.is_empty());
        let mode_fit = match (&mode, &stated) {
            (Some(m), Some(s)) => match agree(m, s) {
                0 => continue,
                n => n + 1,
            },
            // One side does not say: usable, after any that agree.
            _ => 1,
        };
        of_mode += 1;
        if !same_aspect(p.calib, size) {
            continue;
        }
        let exact_size = p
            .settings
            .iter()
            .any(|s| (s.width, s.height) == size && same_aspect((s.width, s.height), p.calib));
        let eis_fit = eis
            .as_ref()
            .is_some_and(|e| norm(&p.note).contains(e.as_str()));
        let default_fit = default_mode.is_some_and(|d| stated.as_deref() == Some(d));
        let key = (
            model_fit,
            mode_fit,
            default_fit,
            exact_size,
            eis_fit,
            p.official,
        );
        ranked.push((Reverse(key), p));
    }
    // Stable: equal keys keep the folder's name order.
    ranked.sort_by_key(|(k, _)| *k);
    let mut skipped = Vec::new();
    for (_, p) in ranked {
        match camera_of(p, size) {
            Ok(camera_model) => {
                return Selection {
                    pick: Some(LensPick {
                        name: p.name.clone(),
                        file: p.path.clone(),
                        camera: format!("{} {}", p.brand, p.model).trim().to_string(),
                        lens_mode: [&p.lens_model, &p.setting]
                            .into_iter()
                            .find(|s| !s.is_empty())
                            .cloned(),
                        calib_size: p.calib,
                        size,
                        readout_ms: readout_for(p, size, fps),
                        intrinsics: [
                            camera_model.fx,
                            camera_model.fy,
                            camera_model.cx,
                            camera_model.cy,
                        ],
                        camera_model,
                    }),
                    skipped,
                    why_none: String::new(),
                }
            }
            Err(why) => skipped.push((p.path.clone(), why)),
        }
    }
    let why = if of_camera == 0 {
        format!(
            "none of its {} profiles is for this camera",
            db.profiles.len()
        )
    } else if of_mode == 0 {
        format!("{of_camera} are for this camera, none for this lens mode")
    } else if skipped.is_empty() {
        format!(
            "{of_mode} are for this camera and lens mode, none for a {}x{} frame's aspect ratio",
            size.0, size.1
        )
    } else {
        format!(
            "{} fit, but none has a lens we can use: {}",
            skipped.len(),
            skipped[0].1
        )
    };
    Selection {
        pick: None,
        skipped,
        why_none: why,
    }
}

/// The profile's lens at `size`: parsed as `--lens` parses a profile
/// (which refuses what we cannot model), scaled from its calibration.
fn camera_of(p: &Profile, size: (usize, usize)) -> Result<CameraModel, String> {
    let text = std::fs::read_to_string(&p.path).map_err(|e| e.to_string())?;
    let file = parse_lens_file(&text).map_err(|e| e.to_string())?;
    Ok(if (file.camera.width, file.camera.height) == size {
        file.camera
    } else {
        file.camera.rescaled(size.0, size.1)
    })
}

/// The readout a profile states for this size and rate (rates within
/// 1%: 29.97 is 30); none where it states none for them, since a sensor
/// reads out faster at higher rates and the profile's own is for its own.
fn readout_for(p: &Profile, size: (usize, usize), fps: Option<f64>) -> Option<f64> {
    let fps = fps?;
    p.settings
        .iter()
        .filter(|s| (s.width, s.height) == size)
        .filter(|s| s.fps.is_some_and(|f| (f - fps).abs() <= 0.01 * fps))
        .find_map(|s| s.readout_ms)
        .filter(|ms| *ms <= amc_core::shutter::MAX_READOUT_MS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_agree_across_case_spaces_and_a_trailing_word() {
        let fit = |a: &str, b: &str| agree(&norm(a), &norm(b));
        assert_eq!(fit("HERO8 Black", "hero8-black"), 2);
        assert_eq!(fit("Hero 8", "HERO8 Black"), 1);
        assert_eq!(fit("Super", "SuperView"), 1);
        // A digit is another model, not a word more.
        assert_eq!(fit("HERO1", "HERO10 Black"), 0);
        assert_eq!(fit("HERO5 Black", "HERO5 Session"), 0);
        assert_eq!(fit("", "Wide"), 0);
        assert!(same_aspect((1920, 1080), (854, 480)));
        assert!(!same_aspect((2704, 2028), (854, 480)));
    }

    /// Another camera's profile, or another lens mode's, is never picked;
    /// without a model or any camera, nothing is, with the reason.
    #[test]
    fn only_the_clips_camera_and_mode_are_picked() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, model: &str, lens: &str| {
            let text = format!(
                r#"{{"name": "{name}", "camera_brand": "GoPro", "camera_model": "{model}", "lens_model": "{lens}",
                "calib_dimension": {{"w": 1920, "h": 1080}},
                "fisheye_params": {{"camera_matrix": [[900, 0, 960], [0, 900, 540], [0, 0, 1]],
                "distortion_coeffs": [0.04, 0.03, -0.03, 0.01]}}}}"#
            );
            std::fs::write(dir.path().join(format!("{name}.json")), text).unwrap();
        };
        write("a", "HERO8 Black", "Linear");
        write("b", "HERO8 Black", "Wide");
        write("c", "HERO9 Black", "Wide");
        let db = LensDb::load(dir.path()).unwrap();
        assert_eq!((db.profiles.len(), db.unreadable), (3, 0));
        let clip = |model: Option<&str>, mode: Option<&str>| ClipCamera {
            brand: "GoPro".into(),
            model: model.map(String::from),
            lens_mode: mode.map(String::from),
            eis: None,
        };
        let pick = |c: &ClipCamera| select(&db, Some(c), (1280, 720), Some(30.0));
        let wide = pick(&clip(Some("Hero 8"), Some("Wide"))).pick.unwrap();
        assert_eq!(wide.name, "b");
        assert!((wide.intrinsics[0] - 600.0).abs() < 1e-9);
        assert_eq!(
            pick(&clip(Some("HERO8 Black"), Some("Linear")))
                .pick
                .unwrap()
                .name,
            "a"
        );
        let none = pick(&clip(Some("HERO8 Black"), Some("SuperView")));
        assert!(none.pick.is_none());
        assert!(
            none.why_none.contains("none for this lens mode"),
            "{}",
            none.why_none
        );
        assert!(pick(&clip(None, Some("Wide")))
            .why_none
            .contains("no model"));
        let other = select(
            &db,
            Some(&clip(Some("HERO8 Black"), None)),
            (640, 480),
            None,
        );
        assert!(
            other.why_none.contains("aspect ratio"),
            "{}",
            other.why_none
        );
        assert!(select(&db, None, (1280, 720), None).pick.is_none());
    }
}
