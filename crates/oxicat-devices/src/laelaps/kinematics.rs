//! Planar two-link leg kinematics (thesis §3.2, equations 3-1 to 3-5; Appendix 7.1) and
//! the left/right sign conventions.
//!
//! # Conventions (the one place they are written down)
//!
//! **Kinematic frame** (same for both sides): origin at the hip axis, `x` positive to the
//! right of the leg's side view, `y` positive **downward** (the thesis' Matlab plots use a
//! reversed y axis). Angles are absolute, measured from the downward vertical, positive
//! towards +x: θ1 (hip) is the upper link l1, θ2 (knee) is the lower virtual link l2:
//!
//! ```text
//! x = l1·sin θ1 + l2·sin θ2        y = l1·cos θ1 + l2·cos θ2
//! ```
//!
//! The inverse uses the thesis' knee configuration −1 (`sin φ = −√(1 − cos²φ)`, φ = θ2 − θ1),
//! so reachable points give φ ∈ (−π/2, 0): θ1 > θ2. The workspace is the annulus
//! `√(l1² + l2²) < r < l1 + l2` (0.4301 m < r < 0.6 m); outside it the leg holds the last
//! valid point ([`Ik`]). The reset pose (encoders zeroed) is θ1 = θ2 = 0: the leg hanging
//! straight down, since the thesis firmware compares the IK angles with the encoder
//! angles without an offset.
//!
//! **Joint (motor) frame**: what the encoders measure, the PIV controller regulates and the
//! PDO carries (`hip_angle`, `Desired_hip_angle`, velocities, PWM signs):
//! `q = σ·θ`, with σ = +1 for a left leg and σ = −1 for a right leg ([`Side::sign`]). This is
//! the thesis' `#ifdef RIGHT_LEG Desired_hip_angle = −hip_angle/(2π)` (left: `+`), and the
//! reason its Matlab post-processing negates the right legs' angles and velocities. A right
//! leg is a mirrored left leg: the same toe path needs opposite motor rotations.

use super::fmath::{atan2, sqrt};
use super::hw::{L1, L2};

/// Which side of the robot a leg is on (the thesis' `LEFT_LEG` / `RIGHT_LEG` builds).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Left leg (`LEFT_LEG`): joint frame = kinematic frame.
    Left,
    /// Right leg (`RIGHT_LEG`): joint frame = negated kinematic frame.
    Right,
}

impl Side {
    /// σ: joint-frame angle = σ × kinematic angle (+1 left, −1 right).
    pub const fn sign(self) -> f32 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }

    /// Kinematic angle → joint (motor/encoder/PDO) frame.
    pub fn to_joint(self, theta: f32) -> f32 {
        self.sign() * theta
    }

    /// Joint (motor/encoder/PDO) frame → kinematic angle.
    pub fn to_kinematic(self, q: f32) -> f32 {
        self.sign() * q
    }
}

/// Hip and knee angles \[rad\], kinematic frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LegAngles {
    /// θ1: upper link from the downward vertical.
    pub hip: f32,
    /// θ2: lower (virtual) link from the downward vertical.
    pub knee: f32,
}

/// Smallest toe distance from the hip that the IK accepts: √(l1² + l2²) (equation 3-5).
pub const R_MIN: f32 = 0.430_116_3;
/// Largest toe distance from the hip: l1 + l2 (equation 3-4).
pub const R_MAX: f32 = L1 + L2;

/// Toe position of the angles (equation 3-1): `(x, y)` \[m\], y downward.
pub fn forward(a: LegAngles) -> (f32, f32) {
    use super::fmath::{cos, sin};
    (
        L1 * sin(a.hip) + L2 * sin(a.knee),
        L1 * cos(a.hip) + L2 * cos(a.knee),
    )
}

/// True if the thesis' workspace check accepts `(x, y)`: `R_MIN < r < R_MAX`.
pub fn reachable(x: f32, y: f32) -> bool {
    let r = sqrt(x * x + y * y);
    r > R_MIN && r < R_MAX
}

/// Inverse kinematics (equations 3-2, 3-3; knee configuration −1); `None` outside the
/// workspace (or for non-finite input).
pub fn inverse(x: f32, y: f32) -> Option<LegAngles> {
    if !reachable(x, y) {
        return None;
    }
    let c = (y * y + x * x - L1 * L1 - L2 * L2) / (2.0 * L1 * L2);
    let s = -sqrt(1.0 - c * c);
    let knee = -atan2(y, x) + atan2(L1 * s, L2 + L1 * c) + core::f32::consts::FRAC_PI_2;
    let hip = knee - atan2(s, c);
    Some(LegAngles { hip, knee })
}

/// Inverse kinematics that holds the last valid solution when the target leaves the
/// workspace, as the thesis firmware does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ik {
    last: LegAngles,
    last_point: (f32, f32),
}

impl Default for Ik {
    fn default() -> Self {
        Self::new()
    }
}

