//! Native single-thread reference for `web/bench.mjs`: stabilizes the same raw
//! frames the browser bench uses (RGBA, or planar I420 as ffmpeg's `yuv420p`
//! rawvideo writes it) and prints frames/s as JSON.
//!
//! `cargo run --release -p amc-wasm --example native_bench -- FRAMES WIDTH HEIGHT [FOV] [FRAMES_TO_RUN] [rgba|i420]`

use amc_core::{CameraModel, FrameRef, PixelFormat, Stabilizer, StabilizerParams};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        return Err(
            "usage: native_bench FRAMES WIDTH HEIGHT [FOV] [FRAMES_TO_RUN] [rgba|i420]".into(),
        );
    }
    let data = std::fs::read(&args[1])?;
    let (w, h): (usize, usize) = (args[2].parse()?, args[3].parse()?);
    let fov: f64 = args.get(4).map_or(Ok(70.0), |s| s.parse())?;
    let format = match args.get(6).map(|s| s.to_ascii_lowercase()).as_deref() {
        None | Some("rgba") => PixelFormat::Rgba8,
        Some("i420") | Some("yuv420p") => PixelFormat::Yuv420p,
        Some(other) => return Err(format!("unknown format {other:?} (allowed: rgba, i420)").into()),
    };
    let size = format.buffer_len(w, h).ok_or("frame too large")?;
    let n_src = data.len() / size;
    if n_src == 0 {
        return Err(format!("{} holds no {w}x{h} {format:?} frame", args[1]).into());
    }
    let n: usize = args.get(5).map_or(Ok(n_src), |s| s.parse())?;
    let lens = CameraModel::pinhole_hfov(w, h, fov)?;
    let mut stab = Stabilizer::new(&lens, w, h, StabilizerParams::default())?;
    let t0 = Instant::now();
    let mut outs = 0usize;
    for i in 0..n {
        // Played forwards then backwards, so the motion stays continuous.
        let k = if (i / n_src) % 2 == 0 {
            i % n_src
        } else {
            n_src - 1 - i % n_src
        };
        let frame = FrameRef::new(w, h, format, &data[k * size..(k + 1) * size])?;
        if stab.push(frame, i as f64 / 30.0)?.is_some() {
            outs += 1;
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    println!(
        "{{\"width\":{w},\"height\":{h},\"format\":\"{}\",\"frames\":{n},\"outputs\":{outs},\"seconds\":{secs:.4},\"fps\":{:.1},\"avx2\":{}}}",
        if format == PixelFormat::Yuv420p { "I420" } else { "RGBA" },
        n as f64 / secs,
        amc_core::render::kernels::avx2_available()
    );
    Ok(())
}
