//! The leg: two drives (amplifier, motor, gearhead, coupler, pulley, encoder), the planar
//! two-link Lagrangian dynamics and the treadmill contact, stepped together.

use crate::body::HipMotion;
use crate::encoder::Encoder;
use crate::gear;
use crate::motor::{AmplifierParams, MotorParams};

/// `x.ceil()` without the libm call the baseline x86-64 target makes for it (no SSE4.1
/// `roundsd`): the same value for every `x` (the sign of a zero aside, which `max(1.0)`
/// drops where it is used); called once per substep.
#[inline]
pub(crate) fn ceil(x: f64) -> f64 {
    // Below 2^52 in magnitude the truncation is exact in i64 and back in f64; beyond,
    // every f64 is an integer already (and NaN/inf go to the library too).
    if x.abs() < 4_503_599_627_370_496.0 {
        let i = x as i64 as f64;
        if i < x {
            i + 1.0
        } else {
            i
        }
    } else {
        x.ceil()
    }
}

/// Standard gravity [m/s²].
pub const GRAVITY: f64 = 9.81;

/// Default integration substep: 50 µs (20 kHz), twice the firmware's 10 kHz joint loop.
pub const SUBSTEP: f64 = 50e-6;

/// Which leg of the robot: decides the mirrored motor and encoder sign.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Left leg: motor/encoder positive = positive thesis angle (firmware `LEFT_LEG`).
    Left,
    /// Right leg: motor/encoder positive = negative thesis angle (firmware `RIGHT_LEG`).
    Right,
}

impl Side {
    /// +1 for the left leg, −1 for the right leg: motor angle = sign · ratio · joint angle.
    pub fn sign(self) -> f64 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }
}

/// Joint index into the per-joint arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Joint {
    /// Hip (θ1, thigh), EC 45 motor.
    Hip = 0,
    /// Knee (θ2, shank), RE 50 motor.
    Knee = 1,
}

/// Mass properties of one link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkParams {
    /// Length, joint to joint (or joint to toe) [m].
    pub length: f64,
    /// Mass [kg].
    pub mass: f64,
    /// Distance of the centre of mass from the proximal joint, along the link [m].
    pub com: f64,
    /// Moment of inertia about the centre of mass [kg·m²].
    pub inertia: f64,
}

impl LinkParams {
    /// Thigh: l1 = 0.25 m (thesis §3.2). Mass 0.6 kg, COM 0.10 m, I = m·l²/12: **plausible
    /// values** (the thesis gives no masses; aluminium/carbon link, motors on the body).
    pub fn laelaps_thigh() -> Self {
        LinkParams {
            length: 0.25,
            mass: 0.6,
            com: 0.10,
            inertia: 0.6 * 0.25 * 0.25 / 12.0,
        }
    }

    /// Shank (virtual lower link with spring and foot): l2 = 0.35 m (thesis §3.2). Mass 0.4 kg,
    /// COM 0.15 m from the knee, I = m·l²/12: **plausible values**.
    pub fn laelaps_shank() -> Self {
        LinkParams {
            length: 0.35,
            mass: 0.4,
            com: 0.15,
            inertia: 0.4 * 0.35 * 0.35 / 12.0,
        }
    }
}

/// One joint's drive train: amplifier → motor → gearhead → coupler → pulley → joint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveParams {
    /// Motor constants.
    pub motor: MotorParams,
    /// Current-controlled amplifier.
    pub amplifier: AmplifierParams,
    /// Gearhead reduction (motor turns per gearhead output turn).
    pub gearhead_ratio: f64,
    /// Pulley reduction (coupler turns per joint turn), 48/26.
    pub pulley_ratio: f64,
    /// Combined gearhead × pulley efficiency; the loss (1 − η)·|τ_motor| acts as extra Coulomb
    /// friction at the motor shaft (always dissipative, also when back-driven).
    pub efficiency: f64,
    /// Coupler slip torque, at the gearhead output [N·m].
    pub coupler_slip_torque: f64,
}

