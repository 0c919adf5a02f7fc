//! Incremental encoders: joint angle from the eQEP position counter relative to the reset
//! pose, and the eQEP edge-capture ("low speed") speed estimate (thesis §3.7, Figure 3-17,
//! Table 3-4).
//!
//! Angle: `q = (QPOSCNT − pos_init) / (2000 · ratio)` revolutions at the joint (joint
//! frame, see [`super::kinematics`]), `ratio` from [`super::hw::JOINT_RATIO_HIP`].
//!
//! Speed: every unit position event (`2^UPPS` quadrature edges) latches the capture timer
//! (clocked at `SYSCLK / 2^CCPS`) into `QCPRD`, so `ω = SpeedScaler / QCPRD` with
//! `SpeedScaler = 2π · 2^UPPS · (SYSCLK / 2^CCPS) / 2000` rad/s of the motor. `QCPRD` is 16
//! bits, which fixes the measurable range (Table 3-4): at most `SpeedScaler / 1` =
//! 19634.95 rad/s, at least `SpeedScaler / 65535` = 0.2996 rad/s at the motor (÷ the joint
//! ratio: hip 248.06 … 0.0038, knee 200.36 … 0.0031 rad/s). The thesis only ever uses this
//! capture-based estimate (no switching to a count-per-unit-time estimate at high speed:
//! its speeds stay far below the maximum); so do we.
//!
//! Out of range, per the thesis text: faster than the maximum saturates at the maximum
//! (`QCPRD` cannot be below 1), slower than the minimum reads 0. For the slow side the
//! thesis code differs from its text: on capture overflow it uses `QCPRD = 0xFFFF`
//! (reading ±0.2996 rad/s), and with no unit event at all (standstill) it keeps the last
//! speed forever. We follow the text: capture overflow reads 0, and so does a joint with
//! no unit event for longer than the capture timer range (`65535 · 2^CCPS / SYSCLK`).
//! The sign follows `QDF` (0 = reverse = negative); a direction change (`CDEF`) reads 0.

use super::hw::{Joint, ENCODER_COUNTS_PER_REV};
use core::f32::consts::TAU;

/// One read of a joint's eQEP registers, as the 10 kHz loop sees it. Reading clears the
/// event flags (the firmware's write-1-to-clear).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct QepSample {
    /// Position counter `QPOSCNT` (free-running, wraps).
    pub position: u32,
    /// `QEPSTS.QDF`: true = forward (CW).
    pub forward: bool,
    /// `QEPSTS.UPEVNT`: a unit position event happened since the last read.
    pub unit_event: bool,
    /// `QEPSTS.COEF`: the capture timer overflowed.
    pub capture_overflow: bool,
    /// `QEPSTS.CDEF`: the direction changed between unit events.
    pub direction_change: bool,
    /// `QCPRD`: capture timer ticks between the last two unit position events.
    pub capture_period: u16,
}

/// The encoder inputs of a leg node (eQEP1 knee, eQEP2 hip).
pub trait EncoderIn {
    /// Reads (and clears the event flags of) one joint's eQEP.
    fn sample(&mut self, joint: Joint) -> QepSample;
}

/// Position relative to the reset pose (`pos_init` captured when Reset is pressed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct JointEncoder {
    init: u32,
}

impl JointEncoder {
    /// Zeroes the encoder at counter value `position` (the reset pose).
    pub const fn zeroed_at(position: u32) -> Self {
        Self { init: position }
    }

    /// Signed counts since the reset pose (wrap-safe).
    pub fn counts(&self, position: u32) -> i32 {
        position.wrapping_sub(self.init) as i32
    }

    /// Joint angle in revolutions (joint frame) for counter value `position`.
    pub fn joint_revs(&self, position: u32, joint: Joint) -> f32 {
        counts_to_joint_revs(self.counts(position), joint)
    }
}

/// Encoder counts since the reset pose → joint revolutions (2000 counts per motor turn,
/// divided by the joint's total ratio).
pub fn counts_to_joint_revs(counts: i32, joint: Joint) -> f32 {
    counts as f32 / (ENCODER_COUNTS_PER_REV * joint.ratio())
}

/// eQEP capture unit configuration (`QCAPCTL`) and clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureConfig {
    /// eQEP clock (SYSCLKOUT) \[Hz\].
    pub sysclk_hz: f32,
    /// `QCAPCTL.CCPS`: capture timer clock = SYSCLK / 2^CCPS.
    pub ccps: u8,
    /// `QCAPCTL.UPPS`: unit position event every 2^UPPS quadrature edges.
    pub upps: u8,
}

impl CaptureConfig {
    /// A configuration reproducing Table 3-4: 200 MHz F28379D SYSCLK, CCPS = 7 (÷128),
    /// UPPS = 2 (4 edges), giving SpeedScaler = 2π·3125 = 19634.95 rad/s. \[derived\] The
    /// thesis prints neither register; any pair with CCPS − UPPS = 5 gives its table.
    pub const THESIS: CaptureConfig = CaptureConfig {
        sysclk_hz: 200.0e6,
        ccps: 7,
        upps: 2,
    };

    /// Capture timer tick \[s\].
    pub fn tick_s(&self) -> f32 {
        (1u32 << self.ccps) as f32 / self.sysclk_hz
    }

    /// `SpeedScaler` [rad/s of the motor × capture ticks].
    pub fn speed_scaler(&self) -> f32 {
        TAU * (1u32 << self.upps) as f32 / (ENCODER_COUNTS_PER_REV * self.tick_s())
    }

    /// Largest measurable motor speed \[rad/s\] (`QCPRD` = 1).
    pub fn max_speed(&self) -> f32 {
        self.speed_scaler()
    }

