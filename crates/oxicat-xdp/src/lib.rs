//! `oxicat-xdp`: AF_XDP sockets for oxicat's served segment, and the XDP program that steers
//! EtherCAT frames (EtherType 0x88A4, also 802.1Q-tagged) to them while every other frame
//! goes on to the kernel's stack.
//!
//! [`XdpSocket::open`] builds the whole path on one interface queue: a UMEM of 2 KiB frames,
//! its fill and completion rings, the socket's RX and TX rings (mapped at the kernel's
//! `XDP_MMAP_OFFSETS`), the bind (copy mode unless zero-copy is asked), an XSKMAP holding the
//! socket at its queue, the program ([`insn::ethercat_redirect`], assembled by hand) and its
//! attachment as a BPF link. Dropping the socket closes the link, which detaches the program;
//! so does the process ending, however it ends.
//!
//! All `unsafe` code of oxicat's AF_XDP path is in the private `sys` module; the rest of the
//! crate (and `oxicat-sim`, which keeps `forbid(unsafe_code)`) is safe code. Linux only: on
//! other systems the crate is empty.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod insn;
#[cfg(target_os = "linux")]
mod sys;
#[cfg(target_os = "linux")]
mod xsk;

#[cfg(target_os = "linux")]
pub use xsk::{Config, Mode, Step, XdpError, XdpSocket};
