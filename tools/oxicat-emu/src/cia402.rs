//! The CiA402 joint on the pins of its board image (`firmware/cia402-joint`): the host
//! rig's plant ([`oxicat_plant::bldc_joint::BldcJoint`]) as a [`BoardPlant`].
//!
//! | image side | pins / registers | plant side |
//! |---|---|---|
//! | three-phase bridge | TIM1 CH1 (PA8), CH2 (PA9), CH3N alone (PB15) duties; enable PC11 | phase voltages `V_bus · (d_x − ½)` → Clarke/Park at the rotor's electrical angle → the q-axis voltage of `BldcJoint::set_voltage` (bridge off: coasting) |
//! | encoder A/B | TIM2 in encoder mode ×4 (PA0/PA1) | motor encoder count (`counts_per_rev` per turn) |
//! | encoder index Z | TIM2 CH3 input capture (PB10) | the index pulse once per motor turn |
//! | phase currents | ADC1 IN10 (PC0), IN11 (PC1) | `i_a`, `i_b` of the q-axis current at the rotor angle: `VREF/2 + G·R·i` (20 V/V, 2 mΩ) |
//! | joint torque | ADC1 IN12 (PC2) | gear torque: `1.65 V + τ · 1.65/100 V/N·m` |
//! | bus voltage | ADC1 IN13 (PC3) | 48 V / 21 |
//! | home switch | PC10, active low | `BldcJoint::home_switch` |
//!
//! The scaling is the image's (its README, "ADC scheme and scaling"). The motor's rotor
//! starts at electrical angle 0 with the encoder at 0, so the image's start-up alignment
//! (a d-axis voltage on phase a's axis) holds it where it is. The plant is the q-axis
//! model the host rig uses: the d-axis voltage the modulation may carry makes no current.
//!
//! Every plant period (25 µs: two per PWM period) the adapter reads the outputs, advances
//! the joint and schedules, at the period's end, the encoder count, the analogue inputs and
//! the home switch; an index crossing is scheduled at its interpolated time, with the
//! count it latches. ADC1 samples at its trigger what the last step set (a sample-and-hold
//! up to one plant period old).

use std::f64::consts::TAU;
use std::sync::{Arc, Mutex};

use oxicat_plant::bldc_joint::{BldcJoint, BldcJointParams};

use crate::plant::BoardPlant;
use crate::{Board, Stimulus};

/// The board's analogue front end (README of `firmware/cia402-joint`).
pub mod scaling {
    /// ADC reference \[V\].
    pub const VREF: f64 = 3.3;
    /// Shunt \[Ω\].
    pub const R_SHUNT: f64 = 0.002;
    /// Current-sense amplifier gain \[V/V\].
    pub const CSA_GAIN: f64 = 20.0;
    /// Bus divider (V_bus / V_pin).
    pub const VBUS_DIVIDER: f64 = 21.0;
    /// Torque amplifier output at zero torque \[V\].
    pub const TORQUE_ZERO_V: f64 = 1.65;
    /// Torque per volt \[N·m/V\].
    pub const TORQUE_NM_PER_V: f64 = 100.0 / 1.65;
}

/// ADC channels and pins of the board.
pub mod pins {
    /// Phase a current: IN10 (PC0).
    pub const IA: u8 = 10;
    /// Phase b current: IN11 (PC1).
    pub const IB: u8 = 11;
    /// Joint torque: IN12 (PC2).
    pub const TORQUE: u8 = 12;
    /// Bus voltage: IN13 (PC3).
    pub const VBUS: u8 = 13;
    /// Bridge enable PC11 (output, active high).
    pub const ENABLE: (char, u8) = ('C', 11);
    /// Home switch PC10 (input, active low).
    pub const HOME: (char, u8) = ('C', 10);
    /// PWM timer.
    pub const PWM_TIM: u8 = 1;
    /// Encoder timer.
    pub const ENC_TIM: u8 = 2;
    /// Index capture input of the encoder timer (TI3).
    pub const INDEX_INPUT: u8 = 3;
}

/// What the joint does, for tests and tools ([`JointBoardPlant::observer`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointState {
    /// Plant steps so far.
    pub steps: u64,
    /// Steps with the bridge enabled.
    pub powered_steps: u64,
    /// Motor angle \[rad\].
    pub motor_angle: f64,
    /// Link (joint) angle \[rad\].
    pub link_angle: f64,
    /// q-axis current \[A\].
    pub current: f64,
    /// q-axis voltage applied \[V\].
    pub v_q: f64,
    /// Encoder count.
    pub count: i64,
    /// Index pulses injected.
    pub index_pulses: u64,
}

/// The joint on the board's pins (module docs).
pub struct JointBoardPlant {
    joint: BldcJoint,
    pole_pairs: f64,
    bus_voltage: f64,
    period_ns: u64,
    count: i64,
    state: Arc<Mutex<JointState>>,
}

