//! `amc synth`: renders a shaky synthetic clip from an equirectangular panorama,
//! with its exact ground-truth orientations.
//!
//! Output directory layout:
//! * `frame-000000.png`, `frame-000001.png`, ...: RGB8 frames.
//! * `gt.csv`: `frame,t,rx,ry,rz`, one row per frame: `t = frame / fps` in
//!   seconds and `(rx, ry, rz)` the rotation vector (axis times angle, radians)
//!   of `R_{0,j}`, which maps camera-`j` vectors into camera-0 (world)
//!   coordinates (camera x right, y down, z forward; `R_{0,0} = I`). With a
//!   rolling shutter, row `v` of frame `j` is exposed at
//!   `t + readout * v / (height - 1)`; the ground truth is the orientation at
//!   the FIRST row's exposure, time `t`.
//! * `lens.json`: the camera model (`amc_core::lens::to_project_json`).
//!
//! The clip is rendered into a hidden temporary sibling directory that is
//! renamed to the output at the end, so a failure leaves nothing behind.

use crate::error::CliError;
use amc_core::camera::{CameraModel, Distortion};
use amc_core::image::{Frame, FrameRef, PixelFormat};
use amc_core::so3;
use amc_core::synth::{
    downsample_pano, pano_downsample_factor, EquirectRenderer, Shake, ShakeParams,
};
use std::fs;
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;

/// Render a shaky synthetic clip (PNG frames, gt.csv, lens.json) from an
/// equirectangular panorama.
#[derive(clap::Args, Debug, Clone)]
pub struct SynthArgs {
    /// Equirectangular (2:1, full-sphere) panorama, PNG or JPEG.
    pub panorama: PathBuf,

    /// Output directory (must not exist, or be empty).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,

    /// Horizontal field of view, degrees (of the fisheye with --fisheye).
    #[arg(
        long,
        default_value_t = 90.0,
        value_name = "DEG",
        allow_negative_numbers = true
    )]
    pub fov: f64,

    /// Render through a Kannala-Brandt (OpenCV fisheye) lens with these
    /// coefficients instead of a pinhole.
    #[arg(long, value_name = "K1,K2,K3,K4", value_parser = parse_k4, allow_hyphen_values = true)]
    pub fisheye: Option<[f64; 4]>,

    /// Frame width, pixels.
    #[arg(long, default_value_t = 320)]
    pub width: usize,

    /// Frame height, pixels.
    #[arg(long, default_value_t = 180)]
    pub height: usize,

    /// Frames per second.
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true)]
    pub fps: f64,

    /// Clip length, seconds.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub seconds: f64,

    /// RMS angular speed of the shake, deg/s.
    #[arg(
        long,
        default_value_t = 100.0,
        value_name = "DEG_PER_S",
        allow_negative_numbers = true
    )]
    pub shake_dps: f64,

    /// Frequency band of the shake, Hz.
    #[arg(long, default_value = "12,20", value_name = "LO,HI", value_parser = parse_band, allow_hyphen_values = true)]
    pub shake_band: (f64, f64),

    /// Seed of the shake trajectory.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,

    /// Constant yaw pan, deg/s (positive turns right).
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "DEG_PER_S",
        allow_negative_numbers = true
    )]
    pub pan_dps: f64,

    /// Rolling-shutter readout time (first to last row), ms; 0 = global
    /// shutter. gt.csv holds the orientation at the first row's exposure.
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "MS",
        allow_negative_numbers = true
    )]
    pub rolling_shutter_ms: f64,

    /// Anti-aliasing: N x N rays per output pixel.
    #[arg(long, default_value_t = 2, value_name = "N")]
    pub supersample: usize,
}

fn parse_floats<const N: usize>(s: &str, what: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} comma-separated numbers ({what}), got '{s}'"
        ));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("'{p}' is not a finite number ({what})"))?;
    }
    Ok(out)
}

fn parse_band(s: &str) -> Result<(f64, f64), String> {
    let [lo, hi] = parse_floats::<2>(s, "LO,HI in Hz")?;
    Ok((lo, hi))
}

fn parse_k4(s: &str) -> Result<[f64; 4], String> {
    parse_floats::<4>(s, "K1,K2,K3,K4")
}

/// Kannala-Brandt distortion `theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)`.
fn kb_theta_d(k: &[f64; 4], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))
}

