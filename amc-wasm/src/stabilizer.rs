//! The streaming stabilizer of one clip (`new Stabilizer`).

use crate::args::{self, nv12_to_i420, InputFormat};
use crate::js::{err, to_js, with_lens};
use amc_core::metrics::{FrameMetrics, MetricsAccumulator};
use amc_core::{FrameRef, GivenPose, Telemetry};
use std::collections::VecDeque;
use wasm_bindgen::prelude::*;

/// Most outputs reported and not measured that a stabilizer remembers the
/// telemetry of ([`Stabilizer::measure_output_of`] measures the oldest).
const MAX_UNMEASURED: usize = 64;

fn metrics_json(m: &FrameMetrics) -> serde_json::Value {
    serde_json::json!({
        "rms_normal_flow": m.rms_normal_flow,
        "rms_change": m.rms_change,
        "sharpness": m.sharpness,
    })
}

fn norm_dps(v: [f64; 3]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt().to_degrees()
}

/// A streaming stabilizer for one clip of `width x height` frames (RGBA, I420 or NV12).
#[wasm_bindgen]
pub struct Stabilizer {
    inner: amc_core::Stabilizer,
    width: usize,
    height: usize,
    format: InputFormat,
    /// Frame buffer JS may decode into directly ([`Stabilizer::input_buffer`]).
    input: Vec<u8>,
    /// The NV12 input de-interleaved to I420 (unused for the other formats).
    planar: Vec<u8>,
    metrics: Option<Metrics>,
    /// The frames' poses still to push, from a gyro pass
    /// ([`Stabilizer::set_poses`]); `None`: frames are tracked.
    poses: Option<VecDeque<GivenPose>>,
}

/// Per-frame image metrics of the input and the output (for the page's plot).
struct Metrics {
    output: MetricsAccumulator,
    input: MetricsAccumulator,
    full: Vec<u8>,
    /// Telemetry of the outputs reported and not yet measured, oldest first
    /// (angular speeds for the clip summary); at most [`MAX_UNMEASURED`].
    unmeasured: VecDeque<Telemetry>,
}

#[wasm_bindgen]
impl Stabilizer {
    /// `new Stabilizer(width, height, paramsJson, lens, format?)`: `paramsJson`
    /// is a JSON `StabilizerParams` (unknown fields are errors; `"{}"` gives the
    /// paper's settings); `lens` is a horizontal field of view in degrees or
    /// the text of a lens file; `format` is the pixel layout of the frames
    /// pushed, named as WebCodecs' `VideoPixelFormat`:
    ///
    /// - `"RGBA"` (the default, also for `undefined`/`null`): `width * height * 4`
    ///   bytes; the output is RGBA.
    /// - `"I420"`: planar 4:2:0 (`VideoFrame.copyTo` of an I420 frame with
    ///   packed planes): the Y plane (`width * height` bytes), then U and V
    ///   (`ceil(width/2) * ceil(height/2)` bytes each); the output is I420 of
    ///   the output size, black borders Y 16, U = V 128.
    /// - `"NV12"`: the Y plane, then the interleaved UV plane (as hardware
    ///   decoders give it; same length as I420), de-interleaved in the module;
    ///   the output is I420.
    ///
    /// Any other value is an error naming the allowed ones.
    #[wasm_bindgen(constructor)]
    pub fn new(
        width: f64,
        height: f64,
        params_json: &str,
        lens: JsValue,
        format: Option<String>,
    ) -> Result<Stabilizer, JsError> {
        let args::Opened {
            stabilizer: inner,
            width,
            height,
            format,
        } = with_lens(&lens, |l| {
            args::check(width, height, params_json, l, format.as_deref())
        })
        .and_then(args::Checked::open)
        .map_err(err)?;
        Ok(Stabilizer {
            inner,
            width,
            height,
            format,
            input: Vec::new(),
            planar: Vec::new(),
            metrics: None,
            poses: None,
        })
    }

