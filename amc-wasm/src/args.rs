//! The checks of every argument the page passes in, in plain Rust (no
//! `JsValue`), so that they run natively too: in the unit tests and under
//! the fuzzer (`fuzz/`, target `wasm_args`). The bindings in `lib.rs` only
//! convert JavaScript values into these types and map [`ArgError`] to a
//! JavaScript `Error` with the same message.

use amc_core::camera::CameraModel;
use amc_core::plan::{LensChoice, LensNote, PassPlan, PlanChoices, ResolvedLens};
use amc_core::{AmcError, PixelFormat, ReadoutSpec, StabilizerParams};
use thiserror::Error;

/// Largest frame side accepted (the core's limit).
pub const MAX_SIDE: f64 = 16384.0;

/// WebAssembly (wasm32) memory a stabilizer may use; beyond it allocations
/// would fail inside the module (a trap), so such sizes are refused up front.
pub const MEMORY_BUDGET: usize = 2 << 30;

/// A bad argument from JavaScript; the message names the value and what is allowed.
#[derive(Debug, Error)]
pub enum ArgError {
    #[error("invalid {name}: {value} (allowed: an integer 1..=16384 pixels)")]
    Dimension { name: &'static str, value: f64 },
    #[error(
        "invalid stabilizer parameters: {detail} (allowed: a JSON object of StabilizerParams: \
         track_width, tracker, view, render, framing)"
    )]
    ParamsJson { detail: String },
    #[error("invalid format: {found:?} (allowed: {})", InputFormat::ALLOWED)]
    Format { found: String },
    #[error(
        "invalid size: {width}x{height} with n_avg {n_avg} and lookahead {lookahead} needs about \
         {need_mib} MiB (allowed: at most {} MiB of WebAssembly memory; use a smaller frame, \
         n_avg or lookahead)", MEMORY_BUDGET >> 20
    )]
    Memory {
        width: usize,
        height: usize,
        n_avg: usize,
        lookahead: usize,
        need_mib: usize,
    },
    #[error("lens file: {0}")]
    LensFile(amc_core::lens::LensError),
    #[error(
        "invalid lens: expected a number (horizontal field of view, degrees) or the text of a lens file"
    )]
    LensType,
    #[error(
        "invalid lens: \"auto\" (allowed here: a horizontal field of view in degrees or the text of a \
         lens file; fov auto is estimated by a PassPlan's lens pass, which gives the field of view)"
    )]
    LensAuto,
    #[error(
        "invalid size: fov auto keeps the clip's first {frames} frames, and {width}x{height} needs \
         about {need_mib} MiB with them (allowed: at most {} MiB of WebAssembly memory; give the \
         field of view in degrees)", MEMORY_BUDGET >> 20
    )]
    AutoFovMemory {
        width: usize,
        height: usize,
        frames: usize,
        need_mib: usize,
    },
    #[error(
        "invalid frame buffer length: {got} bytes (allowed: exactly {expected} = {width}x{height} {format})"
    )]
    BufferLength {
        got: usize,
        expected: usize,
        width: usize,
        height: usize,
        format: &'static str,
    },
    /// The core refused a value (parameters, lens, timestamps).
    #[error(transparent)]
    Core(#[from] AmcError),
}

impl From<amc_core::camera::CameraError> for ArgError {
    fn from(e: amc_core::camera::CameraError) -> Self {
        ArgError::Core(e.into())
    }
}

/// Checks a frame dimension given as a JS number.
pub fn dimension(name: &'static str, value: f64) -> Result<usize, ArgError> {
    if value.is_finite() && value.fract() == 0.0 && (1.0..=MAX_SIDE).contains(&value) {
        Ok(value as usize)
    } else {
        Err(ArgError::Dimension { name, value })
    }
}

/// Parses the shared parameters from JSON (`""`, `null` or `{}`: the defaults).
pub fn parse_params(json: &str) -> Result<StabilizerParams, ArgError> {
    let json = json.trim();
    let params: StabilizerParams = if json.is_empty() || json == "null" {
        StabilizerParams::default()
    } else {
        serde_json::from_str(json).map_err(|e| ArgError::ParamsJson {
            detail: e.to_string(),
        })?
    };
    params.validate()?;
    Ok(params)
}

/// Whether the parameters' JSON sets the shutter (`shutter.readout_ms`);
/// without it a lens file's readout applies.
pub fn sets_shutter(json: &str) -> bool {
    serde_json::from_str::<serde_json::Value>(json)
        .ok()
        .is_some_and(|v| v.get("shutter").is_some_and(|s| !s.is_null()))
}

