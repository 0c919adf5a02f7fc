//! Cost of the plant: one 10 kHz step (two 50 µs substeps) of one leg, and four legs trotting
//! under a simple joint PD so that contact, friction and encoders are all active.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use oxicat_plant::{Joint, Leg, LegParams, Side};
use std::time::Instant;

const DT: f64 = 100e-6;

fn pd_step(leg: &mut Leg, t: f64, phase: f64) {
    // Desired joint angles: small sinusoids around the stand pose, PD on the true angles.
    let w = 2.0 * std::f64::consts::PI;
    let des = [
        0.15 * (w * t + phase).sin() + 0.05,
        0.15 * (w * t + phase).cos() - 0.05,
    ];
    let q = leg.joint_angles();
    let v = leg.joint_speeds();
    let s = leg.params().side.sign();
    for (k, j) in [Joint::Hip, Joint::Knee].into_iter().enumerate() {
        let u = s * (3.0 * (des[k] - q[k]) - 0.1 * v[k]);
        leg.set_duty(j, u.abs().min(0.41), u < 0.0);
    }
    leg.advance(DT);
}

fn legs(substep: f64) -> Vec<Leg> {
    [Side::Right, Side::Left, Side::Left, Side::Right]
        .into_iter()
        .map(|s| {
            let mut p = LegParams::laelaps(s);
            p.treadmill.speed = 0.3;
            p.substep = substep;
            Leg::new(p)
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let mut leg = Leg::new(LegParams::laelaps(Side::Left));
    leg.set_belt_speed(0.3);
    let mut t = 0.0;
    c.bench_function("leg_step_10kHz (one leg, 2 substeps)", |b| {
        b.iter(|| {
            pd_step(black_box(&mut leg), t, 0.0);
            t += DT;
        })
    });

    // Simulated seconds per wall second, four legs, 10 s of virtual time.
    for substep in [50e-6, 100e-6] {
        four_legs(substep);
    }
}

fn four_legs(substep: f64) {
    let mut four = legs(substep);
    let steps = 100_000u32;
    let start = Instant::now();
    for n in 0..steps {
        let t = n as f64 * DT;
        for (i, leg) in four.iter_mut().enumerate() {
            pd_step(
                leg,
                t,
                if i % 3 == 0 {
                    std::f64::consts::PI
                } else {
                    0.0
                },
            );
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let sim = steps as f64 * DT;
    println!(
        "four legs, substep {:.0} µs: {sim:.1} s simulated in {wall:.3} s wall = {:.0}x real time ({:.0} ns per leg step)",
        substep * 1e6,
        sim / wall,
        wall * 1e9 / (steps as f64 * 4.0)
    );
    black_box(&four);
}

criterion_group!(benches, bench);
criterion_main!(benches);
