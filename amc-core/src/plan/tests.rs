use super::*;
use crate::framing::Zoom;
use crate::image::PixelFormat;
use crate::readout;
use crate::view::Mode;

const W: usize = 160;
const H: usize = 120;

/// An RGB frame of a smooth pattern, slid `shift` pixels to the right and
/// half as far down (the shake of a pan: a translation the focal length
/// cannot be told from).
fn frame(shift: f64) -> Frame {
    let mut f = Frame::new(W, H, PixelFormat::Rgb8);
    for y in 0..H {
        for x in 0..W {
            let (u, v) = (x as f64 - shift, y as f64 - 0.5 * shift);
            let g = 128.0
                + 50.0 * (u * 0.21).sin() * (v * 0.17).cos()
                + 30.0 * (u * 0.05 + v * 0.09).sin()
                + 20.0 * ((u * 0.013 - v * 0.031) * 3.0).cos();
            let g = g.clamp(0.0, 255.0) as u8;
            let i = 3 * (y * W + x);
            f.data[i..i + 3].copy_from_slice(&[g, g / 2 + 60, 255 - g]);
        }
    }
    f
}

/// `n` frames at 30 fps, shaking by a few pixels.
fn clip(n: usize) -> Vec<(Frame, f64)> {
    (0..n)
        .map(|i| {
            let t = i as f64 / 30.0;
            (frame(3.0 * (t * 9.0).sin() + 0.5 * i as f64), t)
        })
        .collect()
}

fn known() -> LensChoice {
    LensChoice::Known(ResolvedLens {
        camera: CameraModel::pinhole_hfov(W, H, 70.0).unwrap(),
        note: LensNote::Given,
        readout_ms: None,
    })
}

fn choices(lens: LensChoice, readout: ReadoutSpec) -> PlanChoices {
    PlanChoices {
        lens,
        readout,
        params: StabilizerParams::default(),
        static_zoom: true,
        frame_size: Some((W, H)),
    }
}

fn static_params(mode: Mode) -> StabilizerParams {
    let mut p = StabilizerParams::default();
    p.framing.zoom = Zoom::Static;
    p.view.mode = mode;
    p
}

/// Makes every pass as a driver does: each reads `frames` from the start
/// until it is full or they end; returns the frames each pass took.
fn drive(plan: &mut PassPlan, frames: &[(Frame, f64)]) -> Vec<(Pass, usize)> {
    let mut read = Vec::new();
    while let Some(pass) = plan.pass() {
        let mut n = 0;
        for (f, t) in frames {
            if plan.is_full() {
                break;
            }
            plan.push(f.as_ref(), *t).unwrap();
            n += 1;
        }
        read.push((pass, n));
        assert_eq!(plan.finish_pass().unwrap(), pass);
    }
    read
}

#[test]
fn the_choices_decide_the_passes_and_their_order() {
    let plan = |lens, readout, params: StabilizerParams, static_zoom| {
        let c = PlanChoices {
            params,
            static_zoom,
            ..choices(lens, readout)
        };
        PassPlan::new(c).unwrap().passes().to_vec()
    };
    let default = StabilizerParams::default;
    let fov = || LensChoice::Fov(70.0);
    assert_eq!(plan(known(), ReadoutSpec::FromLens, default(), true), []);
    assert_eq!(plan(fov(), ReadoutSpec::Ms(10.0), default(), true), []);
    assert_eq!(
        plan(LensChoice::Auto, ReadoutSpec::FromLens, default(), true),
        [Pass::Lens]
    );
    assert_eq!(
        plan(fov(), ReadoutSpec::Auto, default(), true),
        [Pass::Readout]
    );
    assert_eq!(
        plan(
            known(),
            ReadoutSpec::Ms(0.0),
            static_params(Mode::Stabilize),
            true
        ),
        [Pass::StaticZoom]
    );
    // The readout needs the lens, the static zoom both.
    assert_eq!(
        plan(
            LensChoice::Auto,
            ReadoutSpec::Auto,
            static_params(Mode::Lock),
            true
        ),
        [Pass::Lens, Pass::Readout, Pass::StaticZoom]
    );
    // Saccade and none hold no static zoom; a caller may leave the pass to later.
    for mode in [Mode::Saccade, Mode::None] {
        assert_eq!(
            plan(known(), ReadoutSpec::Auto, static_params(mode), true),
            [Pass::Readout]
        );
    }
    assert_eq!(
        plan(
            LensChoice::Auto,
            ReadoutSpec::Auto,
            static_params(Mode::Stabilize),
            false
        ),
        [Pass::Lens, Pass::Readout]
    );
}

