//! The streaming stabilizer: push a frame and its timestamp, get the stabilized
//! frame and its telemetry back.
//!
//! Per frame `j` (paper, Algorithm 1):
//! 1. track: `R_hat_{0,j} = R_hat_{0,k} R_hat_{k,j}` (template `k` reset every `N_track` frames);
//! 2. view: `R^view_{0,j}` from the SO(3) low-pass filter (or fixed, in saccade mode);
//! 3. frame: the zoom `z_j` that shows no border within the crop budget, the
//!    view pulled toward the camera where it would need more (`framing`);
//! 4. render: warp frames `i = j - N_avg + 1 ..= j` by `R_hat_{0,i}^T R^view_{0,j} Z_j^-1` and average.
//!
//! Memory is bounded by the averaging window (plus `lookahead` frames): the
//! frame ring, the accumulator and (saccade) the warped slots are allocated once
//! and reused; steady state allocates nothing per frame.

use crate::camera::CameraModel;
use crate::error::AmcError;
use crate::framing::{
    needed_zoom, pull_view, view_need, zoom_matrix, Border, Framer, FramingParams, Zoom,
};
use crate::frontend::TrackingFrontend;
use crate::image::{Frame, FrameRef, PixelFormat};
use crate::pyramid::Pyramid;
use crate::render::robust::weighted_average;
use crate::render::{chroma_camera, Accumulator, Deghost, RenderParams, WarpedFrame, Warper};
use crate::shutter::{
    GaugeEase, IntraFrame, RollingProjector, RowTime, ShutterParams, TrajectorySmoother,
};
use crate::so3::{self, Rot};
use crate::tracker::{TrackInfo, Tracker, TrackerParams};
use crate::view::{backward_pass, Mode, ViewParams};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// All parameters of the stabilizer: one definition shared by the CLI, the REST
/// API and the WASM API.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StabilizerParams {
    /// Width (pixels) of the grayscale image the tracker works on; frames are
    /// box-averaged by `floor(width / track_width)`. Range 32..=8192.
    pub track_width: usize,
    /// Rotation tracker.
    pub tracker: TrackerParams,
    /// View path (smoothing, lookahead, saccades).
    pub view: ViewParams,
    /// Output rendering (averaging, fixed margin, output size).
    pub render: RenderParams,
    /// Framing (zoom and crop budget).
    pub framing: FramingParams,
    /// The camera's shutter (rolling-shutter readout).
    pub shutter: ShutterParams,
}

impl Default for StabilizerParams {
    fn default() -> Self {
        Self {
            track_width: 320,
            tracker: TrackerParams::default(),
            view: ViewParams::default(),
            render: RenderParams::default(),
            framing: FramingParams::default(),
            shutter: ShutterParams::default(),
        }
    }
}

impl StabilizerParams {
    /// Checks every stage's parameters.
    pub fn validate(&self) -> Result<(), AmcError> {
        if !(32..=8192).contains(&self.track_width) {
            return Err(AmcError::invalid(
                "track_width",
                self.track_width,
                "32..=8192 pixels",
            ));
        }
        self.tracker.validate()?;
        self.view.validate()?;
        self.framing.validate()?;
        self.shutter.validate()?;
        self.render.validate()
    }
}

