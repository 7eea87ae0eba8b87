//! Lens files: parsing calibrations into a [`CameraModel`] and writing the project format.
//!
//! [`parse_lens`] detects the format from the content:
//!
//! 1. **Project JSON** (written by [`to_project_json`]):
//!    ```text
//!    {"model": "pinhole" | "opencv" | "fisheye", "width": 800, "height": 600,
//!     "fx": .., "fy": .., "cx": .., "cy": .., "skew": 0.0 (optional), "dist": [..]}
//!    ```
//!    `dist`: pinhole -> empty, absent or all zeros; opencv -> `k1 k2 p1 p2 [k3]`;
//!    fisheye -> `k1 k2 k3 k4`.
//! 2. **OpenCV calibration**, JSON or YAML as written by `cv::FileStorage` (the
//!    `%YAML:1.0` header and `!!opencv-matrix` tags are accepted): `camera_matrix`
//!    (`{rows, cols, dt, data}` or a nested 3x3 array) with `K = [[fx, skew, cx], [0, fy, cy],
//!    [0, 0, 1]]`, `distortion_coefficients` (4 or 5 values `k1 k2 p1 p2 [k3]`, or 4 values
//!    `k1..k4` when `distortion_model` is `fisheye`/`equidistant` or `fisheye: true`), and
//!    the image size as `image_width`/`image_height`, `width`/`height` or `image_size: [w, h]`.
//! 3. **Gyroflow lens profile** (JSON): `calib_dimension: {w, h}` and
//!    `fisheye_params: {camera_matrix: [[fx,0,cx],[0,fy,cy],[0,0,1]], distortion_coeffs: [k1..k4]}`
//!    (OpenCV fisheye, the Gyroflow default `distortion_model`).
//!
//! The resulting model is checked with [`CameraModel::validate`]. Every error names the key
//! and what was expected, so a person can fix the file.

use crate::camera::{CameraError, CameraModel, Distortion};
use serde_json::{Map, Value};
use thiserror::Error;

/// Why a lens file could not be loaded.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum LensError {
    /// The text is not valid JSON or YAML, or has no recognisable structure.
    #[error("lens file is not valid: {0}")]
    Parse(String),
    /// The content is valid JSON/YAML but matches none of the supported formats.
    #[error(
        "unrecognised lens file: expected the project format (keys model, width, height, fx, fy, cx, cy, dist), \
         an OpenCV calibration (camera_matrix, distortion_coefficients, image_width, image_height) \
         or a Gyroflow lens profile (calib_dimension, fisheye_params); found keys: {found}"
    )]
    UnknownFormat {
        /// The top-level keys that were found.
        found: String,
    },
    /// A required key is absent.
    #[error("{format} lens file is missing the key `{key}`")]
    MissingKey {
        /// Which format was detected.
        format: &'static str,
        /// Dotted path of the missing key.
        key: String,
    },
    /// A key is present but its value is wrong.
    #[error("`{key}` must be {expected}, found {found}")]
    InvalidValue {
        /// Dotted path of the key.
        key: String,
        /// What was expected.
        expected: String,
        /// The value that was found (abbreviated).
        found: String,
    },
    /// The file does not state the image size the calibration belongs to.
    #[error(
        "the lens file must state its image size (the resolution it was calibrated at): \
         add image_width and image_height, or image_size: [w, h]"
    )]
    MissingImageSize,
    /// The distortion model is not supported.
    #[error("unsupported distortion model in `{key}`: {found} (supported: {supported})")]
    UnsupportedModel {
        /// Dotted path of the key.
        key: String,
        /// The model that was found.
        found: String,
        /// The supported models.
        supported: &'static str,
    },
    /// The parameters were read but do not form a valid camera.
    #[error("lens parameters are invalid: {0}")]
    Camera(#[from] CameraError),
}

/// Parses a lens file in any supported format (see module docs) and validates it.
pub fn parse_lens(text: &str) -> Result<CameraModel, LensError> {
    let root = parse_document(text)?;
    let obj = match &root {
        Value::Object(m) => m,
        Value::Null => return Err(LensError::Parse("the file is empty".into())),
        other => {
            return Err(LensError::Parse(format!(
                "expected a JSON object or YAML mapping at the top level, found {}",
                show(other)
            )))
        }
    };
    let cam = if obj.contains_key("calib_dimension") || obj.contains_key("fisheye_params") {
        parse_gyroflow(obj)?
    } else if obj.contains_key("camera_matrix") || obj.contains_key("distortion_coefficients") {
        parse_opencv(obj)?
    } else if obj.contains_key("model") || obj.contains_key("fx") {
        parse_project(obj)?
    } else {
        let mut keys: Vec<&str> = obj.keys().map(String::as_str).take(20).collect();
        if keys.is_empty() {
            keys.push("(none)");
        }
        return Err(LensError::UnknownFormat {
            found: keys.join(", "),
        });
    };
    cam.validate()?;
    Ok(cam)
}

