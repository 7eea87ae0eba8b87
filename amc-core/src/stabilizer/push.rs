//! The stream: each pushed frame is tracked into the ring, and each output
//! the lookahead lets out is rendered (beside the next frame's tracking when
//! pipelined).

use super::buffered::Buffered;
use super::telemetry::Telemetry;
use super::tracking::Tracked;
use super::Stabilizer;
use crate::error::AmcError;
use crate::image::{Frame, FrameRef};
use crate::shutter::RollingProjector;

impl Stabilizer {
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
        let deghost = self
            .auto_deghost
            .as_mut()
            .and_then(|a| a.observe(self.received, &frame));
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
