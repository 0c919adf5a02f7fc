//! Simulated SPI peripherals: a LAN9252 and an ET1100 SPI PDI in front of the software
//! ESC, byte-exact per transaction (CS low = one [`SpiDevice::transaction`]), with bus
//! time counted at a configured SCLK.
//!
//! A peripheral and its pins share the chip through a [`Handle`]; the ECAT side of the
//! ESC (master frames, time) is reached with [`Handle::with_esc`]. The handle is `Send`
//! (an `Arc<Mutex<_>>`), so a driver over a simulated chip can live inside firmware that a
//! virtual segment runs on another thread. When the ESC belongs to someone else (the
//! segment), [`Handle::swap_esc`] lends it to the chip for the duration of an access.

mod et1100;
mod lan9252;

pub use et1100::{Et1100Frame, Et1100Model};
pub use lan9252::{Lan9252Frame, Lan9252Model};

use core::convert::Infallible;
use embedded_hal::digital::{self, InputPin};
use embedded_hal::spi::{self, Operation, SpiDevice};
use oxicat_esc::Esc;
use std::sync::{Arc, Mutex, MutexGuard};
use std::vec;
use std::vec::Vec;

/// Bus timing model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusConfig {
    /// SPI clock in Hz.
    pub sclk_hz: u32,
    /// Per-transaction overhead: CS setup + hold + CS high time between frames (ns).
    pub cs_overhead_ns: u32,
}

impl BusConfig {
    /// A bus at `mhz` MHz with 100 ns CS overhead per transaction.
    pub fn mhz(mhz: u32) -> Self {
        BusConfig {
            sclk_hz: mhz * 1_000_000,
            cs_overhead_ns: 100,
        }
    }
}

/// What the bus carried since the last [`Handle::reset_stats`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BusStats {
    /// Transactions (CS-low frames).
    pub transactions: u64,
    /// Bytes clocked (both directions at once).
    pub bytes: u64,
    /// Bus time in picoseconds (bits at SCLK + CS overhead + in-frame delays).
    pub ps: u64,
    /// Frames the chip found malformed.
    pub protocol_errors: u64,
}

impl BusStats {
    /// Bus time in µs.
    pub fn us(&self) -> f64 {
        self.ps as f64 / 1e6
    }
}

/// Misbehaviour to inject.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Fault {
    /// A healthy chip.
    #[default]
    None,
    /// No chip: MISO reads 0xFF (pull-up), the chip sees nothing.
    MisoStuckHigh,
    /// No chip: MISO reads 0x00 (pull-down), the chip sees nothing.
    MisoStuckLow,
    /// LAN9252: CSR busy never clears.
    CsrStuckBusy,
    /// LAN9252: PRAM FIFOs never report data/space.
    PramNeverReady,
    /// LAN9252: PRAM command registers report an impossible FIFO count.
    PramBadCount,
    /// LAN9252: HW_CFG READY never sets.
    NeverReady,
    /// ET1100: EEPROM_LOADED stays low.
    EepromNotLoaded,
}

/// The pins of a chip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PinKind {
    /// IRQ (LAN9252) / SPI_IRQ (ET1100), electrical level.
    Irq,
    /// SYNC0.
    Sync0,
    /// SYNC1.
    Sync1,
    /// EEPROM_LOADED (ET1100).
    EepromLoaded,
}

/// A PDI write the chip accepted but holds back (see [`Handle::hold_writes`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HeldWrite {
    /// ESC address.
    pub addr: u16,
    /// The bytes.
    pub data: Vec<u8>,
}

/// State common to both chip models.
pub struct Core {
    /// The software ESC behind the chip.
    pub esc: Esc,
    /// Bus timing.
    pub bus: BusConfig,
    /// Counters.
    pub stats: BusStats,
    /// Injected fault.
    pub fault: Fault,
    /// While `Some`, PDI writes are held here instead of reaching the ESC.
    pub held: Option<Vec<HeldWrite>>,
}

impl Core {
    /// A chip core in front of `esc`.
    pub fn new(esc: Esc, bus: BusConfig) -> Self {
        Core {
            esc,
            bus,
            stats: BusStats::default(),
            fault: Fault::None,
            held: None,
        }
    }