/// A centred Kannala-Brandt camera whose image edge (`width / 2` from the
/// centre) sees `hfov / 2` off-axis: `fx = (width / 2) / theta_d(hfov / 2)`.
fn fisheye_camera(
    width: usize,
    height: usize,
    hfov_deg: f64,
    k: [f64; 4],
) -> Result<CameraModel, CliError> {
    let half = hfov_deg.to_radians() / 2.0;
    // theta_d must increase monotonically up to the edge, or the lens folds.
    let steps = 1000;
    let mut prev = 0.0;
    for i in 1..=steps {
        let td = kb_theta_d(&k, half * i as f64 / steps as f64);
        if td.is_nan() || td <= prev {
            return Err(CliError::Usage(format!(
                "--fisheye {},{},{},{}: the lens mapping is not increasing up to half the --fov ({} deg); \
                 use smaller coefficients or a smaller --fov",
                k[0], k[1], k[2], k[3], hfov_deg / 2.0
            )));
        }
        prev = td;
    }
    let fx = (width as f64 / 2.0) / prev;
    Ok(CameraModel {
        width,
        height,
        fx,
        fy: fx,
        cx: (width as f64 - 1.0) / 2.0,
        cy: (height as f64 - 1.0) / 2.0,
        skew: 0.0,
        distortion: Distortion::Fisheye {
            k1: k[0],
            k2: k[1],
            k3: k[2],
            k4: k[3],
        },
    })
}

fn usage(msg: String) -> CliError {
    CliError::Usage(msg)
}

fn check(ok: bool, msg: impl FnOnce() -> String) -> Result<(), CliError> {
    if ok {
        Ok(())
    } else {
        Err(usage(msg()))
    }
}

/// Validated settings derived from the arguments.
struct Plan {
    camera: CameraModel,
    frames: usize,
    readout_s: f64,
    shake: ShakeParams,
}

fn plan(args: &SynthArgs) -> Result<Plan, CliError> {
    check((2..=4096).contains(&args.width), || {
        format!("--width must be 2 to 4096 pixels, got {}", args.width)
    })?;
    check((2..=4096).contains(&args.height), || {
        format!("--height must be 2 to 4096 pixels, got {}", args.height)
    })?;
    check(
        args.fps.is_finite() && args.fps > 0.0 && args.fps <= 10_000.0,
        || format!("--fps must be in (0, 10000], got {}", args.fps),
    )?;
    check(
        args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 36_000.0,
        || format!("--seconds must be in (0, 36000], got {}", args.seconds),
    )?;
    let frames = (args.seconds * args.fps).round();
    check((1.0..=1_000_000.0).contains(&frames), || {
        format!(
            "--seconds {} at --fps {} gives {frames} frames; allowed: 1 to 1000000",
            args.seconds, args.fps
        )
    })?;
    check(
        (1..=EquirectRenderer::MAX_SUPERSAMPLE).contains(&args.supersample),
        || {
            format!(
                "--supersample must be 1 to {}, got {}",
                EquirectRenderer::MAX_SUPERSAMPLE,
                args.supersample
            )
        },
    )?;
    check(
        args.shake_dps.is_finite() && (0.0..=2000.0).contains(&args.shake_dps),
        || {
            format!(
                "--shake-dps must be 0 to 2000 deg/s, got {}",
                args.shake_dps
            )
        },
    )?;
    let (lo, hi) = args.shake_band;
    check(lo > 0.0 && lo < hi && hi <= 1000.0, || {
        format!("--shake-band must be LO,HI with 0 < LO < HI <= 1000 Hz, got {lo},{hi}")
    })?;
    check(
        args.pan_dps.is_finite() && (-720.0..=720.0).contains(&args.pan_dps),
        || format!("--pan-dps must be -720 to 720 deg/s, got {}", args.pan_dps),
    )?;
    let period_ms = 1000.0 / args.fps;
    check(
        args.rolling_shutter_ms.is_finite()
            && args.rolling_shutter_ms >= 0.0
            && args.rolling_shutter_ms <= period_ms + 1e-9,
        || {
            format!(
                "--rolling-shutter-ms must be 0 to the frame period ({period_ms:.3} ms at --fps {}), got {}",
                args.fps, args.rolling_shutter_ms
            )
        },
    )?;
    let camera = match args.fisheye {
        None => {
            check(
                args.fov.is_finite() && args.fov >= 1.0 && args.fov <= 170.0,
                || {
                    format!(
                        "--fov must be 1 to 170 degrees for a pinhole camera, got {}",
                        args.fov
                    )
                },
            )?;
            CameraModel::pinhole_hfov(args.width, args.height, args.fov)
                .map_err(amc_core::AmcError::from)?
        }
        Some(k) => {
            check(
                args.fov.is_finite() && args.fov >= 1.0 && args.fov <= 270.0,
                || {
                    format!(
                        "--fov must be 1 to 270 degrees for a fisheye camera, got {}",
                        args.fov
                    )
                },
            )?;
            check(k.iter().all(|v| v.is_finite() && v.abs() <= 10.0), || {
                format!("--fisheye coefficients must be finite and within [-10, 10], got {k:?}")
            })?;
            fisheye_camera(args.width, args.height, args.fov, k)?
        }
    };
    camera.validate().map_err(amc_core::AmcError::from)?;
    let shake = ShakeParams {
        shake_dps: args.shake_dps,
        band_hz: args.shake_band,
        seed: args.seed,
        pan_dps: args.pan_dps,
    };
    shake.validate()?;
    Ok(Plan {
        camera,
        frames: frames as usize,
        readout_s: args.rolling_shutter_ms / 1000.0,
        shake,
    })
}

