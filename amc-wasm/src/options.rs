//! The core's option table for the page (`options()`), and the page's values
//! read as the command line and the REST API read them (`resolveOptions`).
//!
//! The page builds its settings form from [`amc_core::options::OPTIONS`]:
//! every option's name, flag, help (with its range and default), allowed
//! values and default, so its limits, tooltips and starting values are the
//! CLI's. The defaults are not written here: each is read off
//! [`StabilizerOptions::default`], at the field the option's setter writes.

use crate::js::{err, to_js};
use amc_core::options::{Allowed, OptionSpec, OPTIONS};
use amc_core::{AmcError, LensSpec, ReadoutSpec, StabilizerOptions};
use serde_json::{json, Map, Value};
use wasm_bindgen::prelude::*;

/// The parameters as JSON (the readout is set apart: [`ReadoutSpec`]).
fn params_value(o: &StabilizerOptions) -> Value {
    serde_json::to_value(&o.params).expect("StabilizerParams serialize")
}

/// The first leaf where `a` and `b` differ, as a path of object keys.
fn diff_path(a: &Value, b: &Value) -> Option<Vec<String>> {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => x.iter().find_map(|(k, va)| {
            let vb = y.get(k).unwrap_or(&Value::Null);
            diff_path(va, vb).map(|mut p| {
                p.insert(0, k.clone());
                p
            })
        }),
        _ if a == b => None,
        _ => Some(Vec::new()),
    }
}

fn at<'a>(v: &'a Value, path: &[String]) -> &'a Value {
    path.iter().fold(v, |v, k| v.get(k).unwrap_or(&Value::Null))
}

/// Values to set an option to, to find the field its setter writes (one of
/// them differs from the default).
fn probes(spec: &OptionSpec) -> Vec<String> {
    match spec.allowed {
        Allowed::Words(words) => words.iter().map(|w| w.to_string()).collect(),
        Allowed::Integer { min, max } => vec![max.to_string(), min.to_string()],
        Allowed::Number { min, max, .. } => vec![
            max.to_string(),
            ((min + max) / 2.0).to_string(),
            min.to_string(),
        ],
    }
}

/// An option's default as JSON: a number, a word, or `null` where the
/// default is not a value of the option (`readout_ms`: the lens file's;
/// `roll_rate_a`: `rate_a`'s; `output_width`: the input's).
pub fn default_of(spec: &OptionSpec) -> Value {
    let base = StabilizerOptions::default();
    match spec.name {
        "fov" => {
            return match base.lens {
                LensSpec::Fov(deg) => json!(deg),
                _ => json!("auto"),
            }
        }
        "readout_ms" => {
            return match base.readout {
                ReadoutSpec::Ms(ms) => json!(ms),
                ReadoutSpec::Auto => json!("auto"),
                ReadoutSpec::FromLens => Value::Null,
            }
        }
        _ => {}
    }
    let def = params_value(&base);
    for probe in probes(spec) {
        let mut o = StabilizerOptions::default();
        if o.set(spec.name, &probe).is_err() {
            continue;
        }
        match diff_path(&def, &params_value(&o)) {
            // Setting it to this word changed nothing: this word is the default.
            None if matches!(spec.allowed, Allowed::Words(_)) => return json!(probe),
            None => continue,
            Some(path) => {
                let v = at(&def, &path);
                if let (Allowed::Words(_), Some(word)) = (spec.allowed, v.as_str()) {
                    return json!(word);
                }
                return v.clone();
            }
        }
    }
    Value::Null
}

/// What an option accepts, as JSON: `{kind: "words", words}`,
/// `{kind: "integer", min, max}` or `{kind: "number", min, max, above_min, words}`.
fn allowed_value(a: Allowed) -> Value {
    match a {
        Allowed::Words(words) => json!({ "kind": "words", "words": words }),
        Allowed::Integer { min, max } => json!({ "kind": "integer", "min": min, "max": max }),
        Allowed::Number {
            min,
            max,
            above_min,
            words,
        } => json!({
            "kind": "number", "min": min, "max": max, "above_min": above_min, "words": words,
        }),
    }
}

/// The option table as JSON, in the order of `amc stabilize --help`.
pub fn table() -> Value {
    Value::Array(
        OPTIONS
            .iter()
            .map(|o| {
                json!({
                    "name": o.name,
                    "flag": o.flag,
                    "value_name": o.value_name,
                    "help": o.help,
                    "allowed": allowed_value(o.allowed),
                    "default": default_of(o),
                })
            })
            .collect(),
    )
}

