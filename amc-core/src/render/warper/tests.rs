//! Unit tests of the warper's maps.

use super::buffers::RowMap;
use super::Warper;
use crate::camera::CameraModel;
use crate::shutter::fixtures;
use crate::shutter::{project_rolling, IntraFrame};
use crate::shutter::{LandingGrid, RollingProjector};
use crate::so3::{self, Tangent};
use nalgebra::{Matrix3, Vector2};

/// Every grid node of a rolling-shutter map is the fixed point of the
/// projection through the readout (within its tolerance), whichever row
/// it started from: the left neighbours' extrapolation, or none at a
/// row's start and next to nodes out of view.
#[test]
fn grid_nodes_are_the_rolling_fixed_point() {
    let cams = fixtures::cameras();
    let intra = fixtures::readout_motion();
    for src in &cams {
        let out = CameraModel::pinhole_hfov(240, 136, 70.0).unwrap();
        let warper = Warper::new(src, &out);
        let mut rows = RollingProjector::default();
        rows.set(&intra, src.height);
        // A turn that takes part of the view out of the frame.
        let m: Matrix3<f64> = *so3::exp(&Tangent::new(0.1, 0.5, 0.2)).matrix();
        let mut map = RowMap::default();
        warper.prepare_map(&mut map, &m, &rows, None);
        assert!(map.gridded);
        let (mut inside, mut outside) = (0, 0);
        for (ray, node) in warper.grid_rays.iter().zip(&map.grid) {
            // (Past the sensor's first and last rows the table holds the
            // end rows' rotations, where the exact path extrapolates: only
            // nodes that land on the sensor are sampled.)
            let on_sensor = |p: &Vector2<f64>| {
                (0.0..=(src.width - 1) as f64).contains(&p.x)
                    && (0.0..=(src.height - 1) as f64).contains(&p.y)
            };
            match project_rolling(src, &m, &intra, ray) {
                Some(p) if !on_sensor(&p) => outside += 1,
                Some(p) => {
                    let d =
                        ((node[0] as f64 - p.x).powi(2) + (node[1] as f64 - p.y).powi(2)).sqrt();
                    assert!(d < 1e-3, "node {node:?} vs fixed point {p}");
                    inside += 1;
                }
                None => {
                    assert!(node[0].is_nan(), "{node:?}");
                    outside += 1;
                }
            }
        }
        // (The 150 deg fisheye sees every node; the pinhole loses some.)
        let lost = if src.is_pinhole() { 10 } else { 0 };
        assert!(
            inside > 100 && outside >= lost,
            "{inside} nodes on the sensor, {outside} not"
        );
        // Looked up in the frame's landing map instead: the same nodes
        // within the map's interpolation error wherever they land on
        // the sensor (0.01 px for this 8.7 deg turn across the readout,
        // more than 300 deg/s turns through 20 ms), and none made up
        // where the lens sees nothing.
        let mut landing = LandingGrid::default();
        landing.set(&rows, src);
        let mut looked_up = RowMap::default();
        warper.prepare_map(&mut looked_up, &m, &rows, Some(&landing));
        let on_sensor = |p: &[f32; 2]| {
            (0.0..=(src.width - 1) as f32).contains(&p[0])
                && (0.0..=(src.height - 1) as f32).contains(&p[1])
        };
        let mut compared = 0;
        for (exact, node) in map.grid.iter().zip(&looked_up.grid) {
            assert_eq!(exact[0].is_nan(), node[0].is_nan());
            if on_sensor(exact) {
                let d = (exact[0] - node[0]).hypot(exact[1] - node[1]);
                assert!(d < 1e-2, "looked up {node:?} vs {exact:?}");
                compared += 1;
            }
        }
        assert_eq!(compared, inside);
    }
}

/// A frame keeps its landing map while it stays in the averaging window
/// (found again one place further on), gets one at its first averaged
/// map, and a frame that arrives starts without one.
#[test]
fn landing_maps_follow_their_frames() {
    let src = CameraModel::fisheye_hfov(320, 180, 150.0, [0.05, -0.01, 0.002, -0.0005]).unwrap();
    let frames: Vec<RollingProjector> = (0..4)
        .map(|k| {
            let intra = IntraFrame {
                phi: Tangent::new(0.02 * (k + 1) as f64, -0.01, 0.005),
                ..IntraFrame::default()
            };
            let mut rows = RollingProjector::default();
            rows.set(&intra, src.height);
            rows
        })
        .collect();
    let identity = [Matrix3::identity(); 3];
    let out = CameraModel::pinhole_hfov(160, 90, 70.0).unwrap();
    let mut warper = Warper::new(&src, &out);
    let built = |w: &Warper| w.landing.iter().map(|g| !g.is_empty()).collect::<Vec<_>>();
    warper.set_readout_rows(&frames[..3]);
    assert_eq!(built(&warper), [false; 3]);
    warper.prepare_maps(&identity);
    assert_eq!(built(&warper), [true; 3]);
    let first = warper.landing[1].clone();
    // The window moves on by one frame: the two that stay keep theirs,
    // the new one has none until it is mapped.
    warper.set_readout_rows(&frames[1..4]);
    assert_eq!(warper.readout_rows(), &frames[1..4]);
    assert_eq!(built(&warper), [true, true, false]);
    let p = Vector2::new(150.0, 80.0);
    assert_eq!(warper.landing[0].land(&p), first.land(&p));
    warper.prepare_maps(&identity);
    assert_eq!(built(&warper), [true; 3]);
    // One frame alone (a saccade slot) gets none.
    warper.set_readout_rows(&frames[..1]);
    warper.prepare_maps(&identity[..1]);
    assert_eq!(built(&warper), [false]);
    // Nor do a global shutter's frames.
    warper.set_readout_rows(&[RollingProjector::default(), RollingProjector::default()]);
    warper.prepare_maps(&identity[..2]);
    assert_eq!(built(&warper), [false, false]);
}
