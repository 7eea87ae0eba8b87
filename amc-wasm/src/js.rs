//! What every binding shares: errors and values for JavaScript, the lens argument.

use crate::args::LensArg;
use wasm_bindgen::prelude::*;

/// Any error as a JavaScript `Error` with its message.
pub(crate) fn err(e: impl std::fmt::Display) -> JsError {
    JsError::new(&e.to_string())
}

/// A JSON value as a plain JavaScript object.
pub(crate) fn to_js(v: &serde_json::Value) -> Result<JsValue, JsError> {
    js_sys::JSON::parse(&v.to_string()).map_err(|_| JsError::new("internal: telemetry is not JSON"))
}

/// Calls `f` with the lens argument `lens`: a number is a field of view,
/// `"auto"` (any case) the field of view estimated from the clip, another
/// string the text of a lens file.
pub(crate) fn with_lens<T>(lens: &JsValue, f: impl FnOnce(LensArg<'_>) -> T) -> T {
    let text = lens.as_string();
    f(match (lens.as_f64(), text.as_deref()) {
        (Some(deg), _) => LensArg::Fov(deg),
        (None, Some(text)) if text.trim().eq_ignore_ascii_case("auto") => LensArg::Auto,
        (None, Some(text)) => LensArg::Text(text),
        (None, None) => LensArg::Other,
    })
}
