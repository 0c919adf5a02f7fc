//! `oxicat-pdi`: ESC chip drivers over `embedded-hal` 1.0 [`SpiDevice`], each an
//! implementation of the stack's one seam, [`oxicat_slave::Pdi`].
//!
//! - [`Lan9252`]: Microchip LAN9252 in SPI mode (read 0x03 / fast read 0x0B / write
//!   0x02), BYTE_TEST/ID_REV/HW_CFG checks and reset at start-up, ESC registers through the
//!   EtherCAT CSR indirect command/data registers, process RAM through the PRAM FIFOs;
//! - [`Et1100Spi`]: Beckhoff ET1100/ET1200 (FB1111-0141) SPI PDI with two- and three-byte
//!   addressing, read / read-with-wait-state / write, the AL event request clocked out in
//!   the address phase, EEPROM_LOADED check.
//!
//! Every wait on the chip is bounded by a retry count and ends in [`Error::Timeout`]:
//! a driver never hangs on a dead or misbehaving chip.
//!
//! With the `sim` feature, [`sim`] holds SPI peripherals that speak both chips' SPI
//! protocols byte for byte on top of the software ESC `oxicat_esc::Esc` and count bus
//! time at a configured SCLK.
//!
//! [`SpiDevice`]: embedded_hal::spi::SpiDevice
#![cfg_attr(not(feature = "sim"), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod et1100;
pub mod lan9252;
pub mod pins;
#[cfg(feature = "sim")]
pub mod sim;

pub use et1100::{AddressMode, Et1100Config, Et1100Spi, ReadMode};
pub use lan9252::{Lan9252, Lan9252Config};
pub use pins::{Lines, NoLines, Pins};

/// Why a driver access failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The SPI bus reported an error.
    Spi(E),
    /// The chip did not finish (CSR busy, PRAM FIFO not ready, chip not ready) within the
    /// configured number of polls.
    Timeout,
    /// LAN9252 BYTE_TEST (0x0064) did not read 0x87654321: no chip, wrong SPI mode or a
    /// stuck MISO line (the value read is kept).
    ByteTest(u32),
    /// LAN9252 ID_REV (0x0050) is not a LAN9252 (0x9252_xxxx).
    ChipId(u32),
    /// ET1100: ESC type register 0x0000 did not read an ESC type (0x00 and 0xFF are what
    /// a dead bus gives).
    EscType(u8),
    /// ET1100: the PDI control register 0x0140 does not select the SPI PDI (0x05).
    PdiType(u8),
    /// ET1100: EEPROM_LOADED stayed low (no or invalid SII EEPROM; PDI not configured).
    EepromNotLoaded,
    /// The address (plus length) is beyond what the chip/addressing mode can reach.
    Address(u16),
    /// The chip returned a reply the protocol does not allow (e.g. a PRAM FIFO count
    /// beyond the FIFO size).
    Protocol,
}

impl<E: core::fmt::Debug> core::fmt::Display for Error<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Spi(e) => write!(f, "SPI error: {e:?}"),
            Error::Timeout => write!(f, "ESC did not answer within the retry budget"),
            Error::ByteTest(v) => write!(f, "BYTE_TEST read {v:#010x}, expected 0x87654321"),
            Error::ChipId(v) => write!(f, "ID_REV {v:#010x} is not a LAN9252"),
            Error::EscType(v) => write!(f, "ESC type {v:#04x} is not an ESC"),
            Error::PdiType(v) => write!(f, "PDI control {v:#04x} is not SPI (0x05)"),
            Error::EepromNotLoaded => write!(f, "EEPROM_LOADED is low"),
            Error::Address(a) => write!(f, "address {a:#06x} out of reach"),
            Error::Protocol => write!(f, "reply violates the SPI protocol"),
        }
    }
}
