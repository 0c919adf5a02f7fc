//! Field-oriented transforms of the board, `core` only: the electrical angle from the
//! encoder, Clarke/Park for the measured currents, inverse Park and space-vector
//! modulation for the q-axis voltage the drive's current loop asks for.
//!
//! Conventions (amplitude-invariant Clarke, as most drive firmware):
//!
//! - `i_α = i_a`, `i_β = (i_a + 2·i_b)/√3` (two measured phases, `i_a + i_b + i_c = 0`);
//! - `i_q = −i_α·sin θ + i_β·cos θ` (`i_d = i_α·cos θ + i_β·sin θ`);
//! - `v_α = −v_q·sin θ`, `v_β = v_q·cos θ` (`v_d = 0`), then
//!   `v_a = v_α`, `v_b = (−v_α + √3·v_β)/2`, `v_c = (−v_α − √3·v_β)/2`.
//!
//! With θ the electrical angle of the rotor's d axis (the flux), `v_q > 0` makes positive
//! torque, i.e. the encoder counting up — provided the phases are wired in the order that
//! makes the encoder count up when the field turns from a to b to c (README, "Wiring").
//!
//! Modulation is space-vector PWM by min–max zero-sequence injection: the three phase
//! voltages are shifted by `−(max + min)/2`, which centres the active vectors in the
//! period exactly as the symmetric seven-segment SVM does, and reaches `|v| = V_bus/√3`
//! in the linear range (sine PWM: `V_bus/2`).

use core::f32::consts::{FRAC_PI_2, PI, TAU};

/// 1/√3.
const INV_SQRT3: f32 = 0.577_350_26;
/// √3/2.
const SQRT3_2: f32 = 0.866_025_4;

