//! The rolling-shutter readout estimate as a pass of its own (`new ReadoutEstimator`).

use crate::args;
use crate::input::FrameInput;
use crate::js::{err, to_js, with_lens};
use wasm_bindgen::prelude::*;

/// `readout_ms: "auto"`: estimates the rolling-shutter readout time from a
/// clip's first frames ([`amc_core::readout::ReadoutEstimator`]), the first
/// pass before the [`Stabilizer`](crate::Stabilizer) is made with the estimate. Same arguments
/// as `new Stabilizer`; push frames until [`ReadoutEstimator::is_full`](crate::ReadoutEstimator::is_full) or the
/// clip ends, then [`ReadoutEstimator::finish`](crate::ReadoutEstimator::finish). The page makes this pass
/// through [`PassPlan`](crate::PassPlan), which also decides the fallback to 0.
#[wasm_bindgen]
pub struct ReadoutEstimator {
    inner: Option<amc_core::readout::ReadoutEstimator>,
    input: FrameInput,
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
            input: FrameInput::new(c.width, c.height, c.format),
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
    /// [`Stabilizer::input_buffer`](crate::Stabilizer::input_buffer); then call [`ReadoutEstimator::push_input`](crate::ReadoutEstimator::push_input).
    #[wasm_bindgen(js_name = inputBuffer)]
    pub fn input_buffer(&mut self) -> js_sys::Uint8Array {
        self.input.view()
    }

    /// Tracks the frame in [`ReadoutEstimator::input_buffer`](crate::ReadoutEstimator::input_buffer) at `t` seconds.
    #[wasm_bindgen(js_name = pushInput)]
    pub fn push_input(&mut self, t: f64) -> Result<(), JsError> {
        track(&mut self.inner, &mut self.input, None, t)
    }

    /// Tracks a frame in this estimator's format at `t` seconds.
    pub fn push(&mut self, data: &[u8], t: f64) -> Result<(), JsError> {
        track(&mut self.inner, &mut self.input, Some(data), t)
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

/// Tracks the frame `data` (`None`: the one in `input`'s buffer) at `t`
/// seconds with `est`, unless it is finished.
fn track(
    est: &mut Option<amc_core::readout::ReadoutEstimator>,
    input: &mut FrameInput,
    data: Option<&[u8]>,
    t: f64,
) -> Result<(), JsError> {
    let est = est
        .as_mut()
        .ok_or_else(|| JsError::new("the estimate is finished: make a new ReadoutEstimator"))?;
    input
        .with_frame(data, |frame| Ok(est.push(frame, t)?))
        .map_err(err)
}
