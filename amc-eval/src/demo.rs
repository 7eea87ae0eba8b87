//! `amc demo`: the quick start. Films a shaky clip from a panorama (the shared
//! Jordan Pond panorama when present, else a built-in procedural scene),
//! stabilizes it, and says where everything is and how accurate it was.

use crate::gt::{self, GtError};
use crate::synth::{self, SynthConfig, SynthError};
use amc_core::so3::{self, Tangent};
use amc_core::view::Mode;
use amc_core::{Frame, PixelFormat};
use amc_engine::{self as engine, RunConfig, RunError};
use amc_video::{self as video, InputOptions, OutputSpec};
use rand::{rngs::SmallRng, Rng, SeedableRng};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What the demo films.
#[derive(Clone, Debug, PartialEq)]
pub struct DemoConfig {
    /// Folder for the demo's files.
    pub output: PathBuf,
    /// Equirectangular panorama to film (default: the shared Jordan Pond
    /// panorama if present, else a built-in procedural scene).
    pub panorama: Option<PathBuf>,
    /// RMS shake, deg/s.
    pub shake_dps: f64,
    /// Clip length, seconds.
    pub seconds: f64,
}

/// Why the demo stopped.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// Rendering the shaky clip failed.
    #[error(transparent)]
    Synth(#[from] SynthError),
    /// Stabilizing failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// Encoding the shaky clip failed.
    #[error(transparent)]
    Video(#[from] amc_video::VideoError),
    /// The clip's ground truth could not be read back.
    #[error(transparent)]
    Gt(#[from] GtError),
    /// A file of the demo's folder could not be written or removed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The procedural panorama could not be written, or the lens read back.
    #[error("{}: {detail}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What failed.
        detail: String,
    },
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> DemoError + '_ {
    move |source| DemoError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Where the shared panorama lives relative to the repository root.
const SHARED_PANO: &str = "../shared/data/pano/pannellum_examplepano.jpg";

/// A 2048x1024 equirectangular scene of random shapes over a textured ground
/// and sky: enough texture at every scale for a rotation tracker.
fn procedural_panorama(path: &Path) -> Result<(), DemoError> {
    let (w, h) = (2048u32, 1024u32);
    let mut rng = SmallRng::seed_from_u64(7);
    let mut img = image::RgbImage::new(w, h);
    for (x, y, p) in img.enumerate_pixels_mut() {
        let sky = y < h / 2;
        let n: u8 = rng.gen_range(0..24);
        let base = if sky { [110, 150, 200] } else { [90, 110, 60] };
        let stripe = (((x / 37) + (y / 53)) % 2) as u8 * 12;
        *p = image::Rgb([base[0] + n + stripe, base[1] + n, base[2] + n / 2]);
    }
    for _ in 0..900 {
        let (cx, cy) = (
            rng.gen_range(0..w) as i64,
            rng.gen_range(h / 8..7 * h / 8) as i64,
        );
        let r = rng.gen_range(4..40i64);
        let c = image::Rgb([rng.gen(), rng.gen(), rng.gen()]);
        let square = rng.gen_bool(0.5);
        for dy in -r..=r {
            for dx in -r..=r {
                if square || dx * dx + dy * dy <= r * r {
                    let x = (cx + dx).rem_euclid(w as i64) as u32;
                    let y = (cy + dy).clamp(0, h as i64 - 1) as u32;
                    img.put_pixel(x, y, c);
                }
            }
        }
    }
    img.save(path).map_err(|e| DemoError::File {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })
}

fn encode_dir(frames: &Path, out: &Path, fps: f64) -> Result<(), DemoError> {
    let mut src = video::open_input(
        frames,
        &InputOptions {
            fps_override: Some(fps),
            ..Default::default()
        },
    )?;
    let info = src.info().clone();
    let mut sink = video::create_output(out, &OutputSpec::new(info.width, info.height, fps))?;
    let mut f = Frame::new(info.width, info.height, PixelFormat::Rgb8);
    while let Some(t) = src.next_frame(&mut f)? {
        sink.write_frame(&f.as_ref(), t)?;
    }
    sink.finish()?;
    Ok(())
}

/// Runs the demo; `say` receives a line for each step. Returns the report:
/// where the results are and how accurate the tracking was.
pub fn run(args: &DemoConfig, say: &dyn Fn(&str)) -> Result<String, DemoError> {
    // Without ffmpeg the demo still runs: frames are PNG (read natively) and
    // results are written as .y4m by our own writer.
    let ext = match video::ffmpeg_available() {
        Ok(()) => "mp4",
        Err(e) => {
            say(&format!("note: {e}; writing .y4m files instead of .mp4"));
            "y4m"
        }
    };
    let out = &args.output;
    std::fs::create_dir_all(out).map_err(io_error(out))?;
    let pano: PathBuf = match &args.panorama {
        Some(p) => p.clone(),
        None if Path::new(SHARED_PANO).exists() => PathBuf::from(SHARED_PANO),
        None => {
            let p = out.join("procedural-panorama.png");
            procedural_panorama(&p)?;
            p
        }
    };
    let frames = out.join("shaky-frames");
    if frames.exists() {
        std::fs::remove_dir_all(&frames).map_err(io_error(&frames))?;
    }
    for name in ["shaky", "stabilized", "saccade"] {
        for ext in ["mp4", "y4m"] {
            let p = out.join(format!("{name}.{ext}"));
            if p.exists() {
                std::fs::remove_file(&p).map_err(io_error(&p))?;
            }
        }
    }
    let fps = 60.0;
    say(&format!(
        "rendering a {:.0} s shaky clip ({} deg/s RMS, 12-20 Hz) from {}",
        args.seconds,
        args.shake_dps,
        pano.display()
    ));
    synth::run(
        &SynthConfig {
            width: 640,
            height: 360,
            fps,
            seconds: args.seconds,
            shake_dps: args.shake_dps,
            seed: 1,
            pan_dps: 10.0,
            ..SynthConfig::new(pano, frames.clone())
        },
        &|_, _| {},
    )?;
    let shaky = out.join(format!("shaky.{ext}"));
    encode_dir(&frames, &shaky, fps)?;

    let lens_path = frames.join("lens.json");
    let lens_text = std::fs::read_to_string(&lens_path).map_err(io_error(&lens_path))?;
    let lens = amc_core::lens::parse_lens(&lens_text).map_err(|e| DemoError::File {
        path: lens_path.clone(),
        detail: e.to_string(),
    })?;
    let gt_rot = gt::read_orientations(&frames.join("gt.csv"))?;
    let mut lines = Vec::new();
    for (mode, name) in [(Mode::Stabilize, "stabilized"), (Mode::Saccade, "saccade")] {
        let params = amc_core::StabilizerOptions::with_mode(mode).params;
        let output = out.join(format!("{name}.{ext}"));
        let telemetry = out.join(format!("{name}-telemetry.csv"));
        say(&format!(
            "stabilizing in {mode} mode into {}",
            output.display()
        ));
        let run = engine::run(&RunConfig {
            input: &frames,
            output: Some(&output),
            params,
            lens: lens.clone(),
            telemetry: Some(&telemetry),
            also_writes: &[],
            fps: Some(fps),
            timeout: Duration::from_secs(120),
            crf: None,
            preset: None,
            keep_per_frame: true,
            measure: true,
            control: None,
            progress: None,
            gyro: None,
            refit_lens: false,
            measure_readout: None,
            threads: engine::default_threads(),
        })?;
        let est: Vec<_> = run
            .per_frame
            .iter()
            .map(|r| so3::exp(&Tangent::from(r.telemetry.r_est)))
            .collect();
        let g = gt::compare(&gt_rot, &est);
        lines.push(format!(
            "  {:<11} {}  ({} frames at {:.0} frames/s; normal flow {:.3} px, valid {:.1}%)",
            name,
            output.display(),
            run.frames,
            run.frames_per_second,
            run.metrics.as_ref().map_or(0.0, |m| m.rms_normal_flow),
            100.0 * run.metrics.as_ref().map_or(0.0, |m| m.valid_fraction)
        ));
        if mode == Mode::Stabilize {
            lines.push(format!(
                "  tracking vs ground truth: median per-frame error {:.4} deg, orientation error after {:.0} s {:.3} deg",
                g.median_frame_error_deg, args.seconds, g.final_orientation_error_deg
            ));
        }
    }
    let mut report = format!("demo done:\n  shaky input {}", shaky.display());
    for l in lines {
        report += "\n";
        report += &l;
    }
    Ok(report)
}
