//! Throughput benchmarks (one thread): `cargo bench -p amc-core --bench pipeline`.
//!
//! Frames are rendered in memory from a procedural equirectangular scene with
//! flapping-wing shake (100 deg/s RMS, 12-20 Hz, 60 fps), so the numbers need
//! no data files; with ffmpeg and `../shared/data/karma/karma.mp4` present, the
//! same work is also measured on that real handheld footage (`*-karma`).
//! Each iteration processes one frame; criterion reports frames/s as "elem/s".
//!
//! Kept honest against the whole process (`bench/e2e.sh`): the clips are long
//! enough (240 frames) that at 720p the frames do not fit in any cache, as in a
//! real run; they are played forwards then backwards, so the motion stays
//! continuous (a wrap-around would be a jump the tracker has to recover from);
//! and frames come as the decoder delivers them, planar 4:2:0 (`yuv420p`), as
//! well as RGB. What the whole process adds on top (decoding, encoding, pipe
//! copies) is measured there, not here.

use amc_core::camera::CameraModel;
use amc_core::frontend::TrackingFrontend;
use amc_core::pyramid::Pyramid;
use amc_core::render::Interpolation;
use amc_core::shutter::{IntraFrame, RowTime, TrajectorySmoother, TRAJECTORY_FRAMES};
use amc_core::so3::Rot;
use amc_core::tracker::{Tracker, TrackerParams};
use amc_core::view::Mode;
use amc_core::Zoom;
use amc_core::{Frame, PixelFormat, Stabilizer, StabilizerParams};
use amc_synth::{EquirectRenderer, Shake, ShakeParams};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;

const FPS: f64 = 60.0;
const CLIP_FRAMES: usize = 240;

/// A 2048x1024 scene of random rectangles over a textured background.
fn panorama() -> Frame {
    let (w, h) = (2048usize, 1024usize);
    let mut f = Frame::new(w, h, PixelFormat::Rgb8);
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for (i, px) in f.data.chunks_exact_mut(3).enumerate() {
        let (x, y) = (i % w, i / w);
        let v = (((x / 24) + (y / 24)) % 2 * 40 + 60) as u8 + (rnd() % 20) as u8;
        px.copy_from_slice(&[v, v.wrapping_add(20), v / 2 + 40]);
    }
    for _ in 0..1500 {
        let (cx, cy) = ((rnd() % w as u64) as usize, (rnd() % h as u64) as usize);
        let (rw, rh) = (4 + (rnd() % 40) as usize, 4 + (rnd() % 40) as usize);
        let c = [
            (rnd() % 256) as u8,
            (rnd() % 256) as u8,
            (rnd() % 256) as u8,
        ];
        for y in cy..(cy + rh).min(h) {
            for x in cx..(cx + rw).min(w) {
                f.data[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&c);
            }
        }
    }
    f
}

/// Frame `j` of a run over a clip played forwards, then backwards, and again.
fn ping_pong(frames: &[Frame], j: usize) -> &Frame {
    &frames[ping_pong_index(frames.len(), j)]
}

/// The index of frame `j` of such a run over `n` frames.
fn ping_pong_index(n: usize, j: usize) -> usize {
    let k = j % (2 * n - 2);
    if k < n {
        k
    } else {
        2 * n - 2 - k
    }
}

/// The frames converted to planar 4:2:0.
fn to_yuv(frames: &[Frame]) -> Vec<Frame> {
    frames
        .iter()
        .map(|f| {
            let mut y = Frame::new(f.width, f.height, PixelFormat::Yuv420p);
            amc_core::color::rgb_to_yuv420p_into(f.width, f.height, 3, &f.data, &mut y.data);
            y
        })
        .collect()
}

