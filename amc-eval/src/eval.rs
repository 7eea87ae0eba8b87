//! `amc eval`: the paper's table for one clip: none / stabilize / saccade.

use crate::gt::{self, GtError, GtReport};
use crate::plot::{self, ModeSeries, PlotError};
use amc_core::so3::{self, Tangent};
use amc_core::view::Mode;
use amc_core::StabilizerOptions;
use amc_engine::{self as engine, Progress, Resolved, RunConfig, RunError, RunSummary};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Duration;

/// One row of the table.
#[derive(Serialize)]
pub struct ModeResult {
    pub mode: String,
    /// The run's framing (`auto`, `static` or `none`): each row's ratios are to
    /// the `none` row of the same framing.
    pub zoom: String,
    #[serde(flatten)]
    pub run: RunSummary,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<GtReport>,
}

/// The whole evaluation.
#[derive(Serialize)]
pub struct EvalReport {
    pub input: String,
    pub lens: amc_core::CameraModel,
    pub hfov_deg: f64,
    pub modes: Vec<ModeResult>,
}

/// What `amc eval` measures.
#[derive(Clone, Debug)]
pub struct EvalConfig {
    /// The clip (as for `stabilize`).
    pub input: PathBuf,
    /// The stabilizer's options (the mode is set per row) and the lens.
    pub options: StabilizerOptions,
    /// Frame rate for image folders, or to override a video's timestamps.
    pub fps: Option<f64>,
    /// Longest an ffmpeg child may stall.
    pub timeout: Duration,
    /// Ground-truth orientations (`gt.csv` from `amc synth`).
    pub gt: Option<PathBuf>,
    /// Where to write the per-frame plot (PNG).
    pub plot: Option<PathBuf>,
    /// Threads of each run (see [`RunConfig::threads`]).
    pub threads: usize,
}