#[test]
fn each_pass_has_its_estimators_budget() {
    assert_eq!(Pass::Lens.frame_budget(), Some(AUTO_FOV_FRAMES));
    assert_eq!(Pass::Readout.frame_budget(), Some(readout::READOUT_FRAMES));
    assert_eq!(Pass::StaticZoom.frame_budget(), None);
    assert_eq!((AUTO_FOV_FRAMES, READOUT_FRAMES), (90, 180));
    // The lens pass keeps its budget's frames and ignores more.
    let mut plan = PassPlan::new(choices(LensChoice::Auto, ReadoutSpec::FromLens)).unwrap();
    let f = frame(0.0);
    for i in 0..AUTO_FOV_FRAMES + 5 {
        assert_eq!(plan.is_full(), i >= AUTO_FOV_FRAMES);
        plan.push(f.as_ref(), i as f64 / 30.0).unwrap();
    }
    assert_eq!(plan.frames(), AUTO_FOV_FRAMES);
}

#[test]
fn given_lenses_and_readouts_need_no_frames() {
    let file = |ms| {
        LensChoice::Known(ResolvedLens::from(LensFile {
            camera: CameraModel::pinhole_hfov(W, H, 70.0).unwrap(),
            readout_ms: ms,
        }))
    };
    let resolved = |lens, spec| {
        let plan = PassPlan::new(choices(lens, spec)).unwrap();
        assert_eq!(plan.pass(), None);
        assert!(plan.is_full());
        plan.finish().unwrap()
    };
    // The option beats the lens file, which beats 0.
    let r = resolved(file(Some(20.0)), ReadoutSpec::Ms(7.5));
    assert_eq!(
        (r.readout.readout_ms, &r.readout.note),
        (7.5, &ReadoutNote::Given)
    );
    assert_eq!(r.params.shutter.readout_ms, 7.5);
    let r = resolved(file(Some(20.0)), ReadoutSpec::FromLens);
    assert_eq!(
        (r.readout.readout_ms, &r.readout.note),
        (20.0, &ReadoutNote::FromLens)
    );
    assert!(r.readout.message().unwrap().contains("20 ms"));
    assert_eq!(r.params.shutter.readout_ms, 20.0);
    let r = resolved(file(None), ReadoutSpec::FromLens);
    assert_eq!((r.readout.readout_ms, r.readout.message()), (0.0, None));
    assert_eq!((r.lens_note(), r.static_zoom), (&LensNote::Given, None));
}

#[test]
fn a_field_of_view_needs_the_frame_size() {
    let c = PlanChoices {
        frame_size: None,
        ..choices(LensChoice::Fov(90.0), ReadoutSpec::FromLens)
    };
    let mut plan = PassPlan::new(c.clone()).unwrap();
    assert!(plan.needs_frame_size());
    plan.set_frame_size(W, H).unwrap();
    assert!(!plan.needs_frame_size());
    let lens = plan.finish().unwrap().lens;
    assert!((lens.camera.hfov_deg() - 90.0).abs() < 1e-9);
    assert_eq!(lens.camera.width, W);
    // Without it the plan cannot finish; a pass's first frame gives it.
    assert!(PassPlan::new(c.clone()).unwrap().finish().is_err());
    let mut plan = PassPlan::new(PlanChoices {
        readout: ReadoutSpec::Auto,
        ..c
    })
    .unwrap();
    plan.push(frame(0.0).as_ref(), 0.0).unwrap();
    assert_eq!(plan.lens().unwrap().camera.width, W);
    // An impossible field of view is the camera's error.
    let mut plan = PassPlan::new(PlanChoices {
        frame_size: None,
        ..choices(LensChoice::Fov(200.0), ReadoutSpec::FromLens)
    })
    .unwrap();
    assert!(plan.set_frame_size(W, H).is_err());
}

