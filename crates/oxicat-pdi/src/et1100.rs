//! Beckhoff ET1100/ET1200 (FB1111-0141) SPI PDI.
//!
//! Every access is an address phase and a data phase inside one CS-low frame:
//!
//! - two-byte address (addresses 0x0000..0x1FFF): `A[12:5]`, `A[4:0] CMD[2:0]`;
//! - three-byte address: `A[12:5]`, `A[4:0] 110` (address extension),
//!   `A[15:13] CMD[2:0] 00`.
//!
//! Commands: 000 NOP, 010 read, 011 read with wait state, 100 write, 110 address
//! extension. While the master clocks out the address, the ESC clocks out the AL event
//! request 0x0220, 0x0221 (and 0x0222 in the third byte). A read with wait state is
//! followed by one wait-state byte 0xFF; a plain read needs a pause (≥ 240 ns) between
//! the phases instead. In the data phase of a read the master sends 0x00 and 0xFF on the
//! last byte (read termination), otherwise the ESC prefetches past the end.

use crate::pins::{Lines, NoLines};
use crate::Error;
use embedded_hal::digital::InputPin;
use embedded_hal::spi::{Operation, SpiDevice};
use oxicat_slave::{IrqLines, Pdi};

/// SPI commands (3 bits).
pub mod cmd {
    /// No operation (the address phase still returns the AL event request).
    pub const NOP: u8 = 0b000;
    /// Read.
    pub const READ: u8 = 0b010;
    /// Read with wait state byte.
    pub const READ_WS: u8 = 0b011;
    /// Write.
    pub const WRITE: u8 = 0b100;
    /// Address extension (three-byte addressing).
    pub const ADDR_EXT: u8 = 0b110;
    /// The wait-state byte.
    pub const WAIT_STATE: u8 = 0xFF;
    /// The read termination byte (last byte of a read's data phase).
    pub const READ_TERMINATION: u8 = 0xFF;
}

/// How addresses are sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AddressMode {
    /// Two bytes where the address fits 13 bits, three above.
    TwoByte,
    /// Always three bytes (24 AL event request bits on every access).
    ThreeByte,
}

/// How the ESC gets time to fetch read data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadMode {
    /// Command 011 and a wait-state byte 0xFF.
    WaitState,
    /// Command 010 and a pause of `ns` between address and data phase.
    Delay {
        /// Pause in ns (ET1100: ≥ 240 ns).
        ns: u32,
    },
}

/// Driver settings.
#[derive(Debug, Clone, Copy)]
pub struct Et1100Config {
    /// Address mode.
    pub address_mode: AddressMode,
    /// Read mode.
    pub read_mode: ReadMode,
    /// Polls of EEPROM_LOADED at start-up before [`Error::EepromNotLoaded`].
    pub retries: u32,
}

impl Default for Et1100Config {
    fn default() -> Self {
        Et1100Config {
            address_mode: AddressMode::TwoByte,
            read_mode: ReadMode::WaitState,
            retries: 64,
        }
    }
}

/// An ET1100/ET1200 SPI PDI on an SPI bus, with its SPI_IRQ/SYNC0/SYNC1 lines.
pub struct Et1100Spi<SPI, L = NoLines> {
    spi: SPI,
    lines: L,
    cfg: Et1100Config,
    last_event: u32,
}

type R<T, SPI> = Result<T, Error<<SPI as embedded_hal::spi::ErrorType>::Error>>;

/// Address phase bytes for `addr` and `command`.
pub fn address_phase(addr: u16, command: u8, three: bool) -> ([u8; 3], usize) {
    let b0 = (addr >> 5) as u8;
    let lo = ((addr & 0x1F) as u8) << 3;
    if three {
        (
            [
                b0,
                lo | cmd::ADDR_EXT,
                (((addr >> 13) as u8) << 5) | (command << 2),
            ],
            3,
        )
    } else {
        ([b0, lo | command, 0], 2)
    }
}

impl<SPI: SpiDevice, L: Lines> Et1100Spi<SPI, L> {
    /// A driver; call [`Et1100Spi::init`] before use.
    pub fn new(spi: SPI, lines: L, cfg: Et1100Config) -> Self {
        Et1100Spi {
            spi,
            lines,
            cfg,
            last_event: 0,
        }
    }

    /// The SPI device.
    pub fn spi_mut(&mut self) -> &mut SPI {
        &mut self.spi
    }

    /// Gives back the bus and the lines.
    pub fn release(self) -> (SPI, L) {
        (self.spi, self.lines)
    }

