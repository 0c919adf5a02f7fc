//! The axis communication hub (Reyes Andrade 2020, Han's Robot Germany): an EtherCAT node
//! that reads up to 15 DS18B20 temperature sensors on a 1-Wire bus, drives WS2812 LED rings
//! that show the system state, and reports status, events and errors to the master.
//!
//! - [`device`]: the process data (0x6000 Temperature, 0x6001 SystemStatus, 0x7000
//!   MasterCMDs, 0xF000 modular device profile) and the [`DeviceDef`](oxicat_slave::DeviceDef);
//! - [`codes`]: the report's event/error codes, hard vs soft errors, the status word
//!   (4-bit general state, 14-bit last error, 14-bit last event) and the event handler;
//! - [`onewire`]: the bit-level [`OneWireBus`] trait, ROM search, DS18B20 driver, the
//!   temperature task;
//! - [`ws2812`]: the PWM+DMA bit encoder, colours per state, the LED task;
//! - [`app`]: the application ([`HubApp`]) and the firmware main with the EtherCAT
//!   supervisor ([`HubFirmware`]).
//!
//! # Tasks
//!
//! The report's FreeRTOS threads become event-driven tasks, released by `on_timer(id)`
//! ([`TASKS`], in priority order; when several are due at the same instant the higher
//! priority runs first):
//!
//! | task | report thread | priority | period | does |
//! |---|---|---|---|---|
//! | [`TIMER_APP`] | SOES APP SDM | AboveNormal | 10 ms | `Slave::poll`: ESM, mailbox, free-run process data |
//! | event handler | Event Handler SDM | AboveNormal | event driven | after every task: drains the [`codes::EventQueue`] |
//! | [`TIMER_LED`] | LED SDM | Normal | 33 ms | colour from the state, encode, start DMA, DMA timeout |
//! | [`TIMER_SUPERVISOR`] | ECAT SDM (+ task manager) | Normal | 100 ms | DL status link, SM watchdog, output flow; PDI faults, stack restart |
//! | [`TIMER_TEMP`] | Temperature SDM | Normal | 1 s | read previous conversion (CRC-8), start the next; overheat |
//!
//! In SM-synchronous mode the process-data cycle also runs on the PDI interrupt
//! ([`HubFirmware::on_pdi_irq`]), in DC mode on SYNC0 ([`HubFirmware::on_sync0`]).
//!
//! # No hang when the ESC or the cable goes away
//!
//! SOES busy-waited on ESC registers, so a missing ESC or cable hung the node and the report
//! needed one-shot OS timers and a task manager that killed and re-created the SOES thread.
//! Here every ESC access goes through [`oxicat_slave::Pdi`], which returns an error instead
//! of waiting (the SPI driver has a timeout); nothing loops on a register. The supervisor
//! takes the stack down after [`PDI_FAULT_LIMIT`] failed accesses in a row
//! (`ERR_ECAT_TIMEOUT`) and re-creates it every [`app::RESTART_MS`] until the ESC answers
//! (`EV_ECAT_ESC_INIT`, `EV_SOES_RESPAWNED`); the other tasks keep running meanwhile.
//! Communication loss (port 0 link down in DL status 0x0110, the SM watchdog expiring, or no
//! new outputs in OP for [`app::QUIET_LIMIT_MS`]) is `ERR_ECAT_COMM_LOST` (hard: red LEDs);
//! when the master comes back and the node is in OP with outputs flowing again,
//! `EV_ECAT_APP_OP` clears it, as the report's event handler does.
//!
//! # No data race between the temperature task and the process data
//!
//! The report's temperature thread wrote `gv_temperatureData[15]` while the SOES thread read
//! it, unprotected (a reader could publish half of one read-out and half of the next). Here:
//!
//! 1. the temperature task owns its working state ([`onewire::TempTask`]) and builds a
//!    complete [`onewire::TempFrame`] (15 values + sequence number) on its own stack;
//! 2. it hands the frame over **by value** into a one-element mailbox (`temp_slot:
//!    Option<TempFrame>`), replacing an unread older one as a whole;
//! 3. the application task is the only reader: it `take()`s the frame in one place
//!    ([`HubApp`]'s `cycle`) and copies it into the object dictionary, which only it writes.
//!
//! Both tasks are `&mut self` methods of the one [`HubApp`], so the borrow checker proves
//! they never run on the data at the same time; there is no `static mut` (the crate forbids
//! `unsafe`), so an unprotected shared buffer cannot even be written. On a preemptive RTOS
//! the same split becomes a single-producer/single-consumer queue whose producer and
//! consumer halves are moved into the two tasks (e.g. `heapless::spsc`), or the frame is
//! swapped in a critical section — the types do not allow anything else.
//!
//! # Events are never lost silently
//!
//! CMSIS event flags lost codes (only 24 bits; codes OR-ed without shifting; a second code
//! before the handler ran overwrote the first). Codes here go through a bounded FIFO that the
//! handler drains after every task; a full queue is counted and raises `ERR_SYS_UNKNOWN`.

pub mod app;
pub mod codes;
pub mod device;
pub mod onewire;
/// The hub on the virtual segment with its plant (feature `bench`).
#[cfg(feature = "bench")]
pub mod rig;
pub mod ws2812;

pub use app::{
    EcatPhase, HubApp, HubFirmware, HubSlave, HubSlot, Priority, Supervisor, Task, PDI_FAULT_LIMIT,
    TASKS, TIMER_APP, TIMER_LED, TIMER_SUPERVISOR, TIMER_TEMP,
};
pub use codes::{StatusWord, SystemState};
pub use onewire::{OneWireBus, Resolution, Rom, Slot, TempFrame, TempTask, Txn, TxnStatus};
pub use ws2812::{LedStrip, PwmTiming, Rgb, Shown};

#[cfg(test)]
mod tests;
