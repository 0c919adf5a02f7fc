//! Behavioural tests of the leg plant (no timings).

use oxicat_plant::{gear, Joint, Leg, LegParams, Side, Treadmill, COUNTS_PER_REV};
use std::f64::consts::PI;

const DT: f64 = 100e-6;

fn far_belt() -> Treadmill {
    Treadmill {
        speed: 0.0,
        height: 10.0,
    }
}

#[test]
fn energy_conserved_unactuated_frictionless_no_contact() {
    let mut p = LegParams::laelaps(Side::Left);
    p.hip = p.hip.ideal();
    p.knee = p.knee.ideal();
    p.treadmill = far_belt();
    p.initial_angles = [0.6, -0.4];
    let mut leg = Leg::new(p);
    let e0 = leg.mechanical_energy();
    let mut max_dev: f64 = 0.0;
    let mut max_speed = 0.0f64;
    for _ in 0..50_000 {
        leg.step(DT, 0.0, false, 0.0, false);
        max_dev = max_dev.max((leg.mechanical_energy() - e0).abs());
        max_speed = max_speed.max(leg.joint_speeds()[1].abs());
    }
    // It really swings (slowly: the reflected rotor inertia dominates) ...
    assert!(max_speed > 0.3, "max knee speed {max_speed}");
    // ... and the energy stays within 0.1 % of the potential energy scale.
    let scale: f64 = 9.81 * (0.6 * 0.1 + 0.4 * 0.25 + 0.4 * 0.15);
    assert!(
        max_dev < 1e-3 * scale,
        "energy drift {max_dev} J (scale {scale} J)"
    );
}

#[test]
fn gravity_torque_is_gradient_of_potential() {
    let mut p = LegParams::laelaps(Side::Left);
    p.initial_angles = [0.3, -0.2];
    let leg = Leg::new(p);
    let g = leg.gravity_torque();
    let pot = |q: [f64; 2]| {
        let mut pp = p;
        pp.initial_angles = q;
        let l = Leg::new(pp);
        l.mechanical_energy()
    };
    let e = 1e-6;
    for k in 0..2 {
        let mut qp = p.initial_angles;
        let mut qm = p.initial_angles;
        qp[k] += e;
        qm[k] -= e;
        let num = -(pot(qp) - pot(qm)) / (2.0 * e);
        assert!((num - g[k]).abs() < 1e-6, "joint {k}: {num} vs {}", g[k]);
    }
}

/// Command the torques −G − JᵀF that hold a pose against gravity and a foot force from the
/// belt; with ideal drives the leg stays put, and the contact force is the one predicted.
#[test]
fn static_holding_torque_equals_gravity_plus_jt_f() {
    for side in [Side::Left, Side::Right] {
        let mut p = LegParams::laelaps(side);
        p.hip = p.hip.ideal();
        p.knee = p.knee.ideal();
        p.initial_angles = [0.25, -0.15];
        let probe = Leg::new(p);
        let toe = probe.toe_position();
        let pen = 0.002;
        p.treadmill = Treadmill {
            speed: 0.0,
            height: toe[1] - pen,
        };
        let mut leg = Leg::new(p);
        let f = [0.0, -p.contact.stiffness * pen];
        let g = leg.gravity_torque();
        let j = leg.jacobian();
        let hold = [
            -g[0] - (j[0][0] * f[0] + j[1][0] * f[1]),
            -g[1] - (j[0][1] * f[0] + j[1][1] * f[1]),
        ];
        // Let the current loop settle with the leg locked in place first: start at the
        // commanded currents by stepping with the duties (the rotor inertia keeps it still).
        let duty = leg.duty_for_joint_torque(hold);
        for _ in 0..5000 {
            leg.step(DT, duty[0].0, duty[0].1, duty[1].0, duty[1].1);
        }
        let q = leg.joint_angles();
        assert!(
            (q[0] - 0.25).abs() < 2e-4 && (q[1] + 0.15).abs() < 2e-4,
            "{side:?}: drifted to {q:?}"
        );
        let tau = leg.joint_torques();
        for k in 0..2 {
            assert!(
                (tau[k] - hold[k]).abs() < 1e-3 * hold[k].abs().max(1.0),
                "{side:?} joint {k}: {} vs {}",
                tau[k],
                hold[k]
            );
        }
        let fc = leg.contact_force();
        assert!((fc[1] - f[1]).abs() < 0.02 * f[1].abs(), "{fc:?} vs {f:?}");
    }
}