impl DriveParams {
    /// Hip drive: EC 45 136209, GP 52 C 343/8, pulley 48/26, 30 Nm coupler.
    pub fn laelaps_hip() -> Self {
        DriveParams {
            motor: MotorParams::ec45_136209(),
            amplifier: AmplifierParams::default(),
            gearhead_ratio: gear::HIP_GEARHEAD_RATIO,
            pulley_ratio: gear::PULLEY_RATIO,
            efficiency: gear::GEARHEAD_EFFICIENCY * gear::PULLEY_EFFICIENCY,
            coupler_slip_torque: gear::COUPLER_SLIP_TORQUE,
        }
    }

    /// Knee drive: RE 50 370356, GP 52 C 637/12, pulley 48/26, 30 Nm coupler.
    pub fn laelaps_knee() -> Self {
        DriveParams {
            motor: MotorParams::re50_370356(),
            amplifier: AmplifierParams::default(),
            gearhead_ratio: gear::KNEE_GEARHEAD_RATIO,
            pulley_ratio: gear::PULLEY_RATIO,
            efficiency: gear::GEARHEAD_EFFICIENCY * gear::PULLEY_EFFICIENCY,
            coupler_slip_torque: gear::COUPLER_SLIP_TORQUE,
        }
    }

    /// Total reduction motor → joint.
    pub fn ratio(&self) -> f64 {
        self.gearhead_ratio * self.pulley_ratio
    }

    /// Lossless, frictionless variant (for conservation tests).
    pub fn ideal(mut self) -> Self {
        self.motor = self.motor.frictionless();
        self.efficiency = 1.0;
        self
    }
}

/// Foot–belt contact law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactParams {
    /// Normal stiffness [N/m] (rubber foot on belt; plausible).
    pub stiffness: f64,
    /// Normal damping [N·s/m] (plausible).
    pub damping: f64,
    /// Coulomb friction coefficient (rubber on treadmill belt; plausible).
    pub friction: f64,
    /// Slip speed below which friction is regularised linearly [m/s].
    pub reg_speed: f64,
}

impl Default for ContactParams {
    fn default() -> Self {
        ContactParams {
            stiffness: 3.0e4,
            damping: 300.0,
            friction: 0.8,
            reg_speed: 2e-3,
        }
    }
}

/// The treadmill belt under one leg.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Treadmill {
    /// Belt surface speed [m/s]; positive moves the surface toward −x (backwards).
    pub speed: f64,
    /// Depth of the belt surface below the hip axis [m] (y of the surface, y down).
    pub height: f64,
}

impl Default for Treadmill {
    /// Belt at rest, its surface at the flat bottom of the nominal ellipse of Table 4-1
    /// (y centre 0.599 m: flatness 0 makes the stance half the line y = y centre).
    fn default() -> Self {
        Treadmill {
            speed: 0.0,
            height: 0.599,
        }
    }
}

/// Everything that defines one leg.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LegParams {
    /// Left or right (mirrored motors).
    pub side: Side,
    /// Upper link (θ1).
    pub thigh: LinkParams,
    /// Lower virtual link (θ2).
    pub shank: LinkParams,
    /// Hip drive train.
    pub hip: DriveParams,
    /// Knee drive train.
    pub knee: DriveParams,
    /// Foot contact law.
    pub contact: ContactParams,
    /// Belt.
    pub treadmill: Treadmill,
    /// Gravity [m/s²] along +y.
    pub gravity: f64,
    /// Joint angles (θ1, θ2) at start, which is also the encoder reset pose [rad].
    pub initial_angles: [f64; 2],
    /// Integration substep upper bound [s]; `advance(dt)` splits dt into equal substeps ≤ this.
    pub substep: f64,
    /// Encoder edges per unit position event (eQEP UPPS).
    pub encoder_unit_prescaler: u32,
}

impl LegParams {
    /// Laelaps II leg of the given side with the thesis' values (see the crate README).
    pub fn laelaps(side: Side) -> Self {
        LegParams {
            side,
            thigh: LinkParams::laelaps_thigh(),
            shank: LinkParams::laelaps_shank(),
            hip: DriveParams::laelaps_hip(),
            knee: DriveParams::laelaps_knee(),
            contact: ContactParams::default(),
            treadmill: Treadmill::default(),
            gravity: GRAVITY,
            initial_angles: [0.0, 0.0],
            substep: SUBSTEP,
            encoder_unit_prescaler: 32,
        }
    }
}

