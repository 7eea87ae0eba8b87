//! The comparison itself: per clip, decode once, run every method as a
//! timed child, measure ours in-process and the peers from their output.

use super::config::{CompareConfig, MAX_LOOKAHEAD};
use super::error::CompareError;
use super::paper::{self, PaperStatus};
use super::results::{Clip, ClipResult, MethodResult};
use super::{homography, measure, peers, report, synthetic};
use crate::gt::{self, GtReport};
use amc_core::image::{Frame, GrayImage, PixelFormat};
use amc_core::metrics::masked_luma_into;
use amc_core::so3::{self, Rot, Tangent};
use amc_core::view::Mode;
use amc_core::{Stabilizer, StabilizerParams};
use amc_engine as engine;
use amc_video::{self as video, InputOptions};
use measure::{Measured, Measurer};
use peers::{Fed, FfmpegInput, Method};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The input decoded once: luma pyramids, timestamps and the middle frame.
struct DecodedInput {
    pyramids: Vec<homography::Pyramid>,
    /// Through a distorted lens: the same frames as `pyramids`, seen through
    /// a pinhole of the lens's focal length (none for a pinhole lens). Ours
    /// and the paper's code render distorted lenses that way, and a camera's
    /// turn is then a homography; against the lens's own projection the
    /// homography fit reads the undistortion itself as anisotropic stretch,
    /// and `none` alone scored 0.96-0.97 on the synthetic fisheye.
    rectilinear: Option<Vec<homography::Pyramid>>,
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
        ..output_options(args)
    }
}

