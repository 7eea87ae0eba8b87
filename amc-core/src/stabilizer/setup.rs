//! Building a stabilizer, its settings and what it reports between frames.

use super::params::StabilizerParams;
use super::rendering::Rendering;
use super::tracking::Tracking;
use super::Stabilizer;
use crate::camera::CameraModel;
use crate::error::AmcError;
use crate::framing::{needed_zoom, Border, Framer, Zoom};
use crate::frontend::TrackingFrontend;
use crate::image::{Frame, FrameRef, PixelFormat};
use crate::pyramid::Pyramid;
use crate::render::{chroma_camera, Accumulator, AutoDeghost, DeghostLevel, Warper};
use crate::shutter::{GaugeEase, RowTime, TrajectorySmoother};
use crate::so3::Rot;
use crate::tracker::Tracker;
use crate::view::Mode;
use std::collections::VecDeque;

/// Most stabilizers that can share the outputs ([`Stabilizer::set_render_share`]).
pub const MAX_RENDER_SHARE: u32 = 16;

impl Stabilizer {
    /// A stabilizer for `width x height` frames through `lens`. A lens calibrated
    /// at another resolution of the same aspect ratio is rescaled.
    pub fn new(
        lens: &CameraModel,
        width: usize,
        height: usize,
        params: StabilizerParams,
    ) -> Result<Self, AmcError> {
        params.validate()?;
        if width == 0 || height == 0 {
            return Err(AmcError::EmptyFrame { width, height });
        }
        if width > 16384 || height > 16384 {
            return Err(AmcError::FrameTooLarge { width, height });
        }
        lens.validate()?;
        let cam = if lens.width == width && lens.height == height {
            lens.clone()
        } else {
            let (ra, rb) = (
                lens.width as f64 / lens.height as f64,
                width as f64 / height as f64,
            );
            if (ra / rb - 1.0).abs() > 0.01 {
                return Err(AmcError::LensAspectMismatch {
                    width,
                    height,
                    lens_w: lens.width,
                    lens_h: lens.height,
                });
            }
            lens.rescaled(width, height)
        };
        let frontend = TrackingFrontend::new(&cam, params.track_width)?;
        let mut tracker = Tracker::new(frontend.camera(), params.tracker.clone())?;
        if params.shutter.is_rolling() {
            tracker.set_rolling(
                RowTime::new(&cam, frontend.camera()),
                params.shutter.readout_s(),
            );
        }
        let zoomed = params.framing.zoom != Zoom::None;
        let margin = if zoomed { 0.0 } else { params.render.margin };
        let out_cam = params.render.output_camera_with_margin(&cam, margin)?;
        let mut framer = Framer::new(params.framing.clone());
        if zoomed && params.view.mode == Mode::Saccade {
            // A fixed view: the zoom may not change within a saccade, so it is
            // the budget's, and a saccade comes before any border would show.
            framer.set_fixed(params.framing.max_zoom());
        }
        let border = Border::new(&out_cam);
        // Mode none shows the camera's own view (`M = I` on every frame): only
        // its lens can leave pixels uncovered (an off-centre principal point, the
        // corners of an undistorted barrel lens), so it needs one zoom, with no
        // smoothing and no budget. A centred pinhole of the output's size maps
        // onto itself exactly: zoom 1, the input unchanged.
        let identity = cam.is_pinhole()
            && (cam.width, cam.height) == (out_cam.width, out_cam.height)
            && cam.k_matrix() == out_cam.k_matrix();
        let camera_zoom = if identity {
            1.0
        } else {
            needed_zoom(&cam, &border, &[nalgebra::Matrix3::identity()], &[])
        };
        // Anti-aliasing of minified outputs: the chroma planes have the same
        // footprint (both cameras halved), so one factor serves all planes.
        let supersample = params.render.supersample(&cam, &out_cam);
        let mut warper = Warper::supersampled(&cam, &out_cam, supersample);
        let mut chroma =
            Warper::supersampled(&chroma_camera(&cam), &chroma_camera(&out_cam), supersample);
        warper.set_deghost(params.render.deghost());
        chroma.set_deghost(params.render.deghost());
        warper.set_interpolation(params.render.interpolation);
        chroma.set_interpolation(params.render.interpolation);
        Ok(Self {
            width,
            height,
            format: None,
            tracking: Tracking {
                frontend,
                tracker,
                pyr: Pyramid::default(),
                smoother: params
                    .shutter
                    .is_rolling()
                    .then(|| TrajectorySmoother::new(params.shutter.readout_s())),
                ease: GaugeEase::default(),
            },
            rendering: Rendering {
                warper,
                chroma,
                chroma_cov: Vec::new(),
                out_cam,
                saccade_view: None,
                slots: VecDeque::new(),
                spare_slots: Vec::new(),
                acc: Accumulator::default(),
                merged_sum: Vec::new(),
                merged_weight: Vec::new(),
                rotations: Vec::new(),
                window: Vec::new(),
                output: Frame::new(0, 0, PixelFormat::Rgb8),
                next_out: 0,
                last_shown: None,
                last_saccade: None,
                src_cam: cam.clone(),
                framer,
                border,
                window_rots: Vec::new(),
                need_rots: Vec::new(),
                render: true,
                tracking_only: false,
                share: (1, 0),
                locked_view: None,
                camera_zoom,
                max_need: 1.0,
            },
            ring: VecDeque::new(),
            spare: Vec::new(),
            view_fwd: Rot::identity(),
            received: 0,
            last_t: None,
            pipelined: false,
            auto_deghost: (params.render.deghost == DeghostLevel::Auto).then(AutoDeghost::default),
            params,
        })
    }

