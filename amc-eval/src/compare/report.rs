//! The comparison report: `README.md` (one table per clip, the bars we set
//! ourselves and whether they are cleared), per clip a plot (apparent angular
//! speed and normal flow per frame, every method) and a strip of the middle
//! frame side by side, and `results.json` with every number.

use super::config::CompareConfig;
use super::error::CompareError;
use super::paper::PaperStatus;
use super::peers::{Fed, Method};
use super::results::{ClipResult, MethodResult};
use crate::plot::{self, ModeSeries};
use amc_core::image::Frame;
use std::fmt::Write as _;
use std::path::Path;

/// Name of the Markdown report in the report folder.
pub const REPORT_FILE: &str = "README.md";
/// Width of one tile of the frame strip, px.
const TILE_WIDTH: u32 = 320;
/// Tiles per row of the frame strip.
const STRIP_COLUMNS: u32 = 3;
/// "Equal" cropping tolerance for the bars (cropping ratios differing by less).
const CROP_TOLERANCE: f64 = 0.005;
/// Speed factor our `stabilize` must have over vid.stab's two passes.
const SPEED_BAR: f64 = 5.0;

/// Writes `bytes` to `path` atomically, readable by everyone (0644), like the plots.
fn write_public(path: &Path, bytes: &[u8]) -> Result<(), CompareError> {
    amc_video::write_atomic(path, bytes)?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o644))
            .map_err(|e| CompareError::io(path, e))?;
    }
    Ok(())
}

/// The machine the report ran on: CPU model, logical CPUs, memory.
pub fn machine_description(extra: Option<&str>) -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cpus = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let mem_gib = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("MemTotal:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map(|kib| kib / 1024.0 / 1024.0);
    let mut s = format!("{cpu}, {cpus} logical CPUs");
    if let Some(m) = mem_gib {
        s += &format!(", {m:.0} GiB memory");
    }
    if let Some(e) = extra {
        s = format!("{e} ({s})");
    }
    s
}

fn ffmpeg_version() -> String {
    std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .ok()
        .and_then(|o| {
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .next()
                .map(|l| l.split(" Copyright").next().unwrap_or(l).to_string())
        })
        .unwrap_or_else(|| "ffmpeg (version unknown)".into())
}

fn opt(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        _ => "-".into(),
    }
}

/// Whether `label` is one of ours at the paper's settings.
fn is_matched(label: &str) -> bool {
    Method::PAPER
        .iter()
        .any(|m| m.is_matched() && m.label() == label)
}

fn find<'a>(c: &'a ClipResult, label: &str) -> Option<&'a MethodResult> {
    c.methods.iter().find(|m| m.method == label)
}

/// The Markdown table of one clip.
pub fn clip_table(c: &ClipResult) -> String {
    let mut s = String::new();
    let base = find(c, "vidstab-s10").map(|m| m.frames_per_second);
    let _ = writeln!(
        s,
        "| method | frames/s | x vid.stab s10 | peak MiB | normal flow (px) | normal flow (input px) | frame change | sharpness | valid % | cropping | distortion | stability (Liu) | stability (<= {} Hz) | ITF (dB) |",
        super::liu::STABILITY_BAND_HZ
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
        out.push(Bar {
            what: format!("stabilize < {peer} on RMS normal flow (input px)"),
            cleared: a < b,
            detail: format!("{a:.3} vs {b:.3}"),
        });
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
        out.push(Bar {
            what: "saccade < vidstab-tripod on RMS frame change".into(),
            cleared: a < b,
            detail: format!("{a:.4} vs {b:.4}"),
        });
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
        out.push(Bar {
            what: format!("{ours} <= {peer} on RMS frame change"),
            cleared: x <= y,
            detail: format!("{x:.4} vs {y:.4}"),
        });
        let (x, y) = (
            a.measured.rms_normal_flow_input_px,
            p.measured.rms_normal_flow_input_px,
        );
        out.push(Bar {
            what: format!("{ours} <= {peer} on RMS normal flow (input px)"),
            cleared: x <= y,
            detail: format!("{x:.3} vs {y:.3}"),
        });
    }
    out
}

