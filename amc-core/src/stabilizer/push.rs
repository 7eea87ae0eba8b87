//! The stream: each pushed frame is tracked into the ring, and each output
//! the lookahead lets out is rendered (beside the next frame's tracking when
//! pipelined).

use super::buffered::Buffered;
use super::telemetry::Telemetry;
use super::tracking::Tracked;
use super::Stabilizer;
use crate::error::AmcError;
use crate::image::{Frame, FrameRef, PixelFormat};
use crate::render::{AutoDeghost, Deghost};
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
        // rendered now, beside the tracking of this frame and its copy into
        // the ring's next buffer (the ring still holds every frame the render
        // needs: this one is added after).
        let pending = self.output_pending();
        let src = (self.width, self.height);
        let mut copy = self.copy_slot();
        let (tracked, rendered) = if pending {
            let (tracking, rendering) = (&mut self.tracking, &mut self.rendering);
            let (ring, params) = (&self.ring, &self.params);
            let (copy, meter) = (&mut copy, self.auto_deghost.as_mut());
            join(
                || {
                    copy.fill(&frame, meter);
                    tracking.track(&frame, t)
                },
                || Some(rendering.render_next(ring, params, src)),
            )
        } else {
            copy.fill(&frame, self.auto_deghost.as_mut());
            (self.tracking.track(&frame, t), None)
        };
        self.enqueue(copy, t, dt, tracked);
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
        let mut copy = self.copy_slot();
        let rendered = if self.output_pending() {
            let (rendering, ring, params) = (&mut self.rendering, &self.ring, &self.params);
            let src = (self.width, self.height);
            let (copy, meter) = (&mut copy, self.auto_deghost.as_mut());
            join(
                || copy.fill(&frame, meter),
                || Some(rendering.render_next(ring, params, src)),
            )
            .1
        } else {
            copy.fill(&frame, self.auto_deghost.as_mut());
            None
        };
        let tracked = Tracked {
            pose: given.pose,
            path: given.path,
            rendered: given.path,
            info: given.info,
        };
        self.enqueue(copy, t, dt, tracked);
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

    /// A buffer for the next frame's copy into the ring: one that left the
    /// ring, else a new one (one more than the ring holds, so that the copy
    /// can run before the ring's oldest frame leaves it).
    fn copy_slot(&mut self) -> FrameCopy {
        let (frame, rows) = self.spare.pop().unwrap_or_else(|| {
            (
                Frame::new(0, 0, PixelFormat::Rgb8),
                RollingProjector::default(),
            )
        });
        FrameCopy {
            frame,
            rows,
            index: self.received,
            deghost: None,
        }
    }

    /// Filters the view with a tracked frame (copied into `copy`) and adds it
    /// to the ring.
    fn enqueue(&mut self, copy: FrameCopy, t: f64, dt: f64, tracked: Tracked) {
        let FrameCopy {
            frame: buf,
            mut rows,
            deghost,
            ..
        } = copy;
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
        rows.set(&rendered_path, self.height);
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

/// A pushed frame on its way into the ring: its copy, and what `deghost=auto`
/// measured of it (both done beside the render of the previous output).
struct FrameCopy {
    frame: Frame,
    rows: RollingProjector,
    index: u64,
    deghost: Option<Deghost>,
}

impl FrameCopy {
    /// Copies `frame` (with the tail padding of the vectorized samplers'
    /// dword loads) and lets `deghost=auto`'s noise meter observe it.
    fn fill(&mut self, frame: &FrameRef<'_>, meter: Option<&mut AutoDeghost>) {
        self.frame.copy_from(frame);
        self.frame
            .data
            .extend_from_slice(&[0; crate::render::kernels::FRAME_PADDING]);
        self.deghost = meter.and_then(|a| a.observe(self.index, frame));
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
