//! The vectorized paths against the scalar reference, and warping round trips.

use super::kernels::{Geometry, FRAME_PADDING};
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

/// Four frames' readout motions (a few degrees over the readout) for frames
/// `height` rows high.
fn readout_rows(height: usize) -> Vec<RollingProjector> {
    (0..4)
        .map(|i| {
            let intra = IntraFrame {
                phi: Tangent::new(0.03, -0.02 * i as f64, 0.01),
                psi: Tangent::new(-0.01, 0.005, 0.002 * i as f64),
                chi: Tangent::new(0.002, 0.0, -0.001),
                xi: Tangent::new(0.0, -0.001, 0.0005),
            };
            let mut p = RollingProjector::default();
            p.set(&intra, height);
            p
        })
        .collect()
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
        warper.set_readout_rows(&readout_rows(src.height));
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
/// The kernel tests' cameras: an 80 deg pinhole `width` x 117 (odd sizes, so
/// that rows end in scalar tails), and the same behind a fisheye lens.
fn pinhole_and_fisheye(width: usize) -> (CameraModel, CameraModel) {
    let pinhole = CameraModel::pinhole_hfov(width, 117, 80.0).unwrap();
    let mut fisheye = pinhole.clone();
    fisheye.distortion = crate::camera::Distortion::Fisheye {
        k1: 0.05,
        k2: -0.01,
        k3: 0.0,
        k4: 0.0,
    };
    (pinhole, fisheye)
}

#[test]
fn vectorized_matches_scalar() {
    for format in [PixelFormat::Rgb8, PixelFormat::Rgba8] {
        let (pinhole, fisheye) = pinhole_and_fisheye(203);
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
    let (pinhole, fisheye) = pinhole_and_fisheye(211);
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
    let mut values = Vec::new();
    for interpolation in [Interpolation::Bilinear, Interpolation::Bicubic] {
        let mut warper = Warper::new(&cam, &out);
        warper.set_interpolation(interpolation);
        let (mut a, mut b) = (WarpedFrame::default(), WarpedFrame::default());
        warper.warp_into_slot(&f.as_ref(), &m, &mut a, 7);
        b.fill(&mut warper, &f.as_ref(), &m, 7);
        assert_eq!(a.covered, b.covered);
        assert_eq!(a.value, b.value, "{interpolation}");
        assert!(a.covered.contains(&0) && a.covered.contains(&1));
        values.push(a.value);
    }
    assert_ne!(values[0], values[1]);
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
    let (pinhole, fisheye) = pinhole_and_fisheye(203);
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
    // And supersampled (the blocks are averaged in bands too).
    let view = CameraModel::pinhole(160, 90, cam.fx / 2.0, cam.fy / 2.0, 79.5, 44.5);
    let frames: Vec<Frame> = (0..3)
        .map(|i| noise_frame(320, 180, PixelFormat::Rgb8, i))
        .collect();
    let rots: Vec<Matrix3<f64>> = (0..3)
        .map(|i| *so3::exp(&Tangent::new(0.03 * i as f64, -0.12, 0.05)).matrix())
        .collect();
    let supersampled = || {
        let mut w = Warper::supersampled(&cam, &view, 2);
        let mut img = vec![0u8; 160 * 90 * 3];
        let mut cov = Vec::new();
        let vf = w.average_into(|i| frames[i].as_ref(), &rots, &mut img, 3, &mut cov);
        let mut slot = WarpedFrame::default();
        w.warp_into_slot(&frames[0].as_ref(), &rots[1], &mut slot, 0);
        (img, cov, vf, slot.value, slot.covered)
    };
    let both = || {
        (
            render(&cam, true, PixelFormat::Rgb8),
            render_planar(&cam, true, 1.0),
            supersampled(),
        )
    };
    let one = pool(1).install(both);
    let four = pool(4).install(both);
    assert_eq!(one, four);
}

/// A frame of 1-px stripes (columns alternately 0 and 255) crossed with
/// 1-px rows of a second phase: the highest frequency a frame can hold.
fn checkerboard(w: usize, h: usize, format: PixelFormat) -> Frame {
    let mut f = Frame::new(w, h, format);
    let c = format.channels();
    if format == PixelFormat::Yuv420p {
        // Luma checkered, chroma neutral grey.
        let n = w * h;
        for (i, b) in f.data.iter_mut().enumerate() {
            *b = if i < n {
                if (i % w + i / w) & 1 == 0 {
                    16
                } else {
                    235
                }
            } else {
                128
            };
        }
    } else {
        for (i, px) in f.data.chunks_exact_mut(c).enumerate() {
            let v = if (i % w + i / w) & 1 == 0 { 0 } else { 255 };
            px[..3].fill(v);
            if c == 4 {
                px[3] = 255;
            }
        }
    }
    f.data.extend_from_slice(&[0; FRAME_PADDING]);
    f
}

/// The footprint is the ratio of focal lengths for pinholes, and the auto
/// factor follows the documented rule.
#[test]
fn supersample_factor_follows_the_footprint() {
    let src = CameraModel::pinhole_hfov(320, 180, 80.0).unwrap();
    let at = |w: Option<usize>, antialias: Antialias| {
        let p = RenderParams {
            output_width: w,
            margin: 0.0,
            antialias,
            ..Default::default()
        };
        let out = p.output_camera(&src).unwrap();
        (footprint(&src, &out), p.supersample(&src, &out))
    };
    let (f, s) = at(None, Antialias::Auto);
    assert!((f - 1.0).abs() < 1e-9 && s == 1, "{f} {s}");
    // 1.5 source px per output px: still one sample.
    let (f, s) = at(Some(214), Antialias::Auto);
    assert!(f > 1.49 && f < 1.5 && s == 1, "{f} {s}");
    let (f, s) = at(Some(160), Antialias::Auto);
    assert!((f - 2.0).abs() < 1e-9 && s == 2, "{f} {s}");
    assert_eq!(at(Some(160), Antialias::Off).1, 1);
    assert_eq!(at(Some(100), Antialias::Auto).1, 4);
    assert_eq!(at(Some(16), Antialias::Auto).1, MAX_SUPERSAMPLE);
    // The default output of the default parameters (margins cropped).
    let out = RenderParams::default().output_camera(&src).unwrap();
    assert_eq!(RenderParams::default().supersample(&src, &out), 1);
    // A fisheye source: the centre's scale (the lens map's slope at the
    // centre is the focal length whatever the distortion).
    let mut fish = src.clone();
    fish.distortion = crate::camera::Distortion::Fisheye {
        k1: 0.05,
        k2: -0.01,
        k3: 0.0,
        k4: 0.0,
    };
    let out = CameraModel::pinhole(160, 90, src.fx / 3.0, src.fy / 3.0, 79.5, 44.5);
    assert!((footprint(&fish, &out) - 3.0).abs() < 1e-3);
    assert_eq!(RenderParams::default().supersample(&fish, &out), 3);
    assert!("OFF".parse::<Antialias>().unwrap() == Antialias::Off);
    assert!("wobble".parse::<Antialias>().is_err());
}

/// A warper built with `S = 1` is the plain one: bit-identical output on
/// every entry point (the default runs, whose factor is 1, are unchanged).
#[test]
fn supersample_one_is_the_plain_render() {
    let cam = CameraModel::pinhole_hfov(211, 117, 80.0).unwrap();
    let out = RenderParams::default().output_camera(&cam).unwrap();
    let a = Warper::new(&cam, &out);
    let b = Warper::supersampled(&cam, &out, 1);
    assert_eq!(b.supersample(), 1);
    assert_eq!(a.render_size(), b.render_size());
    let frames: Vec<Frame> = (0..3)
        .map(|i| noise_frame(211, 117, PixelFormat::Rgb8, i))
        .collect();
    let rots: Vec<Matrix3<f64>> = (0..3)
        .map(|i| *so3::exp(&Tangent::new(0.02 * i as f64, -0.05, 0.03)).matrix())
        .collect();
    let run = |mut w: Warper| {
        let mut img = vec![0u8; out.width * out.height * 3];
        let mut cov = Vec::new();
        w.average_into(|i| frames[i].as_ref(), &rots, &mut img, 3, &mut cov);
        let mut slot = WarpedFrame::default();
        w.warp_into_slot(&frames[0].as_ref(), &rots[1], &mut slot, 1);
        (img, cov, slot.value, slot.covered)
    };
    assert_eq!(run(a), run(b));
}

/// What [`Warper::supersampled`] must equal: the plain render at `S` times
/// the size (the output camera rescaled), each `S x S` block averaged by
/// hand with the documented rule. Returns (image, coverage).
fn box_by_hand(
    fine: &[u8],
    fine_cov: &[u8],
    s: usize,
    channels: usize,
    (ow, oh): (usize, usize),
) -> (Vec<u8>, Vec<u8>) {
    let mut img = vec![0u8; ow * oh * channels];
    let mut cov = vec![0u8; ow * oh];
    for v in 0..oh {
        for u in 0..ow {
            let idx: Vec<usize> = (0..s * s)
                .map(|k| (s * v + k / s) * s * ow + s * u + k % s)
                .collect();
            let covered: Vec<usize> = idx.iter().copied().filter(|&i| fine_cov[i] > 0).collect();
            let used = if covered.is_empty() { &idx } else { &covered };
            for ch in 0..channels {
                let sum: u32 = used.iter().map(|&i| fine[i * channels + ch] as u32).sum();
                let n = used.len() as u32;
                img[(v * ow + u) * channels + ch] = ((sum + n / 2) / n) as u8;
            }
            cov[v * ow + u] = idx.iter().map(|&i| fine_cov[i]).min().unwrap();
        }
    }
    (img, cov)
}

/// Supersampling is exactly the plain render at `S` times the size, box
/// averaged: interleaved (RGB, RGBA) and planar (Y, U and V as a pair),
/// plain and ghost-free averages, pinhole and fisheye sources, a rolling
/// shutter; and the saccade slots likewise, covered only where every sample is.
#[test]
fn supersampled_equals_fine_render_box_averaged() {
    let (pinhole, fisheye) = pinhole_and_fisheye(203);
    let rots: Vec<Matrix3<f64>> = (0..3)
        .map(|i| *so3::exp(&Tangent::new(0.03 * i as f64, -0.12, 0.05)).matrix())
        .collect();
    let rows: Vec<RollingProjector> = (0..3)
        .map(|i| {
            let intra = IntraFrame {
                phi: Tangent::new(0.03, -0.02 * i as f64, 0.01),
                psi: Tangent::new(-0.01, 0.005, 0.0),
                chi: Tangent::zeros(),
                xi: Tangent::zeros(),
            };
            let mut p = RollingProjector::default();
            p.set(&intra, pinhole.height);
            p
        })
        .collect();
    for (cam, s, rolling, deghost) in [
        (&pinhole, 2, false, None),
        (&fisheye, 3, false, None),
        (&pinhole, 2, true, Deghost::new(60.0)),
        (&fisheye, 2, false, Deghost::new(60.0)),
    ] {
        // 101 x 57: an odd size (odd chroma planes, a scalar tail per row).
        let view = CameraModel::pinhole(101, 57, cam.fx / 2.0, cam.fy / 2.0, 50.0, 28.0);
        let fine_cam = view.rescaled(s * 101, s * 57);
        let setup = |w: &mut Warper| {
            w.set_deghost(deghost);
            if rolling {
                w.set_readout_rows(&rows);
            }
        };
        let mut ss = Warper::supersampled(cam, &view, s);
        let mut fine = Warper::new(cam, &fine_cam);
        setup(&mut ss);
        setup(&mut fine);
        assert_eq!(ss.output_size(), (101, 57));
        assert_eq!(ss.render_size(), (s * 101, s * 57));
        for format in [PixelFormat::Rgb8, PixelFormat::Rgba8] {
            let c = format.channels();
            let frames: Vec<Frame> = (0..3).map(|i| noise_frame(203, 117, format, i)).collect();
            let mut img = vec![0u8; 101 * 57 * c];
            let mut cov = Vec::new();
            let vf = ss.average_into(|i| frames[i].as_ref(), &rots, &mut img, c, &mut cov);
            let mut fimg = vec![0u8; s * s * 101 * 57 * c];
            let mut fcov = Vec::new();
            fine.average_into(|i| frames[i].as_ref(), &rots, &mut fimg, c, &mut fcov);
            let want = box_by_hand(&fimg, &fcov, s, c, (101, 57));
            assert_eq!((&img, &cov), (&want.0, &want.1), "{format:?} s {s}");
            let full = cov.iter().filter(|&&k| k == 3).count();
            assert_eq!(vf, full as f64 / (101.0 * 57.0));
            assert!(full > 0 && full < 101 * 57, "some border: {full}");
            // The saccade slot (one frame, its own readout rows).
            let (mut a, mut b) = (WarpedFrame::default(), WarpedFrame::default());
            ss.warp_into_slot(&frames[1].as_ref(), &rots[2], &mut a, 4);
            fine.warp_into_slot(&frames[1].as_ref(), &rots[2], &mut b, 4);
            let (mut value, mut covered) = (vec![0u16; 3 * 101 * 57], vec![0u8; 101 * 57]);
            for p in 0..101 * 57 {
                let (u, v) = (p % 101, p / 101);
                let idx: Vec<usize> = (0..s * s)
                    .map(|k| (s * v + k / s) * s * 101 + s * u + k % s)
                    .collect();
                if idx.iter().all(|&i| b.covered[i] == 1) {
                    covered[p] = 1;
                    for ch in 0..3 {
                        let sum: u32 = idx.iter().map(|&i| b.value[3 * i + ch] as u32).sum();
                        let n = (s * s) as u32;
                        value[3 * p + ch] = ((sum + n / 2) / n) as u16;
                    }
                }
            }
            assert_eq!(a.index, 4);
            assert_eq!((&a.value, &a.covered), (&value, &covered));
            // The scalar reference slot agrees.
            let mut r = WarpedFrame::default();
            r.fill(&mut ss, &frames[1].as_ref(), &rots[2], 4);
            assert_eq!((&r.value, &r.covered), (&value, &covered));
        }
        // Planar 4:2:0: Y, then U and V as a pair, through the chroma cameras.
        let n = 203 * 117;
        let (scw, sch) = crate::image::chroma_size(203, 117);
        let nc = scw * sch;
        let frames: Vec<Vec<u8>> = (0..3)
            .map(|i| {
                let mut f = noise_frame(203, 117, PixelFormat::Rgb8, i + 7).data;
                f.truncate(n + 2 * nc);
                f.extend_from_slice(&[0; FRAME_PADDING]);
                f
            })
            .collect();
        let cv = chroma_camera(&view);
        // The chroma view rescaled (not the fine luma's chroma: odd sizes round).
        let cf = cv.rescaled(s * cv.width, s * cv.height);
        let mut ss_c = Warper::supersampled(&chroma_camera(cam), &cv, s);
        let mut fine_c = Warper::new(&chroma_camera(cam), &cf);
        setup(&mut ss_c);
        setup(&mut fine_c);
        let mut y = vec![0u8; 101 * 57];
        let mut cov = Vec::new();
        let k = ss.average_plane_into(|i| &frames[i], 203, 117, &rots, &mut y, &mut cov, 16);
        let mut fy = vec![0u8; s * s * 101 * 57];
        let mut fcov = Vec::new();
        fine.average_plane_into(|i| &frames[i], 203, 117, &rots, &mut fy, &mut fcov, 16);
        let want = box_by_hand(&fy, &fcov, s, 1, (101, 57));
        assert_eq!((&y, &cov), (&want.0, &want.1), "luma s {s}");
        assert_eq!(k, cov.iter().filter(|&&c| c == 3).count());
        let (ocw, och) = (cv.width, cv.height);
        let (mut u, mut v) = (vec![0u8; ocw * och], vec![0u8; ocw * och]);
        let (fcw, fch) = (cf.width, cf.height);
        assert_eq!((fcw, fch), (s * ocw, s * och));
        let (mut fu, mut fv) = (vec![0u8; fcw * fch], vec![0u8; fcw * fch]);
        let pair = |i: usize| (&frames[i][n..], &frames[i][n + nc..]);
        let (mut ccov, mut fccov) = (Vec::new(), Vec::new());
        ss_c.average_plane_pair_into(pair, scw, sch, &rots, &mut u, &mut v, &mut ccov, 128);
        fine_c.average_plane_pair_into(pair, scw, sch, &rots, &mut fu, &mut fv, &mut fccov, 128);
        let wu = box_by_hand(&fu, &fccov, s, 1, (ocw, och));
        let wv = box_by_hand(&fv, &fccov, s, 1, (ocw, och));
        assert_eq!((&u, &ccov), (&wu.0, &wu.1), "U s {s}");
        assert_eq!(v, wv.0, "V s {s}");
        // A planar saccade slot.
        let (mut vals, mut covd) = (vec![0u16; 101 * 57], vec![0u8; 101 * 57]);
        ss.warp_plane_into(&frames[0], 203, 117, &rots[1], &mut vals, &mut covd);
        let (mut fvals, mut fcovd) = (vec![0u16; s * s * 101 * 57], vec![0u8; s * s * 101 * 57]);
        fine.warp_plane_into(&frames[0], 203, 117, &rots[1], &mut fvals, &mut fcovd);
        for p in 0..101 * 57 {
            let (pu, pv) = (p % 101, p / 101);
            let idx: Vec<usize> = (0..s * s)
                .map(|k| (s * pv + k / s) * s * 101 + s * pu + k % s)
                .collect();
            let all = idx.iter().all(|&i| fcovd[i] == 1);
            let sum: u32 = idx.iter().map(|&i| fvals[i] as u32).sum();
            let n = (s * s) as u32;
            let want = if all { ((sum + n / 2) / n) as u16 } else { 0 };
            assert_eq!(
                (vals[p], covd[p]),
                (want, all as u8),
                "plane slot pixel {p}"
            );
        }
    }
}

/// Every kernel gives the same supersampled bytes (the box average is
/// integer and shared).
#[test]
fn supersampled_kernels_match_scalar() {
    let cam = CameraModel::pinhole_hfov(203, 117, 80.0).unwrap();
    let view = CameraModel::pinhole(101, 57, cam.fx / 2.0, cam.fy / 2.0, 50.0, 28.0);
    let frames: Vec<Frame> = (0..3)
        .map(|i| noise_frame(203, 117, PixelFormat::Rgba8, i))
        .collect();
    let rots: Vec<Matrix3<f64>> = (0..3)
        .map(|i| *so3::exp(&Tangent::new(0.03 * i as f64, -0.12, 0.05)).matrix())
        .collect();
    let run = |kernel: kernels::Kernel| {
        let mut w = Warper::supersampled(&cam, &view, 2);
        assert!(w.set_kernel(kernel));
        let mut img = vec![0u8; 101 * 57 * 4];
        let mut cov = Vec::new();
        w.average_into(|i| frames[i].as_ref(), &rots, &mut img, 4, &mut cov);
        (img, cov)
    };
    let reference = run(kernels::Kernel::Scalar);
    for kernel in kernels::Kernel::available() {
        assert_eq!(run(kernel), reference, "{kernel:?}");
    }
}

/// Minifying a 1-px checkerboard by 2: one bilinear sample per output pixel
/// lands between source pixels at a phase that drifts across the output
/// (moire: bands from grey to full contrast), while the supersampled output
/// averages each output pixel's 2x2 source pixels: uniform grey.
#[test]
fn supersampling_removes_the_aliasing_of_minification() {
    let cam = CameraModel::pinhole_hfov(320, 180, 80.0).unwrap();
    let params = |antialias| RenderParams {
        output_width: Some(160),
        margin: 0.0,
        antialias,
        ..Default::default()
    };
    let out = params(Antialias::Auto).output_camera(&cam).unwrap();
    assert_eq!((out.width, out.height), (160, 90));
    // A small turn so the sampling phase is not the grid's own.
    let m = *so3::exp(&Tangent::new(0.004, -0.003, 0.01)).matrix();
    let spread = |antialias| {
        let s = params(antialias).supersample(&cam, &out);
        let mut w = Warper::supersampled(&cam, &out, s);
        let f = checkerboard(320, 180, PixelFormat::Rgb8);
        let mut img = vec![0u8; 160 * 90 * 3];
        let mut cov = Vec::new();
        w.average_into(|_| f.as_ref(), &[m], &mut img, 3, &mut cov);
        let vals: Vec<f64> = img
            .chunks_exact(3)
            .zip(&cov)
            .filter(|(_, &c)| c == 1)
            .map(|(px, _)| px[0] as f64)
            .collect();
        assert!(vals.len() > 160 * 80);
        let mean = vals.iter().sum::<f64>() / vals.len() as f64;
        let sd =
            (vals.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / vals.len() as f64).sqrt();
        (mean, sd)
    };
    let (mean_aa, sd_aa) = spread(Antialias::Auto);
    let (_, sd_off) = spread(Antialias::Off);
    assert!((mean_aa - 127.5).abs() < 3.0, "grey: mean {mean_aa}");
    assert!(sd_aa < 12.0, "antialiased: sd {sd_aa}");
    assert!(sd_off > 40.0, "aliased: sd {sd_off}");
    // Planar too: the luma of a 4:2:0 frame.
    let f = checkerboard(320, 180, PixelFormat::Yuv420p);
    // (Video range: 16..=235, so the aliased spread is a little less.)
    for (antialias, bound) in [(Antialias::Auto, 12.0), (Antialias::Off, -30.0)] {
        let s = params(antialias).supersample(&cam, &out);
        let mut w = Warper::supersampled(&cam, &out, s);
        let mut y = vec![0u8; 160 * 90];
        let mut cov = Vec::new();
        w.average_plane_into(|_| &f.data, 320, 180, &[m], &mut y, &mut cov, 16);
        let vals: Vec<f64> = y
            .iter()
            .zip(&cov)
            .filter(|(_, &c)| c == 1)
            .map(|(&v, _)| v as f64)
            .collect();
        let mean = vals.iter().sum::<f64>() / vals.len() as f64;
        let sd =
            (vals.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / vals.len() as f64).sqrt();
        if bound > 0.0 {
            assert!(sd < bound, "{antialias}: sd {sd}");
        } else {
            assert!(sd > -bound, "{antialias}: sd {sd}");
        }
    }
}

/// The Catmull-Rom weights in 1/256: they sum to 256 at every fraction, a
/// whole pixel is the pixel, and each is the rounded kernel value.
#[test]
fn cubic_weights_are_the_rounded_kernel() {
    use super::kernels::cubic_weights;
    let keys = |x: f64| {
        let x = x.abs();
        if x <= 1.0 {
            1.5 * x * x * x - 2.5 * x * x + 1.0
        } else if x < 2.0 {
            -0.5 * x * x * x + 2.5 * x * x - 4.0 * x + 2.0
        } else {
            0.0
        }
    };
    assert_eq!(cubic_weights(0), [0, 256, 0, 0]);
    assert_eq!(cubic_weights(256), [0, 0, 256, 0]);
    for a in 0..=256 {
        let w = cubic_weights(a);
        assert_eq!(w.iter().sum::<i32>(), 256, "a = {a}");
        let t = a as f64 / 256.0;
        for (i, &wi) in w.iter().enumerate() {
            let exact = 256.0 * keys(t + 1.0 - i as f64);
            // w1 takes the other three's rounding: up to 1.5 off.
            assert!(
                (wi as f64 - exact).abs() <= 1.5,
                "a = {a}, tap {i}: {wi} vs {exact}"
            );
        }
    }
}

/// Bicubic samples: a whole pixel is the pixel, a linear ramp is reproduced
/// between pixels (Catmull-Rom is exact on linear functions), and the edge is
/// sampled by repeating the edge pixel (no read outside the plane).
#[test]
fn bicubic_samples_whole_pixels_and_ramps() {
    let (w, h) = (37, 23);
    let ramp: Vec<u8> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (3 * x + 4 * y + 20) as u8))
        .collect();
    let g = Geometry::plane(w, h, 1).with_cubic(true);
    for y in 0..h {
        for x in 0..w {
            let v = g.sample_gray(&ramp, x as f32, y as f32).unwrap();
            assert_eq!(v, 256 * ramp[y * w + x] as u32, "({x}, {y})");
        }
    }
    for (sx, sy) in [
        (1.25f32, 1.5f32),
        (10.37, 7.81),
        (30.5, 20.125),
        (34.9, 20.99),
    ] {
        let exact = 3.0 * sx + 4.0 * sy + 20.0;
        let v = g.sample_gray(&ramp, sx, sy).unwrap() as f32 / 256.0;
        // The 8-bit fractions quantize the point by up to 1/512 px.
        assert!((v - exact).abs() < 0.03, "({sx}, {sy}): {v} vs {exact}");
    }
    // The last column and row sample exactly; outside the tolerance, nothing.
    let last = g
        .sample_gray(&ramp, (w - 1) as f32, (h - 1) as f32)
        .unwrap();
    assert_eq!(last, 256 * ramp[w * h - 1] as u32);
    assert_eq!(g.sample_gray(&ramp, -0.01, 3.0), None);
    assert_eq!(g.sample_gray(&ramp, 3.0, (h - 1) as f32 + 0.01), None);
}

