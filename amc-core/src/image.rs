//! Image buffers used throughout the core.
//!
//! The core never decodes or encodes files: callers hand it raw pixels.
//! Colour frames are interleaved 8-bit RGB or RGBA, rows packed without padding
//! (`stride = width * channels`), or planar 8-bit YUV 4:2:0 as video decoders
//! deliver it ([`PixelFormat::Yuv420p`]: half the bytes of RGB and no colour
//! conversion on the way in or out). Grayscale working images are `f32` in `[0, 1]`.
//! Pixel centres sit at integer coordinates (OpenCV convention): pixel `(u, v)`
//! covers `[u - 0.5, u + 0.5] x [v - 0.5, v + 0.5]`.

use crate::error::AmcError;

pub use crate::format::{chroma_size, yuv_plane_offsets, PixelFormat};

/// The three planes of a [`PixelFormat::Yuv420p`] buffer: `(y, u, v)`.
/// Panics when `data` is shorter than [`PixelFormat::buffer_len`].
pub fn yuv_planes(width: usize, height: usize, data: &[u8]) -> (&[u8], &[u8], &[u8]) {
    let (u, v) = yuv_plane_offsets(width, height);
    (&data[..u], &data[u..v], &data[v..v + (v - u)])
}

/// The three planes of a [`PixelFormat::Yuv420p`] buffer, mutable: `(y, u, v)`.
/// Panics when `data` is shorter than [`PixelFormat::buffer_len`].
pub fn yuv_planes_mut(
    width: usize,
    height: usize,
    data: &mut [u8],
) -> (&mut [u8], &mut [u8], &mut [u8]) {
    let (u, v) = yuv_plane_offsets(width, height);
    let (y, rest) = data.split_at_mut(u);
    let (u_plane, rest) = rest.split_at_mut(v - u);
    (y, u_plane, &mut rest[..v - u])
}

/// A borrowed colour frame.
#[derive(Clone, Copy, Debug)]
pub struct FrameRef<'a> {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Pixel layout of `data`.
    pub format: PixelFormat,
    /// Interleaved pixels, row by row without row padding, or the planes of a
    /// planar format one after the other (may carry tail padding).
    pub data: &'a [u8],
}

impl<'a> FrameRef<'a> {
    /// Wraps `data`, checking that its length matches [`PixelFormat::buffer_len`].
    pub fn new(
        width: usize,
        height: usize,
        format: PixelFormat,
        data: &'a [u8],
    ) -> Result<Self, AmcError> {
        if width == 0 || height == 0 {
            return Err(AmcError::EmptyFrame { width, height });
        }
        let expected = format
            .buffer_len(width, height)
            .ok_or(AmcError::FrameTooLarge { width, height })?;
        if data.len() != expected {
            return Err(AmcError::BufferLength {
                expected,
                actual: data.len(),
            });
        }
        Ok(Self {
            width,
            height,
            format,
            data,
        })
    }

    /// Bytes per row (of the Y plane for planar formats).
    pub fn stride(&self) -> usize {
        self.width * self.format.channels()
    }

    /// The Y, U and V planes of a [`PixelFormat::Yuv420p`] frame.
    pub fn yuv_planes(&self) -> (&'a [u8], &'a [u8], &'a [u8]) {
        yuv_planes(self.width, self.height, self.data)
    }
}

/// An owned colour frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Pixel layout of `data`.
    pub format: PixelFormat,
    /// Interleaved pixels, row by row without row padding, or the planes of a
    /// planar format one after the other (may carry tail padding).
    pub data: Vec<u8>,
}

impl Frame {
    /// A black frame (all zeros; for [`PixelFormat::Yuv420p`] Y 16, U = V 128).
    pub fn new(width: usize, height: usize, format: PixelFormat) -> Self {
        let mut f = Self {
            width,
            height,
            format,
            data: Vec::new(),
        };
        f.reshape(width, height, format);
        f
    }

