//! A robot joint module driven by a BLDC motor through a harmonic-drive-like gear: the
//! plant of the CiA402 joint drive (`oxicat_devices::cia402`).
//!
//! * **Motor** (q-axis model of a field-oriented BLDC): `L di/dt = v − R i − k_e ω_m`,
//!   torque `k_t i`; with the bridge off the current is 0 (the motor coasts).
//! * **Rotor**: `J_m ω̇_m = k_t i − b_m ω_m − τ_c sat(ω_m/ε) − τ_g / N` (viscous and
//!   Coulomb friction, the latter regularised over ±ε so the step is deterministic and
//!   smooth).
//! * **Gear** (ratio `N`, compliant like a flexspline): a two-mass model, output torque
//!   `τ_g = K (θ_m/N − θ_l) + c (ω_m/N − ω_l)`.
//! * **Link**: `J_l ω̇_l = τ_g − b_l ω_l + τ_ext`.
//! * **Sensors**: a motor encoder (`counts_per_rev` increments per motor revolution) with an
//!   index pulse once per motor revolution at `index_angle`; a joint torque sensor reading
//!   `τ_g`; a home switch on the joint, active for `θ_l > home_angle`.
//!
//! Integration: semi-implicit Euler in `f64` with fixed substeps of at most
//! [`BLDC_SUBSTEP`]; a run is a function of the inputs only.

use core::f64::consts::TAU;

/// Largest integration substep \[s\].
pub const BLDC_SUBSTEP: f64 = 5e-6;

/// Parameters of the joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BldcJointParams {
    /// Torque constant \[N·m/A\] (= back-EMF constant \[V·s/rad\]).
    pub kt: f64,
    /// Winding resistance (q axis) \[Ω\].
    pub resistance: f64,
    /// Winding inductance (q axis) \[H\].
    pub inductance: f64,
    /// Rotor inertia (with the wave generator) \[kg·m²\].
    pub rotor_inertia: f64,
    /// Motor viscous friction \[N·m·s/rad\].
    pub viscous: f64,
    /// Motor Coulomb friction \[N·m\].
    pub coulomb: f64,
    /// Velocity over which Coulomb friction is regularised \[rad/s\].
    pub coulomb_band: f64,
    /// Gear ratio (motor turns per output turn).
    pub ratio: f64,
    /// Gear torsional stiffness, output side \[N·m/rad\].
    pub stiffness: f64,
    /// Gear torsional damping, output side \[N·m·s/rad\].
    pub damping: f64,
    /// Link inertia about the joint axis \[kg·m²\].
    pub link_inertia: f64,
    /// Link (output bearing) viscous friction \[N·m·s/rad\].
    pub link_viscous: f64,
    /// Encoder increments per motor revolution.
    pub counts_per_rev: u32,
    /// Motor angle of the index pulse within a revolution \[rad\].
    pub index_angle: f64,
    /// Joint angle above which the home switch is active \[rad\].
    pub home_angle: f64,
}

impl Default for BldcJointParams {
    /// A mid-size robot joint: 48 V BLDC (k_t 0.05 N·m/A, 0.5 Ω, 0.3 mH), ratio 100,
    /// 20 kN·m/rad gear, 0.5 kg·m² link, 16384-count encoder, index at 0.3 rad, home
    /// switch above 0.1 rad joint angle.
    fn default() -> Self {
        Self {
            kt: 0.05,
            resistance: 0.5,
            inductance: 0.3e-3,
            rotor_inertia: 1.0e-5,
            viscous: 2.0e-6,
            coulomb: 2.0e-3,
            coulomb_band: 0.5,
            ratio: 100.0,
            stiffness: 20_000.0,
            damping: 5.0,
            link_inertia: 0.5,
            link_viscous: 0.5,
            counts_per_rev: 16_384,
            index_angle: 0.3,
            home_angle: 0.1,
        }
    }
}

/// The joint.
#[derive(Debug, Clone, PartialEq)]
pub struct BldcJoint {
    /// Parameters.
    pub params: BldcJointParams,
    /// q-axis current \[A\].
    pub current: f64,
    /// Motor angle \[rad\].
    pub motor_angle: f64,
    /// Motor velocity \[rad/s\].
    pub motor_velocity: f64,
    /// Link (joint output) angle \[rad\].
    pub link_angle: f64,
    /// Link velocity \[rad/s\].
    pub link_velocity: f64,
    /// External torque on the link \[N·m\].
    pub external_torque: f64,
    /// Locks the link (a mechanical stop or a held brake) when set.
    pub link_locked: bool,
    bridge_on: bool,
    voltage: f64,
    index_latch: Option<i32>,
}

impl BldcJoint {
    /// A joint at rest at angle 0.
    pub fn new(params: BldcJointParams) -> Self {
        Self {
            params,
            current: 0.0,
            motor_angle: 0.0,
            motor_velocity: 0.0,
            link_angle: 0.0,
            link_velocity: 0.0,
            external_torque: 0.0,
            link_locked: false,
            bridge_on: false,
            voltage: 0.0,
            index_latch: None,
        }
    }

