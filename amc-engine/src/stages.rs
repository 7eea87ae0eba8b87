//! Decoding and encoding beside the stabilizer: with `threads >= 2` a run
//! reads its input on one thread and writes its output on another, so the
//! in-process work of both (y4m and image decoding, colour conversions, pipe
//! copies) overlaps the stabilizer instead of adding to it. With `threads == 1`
//! both run inline, as before.
//!
//! Memory stays bounded: each side owns at most [`QUEUE`] + 2 frame buffers,
//! recycled through a return channel.

use super::RunError;
use amc_core::{Frame, FrameRef, PixelFormat};
use amc_video::{FrameSink, FrameSource, VideoError};
use std::sync::mpsc::{channel, sync_channel, Receiver, Sender, SyncSender};
use std::thread::JoinHandle;

/// Frames that may wait between two stages.
pub const QUEUE: usize = 2;

/// A decoded frame and its timestamp, or the error that ended decoding.
type Decoded = Result<(Frame, f64), VideoError>;

/// The input side of a run.
pub(crate) enum Reader {
    /// Decoding on the caller's thread.
    Inline(Box<dyn FrameSource>),
    /// Decoding on a thread of its own.
    Threaded {
        frames: Option<Receiver<Decoded>>,
        spare: Option<Sender<Frame>>,
        handle: Option<JoinHandle<()>>,
    },
}

impl Reader {
    /// Reads `src` (opened for `format` frames) inline, or on a thread when `threaded`.
    pub fn new(mut src: Box<dyn FrameSource>, format: PixelFormat, threaded: bool) -> Self {
        if !threaded {
            return Reader::Inline(src);
        }
        let (w, h) = (src.info().width, src.info().height);
        let (frames_tx, frames) = sync_channel::<Decoded>(QUEUE);
        let (spare, spare_rx) = channel::<Frame>();
        for _ in 0..QUEUE + 1 {
            let _ = spare.send(Frame::new(w, h, format));
        }
        let handle = std::thread::Builder::new()
            .name("amc-decode".into())
            .spawn(move || {
                // Ends when decoding ends, or when the run stops listening
                // (its receiver or its spare sender dropped).
                while let Ok(mut buf) = spare_rx.recv() {
                    let sent = match src.next_frame(&mut buf) {
                        Ok(Some(t)) => frames_tx.send(Ok((buf, t))),
                        Ok(None) => break,
                        Err(e) => {
                            let _ = frames_tx.send(Err(e));
                            break;
                        }
                    };
                    if sent.is_err() {
                        break;
                    }
                }
            })
            .expect("spawning the decoder thread");
        Reader::Threaded {
            frames: Some(frames),
            spare: Some(spare),
            handle: Some(handle),
        }
    }

    /// Decodes the next frame into `buf` (by swapping buffers when threaded),
    /// returning its timestamp, or `None` at the end.
    pub fn next_frame(&mut self, buf: &mut Frame) -> Result<Option<f64>, VideoError> {
        match self {
            Reader::Inline(src) => src.next_frame(buf),
            Reader::Threaded { frames, spare, .. } => {
                let Some(rx) = frames.as_ref() else {
                    return Ok(None);
                };
                match rx.recv() {
                    Ok(Ok((mut frame, t))) => {
                        std::mem::swap(buf, &mut frame);
                        if let Some(s) = spare.as_ref() {
                            let _ = s.send(frame);
                        }
                        Ok(Some(t))
                    }
                    Ok(Err(e)) => Err(e),
                    // The decoder ended without an error: end of input.
                    Err(_) => Ok(None),
                }
            }
        }
    }
}

impl Drop for Reader {
    fn drop(&mut self) {
        if let Reader::Threaded {
            frames,
            spare,
            handle,
        } = self
        {
            // Stop listening first, so the thread's next send or recv fails.
            drop(frames.take());
            drop(spare.take());
            if let Some(h) = handle.take() {
                let _ = h.join();
            }
        }
    }
}

