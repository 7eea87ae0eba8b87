//! `amc compare`: our modes against the stabilizers people use today
//! (ffmpeg's vid.stab and deshake) on the same clips in the same run, for
//! speed and quality, written as one Markdown report with plots.
//!
//! * [`peers`]: the methods and how each runs as a timed child process;
//! * [`measure`]: per-frame measurement of an output against the input;
//! * [`homography`]: the direct homography fit the Liu et al. metrics need;
//! * [`liu`]: cropping, distortion, stability, ITF;
//! * [`synthetic`]: the flapping-wing test sequences;
//! * [`report`]: tables, bars, plots and the frame strip.
//!
//! Per clip: the input is decoded once (luma pyramids kept for the fits);
//! every method runs as a child process writing raw `.y4m` (timed); ours are
//! then re-run in-process (deterministic, same output) to measure them with
//! the renderer's exact coverage mask, peers are measured from their `.y4m`
//! with the validity mask of [`peers`].

pub mod homography;
pub mod liu;
pub mod measure;
pub mod peers;
pub mod report;
pub mod synthetic;

use crate::engine::{self, RunError};
use crate::gt::{self, GtError, GtReport};
use crate::plot::PlotError;
use crate::synth::SynthError;
use amc_core::image::{Frame, GrayImage, PixelFormat};
use amc_core::metrics::masked_luma_into;
use amc_core::so3::{self, Tangent};
use amc_core::view::Mode;
use amc_core::{AmcError, LensSpec};
use amc_core::{CameraModel, Stabilizer, StabilizerParams};
use amc_video::VideoError;
use amc_video::{self as video, InputOptions};
use measure::{Measured, Measurer};
use peers::{FfmpegInput, Method, Usage};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Duration;
use thiserror::Error;

/// Largest `--lookahead` accepted: the stabilizer's own limit.
pub const MAX_LOOKAHEAD: usize = amc_core::options::MAX_LOOKAHEAD;

/// Errors of `amc compare` that are not video or stabilizer errors.
#[derive(Debug, Error)]
pub enum CompareError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot run {what}: {source}")]
    Spawn {
        what: String,
        source: std::io::Error,
    },
    #[error("{what} failed: {detail}")]
    ChildFailed { what: String, detail: String },
    #[error("{what} ran longer than {seconds} s (allowed: --timeout SECS)")]
    Timeout { what: String, seconds: u64 },
    #[error("nothing to compare: give one or more CLIP paths or --synthetic")]
    NoClips,
    #[error("invalid --synthetic-seconds {0} (allowed: 0.5 to 60 seconds)")]
    SyntheticSeconds(f64),
    #[error("invalid --lookahead {0} (allowed: 1 to {MAX_LOOKAHEAD} frames)")]
    Lookahead(usize),
    #[error("invalid --repeat {0} (allowed: 1 to 10 runs)")]
    Repeat(usize),
    #[error("{}: the panorama for --synthetic does not exist (pass --panorama FILE)", .0.display())]
    NoPanorama(PathBuf),
    #[error("{method} on {clip}: produced no frames")]
    NoOutput { method: String, clip: String },
    #[error("internal error: {0}")]
    Internal(String),
    /// A clip decoded to no frames.
    #[error("{}: no frames could be read", .0.display())]
    NoFrames(PathBuf),
    /// A clip's `lens.json` is not a calibration we understand.
    #[error("{}: {source}", path.display())]
    Lens {
        /// The lens file.
        path: PathBuf,
        /// What is wrong with it.
        source: amc_core::lens::LensError,
    },
    /// A figure or image could not be encoded.
    #[error("{}: {detail}", path.display())]
    Image {
        /// The file.
        path: PathBuf,
        /// What failed.
        detail: String,
    },
    /// A run of ours failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// Reading a clip or writing a file failed.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// The stabilizer refused a parameter or a frame.
    #[error(transparent)]
    Core(#[from] AmcError),
    /// A synthetic sequence could not be rendered.
    #[error(transparent)]
    Synth(#[from] SynthError),
    /// A plot could not be written.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// A ground truth could not be read.
    #[error(transparent)]
    Gt(#[from] GtError),
}

impl CompareError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        CompareError::Io {
            path: path.into(),
            source,
        }
    }
}

