//! A check telemetry-parser needs and does not make: an MP4 without a whole
//! `moov` box (a recording cut short, a partial download) makes it panic
//! (`unwrap` on mp4parse's `NoMoov`), and in wasm32 a panic aborts the page's
//! module instance, so such a file is refused here first.

use std::io::{Read, Seek, SeekFrom};

/// Top-level boxes looked at before giving up on finding `moov`.
const MAX_BOXES: usize = 4096;

/// `Err(why)` for an ISO-BMFF file (it starts with `ftyp`) whose top-level
/// boxes hold no whole `moov` within its `size` bytes; `Ok` for any other
/// file (not an MP4: the parsers that know it decide). The stream is left
/// at its start.
pub(crate) fn check_mp4_has_moov<R: Read + Seek>(stream: &mut R, size: u64) -> Result<(), String> {
    let found = find_moov(stream, size);
    stream.seek(SeekFrom::Start(0)).map_err(|e| e.to_string())?;
    match found {
        Ok(Some(false)) => Err(
            "the MP4 has no whole moov box (a recording cut short, or a partial copy): its tracks cannot be read"
                .into(),
        ),
        Ok(_) => Ok(()),
        Err(e) => Err(e.to_string()),
    }
}

/// `None`: not an MP4; `Some(found)`: whether a whole `moov` is there.
fn find_moov<R: Read + Seek>(stream: &mut R, size: u64) -> std::io::Result<Option<bool>> {
    // Too short for a box: not an MP4 (the parsers that know it decide).
    if size < 8 {
        return Ok(None);
    }
    let mut pos = 0u64;
    for index in 0..MAX_BOXES {
        if pos + 8 > size {
            break;
        }
        stream.seek(SeekFrom::Start(pos))?;
        let mut head = [0u8; 8];
        stream.read_exact(&mut head)?;
        let kind = &head[4..8];
        if index == 0 && kind != b"ftyp" {
            return Ok(None);
        }
        let len = match u32::from_be_bytes([head[0], head[1], head[2], head[3]]) {
            // To the end of the file.
            0 => size - pos,
            // A 64-bit size follows.
            1 => {
                if pos + 16 > size {
                    break;
                }
                let mut large = [0u8; 8];
                stream.read_exact(&mut large)?;
                u64::from_be_bytes(large)
            }
            n => u64::from(n),
        };
        if len < 8 || pos.saturating_add(len) > size {
            // A box that runs past the end: the file was cut there.
            break;
        }
        if kind == b"moov" {
            return Ok(Some(true));
        }
        pos += len;
    }
    Ok(Some(false))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    fn boxed(kind: &[u8; 4], body: usize) -> Vec<u8> {
        let mut b = ((body + 8) as u32).to_be_bytes().to_vec();
        b.extend_from_slice(kind);
        b.resize(body + 8, 0);
        b
    }

    fn check(bytes: &[u8]) -> Result<(), String> {
        check_mp4_has_moov(&mut Cursor::new(bytes), bytes.len() as u64)
    }

    #[test]
    fn an_mp4_needs_a_whole_moov_and_other_files_pass() {
        let whole = [boxed(b"ftyp", 12), boxed(b"mdat", 100), boxed(b"moov", 40)].concat();
        assert_eq!(check(&whole), Ok(()));
        // Cut inside moov, or before it.
        assert!(check(&whole[..whole.len() - 1]).is_err());
        assert!(check(&whole[..60]).is_err());
        // moov first (fast start), mdat cut short: the tracks are described.
        let fast = [boxed(b"ftyp", 12), boxed(b"moov", 40), boxed(b"mdat", 100)].concat();
        assert_eq!(check(&fast[..fast.len() - 50]), Ok(()));
        // Not an MP4 (a CSV, a blackbox log), or nothing at all.
        assert_eq!(check(b"time,x,y,z\n0,0,0,0\n"), Ok(()));
        assert_eq!(check(b""), Ok(()));
    }
}
