//! # amc-wasm
//!
//! Thin wasm-bindgen bindings over [`amc_core`] for the web page: a
//! [`Stabilizer`] built from the shared [`StabilizerParams`](amc_core::StabilizerParams) (JSON, the same
//! definition the CLI and the REST API use), fed frames with their timestamps,
//! returning the stabilized frame as a view into WASM memory and its telemetry
//! as a plain object.
//!
//! Frames are RGBA (the default), or planar 4:2:0 as WebCodecs decoders give
//! them: `"I420"` (Y, U, V planes) or `"NV12"` (Y plane, then interleaved UV,
//! de-interleaved here). Planar frames are rendered plane by plane with no
//! colour conversion and come out as I420 (see [`Stabilizer::new`]).
//!
//! Every bad input (sizes, buffer lengths, timestamps, parameters, lens files)
//! becomes a JavaScript `Error` whose message names the value and the allowed
//! range; nothing here panics on user input.
//!
//! Views returned by [`Stabilizer::input_buffer`], [`Stabilizer::output`] and
//! [`Stabilizer::coverage`] alias WASM memory: they are valid until the next
//! call into the module (memory growth detaches them); copy what you keep.

use amc_core::camera::CameraModel;
use amc_core::metrics::{FrameMetrics, MetricsAccumulator};
use amc_core::{FrameRef, PixelFormat, Telemetry};
use args::{nv12_to_i420, InputFormat, LensArg};
use std::collections::VecDeque;
use wasm_bindgen::prelude::*;

/// Most outputs reported and not measured that a stabilizer remembers the
/// telemetry of ([`Stabilizer::measure_output_of`] measures the oldest).
const MAX_UNMEASURED: usize = 64;

pub mod args;

fn err(e: impl std::fmt::Display) -> JsError {
    JsError::new(&e.to_string())
}

fn to_js(v: &serde_json::Value) -> Result<JsValue, JsError> {
    js_sys::JSON::parse(&v.to_string()).map_err(|_| JsError::new("internal: telemetry is not JSON"))
}

fn metrics_json(m: &FrameMetrics) -> serde_json::Value {
    serde_json::json!({
        "rms_normal_flow": m.rms_normal_flow,
        "rms_change": m.rms_change,
        "sharpness": m.sharpness,
    })
}

