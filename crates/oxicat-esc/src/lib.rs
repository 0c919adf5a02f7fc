//! `oxicat-esc`: a software EtherCAT Slave Controller.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

extern crate alloc;

pub mod dc;