    /// Smallest measurable motor speed \[rad/s\] (`QCPRD` = 0xFFFF).
    pub fn min_speed(&self) -> f32 {
        self.speed_scaler() / 65535.0
    }

    /// Longest time between unit events that is still measurable \[s\].
    pub fn max_period_s(&self) -> f32 {
        65535.0 * self.tick_s()
    }
}

/// The capture-based speed estimate of one motor (`POSSPEED_Calc`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedEstimator {
    cfg: CaptureConfig,
    speed: f32,
    since_event_s: f32,
}

impl SpeedEstimator {
    /// An estimator at rest.
    pub const fn new(cfg: CaptureConfig) -> Self {
        Self {
            cfg,
            speed: 0.0,
            since_event_s: 0.0,
        }
    }

    /// The configuration.
    pub fn config(&self) -> CaptureConfig {
        self.cfg
    }

    /// The current motor speed estimate \[rad/s\] (sign: QDF).
    pub fn speed(&self) -> f32 {
        self.speed
    }

    /// Takes one register sample, `dt_s` after the previous one; returns the motor speed.
    pub fn update(&mut self, s: &QepSample, dt_s: f32) -> f32 {
        if s.unit_event {
            self.since_event_s = 0.0;
            let v = if s.capture_overflow || s.direction_change {
                0.0
            } else {
                self.cfg.speed_scaler() / s.capture_period.max(1) as f32
            };
            self.speed = if s.forward { v } else { -v };
        } else {
            self.since_event_s += dt_s;
            if self.since_event_s > self.cfg.max_period_s() {
                self.since_event_s = self.cfg.max_period_s();
                self.speed = 0.0;
            }
        }
        self.speed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laelaps::hw::{JOINT_RATIO_HIP, JOINT_RATIO_KNEE};

    fn event(period: u16, forward: bool) -> QepSample {
        QepSample {
            unit_event: true,
            capture_period: period,
            forward,
            ..QepSample::default()
        }
    }

    #[test]
    fn table_3_4_range() {
        let c = CaptureConfig::THESIS;
        assert!((c.max_speed() - 19634.95).abs() < 0.01);
        assert!((c.min_speed() - 0.2996).abs() < 1e-4);
        assert!((c.max_speed() / JOINT_RATIO_HIP - 248.06).abs() < 0.01);
        assert!((c.max_speed() / JOINT_RATIO_KNEE - 200.36).abs() < 0.01);
        assert!((c.min_speed() / JOINT_RATIO_HIP - 0.0038).abs() < 5e-5);
        assert!((c.min_speed() / JOINT_RATIO_KNEE - 0.0031).abs() < 5e-5);
    }

    #[test]
    fn speed_inside_and_outside_the_range() {
        let c = CaptureConfig::THESIS;
        let mut e = SpeedEstimator::new(c);
        // In range: ω = scaler / QCPRD, sign from QDF.
        assert!((e.update(&event(1000, true), 1e-4) - c.speed_scaler() / 1000.0).abs() < 1e-3);
        assert!((e.update(&event(1000, false), 1e-4) + c.speed_scaler() / 1000.0).abs() < 1e-3);
        // Both ends of the range.
        assert_eq!(e.update(&event(1, true), 1e-4), c.max_speed());
        assert_eq!(e.update(&event(0xFFFF, true), 1e-4), c.min_speed());
        // Above the maximum (QCPRD would be < 1): saturates.
        assert_eq!(e.update(&event(0, true), 1e-4), c.max_speed());
        assert_eq!(e.update(&event(0, false), 1e-4), -c.max_speed());
        // Below the minimum: capture overflow reads 0.
        let ov = QepSample {
            capture_overflow: true,
            ..event(0xFFFF, true)
        };
        assert_eq!(e.update(&ov, 1e-4), 0.0);
        // Direction change reads 0.
        let dc = QepSample {
            direction_change: true,
            ..event(500, true)
        };
        assert_eq!(e.update(&dc, 1e-4), 0.0);
    }

    #[test]
    fn standstill_reads_zero_after_the_capture_range() {
        let c = CaptureConfig::THESIS;
        let mut e = SpeedEstimator::new(c);
        let v = e.update(&event(40_000, true), 1e-4);
        assert!(v > 0.0);
        // Without events the estimate holds while a slower event could still come …
        let quiet = QepSample::default();
        let hold_steps = (c.max_period_s() / 1e-4) as u32 - 1;
        for _ in 0..hold_steps {
            assert_eq!(e.update(&quiet, 1e-4), v);
        }
        // … then the speed is below the measurable minimum: 0.
        for _ in 0..3 {
            e.update(&quiet, 1e-4);
        }
        assert_eq!(e.speed(), 0.0);
    }

    #[test]
    fn counts_relative_to_reset_pose() {
        let enc = JointEncoder::zeroed_at(u32::MAX - 10);
        assert_eq!(enc.counts(u32::MAX - 10), 0);
        assert_eq!(enc.counts(9), 20); // across the counter wrap
        assert_eq!(enc.counts(u32::MAX - 30), -20);
        // One joint turn = 2000 × ratio counts.
        let turn_knee = (2000.0 * JOINT_RATIO_KNEE) as i32;
        assert!((counts_to_joint_revs(turn_knee, Joint::Knee) - 1.0).abs() < 1e-6);
        let q = JointEncoder::zeroed_at(0).joint_revs(19_600 / 2, Joint::Knee);
        assert!((q - 0.05).abs() < 1e-6);
        let hip = counts_to_joint_revs(-(2000.0 * JOINT_RATIO_HIP / 4.0) as i32, Joint::Hip);
        assert!((hip + 0.25).abs() < 1e-4);
    }
}
