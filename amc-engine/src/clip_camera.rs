//! What a clip says about the camera that recorded it: brand, model and lens
//! mode (GoPro's FOV setting, Insta360's FOV type, ...), read with the
//! `telemetry-parser` crate as Gyroflow reads them to pick a lens profile
//! (`src/core/camera_identifier.rs` there). A lens mode is the field of
//! view the camera cropped or dewarped to: the same body in Wide and Linear
//! is two lenses, so a run says which mode it saw.

use serde::Serialize;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// The camera a clip names.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ClipCamera {
    /// The maker, as telemetry-parser names it (`"GoPro"`, `"Sony"`, `"Insta360"`).
    pub brand: String,
    /// The model without the brand (`"HERO5 Black"`), where the clip records it.
    pub model: Option<String>,
    /// The lens mode (`"Wide"`, `"Linear"`, `"SuperView"`), where recorded.
    pub lens_mode: Option<String>,
    /// In-camera electronic stabilization as Gyroflow's profiles name it
    /// (`"EIS-Y"`, `"NO-EIS"`), where recorded: profiles of one mode differ by it.
    pub eis: Option<String>,
}

impl ClipCamera {
    /// `"GoPro HERO5 Black"` (the brand alone where no model is recorded).
    pub fn name(&self) -> String {
        match &self.model {
            Some(m) => format!("{} {m}", self.brand),
            None => self.brand.clone(),
        }
    }

    /// `"camera GoPro HERO5 Black, lens mode Wide"`, or `", no lens mode
    /// recorded"`.
    pub fn describe(&self) -> String {
        match &self.lens_mode {
            Some(mode) => format!("camera {}, lens mode {mode}", self.name()),
            None => format!("camera {}, no lens mode recorded", self.name()),
        }
    }
}

/// The camera the clip at `path` names; `None` for a folder, a file
/// telemetry-parser does not know, or one that names no maker. A parser
/// that panics on a damaged file is a clip that names nothing, not the
/// end of the run.
pub fn clip_camera(path: &Path) -> Option<ClipCamera> {
    if !path.is_file() {
        return None;
    }
    std::panic::catch_unwind(|| read(path)).ok().flatten()
}

fn read(path: &Path) -> Option<ClipCamera> {
    let mut file = std::fs::File::open(path).ok()?;
    let size = file.metadata().ok()?.len() as usize;
    let input = telemetry_parser::Input::from_stream(
        &mut file,
        size,
        path,
        |_| {},
        Arc::new(AtomicBool::new(false)),
    )
    .ok()?;
    let brand = input.camera_type().trim().to_string();
    if brand.is_empty() {
        return None;
    }
    // GoPro's MINF is "HERO5 Black"; others may repeat the brand in the model.
    let model = input
        .camera_model()
        .map(|m| m.replace(&brand, "").trim().to_string())
        .filter(|m| !m.is_empty());
    let (lens_mode, eis) = lens_mode(&input, &brand);
    Some(ClipCamera {
        brand,
        model,
        lens_mode,
        eis,
    })
}

/// The lens mode and EIS setting, from the tags Gyroflow reads for them.
fn lens_mode(input: &telemetry_parser::Input, brand: &str) -> (Option<String>, Option<String>) {
    use telemetry_parser::tags_impl::{GetWithType, GroupId, TagId};
    let Some(samples) = input.samples.as_ref() else {
        return (None, None);
    };
    let maps = samples.iter().filter_map(|s| s.tag_map.as_ref());
    let text = |s: &String| Some(s.trim().to_string()).filter(|s| !s.is_empty());
    match brand {
        "GoPro" => {
            // The first sample holds the clip's settings (the GPMF header).
            for map in maps {
                let Some(m) = map.get(&GroupId::Default) else {
                    continue;
                };
                let tag = |fourcc: &[u8; 4]| TagId::Unknown(u32::from_be_bytes(*fourcc));
                let vfov = (m.get_t(tag(b"VFOV")) as Option<&String>).and_then(text);
                let zfov = m.get_t(tag(b"ZFOV")) as Option<&f32>;
                let prjt = (m.get_t(tag(b"PRJT")) as Option<&String>).and_then(text);
                let mut mode = vfov.map(|v| gopro_fov(&v, zfov.copied()));
                if prjt.as_deref() == Some("GPMW") {
                    mode = Some("Max Wide".into());
                }
                let eisa = (m.get_t(tag(b"EISA")) as Option<&String>).and_then(text);
                let eise = (m.get_t(tag(b"EISE")) as Option<&String>).and_then(text);
                let eis = match (eisa.as_deref(), eise.as_deref()) {
                    // EISA decides where it says; EISE where it does not.
                    (Some("Y"), _) => Some("EIS-Y".to_string()),
                    (Some("N"), _) => Some("NO-EIS".to_string()),
                    (Some(v), _) if v != "N/A" => Some(v.to_string()),
                    (_, Some("N")) => Some("NO-EIS".to_string()),
                    (_, Some(e)) => Some(format!("EIS-{e}")),
                    (_, None) => None,
                };
                if mode.is_some() || eis.is_some() {
                    return (mode, eis);
                }
            }
            (None, None)
        }
        _ => {
            // Insta360 and the generic metadata (a .gcsv header, DJI): a JSON object.
            for map in maps {
                if let Some(name) = map
                    .get(&GroupId::Lens)
                    .and_then(|m| m.get_t(TagId::Name) as Option<&String>)
                    .and_then(text)
                {
                    return (Some(name), None);
                }
                let Some(meta) = map
                    .get(&GroupId::Default)
                    .and_then(|m| m.get_t(TagId::Metadata) as Option<&serde_json::Value>)
                else {
                    continue;
                };
                let s = |k: &str| meta.get(k).and_then(|v| v.as_str()).map(str::trim);
                if let Some(fov) = s("fov_type").filter(|v| !v.is_empty()) {
                    let eis = meta
                        .get("is_flowstate_online")
                        .and_then(|v| v.as_bool())
                        .map(|on| if on { "EIS" } else { "NO-EIS" }.to_string());
                    return (Some(fov.replace("FovType", "")), eis);
                }
                if let Some(v) = s("lens_info").filter(|v| !v.is_empty()) {
                    return (Some(v.to_string()), None);
                }
            }
            (None, None)
        }
    }
}

/// GoPro's VFOV letter as its menus (and Gyroflow's profiles) name the mode;
/// a Linear clip with a field of view under 80 degrees is Narrow.
fn gopro_fov(letter: &str, zfov: Option<f32>) -> String {
    match letter {
        "X" => "Max",
        "W" => "Wide",
        "S" => "SuperView",
        "H" => "HyperView",
        "L" if zfov.is_some_and(|z| z < 80.0) => "Narrow",
        "L" => "Linear",
        "N" => "Narrow",
        "M" => "Medium",
        other => other,
    }
    .to_string()
}
