//! `amc synth`: renders a shaky synthetic clip from an equirectangular panorama,
//! with its exact ground-truth orientations.
//!
//! Output directory layout:
//! * `frame-000000.png`, `frame-000001.png`, ...: RGB8 frames.
//! * `gt.csv`: `frame,t,rx,ry,rz`, one row per frame: `t = frame / fps` in
//!   seconds and `(rx, ry, rz)` the rotation vector (axis times angle, radians)
//!   of `R_{0,j}`, which maps camera-`j` vectors into camera-0 (world)
//!   coordinates (camera x right, y down, z forward; `R_{0,0} = I`). With a
//!   rolling shutter, row `v` of frame `j` (`H` rows) is exposed at
//!   `t + readout * (v / H - 1/2)` (`amc_core::shutter::row_fraction`); the
//!   ground truth is the orientation at time `t`, the MID-readout pose, as the
//!   stabilizer's telemetry reports it.
//! * `lens.json`: the camera model (`amc_core::lens::LensFile::to_project_json`),
//!   with `readout_ms` when the clip has a rolling shutter.
//!
//! The clip is rendered into a hidden temporary sibling directory that is
//! renamed to the output at the end, so a failure leaves nothing behind.

use amc_core::camera::CameraModel;
use amc_core::image::{Frame, FrameRef, PixelFormat};
use amc_synth::{downsample_pano, pano_downsample_factor, EquirectRenderer, Shake, ShakeParams};
use amc_video::AtomicDir;
use amc_video::VideoError;
use std::fs;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use thiserror::Error;

/// Render a shaky synthetic clip (PNG frames, gt.csv, lens.json) from an
/// equirectangular panorama.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthConfig {
    /// Equirectangular (2:1, full-sphere) panorama, PNG or JPEG.
    pub panorama: PathBuf,

    /// Output directory (must not exist, or be empty).
    pub output: PathBuf,

    /// Horizontal field of view, degrees (of the fisheye with --fisheye).
    pub fov: f64,

    /// Render through a Kannala-Brandt (OpenCV fisheye) lens with these
    /// coefficients instead of a pinhole.
    pub fisheye: Option<[f64; 4]>,

    /// Frame width, pixels.
    pub width: usize,

    /// Frame height, pixels.
    pub height: usize,

    /// Frames per second.
    pub fps: f64,

    /// Clip length, seconds.
    pub seconds: f64,

    /// RMS angular speed of the shake, deg/s.
    pub shake_dps: f64,

    /// Frequency band of the shake, Hz.
    pub shake_band: (f64, f64),

    /// Seed of the shake trajectory.
    pub seed: u64,

    /// Constant yaw pan, deg/s (positive turns right).
    pub pan_dps: f64,

    /// Rolling-shutter readout time (first to last row), ms; 0 = global
    /// shutter. gt.csv holds the mid-readout orientation; lens.json states
    /// the readout (`readout_ms`).
    pub rolling_shutter_ms: f64,

    /// Anti-aliasing: N x N rays per output pixel.
    pub supersample: usize,

    /// A gyro log of the clip's motion (`gyro.gcsv`), recorded as this says.
    pub gyro: Option<crate::synth_gyro::GyroLogConfig>,
}

