//! Large outputs written past the page cache (Linux `O_DIRECT`): the bytes
//! are staged in an aligned buffer and go to the disk a few megabytes at a
//! time, straight from it.
//!
//! Why: a buffered write copies every byte into page-cache pages the kernel
//! has to find first, and on the VMs measured (docs/speed.md) that copy cost
//! about 1.2 ms of CPU per megabyte, 1.0-1.4 s for a 720p `.y4m` of 600
//! frames, taken from the two cores the stabilizer runs on. A direct write
//! leaves the copy to the disk's DMA; the writer thread only waits.

use std::fs::File;
use std::io;

/// Alignment of a direct write's buffer, file offset and length: the
/// largest logical block size of common disks.
const ALIGN: usize = 4096;

/// Bytes staged before they are written: a multiple of [`ALIGN`].
const CHUNK: usize = 4 << 20;

/// Bytes staged for a file in direct mode.
pub(crate) struct Staging {
    /// `CHUNK + ALIGN` bytes, of which `CHUNK` from `start` are aligned.
    buf: Vec<u8>,
    start: usize,
    len: usize,
}

impl Staging {
    /// Switches `file` (empty, opened for writing) to direct writes, or
    /// returns `None` where the file system does not take them (tmpfs, some
    /// network file systems): its writes then stay buffered.
    pub fn enable(file: &File) -> Option<Self> {
        if !set_direct(file, true) {
            return None;
        }
        let buf = vec![0u8; CHUNK + ALIGN];
        let start = buf.as_ptr().align_offset(ALIGN);
        Some(Self { buf, start, len: 0 })
    }

    /// Stages `data`, writing each full chunk to `file`.
    pub fn write(&mut self, file: &mut File, mut data: &[u8]) -> io::Result<()> {
        while !data.is_empty() {
            let n = data.len().min(CHUNK - self.len);
            let at = self.start + self.len;
            self.buf[at..at + n].copy_from_slice(&data[..n]);
            self.len += n;
            data = &data[n..];
            if self.len == CHUNK {
                self.drain(file, CHUNK)?;
            }
        }
        Ok(())
    }

    /// Writes what is staged: the aligned part directly, the rest (under one
    /// block) through the page cache, after which `file` is buffered again.
    pub fn finish(&mut self, file: &mut File) -> io::Result<()> {
        let aligned = self.len / ALIGN * ALIGN;
        if aligned > 0 {
            self.drain(file, aligned)?;
        }
        if !set_direct(file, false) {
            return Err(io::Error::other("could not leave direct writes"));
        }
        let tail = &self.buf[self.start..self.start + self.len];
        io::Write::write_all(file, tail)?;
        self.len = 0;
        Ok(())
    }

    /// Writes the first `n` staged bytes (a multiple of [`ALIGN`]) and moves
    /// the rest to the front. A file system that takes the flag but refuses
    /// a direct write (`EINVAL`) gets the rest through the page cache.
    fn drain(&mut self, file: &mut File, n: usize) -> io::Result<()> {
        debug_assert!(n.is_multiple_of(ALIGN) && n <= self.len);
        let mut chunk = &self.buf[self.start..self.start + n];
        while !chunk.is_empty() {
            match io::Write::write(file, chunk) {
                Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
                Ok(k) => chunk = &chunk[k..],
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == io::ErrorKind::InvalidInput && set_direct(file, false) => {}
                Err(e) => return Err(e),
            }
        }
        self.buf
            .copy_within(self.start + n..self.start + self.len, self.start);
        self.len -= n;
        Ok(())
    }
}

/// Turns direct writes on or off for `file`; whether that succeeded.
#[cfg(target_os = "linux")]
fn set_direct(file: &File, on: bool) -> bool {
    use std::os::fd::AsRawFd;
    let fd = file.as_raw_fd();
    // SAFETY: plain system calls on a descriptor `file` owns; they read no
    // memory of ours.
    unsafe {
        let flags = libc::fcntl(fd, libc::F_GETFL);
        if flags < 0 {
            return false;
        }
        let flags = if on {
            flags | libc::O_DIRECT
        } else {
            flags & !libc::O_DIRECT
        };
        libc::fcntl(fd, libc::F_SETFL, flags) == 0
    }
}

#[cfg(not(target_os = "linux"))]
fn set_direct(_file: &File, on: bool) -> bool {
    !on
}

#[cfg(test)]
mod tests {
    use crate::atomic::AtomicFile;
    use std::io::Write;
    use std::path::Path;

    /// Pieces of odd sizes (a `.y4m`'s 6-byte headers, frames that cross the
    /// staging chunk) come back whole and in order, whether the directory's
    /// file system takes direct writes or not.
    fn round_trip_in(dir: &Path) {
        let path = dir.join("direct.y4m");
        let mut file = AtomicFile::create(&path, ".y4m").unwrap();
        file.write_direct();
        let mut expected = Vec::new();
        for (i, len) in [6usize, 1_382_400, 6, 3_000_001, 5_000_000, 4095, 1]
            .iter()
            .enumerate()
        {
            let piece: Vec<u8> = (0..*len).map(|k| (k * 7 + i * 13) as u8).collect();
            file.write_all(&piece).unwrap();
            expected.extend_from_slice(&piece);
        }
        file.persist().unwrap();
        let back = std::fs::read(&path).unwrap();
        assert_eq!(back.len(), expected.len());
        assert!(back == expected, "the bytes differ");
    }

    #[test]
    fn direct_writes_keep_every_byte_in_order() {
        let dir = tempfile::tempdir().unwrap();
        round_trip_in(dir.path());
        // tmpfs takes no direct writes: the file stays buffered.
        if Path::new("/dev/shm").is_dir() {
            let shm = tempfile::tempdir_in("/dev/shm").unwrap();
            round_trip_in(shm.path());
        }
    }
}