/// Checks the output location; returns the directory the temporary sibling goes in.
fn check_output(output: &Path) -> Result<PathBuf, CliError> {
    match fs::metadata(output) {
        Ok(meta) => {
            check(meta.is_dir(), || {
                format!("output {} exists and is not a directory", output.display())
            })?;
            let mut entries = fs::read_dir(output).map_err(|e| CliError::io(output, e))?;
            check(entries.next().is_none(), || {
                format!(
                    "output directory {} is not empty; choose a new directory or empty it",
                    output.display()
                )
            })?;
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(CliError::io(output, e)),
    }
    let parent = match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    check(parent.is_dir(), || {
        format!(
            "the parent of the output directory, {}, does not exist",
            parent.display()
        )
    })?;
    Ok(parent)
}

fn load_panorama(path: &Path) -> Result<Frame, CliError> {
    let img = image::ImageReader::open(path)
        .map_err(|e| CliError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| CliError::io(path, e))?
        .decode()
        .map_err(|e| CliError::Image {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?
        .into_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w < 4 || h < 2 || (w as f64 / h as f64 - 2.0).abs() > 0.02 {
        return Err(CliError::Image {
            path: path.to_path_buf(),
            msg: format!(
                "panorama is {w}x{h}; an equirectangular panorama must be 2:1 (width = 2 x height)"
            ),
        });
    }
    Ok(Frame {
        width: w,
        height: h,
        format: PixelFormat::Rgb8,
        data: img.into_raw(),
    })
}

fn write_png(path: &Path, frame: &Frame) -> Result<(), CliError> {
    use image::ImageEncoder;
    let file = fs::File::create(path).map_err(|e| CliError::io(path, e))?;
    let mut w = BufWriter::new(file);
    image::codecs::png::PngEncoder::new(&mut w)
        .write_image(
            &frame.data,
            frame.width as u32,
            frame.height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| CliError::Image {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
    w.flush().map_err(|e| CliError::io(path, e))
}

/// Frame file name for index `j`.
pub fn frame_name(j: usize) -> String {
    format!("frame-{j:06}.png")
}

/// Renders every frame into `dir`, in parallel over frames.
fn render_frames(
    dir: &Path,
    pano: &FrameRef<'_>,
    renderer: &EquirectRenderer,
    shake: &Shake,
    plan: &Plan,
    fps: f64,
) -> Result<(), CliError> {
    let n = plan.frames;
    let progress = if std::io::stderr().is_terminal() {
        let pb = indicatif::ProgressBar::new(n as u64);
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "rendering {bar:40} {pos}/{len} frames, eta {eta}",
        ) {
            pb.set_style(style);
        }
        pb
    } else {
        indicatif::ProgressBar::hidden()
    };
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, 16)
        .min(n);
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let first_error: Mutex<Option<CliError>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
                let mut out = Frame::new(renderer.width(), renderer.height(), PixelFormat::Rgb8);
                loop {
                    let j = next.fetch_add(1, Ordering::Relaxed);
                    if j >= n || failed.load(Ordering::Relaxed) {
                        break;
                    }
                    let t = j as f64 / fps;
                    let readout = plan.readout_s;
                    let result = renderer
                        .render_rolling_into(
                            pano,
                            &|s| shake.orientation_at(t + readout * s),
                            &mut out,
                        )
                        .map_err(CliError::from)
                        .and_then(|()| write_png(&dir.join(frame_name(j)), &out));
                    if let Err(e) = result {
                        failed.store(true, Ordering::Relaxed);
                        let mut slot = first_error.lock().unwrap_or_else(|p| p.into_inner());
                        slot.get_or_insert(e);
                        break;
                    }
                    progress.inc(1);
                }
            });
        }
    });
    progress.finish_and_clear();
    match first_error.into_inner().unwrap_or_else(|p| p.into_inner()) {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// The `gt.csv` text: `frame,t,rx,ry,rz` (rotation vector of `R_{0,j}` at the
/// first row's exposure time `t = frame / fps`).
fn ground_truth_csv(shake: &Shake, frames: usize, fps: f64) -> String {
    let mut s = String::from("frame,t,rx,ry,rz\n");
    for j in 0..frames {
        let t = j as f64 / fps;
        let r = so3::log(&shake.orientation_at(t));
        s.push_str(&format!("{j},{t},{},{},{}\n", r.x, r.y, r.z));
    }
    s
}

/// Runs `amc synth`.
pub fn run(args: &SynthArgs) -> Result<(), CliError> {
    let plan = plan(args)?;
    let parent = check_output(&args.output)?;
    let pano_full = load_panorama(&args.panorama)?;
    let factor = pano_downsample_factor(pano_full.width, &plan.camera);
    let pano = downsample_pano(&pano_full.as_ref(), factor);
    drop(pano_full);
    let renderer = EquirectRenderer::new(&plan.camera, args.supersample)?;
    let shake = Shake::new(&plan.shake)?;

    let mut builder = tempfile::Builder::new();
    builder.prefix(".amc-synth-");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // Like mkdir: 0777 minus the umask (a temp dir is 0700 by default).
        builder.permissions(fs::Permissions::from_mode(0o777));
    }
    let tmp = builder
        .tempdir_in(&parent)
        .map_err(|e| CliError::io(&parent, e))?;
    let dir = tmp.path().to_path_buf();

    render_frames(&dir, &pano.as_ref(), &renderer, &shake, &plan, args.fps)?;
    let gt_path = dir.join("gt.csv");
    fs::write(&gt_path, ground_truth_csv(&shake, plan.frames, args.fps))
        .map_err(|e| CliError::io(&gt_path, e))?;
    let lens_path = dir.join("lens.json");
    fs::write(&lens_path, amc_core::lens::to_project_json(&plan.camera))
        .map_err(|e| CliError::io(&lens_path, e))?;

    // An existing output directory was checked to be empty; rename needs it gone.
    if args.output.is_dir() {
        fs::remove_dir(&args.output).map_err(|e| CliError::io(&args.output, e))?;
    }
    let kept = tmp.keep();
    if let Err(e) = fs::rename(&kept, &args.output) {
        let _ = fs::remove_dir_all(&kept);
        return Err(CliError::io(&args.output, e));
    }

    let lens = match args.fisheye {
        Some(_) => "fisheye",
        None => "pinhole",
    };
    let rs = if plan.readout_s > 0.0 {
        format!(", rolling shutter {} ms", args.rolling_shutter_ms)
    } else {
        String::new()
    };
    println!(
        "wrote {} frames of {}x{} ({lens}, {} deg hfov, {} fps, shake {} deg/s in {}-{} Hz{rs}) with gt.csv and lens.json to {}",
        plan.frames,
        args.width,
        args.height,
        args.fov,
        args.fps,
        args.shake_dps,
        args.shake_band.0,
        args.shake_band.1,
        args.output.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct Cli {
        #[command(flatten)]
        synth: SynthArgs,
    }

    fn parse(args: &[&str]) -> Result<SynthArgs, clap::Error> {
        Cli::try_parse_from(std::iter::once("synth").chain(args.iter().copied())).map(|c| c.synth)
    }

    fn write_test_pano(path: &Path) {
        let (w, h) = (256u32, 128u32);
        let img = image::RgbImage::from_fn(w, h, |u, v| {
            image::Rgb([u as u8, (2 * v) as u8, ((u * 7 + v * 3) % 256) as u8])
        });
        img.save(path).unwrap();
    }

    #[test]
    fn defaults_and_parsing() {
        let a = parse(&["p.jpg", "-o", "out"]).unwrap();
        assert_eq!((a.width, a.height, a.supersample, a.seed), (320, 180, 2, 0));
        assert_eq!(
            (a.fov, a.fps, a.seconds, a.shake_dps),
            (90.0, 60.0, 10.0, 100.0)
        );
        assert_eq!(a.shake_band, (12.0, 20.0));
        assert!(a.fisheye.is_none());
        let a = parse(&[
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
        .unwrap();
        assert_eq!(a.fisheye, Some([-0.01, 0.002, 0.0, 0.0]));
        assert_eq!((a.pan_dps, a.shake_band), (-5.0, (5.0, 9.0)));
        assert!(parse(&["p.jpg"]).is_err());
        assert!(parse(&["p.jpg", "-o", "o", "--shake-band", "12"]).is_err());
        assert!(parse(&["p.jpg", "-o", "o", "--fisheye", "1,2,x,4"]).is_err());
    }

    #[test]
    fn bad_values_are_usage_errors() {
        for extra in [
            &["--width", "1"][..],
            &["--fps", "0"],
            &["--seconds", "-1"],
            &["--shake-dps", "3000"],
            &["--shake-band", "20,12"],
            &["--shake-band", "-1,12"],
            &["--shake-dps", "-1"],
            &["--pan-dps", "-1000"],
            &["--supersample", "0"],
            &["--fov", "179"],
            &["--rolling-shutter-ms", "20"],
            &["--fisheye", "0,0,0,-10", "--fov", "200"],
        ] {
            let mut v = vec!["p.jpg", "-o", "out"];
            v.extend_from_slice(extra);
            let a = parse(&v).unwrap();
            let e = plan(&a)
                .err()
                .unwrap_or_else(|| panic!("{extra:?} accepted"));
            assert!(matches!(e, CliError::Usage(_)), "{extra:?}: {e}");
        }
    }

    #[test]
    fn renders_a_small_clip_and_refuses_non_empty_output() {
        let tmp = tempfile::tempdir().unwrap();
        let pano = tmp.path().join("pano.png");
        write_test_pano(&pano);
        let out = tmp.path().join("clip");
        let s = |p: &Path| p.to_str().unwrap().to_string();
        let argv = [
            s(&pano),
            "-o".into(),
            s(&out),
            "--width".into(),
            "32".into(),
            "--height".into(),
            "18".into(),
            "--seconds".into(),
            "0.1".into(),
            "--rolling-shutter-ms".into(),
            "5".into(),
        ];
        let a = parse(&argv.iter().map(String::as_str).collect::<Vec<_>>()).unwrap();
        run(&a).unwrap();
        let gt = fs::read_to_string(out.join("gt.csv")).unwrap();
        let lines: Vec<&str> = gt.lines().collect();
        assert_eq!(lines[0], "frame,t,rx,ry,rz");
        assert_eq!(lines.len(), 7);
        let first: Vec<f64> = lines[1].split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!(first.len(), 5);
        assert!(first.iter().all(|v| v.abs() < 1e-12), "{first:?}");
        let last: Vec<f64> = lines[6].split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!((last[0], last[1]), (5.0, 5.0 / 60.0));
        assert!(last[2..].iter().any(|v| v.abs() > 1e-4), "{last:?}");
        assert!(out.join("lens.json").exists());
        let img = image::open(out.join(frame_name(5))).unwrap().into_rgb8();
        assert_eq!(img.dimensions(), (32, 18));
        assert!(!out.join(frame_name(6)).exists());
        // Only our outputs, and no temporary directory left beside it.
        assert_eq!(fs::read_dir(&out).unwrap().count(), 8);
        assert_eq!(fs::read_dir(tmp.path()).unwrap().count(), 2);
        // A second run into the same (now non-empty) directory is refused.
        assert!(matches!(run(&a), Err(CliError::Usage(_))));
        // A missing panorama fails and leaves nothing behind.
        let out2 = tmp.path().join("clip2");
        let b = SynthArgs {
            panorama: tmp.path().join("missing.png"),
            output: out2.clone(),
            ..a
        };
        assert!(run(&b).is_err());
        assert!(!out2.exists());
        assert_eq!(fs::read_dir(tmp.path()).unwrap().count(), 2);
    }
}
