//! `oxicat-slave`: a `no_std`, allocation-free EtherCAT slave stack.
//!
//! The firmware sees the ESC only through [`Pdi`]. A device is one static
//! [`DeviceDef`]; the stack derives from it the object dictionary ([`Od`]), the PDO
//! layout and the checks of the EtherCAT state machine. The application owns a
//! [`Slave`] and delivers events to it: [`Slave::poll`] from the main loop (ESM,
//! mailbox, free-run process data), [`Slave::on_pdi_irq`], [`Slave::on_sync0`],
//! [`Slave::on_sync1`] and [`Slave::on_timer`] from interrupts or the simulator.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod coe;
pub mod device;
pub mod esm;
pub mod foe;
pub mod od;
pub mod pdi;
pub mod pdo;
pub mod slave;

pub use device::{pdo_bytes, DeviceDef, Identity, MailboxDef, PdoDef, PdoEntry, SyncDef, SyncMode};
pub use esm::{AlState, AlStatusCode};
pub use od::{
    find_entry, image_size, Access, CheckedDef, DataType, DefError, DefaultValue, EntryDef,
    EntryRef, Limits, ObjectCode, ObjectDef, Od, OdError, OdType, PdoMapping, Scale, Var,
};
pub use pdi::{IrqLines, Pdi};
pub use slave::{Application, InitError, Slave, SlaveSlot, Stats};