/// The lens argument: a number is a horizontal field of view in degrees
/// (pinhole), `"auto"` the field of view estimated from the clip (a
/// [`PassPlan`]'s lens pass; a stabilizer refuses it), another string the
/// text of a lens file; anything else is refused.
#[derive(Clone, Copy, Debug)]
pub enum LensArg<'a> {
    Fov(f64),
    Auto,
    Text(&'a str),
    Other,
}

/// The camera of `width x height` frames described by `lens`.
pub fn parse_camera(
    lens: LensArg<'_>,
    width: usize,
    height: usize,
) -> Result<CameraModel, ArgError> {
    parse_lens(lens, width, height).map(|l| l.camera)
}

/// The camera of `width x height` frames described by `lens`, with the
/// readout a lens file states (`readout_ms`, Gyroflow's `frame_readout_time`).
pub fn parse_lens(
    lens: LensArg<'_>,
    width: usize,
    height: usize,
) -> Result<amc_core::lens::LensFile, ArgError> {
    match lens {
        LensArg::Fov(deg) => {
            // The one definition of the `fov` option's range.
            amc_core::LensSpec::parse_fov(&deg.to_string())?;
            Ok(amc_core::lens::LensFile {
                camera: CameraModel::pinhole_hfov(width, height, deg)?,
                readout_ms: None,
            })
        }
        LensArg::Text(text) => amc_core::lens::parse_lens_file(text).map_err(ArgError::LensFile),
        LensArg::Auto => Err(ArgError::LensAuto),
        LensArg::Other => Err(ArgError::LensType),
    }
}

/// Rough upper bound of the stabilizer's memory: the frame ring (`n_avg +
/// lookahead` frames), the input buffer, the saccade slots (7 bytes per
/// output pixel per frame) and working images; refuses what cannot fit.
pub fn check_memory(
    width: usize,
    height: usize,
    format: InputFormat,
    p: &StabilizerParams,
) -> Result<(), ArgError> {
    let frame = format.buffer_len(width, height);
    let frames = p
        .render
        .n_avg
        .saturating_add(p.view.lookahead)
        .saturating_add(4);
    let slots = if p.view.mode == amc_core::Mode::Saccade {
        p.render.n_avg.saturating_mul(width * height * 7)
    } else {
        0
    };
    let need = frame
        .saturating_mul(frames)
        .saturating_add(slots)
        .saturating_add(width * height * 8);
    if need > MEMORY_BUDGET {
        return Err(ArgError::Memory {
            width,
            height,
            n_avg: p.render.n_avg,
            lookahead: p.view.lookahead,
            need_mib: need >> 20,
        });
    }
    Ok(())
}

/// The pixel layout of the frames pushed, named as WebCodecs' `VideoPixelFormat`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputFormat {
    /// `"RGBA"`: 4 bytes per pixel; the output is RGBA.
    Rgba,
    /// `"I420"`: planar 4:2:0, Y then U then V, rows packed; the output is I420.
    I420,
    /// `"NV12"`: the Y plane, then one plane of interleaved U, V pairs
    /// (`ceil(w/2) x ceil(h/2)` pairs, rows packed); the output is I420.
    Nv12,
}

impl InputFormat {
    pub const ALLOWED: &'static str = r#""RGBA" (the default), "I420" or "NV12""#;

    /// `None` (JavaScript `undefined` or `null`) is RGBA.
    pub fn parse(name: Option<&str>) -> Result<Self, ArgError> {
        match name {
            None | Some("RGBA") => Ok(InputFormat::Rgba),
            Some("I420") => Ok(InputFormat::I420),
            Some("NV12") => Ok(InputFormat::Nv12),
            Some(other) => Err(ArgError::Format {
                found: other.to_string(),
            }),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            InputFormat::Rgba => "RGBA",
            InputFormat::I420 => "I420",
            InputFormat::Nv12 => "NV12",
        }
    }

    /// The core's format of the frames pushed (NV12 is de-interleaved to I420).
    pub fn core(self) -> PixelFormat {
        match self {
            InputFormat::Rgba => PixelFormat::Rgba8,
            InputFormat::I420 | InputFormat::Nv12 => PixelFormat::Yuv420p,
        }
    }

    /// Bytes of one `width x height` frame (NV12 and I420 have the same size).
    /// Sizes are at most 16384 x 16384, so this cannot overflow.
    pub fn buffer_len(self, width: usize, height: usize) -> usize {
        self.core().buffer_len(width, height).unwrap_or(usize::MAX)
    }
}