/// `CLIP_FRAMES` frames of karma.mp4 (real handheld footage) at `width x height`,
/// planar 4:2:0, decoded by ffmpeg; `None` when either is missing.
fn karma(width: usize, height: usize) -> Option<Vec<Frame>> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/karma/karma.mp4"
    );
    if !std::path::Path::new(path).exists() {
        return None;
    }
    let out = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-i", path, "-frames:v"])
        .arg(CLIP_FRAMES.to_string())
        .args([
            "-vf",
            &format!("scale={width}:{height}"),
            "-pix_fmt",
            "yuv420p",
        ])
        .args(["-f", "rawvideo", "-"])
        .output()
        .ok()?;
    let len = PixelFormat::Yuv420p.buffer_len(width, height)?;
    let frames: Vec<Frame> = out
        .stdout
        .chunks_exact(len)
        .map(|c| Frame {
            width,
            height,
            format: PixelFormat::Yuv420p,
            data: c.to_vec(),
        })
        .collect();
    (frames.len() >= 2).then_some(frames)
}

/// A shaky clip of `CLIP_FRAMES` frames at `width x height` (90 deg pinhole).
fn clip(width: usize, height: usize) -> (CameraModel, Vec<Frame>) {
    clip_rolling(width, height, 0.0)
}

/// [`clip`] filmed through a rolling shutter read out in `readout_s` seconds.
fn clip_rolling(width: usize, height: usize, readout_s: f64) -> (CameraModel, Vec<Frame>) {
    let cam = CameraModel::pinhole_hfov(width, height, 90.0).expect("camera");
    clip_through(cam, readout_s)
}

/// A shaky clip of `CLIP_FRAMES` frames filmed by `cam` through a rolling
/// shutter read out in `readout_s` seconds (0: a global shutter).
fn clip_through(cam: CameraModel, readout_s: f64) -> (CameraModel, Vec<Frame>) {
    let (width, height) = (cam.width, cam.height);
    let pano = panorama();
    let renderer = EquirectRenderer::new(&cam, 1).expect("renderer");
    let shake = Shake::new(&ShakeParams::default()).expect("shake");
    let frames = (0..CLIP_FRAMES)
        .map(|j| {
            let mut out = Frame::new(width, height, PixelFormat::Rgb8);
            let t = j as f64 / FPS;
            renderer
                .render_rolling_into(
                    &pano.as_ref(),
                    &|s| shake.orientation_at(t + readout_s * s),
                    &mut out,
                )
                .expect("render");
            out
        })
        .collect();
    (cam, frames)
}

/// Readout of the rolling-shutter runs, seconds (a phone's).
const READOUT_S: f64 = 0.015;

fn bench_tracking(c: &mut Criterion) {
    let mut g = c.benchmark_group("track");
    g.throughput(Throughput::Elements(1));
    // The global shutter, and a rolling shutter with its readout motion
    // estimated (on frames filmed through one); a pinhole, and a 150 deg
    // fisheye (an action camera's), whose undistorted rows bend.
    let pinhole = CameraModel::pinhole_hfov(320, 180, 90.0).expect("camera");
    let fisheye =
        CameraModel::fisheye_hfov(320, 180, 150.0, [0.05, -0.01, 0.002, -0.0005]).expect("camera");
    for (lens, cam) in [("", pinhole), ("-fisheye", fisheye)] {
        for readout_s in [0.0, READOUT_S] {
            bench_tracking_clip(
                &mut g,
                lens,
                clip_through(cam.clone(), readout_s),
                readout_s,
            );
        }
    }
    g.finish();
}

/// One tracking bench: `clip` (its camera and frames, filmed through a
/// `readout_s` readout) tracked frame by frame.
fn bench_tracking_clip(
    g: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>,
    lens: &str,
    (cam, frames): (CameraModel, Vec<Frame>),
    readout_s: f64,
) {
    let shutter = if readout_s > 0.0 { "-rolling" } else { "" };
    g.bench_function(format!("320x180{lens}{shutter}"), |b| {
        let mut frontend = TrackingFrontend::new(&cam, 320).expect("frontend");
        let mut tracker =
            Tracker::new(frontend.camera(), TrackerParams::default()).expect("tracker");
        if readout_s > 0.0 {
            tracker.set_rolling(RowTime::new(&cam, frontend.camera()), readout_s);
        }
        let mut pyr = Pyramid::default();
        let mut j = 0usize;
        b.iter(|| {
            let f = ping_pong(&frames, j);
            frontend.prepare(&f.as_ref(), &mut pyr, tracker.levels());
            black_box(tracker.track(&pyr, j as f64 / FPS));
            j += 1;
        })
    });
}

