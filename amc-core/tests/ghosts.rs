//! Averaging without ghosts: a disc moves across a static panorama while the camera
//! shakes; the stabilized output is compared with the true frame (the noise-free scene,
//! disc included, rendered through the output camera at the output's view).
//!
//! * Where the disc is or was during the averaging window, the ghost-free average's error
//!   is at most 1.2x that of no averaging (`n_avg 1`): the disc comes from the newest frame.
//!   The plain average's error there is well above it (the ghosts this removes).
//! * On the static scene, the averaging's noise reduction is kept.
//!
//! For RGB frames in both averaging modes (stabilize: every frame re-rendered; saccade: the
//! slots merged), and planar 4:2:0 frames as decoders give them (luma compared).

mod common;

use amc_core::framing::FramingParams;
use amc_core::so3::{self, Rot, Tangent};
use amc_core::{CameraModel, Frame, Mode, PixelFormat, Stabilizer, StabilizerParams, Zoom};
use amc_synth::{downsample_pano, pano_downsample_factor, EquirectRenderer, Shake, ShakeParams};
use common::{hash, panorama};
use nalgebra::{Vector2, Vector3};

const FPS: f64 = 60.0;
const FRAMES: usize = 90;
const SIZE: (usize, usize) = (320, 180);
const HFOV_DEG: f64 = 70.0;
/// The disc: angular radius, and its path (about the camera's y axis, degrees per second,
/// starting `START_DEG` left of the first frame's centre).
const DISC_RADIUS_DEG: f64 = 6.0;
const DISC_SPEED_DPS: f64 = 60.0;
const DISC_START_DEG: f64 = -40.0;
const DISC_RGB: [u8; 3] = [235, 40, 60];
/// Sensor noise of the input: the sum of four uniform variables, standard deviation ~4.6 levels.
const NOISE_LEVELS: f32 = 8.0;

/// Where the disc's centre points at time `t`, in the first camera's frame.
fn disc_centre(t: f64) -> Vector3<f64> {
    let a = (DISC_START_DEG + DISC_SPEED_DPS * t).to_radians();
    Vector3::new(a.sin(), -0.05, a.cos()).normalize()
}

/// Paints the disc at time `t` into `frame`, seen by `cam` with orientation `r` (camera to
/// the first camera's frame); with `noise` also adds sensor noise to every pixel.
fn paint(frame: &mut Frame, cam: &CameraModel, r: &Rot, t: f64, noise: Option<u32>) {
    let centre = disc_centre(t);
    let cos_radius = DISC_RADIUS_DEG.to_radians().cos();
    for v in 0..cam.height {
        for u in 0..cam.width {
            let i = 3 * (v * cam.width + u);
            let inside = cam
                .unproject(&Vector2::new(u as f64, v as f64))
                .is_some_and(|ray| (r * ray.normalize()).dot(&centre) >= cos_radius);
            if inside {
                frame.data[i..i + 3].copy_from_slice(&DISC_RGB);
            }
            if let Some(seed) = noise {
                for c in 0..3 {
                    let n: f32 = (0..4)
                        .map(|k| hash((i + c) as u32, seed, k) - 0.5)
                        .sum::<f32>();
                    let x = frame.data[i + c] as f32 + n * NOISE_LEVELS;
                    frame.data[i + c] = x.round().clamp(0.0, 255.0) as u8;
                }
            }
        }
    }
}

/// RMS errors of one run against the true frames, intensity levels.
#[derive(Debug)]
struct Errors {
    /// Where the disc is or was during the window (and 1 deg around it).
    moving: f64,
    /// Farther than 4 deg from every position of the disc during the window.
    still: f64,
}