/// Full duty, couplers slipping-free, no load but the (frictionless) rotor: speed settles at
/// the back-EMF limit V/k_e of the 40 V supply, i.e. the 48 V no-load speed scaled by 40/48.
#[test]
fn no_load_speed_is_back_emf_limited() {
    for (joint, dp) in [
        (Joint::Hip, oxicat_plant::DriveParams::laelaps_hip()),
        (Joint::Knee, oxicat_plant::DriveParams::laelaps_knee()),
    ] {
        let mut p = LegParams::laelaps(Side::Left);
        p.gravity = 0.0;
        p.treadmill = far_belt();
        // "No load": massless links.
        for l in [&mut p.thigh, &mut p.shank] {
            l.mass = 1e-9;
            l.inertia = 1e-9;
        }
        let mut leg = Leg::new(p);
        for _ in 0..20_000 {
            leg.set_duty(joint, 1.0, false);
            leg.advance(DT);
        }
        let w = leg.motor_speeds()[joint as usize];
        let m = dp.motor;
        let datasheet_no_load_48v = m.ideal_no_load_speed(m.nominal_voltage);
        let expected = datasheet_no_load_48v * 40.0 / m.nominal_voltage;
        // Friction (no-load current) lowers it by a few per cent, as on the datasheet.
        assert!(
            w < expected && w > 0.95 * expected,
            "{joint:?}: {w} rad/s vs {expected} rad/s"
        );
        // The current is what the friction needs, far below the 12 A command.
        assert!(leg.motor_currents()[joint as usize] < 1.0);
    }
}

fn locked_leg() -> Leg {
    let mut p = LegParams::laelaps(Side::Left);
    p.gravity = 0.0;
    p.treadmill = far_belt();
    // A joint load so heavy it barely moves: the coupler sees the motor's torque.
    p.thigh.inertia = 1e5;
    p.shank.inertia = 1e5;
    Leg::new(p)
}

#[test]
fn coupler_slips_above_30_nm_and_sticks_below() {
    let knee = oxicat_plant::DriveParams::laelaps_knee();
    let kt = knee.motor.torque_constant;
    // Duty giving 20 Nm at the gearhead output: sticks, transmits it.
    let duty_low = 20.0 / (knee.gearhead_ratio * kt * 12.0);
    let mut leg = locked_leg();
    for _ in 0..3000 {
        leg.step(DT, 0.0, false, duty_low, false);
    }
    assert!(!leg.coupler_slipping()[1]);
    let tc = leg.coupler_torques()[1];
    assert!(tc > 15.0 && tc < 30.0, "{tc}");
    let enc = leg.encoder_counts()[1] as f64;
    let expect = leg.joint_angles()[1] * knee.ratio() * COUNTS_PER_REV / (2.0 * PI);
    assert!((enc - expect).abs() <= 1.0, "stuck: encoder follows joint");

    // Full duty: 12 A · k_t · 53 ≈ 58 Nm > 30 Nm: slips, transmits exactly 30 Nm, the motor
    // runs away from the joint.
    let mut leg = locked_leg();
    for _ in 0..3000 {
        leg.step(DT, 0.0, false, 1.0, false);
    }
    assert!(leg.coupler_slipping()[1]);
    assert_eq!(leg.coupler_torques()[1], gear::COUPLER_SLIP_TORQUE);
    let motor_as_joint = leg.motor_angles()[1] / knee.ratio();
    assert!(motor_as_joint > 10.0 * leg.joint_angles()[1].abs() + 0.1);

    // Release: back to zero duty, the motor side is braked by the coupler and re-sticks.
    for _ in 0..20_000 {
        leg.step(DT, 0.0, false, 0.0, false);
    }
    assert!(!leg.coupler_slipping()[1]);
}

#[test]
fn encoder_counts_per_joint_revolution_with_sign() {
    for side in [Side::Left, Side::Right] {
        let mut p = LegParams::laelaps(side);
        p.gravity = 0.0;
        p.treadmill = far_belt();
        let mut leg = Leg::new(p);
        // Drive each joint forward (positive thesis angle) past one revolution.
        let dir_neg = side == Side::Right;
        while leg.joint_angles()[0] < 2.0 * PI || leg.joint_angles()[1] < 2.0 * PI {
            let d0 = if leg.joint_angles()[0] < 2.0 * PI {
                0.3
            } else {
                0.0
            };
            let d1 = if leg.joint_angles()[1] < 2.0 * PI {
                0.3
            } else {
                0.0
            };
            leg.step(DT, d0, dir_neg, d1, dir_neg);
            assert!(leg.time() < 60.0, "did not turn");
        }
        assert_eq!(leg.coupler_slipping(), [false, false]);
        let q = leg.joint_angles();
        let c = leg.encoder_counts();
        for (k, ratio) in [gear::HIP_RATIO, gear::KNEE_RATIO].into_iter().enumerate() {
            let per_rev = COUNTS_PER_REV * ratio;
            let expected = side.sign() * per_rev * q[k] / (2.0 * PI);
            assert!(
                (c[k] as f64 - expected).abs() <= 1.0,
                "{side:?} joint {k}: {} vs {expected}",
                c[k]
            );
            assert!(c[k].unsigned_abs() as f64 >= per_rev - 1.0);
            // Hip 158 308, knee 196 000 counts per joint revolution.
            assert_eq!(c[k].signum() as f64, side.sign());
        }
        assert!((COUNTS_PER_REV * gear::KNEE_RATIO - 196_000.0).abs() < 1e-6);
    }
}