/// Compare our stabilizer with ffmpeg's vid.stab and deshake on the same clips.
#[derive(Debug, Clone)]
pub struct CompareConfig {
    /// Clips: videos, image folders, or folders holding `lens.json` with the images
    /// (directly or in `frames/`) and optionally `gt.csv` (as `amc synth` writes).
    pub clips: Vec<PathBuf>,
    /// Folder for the report (`README.md`, plots, `results.json`); created if missing.
    pub report: PathBuf,
    /// Also render and compare the synthetic flapping-wing sequences (12-20 Hz shake,
    /// 100 and 300 deg/s, pinhole and fisheye, with and without rolling shutter).
    pub synthetic: bool,
    /// Length of each synthetic sequence, seconds (0.5..=60).
    pub synthetic_seconds: f64,
    /// Size of the synthetic sequences, WxH.
    pub synthetic_size: (usize, usize),
    /// Equirectangular panorama the synthetic sequences are rendered from.
    pub panorama: PathBuf,
    /// Lens of clips without a `lens.json` (default: --fov auto).
    pub lens: LensSpec,
    /// Future frames of the `stabilize --lookahead` method (1..=300).
    pub lookahead: usize,
    /// Frame rate of image folders without `gt.csv` timestamps (default 30).
    pub fps: Option<f64>,
    /// Longest any one child process (a method on a clip) may run, seconds.
    pub timeout: u64,
    /// Text describing the machine, added to the detected CPU and memory in the report.
    pub machine: Option<String>,
    /// Timed runs per method (1..=10); the fastest counts (least disturbed on a shared machine).
    pub repeat: usize,
    /// Also write every method's per-frame measurements (`CLIP-frames.csv`).
    pub per_frame: bool,
    /// No progress messages.
    pub quiet: bool,
}

/// A clip ready to compare.
#[derive(Clone, Debug)]
pub struct Clip {
    /// Short name (file stem or folder name).
    pub name: String,
    /// What `amc stabilize` reads: a video file or an image folder.
    pub input: PathBuf,
    pub lens: CameraModel,
    /// Frame rate of image folders.
    pub fps: Option<f64>,
    /// Ground-truth orientations (synthetic clips).
    pub gt: Option<Vec<so3::Rot>>,
    /// One line on where the clip comes from.
    pub description: String,
}

/// One method's result on one clip.
#[derive(Serialize)]
pub struct MethodResult {
    pub method: &'static str,
    pub frames: usize,
    pub usage: Usage,
    pub frames_per_second: f64,
    pub measured: Measured,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<GtReport>,
    /// The middle output frame, for the strip.
    #[serde(skip)]
    pub middle: Option<Frame>,
    #[serde(skip)]
    pub saccades: Vec<bool>,
}

/// All methods on one clip.
#[derive(Serialize)]
pub struct ClipResult {
    pub clip: String,
    pub description: String,
    pub input_size: (usize, usize),
    pub frames: usize,
    pub fps: f64,
    pub hfov_deg: f64,
    /// Whether the bars apply (synthetic clips and `cup`).
    pub has_bars: bool,
    pub methods: Vec<MethodResult>,
    #[serde(skip)]
    pub input_middle: Option<Frame>,
}

/// The input decoded once: luma pyramids, timestamps and the middle frame.
struct DecodedInput {
    pyramids: Vec<homography::Pyramid>,
    times: Vec<f64>,
    size: (usize, usize),
    middle: Option<Frame>,
}

fn timeout(args: &CompareConfig) -> Duration {
    Duration::from_secs(args.timeout.max(1))
}

fn input_options(clip: &Clip, args: &CompareConfig) -> InputOptions {
    InputOptions {
        fps_override: clip.fps,
        timeout: timeout(args).min(Duration::from_secs(300)),
        ..InputOptions::default()
    }
}