#[test]
fn the_lens_pass_is_the_estimate_or_the_fallback() {
    let frames = clip(14);
    let mut plan = PassPlan::new(choices(LensChoice::Auto, ReadoutSpec::FromLens)).unwrap();
    assert_eq!(drive(&mut plan, &frames), [(Pass::Lens, 14)]);
    let r = plan.finish().unwrap();
    // The same frames through the estimator itself.
    let refs: Vec<_> = frames.iter().map(|(f, t)| (f.as_ref(), *t)).collect();
    let p = StabilizerParams::default();
    let est = selfcal::estimate_hfov(&refs, p.track_width, &p.tracker, 0.0).unwrap();
    if est.confident {
        assert_eq!(
            r.lens.note,
            LensNote::Estimated {
                hfov_deg: est.hfov_deg,
                frames: 14
            }
        );
        assert_eq!(r.lens.camera.hfov_deg(), est.hfov_deg);
    } else {
        assert_eq!(r.lens.note, LensNote::FellBack);
        assert!((r.lens.camera.hfov_deg() - FALLBACK_FOV_DEG).abs() < 1e-9);
    }
    assert_eq!((r.lens.camera.width, r.lens.camera.height), (W, H));
    // A readout from the lens: none after an estimate, so 0.
    assert_eq!(
        (r.readout.readout_ms, &r.readout.note),
        (0.0, &ReadoutNote::Given)
    );
}

#[test]
fn a_lens_pass_of_too_few_frames_is_an_error() {
    let mut plan = PassPlan::new(choices(LensChoice::Auto, ReadoutSpec::FromLens)).unwrap();
    drive_err(&mut plan, &clip(selfcal::MIN_FRAMES - 1));
}

fn drive_err(plan: &mut PassPlan, frames: &[(Frame, f64)]) {
    for (f, t) in frames {
        plan.push(f.as_ref(), *t).unwrap();
    }
    assert!(matches!(
        plan.finish_pass(),
        Err(AmcError::TooFewFrames { needed, .. }) if needed == selfcal::MIN_FRAMES
    ));
}

/// The readout a driver of the estimator itself gets from `frames`.
fn direct_readout(frames: &[(Frame, f64)]) -> Result<ReadoutEstimate, AmcError> {
    let cam = CameraModel::pinhole_hfov(W, H, 70.0).unwrap();
    let mut est = ReadoutEstimator::new(&cam, W, H, &StabilizerParams::default()).unwrap();
    for (f, t) in frames {
        if est.is_full() {
            break;
        }
        est.push(f.as_ref(), *t).unwrap();
    }
    est.finish()
}

#[test]
fn the_readout_pass_is_the_estimate_or_a_global_shutter() {
    let frames = clip(60);
    let mut plan = PassPlan::new(choices(known(), ReadoutSpec::Auto)).unwrap();
    assert_eq!(drive(&mut plan, &frames), [(Pass::Readout, 60)]);
    let r = plan.finish().unwrap();
    let e = direct_readout(&frames).unwrap();
    let want = if e.confident {
        ReadoutNote::Estimated(e.clone())
    } else {
        ReadoutNote::FellBack {
            estimate: Some(e.clone()),
        }
    };
    assert_eq!(r.readout.note, want);
    let ms = if e.confident { e.readout_ms } else { 0.0 };
    assert_eq!(
        (r.readout.readout_ms, r.params.shutter.readout_ms),
        (ms, ms)
    );
    assert_eq!(r.readout.note.is_warning(), !e.confident);
}