/// Calls `f` with the lens argument `lens`: a number is a field of view, a
/// string the text of a lens file.
fn with_lens<T>(lens: &JsValue, f: impl FnOnce(LensArg<'_>) -> T) -> T {
    let text = lens.as_string();
    f(match (lens.as_f64(), text.as_deref()) {
        (Some(deg), _) => LensArg::Fov(deg),
        (None, Some(text)) => LensArg::Text(text),
        (None, None) => LensArg::Other,
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
        })
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
        let mut planar = std::mem::take(&mut self.planar);
        let pushed = args::push_frame(
            &mut self.inner,
            self.format,
            self.width,
            self.height,
            data,
            t,
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

/// The first passes of a clip before it is stabilized, as the core plans
/// them ([`amc_core::plan`]): `readout: "auto"`'s pass over the clip's first
/// frames, then `zoom: "static"`'s over all of them (stabilize and lock
/// modes), each reading the clip from its start. The page reads the pass
/// [`PassPlan::pass`] names, pushing frames until [`PassPlan::is_full`] or
/// the clip ends, then [`PassPlan::finish_pass`]; once no pass is left, the
/// main [`Stabilizer`] is made with [`PassPlan::params_json`] and given
/// [`PassPlan::static_zoom`].
#[wasm_bindgen]
pub struct PassPlan {
    inner: amc_core::plan::PassPlan,
    width: usize,
    height: usize,
    format: InputFormat,
    input: Vec<u8>,
    planar: Vec<u8>,
}

#[wasm_bindgen]
impl PassPlan {
    /// `new PassPlan(width, height, paramsJson, lens, format?, readout?)`:
    /// the first four as `new Stabilizer`'s (and checked the same way);
    /// `readout` is `"auto"` (estimate it: a pass), milliseconds, or
    /// `undefined`/`null` (the parameters' shutter, else the lens file's
    /// readout, else 0).
    #[wasm_bindgen(constructor)]
    pub fn new(
        width: f64,
        height: f64,
        params_json: &str,
        lens: JsValue,
        format: Option<String>,
        readout: JsValue,
    ) -> Result<PassPlan, JsError> {
        let c = with_lens(&lens, |l| {
            args::check(width, height, params_json, l, format.as_deref())
        })
        .map_err(err)?;
        let (width, height, format) = (c.width, c.height, c.format);
        let text = readout.as_string();
        let arg = match (readout.as_f64(), text.as_deref()) {
            (Some(ms), _) => args::ReadoutArg::Ms(ms),
            (None, Some(text)) => args::ReadoutArg::Text(text),
            (None, None) if readout.is_null() || readout.is_undefined() => args::ReadoutArg::Unset,
            (None, None) => {
                return Err(JsError::new(
                    "invalid readout: expected \"auto\", milliseconds, or undefined",
                ))
            }
        };
        let inner = c.plan(arg).map_err(err)?;
        Ok(PassPlan {
            inner,
            width,
            height,
            format,
            input: Vec::new(),
            planar: Vec::new(),
        })
    }

    /// Every pass planned, in order: `"readout"`, `"static_zoom"`.
    #[wasm_bindgen(getter)]
    pub fn passes(&self) -> Vec<String> {
        self.inner
            .passes()
            .iter()
            .map(|p| p.name().to_string())
            .collect()
    }

    /// The pass to read now (`"readout"` or `"static_zoom"`), `undefined`
    /// once all are made.
    #[wasm_bindgen(getter)]
    pub fn pass(&self) -> Option<String> {
        self.inner.pass().map(|p| p.name().to_string())
    }

    /// The most frames the pass to read takes from the clip's start
    /// (`undefined`: all of them, or no pass left).
    #[wasm_bindgen(getter, js_name = frameBudget)]
    pub fn frame_budget(&self) -> Option<usize> {
        self.inner.pass().and_then(|p| p.frame_budget())
    }

    /// Whether the pass has the frames it wants: stop decoding.
    #[wasm_bindgen(getter, js_name = isFull)]
    pub fn is_full(&self) -> bool {
        self.inner.is_full()
    }

    /// Frames the pass has taken so far.
    #[wasm_bindgen(getter)]
    pub fn frames(&self) -> usize {
        self.inner.frames()
    }

    /// A view into WASM memory to decode the next frame into, as
    /// [`Stabilizer::input_buffer`]; then call [`PassPlan::push_input`].
    #[wasm_bindgen(js_name = inputBuffer)]
    pub fn input_buffer(&mut self) -> js_sys::Uint8Array {
        let len = self.format.buffer_len(self.width, self.height);
        self.input.resize(len, 0);
        // SAFETY: as for `Stabilizer::input_buffer`.
        unsafe { js_sys::Uint8Array::view(&self.input) }
    }

    /// Gives the pass the frame in [`PassPlan::input_buffer`], `t` seconds in.
    #[wasm_bindgen(js_name = pushInput)]
    pub fn push_input(&mut self, t: f64) -> Result<(), JsError> {
        let input = std::mem::take(&mut self.input);
        let r = self.push(&input, t);
        self.input = input;
        r
    }

    /// Gives the pass a frame in this plan's format, `t` seconds in.
    pub fn push(&mut self, data: &[u8], t: f64) -> Result<(), JsError> {
        let Self {
            inner,
            width,
            height,
            format,
            planar,
            ..
        } = self;
        args::with_frame(*format, *width, *height, data, planar, |frame| {
            Ok(inner.push(frame, t)?)
        })
        .map_err(err)
    }

    /// Resolves the pass from its frames and moves on. Returns what it
    /// found: `{pass: "readout", readout_ms, note, estimate}` (`note`
    /// `"estimated"`, or `"fell_back"` with `readout_ms` 0 when the estimate
    /// is not reliable or the clip too short to fit; `estimate` is
    /// `{readout_ms, confident, explained, motion_deg, frames}`), or
    /// `{pass: "static_zoom", zoom}`.
    #[wasm_bindgen(js_name = finishPass)]
    pub fn finish_pass(&mut self) -> Result<JsValue, JsError> {
        use amc_core::plan::{LensNote, Pass, ReadoutNote};
        let frames = self.inner.frames();
        let v = match self.inner.finish_pass().map_err(err)? {
            Pass::Readout => {
                let r = self
                    .inner
                    .readout()
                    .ok_or_else(|| JsError::new("internal: no readout after its pass"))?;
                let (note, e) = match &r.note {
                    ReadoutNote::Estimated(e) => ("estimated", Some(e)),
                    ReadoutNote::FellBack { estimate } => ("fell_back", estimate.as_ref()),
                    ReadoutNote::Given | ReadoutNote::FromLens => ("given", None),
                };
                let estimate = match e {
                    Some(e) => serde_json::json!({
                        "readout_ms": e.readout_ms,
                        "confident": e.confident,
                        "explained": e.explained,
                        "motion_deg": e.motion_deg,
                        "frames": e.frames,
                    }),
                    // Too few frames to fit.
                    None => serde_json::json!({
                        "readout_ms": 0.0,
                        "confident": false,
                        "explained": 0.0,
                        "motion_deg": 0.0,
                        "frames": frames,
                    }),
                };
                serde_json::json!({
                    "pass": "readout",
                    "readout_ms": r.readout_ms,
                    "note": note,
                    "estimate": estimate,
                })
            }
            Pass::StaticZoom => serde_json::json!({
                "pass": "static_zoom",
                "zoom": self.inner.static_zoom(),
            }),
            Pass::Lens => {
                let l = self
                    .inner
                    .lens()
                    .ok_or_else(|| JsError::new("internal: no lens after its pass"))?;
                let note = match l.note {
                    LensNote::FellBack => "fell_back",
                    _ => "estimated",
                };
                serde_json::json!({
                    "pass": "lens",
                    "hfov_deg": l.camera.hfov_deg(),
                    "note": note,
                })
            }
        };
        to_js(&v)
    }

    /// The parameters the main [`Stabilizer`] runs with (the readout set),
    /// as JSON, once the readout is known (after its pass, if any).
    #[wasm_bindgen(js_name = paramsJson)]
    pub fn params_json(&self) -> Result<String, JsError> {
        if self.inner.readout().is_none() {
            return Err(JsError::new(
                "the readout is not known yet: finish the readout pass first",
            ));
        }
        serde_json::to_string(self.inner.params()).map_err(err)
    }

    /// The zoom `zoom: "static"`'s pass found, for
    /// [`Stabilizer::set_static_zoom`] (`undefined` before it or without it).
    #[wasm_bindgen(getter, js_name = staticZoom)]
    pub fn static_zoom(&self) -> Option<f64> {
        self.inner.static_zoom()
    }
}

/// `readout_ms: "auto"`: estimates the rolling-shutter readout time from a
/// clip's first frames ([`amc_core::readout::ReadoutEstimator`]), the first
/// pass before the [`Stabilizer`] is made with the estimate. Same arguments
/// as `new Stabilizer`; push frames until [`ReadoutEstimator::is_full`] or the
/// clip ends, then [`ReadoutEstimator::finish`]. The page makes this pass
/// through [`PassPlan`], which also decides the fallback to 0.
#[wasm_bindgen]
pub struct ReadoutEstimator {
    inner: Option<amc_core::readout::ReadoutEstimator>,
    width: usize,
    height: usize,
    format: InputFormat,
    input: Vec<u8>,
    planar: Vec<u8>,
}

#[wasm_bindgen]
impl ReadoutEstimator {
    /// `new ReadoutEstimator(width, height, paramsJson, lens, format?)`, as
    /// `new Stabilizer` (the parameters' tracker settings are used).
    #[wasm_bindgen(constructor)]
    pub fn new(
        width: f64,
        height: f64,
        params_json: &str,
        lens: JsValue,
        format: Option<String>,
    ) -> Result<ReadoutEstimator, JsError> {
        let c = with_lens(&lens, |l| {
            args::check(width, height, params_json, l, format.as_deref())
        })
        .map_err(err)?;
        let inner =
            amc_core::readout::ReadoutEstimator::new(&c.camera, c.width, c.height, &c.params)
                .map_err(err)?;
        Ok(ReadoutEstimator {
            inner: Some(inner),
            width: c.width,
            height: c.height,
            format: c.format,
            input: Vec::new(),
            planar: Vec::new(),
        })
    }

    /// Whether it has the frames it wants (`READOUT_FRAMES`, 180).
    #[wasm_bindgen(getter, js_name = isFull)]
    pub fn is_full(&self) -> bool {
        self.inner.as_ref().map_or(true, |e| e.is_full())
    }

    /// Frames pushed so far.
    #[wasm_bindgen(getter)]
    pub fn frames(&self) -> usize {
        self.inner.as_ref().map_or(0, |e| e.frames())
    }

    /// A view into WASM memory to decode the next frame into, as
    /// [`Stabilizer::input_buffer`]; then call [`ReadoutEstimator::push_input`].
    #[wasm_bindgen(js_name = inputBuffer)]
    pub fn input_buffer(&mut self) -> js_sys::Uint8Array {
        let len = self.format.buffer_len(self.width, self.height);
        self.input.resize(len, 0);
        // SAFETY: as for `Stabilizer::input_buffer`.
        unsafe { js_sys::Uint8Array::view(&self.input) }
    }

    /// Tracks the frame in [`ReadoutEstimator::input_buffer`] at `t` seconds.
    #[wasm_bindgen(js_name = pushInput)]
    pub fn push_input(&mut self, t: f64) -> Result<(), JsError> {
        let Self {
            inner,
            width,
            height,
            format,
            input,
            planar,
        } = self;
        track(inner, (*format, *width, *height), input, planar, t)
    }

    /// Tracks a frame in this estimator's format at `t` seconds.
    pub fn push(&mut self, data: &[u8], t: f64) -> Result<(), JsError> {
        let size = (self.format, self.width, self.height);
        track(&mut self.inner, size, data, &mut self.planar, t)
    }

    /// The estimate: `{readout_ms, confident, explained, motion_deg, frames}`.
    /// Use `readout_ms` only when `confident` (else a global shutter, 0); a
    /// clip too short to fit is not confident. Call once.
    pub fn finish(&mut self) -> Result<JsValue, JsError> {
        let est = self
            .inner
            .take()
            .ok_or_else(|| JsError::new("the estimate is finished: make a new ReadoutEstimator"))?;
        let frames = est.frames();
        let v = match est.finish() {
            Ok(e) => serde_json::json!({
                "readout_ms": e.readout_ms,
                "confident": e.confident,
                "explained": e.explained,
                "motion_deg": e.motion_deg,
                "frames": e.frames,
            }),
            Err(amc_core::AmcError::TooFewFrames { .. }) => serde_json::json!({
                "readout_ms": 0.0,
                "confident": false,
                "explained": 0.0,
                "motion_deg": 0.0,
                "frames": frames,
            }),
            Err(e) => return Err(err(e)),
        };
        to_js(&v)
    }
}

/// Tracks the frame `data` (`format`, `width x height`; NV12 de-interleaved
/// into `planar`) at `t` seconds with `est`, unless it is finished.
fn track(
    est: &mut Option<amc_core::readout::ReadoutEstimator>,
    (format, width, height): (InputFormat, usize, usize),
    data: &[u8],
    planar: &mut Vec<u8>,
    t: f64,
) -> Result<(), JsError> {
    let est = est
        .as_mut()
        .ok_or_else(|| JsError::new("the estimate is finished: make a new ReadoutEstimator"))?;
    args::with_frame(format, width, height, data, planar, |frame| {
        Ok(est.push(frame, t)?)
    })
    .map_err(err)
}

/// Renders random frames through random rotations with the vectorized kernel
/// (wasm `simd128` when the module was built with it) and with the scalar
/// reference, and returns whether the images, coverage and valid share are
/// identical, for RGBA and RGB frames and for one plane of a planar (I420)
/// frame, averaged plainly and without ghosts. `fisheye` exercises the
/// coordinate-table path.
#[wasm_bindgen(js_name = simdMatchesScalar)]
pub fn simd_matches_scalar(
    width: f64,
    height: f64,
    seed: u32,
    fisheye: bool,
) -> Result<bool, JsError> {
    use amc_core::render::{Deghost, RenderParams, Warper};
    use amc_core::so3::{self, Tangent};
    let (w, h) = (
        args::dimension("width", width).map_err(err)?,
        args::dimension("height", height).map_err(err)?,
    );
    if w < 16 || h < 16 {
        return Err(JsError::new(&format!(
            "invalid size: {w}x{h} (allowed: at least 16x16)"
        )));
    }
    let mut cam = CameraModel::pinhole_hfov(w, h, 80.0).map_err(err)?;
    if fisheye {
        cam.distortion = amc_core::camera::Distortion::Fisheye {
            k1: 0.05,
            k2: -0.01,
            k3: 0.0,
            k4: 0.0,
        };
    }
    let out = RenderParams::default().output_camera(&cam).map_err(err)?;
    let rots: Vec<_> = (0..4)
        .map(|i| {
            *so3::exp(&Tangent::new(
                0.06 * i as f64,
                -0.1 + 0.01 * (seed % 7) as f64,
                0.05 * i as f64,
            ))
            .matrix()
        })
        .collect();
    // The plain average and the ghost-free one (random frames differ by up
    // to 255 levels: a 60-level threshold gives every weight from 0 to 16).
    let deghosts = [None, Deghost::new(60.0)];
    // Both pixel formats (the kernel has an RGBA and an RGB path).
    for format in [PixelFormat::Rgba8, PixelFormat::Rgb8] {
        let c = format.channels();
        let mut s = seed as u64 + 1;
        let frames: Vec<Vec<u8>> = (0..4)
            .map(|_| {
                let mut f = vec![0u8; w * h * c + amc_core::render::kernels::FRAME_PADDING];
                for b in f.iter_mut().take(w * h * c) {
                    s = s
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    *b = (s >> 56) as u8;
                }
                f
            })
            .collect();
        let render = |vectorized: bool, deghost: Option<Deghost>| {
            let mut warper = Warper::new(&cam, &out);
            warper.set_vectorized(vectorized);
            warper.set_deghost(deghost);
            let mut img = vec![0u8; out.width * out.height * c];
            let mut cov = Vec::new();
            let vf = warper.average_into(
                |i| FrameRef {
                    width: w,
                    height: h,
                    format,
                    data: &frames[i],
                },
                &rots,
                &mut img,
                c,
                &mut cov,
            );
            (img, cov, vf)
        };
        for deghost in deghosts {
            if render(false, deghost) != render(true, deghost) {
                return Ok(false);
            }
        }
    }
    // One plane of a planar frame (the single-channel kernel of I420 input).
    let mut s = seed as u64 + 7;
    let planes: Vec<Vec<u8>> = (0..4)
        .map(|_| {
            let mut f = vec![0u8; w * h + amc_core::render::kernels::FRAME_PADDING];
            for b in f.iter_mut().take(w * h) {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                *b = (s >> 56) as u8;
            }
            f
        })
        .collect();
    let render = |vectorized: bool, deghost: Option<Deghost>| {
        let mut warper = Warper::new(&cam, &out);
        warper.set_vectorized(vectorized);
        warper.set_deghost(deghost);
        let mut img = vec![0u8; out.width * out.height];
        let mut cov = Vec::new();
        let complete =
            warper.average_plane_into(|i| &planes[i][..], w, h, &rots, &mut img, &mut cov, 16);
        (img, cov, complete)
    };
    Ok(deghosts
        .into_iter()
        .all(|deghost| render(false, deghost) == render(true, deghost)))
}

/// Whether this module was built with the WebAssembly `simd128` kernel.
#[wasm_bindgen(js_name = simdEnabled)]
pub fn simd_enabled() -> bool {
    amc_core::render::kernels::vector_kernel_available()
}
