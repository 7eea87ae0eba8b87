//! A run's first passes (`new PassPlan`): the core's plan, driven by the page.

use crate::args;
use crate::input::FrameInput;
use crate::js::{err, to_js, with_lens};
use wasm_bindgen::prelude::*;

/// The first passes of a clip before it is stabilized, as the core plans
/// them ([`amc_core::plan`]): `lens: "auto"`'s pass over the clip's first
/// frames, then `readout: "auto"`'s pass over the clip's first
/// frames, then `zoom: "static"`'s over all of them (stabilize and lock
/// modes), each reading the clip from its start. The page reads the pass
/// [`PassPlan::pass`] names, pushing frames until [`PassPlan::is_full`] or
/// the clip ends, then [`PassPlan::finish_pass`]; once no pass is left, the
/// main [`Stabilizer`](crate::Stabilizer) is made with [`PassPlan::params_json`] and given
/// [`PassPlan::static_zoom`].
#[wasm_bindgen]
pub struct PassPlan {
    inner: amc_core::plan::PassPlan,
    input: FrameInput,
}

#[wasm_bindgen]
impl PassPlan {
    /// `new PassPlan(width, height, paramsJson, lens, format?, readout?)`:
    /// the first four as `new Stabilizer`'s (and checked the same way), but
    /// `lens` may also be `"auto"`: a first pass (`"lens"`) estimates the
    /// field of view from the clip's first frames (`fov=auto`; a pinhole of
    /// 70 degrees when the footage does not pin it down), and its
    /// [`PassPlan::finish_pass`] gives the degrees for the main stabilizer;
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
        let (inner, width, height, format) = with_lens(&lens, |l| {
            args::check_plan(width, height, params_json, l, format.as_deref(), arg)
        })
        .map_err(err)?;
        Ok(PassPlan {
            inner,
            input: FrameInput::new(width, height, format),
        })
    }

    /// Every pass planned, in order: `"lens"`, `"readout"`, `"static_zoom"`.
    #[wasm_bindgen(getter)]
    pub fn passes(&self) -> Vec<String> {
        self.inner
            .passes()
            .iter()
            .map(|p| p.name().to_string())
            .collect()
    }

    /// The pass to read now (`"lens"`, `"readout"` or `"static_zoom"`), `undefined`
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
    /// [`Stabilizer::input_buffer`](crate::Stabilizer::input_buffer); then call [`PassPlan::push_input`].
    #[wasm_bindgen(js_name = inputBuffer)]
    pub fn input_buffer(&mut self) -> js_sys::Uint8Array {
        self.input.view()
    }

    /// Gives the pass the frame in [`PassPlan::input_buffer`], `t` seconds in.
    #[wasm_bindgen(js_name = pushInput)]
    pub fn push_input(&mut self, t: f64) -> Result<(), JsError> {
        let inner = &mut self.inner;
        self.input
            .with_frame(None, |frame| Ok(inner.push(frame, t)?))
            .map_err(err)
    }

    /// Gives the pass a frame in this plan's format, `t` seconds in.
    pub fn push(&mut self, data: &[u8], t: f64) -> Result<(), JsError> {
        let inner = &mut self.inner;
        self.input
            .with_frame(Some(data), |frame| Ok(inner.push(frame, t)?))
            .map_err(err)
    }

    /// Resolves the pass from its frames and moves on. Returns what it
    /// found: `{pass: "readout", readout_ms, note, estimate}` (`note`
    /// `"estimated"`, or `"fell_back"` with `readout_ms` 0 when the estimate
    /// is not reliable or the clip too short to fit; `estimate` is
    /// `{readout_ms, confident, explained, motion_deg, frames}`),
    /// `{pass: "static_zoom", zoom}`, or `{pass: "lens", hfov_deg, note}`
    /// (`note` `"estimated"`, or `"fell_back"` with the 70 degrees assumed
    /// when the footage does not pin the focal length down).
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

    /// The parameters the main [`Stabilizer`](crate::Stabilizer) runs with (the readout set),
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
    /// [`Stabilizer::set_static_zoom`](crate::Stabilizer::set_static_zoom) (`undefined` before it or without it).
    #[wasm_bindgen(getter, js_name = staticZoom)]
    pub fn static_zoom(&self) -> Option<f64> {
        self.inner.static_zoom()
    }
}