/// Writes `cam` in the project JSON format; [`parse_lens`] reads it back unchanged.
/// Non-finite numbers are written as `null` (and rejected when read back).
pub fn to_project_json(cam: &CameraModel) -> String {
    let (model, dist): (&str, Vec<f64>) = match cam.distortion {
        Distortion::None => ("pinhole", vec![]),
        Distortion::RadTan { k1, k2, p1, p2, k3 } => ("opencv", vec![k1, k2, p1, p2, k3]),
        Distortion::Fisheye { k1, k2, k3, k4 } => ("fisheye", vec![k1, k2, k3, k4]),
    };
    let dist: Vec<String> = dist.into_iter().map(num).collect();
    format!(
        "{{\n  \"model\": \"{model}\",\n  \"width\": {},\n  \"height\": {},\n  \"fx\": {},\n  \"fy\": {},\n  \
         \"cx\": {},\n  \"cy\": {},\n  \"skew\": {},\n  \"dist\": [{}]\n}}\n",
        cam.width,
        cam.height,
        num(cam.fx),
        num(cam.fy),
        num(cam.cx),
        num(cam.cy),
        num(cam.skew),
        dist.join(", ")
    )
}

/// Shortest round-trip representation of a float as a JSON number (`null` if not finite).
fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:?}")
    } else {
        "null".into()
    }
}

// ---------------------------------------------------------------------------------------
// Document parsing: JSON first, then (OpenCV-flavoured) YAML, unified as serde_json::Value
// ---------------------------------------------------------------------------------------

fn parse_document(text: &str) -> Result<Value, LensError> {
    let trimmed = text.trim_start_matches('\u{feff}').trim_start();
    if trimmed.starts_with("<?xml") || trimmed.starts_with("<opencv_storage") {
        return Err(LensError::Parse(
            "OpenCV XML calibration files are not supported; save the calibration as YAML or JSON"
                .into(),
        ));
    }
    if text.len() > MAX_LEN {
        return Err(LensError::Parse(format!(
            "the file is {} bytes; a lens file is a small text file (at most {MAX_LEN} bytes)",
            text.len()
        )));
    }
    let json_err = match serde_json::from_str::<Value>(trimmed) {
        Ok(v) => return Ok(v),
        Err(e) => e,
    };
    // OpenCV writes "%YAML:1.0", which YAML 1.2 parsers reject: drop directive lines and
    // the document start marker that follows them.
    let mut body = trimmed;
    loop {
        let (line, rest) = body.split_once('\n').unwrap_or((body, ""));
        let l = line.trim();
        if l.starts_with('%') || l == "---" || l.is_empty() || l.starts_with('#') {
            body = rest;
            if rest.is_empty() {
                break;
            }
        } else {
            break;
        }
    }
    // The YAML parser is quadratic in the flow nesting depth; refuse absurd nesting early.
    if flow_depth(body) > MAX_DEPTH {
        return Err(LensError::Parse(format!(
            "brackets are nested more than {MAX_DEPTH} levels deep"
        )));
    }
    match serde_yaml::from_str::<serde_yaml::Value>(body) {
        Ok(v) => Ok(yaml_to_json(v)),
        Err(yaml_err) => {
            let looks_json = trimmed.starts_with('{') || trimmed.starts_with('[');
            Err(LensError::Parse(if looks_json {
                format!("invalid JSON: {json_err}")
            } else {
                format!("neither JSON ({json_err}) nor YAML ({yaml_err})")
            }))
        }
    }
}

/// Largest accepted lens file, in bytes.
const MAX_LEN: usize = 1 << 20;
/// Largest accepted nesting depth of `[` / `{` in YAML input.
const MAX_DEPTH: usize = 64;

/// Maximum nesting depth of flow brackets outside quoted strings and comments.
fn flow_depth(text: &str) -> usize {
    let (mut depth, mut max) = (0usize, 0usize);
    let mut quote: Option<char> = None;
    let mut chars = text.chars().peekable();
    let mut prev = '\n';
    while let Some(c) = chars.next() {
        match quote {
            Some('"') if c == '\\' => {
                chars.next();
            }
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None => match c {
                '"' | '\'' => quote = Some(c),
                '#' if prev.is_whitespace() => {
                    // Comment: skip to the end of the line.
                    for d in chars.by_ref() {
                        if d == '\n' {
                            break;
                        }
                    }
                }
                '[' | '{' => {
                    depth += 1;
                    max = max.max(depth);
                }
                ']' | '}' => depth = depth.saturating_sub(1),
                _ => {}
            },
        }
        prev = c;
    }
    max
}

/// Converts a YAML value to JSON, dropping tags (`!!opencv-matrix`). Plain scalars that
/// OpenCV writes as numbers (`1.`, `-2.5e-01`) but YAML leaves as strings become numbers.
fn yaml_to_json(v: serde_yaml::Value) -> Value {
    use serde_yaml::Value as Y;
    match v {
        Y::Null => Value::Null,
        Y::Bool(b) => Value::Bool(b),
        Y::Number(n) => {
            if let Some(i) = n.as_i64() {
                Value::from(i)
            } else if let Some(u) = n.as_u64() {
                Value::from(u)
            } else {
                let f = n.as_f64().unwrap_or(f64::NAN);
                serde_json::Number::from_f64(f)
                    .map_or_else(|| Value::String(f.to_string()), Value::Number)
            }
        }
        Y::String(s) => match s.trim().parse::<f64>() {
            Ok(f) if f.is_finite() && looks_numeric(&s) => {
                serde_json::Number::from_f64(f).map_or(Value::String(s), Value::Number)
            }
            _ => Value::String(s),
        },
        Y::Sequence(seq) => Value::Array(seq.into_iter().map(yaml_to_json).collect()),
        Y::Mapping(m) => {
            let mut out = Map::new();
            for (k, v) in m {
                let key = match k {
                    Y::String(s) => s,
                    Y::Number(n) => n.to_string(),
                    Y::Bool(b) => b.to_string(),
                    _ => continue,
                };
                out.insert(key, yaml_to_json(v));
            }
            Value::Object(out)
        }
        Y::Tagged(t) => yaml_to_json(t.value),
    }
}

