//! The command line's parsing, as a user types it.

use super::*;
use amc_core::view::Mode;
use amc_core::LensSpec;
use clap::Parser;
use std::path::PathBuf;

fn parse(argv: &[&str]) -> Result<Cli, clap::Error> {
    Cli::try_parse_from(std::iter::once("amc").chain(argv.iter().copied()))
}

#[test]
fn compare_runs_the_paper_only_when_asked() {
    let config = |argv: &[&str]| {
        let Command::Compare(a) = parse(argv).unwrap().command else {
            panic!("not compare")
        };
        a.config().unwrap()
    };
    assert_eq!(
        config(&["compare", "c.mp4", "--report", "r"]).paper_env,
        None
    );
    let c = config(&[
        "compare",
        "c.mp4",
        "--report",
        "r",
        "--peer",
        "paper",
        "--paper-env",
        "/env",
    ]);
    assert_eq!(c.paper_env, Some(PathBuf::from("/env")));
    // Without --paper-env: $AMC_PAPER_PEER or ~/.cache/amc/paper-peer.
    let c = config(&["compare", "c.mp4", "--report", "r", "--peer", "paper"]);
    assert_eq!(
        c.paper_env,
        Some(amc_eval::compare::paper::default_env_dir())
    );
    assert!(parse(&["compare", "c.mp4", "--report", "r", "--peer", "vidstab"]).is_err());
}

#[test]
fn the_job_table_and_bucket_go_together_and_are_checked() {
    // Without them, serve keeps its jobs in memory.
    let Command::Serve(a) = parse(&["serve"]).unwrap().command else {
        panic!("not serve")
    };
    assert!(a.config().unwrap().cluster.is_none());
    // One without the other is a usage error.
    for argv in [
        &["serve", "--queue", "postgres://h/db"][..],
        &["serve", "--store", "s3://amc"][..],
        &["worker", "--queue", "postgres://h/db"][..],
    ] {
        let e = parse(argv).err().unwrap().to_string();
        assert!(
            e.contains("--store") || e.contains("--queue"),
            "{argv:?}: {e}"
        );
    }
    // A worker needs both.
    let Command::Worker(a) = parse(&["worker"]).unwrap().command else {
        panic!("not worker")
    };
    let e = a.config().err().unwrap().to_string();
    assert!(e.contains("--queue") && e.contains("--store"), "{e}");
    // Both, with the flags beside them.
    let argv = [
        "worker",
        "--queue",
        "postgres://amc:pw@db:5432/amc",
        "--store",
        "s3://amc-videos/team",
        "--s3-endpoint",
        "http://127.0.0.1:8333",
        "--lease-secs",
        "10",
        "--threads",
        "1",
    ];
    let Command::Worker(a) = parse(&argv).unwrap().command else {
        panic!("not worker")
    };
    let c = a.config().unwrap();
    assert_eq!(c.cluster.store.bucket, "amc-videos");
    assert_eq!(c.cluster.store.prefix, "team");
    assert_eq!(
        c.cluster.store.endpoint.as_deref(),
        Some("http://127.0.0.1:8333")
    );
    assert_eq!(c.cluster.lease, std::time::Duration::from_secs(10));
    assert_eq!(c.threads, 1);
    // Bad values name their flag and range.
    for (queue, store, extra, expect) in [
        ("postgres://h/db", "s3://Bad_Bucket", None, "--store"),
        ("mysql://u:secret@h/db", "s3://amc", None, "--queue"),
        (
            "postgres://h/db",
            "s3://amc",
            Some(["--lease-secs", "1"]),
            "2..=3600",
        ),
        (
            "postgres://h/db",
            "s3://amc",
            Some(["--max-attempts", "0"]),
            "1..=100",
        ),
    ] {
        let mut argv = vec!["serve", "--queue", queue, "--store", store];
        argv.extend(extra.into_iter().flatten());
        let Command::Serve(a) = parse(&argv).unwrap().command else {
            panic!("not serve")
        };
        let e = a.config().err().unwrap().to_string();
        assert!(e.contains(expect) && !e.contains("secret"), "{argv:?}: {e}");
    }
}

/// The live feed's stabilizer parameters from `amc ARGV` (a `serve` command line).
fn live_params(argv: &[&str]) -> Result<amc_core::StabilizerParams, String> {
    let Command::Serve(a) = parse(argv).unwrap().command else {
        panic!("not serve")
    };
    a.config()
        .map_err(|e| e.to_string())?
        .live()
        .map(|live| live.params)
        .map_err(|e| e.to_string())
}

