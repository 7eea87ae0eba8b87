//! JPEG in and out of the live feed: stabilized frames encoded for viewers,
//! a publisher's frames decoded for the processor.

use amc_core::{Frame, PixelFormat};

/// Encodes a stabilized frame for viewers (jpeg-encoder's SIMD path: a
/// few milliseconds at 960x540, several times faster than `image`'s encoder).
pub fn encode_jpeg(
    frame: &amc_core::FrameRef<'_>,
    quality: u8,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let (Ok(w), Ok(h)) = (u16::try_from(frame.width), u16::try_from(frame.height)) else {
        return Err(format!(
            "{}x{} is too large for JPEG",
            frame.width, frame.height
        ));
    };
    let mut rgb = Vec::new();
    let (data, color) = match frame.format {
        PixelFormat::Rgb8 => (frame.data, jpeg_encoder::ColorType::Rgb),
        PixelFormat::Rgba8 => (frame.data, jpeg_encoder::ColorType::Rgba),
        PixelFormat::Yuv420p => {
            amc_core::color::yuv420p_to_rgb_into(
                frame.width,
                frame.height,
                frame.data,
                false,
                3,
                &mut rgb,
            );
            (&rgb[..], jpeg_encoder::ColorType::Rgb)
        }
    };
    jpeg_encoder::Encoder::new(out, quality)
        .encode(data, w, h, color)
        .map_err(|e| e.to_string())
}

pub fn decode_jpeg(bytes: &[u8], into: &mut Frame) -> Result<(), image::ImageError> {
    let img = image::load_from_memory_with_format(bytes, image::ImageFormat::Jpeg)?.into_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    into.width = w;
    into.height = h;
    into.format = PixelFormat::Rgb8;
    into.data = img.into_raw();
    Ok(())
}
