//! A run with a gyro log: a first pass tracks the whole clip from the
//! picture, the log is synchronized with it and the two are fused
//! ([`amc_gyrolog::fuse_log`], as the page does) into each frame's pose and
//! readout path, which the main pass renders without tracking again. A clip
//! that fits in [`CACHE_BYTES`] is kept from the first pass for the main
//! one, so it is decoded once. `zoom = static` frames the fused poses
//! ([`static_zoom`]) instead of tracking the clip once more: a run with a
//! gyro tracks once where one from the picture alone tracks twice.

use super::control::RunControl;
use super::gyro::{GyroLog, GyroReport};
use super::stages::Reader;
use super::RunError;
use amc_core::plan::static_zoom_posed;
use amc_core::{CameraModel, Frame, GivenPose, Stabilizer, StabilizerParams, Telemetry};
use amc_gyrolog::{fuse_log, video_only_warning, FuseLogError, FusedLog};
use amc_video::{self as video, FrameSource, InputOptions, VideoError, VideoInfo};
use std::path::Path;

/// Most bytes of decoded frames the first pass keeps for the main one.
pub const CACHE_BYTES: usize = 1 << 30;

/// What the first pass and the fusion hand to the main pass.
pub(crate) struct Fused {
    /// One per frame of the clip, in order.
    pub poses: Vec<GivenPose>,
    /// Each pose's frame time, seconds.
    pub times: Vec<f64>,
    /// The frames' size.
    pub size: (usize, usize),
    pub report: GyroReport,
    /// The clip's frames, when they fit in [`CACHE_BYTES`].
    pub cached: Option<CachedClip>,
}

/// A clip's frames as the first pass decoded them, played again.
pub(crate) struct CachedClip {
    info: VideoInfo,
    frames: std::vec::IntoIter<(Frame, f64)>,
}

impl FrameSource for CachedClip {
    fn info(&self) -> &VideoInfo {
        &self.info
    }

    fn next_frame(&mut self, buf: &mut Frame) -> Result<Option<f64>, VideoError> {
        Ok(self.frames.next().map(|(mut frame, t)| {
            std::mem::swap(buf, &mut frame);
            t
        }))
    }
}

/// Tracks `input` from the picture alone, synchronizes `log` with it and
/// fuses the two. `Ok(Err(warning))`: the log does not fit the video (the
/// run goes on from the picture alone, with the warning).
#[allow(clippy::too_many_arguments)]
pub(crate) fn fuse_pass(
    input: &Path,
    opts: &InputOptions,
    lens: &CameraModel,
    params: &StabilizerParams,
    log: &GyroLog,
    pool: &rayon::ThreadPool,
    control: Option<&RunControl>,
) -> Result<Result<Fused, String>, RunError> {
    let check = || control.map_or(Ok(()), RunControl::check);
    let src = video::open_input(input, opts)?;
    let info = src.info().clone();
    let mut src = Reader::new(src, opts.pixel_format, pool.current_num_threads() > 1);
    let mut cache: Option<Vec<(Frame, f64)>> = Some(Vec::new());
    let mut cached_bytes = 0usize;
    let mut stab = Stabilizer::new(lens, info.width, info.height, params.clone())?;
    stab.set_tracking_only(true);
    let mut frame = Frame::new(info.width, info.height, opts.pixel_format);
    let mut seen: Vec<Telemetry> = Vec::new();
    while let Some(t) = src.next_frame(&mut frame)? {
        check()?;
        if let Some(tel) = stab.push(frame.as_ref(), t)? {
            seen.push(tel);
        }
        cached_bytes += frame.data.len();
        match cache.as_mut() {
            Some(c) if cached_bytes <= CACHE_BYTES => c.push((frame.clone(), t)),
            _ => cache = None,
        }
    }
    drop(src);
    while let Some(tel) = stab.finish() {
        seen.push(tel);
    }
    check()?;
    if seen.is_empty() {
        return Err(RunError::NoFrames {
            path: input.to_path_buf(),
        });
    }
    let readout_s = params.shutter.readout_ms * 1e-3;
    // On the pool: the sync's searches use its threads.
    let FusedLog { poses, report } = match pool.install(|| fuse_log(log, &seen, readout_s)) {
        Ok(fused) => fused,
        Err(FuseLogError::Sync(e)) => return Ok(Err(video_only_warning(&e))),
        Err(FuseLogError::Fuse(e)) => return Err(e.into()),
    };
    let size = (info.width, info.height);
    let cached = cache.map(|frames| CachedClip {
        info,
        frames: frames.into_iter(),
    });
    Ok(Ok(Fused {
        poses,
        times: seen.iter().map(|tel| tel.t).collect(),
        size,
        report,
        cached,
    }))
}

/// `zoom = static`'s zoom for the fused poses (`None`: `params` need none).
pub(crate) fn static_zoom(
    fused: &Fused,
    lens: &CameraModel,
    params: &StabilizerParams,
) -> Result<Option<f64>, RunError> {
    let (w, h) = fused.size;
    let posed = fused.times.iter().copied().zip(fused.poses.iter().copied());
    Ok(static_zoom_posed(lens, w, h, params, posed)?)
}
