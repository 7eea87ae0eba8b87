//! The vectorized paths against the scalar reference, and warping round trips.

use super::kernels::FRAME_PADDING;
use super::*;
use crate::camera::CameraModel;
use crate::image::{Frame, PixelFormat};
use crate::so3::{self, Tangent};
use nalgebra::Matrix3;

fn noise_frame(w: usize, h: usize, format: PixelFormat, seed: u64) -> Frame {
    let mut f = Frame::new(w, h, format);
    let mut s = seed;
    for b in f.data.iter_mut() {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *b = (s >> 56) as u8;
    }
    f.data.extend_from_slice(&[0; FRAME_PADDING]);
    f
}

#[test]
fn rounding_the_output_size_never_stretches() {
    // 320x180 with 12.5% margins crops 240x135, rounded to 240x136.
    let src = CameraModel::pinhole_hfov(320, 180, 90.0).unwrap();
    let out = RenderParams::default().output_camera(&src).unwrap();
    assert_eq!((out.width, out.height), (240, 136));
    assert_eq!((out.fx, out.fy), (src.fx, src.fy));
    // One explicit dimension scales both axes alike.
    let p = RenderParams {
        output_width: Some(480),
        ..RenderParams::default()
    };
    let out = p.output_camera(&src).unwrap();
    assert_eq!((out.width, out.height), (480, 270));
    assert!((out.fx / src.fx - 2.0).abs() < 1e-12 && (out.fy / src.fy - 2.0).abs() < 1e-12);
}

fn render(src: &CameraModel, vectorized: bool, format: PixelFormat) -> (Vec<u8>, Vec<u8>, f64) {
    let out = RenderParams::default().output_camera(src).unwrap();
    let mut warper = Warper::new(src, &out);
    warper.set_vectorized(vectorized);
    let frames: Vec<Frame> = (0..4)
        .map(|i| noise_frame(src.width, src.height, format, i))
        .collect();
    let rots: Vec<Matrix3<f64>> = (0..4)
        .map(|i| *so3::exp(&Tangent::new(0.06 * i as f64, -0.1, 0.05 * i as f64)).matrix())
        .collect();
    let mut img = vec![0u8; out.width * out.height * format.channels()];
    let mut cov = Vec::new();
    let vf = warper.average_into(
        |i| frames[i].as_ref(),
        &rots,
        &mut img,
        format.channels(),
        &mut cov,
    );
    (img, cov, vf)
}

/// The AVX2 kernel must be bit-exact with the scalar sampler.
#[test]
fn vectorized_matches_scalar() {
    for format in [PixelFormat::Rgb8, PixelFormat::Rgba8] {
        let pinhole = CameraModel::pinhole_hfov(203, 117, 80.0).unwrap();
        let mut fisheye = CameraModel::pinhole_hfov(203, 117, 80.0).unwrap();
        fisheye.distortion = crate::camera::Distortion::Fisheye {
            k1: 0.05,
            k2: -0.01,
            k3: 0.0,
            k4: 0.0,
        };
        for cam in [pinhole, fisheye] {
            let a = render(&cam, false, format);
            let b = render(&cam, true, format);
            if let Some(i) = a.0.iter().zip(&b.0).position(|(x, y)| x != y) {
                let c = format.channels();
                panic!(
                    "pixel {} ch {}: scalar {} simd {} (cov {} vs {})",
                    i / c,
                    i % c,
                    a.0[i],
                    b.0[i],
                    a.1[i / c],
                    b.1[i / c]
                );
            }
            assert_eq!(a.0, b.0);
            assert_eq!(a.1, b.1);
            assert_eq!(a.2, b.2);
            assert!(
                a.2 < 1.0 && a.2 > 0.5,
                "rotations should leave some border: {}",
                a.2
            );
        }
    }
}

/// The vectorized saccade slot equals the scalar reference.
#[test]
fn slot_matches_scalar_reference() {
    let cam = CameraModel::pinhole_hfov(211, 119, 75.0).unwrap();
    let params = RenderParams {
        output_width: Some(150),
        ..Default::default()
    };
    let out = params.output_camera(&cam).unwrap();
    let f = noise_frame(211, 119, PixelFormat::Rgb8, 3);
    let m = *so3::exp(&Tangent::new(0.05, -0.08, 0.1)).matrix();
    let mut warper = Warper::new(&cam, &out);
    let (mut a, mut b) = (WarpedFrame::default(), WarpedFrame::default());
    warper.warp_into_slot(&f.as_ref(), &m, &mut a, 7);
    b.fill(&mut warper, &f.as_ref(), &m, 7);
    assert_eq!(a.covered, b.covered);
    assert_eq!(a.value, b.value);
    assert!(a.covered.iter().any(|&c| c == 0) && a.covered.iter().any(|&c| c == 1));
}

/// Warping by R then by R^T gives the image back (inside the common area).
#[test]
fn warp_then_inverse_restores_image() {
    let cam = CameraModel::pinhole_hfov(160, 120, 70.0).unwrap();
    let params = RenderParams {
        margin: 0.0,
        ..Default::default()
    };
    let out = params.output_camera(&cam).unwrap();
    // A smooth image (bilinear resampling is exact on linear ramps).
    let mut f = Frame::new(160, 120, PixelFormat::Rgb8);
    for v in 0..120 {
        for u in 0..160 {
            let i = 3 * (v * 160 + u);
            f.data[i] = (u + v / 2) as u8;
            f.data[i + 1] = (2 * v) as u8;
            f.data[i + 2] = 128;
        }
    }
    f.data.extend_from_slice(&[0; FRAME_PADDING]);
    let r = so3::exp(&Tangent::new(0.02, -0.03, 0.05));
    let mut warper = Warper::new(&cam, &out);
    let mut once = vec![0u8; 160 * 120 * 3];
    let mut cov = Vec::new();
    warper.average_into(|_| f.as_ref(), &[*r.matrix()], &mut once, 3, &mut cov);
    let mut g = Frame {
        width: 160,
        height: 120,
        format: PixelFormat::Rgb8,
        data: once,
    };
    g.data.extend_from_slice(&[0; FRAME_PADDING]);
    let mut back = vec![0u8; 160 * 120 * 3];
    let mut cov2 = Vec::new();
    warper.average_into(
        |_| g.as_ref(),
        &[*r.transpose().matrix()],
        &mut back,
        3,
        &mut cov2,
    );
    let (mut err, mut n) = (0f64, 0);
    for v in 20..100 {
        for u in 25..135 {
            let i = v * 160 + u;
            if cov[i] > 0 && cov2[i] > 0 {
                for c in 0..3 {
                    err += (back[3 * i + c] as f64 - f.data[3 * i + c] as f64).abs();
                    n += 1;
                }
            }
        }
    }
    assert!(n > 20000);
    assert!(err / (n as f64) < 1.0, "mean abs error {}", err / n as f64);
}