    /// The ghost-free average's threshold, levels of 255: the one given, or
    /// with `deghost=auto` the one in force now (`None` before the first
    /// frame); 0: the plain average.
    pub fn deghost_levels(&self) -> Option<f64> {
        match self.params.render.deghost {
            DeghostLevel::Levels(l) => Some(l),
            DeghostLevel::Auto => self.auto_deghost.as_ref().and_then(|a| a.levels()),
        }
    }

    /// Output frame size.
    pub fn output_size(&self) -> (usize, usize) {
        (self.rendering.out_cam.width, self.rendering.out_cam.height)
    }

    /// The output (pinhole) camera.
    pub fn output_camera(&self) -> &CameraModel {
        &self.rendering.out_cam
    }

    /// The undistorted pinhole camera the tracker works on.
    pub fn tracking_camera(&self) -> &CameraModel {
        self.tracking.frontend.camera()
    }

    /// With a rolling shutter, each frame's pose is read off one trajectory
    /// fitted through the recent frames' poses and readout paths
    /// ([`TrajectorySmoother`]); on by default. Off, it is the tracker's own
    /// per-frame estimate: the readout estimator measures the readout from
    /// those, which the fit would tie to the nominal readout it tracks with.
    /// No effect with a global shutter. Set it before the first frame.
    pub fn set_trajectory_smoothing(&mut self, on: bool) {
        let shutter = &self.params.shutter;
        self.tracking.smoother =
            (on && shutter.is_rolling()).then(|| TrajectorySmoother::new(shutter.readout_s()));
    }

    /// Pipelining: when on, each [`Stabilizer::push`] renders the output that
    /// became ready at the *previous* push while it tracks its own frame (both
    /// at once on the caller's rayon pool with the `parallel` feature; in turn
    /// without it). Outputs are the same, bytes and telemetry, each one push
    /// later (one more frame of latency; [`Stabilizer::finish`] returns the
    /// last). Off by default. Set it before the first frame.
    pub fn set_pipelined(&mut self, on: bool) {
        if self.received == 0 {
            self.pipelined = on;
        }
    }

    /// Rendering: off, [`Stabilizer::push`] and [`Stabilizer::finish`] still
    /// track, filter and frame every output (telemetry, [`Stabilizer::max_zoom_need`])
    /// but leave the output's pixels alone: the first pass of `zoom = static`.
    /// On by default.
    pub fn set_rendering(&mut self, on: bool) {
        self.rendering.render = on;
    }

