//! Physics of one Laelaps II leg on the treadmill: current-controlled amplifier, motor,
//! gearhead, slipping coupler, pulley, motor encoder, planar two-link leg with gravity, and
//! foot contact with a moving belt. Deterministic fixed-step integration in `f64`.
//!
//! # Conventions (the one place)
//!
//! * Leg frame (thesis §3.2): origin at the hip axis, **x positive to the right (the direction
//!   of travel), y positive downward**; gravity acts along +y.
//! * Joint angles (thesis eq. 3-1): θ1 = hip = absolute angle of the thigh, θ2 = knee =
//!   **absolute** angle of the shank (virtual lower link), both measured from the downward
//!   vertical, positive towards +x: toe = (l1 sin θ1 + l2 sin θ2, l1 cos θ1 + l2 cos θ2).
//!   Both motors sit on the body; the knee motor drives the shank's absolute angle through the
//!   leg's linkage, so each motor acts directly on its own generalised coordinate.
//! * Left and right legs are mirror images: the dynamics are identical in the leg frame; the
//!   motors are mounted mirrored, so for a right leg positive current and positive encoder
//!   counts mean a *negative* thesis angle ([`Side::sign`]). This matches the firmware's
//!   `RIGHT_LEG` negation (`Desired_hip = −θ1/(2π)`) and the Matlab post-processing.
//! * Amplifier direction pin: `dir = false` → positive current (firmware: DIR = 0 when u ≥ 0).
//! * Encoder counts are zero at the reset pose (the thesis' Reset button), default θ = (0, 0):
//!   the leg hanging straight down, where the firmware's angle 0 must be.
//! * Treadmill: the belt's top surface lies at y = [`Treadmill::height`] below the hip (the
//!   support rig holds the hip axis fixed, or [`body`] moves it); the surface moves with
//!   velocity −[`Treadmill::speed`] along x (backwards, so a leg walking toward +x is carried
//!   back).
//! * Joint index 0 = hip, 1 = knee ([`Joint`]).

#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod bldc_joint;
pub mod body;
pub mod encoder;
pub mod gear;
pub mod motor;
pub mod onewire;
pub mod re30;
pub mod thermal;
pub mod ws2812;

mod leg;

pub use body::{Body, BodyParams, BodyStats, HipMotion, BODY_LEGS};
pub use encoder::{Encoder, UnitCapture, COUNTS_PER_REV};
pub use leg::{
    ContactParams, DriveParams, Joint, Leg, LegParams, LinkParams, Side, Treadmill, GRAVITY,
    SUBSTEP,
};
pub use motor::{AmplifierParams, MotorParams};