    /// The AL event request bits seen in the last address phase.
    pub fn last_al_event(&self) -> u32 {
        self.last_event
    }

    /// Start-up: waits for EEPROM_LOADED (the PDI is configured only after the SII was
    /// loaded), checks the ESC type (0x0000) and that the PDI control (0x0140) selects
    /// SPI. Returns the ESC type.
    pub fn init<EL: InputPin>(&mut self, eeprom_loaded: &mut EL) -> R<u8, SPI> {
        let mut loaded = false;
        for _ in 0..self.cfg.retries.max(1) {
            if eeprom_loaded.is_high().unwrap_or(false) {
                loaded = true;
                break;
            }
        }
        if !loaded {
            return Err(Error::EepromNotLoaded);
        }
        let mut b = [0u8; 1];
        self.read_esc(0x0000, &mut b)?;
        if b[0] == 0x00 || b[0] == 0xFF {
            return Err(Error::EscType(b[0]));
        }
        let ty = b[0];
        self.read_esc(0x0140, &mut b)?;
        if b[0] != 0x05 {
            return Err(Error::PdiType(b[0]));
        }
        Ok(ty)
    }

    fn three(&self, addr: u16, len: usize) -> R<bool, SPI> {
        let end = addr as usize + len;
        if end > 0x1_0000 {
            return Err(Error::Address(addr));
        }
        Ok(self.cfg.address_mode == AddressMode::ThreeByte || end > 0x2000)
    }

    fn note_event(&mut self, ev: &[u8; 3], n: usize) {
        let mut e = u32::from(ev[0]) | u32::from(ev[1]) << 8;
        if n == 3 {
            e |= u32::from(ev[2]) << 16;
        }
        self.last_event = e;
    }

    /// One read access.
    pub fn read_esc(&mut self, addr: u16, buf: &mut [u8]) -> R<(), SPI> {
        if buf.is_empty() {
            return Ok(());
        }
        let three = self.three(addr, buf.len())?;
        let command = match self.cfg.read_mode {
            ReadMode::WaitState => cmd::READ_WS,
            ReadMode::Delay { .. } => cmd::READ,
        };
        let (a, n) = address_phase(addr, command, three);
        let mut ev = [0u8; 3];
        buf.fill(0x00);
        let last = buf.len() - 1;
        buf[last] = cmd::READ_TERMINATION;
        let res = match self.cfg.read_mode {
            ReadMode::WaitState => self.spi.transaction(&mut [
                Operation::Transfer(&mut ev[..n], &a[..n]),
                Operation::Write(&[cmd::WAIT_STATE]),
                Operation::TransferInPlace(buf),
            ]),
            ReadMode::Delay { ns } => self.spi.transaction(&mut [
                Operation::Transfer(&mut ev[..n], &a[..n]),
                Operation::DelayNs(ns),
                Operation::TransferInPlace(buf),
            ]),
        };
        res.map_err(Error::Spi)?;
        self.note_event(&ev, n);
        Ok(())
    }

    /// One write access.
    pub fn write_esc(&mut self, addr: u16, data: &[u8]) -> R<(), SPI> {
        if data.is_empty() {
            return Ok(());
        }
        let three = self.three(addr, data.len())?;
        let (a, n) = address_phase(addr, cmd::WRITE, three);
        let mut ev = [0u8; 3];
        self.spi
            .transaction(&mut [
                Operation::Transfer(&mut ev[..n], &a[..n]),
                Operation::Write(data),
            ])
            .map_err(Error::Spi)?;
        self.note_event(&ev, n);
        Ok(())
    }

    /// A three-byte NOP: only the address phase, which returns AL event request bits
    /// 0..23 (bits 24..31 are reserved in the ET1100).
    pub fn nop(&mut self) -> R<u32, SPI> {
        let (a, n) = address_phase(0, cmd::NOP, true);
        let mut ev = [0u8; 3];
        self.spi
            .transaction(&mut [Operation::Transfer(&mut ev[..n], &a[..n])])
            .map_err(Error::Spi)?;
        self.note_event(&ev, n);
        Ok(self.last_event)
    }
}

impl<SPI: SpiDevice, L: Lines> Pdi for Et1100Spi<SPI, L> {
    type Error = Error<SPI::Error>;

    fn read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), Self::Error> {
        self.read_esc(addr, buf)
    }

    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), Self::Error> {
        self.write_esc(addr, data)
    }

    fn al_event_request(&mut self) -> Result<u32, Self::Error> {
        self.nop()
    }

    fn irq_lines(&mut self) -> IrqLines {
        self.lines.lines()
    }
}