/// Why a clip could not be rendered.
#[derive(Debug, Error)]
pub enum SynthError {
    /// A setting outside its range; `detail` names the flag, the value and the range.
    #[error("{detail}")]
    Invalid {
        /// The setting (its CLI flag without dashes).
        option: &'static str,
        /// The value, what is allowed, and why.
        detail: String,
    },
    /// The output location cannot be used.
    #[error("{}: {detail}", path.display())]
    Output {
        /// The output directory.
        path: PathBuf,
        /// What is wrong with it.
        detail: String,
    },
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The panorama cannot be decoded, or a frame cannot be encoded.
    #[error("{}: {detail}", path.display())]
    Image {
        /// The image.
        path: PathBuf,
        /// What failed.
        detail: String,
    },
    /// The core refused the camera or the shake.
    #[error(transparent)]
    Core(#[from] amc_core::AmcError),
    /// Writing an output file failed.
    #[error(transparent)]
    Video(#[from] VideoError),
}

impl SynthError {
    fn io(path: &Path, source: std::io::Error) -> Self {
        SynthError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

fn check(ok: bool, option: &'static str, msg: impl FnOnce() -> String) -> Result<(), SynthError> {
    if ok {
        Ok(())
    } else {
        Err(SynthError::Invalid {
            option,
            detail: msg(),
        })
    }
}

/// Validated settings derived from the arguments.
struct Plan {
    camera: CameraModel,
    frames: usize,
    readout_s: f64,
    shake: ShakeParams,
}

fn plan(args: &SynthConfig) -> Result<Plan, SynthError> {
    check((2..=4096).contains(&args.width), "width", || {
        format!("--width must be 2 to 4096 pixels, got {}", args.width)
    })?;
    check((2..=4096).contains(&args.height), "height", || {
        format!("--height must be 2 to 4096 pixels, got {}", args.height)
    })?;
    check(
        args.fps.is_finite() && args.fps > 0.0 && args.fps <= 10_000.0,
        "fps",
        || format!("--fps must be in (0, 10000], got {}", args.fps),
    )?;
    check(
        args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 36_000.0,
        "seconds",
        || format!("--seconds must be in (0, 36000], got {}", args.seconds),
    )?;
    let frames = (args.seconds * args.fps).round();
    check((1.0..=1_000_000.0).contains(&frames), "seconds", || {
        format!(
            "--seconds {} at --fps {} gives {frames} frames; allowed: 1 to 1000000",
            args.seconds, args.fps
        )
    })?;
    check(
        (1..=EquirectRenderer::MAX_SUPERSAMPLE).contains(&args.supersample),
        "supersample",
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
        "shake-dps",
        || {
            format!(
                "--shake-dps must be 0 to 2000 deg/s, got {}",
                args.shake_dps
            )
        },
    )?;
    let (lo, hi) = args.shake_band;
    check(lo > 0.0 && lo < hi && hi <= 1000.0, "shake-band", || {
        format!("--shake-band must be LO,HI with 0 < LO < HI <= 1000 Hz, got {lo},{hi}")
    })?;
    check(
        args.pan_dps.is_finite() && (-720.0..=720.0).contains(&args.pan_dps),
        "pan-dps",
        || format!("--pan-dps must be -720 to 720 deg/s, got {}", args.pan_dps),
    )?;
    // A readout longer than the frame period overlaps the next frame's (no
    // sensor reads that way, but a test may ask for it: the tracker and the
    // gyro's rows take it as it is).
    check(
        args.rolling_shutter_ms.is_finite()
            && args.rolling_shutter_ms >= 0.0
            && args.rolling_shutter_ms <= amc_core::shutter::MAX_READOUT_MS,
        "rolling-shutter-ms",
        || {
            format!(
                "--rolling-shutter-ms must be 0 to {} ms, got {}",
                amc_core::shutter::MAX_READOUT_MS,
                args.rolling_shutter_ms
            )
        },
    )?;
    let camera = match args.fisheye {
        None => {
            check(
                args.fov.is_finite() && args.fov >= 1.0 && args.fov <= 170.0,
                "fov",
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
                "fov",
                || {
                    format!(
                        "--fov must be 1 to 270 degrees for a fisheye camera, got {}",
                        args.fov
                    )
                },
            )?;
            check(
                k.iter().all(|v| v.is_finite() && v.abs() <= 10.0),
                "fisheye",
                || format!("--fisheye coefficients must be finite and within [-10, 10], got {k:?}"),
            )?;
            CameraModel::fisheye_hfov(args.width, args.height, args.fov, k)
                .map_err(amc_core::AmcError::from)?
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
fn check_output(output: &Path) -> Result<PathBuf, SynthError> {
    match fs::metadata(output) {
        Ok(meta) => {
            if !meta.is_dir() {
                return Err(SynthError::Output {
                    path: output.to_path_buf(),
                    detail: "exists and is not a directory".into(),
                });
            }
            let mut entries = fs::read_dir(output).map_err(|e| SynthError::io(output, e))?;
            if entries.next().is_some() {
                return Err(SynthError::Output {
                    path: output.to_path_buf(),
                    detail: "the output directory is not empty; choose a new directory or empty it"
                        .into(),
                });
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(SynthError::io(output, e)),
    }
    let parent = match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !parent.is_dir() {
        return Err(SynthError::Output {
            path: output.to_path_buf(),
            detail: format!("its parent directory {} does not exist", parent.display()),
        });
    }
    Ok(parent)
}

fn load_panorama(path: &Path) -> Result<Frame, SynthError> {
    let img = image::ImageReader::open(path)
        .map_err(|e| SynthError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| SynthError::io(path, e))?
        .decode()
        .map_err(|e| SynthError::Image {
            path: path.to_path_buf(),
            detail: e.to_string(),
        })?
        .into_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w < 4 || h < 2 || (w as f64 / h as f64 - 2.0).abs() > 0.02 {
        return Err(SynthError::Image {
            path: path.to_path_buf(),
            detail: format!(
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

fn write_png(path: &Path, frame: &Frame) -> Result<(), SynthError> {
    use image::ImageEncoder;
    let file = fs::File::create(path).map_err(|e| SynthError::io(path, e))?;
    let mut w = BufWriter::new(file);
    image::codecs::png::PngEncoder::new(&mut w)
        .write_image(
            &frame.data,
            frame.width as u32,
            frame.height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| SynthError::Image {
            path: path.to_path_buf(),
            detail: e.to_string(),
        })?;
    w.flush().map_err(|e| SynthError::io(path, e))
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
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(), SynthError> {
    let n = plan.frames;
    let done = AtomicUsize::new(0);
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, 16)
        .min(n);
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let first_error: Mutex<Option<SynthError>> = Mutex::new(None);
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
                            // s: the row's readout fraction, 0 at mid-readout (time t).
                            &|s| shake.orientation_at(t + readout * s),
                            &mut out,
                        )
                        .map_err(SynthError::from)
                        .and_then(|()| write_png(&dir.join(frame_name(j)), &out));
                    if let Err(e) = result {
                        failed.store(true, Ordering::Relaxed);
                        let mut slot = first_error.lock().unwrap_or_else(|p| p.into_inner());
                        slot.get_or_insert(e);
                        break;
                    }
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, n);
                }
            });
        }
    });
    match first_error.into_inner().unwrap_or_else(|p| p.into_inner()) {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// The `gt.csv` text: `frame,t,rx,ry,rz` (rotation vector of `R_{0,j}` at
/// `t = frame / fps`, the mid-readout time with a rolling shutter).
fn ground_truth_csv(shake: &Shake, frames: usize, fps: f64) -> String {
    let times: Vec<f64> = (0..frames).map(|j| j as f64 / fps).collect();
    let rots: Vec<_> = times.iter().map(|&t| shake.orientation_at(t)).collect();
    crate::gt::orientations_csv(&times, &rots)
}

/// Renders the clip described by `args` into `args.output` (a new or empty
/// directory): frames, `gt.csv`, `lens.json` and `meta.json` (`{"fps": ...}`,
/// read back by image-folder inputs so the clip plays at its own rate).
/// `progress(done, total)` is called after each frame. Returns a one-line
/// description of what was written.
pub fn run(
    args: &SynthConfig,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<String, SynthError> {
    let plan = plan(args)?;
    if let Some(g) = &args.gyro {
        g.validate().map_err(|e| SynthError::Invalid {
            option: e.option,
            detail: e.detail,
        })?;
    }
    check_output(&args.output)?;
    let pano_full = load_panorama(&args.panorama)?;
    let factor = pano_downsample_factor(pano_full.width, &plan.camera);
    let pano = downsample_pano(&pano_full.as_ref(), factor);
    drop(pano_full);
    let renderer = EquirectRenderer::new(&plan.camera, args.supersample)?;
    let shake = Shake::new(&plan.shake)?;

    let out = AtomicDir::create(&args.output)?;
    let dir = out.partial_path().to_path_buf();
    render_frames(
        &dir,
        &pano.as_ref(),
        &renderer,
        &shake,
        &plan,
        args.fps,
        progress,
    )?;
    let write = |name: &str, text: String| {
        let path = dir.join(name);
        fs::write(&path, text).map_err(|e| SynthError::io(&path, e))
    };
    write("gt.csv", ground_truth_csv(&shake, plan.frames, args.fps))?;
    let lens = amc_core::lens::LensFile {
        camera: plan.camera.clone(),
        readout_ms: (plan.readout_s > 0.0).then_some(args.rolling_shutter_ms),
    };
    write("lens.json", lens.to_project_json())?;
    write(
        amc_video::FOLDER_META,
        format!("{{\"fps\": {}}}\n", args.fps),
    )?;
    if let Some(g) = &args.gyro {
        write(crate::synth_gyro::GYRO_LOG, g.gcsv(&shake, args.seconds))?;
    }
    out.persist()?;

    let lens = match args.fisheye {
        Some(_) => "fisheye",
        None => "pinhole",
    };
    let rs = if plan.readout_s > 0.0 {
        format!(", rolling shutter {} ms", args.rolling_shutter_ms)
    } else {
        String::new()
    };
    let gyro = if args.gyro.is_some() {
        ", gyro.gcsv"
    } else {
        ""
    };
    Ok(format!(
        "wrote {} frames of {}x{} ({lens}, {} deg hfov, {} fps, shake {} deg/s in {}-{} Hz{rs}) with gt.csv, lens.json{gyro} and meta.json to {}",
        plan.frames,
        args.width,
        args.height,
        args.fov,
        args.fps,
        args.shake_dps,
        args.shake_band.0,
        args.shake_band.1,
        args.output.display()
    ))
}

impl SynthConfig {
    /// The defaults of `amc synth PANORAMA -o OUTPUT`: 320x180 pinhole 90 deg,
    /// 60 fps, 10 s, 100 deg/s RMS shake at 12-20 Hz.
    pub fn new(panorama: PathBuf, output: PathBuf) -> Self {
        Self {
            panorama,
            output,
            fov: 90.0,
            fisheye: None,
            width: 320,
            height: 180,
            fps: 60.0,
            seconds: 10.0,
            shake_dps: 100.0,
            shake_band: (12.0, 20.0),
            seed: 0,
            pan_dps: 0.0,
            rolling_shutter_ms: 0.0,
            supersample: 2,
            gyro: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_progress(_: usize, _: usize) {}

    fn write_test_pano(path: &Path) {
        let (w, h) = (256u32, 128u32);
        let img = image::RgbImage::from_fn(w, h, |u, v| {
            image::Rgb([u as u8, (2 * v) as u8, ((u * 7 + v * 3) % 256) as u8])
        });
        img.save(path).unwrap();
    }

    #[test]
    fn bad_values_are_refused() {
        let base = SynthConfig::new("p.jpg".into(), "out".into());
        let cases: Vec<(&str, SynthConfig)> = vec![
            (
                "width",
                SynthConfig {
                    width: 1,
                    ..base.clone()
                },
            ),
            (
                "fps",
                SynthConfig {
                    fps: 0.0,
                    ..base.clone()
                },
            ),
            (
                "seconds",
                SynthConfig {
                    seconds: -1.0,
                    ..base.clone()
                },
            ),
            (
                "shake-dps",
                SynthConfig {
                    shake_dps: 3000.0,
                    ..base.clone()
                },
            ),
            (
                "shake-band",
                SynthConfig {
                    shake_band: (20.0, 12.0),
                    ..base.clone()
                },
            ),
            (
                "shake-band",
                SynthConfig {
                    shake_band: (-1.0, 12.0),
                    ..base.clone()
                },
            ),
            (
                "shake-dps",
                SynthConfig {
                    shake_dps: -1.0,
                    ..base.clone()
                },
            ),
            (
                "pan-dps",
                SynthConfig {
                    pan_dps: -1000.0,
                    ..base.clone()
                },
            ),
            (
                "supersample",
                SynthConfig {
                    supersample: 0,
                    ..base.clone()
                },
            ),
            (
                "fov",
                SynthConfig {
                    fov: 179.0,
                    ..base.clone()
                },
            ),
            (
                "rolling-shutter-ms",
                SynthConfig {
                    rolling_shutter_ms: 120.0,
                    ..base.clone()
                },
            ),
        ];
        for (option, cfg) in cases {
            match plan(&cfg) {
                Err(SynthError::Invalid { option: o, .. }) => assert_eq!(o, option),
                other => panic!("{option}: {:?}", other.err()),
            }
        }
        let folded = SynthConfig {
            fisheye: Some([0.0, 0.0, 0.0, -10.0]),
            fov: 200.0,
            ..base
        };
        assert!(plan(&folded).is_err());
    }

    #[test]
    fn renders_a_small_clip_and_refuses_non_empty_output() {
        let tmp = tempfile::tempdir().unwrap();
        let pano = tmp.path().join("pano.png");
        write_test_pano(&pano);
        let out = tmp.path().join("clip");
        let a = SynthConfig {
            width: 32,
            height: 18,
            seconds: 0.1,
            rolling_shutter_ms: 5.0,
            ..SynthConfig::new(pano.clone(), out.clone())
        };
        run(&a, &no_progress).unwrap();
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
        let lens =
            amc_core::lens::parse_lens_file(&fs::read_to_string(out.join("lens.json")).unwrap())
                .unwrap();
        assert_eq!(lens.readout_ms, Some(5.0));
        let img = image::open(out.join(frame_name(5))).unwrap().into_rgb8();
        assert_eq!(img.dimensions(), (32, 18));
        assert!(!out.join(frame_name(6)).exists());
        // Only our outputs, and no temporary directory left beside it.
        assert_eq!(fs::read_dir(&out).unwrap().count(), 9);
        assert_eq!(fs::read_dir(tmp.path()).unwrap().count(), 2);
        // A second run into the same (now non-empty) directory is refused.
        assert!(matches!(
            run(&a, &no_progress),
            Err(SynthError::Output { .. })
        ));
        // A missing panorama fails and leaves nothing behind.
        let out2 = tmp.path().join("clip2");
        let b = SynthConfig {
            panorama: tmp.path().join("missing.png"),
            output: out2.clone(),
            ..a
        };
        assert!(run(&b, &no_progress).is_err());
        assert!(!out2.exists());
        assert_eq!(fs::read_dir(tmp.path()).unwrap().count(), 2);
    }
}