/// The output side of a run: a sink written inline, or on a thread of its own.
pub(crate) struct Writer {
    /// The sink, when written on the caller's thread.
    inline: Option<Box<dyn FrameSink>>,
    /// Frames for the encoder thread.
    frames: Option<SyncSender<(Frame, f64)>>,
    /// Buffers the encoder thread has written, for reuse.
    spare: Option<Receiver<Frame>>,
    /// Buffers made so far (at most `QUEUE + 2`).
    allocated: usize,
    /// The encoder thread; it hands the sink back when its frames are written.
    handle: Option<JoinHandle<Result<Box<dyn FrameSink>, VideoError>>>,
}

impl Writer {
    /// Writes into `sink` inline, or on a thread when `threaded`.
    pub fn new(mut sink: Box<dyn FrameSink>, threaded: bool) -> Self {
        if !threaded {
            return Self {
                inline: Some(sink),
                frames: None,
                spare: None,
                allocated: 0,
                handle: None,
            };
        }
        let (frames, frames_rx) = sync_channel::<(Frame, f64)>(QUEUE);
        let (spare_tx, spare) = channel::<Frame>();
        let handle = std::thread::Builder::new()
            .name("amc-encode".into())
            .spawn(move || {
                for (frame, t) in frames_rx {
                    sink.write_frame(&frame.as_ref(), t)?;
                    let _ = spare_tx.send(frame);
                }
                Ok(sink)
            })
            .expect("spawning the encoder thread");
        Self {
            inline: None,
            frames: Some(frames),
            spare: Some(spare),
            allocated: 0,
            handle: Some(handle),
        }
    }

    /// Appends a copy of `frame`, shown at `t` seconds.
    pub fn write_frame(&mut self, frame: &FrameRef<'_>, t: f64) -> Result<(), RunError> {
        if let Some(sink) = self.inline.as_mut() {
            return Ok(sink.write_frame(frame, t)?);
        }
        let Some(spare) = self.spare.as_ref() else {
            return Err(self.stopped());
        };
        let mut buf = match spare.try_recv() {
            Ok(b) => b,
            Err(_) if self.allocated < QUEUE + 2 => {
                self.allocated += 1;
                Frame::new(0, 0, PixelFormat::Rgb8)
            }
            // Every buffer is queued or being written: wait for one.
            Err(_) => match spare.recv() {
                Ok(b) => b,
                Err(_) => return Err(self.stopped()),
            },
        };
        buf.width = frame.width;
        buf.height = frame.height;
        buf.format = frame.format;
        buf.data.clear();
        buf.data.extend_from_slice(frame.data);
        match self.frames.as_ref().map(|f| f.send((buf, t))) {
            Some(Ok(())) => Ok(()),
            _ => Err(self.stopped()),
        }
    }

    /// The error that stopped the encoder thread.
    fn stopped(&mut self) -> RunError {
        drop(self.frames.take());
        if let Some(h) = self.handle.take() {
            match h.join() {
                Ok(Err(e)) => return RunError::Video(e),
                Ok(Ok(sink)) => drop(sink),
                Err(_) => {}
            }
        }
        RunError::ThreadFailed { stage: "encoder" }
    }

    /// Waits for every frame to be written, then completes the output.
    pub fn finish(mut self) -> Result<(), RunError> {
        if let Some(sink) = self.inline.take() {
            return Ok(sink.finish()?);
        }
        drop(self.frames.take());
        match self.handle.take().map(JoinHandle::join) {
            Some(Ok(Ok(sink))) => Ok(sink.finish()?),
            Some(Ok(Err(e))) => Err(RunError::Video(e)),
            _ => Err(RunError::ThreadFailed { stage: "encoder" }),
        }
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        // Unfinished: stop the thread; the sink drops with it, which removes
        // the partial output and stops the encoder child.
        drop(self.frames.take());
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}