    /// Gives every frame of the clip its pose, in order (the `poses` of a
    /// [`GyroPass`](crate::GyroPass)'s `fuse()`, a JSON array): frames pushed
    /// after it are not tracked but rendered with their pose, the gyro fused
    /// with the picture. Call before the first frame. Errors: JSON that is
    /// no array of poses; later, a frame beyond the last pose.
    #[wasm_bindgen(js_name = setPoses)]
    pub fn set_poses(&mut self, poses_json: &str) -> Result<(), JsError> {
        let poses: VecDeque<GivenPose> = serde_json::from_str(poses_json)
            .map_err(|e| JsError::new(&format!("poses: not a gyro pass's poses ({e})")))?;
        self.poses = Some(poses);
        Ok(())
    }

    /// The pixel layout of the input frames: `"RGBA"`, `"I420"` or `"NV12"`.
    #[wasm_bindgen(getter)]
    pub fn format(&self) -> String {
        self.format.name().to_string()
    }

    /// The pixel layout of [`Stabilizer::output`]: `"RGBA"` for RGBA input,
    /// `"I420"` for I420 and NV12 input (a `VideoFrame` format).
    #[wasm_bindgen(getter, js_name = outputFormat)]
    pub fn output_format(&self) -> String {
        match self.format {
            InputFormat::Rgba => "RGBA",
            InputFormat::I420 | InputFormat::Nv12 => "I420",
        }
        .to_string()
    }

    /// Bytes of one input frame in this stabilizer's format.
    #[wasm_bindgen(getter, js_name = inputLength)]
    pub fn input_length(&self) -> usize {
        self.format.buffer_len(self.width, self.height)
    }

    /// The effective parameters, as a JSON string (defaults filled in).
    #[wasm_bindgen(js_name = paramsJson)]
    pub fn params_json(&self) -> String {
        serde_json::to_string(self.inner.params()).unwrap_or_default()
    }

    /// Horizontal field of view of the output camera, degrees.
    #[wasm_bindgen(getter, js_name = outputHfovDeg)]
    pub fn output_hfov_deg(&self) -> f64 {
        self.inner.output_camera().hfov_deg()
    }

    #[wasm_bindgen(getter)]
    pub fn width(&self) -> usize {
        self.width
    }

    #[wasm_bindgen(getter)]
    pub fn height(&self) -> usize {
        self.height
    }

    #[wasm_bindgen(getter, js_name = outputWidth)]
    pub fn output_width(&self) -> usize {
        self.inner.output_size().0
    }

    #[wasm_bindgen(getter, js_name = outputHeight)]
    pub fn output_height(&self) -> usize {
        self.inner.output_size().1
    }

    /// Rendering on (the default) or off. Off, frames are still tracked,
    /// smoothed and framed (telemetry, [`Stabilizer::max_zoom_need`]) but no
    /// pixels are produced: the first pass of `zoom: "static"`.
    #[wasm_bindgen(js_name = setRendering)]
    pub fn set_rendering(&mut self, on: bool) {
        self.inner.set_rendering(on);
    }

    /// Renders only outputs `j` with `j % count == index`; the others are
    /// tracked, filtered and framed but not drawn (their telemetry has
    /// `valid_fraction` 0, and [`Stabilizer::output`] still holds the last
    /// drawn one). `count` workers, each with a stabilizer fed every frame and
    /// a share `index` of `0..count`, draw every output once between them,
    /// byte for byte as one would: the page's way to more than one core.
    /// Errors: `count` 0 or above 16, `index >= count`, `count > 1` in
    /// saccade mode.
    #[wasm_bindgen(js_name = setRenderShare)]
    pub fn set_render_share(&mut self, count: u32, index: u32) -> Result<(), JsError> {
        self.inner.set_render_share(count, index).map_err(err)
    }

    /// The highest zoom any output needed so far to show no border (at least
    /// 1): after a first pass without rendering, the zoom to pass to
    /// [`Stabilizer::set_static_zoom`].
    #[wasm_bindgen(js_name = maxZoomNeed)]
    pub fn max_zoom_need(&self) -> f64 {
        self.inner.max_zoom_need()
    }

    /// `zoom: "static"`: holds this zoom (clamped to the crop budget) for the
    /// whole clip; call before the first frame. Without it a static stabilizer
    /// that renders refuses frames.
    #[wasm_bindgen(js_name = setStaticZoom)]
    pub fn set_static_zoom(&mut self, zoom: f64) {
        self.inner.set_static_zoom(zoom);
    }