    /// Tracking only: [`Stabilizer::push`] and [`Stabilizer::finish`] track
    /// every frame and return its telemetry (the pose, the readout path, how
    /// tracking went), with no view filter, framing or pixels (the view is
    /// the camera's own, the zoom 1): the first pass of a run with a gyro,
    /// which needs the picture's motion alone. Off by default.
    pub fn set_tracking_only(&mut self, on: bool) {
        self.rendering.tracking_only = on;
    }

    /// Renders only outputs `j` with `j % count == index`: the others are
    /// tracked, filtered and framed as with [`Stabilizer::set_rendering`] off
    /// (their telemetry has `valid_fraction` 0 and `uncovered` 0, and the
    /// output's pixels are left as they were). `count` stabilizers fed the same
    /// frames, with `index` `0..count`, then render every output once between
    /// them, each byte for byte as one stabilizer would (the tracker, the view
    /// filter and the framing see every frame in each): how the browser, which
    /// has one core per worker and no shared memory, puts more cores to work.
    /// The default is `(1, 0)`.
    ///
    /// Saccade mode builds each output on the previous one's warped frames,
    /// so it takes only `count` 1. Errors: `count` 0 or above [`MAX_RENDER_SHARE`],
    /// `index >= count`, or `count > 1` in saccade mode.
    pub fn set_render_share(&mut self, count: u32, index: u32) -> Result<(), AmcError> {
        if count == 0 || count > MAX_RENDER_SHARE {
            return Err(AmcError::invalid("render share count", count, "1 to 16"));
        }
        if index >= count {
            return Err(AmcError::invalid(
                "render share index",
                index,
                "0 to the share count - 1",
            ));
        }
        if count > 1 && self.params.view.mode == Mode::Saccade {
            return Err(AmcError::invalid(
                "render share count",
                count,
                "1 in saccade mode (each output builds on the previous one's frames)",
            ));
        }
        self.rendering.share = (count.into(), index.into());
        Ok(())
    }

    /// `zoom = static`: holds the zoom at `zoom` (clamped to the budget) for
    /// every output; the view is pulled toward the camera where it needs more.
    /// Used in stabilize and lock modes; ignored with `zoom = none`, in saccade
    /// mode (whose zoom is fixed anyway) and in mode none.
    pub fn set_static_zoom(&mut self, zoom: f64) {
        let mode = self.params.view.mode;
        if self.params.framing.zoom != Zoom::None && matches!(mode, Mode::Stabilize | Mode::Lock) {
            self.rendering.framer.set_fixed(zoom);
        }
    }

    /// Whether this stabilizer renders with `zoom = static` but was not told
    /// the zoom yet ([`Stabilizer::set_static_zoom`]).
    pub(super) fn needs_static_zoom(&self) -> bool {
        self.params.wants_static_zoom()
            && self.rendering.render
            && !self.rendering.tracking_only
            && self.rendering.framer.fixed().is_none()
    }

    /// The highest zoom any smoothed view needed so far to show no border
    /// (before pulls, at least 1): after a pass without rendering, the zoom
    /// `static` holds, once clamped to the budget.
    pub fn max_zoom_need(&self) -> f64 {
        self.rendering.max_need
    }

    /// Parameters in use.
    pub fn params(&self) -> &StabilizerParams {
        &self.params
    }

    /// The latest output frame (valid after `push`/`finish` returned telemetry).
    pub fn output(&self) -> FrameRef<'_> {
        self.rendering.output.as_ref()
    }

    /// Per-pixel count of frames averaged into the latest output (0 = black
    /// border); for planar frames, of its luma pixels.
    pub fn output_coverage(&self) -> &[u8] {
        let (w, h) = self.output_size();
        let count = &self.rendering.acc.count;
        &count[..(w * h).min(count.len())]
    }
}