impl Default for LegParams {
    fn default() -> Self {
        LegParams::laelaps(Side::Left)
    }
}

/// Per-joint drive state.
#[derive(Clone, Debug)]
struct Drive {
    p: DriveParams,
    /// `p.ratio()`, computed once (a drive's parameters do not change after it is built:
    /// the same product, the same bits).
    n: f64,
    /// Motor angle in the joint-aligned frame (= sign · motor shaft angle) [rad].
    psi: f64,
    /// Motor speed in the joint-aligned frame [rad/s].
    w: f64,
    /// Amplifier commanded current (motor frame) [A].
    i_cmd: f64,
    /// Actual current (motor frame) [A].
    i: f64,
    stuck: bool,
    slip_dir: f64,
    coupler_torque: f64,
    encoder: Encoder,
}

/// One simulated leg: drives, links, contact, integrated at a fixed substep.
#[derive(Clone, Debug)]
pub struct Leg {
    p: LegParams,
    sign: f64,
    q: [f64; 2],
    /// `q[k].sin_cos()`, kept with `q`: a substep needs them at its start and the body's
    /// coupling needs the sines before and after it, so each pose's sines and cosines are
    /// computed once instead of three times (the same calls on the same angles: the same
    /// bits).
    trig: [(f64, f64); 2],
    v: [f64; 2],
    d: [Drive; 2],
    time: f64,
    contact_force: [f64; 2],
    alpha_h: f64,
    alpha: [f64; 2],
    /// The hip's motion with the body (zero: hip fixed, the old single-leg rig).
    hip: HipMotion,
    // Constant mass-matrix terms.
    m_a: f64,
    m_b: f64,
    m_d: f64,
    g1: f64,
    g2: f64,
    // Gravity terms per unit acceleration (g1 = gravity · g1m).
    g1m: f64,
    g2m: f64,
}

impl Leg {
    /// A leg at rest at `params.initial_angles`, couplers stuck, encoders zeroed there.
    pub fn new(params: LegParams) -> Self {
        let sign = params.side.sign();
        let (t, s) = (params.thigh, params.shank);
        let m_a = t.inertia + t.mass * t.com * t.com + s.mass * t.length * t.length;
        let m_b = s.mass * t.length * s.com;
        let m_d = s.inertia + s.mass * s.com * s.com;
        let g1m = t.mass * t.com + s.mass * t.length;
        let g2m = s.mass * s.com;
        let g1 = params.gravity * g1m;
        let g2 = params.gravity * s.mass * s.com;
        let mk = |dp: DriveParams, q: f64| {
            let psi = dp.ratio() * q;
            Drive {
                p: dp,
                n: dp.ratio(),
                psi,
                w: 0.0,
                i_cmd: 0.0,
                i: 0.0,
                stuck: true,
                slip_dir: 1.0,
                coupler_torque: 0.0,
                encoder: Encoder::new(sign * psi, params.encoder_unit_prescaler),
            }
        };
        let q = params.initial_angles;
        Leg {
            p: params,
            sign,
            q,
            trig: [q[0].sin_cos(), q[1].sin_cos()],
            v: [0.0; 2],
            d: [mk(params.hip, q[0]), mk(params.knee, q[1])],
            time: 0.0,
            contact_force: [0.0; 2],
            alpha_h: f64::NAN,
            alpha: [0.0; 2],
            hip: HipMotion::default(),
            m_a,
            m_b,
            m_d,
            g1,
            g2,
            g1m,
            g2m,
        }
    }

    /// Moves the hip with the body from the next substep on: the leg frame sees gravity
    /// `g − az` and the belt `z` closer, the foot's speed against the belt gains `vz`
    /// ([`crate::body`]). The default (all zero) is the fixed hip.
    pub fn set_hip_motion(&mut self, m: HipMotion) {
        self.hip = m;
    }

    /// The hip's motion as last set.
    pub fn hip_motion(&self) -> HipMotion {
        self.hip
    }