fn decode_input(clip: &Clip, args: &CompareConfig) -> Result<DecodedInput, CompareError> {
    let mut src = video::open_input(&clip.input, &input_options(clip, args))?;
    let info = src.info().clone();
    let mid = info.frame_count.map(|n| n / 2);
    let mut frame = Frame::new(info.width, info.height, PixelFormat::Rgb8);
    let mut luma = GrayImage::default();
    let all = vec![1u8; info.width * info.height];
    let mut out = DecodedInput {
        pyramids: Vec::new(),
        times: Vec::new(),
        size: (info.width, info.height),
        middle: None,
    };
    while let Some(t) = src.next_frame(&mut frame)? {
        if Some(out.times.len() as u64) == mid {
            out.middle = Some(frame.clone());
        }
        masked_luma_into(&frame.as_ref(), &all, &mut luma);
        out.pyramids.push(homography::Pyramid::new(&luma));
        out.times.push(t);
    }
    if out.times.is_empty() {
        return Err(CompareError::NoFrames(clip.input.clone()));
    }
    Ok(out)
}

/// The stabilizer parameters `amc stabilize` uses by default for `method`.
fn our_params(method: Method, lookahead: usize) -> StabilizerParams {
    let mode = match method {
        Method::None => Mode::None,
        Method::Saccade => Mode::Saccade,
        _ => Mode::Stabilize,
    };
    let mut p = amc_core::StabilizerOptions::with_mode(mode).params;
    if method == Method::StabilizeLookahead {
        p.view.lookahead = lookahead;
    }
    p
}

fn fps_of(input: &DecodedInput) -> f64 {
    let n = input.times.len();
    if n >= 2 {
        let span = input.times[n - 1] - input.times[0];
        if span > 0.0 {
            return (n - 1) as f64 / span;
        }
    }
    30.0
}

/// What the in-process run of one of our modes gives besides the measurements.
struct OursMeasured {
    measured: Measured,
    ground_truth: Option<GtReport>,
    middle: Option<Frame>,
    saccades: Vec<bool>,
}

/// Measures one of our modes in-process (same output as the timed child).
fn measure_ours(
    method: Method,
    clip: &Clip,
    input: &DecodedInput,
    args: &CompareConfig,
) -> Result<OursMeasured, CompareError> {
    let params = our_params(method, args.lookahead);
    let mut src = video::open_input(&clip.input, &input_options(clip, args))?;
    let (w, h) = input.size;
    let mut stab = Stabilizer::new(&clip.lens, w, h, params)?;
    let mut m = Measurer::new(fps_of(input), w, clip.lens.fx);
    let mut frame = Frame::new(w, h, PixelFormat::Rgb8);
    let mut est = Vec::new();
    let mut saccades = Vec::new();
    let mut middle = None;
    let mid = input.times.len() / 2;
    let mut handle = |stab: &Stabilizer, tel: amc_core::Telemetry| {
        let j = tel.frame as usize;
        let Some(pyr) = input.pyramids.get(j) else {
            return;
        };
        let out = stab.output();
        m.push(
            tel.t,
            pyr,
            &out,
            stab.output_coverage(),
            tel.valid_fraction,
            Some(&tel),
        );
        if j == mid {
            let mut f = Frame::new(out.width, out.height, out.format);
            f.copy_from(&out);
            middle = Some(f);
        }
        est.push(so3::exp(&Tangent::from(tel.r_est)));
        saccades.push(tel.saccade);
    };
    while let Some(t) = src.next_frame(&mut frame)? {
        if let Some(tel) = stab.push(frame.as_ref(), t)? {
            handle(&stab, tel);
        }
    }
    while let Some(tel) = stab.finish() {
        handle(&stab, tel);
    }
    let ground_truth = clip.gt.as_ref().map(|g| gt::compare(g, &est));
    Ok(OursMeasured {
        measured: m.finish(),
        ground_truth,
        middle,
        saccades,
    })
}

