//! FLV in, H.264 access units in Annex-B form out: how the live encoder's
//! output (ffmpeg's `-f flv` on a pipe) is cut into frames. FLV frames each
//! packet with its size, so a frame is whole as soon as its bytes are read,
//! never held back until the next one starts (as cutting a raw `-f h264`
//! stream at its next access-unit delimiter would be).
//!
//! Layout (Adobe FLV 10.1): a 9-byte header and a 4-byte previous-tag size,
//! then tags of an 11-byte header (type, 24-bit data size, timestamp, stream
//! id), the data and a 4-byte previous-tag size. A video tag's data starts
//! with frame type and codec (7: AVC), the AVC packet type (0: the decoder
//! configuration record holding SPS and PPS; 1: NAL units, each with a 4-byte
//! length) and a composition time.

/// One encoded picture, ready for a decoder from its first byte when `key`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AccessUnit {
    /// Start-code-prefixed NAL units; an IDR unit begins with SPS and PPS.
    pub data: Vec<u8>,
    /// An IDR picture: a decoder can start here.
    pub key: bool,
    /// The FLV timestamp, milliseconds.
    pub pts_ms: u32,
}

/// Why the stream cannot be read as FLV with H.264.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum FlvError {
    /// The stream does not start with an FLV header.
    #[error("not an FLV stream (its first bytes are {0:02x?}, allowed: \"FLV\")")]
    NotFlv([u8; 3]),
    /// A video tag of another codec.
    #[error("FLV video tag with codec {0} (allowed: 7, H.264)")]
    NotH264(u8),
    /// A video tag whose sizes do not add up.
    #[error("malformed FLV video tag: {0}")]
    Malformed(&'static str),
}

const START: [u8; 4] = [0, 0, 0, 1];

/// Reads FLV bytes as they come and hands out whole access units.
#[derive(Default)]
pub struct FlvToAnnexB {
    buf: Vec<u8>,
    /// Bytes of `buf` already consumed.
    pos: usize,
    header_done: bool,
    /// SPS and PPS with start codes, put before every IDR picture.
    parameter_sets: Vec<u8>,
    length_size: usize,
}

impl FlvToAnnexB {
    /// A reader expecting the FLV header first.
    pub fn new() -> Self {
        Self {
            length_size: 4,
            ..Self::default()
        }
    }

    /// Adds `bytes` and returns the access units they complete.
    pub fn push(&mut self, bytes: &[u8]) -> Result<Vec<AccessUnit>, FlvError> {
        self.buf.extend_from_slice(bytes);
        let mut out = Vec::new();
        loop {
            let rest = &self.buf[self.pos..];
            if !self.header_done {
                if rest.len() < 3 {
                    break;
                }
                if &rest[..3] != b"FLV" {
                    return Err(FlvError::NotFlv([rest[0], rest[1], rest[2]]));
                }
                if rest.len() < 9 {
                    break;
                }
                let header = u32::from_be_bytes([rest[5], rest[6], rest[7], rest[8]]) as usize;
                if rest.len() < header + 4 {
                    break;
                }
                self.pos += header + 4;
                self.header_done = true;
                continue;
            }
            if rest.len() < 11 {
                break;
            }
            let size = u32::from_be_bytes([0, rest[1], rest[2], rest[3]]) as usize;
            if rest.len() < 11 + size + 4 {
                break;
            }
            let kind = rest[0] & 0x1f;
            let pts_ms = u32::from_be_bytes([rest[7], rest[4], rest[5], rest[6]]);
            let data = rest[11..11 + size].to_vec();
            self.pos += 11 + size + 4;
            if kind == 9 {
                if let Some(unit) = self.video(&data, pts_ms)? {
                    out.push(unit);
                }
            }
        }
        // Keep the buffer small: drop what was consumed.
        if self.pos > 0 {
            self.buf.drain(..self.pos);
            self.pos = 0;
        }
        Ok(out)
    }

    fn video(&mut self, data: &[u8], pts_ms: u32) -> Result<Option<AccessUnit>, FlvError> {
        if data.len() < 5 {
            return Err(FlvError::Malformed("shorter than its 5-byte header"));
        }
        let codec = data[0] & 0x0f;
        if codec != 7 {
            return Err(FlvError::NotH264(codec));
        }
        let key = data[0] >> 4 == 1;
        let body = &data[5..];
        match data[1] {
            0 => {
                self.configure(body)?;
                Ok(None)
            }
            1 => {
                let mut unit = Vec::with_capacity(body.len() + self.parameter_sets.len() + 16);
                let mut idr = false;
                let mut p = 0;
                while p < body.len() {
                    if p + self.length_size > body.len() {
                        return Err(FlvError::Malformed("a NAL unit's length is cut off"));
                    }
                    let mut n = 0usize;
                    for &b in &body[p..p + self.length_size] {
                        n = n << 8 | b as usize;
                    }
                    p += self.length_size;
                    if n == 0 || p + n > body.len() {
                        return Err(FlvError::Malformed("a NAL unit runs past its tag"));
                    }
                    let nal = &body[p..p + n];
                    let nal_type = nal[0] & 0x1f;
                    if nal_type == 5 && !idr {
                        idr = true;
                        unit.extend_from_slice(&self.parameter_sets);
                    }
                    // In-band SPS/PPS (types 7, 8) are kept as they are.
                    unit.extend_from_slice(&START);
                    unit.extend_from_slice(nal);
                    p += n;
                }
                Ok(Some(AccessUnit {
                    data: unit,
                    key: key && idr,
                    pts_ms,
                }))
            }
            _ => Ok(None),
        }
    }