    /// Vertical momentum (down) of the two links relative to the hip \[kg·m/s\].
    pub fn vertical_momentum(&self) -> f64 {
        let (t, s) = (self.p.thigh, self.p.shank);
        let (s1, s2) = (self.trig[0].0, self.trig[1].0);
        let [v1, v2] = self.v;
        t.mass * (-t.com * s1 * v1) + s.mass * (-t.length * s1 * v1 - s.com * s2 * v2)
    }

    /// The parameters this leg was built with (treadmill as last set).
    pub fn params(&self) -> &LegParams {
        &self.p
    }

    /// Set the amplifier input of one joint: PWM duty in [0, 1] and direction pin.
    pub fn set_duty(&mut self, joint: Joint, duty: f64, dir_negative: bool) {
        let d = &mut self.d[joint as usize];
        d.i_cmd = d.p.amplifier.command(duty, dir_negative);
    }

    /// Set both duties and advance by `dt` (e.g. one 100 µs period of the 10 kHz loop).
    pub fn step(&mut self, dt: f64, duty_hip: f64, dir_hip: bool, duty_knee: f64, dir_knee: bool) {
        self.set_duty(Joint::Hip, duty_hip, dir_hip);
        self.set_duty(Joint::Knee, duty_knee, dir_knee);
        self.advance(dt);
    }

    /// Advance by `dt` [s] in equal substeps no longer than `params.substep`.
    pub fn advance(&mut self, dt: f64) {
        let s = self.split(dt);
        self.run_split(s);
    }

    /// How [`advance`](Self::advance) splits `dt` [s]: `(n, h)`, `n` substeps of `h`
    /// (none for a `dt` that is not positive and finite). A caller advancing by the same
    /// `dt` many times splits it once.
    pub fn split(&self, dt: f64) -> (u64, f64) {
        if dt <= 0.0 || !dt.is_finite() {
            return (0, dt);
        }
        let n = ceil(dt / self.p.substep - 1e-9).max(1.0);
        (n as u64, dt / n)
    }

    /// `(dt / params.substep − 1e-9).ceil().max(1.0) as u64` for any `dt` (a zero or
    /// negative span gives one), without the libm `ceil` call: how many substeps a caller
    /// stepping the leg itself (the body coupling) cuts `dt` into.
    pub fn substep_count(&self, dt: f64) -> u64 {
        ceil(dt / self.p.substep - 1e-9).max(1.0) as u64
    }

    /// Runs a split from [`split`](Self::split): `advance(dt)` is `run_split(split(dt))`.
    pub fn run_split(&mut self, (n, h): (u64, f64)) {
        for _ in 0..n {
            self.substep(h);
        }
    }

    /// Change the belt speed [m/s] (see [`Treadmill::speed`]).
    pub fn set_belt_speed(&mut self, speed: f64) {
        self.p.treadmill.speed = speed;
    }

    /// Replace the treadmill (speed and height).
    pub fn set_treadmill(&mut self, t: Treadmill) {
        self.p.treadmill = t;
    }

    /// Virtual time since construction [s].
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Encoder position counters (hip, knee), relative to the reset pose.
    pub fn encoder_counts(&self) -> [i32; 2] {
        [self.d[0].encoder.count(), self.d[1].encoder.count()]
    }

    /// The encoder of one joint (count, last edge time, unit captures).
    pub fn encoder(&self, joint: Joint) -> &Encoder {
        &self.d[joint as usize].encoder
    }

    /// The encoder of one joint, mutable (to take captures, as firmware clears eQEP flags).
    pub fn encoder_mut(&mut self, joint: Joint) -> &mut Encoder {
        &mut self.d[joint as usize].encoder
    }

    /// Zero both encoders at the present pose (the thesis' Reset button).
    pub fn reset_encoders(&mut self) {
        for d in &mut self.d {
            d.encoder.reset(self.sign * d.psi);
        }
    }

    /// Joint angles (θ1 hip, θ2 knee) in the thesis convention [rad].
    pub fn joint_angles(&self) -> [f64; 2] {
        self.q
    }

