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

/// ESC register addresses used by the stack (Beckhoff ESC datasheet section II).
pub mod reg {
    /// AL control (requested state, error acknowledge).
    pub const AL_CONTROL: u16 = 0x0120;
    /// AL status (current state, error indication).
    pub const AL_STATUS: u16 = 0x0130;
    /// AL status code.
    pub const AL_STATUS_CODE: u16 = 0x0134;
    /// AL event mask (which AL events drive the PDI IRQ).
    pub const AL_EVENT_MASK: u16 = 0x0204;
    /// AL event request.
    pub const AL_EVENT_REQ: u16 = 0x0220;
    /// Process-data watchdog status (bit 0: watchdog active/not expired).
    pub const WD_STATUS_PD: u16 = 0x0440;
    /// First SyncManager register block (8 bytes per SM).
    pub const SM_BASE: u16 = 0x0800;
    /// DC cyclic unit control / activation (0x0980 unit control, 0x0981 activation).
    pub const DC_ACTIVATION: u16 = 0x0980;
    /// SYNC0 status (reading acknowledges in acknowledge mode).
    pub const DC_SYNC0_STATUS: u16 = 0x098E;
    /// SYNC1 status.
    pub const DC_SYNC1_STATUS: u16 = 0x098F;
    /// SYNC0 cycle time (u32, ns).
    pub const DC_SYNC0_CYCLE: u16 = 0x09A0;
    /// SYNC1 cycle time (u32, ns).
    pub const DC_SYNC1_CYCLE: u16 = 0x09A4;

    /// Address of register byte `off` of SyncManager `n`.
    pub const fn sm(n: u8, off: u16) -> u16 {
        SM_BASE + 8 * n as u16 + off
    }

    /// AL event request bit 0: AL control written.
    pub const EV_AL_CONTROL: u32 = 1 << 0;
    /// AL event request bit 2: SYNC0.
    pub const EV_SYNC0: u32 = 1 << 2;
    /// AL event request bit 3: SYNC1.
    pub const EV_SYNC1: u32 = 1 << 3;
    /// AL event request bit 4: SM activation changed.
    pub const EV_SM_CHANGE: u32 = 1 << 4;
    /// AL event request bit 6: process-data watchdog expired.
    pub const EV_WATCHDOG: u32 = 1 << 6;
    /// AL event request bit 8 + n: SyncManager n.
    pub const fn ev_sm(n: u8) -> u32 {
        1 << (8 + n as u32)
    }
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