/// sin and cos of `x` (any finite angle, rad): quadrant reduction to |r| ≤ π/4 and
/// Taylor polynomials to r⁷ / r⁸ — error below 4e-7 there, i.e. float rounding.
pub fn sin_cos(x: f32) -> (f32, f32) {
    // Quadrant q = round(x / (π/2)); r = x − q·π/2 in [−π/4, π/4].
    let qf = x * (2.0 / PI);
    let q = if qf >= 0.0 {
        (qf + 0.5) as i32
    } else {
        (qf - 0.5) as i32
    };
    let r = x - q as f32 * FRAC_PI_2;
    let r2 = r * r;
    let s = r * (1.0 - r2 / 6.0 * (1.0 - r2 / 20.0 * (1.0 - r2 / 42.0)));
    let c = 1.0 - r2 / 2.0 * (1.0 - r2 / 12.0 * (1.0 - r2 / 30.0 * (1.0 - r2 / 56.0)));
    match q & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// The rotor's electrical angle, tracked from the encoder count.
///
/// The count is followed incrementally (difference since the last update, wrapping), the
/// position within one motor revolution kept in `[0, counts_per_rev)`: so the angle stays
/// continuous through the 32-bit counter's wrap whatever `counts_per_rev` is.
#[derive(Debug, Clone, Copy)]
pub struct ElecAngle {
    counts_per_rev: i32,
    pole_pairs: u32,
    last: u32,
    in_rev: i32,
}

impl ElecAngle {
    /// Starts tracking at counter value `count`, which is taken as electrical angle 0
    /// (the rotor's d axis on phase a: where the start-up alignment leaves it).
    pub fn new(count: u32, counts_per_rev: u32, pole_pairs: u32) -> Self {
        Self {
            counts_per_rev: counts_per_rev.clamp(1, i32::MAX as u32) as i32,
            pole_pairs,
            last: count,
            in_rev: 0,
        }
    }

    /// Takes the counter value `count` and returns the electrical angle in (−π, π].
    pub fn update(&mut self, count: u32) -> f32 {
        let d = count.wrapping_sub(self.last) as i32;
        self.last = count;
        // |d| per 50 µs tick is far below counts_per_rev: one rem_euclid is exact.
        self.in_rev = (self.in_rev.wrapping_add(d)).rem_euclid(self.counts_per_rev);
        // Position within the electrical turn, in counts: (in_rev · p) mod cpr — in 32 bits
        // (hardware divide) when cpr · p fits, as for every real encoder and motor.
        let cpr = self.counts_per_rev as u32;
        let e = match (self.in_rev as u32).checked_mul(self.pole_pairs) {
            Some(m) => m % cpr,
            None => ((self.in_rev as u64 * u64::from(self.pole_pairs)) % u64::from(cpr)) as u32,
        };
        let frac = e as f32 / cpr as f32;
        if frac > 0.5 {
            (frac - 1.0) * TAU
        } else {
            frac * TAU
        }
    }
}

/// q-axis current from two phase currents at electrical angle `(sin θ, cos θ)`.
pub fn iq_from_phases(ia: f32, ib: f32, (s, c): (f32, f32)) -> f32 {
    let alpha = ia;
    let beta = (ia + 2.0 * ib) * INV_SQRT3;
    -alpha * s + beta * c
}

/// The three phase voltages (star point reference) for `v_q` at `(sin θ, cos θ)`, `v_d` = 0.
pub fn phase_voltages(vq: f32, (s, c): (f32, f32)) -> [f32; 3] {
    let alpha = -vq * s;
    let beta = vq * c;
    [
        alpha,
        -0.5 * alpha + SQRT3_2 * beta,
        -0.5 * alpha - SQRT3_2 * beta,
    ]
}

/// Space-vector duties (0..1, high-side on-time fraction) of the phase voltages `v` on a
/// bus of `vbus`, each clamped to `[1 − max_duty, max_duty]`.
///
/// `v` is first scaled down, keeping its angle, if it lies beyond what the clamp allows —
/// so an over-large `v_q` saturates in amplitude rather than distorting the vector.
pub fn svpwm(v: [f32; 3], vbus: f32, max_duty: f32) -> [f32; 3] {
    let max = v[0].max(v[1]).max(v[2]);
    let min = v[0].min(v[1]).min(v[2]);
    // After zero-sequence injection the phases span [−(max − min)/2, (max − min)/2].
    let half_span = 0.5 * (max - min);
    let room = (max_duty - 0.5) * vbus;
    let k = if half_span > room && half_span > 0.0 {
        room / half_span
    } else {
        1.0
    };
    let offset = -0.5 * (max + min);
    let lo = 1.0 - max_duty;
    v.map(|x| (0.5 + k * (x + offset) / vbus).clamp(lo, max_duty))
}

#[cfg(test)]
mod tests {
    //! Host check: `rustc --edition 2021 --test src/foc.rs -o /tmp/foc && /tmp/foc`.
    use super::*;

    #[test]
    fn sin_cos_matches_std() {
        let mut x = -20.0f32;
        while x < 20.0 {
            let (s, c) = sin_cos(x);
            assert!((s - x.sin()).abs() < 2e-6, "sin {x}");
            assert!((c - x.cos()).abs() < 2e-6, "cos {x}");
            x += 0.001;
        }
    }

    #[test]
    fn angle_tracks_through_the_counter_wrap() {
        let mut a = ElecAngle::new(u32::MAX - 10, 10_000, 4);
        assert_eq!(a.update(u32::MAX - 10), 0.0);
        // A quarter motor revolution = one electrical turn at 4 pole pairs.
        let e = a.update((u32::MAX - 10).wrapping_add(2_500));
        assert!(e.abs() < 1e-6, "{e}");
        // An eighth of an electrical turn forward: π/4.
        let e = a.update((u32::MAX - 10).wrapping_add(2_500 + 312));
        assert!((e - PI / 4.0 * 312.0 / 312.5).abs() < 1e-5, "{e}");
        // Backwards past zero.
        let e = a.update((u32::MAX - 10).wrapping_sub(625));
        assert!((e + FRAC_PI_2).abs() < 1e-5, "{e}");
    }

    #[test]
    fn park_inverts_the_modulation() {
        // The currents of a balanced load in phase with the voltages give i_q = v_q / R.
        for k in 0..64 {
            let th = k as f32 * 0.1;
            let sc = sin_cos(th);
            let v = phase_voltages(3.0, sc);
            assert!((v[0] + v[1] + v[2]).abs() < 1e-5);
            let iq = iq_from_phases(v[0] / 0.5, v[1] / 0.5, sc);
            assert!((iq - 6.0).abs() < 1e-4, "{th}: {iq}");
        }
    }

    #[test]
    fn svpwm_keeps_line_voltages_and_clamps() {
        let v = phase_voltages(10.0, sin_cos(0.7));
        let d = svpwm(v, 48.0, 0.9);
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            let line = (d[i] - d[j]) * 48.0;
            assert!((line - (v[i] - v[j])).abs() < 1e-4);
        }
        // Centred: max and min duty equidistant from 0.5.
        let (mx, mn) = (d[0].max(d[1]).max(d[2]), d[0].min(d[1]).min(d[2]));
        assert!((mx + mn - 1.0).abs() < 1e-6);
        // Linear up to |v| = 0.4 · 48 V · 2/√3 ≈ 22.2 V; beyond, scaled, angle kept.
        let big = phase_voltages(48.0, sin_cos(0.7));
        let d = svpwm(big, 48.0, 0.9);
        assert!(d.iter().all(|&x| (0.1 - 1e-6..=0.9 + 1e-6).contains(&x)));
        let r = (d[0] - d[1]) / (d[1] - d[2]);
        let r0 = (big[0] - big[1]) / (big[1] - big[2]);
        assert!((r - r0).abs() < 1e-4);
    }
}