    /// Joint speeds (θ1', θ2') [rad/s].
    pub fn joint_speeds(&self) -> [f64; 2] {
        self.v
    }

    /// Motor shaft speeds as the encoders see them (mirrored for a right leg) [rad/s].
    pub fn motor_speeds(&self) -> [f64; 2] {
        [self.sign * self.d[0].w, self.sign * self.d[1].w]
    }

    /// Motor shaft angles as the encoders see them, absolute (zero at joint angle 0) [rad].
    pub fn motor_angles(&self) -> [f64; 2] {
        [self.sign * self.d[0].psi, self.sign * self.d[1].psi]
    }

    /// Motor currents (signed like the amplifier command) [A].
    pub fn motor_currents(&self) -> [f64; 2] {
        [self.d[0].i, self.d[1].i]
    }

    /// Commanded currents (duty × 12 A, signed) [A].
    pub fn commanded_currents(&self) -> [f64; 2] {
        [self.d[0].i_cmd, self.d[1].i_cmd]
    }

    /// Electromagnetic motor torques k_t·i (motor frame) [N·m].
    pub fn motor_torques(&self) -> [f64; 2] {
        [
            self.d[0].p.motor.torque_constant * self.d[0].i,
            self.d[1].p.motor.torque_constant * self.d[1].i,
        ]
    }

    /// Torque transmitted by each coupler during the last substep, joint frame [N·m].
    pub fn coupler_torques(&self) -> [f64; 2] {
        [self.d[0].coupler_torque, self.d[1].coupler_torque]
    }

    /// Torque the pulleys apply to the joints during the last substep [N·m].
    pub fn joint_torques(&self) -> [f64; 2] {
        [
            self.d[0].coupler_torque * self.d[0].p.pulley_ratio,
            self.d[1].coupler_torque * self.d[1].p.pulley_ratio,
        ]
    }

    /// Whether each coupler is slipping.
    pub fn coupler_slipping(&self) -> [bool; 2] {
        [!self.d[0].stuck, !self.d[1].stuck]
    }

    /// Toe position (x, y) in the leg frame [m] (thesis eq. 3-1).
    pub fn toe_position(&self) -> [f64; 2] {
        let (l1, l2) = (self.p.thigh.length, self.p.shank.length);
        let (s1, c1) = self.q[0].sin_cos();
        let (s2, c2) = self.q[1].sin_cos();
        [l1 * s1 + l2 * s2, l1 * c1 + l2 * c2]
    }

    /// Toe velocity (ẋ, ẏ) [m/s].
    pub fn toe_velocity(&self) -> [f64; 2] {
        let j = self.jacobian();
        [
            j[0][0] * self.v[0] + j[0][1] * self.v[1],
            j[1][0] * self.v[0] + j[1][1] * self.v[1],
        ]
    }

    /// Toe Jacobian ∂(x, y)/∂(θ1, θ2), row-major.
    pub fn jacobian(&self) -> [[f64; 2]; 2] {
        let (l1, l2) = (self.p.thigh.length, self.p.shank.length);
        let (s1, c1) = self.q[0].sin_cos();
        let (s2, c2) = self.q[1].sin_cos();
        [[l1 * c1, l2 * c2], [-l1 * s1, -l2 * s2]]
    }

    /// Force of the belt on the foot (Fx, Fy) in the leg frame during the last substep [N]
    /// (Fy ≤ 0: the belt pushes up).
    pub fn contact_force(&self) -> [f64; 2] {
        self.contact_force
    }

    /// Generalised gravity torques on (θ1, θ2) at the present pose, hip fixed [N·m].
    pub fn gravity_torque(&self) -> [f64; 2] {
        [-self.g1 * self.q[0].sin(), -self.g2 * self.q[1].sin()]
    }

    /// Leg mass matrix (links only, no reflected motor inertia) at the present pose.
    pub fn mass_matrix(&self) -> [[f64; 2]; 2] {
        let off = self.m_b * (self.q[0] - self.q[1]).cos();
        [[self.m_a, off], [off, self.m_d]]
    }

