//! The vectorized paths against the scalar reference, and warping round trips.

use super::kernels::FRAME_PADDING;
use super::*;
use crate::camera::CameraModel;
use crate::image::{Frame, PixelFormat};
use crate::shutter::{IntraFrame, RollingProjector};
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
    render_rolling(src, vectorized, format, false, None)
}

/// [`render`], with a rolling shutter's readout motion on every frame when
/// `rolling`, averaged without ghosts with `deghost`.
fn render_rolling(
    src: &CameraModel,
    vectorized: bool,
    format: PixelFormat,
    rolling: bool,
    deghost: Option<Deghost>,
) -> (Vec<u8>, Vec<u8>, f64) {
    let out = RenderParams::default().output_camera(src).unwrap();
    let mut warper = Warper::new(src, &out);
    warper.set_vectorized(vectorized);
    warper.set_deghost(deghost);
    if rolling {
        let rows: Vec<RollingProjector> = (0..4)
            .map(|i| {
                let intra = IntraFrame {
                    phi: Tangent::new(0.03, -0.02 * i as f64, 0.01),
                    psi: Tangent::new(-0.01, 0.005, 0.002 * i as f64),
                    chi: Tangent::new(0.002, 0.0, -0.001),
                    xi: Tangent::new(0.0, -0.001, 0.0005),
                };
                let mut p = RollingProjector::default();
                p.set(&intra, src.height);
                p
            })
            .collect();
        warper.set_readout_rows(&rows);
    }
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

/// The AVX2 kernel must be bit-exact with the scalar sampler, with a global
/// and a rolling shutter.
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
        for (cam, rolling) in [
            (&pinhole, false),
            (&fisheye, false),
            (&pinhole, true),
            (&fisheye, true),
        ] {
            let a = render_rolling(cam, false, format, rolling, None);
            let b = render_rolling(cam, true, format, rolling, None);
            if rolling {
                // The readout motion moves the picture.
                assert_ne!(a.0, render(cam, false, format).0);
            }
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

/// The ghost-free average: the vectorized kernels against the scalar reference
/// (interleaved and planar, pinhole and fisheye, global and rolling shutter),
/// output widths that leave a scalar tail; and it differs from the plain average.
#[test]
fn ghost_free_vectorized_matches_scalar() {
    // Noise frames differ by up to 255 levels: 60 gives weights from 0 to 16.
    let deghost = Deghost::new(60.0);
    // 211 px: the output (158 px) leaves a scalar tail of 6 pixels per row.
    let pinhole = CameraModel::pinhole_hfov(211, 117, 80.0).unwrap();
    let mut fisheye = pinhole.clone();
    fisheye.distortion = crate::camera::Distortion::Fisheye {
        k1: 0.05,
        k2: -0.01,
        k3: 0.0,
        k4: 0.0,
    };
    for format in [PixelFormat::Rgb8, PixelFormat::Rgba8] {
        for (cam, rolling) in [(&pinhole, false), (&fisheye, false), (&pinhole, true)] {
            let a = render_rolling(cam, false, format, rolling, deghost);
            let b = render_rolling(cam, true, format, rolling, deghost);
            assert_eq!(a, b, "{format:?} rolling {rolling}");
            let plain = render_rolling(cam, true, format, rolling, None);
            assert_ne!(a.0, plain.0);
            // Coverage counts frames, whatever their weights.
            assert_eq!(a.1, plain.1);
        }
    }
    for cam in [&pinhole, &fisheye] {
        let a = render_planar_deghost(cam, false, 1.0, deghost);
        let b = render_planar_deghost(cam, true, 1.0, deghost);
        assert_eq!(a, b);
        assert_ne!(a.0, render_planar(cam, true, 1.0).0);
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

/// Renders four noise frames' planes (Y through `src`, U and V through the
/// chroma cameras) with the scalar or vectorized kernel.
fn render_planar(src: &CameraModel, vectorized: bool, spin: f64) -> (Vec<u8>, Vec<u8>, usize) {
    render_planar_deghost(src, vectorized, spin, None)
}

/// [`render_planar`], averaged without ghosts with `deghost`.
fn render_planar_deghost(
    src: &CameraModel,
    vectorized: bool,
    spin: f64,
    deghost: Option<Deghost>,
) -> (Vec<u8>, Vec<u8>, usize) {
    let out = RenderParams::default().output_camera(src).unwrap();
    let (sc, oc) = (chroma_camera(src), chroma_camera(&out));
    let mut luma = Warper::new(src, &out);
    let mut chroma = Warper::new(&sc, &oc);
    luma.set_vectorized(vectorized);
    chroma.set_vectorized(vectorized);
    luma.set_deghost(deghost);
    chroma.set_deghost(deghost);
    let frames: Vec<Frame> = (0..4)
        .map(|i| {
            let mut f = noise_frame(src.width, src.height, PixelFormat::Rgb8, i + 10);
            let len = PixelFormat::Yuv420p
                .buffer_len(src.width, src.height)
                .unwrap();
            f.format = PixelFormat::Yuv420p;
            f.data.truncate(len);
            f.data.extend_from_slice(&[0; FRAME_PADDING]);
            f
        })
        .collect();
    let rots: Vec<Matrix3<f64>> = (0..4)
        .map(|i| {
            let i = i as f64;
            *so3::exp(&(spin * Tangent::new(0.1 * i, 0.3, -0.04 * i))).matrix()
        })
        .collect();
    let mut img = Frame::new(out.width, out.height, PixelFormat::Yuv420p);
    let (n, nc) = (src.width * src.height, sc.width * sc.height);
    let (oy, ou, ov) = crate::image::yuv_planes_mut(out.width, out.height, &mut img.data);
    let (mut cov, mut ccov) = (Vec::new(), Vec::new());
    let full = luma.average_plane_into(
        |i| &frames[i].data,
        src.width,
        src.height,
        &rots,
        oy,
        &mut cov,
        16,
    );
    // U and V as a pair (one pass of the vector kernels; the scalar and
    // ghost-free paths take them in turn).
    let chroma_full = chroma.average_plane_pair_into(
        |i| (&frames[i].data[n..], &frames[i].data[n + nc..]),
        sc.width,
        sc.height,
        &rots,
        ou,
        ov,
        &mut ccov,
        128,
    );
    assert_eq!(
        chroma_full,
        ccov.iter().filter(|&&c| c as usize == rots.len()).count()
    );
    (img.data, cov, full)
}

/// The planar kernels are bit-exact with the scalar sampler, for pinhole and
/// distorted sources and odd sizes (chroma planes of `ceil` halves).
#[test]
fn planar_vectorized_matches_scalar() {
    let pinhole = CameraModel::pinhole_hfov(203, 117, 80.0).unwrap();
    let mut fisheye = pinhole.clone();
    fisheye.distortion = crate::camera::Distortion::Fisheye {
        k1: 0.05,
        k2: -0.01,
        k3: 0.0,
        k4: 0.0,
    };
    for cam in [pinhole.clone(), fisheye.clone()] {
        // Small turns: most lanes take the kernel's gather-free window path.
        for spin in [0.01, 0.05] {
            assert_eq!(
                render_planar(&cam, false, spin),
                render_planar(&cam, true, spin)
            );
        }
    }
    for cam in [pinhole, fisheye] {
        let a = render_planar(&cam, false, 1.0);
        let b = render_planar(&cam, true, 1.0);
        assert_eq!(a, b);
        let px = a.1.len();
        assert!(
            a.2 > px / 2 && a.2 < px,
            "some border expected: {} of {px}",
            a.2
        );
        // Uncovered luma is black (16).
        assert!(a.1.contains(&0), "a view turned 17 degrees leaves a border");
        assert!(a.1.iter().zip(&a.0).all(|(&c, &y)| c > 0 || y == 16));
    }
}

/// A smooth colour image rendered as RGB and as 4:2:0 planes with the same
/// rotations agrees after conversion to within rounding (the promise of the
/// planar path: same picture, half the samples).
#[test]
fn planar_render_matches_rgb_render() {
    use crate::color::{rgb_to_yuv420p_into, yuv420p_to_rgb_into};
    let cam = CameraModel::pinhole_hfov(240, 136, 75.0).unwrap();
    let out = RenderParams::default().output_camera(&cam).unwrap();
    let mut rgb = Frame::new(240, 136, PixelFormat::Rgb8);
    for v in 0..136 {
        for u in 0..240 {
            let i = 3 * (v * 240 + u);
            let (x, y) = (u as f64 / 240.0, v as f64 / 136.0);
            rgb.data[i] = (128.0 + 100.0 * (6.0 * x).sin() * (4.0 * y).cos()) as u8;
            rgb.data[i + 1] = (40.0 + 180.0 * y) as u8;
            rgb.data[i + 2] = (200.0 - 150.0 * x * y) as u8;
        }
    }
    let mut yuv = Frame::new(240, 136, PixelFormat::Yuv420p);
    rgb_to_yuv420p_into(240, 136, 3, &rgb.data, &mut yuv.data);
    rgb.data.extend_from_slice(&[0; FRAME_PADDING]);
    yuv.data.extend_from_slice(&[0; FRAME_PADDING]);
    let rots: Vec<Matrix3<f64>> = (0..3)
        .map(|i| *so3::exp(&Tangent::new(0.01 * i as f64, -0.02, 0.03)).matrix())
        .collect();
    let mut warper = Warper::new(&cam, &out);
    let (mut out_rgb, mut cov) = (vec![0u8; out.width * out.height * 3], Vec::new());
    warper.average_into(|_| rgb.as_ref(), &rots, &mut out_rgb, 3, &mut cov);
    let mut chroma = Warper::new(&chroma_camera(&cam), &chroma_camera(&out));
    let mut out_yuv = Frame::new(out.width, out.height, PixelFormat::Yuv420p);
    let (n, nc) = (240 * 136, 120 * 68);
    let (oy, ou, ov) = crate::image::yuv_planes_mut(out.width, out.height, &mut out_yuv.data);
    let mut c2 = Vec::new();
    warper.average_plane_into(|_| &yuv.data, 240, 136, &rots, oy, &mut c2, 16);
    chroma.average_plane_into(|_| &yuv.data[n..], 120, 68, &rots, ou, &mut Vec::new(), 128);
    chroma.average_plane_into(
        |_| &yuv.data[n + nc..],
        120,
        68,
        &rots,
        ov,
        &mut Vec::new(),
        128,
    );
    assert_eq!(cov, c2, "both paths cover the same luma pixels");
    let mut back = Vec::new();
    yuv420p_to_rgb_into(out.width, out.height, &out_yuv.data, false, 3, &mut back);
    let (mut se, mut k) = (0f64, 0usize);
    for (i, &c) in cov.iter().enumerate() {
        if c == rots.len() as u8 {
            for ch in 0..3 {
                let d = back[3 * i + ch] as f64 - out_rgb[3 * i + ch] as f64;
                se += d * d;
                k += 1;
            }
        }
    }
    let psnr = 10.0 * (255.0f64 * 255.0 / (se / k as f64)).log10();
    assert!(
        k > 10_000 && psnr > 38.0,
        "PSNR {psnr:.1} dB over {k} samples"
    );
}

/// Rendering in bands on a rayon pool gives the same bytes as one thread.
#[cfg(feature = "parallel")]
#[test]
fn parallel_bands_match_one_thread() {
    let cam = CameraModel::pinhole_hfov(320, 180, 80.0).unwrap();
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let both = || {
        (
            render(&cam, true, PixelFormat::Rgb8),
            render_planar(&cam, true, 1.0),
        )
    };
    let one = pool(1).install(both);
    let four = pool(4).install(both);
    assert_eq!(one, four);
}