/// Only digits, sign, dot and exponent (so words like "inf" or "nan" stay strings).
fn looks_numeric(s: &str) -> bool {
    s.trim()
        .chars()
        .all(|c| c.is_ascii_digit() || matches!(c, '+' | '-' | '.' | 'e' | 'E'))
}

/// Abbreviated rendering of a value for error messages.
fn show(v: &Value) -> String {
    let s = match v {
        Value::Null => "null".to_string(),
        Value::Bool(_) | Value::Number(_) | Value::String(_) => v.to_string(),
        Value::Array(a) => format!("a list of {} items {}", a.len(), v),
        Value::Object(_) => format!("an object {v}"),
    };
    if s.chars().count() > 80 {
        let cut: String = s.chars().take(77).collect();
        format!("{cut}...")
    } else {
        s
    }
}

fn invalid(key: &str, expected: impl Into<String>, found: &Value) -> LensError {
    LensError::InvalidValue {
        key: key.to_string(),
        expected: expected.into(),
        found: show(found),
    }
}

fn get<'a>(
    obj: &'a Map<String, Value>,
    key: &str,
    path: &str,
    format: &'static str,
) -> Result<&'a Value, LensError> {
    match obj.get(key) {
        Some(v) if !v.is_null() => Ok(v),
        _ => Err(LensError::MissingKey {
            format,
            key: join(path, key),
        }),
    }
}

fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

fn as_f64(v: &Value, key: &str) -> Result<f64, LensError> {
    match v.as_f64() {
        Some(f) if f.is_finite() => Ok(f),
        _ => Err(invalid(key, "a finite number", v)),
    }
}

fn as_size(v: &Value, key: &str) -> Result<usize, LensError> {
    const EXPECTED: &str = "a positive whole number of pixels";
    if let Some(u) = v.as_u64() {
        return match usize::try_from(u) {
            Ok(u) if u >= 1 => Ok(u),
            _ => Err(invalid(key, EXPECTED, v)),
        };
    }
    match v.as_f64() {
        Some(f) if f >= 1.0 && f.fract() == 0.0 && f <= u32::MAX as f64 => Ok(f as usize),
        _ => Err(invalid(key, EXPECTED, v)),
    }
}

/// Flattens a (possibly nested) list of numbers.
fn flat_numbers(v: &Value, key: &str, out: &mut Vec<f64>) -> Result<(), LensError> {
    match v {
        Value::Array(items) => {
            for it in items {
                if out.len() > 64 {
                    return Err(invalid(key, "a short list of numbers", v));
                }
                flat_numbers(it, key, out)?;
            }
            Ok(())
        }
        other => {
            out.push(as_f64(other, key)?);
            Ok(())
        }
    }
}

/// Reads a matrix/vector given as `{rows, cols, data}` (OpenCV) or a (nested) list.
fn read_matrix(v: &Value, key: &str) -> Result<Vec<f64>, LensError> {
    let mut out = Vec::new();
    match v {
        Value::Object(m) => {
            let data = m.get("data").ok_or_else(|| LensError::MissingKey {
                format: "OpenCV",
                key: format!("{key}.data"),
            })?;
            flat_numbers(data, &format!("{key}.data"), &mut out)?;
            let dim = |k: &str| {
                m.get(k)
                    .map(|d| as_size(d, &format!("{key}.{k}")))
                    .transpose()
            };
            if let (Some(rows), Some(cols)) = (dim("rows")?, dim("cols")?) {
                if rows.checked_mul(cols) != Some(out.len()) {
                    return Err(invalid(
                        &format!("{key}.data"),
                        format!("rows x cols = {rows} x {cols} numbers"),
                        data,
                    ));
                }
            }
        }
        Value::Array(_) => flat_numbers(v, key, &mut out)?,
        other => {
            return Err(invalid(
                key,
                "a matrix ({rows, cols, data} or a list of numbers)",
                other,
            ))
        }
    }
    Ok(out)
}

/// Intrinsics from a 3x3 camera matrix `[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`.
fn intrinsics_from_k(v: &Value, key: &str) -> Result<(f64, f64, f64, f64, f64), LensError> {
    let k = read_matrix(v, key)?;
    if k.len() != 9 {
        return Err(invalid(
            key,
            format!("a 3x3 camera matrix (9 numbers), got {} numbers", k.len()),
            v,
        ));
    }
    let small = |x: f64| x.abs() <= 1e-9 * (1.0 + k[0].abs());
    if !small(k[3]) || !small(k[6]) || !small(k[7]) || (k[8] - 1.0).abs() > 1e-9 {
        return Err(invalid(key, "[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]", v));
    }
    Ok((k[0], k[4], k[2], k[5], k[1]))
}