/// Where a peer wins on a headline metric against our best corresponding mode.
fn peer_wins(c: &ClipResult) -> Vec<String> {
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

fn file_stem(clip: &str) -> String {
    clip.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Writes the plot of one clip.
fn write_clip_plot(dir: &Path, c: &ClipResult) -> Result<String, CompareError> {
    let name = format!("{}-motion.png", file_stem(&c.clip));
    let none_speed: Vec<f64> = find(c, "none")
        .map(|m| {
            m.measured
                .frames
                .iter()
                .map(|r| r.apparent_speed_dps.unwrap_or(f64::NAN))
                .collect()
        })
        .unwrap_or_default();
    let series: Vec<ModeSeries> = c
        .methods
        .iter()
        .map(|m| {
            let rows = &m.measured.frames;
            let n = rows.len();
            let mut est = none_speed.clone();
            est.resize(n, f64::NAN);
            ModeSeries {
                mode: m.method.to_string(),
                t: rows.iter().map(|r| r.t).collect(),
                est_speed_dps: est,
                view_speed_dps: rows
                    .iter()
                    .map(|r| r.apparent_speed_dps.unwrap_or(f64::NAN))
                    .collect(),
                normal_flow: rows.iter().map(|r| r.rms_normal_flow).collect(),
                saccade: if m.saccades.len() == n {
                    m.saccades.clone()
                } else {
                    vec![false; n]
                },
            }
        })
        .collect();
    let title = format!(
        "{}: apparent angular speed of each output (top; 'camera' = none) and normal flow (bottom)",
        c.clip
    );
    plot::write_plot(&dir.join(&name), &title, &series)?;
    Ok(name)
}

/// Writes the strip of middle frames (input first, then each method, row-major).
fn write_strip(dir: &Path, c: &ClipResult) -> Result<Option<String>, CompareError> {
    let tiles: Vec<&Frame> = c
        .input_middle
        .iter()
        .chain(c.methods.iter().filter_map(|m| m.middle.as_ref()))
        .collect();
    if tiles.is_empty() {
        return Ok(None);
    }
    let (iw, ih) = c.input_size;
    let tile_h = ((TILE_WIDTH as f64) * ih as f64 / iw.max(1) as f64)
        .round()
        .max(1.0) as u32;
    let rows = (tiles.len() as u32).div_ceil(STRIP_COLUMNS);
    let mut canvas = image::RgbImage::from_pixel(
        STRIP_COLUMNS * TILE_WIDTH,
        rows * tile_h,
        image::Rgb([255, 255, 255]),
    );
    for (k, f) in tiles.iter().enumerate() {
        let c = f.format.channels();
        let rgb: Vec<u8> = f
            .data
            .chunks_exact(c)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        let Some(img) = image::RgbImage::from_raw(f.width as u32, f.height as u32, rgb) else {
            continue;
        };
        let small = image::imageops::resize(
            &img,
            TILE_WIDTH,
            tile_h,
            image::imageops::FilterType::Triangle,
        );
        let (x, y) = (
            (k as u32 % STRIP_COLUMNS) * TILE_WIDTH,
            (k as u32 / STRIP_COLUMNS) * tile_h,
        );
        image::imageops::replace(&mut canvas, &small, x as i64, y as i64);
    }
    let name = format!("{}-strip.png", file_stem(&c.clip));
    let path = dir.join(&name);
    let mut png = std::io::Cursor::new(Vec::new());
    canvas
        .write_to(&mut png, image::ImageFormat::Png)
        .map_err(|e| CompareError::Image {
            path: path.clone(),
            detail: e.to_string(),
        })?;
    write_public(&path, png.get_ref())?;
    Ok(Some(name))
}

/// Writes every method's per-frame measurements of one clip as CSV.
fn write_frames_csv(dir: &Path, c: &ClipResult) -> Result<(), CompareError> {
    let f = |v: Option<f64>| {
        v.filter(|x| x.is_finite())
            .map(|x| format!("{x:.6}"))
            .unwrap_or_default()
    };
    let mut s = String::from(
        "method,frame,t,rms_normal_flow,apparent_speed_dps,cropping,distortion,fit_residual,psnr_db,valid_fraction\n",
    );
    for m in &c.methods {
        for (j, r) in m.measured.frames.iter().enumerate() {
            let _ = writeln!(
                s,
                "{},{j},{:.6},{},{},{},{},{},{},{:.5}",
                m.method,
                r.t,
                f(r.rms_normal_flow),
                f(r.apparent_speed_dps),
                f(r.cropping),
                f(r.distortion),
                f(r.fit_residual),
                f(r.psnr_db),
                r.valid_fraction
            );
        }
    }
    write_public(
        &dir.join(format!("{}-frames.csv", file_stem(&c.clip))),
        s.as_bytes(),
    )
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
fn fed_table(c: &ClipResult, base: &amc_core::metrics::ClipMetrics, mode: &str) -> Option<String> {
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
fn base_of(v: f64) -> f64 {
    v.max(f64::MIN_POSITIVE)
}

/// `v / base` for the paper's tables, three decimals; `-` without a baseline.
fn ratio(v: f64, base: f64) -> String {
    if base > 0.0 {
        format!("{:.3}", v / base)
    } else {
        "-".into()
    }
}

/// The report's line on the paper's code (none when it was not asked for).
fn paper_line(paper: &PaperStatus) -> Option<String> {
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

/// Writes the report for the clips done so far.
pub fn write(
    dir: &Path,
    results: &[ClipResult],
    args: &CompareConfig,
    paper: &PaperStatus,
) -> Result<(), CompareError> {
    let mut s = String::new();
    s += "# amc compare: our stabilizer against vid.stab and deshake\n\n";
    let _ = writeln!(
        s,
        "Generated by `amc compare` ({} {}). Machine: {}. Peers: {}.\n",
        env!("CARGO_PKG_NAME"),
        env!("CARGO_PKG_VERSION"),
        machine_description(args.machine.as_deref()),
        ffmpeg_version()
    );
    if let Some(line) = paper_line(paper) {
        s += &line;
        s += "\n";
    }
    s += "A reading of these numbers, written by hand after the run, is in [NOTES.md](NOTES.md) \
          next to this file (where present).\n\n";
    s += METHODS_TEXT;
    let mut all_bars = Vec::new();
    for c in results {
        let _ = writeln!(s, "\n## {}\n", c.clip);
        let _ = writeln!(
            s,
            "{}; {}x{}, {} frames, {:.2} fps; lens hfov {:.1} deg.\n",
            c.description, c.input_size.0, c.input_size.1, c.frames, c.fps, c.hfov_deg
        );
        s += &clip_table(c);
        if let Some(why) = &c.paper_skipped {
            let _ = writeln!(s, "\nThe paper's code was skipped on this clip: {why}.");
        }
        if let Some(t) = paper_table(c) {
            s += "\nThe paper's code beside ours at its settings (dt 1/60 s per frame, its gains, \
                  its 12.5% margin, its output size):\n\n";
            s += &t;
        }
        for m in &c.methods {
            if let Some(g) = &m.ground_truth {
                if m.method == "stabilize" {
                    let _ = writeln!(
                        s,
                        "\nRotation error of our estimate against ground truth ({} frames): per frame median {:.4} deg, p95 {:.4} deg, max {:.4} deg; orientation after the clip {:.3} deg (max {:.3} deg).",
                        g.frames,
                        g.median_frame_error_deg,
                        g.p95_frame_error_deg,
                        g.max_frame_error_deg,
                        g.final_orientation_error_deg,
                        g.max_orientation_error_deg
                    );
                }
            }
        }
        let fails: Vec<String> = c
            .methods
            .iter()
            .filter(|m| m.measured.fit_failures > 0)
            .map(|m| format!("{} ({} frames)", m.method, m.measured.fit_failures))
            .collect();
        if !fails.is_empty() {
            let _ = writeln!(
                s,
                "\nHomography fit failed (frames left out of cropping/distortion): {}.",
                fails.join(", ")
            );
        }
        let b = bars(c);
        if !b.is_empty() {
            s += "\nTargets:\n\n";
            for bar in &b {
                let _ = writeln!(
                    s,
                    "- {} {}: {}",
                    if bar.cleared { "met:" } else { "**NOT met:**" },
                    bar.what,
                    bar.detail
                );
            }
        }
        let wins = peer_wins(c);
        if !wins.is_empty() {
            s += "\nWhere a peer wins:\n\n";
            for w in &wins {
                let _ = writeln!(s, "- {w}");
            }
        }
        if args.per_frame {
            write_frames_csv(dir, c)?;
        }
        let plot_name = write_clip_plot(dir, c)?;
        let _ = writeln!(s, "\n![{} motion]({plot_name})", c.clip);
        if let Some(strip) = write_strip(dir, c)? {
            let order: Vec<&str> = std::iter::once("input")
                .filter(|_| c.input_middle.is_some())
                .chain(
                    c.methods
                        .iter()
                        .filter(|m| m.middle.is_some())
                        .map(|m| m.method),
                )
                .collect();
            let _ = writeln!(
                s,
                "\nMiddle frame, left to right and top to bottom: {}.\n\n![{} frames]({strip})",
                order.join(", "),
                c.clip
            );
        }
        all_bars.extend(b.into_iter().map(|bar| (c.clip.clone(), bar)));
    }
    let missed: Vec<_> = all_bars.iter().filter(|(_, b)| !b.cleared).collect();
    s += "\n## Summary of the targets\n\n";
    let _ = writeln!(
        s,
        "{} of {} targets met.{}\n",
        all_bars.len() - missed.len(),
        all_bars.len(),
        if missed.is_empty() { "" } else { " Not met:" }
    );
    for (clip, b) in &missed {
        let _ = writeln!(s, "- {clip}: {} ({})", b.what, b.detail);
    }
    write_public(&dir.join(REPORT_FILE), s.as_bytes())?;
    let json =
        serde_json::to_string_pretty(results).map_err(|e| CompareError::Internal(e.to_string()))?;
    write_public(&dir.join("results.json"), json.as_bytes())?;
    Ok(())
}

const METHODS_TEXT: &str = r#"## How it is measured

- **Methods**, all run on the same input in the same run: ours (`amc stabilize`) in modes
  `none` (the undistorted input, zoomed only as far as its lens needs: the baseline), `stabilize`, `saccade` and `stabilize
  --lookahead N` (default 30, the frames vid.stab `smoothing=30` uses on each side); ffmpeg's vid.stab in two passes (`vidstabdetect`, then `vidstabtransform`
  with `smoothing=10`, `smoothing=30`, and `tripod=1` (detect and transform), the peer of
  our saccade mode), all other options at their defaults (so vid.stab zooms to hide most
  borders, `optzoom=1`); ffmpeg's `deshake=rx=48:ry=48` (online). With `--peer paper`:
  the paper's own code (github.com/prgumd/AMC, `rotation_stabilize.py`, set up by
  `tools/paper-peer/setup.sh`) at its own settings (`--downsample 2 --stride 1 --margins
  0.125`; `paper-none`: `--N_frames 1`; `paper-stabilize`: `--N_frames 6 --rotstab2`;
  `paper-saccade`: adds `--saccade`), its exported crop read back at its processing
  resolution, and ours at matched settings (`ours-matched-*`: `--fps 60`, since its view
  filter steps 1/60 s per frame whatever the clip's rate, `--rate-a 2 --rate-b 40` (its
  gains), `--zoom none --margin 0.125`, its output size); then its stabilize and saccade
  modes with its tracker's orientations replaced (`paper-fed-ours-*`: those of our matched
  run in the same mode; `paper-fed-truth-*`: the true ones, where the clip has them), which
  tells what its tracker does to its numbers from what its renderer does. Its speed is that of the whole
  Python process (decoding the clip into its recording layout, JAX start-up and
  compilation, its loop; in brackets "its loop": its `stabilize()` call alone, JAX's
  compilation on the first frames included); its valid pixels are those its own
  renderer marks covered by every averaged frame, less the one-pixel band its bilinear
  warp mixes with its black border.
- **Speed**: input frames / wall time of the whole child process (decode, stabilize, write
  raw `.y4m`; vid.stab's two passes summed), and its peak resident memory (`ru_maxrss`).
  "x vid.stab s10" is the frame-rate ratio to vid.stab's two passes with `smoothing=10`.
- **Valid pixels**: ours from the renderer's coverage (pixels some averaged frame covers).
  Peers fill uncovered pixels, so each is run a second time with another fill
  (`crop=keep` instead of `crop=black`; `edge=original` instead of `edge=blank`) and the same
  motion; pixels where the two outputs differ are fill (invalid). Every metric uses valid
  pixels only, never borders. "valid %" is, for ours, the share covered by every averaged
  frame (stricter), for peers the share of valid pixels.
- **The paper's metrics** (luma in [0, 1]; Sobel 3x3 / 8; normal flow where |grad| >= 15/255):
  RMS normal flow in output pixels, and in input pixels (times the output's scale against
  the input, so vid.stab's zoom does not count against it), RMS frame change, sharpness.
- **Liu et al. 2013**: homographies fitted directly on intensities (Levenberg-Marquardt on
  a pyramid, valid pixels only, coordinates normalized by each frame's width, so outputs
  smaller than the input compare correctly) between input and output frames, and between
  consecutive outputs. Cropping: mean of 1/sqrt|det A| (kept linear fraction of the input;
  our default margin keeps 0.75). Distortion: worst frame's ratio of the two eigenvalue
  magnitudes of A's 2x2 part (through a distorted lens, ours and the paper's code are fitted
  to the input seen through a pinhole of its focal length, as they render it, so a camera's
  turn is a homography; ffmpeg's filters to the input as filmed; a fit whose residual is 3x
  the clip's mean is retried from fresh starts). Stability: share of the 2nd-6th FFT
  bins in the energy of the accumulated translation and rotation paths, the smaller of the
  two; the fixed-band variant uses 0 < f <= 1 Hz instead of bins. ITF: mean PSNR of
  consecutive outputs (dB, valid pixels).
- **Apparent angular speed** (plots): the motion between consecutive outputs expressed as a
  camera rotation (translation over the focal length, plus roll), for every method alike.
- **Bars** (our own targets): on the synthetic clips and `cup`, `stabilize` beats both
  vid.stab settings on RMS normal flow (input px) and distortion at equal or better cropping
  (within 0.005) while running at least 5x faster than vid.stab's two passes; `saccade`
  beats `tripod=1` on RMS frame change. Framing, on every clip: each of our modes shows no
  uncovered pixel (counted from the renderer's coverage, not from black values); with the
  default framing (`--zoom auto`, `--max-crop 0.15`) `stabilize-lookahead` and `stabilize`
  keep at least vid.stab `smoothing=30`'s share of the width (cropping, within 0.005), and
  `stabilize-lookahead` has no more RMS frame change and normal flow (input px) than
  `smoothing=30`, online `stabilize` no more than `smoothing=10`.
  Every clip lists them; a peer's wins are listed too.
"#;
