//! `amc`: the command line of Artificial Microsaccade Compensation. Thin:
//! parse, convert, call the library, print, map the error to an exit code.

mod args;
mod clip_lens;
mod error;
mod options;
mod progress;
mod signals;

use amc_engine::{self as engine, LensNote, RunConfig, FALLBACK_FOV_DEG};
use amc_eval::{compare, demo, eval, synth};
use amc_server::serve;
use args::{Cli, Command, KeysCommand, StabilizeArgs};
use clap::Parser;
use error::CliError;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

/// Tells the user how `--fov auto` and `--readout-ms auto` went (a readout
/// fallback is a warning, shown even with `--quiet`).
fn say_resolved(resolved: &engine::Resolved, quiet: bool) {
    say_lens(resolved.lens_note(), quiet);
    if let Some(line) = resolved.readout.message() {
        if !quiet || resolved.readout.note.is_warning() {
            eprintln!("{line}");
        }
    }
}

/// Tells the user how `--fov auto` went.
fn say_lens(note: &LensNote, quiet: bool) {
    if quiet {
        return;
    }
    match note {
        LensNote::Given => {}
        LensNote::Estimated { hfov_deg, frames } => eprintln!(
            "estimated horizontal field of view: {hfov_deg:.1} deg (from {frames} frames; pass --fov or --lens to set it)"
        ),
        LensNote::FellBack => eprintln!(
            "warning: the footage does not pin down the focal length (translation or little rotation); \
             assuming a {FALLBACK_FOV_DEG} deg horizontal field of view: pass --fov DEG or --lens FILE for best results"
        ),
    }
}

/// Where an input's frames, lens and rate come from. An image folder may be
/// a recording laid out as `amc compare` reads one: its own `lens.json` (as
/// `amc synth` writes beside its frames, `meta.json` and `gt.csv`) with the
/// images beside it or in `frames/` (as `../shared/data/cc9` is).
struct Input {
    /// The video, or the folder the images are read from.
    frames: PathBuf,
    /// The lens file given (`--lens`), else the folder's own where `--fov`
    /// is not given either.
    lens: Option<PathBuf>,
    /// The frame rate given (`--fps`), else the one the recording states
    /// when its images are in `frames/` (a folder of images read directly
    /// states its own, `meta.json` or `gt.csv`, to the reader).
    fps: Option<f64>,
}

/// Resolves `path` with the run's flags (see [`Input`]); says which lens file
/// a folder brought. Without this, the folder's calibration was thrown away
/// for an estimate of the focal length, which on a rolling-shutter clip
/// tracked as a global shutter fell back to 70 deg for a 90 deg lens.
fn input_of(path: &std::path::Path, run: &args::RunFlags, quiet: bool) -> Input {
    let in_subfolder =
        path.is_dir() && path.join("frames").is_dir() && amc_video::list_images(path).is_err();
    let frames = if in_subfolder {
        path.join("frames")
    } else {
        path.to_path_buf()
    };
    let folder_lens = (run.lens.is_none() && !run.stabilizer.has("fov"))
        .then(|| engine::folder_lens_file(path))
        .flatten();
    if let (Some(lens), false) = (&folder_lens, quiet) {
        eprintln!(
            "lens: {} (the folder's own; pass --lens or --fov to override it)",
            lens.display()
        );
    }
    let fps = run
        .input
        .fps
        .or_else(|| in_subfolder.then(|| amc_video::folder_fps(path)).flatten());
    Input {
        frames,
        lens: run.lens.clone().or(folder_lens),
        fps,
    }
}

/// Warns when an image folder's frame rate was assumed.
fn say_rate(input: &std::path::Path, fps: Option<f64>, timeout: Duration, quiet: bool) {
    if quiet || fps.is_some() || !input.is_dir() {
        return;
    }
    if let Ok(src) = amc_video::open_input(input, &engine::input_options(None, timeout)) {
        if src.info().fps_assumed {
            eprintln!(
                "warning: {} states no frame rate (no meta.json or gt.csv): assuming {} frames/s; pass --fps to set it",
                input.display(),
                amc_video::DEFAULT_IMAGE_FPS
            );
        }
    }
}