/// A checked `new Stabilizer(width, height, paramsJson, lens, format)`.
pub struct Opened {
    pub stabilizer: amc_core::Stabilizer,
    pub width: usize,
    pub height: usize,
    pub format: InputFormat,
}

/// The constructor's arguments, checked in the order the page's errors name
/// them (format, sizes, parameters, memory, lens): the camera, and the
/// parameters with the lens file's readout when `paramsJson` sets no shutter.
pub struct Checked {
    pub camera: CameraModel,
    pub params: StabilizerParams,
    pub width: usize,
    pub height: usize,
    pub format: InputFormat,
    /// The readout the lens file states (none for a field of view).
    pub lens_readout_ms: Option<f64>,
    /// Whether `paramsJson` sets the shutter (then the lens file's readout does not apply).
    pub sets_shutter: bool,
}

/// The arguments every binding checks first, in the order the page's errors
/// name them: the format, the sizes, the parameters and the memory they need.
fn check_input(
    width: f64,
    height: f64,
    params_json: &str,
    format: Option<&str>,
) -> Result<(InputFormat, usize, usize, StabilizerParams), ArgError> {
    let format = InputFormat::parse(format)?;
    let width = dimension("width", width)?;
    let height = dimension("height", height)?;
    let params = parse_params(params_json)?;
    check_memory(width, height, format, &params)?;
    Ok((format, width, height, params))
}

/// Checks the arguments of a stabilizer or a readout estimator (see [`Checked`]).
pub fn check(
    width: f64,
    height: f64,
    params_json: &str,
    lens: LensArg<'_>,
    format: Option<&str>,
) -> Result<Checked, ArgError> {
    let (format, width, height, mut params) = check_input(width, height, params_json, format)?;
    let lens = parse_lens(lens, width, height)?;
    let sets_shutter = sets_shutter(params_json);
    if let (false, Some(ms)) = (sets_shutter, lens.readout_ms) {
        params.shutter.readout_ms = ms;
    }
    Ok(Checked {
        camera: lens.camera,
        params,
        width,
        height,
        format,
        lens_readout_ms: lens.readout_ms,
        sets_shutter,
    })
}

impl Checked {
    /// Builds the core's stabilizer from the checked arguments.
    pub fn open(self) -> Result<Opened, ArgError> {
        let stabilizer =
            amc_core::Stabilizer::new(&self.camera, self.width, self.height, self.params)?;
        Ok(Opened {
            stabilizer,
            width: self.width,
            height: self.height,
            format: self.format,
        })
    }
}

/// The readout argument of a pass plan.
#[derive(Clone, Copy, Debug)]
pub enum ReadoutArg<'a> {
    /// `undefined` or `null`: as the parameters say (their shutter, else the
    /// lens file's readout, else 0).
    Unset,
    /// `"auto"` or milliseconds as text.
    Text(&'a str),
    /// Milliseconds.
    Ms(f64),
}

impl ReadoutArg<'_> {
    /// The readout a plan takes: `Unset` is the parameters' shutter when
    /// `sets_shutter`, else the lens file's readout (else 0).
    fn spec(self, sets_shutter: bool, params: &StabilizerParams) -> Result<ReadoutSpec, ArgError> {
        Ok(match self {
            ReadoutArg::Unset if sets_shutter => ReadoutSpec::Ms(params.shutter.readout_ms),
            ReadoutArg::Unset => ReadoutSpec::FromLens,
            ReadoutArg::Text(text) => ReadoutSpec::parse(text)?,
            ReadoutArg::Ms(ms) => ReadoutSpec::parse(&ms.to_string())?,
        })
    }
}