/// Reads `values` (option name to its text; `null` or empty: the default)
/// as `--name value` would be: `{params, fov, readout}`, the parameters
/// without the shutter (the readout is `readout`: milliseconds, `"auto"`
/// or `null` for the lens file's, else 0, as `PassPlan` takes it), and
/// `fov` degrees or `"auto"`.
pub fn resolve(values: &Map<String, Value>) -> Result<Value, AmcError> {
    let mut o = StabilizerOptions::default();
    for (name, v) in values {
        let text = match v {
            Value::Null => continue,
            Value::String(s) if s.trim().is_empty() => continue,
            Value::String(s) => s.clone(),
            other => other.to_string(),
        };
        o.set(name, &text)?;
    }
    o.validate()?;
    let mut params = params_value(&o);
    if let Some(p) = params.as_object_mut() {
        p.remove("shutter");
    }
    let fov = match o.lens {
        LensSpec::Fov(deg) => json!(deg),
        _ => json!("auto"),
    };
    let readout = match o.readout {
        ReadoutSpec::Ms(ms) => json!(ms),
        ReadoutSpec::Auto => json!("auto"),
        ReadoutSpec::FromLens => Value::Null,
    };
    Ok(json!({ "params": params, "fov": fov, "readout": readout }))
}

/// `options()`: every option of a run as the command line has it (see
/// `table`): `[{name, flag, value_name, help, allowed, default}]`.
#[wasm_bindgen]
pub fn options() -> Result<JsValue, JsError> {
    to_js(&table())
}

/// `resolveOptions(valuesJson)`: the page's values (a JSON object of option
/// name to text) as the core reads them (see `resolve`); a bad value is an
/// `Error` naming the option and what it allows.
#[wasm_bindgen(js_name = resolveOptions)]
pub fn resolve_options(values_json: &str) -> Result<JsValue, JsError> {
    let values: Map<String, Value> = serde_json::from_str(values_json).map_err(|e| {
        JsError::new(&format!(
            "invalid options: {e} (allowed: a JSON object of option name to value)"
        ))
    })?;
    to_js(&resolve(&values).map_err(err)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_cores() {
        let t = table();
        let def = |name: &str| {
            t.as_array()
                .unwrap()
                .iter()
                .find(|o| o["name"] == name)
                .unwrap()["default"]
                .clone()
        };
        assert_eq!(def("mode"), json!("stabilize"));
        assert_eq!(def("roll"), json!("smooth"));
        assert_eq!(def("zoom"), json!("auto"));
        assert_eq!(def("interpolation"), json!("bilinear"));
        assert_eq!(def("antialias"), json!("auto"));
        assert_eq!(def("fov"), json!("auto"));
        assert_eq!(def("readout_ms"), Value::Null);
        assert_eq!(def("n_avg"), json!(6));
        assert_eq!(def("deghost"), json!("auto"));
        assert_eq!(def("margin"), json!(0.125));
        assert_eq!(def("max_crop"), json!(0.15));
        assert_eq!(def("rate_a"), json!(2.0));
        assert_eq!(def("rate_b"), json!(20.0));
        assert_eq!(def("lookahead"), json!(0));
        assert_eq!(def("n_track"), json!(5));
        assert_eq!(def("track_width"), json!(320));
        for unset in [
            "roll_rate_a",
            "roll_rate_b",
            "output_width",
            "output_height",
        ] {
            assert_eq!(def(unset), Value::Null, "{unset}");
        }
        // Every option's help names its default: a word or a number the help shows.
        for o in t.as_array().unwrap() {
            let help = o["help"].as_str().unwrap();
            match &o["default"] {
                Value::Null => assert!(help.contains("(default: "), "{help}"),
                Value::String(w) => assert!(help.contains(&format!("(default {w}")), "{help}"),
                Value::Number(n) => {
                    let n = n.as_f64().unwrap();
                    assert!(
                        help.contains(&format!("(default {n}")),
                        "{}: {help}",
                        o["name"]
                    );
                }
                other => panic!("{other}"),
            }
        }
    }

    #[test]
    fn resolve_reads_values_as_the_cli_does() {
        let empty = resolve(&Map::new()).unwrap();
        let mut core = serde_json::to_value(amc_core::StabilizerParams::default()).unwrap();
        core.as_object_mut().unwrap().remove("shutter");
        assert_eq!(empty["params"], core);
        assert_eq!(empty["fov"], json!("auto"));
        assert_eq!(empty["readout"], Value::Null);
        let v: Map<String, Value> = serde_json::from_value(json!({
            "n_avg": "4", "fov": "90", "readout_ms": "auto", "roll": "lock", "rate_a": 1.5,
            "roll_rate_b": "", "output_width": null,
        }))
        .unwrap();
        let r = resolve(&v).unwrap();
        assert_eq!(r["params"]["render"]["n_avg"], json!(4));
        assert_eq!(r["params"]["view"]["roll"], json!("lock"));
        assert_eq!(r["params"]["view"]["rate_a"], json!(1.5));
        assert_eq!(r["params"]["view"]["roll_rate_b"], Value::Null);
        assert_eq!(r["fov"], json!(90.0));
        assert_eq!(r["readout"], json!("auto"));
        let bad: Map<String, Value> = serde_json::from_value(json!({ "n_avg": "0" })).unwrap();
        assert!(resolve(&bad).unwrap_err().to_string().contains("n_avg"));
        let unknown: Map<String, Value> = serde_json::from_value(json!({ "bogus": "1" })).unwrap();
        assert!(resolve(&unknown).is_err());
    }
}
