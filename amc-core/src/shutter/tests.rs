//! Identities of the rolling-shutter model.

use super::fixtures;
use super::*;
use crate::so3::{self, Tangent};
use nalgebra::{Matrix3, Vector3};

/// The projected pixel is the fixed point: the row it lands on, read at its
/// own time, sees the ray there (pinhole and fisheye).
#[test]
fn projection_lands_on_its_own_rows_time() {
    let cams = fixtures::cameras();
    let intra = fixtures::readout_motion();
    let m: Matrix3<f64> = *so3::exp(&Tangent::new(0.1, -0.2, 0.05)).matrix();
    for cam in &cams {
        for &(x, y) in &[(0.0, 0.0), (0.4, -0.3), (-0.5, 0.4), (0.2, 0.5)] {
            let ray = Vector3::new(x, y, 1.0);
            let p = project_rolling(cam, &m, &intra, &ray).expect("in view");
            let s = row_fraction(p.y, cam.height);
            let q = cam
                .project(&(intra.rotation_at(s).inverse() * (m * ray)))
                .unwrap();
            assert!((p - q).norm() < 1e-3, "{p} vs {q}");
        }
        // The tabulated projector agrees.
        let mut table = RollingProjector::default();
        table.set(&intra, cam.height);
        for &(x, y) in &[(0.0, 0.0), (0.4, -0.3), (-0.5, 0.4)] {
            let ray = Vector3::new(x, y, 1.0);
            let p = project_rolling(cam, &m, &intra, &ray).unwrap();
            let q = table.project(cam, &(m * ray), None).unwrap();
            let r = table.project(cam, &(m * ray), Some(p.y + 3.0)).unwrap();
            assert!((p - r).norm() < 1e-4, "{p} vs {r}");
            assert!((p - q).norm() < 1e-4, "{p} vs {q}");
        }
        // A global shutter is the plain projection.
        let ray = Vector3::new(0.3, 0.2, 1.0);
        assert_eq!(
            project_rolling(cam, &m, &IntraFrame::ZERO, &ray),
            cam.project(&(m * ray))
        );
    }
}

#[test]
fn readout_range_is_checked() {
    assert!(ShutterParams { readout_ms: 0.0 }.validate().is_ok());
    assert!(ShutterParams { readout_ms: 33.0 }.validate().is_ok());
    for bad in [-1.0, 100.5, f64::NAN, f64::INFINITY] {
        assert!(
            ShutterParams { readout_ms: bad }.validate().is_err(),
            "{bad}"
        );
    }
}
