//! The report's figures: per clip a plot of the motion, a strip of middle
//! frames side by side, and the per-frame CSV.

use super::output::{file_stem, write_public};
use super::tables::find;
use crate::compare::error::CompareError;
use crate::compare::results::ClipResult;
use crate::plot::{self, ModeSeries};
use amc_core::image::Frame;
use std::fmt::Write as _;
use std::path::Path;

/// Width of one tile of the frame strip, px.
pub(super) const TILE_WIDTH: u32 = 320;
/// Tiles per row of the frame strip.
pub(super) const STRIP_COLUMNS: u32 = 3;

/// Writes the plot of one clip.
pub(super) fn write_clip_plot(dir: &Path, c: &ClipResult) -> Result<String, CompareError> {
    let name = format!("{}-motion.png", file_stem(&c.clip));
    let none_speed: Vec<f64> = find(c, "none")
        .map(|m| {
            m.measured
                .frames
                .iter()
                .map(|r| r.apparent_speed_dps.unwrap_or(f64::NAN))
                .collect()
        })
        .unwrap_or_default();
    let series: Vec<ModeSeries> = c
        .methods
        .iter()
        .map(|m| {
            let rows = &m.measured.frames;
            let n = rows.len();
            let mut est = none_speed.clone();
            est.resize(n, f64::NAN);
            ModeSeries {
                mode: m.method.to_string(),
                t: rows.iter().map(|r| r.t).collect(),
                est_speed_dps: est,
                view_speed_dps: rows
                    .iter()
                    .map(|r| r.apparent_speed_dps.unwrap_or(f64::NAN))
                    .collect(),
                normal_flow: rows.iter().map(|r| r.rms_normal_flow).collect(),
                saccade: if m.saccades.len() == n {
                    m.saccades.clone()
                } else {
                    vec![false; n]
                },
            }
        })
        .collect();
    let title = format!(
        "{}: apparent angular speed of each output (top; 'camera' = none) and normal flow (bottom)",
        c.clip
    );
    plot::write_plot(&dir.join(&name), &title, &series)?;
    Ok(name)
}

/// Writes the strip of middle frames (input first, then each method, row-major).
pub(super) fn write_strip(dir: &Path, c: &ClipResult) -> Result<Option<String>, CompareError> {
    let tiles: Vec<&Frame> = c
        .input_middle
        .iter()
        .chain(c.methods.iter().filter_map(|m| m.middle.as_ref()))
        .collect();
    if tiles.is_empty() {
        return Ok(None);
    }
    let (iw, ih) = c.input_size;
    let tile_h = ((TILE_WIDTH as f64) * ih as f64 / iw.max(1) as f64)
        .round()
        .max(1.0) as u32;
    let rows = (tiles.len() as u32).div_ceil(STRIP_COLUMNS);
    let mut canvas = image::RgbImage::from_pixel(
        STRIP_COLUMNS * TILE_WIDTH,
        rows * tile_h,
        image::Rgb([255, 255, 255]),
    );
    for (k, f) in tiles.iter().enumerate() {
        let c = f.format.channels();
        let rgb: Vec<u8> = f
            .data
            .chunks_exact(c)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        let Some(img) = image::RgbImage::from_raw(f.width as u32, f.height as u32, rgb) else {
            continue;
        };
        let small = image::imageops::resize(
            &img,
            TILE_WIDTH,
            tile_h,
            image::imageops::FilterType::Triangle,
        );
        let (x, y) = (
            (k as u32 % STRIP_COLUMNS) * TILE_WIDTH,
            (k as u32 / STRIP_COLUMNS) * tile_h,
        );
        image::imageops::replace(&mut canvas, &small, x as i64, y as i64);
    }
    let name = format!("{}-strip.png", file_stem(&c.clip));
    let path = dir.join(&name);
    let mut png = std::io::Cursor::new(Vec::new());
    canvas
        .write_to(&mut png, image::ImageFormat::Png)
        .map_err(|e| CompareError::Image {
            path: path.clone(),
            detail: e.to_string(),
        })?;
    write_public(&path, png.get_ref())?;
    Ok(Some(name))
}

/// Writes every method's per-frame measurements of one clip as CSV.
pub(super) fn write_frames_csv(dir: &Path, c: &ClipResult) -> Result<(), CompareError> {
    let f = |v: Option<f64>| {
        v.filter(|x| x.is_finite())
            .map(|x| format!("{x:.6}"))
            .unwrap_or_default()
    };
    let mut s = String::from(
        "method,frame,t,rms_normal_flow,apparent_speed_dps,cropping,distortion,fit_residual,psnr_db,valid_fraction\n",
    );
    for m in &c.methods {
        for (j, r) in m.measured.frames.iter().enumerate() {
            let _ = writeln!(
                s,
                "{},{j},{:.6},{},{},{},{},{},{},{:.5}",
                m.method,
                r.t,
                f(r.rms_normal_flow),
                f(r.apparent_speed_dps),
                f(r.cropping),
                f(r.distortion),
                f(r.fit_residual),
                f(r.psnr_db),
                r.valid_fraction
            );
        }
    }
    write_public(
        &dir.join(format!("{}-frames.csv", file_stem(&c.clip))),
        s.as_bytes(),
    )
}