fn radtan_from(d: &[f64], key: &str, found: &Value) -> Result<Distortion, LensError> {
    match d.len() {
        4 | 5 => Ok(Distortion::RadTan { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: d.get(4).copied().unwrap_or(0.0) }),
        8 | 12 | 14 if d[5..].iter().all(|&c| c == 0.0) => {
            Ok(Distortion::RadTan { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: d[4] })
        }
        8 | 12 | 14 => Err(invalid(
            key,
            "4 or 5 coefficients k1 k2 p1 p2 [k3]: only the standard OpenCV model is supported, \
             not the rational / thin-prism / tilted models (k4..k6, s1..s4, tx, ty); recalibrate without \
             CALIB_RATIONAL_MODEL, CALIB_THIN_PRISM_MODEL and CALIB_TILTED_MODEL",
            found,
        )),
        n => Err(invalid(key, format!("4 or 5 coefficients k1 k2 p1 p2 [k3], got {n}"), found)),
    }
}

fn fisheye_from(d: &[f64], key: &str, found: &Value) -> Result<Distortion, LensError> {
    match d {
        [k1, k2, k3, k4] => Ok(Distortion::Fisheye {
            k1: *k1,
            k2: *k2,
            k3: *k3,
            k4: *k4,
        }),
        _ => Err(invalid(
            key,
            format!("4 fisheye coefficients k1 k2 k3 k4, got {}", d.len()),
            found,
        )),
    }
}

// ---------------------------------------------------------------------------------------
// Formats
// ---------------------------------------------------------------------------------------

fn parse_project(obj: &Map<String, Value>) -> Result<CameraModel, LensError> {
    const F: &str = "project";
    let model_v = get(obj, "model", "", F)?;
    let model = model_v
        .as_str()
        .ok_or_else(|| invalid("model", "\"pinhole\", \"opencv\" or \"fisheye\"", model_v))?;
    let num = |k: &str| get(obj, k, "", F).and_then(|v| as_f64(v, k));
    let width = as_size(get(obj, "width", "", F)?, "width")?;
    let height = as_size(get(obj, "height", "", F)?, "height")?;
    let (fx, fy, cx, cy) = (num("fx")?, num("fy")?, num("cx")?, num("cy")?);
    let skew = match obj.get("skew") {
        None | Some(Value::Null) => 0.0,
        Some(v) => as_f64(v, "skew")?,
    };
    let mut dist = Vec::new();
    let dist_v = obj.get("dist").unwrap_or(&Value::Null);
    match dist_v {
        Value::Null => {}
        Value::Array(_) => flat_numbers(dist_v, "dist", &mut dist)?,
        other => return Err(invalid("dist", "a list of distortion coefficients", other)),
    }
    let distortion = match model.trim().to_ascii_lowercase().as_str() {
        "pinhole" | "none" => {
            if dist.iter().any(|&c| c != 0.0) {
                return Err(invalid(
                    "dist",
                    "empty (or all zeros) for model \"pinhole\"; use model \"opencv\" or \"fisheye\" for a distorted lens",
                    dist_v,
                ));
            }
            Distortion::None
        }
        "opencv" | "radtan" => {
            if dist_v.is_null() {
                return Err(LensError::MissingKey {
                    format: F,
                    key: "dist (k1 k2 p1 p2 [k3])".into(),
                });
            }
            match dist.len() {
                4 | 5 => radtan_from(&dist, "dist", dist_v)?,
                n => {
                    return Err(invalid(
                        "dist",
                        format!(
                            "4 or 5 coefficients k1 k2 p1 p2 [k3] for model \"opencv\", got {n}"
                        ),
                        dist_v,
                    ))
                }
            }
        }
        "fisheye" => {
            if dist_v.is_null() {
                return Err(LensError::MissingKey {
                    format: F,
                    key: "dist (k1 k2 k3 k4)".into(),
                });
            }
            fisheye_from(&dist, "dist", dist_v)?
        }
        _ => {
            return Err(LensError::UnsupportedModel {
                key: "model".into(),
                found: show(model_v),
                supported: "\"pinhole\", \"opencv\", \"fisheye\"",
            })
        }
    };
    Ok(CameraModel {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
        skew,
        distortion,
    })
}

fn parse_opencv(obj: &Map<String, Value>) -> Result<CameraModel, LensError> {
    const F: &str = "OpenCV";
    let (fx, fy, cx, cy, skew) =
        intrinsics_from_k(get(obj, "camera_matrix", "", F)?, "camera_matrix")?;
    let (width, height) = opencv_image_size(obj)?;
    let dist_v = get(obj, "distortion_coefficients", "", F)?;
    let dist = read_matrix(dist_v, "distortion_coefficients")?;
    let fisheye_flag = match obj.get("fisheye") {
        None | Some(Value::Null) => false,
        Some(Value::Bool(b)) => *b,
        Some(v) if v.as_i64().is_some() => v.as_i64() != Some(0),
        Some(v) => return Err(invalid("fisheye", "true or false", v)),
    };
    let model = match obj.get("distortion_model") {
        None | Some(Value::Null) => String::new(),
        Some(Value::String(s)) => s.trim().to_ascii_lowercase(),
        Some(v) => {
            return Err(invalid(
                "distortion_model",
                "a string such as \"plumb_bob\" or \"fisheye\"",
                v,
            ))
        }
    };
    let is_fisheye =
        fisheye_flag
            || match model.as_str() {
                "fisheye" | "equidistant" | "kannala_brandt" | "kannala-brandt"
                | "opencv_fisheye" => true,
                ""
                | "plumb_bob"
                | "radtan"
                | "radial-tangential"
                | "radial_tangential"
                | "opencv"
                | "pinhole"
                | "rational_polynomial" => false,
                other => return Err(LensError::UnsupportedModel {
                    key: "distortion_model".into(),
                    found: format!("\"{other}\""),
                    supported:
                        "plumb_bob / radtan (k1 k2 p1 p2 [k3]) or fisheye / equidistant (k1..k4)",
                }),
            };
    let distortion = if is_fisheye {
        fisheye_from(&dist, "distortion_coefficients", dist_v)?
    } else if dist.is_empty() {
        Distortion::None
    } else {
        radtan_from(&dist, "distortion_coefficients", dist_v)?
    };
    Ok(CameraModel {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
        skew,
        distortion,
    })
}