impl JointBoardPlant {
    /// The joint with `params` (the rig's default: `BldcJointParams::default()`), the
    /// image's motor (4 pole pairs, `DriveParams::default()`) and a 48 V bus.
    pub fn new(params: BldcJointParams) -> Self {
        let drive = oxicat_devices::cia402::DriveParams::default();
        JointBoardPlant {
            joint: BldcJoint::new(params),
            pole_pairs: f64::from(drive.pole_pairs),
            bus_voltage: f64::from(drive.bus_voltage),
            period_ns: 25_000,
            count: 0,
            state: Arc::default(),
        }
    }

    /// A shared view of the joint, updated every plant step.
    pub fn observer(&self) -> Arc<Mutex<JointState>> {
        self.state.clone()
    }

    /// The joint model.
    pub fn joint(&self) -> &BldcJoint {
        &self.joint
    }

    /// The analogue inputs for the joint's present state.
    fn analog(&self, board: &mut Board, at_ns: u64) {
        use scaling::*;
        let theta = self.pole_pairs * self.joint.motor_angle;
        let (s, c) = theta.sin_cos();
        let iq = self.joint.current;
        let (ialpha, ibeta) = (-iq * s, iq * c);
        let ia = ialpha;
        let ib = -0.5 * ialpha + 0.5 * 3f64.sqrt() * ibeta;
        let csa = |i: f64| VREF / 2.0 + CSA_GAIN * R_SHUNT * i;
        let torque = TORQUE_ZERO_V + self.joint.gear_torque() / TORQUE_NM_PER_V;
        for (channel, volts) in [
            (pins::IA, csa(ia)),
            (pins::IB, csa(ib)),
            (pins::TORQUE, torque),
            (pins::VBUS, self.bus_voltage / VBUS_DIVIDER),
        ] {
            board.schedule(at_ns, Stimulus::Analog { channel, volts });
        }
    }

    /// The q-axis voltage the bridge applies, `None` when it is off.
    fn v_q(&self, board: &Board) -> Option<f64> {
        if !board.output(pins::ENABLE.0, pins::ENABLE.1) {
            return None;
        }
        let mut d = [0.0; 3];
        for (k, x) in d.iter_mut().enumerate() {
            let v = board.pwm_duty(pins::PWM_TIM, k as u8 + 1)?;
            *x = if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            };
        }
        let v = d.map(|x| self.bus_voltage * (x - 0.5));
        // Amplitude-invariant Clarke, Park at the rotor's electrical angle.
        let alpha = (2.0 * v[0] - v[1] - v[2]) / 3.0;
        let beta = (v[1] - v[2]) / 3f64.sqrt();
        let (s, c) = (self.pole_pairs * self.joint.motor_angle).sin_cos();
        Some(-alpha * s + beta * c)
    }
}

impl BoardPlant for JointBoardPlant {
    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn step(&mut self, board: &mut Board, t_ns: u64) {
        if t_ns == 0 {
            // The sensors before the first step.
            self.analog(board, 0);
            board.schedule(
                0,
                Stimulus::Input {
                    port: pins::HOME.0,
                    pin: pins::HOME.1,
                    level: !self.joint.home_switch(),
                },
            );
        }
        let vq = self.v_q(board);
        self.joint.set_voltage(vq.is_some(), vq.unwrap_or(0.0));
        let a0 = self.joint.motor_angle;
        let h = self.period_ns as f64 * 1e-9;
        self.joint.step(h);
        let a1 = self.joint.motor_angle;
        let end = t_ns + self.period_ns;
        let mut pulses = 0;
        if let Some(latched) = self.joint.take_index_latch() {
            // The index at its interpolated time, with the count it latches.
            let p = self.joint.params;
            let turns = ((a0.max(a1) - p.index_angle) / TAU).floor();
            let at_angle = p.index_angle + turns * TAU;
            let frac = if a1 != a0 {
                ((at_angle - a0) / (a1 - a0)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let at = t_ns + (frac * self.period_ns as f64).round() as u64;
            board.schedule(
                at,
                Stimulus::Encoder {
                    tim: pins::ENC_TIM,
                    edges: i64::from(latched),
                },
            );
            board.schedule(
                at,
                Stimulus::Capture {
                    tim: pins::ENC_TIM,
                    input: pins::INDEX_INPUT,
                },
            );
            pulses = 1;
        }
        let c1 = self.joint.motor_counts().floor() as i64;
        board.schedule(
            end,
            Stimulus::Encoder {
                tim: pins::ENC_TIM,
                edges: c1,
            },
        );
        self.count = c1;
        self.analog(board, end);
        board.schedule(
            end,
            Stimulus::Input {
                port: pins::HOME.0,
                pin: pins::HOME.1,
                level: !self.joint.home_switch(),
            },
        );
        if let Ok(mut s) = self.state.lock() {
            s.steps += 1;
            s.powered_steps += u64::from(vq.is_some());
            s.motor_angle = self.joint.motor_angle;
            s.link_angle = self.joint.link_angle;
            s.current = self.joint.current;
            s.v_q = vq.unwrap_or(0.0);
            s.count = self.count;
            s.index_pulses += pulses;
        }
    }
}
