//! The robot's body on its treadmill support, coupling the four legs.
//!
//! The body moves vertically (heave `z`, positive **down**, as the leg frame's y) and
//! pitches (`φ`, positive nose **up**); the support mechanism holds it fore–aft and in roll.
//! A hip at `x` ahead of the robot's centre of mass moves down by `z − x·φ`.
//!
//! # How the legs and the body exchange forces (deterministic, lock-step)
//!
//! Time is each leg's time since its release (the four legs are released at the same
//! SYNC0), cut into body steps of [`BodyParams::step_ns`]. A leg integrating a substep
//! that starts in body step `j`:
//!
//! 1. takes its hip's motion of step `j` ([`Body::hip_motion`]: displacement, velocity,
//!    acceleration; constant over the step) — the leg frame then sees gravity `g − a_hip`
//!    and the belt `z_hip` closer;
//! 2. gives the body the vertical impulse it put into the hip over that substep
//!    ([`Body::add_impulse`]): belt force on the foot × substep − the change of the leg
//!    links' own vertical momentum relative to the hip (Newton for the leg: what the belt
//!    pushes and the links do not keep for themselves goes into the hip).
//!
//! The body's motion of step `j` is computed from the impulses of step `j − delay_steps`
//! of **all** legs, in leg order, once every leg has reported that step
//! ([`Body::reached`]). Which leg asks first never changes a number, so a run does not
//! depend on the order the segment wakes the legs in. With the legs stepped every joint
//! loop tick (100 µs) and `delay_steps ≥ 2` every asked-for step is ready; a step asked
//! for before it is (a leg far ahead of the others) gets the last computed motion and is
//! counted in [`Body::late`].
//!
//! Before step `delay_steps` (no impulse yet) the body is held where it was released. The
//! legs' masses are lumped at their hips for the body's motion (translation and pitch);
//! their swing is in the impulses. No allocation after [`Body::new`].

use crate::leg::GRAVITY;

/// Legs on the body.
pub const BODY_LEGS: usize = 4;

/// Ring of body steps kept (computed motions and collected impulses).
const RING: usize = 32;

/// What a hip does during one body step, in the leg frame (y down).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct HipMotion {
    /// Displacement down from where the body was released \[m\].
    pub z: f64,
    /// Velocity down \[m/s\].
    pub vz: f64,
    /// Acceleration down \[m/s²\].
    pub az: f64,
}

/// The body, its support and where the legs attach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyParams {
    /// Mass of the whole robot, legs included \[kg\].
    pub mass: f64,
    /// Pitch inertia of the whole robot about its centre of mass \[kg·m²\].
    pub pitch_inertia: f64,
    /// Hip positions ahead of the centre of mass \[m\] (hind hips negative), per leg.
    pub hip_x: [f64; BODY_LEGS],
    /// Share of the robot's weight the support carries where the body was released (0 … 1).
    pub support_share: f64,
    /// Vertical stiffness of the support about that point \[N/m\].
    pub support_stiffness: f64,
    /// Vertical damping of the support \[N·s/m\].
    pub support_damping: f64,
    /// Pitch stiffness of the support \[N·m/rad\].
    pub pitch_stiffness: f64,
    /// Pitch damping of the support \[N·m·s/rad\].
    pub pitch_damping: f64,
    /// Gravity \[m/s²\].
    pub gravity: f64,
    /// Body step \[ns\].
    pub step_ns: u64,
    /// Body steps between a leg's impulse and the body motion it causes (≥ 1).
    pub delay_steps: u64,
}