fn opencv_image_size(obj: &Map<String, Value>) -> Result<(usize, usize), LensError> {
    for (wk, hk) in [("image_width", "image_height"), ("width", "height")] {
        match (obj.get(wk), obj.get(hk)) {
            (Some(w), Some(h)) => return Ok((as_size(w, wk)?, as_size(h, hk)?)),
            (Some(_), None) => {
                return Err(LensError::MissingKey {
                    format: "OpenCV",
                    key: hk.into(),
                })
            }
            (None, Some(_)) => {
                return Err(LensError::MissingKey {
                    format: "OpenCV",
                    key: wk.into(),
                })
            }
            (None, None) => {}
        }
    }
    if let Some(v) = obj.get("image_size") {
        let mut wh = Vec::new();
        let parsed = match v {
            Value::Object(m) => match (
                m.get("width").or(m.get("w")),
                m.get("height").or(m.get("h")),
            ) {
                (Some(w), Some(h)) => Some((
                    as_size(w, "image_size.width")?,
                    as_size(h, "image_size.height")?,
                )),
                _ => None,
            },
            Value::Array(_) => {
                flat_numbers(v, "image_size", &mut wh)?;
                None
            }
            _ => None,
        };
        if let Some(p) = parsed {
            return Ok(p);
        }
        if let [w, h] = wh[..] {
            return Ok((
                as_size(&Value::from(w), "image_size[0]")?,
                as_size(&Value::from(h), "image_size[1]")?,
            ));
        }
        return Err(invalid("image_size", "[width, height]", v));
    }
    Err(LensError::MissingImageSize)
}

