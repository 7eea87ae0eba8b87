use super::*;
use crate::camera::CameraModel;
use crate::so3::{self, Rot, Tangent};
use nalgebra::Matrix3;

fn pinhole() -> CameraModel {
    CameraModel::pinhole_hfov(320, 180, 60.0).unwrap()
}

fn rots(window: &[Rot], view: &Rot) -> Vec<Matrix3<f64>> {
    window
        .iter()
        .map(|r| r.matrix().transpose() * view.matrix())
        .collect()
}

#[test]
fn the_camera_itself_needs_no_zoom() {
    let cam = pinhole();
    let border = Border::new(&cam);
    let need = needed_zoom(&cam, &border, &[Matrix3::identity()], &[]);
    // The edge allowance of EDGE_PX source pixels, nothing more.
    let e = coverage_edge();
    let expected = (159.5 / (159.5 - e)).max(89.5 / (89.5 - e));
    assert!((need - expected).abs() < 1e-3, "{need} vs {expected}");
}

fn coverage_edge() -> f64 {
    super::coverage::EDGE_PX
}

#[test]
fn a_pan_needs_the_zoom_that_hides_it() {
    // A pure pan by angle a moves the frame's edge: the output's half-width
    // x = tan(hfov / 2) must shrink so that the far side, rotated by a, stays inside.
    let cam = pinhole();
    let border = Border::new(&cam);
    let a = 3f64.to_radians();
    let view = so3::exp(&Tangent::new(0.0, a, 0.0));
    let need = needed_zoom(&cam, &border, &rots(&[Rot::identity()], &view), &[]);
    // Edge of the source (2 px inside), normalized: (159.5 - 2) / fx.
    let edge = (159.5 - coverage_edge()) / cam.fx;
    let half = 159.5 / cam.fx;
    // Output point x maps to tan(atan(x) + a) (a turn to the right).
    let x = (edge.atan() - a).tan();
    let expected = half / x;
    assert!(
        (need - expected).abs() / expected < 2e-3,
        "{need} vs {expected}"
    );
}

#[test]
fn the_union_of_frames_counts() {
    // Two frames turned to either side cover together what neither covers alone.
    let cam = pinhole();
    let border = Border::new(&cam);
    let a = 4f64.to_radians();
    let left = so3::exp(&Tangent::new(0.0, -a, 0.0));
    let right = so3::exp(&Tangent::new(0.0, a, 0.0));
    let view = Rot::identity();
    let one = needed_zoom(&cam, &border, &rots(&[left], &view), &[]);
    let both = needed_zoom(&cam, &border, &rots(&[left, right], &view), &[]);
    assert!(both < one, "{both} vs {one}");
    assert!(both >= 1.0);
}

#[test]
fn an_uncovered_centre_needs_more_than_any_zoom() {
    let cam = pinhole();
    let border = Border::new(&cam);
    let view = so3::exp(&Tangent::new(0.0, 1.2, 0.0));
    let need = needed_zoom(&cam, &border, &rots(&[Rot::identity()], &view), &[]);
    assert_eq!(need, super::coverage::NO_ZOOM_SUFFICES);
}

#[test]
fn pulling_keeps_the_view_within_the_zoom_and_moves_it_least() {
    let cam = pinhole();
    let border = Border::new(&cam);
    let camera = so3::exp(&Tangent::new(0.02, 0.05, 0.01));
    let view = Rot::identity();
    let mut scratch = Vec::new();
    let zoom = 1.1;
    let (pulled, need) = pull_view(
        &cam,
        &border,
        &[camera],
        &[],
        &view,
        &camera,
        zoom,
        &mut scratch,
    );
    assert!(need <= zoom + 1e-9, "{need}");
    let before = needed_zoom(&cam, &border, &rots(&[camera], &view), &[]);
    assert!(
        before > zoom,
        "the test needs a view out of the budget: {before}"
    );
    // On the geodesic, and not much further than needed: a slightly smaller
    // pull is out of the budget.
    let w = so3::log(&(view.transpose() * camera));
    let a = so3::angle_between(&view, &pulled) / w.norm();
    let less = view * so3::exp(&(w * (a - 0.01)));
    assert!(needed_zoom(&cam, &border, &rots(&[camera], &less), &[]) > zoom);
    // Already within: untouched.
    let (same, _) = pull_view(
        &cam,
        &border,
        &[camera],
        &[],
        &camera,
        &camera,
        zoom,
        &mut scratch,
    );
    assert_eq!(same, camera);
}

#[test]
fn the_zoom_rises_and_falls_at_bounded_rates_and_holds() {
    let params = FramingParams::default();
    let z_max = params.max_zoom();
    let mut framer = Framer::new(params);
    let dt = 1.0 / 30.0;
    let mut prev = framer.next(0.0, 1.0);
    assert!((prev - z_max).abs() < 1e-12, "starts at the budget");
    let mut zooms = Vec::new();
    for j in 1..600 {
        let t = j as f64 * dt;
        // A sudden need for the budget between 10 s and 10.1 s.
        let need = if (10.0..10.1).contains(&t) { 1.5 } else { 1.02 };
        let z = framer.next(t, need);
        assert!((z - prev).abs() <= ZOOM_RISE_PER_S * dt + 1e-12);
        assert!(z - prev >= -ZOOM_FALL_PER_S * dt - 1e-12);
        assert!((1.0..=z_max).contains(&z));
        zooms.push((t, z));
        prev = z;
    }
    let at = |t: f64| zooms.iter().find(|&&(tt, _)| tt >= t).unwrap().1;
    assert!(
        (at(9.9) - 1.02).abs() < 1e-9,
        "eased out to the need: {}",
        at(9.9)
    );
    assert!((at(10.6) - z_max).abs() < 1e-9, "rose to the budget");
    assert!((at(11.0) - z_max).abs() < 1e-9, "held for a second");
    assert!(at(12.0) < z_max && at(12.0) > 1.05, "eases out slowly");
}

#[test]
fn fixed_and_none_zooms() {
    let mut framer = Framer::new(FramingParams::default());
    framer.set_fixed(1.08);
    assert_eq!(framer.next(0.0, 1.5), 1.08);
    assert_eq!(framer.next(1.0, 1.0), 1.08);
    let mut none = Framer::new(FramingParams {
        zoom: Zoom::None,
        ..Default::default()
    });
    assert_eq!(none.next(0.0, 3.0), 1.0);
    assert!("STATIC".parse::<Zoom>().unwrap() == Zoom::Static);
    assert!("wide".parse::<Zoom>().is_err());
    assert!(FramingParams {
        max_crop: 0.6,
        ..Default::default()
    }
    .validate()
    .is_err());
}
