//! `oxicat-sim`: the virtual EtherCAT segment.
//!
//! Chains of software ESCs in a topology, a virtual clock in nanoseconds, lockstep frame
//! exchange, pcapng capture and fault hooks, and transports that let a master drive it: in
//! the same process through [`oxicat_wire::pipe::FramePipe`] (which [`segment::Segment`]
//! implements; `oxicat-master` runs ethercrab over it), or a real master on an interface or
//! over UDP. No master and no device lives here: devices come as firmware hosted on the
//! segment's ESCs (their rigs live in the device kits of `oxicat-devices`).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod capture;
pub mod exec_time;
pub mod firmware;
pub mod model;
pub mod net;
pub mod node;
pub mod pcapng;
pub mod pdi_path;
pub mod realtime;
pub mod rt;
mod sched;
pub mod segment;