/// What the stabilizer knows about one output frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// Index of the input frame this output shows (0-based).
    pub frame: u64,
    /// Its timestamp, seconds.
    pub t: f64,
    /// Rotation vector (radians) of the estimated orientation `R_hat_{0,j}`.
    pub r_est: [f64; 3],
    /// Rotation vector (radians) of the view `R^view_{0,j}`.
    pub r_view: [f64; 3],
    /// Body angular velocity of the estimate, `log(R_{0,j-1}^T R_{0,j}) / dt`, rad/s.
    pub rate_est: [f64; 3],
    /// Body angular velocity of the view, rad/s.
    pub rate_view: [f64; 3],
    /// Share of output pixels covered by every averaged frame.
    pub valid_fraction: f64,
    /// Frames averaged into this output.
    pub frames_averaged: usize,
    /// True when the saccade view was re-centred at this frame.
    pub saccade: bool,
    /// Zoom of the output: `1 / zoom` is the share of the source's width it
    /// keeps (with `zoom = none`, `1 / (1 - 2 margin)`).
    pub zoom: f64,
    /// Output pixels no averaged frame covers (shown black; 0 with `zoom`
    /// `auto` or `static`); for planar frames, luma pixels.
    pub uncovered: u64,
    /// Rotation vector (radians, this frame's camera axes) of the camera's
    /// rotation across its readout, first row to last (`a(1/2) - a(-1/2)` of
    /// [`IntraFrame`]; about the readout time times the angular velocity at
    /// mid-readout). Zero with a global shutter.
    pub readout_rotation: [f64; 3],
    /// Tracking quality.
    pub track: TrackInfo,
}

struct Buffered {
    frame: Frame,
    index: u64,
    t: f64,
    r_est: Rot,
    /// Its motion during the readout (zero with a global shutter).
    intra: IntraFrame,
    /// Its rows' readout rotations as rendered (`Tracked::rendered`),
    /// tabulated (empty with a global shutter).
    rows: RollingProjector,
    info: TrackInfo,
    /// Forward-filtered view at this frame.
    view_fwd: Rot,
}

/// The tracking stage: frames in, orientations out.
struct Tracking {
    frontend: TrackingFrontend,
    tracker: Tracker,
    pyr: Pyramid,
    /// With a rolling shutter, the recent frames' poses and readout paths
    /// fitted as one trajectory, which gives each frame its pose (`None`: a
    /// global shutter, or switched off with
    /// [`Stabilizer::set_trajectory_smoothing`]).
    smoother: Option<TrajectorySmoother>,
    /// With a rolling shutter, the gauge's corrections eased into the
    /// rendered paths.
    ease: GaugeEase,
}

/// One frame as [`Tracking`] estimated it.
struct Tracked {
    /// `R_{0,j}`, at mid-readout.
    pose: Rot,
    /// Its motion during the readout, as best known (telemetry).
    path: IntraFrame,
    /// The motion its rows are rendered with: `path` with the gauge's latest
    /// corrections eased in ([`GaugeEase`]).
    rendered: IntraFrame,
    info: TrackInfo,
}

impl Tracking {
    /// Estimates the orientation of `frame`, taken at `t`.
    fn track(&mut self, frame: &FrameRef<'_>, t: f64) -> Tracked {
        let levels = self.tracker.levels();
        self.frontend.prepare(frame, &mut self.pyr, levels);
        let gauge_before = self.tracker.gauge_corrections();
        let (r, info) = self.tracker.track(&self.pyr, t);
        let mut pose = r;
        let mut path = self.tracker.intra();
        let mut corrections = self.tracker.gauge_corrections();
        if let Some(smoother) = &mut self.smoother {
            // The frames held were reported before this frame's correction
            // of the gauge, if it made one: they move with it, so that the
            // window keeps one common offset.
            smoother.regauge(&corrections.plus(&gauge_before, -1.0));
            let weight = if info.lost { 0.0 } else { 1.0 };
            let smoothed = smoother.push(t, r, path, weight);
            // At a slow pace the tracker fits `phi` alone, which leaves the
            // pose as certain as a global shutter's: there the fit only adds
            // its own assumptions (cc9 against its gyro: 0.057 -> 0.064 deg
            // per frame), and the tracker's own pose and gauge stand.
            if self.tracker.estimates_bend() {
                // A new template is rectified again with its path's level as
                // the trajectory finds it (the tracker's own gauge check is
                // slower and noisier); frames aligned to it inherit it.
                if let (true, Some(error)) = (info.template_reset, smoother.path_offset()) {
                    self.tracker.regauge_template(&error);
                    // This frame, pushed before, and the ones held move alike.
                    smoother.regauge(&self.tracker.gauge_corrections().plus(&corrections, -1.0));
                }
                pose = smoothed;
                path = self.tracker.intra();
                corrections = self.tracker.gauge_corrections();
                // Until the tracker first checks its gauge (8 frames), every
                // path is off by minus the first frame's: the trajectory's
                // offset finds it from the third frame on.
                if let (false, Some(offset)) =
                    (self.tracker.gauge_known(), smoother.fitted_offset())
                {
                    path = path.plus(&offset, -1.0);
                    corrections = corrections.plus(&offset, 1.0);
                }
            }
        }
        let rendered = self.ease.rendered(&path, &corrections);
        Tracked {
            pose,
            path,
            rendered,
            info,
        }
    }
}

