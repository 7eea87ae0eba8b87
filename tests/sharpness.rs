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

/// `amc stabilize` of `clip` with `args` (`-o` a `.y4m`): its `--metrics` JSON.
fn stabilize_metrics(clip: &[String], args: &[&str], dir: &std::path::Path) -> Value {
    let (out, metrics) = (dir.join("out.y4m"), dir.join("metrics.json"));
    let mut all = vec!["stabilize".to_string()];
    all.extend(clip.iter().cloned());
    all.extend([
        "-o".into(),
        s(&out),
        "--metrics".into(),
        s(&metrics),
        "-q".into(),
    ]);
    all.extend(args.iter().map(|a| a.to_string()));
    amc_ok(&all);
    read_json(&metrics)
}

/// Issue 48's bar: on real footage the default (ghost-free averaging with its
/// threshold from the clip's noise) keeps at least 0.95 of the sharpness of
/// one frame (`--n-avg 1`, the same framing), where the plain average does not.
#[test]
fn the_default_keeps_real_footage_as_sharp_as_one_frame() {
    let dir = tempfile::tempdir().unwrap();
    let clips: [(&str, Vec<String>); 3] = [
        ("karma", vec![s(&data("karma/karma.mp4"))]),
        ("cup", vec![s(&data("cup/cup.mp4"))]),
        (
            "cc9",
            vec![
                s(&data("cc9/frames")),
                "--lens".into(),
                s(&data("cc9/lens.json")),
                "--fps".into(),
                "30".into(),
            ],
        ),
    ];
    let mut failed = Vec::new();
    for (name, clip) in &clips {
        let sharp = |args: &[&str]| {
            let m = stabilize_metrics(clip, args, dir.path());
            (
                json_f64(&m, "/metrics/sharpness"),
                m["deghost_levels"].clone(),
            )
        };
        let (default, levels) = sharp(&[]);
        let (one, _) = sharp(&["--n-avg", "1"]);
        let (plain, _) = sharp(&["--deghost", "off"]);
        let (kept, plain_kept) = (default / one, plain / one);
        eprintln!(
            "[{name}] sharpness / --n-avg 1: default {kept:.3} (threshold {levels}), plain average {plain_kept:.3}"
        );
        assert!(
            levels.as_f64().is_some_and(|l| (2.0..=8.0).contains(&l)),
            "{name}: {levels}"
        );
        if kept < 0.95 {
            failed.push(format!(
                "{name}: the default keeps {kept:.3} of one frame's sharpness"
            ));
        }
        // The check can fail: the plain average smears these clips.
        if plain_kept > 0.9 {
            failed.push(format!(
                "{name}: the plain average keeps {plain_kept:.3}: no smear to remove?"
            ));
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

/// Where the scene is static (a panorama seen by a rotating camera, with
/// sensor noise and x264's artefacts), the default still averages: less frame
/// change and normal flow than one frame, and a threshold above the floor.
#[test]
fn the_default_still_averages_a_static_noisy_scene() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("clip");
    synth(
        &frames,
        &[
            "--width",
            "640",
            "--height",
            "360",
            "--seconds",
            "2",
            "--seed",
            "41",
            "--shake-dps",
            "150",
        ],
    );
    let clip = dir.path().join("noisy.mp4");
    amc_e2e::fixtures::ffmpeg(&[
        "-framerate",
        "60",
        "-i",
        &s(&frames.join("frame-%06d.png")),
        "-vf",
        "noise=alls=10:allf=t+u,format=yuv420p",
        "-c:v",
        "libx264",
        "-crf",
        "20",
        &s(&clip),
    ]);
    let input = vec![s(&clip), "--lens".into(), s(&frames.join("lens.json"))];
    let default = stabilize_metrics(&input, &[], dir.path());
    let one = stabilize_metrics(&input, &["--n-avg", "1"], dir.path());
    let m = |v: &Value, k: &str| json_f64(v, &format!("/metrics/{k}"));
    let levels = json_f64(&default, "/deghost_levels");
    eprintln!(
        "static noisy scene: threshold {levels:.2}; frame change {:.4} vs {:.4}, normal flow {:.3} vs {:.3}, sharpness {:.4} vs {:.4}",
        m(&default, "rms_change"),
        m(&one, "rms_change"),
        m(&default, "rms_normal_flow"),
        m(&one, "rms_normal_flow"),
        m(&default, "sharpness"),
        m(&one, "sharpness"),
    );
    assert!(levels > 2.5, "the noise sets the threshold: {levels}");
    // Measured 0.92x and 0.96x (the threshold spares the edges, which carry
    // normal flow).
    assert!(m(&default, "rms_change") < 0.98 * m(&one, "rms_change"));
    assert!(m(&default, "rms_normal_flow") < 0.98 * m(&one, "rms_normal_flow"));
}