    /// Kinetic + potential energy of links and motor rotors [J] (potential zero at the hip).
    pub fn mechanical_energy(&self) -> f64 {
        let m = self.mass_matrix();
        let v = self.v;
        let kin_links =
            0.5 * (m[0][0] * v[0] * v[0] + 2.0 * m[0][1] * v[0] * v[1] + m[1][1] * v[1] * v[1]);
        let kin_rot: f64 = self
            .d
            .iter()
            .map(|d| 0.5 * d.p.motor.inertia * d.w * d.w)
            .sum();
        let pot = -self.g1 * self.q[0].cos() - self.g2 * self.q[1].cos();
        kin_links + kin_rot + pot
    }

    /// Duty and direction that make the motors hold `tau` at the joints in steady state,
    /// with couplers stuck (τ_joint = ratio · k_t · i; friction and efficiency not included).
    pub fn duty_for_joint_torque(&self, tau: [f64; 2]) -> [(f64, bool); 2] {
        let f = |k: usize| {
            let d = &self.d[k];
            let i = self.sign * tau[k] / (d.p.ratio() * d.p.motor.torque_constant);
            ((i.abs() / d.p.amplifier.max_current), i < 0.0)
        };
        [f(0), f(1)]
    }

    fn substep(&mut self, h: f64) {
        if h != self.alpha_h {
            self.alpha_h = h;
            for k in 0..2 {
                let bw = self.d[k].p.amplifier.current_bandwidth;
                self.alpha[k] = 1.0 - (-h * 2.0 * core::f64::consts::PI * bw).exp();
            }
        }
        let sign = self.sign;

        // 1. Amplifiers: first-order current loop, clamped by what the supply can push
        //    against the back-EMF.
        let mut tau_em = [0.0; 2];
        for (k, (d, tau)) in self.d.iter_mut().zip(tau_em.iter_mut()).enumerate() {
            let (lo, hi) = d.p.amplifier.current_window(&d.p.motor, sign * d.w);
            let target = d.i_cmd.clamp(lo, hi);
            d.i += (target - d.i) * self.alpha[k];
            d.i = d.i.clamp(lo, hi);
            *tau = sign * d.p.motor.torque_constant * d.i;
        }

        // 2. Leg kinematics and Lagrangian terms (absolute angles).
        let (l1, l2) = (self.p.thigh.length, self.p.shank.length);
        let [(s1, c1), (s2, c2)] = self.trig;
        let sd = s1 * c2 - c1 * s2; // sin(θ1 − θ2)
        let cd = c1 * c2 + s1 * s2; // cos(θ1 − θ2)
        let [v1, v2] = self.v;
        let m12 = self.m_b * cd;
        let cor = [self.m_b * sd * v2 * v2, -self.m_b * sd * v1 * v1];
        // A moving hip: gravity g − a_hip in the leg frame (the fixed hip keeps g1, g2 bit
        // for bit).
        let (g1, g2) = if self.hip.az == 0.0 {
            (self.g1, self.g2)
        } else {
            let g = self.p.gravity - self.hip.az;
            (g * self.g1m, g * self.g2m)
        };
        let grav = [-g1 * s1, -g2 * s2];
        let jx = [l1 * c1, l2 * c2];
        let jy = [-l1 * s1, -l2 * s2];
        let y = l1 * c1 + l2 * c2;
        let xd = jx[0] * v1 + jx[1] * v2;
        let yd = jy[0] * v1 + jy[1] * v2;

        // 3. Contact: spring-damper normal force (no pull), regularised Coulomb friction.
        let cp = self.p.contact;
        let tm = self.p.treadmill;
        let (mut fx, mut fy, mut dx, mut dy) = (0.0, 0.0, 0.0, 0.0);
        let moving = self.hip.z != 0.0 || self.hip.vz != 0.0;
        let pen = if moving {
            y - (tm.height - self.hip.z)
        } else {
            y - tm.height
        };
        if pen > 0.0 {
            // The foot's vertical speed against the belt (the belt does not move vertically).
            let yd_belt = if moving { yd + self.hip.vz } else { yd };
            let fn_raw = cp.stiffness * pen + cp.damping * yd_belt;
            if fn_raw > 0.0 {
                fy = -fn_raw;
                dy = cp.damping;
                let vs = xd + tm.speed; // foot speed relative to the belt surface (at −speed)
                let lim = cp.friction * fn_raw;
                if vs > cp.reg_speed {
                    fx = -lim;
                } else if vs < -cp.reg_speed {
                    fx = lim;
                } else {
                    let slope = lim / cp.reg_speed;
                    fx = -slope * vs;
                    dx = slope;
                }
            }
        }
        self.contact_force = [fx, fy];

        // Common part of the linear system (M + h·D) Δv = h·b.
        let base_a = [
            [
                self.m_a + h * (dx * jx[0] * jx[0] + dy * jy[0] * jy[0]),
                m12 + h * (dx * jx[0] * jx[1] + dy * jy[0] * jy[1]),
            ],
            [
                0.0,
                self.m_d + h * (dx * jx[1] * jx[1] + dy * jy[1] * jy[1]),
            ],
        ];
        let base_b = [
            grav[0] - cor[0] + jx[0] * fx + jy[0] * fy,
            grav[1] - cor[1] + jx[1] * fx + jy[1] * fy,
        ];

        // 4. Drive friction (plus gear losses as load-dependent Coulomb friction).
        let mut fr = [(0.0, 0.0); 2];
        for k in 0..2 {
            let d = &self.d[k];
            let extra = (1.0 - d.p.efficiency) * tau_em[k].abs();
            fr[k] = d.p.motor.friction(d.w, extra);
        }

        // 5. Solve with the present stick/slip states; break stuck couplers that would need
        //    more than the slip torque and solve again (at most twice more).
        let mut dv = [0.0; 2];
        for _ in 0..3 {
            let mut a = base_a;
            let mut b = base_b;
            for k in 0..2 {
                let d = &self.d[k];
                let n = d.n;
                if d.stuck {
                    a[k][k] += n * n * (d.p.motor.inertia + h * fr[k].1);
                    b[k] += n * (tau_em[k] - fr[k].0);
                } else {
                    b[k] += d.p.pulley_ratio * d.slip_dir * d.p.coupler_slip_torque;
                }
            }
            let a10 = a[0][1];
            let det = a[0][0] * a[1][1] - a[0][1] * a10;
            dv = [
                h * (a[1][1] * b[0] - a[0][1] * b[1]) / det,
                h * (a[0][0] * b[1] - a10 * b[0]) / det,
            ];
            let mut changed = false;
            for k in 0..2 {
                let d = &mut self.d[k];
                if !d.stuck {
                    continue;
                }
                let n = d.n;
                let dw = n * dv[k];
                // Coupler torque at the gearhead output from the motor-side balance.
                let tc = d.p.gearhead_ratio
                    * (tau_em[k] - fr[k].0 - fr[k].1 * dw - d.p.motor.inertia * dw / h);
                if tc.abs() > d.p.coupler_slip_torque {
                    d.stuck = false;
                    d.slip_dir = if tc > 0.0 { 1.0 } else { -1.0 };
                    changed = true;
                } else {
                    d.coupler_torque = tc;
                }
            }
            if !changed {
                break;
            }
        }

        // 6. Velocities: joints, then motors (rigid when stuck, own dynamics when slipping).
        let mut vn = [v1 + dv[0], v2 + dv[1]];
        let mdiag = [self.m_a, self.m_d];
        let mut wn = [0.0; 2];
        for k in 0..2 {
            let d = &mut self.d[k];
            let n = d.n;
            if d.stuck {
                wn[k] = n * vn[k];
                continue;
            }
            let tc = d.slip_dir * d.p.coupler_slip_torque;
            d.coupler_torque = tc;
            let jm = d.p.motor.inertia;
            let w = d.w + h * (tau_em[k] - fr[k].0 - tc / d.p.gearhead_ratio) / (jm + h * fr[k].1);
            let v_rel = w / d.p.gearhead_ratio - d.p.pulley_ratio * vn[k];
            if v_rel * d.slip_dir <= 0.0 {
                // Relative motion stopped: re-stick with an inelastic merge on this axis.
                let jr = jm * n * n;
                let vc = (jr * (w / n) + mdiag[k] * vn[k]) / (jr + mdiag[k]);
                vn[k] = vc;
                wn[k] = n * vc;
                d.stuck = true;
            } else {
                wn[k] = w;
            }
        }

        // 7. Positions (semi-implicit Euler) and encoders.
        self.v = vn;
        self.q[0] += h * vn[0];
        self.q[1] += h * vn[1];
        self.trig = [self.q[0].sin_cos(), self.q[1].sin_cos()];
        let t0 = self.time;
        for (d, &w) in self.d.iter_mut().zip(wn.iter()) {
            let psi0 = d.psi;
            d.w = w;
            d.psi += h * w;
            d.encoder.update(sign * psi0, sign * d.psi, t0, h);
        }
        self.time += h;
    }
}