    /// The chip reads the ESC: what the ESC answers, overlaid with the writes held back
    /// so far (the firmware reads what it wrote).
    pub fn pdi_read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), oxicat_esc::PdiError> {
        self.esc.pdi_read(addr, buf)?;
        for w in self.held.iter().flatten() {
            let (a, b) = (usize::from(addr), usize::from(w.addr));
            let lo = a.max(b);
            let hi = (a + buf.len()).min(b + w.data.len());
            if lo < hi {
                buf[lo - a..hi - a].copy_from_slice(&w.data[lo - b..hi - b]);
            }
        }
        Ok(())
    }

    /// The chip writes the ESC, or holds the write back (range-checked all the same).
    pub fn pdi_write(&mut self, addr: u16, data: &[u8]) -> Result<(), oxicat_esc::PdiError> {
        match self.held.as_mut() {
            Some(h) => {
                self.esc.pdi_check(addr, data.len())?;
                h.push(HeldWrite {
                    addr,
                    data: data.to_vec(),
                });
                Ok(())
            }
            None => self.esc.pdi_write(addr, data),
        }
    }
}

/// A chip model: one CS-low frame in, MISO bytes out.
pub trait Model {
    /// Common state.
    fn core(&mut self) -> &mut Core;
    /// Processes one frame: `mosi` all bytes the master clocked, `delays` the in-frame
    /// pauses as (byte position, ns). Returns MISO, one byte per MOSI byte.
    fn frame(&mut self, mosi: &[u8], delays: &[(usize, u32)]) -> Vec<u8>;
    /// Electrical level of a pin.
    fn pin(&mut self, pin: PinKind) -> bool;
}

/// Shared access to a chip model (`Send` when the model is).
pub struct Handle<M>(Arc<Mutex<M>>);

impl<M> Clone for Handle<M> {
    fn clone(&self) -> Self {
        Handle(self.0.clone())
    }
}

impl<M: Model> Handle<M> {
    /// Wraps a model.
    pub fn new(m: M) -> Self {
        Handle(Arc::new(Mutex::new(m)))
    }
    /// The model, locked. A panic while it was locked (only a test's own assertion can do
    /// that) does not make the chip unusable: the poison is ignored.
    fn lock(&self) -> MutexGuard<'_, M> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
    /// Runs `f` on the ESC (ECAT side: frames, time).
    pub fn with_esc<T>(&self, f: impl FnOnce(&mut Esc) -> T) -> T {
        f(&mut self.lock().core().esc)
    }
    /// Runs `f` on the model.
    pub fn with<T>(&self, f: impl FnOnce(&mut M) -> T) -> T {
        f(&mut self.lock())
    }
    /// Exchanges the chip's ESC with `esc` (cheap: `Esc` is about 1.4 KB, its register file,
    /// process RAM and EEPROM are on the heap). A virtual segment that owns the ESC swaps it in before the firmware runs an
    /// event through the driver and swaps it back afterwards; in between, the chip holds
    /// whatever stand-in it was built with.
    pub fn swap_esc(&self, esc: &mut Esc) {
        core::mem::swap(&mut self.lock().core().esc, esc);
    }
    /// Starts (`true`) or stops holding the chip's PDI writes back: while held, a write
    /// is range-checked and kept (reads see it overlaid) but does not reach the ESC until
    /// someone takes it ([`take_held_writes`](Self::take_held_writes)) and commits it —
    /// how a simulator makes a handler's writes land when its bus time has passed.
    /// Stopping drops nothing: take the writes first.
    pub fn hold_writes(&self, on: bool) {
        let mut m = self.lock();
        let c = m.core();
        match (on, c.held.is_some()) {
            (true, false) => c.held = Some(Vec::new()),
            (false, true) => c.held = None,
            _ => {}
        }
    }
    /// The writes held back so far, in the order the chip accepted them.
    pub fn take_held_writes(&self) -> Vec<HeldWrite> {
        self.lock()
            .core()
            .held
            .as_mut()
            .map(core::mem::take)
            .unwrap_or_default()
    }
    /// Counters since the last reset.
    pub fn stats(&self) -> BusStats {
        self.lock().core().stats
    }
    /// Clears the counters.
    pub fn reset_stats(&self) {
        self.lock().core().stats = BusStats::default();
    }
    /// Injects a fault.
    pub fn set_fault(&self, f: Fault) {
        self.lock().core().fault = f;
    }
    /// Changes the bus timing.
    pub fn set_bus(&self, b: BusConfig) {
        self.lock().core().bus = b;
    }
    /// The SPI device.
    pub fn spi(&self) -> SimSpi<M> {
        SimSpi(self.clone())
    }
    /// A pin.
    pub fn pin(&self, pin: PinKind) -> SimPin<M> {
        SimPin(self.clone(), pin)
    }
}

/// The simulated SPI device (CS included).
pub struct SimSpi<M>(pub Handle<M>);