#[test]
fn live_roll_reaches_the_live_feeds_view() {
    let roll = |argv: &[&str]| live_params(argv).unwrap().view.roll;
    assert_eq!(roll(&["serve"]), amc_core::Roll::Smooth);
    assert_eq!(
        roll(&["serve", "--live-roll", "lock"]),
        amc_core::Roll::Lock
    );
    let e = parse(&["serve", "--live-roll", "level"])
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("smooth, lock or follow"), "{e}");
}

#[test]
fn live_saccade_mode_keeps_a_fixed_crop_unless_a_zoom_is_given() {
    let zoom = |argv: &[&str]| live_params(argv).unwrap().framing.zoom;
    assert_eq!(zoom(&["serve"]), amc_core::Zoom::Auto);
    assert_eq!(
        zoom(&["serve", "--live-mode", "saccade"]),
        amc_core::Zoom::None
    );
    assert_eq!(
        zoom(&["serve", "--live-mode", "saccade", "--live-zoom", "auto"]),
        amc_core::Zoom::Auto
    );
}

#[test]
fn live_readout_is_a_number_and_auto_is_refused() {
    let readout = |argv: &[&str]| live_params(argv).unwrap().shutter.readout_ms;
    assert_eq!(readout(&["serve"]), 0.0);
    assert_eq!(readout(&["serve", "--live-readout-ms", "16.5"]), 16.5);
    for (value, needle) in [("auto", "whole clip"), ("200", "0..=100"), ("x", "0..=100")] {
        let e = live_params(&["serve", "--live-readout-ms", value]).unwrap_err();
        assert!(
            e.contains("--live-readout-ms") && e.contains(needle),
            "{value}: {e}"
        );
    }
}

#[test]
fn synth_defaults_and_lists() {
    let Command::Synth(a) = parse(&["synth", "p.jpg", "-o", "out"]).unwrap().command else {
        panic!("not synth")
    };
    let c = a.config();
    assert_eq!(
        c,
        amc_eval::synth::SynthConfig::new("p.jpg".into(), "out".into())
    );
    let Command::Synth(a) = parse(&[
        "synth",
        "p.jpg",
        "-o",
        "out",
        "--fisheye",
        "-0.01,0.002,0,0",
        "--pan-dps",
        "-5",
        "--shake-band",
        "5, 9",
    ])
    .unwrap()
    .command
    else {
        panic!("not synth")
    };
    assert_eq!(a.fisheye, Some([-0.01, 0.002, 0.0, 0.0]));
    assert_eq!((a.pan_dps, a.shake_band), (-5.0, (5.0, 9.0)));
    assert!(parse(&["synth", "p.jpg"]).is_err());
    assert!(parse(&["synth", "p.jpg", "-o", "o", "--shake-band", "12"]).is_err());
    assert!(parse(&["synth", "p.jpg", "-o", "o", "--fisheye", "1,2,x,4"]).is_err());
}

#[test]
fn stabilizer_flags_come_from_the_core_table() {
    let Command::Stabilize(a) = parse(&[
        "stabilize",
        "in.mp4",
        "-o",
        "out.mp4",
        "--n-avg",
        "4",
        "--rate-a",
        "0.5",
        "--mode",
        "saccade",
        "--fov",
        "90",
    ])
    .unwrap()
    .command
    else {
        panic!("not stabilize")
    };
    let o = a.run.stabilizer.options(Mode::Stabilize, None).unwrap();
    assert_eq!(o.params.render.n_avg, 4);
    assert_eq!(o.params.view.rate_a, 0.5);
    assert_eq!(o.params.view.mode, Mode::Saccade);
    assert_eq!(o.lens, LensSpec::Fov(90.0));
    // Every option of the table is a flag.
    let cmd = <Cli as clap::CommandFactory>::command();
    let stabilize = cmd.find_subcommand("stabilize").unwrap();
    for o in amc_core::options::OPTIONS {
        assert!(
            stabilize
                .get_arguments()
                .any(|a| a.get_long() == Some(o.flag)),
            "--{} missing",
            o.flag
        );
    }
    // A lens file and a field of view exclude each other; ranges are the core's.
    assert!(parse(&[
        "stabilize",
        "i",
        "-o",
        "o",
        "--lens",
        "l.json",
        "--fov",
        "90"
    ])
    .is_err());
    let Command::Stabilize(a) = parse(&["stabilize", "i", "-o", "o", "--n-avg", "0"])
        .unwrap()
        .command
    else {
        panic!("not stabilize")
    };
    let e = a.run.stabilizer.options(Mode::Stabilize, None).unwrap_err();
    assert!(
        e.to_string().contains("n_avg") && e.to_string().contains("1..=64"),
        "{e}"
    );
}
