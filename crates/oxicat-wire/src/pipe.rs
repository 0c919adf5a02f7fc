//! The contract between a master and a segment in the same process: Ethernet frames in and
//! out, and the segment's virtual clock.
//!
//! A master drives an in-process segment only through this trait (as ethercrab's
//! `PduTx`/`PduRx` split keeps its PDU loop apart from the network), so the master knows
//! no simulator and the simulator knows no master. `oxicat-sim`'s `Segment` implements it;
//! `oxicat-master` runs ethercrab's PDU loop over it.

/// A segment that takes whole Ethernet frames and keeps virtual time (ns).
pub trait FramePipe {
    /// Passes the Ethernet frame `frame` through the segment at its current virtual time,
    /// in place; true when the frame came back (then `frame` holds it as returned).
    fn exchange_in_place(&mut self, frame: &mut [u8]) -> bool;

    /// Passes `frames` through the segment as the master's NIC sends a queue: from the
    /// current virtual time, each frame after the first `spacing_ns` (the master's own time
    /// per frame) or one wire time (the line's) after the one before, whichever is longer;
    /// a segment that models the line has them on it together, each behind the one before.
    /// This default sends each when the one before is back and `spacing_ns` passed.
    /// `back[k]` is set to whether frame k came back (only the first `min(frames.len(),
    /// back.len())` frames are sent).
    fn exchange_train(&mut self, frames: &mut [&mut [u8]], back: &mut [bool], spacing_ns: u64) {
        for (k, (f, b)) in frames.iter_mut().zip(back.iter_mut()).enumerate() {
            if k > 0 {
                self.advance_by(spacing_ns);
            }
            *b = self.exchange_in_place(f);
        }
    }

    /// The segment's virtual time, ns.
    fn now(&self) -> u64;

    /// Lets virtual time pass up to `t` (ns; no-op when `t` is past), with every event due
    /// meanwhile (SYNC edges, firmware timers, plant steps).
    fn advance_to(&mut self, t: u64);

    /// A copyable handle on the segment's virtual time that any thread may read without
    /// locking the segment (ethercrab asks for the time while frames are on their way).
    fn clock(&self) -> &'static dyn VirtualClock;

    /// Lets `dt` ns of virtual time pass.
    fn advance_by(&mut self, dt: u64) {
        let t = self.now().saturating_add(dt);
        self.advance_to(t);
    }
}

/// A segment's virtual time (ns), readable from any thread.
pub trait VirtualClock: Sync {
    /// Virtual time in ns.
    fn now(&self) -> u64;
}
