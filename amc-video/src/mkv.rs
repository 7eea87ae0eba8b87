//! A minimal Matroska writer for raw frames (RGB24 or planar YUV 4:2:0) with
//! their timestamps, the stream our encoder child reads from its stdin. It
//! converts nothing: the frames arrive in the track's [`RawFormat`].
//!
//! A raw pipe (`-f rawvideo`) has no timestamps, so every frame would be
//! placed at `i / fps`: a variable-frame-rate input (phones, screen captures,
//! cup.mp4) then drifts against its copied audio. Matroska carries one
//! timestamp per block and can be streamed: the segment has an unknown size
//! (as in live WebM), and each frame is one cluster holding one `SimpleBlock`.
//! Only the elements ffmpeg's demuxer needs are written (EBML header, `Info`
//! with a microsecond `TimestampScale`, one `V_UNCOMPRESSED` video track whose
//! `ColourSpace` FourCC ffmpeg maps to a pixel format: `RGB\x18` to `rgb24`,
//! `I420` to `yuv420p`).
//!
//! Element layout (RFC 8794 EBML, RFC 9559 Matroska): ID bytes, the data size
//! as a variable-length integer (a length marker bit, then the value), data.

use std::io::{self, Write};

/// `TimestampScale`: timestamps count microseconds.
const TIMESTAMP_SCALE_NS: u64 = 1000;

/// The layout of the raw frames of the track.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RawFormat {
    /// Packed 8-bit RGB (ffmpeg's `rgb24`).
    Rgb24,
    /// Planar YUV 4:2:0, Y then U then V (ffmpeg's `yuv420p`).
    I420,
}

impl RawFormat {
    /// The `ColourSpace` FourCC by which ffmpeg's demuxer knows the layout
    /// (its raw pixel-format tag table).
    fn fourcc(self) -> &'static [u8; 4] {
        match self {
            RawFormat::Rgb24 => b"RGB\x18",
            RawFormat::I420 => b"I420",
        }
    }
}

/// Appends an element with `data`.
fn element(out: &mut Vec<u8>, id: u32, data: &[u8]) {
    id_bytes(out, id);
    size_vint(out, data.len() as u64);
    out.extend_from_slice(data);
}

/// Appends an unsigned-integer element (big-endian, shortest form).
fn uint_element(out: &mut Vec<u8>, id: u32, v: u64) {
    let bytes = v.to_be_bytes();
    let skip = bytes.iter().take_while(|&&b| b == 0).count().min(7);
    element(out, id, &bytes[skip..]);
}

/// An element ID is written as its own bytes (its length marker is part of it).
fn id_bytes(out: &mut Vec<u8>, id: u32) {
    let bytes = id.to_be_bytes();
    let skip = bytes.iter().take_while(|&&b| b == 0).count();
    out.extend_from_slice(&bytes[skip..]);
}

/// A data size as an 8-byte variable-length integer (marker `0x01`, 56-bit value).
fn size_vint(out: &mut Vec<u8>, n: u64) {
    debug_assert!(n < (1 << 56) - 1);
    out.push(0x01);
    out.extend_from_slice(&n.to_be_bytes()[1..]);
}

