//! The one seam between firmware and an EtherCAT Slave Controller: [`Pdi`].
//!
//! Register addresses the stack uses are in [`reg`]; the stack never needs more than
//! byte reads/writes, the AL event request and the interrupt lines.

/// Interrupt lines of the ESC as the MCU sees them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IrqLines {
    /// The PDI interrupt (AL event request & AL event mask != 0).
    pub pdi_irq: bool,
    /// The DC SYNC0 output.
    pub sync0: bool,
    /// The DC SYNC1 output.
    pub sync1: bool,
}

/// Access to an ESC from the MCU side: the software ESC, an SPI chip driver, ...
pub trait Pdi {
    /// Why an access failed (an SPI transfer can time out; the software ESC refuses
    /// addresses beyond its memory).
    type Error: core::fmt::Debug;

    /// Reads `buf.len()` bytes at ESC address `addr` (SyncManager rules apply).
    fn read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), Self::Error>;

    /// Writes `data` at ESC address `addr` (SyncManager rules apply).
    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), Self::Error>;

    /// The AL event request register 0x0220..0x0223.
    fn al_event_request(&mut self) -> Result<u32, Self::Error>;

    /// Which interrupt lines are active now.
    fn irq_lines(&mut self) -> IrqLines;

    /// Reads one byte.
    fn read_u8(&mut self, addr: u16) -> Result<u8, Self::Error> {
        let mut b = [0u8; 1];
        self.read(addr, &mut b)?;
        Ok(b[0])
    }

    /// Reads a little-endian u16.
    fn read_u16(&mut self, addr: u16) -> Result<u16, Self::Error> {
        let mut b = [0u8; 2];
        self.read(addr, &mut b)?;
        Ok(u16::from_le_bytes(b))
    }

    /// Reads a little-endian u32.
    fn read_u32(&mut self, addr: u16) -> Result<u32, Self::Error> {
        let mut b = [0u8; 4];
        self.read(addr, &mut b)?;
        Ok(u32::from_le_bytes(b))
    }

    /// Writes a little-endian u16.
    fn write_u16(&mut self, addr: u16, v: u16) -> Result<(), Self::Error> {
        self.write(addr, &v.to_le_bytes())
    }
}

/// ESC register addresses used by the stack: the one map of `oxicat_wire::regs`.
pub mod reg {
    pub use oxicat_wire::regs::*;
}

#[cfg(feature = "soft-esc")]
mod soft {
    use super::{IrqLines, Pdi};
    use oxicat_esc::{Esc, PdiError};

    impl Pdi for Esc {
        type Error = PdiError;

        fn read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), PdiError> {
            self.pdi_read(addr, buf)
        }

        fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), PdiError> {
            self.pdi_write(addr, data)
        }

        fn al_event_request(&mut self) -> Result<u32, PdiError> {
            Ok(Esc::al_event_request(self))
        }

        fn irq_lines(&mut self) -> IrqLines {
            let (sync0, sync1) = self.sync_lines();
            IrqLines {
                pdi_irq: self.irq_line(),
                sync0,
                sync1,
            }
        }
    }
}