/// Why an evaluation stopped.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A run failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The ground truth cannot be read.
    #[error(transparent)]
    Gt(#[from] GtError),
    /// The plot cannot be written.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// Runs none / stabilize / saccade; `resolved` hears how the lens and the
/// readout were found, `progress` each run's progress (with its mode).
pub fn run(
    args: &EvalConfig,
    resolved: &dyn Fn(&Resolved),
    progress: &(dyn Fn(Mode, Progress) + Sync),
) -> Result<EvalReport, EvalError> {
    let timeout = args.timeout;
    args.options.params.validate().map_err(RunError::from)?;
    let found = engine::resolve(
        &args.options,
        &args.input,
        &engine::input_options(args.fps, timeout),
        None,
    )?;
    resolved(&found);
    let base = found.params;
    let lens = found.lens.camera;
    let gt_rot = match &args.gt {
        Some(p) => Some(gt::read_orientations(p)?),
        None => None,
    };
    let mut modes = Vec::new();
    // Each mode framed as `amc stabilize` frames it; where saccade mode's fixed
    // crop differs from the `none` row's framing, a second `none` row in its
    // framing, so that its ratios compare like with like (a crop magnifies the
    // motion in pixels).
    let zoom_of = |mode| {
        if args.options.zoom_given {
            base.framing.zoom
        } else {
            StabilizerOptions::default_zoom(mode)
        }
    };
    let mut rows = vec![
        (Mode::None, zoom_of(Mode::None)),
        (Mode::Stabilize, zoom_of(Mode::Stabilize)),
        (Mode::Saccade, zoom_of(Mode::Saccade)),
    ];
    if zoom_of(Mode::Saccade) != zoom_of(Mode::None) {
        rows.push((Mode::None, zoom_of(Mode::Saccade)));
    }
    for (mode, zoom) in rows {
        let label = mode.to_string();
        let mut params = base.clone();
        params.view.mode = mode;
        params.framing.zoom = zoom;
        let report = |p: Progress| progress(mode, p);
        let cfg = RunConfig {
            input: &args.input,
            output: None,
            params,
            lens: lens.clone(),
            telemetry: None,
            also_writes: &[],
            fps: args.fps,
            timeout,
            crf: None,
            preset: None,
            keep_per_frame: true,
            measure: true,
            control: None,
            progress: Some(&report),
            gyro: None,
            refit_lens: false,
            measure_readout: None,
            threads: args.threads,
        };
        let run = engine::run(&cfg)?;
        let ground_truth = gt_rot
            .as_ref()
            .filter(|_| mode == Mode::Stabilize)
            .map(|g| {
                let est: Vec<_> = run
                    .per_frame
                    .iter()
                    .map(|r| so3::exp(&Tangent::from(r.telemetry.r_est)))
                    .collect();
                gt::compare(g, &est)
            });
        modes.push(ModeResult {
            mode: label,
            zoom: zoom.to_string(),
            run,
            ground_truth,
        });
    }
    if let Some(path) = &args.plot {
        let series: Vec<ModeSeries> = modes
            .iter()
            .map(|m| {
                let speed = |v: [f64; 3]| Tangent::from(v).norm().to_degrees();
                let pf = &m.run.per_frame;
                ModeSeries {
                    mode: row_label(m, &modes[0].zoom),
                    t: pf.iter().map(|r| r.telemetry.t).collect(),
                    est_speed_dps: pf.iter().map(|r| speed(r.telemetry.rate_est)).collect(),
                    view_speed_dps: pf.iter().map(|r| speed(r.telemetry.rate_view)).collect(),
                    normal_flow: pf.iter().map(|r| r.metrics.rms_normal_flow).collect(),
                    saccade: pf.iter().map(|r| r.telemetry.saccade).collect(),
                }
            })
            .collect();
        let title = format!("{}", args.input.display());
        plot::write_plot(path, &title, &series)?;
    }
    Ok(EvalReport {
        input: args.input.display().to_string(),
        hfov_deg: lens.hfov_deg(),
        lens,
        modes,
    })
}

/// A row's name: its mode, and its framing where it differs from the first row's.
fn row_label(m: &ModeResult, first_zoom: &str) -> String {
    if m.zoom == first_zoom {
        m.mode.clone()
    } else {
        format!("{} (zoom {})", m.mode, m.zoom)
    }
}

/// The paper's table, in Markdown.
pub fn markdown(r: &EvalReport) -> String {
    let mut s = format!(
        "Clip: `{}`; lens hfov {:.1} deg\n\n| mode | RMS normal flow (px) | RMS frame change | sharpness | valid px (mean / min) | est. speed (deg/s) | view speed (deg/s) | saccades | frames/s |\n|---|---|---|---|---|---|---|---|---|\n",
        r.input, r.hfov_deg
    );
    let first_zoom = r.modes.first().map(|m| m.zoom.clone());
    for m in &r.modes {
        let Some(c) = m.run.metrics.as_ref() else {
            continue;
        };
        let none = r
            .modes
            .iter()
            .find(|n| n.mode == "none" && n.zoom == m.zoom)
            .and_then(|n| n.run.metrics.clone());
        let label = first_zoom
            .as_ref()
            .map_or(m.mode.clone(), |z| row_label(m, z));
        let ratio = |v: f64, base: Option<f64>| match base {
            Some(b) if b > 0.0 && m.mode != "none" => format!(" ({:.2}x)", v / b),
            _ => String::new(),
        };
        s += &format!(
            "| {} | {:.3}{} | {:.4}{} | {:.4}{} | {:.1}% / {:.1}% | {:.1} | {:.1} | {} | {:.0} |\n",
            label,
            c.rms_normal_flow,
            ratio(c.rms_normal_flow, none.as_ref().map(|n| n.rms_normal_flow)),
            c.rms_change,
            ratio(c.rms_change, none.as_ref().map(|n| n.rms_change)),
            c.sharpness,
            ratio(c.sharpness, none.as_ref().map(|n| n.sharpness)),
            100.0 * c.valid_fraction,
            100.0 * c.min_valid_fraction,
            c.rms_speed_est_dps,
            c.rms_speed_view_dps,
            c.saccades,
            m.run.frames_per_second,
        );
    }
    for m in &r.modes {
        if let Some(g) = &m.ground_truth {
            s += &format!(
                "\nGround truth ({} frames): per-frame rotation error median {:.4} deg, mean {:.4}, p95 {:.4}, max {:.4}; orientation error final {:.3} deg, max {:.3} deg\n",
                g.frames,
                g.median_frame_error_deg,
                g.mean_frame_error_deg,
                g.p95_frame_error_deg,
                g.max_frame_error_deg,
                g.final_orientation_error_deg,
                g.max_orientation_error_deg
            );
        }
    }
    s
}
