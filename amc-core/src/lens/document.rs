//! Document parsing: JSON first, then (OpenCV-flavoured) YAML, unified as
//! `serde_json::Value`.

use super::LensError;
use serde_json::{Map, Value};

pub(super) fn parse_document(text: &str) -> Result<Value, LensError> {
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
pub(super) fn flow_depth(text: &str) -> usize {
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