impl BodyParams {
    /// Laelaps II on its treadmill support with `mass` kg, fore hips `fore_x` m and hind
    /// hips `hind_x` m (negative) from the centre of mass; the other values are the
    /// **assumptions** the crate README lists (support carrying a fifth of the weight, soft
    /// in heave and pitch, 100 µs steps, 200 µs delay).
    pub fn laelaps(mass: f64, fore_x: f64, hind_x: f64) -> Self {
        let half_length = 0.5 * (fore_x - hind_x);
        BodyParams {
            mass,
            // A uniform box as long as the hip spacing plus 20 %: m·(1.2·2L)²/12.
            pitch_inertia: mass * (2.4 * half_length).powi(2) / 12.0,
            hip_x: [fore_x, fore_x, hind_x, hind_x],
            support_share: 0.2,
            support_stiffness: 2.0e3,
            support_damping: 400.0,
            pitch_stiffness: 200.0,
            pitch_damping: 40.0,
            gravity: GRAVITY,
            step_ns: 100_000,
            delay_steps: 2,
        }
    }
}

/// The body's state and the ring of steps (see the module documentation).
#[derive(Clone, Debug)]
pub struct Body {
    p: BodyParams,
    /// Heave \[m\], heave velocity \[m/s\], pitch \[rad\], pitch rate \[rad/s\] at the start
    /// of step `next`.
    z: f64,
    vz: f64,
    phi: f64,
    w: f64,
    /// The first step whose motion is not computed yet.
    next: u64,
    motion: [[HipMotion; BODY_LEGS]; RING],
    impulse: [[f64; BODY_LEGS]; RING],
    reached_ns: [u64; BODY_LEGS],
    late: u64,
    stats: BodyStats,
}

/// What the body went through (all computed steps since the release).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct BodyStats {
    /// Each leg's impulse into the body (down; a leg carrying weight pushes up, negative)
    /// \[N·s\].
    pub impulse: [f64; BODY_LEGS],
    /// Time those impulses cover \[s\].
    pub time: f64,
    /// Lowest and highest heave (down) \[m\].
    pub z_range: (f64, f64),
    /// Lowest and highest pitch (nose up) \[rad\].
    pub phi_range: (f64, f64),
}

impl BodyStats {
    /// Each leg's mean vertical force carrying the body (up, positive) \[N\].
    pub fn mean_load(&self) -> [f64; BODY_LEGS] {
        let t = self.time.max(1e-12);
        self.impulse.map(|j| -j / t)
    }
}

impl Body {
    /// The body at rest where it is released; `delay_steps` is raised to 1 and kept below
    /// the ring, `step_ns` to 1 µs.
    pub fn new(mut p: BodyParams) -> Self {
        p.delay_steps = p.delay_steps.clamp(1, RING as u64 / 2);
        p.step_ns = p.step_ns.max(1_000);
        Body {
            p,
            z: 0.0,
            vz: 0.0,
            phi: 0.0,
            w: 0.0,
            next: 0,
            motion: [[HipMotion::default(); BODY_LEGS]; RING],
            impulse: [[0.0; BODY_LEGS]; RING],
            reached_ns: [0; BODY_LEGS],
            late: 0,
            stats: BodyStats::default(),
        }
    }

    /// The parameters.
    pub fn params(&self) -> &BodyParams {
        &self.p
    }

    /// The body step containing leg time `t_ns`.
    pub fn step_of(&self, t_ns: u64) -> u64 {
        t_ns / self.p.step_ns
    }

    /// Heave (down) \[m\] and pitch (nose up) \[rad\] at the start of the first step not yet
    /// computed.
    pub fn pose(&self) -> (f64, f64) {
        (self.z, self.phi)
    }

    /// Loads, heave and pitch so far.
    pub fn stats(&self) -> BodyStats {
        self.stats
    }

    /// Starts the figures of [`Body::stats`] afresh from the present pose.
    pub fn reset_stats(&mut self) {
        self.stats = BodyStats {
            z_range: (self.z, self.z),
            phi_range: (self.phi, self.phi),
            ..BodyStats::default()
        };
    }

    /// Body steps computed so far.
    pub fn steps(&self) -> u64 {
        self.next
    }

    /// Steps a leg asked for before every leg had reported what they depend on.
    pub fn late(&self) -> u64 {
        self.late
    }

