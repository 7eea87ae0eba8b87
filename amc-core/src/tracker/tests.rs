//! Unit tests of the tracker: the Gauss-Newton step, the gauge of the readout
//! motion and the template handover, on images rendered through the core's
//! own camera model from a smooth texture on the sphere of view directions.

use super::gauge::GAUGE_FIRST_BLOCK;
use super::state::Pose;
use super::{Tracker, TrackerParams};
use crate::camera::CameraModel;
use crate::image::GrayImage;
use crate::pyramid::Pyramid;
use crate::shutter::{IntraFrame, RowTime};
use crate::so3::{self, Rot, Tangent};
use nalgebra::{Vector2, Vector3};

/// The tracking camera of every test: 320x180, 90 deg across.
fn camera() -> CameraModel {
    CameraModel::pinhole_hfov(320, 180, 90.0).unwrap()
}

/// Intensity (in `[0, 1]`) the scene shows along world direction `d`: a few
/// smooth waves over the sphere, textured at every pyramid level.
fn scene(d: &Vector3<f64>) -> f32 {
    let d = d.normalize();
    let (x, y, z) = (d.x, d.y, d.z);
    let v = 0.5
        + 0.12 * (11.0 * x + 2.0).sin() * (9.0 * y + 0.5).cos()
        + 0.1 * (23.0 * x - 17.0 * y + 1.0).sin()
        + 0.08 * (31.0 * y + 13.0 * z).cos()
        + 0.06 * (41.0 * x + 37.0 * y).sin();
    v as f32
}

/// The pyramid of the view of `cam` with orientation `r_0j` (camera to world,
/// the world being the first frame's camera), every pixel unprojected by the
/// camera model and turned into the world.
fn view(cam: &CameraModel, r_0j: &Rot, levels: usize) -> Pyramid {
    let mut img = GrayImage::new(cam.width, cam.height);
    for v in 0..cam.height {
        for u in 0..cam.width {
            let ray = cam
                .unproject(&Vector2::new(u as f64, v as f64))
                .expect("a pinhole sees every pixel");
            img.data[v * cam.width + u] = scene(&(r_0j * ray));
        }
    }
    let mut pyr = Pyramid { levels: vec![img] };
    pyr.rebuild(levels);
    pyr
}

/// Degrees between two orientations.
fn degrees_apart(a: &Rot, b: &Rot) -> f64 {
    so3::angle_between(a, b).to_degrees()
}

/// One inverse-compositional Gauss-Newton step from the template's own pose
/// recovers a small rotation of the view: the step is the rotation to first
/// order, so for 0.05 deg it is within 2% of it (axis and size); iterated to
/// convergence, the coarse-to-fine estimate is within 0.001 deg of a 1.5 deg
/// turn.
#[test]
fn gauss_newton_step_recovers_a_small_rotation() {
    let cam = camera();
    let mut tracker = Tracker::new(&cam, TrackerParams::default()).unwrap();
    let levels = tracker.levels();
    let truth = Tangent::new(0.0004, -0.0007, 0.0003);
    assert!((truth.norm().to_degrees() - 0.05).abs() < 0.01);
    tracker.set_template(&view(&cam, &Rot::identity(), levels));
    // `R_{k,j}`: the template (frame 0, the world) to the current frame.
    let moved = view(&cam, &so3::exp(&truth), levels);
    let start = Pose {
        r: Rot::identity(),
        intra: IntraFrame::ZERO,
    };
    let eval = tracker.evaluate(0, &moved.levels[0], &start, None);
    let step = eval
        .pose_step(&start, false, 0, None)
        .expect("a textured view gives a step");
    let after = step.apply(&start, 1.0);
    let error = so3::log(&(after.r * so3::exp(&truth).transpose()));
    assert!(
        error.norm() < 0.02 * truth.norm(),
        "step {:?} for {truth:?}: off by {:.2}%",
        step.delta,
        100.0 * error.norm() / truth.norm()
    );

    // The whole estimate of a larger turn (three axes, 1.5 deg).
    let truth = so3::exp(&Tangent::new(0.012, -0.02, 0.009));
    let (r_0j, info) = tracker.track(&view(&cam, &Rot::identity(), levels), 0.0);
    assert_eq!(r_0j, Rot::identity());
    assert!(info.template_reset);
    let (r_0j, info) = tracker.track(&view(&cam, &truth, levels), 1.0 / 60.0);
    let off = degrees_apart(&r_0j, &truth);
    assert!(!info.lost && info.valid_fraction > 0.8, "{info:?}");
    assert!(off < 1e-3, "tracked {off} deg off after {info:?}");
}