/// The rendering stage: the ring's frames in, stabilized frames out. Apart
/// from [`Tracking`] so that the two can run at once (see
/// [`Stabilizer::set_pipelined`]).
struct Rendering {
    /// Renders colour frames, or the Y plane of planar ones.
    warper: Warper,
    /// Renders the U and V planes of 4:2:0 frames (the chroma cameras).
    chroma: Warper,
    /// Coverage of the chroma planes (reused; the luma's is reported).
    chroma_cov: Vec<u8>,
    out_cam: CameraModel,
    saccade_view: Option<Rot>,
    slots: VecDeque<WarpedFrame>,
    spare_slots: Vec<WarpedFrame>,
    acc: Accumulator,
    /// Ghost-free averaging of the saccade slots (the running sum `acc` is the
    /// plain average; the weights change with every newest frame, so the
    /// weighted one is merged from the slots per output, with the warper's
    /// [`Warper::deghost`]): its weighted sums and weights' sums (reused).
    merged_sum: Vec<u32>,
    merged_weight: Vec<u32>,
    rotations: Vec<nalgebra::Matrix3<f64>>,
    /// Forward-filtered views of the lookahead window (reused).
    window: Vec<(f64, Rot)>,
    output: Frame,
    next_out: u64,
    last_shown: Option<(f64, Rot, Rot)>,
    last_saccade: Option<u64>,
    /// The source camera (the one the frames were taken with).
    src_cam: CameraModel,
    /// The zoom over time.
    framer: Framer,
    /// The output's border, for the framing's coverage test.
    border: Border,
    /// Orientations of the averaged frames (reused).
    window_rots: Vec<Rot>,
    /// Rotations of the framing's coverage test (reused).
    need_rots: Vec<nalgebra::Matrix3<f64>>,
    /// Whether pixels are rendered (off: views and zoom needs only).
    render: bool,
    /// Which outputs this stabilizer renders: output `j` when `j % share.0 ==
    /// share.1` ([`Stabilizer::set_render_share`]); `(1, 0)`: every one.
    share: (u64, u64),
    /// Lock mode's view: the first frame's orientation.
    locked_view: Option<Rot>,
    /// The zoom of mode none (the camera's own view, the same on every frame).
    camera_zoom: f64,
    /// Highest need of a smoothed view so far.
    max_need: f64,
}

/// Most stabilizers that can share the outputs ([`Stabilizer::set_render_share`]).
pub const MAX_RENDER_SHARE: u32 = 16;

/// Most saccade slots merged at once (the range of `n_avg`).
const MAX_SLOTS: usize = 64;

