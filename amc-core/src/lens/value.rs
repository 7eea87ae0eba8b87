//! Reading typed, checked values (numbers, sizes, matrices, distortion coefficients)
//! out of a parsed document, with errors that name the key.

use super::LensError;
use crate::camera::Distortion;
use serde_json::{Map, Value};

/// Abbreviated rendering of a value for error messages.
pub(super) fn show(v: &Value) -> String {
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

pub(super) fn invalid(key: &str, expected: impl Into<String>, found: &Value) -> LensError {
    LensError::InvalidValue {
        key: key.to_string(),
        expected: expected.into(),
        found: show(found),
    }
}

pub(super) fn get<'a>(
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

pub(super) fn as_f64(v: &Value, key: &str) -> Result<f64, LensError> {
    match v.as_f64() {
        Some(f) if f.is_finite() => Ok(f),
        _ => Err(invalid(key, "a finite number", v)),
    }
}

pub(super) fn as_size(v: &Value, key: &str) -> Result<usize, LensError> {
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
pub(super) fn flat_numbers(v: &Value, key: &str, out: &mut Vec<f64>) -> Result<(), LensError> {
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
pub(super) fn read_matrix(v: &Value, key: &str) -> Result<Vec<f64>, LensError> {
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

/// Intrinsics `[fx, fy, cx, cy, skew]` from a 3x3 camera matrix
/// `[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`.
pub(super) fn intrinsics_from_k(v: &Value, key: &str) -> Result<[f64; 5], LensError> {
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
    Ok([k[0], k[4], k[2], k[5], k[1]])
}

pub(super) fn radtan_from(d: &[f64], key: &str, found: &Value) -> Result<Distortion, LensError> {
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

pub(super) fn fisheye_from(d: &[f64], key: &str, found: &Value) -> Result<Distortion, LensError> {
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
