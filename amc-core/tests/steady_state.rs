//! The streaming API allocates nothing per frame once warmed up, and its memory
//! does not grow with the clip: checked with a counting global allocator. And
//! pipelining (tracking one frame while rendering the previous output) changes
//! when outputs come, never what they are.

use amc_core::view::Mode;
use amc_core::{CameraModel, Frame, PixelFormat, Stabilizer, StabilizerParams};
use amc_synth::{EquirectRenderer, Shake, ShakeParams};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The allocation counter is process-wide: tests take turns.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// A procedural panorama (no data files needed).
fn panorama() -> Frame {
    let (w, h) = (1024usize, 512usize);
    let mut f = Frame::new(w, h, PixelFormat::Rgb8);
    for (i, px) in f.data.chunks_exact_mut(3).enumerate() {
        let (x, y) = (i % w, i / w);
        let v = ((x * 7 + y * 13) % 97 + ((x / 16 + y / 16) % 2) * 100) as u8;
        px.copy_from_slice(&[v, v / 2 + 60, 255 - v]);
    }
    f
}

/// 40 frames of a shaky 160x96 clip, as RGB and as planar 4:2:0.
fn clips(cam: &CameraModel) -> (Vec<Frame>, Vec<Frame>) {
    let pano = panorama();
    let renderer = EquirectRenderer::new(&cam, 1).unwrap();
    let shake = Shake::new(&ShakeParams::default()).unwrap();
    let frames: Vec<Frame> = (0..40)
        .map(|j| {
            let mut out = Frame::new(160, 96, PixelFormat::Rgb8);
            renderer
                .render_into(
                    &pano.as_ref(),
                    &shake.orientation_at(j as f64 / 60.0),
                    &mut out,
                )
                .unwrap();
            out
        })
        .collect();
    let yuv: Vec<Frame> = frames
        .iter()
        .map(|f| {
            let mut y = Frame::new(160, 96, PixelFormat::Yuv420p);
            amc_core::color::rgb_to_yuv420p_into(160, 96, 3, &f.data, &mut y.data);
            y
        })
        .collect();
    (frames, yuv)
}

#[test]
fn no_allocation_per_frame_in_steady_state() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let cam = CameraModel::pinhole_hfov(160, 96, 90.0).unwrap();
    let (frames, yuv) = clips(&cam);
    // One thread: nothing at all. On a rayon pool of several (the `parallel`
    // feature), rayon's job queue allocates a block now and then (amortized,
    // freed again): bounded, but not zero.
    #[cfg(feature = "parallel")]
    let pools: Vec<(usize, usize)> = vec![(1, 0), (2, 240 / 16)];
    #[cfg(not(feature = "parallel"))]
    let pools: Vec<(usize, usize)> = vec![(1, 0)];
    for (threads, allowed) in pools {
        for clip in [&frames, &yuv] {
            let run = || check_steady_state(&cam, clip, allowed);
            #[cfg(feature = "parallel")]
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(run);
            #[cfg(not(feature = "parallel"))]
            {
                let _ = threads;
                run();
            }
        }
    }
}

/// Pushes 240 frames after a warm-up in every mode; at most `allowed` allocations.
fn check_steady_state(cam: &CameraModel, frames: &[Frame], allowed: usize) {
    for (mode, lookahead) in [
        (Mode::Stabilize, 0),
        (Mode::Stabilize, 5),
        (Mode::Saccade, 0),
        (Mode::None, 0),
    ] {
        let mut params = StabilizerParams::default();
        params.track_width = 160;
        params.view.mode = mode;
        params.view.lookahead = lookahead;
        let mut stab = Stabilizer::new(cam, 160, 96, params).unwrap();
        // Warm up: fill the window, the lookahead and every reusable buffer.
        for j in 0..60 {
            stab.push(frames[j % 40].as_ref(), j as f64 / 60.0).unwrap();
        }
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        for j in 60..300 {
            stab.push(frames[j % 40].as_ref(), j as f64 / 60.0).unwrap();
        }
        let allocs = ALLOCATIONS.load(Ordering::Relaxed) - before;
        let format = frames[0].format;
        assert!(
            allocs <= allowed,
            "{mode} (lookahead {lookahead}, {format:?}): {allocs} allocations in 240 frames"
        );
    }
}