/// The streaming stabilizer (one per clip).
pub struct Stabilizer {
    params: StabilizerParams,
    width: usize,
    height: usize,
    format: Option<PixelFormat>,
    tracking: Tracking,
    rendering: Rendering,
    ring: VecDeque<Buffered>,
    /// Buffers of frames that left the ring, for reuse.
    spare: Vec<(Frame, RollingProjector)>,
    view_fwd: Rot,
    received: u64,
    last_t: Option<f64>,
    /// Render output `j` while tracking frame `j + 1 + lookahead` (on the
    /// caller's rayon pool with the `parallel` feature).
    pipelined: bool,
}

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
            params,
        })
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
    fn needs_static_zoom(&self) -> bool {
        self.params.framing.zoom == Zoom::Static
            && matches!(self.params.view.mode, Mode::Stabilize | Mode::Lock)
            && self.rendering.render
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

    /// Pushes frame `t` seconds into the clip. Returns the telemetry of the
    /// output frame that became ready (`None` while the lookahead fills); read
    /// the pixels with [`Stabilizer::output`].
    pub fn push(&mut self, frame: FrameRef<'_>, t: f64) -> Result<Option<Telemetry>, AmcError> {
        if frame.width != self.width || frame.height != self.height {
            return Err(AmcError::FrameSizeChanged {
                expected_w: self.width,
                expected_h: self.height,
                actual_w: frame.width,
                actual_h: frame.height,
            });
        }
        if let Some(format) = self.format.filter(|&f| f != frame.format) {
            return Err(AmcError::FormatChanged {
                expected: format,
                actual: frame.format,
            });
        }
        let expected =
            frame
                .format
                .buffer_len(self.width, self.height)
                .ok_or(AmcError::FrameTooLarge {
                    width: self.width,
                    height: self.height,
                })?;
        if frame.data.len() != expected {
            return Err(AmcError::BufferLength {
                expected,
                actual: frame.data.len(),
            });
        }
        if !t.is_finite() {
            return Err(AmcError::NonFiniteTimestamp(t));
        }
        if self.needs_static_zoom() {
            return Err(AmcError::invalid(
                "zoom",
                "static",
                "static only once its zoom is known: make a first pass with \
                 set_rendering(false), then set_static_zoom(max_zoom_need()) on the \
                 stabilizer that renders; or auto or none",
            ));
        }
        if let Some(prev) = self.last_t {
            if t <= prev {
                return Err(AmcError::NonMonotonicTimestamp { t, prev });
            }
        }
        let dt = self.last_t.map_or(0.0, |p| t - p);
        self.last_t = Some(t);
        if self.format.is_none() {
            self.format = Some(frame.format);
            let (w, h) = self.output_size();
            self.rendering.output = Frame::new(w, h, frame.format);
        }

        let lookahead = self.params.view.lookahead as u64;
        // Pipelined, the output that became ready at the previous push is
        // rendered now, beside the tracking of this frame (the ring still
        // holds every frame it needs: this one is added after).
        let pending = self.pipelined && self.received > lookahead + self.rendering.next_out;
        let src = (self.width, self.height);
        let (tracked, rendered) = if pending {
            let (tracking, rendering) = (&mut self.tracking, &mut self.rendering);
            let (ring, params) = (&self.ring, &self.params);
            join(
                || tracking.track(&frame, t),
                || Some(rendering.render_next(ring, params, src)),
            )
        } else {
            (self.tracking.track(&frame, t), None)
        };
        let Tracked {
            pose: r_est,
            path: intra,
            rendered: rendered_path,
            info,
        } = tracked;
        self.view_fwd = if self.received == 0 {
            r_est
        } else {
            self.params.view.step(&self.view_fwd, &r_est, dt)
        };

        let capacity = self.params.render.n_avg + self.params.view.lookahead;
        if self.ring.len() >= capacity {
            if let Some(old) = self.ring.pop_front() {
                self.spare.push((old.frame, old.rows));
            }
        }
        let (mut buf, mut rows) = self
            .spare
            .pop()
            .unwrap_or_else(|| (Frame::new(0, 0, frame.format), RollingProjector::default()));
        rows.set(&rendered_path, self.height);
        buf.copy_from(&frame);
        // Tail padding for the vectorized sampler's dword gathers.
        buf.data
            .extend_from_slice(&[0; crate::render::kernels::FRAME_PADDING]);
        self.ring.push_back(Buffered {
            frame: buf,
            index: self.received,
            t,
            r_est,
            intra,
            rows,
            info,
            view_fwd: self.view_fwd,
        });
        self.received += 1;

        if self.pipelined {
            Ok(rendered)
        } else if self.received > lookahead {
            Ok(Some(self.render_next()))
        } else {
            Ok(None)
        }
    }

    /// After the last frame: returns the next output still held back by the
    /// lookahead (or the pipeline), or `None` when all are out.
    pub fn finish(&mut self) -> Option<Telemetry> {
        (self.rendering.next_out < self.received).then(|| self.render_next())
    }

    /// Renders the next output from the ring.
    fn render_next(&mut self) -> Telemetry {
        let src = (self.width, self.height);
        self.rendering.render_next(&self.ring, &self.params, src)
    }
}