    /// Turns per-frame image metrics on (fresh accumulators) or off; off by
    /// default. Measuring is separate from stabilizing ([`Stabilizer::measure_input`],
    /// [`Stabilizer::measure_output`]) so callers can time and skip it.
    #[wasm_bindgen(js_name = setMetrics)]
    pub fn set_metrics(&mut self, on: bool) {
        self.metrics = on.then(|| Metrics {
            output: MetricsAccumulator::new(),
            input: MetricsAccumulator::new(),
            full: vec![1; self.width * self.height],
            unmeasured: VecDeque::new(),
        });
    }

    /// Image metrics (`rms_normal_flow`, `rms_change` against the previous
    /// measured input, `sharpness`) of the frame in [`Stabilizer::input_buffer`].
    #[wasm_bindgen(js_name = measureInput)]
    pub fn measure_input(&mut self) -> Result<JsValue, JsError> {
        let m = self
            .metrics
            .as_mut()
            .ok_or_else(|| JsError::new("metrics are off: call setMetrics(true) first"))?;
        if self.input.len() != self.format.buffer_len(self.width, self.height) {
            return Err(JsError::new(
                "no input frame: fill inputBuffer() before measureInput()",
            ));
        }
        let data = if self.format == InputFormat::Nv12 {
            nv12_to_i420(self.width, self.height, &self.input, &mut self.planar);
            &self.planar
        } else {
            &self.input
        };
        let frame =
            FrameRef::new(self.width, self.height, self.format.core(), data).map_err(err)?;
        let fm = m.input.push(&frame, &m.full, 1.0, None);
        to_js(&metrics_json(&fm))
    }

    /// Image metrics of the latest output frame (black borders excluded),
    /// against the previous measured output.
    #[wasm_bindgen(js_name = measureOutput)]
    pub fn measure_output(&mut self) -> Result<JsValue, JsError> {
        let m = self
            .metrics
            .as_mut()
            .ok_or_else(|| JsError::new("metrics are off: call setMetrics(true) first"))?;
        // The newest output is the one in the output buffer; older unmeasured
        // ones are gone from it.
        let tel = m
            .unmeasured
            .pop_back()
            .ok_or_else(|| JsError::new("no new output frame to measure"))?;
        m.unmeasured.clear();
        let fm = m.output.push(
            &self.inner.output(),
            self.inner.output_coverage(),
            tel.valid_fraction,
            Some(&tel),
        );
        to_js(&metrics_json(&fm))
    }

    /// Image metrics of the oldest output reported and not yet measured, from
    /// a copy of its pixels and coverage (as [`Stabilizer::output`] and
    /// [`Stabilizer::coverage`] gave them, here or in another worker's
    /// stabilizer drawing its share, [`Stabilizer::set_render_share`]) and the
    /// `valid_fraction` of the telemetry of the stabilizer that drew it: the
    /// outputs measured in order while they are drawn elsewhere or later.
    #[wasm_bindgen(js_name = measureOutputOf)]
    pub fn measure_output_of(
        &mut self,
        pixels: &[u8],
        coverage: &[u8],
        valid_fraction: f64,
    ) -> Result<JsValue, JsError> {
        let (ow, oh) = self.inner.output_size();
        let format = self.format.core();
        let m = self
            .metrics
            .as_mut()
            .ok_or_else(|| JsError::new("metrics are off: call setMetrics(true) first"))?;
        if coverage.len() != ow * oh {
            return Err(JsError::new(&format!(
                "coverage: {} bytes, expected {} (outputWidth * outputHeight)",
                coverage.len(),
                ow * oh
            )));
        }
        let frame = FrameRef::new(ow, oh, format, pixels).map_err(err)?;
        let tel = m
            .unmeasured
            .pop_front()
            .ok_or_else(|| JsError::new("no output frame left to measure"))?;
        let fm = m.output.push(&frame, coverage, valid_fraction, Some(&tel));
        to_js(&metrics_json(&fm))
    }