/// The first frame is the reference: its orientation is the identity and it
/// becomes the template, whatever it shows.
#[test]
fn first_frame_is_the_identity() {
    let cam = camera();
    let mut tracker = Tracker::new(&cam, TrackerParams::default()).unwrap();
    let levels = tracker.levels();
    let turned = so3::exp(&Tangent::new(0.1, -0.2, 0.05));
    let (r, info) = tracker.track(&view(&cam, &turned, levels), 3.0);
    assert_eq!(r, Rot::identity());
    assert!(info.template_reset && !info.lost);
    assert_eq!(tracker.intra(), IntraFrame::ZERO);
    assert!(!tracker.gauge_known());
}

/// The gauge check removes a known offset of the readout paths: frames whose
/// `phi` is the readout time times their rate plus `c` (and whose `psi`,
/// `chi`, `xi` are `c`'s) have `c` taken out of the path at the end of the
/// first block ([`GAUGE_FIRST_BLOCK`] frames), and from every later estimate
/// against the template (its gauge); the corrections add up to `c`, and the
/// next block is twice as long.
#[test]
fn gauge_check_removes_a_known_offset() {
    let cam = camera();
    let mut tracker = Tracker::new(&cam, TrackerParams::default()).unwrap();
    let readout_s = 0.02;
    tracker.set_rolling(RowTime::new(&cam, &cam), readout_s);
    let c = IntraFrame {
        phi: Tangent::new(0.003, -0.002, 0.001),
        psi: Tangent::new(-0.001, 0.0005, 0.0),
        chi: Tangent::new(0.0002, 0.0, -0.0004),
        xi: Tangent::new(0.0, 0.0001, 0.0),
    };
    let mut path = IntraFrame::ZERO;
    for k in 0..GAUGE_FIRST_BLOCK {
        // A different rate per frame: the offset is what they share.
        let rate = Tangent::new(0.5 + 0.1 * k as f64, -0.3, 0.2 * (k as f64).sin());
        tracker.rate = rate;
        path = IntraFrame {
            phi: rate * readout_s,
            ..IntraFrame::ZERO
        }
        .plus(&c, 1.0);
        tracker.intra = path;
        let done = tracker.check_gauge();
        assert_eq!(done, k + 1 == GAUGE_FIRST_BLOCK, "frame {k}");
    }
    let close = |a: &IntraFrame, b: &IntraFrame| {
        a.terms()
            .iter()
            .zip(b.terms())
            .all(|(x, y)| (x - y).norm() < 1e-12)
    };
    assert!(close(&tracker.intra(), &path.plus(&c, -1.0)));
    assert!(close(&tracker.gauge_tpl, &c));
    assert!(close(&tracker.gauge_corrections(), &c));
    assert_eq!(tracker.gauge.block, 2 * GAUGE_FIRST_BLOCK);
    assert_eq!(tracker.gauge.count, 0);
}

/// The template handover keeps the chained orientation continuous: tracked
/// through a known rotation sequence with a template reset every third
/// frame, every frame is within 0.005 deg of the truth even when each new
/// template's orientation is knocked 0.3 deg off right after its reset, since
/// the frame after it, tracked against the outgoing template too, puts the
/// new template back in line.
#[test]
fn handover_keeps_the_chained_orientation_continuous() {
    let cam = camera();
    let params = TrackerParams {
        n_track: 3,
        ..TrackerParams::default()
    };
    let mut tracker = Tracker::new(&cam, params).unwrap();
    let levels = tracker.levels();
    // A turn about an axis that wanders, 0.4-0.6 deg per frame.
    let truth: Vec<Rot> = (0..14)
        .scan(Rot::identity(), |r, j| {
            let j = j as f64;
            let step = Tangent::new(0.004 * (0.7 * j).cos(), 0.008, 0.003 * (0.3 * j).sin());
            let now = *r;
            *r *= so3::exp(&step);
            Some(now)
        })
        .collect();
    let knock = so3::exp(&Tangent::new(0.0, 0.0, 0.3f64.to_radians()));
    let (mut resets, mut worst) = (0, 0f64);
    for (j, r) in truth.iter().enumerate() {
        let (r_0j, info) = tracker.track(&view(&cam, r, levels), j as f64 / 60.0);
        assert!(!info.lost, "frame {j}: {info:?}");
        let off = degrees_apart(&r_0j, r);
        worst = worst.max(off);
        assert!(off < 5e-3, "frame {j}: {off} deg off the truth ({info:?})");
        if info.template_reset && j > 0 {
            // The new template's orientation, as a biased estimate would leave it.
            tracker.r_0k *= knock;
            assert!(tracker.handover.is_some());
            resets += 1;
        }
    }
    assert!(resets >= 3, "{resets} template resets");
    eprintln!("worst {worst:.5} deg over {} frames", truth.len());
}
