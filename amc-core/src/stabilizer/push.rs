//! The stream: each pushed frame is tracked into the ring, and each output
//! the lookahead lets out is rendered (beside the next frame's tracking when
//! pipelined).

use super::buffered::Buffered;
use super::telemetry::Telemetry;
use super::tracking::Tracked;
use super::Stabilizer;
use crate::error::AmcError;
use crate::image::{Frame, FrameRef};
use crate::shutter::{IntraFrame, RollingProjector};
use crate::so3::Rot;
use crate::tracker::TrackInfo;

/// A frame's motion given from outside the tracker ([`Stabilizer::push_posed`]).
/// Serializable: the page hands a gyro pass's poses to its render helpers.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GivenPose {
    /// `R_{0,j}`, mid-readout.
    pub pose: Rot,
    /// Its motion during the readout (zero with a global shutter).
    pub path: IntraFrame,
    /// How tracking went on it, for the telemetry.
    pub info: TrackInfo,
}

impl Stabilizer {
    /// Pushes frame `t` seconds into the clip. Returns the telemetry of the
    /// output frame that became ready (`None` while the lookahead fills); read
    /// the pixels with [`Stabilizer::output`].
    pub fn push(&mut self, frame: FrameRef<'_>, t: f64) -> Result<Option<Telemetry>, AmcError> {
        let dt = self.begin(&frame, t)?;
        // Pipelined, the output that became ready at the previous push is
        // rendered now, beside the tracking of this frame (the ring still
        // holds every frame it needs: this one is added after).
        let pending = self.output_pending();
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
        self.enqueue(&frame, t, dt, tracked);
        Ok(self.ready(rendered))
    }

    /// Pushes frame `t` seconds into the clip with its motion known (a gyro
    /// fused with a first pass's tracking, [`crate::gyro::fuse`]): nothing is
    /// tracked; the frame is filtered, framed and rendered with `given` as
    /// [`Stabilizer::push`] would with the tracker's. Frames of one clip go
    /// through one of the two.
    pub fn push_posed(
        &mut self,
        frame: FrameRef<'_>,
        t: f64,
        given: GivenPose,
    ) -> Result<Option<Telemetry>, AmcError> {
        let dt = self.begin(&frame, t)?;
        let rendered = self.output_pending().then(|| self.render_next());
        let tracked = Tracked {
            pose: given.pose,
            path: given.path,
            rendered: given.path,
            info: given.info,
        };
        self.enqueue(&frame, t, dt, tracked);
        Ok(self.ready(rendered))
    }

    /// Checks a pushed frame and starts the stream's clock and output on the
    /// first; returns the time since the previous frame (0 for the first).
    fn begin(&mut self, frame: &FrameRef<'_>, t: f64) -> Result<f64, AmcError> {
        self.check_frame(frame, t)?;
        let dt = self.last_t.map_or(0.0, |p| t - p);
        self.last_t = Some(t);
        if self.format.is_none() {
            self.format = Some(frame.format);
            let (w, h) = self.output_size();
            self.rendering.output = Frame::new(w, h, frame.format);
        }
        Ok(dt)
    }

    /// Filters the view with a tracked frame and adds it to the ring.
    fn enqueue(&mut self, frame: &FrameRef<'_>, t: f64, dt: f64, tracked: Tracked) {
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
        buf.copy_from(frame);
        // Tail padding for the vectorized sampler's dword gathers.
        buf.data
            .extend_from_slice(&[0; crate::render::kernels::FRAME_PADDING]);
        let deghost = self
            .auto_deghost
            .as_mut()
            .and_then(|a| a.observe(self.received, frame));
        self.ring.push_back(Buffered {
            frame: buf,
            index: self.received,
            t,
            r_est,
            intra,
            rows,
            info,
            view_fwd: self.view_fwd,
            deghost,
        });
        self.received += 1;
    }

    /// Pipelined, whether the previous push made an output ready that is
    /// not rendered yet.
    fn output_pending(&self) -> bool {
        let lookahead = self.params.view.lookahead as u64;
        self.pipelined && self.received > lookahead + self.rendering.next_out
    }

    /// The output ready after a push: the one rendered beside it when
    /// pipelined, else the next one once the lookahead is full.
    fn ready(&mut self, rendered: Option<Telemetry>) -> Option<Telemetry> {
        if self.pipelined {
            rendered
        } else if self.received > self.params.view.lookahead as u64 {
            Some(self.render_next())
        } else {
            None
        }
    }

    /// Checks a pushed frame against the stream's size, format and clock.
    fn check_frame(&self, frame: &FrameRef<'_>, t: f64) -> Result<(), AmcError> {
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
        Ok(())
    }

    /// After the last frame: returns the next output still held back by the
    /// lookahead (or the pipeline), or `None` when all are out.
    pub fn finish(&mut self) -> Option<Telemetry> {
        (self.rendering.next_out < self.received).then(|| self.render_next())
    }

    /// Renders the next output from the ring.
    pub(super) fn render_next(&mut self) -> Telemetry {
        let src = (self.width, self.height);
        self.rendering.render_next(&self.ring, &self.params, src)
    }
}

/// Runs `a` and `b`, at once on the rayon pool with the `parallel` feature.
pub(super) fn join<A, B, RA, RB>(a: A, b: B) -> (RA, RB)
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