/// A checked `new PassPlan(width, height, paramsJson, lens, format, readout)`:
/// the plan, and the frames' size and format. A `lens` of `"auto"` plans the
/// lens pass (the clip's first [`amc_core::plan::AUTO_FOV_FRAMES`] frames,
/// kept in memory: sizes whose frames would not fit are refused); any other
/// lens is checked as [`check`] does.
pub fn check_plan(
    width: f64,
    height: f64,
    params_json: &str,
    lens: LensArg<'_>,
    format: Option<&str>,
    readout: ReadoutArg<'_>,
) -> Result<(PassPlan, usize, usize, InputFormat), ArgError> {
    if !matches!(lens, LensArg::Auto) {
        let c = check(width, height, params_json, lens, format)?;
        let (w, h, f) = (c.width, c.height, c.format);
        return Ok((c.plan(readout)?, w, h, f));
    }
    let (format, width, height, params) = check_input(width, height, params_json, format)?;
    let frames = amc_core::plan::AUTO_FOV_FRAMES;
    // The lens pass keeps its frames (as the core's 4:2:0 or RGBA) next to
    // what the stabilizer needs later.
    let kept = format
        .core()
        .buffer_len(width, height)
        .unwrap_or(usize::MAX);
    let need = kept.saturating_mul(frames).saturating_add(
        format
            .buffer_len(width, height)
            .saturating_mul(params.render.n_avg + params.view.lookahead + 4),
    );
    if need > MEMORY_BUDGET {
        return Err(ArgError::AutoFovMemory {
            width,
            height,
            frames,
            need_mib: need >> 20,
        });
    }
    let readout = readout.spec(sets_shutter(params_json), &params)?;
    let plan = PassPlan::new(PlanChoices {
        lens: LensChoice::Auto,
        readout,
        params,
        static_zoom: true,
        frame_size: Some((width, height)),
    })?;
    Ok((plan, width, height, format))
}

impl Checked {
    /// The pass plan of a clip with these arguments and the `readout`
    /// argument (see [`ReadoutArg`]); `zoom: "static"` makes its pass.
    pub fn plan(self, readout: ReadoutArg<'_>) -> Result<PassPlan, ArgError> {
        let readout = readout.spec(self.sets_shutter, &self.params)?;
        let lens = ResolvedLens {
            camera: self.camera,
            note: LensNote::Given,
            readout_ms: self.lens_readout_ms,
        };
        Ok(PassPlan::new(PlanChoices {
            lens: LensChoice::Known(lens),
            readout,
            params: self.params,
            static_zoom: true,
            frame_size: Some((self.width, self.height)),
        })?)
    }
}

/// Checks that a pushed frame has exactly the length its size and format need.
pub fn check_frame_len(
    format: InputFormat,
    width: usize,
    height: usize,
    got: usize,
) -> Result<(), ArgError> {
    let expected = format.buffer_len(width, height);
    if got != expected {
        return Err(ArgError::BufferLength {
            got,
            expected,
            width,
            height,
            format: format.name(),
        });
    }
    Ok(())
}

/// Pushes one frame of `data` (checked against the size and format) at `t`
/// seconds into `stabilizer`, with its pose when a gyro pass gave it
/// (`given`); NV12 is de-interleaved into `planar` (reused).
#[allow(clippy::too_many_arguments)]
pub fn push_frame(
    stabilizer: &mut amc_core::Stabilizer,
    format: InputFormat,
    width: usize,
    height: usize,
    data: &[u8],
    t: f64,
    given: Option<amc_core::GivenPose>,
    planar: &mut Vec<u8>,
) -> Result<Option<amc_core::Telemetry>, ArgError> {
    with_frame(format, width, height, data, planar, |frame| {
        Ok(match given {
            Some(given) => stabilizer.push_posed(frame, t, given)?,
            None => stabilizer.push(frame, t)?,
        })
    })
}

/// Calls `f` with the frame in `data` (checked against the size and format;
/// NV12 de-interleaved into `planar`, reused).
pub fn with_frame<T>(
    format: InputFormat,
    width: usize,
    height: usize,
    data: &[u8],
    planar: &mut Vec<u8>,
    f: impl FnOnce(amc_core::FrameRef<'_>) -> Result<T, ArgError>,
) -> Result<T, ArgError> {
    check_frame_len(format, width, height, data.len())?;
    let data = if format == InputFormat::Nv12 {
        nv12_to_i420(width, height, data, planar);
        &planar[..]
    } else {
        data
    };
    f(amc_core::FrameRef::new(width, height, format.core(), data)?)
}

/// De-interleaves an NV12 frame (`width x height`, its exact length, checked
/// by [`check_frame_len`]) into I420 in `out` (resized).
pub fn nv12_to_i420(width: usize, height: usize, nv12: &[u8], out: &mut Vec<u8>) {
    let n = width * height;
    out.resize(nv12.len(), 0);
    out[..n].copy_from_slice(&nv12[..n]);
    let nc = (nv12.len() - n) / 2;
    let (u, v) = out[n..].split_at_mut(nc);
    for ((pair, u), v) in nv12[n..].chunks_exact(2).zip(u).zip(v) {
        *u = pair[0];
        *v = pair[1];
    }
}