    /// Gives the frame a size and format, reusing the allocation; the pixels
    /// are black (see [`Frame::new`]).
    pub fn reshape(&mut self, width: usize, height: usize, format: PixelFormat) {
        self.width = width;
        self.height = height;
        self.format = format;
        let len = format.buffer_len(width, height).unwrap_or(0);
        self.data.clear();
        match format {
            PixelFormat::Yuv420p => {
                self.data.resize(width * height, 16);
                self.data.resize(len, 128);
            }
            _ => self.data.resize(len, 0),
        }
    }

    /// Borrows this frame.
    pub fn as_ref(&self) -> FrameRef<'_> {
        FrameRef {
            width: self.width,
            height: self.height,
            format: self.format,
            data: &self.data,
        }
    }

    /// Copies `src` into `self`, reusing the allocation when the size allows.
    pub fn copy_from(&mut self, src: &FrameRef<'_>) {
        self.width = src.width;
        self.height = src.height;
        self.format = src.format;
        self.data.clear();
        self.data.extend_from_slice(src.data);
    }
}

/// A single-channel `f32` image with intensities in `[0, 1]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GrayImage {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Intensities in `[0, 1]`, row by row (`width * height` values).
    pub data: Vec<f32>,
}

impl GrayImage {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            data: vec![0.0; width * height],
        }
    }

    /// Resizes in place (contents unspecified), reusing the allocation.
    pub fn resize(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.data.resize(width * height, 0.0);
    }

    /// The intensity at pixel `(x, y)`; panics outside the image.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Bilinear sample at pixel coordinates; `None` outside `[0, w-1] x [0, h-1]`.
    #[inline]
    pub fn sample(&self, x: f32, y: f32) -> Option<f32> {
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let max_x = (self.width - 1) as f32;
        let max_y = (self.height - 1) as f32;
        if x > max_x || y > max_y {
            return None;
        }
        let x0 = (x as usize).min(self.width.saturating_sub(2));
        let y0 = (y as usize).min(self.height.saturating_sub(2));
        let fx = x - x0 as f32;
        let fy = y - y0 as f32;
        let i = y0 * self.width + x0;
        let d = &self.data;
        let (a, b) = (d[i], d[(i + 1).min(d.len() - 1)]);
        let (c, e) = (
            d[(i + self.width).min(d.len() - 1)],
            d[(i + self.width + 1).min(d.len() - 1)],
        );
        let top = a + (b - a) * fx;
        let bot = c + (e - c) * fx;
        Some(top + (bot - top) * fy)
    }
}

/// Rec. 601 luma weights, the weights ffmpeg and OpenCV use for RGB -> gray.
pub const LUMA_WEIGHTS: [f32; 3] = [0.299, 0.587, 0.114];

/// Limited-range luma to `[0, 1]`: `(Y - 16) / 219`, the luma of the RGB a
/// decoder converts the frame to (so tracking and metrics see the same
/// intensities whichever format the frames arrive in).
#[inline]
pub fn y_to_unit(y: u8) -> f32 {
    (y as f32 - 16.0) * (1.0 / 219.0)
}

/// Converts a colour frame to `[0, 1]` luma, into a reused buffer.
pub fn luma_into(src: &FrameRef<'_>, dst: &mut GrayImage) {
    dst.resize(src.width, src.height);
    if src.format == PixelFormat::Yuv420p {
        let (y, _, _) = src.yuv_planes();
        for (out, &v) in dst.data.iter_mut().zip(y) {
            *out = y_to_unit(v).clamp(0.0, 1.0);
        }
        return;
    }
    let c = src.format.channels();
    let k = [
        LUMA_WEIGHTS[0] / 255.0,
        LUMA_WEIGHTS[1] / 255.0,
        LUMA_WEIGHTS[2] / 255.0,
    ];
    for (out, px) in dst.data.iter_mut().zip(src.data.chunks_exact(c)) {
        *out = k[0] * px[0] as f32 + k[1] * px[1] as f32 + k[2] * px[2] as f32;
    }
}