    /// Leg `leg`'s hip motion during step `j`.
    pub fn hip_motion(&mut self, leg: usize, j: u64) -> HipMotion {
        while self.next <= j && self.ready(self.next) {
            self.compute_next();
        }
        if j < self.next && j + RING as u64 > self.next {
            self.motion[(j % RING as u64) as usize][leg]
        } else {
            self.late += 1;
            let last = self.next.saturating_sub(1);
            self.motion[(last % RING as u64) as usize][leg]
        }
    }

    /// Adds the vertical impulse (down) leg `leg` put into its hip during step `j` \[N·s\].
    pub fn add_impulse(&mut self, leg: usize, j: u64, impulse: f64) {
        if j >= self.next.saturating_sub(self.p.delay_steps) {
            self.impulse[(j % RING as u64) as usize][leg] += impulse;
        }
    }

    /// Leg `leg` has integrated (and reported) everything before its time `t_ns`.
    pub fn reached(&mut self, leg: usize, t_ns: u64) {
        self.reached_ns[leg] = self.reached_ns[leg].max(t_ns);
    }

    /// Whether step `c`'s motion can be computed: the impulses of step `c − delay` are
    /// complete for every leg (and the ring has room).
    fn ready(&self, c: u64) -> bool {
        let d = self.p.delay_steps;
        if c < d {
            return true;
        }
        let done = (c - d + 1) * self.p.step_ns;
        self.reached_ns.iter().all(|&t| t >= done)
    }