/// Runs `a` and `b`, at once on the rayon pool with the `parallel` feature.
fn join<A, B, RA, RB>(a: A, b: B) -> (RA, RB)
where
    A: FnOnce() -> RA + Send,
    B: FnOnce() -> RB + Send,
    RA: Send,
    RB: Send,
{
    #[cfg(feature = "parallel")]
    {
        rayon::join(a, b)
    }
    #[cfg(not(feature = "parallel"))]
    {
        (a(), b())
    }
}

impl Rendering {
    /// Renders output frame `self.next_out` from `ring` (frames of size `src`).
    fn render_next(
        &mut self,
        ring: &VecDeque<Buffered>,
        params: &StabilizerParams,
        src: (usize, usize),
    ) -> Telemetry {
        let j = self.next_out;
        self.next_out += 1;
        let render = self.render && j % self.share.0 == self.share.1;
        let pos = ring.iter().position(|b| b.index == j).unwrap_or(0);
        let cur = &ring[pos];
        let (t, r_est, info) = (cur.t, cur.r_est, cur.info);
        let mode = params.view.mode;
        let window = match mode {
            Mode::None => 1,
            _ => params.render.n_avg,
        };
        let first = pos + 1 - window.min(pos + 1);
        let mut saccade = false;
        self.window_rots.clear();
        self.window_rots
            .extend(ring.range(first..=pos).map(|b| b.r_est));
        if params.shutter.is_rolling() {
            // The window's readout rows, for the coverage test and the render.
            self.warper
                .set_readout_rows(ring.range(first..=pos).map(|b| &b.rows));
            self.chroma.set_readout_rows(self.warper.readout_rows());
        }
        let mut r_view = match mode {
            Mode::None => r_est,
            Mode::Stabilize => {
                let filtered = if params.view.lookahead == 0 {
                    cur.view_fwd
                } else {
                    self.window.clear();
                    self.window
                        .extend(ring.iter().skip(pos).map(|b| (b.t, b.view_fwd)));
                    backward_pass(&params.view, &self.window)
                };
                params.view.roll.apply(&filtered, &r_est)
            }
            Mode::Saccade => *self.saccade_view.get_or_insert(r_est),
            Mode::Lock => *self.locked_view.get_or_insert(r_est),
        };

        // Framing: the zoom of this output, and the view within it.
        let zoomed = params.framing.zoom != Zoom::None;
        let zoom = if !zoomed {
            1.0
        } else if mode == Mode::None {
            if params.shutter.is_rolling() {
                // Rows rendered at their own orientations no longer fill the
                // frame: the least zoom that shows no border, per frame.
                let need = self.need(&r_view);
                self.camera_zoom.max(need).min(params.framing.max_zoom())
            } else {
                self.camera_zoom
            }
        } else {
            let need = self.need(&r_view);
            self.max_need = self.max_need.max(need);
            let z = self.framer.next(t, need);
            if need > z {
                if mode == Mode::Saccade && j > 0 {
                    // A border would show: re-centre now, whatever the refractory period.
                    saccade = true;
                } else {
                    let (pulled, _) = pull_view(
                        &self.src_cam,
                        &self.border,
                        &self.window_rots,
                        self.warper.readout_rows(),
                        &r_view,
                        &r_est,
                        z,
                        &mut self.need_rots,
                    );
                    r_view = pulled;
                }
            }
            z
        };
        let zinv = zoom_matrix(zoom);

        let format = self.output.format;
        let channels = format.channels();
        let (ow, oh) = (self.out_cam.width, self.out_cam.height);
        let mut valid_fraction = 0.0;
        if !render {
            // First pass of `zoom = static`, or another stabilizer's share:
            // views and needs only.
        } else if mode == Mode::Saccade {
            if saccade {
                self.last_saccade = Some(j);
                self.saccade_view = Some(r_est);
                self.slots.drain(..).for_each(|s| self.spare_slots.push(s));
                r_view = r_est;
            }
            self.saccade_update(ring, src, first, pos, &r_view, &zinv);
            let full = self.slots.len() as u8;
            let mut vf = self.finish_saccade(full);
            // After a saccade the older frames of the window cannot cover the new
            // view; coverage by every averaged frame recovers only once the
            // window has refilled, so the next saccade waits `n_avg` frames
            // (without this, strong motion re-centres on every frame).
            let refractory = self
                .last_saccade
                .is_some_and(|s| j < s + params.render.n_avg as u64);
            if vf < params.view.saccade_coverage && j > 0 && !refractory {
                self.last_saccade = Some(j);
                // Re-centre the view on the current estimate and rebuild the sums.
                saccade = true;
                self.saccade_view = Some(r_est);
                self.slots.drain(..).for_each(|s| self.spare_slots.push(s));
                self.saccade_update(ring, src, first, pos, &r_est, &zinv);
                let full = self.slots.len() as u8;
                vf = self.finish_saccade(full);
            }
            valid_fraction = vf;
        } else {
            self.rotations.clear();
            self.rotations.extend(
                ring.range(first..=pos)
                    .map(|b| b.r_est.matrix().transpose() * r_view.matrix() * zinv),
            );
            valid_fraction = if format.is_planar() {
                // One geometry, three planes: Y through the luma cameras, U and V
                // through the chroma cameras, all with the same rotations.
                let (w, h) = (src.0, src.1);
                let (cw, ch) = crate::image::chroma_size(w, h);
                let (u_at, v_at) = crate::image::yuv_plane_offsets(w, h);
                let (oy, ou, ov) = crate::image::yuv_planes_mut(ow, oh, &mut self.output.data);
                // Each plane is passed with what follows it in the buffer (the
                // next planes, then the tail padding) for the kernels' gathers.
                let plane = |i: usize, at: usize| &ring[first + i].frame.data[at..];
                let complete = self.warper.average_plane_into(
                    |i| plane(i, 0),
                    w,
                    h,
                    &self.rotations,
                    oy,
                    &mut self.acc.count,
                    16,
                );
                self.chroma.average_plane_pair_into(
                    |i| (plane(i, u_at), plane(i, v_at)),
                    cw,
                    ch,
                    &self.rotations,
                    ou,
                    ov,
                    &mut self.chroma_cov,
                    128,
                );
                complete as f64 / (ow * oh).max(1) as f64
            } else {
                self.warper.average_into(
                    |i| ring[first + i].frame.as_ref(),
                    &self.rotations,
                    &mut self.output.data,
                    channels,
                    &mut self.acc.count,
                )
            };
        }
        let r_view = if saccade { r_est } else { r_view };
        let uncovered = if render {
            let n = (ow * oh).min(self.acc.count.len());
            self.acc.count[..n].iter().filter(|&&c| c == 0).count() as u64
        } else {
            0
        };

        let (rate_est, rate_view) = match self.last_shown {
            Some((tp, rp, vp)) if t > tp => (
                so3::body_rate(&rp, &r_est, t - tp),
                so3::body_rate(&vp, &r_view, t - tp),
            ),
            _ => Default::default(),
        };
        self.last_shown = Some((t, r_est, r_view));
        Telemetry {
            frame: j,
            t,
            r_est: so3::log(&r_est).into(),
            r_view: so3::log(&r_view).into(),
            rate_est: rate_est.into(),
            rate_view: rate_view.into(),
            valid_fraction,
            frames_averaged: pos + 1 - first,
            saccade,
            zoom: if zoomed {
                zoom
            } else {
                1.0 / (1.0 - 2.0 * params.render.margin)
            },
            uncovered,
            readout_rotation: (cur.intra.at(0.5) - cur.intra.at(-0.5)).into(),
            track: info,
        }
    }