#[test]
fn encoder_edge_times_and_unit_captures() {
    let mut p = LegParams::laelaps(Side::Left);
    p.gravity = 0.0;
    p.treadmill = far_belt();
    let mut leg = Leg::new(p);
    for _ in 0..2000 {
        leg.step(DT, 0.2, false, 0.0, false);
    }
    let w = leg.motor_speeds()[0];
    let enc = leg.encoder_mut(Joint::Hip);
    assert!(enc.forward());
    assert!(enc.last_edge_time() <= 0.2 + 1e-12 && enc.last_edge_time() > 0.2 - 1e-3);
    let cap = enc.take_capture().expect("unit event");
    let est = enc.unit_prescaler() as f64 * 2.0 * PI / COUNTS_PER_REV / cap.period;
    assert!((est - w).abs() < 0.02 * w, "{est} vs {w}");
    assert!(enc.take_capture().is_none(), "flag cleared");
}

/// A passive leg (no current) with its foot pressed on the moving belt is dragged along at the
/// belt speed: the contact friction sticks and the stiff, heavily geared leg follows.
#[test]
fn foot_dragged_at_belt_speed() {
    let mut p = LegParams::laelaps(Side::Left);
    // Straight leg reaching forward: dragging it back presses the foot into the belt.
    p.initial_angles = [0.2, 0.2];
    let toe = Leg::new(p).toe_position();
    let speed = 0.2;
    p.treadmill = Treadmill {
        speed,
        height: toe[1] - 0.002,
    };
    let mut leg = Leg::new(p);
    let mut xs = Vec::new();
    for n in 0..2000 {
        leg.step(DT, 0.0, false, 0.0, false);
        if n >= 200 && n % 100 == 0 {
            xs.push(leg.toe_velocity()[0]);
        }
    }
    for vx in &xs {
        assert!(
            (vx + speed).abs() < 0.02 * speed,
            "toe vx {vx} vs belt {}",
            -speed
        );
    }
    assert!(leg.contact_force()[1] < 0.0, "still in contact");
}

fn run(side: Side) -> Vec<u64> {
    let mut p = LegParams::laelaps(side);
    p.treadmill.speed = 0.3;
    let mut leg = Leg::new(p);
    let mut out = Vec::new();
    for n in 0..20_000 {
        let t = n as f64 * DT;
        let u = 0.3 * (2.0 * PI * t).sin();
        let u2 = 0.3 * (2.0 * PI * t).cos();
        leg.step(DT, u.abs(), u < 0.0, u2.abs(), u2 < 0.0);
        if n % 97 == 0 {
            let q = leg.joint_angles();
            let c = leg.encoder_counts();
            let f = leg.contact_force();
            out.extend([q[0].to_bits(), q[1].to_bits(), c[0] as u64, c[1] as u64]);
            out.extend([f[0].to_bits(), f[1].to_bits()]);
        }
    }
    out
}

#[test]
fn deterministic_bit_identical() {
    assert_eq!(run(Side::Left), run(Side::Left));
    assert_eq!(run(Side::Right), run(Side::Right));
}

#[test]
fn left_and_right_are_mirrored() {
    // Same physical motion needs opposite currents; counts are opposite.
    let mut l = Leg::new(LegParams::laelaps(Side::Left));
    let mut r = Leg::new(LegParams::laelaps(Side::Right));
    for _ in 0..1000 {
        l.step(DT, 0.1, false, 0.1, false);
        r.step(DT, 0.1, true, 0.1, true);
    }
    assert_eq!(l.joint_angles(), r.joint_angles());
    let (cl, cr) = (l.encoder_counts(), r.encoder_counts());
    assert_eq!([cl[0], cl[1]], [-cr[0], -cr[1]]);
    assert!(l.joint_angles()[0] > 0.0);
}