    fn compute_next(&mut self) {
        let c = self.next;
        let p = self.p;
        let dt = p.step_ns as f64 * 1e-9;
        let (az, alpha) = if c < p.delay_steps {
            (0.0, 0.0)
        } else {
            let slot = ((c - p.delay_steps) % RING as u64) as usize;
            let mut f = 0.0;
            let mut tau = 0.0;
            for (i, x) in p.hip_x.iter().enumerate() {
                self.stats.impulse[i] += self.impulse[slot][i];
                let fi = self.impulse[slot][i] / dt;
                f += fi;
                tau -= x * fi;
            }
            self.impulse[slot] = [0.0; BODY_LEGS];
            self.stats.time += dt;
            let weight = p.mass * p.gravity;
            let support = p.support_share * weight
                + p.support_stiffness * self.z
                + p.support_damping * self.vz;
            let az = (weight - support + f) / p.mass;
            let alpha =
                (tau - p.pitch_stiffness * self.phi - p.pitch_damping * self.w) / p.pitch_inertia;
            (az, alpha)
        };
        let slot = (c % RING as u64) as usize;
        for (m, x) in self.motion[slot].iter_mut().zip(p.hip_x) {
            *m = HipMotion {
                z: self.z - x * self.phi,
                vz: self.vz - x * self.w,
                az: az - x * alpha,
            };
        }
        // Semi-implicit Euler over the step.
        self.vz += az * dt;
        self.z += self.vz * dt;
        self.w += alpha * dt;
        self.phi += self.w * dt;
        let st = &mut self.stats;
        st.z_range = (st.z_range.0.min(self.z), st.z_range.1.max(self.z));
        st.phi_range = (st.phi_range.0.min(self.phi), st.phi_range.1.max(self.phi));
        self.next = c + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::leg::{Leg, LegParams, Side};

    /// A hip falling with gravity leaves the leg weightless: tilted, it does not swing; a
    /// fixed hip lets it swing. A hip lowered by z meets the belt z earlier.
    #[test]
    fn the_hip_s_motion_reaches_the_leg() {
        let mut p = LegParams::laelaps(Side::Left);
        p.initial_angles = [0.3, 0.3];
        p.treadmill.height = 0.7;
        p.hip = p.hip.ideal();
        p.knee = p.knee.ideal();
        let swing = |az: f64| {
            let mut leg = Leg::new(p);
            leg.set_hip_motion(HipMotion {
                z: 0.0,
                vz: 0.0,
                az,
            });
            leg.advance(0.1);
            (leg.joint_angles()[0] - 0.3).abs()
        };
        assert!(swing(0.0) > 1e-3, "{}", swing(0.0));
        assert!(swing(GRAVITY) < 1e-9, "{}", swing(GRAVITY));
        let mut leg = Leg::new(LegParams::laelaps(Side::Left));
        leg.set_treadmill(crate::leg::Treadmill {
            speed: 0.0,
            height: 0.605,
        });
        leg.advance(1e-4);
        assert_eq!(leg.contact_force(), [0.0, 0.0]);
        leg.set_hip_motion(HipMotion {
            z: 0.01,
            vz: 0.0,
            az: 0.0,
        });
        leg.advance(1e-4);
        assert!(leg.contact_force()[1] < -100.0, "{:?}", leg.contact_force());
    }

    fn params() -> BodyParams {
        BodyParams::laelaps(20.0, 0.35, -0.35)
    }

    /// Four legs each pushing up a quarter of the weight the support does not carry keep
    /// the body where it was released; pushing less lets it sink until the support's
    /// spring makes up the difference.
    #[test]
    fn legs_carrying_their_share_hold_the_body() {
        let p = params();
        let dt = p.step_ns as f64 * 1e-9;
        let share = -(1.0 - p.support_share) * p.mass * p.gravity / 4.0;
        for (push, want_z) in [
            (1.0, 0.0),
            (
                0.5,
                0.5 * (1.0 - p.support_share) * p.mass * p.gravity / p.support_stiffness,
            ),
        ] {
            let mut b = Body::new(p);
            for j in 0..200_000u64 {
                for leg in 0..BODY_LEGS {
                    let _ = b.hip_motion(leg, j);
                    b.add_impulse(leg, j, push * share * dt);
                    b.reached(leg, (j + 1) * p.step_ns);
                }
            }
            assert_eq!(b.late(), 0);
            let (z, phi) = b.pose();
            assert!(
                (z - want_z).abs() < 1e-6,
                "push {push}: z {z}, want {want_z}"
            );
            assert!(phi.abs() < 1e-9, "{phi}");
        }
    }

    /// The hind legs pushing more pitches the body nose down (hind hips up).
    #[test]
    fn hind_legs_pushing_more_pitch_the_nose_down() {
        let p = params();
        let dt = p.step_ns as f64 * 1e-9;
        let mut b = Body::new(p);
        for j in 0..20_000u64 {
            for leg in 0..BODY_LEGS {
                let m = b.hip_motion(leg, j);
                let f = if leg >= 2 { -60.0 } else { -40.0 };
                b.add_impulse(leg, j, f * dt);
                b.reached(leg, (j + 1) * p.step_ns);
                if j == 19_999 && leg == 2 {
                    assert!(m.z < 0.0, "a hind hip rises: {m:?}");
                }
            }
        }
        assert!(b.pose().1 < 0.0, "{:?}", b.pose());
    }

    /// The motion of a step does not depend on which leg asks first, and a step asked for
    /// before the others reported is counted late.
    #[test]
    fn order_of_the_legs_does_not_matter() {
        let p = params();
        let dt = p.step_ns as f64 * 1e-9;
        let run = |order: [usize; BODY_LEGS]| {
            let mut b = Body::new(p);
            let mut out = Vec::new();
            for j in 0..5_000u64 {
                for &leg in &order {
                    let m = b.hip_motion(leg, j);
                    out.push((leg, j, m.z.to_bits(), m.az.to_bits()));
                    let f = -30.0 - 10.0 * leg as f64 + (j as f64 * 1e-2).sin();
                    b.add_impulse(leg, j, f * dt);
                    b.reached(leg, (j + 1) * p.step_ns);
                }
            }
            assert_eq!(b.late(), 0);
            out.sort_unstable();
            out
        };
        assert_eq!(run([0, 1, 2, 3]), run([3, 1, 0, 2]));
        let mut b = Body::new(p);
        for j in 0..10 {
            let _ = b.hip_motion(0, j);
            b.reached(0, (j + 1) * p.step_ns);
        }
        assert!(b.late() > 0);
    }
}