    /// The zoom at which `view` shows no border with the averaged frames
    /// `self.window_rots`.
    fn need(&mut self, view: &Rot) -> f64 {
        view_need(
            &self.src_cam,
            &self.border,
            &self.window_rots,
            self.warper.readout_rows(),
            view,
            &mut self.need_rots,
        )
    }

    /// Writes the saccade sums into the output frame; returns the share of
    /// pixels covered by `full` frames.
    fn finish_saccade(&mut self, full: u8) -> f64 {
        let (ow, oh) = (self.out_cam.width, self.out_cam.height);
        if let Some(deghost) = self.warper.deghost().filter(|_| self.slots.len() > 1) {
            self.finish_saccade_merged(deghost, full)
        } else if self.output.format.is_planar() {
            self.acc
                .finish_yuv420_into(&mut self.output.data, ow, oh, full)
        } else {
            let channels = self.output.format.channels();
            self.acc.finish_into(&mut self.output.data, channels, full)
        }
    }

    /// [`Rendering::finish_saccade`] with ghost-free averaging: merges the
    /// slots against the newest one, plane by plane (or the three interleaved
    /// channels at once), into the output frame.
    fn finish_saccade_merged(&mut self, deghost: Deghost, full: u8) -> f64 {
        let (ow, oh) = (self.out_cam.width, self.out_cam.height);
        let n_px = ow * oh;
        let n = self.slots.len().min(MAX_SLOTS);
        let reference = n - 1;
        let slots = &self.slots;
        let (sum, weight) = (&mut self.merged_sum, &mut self.merged_weight);
        if self.output.format.is_planar() {
            let (cw, ch) = crate::image::chroma_size(ow, oh);
            let nc = cw * ch;
            sum.resize(n_px, 0);
            weight.resize(n_px, 0);
            let (oy, ou, ov) = crate::image::yuv_planes_mut(ow, oh, &mut self.output.data);
            // (output plane, its values' offset in a slot, its coverage's, size, fill)
            let planes = [
                (oy, 0, 0, n_px, 16u8),
                (ou, n_px, n_px, nc, 128),
                (ov, n_px + nc, n_px, nc, 128),
            ];
            for (out, at, cov_at, len, fill) in planes {
                let mut values: [&[u16]; MAX_SLOTS] = [&[]; MAX_SLOTS];
                let mut covered: [&[u8]; MAX_SLOTS] = [&[]; MAX_SLOTS];
                for (f, slot) in slots.iter().take(n).enumerate() {
                    values[f] = &slot.value[at..at + len];
                    covered[f] = &slot.covered[cov_at..cov_at + len];
                }
                deghost.merge_plane(&values[..n], &covered[..n], reference, len, sum, weight);
                for ((o, &s), &w) in out.iter_mut().zip(&sum[..len]).zip(&weight[..len]) {
                    *o = weighted_average(s, w, fill);
                }
            }
        } else {
            let channels = self.output.format.channels();
            sum.resize(3 * n_px, 0);
            weight.resize(n_px, 0);
            let mut values: [[&[u16]; 3]; MAX_SLOTS] = [[&[]; 3]; MAX_SLOTS];
            let mut covered: [&[u8]; MAX_SLOTS] = [&[]; MAX_SLOTS];
            for (f, slot) in slots.iter().take(n).enumerate() {
                let v = &slot.value[..];
                values[f] = [v, &v[1..], &v[2..]];
                covered[f] = &slot.covered;
            }
            let (sr, rest) = sum.split_at_mut(n_px);
            let (sg, sb) = rest.split_at_mut(n_px);
            deghost.merge_rgb(
                &values[..n],
                3,
                &covered[..n],
                reference,
                n_px,
                [sr, sg, sb],
                weight,
            );
            for (i, px) in self.output.data[..channels * n_px]
                .chunks_exact_mut(channels)
                .enumerate()
            {
                let w = weight[i];
                px[0] = weighted_average(sr[i], w, 0);
                px[1] = weighted_average(sg[i], w, 0);
                px[2] = weighted_average(sb[i], w, 0);
                if channels == 4 {
                    px[3] = 255;
                }
            }
        }
        let complete = self.acc.count[..n_px]
            .iter()
            .filter(|&&k| k >= full)
            .count();
        complete as f64 / n_px.max(1) as f64
    }

