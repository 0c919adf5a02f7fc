//! The ESC chip on a board's SPI1: a LAN9252 or an ET1100 (`oxicat-pdi`'s byte-exact
//! models), clocked a byte at a time by the emulated SPI peripheral. A board chooses its
//! chip ([`EscChip`]); the chip's pins are the same on every image (PA10 IRQ, PB3 SYNC0,
//! PB5 SYNC1; the ET1100's EEPROM_LOADED on PB4).

use oxicat_esc::Esc;
use oxicat_pdi::sim::{
    BusStats, Et1100Frame, Et1100Model, Handle, Lan9252Frame, Lan9252Model, Model, PinKind,
};

/// Which ESC chip a board carries (for [`crate::node::EmulatedNode::with_chip`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ChipKind {
    /// Microchip LAN9252 (SPI, DWORD registers and PRAM FIFOs).
    #[default]
    Lan9252,
    /// Beckhoff ET1100 (SPI PDI, two/three-byte addressing, EEPROM_LOADED output).
    Et1100,
}

/// The ESC chip on SPI1, shared with whoever owns its ESC (a test, the segment's node).
#[derive(Clone)]
pub enum EscChip {
    /// A LAN9252.
    Lan9252(Handle<Lan9252Model>),
    /// An ET1100.
    Et1100(Handle<Et1100Model>),
}

impl From<Handle<Lan9252Model>> for EscChip {
    fn from(h: Handle<Lan9252Model>) -> Self {
        EscChip::Lan9252(h)
    }
}

impl From<Handle<Et1100Model>> for EscChip {
    fn from(h: Handle<Et1100Model>) -> Self {
        EscChip::Et1100(h)
    }
}

/// One CS-low frame in progress.
pub(crate) enum ChipFrame {
    Lan9252(Lan9252Frame),
    Et1100(Et1100Frame),
}

impl EscChip {
    /// Which chip this is.
    pub fn kind(&self) -> ChipKind {
        match self {
            EscChip::Lan9252(_) => ChipKind::Lan9252,
            EscChip::Et1100(_) => ChipKind::Et1100,
        }
    }

    /// The electrical level of one of the chip's pins.
    pub fn pin(&self, kind: PinKind) -> bool {
        match self {
            EscChip::Lan9252(h) => h.with(|m| m.pin(kind)),
            EscChip::Et1100(h) => h.with(|m| m.pin(kind)),
        }
    }

    /// Runs `f` on the chip's ESC.
    pub fn with_esc<T>(&self, f: impl FnOnce(&mut Esc) -> T) -> T {
        match self {
            EscChip::Lan9252(h) => h.with_esc(f),
            EscChip::Et1100(h) => h.with_esc(f),
        }
    }

    /// Exchanges the chip's ESC with `esc` ([`Handle::swap_esc`]).
    pub fn swap_esc(&self, esc: &mut Esc) {
        match self {
            EscChip::Lan9252(h) => h.swap_esc(esc),
            EscChip::Et1100(h) => h.swap_esc(esc),
        }
    }

    /// The chip's bus counters (malformed frames among them).
    pub fn stats(&self) -> BusStats {
        match self {
            EscChip::Lan9252(h) => h.stats(),
            EscChip::Et1100(h) => h.stats(),
        }
    }

    /// Clears the chip's bus counters.
    pub fn reset_stats(&self) {
        match self {
            EscChip::Lan9252(h) => h.reset_stats(),
            EscChip::Et1100(h) => h.reset_stats(),
        }
    }

    /// CS fell: a new frame.
    pub(crate) fn begin(&self) -> ChipFrame {
        match self {
            EscChip::Lan9252(_) => ChipFrame::Lan9252(Lan9252Frame::default()),
            EscChip::Et1100(_) => ChipFrame::Et1100(Et1100Frame::default()),
        }
    }

    /// One byte of frame `f`; `pause_ns` the bus idled before it.
    pub(crate) fn clock_byte(&self, f: &mut ChipFrame, mosi: u8, pause_ns: u32) -> u8 {
        match (self, f) {
            (EscChip::Lan9252(h), ChipFrame::Lan9252(f)) => h.with(|m| m.clock_byte(f, mosi)),
            (EscChip::Et1100(h), ChipFrame::Et1100(f)) => {
                h.with(|m| m.clock_byte(f, mosi, pause_ns))
            }
            _ => 0xFF,
        }
    }

    /// CS rose: the frame ends.
    pub(crate) fn end(&self, f: ChipFrame) {
        match (self, f) {
            (EscChip::Lan9252(h), ChipFrame::Lan9252(f)) => h.with(|m| m.end_frame(f)),
            (EscChip::Et1100(h), ChipFrame::Et1100(f)) => h.with(|m| m.end_frame(f)),
            _ => {}
        }
    }
}
