//! `oxicat-esc`: a software EtherCAT Slave Controller.
//!
//! The register file 0x0000..0x0FFF and process RAM, datagram execution with the
//! working-counter rules, SyncManagers, FMMUs, AL/DL state, SII EEPROM emulation,
//! watchdogs and Distributed Clocks; an ECAT side ([`Esc::forward`]) and a PDI side
//! ([`Esc::pdi_read`], [`Esc::pdi_write`], ...).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

extern crate alloc;
#[cfg(test)]
extern crate std;

pub mod config;
pub mod dc;
pub mod dispatch;
pub mod esc;
pub mod fmmu;
pub mod regs;
pub mod sii;
pub mod sm;

pub use config::{DcSupport, EscConfig};
pub use dispatch::FrameDispatch;
pub use esc::{Esc, EscEvents, Forward, PdiError};

#[cfg(test)]
mod proptests;
#[cfg(test)]
mod tests;