/// What bicubic sampling is for: a fine pattern (a 4-pixel period) sampled
/// half a pixel off its pixels keeps most of its contrast (the wave's true
/// amplitude there is `100 sin(pi / 4)`: the samples fall between its peaks),
/// where bilinear sampling, which averages the two neighbours, loses 29%.
#[test]
fn bicubic_keeps_the_detail_bilinear_blurs() {
    let (w, h) = (64, 8);
    let wave: Vec<u8> = (0..h)
        .flat_map(|_| {
            (0..w).map(|x| (128.0 + 100.0 * (std::f32::consts::FRAC_PI_2 * x as f32).sin()) as u8)
        })
        .collect();
    let amplitude = |cubic: bool| {
        let g = Geometry::plane(w, h, 1).with_cubic(cubic);
        let vals: Vec<f32> = (8..56)
            .map(|x| g.sample_gray(&wave, x as f32 + 0.5, 4.0).unwrap() as f32 / 256.0)
            .collect();
        let max = vals.iter().cloned().fold(f32::MIN, f32::max);
        let min = vals.iter().cloned().fold(f32::MAX, f32::min);
        (max - min) / 2.0
    };
    let truth = 100.0 * std::f32::consts::FRAC_1_SQRT_2;
    let (bilinear, bicubic) = (amplitude(false) / truth, amplitude(true) / truth);
    assert!(bilinear < 0.72, "bilinear keeps {bilinear}");
    assert!(bicubic > 0.87, "bicubic keeps {bicubic}");
}