    /// Puts the joint at rest at motor angle `motor` (link angle `motor / N`, gear unloaded).
    pub fn place(&mut self, motor: f64) {
        self.motor_angle = motor;
        self.link_angle = motor / self.params.ratio;
        self.motor_velocity = 0.0;
        self.link_velocity = 0.0;
        self.current = 0.0;
    }

    /// Sets the bridge: off (coast) or on with `volts` on the q axis.
    pub fn set_voltage(&mut self, enable: bool, volts: f64) {
        self.bridge_on = enable;
        self.voltage = volts;
    }

    /// Gear (joint) torque \[N·m\]: what the joint torque sensor measures.
    pub fn gear_torque(&self) -> f64 {
        let p = &self.params;
        p.stiffness * (self.motor_angle / p.ratio - self.link_angle)
            + p.damping * (self.motor_velocity / p.ratio - self.link_velocity)
    }

    /// The encoder counter (increments, wraps like a 32-bit hardware counter).
    pub fn encoder_count(&self) -> i32 {
        let c = (self.motor_angle / TAU * self.params.counts_per_rev as f64).floor();
        c as i64 as i32
    }

    /// Motor angle in counts, unrounded.
    pub fn motor_counts(&self) -> f64 {
        self.motor_angle / TAU * self.params.counts_per_rev as f64
    }

    /// Takes the counter value latched at the last index pulse.
    pub fn take_index_latch(&mut self) -> Option<i32> {
        self.index_latch.take()
    }

    /// The home switch.
    pub fn home_switch(&self) -> bool {
        self.link_angle > self.params.home_angle
    }

    fn index_rev(&self, angle: f64) -> f64 {
        ((angle - self.params.index_angle) / TAU).floor()
    }

    /// Advances by `dt` in fixed substeps.
    pub fn step(&mut self, dt: f64) {
        let n = (dt / BLDC_SUBSTEP).ceil().max(1.0) as usize;
        let h = dt / n as f64;
        for _ in 0..n {
            self.substep(h);
        }
    }

    fn substep(&mut self, h: f64) {
        let p = self.params;
        if self.bridge_on {
            // Exact for the R-L part, so large R·h/L stays stable.
            let tau = p.inductance / p.resistance;
            let i_inf = (self.voltage - p.kt * self.motor_velocity) / p.resistance;
            self.current = i_inf + (self.current - i_inf) * (-h / tau).exp();
        } else {
            self.current = 0.0;
        }
        let tg = self.gear_torque();
        let friction = p.viscous * self.motor_velocity
            + p.coulomb * (self.motor_velocity / p.coulomb_band).clamp(-1.0, 1.0);
        let am = (p.kt * self.current - friction - tg / p.ratio) / p.rotor_inertia;
        self.motor_velocity += am * h;
        let before = self.motor_angle;
        self.motor_angle += self.motor_velocity * h;
        if self.link_locked {
            self.link_velocity = 0.0;
        } else {
            let al =
                (tg - p.link_viscous * self.link_velocity + self.external_torque) / p.link_inertia;
            self.link_velocity += al * h;
            self.link_angle += self.link_velocity * h;
        }
        // Index pulse: the motor angle crossed index_angle + k·2π.
        let (r0, r1) = (self.index_rev(before), self.index_rev(self.motor_angle));
        if r0 != r1 {
            let k = r0.max(r1);
            let a = p.index_angle + k * TAU;
            let c = (a / TAU * p.counts_per_rev as f64).floor();
            self.index_latch = Some(c as i64 as i32);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_voltage_spins_up_to_the_back_emf_speed() {
        let mut j = BldcJoint::new(BldcJointParams {
            coulomb: 0.0,
            viscous: 0.0,
            link_viscous: 0.0,
            ..BldcJointParams::default()
        });
        j.set_voltage(true, 5.0);
        for _ in 0..4000 {
            j.step(1e-3);
        }
        // No load torque: the motor settles where k_e ω = v.
        assert!(
            (j.motor_velocity - 5.0 / 0.05).abs() < 1.0,
            "{}",
            j.motor_velocity
        );
        assert!((j.link_velocity - j.motor_velocity / 100.0).abs() < 0.02);
    }

    #[test]
    fn index_pulse_latches_once_per_revolution() {
        let mut j = BldcJoint::new(BldcJointParams {
            coulomb: 0.0,
            viscous: 0.0,
            link_viscous: 0.0,
            ..BldcJointParams::default()
        });
        j.motor_velocity = 10.0;
        j.link_velocity = 0.1;
        j.step(0.02); // 0.2 rad: not yet at 0.3
        assert_eq!(j.take_index_latch(), None);
        j.step(0.02); // 0.4 rad: crossed 0.3
        let l = j.take_index_latch().unwrap();
        assert_eq!(l, (0.3 / TAU * 16384.0f64).floor() as i32);
    }

    #[test]
    fn locked_link_loads_the_torque_sensor() {
        let mut j = BldcJoint::new(BldcJointParams::default());
        j.link_locked = true;
        j.set_voltage(true, 1.0);
        for _ in 0..500 {
            j.step(1e-3);
        }
        // At rest the gear carries N·k_t·i.
        let expect = 100.0 * 0.05 * j.current;
        assert!((j.gear_torque() - expect).abs() < 0.05 * expect.abs() + 0.01);
        assert!(j.motor_velocity.abs() < 0.1);
    }
}
