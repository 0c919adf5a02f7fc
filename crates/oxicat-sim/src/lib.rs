//! `oxicat-sim`: the virtual EtherCAT segment.
//!
//! Chains of software ESCs in a topology, a virtual clock in nanoseconds, lockstep frame
//! exchange, pcapng capture and fault hooks, and transports that let a master (ethercrab
//! in the same process, or a real master on an interface) drive it.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod axis_hub;
pub mod capture;
pub mod cia402;
pub mod exec_time;
pub mod firmware;
pub mod laelaps;
pub mod model;
pub mod net;
pub mod node;
pub mod pcapng;
pub mod pdi_path;
pub mod realtime;
pub mod segment;
pub mod timing_probe;
pub mod transport;
pub mod tue_es030;