    /// A view into WASM memory of one input frame (`inputLength` bytes: RGBA
    /// `width * height * 4`, I420 and NV12 `width * height + 2 *
    /// ceil(width/2) * ceil(height/2)`) to decode the next frame into (e.g.
    /// `VideoFrame.copyTo`), then call [`Stabilizer::push_input`]: no copy through JS.
    #[wasm_bindgen(js_name = inputBuffer)]
    pub fn input_buffer(&mut self) -> js_sys::Uint8Array {
        self.input
            .resize(self.format.buffer_len(self.width, self.height), 0);
        // SAFETY: the view aliases `self.input`, which is not touched until the
        // next call into the module; callers are told views die at that point.
        unsafe { js_sys::Uint8Array::view(&self.input) }
    }

    /// Pushes the frame in [`Stabilizer::input_buffer`] at `t` seconds.
    /// Returns the telemetry of the output frame that became ready, or
    /// `undefined` while the lookahead fills.
    #[wasm_bindgen(js_name = pushInput)]
    pub fn push_input(&mut self, t: f64) -> Result<JsValue, JsError> {
        let input = std::mem::take(&mut self.input);
        let r = self.push(&input, t);
        self.input = input;
        r
    }

    /// Pushes a frame in this stabilizer's format (`inputLength` bytes,
    /// copied into WASM memory) at `t` seconds (strictly increasing). Returns
    /// the telemetry of the output frame that became ready, or `undefined`.
    pub fn push(&mut self, data: &[u8], t: f64) -> Result<JsValue, JsError> {
        let given = match self.poses.as_mut() {
            Some(poses) => Some(poses.pop_front().ok_or_else(|| {
                JsError::new("more frames than the gyro pass gave poses for (setPoses)")
            })?),
            None => None,
        };
        let mut planar = std::mem::take(&mut self.planar);
        let pushed = args::push_frame(
            &mut self.inner,
            self.format,
            self.width,
            self.height,
            data,
            t,
            given,
            &mut planar,
        )
        .map_err(err);
        self.planar = planar;
        match pushed? {
            Some(tel) => self.report(&tel),
            None => Ok(JsValue::UNDEFINED),
        }
    }

    /// After the last frame: the next output still held back by the lookahead
    /// (read it with [`Stabilizer::output`]), or `undefined` when all are out.
    pub fn finish(&mut self) -> Result<JsValue, JsError> {
        match self.inner.finish() {
            Some(tel) => self.report(&tel),
            None => Ok(JsValue::UNDEFINED),
        }
    }

    /// The latest stabilized frame: a view into WASM memory, empty before the
    /// first output. RGBA (`outputWidth * outputHeight * 4` bytes) for RGBA
    /// input; I420 (`outputWidth * outputHeight + 2 * ceil(outputWidth/2) *
    /// ceil(outputHeight/2)` bytes, planes packed) for I420 and NV12 input.
    pub fn output(&self) -> js_sys::Uint8Array {
        // SAFETY: aliases the core's output buffer, unchanged until the next call.
        unsafe { js_sys::Uint8Array::view(self.inner.output().data) }
    }

    /// Per-pixel count of frames averaged into the latest output (0: black
    /// border); for I420 output, per luma pixel.
    pub fn coverage(&self) -> js_sys::Uint8Array {
        // SAFETY: as for `output`.
        unsafe { js_sys::Uint8Array::view(self.inner.output_coverage()) }
    }

    /// Clip metrics so far (`null` unless metrics are on).
    pub fn summary(&self) -> Result<JsValue, JsError> {
        match &self.metrics {
            None => Ok(JsValue::NULL),
            Some(m) => {
                let v = serde_json::json!({
                    "output": m.output.summary(),
                    "input": m.input.summary(),
                });
                to_js(&v)
            }
        }
    }

    /// Telemetry object of an output: the core's [`Telemetry`] plus angular
    /// speeds in deg/s.
    fn report(&mut self, tel: &Telemetry) -> Result<JsValue, JsError> {
        let mut v = serde_json::to_value(tel).map_err(err)?;
        v["speed_est_dps"] = norm_dps(tel.rate_est).into();
        v["speed_view_dps"] = norm_dps(tel.rate_view).into();
        if let Some(m) = &mut self.metrics {
            if m.unmeasured.len() == MAX_UNMEASURED {
                m.unmeasured.pop_front();
            }
            m.unmeasured.push_back(tel.clone());
        }
        to_js(&v)
    }
}
