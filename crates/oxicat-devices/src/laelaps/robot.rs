//! The whole robot of the trot (`[robot]` in a scenario): the four legs' hips on one body
//! on the treadmill's support ([`oxicat_plant::body`]), and each leg's link masses and
//! motor constants drawn within tolerances from a seed, so that the legs differ as built
//! legs do and their differences come from physics.
//!
//! Assumptions (the thesis gives none of these numbers; all are in the scenario and the
//! README): the robot's mass, the hip spacing, where its centre of mass lies (behind the
//! hips' midpoint), the share of the weight the support mechanism carries, the support's
//! stiffness and damping ([`oxicat_plant::BodyParams::laelaps`]), the legs' masses lumped
//! at their hips for the body's motion, no roll or fore–aft motion (the support holds
//! them), and the leg frames not turned by the small pitch.

use std::sync::{Arc, Mutex};

use crate::laelaps::rig::{BodyLink, LegId};
use crate::laelaps::scenario::Robot;
use oxicat_plant::{Body, BodyParams, LegParams};

/// The body of `r` with the four legs' link masses (Table 4-1 order), or `None` when
/// `r.body` is off.
pub fn body(r: &Robot) -> Option<Arc<Mutex<Body>>> {
    if !r.body {
        return None;
    }
    let half = 0.5 * r.hip_spacing_cm / 100.0;
    let com = r.com_behind_cm / 100.0;
    // Hips ahead of the centre of mass: the fore hips L + e, the hind hips −(L − e).
    let mut p = BodyParams::laelaps(r.mass_kg, half + com, -(half - com));
    p.support_share = r.support_share;
    Some(Arc::new(Mutex::new(Body::new(p))))
}

/// The rigs' links to `body`, one per leg (Table 4-1 order).
pub fn link(body: &Arc<Mutex<Body>>, leg: LegId) -> BodyLink {
    BodyLink {
        body: body.clone(),
        leg: crate::laelaps::experiment::table_index(leg),
    }
}