fn stabilize(args: StabilizeArgs, control: &engine::RunControl) -> Result<(), CliError> {
    // Outputs are checked before any work: a field-of-view estimate alone takes seconds.
    amc_video::check_output(&args.output)?;
    for p in args.telemetry.iter().chain(&args.metrics) {
        amc_video::check_parent_dir(p)?;
    }
    let input = input_of(&args.input, &args.run, args.quiet);
    let options = args
        .run
        .stabilizer
        .options(amc_core::Mode::Stabilize, input.lens.as_ref())?;
    let timeout = Duration::from_secs(args.run.input.timeout);
    let fps = input.fps;
    let mut paths = vec![
        ("input", input.frames.as_path()),
        ("output", args.output.as_path()),
    ];
    paths.extend(args.telemetry.iter().map(|p| ("telemetry", p.as_path())));
    paths.extend(args.metrics.iter().map(|p| ("metrics", p.as_path())));
    paths.extend(
        args.export_gcsv
            .iter()
            .map(|p| ("export-gcsv", p.as_path())),
    );
    engine::check_distinct(&paths)?;
    if !args.quiet && args.output.is_file() {
        eprintln!(
            "note: {} exists: it is replaced once the new output is complete (until then it stays as it is)",
            args.output.display()
        );
    }
    say_rate(&input.frames, fps, timeout, args.quiet);
    let clip = clip_lens::clip_lens(
        &input.frames,
        args.lens_db.as_deref(),
        &engine::input_options(fps, timeout),
        args.quiet,
    )?;
    // The gyro log is read before the run: a file that cannot be read fails now.
    let gyro_log = match &args.gyro {
        engine::gyro::GyroChoice::Off => None,
        engine::gyro::GyroChoice::Auto => engine::gyro::clip_gyro(&input.frames),
        engine::gyro::GyroChoice::File(p) => Some(engine::gyro::read_gyro_log(p)?),
    };
    // What the log does to the readout: a recorded one answers `auto`;
    // `auto` with one that records none is measured against it in the run.
    let readout_asked = options.readout.clone();
    let log_readout = engine::LogReadout::choose(&readout_asked, gyro_log.as_ref());
    let mut options = options;
    options.readout = log_readout.spec(&readout_asked);
    let in_opts = engine::input_options(fps, timeout);
    let mut resolved = match &clip.pick {
        Some(pick) => engine::resolve_known(&options, pick.lens(), &input.frames, &in_opts)?,
        None => engine::resolve(&options, &input.frames, &in_opts, None)?,
    };
    if let Some(line) = log_readout.apply(&readout_asked, &mut resolved.readout) {
        resolved.params.shutter.readout_ms = resolved.readout.readout_ms;
        if !args.quiet {
            eprintln!("{line}");
        }
    }
    // Measured against the log in the run (which says how it went).
    let measure_readout = log_readout.measure(&readout_asked, &resolved.readout);
    if measure_readout.is_some() {
        say_lens(resolved.lens_note(), args.quiet);
    } else {
        say_resolved(&resolved, args.quiet);
    }
    let also: Vec<(&'static str, &std::path::Path)> = args
        .metrics
        .iter()
        .map(|p| ("metrics", p.as_path()))
        .chain(
            args.export_gcsv
                .iter()
                .map(|p| ("export-gcsv", p.as_path())),
        )
        .collect();
    let bar = progress::Bar::new("stabilize", !args.quiet);
    let report = |p| bar.update(p);
    let refit_lens = matches!(resolved.lens.note, engine::LensNote::FellBack);
    let run = engine::run(&RunConfig {
        input: &input.frames,
        output: Some(&args.output),
        params: resolved.params,
        lens: resolved.lens.camera,
        telemetry: args.telemetry.as_deref(),
        also_writes: &also,
        fps,
        timeout,
        crf: args.crf,
        preset: args.preset,
        keep_per_frame: args.export_gcsv.is_some(),
        measure: args.metrics.is_some(),
        control: Some(control),
        progress: Some(&report),
        gyro: gyro_log.as_ref(),
        measure_readout,
        refit_lens,
        threads: args.run.input.threads(),
    })?;
    bar.finish();
    if let (Some(hfov), false) = (run.refit_hfov_deg, args.quiet) {
        eprintln!("{}", engine::refit_line(hfov));
    }
    if let (Some(g), false) = (&run.gyro, args.quiet) {
        eprintln!("{}", g.line());
    }
    // A log that does not fit the video: the output stands on the video alone.
    for w in &run.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(p) = &args.export_gcsv {
        amc_video::write_atomic(
            p,
            engine::gcsv::gcsv(&run.per_frame, run.readout_ms).as_bytes(),
        )?;
    }
    if run.looks_truncated() {
        eprintln!(
            "warning: {} declares {} frames but only {} could be decoded: the file looks truncated or damaged",
            args.input.display(),
            run.frames_declared.unwrap_or(0),
            run.frames
        );
    }
    if let Some(p) = &args.metrics {
        let mut json = serde_json::to_value(&run).expect("a run summary is plain data");
        // What the clip names and the profile --lens-db picked (null: none matched).
        if let Some(c) = &clip.camera {
            json["clip_camera"] = serde_json::to_value(c).expect("plain data");
        }
        if args.lens_db.is_some() {
            json["lens_profile"] = serde_json::to_value(&clip.pick).expect("plain data");
        }
        let text = serde_json::to_string_pretty(&json).expect("plain data");
        amc_video::write_atomic(p, text.as_bytes())?;
    }
    if !args.quiet {
        let mut line = format!(
            "wrote {} ({} frames, {}x{}, {:.0} frames/s)",
            args.output.display(),
            run.frames,
            run.output_size.0,
            run.output_size.1,
            run.frames_per_second
        );
        if let Some(m) = &run.metrics {
            line += &format!(
                ": normal flow {:.3} px, frame change {:.4}, sharpness {:.4}, valid {:.1}%, view {:.1} deg/s vs camera {:.1} deg/s",
                m.rms_normal_flow,
                m.rms_change,
                m.sharpness,
                100.0 * m.valid_fraction,
                m.rms_speed_view_dps,
                m.rms_speed_est_dps
            );
        }
        if let Some(p) = &args.telemetry {
            line += &format!("; telemetry in {}", p.display());
        }
        if let Some(p) = &args.metrics {
            line += &format!("; metrics in {}", p.display());
        }
        eprintln!("{line}");
    }
    Ok(())
}

fn evaluate(a: args::EvalArgs) -> Result<(), CliError> {
    let quiet = a.quiet;
    let timeout = Duration::from_secs(a.run.input.timeout);
    if let Some(p) = &a.plot {
        amc_video::check_parent_dir(p)?;
    }
    let input = input_of(&a.input, &a.run, quiet);
    say_rate(&input.frames, input.fps, timeout, quiet);
    let cfg = eval::EvalConfig {
        options: a
            .run
            .stabilizer
            .options(amc_core::Mode::Stabilize, input.lens.as_ref())?,
        input: input.frames,
        fps: input.fps,
        timeout,
        gt: a.gt,
        plot: a.plot.clone(),
        threads: a.run.input.threads(),
    };
    let bars = progress::Bars::new(!quiet);
    let report = eval::run(&cfg, &|r| say_resolved(r, quiet), &|mode, p| {
        bars.update(mode, p)
    })?;
    bars.finish();
    if a.json {
        let s = serde_json::to_string_pretty(&report).expect("a report is plain data");
        println!("{s}");
    } else {
        print!("{}", eval::markdown(&report));
    }
    if let Some(p) = &a.plot {
        if !quiet {
            eprintln!("wrote the plot to {}", p.display());
        }
    }
    Ok(())
}

fn run(cli: Cli, control: &engine::RunControl) -> Result<(), CliError> {
    match cli.command {
        Command::Stabilize(a) => stabilize(a, control),
        Command::Eval(a) => evaluate(a),
        Command::Synth(a) => {
            let bar = progress::Bar::new("rendering", true);
            let line = synth::run(&a.config(), &|done, total| {
                bar.count(done as u64, total as u64)
            })?;
            bar.finish();
            println!("{line}");
            Ok(())
        }
        Command::Demo(a) => {
            let report = demo::run(&a.config(), &|line| eprintln!("{line}"))?;
            println!("{report}");
            Ok(())
        }
        Command::Serve(a) => Ok(serve::run(&a.config()?)?),
        Command::Worker(a) => Ok(amc_server::worker::run(&a.config()?)?),
        Command::Compare(a) => Ok(compare::run(&a.config()?)?),
        Command::Keys(a) => match a.command {
            KeysCommand::New {
                tenant,
                roles,
                append,
            } => {
                let (key, line) =
                    amc_server::auth::new_key(&tenant, &roles).map_err(CliError::Keys)?;
                if let Some(path) = &append {
                    append_line(path, &line)?;
                }
                // Stdout: the key, then (without --append) the file's line,
                // one a line so scripts can take either; how to use them on stderr.
                println!("{key}");
                match &append {
                    Some(p) => {
                        eprintln!("The key above is shown once: give it to its user (`Authorization: Bearer KEY`).");
                        eprintln!("Added to {}: {line}", p.display());
                    }
                    None => {
                        println!("{line}");
                        eprintln!(
                            "The first line is the key, shown once: give it to its user (`Authorization: Bearer KEY`).\n\
                             The second is the line for the --auth-keys file (it holds only the key's SHA-256)."
                        );
                    }
                }
                Ok(())
            }
        },
    }
}

/// Appends a keys file's line (the file made owner-only if new).
fn append_line(path: &std::path::Path, line: &str) -> Result<(), CliError> {
    use std::io::Write;
    let mut open = std::fs::OpenOptions::new();
    open.create(true).append(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut open, 0o600);
    let io = |e: std::io::Error| CliError::Keys(format!("{}: {e}", path.display()));
    let mut f = open.open(path).map_err(io)?;
    writeln!(f, "{line}").map_err(io)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let serving = matches!(cli.command, Command::Serve(_) | Command::Worker(_));
    let control = std::sync::Arc::new(engine::RunControl::new(None));
    if !serving {
        // The service handles its own signals (graceful shutdown).
        signals::on_interrupt(control.clone());
    }
    match run(cli, &control) {
        Ok(()) => ExitCode::SUCCESS,
        Err(CliError::Run(engine::RunError::Cancelled)) => ExitCode::from(signals::exit_code()),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