fn bench_stabilize(c: &mut Criterion) {
    let mut g = c.benchmark_group("stabilize");
    g.throughput(Throughput::Elements(1));
    // Every sample pushes the same number of frames: criterion's default
    // (linear) sampling fits a line to samples of 1, 2, ... n iterations and,
    // for a stateful stream whose cost varies frame to frame, reported up to
    // twice the frames/s a plain loop over the same frames achieves.
    g.sampling_mode(criterion::SamplingMode::Flat);
    g.sample_size(20);
    for (w, h) in [(320, 180), (1280, 720)] {
        let (cam, rgb) = clip(w, h);
        let yuv = to_yuv(&rgb);
        let (_, rolling) = clip_rolling(w, h, READOUT_S);
        let rolling = to_yuv(&rolling);
        let real = karma(w, h);
        // The paper's framing (`zoom = none`: the central 75%) as the numbers
        // in the README; `-zoom-auto` is the default framing (the input's
        // size, a zoom and its coverage test per frame).
        // `-deghost`: the ghost-free average (`deghost` 6) instead of the plain one
        // (`-deghost-bicubic`: with bicubic sampling, the README's choice for sharpness).
        // `-bicubic`: frames sampled bicubically (`interpolation` bicubic;
        // `-rgb-bicubic` the interleaved frames' kernels, as image folders and
        // the page's RGBA input run).
        // `-rolling`: the same motion through a rolling shutter, its readout
        // given (`readout_ms` 15): tracking with the readout motion, every
        // source row rendered at its own orientation.
        let mut runs: Vec<(String, Mode, Zoom, &[Frame])> = vec![
            (format!("{w}x{h}-rgb"), Mode::Stabilize, Zoom::None, &rgb),
            (
                format!("{w}x{h}-rgb-bicubic"),
                Mode::Stabilize,
                Zoom::None,
                &rgb,
            ),
            (
                format!("{w}x{h}-yuv420p"),
                Mode::Stabilize,
                Zoom::None,
                &yuv,
            ),
            (
                format!("{w}x{h}-yuv420p-deghost"),
                Mode::Stabilize,
                Zoom::None,
                &yuv,
            ),
            (
                format!("{w}x{h}-yuv420p-bicubic"),
                Mode::Stabilize,
                Zoom::None,
                &yuv,
            ),
            (
                format!("{w}x{h}-yuv420p-deghost-bicubic"),
                Mode::Stabilize,
                Zoom::None,
                &yuv,
            ),
            (
                format!("{w}x{h}-yuv420p-rolling"),
                Mode::Stabilize,
                Zoom::None,
                &rolling,
            ),
            (
                format!("{w}x{h}-yuv420p-zoom-auto"),
                Mode::Stabilize,
                Zoom::Auto,
                &yuv,
            ),
        ];
        if w == 320 {
            for name in ["saccade-yuv420p", "saccade-yuv420p-deghost"] {
                runs.push((format!("{w}x{h}-{name}"), Mode::Saccade, Zoom::None, &yuv));
            }
        }
        if let Some(real) = real.as_deref() {
            runs.push((
                format!("{w}x{h}-yuv420p-karma"),
                Mode::Stabilize,
                Zoom::None,
                real,
            ));
        }
        for (name, mode, zoom, frames) in runs {
            g.bench_function(&name, |b| {
                let mut params = StabilizerParams::default();
                params.view.mode = mode;
                params.framing.zoom = zoom;
                if name.contains("-deghost") {
                    params.render.deghost =
                        amc_core::render::DeghostLevel::Levels(amc_core::render::SUGGESTED_DEGHOST);
                }
                if name.ends_with("-rolling") {
                    params.shutter.readout_ms = READOUT_S * 1000.0;
                }
                if name.contains("-bicubic") {
                    params.render.interpolation = Interpolation::Bicubic;
                }
                let mut stab = Stabilizer::new(&cam, w, h, params).expect("stabilizer");
                let mut j = 0usize;
                b.iter(|| {
                    let f = ping_pong(frames, j);
                    black_box(stab.push(f.as_ref(), j as f64 / FPS).expect("push"));
                    j += 1;
                })
            });
        }
    }
    g.finish();
}

