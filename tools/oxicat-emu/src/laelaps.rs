//! The Laelaps II leg on the pins of the leg-node board image (`firmware/laelaps-leg`):
//! the host rig's plant ([`oxicat_plant::Leg`], configured by the rig's [`RigConfig`]) as
//! a [`BoardPlant`].
//!
//! | image side | pins / registers | plant side |
//! |---|---|---|
//! | knee amplifier | TIM1 CH1 duty (PA8), DIR PC10 | `Leg::set_duty(Knee, duty, dir)` |
//! | hip amplifier | TIM1 CH2 duty (PA9), DIR PC11 | `Leg::set_duty(Hip, duty, dir)` |
//! | knee encoder | TIM2 in encoder mode (PA0/PA1); CH1 captures on rising A | knee motor shaft, 2000 counts/rev |
//! | hip encoder | TIM3 in encoder mode (PC6/PC7); CH1 captures on rising A | hip motor shaft |
//!
//! Every plant period (the rig's `plant_period_ns`, 50 µs by default) the adapter reads
//! both duties (0 when a channel is not an enabled PWM output or MOE is off: the
//! amplifier inputs' pull-downs) and direction pins, advances the leg one substep with
//! them, and schedules every quadrature edge the motor shafts cross in that substep at its
//! time, interpolated within the substep exactly as the plant's own encoder places it:
//! the encoder timer's count follows edge by edge, and on each rising edge of A (one per
//! four counts: count 4k → 4k+1 forwards, 4k+3 → 4k+2 backwards) its TI1 captures — its
//! CH1 latches the count and, as the image sets CR2.MMS = compare pulse, its TRGO makes the
//! linked capture timer (TIM5 for TIM2, TIM4 for TIM3, by their SMCR.TS) latch its time.
//! That link is modelled in the timer model (`timers`), not here.
//!
//! **The support rig.** As in `oxicat_devices::laelaps::rig`, the leg is held at its reset
//! pose (not integrated) until its node goes Operational. The rig sees the application's
//! mode; an emulated board shows only its pins, so the adapter releases the leg at the
//! first plant step where the image drives an amplifier (a non-zero duty on either
//! channel) — in the Configuration state the leg node keeps both duties at zero, in the
//! Operational state the PIV drives them. Before that the leg rests with both encoders at
//! zero, which is what the image zeroed them at.

use std::f64::consts::TAU;
use std::sync::{Arc, Mutex};

use oxicat_devices::laelaps::rig::{LegId, RigConfig};
use oxicat_plant::{Joint, Leg, COUNTS_PER_REV};

use crate::plant::BoardPlant;
use crate::{Board, Stimulus};

/// The board's amplifier and encoder wiring (README of `firmware/laelaps-leg`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LegPins {
    /// PWM timer (TIM1) and its channels (knee, hip).
    pub pwm_timer: u8,
    /// PWM channel of the knee amplifier.
    pub knee_pwm_ch: u8,
    /// PWM channel of the hip amplifier.
    pub hip_pwm_ch: u8,
    /// Knee direction pin (port, pin).
    pub knee_dir: (char, u8),
    /// Hip direction pin.
    pub hip_dir: (char, u8),
    /// Knee encoder timer.
    pub knee_encoder: u8,
    /// Hip encoder timer.
    pub hip_encoder: u8,
}

impl LegPins {
    /// The leg-node board: TIM1 CH1/CH2, DIR PC10/PC11, encoders TIM2 (knee) and TIM3 (hip).
    pub const BOARD: LegPins = LegPins {
        pwm_timer: 1,
        knee_pwm_ch: 1,
        hip_pwm_ch: 2,
        knee_dir: ('C', 10),
        hip_dir: ('C', 11),
        knee_encoder: 2,
        hip_encoder: 3,
    };
}

/// What the leg does, for tests and tools ([`LegBoardPlant::observer`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LegState {
    /// Board time of the release \[ns\] (`None`: still held).
    pub released_at_ns: Option<u64>,
    /// Plant steps integrated since the release.
    pub steps: u64,
    /// Joint angles (hip θ1, knee θ2) \[rad\], thesis convention.
    pub joint_angles: [f64; 2],
    /// Motor shaft speeds as the encoders see them (hip, knee) \[rad/s\].
    pub motor_speeds: [f64; 2],
    /// Encoder counts (hip, knee) relative to the reset pose.
    pub counts: [i64; 2],
    /// Rising A edges (unit events) injected (hip, knee).
    pub unit_events: [u64; 2],
    /// Last duty and direction the amplifiers took (hip, knee).
    pub duty: [(f64, bool); 2],
}

/// The Laelaps II leg as a plant on the leg-node board's pins (module docs).
pub struct LegBoardPlant {
    leg: Leg,
    config: RigConfig,
    pins: LegPins,
    period_ns: u64,
    /// Motor angles at the reset pose: the encoders' zero (hip, knee).
    zero: [f64; 2],
    count: [i64; 2],
    released_at: Option<u64>,
    state: Arc<Mutex<LegState>>,
}

