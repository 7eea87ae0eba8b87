//! The bars we set ourselves, whether each clip clears them, and where a peer wins.

use super::tables::{find, is_matched, opt};
use crate::compare::results::{ClipResult, MethodResult};

/// "Equal" cropping tolerance for the bars (cropping ratios differing by less).
pub(super) const CROP_TOLERANCE: f64 = 0.005;
/// Speed factor our `stabilize` must have over vid.stab's two passes.
pub(super) const SPEED_BAR: f64 = 5.0;
/// Share of the peer's sharpness a method must keep for a win on frame change
/// or normal flow to count: blur lowers both, and must not pass for stability.
pub(super) const SHARPNESS_BAR: f64 = 0.95;

/// Lower is better on these; `OrEqual`: a tie clears the bar too.
#[derive(Clone, Copy, PartialEq)]
enum Below {
    Strictly,
    OrEqual,
}

/// A bar on frame change or normal flow (`x` ours, `y` the peer's, lower is
/// better), cleared only where ours also keeps [`SHARPNESS_BAR`] of the
/// peer's sharpness.
fn stability_bar(
    what: String,
    (ours, peer): (&MethodResult, &MethodResult),
    (x, y): (f64, f64),
    below: Below,
    digits: usize,
) -> Bar {
    let (a, b) = (ours.measured.paper.sharpness, peer.measured.paper.sharpness);
    let sharp = a >= SHARPNESS_BAR * b;
    let lower = if below == Below::OrEqual {
        x <= y
    } else {
        x < y
    };
    Bar {
        what: format!("{what}, keeping >= {SHARPNESS_BAR} of its sharpness"),
        cleared: lower && sharp,
        detail: format!("{x:.digits$} vs {y:.digits$}; sharpness {a:.4} vs {b:.4}"),
    }
}

/// One bar: what, ours, theirs, cleared.
pub struct Bar {
    pub what: String,
    pub cleared: bool,
    pub detail: String,
}

/// The bars of the issue for one clip (`stabilize` vs vid.stab, `saccade` vs tripod).
pub fn bars(c: &ClipResult) -> Vec<Bar> {
    let mut out = framing_bars(c);
    if !c.has_bars {
        return out;
    }
    let (Some(st), Some(sa)) = (find(c, "stabilize"), find(c, "saccade")) else {
        return out;
    };
    for peer in ["vidstab-s10", "vidstab-s30"] {
        let Some(p) = find(c, peer) else { continue };
        let (a, b) = (
            st.measured.rms_normal_flow_input_px,
            p.measured.rms_normal_flow_input_px,
        );
        out.push(stability_bar(
            format!("stabilize < {peer} on RMS normal flow (input px)"),
            (st, p),
            (a, b),
            Below::Strictly,
            3,
        ));
        let (a, b) = (st.measured.distortion, p.measured.distortion);
        out.push(Bar {
            what: format!("stabilize >= {peer} on distortion (1 = none)"),
            cleared: matches!((a, b), (Some(x), Some(y)) if x >= y),
            detail: format!("{} vs {}", opt(a, 3), opt(b, 3)),
        });
        // `framing_bars` already states stabilize against s30 on cropping, on every clip.
        if peer != "vidstab-s30" {
            let (a, b) = (st.measured.cropping, p.measured.cropping);
            out.push(Bar {
                what: format!("stabilize >= {peer} on cropping (kept fraction)"),
                cleared: matches!((a, b), (Some(x), Some(y)) if x >= y - CROP_TOLERANCE),
                detail: format!("{} vs {}", opt(a, 3), opt(b, 3)),
            });
        }
        let r = st.frames_per_second / p.frames_per_second.max(1e-9);
        out.push(Bar {
            what: format!("stabilize >= {SPEED_BAR}x faster than {peer} (both passes)"),
            cleared: r >= SPEED_BAR,
            detail: format!(
                "{:.0} vs {:.0} frames/s = {r:.1}x",
                st.frames_per_second, p.frames_per_second
            ),
        });
    }
    if let Some(t) = find(c, "vidstab-tripod") {
        let (a, b) = (sa.measured.paper.rms_change, t.measured.paper.rms_change);
        out.push(stability_bar(
            "saccade < vidstab-tripod on RMS frame change".into(),
            (sa, t),
            (a, b),
            Below::Strictly,
            4,
        ));
    }
    out
}