/// The render alone, one row kernel after another in one run: the average of
/// six frames' three planes (`yuv420p`) into the view with the paper's framing
/// (the central 75%, as `stabilize/*-yuv420p` renders), each frame through its
/// true orientation under the synthetic shake (the view held at the start).
/// Each iteration renders one output from the next six frames of the clip.
fn bench_render(c: &mut Criterion) {
    use amc_core::render::kernels::Kernel;
    use amc_core::render::kernels::FRAME_PADDING;
    use amc_core::render::{chroma_camera, RenderParams, Warper};
    let mut g = c.benchmark_group("render");
    g.throughput(Throughput::Elements(1));
    g.sampling_mode(criterion::SamplingMode::Flat);
    g.sample_size(20);
    let shake = Shake::new(&ShakeParams::default()).expect("shake");
    let n_avg = RenderParams::default().n_avg;
    for (w, h) in [(320, 180), (1280, 720)] {
        let (cam, rgb) = clip(w, h);
        let mut yuv = to_yuv(&rgb);
        // The vector kernels read a few bytes past the last plane.
        for f in &mut yuv {
            f.data.extend_from_slice(&[0; FRAME_PADDING]);
        }
        let out = RenderParams::default()
            .output_camera_with_margin(&cam, 0.125)
            .expect("output camera");
        let rotations: Vec<_> = (0..CLIP_FRAMES)
            .map(|j| *shake.orientation_at(j as f64 / FPS).inverse().matrix())
            .collect();
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        // Every kernel at the default output size (one sample per pixel), and
        // with the detected kernel an output half as wide (`-half`: 2 source
        // pixels per output pixel) plainly and with `antialias` (2x2 samples).
        // `-bicubic-*`: every kernel sampling bicubically.
        let mut cases: Vec<(String, CameraModel, usize, Kernel, Interpolation)> = [
            ("", Interpolation::Bilinear),
            ("bicubic-", Interpolation::Bicubic),
        ]
        .into_iter()
        .flat_map(|(tag, interp)| {
            Kernel::available()
                .into_iter()
                .map(move |k| (format!("{w}x{h}-yuv420p-{tag}{k:?}"), k, interp))
        })
        .map(|(name, k, interp)| (name, out.clone(), 1, k, interp))
        .collect();
        if w == 1280 {
            let params = RenderParams {
                output_width: Some(out.width / 2),
                ..RenderParams::default()
            };
            let half = params
                .output_camera_with_margin(&cam, 0.125)
                .expect("output camera");
            let s = params.supersample(&cam, &half);
            for (name, s) in [("off", 1), ("antialias", s)] {
                let name = format!("{w}x{h}-yuv420p-half-{name}");
                cases.push((
                    name,
                    half.clone(),
                    s,
                    Kernel::detect(),
                    Interpolation::Bilinear,
                ));
            }
        }
        for (name, out, s, kernel, interpolation) in cases {
            let (ow, oh) = (out.width, out.height);
            let mut luma = Warper::supersampled(&cam, &out, s);
            let mut chroma = Warper::supersampled(&chroma_camera(&cam), &chroma_camera(&out), s);
            luma.set_interpolation(interpolation);
            chroma.set_interpolation(interpolation);
            if !(luma.set_kernel(kernel) && chroma.set_kernel(kernel)) {
                continue;
            }
            let mut img = Frame::new(ow, oh, PixelFormat::Yuv420p);
            let mut coverage = Vec::new();
            g.bench_function(name, |b| {
                let mut j = 0usize;
                b.iter(|| {
                    let frame = |i: usize| ping_pong_index(CLIP_FRAMES, j + i);
                    let rots: Vec<_> = (0..n_avg).map(|i| rotations[frame(i)]).collect();
                    let (oy, ou, ov) = amc_core::image::yuv_planes_mut(ow, oh, &mut img.data);
                    // Each plane runs on to the frame's end (the padding).
                    let plane =
                        |i: usize, p: usize| &yuv[frame(i)].data[[0, w * h, w * h + cw * ch][p]..];
                    luma.average_plane_into(|i| plane(i, 0), w, h, &rots, oy, &mut coverage, 0);
                    chroma.average_plane_pair_into(
                        |i| (plane(i, 1), plane(i, 2)),
                        cw,
                        ch,
                        &rots,
                        ou,
                        ov,
                        &mut coverage,
                        128,
                    );
                    black_box(&img);
                    j += 1;
                })
            });
        }
    }
    g.finish();
}