/// A uniform number in [−1, 1) from the seed, the leg and which parameter (splitmix64: the
/// same on every platform).
pub fn unit(seed: u64, leg: LegId, what: u64) -> f64 {
    let li = crate::laelaps::experiment::table_index(leg) as u64;
    let mut z = seed
        .wrapping_add(0x9E37_79B9_7F4A_7C15u64.wrapping_mul(1 + li * 16 + what))
        .wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// `p` with leg `leg`'s tolerances of `r` applied: thigh and shank mass (inertia scaling
/// with it), hip and knee motor torque constant and resistance, each its own draw within
/// ± its tolerance. Zero tolerances leave `p` untouched (bit for bit).
pub fn leg_params(r: &Robot, leg: LegId, mut p: LegParams) -> LegParams {
    let f = |tol_pct: f64, what: u64| 1.0 + tol_pct / 100.0 * unit(r.seed, leg, what);
    if r.mass_tolerance_pct > 0.0 {
        for (k, link) in [&mut p.thigh, &mut p.shank].into_iter().enumerate() {
            let s = f(r.mass_tolerance_pct, k as u64);
            link.mass *= s;
            link.inertia *= s;
        }
    }
    if r.motor_tolerance_pct > 0.0 {
        for (k, d) in [&mut p.hip, &mut p.knee].into_iter().enumerate() {
            d.motor.torque_constant *= f(r.motor_tolerance_pct, 2 + 2 * k as u64);
            d.motor.resistance *= f(r.motor_tolerance_pct, 3 + 2 * k as u64);
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laelaps::scenario::Scenario;

    #[test]
    fn draws_are_uniform_in_the_interval_and_differ_per_leg_and_seed() {
        let mut n = 0;
        let mut sum = 0.0;
        for seed in 0..200 {
            for leg in LegId::TABLE {
                for what in 0..6 {
                    let u = unit(seed, leg, what);
                    assert!((-1.0..1.0).contains(&u), "{u}");
                    sum += u;
                    n += 1;
                }
            }
        }
        assert!(
            (sum / f64::from(n)).abs() < 0.05,
            "mean {}",
            sum / f64::from(n)
        );
        assert_ne!(unit(1, LegId::ForeLeft, 0), unit(1, LegId::ForeRight, 0));
        assert_ne!(unit(1, LegId::ForeLeft, 0), unit(2, LegId::ForeLeft, 0));
    }

    #[test]
    fn tolerances_stay_within_their_range_and_zero_is_nominal() {
        let mut r = Scenario::thesis().robot;
        let nominal = LegParams::laelaps(oxicat_plant::Side::Left);
        r.mass_tolerance_pct = 0.0;
        r.motor_tolerance_pct = 0.0;
        assert_eq!(leg_params(&r, LegId::HindLeft, nominal), nominal);
        r.mass_tolerance_pct = 5.0;
        r.motor_tolerance_pct = 3.0;
        let mut masses = Vec::new();
        for leg in LegId::TABLE {
            let p = leg_params(&r, leg, nominal);
            let dm = p.thigh.mass / nominal.thigh.mass - 1.0;
            let dk = p.knee.motor.torque_constant / nominal.knee.motor.torque_constant - 1.0;
            assert!(dm.abs() <= 0.05 && dk.abs() <= 0.03, "{leg:?}: {dm} {dk}");
            let (ri, rm) = (
                p.thigh.inertia / nominal.thigh.inertia,
                p.thigh.mass / nominal.thigh.mass,
            );
            assert!((ri - rm).abs() < 1e-12, "{ri} {rm}");
            masses.push(p.thigh.mass);
        }
        masses.dedup();
        assert_eq!(masses.len(), 4, "{masses:?}");
    }

    /// A centre of mass outside the hips is refused with both keys; NaN with key and range;
    /// no `[robot]` table is the fixed-hip robot with nominal legs.
    #[test]
    fn robot_numbers_are_checked() {
        use crate::laelaps::scenario::DEFAULT_TOML;
        let e =
            Scenario::parse(&DEFAULT_TOML.replace("com_behind_cm = 5.0", "com_behind_cm = 35.0"))
                .expect_err("outside the hips")
                .to_string();
        assert!(
            e.contains("robot.com_behind_cm = 35") && e.contains("robot.hip_spacing_cm"),
            "{e}"
        );
        let e =
            Scenario::parse(&DEFAULT_TOML.replace("support_share = 0.2", "support_share = nan"))
                .expect_err("NaN")
                .to_string();
        assert!(
            e.contains("robot.support_share = NaN is not in 0 … 1"),
            "{e}"
        );
        let i = DEFAULT_TOML
            .find("[robot]")
            .expect("[robot] in the shipped file");
        let j = DEFAULT_TOML[i..]
            .find("[pdi]")
            .expect("[pdi] after [robot]")
            + i;
        let s = Scenario::parse(&format!("{}{}", &DEFAULT_TOML[..i], &DEFAULT_TOML[j..]))
            .expect("no [robot]");
        assert!(!s.robot.body);
        assert_eq!(
            (s.robot.mass_tolerance_pct, s.robot.motor_tolerance_pct),
            (0.0, 0.0)
        );
    }

    /// The centre of mass behind the hips' midpoint puts the hind hips nearer to it.
    #[test]
    fn body_hips_from_the_scenario() {
        let r = Scenario::thesis().robot;
        let b = body(&r).expect("the shipped scenario has the body");
        let b = b.lock().expect("lock");
        let x = b.params().hip_x;
        assert!(x[0] > 0.0 && x[2] < 0.0 && x[0] == x[1] && x[2] == x[3]);
        assert!((x[0] - x[2] - r.hip_spacing_cm / 100.0).abs() < 1e-12);
        assert!(x[0] > -x[2], "{x:?}");
        let mut off = r.clone();
        off.body = false;
        assert!(body(&off).is_none());
    }
}