    /// The AVC decoder configuration record (ISO 14496-15 5.2.4.1).
    fn configure(&mut self, r: &[u8]) -> Result<(), FlvError> {
        let bad = FlvError::Malformed("a cut-off decoder configuration record");
        if r.len() < 6 {
            return Err(bad);
        }
        self.length_size = (r[4] & 3) as usize + 1;
        let mut sets = Vec::new();
        let mut p = 5;
        for count_mask in [0x1f_u8, 0xff] {
            let count = r
                .get(p)
                .ok_or(FlvError::Malformed("no parameter set count"))?
                & count_mask;
            p += 1;
            for _ in 0..count {
                let len = match r.get(p..p + 2) {
                    Some(l) => u16::from_be_bytes([l[0], l[1]]) as usize,
                    None => return Err(FlvError::Malformed("a cut-off parameter set")),
                };
                p += 2;
                let set = r
                    .get(p..p + len)
                    .ok_or(FlvError::Malformed("a cut-off parameter set"))?;
                sets.extend_from_slice(&START);
                sets.extend_from_slice(set);
                p += len;
            }
        }
        self.parameter_sets = sets;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tag(kind: u8, ts: u32, data: &[u8]) -> Vec<u8> {
        let mut t = vec![kind];
        t.extend_from_slice(&(data.len() as u32).to_be_bytes()[1..]);
        t.extend_from_slice(&ts.to_be_bytes()[1..]);
        t.push((ts >> 24) as u8);
        t.extend_from_slice(&[0, 0, 0]);
        t.extend_from_slice(data);
        t.extend_from_slice(&((11 + data.len()) as u32).to_be_bytes());
        t
    }

    fn stream() -> Vec<u8> {
        let mut s = b"FLV\x01\x01\x00\x00\x00\x09\x00\x00\x00\x00".to_vec();
        s.extend(tag(18, 0, b"metadata"));
        // Configuration: one SPS (67 aa), one PPS (68 bb), 4-byte lengths.
        let config = [
            0x17, 0, 0, 0, 0, 1, 0x64, 0, 0x1f, 0xff, 0xe1, 0, 2, 0x67, 0xaa, 1, 0, 2, 0x68, 0xbb,
        ];
        s.extend(tag(9, 0, &config));
        // An IDR picture (65 ...) and a P picture (41 ...).
        s.extend(tag(9, 0, &[0x17, 1, 0, 0, 0, 0, 0, 0, 3, 0x65, 1, 2]));
        s.extend(tag(9, 17, &[0x27, 1, 0, 0, 0, 0, 0, 0, 2, 0x41, 9]));
        s
    }

    #[test]
    fn idr_units_carry_their_parameter_sets_and_p_units_do_not() {
        let units = FlvToAnnexB::new().push(&stream()).unwrap();
        assert_eq!(units.len(), 2);
        assert!(units[0].key);
        assert_eq!(
            units[0].data,
            [0, 0, 0, 1, 0x67, 0xaa, 0, 0, 0, 1, 0x68, 0xbb, 0, 0, 0, 1, 0x65, 1, 2]
        );
        assert!(!units[1].key);
        assert_eq!(units[1].data, [0, 0, 0, 1, 0x41, 9]);
        assert_eq!(units[1].pts_ms, 17);
    }

    #[test]
    fn bytes_in_any_pieces_give_the_same_units() {
        let s = stream();
        let whole = FlvToAnnexB::new().push(&s).unwrap();
        for piece in [1, 2, 5, 13] {
            let mut p = FlvToAnnexB::new();
            let mut units = Vec::new();
            for chunk in s.chunks(piece) {
                units.extend(p.push(chunk).unwrap());
            }
            assert_eq!(units, whole, "pieces of {piece}");
        }
    }

    #[test]
    fn other_streams_are_refused() {
        assert!(matches!(
            FlvToAnnexB::new().push(b"RIFF...."),
            Err(FlvError::NotFlv(_))
        ));
        let mut s = b"FLV\x01\x01\x00\x00\x00\x09\x00\x00\x00\x00".to_vec();
        s.extend(tag(9, 0, &[0x12, 1, 0, 0, 0]));
        assert_eq!(FlvToAnnexB::new().push(&s), Err(FlvError::NotH264(2)));
    }
}