    /// Saccade mode's recursive update: keeps one warped slot per frame of the
    /// window, warps only frames not yet warped into `view`, and maintains the
    /// running sum by adding the newest and subtracting the oldest.
    fn saccade_update(
        &mut self,
        ring: &VecDeque<Buffered>,
        src: (usize, usize),
        first: usize,
        pos: usize,
        view: &Rot,
        zinv: &nalgebra::Matrix3<f64>,
    ) {
        let (ow, oh) = (self.out_cam.width, self.out_cam.height);
        let n_px = ow * oh;
        let planar = self.output.format.is_planar();
        let (cw, ch) = crate::image::chroma_size(ow, oh);
        let nc = cw * ch;
        let first_index = ring[first].index;
        if self.slots.is_empty() {
            if planar {
                self.acc.reset_to(n_px + 2 * nc, n_px + nc);
            } else {
                self.acc.reset(n_px);
            }
        }
        while self.slots.front().is_some_and(|s| s.index < first_index) {
            if let Some(old) = self.slots.pop_front() {
                old.apply(&mut self.acc, false);
                self.spare_slots.push(old);
            }
        }
        let have_until = self
            .slots
            .back()
            .map(|s| s.index + 1)
            .unwrap_or(first_index);
        for b in ring.range(first..=pos) {
            if b.index < have_until {
                continue;
            }
            let m = b.r_est.matrix().transpose() * view.matrix() * zinv;
            let rows = std::slice::from_ref(&b.rows);
            self.warper.set_readout_rows(rows);
            self.chroma.set_readout_rows(rows);
            let mut slot = self.spare_slots.pop().unwrap_or_default();
            if planar {
                let (w, h) = (src.0, src.1);
                let (scw, sch) = crate::image::chroma_size(w, h);
                let (u_at, v_at) = crate::image::yuv_plane_offsets(w, h);
                slot.index = b.index;
                slot.value.clear();
                slot.value.resize(n_px + 2 * nc, 0);
                slot.covered.clear();
                slot.covered.resize(n_px + nc, 0);
                self.chroma_cov.resize(nc, 0);
                let (vy, vc) = slot.value.split_at_mut(n_px);
                let (vu, vv) = vc.split_at_mut(nc);
                let (cy, cc) = slot.covered.split_at_mut(n_px);
                let data = &b.frame.data;
                self.warper.warp_plane_into(data, w, h, &m, vy, cy);
                self.chroma
                    .warp_plane_into(&data[u_at..], scw, sch, &m, vu, cc);
                self.chroma
                    .warp_plane_into(&data[v_at..], scw, sch, &m, vv, &mut self.chroma_cov);
            } else {
                self.warper
                    .warp_into_slot(&b.frame.as_ref(), &m, &mut slot, b.index);
            }
            slot.apply(&mut self.acc, true);
            self.slots.push_back(slot);
        }
    }
}
