//! A first pass's frames from the page: their size and format, the buffer the
//! page decodes into, and the scratch NV12 frames are de-interleaved into.

use crate::args::{self, ArgError, InputFormat};
use amc_core::FrameRef;

/// Where a pass binding ([`PassPlan`](crate::PassPlan),
/// [`ReadoutEstimator`](crate::ReadoutEstimator)) takes its frames.
pub(crate) struct FrameInput {
    pub width: usize,
    pub height: usize,
    pub format: InputFormat,
    /// The buffer behind [`FrameInput::view`].
    buffer: Vec<u8>,
    /// NV12 frames de-interleaved to I420.
    planar: Vec<u8>,
}

impl FrameInput {
    pub fn new(width: usize, height: usize, format: InputFormat) -> Self {
        Self {
            width,
            height,
            format,
            buffer: Vec::new(),
            planar: Vec::new(),
        }
    }

    /// A view into WASM memory to decode the next frame into (valid until
    /// the next call into the module), as `Stabilizer::input_buffer`.
    pub fn view(&mut self) -> js_sys::Uint8Array {
        let len = self.format.buffer_len(self.width, self.height);
        self.buffer.resize(len, 0);
        // SAFETY: as for `Stabilizer::input_buffer`: the view is handed to
        // JavaScript, which writes the frame before its next call.
        unsafe { js_sys::Uint8Array::view(&self.buffer) }
    }

    /// Calls `f` with `data` (a frame in this input's format; `None`: the
    /// frame in [`FrameInput::view`]'s buffer), its length checked.
    pub fn with_frame<T>(
        &mut self,
        data: Option<&[u8]>,
        f: impl FnOnce(FrameRef<'_>) -> Result<T, ArgError>,
    ) -> Result<T, ArgError> {
        let Self {
            width,
            height,
            format,
            buffer,
            planar,
        } = self;
        args::with_frame(*format, *width, *height, data.unwrap_or(buffer), planar, f)
    }
}