/// Every output of a pipelined run, bytes and telemetry, equals the plain run's.
#[test]
fn pipelined_outputs_equal_plain_outputs() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let cam = CameraModel::pinhole_hfov(160, 96, 90.0).unwrap();
    let (rgb, yuv) = clips(&cam);
    for clip in [&rgb, &yuv] {
        for (mode, lookahead) in [
            (Mode::Stabilize, 0),
            (Mode::Stabilize, 5),
            (Mode::Saccade, 0),
        ] {
            let run = |pipelined: bool| {
                let mut params = StabilizerParams::default();
                params.track_width = 160;
                params.view.mode = mode;
                params.view.lookahead = lookahead;
                let mut stab = Stabilizer::new(&cam, 160, 96, params).unwrap();
                stab.set_pipelined(pipelined);
                let mut outs = Vec::new();
                for j in 0..60 {
                    if let Some(tel) = stab.push(clip[j % 40].as_ref(), j as f64 / 60.0).unwrap() {
                        outs.push((format!("{tel:?}"), stab.output().data.to_vec()));
                    }
                }
                while let Some(tel) = stab.finish() {
                    outs.push((format!("{tel:?}"), stab.output().data.to_vec()));
                }
                outs
            };
            let (plain, piped) = (run(false), run(true));
            assert_eq!(plain.len(), 60);
            assert!(
                plain == piped,
                "{mode} lookahead {lookahead} {:?}",
                clip[0].format
            );
        }
    }
}

/// Stabilizers fed the same frames, each rendering its share of the outputs
/// (`set_render_share`), give every output once between them, byte for byte
/// the single stabilizer's; their other outputs' telemetry is the same but
/// for what only a render measures.
#[test]
fn shared_renders_equal_one_stabilizers() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // A fisheye too: through a rolling shutter its frames' nodes come from
    // their landing maps, which must not depend on which outputs came before.
    let cams = [
        CameraModel::pinhole_hfov(160, 96, 90.0).unwrap(),
        CameraModel::fisheye_hfov(160, 96, 150.0, [0.05, -0.01, 0.002, -0.0005]).unwrap(),
    ];
    let params = |mode: Mode, lookahead: usize, readout_ms: f64| {
        let mut params = StabilizerParams::default();
        params.track_width = 160;
        params.view.mode = mode;
        params.view.lookahead = lookahead;
        params.shutter.readout_ms = readout_ms;
        params
    };
    for cam in &cams {
        let (rgb, yuv) = clips(cam);
        for clip in [&rgb, &yuv] {
            for (mode, lookahead, readout_ms, count) in [
                (Mode::Stabilize, 0, 0.0, 2),
                (Mode::Stabilize, 5, 0.0, 3),
                (Mode::Stabilize, 0, 10.0, 2),
                (Mode::Lock, 0, 0.0, 2),
                (Mode::None, 0, 0.0, 2),
            ] {
                let run = |share: Option<u32>| {
                    let mut stab =
                        Stabilizer::new(cam, 160, 96, params(mode, lookahead, readout_ms)).unwrap();
                    if let Some(index) = share {
                        stab.set_render_share(count, index).unwrap();
                    }
                    let mut outs = Vec::new();
                    for j in 0..50 {
                        if let Some(tel) =
                            stab.push(clip[j % 40].as_ref(), j as f64 / 60.0).unwrap()
                        {
                            outs.push((tel, stab.output().data.to_vec()));
                        }
                    }
                    while let Some(tel) = stab.finish() {
                        outs.push((tel, stab.output().data.to_vec()));
                    }
                    outs
                };
                let plain = run(None);
                assert_eq!(plain.len(), 50);
                let shares: Vec<_> = (0..count).map(|i| run(Some(i))).collect();
                let what = format!(
                    "{mode} lookahead {lookahead} readout {readout_ms} ms {:?}",
                    clip[0].format
                );
                for (j, (tel, bytes)) in plain.iter().enumerate() {
                    for (i, share) in shares.iter().enumerate() {
                        let (shared_tel, shared_bytes) = &share[j];
                        if j % count as usize == i {
                            assert!(shared_bytes == bytes, "{what}: output {j} of share {i}");
                            assert_eq!(format!("{shared_tel:?}"), format!("{tel:?}"), "{what}");
                        } else {
                            assert_eq!((shared_tel.valid_fraction, shared_tel.uncovered), (0.0, 0));
                            let mut unrendered = tel.clone();
                            (unrendered.valid_fraction, unrendered.uncovered) = (0.0, 0);
                            assert_eq!(
                                format!("{shared_tel:?}"),
                                format!("{unrendered:?}"),
                                "{what}"
                            );
                        }
                    }
                }
            }
        }
    }
    // The shares a stabilizer refuses, naming what it takes.
    let cam = &cams[0];
    let mut stab = Stabilizer::new(cam, 160, 96, params(Mode::Stabilize, 0, 0.0)).unwrap();
    for (count, index, allowed) in [(0, 0, "1 to 16"), (17, 0, "1 to 16"), (2, 2, "count - 1")] {
        let e = stab.set_render_share(count, index).unwrap_err().to_string();
        assert!(e.contains(allowed), "{count} {index}: {e}");
    }
    let mut saccade = Stabilizer::new(cam, 160, 96, params(Mode::Saccade, 0, 0.0)).unwrap();
    let e = saccade.set_render_share(2, 1).unwrap_err().to_string();
    assert!(e.contains("saccade"), "{e}");
    saccade.set_render_share(1, 0).unwrap();
}
