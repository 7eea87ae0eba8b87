//! The gyro's first pass (`new GyroPass`): the whole clip tracked from the
//! picture by a stabilizer that only tracks, as the engine's fusion
//! pass does; then the clip's log synchronized and fused with it
//! (amc-gyrolog's `fuse_log`, the engine's own) into each frame's pose for
//! the main [`Stabilizer`](crate::Stabilizer) ([`Stabilizer::set_poses`](crate::Stabilizer::set_poses)).

use crate::args;
use crate::gyro::ClipGyro;
use crate::input::FrameInput;
use crate::js::{err, to_js, with_lens};
use amc_core::Telemetry;
use amc_gyrolog::{fuse_log, video_only_warning, FuseLogError};
use wasm_bindgen::prelude::*;

/// A first pass over every frame of a clip for its gyro log.
#[wasm_bindgen]
pub struct GyroPass {
    stab: amc_core::Stabilizer,
    input: FrameInput,
    /// The telemetry of every output so far: the picture's poses.
    seen: Vec<Telemetry>,
}

#[wasm_bindgen]
impl GyroPass {
    /// `new GyroPass(width, height, paramsJson, lens, format?)`: as the main
    /// `new Stabilizer` is made (the same parameters, the readout resolved,
    /// and the same lens), so the picture's poses are the ones it would track.
    #[wasm_bindgen(constructor)]
    pub fn new(
        width: f64,
        height: f64,
        params_json: &str,
        lens: JsValue,
        format: Option<String>,
    ) -> Result<GyroPass, JsError> {
        let args::Opened {
            stabilizer: mut stab,
            width,
            height,
            format,
        } = with_lens(&lens, |l| {
            args::check(width, height, params_json, l, format.as_deref())
        })
        .and_then(args::Checked::open)
        .map_err(err)?;
        stab.set_tracking_only(true);
        Ok(GyroPass {
            stab,
            input: FrameInput::new(width, height, format),
            seen: Vec::new(),
        })
    }

    /// Frames tracked so far (outputs the lookahead let out).
    #[wasm_bindgen(getter)]
    pub fn frames(&self) -> usize {
        self.seen.len()
    }

    /// A view into WASM memory to decode the next frame into, as
    /// [`Stabilizer::input_buffer`](crate::Stabilizer::input_buffer); then call [`GyroPass::push_input`].
    #[wasm_bindgen(js_name = inputBuffer)]
    pub fn input_buffer(&mut self) -> js_sys::Uint8Array {
        self.input.view()
    }

    /// Tracks the frame in [`GyroPass::input_buffer`], `t` seconds in.
    #[wasm_bindgen(js_name = pushInput)]
    pub fn push_input(&mut self, t: f64) -> Result<(), JsError> {
        self.push_from(None, t)
    }

    /// Tracks a frame in this pass's format, `t` seconds in.
    pub fn push(&mut self, data: &[u8], t: f64) -> Result<(), JsError> {
        self.push_from(Some(data), t)
    }

    fn push_from(&mut self, data: Option<&[u8]>, t: f64) -> Result<(), JsError> {
        let stab = &mut self.stab;
        let tel = self
            .input
            .with_frame(data, |frame| Ok(stab.push(frame, t)?))
            .map_err(err)?;
        self.seen.extend(tel);
        Ok(())
    }

    /// After the clip's last frame: synchronizes `gyro` with the frames
    /// tracked and fuses the two. Returns `{report, line, poses}` (`report`:
    /// the CLI's `--metrics` `"gyro"` object; `line`: the CLI's line for it;
    /// `poses`: the JSON for [`Stabilizer::set_poses`](crate::Stabilizer::set_poses), one per frame), or
    /// `{warning}` when the log does not fit the video (the run then goes
    /// on from the picture alone, as the CLI's does).
    pub fn fuse(&mut self, gyro: &ClipGyro) -> Result<JsValue, JsError> {
        while let Some(tel) = self.stab.finish() {
            self.seen.push(tel);
        }
        let readout_s = self.stab.params().shutter.readout_ms * 1e-3;
        let v = match fuse_log(&gyro.log, &self.seen, readout_s) {
            Ok(fused) => serde_json::json!({
                "line": fused.report.line(),
                "report": serde_json::to_value(&fused.report).map_err(err)?,
                "poses": serde_json::to_string(&fused.poses).map_err(err)?,
            }),
            Err(FuseLogError::Sync(e)) => serde_json::json!({ "warning": video_only_warning(&e) }),
            Err(FuseLogError::Fuse(e)) => return Err(err(e)),
        };
        to_js(&v)
    }
}
