//! Capture of the frames crossing the master link, both directions, with virtual timestamps.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::{Arc, Mutex};

use crate::pcapng::{PcapngError, PcapngWriter};

/// Which way a captured frame travelled on the master link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Master → segment (the frame as sent).
    ToSegment,
    /// Segment → master (the frame as returned by the first slave).
    ToMaster,
}

/// A receiver of captured Ethernet frames (e.g. a pcapng writer).
pub trait CaptureSink: Send {
    /// `frame` (a whole Ethernet frame without FCS) crossed the master link at virtual time
    /// `t_ns` in direction `dir`.
    fn record(&mut self, t_ns: u64, dir: Direction, frame: &[u8]);

    /// Pushes buffered frames to their destination and reports the first failure so far.
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// One captured frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CapturedFrame {
    /// Virtual time in ns.
    pub t_ns: u64,
    /// Direction on the master link.
    pub dir: Direction,
    /// The Ethernet frame bytes.
    pub data: Vec<u8>,
}

/// A capture kept in memory, shareable so a test can read it while the segment owns the sink.
#[derive(Debug, Clone, Default)]
pub struct MemoryCapture {
    frames: Arc<Mutex<Vec<CapturedFrame>>>,
}

impl MemoryCapture {
    /// An empty capture.
    pub fn new() -> Self {
        Self::default()
    }

    /// A copy of the frames captured so far, in order.
    pub fn frames(&self) -> Vec<CapturedFrame> {
        self.frames
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Removes and returns the frames captured so far.
    pub fn take(&self) -> Vec<CapturedFrame> {
        std::mem::take(&mut *self.frames.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl CaptureSink for MemoryCapture {
    fn record(&mut self, t_ns: u64, dir: Direction, frame: &[u8]) {
        self.frames
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(CapturedFrame {
                t_ns,
                dir,
                data: frame.to_vec(),
            });
    }
}

/// A capture written as pcapng (Ethernet link type, ns timestamps) from the master's point of
/// view: master → segment frames are outbound, returned frames inbound.
#[derive(Debug)]
pub struct PcapngCapture<W: Write + Send> {
    writer: PcapngWriter<W>,
    error: Option<PcapngError>,
}

impl PcapngCapture<BufWriter<File>> {
    /// Creates (truncates) the pcapng file at `path`.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, PcapngError> {
        Self::new(BufWriter::new(File::create(path)?))
    }
}

impl<W: Write + Send> PcapngCapture<W> {
    /// Starts a pcapng stream on `out` (section header and interface description).
    pub fn new(out: W) -> Result<Self, PcapngError> {
        Ok(Self {
            writer: PcapngWriter::new(out)?,
            error: None,
        })
    }

    /// Flushes and returns the underlying writer, or the first error met while writing.
    pub fn finish(mut self) -> Result<W, PcapngError> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.writer.flush()?;
        Ok(self.writer.into_inner())
    }
}

impl<W: Write + Send> CaptureSink for PcapngCapture<W> {
    fn record(&mut self, t_ns: u64, dir: Direction, frame: &[u8]) {
        if self.error.is_some() {
            return;
        }
        if let Err(e) = self
            .writer
            .write_packet(t_ns, frame, dir == Direction::ToSegment)
        {
            self.error = Some(e);
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(e) = self.error.as_ref() {
            return Err(std::io::Error::other(e.to_string()));
        }
        self.writer
            .flush()
            .map_err(|e| std::io::Error::other(e.to_string()))
    }
}