/// The paper's image metrics of an output frame (normal flow and change
/// against the previous one, sharpness over R, G and B), as `--metrics` and
/// the service measure every output: consecutive frames of the clip, planar
/// and packed, with a black border a tenth of the width wide on each side.
fn bench_metrics(c: &mut Criterion) {
    use amc_core::metrics::MetricsAccumulator;
    let mut g = c.benchmark_group("metrics");
    g.throughput(Throughput::Elements(1));
    g.sampling_mode(criterion::SamplingMode::Flat);
    g.sample_size(20);
    for (w, h) in [(320, 180), (1280, 720)] {
        let (_, rgb) = clip(w, h);
        let yuv = to_yuv(&rgb);
        let coverage: Vec<u8> = (0..w * h)
            .map(|i| u8::from((w / 10..w - w / 10).contains(&(i % w))) * 6)
            .collect();
        for (name, frames) in [("yuv420p", &yuv), ("rgb", &rgb)] {
            let mut acc = MetricsAccumulator::new();
            g.bench_function(format!("{w}x{h}-{name}"), |b| {
                let mut j = 0usize;
                b.iter(|| {
                    let f = &frames[ping_pong_index(CLIP_FRAMES, j)];
                    black_box(acc.push(&f.as_ref(), &coverage, 0.8, None));
                    j += 1;
                })
            });
        }
    }
    g.finish();
}

/// The rolling shutter's trajectory fit, per frame (a part of tracking: the
/// stabilizer runs it after the tracker on every frame).
fn bench_trajectory(c: &mut Criterion) {
    let mut g = c.benchmark_group("trajectory");
    g.throughput(Throughput::Elements(1));
    let shake = Shake::new(&ShakeParams {
        shake_dps: 300.0,
        band_hz: (12.0, 20.0),
        seed: 1,
        ..ShakeParams::default()
    })
    .expect("shake");
    let frames: Vec<(f64, Rot, IntraFrame)> = (0..CLIP_FRAMES)
        .map(|j| {
            let t = j as f64 / FPS;
            let phi = shake.angular_velocity_at(t) * READOUT_S;
            let intra = IntraFrame {
                phi,
                ..IntraFrame::ZERO
            };
            (t, shake.orientation_at(t), intra)
        })
        .collect();
    g.bench_function(format!("{TRAJECTORY_FRAMES}-frames"), |b| {
        let mut smoother = TrajectorySmoother::new(READOUT_S);
        let mut j = 0usize;
        b.iter(|| {
            // Time runs on past the clip (a fit needs increasing times).
            let (t, pose, intra) = frames[j % frames.len()];
            let t = t + (j / frames.len()) as f64 * frames.len() as f64 / FPS;
            black_box(smoother.push(t, pose, intra, 1.0));
            j += 1;
        })
    });
    g.finish();
}

criterion_group!(
    benches,
    bench_tracking,
    bench_trajectory,
    bench_stabilize,
    bench_render,
    bench_metrics
);
criterion_main!(benches);
