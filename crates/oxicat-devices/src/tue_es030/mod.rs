//! The TUeES030 motor I/O board (TU Eindhoven, manual CST 2016.141): an EtherCAT node
//! (ET1200 + a soft core in a Spartan-6) that drives three brushed DC motors with local
//! 20 kHz current loops (M1 6 A on a parallel-mode DRV8412, M2/M3 3 A each) and serves
//! encoders, ADCs, two DAC outputs and digital I/O to a 1 kHz master.
//!
//! - [`device`]: process data of the normal and FRF modes, motor parameters, the internal
//!   voltages 0x8040, FoE (`firmware.bin` in BOOT), [`device::DEF`];
//! - [`control`]: `currentPI`, `encoder_calculations`, `param2int`, fixed-point helpers and
//!   the board constants;
//! - [`ring`]: the FRF ring buffers;
//! - `experiment` and `ident` (feature `bench`): the master side — mode switch, FRF
//!   streaming, the manual's time-domain experiments, hard braking against the
//!   over-voltage kill, and identification (chirp, noise,
//!   setpoint files, Welch with coherence, the plant model);
//! - [`app`]: the [`Application`](oxicat_slave::Application) ([`TuEs030`]) and the hardware
//!   traits ([`Board`]).
//!
//! Events: the 20 kHz current loop is timer [`CURRENT_TIMER`] (`i_handler_pwm`), the 1 kHz
//! service routine timer [`SERVICE_TIMER`] (`i_handler_ec`); the process data run on every
//! RxPDO (SM-synchronous, as the firmware's `ESCvar.ALevent & SM2` test). The watchdog is
//! the ESC's SM watchdog: the stack calls `safe_outputs` (motors braked) and drops to
//! SAFEOP with error 0x001B (SOES `ALERR_WATCHDOG`).
//!
//! ```
//! use oxicat_devices::tue_es030::{self, device, TuEs030};
//! use oxicat_slave::{Application, Od};
//!
//! struct Hw;
//! impl tue_es030::Bridges for Hw { fn set_bridge(&mut self, _: usize, _: u16, _: u16, _: bool) {} }
//! impl tue_es030::Adcs for Hw {
//!     fn adc1(&mut self, _: usize) -> u16 { 0 }
//!     fn adc2(&mut self, ch: usize) -> u16 { if ch == 2 { 2708 } else { 2168 } }
//! }
//! impl tue_es030::Encoders for Hw { fn latch(&mut self, _: usize) -> (u32, u32) { (0, 0) } }
//! impl tue_es030::Io for Hw {
//!     fn digin(&mut self) -> u8 { 0 }
//!     fn digout(&mut self, _: u8) {}
//!     fn dac(&mut self, _: usize, _: u16) {}
//!     fn calipers(&mut self) -> [u16; 2] { [0; 2] }
//! }
//! let mut od = Od::<{ device::IMAGE }>::new(&device::DEF).unwrap();
//! let mut fw = TuEs030::new(Hw);
//! fw.timer(tue_es030::SERVICE_TIMER, &mut od);
//! fw.timer(tue_es030::CURRENT_TIMER, &mut od);
//! assert_eq!(fw.linevoltage, 2401); // 24 V in 10 mV, through the ADC
//! ```

pub mod app;
pub mod control;
pub mod device;
// The std side (feature `bench`): the board on the virtual segment with its motors, and the
// master-side experiments.
#[cfg(feature = "bench")]
pub mod experiment;
#[cfg(feature = "bench")]
pub mod ident;
#[cfg(feature = "bench")]
pub mod rig;
pub mod ring;

pub use app::{
    Adcs, Board, Bridges, Encoders, FwLock, Hooks, Io, Mode, TuEs030, CURRENT_TIMER, MCOM_ENABLE,
    MCOM_FRF_ENABLE, MCOM_FRF_TRISTATE, MCOM_TRISTATE, SERVICE_TIMER,
};
pub use control::{BoardRev, Motor, MotorParams};

/// Name of the firmware file the board takes over FoE in BOOT.
pub const FIRMWARE_FILE: &str = "firmware.bin";
/// Payload of the factory image the board ships with (the host rig's
/// `demo::rig::ram_files` builds the same from [`device::DEF`]'s `sw_version`).
pub const FACTORY_PAYLOAD: &str = concat!("oxicat tue-es030 firmware ", env!("CARGO_PKG_VERSION"));

/// The board's FoE update flow (`oxicat_slave::foe::FirmwareUpdate`) settings: images for
/// [`device::IDENTITY`], [`FIRMWARE_FILE`], no password, read back in BOOT — the host
/// rig's and the board image's.
pub const UPDATE: oxicat_slave::foe::UpdateConfig = oxicat_slave::foe::UpdateConfig {
    identity: device::IDENTITY,
    file_name: FIRMWARE_FILE,
    password: 0,
    read_back: true,
};

#[cfg(test)]
mod tests;