#[cfg(test)]
mod tests {
    use super::{Leg, LegParams};

    /// `split` cuts a span into equal substeps no longer than the bound (a hair over it is
    /// one substep), covering it; nothing for a span that is not positive and finite; and
    /// a split's own substep splits into itself (what the body coupling relies on when it
    /// splits once per tick).
    #[test]
    fn split_cuts_into_equal_bounded_substeps() {
        let leg = Leg::new(LegParams::default());
        let s = leg.params().substep;
        for dt in [
            s,
            s * (1.0 + 1e-12),
            s * 1.5,
            2.0 * s,
            99_990e-9,
            100_000e-9,
            1e-3,
            1e-7,
        ] {
            let (n, h) = leg.split(dt);
            assert!(n >= 1 && h <= s * (1.0 + 1e-9), "{dt}: {n} × {h}");
            assert!(
                (n as f64 * h - dt).abs() <= 1e-15 * dt.max(1.0),
                "{dt}: {n} × {h}"
            );
            assert!(
                n == 1 || h > s / 2.0 * 0.999,
                "{dt}: no more substeps than needed"
            );
            assert_eq!(leg.split(h), (1, h), "{dt}");
        }
        for dt in [0.0, -1e-4, f64::NAN, f64::INFINITY] {
            assert_eq!(leg.split(dt).0, 0, "{dt}");
        }
    }

