//! `amc`: the command line of Artificial Microsaccade Compensation.

mod cli;
mod compare;
mod demo;
mod error;
mod eval;
mod gt;
mod measure;
mod pipeline;
mod plot;
mod serve;
mod synth_cmd;

use clap::Parser;
use cli::{Cli, Command, StabilizeArgs};
use error::CliError;
use pipeline::RunConfig;
use std::process::ExitCode;
use std::time::Duration;

fn stabilize(args: &StabilizeArgs) -> Result<(), CliError> {
    let params = args.tuning.params(args.mode);
    params.validate()?;
    let timeout = Duration::from_secs(args.tuning.timeout);
    let lens = pipeline::resolve_lens(
        &args.lens.choice()?,
        &args.input,
        &params,
        args.tuning.fps,
        timeout,
        args.quiet,
    )?;
    let run = pipeline::run(&RunConfig {
        input: &args.input,
        output: Some(&args.output),
        params,
        lens,
        telemetry: args.telemetry.as_deref(),
        fps: args.tuning.fps,
        timeout,
        crf: args.crf,
        progress: !args.quiet,
        keep_per_frame: false,
        measure: args.metrics.is_some(),
        label: "stabilize",
        control: None,
    })?;
    if run.looks_truncated() {
        eprintln!(
            "warning: {} declares {} frames but only {} could be decoded: the file looks truncated or damaged",
            args.input.display(),
            run.frames_declared.unwrap_or(0),
            run.frames
        );
    }
    if let Some(p) = &args.metrics {
        let json =
            serde_json::to_string_pretty(&run).map_err(|e| CliError::Usage(e.to_string()))?;
        pipeline::write_atomic(p, json.as_bytes())?;
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
                ": normal flow {:.3} px, frame change {:.4}, valid {:.1}%, view {:.1} deg/s vs camera {:.1} deg/s",
                m.rms_normal_flow,
                m.rms_change,
                100.0 * m.valid_fraction,
                m.rms_speed_view_dps,
                m.rms_speed_est_dps
            );
        }
        eprintln!("{line}");
    }
    Ok(())
}

fn run(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::Stabilize(a) => stabilize(&a),
        Command::Eval(a) => {
            let report = eval::run(&a)?;
            if a.json {
                let s = serde_json::to_string_pretty(&report)
                    .map_err(|e| CliError::Usage(e.to_string()))?;
                println!("{s}");
            } else {
                print!("{}", eval::markdown(&report));
            }
            Ok(())
        }
        Command::Synth(a) => synth_cmd::run(&a),
        Command::Demo(a) => demo::run(&a),
        Command::Serve(a) => serve::run(&a),
        Command::Compare(a) => compare::run(&a),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
