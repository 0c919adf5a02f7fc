//! Fixed hardware and firmware constants of a Laelaps II leg node (thesis §3.2, §3.5,
//! §3.6, §6.10, Table 3-4), and the two joints.

/// A joint of the leg.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Joint {
    /// Hip: Maxon EC 45 brushless motor, ePWM2/eQEP2 in the thesis firmware.
    Hip,
    /// Knee: Maxon RE 50 brushed motor, ePWM1/eQEP1 in the thesis firmware.
    Knee,
}

impl Joint {
    /// Both joints, in the order the 10 kHz loop runs them (knee first, as ePWM1 before ePWM2).
    pub const ALL: [Joint; 2] = [Joint::Knee, Joint::Hip];

    /// Total reduction motor → joint (gearhead × pulley), see [`JOINT_RATIO_HIP`].
    pub const fn ratio(self) -> f32 {
        match self {
            Joint::Hip => JOINT_RATIO_HIP,
            Joint::Knee => JOINT_RATIO_KNEE,
        }
    }

    /// PIV output limit (fraction of full PWM), a compile-time constant as in the thesis.
    pub const fn u_max(self) -> f32 {
        match self {
            Joint::Hip => U_MAX_HIP,
            Joint::Knee => U_MAX_KNEE,
        }
    }
}

/// Upper (actual) link length l1 \[m\] (§3.2).
pub const L1: f32 = 0.25;
/// Lower (virtual) link length l2 \[m\] (§3.2).
pub const L2: f32 = 0.35;

/// Encoder counts per motor revolution (quadrature edges), both joints.
pub const ENCODER_COUNTS_PER_REV: f32 = 2000.0;

/// Pulley stage after each gearhead: 48/26 (§6.10). It is part of the joint angle.
pub const PULLEY_RATIO: f32 = 48.0 / 26.0;
/// Hip gearhead: Maxon GP 52 C 343/8 (part 223089), on the EC 45 brushless motor.
pub const GEARHEAD_HIP: f32 = 343.0 / 8.0;
/// Knee gearhead: Maxon GP 52 C 637/12 (part 223090), on the RE 50 brushed motor.
pub const GEARHEAD_KNEE: f32 = 637.0 / 12.0;

/// Total hip reduction motor → joint: 343/8 × 48/26 = 1029/13 ≈ 79.15.
///
/// **The one place where the gear-ratio choice is made.** The thesis contradicts
/// itself: §6.10 (motor and gearhead list) and Table 3-4 (joint speed range:
/// 19634.95 / 79.15 = 248.06 rad/s for the hip) give the hip 79.15 and the knee 98, while
/// its firmware ISRs (`ngwnia1 = raw·8·26/(2000·343·48)` for the *knee*) and its Matlab
/// post-processing (`i_knee = 8·26/(343·48)`) swap them. We follow §6.10 and Table 3-4
/// (the hardware description, which two independent places agree on). The 48/26 pulley
/// is included, as in the firmware's angle formula.
pub const JOINT_RATIO_HIP: f32 = GEARHEAD_HIP * PULLEY_RATIO;
/// Total knee reduction motor → joint: 637/12 × 48/26 = 98 (see [`JOINT_RATIO_HIP`]).
pub const JOINT_RATIO_KNEE: f32 = GEARHEAD_KNEE * PULLEY_RATIO;

/// Knee PIV output limit: 38.25 % of full PWM (≈ 4.59 A of the 12 A amplifier).
pub const U_MAX_KNEE: f32 = 0.3825;
/// Hip PIV output limit: 41.17 % of full PWM (≈ 4.94 A of the 12 A amplifier).
pub const U_MAX_HIP: f32 = 0.4117;

/// Joint control loop period \[s\]: 10 kHz (the Matlab model's `T = 1/10000`).
pub const CONTROL_PERIOD_S: f32 = 1.0e-4;
/// Id of the 10 kHz joint-loop timer event ([`oxicat_slave::Slave::on_timer`]).
pub const JOINT_LOOP_TIMER: u8 = 0;

/// Derivative-filter bandwidth \[Hz\] until the master writes a non-zero `FilterBandwidth`.
pub const DEFAULT_FILTER_HZ: f32 = 20.0;
/// `Transition_time` \[s\] until the master writes a non-zero value (Table 4-1's value).
pub const DEFAULT_TRANSITION_TIME_S: f32 = 3.0;
/// Application cycle \[ns\] assumed when no SYNC0 cycle time is known (free run / SM
/// synchronous; 0x1C32:02 is 0): the thesis' 400 µs bus cycle.
pub const DEFAULT_CYCLE_NS: u32 = 400_000;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratios_as_section_6_10() {
        assert!((JOINT_RATIO_HIP - 1029.0 / 13.0).abs() < 1e-4);
        assert!((JOINT_RATIO_HIP - 79.15).abs() < 0.01);
        assert!((JOINT_RATIO_KNEE - 98.0).abs() < 1e-4);
    }
}