/// The framing bars, on every clip: our default framing (`--zoom auto`, crop
/// budget 0.15) shows no border and keeps at least vid.stab `smoothing=30`'s
/// share of the width (at its default zoom), online and offline, and moves no
/// more than vid.stab: offline (`--lookahead`) than `smoothing=30`, online than
/// `smoothing=10` (frame change, and normal flow in input px).
pub fn framing_bars(c: &ClipResult) -> Vec<Bar> {
    let mut out = Vec::new();
    // The matched runs keep the paper's fixed margin, not the default framing.
    let default_framing = |m: &&MethodResult| !is_matched(m.method);
    for m in c.methods.iter().filter(default_framing) {
        if let Some(n) = m.frames_with_border {
            out.push(Bar {
                what: format!("{}: no output frame with an uncovered pixel", m.method),
                cleared: n == 0,
                detail: format!("{n} of {} frames", m.frames),
            });
        }
    }
    for (ours, peer) in [
        ("stabilize-lookahead", "vidstab-s30"),
        ("stabilize", "vidstab-s10"),
    ] {
        let (Some(a), Some(p)) = (find(c, ours), find(c, peer)) else {
            continue;
        };
        if let Some(wide) = find(c, "vidstab-s30") {
            let (x, y) = (a.measured.cropping, wide.measured.cropping);
            out.push(Bar {
                what: format!("{ours} >= vidstab-s30 on cropping (kept fraction)"),
                cleared: matches!((x, y), (Some(x), Some(y)) if x >= y - CROP_TOLERANCE),
                detail: format!("{} vs {}", opt(x, 3), opt(y, 3)),
            });
        }
        let (x, y) = (a.measured.paper.rms_change, p.measured.paper.rms_change);
        out.push(stability_bar(
            format!("{ours} <= {peer} on RMS frame change"),
            (a, p),
            (x, y),
            Below::OrEqual,
            4,
        ));
        let (x, y) = (
            a.measured.rms_normal_flow_input_px,
            p.measured.rms_normal_flow_input_px,
        );
        out.push(stability_bar(
            format!("{ours} <= {peer} on RMS normal flow (input px)"),
            (a, p),
            (x, y),
            Below::OrEqual,
            3,
        ));
    }
    out
}

/// Where a peer wins on a headline metric against our best corresponding mode.
pub(super) fn peer_wins(c: &ClipResult) -> Vec<String> {
    let mut wins = Vec::new();
    let ours: Vec<&MethodResult> = c
        .methods
        .iter()
        .filter(|m| matches!(m.method, "stabilize" | "saccade" | "stabilize-lookahead"))
        .collect();
    let peers = c
        .methods
        .iter()
        .filter(|m| m.method.starts_with("vidstab") || m.method == "deshake");
    type Get = fn(&MethodResult) -> Option<f64>;
    let metrics: [(&str, Get, bool); 4] = [
        (
            "normal flow (input px)",
            |m| Some(m.measured.rms_normal_flow_input_px),
            false,
        ),
        ("frame change", |m| Some(m.measured.paper.rms_change), false),
        ("stability (Liu)", |m| m.measured.stability.score, true),
        ("ITF", |m| m.measured.itf_db, true),
    ];
    for p in peers {
        for (name, get, higher_better) in metrics {
            let Some(pv) = get(p).filter(|v| v.is_finite()) else {
                continue;
            };
            let best = ours
                .iter()
                .filter_map(|m| get(m).filter(|v| v.is_finite()))
                .fold(None, |acc: Option<f64>, v| {
                    Some(match acc {
                        None => v,
                        Some(a) if higher_better => a.max(v),
                        Some(a) => a.min(v),
                    })
                });
            if let Some(b) = best {
                let wins_here = if higher_better { pv > b } else { pv < b };
                if wins_here {
                    wins.push(format!(
                        "{} beats all our modes on {name} ({} vs our best {})",
                        p.method,
                        opt(Some(pv), 4),
                        opt(Some(b), 4)
                    ));
                }
            }
        }
    }
    wins
}