/// Measures a peer's output `.y4m` (validity from the alternative-fill run).
fn measure_peer(
    clip: &Clip,
    input: &DecodedInput,
    outs: &peers::PeerOutputs,
    args: &CompareConfig,
) -> Result<(Measured, Option<Frame>), CompareError> {
    let opts = InputOptions {
        fps_override: None,
        timeout: timeout(args).min(Duration::from_secs(300)),
        ..InputOptions::default()
    };
    let mut a_src = video::open_input(&outs.main, &opts)?;
    let mut b_src = video::open_input(&outs.alt, &opts)?;
    let (w, h) = (a_src.info().width, a_src.info().height);
    let mut a = Frame::new(w, h, PixelFormat::Rgb8);
    let mut b = Frame::new(w, h, PixelFormat::Rgb8);
    let mut m = Measurer::new(fps_of(input), input.size.0, clip.lens.fx);
    let mut mask = Vec::new();
    let mut middle = None;
    let mid = input.times.len() / 2;
    for (j, pyr) in input.pyramids.iter().enumerate() {
        let (Some(_), Some(_)) = (a_src.next_frame(&mut a)?, b_src.next_frame(&mut b)?) else {
            break;
        };
        let valid = measure::agreement_mask(&a.as_ref(), &b.as_ref(), &mut mask);
        m.push(input.times[j], pyr, &a.as_ref(), &mask, valid, None);
        if j == mid {
            middle = Some(a.clone());
        }
    }
    Ok((m.finish(), middle))
}

/// Runs every method on `clip`, in a scratch folder under `work`.
fn compare_clip(
    clip: &Clip,
    args: &CompareConfig,
    work: &Path,
) -> Result<ClipResult, CompareError> {
    let say = |s: String| {
        if !args.quiet {
            eprintln!("[{}] {s}", clip.name);
        }
    };
    let dir = work.join(&clip.name);
    std::fs::create_dir_all(&dir).map_err(|e| CompareError::io(&dir, e))?;
    say("decoding the input".into());
    let input = decode_input(clip, args)?;
    let fps = fps_of(&input);
    let lens_json = dir.join("lens.json");
    std::fs::write(&lens_json, amc_core::lens::to_project_json(&clip.lens))
        .map_err(|e| CompareError::io(&lens_json, e))?;
    let ff_input = if clip.input.is_dir() {
        let list = dir.join("frames.ffconcat");
        let images = video::list_images(&clip.input)?;
        peers::write_concat_list(&list, &images, clip.fps.unwrap_or(fps))?;
        FfmpegInput::Concat(list)
    } else {
        FfmpegInput::File(clip.input.clone())
    };
    let mut methods = Vec::new();
    for method in Method::ALL {
        say(format!("{}: timed run", method.label()));
        let r = if method.is_ours() {
            let (usage, out) = peers::run_ours(
                method,
                &clip.input,
                &lens_json,
                clip.fps,
                args.lookahead,
                &dir,
                timeout(args),
                args.repeat,
            )?;
            let _ = std::fs::remove_file(&out);
            say(format!("{}: measuring", method.label()));
            let OursMeasured {
                measured,
                ground_truth,
                middle,
                saccades,
            } = measure_ours(method, clip, &input, args)?;
            MethodResult {
                method: method.label(),
                frames: measured.frames.len(),
                frames_per_second: input.times.len() as f64 / usage.seconds.max(1e-9),
                usage,
                measured,
                ground_truth,
                middle,
                saccades,
            }
        } else {
            let (usage, outs) =
                peers::run_peer(method, &ff_input, &dir, timeout(args), args.repeat)?;
            say(format!("{}: measuring", method.label()));
            let measured = measure_peer(clip, &input, &outs, args);
            let _ = std::fs::remove_file(&outs.main);
            let _ = std::fs::remove_file(&outs.alt);
            let (measured, middle) = measured?;
            MethodResult {
                method: method.label(),
                frames: measured.frames.len(),
                frames_per_second: input.times.len() as f64 / usage.seconds.max(1e-9),
                usage,
                measured,
                ground_truth: None,
                middle,
                saccades: Vec::new(),
            }
        };
        if r.frames == 0 {
            return Err(CompareError::NoOutput {
                method: method.label().into(),
                clip: clip.name.clone(),
            }
            .into());
        }
        methods.push(r);
    }
    Ok(ClipResult {
        clip: clip.name.clone(),
        description: clip.description.clone(),
        input_size: input.size,
        frames: input.times.len(),
        fps,
        hfov_deg: clip.lens.hfov_deg(),
        has_bars: clip.gt.is_some() || clip.name == "cup",
        methods,
        input_middle: input.middle,
    })
}

