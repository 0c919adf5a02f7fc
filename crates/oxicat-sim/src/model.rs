//! What the segment needs from an ESC, so the scheduler can also be driven by a stand-in.
//!
//! [`oxicat_esc::Esc`] implements [`SegmentEsc`]; unit tests of the walk and the scheduler use
//! a tiny fake.

/// Events an ESC reported while time advanced: the ESC's own type, one for the chip, the
/// segment and its stand-ins.
pub use oxicat_esc::EscEvents as AdvanceEvents;

/// The ECAT-side and timing interface of an ESC, as the segment drives it.
pub trait SegmentEsc: Send {
    /// A frame (starting at the EtherCAT header) reaches `port` at `t`; returns the egress
    /// port, or `None` when the ESC drops it.
    fn forward(&mut self, port: u8, frame: &mut [u8], t: u64, frame_ok: bool) -> Option<u8>;
    /// [`forward`](Self::forward) with the frame's configured-address index (built once per
    /// frame by the segment): an ESC that uses it processes only its own FPRD/FPWR/FPRW
    /// datagrams and records the IRQ bits of the others in `d`. The default ignores it.
    fn forward_dispatched(
        &mut self,
        port: u8,
        frame: &mut [u8],
        t: u64,
        frame_ok: bool,
        d: &mut oxicat_esc::FrameDispatch,
    ) -> Option<u8> {
        let _ = d;
        self.forward(port, frame, t, frame_ok)
    }
    /// Physical link state of `port`.
    fn set_link(&mut self, port: u8, up: bool);
    /// Time passes up to `t`.
    fn advance(&mut self, t: u64) -> AdvanceEvents;
    /// Global time of the next event (SYNC edge, watchdog expiry), if any.
    fn next_event(&self) -> Option<u64>;
    /// Level of the PDI interrupt line.
    fn irq_line(&self) -> bool;
    /// A number that changes whenever [`next_event`](Self::next_event) and
    /// [`irq_line`](Self::irq_line) may answer differently; `None` (the default): unknown,
    /// the segment asks both after every hop of a frame. With `Some`, a hop that leaves it
    /// as the previous hop at this ESC left it skips both (see `oxicat_esc::Esc::query_epoch`).
    fn query_epoch(&self) -> Option<u64> {
        None
    }
}

impl SegmentEsc for oxicat_esc::Esc {
    fn forward(&mut self, port: u8, frame: &mut [u8], t: u64, frame_ok: bool) -> Option<u8> {
        oxicat_esc::Esc::forward(self, port, frame, t, frame_ok).port()
    }

    fn forward_dispatched(
        &mut self,
        port: u8,
        frame: &mut [u8],
        t: u64,
        frame_ok: bool,
        d: &mut oxicat_esc::FrameDispatch,
    ) -> Option<u8> {
        oxicat_esc::Esc::forward_dispatched(self, port, frame, t, frame_ok, d).port()
    }

    fn set_link(&mut self, port: u8, up: bool) {
        oxicat_esc::Esc::set_link(self, port, up)
    }

    fn advance(&mut self, t: u64) -> AdvanceEvents {
        oxicat_esc::Esc::advance(self, t)
    }

    fn next_event(&self) -> Option<u64> {
        oxicat_esc::Esc::next_event(self)
    }

    fn irq_line(&self) -> bool {
        oxicat_esc::Esc::irq_line(self)
    }

    #[inline]
    fn query_epoch(&self) -> Option<u64> {
        oxicat_esc::Esc::query_epoch(self)
    }
}
