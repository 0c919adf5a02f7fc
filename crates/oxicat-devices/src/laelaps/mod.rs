//! The Laelaps II leg node (Athiniotis 2018, chapter 3): one EtherCAT slave per leg that
//! generates an elliptic toe trajectory, solves the leg's inverse kinematics and runs two
//! PIV joint controllers (knee: brushed RE 50, hip: brushless EC 45) at 10 kHz. The
//! master only sends parameters and `State_Machine`.
//!
//! - [`device`]: Tables 3-1/3-2 process data (38/22 bytes), the left/right
//!   [`DeviceDef`](oxicat_slave::DeviceDef)s, and the only PDO ↔ SI scaling code;
//! - [`app`]: the [`Application`](oxicat_slave::Application) ([`LegNode`]) and the PWM
//!   hardware trait;
//! - [`trajectory`]: ellipse with flattening, trajectory clock;
//! - [`kinematics`]: FK/IK with the workspace check, **frames and left/right signs**;
//! - [`transition`]: linear transitions over `Transition_time`;
//! - [`piv`]: `DCL_runPID_C1`, its derivative filter, direction + duty;
//! - [`encoder`]: counts → joint angle, eQEP capture speed estimate (Table 3-4);
//! - [`hw`]: constants, among them **the gear-ratio choice** ([`hw::JOINT_RATIO_HIP`]).
//!
//! Everything inside is SI and `f32`; scaled integers exist only in [`device`].
//!
//! ```
//! use oxicat_devices::laelaps::{self, device, Joint, LegNode, PwmCommand, QepSample, Side};
//! use oxicat_slave::{Application, Od};
//!
//! struct Amp;
//! impl laelaps::PwmOut for Amp { fn set(&mut self, _: Joint, _: PwmCommand) {} }
//! struct Enc;
//! impl laelaps::EncoderIn for Enc { fn sample(&mut self, _: Joint) -> QepSample { QepSample::default() } }
//! struct NoLeds;
//! impl oxicat_devices::demo::Leds for NoLeds { fn set(&mut self, _: bool, _: bool) {} }
//!
//! let mut od = Od::<{ device::IMAGE }>::new(device::device(Side::Right)).unwrap();
//! let mut node = LegNode::new(Side::Right, Amp, Enc, NoLeds);
//! node.cycle(&mut od); // on SYNC0
//! node.timer(laelaps::JOINT_LOOP_TIMER, &mut od); // at 10 kHz
//! ```

pub mod app;
pub mod device;
pub mod encoder;
mod fmath;
pub mod hw;
pub mod kinematics;
pub mod piv;
pub mod trajectory;
pub mod transition;
// The std side of the kit (feature `bench`): the node on the virtual segment with its leg,
// the trot experiment and its results, scenario files and plots.
#[cfg(feature = "bench")]
pub mod experiment;
#[cfg(feature = "bench")]
pub mod frame;
#[cfg(feature = "bench")]
pub mod legs;
#[cfg(feature = "bench")]
pub mod plot;
#[cfg(feature = "bench")]
pub mod results;
#[cfg(feature = "bench")]
pub mod rig;
#[cfg(feature = "bench")]
pub mod robot;
#[cfg(feature = "bench")]
pub mod scenario;
#[cfg(feature = "bench")]
pub mod sweep;
#[cfg(feature = "bench")]
pub mod timing_probe;

pub use app::{LegNode, Mode, PwmOut};
pub use encoder::{CaptureConfig, EncoderIn, QepSample};
pub use hw::{Joint, JOINT_LOOP_TIMER};
pub use kinematics::{LegAngles, Side};
pub use piv::{ControlLaw, Gains, PwmCommand};
pub use trajectory::Ellipse;

#[cfg(test)]
mod tests;