/// Resolves a CLIP argument.
fn resolve_clip(path: &Path, args: &CompareConfig) -> Result<Clip, CompareError> {
    let stem = |p: &Path| {
        p.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "clip".into())
    };
    let timeout = Duration::from_secs(120);
    if path.is_dir() && path.join("lens.json").is_file() {
        let lens_path = path.join("lens.json");
        let text =
            std::fs::read_to_string(&lens_path).map_err(|e| CompareError::io(&lens_path, e))?;
        let lens = amc_core::lens::parse_lens(&text).map_err(|source| CompareError::Lens {
            path: lens_path.clone(),
            source,
        })?;
        let frames = if path.join("frames").is_dir() {
            path.join("frames")
        } else {
            path.to_path_buf()
        };
        let gt_path = path.join("gt.csv");
        let (gt, fps) = if gt_path.is_file() {
            (
                Some(gt::read_orientations(&gt_path)?),
                synthetic::fps_from_gt(&gt_path)?,
            )
        } else {
            (None, None)
        };
        return Ok(Clip {
            name: stem(path),
            input: frames,
            lens,
            fps: fps.or(args.fps),
            gt,
            description: format!("`{}` (lens from lens.json)", path.display()),
        });
    }
    let fps = if path.is_dir() { args.fps } else { None };
    let params = StabilizerParams::default();
    let resolved = engine::resolve_lens(
        &args.lens,
        path,
        &params,
        &engine::input_options(fps, timeout),
        None,
    )?;
    if resolved.note == engine::LensNote::FellBack && !args.quiet {
        eprintln!(
            "warning: {}: the footage does not pin down the focal length; assuming {} deg (pass --fov or --lens)",
            path.display(),
            engine::FALLBACK_FOV_DEG
        );
    }
    let lens = resolved.camera;
    Ok(Clip {
        name: stem(path),
        input: path.to_path_buf(),
        lens: lens.clone(),
        fps,
        gt: None,
        description: format!(
            "`{}` (pinhole, hfov {:.1} deg)",
            path.display(),
            lens.hfov_deg()
        ),
    })
}

/// Runs `amc compare`.
pub fn run(args: &CompareConfig) -> Result<(), CompareError> {
    if args.clips.is_empty() && !args.synthetic {
        return Err(CompareError::NoClips.into());
    }
    if !(0.5..=60.0).contains(&args.synthetic_seconds) {
        return Err(CompareError::SyntheticSeconds(args.synthetic_seconds).into());
    }
    if !(1..=MAX_LOOKAHEAD).contains(&args.lookahead) {
        return Err(CompareError::Lookahead(args.lookahead).into());
    }
    if !(1..=10).contains(&args.repeat) {
        return Err(CompareError::Repeat(args.repeat).into());
    }
    if args.synthetic && !args.panorama.is_file() {
        return Err(CompareError::NoPanorama(args.panorama.clone()).into());
    }
    video::ffmpeg_available()?;
    std::fs::create_dir_all(&args.report).map_err(|e| CompareError::io(&args.report, e))?;
    let work = tempfile::Builder::new()
        .prefix(".amc-compare-")
        .tempdir_in(&args.report)
        .map_err(|e| CompareError::io(&args.report, e))?;
    let mut clips = Vec::new();
    for p in &args.clips {
        clips.push(resolve_clip(p, args)?);
    }
    if args.synthetic {
        for spec in &synthetic::SEQUENCES {
            if !args.quiet {
                eprintln!("rendering synthetic sequence {}", spec.name);
            }
            let dir = synthetic::render(spec, args, work.path())?;
            let mut clip = resolve_clip(&dir, args)?;
            clip.name = spec.name.to_string();
            clip.description = spec.describe(args);
            clips.push(clip);
        }
    }
    let mut results = Vec::new();
    for clip in &clips {
        let r = compare_clip(clip, args, work.path())?;
        // Write as we go, so a long run leaves a report of what finished.
        results.push(r);
        report::write(&args.report, &results, args)?;
    }
    if !args.quiet {
        eprintln!("wrote {}", args.report.join(report::REPORT_FILE).display());
    }
    Ok(())
}