/// Simulated LAN9252 on SPI.
pub type SimLan9252Spi = SimSpi<Lan9252Model>;
/// Simulated ET1100 SPI PDI.
pub type SimEt1100Spi = SimSpi<Et1100Model>;

impl<M> spi::ErrorType for SimSpi<M> {
    type Error = Infallible;
}

impl<M: Model> SpiDevice for SimSpi<M> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        let mut mosi = Vec::new();
        let mut delays = Vec::new();
        let mut delay_ps = 0u64;
        for op in ops.iter() {
            match op {
                Operation::Read(b) => mosi.extend(core::iter::repeat_n(0u8, b.len())),
                Operation::Write(w) => mosi.extend_from_slice(w),
                Operation::Transfer(r, w) => {
                    mosi.extend_from_slice(w);
                    mosi.extend(core::iter::repeat_n(0u8, r.len().saturating_sub(w.len())));
                }
                Operation::TransferInPlace(b) => mosi.extend_from_slice(b),
                Operation::DelayNs(ns) => {
                    delays.push((mosi.len(), *ns));
                    delay_ps += u64::from(*ns) * 1000;
                }
            }
        }
        let mut m = self.0.lock();
        let fault = m.core().fault;
        let miso = match fault {
            Fault::MisoStuckHigh => vec![0xFF; mosi.len()],
            Fault::MisoStuckLow => vec![0x00; mosi.len()],
            _ => m.frame(&mosi, &delays),
        };
        let c = m.core();
        let bit_ps = 1_000_000_000_000u64 / u64::from(c.bus.sclk_hz.max(1));
        c.stats.transactions += 1;
        c.stats.bytes += mosi.len() as u64;
        c.stats.ps +=
            mosi.len() as u64 * 8 * bit_ps + u64::from(c.bus.cs_overhead_ns) * 1000 + delay_ps;
        drop(m);
        let mut pos = 0;
        for op in ops.iter_mut() {
            match op {
                Operation::Read(b) | Operation::TransferInPlace(b) => {
                    b.copy_from_slice(&miso[pos..pos + b.len()]);
                    pos += b.len();
                }
                Operation::Write(w) => pos += w.len(),
                Operation::Transfer(r, w) => {
                    r.copy_from_slice(&miso[pos..pos + r.len()]);
                    pos += r.len().max(w.len());
                }
                Operation::DelayNs(_) => {}
            }
        }
        Ok(())
    }
}

/// A simulated input pin (electrical level).
pub struct SimPin<M>(Handle<M>, PinKind);

impl<M> digital::ErrorType for SimPin<M> {
    type Error = Infallible;
}

impl<M: Model> InputPin for SimPin<M> {
    fn is_high(&mut self) -> Result<bool, Infallible> {
        Ok(self.0.lock().pin(self.1))
    }
    fn is_low(&mut self) -> Result<bool, Infallible> {
        self.is_high().map(|h| !h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use oxicat_esc::EscConfig;

    #[test]
    fn held_writes_are_read_back_but_reach_the_esc_only_when_committed() {
        let h = Lan9252Model::handle(
            Esc::new(EscConfig::lan9252(), Vec::new()),
            BusConfig::mhz(20),
        );
        h.hold_writes(true);
        h.with(|m| {
            let c = m.core();
            c.pdi_write(0x1400, &[1, 2, 3]).unwrap();
            c.pdi_write(0x1401, &[9]).unwrap();
            assert!(c.pdi_write(0xFFFF, &[0, 0]).is_err(), "range-checked");
            let mut b = [0u8; 4];
            c.pdi_read(0x13FF, &mut b).unwrap();
            assert_eq!(b, [0, 1, 9, 3]);
        });
        let mut b = [0u8; 3];
        h.with_esc(|e| e.pdi_read(0x1400, &mut b)).unwrap();
        assert_eq!(b, [0, 0, 0], "not in the ESC yet");
        let w = h.take_held_writes();
        h.hold_writes(false);
        assert_eq!(w.len(), 2);
        h.with_esc(|e| {
            for x in &w {
                e.pdi_write(x.addr, &x.data).unwrap();
            }
            e.pdi_read(0x1400, &mut b).unwrap();
        });
        assert_eq!(b, [1, 9, 3]);
        // Not holding: writes go straight through.
        h.with(|m| m.core().pdi_write(0x1400, &[7]).unwrap());
        h.with_esc(|e| e.pdi_read(0x1400, &mut b)).unwrap();
        assert_eq!(b[0], 7);
    }
}