/// The stream header: EBML header, the start of a segment of unknown size,
/// `Info` and `Tracks` for one `width` x `height` video track of raw `format` frames.
pub(crate) fn header(width: usize, height: usize, format: RawFormat) -> Vec<u8> {
    let mut out = Vec::new();
    let mut ebml = Vec::new();
    uint_element(&mut ebml, 0x4286, 1); // EBMLVersion
    uint_element(&mut ebml, 0x42F7, 1); // EBMLReadVersion
    uint_element(&mut ebml, 0x42F2, 4); // EBMLMaxIDLength
    uint_element(&mut ebml, 0x42F3, 8); // EBMLMaxSizeLength
    element(&mut ebml, 0x4282, b"matroska"); // DocType
    uint_element(&mut ebml, 0x4287, 4); // DocTypeVersion
    uint_element(&mut ebml, 0x4285, 2); // DocTypeReadVersion
    element(&mut out, 0x1A45_DFA3, &ebml);

    // Segment of unknown size: all value bits set.
    id_bytes(&mut out, 0x1853_8067);
    out.extend_from_slice(&[0x01, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]);

    let mut info = Vec::new();
    uint_element(&mut info, 0x2A_D7B1, TIMESTAMP_SCALE_NS); // TimestampScale
    element(&mut info, 0x4D80, b"amc"); // MuxingApp
    element(&mut info, 0x5741, b"amc"); // WritingApp
    element(&mut out, 0x1549_A966, &info);

    let mut video = Vec::new();
    uint_element(&mut video, 0xB0, width as u64); // PixelWidth
    uint_element(&mut video, 0xBA, height as u64); // PixelHeight
    element(&mut video, 0x2E_B524, format.fourcc()); // ColourSpace (FourCC)
    let mut track = Vec::new();
    uint_element(&mut track, 0xD7, 1); // TrackNumber
    uint_element(&mut track, 0x73C5, 1); // TrackUID
    uint_element(&mut track, 0x83, 1); // TrackType: video
    uint_element(&mut track, 0x9C, 0); // FlagLacing
    element(&mut track, 0x86, b"V_UNCOMPRESSED"); // CodecID
    element(&mut track, 0xE0, &video); // Video
    let mut tracks = Vec::new();
    element(&mut tracks, 0xAE, &track); // TrackEntry
    element(&mut out, 0x1654_AE6B, &tracks); // Tracks
    out
}

/// Writes one frame at `t` seconds (non-negative) as a cluster with one
/// keyframe block; `scratch` holds the cluster's small header between calls.
pub(crate) fn write_frame(
    out: &mut impl Write,
    t: f64,
    pixels: &[u8],
    scratch: &mut Vec<u8>,
) -> io::Result<()> {
    let us = (t.max(0.0) * 1e6).round() as u64;
    let mut timestamp = Vec::with_capacity(10);
    uint_element(&mut timestamp, 0xE7, us); // Cluster Timestamp
                                            // SimpleBlock: track number 1 (vint 0x81), relative timestamp 0 (int16), flags: keyframe.
    let block_header = [0x81u8, 0x00, 0x00, 0x80];
    let block_len = (block_header.len() + pixels.len()) as u64;
    let mut block_prefix = Vec::with_capacity(16);
    id_bytes(&mut block_prefix, 0xA3);
    size_vint(&mut block_prefix, block_len);
    let cluster_len = (timestamp.len() + block_prefix.len()) as u64 + block_len;
    scratch.clear();
    id_bytes(scratch, 0x1F43_B675); // Cluster
    size_vint(scratch, cluster_len);
    scratch.extend_from_slice(&timestamp);
    scratch.extend_from_slice(&block_prefix);
    scratch.extend_from_slice(&block_header);
    out.write_all(scratch)?;
    out.write_all(pixels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_are_shortest_big_endian() {
        let mut v = Vec::new();
        uint_element(&mut v, 0xE7, 0x0102);
        assert_eq!(v, [0xE7, 0x01, 0, 0, 0, 0, 0, 0, 0x02, 0x01, 0x02]);
        let mut v = Vec::new();
        uint_element(&mut v, 0xD7, 0);
        assert_eq!(v, [0xD7, 0x01, 0, 0, 0, 0, 0, 0, 0x01, 0x00]);
    }

    #[test]
    fn header_starts_with_the_ebml_magic() {
        let h = header(64, 48, RawFormat::I420);
        assert_eq!(&h[..4], &[0x1A, 0x45, 0xDF, 0xA3]);
        let needle = b"V_UNCOMPRESSED";
        assert!(h.windows(needle.len()).any(|w| w == needle));
        assert!(h.windows(4).any(|w| w == b"I420"));
    }
}