impl Ik {
    /// Starts at the reset pose (θ1 = θ2 = 0, toe at (0, l1 + l2)).
    pub const fn new() -> Self {
        Self {
            last: LegAngles {
                hip: 0.0,
                knee: 0.0,
            },
            last_point: (0.0, R_MAX),
        }
    }

    /// Solves for `(x, y)`; returns the solution, or the last valid one if unreachable.
    pub fn solve(&mut self, x: f32, y: f32) -> LegAngles {
        if let Some(a) = inverse(x, y) {
            self.last = a;
            self.last_point = (x, y);
        }
        self.last
    }

    /// The last valid angles.
    pub fn angles(&self) -> LegAngles {
        self.last
    }

    /// The last reachable target point.
    pub fn point(&self) -> (f32, f32) {
        self.last_point
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::{PI, TAU};

    #[test]
    fn r_min_is_eq_3_5() {
        let r = sqrt(L1 * L1 + L2 * L2);
        assert!((R_MIN - r).abs() < 1e-6);
        assert!((R_MIN - 0.430_116_3).abs() < 1e-6);
    }

    /// FK(IK(p)) = p over a grid covering the workspace annulus.
    #[test]
    fn fk_of_ik_round_trip_over_workspace() {
        let mut n = 0;
        for i in -120..=120 {
            for j in 0..=130 {
                let (x, y) = (i as f32 * 0.005, j as f32 * 0.005);
                match inverse(x, y) {
                    Some(a) => {
                        n += 1;
                        let (fx, fy) = forward(a);
                        assert!(
                            (fx - x).abs() < 2e-5 && (fy - y).abs() < 2e-5,
                            "({x}, {y}) -> {a:?} -> ({fx}, {fy})"
                        );
                        let phi = a.knee - a.hip;
                        assert!(phi <= 0.0 && phi > -core::f32::consts::FRAC_PI_2 - 1e-3);
                    }
                    None => assert!(!reachable(x, y)),
                }
            }
        }
        assert!(n > 3000, "grid hit only {n} reachable points");
    }

    /// IK(FK(θ)) = θ for angles in the knee −1 branch strictly inside the workspace.
    #[test]
    fn ik_of_fk_round_trip_over_joint_grid() {
        for i in -40..=40 {
            for j in 1..=29 {
                let hip = i as f32 * 0.02;
                let phi = -(j as f32) * 0.05; // −0.05 .. −1.45 rad, inside (−π/2, 0)
                let a = LegAngles {
                    hip,
                    knee: hip + phi,
                };
                let (x, y) = forward(a);
                if !reachable(x, y) {
                    continue;
                }
                let b = inverse(x, y).expect("reachable");
                // Equal modulo 2π (atan2 wraps for toes above the hip's horizontal).
                let d = |u: f32, v: f32| {
                    let e = super::super::fmath::rem_euclid(u - v + PI, TAU) - PI;
                    e.abs()
                };
                assert!(
                    d(b.hip, a.hip) < 2e-4 && d(b.knee, a.knee) < 2e-4,
                    "{a:?} -> ({x}, {y}) -> {b:?}"
                );
            }
        }
    }

    #[test]
    fn thesis_matlab_formula() {
        // Appendix 7.1 with knee_configuration = −1, evaluated independently in f64.
        let (x, y) = (0.03f64, 0.55f64);
        let (l1, l2) = (0.25f64, 0.35f64);
        let c = (y * y + x * x - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
        let s = -(1.0 - c * c).sqrt();
        let k1 = l2 + l1 * c;
        let k2 = l1 * s;
        let knee = -y.atan2(x) + k2.atan2(k1) + core::f64::consts::FRAC_PI_2;
        let hip = knee - s.atan2(c);
        let a = inverse(x as f32, y as f32).unwrap();
        assert!((a.knee as f64 - knee).abs() < 1e-5);
        assert!((a.hip as f64 - hip).abs() < 1e-5);
    }

    #[test]
    fn unreachable_targets_hold_the_last_point() {
        let mut ik = Ik::new();
        assert_eq!(ik.angles(), LegAngles::default());
        let good = ik.solve(0.02, 0.55);
        assert_eq!(inverse(0.02, 0.55), Some(good));
        // Too far (r > 0.6), too near (r < 0.43), on the boundaries, at the hip, NaN.
        for (x, y) in [
            (0.0, 0.61),
            (0.05, 0.599),
            (0.0, 0.6),
            (0.0, 0.4),
            (0.0, R_MIN),
            (0.0, 0.0),
            (f32::NAN, 0.5),
        ] {
            assert_eq!(ik.solve(x, y), good, "({x}, {y})");
            assert_eq!(ik.point(), (0.02, 0.55));
        }
        let other = ik.solve(-0.03, 0.5);
        assert_ne!(other, good);
    }

    #[test]
    fn side_signs() {
        assert_eq!(Side::Left.to_joint(0.3), 0.3);
        assert_eq!(Side::Right.to_joint(0.3), -0.3);
        for s in [Side::Left, Side::Right] {
            assert_eq!(s.to_kinematic(s.to_joint(0.7)), 0.7);
        }
    }
}
