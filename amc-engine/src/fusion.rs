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
use super::log_readout::MeasureReadout;
use super::stages::Reader;
use super::RunError;
use amc_core::plan::static_zoom_posed;
use amc_core::readout::{ReadoutEstimate, ReadoutEstimator};
use amc_core::{CameraModel, Frame, GivenPose, Stabilizer, StabilizerParams, Telemetry};
use amc_gyrolog::{
    fuse_log, measure_readout, video_only_warning, FuseLogError, FusedLog, ReadoutReport,
};
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

/// What the first pass hands to the main one.
pub(crate) struct FirstPass {
    /// The fusion, or why the log does not fit the video (the run goes on
    /// from the picture alone, with that warning).
    pub fused: Result<Fused, String>,
    /// Where the pass measured the readout: the main pass's, milliseconds,
    /// and a warning where neither the log nor the picture pinned it down.
    pub readout: Option<(f64, Option<String>)>,
}

/// Tracks `input` from the picture alone, synchronizes `log` with it and
/// fuses the two. With `measure`, the readout is measured against the log
/// first ([`measure_readout`]): the picture's readout pass
/// ([`ReadoutEstimator`]) over the first
/// [`READOUT_FRAMES`](amc_core::readout::READOUT_FRAMES) frames, synchronized
/// with the log, then the first pass tracks with the readout found (the
/// frames kept, so each is decoded once); where the log cannot tell, the
/// fallback `measure` names.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fuse_pass(
    input: &Path,
    opts: &InputOptions,
    lens: &CameraModel,
    params: &StabilizerParams,
    measure: Option<MeasureReadout>,
    log: &GyroLog,
    pool: &rayon::ThreadPool,
    control: Option<&RunControl>,
) -> Result<FirstPass, RunError> {
    let check = || control.map_or(Ok(()), RunControl::check);
    let src = video::open_input(input, opts)?;
    let info = src.info().clone();
    let mut src = Reader::new(src, opts.pixel_format, pool.current_num_threads() > 1);
    let mut frame = Frame::new(info.width, info.height, opts.pixel_format);
    // A decoded frame kept for the main pass: the frame itself, not a copy;
    // the decoder fills a new buffer for the next one (on its own thread
    // with more than one).
    let take = |frame: &mut Frame| {
        std::mem::replace(
            frame,
            Frame::new(info.width, info.height, opts.pixel_format),
        )
    };
    // The readout pass's frames, tracked again by the first pass (decoded
    // again where they would not fit in memory).
    let mut head: Option<Vec<(Frame, f64)>> = Some(Vec::new());
    let mut params = params.clone();
    // The readout measured and its warning; the log's fit, for the report.
    let mut readout: Option<(f64, Option<String>)> = None;
    let mut from_log = None;
    if let Some(how) = measure {
        let mut estimator = ReadoutEstimator::new(lens, info.width, info.height, &params)?;
        while !estimator.is_full() {
            let Some(t) = src.next_frame(&mut frame)? else {
                break;
            };
            check()?;
            estimator.push(frame.as_ref(), t)?;
            match head.as_mut() {
                Some(h) if (h.len() + 1) * frame.data.len() <= CACHE_BYTES => {
                    h.push((take(&mut frame), t))
                }
                _ => head = None,
            }
        }
        if head.is_none() {
            let again = video::open_input(input, opts)?;
            src = Reader::new(again, opts.pixel_format, pool.current_num_threads() > 1);
        }
        let (picture, pass) = estimator.finish_with_telemetry();
        let picture = picture.ok().filter(|p| p.confident);
        from_log = pool.install(|| measure_readout(log, &pass)).ok().flatten();
        let pinned = from_log.as_ref().filter(|r| r.confident);
        params.shutter.readout_ms = match (pinned, how, &picture) {
            (Some(r), _, _) => r.readout_ms,
            (None, MeasureReadout::Auto, Some(p)) => p.readout_ms,
            (None, _, _) => params.shutter.readout_ms,
        };
        let warning = if pinned.is_some() {
            None
        } else {
            fallback_warning(how, &picture)
        };
        readout = Some((params.shutter.readout_ms, warning));
    }
    let mut cache: Option<Vec<(Frame, f64)>> = Some(Vec::new());
    let mut cached_bytes = 0usize;
    let mut stab = Stabilizer::new(lens, info.width, info.height, params.clone())?;
    stab.set_tracking_only(true);
    let mut seen: Vec<Telemetry> = Vec::new();
    let mut head = head.unwrap_or_default().into_iter();
    loop {
        let t = match head.next() {
            Some((f, t)) => {
                frame = f;
                t
            }
            None => match src.next_frame(&mut frame)? {
                Some(t) => t,
                None => break,
            },
        };
        check()?;
        seen.extend(stab.push(frame.as_ref(), t)?);
        cached_bytes += frame.data.len();
        match cache.as_mut() {
            Some(c) if cached_bytes <= CACHE_BYTES => c.push((take(&mut frame), t)),
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
    let FusedLog { poses, mut report } = match pool.install(|| fuse_log(log, &seen, readout_s)) {
        Ok(fused) => fused,
        Err(FuseLogError::Sync(e)) => {
            return Ok(FirstPass {
                fused: Err(video_only_warning(&e)),
                readout,
            })
        }
        Err(FuseLogError::Fuse(e)) => return Err(e.into()),
    };
    report.readout = from_log.as_ref().map(ReadoutReport::from);
    let size = (info.width, info.height);
    let cached = cache.map(|frames| CachedClip {
        info,
        frames: frames.into_iter(),
    });
    Ok(FirstPass {
        fused: Ok(Fused {
            poses,
            times: seen.iter().map(|tel| tel.t).collect(),
            size,
            report,
            cached,
        }),
        readout,
    })
}

/// What `auto` says where the log did not pin the readout down (the unset
/// default says nothing: it keeps its readout).
fn fallback_warning(how: MeasureReadout, picture: &Option<ReadoutEstimate>) -> Option<String> {
    match (how, picture) {
        (MeasureReadout::Unset, _) => None,
        (MeasureReadout::Auto, Some(p)) => Some(format!(
            "readout_ms=auto: the gyro log does not pin the readout down; using the picture's estimate, {:.1} ms",
            p.readout_ms
        )),
        (MeasureReadout::Auto, None) => Some(
            "readout_ms=auto: neither the gyro log nor the picture pins the readout down; assuming a global shutter (set readout_ms for best results)"
                .to_string(),
        ),
    }
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