/// How a method's output is read back to be measured: at its own timestamps,
/// each ffmpeg reader under the run's time limit (at most 5 min).
fn output_options(args: &CompareConfig) -> InputOptions {
    InputOptions {
        fps_override: None,
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
        rectilinear: None,
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
    if let Some(reference) = &clip.reference {
        // The fits run from the global-shutter twin's frames.
        let mut src = video::open_input(reference, &input_options(clip, args))?;
        let mut pyramids = Vec::with_capacity(out.pyramids.len());
        while let Some(_t) = src.next_frame(&mut frame)? {
            masked_luma_into(&frame.as_ref(), &all, &mut luma);
            pyramids.push(homography::Pyramid::new(&luma));
        }
        if pyramids.len() != out.pyramids.len() {
            return Err(CompareError::NoFrames(reference.clone()));
        }
        out.pyramids = pyramids;
    }
    if !clip.lens.is_pinhole() {
        let fitted = clip.reference.as_deref().unwrap_or(&clip.input);
        out.rectilinear = Some(rectilinear_pyramids(fitted, clip, args, out.times.len())?);
    }
    Ok(out)
}

impl DecodedInput {
    /// The frames a method's output is fitted to: `rectilinear` for a method
    /// that renders a distorted lens as a pinhole (`rectilinear_output`).
    fn fit_pyramids(&self, rectilinear_output: bool) -> &[homography::Pyramid] {
        match (&self.rectilinear, rectilinear_output) {
            (Some(r), true) => r,
            _ => &self.pyramids,
        }
    }
}

/// The luma pyramids of `path`'s frames seen through a pinhole of `clip`'s
/// focal length, the lens's full size: our `none` mode with no margin and no
/// zoom, which is that remap (where the pinhole sees beyond the lens, the
/// pixels are invalid and the fits leave them out).
fn rectilinear_pyramids(
    path: &Path,
    clip: &Clip,
    args: &CompareConfig,
    count: usize,
) -> Result<Vec<homography::Pyramid>, CompareError> {
    let mut src = video::open_input(path, &input_options(clip, args))?;
    let (w, h) = (src.info().width, src.info().height);
    let mut options = amc_core::StabilizerOptions::with_mode(Mode::None);
    options.set("zoom", "none")?;
    options.set("margin", "0")?;
    options.validate()?;
    let mut stab = Stabilizer::new(&clip.lens, w, h, options.params)?;
    let mut frame = Frame::new(w, h, PixelFormat::Rgb8);
    let mut luma = GrayImage::default();
    let mut pyramids = Vec::with_capacity(count);
    let mut take = |stab: &Stabilizer| {
        masked_luma_into(&stab.output(), stab.output_coverage(), &mut luma);
        pyramids.push(homography::Pyramid::new(&luma));
    };
    while let Some(t) = src.next_frame(&mut frame)? {
        if stab.push(frame.as_ref(), t)?.is_some() {
            take(&stab);
        }
    }
    while stab.finish().is_some() {
        take(&stab);
    }
    if pyramids.len() != count {
        return Err(CompareError::NoFrames(path.to_path_buf()));
    }
    Ok(pyramids)
}

/// The stabilizer parameters `amc stabilize` uses for `method` (its defaults,
/// or the paper's settings for an input of `input_size` for the matched runs).
fn our_params(
    method: Method,
    lookahead: usize,
    input_size: (usize, usize),
    clip_fps: f64,
) -> Result<StabilizerParams, CompareError> {
    let mode = match method {
        Method::None | Method::MatchedNone => Mode::None,
        Method::Saccade | Method::MatchedSaccade => Mode::Saccade,
        _ => Mode::Stabilize,
    };
    let mut o = amc_core::StabilizerOptions::with_mode(mode);
    if method.is_matched() {
        for (name, value) in paper::matched_options(input_size.0, input_size.1, clip_fps) {
            o.set(name, &value)?;
        }
        o.validate()?;
    }
    let mut p = o.params;
    if method == Method::StabilizeLookahead {
        p.view.lookahead = lookahead;
    }
    Ok(p)
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
    frames_with_border: usize,
    /// The estimated orientations `R_{0,j}` and their times.
    estimates: (Vec<f64>, Vec<Rot>),
}

/// Measures one of our modes in-process (same output as the timed child).
fn measure_ours(
    method: Method,
    clip: &Clip,
    input: &DecodedInput,
    args: &CompareConfig,
) -> Result<OursMeasured, CompareError> {
    let mut params = our_params(method, args.lookahead, input.size, fps_of(input))?;
    params.shutter.readout_ms = clip.readout_ms;
    let mut opts = input_options(clip, args);
    if method.is_matched() {
        // As the timed run: one paper filter step per frame.
        opts.fps_override = Some(paper::matched_fps());
    }
    let mut src = video::open_input(&clip.input, &opts)?;
    let (w, h) = input.size;
    let mut stab = Stabilizer::new(&clip.lens, w, h, params)?;
    let mut m = Measurer::new(fps_of(input), w, clip.lens.fx);
    let mut frame = Frame::new(w, h, PixelFormat::Rgb8);
    let mut est = Vec::new();
    let mut est_times = Vec::new();
    let mut saccades = Vec::new();
    let mut middle = None;
    let mut frames_with_border = 0usize;
    let mid = input.times.len() / 2;
    // Matched runs are measured as the paper's output is: on the pixels every
    // averaged frame covers (the most frames any pixel has), not on every
    // pixel some frame covers; near the border fewer frames are averaged, and
    // those pixels move more.
    let matched = method.is_matched();
    let mut full_mask = Vec::new();
    let mut handle = |stab: &Stabilizer, tel: amc_core::Telemetry| {
        // From the renderer's coverage: pixels no averaged frame covers.
        frames_with_border += (tel.uncovered > 0) as usize;
        let j = tel.frame as usize;
        let Some(pyr) = input.fit_pyramids(true).get(j) else {
            return;
        };
        let out = stab.output();
        let coverage = stab.output_coverage();
        let mask = if matched {
            let full = coverage.iter().copied().max().unwrap_or(0);
            full_mask.clear();
            full_mask.extend(coverage.iter().map(|&c| (c == full && c > 0) as u8));
            &full_mask[..]
        } else {
            coverage
        };
        m.push(tel.t, pyr, &out, mask, tel.valid_fraction, Some(&tel));
        if j == mid {
            let mut f = Frame::new(out.width, out.height, out.format);
            f.copy_from(&out);
            middle = Some(f);
        }
        est.push(so3::exp(&Tangent::from(tel.r_est)));
        est_times.push(tel.t);
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
        frames_with_border,
        estimates: (est_times, est),
    })
}