/// Renders the clip, stabilizes it with `n_avg` frames and `deghost`, and measures every
/// output from frame 12 on against its true frame.
fn run(mode: Mode, n_avg: usize, deghost: f64, format: PixelFormat) -> Errors {
    let cam = CameraModel::pinhole_hfov(SIZE.0, SIZE.1, HFOV_DEG).unwrap();
    let pano_full = panorama();
    let pano = downsample_pano(
        &pano_full.as_ref(),
        pano_downsample_factor(pano_full.width, &cam),
    );
    let mut params = StabilizerParams::default();
    params.view.mode = mode;
    params.render.n_avg = n_avg;
    params.render.deghost = amc_core::render::DeghostLevel::Levels(deghost);
    params.framing = FramingParams {
        zoom: Zoom::None,
        ..FramingParams::default()
    };
    let out_cam = params.render.output_camera(&cam).unwrap();
    let shake = Shake::new(&ShakeParams {
        shake_dps: 100.0,
        band_hz: (12.0, 20.0),
        seed: 11,
        ..ShakeParams::default()
    })
    .unwrap();
    let world = |t: f64| shake.orientation_at(t);
    let r0 = world(0.0);
    let renderer = EquirectRenderer::new(&cam, 2).unwrap();
    let truth_renderer = EquirectRenderer::new(&out_cam, 2).unwrap();
    let mut stab = Stabilizer::new(&cam, cam.width, cam.height, params).unwrap();

    let cos_moving = (DISC_RADIUS_DEG + 1.0).to_radians().cos();
    let cos_still = (DISC_RADIUS_DEG + 4.0).to_radians().cos();
    let (mut moving, mut still) = ((0.0, 0usize), (0.0, 0usize));
    let mut truth = Frame::new(out_cam.width, out_cam.height, PixelFormat::Rgb8);
    let mut truth_yuv = Frame::new(out_cam.width, out_cam.height, PixelFormat::Yuv420p);
    let mut measure = |stab: &Stabilizer, tel: &amc_core::Telemetry| {
        let j = tel.frame as usize;
        if j < 12 {
            return;
        }
        let t = j as f64 / FPS;
        // The output's view in the first camera's frame, and in the panorama's.
        let view = so3::exp(&Tangent::from(tel.r_view));
        truth_renderer
            .render_into(&pano.as_ref(), &(r0 * view), &mut truth)
            .unwrap();
        paint(&mut truth, &out_cam, &view, t, None);
        let out = stab.output();
        let (ow, oh) = (out_cam.width, out_cam.height);
        let (expected, got, channels): (&[u8], &[u8], usize) = if format.is_planar() {
            amc_core::color::rgb_to_yuv420p_into(ow, oh, 3, &truth.data, &mut truth_yuv.data);
            (&truth_yuv.data[..ow * oh], &out.data[..ow * oh], 1)
        } else {
            (&truth.data, out.data, 3)
        };
        let window: Vec<Vector3<f64>> = (0..n_avg.max(6))
            .map(|k| disc_centre((j as f64 - k as f64) / FPS))
            .collect();
        let coverage = stab.output_coverage();
        for v in 2..oh - 2 {
            for u in 2..ow - 2 {
                let p = v * ow + u;
                if coverage[p] == 0 {
                    continue;
                }
                let ray = view
                    * out_cam
                        .unproject(&Vector2::new(u as f64, v as f64))
                        .unwrap();
                let ray = ray.normalize();
                let nearest = window.iter().map(|c| ray.dot(c)).fold(-1.0, f64::max);
                let bucket = if nearest >= cos_moving {
                    &mut moving
                } else if nearest < cos_still {
                    &mut still
                } else {
                    continue;
                };
                for c in 0..channels {
                    let e = got[channels * p + c] as f64 - expected[channels * p + c] as f64;
                    bucket.0 += e * e;
                    bucket.1 += 1;
                }
            }
        }
    };
    let mut frame = Frame::new(cam.width, cam.height, PixelFormat::Rgb8);
    let mut planar = Frame::new(cam.width, cam.height, PixelFormat::Yuv420p);
    for j in 0..FRAMES {
        let t = j as f64 / FPS;
        renderer
            .render_into(&pano.as_ref(), &world(t), &mut frame)
            .unwrap();
        paint(
            &mut frame,
            &cam,
            &(r0.transpose() * world(t)),
            t,
            Some(j as u32),
        );
        let pushed = if format.is_planar() {
            amc_core::color::rgb_to_yuv420p_into(
                cam.width,
                cam.height,
                3,
                &frame.data,
                &mut planar.data,
            );
            &planar
        } else {
            &frame
        };
        if let Some(tel) = stab.push(pushed.as_ref(), t).unwrap() {
            measure(&stab, &tel);
        }
    }
    while let Some(tel) = stab.finish() {
        measure(&stab, &tel);
    }
    assert!(
        moving.1 > 10_000 && still.1 > 100_000,
        "{moving:?} {still:?}"
    );
    Errors {
        moving: (moving.0 / moving.1 as f64).sqrt(),
        still: (still.0 / still.1 as f64).sqrt(),
    }
}

fn check(mode: Mode, format: PixelFormat) {
    let deghost = amc_core::render::SUGGESTED_DEGHOST;
    let single = run(mode, 1, 0.0, format);
    let plain = run(mode, 6, 0.0, format);
    let merged = run(mode, 6, deghost, format);
    eprintln!("{mode:?} {format:?}: n_avg 1 {single:?}, plain {plain:?}, ghost-free {merged:?}");
    assert!(
        merged.moving <= 1.2 * single.moving,
        "{mode:?} {format:?}: moving region {:.2} vs {:.2} without averaging",
        merged.moving,
        single.moving
    );
    assert!(
        plain.moving > 1.3 * single.moving,
        "{mode:?} {format:?}: the plain average should ghost ({:.2} vs {:.2})",
        plain.moving,
        single.moving
    );
    assert!(
        merged.still <= 0.8 * single.still && merged.still <= 1.1 * plain.still,
        "{mode:?} {format:?}: static region {:.2} (plain {:.2}, single {:.2})",
        merged.still,
        plain.still,
        single.still
    );
}

#[test]
fn stabilize_averages_the_scene_but_not_what_moves_in_it() {
    check(Mode::Stabilize, PixelFormat::Rgb8);
}

#[test]
fn saccade_averages_the_scene_but_not_what_moves_in_it() {
    check(Mode::Saccade, PixelFormat::Rgb8);
}

#[test]
fn planar_frames_average_without_ghosts() {
    check(Mode::Stabilize, PixelFormat::Yuv420p);
}
