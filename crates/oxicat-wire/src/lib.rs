//! `oxicat-wire`: EtherCAT byte formats as zero-copy views and builders.
//!
//! This crate knows how EtherCAT bytes are laid out and nothing about what they do:
//! Ethernet II (EtherType 0x88A4, an 802.1Q tag tolerated), EtherCAT over UDP, the
//! EtherCAT frame header, datagrams with all 15 commands, the mailbox header and the
//! CoE/FoE/EoE/SoE headers, and the SII EEPROM layout. Every parser returns a
//! [`WireError`] for malformed input; nothing here panics on bytes that came from the wire.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod coe;
pub mod crc;
pub mod datagram;
pub mod datatype;
pub mod eoe;
pub mod error;
pub mod ethernet;
pub mod foe;
pub mod frame;
pub mod mailbox;
pub mod pipe;
pub mod regs;
pub mod sii;
pub mod soe;
pub mod udp;
pub mod view;

pub use datagram::{Command, DatagramHeader, DatagramMut, DatagramRef};
pub use error::WireError;
pub use ethernet::{EthernetHeader, ETHERCAT_ETHERTYPE, VLAN_ETHERTYPE};
pub use frame::{EcatFrame, EcatHeader, FrameBuilder, FrameType};
pub use mailbox::{MailboxHeader, MailboxRef, MailboxType};
pub use udp::{EcatUdpFrame, UdpEndpoints, ETHERCAT_UDP_PORT};