/// Where the validity of a measured output's pixels comes from.
enum Validity<'a> {
    /// A peer's: where the output agrees with its alternative-fill run, this
    /// `.y4m`. ffmpeg's filters move frames in the lens's own projection.
    Agreement(&'a Path),
    /// The paper's: the masks its loader wrote to this file. Its loader
    /// undistorts distorted lenses (OpenCV's undistortion map).
    Written(&'a Path),
}

/// A [`Validity`], open to be read frame by frame.
enum ValidityReader<'a> {
    Agreement(Box<dyn video::FrameSource>, Frame),
    Written(std::io::BufReader<std::fs::File>, &'a Path),
}

/// Measures a peer's or the paper's output `.y4m`, `main`, with its
/// `validity`; and keeps its middle frame.
fn measure_output(
    clip: &Clip,
    input: &DecodedInput,
    main: &Path,
    validity: Validity<'_>,
    args: &CompareConfig,
) -> Result<(Measured, Option<Frame>), CompareError> {
    let opts = output_options(args);
    let mut src = video::open_input(main, &opts)?;
    let (w, h) = (src.info().width, src.info().height);
    let mut reader = match validity {
        Validity::Agreement(alt) => ValidityReader::Agreement(
            video::open_input(alt, &opts)?,
            Frame::new(w, h, PixelFormat::Rgb8),
        ),
        Validity::Written(path) => {
            let file = std::fs::File::open(path).map_err(|e| CompareError::io(path, e))?;
            ValidityReader::Written(std::io::BufReader::new(file), path)
        }
    };
    let rectilinear_output = matches!(reader, ValidityReader::Written(..));
    let mut frame = Frame::new(w, h, PixelFormat::Rgb8);
    let mut m = Measurer::new(fps_of(input), input.size.0, clip.lens.fx);
    let mut mask = Vec::new();
    let mut middle = None;
    let mid = input.times.len() / 2;
    for (j, pyr) in input.fit_pyramids(rectilinear_output).iter().enumerate() {
        let valid = match &mut reader {
            ValidityReader::Agreement(alt, b) => {
                let (Some(_), Some(_)) = (src.next_frame(&mut frame)?, alt.next_frame(b)?) else {
                    break;
                };
                measure::agreement_mask(&frame.as_ref(), &b.as_ref(), &mut mask)
            }
            ValidityReader::Written(file, path) => {
                if src.next_frame(&mut frame)?.is_none()
                    || !paper::read_valid(file, path, &mut mask, w * h)?
                {
                    break;
                }
                mask.iter().filter(|&&v| v != 0).count() as f64 / (w * h) as f64
            }
        };
        m.push(input.times[j], pyr, &frame.as_ref(), &mask, valid, None);
        if j == mid {
            middle = Some(frame.clone());
        }
    }
    Ok((m.finish(), middle))
}

/// Runs the paper's code on `clip` in `method`'s mode (its renderer fed
/// `rotations` when given) and measures it.
#[allow(clippy::too_many_arguments)]
fn run_paper_method(
    env: &paper::PaperEnv,
    method: Method,
    clip: &Clip,
    input: &DecodedInput,
    lens_json: &Path,
    rotations: Option<&Path>,
    dir: &Path,
    args: &CompareConfig,
) -> Result<MethodResult, CompareError> {
    let (usage, outs) = paper::run(
        env,
        method,
        &clip.input,
        lens_json,
        rotations,
        fps_of(input),
        dir,
        timeout(args),
        args.repeat,
    )?;
    let measured = measure_output(
        clip,
        input,
        &outs.main,
        Validity::Written(&outs.valid),
        args,
    );
    let loop_seconds = paper::loop_seconds(&outs.log);
    let _ = std::fs::remove_file(&outs.main);
    let _ = std::fs::remove_file(&outs.valid);
    let (measured, middle) = measured?;
    Ok(MethodResult {
        loop_frames_per_second: loop_seconds.map(|s| input.times.len() as f64 / s),
        ..MethodResult::new(method.label(), input.times.len(), usage, measured, middle)
    })
}

/// Runs every method on `clip`, in a scratch folder under `work`.
fn compare_clip(
    clip: &Clip,
    args: &CompareConfig,
    paper_status: &PaperStatus,
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
    // Our timed runs read the readout from it, as `amc stabilize --lens` does.
    let lens_file = amc_core::lens::LensFile {
        camera: clip.lens.clone(),
        readout_ms: (clip.readout_ms > 0.0).then_some(clip.readout_ms),
    };
    std::fs::write(&lens_json, lens_file.to_project_json())
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
    let mut paper_skipped = None;
    // Our matched runs' orientations (by mode), which the paper's renderer is
    // fed next, and the true ones (written for the first method fed them).
    let mut ours_orientations: Vec<(&str, PathBuf)> = Vec::new();
    let mut truth_orientations: Option<PathBuf> = None;
    let extra: &[Method] = match paper_status {
        PaperStatus::Ready(_) => &Method::PAPER,
        _ => &[],
    };
    for &method in Method::ALL.iter().chain(extra) {
        if method.paper_mode().is_some() || method.is_matched() {
            if let Some(why) = &paper_skipped {
                say(format!("{}: skipped ({why})", method.label()));
                continue;
            }
        }
        // The orientations the paper's renderer takes instead of its tracker's.
        let mode = method.paper_mode().unwrap_or_default();
        let fed = match method.fed() {
            Some(Fed::Ours) => match ours_orientations.iter().find(|(m, _)| *m == mode) {
                Some((_, path)) => Some(path.clone()),
                None => {
                    say(format!(
                        "{}: skipped (no matched {mode} estimates of ours)",
                        method.label()
                    ));
                    continue;
                }
            },
            // Only where the truth is known (the synthetic clips).
            Some(Fed::Truth) => match (&truth_orientations, &clip.gt) {
                (Some(path), _) => Some(path.clone()),
                (None, Some(gt)) => {
                    let path = dir.join("truth.orientations.csv");
                    std::fs::write(&path, gt::orientations_csv(&input.times, gt))
                        .map_err(|e| CompareError::io(&path, e))?;
                    truth_orientations = Some(path.clone());
                    Some(path)
                }
                (None, None) => continue,
            },
            None => None,
        };
        say(format!("{}: timed run", method.label()));
        let r = if let (PaperStatus::Ready(env), Some(_)) = (paper_status, method.paper_mode()) {
            let measured = run_paper_method(
                env,
                method,
                clip,
                &input,
                &lens_json,
                fed.as_deref(),
                &dir,
                args,
            );
            match measured {
                Ok(r) if r.frames > 0 => r,
                // Research code on a clip it may not take (a lens, a length):
                // reported as skipped on this clip, the comparison goes on.
                Ok(_) => {
                    paper_skipped = Some(format!("{} produced no frames", method.label()));
                    continue;
                }
                Err(e) => {
                    let why = format!("{}: {e}", method.label());
                    eprintln!(
                        "[{}] the paper's code is skipped on this clip: {why}",
                        clip.name
                    );
                    paper_skipped = Some(why);
                    continue;
                }
            }
        } else if method.is_ours() {
            // The paper's smoothing per frame, template resets, framing and output size.
            let matched_options = method
                .is_matched()
                .then(|| paper::matched_options(input.size.0, input.size.1, fps_of(&input)));
            let (usage, out) = peers::run_ours(
                method,
                &clip.input,
                &lens_json,
                clip.fps,
                args.lookahead,
                matched_options.as_deref().map(|options| peers::MatchedRun {
                    options,
                    fps: paper::matched_fps(),
                }),
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
                frames_with_border,
                estimates: (times, estimates),
            } = measure_ours(method, clip, &input, args)?;
            if let (true, Some(mode)) = (method.is_matched(), method.our_mode()) {
                let path = dir.join(format!("{}.orientations.csv", method.label()));
                std::fs::write(&path, gt::orientations_csv(&times, &estimates))
                    .map_err(|e| CompareError::io(&path, e))?;
                ours_orientations.push((mode, path));
            }
            MethodResult {
                ground_truth,
                saccades,
                frames_with_border: Some(frames_with_border),
                ..MethodResult::new(method.label(), input.times.len(), usage, measured, middle)
            }
        } else {
            let (usage, outs) =
                peers::run_peer(method, &ff_input, &dir, timeout(args), args.repeat)?;
            say(format!("{}: measuring", method.label()));
            let measured = measure_output(
                clip,
                &input,
                &outs.main,
                Validity::Agreement(&outs.alt),
                args,
            );
            let _ = std::fs::remove_file(&outs.main);
            let _ = std::fs::remove_file(&outs.alt);
            let (measured, middle) = measured?;
            MethodResult::new(method.label(), input.times.len(), usage, measured, middle)
        };
        if r.frames == 0 {
            return Err(CompareError::NoOutput {
                method: method.label().into(),
                clip: clip.name.clone(),
            });
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
        paper_skipped,
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
    if let Some(lens_path) = engine::folder_lens_file(path) {
        let text =
            std::fs::read_to_string(&lens_path).map_err(|e| CompareError::io(&lens_path, e))?;
        let lens_file =
            amc_core::lens::parse_lens_file(&text).map_err(|source| CompareError::Lens {
                path: lens_path.clone(),
                source,
            })?;
        let (lens, readout_ms) = (lens_file.camera, lens_file.readout_ms.unwrap_or(0.0));
        let frames = if path.join("frames").is_dir() {
            path.join("frames")
        } else {
            path.to_path_buf()
        };
        let gt_path = path.join("gt.csv");
        let gt = if gt_path.is_file() {
            Some(gt::read_orientations(&gt_path)?)
        } else {
            None
        };
        // The rate the folder states (meta.json or gt.csv), as image inputs read it.
        let fps = video::folder_fps(path);
        return Ok(Clip {
            name: stem(path),
            input: frames,
            lens,
            readout_ms,
            reference: None,
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
        readout_ms: 0.0,
        reference: None,
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
        return Err(CompareError::NoClips);
    }
    if !(0.5..=60.0).contains(&args.synthetic_seconds) {
        return Err(CompareError::SyntheticSeconds(args.synthetic_seconds));
    }
    if !(1..=MAX_LOOKAHEAD).contains(&args.lookahead) {
        return Err(CompareError::Lookahead(args.lookahead));
    }
    if !(1..=10).contains(&args.repeat) {
        return Err(CompareError::Repeat(args.repeat));
    }
    if args.synthetic && !args.panorama.is_file() {
        return Err(CompareError::NoPanorama(args.panorama.clone()));
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
            let (dir, twin) = synthetic::render(spec, args, work.path())?;
            let mut clip = resolve_clip(&dir, args)?;
            clip.reference = twin;
            clip.name = spec.name.to_string();
            clip.description = spec.describe(args);
            clips.push(clip);
        }
    }
    let paper_status = PaperStatus::resolve(args.paper_env.as_deref());
    match &paper_status {
        PaperStatus::Skipped(why) => eprintln!("the paper's code (--peer paper) is skipped: {why}"),
        PaperStatus::Ready(env) if !args.quiet => {
            eprintln!(
                "the paper's code (--peer paper): {}",
                env.versions.describe()
            )
        }
        _ => {}
    }
    let mut results = Vec::new();
    for clip in &clips {
        let r = compare_clip(clip, args, &paper_status, work.path())?;
        // Write as we go, so a long run leaves a report of what finished.
        results.push(r);
        report::write(&args.report, &results, args, &paper_status)?;
    }
    if !args.quiet {
        eprintln!("wrote {}", args.report.join(report::REPORT_FILE).display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matched_runs_take_the_papers_settings_and_default_runs_do_not() {
        let p = our_params(Method::MatchedStabilize, 30, (640, 360), 30.0).unwrap();
        assert_eq!(p.render.output_width, Some(240));
        assert_eq!(p.render.output_height, Some(136));
        let d = our_params(Method::Stabilize, 30, (640, 360), 30.0).unwrap();
        assert_eq!(d.render.output_width, None);
        assert_ne!(format!("{:?}", p.view), format!("{:?}", d.view));
        let n = our_params(Method::MatchedNone, 30, (640, 360), 30.0).unwrap();
        assert_eq!(n.render.output_width, Some(240));
    }

    #[test]
    fn without_the_papers_environment_the_report_says_it_was_skipped() {
        let dir = tempfile::tempdir().unwrap();
        let status = PaperStatus::resolve(Some(&dir.path().join("no-env")));
        let PaperStatus::Skipped(why) = &status else {
            panic!("not skipped: {status:?}")
        };
        assert!(why.contains("no-env"), "{why}");
        let args = CompareConfig {
            clips: Vec::new(),
            report: dir.path().join("report"),
            synthetic: false,
            synthetic_seconds: 5.0,
            synthetic_size: (320, 180),
            panorama: dir.path().join("pano.jpg"),
            lens: amc_core::LensSpec::Auto,
            lookahead: 30,
            fps: None,
            timeout: 60,
            machine: None,
            repeat: 1,
            per_frame: false,
            quiet: true,
            paper_env: Some(dir.path().join("no-env")),
        };
        std::fs::create_dir_all(&args.report).unwrap();
        report::write(&args.report, &[], &args, &status).unwrap();
        let text = std::fs::read_to_string(args.report.join(report::REPORT_FILE)).unwrap();
        assert!(
            text.contains(
                "The paper's code (`--peer paper`) was **skipped**: no paper-peer environment"
            ),
            "{text}"
        );
        // Not asked for: not mentioned.
        report::write(&args.report, &[], &args, &PaperStatus::NotRequested).unwrap();
        let text = std::fs::read_to_string(args.report.join(report::REPORT_FILE)).unwrap();
        assert!(!text.contains("was **skipped**"));
    }
}
