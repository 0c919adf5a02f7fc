//! A CiA402 (IEC 61800-7-201/-301, ETG.6010) modular joint drive: the drive profile the
//! Shenyang joint controller (Liu et al., "EtherCAT Based Robot Modular Joint Controller")
//! describes only as 0x6040/0x6041, done completely.
//!
//! - [`fsm`]: the state machine (transitions 0–16, command masks, statusword decoding,
//!   option codes 0x605A–0x605E);
//! - [`device`]: the object dictionary, 0x1000 = 0x00020192, default and configurable PDOs;
//! - [`drive`]: modes PP/PV/PT/HM/IP/CSP/CSV/CST, the abort connection option code 0x6007
//!   and the cascaded loops on [`JointHw`] (velocity and position each DC cycle) and
//!   [`PowerStage`] (the [`CurrentLoop`] at 20 kHz: on a local timer in the drive on the
//!   host, in the ADC interrupt on the board, command and feedback handed over).
//!
//! The joint torque sensor is reported in manufacturer object 0x2002 (mN·m).

pub mod device;
pub mod drive;
pub mod fsm;
// The std side (feature `bench`): the master-side drive helper and the joint on the virtual
// segment with its BLDC plant.
#[cfg(feature = "bench")]
pub mod master;
#[cfg(feature = "bench")]
pub mod rig;
/// The paper's 1 ms task-period experiment on the virtual segment (feature `bench`).
#[cfg(feature = "bench")]
pub mod task_period;

#[cfg(test)]
mod tests;

pub use device::DEF;
pub use drive::{
    error, mode, Cia402Drive, CurrentCommand, CurrentFeedback, CurrentLoop, DriveParams, JointHw,
    NoPowerStage, PowerStage, CURRENT_LOOP_HZ, CURRENT_LOOP_TIMER,
};
pub use fsm::{Command, Events, Fsm, Options, Ramp, State};
