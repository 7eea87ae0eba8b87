//! The vectorized render kernels against their scalar reference, from the page.

use crate::args;
use crate::js::err;
use amc_core::camera::CameraModel;
use amc_core::{FrameRef, PixelFormat};
use wasm_bindgen::prelude::*;

/// Four frames of `len` random bytes (a 64-bit LCG from `seed`), each padded
/// as the kernels read frames.
fn random_frames(len: usize, mut seed: u64) -> Vec<Vec<u8>> {
    (0..4)
        .map(|_| {
            let mut f = vec![0u8; len + amc_core::render::kernels::FRAME_PADDING];
            for b in f.iter_mut().take(len) {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                *b = (seed >> 56) as u8;
            }
            f
        })
        .collect()
}

/// Renders random frames through random rotations with the vectorized kernel
/// (wasm `simd128` when the module was built with it) and with the scalar
/// reference, and returns whether the images, coverage and valid share are
/// identical, for RGBA and RGB frames and for one plane of a planar (I420)
/// frame, averaged plainly and without ghosts. `fisheye` exercises the
/// coordinate-table path.
#[wasm_bindgen(js_name = simdMatchesScalar)]
pub fn simd_matches_scalar(
    width: f64,
    height: f64,
    seed: u32,
    fisheye: bool,
) -> Result<bool, JsError> {
    use amc_core::render::{Deghost, RenderParams, Warper};
    use amc_core::so3::{self, Tangent};
    let (w, h) = (
        args::dimension("width", width).map_err(err)?,
        args::dimension("height", height).map_err(err)?,
    );
    if w < 16 || h < 16 {
        return Err(JsError::new(&format!(
            "invalid size: {w}x{h} (allowed: at least 16x16)"
        )));
    }
    let mut cam = CameraModel::pinhole_hfov(w, h, 80.0).map_err(err)?;
    if fisheye {
        cam.distortion = amc_core::camera::Distortion::Fisheye {
            k1: 0.05,
            k2: -0.01,
            k3: 0.0,
            k4: 0.0,
        };
    }
    let out = RenderParams::default().output_camera(&cam).map_err(err)?;
    let rots: Vec<_> = (0..4)
        .map(|i| {
            *so3::exp(&Tangent::new(
                0.06 * i as f64,
                -0.1 + 0.01 * (seed % 7) as f64,
                0.05 * i as f64,
            ))
            .matrix()
        })
        .collect();
    // The plain average and the ghost-free one (random frames differ by up
    // to 255 levels: a 60-level threshold gives every weight from 0 to 16).
    let deghosts = [None, Deghost::new(60.0)];
    // Both pixel formats (the kernel has an RGBA and an RGB path).
    for format in [PixelFormat::Rgba8, PixelFormat::Rgb8] {
        let c = format.channels();
        let frames = random_frames(w * h * c, seed as u64 + 1);
        let render = |vectorized: bool, deghost: Option<Deghost>| {
            let mut warper = Warper::new(&cam, &out);
            warper.set_vectorized(vectorized);
            warper.set_deghost(deghost);
            let mut img = vec![0u8; out.width * out.height * c];
            let mut cov = Vec::new();
            let vf = warper.average_into(
                |i| FrameRef {
                    width: w,
                    height: h,
                    format,
                    data: &frames[i],
                },
                &rots,
                &mut img,
                c,
                &mut cov,
            );
            (img, cov, vf)
        };
        for deghost in deghosts {
            if render(false, deghost) != render(true, deghost) {
                return Ok(false);
            }
        }
    }
    // One plane of a planar frame (the single-channel kernel of I420 input).
    let planes = random_frames(w * h, seed as u64 + 7);
    let render = |vectorized: bool, deghost: Option<Deghost>| {
        let mut warper = Warper::new(&cam, &out);
        warper.set_vectorized(vectorized);
        warper.set_deghost(deghost);
        let mut img = vec![0u8; out.width * out.height];
        let mut cov = Vec::new();
        let complete =
            warper.average_plane_into(|i| &planes[i][..], w, h, &rots, &mut img, &mut cov, 16);
        (img, cov, complete)
    };
    Ok(deghosts
        .into_iter()
        .all(|deghost| render(false, deghost) == render(true, deghost)))
}

/// Whether this module was built with the WebAssembly `simd128` kernel.
#[wasm_bindgen(js_name = simdEnabled)]
pub fn simd_enabled() -> bool {
    amc_core::render::kernels::vector_kernel_available()
}