    /// The substep count's `ceil` is `f64::ceil` (zero's sign aside) on ordinary values,
    /// halves, integers, both sides of 2^52 and the specials.
    #[test]
    fn ceil_is_the_library_ceil() {
        let big = 4_503_599_627_370_496.0f64;
        let mut xs = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.0 - 1e-9,
            2.0 - 1e-9,
            1.0 + f64::EPSILON,
            -1.5,
            big,
            -big,
            big - 0.5,
            -(big - 0.5),
            big + 2.0,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MIN_POSITIVE,
        ];
        let mut x = 1e-12f64;
        while x < 1e18 {
            xs.extend([x, -x, x * 1.37, -x * 1.37]);
            x *= 3.1;
        }
        for x in xs {
            let (a, b) = (super::ceil(x), x.ceil());
            assert!(a == b || a.is_nan() && b.is_nan(), "{x}: {a} against {b}");
        }
        assert!(super::ceil(f64::NAN).is_nan());
    }

    /// `substep_count` is the libm form it replaced in the body coupling, over spans from
    /// nothing to seconds (and the degenerate ones).
    #[test]
    fn substep_count_is_the_library_form() {
        let leg = Leg::new(LegParams::default());
        let sub = leg.params().substep;
        let mut dts = vec![
            0.0,
            -1.0,
            f64::NAN,
            f64::INFINITY,
            sub,
            2.0 * sub,
            sub * (1.0 + 1e-12),
        ];
        let mut s = 0x1234_5678_9ABC_DEF1u64;
        for _ in 0..100_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            // Spans in whole nanoseconds as the rig has them, up to 10 ms, and any bits.
            dts.push((s % 10_000_000) as f64 * 1e-9);
            dts.push(f64::from_bits(s));
        }
        for dt in dts {
            let old = (dt / sub - 1e-9).ceil().max(1.0) as u64;
            assert_eq!(leg.substep_count(dt), old, "{dt}");
        }
    }
}
