//! The report's tables: one per clip, and the paper's code beside ours.

use crate::compare::paper::PaperStatus;
use crate::compare::peers::{Fed, Method};
use crate::compare::results::{ClipResult, MethodResult};
use std::fmt::Write as _;

pub(super) fn opt(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        _ => "-".into(),
    }
}

/// Whether `label` is one of ours at the paper's settings.
pub(super) fn is_matched(label: &str) -> bool {
    Method::PAPER
        .iter()
        .any(|m| m.is_matched() && m.label() == label)
}

pub(super) fn find<'a>(c: &'a ClipResult, label: &str) -> Option<&'a MethodResult> {
    c.methods.iter().find(|m| m.method == label)
}

/// The Markdown table of one clip.
pub fn clip_table(c: &ClipResult) -> String {
    let mut s = String::new();
    let base = find(c, "vidstab-s10").map(|m| m.frames_per_second);
    let _ = writeln!(
        s,
        "| method | frames/s | x vid.stab s10 | peak MiB | normal flow (px) | normal flow (input px) | frame change | sharpness | valid % | cropping | distortion | stability (Liu) | stability (<= {} Hz) | ITF (dB) |",
        crate::compare::liu::STABILITY_BAND_HZ
    );
    s += "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for m in &c.methods {
        let p = &m.measured.paper;
        let ratio = base
            .filter(|b| *b > 0.0)
            .map(|b| format!("{:.1}x", m.frames_per_second / b))
            .unwrap_or_else(|| "-".into());
        let _ = writeln!(
            s,
            "| {} | {:.0} | {} | {:.0} | {:.3} | {:.3} | {:.4} | {:.4} | {:.1} | {} | {} | {} | {} | {} |",
            m.method,
            m.frames_per_second,
            ratio,
            m.usage.peak_mib,
            p.rms_normal_flow,
            m.measured.rms_normal_flow_input_px,
            p.rms_change,
            p.sharpness,
            100.0 * p.valid_fraction,
            opt(m.measured.cropping, 3),
            opt(m.measured.distortion, 3),
            opt(m.measured.stability.score, 3),
            opt(m.measured.stability.band_score, 3),
            opt(m.measured.itf_db, 1),
        );
    }
    s
}

/// The paper's code beside ours at matched settings, on one clip: frame change
/// and normal flow (output px; both outputs have the paper's crop size) and
/// their ratios to the same implementation's `none`.
pub fn paper_table(c: &ClipResult) -> Option<String> {
    let pairs = [
        ("paper-none", "ours-matched-none"),
        ("paper-stabilize", "ours-matched-stabilize"),
        ("paper-saccade", "ours-matched-saccade"),
    ];
    let (pn, on) = (find(c, pairs[0].0)?, find(c, pairs[0].1)?);
    let mut s = String::new();
    s += "| mode | frame change: paper | ratio to none | ours matched | ratio to none | normal flow (px): paper | ratio to none | ours matched | ratio to none | frames/s: paper (its loop) | ours matched | peak MiB: paper | ours matched |\n";
    s += "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (mode, (paper_label, ours_label)) in ["none", "stabilize", "saccade"].iter().zip(pairs) {
        let (Some(p), Some(o)) = (find(c, paper_label), find(c, ours_label)) else {
            continue;
        };
        let (pp, op) = (&p.measured.paper, &o.measured.paper);
        let _ = writeln!(
            s,
            "| {mode} | {:.4} | {} | {:.4} | {} | {:.3} | {} | {:.3} | {} | {:.1} ({}) | {:.0} | {:.0} | {:.0} |",
            pp.rms_change,
            ratio(pp.rms_change, pn.measured.paper.rms_change),
            op.rms_change,
            ratio(op.rms_change, on.measured.paper.rms_change),
            pp.rms_normal_flow,
            ratio(pp.rms_normal_flow, pn.measured.paper.rms_normal_flow),
            op.rms_normal_flow,
            ratio(op.rms_normal_flow, on.measured.paper.rms_normal_flow),
            p.frames_per_second,
            opt(p.loop_frames_per_second, 1),
            o.frames_per_second,
            p.usage.peak_mib,
            o.usage.peak_mib,
        );
    }
    // The two `none` runs differ: the paper downsamples its input 2x through
    // `initUndistortRectifyMap` with the principal point halved (`c / 2`, not
    // `(c + 0.5) / 2 - 0.5`), so every output pixel is one source pixel
    // (decimation, aliased), where ours averages the 2x2 it covers. Its `none`
    // is sharper and changes more from frame to frame, which inflates its own
    // ratios; against one baseline (ours, the filtered input) the two compare
    // as absolute values do.
    let _ = writeln!(
        s,
        "\nAgainst one baseline (`ours-matched-none`: the same input, filtered; the paper's own `none` \
         decimates its 2x downsampling, sharpness {:.4} against {:.4}, so its frame change is {:.2}x ours):\n",
        pn.measured.paper.sharpness,
        on.measured.paper.sharpness,
        pn.measured.paper.rms_change / base_of(on.measured.paper.rms_change),
    );
    s += "| mode | frame change: paper | ours matched | normal flow: paper | ours matched | sharpness: paper | ours matched |\n";
    s += "|---|---|---|---|---|---|---|\n";
    let base = &on.measured.paper;
    for (mode, (paper_label, ours_label)) in ["stabilize", "saccade"].iter().zip(&pairs[1..]) {
        let (Some(p), Some(o)) = (find(c, paper_label), find(c, ours_label)) else {
            continue;
        };
        let (pp, op) = (&p.measured.paper, &o.measured.paper);
        let _ = writeln!(
            s,
            "| {mode} | {} | {} | {} | {} | {} | {} |",
            ratio(pp.rms_change, base.rms_change),
            ratio(op.rms_change, base.rms_change),
            ratio(pp.rms_normal_flow, base.rms_normal_flow),
            ratio(op.rms_normal_flow, base.rms_normal_flow),
            ratio(pp.sharpness, base.sharpness),
            ratio(op.sharpness, base.sharpness),
        );
    }
    for mode in ["stabilize", "saccade"] {
        if let Some(t) = fed_table(c, base, mode) {
            s += &t;
        }
    }
    let borders: Vec<String> = pairs
        .iter()
        .filter_map(|(_, ours)| find(c, ours))
        .filter_map(|m| {
            Some(format!(
                "{} {} of {}",
                m.method, m.frames_with_border?, m.frames
            ))
        })
        .collect();
    let _ = writeln!(
        s,
        "\nOutput frames with an uncovered pixel at the paper's fixed margin (ours, from the renderer's coverage): {}.",
        borders.join(", ")
    );
    Some(s)
}