impl LegBoardPlant {
    /// The leg `leg` with the rig's configuration `config` (its plant, substep, belt
    /// profile; [`RigConfig::laelaps`] is the host rig's default) on the board's pins.
    pub fn new(leg: LegId, config: RigConfig) -> Self {
        let period_ns = config.plant_period_ns.clamp(1_000, 100_000);
        let mut params = config.leg;
        params.substep = period_ns as f64 * 1e-9;
        debug_assert_eq!(params.side, leg.plant_side());
        let leg = Leg::new(params);
        let m = leg.motor_angles();
        LegBoardPlant {
            leg,
            config,
            pins: LegPins::BOARD,
            period_ns,
            zero: m,
            count: [0; 2],
            released_at: None,
            state: Arc::default(),
        }
    }

    /// A shared view of the leg, updated every plant step.
    pub fn observer(&self) -> Arc<Mutex<LegState>> {
        self.state.clone()
    }

    /// The leg model.
    pub fn leg(&self) -> &Leg {
        &self.leg
    }

    fn duty(&self, board: &Board, ch: u8, dir: (char, u8)) -> (f64, bool) {
        let d = board.pwm_duty(self.pins.pwm_timer, ch).unwrap_or(0.0);
        let d = if d.is_finite() {
            d.clamp(0.0, 1.0)
        } else {
            0.0
        };
        (d, board.output(dir.0, dir.1))
    }

    /// Schedules the edges of joint `j` (0 hip, 1 knee) from count `c0` to `c1` while the
    /// shaft moved from `a0` to `a1` during `[t0, t0 + h]` ns.
    fn edges(&mut self, board: &mut Board, j: usize, a: (f64, f64), c1: i64, t0: u64, h: u64) {
        let tim = if j == 0 {
            self.pins.hip_encoder
        } else {
            self.pins.knee_encoder
        };
        let c0 = self.count[j];
        if c1 == c0 {
            return;
        }
        let k = COUNTS_PER_REV / TAU;
        let up = c1 > c0;
        let da = a.1 - a.0;
        // Bounded by the shaft's travel in one substep; a runaway plant is cut short
        // rather than flooding the queue (the count still lands on c1).
        let n = (c1 - c0).unsigned_abs().min(10_000);
        for e in 1..=n {
            let c = if up { c0 + e as i64 } else { c0 - e as i64 };
            let edge = self.zero[j] + (c as f64 + if up { -0.5 } else { 0.5 }) / k;
            let frac = if da != 0.0 {
                ((edge - a.0) / da).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let at = t0 + (frac * h as f64).round() as u64;
            board.schedule(at, Stimulus::Encoder { tim, edges: c });
            let rising_a = if up {
                c.rem_euclid(4) == 1
            } else {
                c.rem_euclid(4) == 2
            };
            if rising_a {
                board.schedule(at, Stimulus::Capture { tim, input: 1 });
                if let Ok(mut s) = self.state.lock() {
                    s.unit_events[j] += 1;
                }
            }
        }
        if n < (c1 - c0).unsigned_abs() {
            board.schedule(t0 + h, Stimulus::Encoder { tim, edges: c1 });
        }
        self.count[j] = c1;
    }
}

impl BoardPlant for LegBoardPlant {
    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn step(&mut self, board: &mut Board, t_ns: u64) {
        let knee = self.duty(board, self.pins.knee_pwm_ch, self.pins.knee_dir);
        let hip = self.duty(board, self.pins.hip_pwm_ch, self.pins.hip_dir);
        if self.released_at.is_none() && (knee.0 > 0.0 || hip.0 > 0.0) {
            self.released_at = Some(t_ns);
        }
        let Some(t0) = self.released_at else {
            return;
        };
        let since = (t_ns - t0) as f64 * 1e-9;
        let belt = self.config.belt.at(since);
        if belt != self.leg.params().treadmill.speed {
            self.leg.set_belt_speed(belt);
        }
        self.leg.set_duty(Joint::Hip, hip.0, hip.1);
        self.leg.set_duty(Joint::Knee, knee.0, knee.1);
        let a0 = self.leg.motor_angles();
        self.leg.advance(self.period_ns as f64 * 1e-9);
        let a1 = self.leg.motor_angles();
        let counts = self.leg.encoder_counts();
        for j in 0..2 {
            // The plant's count is a wrapping i32; follow it as a difference.
            let d = counts[j].wrapping_sub(self.count[j] as i32);
            let c1 = self.count[j] + i64::from(d);
            self.edges(board, j, (a0[j], a1[j]), c1, t_ns, self.period_ns);
        }
        if let Ok(mut s) = self.state.lock() {
            s.released_at_ns = self.released_at;
            s.steps += 1;
            s.joint_angles = self.leg.joint_angles();
            s.motor_speeds = self.leg.motor_speeds();
            s.counts = self.count;
            s.duty = [hip, knee];
        }
    }
}