#[test]
fn a_readout_pass_too_short_to_fit_falls_back_with_a_warning() {
    let frames = clip(readout::MIN_FRAMES - 1);
    assert!(matches!(
        direct_readout(&frames),
        Err(AmcError::TooFewFrames { .. })
    ));
    let mut plan = PassPlan::new(choices(known(), ReadoutSpec::Auto)).unwrap();
    drive(&mut plan, &frames);
    let r = plan.finish().unwrap().readout;
    assert_eq!(r.note, ReadoutNote::FellBack { estimate: None });
    assert_eq!(r.readout_ms, 0.0);
    assert!(r.message().unwrap().starts_with("warning:"));
}

#[test]
fn the_readout_pass_stops_at_its_budget() {
    let frames = clip(READOUT_FRAMES + 20);
    let mut plan = PassPlan::new(choices(known(), ReadoutSpec::Auto)).unwrap();
    let read = drive(&mut plan, &frames);
    assert_eq!(read, [(Pass::Readout, READOUT_FRAMES)]);
    let r = plan.finish().unwrap().readout;
    let e = direct_readout(&frames).unwrap();
    assert_eq!(e.frames, READOUT_FRAMES);
    match r.note {
        ReadoutNote::Estimated(got)
        | ReadoutNote::FellBack {
            estimate: Some(got),
        } => {
            assert_eq!(got, e)
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn the_static_zoom_pass_tracks_the_whole_clip_with_the_readout() {
    let frames = clip(40);
    let mut c = choices(known(), ReadoutSpec::Ms(8.0));
    c.params = static_params(Mode::Stabilize);
    let mut plan = PassPlan::new(c).unwrap();
    assert_eq!(drive(&mut plan, &frames), [(Pass::StaticZoom, 40)]);
    let r = plan.finish().unwrap();
    // A stabilizer that does not render, with the readout, over every frame.
    let mut p = static_params(Mode::Stabilize);
    p.shutter.readout_ms = 8.0;
    let cam = CameraModel::pinhole_hfov(W, H, 70.0).unwrap();
    let mut stab = Stabilizer::new(&cam, W, H, p.clone()).unwrap();
    stab.set_rendering(false);
    for (f, t) in &frames {
        stab.push(f.as_ref(), *t).unwrap();
    }
    while stab.finish().is_some() {}
    assert_eq!(r.static_zoom, Some(stab.max_zoom_need()));
    assert_eq!(r.params, p);
}

#[test]
fn every_pass_in_order_each_with_what_the_last_found() {
    let frames = clip(30);
    let mut c = choices(LensChoice::Auto, ReadoutSpec::Auto);
    c.params = static_params(Mode::Stabilize);
    let mut plan = PassPlan::new(c).unwrap();
    assert_eq!(
        drive(&mut plan, &frames),
        [
            (Pass::Lens, 30),
            (Pass::Readout, 30),
            (Pass::StaticZoom, 30)
        ]
    );
    let r = plan.finish().unwrap();
    assert_eq!(r.params.shutter.readout_ms, r.readout.readout_ms);
    // The zoom pass ran through the lens and the readout found before it.
    let mut stab = Stabilizer::new(&r.lens.camera, W, H, r.params.clone()).unwrap();
    stab.set_rendering(false);
    for (f, t) in &frames {
        stab.push(f.as_ref(), *t).unwrap();
    }
    while stab.finish().is_some() {}
    assert_eq!(r.static_zoom, Some(stab.max_zoom_need()));
}

#[test]
fn misuse_is_an_error_not_a_panic() {
    let f = frame(0.0);
    // No pass: no frames, nothing to finish.
    let mut plan = PassPlan::new(choices(known(), ReadoutSpec::FromLens)).unwrap();
    assert!(plan.push(f.as_ref(), 0.0).is_err());
    assert!(plan.finish_pass().is_err());
    // A pass without frames cannot be resolved; a plan with a pass left cannot finish.
    let mut plan = PassPlan::new(choices(known(), ReadoutSpec::Auto)).unwrap();
    assert!(plan.finish_pass().is_err());
    assert!(PassPlan::new(choices(known(), ReadoutSpec::Auto))
        .unwrap()
        .finish()
        .is_err());
}

/// Every output's telemetry of `stab` fed `frames` to the end.
fn telemetry_of(stab: &mut Stabilizer, frames: &[(Frame, f64)]) -> Vec<crate::Telemetry> {
    let mut seen = Vec::new();
    for (f, t) in frames {
        seen.extend(stab.push(f.as_ref(), *t).unwrap());
    }
    while let Some(tel) = stab.finish() {
        seen.push(tel);
    }
    seen
}

/// The zoom from given poses is the static-zoom pass's when the poses are
/// the tracker's own (a global shutter: no readout path to carry), and none
/// where the parameters need no such pass.
#[test]
fn the_posed_static_zoom_is_the_pass_s_zoom_for_the_tracker_s_poses() {
    let frames = clip(40);
    let cam = CameraModel::pinhole_hfov(W, H, 70.0).unwrap();
    let p = static_params(Mode::Stabilize);
    let mut stab = Stabilizer::new(&cam, W, H, p.clone()).unwrap();
    stab.set_rendering(false);
    let seen = telemetry_of(&mut stab, &frames);
    assert_eq!(seen.len(), frames.len());
    let need = stab.max_zoom_need();
    assert!(need > 1.0, "the shake needs some zoom ({need})");
    let posed = seen.iter().map(|tel| {
        let pose = crate::so3::exp(&nalgebra::Vector3::from(tel.r_est));
        let given = crate::stabilizer::GivenPose {
            pose,
            path: Default::default(),
            info: tel.track,
        };
        (tel.t, given)
    });
    let got = static_zoom_posed(&cam, W, H, &p, posed.clone()).unwrap();
    let got = got.expect("stabilize mode with zoom = static needs the pass");
    assert!((got - need).abs() < 1e-6, "{got} against {need}");
    for params in [StabilizerParams::default(), static_params(Mode::Saccade)] {
        assert_eq!(
            static_zoom_posed(&cam, W, H, &params, posed.clone()).unwrap(),
            None
        );
    }
}

/// Tracking only (a gyro run's first pass) reports the same poses, readout
/// paths and tracking as a stabilizer that frames without rendering, with
/// no view or zoom of its own.
#[test]
fn tracking_only_reports_the_tracker_s_motion() {
    let frames = clip(40);
    let cam = CameraModel::pinhole_hfov(W, H, 70.0).unwrap();
    let mut p = static_params(Mode::Stabilize);
    p.shutter.readout_ms = 8.0;
    let run = |only: bool| {
        let mut stab = Stabilizer::new(&cam, W, H, p.clone()).unwrap();
        if only {
            stab.set_tracking_only(true);
        } else {
            stab.set_rendering(false);
        }
        telemetry_of(&mut stab, &frames)
    };
    let (only, framed) = (run(true), run(false));
    assert_eq!(only.len(), frames.len());
    assert_eq!(only.len(), framed.len());
    for (a, b) in only.iter().zip(&framed) {
        assert_eq!((a.frame, a.t, a.r_est), (b.frame, b.t, b.r_est));
        assert_eq!(a.readout_rotation, b.readout_rotation);
        assert_eq!(a.track, b.track);
        assert_eq!((a.r_view, a.zoom), (a.r_est, 1.0));
    }
    assert!(
        framed.iter().any(|b| b.r_view != b.r_est),
        "the framed pass has a view"
    );
}