fn parse_gyroflow(obj: &Map<String, Value>) -> Result<CameraModel, LensError> {
    const F: &str = "Gyroflow";
    if let Some(v) = obj.get("distortion_model") {
        match v {
            Value::Null => {}
            Value::String(s) if s.trim().is_empty() || s.trim() == "opencv_fisheye" => {}
            other => {
                return Err(LensError::UnsupportedModel {
                    key: "distortion_model".into(),
                    found: show(other),
                    supported: "opencv_fisheye (Gyroflow's default)",
                })
            }
        }
    }
    if let Some(v) = obj.get("digital_lens") {
        let none = v.is_null() || v.as_str().is_some_and(|s| s.trim().is_empty());
        if !none {
            return Err(LensError::UnsupportedModel {
                key: "digital_lens".into(),
                found: show(v),
                supported: "none (digital lens corrections such as SuperView are not supported)",
            });
        }
    }
    for key in ["input_horizontal_stretch", "input_vertical_stretch"] {
        if let Some(v) = obj.get(key).filter(|v| !v.is_null()) {
            let s = as_f64(v, key)?;
            if s != 1.0 {
                return Err(invalid(
                    key,
                    "1.0 (stretched/anamorphic inputs are not supported)",
                    v,
                ));
            }
        }
    }
    let dim = get(obj, "calib_dimension", "", F)?;
    let dim = dim
        .as_object()
        .ok_or_else(|| invalid("calib_dimension", "an object {\"w\": .., \"h\": ..}", dim))?;
    let width = as_size(get(dim, "w", "calib_dimension", F)?, "calib_dimension.w")?;
    let height = as_size(get(dim, "h", "calib_dimension", F)?, "calib_dimension.h")?;
    let fp = get(obj, "fisheye_params", "", F)?;
    let fp = fp
        .as_object()
        .ok_or_else(|| invalid("fisheye_params", "an object", fp))?;
    let (fx, fy, cx, cy, skew) = intrinsics_from_k(
        get(fp, "camera_matrix", "fisheye_params", F)?,
        "fisheye_params.camera_matrix",
    )?;
    let dist_v = get(fp, "distortion_coeffs", "fisheye_params", F)?;
    let mut dist = Vec::new();
    flat_numbers(dist_v, "fisheye_params.distortion_coeffs", &mut dist)?;
    let distortion = fisheye_from(&dist, "fisheye_params.distortion_coeffs", dist_v)?;
    Ok(CameraModel {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
        skew,
        distortion,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    const OPENCV_YAML: &str = "%YAML:1.0
---
calibration_time: \"Mon 03 Jun 2024 10:12:01 CEST\"
image_width: 1920
image_height: 1080
flags: 0
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1.4123456789012345e+03, 0., 9.5912e+02, 0.,
       1.4131e+03, 5.4233e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -2.8e-01, 7.0000000000000007e-02, 1.0000000000000000e-04,
       -2.0000000000000001e-04, 0. ]
avg_reprojection_error: 3.1415e-01
";

    const OPENCV_JSON: &str = r#"{
    "image_width": 1280,
    "image_height": 720,
    "camera_matrix": {
        "type_id": "opencv-matrix",
        "rows": 3,
        "cols": 3,
        "dt": "d",
        "data": [ 9.0e+02, 0.5, 6.4e+02, 0.0, 9.1e+02, 3.6e+02, 0.0, 0.0, 1.0 ]
    },
    "distortion_coefficients": {
        "type_id": "opencv-matrix",
        "rows": 4,
        "cols": 1,
        "dt": "d",
        "data": [ 0.05, -0.01, 0.002, -0.0005 ]
    },
    "distortion_model": "fisheye"
}"#;

    const GYROFLOW: &str = r#"{
  "name": "GoPro_HERO9 Black_Wide_4by3",
  "note": "",
  "calibrated_by": "someone",
  "camera_brand": "GoPro",
  "camera_model": "HERO9 Black",
  "lens_model": "Wide",
  "camera_setting": "4:3",
  "calib_dimension": { "w": 2704, "h": 2028 },
  "orig_dimension": { "w": 2704, "h": 2028 },
  "output_dimension": { "w": 2704, "h": 2028 },
  "frame_readout_time": 10.0,
  "gyro_lpf": null,
  "input_horizontal_stretch": 1.0,
  "input_vertical_stretch": 1.0,
  "num_images": 14,
  "fps": 59.94,
  "crop": null,
  "official": false,
  "asymmetrical": false,
  "fisheye_params": {
    "RMS_error": 0.41,
    "camera_matrix": [ [ 1195.2, 0.0, 1351.5 ], [ 0.0, 1194.8, 1013.6 ], [ 0.0, 0.0, 1.0 ] ],
    "distortion_coeffs": [ 0.0405, 0.0213, -0.0094, 0.0017 ],
    "radial_distortion_limit": null
  },
  "identifier": "",
  "calibrator_version": "1.5.0",
  "date": "2023-03-01",
  "compatible_settings": [],
  "sync_settings": null,
  "distortion_model": null,
  "digital_lens": null,
  "digital_lens_params": null,
  "interpolations": null,
  "focal_length": null,
  "crop_factor": null,
  "global_shutter": false
}"#;

    const PROJECT: &str = r#"{"model": "opencv", "width": 800, "height": 600, "fx": 600.5, "fy": 601.25,
        "cx": 399.5, "cy": 299.5, "skew": 0.25, "dist": [-0.28, 0.07, 0.0001, -0.0002]}"#;

    #[test]
    fn project_format() {
        let cam = parse_lens(PROJECT).expect("valid");
        assert_eq!((cam.width, cam.height), (800, 600));
        assert_eq!(
            (cam.fx, cam.fy, cam.cx, cam.cy, cam.skew),
            (600.5, 601.25, 399.5, 299.5, 0.25)
        );
        assert_eq!(
            cam.distortion,
            Distortion::RadTan {
                k1: -0.28,
                k2: 0.07,
                p1: 1e-4,
                p2: -2e-4,
                k3: 0.0
            }
        );
        let pin = parse_lens(r#"{"model":"pinhole","width":640,"height":480,"fx":500,"fy":500,"cx":319.5,"cy":239.5}"#)
            .expect("dist and skew are optional for pinhole");
        assert!(pin.is_pinhole());
        assert_eq!(pin.skew, 0.0);
        let zeros = r#"{"model":"pinhole","width":640,"height":480,"fx":500,"fy":500,"cx":319.5,"cy":239.5,"dist":[0,0,0,0,0]}"#;
        assert!(parse_lens(zeros).expect("zeros are fine").is_pinhole());
        let fish = r#"{"model":"fisheye","width":640,"height":480,"fx":300,"fy":300,"cx":319.5,"cy":239.5,"dist":[0.05,-0.01,0.002,-0.0005]}"#;
        assert_eq!(
            parse_lens(fish).expect("valid").distortion,
            Distortion::Fisheye {
                k1: 0.05,
                k2: -0.01,
                k3: 0.002,
                k4: -0.0005
            }
        );
    }

    #[test]
    fn project_round_trip() {
        let cams = [
            CameraModel {
                skew: -0.6974,
                ..CameraModel::pinhole(800, 600, 573.8534, 575.0448, 406.0101, 309.0112)
            },
            parse_lens(PROJECT).expect("valid"),
            CameraModel::fisheye_hfov(1280, 960, 190.0, [0.05, -0.01, 0.002, -0.0005])
                .expect("valid"),
            CameraModel {
                distortion: Distortion::RadTan {
                    k1: 0.1 / 3.0,
                    k2: 1e-17,
                    p1: -0.0,
                    p2: 2.0f64.sqrt(),
                    k3: 0.0,
                },
                ..CameraModel::pinhole(1, 1, 1e-3, 1e7, 0.1, -0.7)
            },
        ];
        for cam in cams {
            let text = to_project_json(&cam);
            assert_eq!(parse_lens(&text).expect("own output parses"), cam, "{text}");
        }
    }

    #[test]
    fn cc9_lens_file() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../shared/data/cc9/lens.json"
        );
        let Ok(text) = std::fs::read_to_string(path) else {
            eprintln!("skipping cc9_lens_file: {path} not found");
            return;
        };
        let cam = parse_lens(&text).expect("cc9 lens parses");
        assert_eq!((cam.width, cam.height), (800, 600));
        assert!(cam.is_pinhole());
        assert_relative_eq!(cam.fx, 573.8534);
        assert_relative_eq!(cam.fy, 575.0448);
        assert_relative_eq!(cam.cx, 406.0101);
        assert_relative_eq!(cam.cy, 309.0112);
        assert_relative_eq!(cam.skew, -0.6974);
        assert_eq!(parse_lens(&to_project_json(&cam)).expect("round trip"), cam);
    }

    #[test]
    fn opencv_yaml() {
        let cam = parse_lens(OPENCV_YAML).expect("OpenCV YAML parses");
        assert_eq!((cam.width, cam.height), (1920, 1080));
        assert_relative_eq!(cam.fx, 1412.3456789012345);
        assert_relative_eq!(cam.fy, 1413.1);
        assert_relative_eq!(cam.cx, 959.12);
        assert_relative_eq!(cam.cy, 542.33);
        assert_eq!(cam.skew, 0.0);
        match cam.distortion {
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                assert_relative_eq!(k1, -0.28);
                assert_relative_eq!(k2, 0.07);
                assert_relative_eq!(p1, 1e-4);
                assert_relative_eq!(p2, -2e-4);
                assert_eq!(k3, 0.0);
            }
            ref d => panic!("expected radtan, got {d:?}"),
        }
        // Nested-list forms, image_size and a fisheye flag.
        let yaml = "%YAML:1.0\nimage_size: [ 640, 480 ]\nfisheye: true\ncamera_matrix: [[300., 0., 320.], [0., 301., 240.], [0., 0., 1.]]\ndistortion_coefficients: [[0.1], [0.01], [-0.002], [0.0003]]\n";
        let cam = parse_lens(yaml).expect("valid");
        assert_eq!((cam.width, cam.height), (640, 480));
        assert_eq!(
            cam.distortion,
            Distortion::Fisheye {
                k1: 0.1,
                k2: 0.01,
                k3: -0.002,
                k4: 0.0003
            }
        );
    }

    #[test]
    fn opencv_json() {
        let cam = parse_lens(OPENCV_JSON).expect("OpenCV JSON parses");
        assert_eq!((cam.width, cam.height), (1280, 720));
        assert_eq!(
            (cam.fx, cam.fy, cam.cx, cam.cy, cam.skew),
            (900.0, 910.0, 640.0, 360.0, 0.5)
        );
        assert_eq!(
            cam.distortion,
            Distortion::Fisheye {
                k1: 0.05,
                k2: -0.01,
                k3: 0.002,
                k4: -0.0005
            }
        );
        // 4 coefficients without a fisheye marker are k1 k2 p1 p2.
        let radtan = OPENCV_JSON.replace(
            "\"distortion_model\": \"fisheye\"",
            "\"width\": 1280, \"height\": 720",
        );
        let radtan = radtan.replace("\"image_width\": 1280,\n    \"image_height\": 720,", "");
        let cam = parse_lens(&radtan).expect("valid");
        assert_eq!(
            cam.distortion,
            Distortion::RadTan {
                k1: 0.05,
                k2: -0.01,
                p1: 0.002,
                p2: -0.0005,
                k3: 0.0
            }
        );
    }

    #[test]
    fn gyroflow_profile() {
        let cam = parse_lens(GYROFLOW).expect("Gyroflow profile parses");
        assert_eq!((cam.width, cam.height), (2704, 2028));
        assert_eq!(
            (cam.fx, cam.fy, cam.cx, cam.cy, cam.skew),
            (1195.2, 1194.8, 1351.5, 1013.6, 0.0)
        );
        assert_eq!(
            cam.distortion,
            Distortion::Fisheye {
                k1: 0.0405,
                k2: 0.0213,
                k3: -0.0094,
                k4: 0.0017
            }
        );
        let other = GYROFLOW.replace(
            "\"distortion_model\": null",
            "\"distortion_model\": \"poly5\"",
        );
        let err = parse_lens(&other).unwrap_err();
        assert!(matches!(err, LensError::UnsupportedModel { .. }), "{err}");
        assert!(err.to_string().contains("poly5"), "{err}");
        let explicit = GYROFLOW.replace(
            "\"distortion_model\": null",
            "\"distortion_model\": \"opencv_fisheye\"",
        );
        assert!(parse_lens(&explicit).is_ok());
    }

    fn err(text: &str) -> String {
        match parse_lens(text) {
            Ok(cam) => panic!("expected an error, got {cam:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn garbage_is_rejected() {
        for text in [
            "",
            "   \n",
            "hello world",
            "{{{{",
            "[1, 2, 3]",
            "\u{0}\u{1}\u{2}",
            "{\"a\": 1}",
            "<?xml version=\"1.0\"?>\n<opencv_storage/>",
            "- a\n- b",
            "%YAML:1.0\n---\n",
        ] {
            let _ = err(text);
        }
        assert!(err("{\"model\": \"pinhole\", ").contains("invalid JSON"));
        assert!(err("{\"a\": 1}").contains("unrecognised lens file"));
        assert!(err("<?xml version=\"1.0\"?>").contains("XML"));
        // Deeply nested input must not overflow the stack.
        let deep = "[".repeat(100_000);
        let _ = err(&deep);
        let deep_yaml = format!("camera_matrix: {}", "[".repeat(100_000));
        assert!(err(&deep_yaml).contains("nested"));
        let deep_map = format!("camera_matrix: {}", "{a: ".repeat(100_000));
        assert!(err(&deep_map).contains("nested"));
        let _ = err(&"- ".repeat(300_000));
        assert!(err(&" ".repeat(2 << 20)).contains("bytes"));
        // Brackets inside quotes and comments do not count.
        assert_eq!(flow_depth("a: \"[[[[\" # {{{{\nb: [[1], '[[']"), 2);
    }

    #[test]
    fn missing_keys_are_named() {
        let no_fx =
            r#"{"model":"pinhole","width":640,"height":480,"fy":500,"cx":319.5,"cy":239.5}"#;
        assert!(err(no_fx).contains("`fx`"), "{}", err(no_fx));
        let no_h = r#"{"model":"pinhole","width":640,"fx":500,"fy":500,"cx":319.5,"cy":239.5}"#;
        assert!(err(no_h).contains("`height`"));
        let no_dist = r#"{"model":"fisheye","width":640,"height":480,"fx":500,"fy":500,"cx":319.5,"cy":239.5}"#;
        assert!(err(no_dist).contains("dist"));
        let no_size = OPENCV_YAML.replace("image_width: 1920\nimage_height: 1080\n", "");
        assert_eq!(parse_lens(&no_size), Err(LensError::MissingImageSize));
        assert!(err(&no_size).contains("image size"));
        let no_k = OPENCV_YAML.replace("camera_matrix", "camera_matrx");
        assert!(err(&no_k).contains("`camera_matrix`"), "{}", err(&no_k));
        let no_dim = GYROFLOW.replace("calib_dimension", "calib_dim");
        assert!(err(&no_dim).contains("`calib_dimension`"));
        let no_coeffs = GYROFLOW.replace("distortion_coeffs", "distortion");
        assert!(err(&no_coeffs).contains("fisheye_params.distortion_coeffs"));
    }

    #[test]
    fn wrong_values_are_explained() {
        let three = PROJECT.replace("[-0.28, 0.07, 0.0001, -0.0002]", "[-0.28, 0.07, 0.0001]");
        assert!(
            err(&three).contains("4 or 5 coefficients"),
            "{}",
            err(&three)
        );
        let pin_dist = PROJECT.replace("\"opencv\"", "\"pinhole\"");
        assert!(err(&pin_dist).contains("pinhole"));
        let fish5 = PROJECT
            .replace("\"opencv\"", "\"fisheye\"")
            .replace("-0.0002]", "-0.0002, 0.1]");
        assert!(
            err(&fish5).contains("4 fisheye coefficients"),
            "{}",
            err(&fish5)
        );
        let unknown = PROJECT.replace("\"opencv\"", "\"kb8\"");
        assert!(err(&unknown).contains("kb8"));
        let rational = OPENCV_YAML.replace("cols: 5", "cols: 8").replace(
            "-2.0000000000000001e-04, 0. ]",
            "-2.0000000000000001e-04, 0., 0.1, 0.2, 0.3 ]",
        );
        let msg = err(&rational);
        assert!(
            msg.contains("k1 k2 p1 p2") && msg.contains("rational"),
            "{msg}"
        );
        let rows_mismatch = OPENCV_YAML.replace("cols: 5", "cols: 4");
        assert!(err(&rows_mismatch).contains("rows x cols"));
        let neg_f = PROJECT.replace("600.5", "-600.5");
        let msg = err(&neg_f);
        assert!(matches!(parse_lens(&neg_f), Err(LensError::Camera(_))));
        assert!(msg.contains("fx") && msg.contains("-600.5"), "{msg}");
        let text_f = PROJECT.replace("600.5", "\"big\"");
        assert!(err(&text_f).contains("`fx` must be a finite number"));
        let bad_w = PROJECT.replace("800", "800.5");
        assert!(err(&bad_w).contains("`width`"));
        let zero_w = PROJECT.replace("800", "0");
        assert!(err(&zero_w).contains("`width`"));
        let bad_k = GYROFLOW.replace("[ 0.0, 0.0, 1.0 ]", "[ 0.0, 0.0, 2.0 ]");
        assert!(err(&bad_k).contains("[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]"));
        let stretched = GYROFLOW.replace(
            "\"input_horizontal_stretch\": 1.0",
            "\"input_horizontal_stretch\": 1.33",
        );
        assert!(err(&stretched).contains("input_horizontal_stretch"));
        let yaml_model = OPENCV_YAML.replace("flags: 0", "distortion_model: omnidir");
        assert!(err(&yaml_model).contains("omnidir"));
        let far_cx = PROJECT.replace("399.5", "1e6");
        assert!(err(&far_cx).contains("cx"));
    }
}