/// Bicubic renders: every kernel this build can run gives the scalar
/// reference's bytes (planes and interleaved frames, pinhole and fisheye,
/// global and rolling shutter, plain and ghost-free averages), and the
/// render differs from the bilinear one.
#[test]
fn bicubic_kernels_match_scalar() {
    let (pinhole, fisheye) = pinhole_and_fisheye(211);
    let rows = readout_rows(pinhole.height);
    let rots: Vec<Matrix3<f64>> = (0..4)
        .map(|i| *so3::exp(&Tangent::new(0.06 * i as f64, -0.1, 0.05 * i as f64)).matrix())
        .collect();
    for cam in [&pinhole, &fisheye] {
        let out = RenderParams::default().output_camera(cam).unwrap();
        let (sc, oc) = (chroma_camera(cam), chroma_camera(&out));
        let frames: Vec<Frame> = (0..4)
            .map(|i| noise_frame(cam.width, cam.height, PixelFormat::Rgb8, i + 20))
            .collect();
        let rgba_frames: Vec<Frame> = (0..4)
            .map(|i| noise_frame(cam.width, cam.height, PixelFormat::Rgba8, i + 30))
            .collect();
        let n = cam.width * cam.height;
        let nc = sc.width * sc.height;
        for rolling in [false, true] {
            for deghost in [None, Deghost::new(60.0)] {
                let run = |kernel: kernels::Kernel, interpolation: Interpolation| {
                    let mut luma = Warper::new(cam, &out);
                    let mut chroma = Warper::new(&sc, &oc);
                    for w in [&mut luma, &mut chroma] {
                        assert!(w.set_kernel(kernel));
                        w.set_deghost(deghost);
                        w.set_interpolation(interpolation);
                    }
                    if rolling {
                        luma.set_readout_rows(&rows);
                        chroma.set_readout_rows(&rows);
                    }
                    let (mut y, mut u, mut v) = (
                        vec![0u8; out.width * out.height],
                        vec![0u8; oc.width * oc.height],
                        vec![0u8; oc.width * oc.height],
                    );
                    let (mut cov, mut ccov) = (Vec::new(), Vec::new());
                    let full = luma.average_plane_into(
                        |i| &frames[i].data,
                        cam.width,
                        cam.height,
                        &rots,
                        &mut y,
                        &mut cov,
                        16,
                    );
                    let cfull = chroma.average_plane_pair_into(
                        |i| (&frames[i].data[n..], &frames[i].data[n + nc..]),
                        sc.width,
                        sc.height,
                        &rots,
                        &mut u,
                        &mut v,
                        &mut ccov,
                        128,
                    );
                    let mut rgb = vec![0u8; out.width * out.height * 3];
                    let mut rgb_cov = Vec::new();
                    let vf =
                        luma.average_into(|i| frames[i].as_ref(), &rots, &mut rgb, 3, &mut rgb_cov);
                    // The page's input: RGBA frames into an RGBA output.
                    let mut rgba = vec![0u8; out.width * out.height * 4];
                    let vf_rgba = luma.average_into(
                        |i| rgba_frames[i].as_ref(),
                        &rots,
                        &mut rgba,
                        4,
                        &mut rgb_cov,
                    );
                    (
                        y,
                        u,
                        v,
                        cov,
                        ccov,
                        full,
                        cfull,
                        rgb,
                        rgb_cov,
                        (vf, vf_rgba),
                        rgba,
                    )
                };
                let reference = run(kernels::Kernel::Scalar, Interpolation::Bicubic);
                assert!(reference.5 > 0 && reference.5 < reference.3.len());
                for kernel in kernels::Kernel::available() {
                    let label = format!("{kernel:?} rolling {rolling} deghost {deghost:?}");
                    assert!(run(kernel, Interpolation::Bicubic) == reference, "{label}");
                }
                let bilinear = run(kernels::Kernel::Scalar, Interpolation::Bilinear);
                assert_ne!(bilinear.0, reference.0);
                assert_ne!(bilinear.7, reference.7);
                assert_ne!(bilinear.10, reference.10);
                // Coverage does not depend on the interpolation.
                assert_eq!(bilinear.3, reference.3);
            }
        }
    }
}
