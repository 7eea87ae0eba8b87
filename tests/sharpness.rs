//! Sharpness on real footage (issue 15's bar: at most 8% lost against `none`).
//!
//! Two things blur a stabilized picture that `none` (which follows the camera,
//! and for a pinhole samples whole pixels) does not: the plain average blends what a rotation cannot align
//! (parallax, a rolling shutter, movers), and bilinear sampling at the
//! fractional offsets of a moving view softens fine detail. `--deghost`
//! takes the first away and `--interpolation bicubic` most of the second; with
//! both, stabilize mode keeps cup, karma and cc9 within 8% of `none`'s
//! sharpness (docs/accuracy.md, "Sharpness"; measured 0.993 / 0.931 / 1.001).
//!
//! A third thing is not blur but magnification: `--zoom auto` shows the
//! crop at the input's size, and a gradient per output pixel falls by the
//! zoom factor. Saccade mode's held view needs more zoom than stabilize
//! mode's (karma: 0.900). In the paper's framing (`--zoom none`: the crop at
//! its own scale, as the paper's code exports it) both modes keep every clip
//! within 8% (measured 2026-12-04: stabilize 0.985 / 0.941 / 1.031, saccade
//! 0.990 / 0.977 / 1.076 on cup / karma / cc9).

use amc_e2e::*;
use serde_json::Value;

/// `amc eval CLIP ARGS --json`: each mode's metrics.
fn eval(args: &[&str]) -> Value {
    let mut all = vec!["eval".to_string()];
    all.extend(args.iter().map(|a| a.to_string()));
    all.extend(["--json".into(), "-q".into()]);
    let r = amc_ok(&all);
    serde_json::from_str(&r.stdout).expect("eval prints JSON")
}

/// A mode's metric `key` from `amc eval --json`.
fn metric(v: &Value, mode: &str, key: &str) -> f64 {
    let modes = v["modes"].as_array().expect("modes");
    let m = modes.iter().find(|m| m["mode"] == mode).expect("mode run");
    m["metrics"][key].as_f64().expect("metric")
}

/// Sharpness of `mode` against `none` in one eval (each against its own
/// `none`: a distorted lens's `none` is resampled too).
fn kept_in(v: &Value, mode: &str) -> f64 {
    metric(v, mode, "sharpness") / metric(v, "none", "sharpness")
}

/// [`kept_in`] stabilize mode.
fn kept(v: &Value) -> f64 {
    kept_in(v, "stabilize")
}

#[test]
fn deghost_and_bicubic_keep_real_footage_sharp() {
    let karma = data("karma/karma.mp4");
    let cup = data("cup/cup.mp4");
    let cc9 = data("cc9/frames");
    let cc9_lens = data("cc9/lens.json");
    let clips: [(&str, Vec<String>); 3] = [
        ("karma", vec![s(&karma), "--fov".into(), "90".into()]),
        ("cup", vec![s(&cup), "--fov".into(), "60".into()]),
        ("cc9", vec![s(&cc9), "--lens".into(), s(&cc9_lens)]),
    ];
    let mut failed = Vec::new();
    for (name, clip) in &clips {
        let clip: Vec<&str> = clip.iter().map(String::as_str).collect();
        let with = |extra: &[&'static str]| {
            let mut args = clip.clone();
            args.extend(extra);
            eval(&args)
        };
        let bilinear = with(&["--deghost", "6"]);
        let bicubic = with(&["--deghost", "6", "--interpolation", "bicubic"]);
        let (lin, cub) = (kept(&bilinear), kept(&bicubic));
        eprintln!("[{name}] stabilize sharpness / none: bilinear {lin:.3}, bicubic {cub:.3}");
        if cub < 0.92 {
            failed.push(format!(
                "{name}: bicubic keeps {cub:.3} of none's sharpness (bar 0.92)"
            ));
        }
        // Bicubic never blurs more than bilinear (cc9, JPEG frames with little
        // fine detail, gains least: 0.999 -> 1.001).
        if cub < lin - 0.002 {
            failed.push(format!("{name}: bicubic {cub:.3} below bilinear {lin:.3}"));
        }
        // The paper's framing: no magnification, so both modes.
        let unzoomed = with(&[
            "--deghost",
            "6",
            "--interpolation",
            "bicubic",
            "--zoom",
            "none",
        ]);
        for mode in ["stabilize", "saccade"] {
            let k = kept_in(&unzoomed, mode);
            eprintln!("[{name}] --zoom none, {mode} sharpness / none: {k:.3}");
            if k < 0.92 {
                failed.push(format!(
                    "{name}: {mode} with --zoom none keeps {k:.3} of none's sharpness (bar 0.92)"
                ));
            }
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}
