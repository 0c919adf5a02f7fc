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