/// The paper's code in `mode` fed our orientations and the true ones, beside
/// its own and ours, against the common baseline `base`: it tells what the
/// paper's tracker does to its numbers (its own row against the row fed ours)
/// from what its renderer does (the row fed ours against ours matched).
pub(super) fn fed_table(
    c: &ClipResult,
    base: &amc_core::metrics::ClipMetrics,
    mode: &str,
) -> Option<String> {
    let in_mode = |m: &Method| m.paper_mode() == Some(mode) || m.our_mode() == Some(mode);
    let of = |fed: Option<Fed>, matched: bool| {
        Method::PAPER
            .into_iter()
            .filter(in_mode)
            .find(|m| m.fed() == fed && m.is_matched() == matched)
    };
    find(c, of(Some(Fed::Ours), false)?.label())?;
    let mut s = format!(
        "\nThe paper's {mode} mode fed other orientations than its tracker's (its view filter, \
         renderer and average unchanged), against the same baseline: its own row against the row \
         fed ours is what the two trackers' estimates do to the numbers, the row fed ours against \
         ours matched is what the two renderers do.\n\n\
         | orientations | renderer | method | frame change | normal flow | sharpness |\n\
         |---|---|---|---|---|---|\n",
    );
    let rows = [
        ("its tracker's", "the paper's", of(None, false)),
        ("ours", "the paper's", of(Some(Fed::Ours), false)),
        ("the truth", "the paper's", of(Some(Fed::Truth), false)),
        ("ours", "ours", of(None, true)),
    ];
    for (orientations, renderer, method) in rows {
        let Some(m) = method.and_then(|method| find(c, method.label())) else {
            continue;
        };
        let p = &m.measured.paper;
        let _ = writeln!(
            s,
            "| {orientations} | {renderer} | {} | {} | {} | {} |",
            m.method,
            ratio(p.rms_change, base.rms_change),
            ratio(p.rms_normal_flow, base.rms_normal_flow),
            ratio(p.sharpness, base.sharpness),
        );
    }
    // Where the paper's code removes more than ours, how much of the
    // difference its orientations make and how much its renderer.
    let get = |m: Option<Method>| {
        m.and_then(|m| find(c, m.label()))
            .map(|r| &r.measured.paper)
    };
    if let (Some(own), Some(fed), Some(ours)) = (
        get(of(None, false)),
        get(of(Some(Fed::Ours), false)),
        get(of(None, true)),
    ) {
        type Metric = fn(&amc_core::metrics::ClipMetrics) -> f64;
        let metrics: [(&str, Metric); 2] = [
            ("frame change", |m| m.rms_change),
            ("normal flow", |m| m.rms_normal_flow),
        ];
        for (name, value) in metrics {
            let (own, fed, ours) = (value(own), value(fed), value(ours));
            if own < ours {
                let b = base_of(value(base));
                let _ = writeln!(
                    s,
                    "\nThe paper's code removes more {name} in {mode} mode than ours matched \
                     ({:.3} against {:.3}); of the difference, {:.3}, its orientations make \
                     {:+.3} (fed ours, its renderer gives {:.3}) and its renderer {:+.3}.",
                    own / b,
                    ours / b,
                    (ours - own) / b,
                    (fed - own) / b,
                    fed / b,
                    (ours - fed) / b,
                );
            }
        }
    }
    Some(s)
}

/// A baseline to divide by (never zero).
pub(super) fn base_of(v: f64) -> f64 {
    v.max(f64::MIN_POSITIVE)
}

/// `v / base` for the paper's tables, three decimals; `-` without a baseline.
pub(super) fn ratio(v: f64, base: f64) -> String {
    if base > 0.0 {
        format!("{:.3}", v / base)
    } else {
        "-".into()
    }
}

/// The report's line on the paper's code (none when it was not asked for).
pub(super) fn paper_line(paper: &PaperStatus) -> Option<String> {
    match paper {
        PaperStatus::NotRequested => None,
        PaperStatus::Skipped(why) => Some(format!(
            "The paper's code (`--peer paper`) was **skipped**: {why}.\n"
        )),
        PaperStatus::Ready(env) => Some(format!(
            "The paper's code (`--peer paper`): {}.\n",
            env.versions.describe()
        )),
    }
}
