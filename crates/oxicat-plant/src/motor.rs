//! Motor and current-amplifier parameters (Maxon datasheet-like values) and the amplifier law.

use core::f64::consts::PI;

/// Electrical and mechanical constants of one motor (SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorParams {
    /// Nominal (datasheet) voltage [V].
    pub nominal_voltage: f64,
    /// Torque constant k_t [N·m/A]; equal to the back-EMF constant k_e [V·s/rad] in SI.
    pub torque_constant: f64,
    /// Terminal resistance (phase to phase for the EC motor) [Ω].
    pub resistance: f64,
    /// Rotor inertia plus the gearhead inertia referred to the motor shaft [kg·m²].
    pub inertia: f64,
    /// Coulomb friction torque at the motor shaft [N·m].
    pub coulomb_friction: f64,
    /// Viscous friction coefficient at the motor shaft [N·m·s/rad].
    pub viscous_friction: f64,
    /// Speed below which Coulomb friction is regularised linearly [rad/s].
    pub friction_reg_speed: f64,
    /// Maximum continuous current from the datasheet [A] (informational; the thesis' PWM limits).
    pub nominal_current: f64,
}

/// rpm → rad/s.
pub const RPM: f64 = 2.0 * PI / 60.0;

/// GP 52 C (3-stage) mass inertia referred to its input, 9.1 g·cm² (Maxon catalogue order of
/// magnitude; plausible value).
const GP52C_INERTIA: f64 = 9.1e-7;

impl MotorParams {
    /// Hip motor: Maxon EC 45 Ø45 mm brushless 250 W, part 136209 (thesis §6.10).
    ///
    /// The exact catalogue line for 136209 is not in the thesis; these are **plausible
    /// datasheet-like values** (Maxon catalogue, "EC 45 Ø45 mm, brushless, 250 Watt"):
    /// 48 V winding; nominal current 4.94 A (= the thesis' hip PWM limit 41.17 % × 12 A, which
    /// the thesis derives from the maximum continuous current); torque constant 72.6 mNm/A,
    /// derived from the thesis' "28 Nm after the gearhead" = 12 A · k_t · 42.875 · 0.75;
    /// terminal resistance 0.40 Ω; rotor inertia 209 g·cm²; no-load current ≈ 0.25 A
    /// (→ ≈ 18 mNm friction). No-load speed at 48 V ≈ 48/k_t ≈ 6310 rpm.
    pub const fn ec45_136209() -> Self {
        MotorParams {
            nominal_voltage: 48.0,
            torque_constant: 0.0726,
            resistance: 0.40,
            inertia: 209e-7 + GP52C_INERTIA,
            coulomb_friction: 0.014,
            viscous_friction: 6.0e-6,
            friction_reg_speed: 0.5,
            nominal_current: 4.94,
        }
    }

    /// Knee motor: Maxon RE 50 Ø50 mm graphite brushes 200 W, part 370356 (thesis §6.10).
    ///
    /// **Datasheet-like values** recalled from the Maxon catalogue ("RE 50 Ø50 mm, Graphite
    /// Brushes, 200 Watt", 48 V winding), not printed in the thesis: nominal current 4.58 A
    /// (the thesis' knee PWM limit 38.25 % × 12 A = 4.59 A), torque constant 91.7 mNm/A
    /// (speed constant 104 rpm/V), terminal resistance 0.493 Ω (starting current 97 A, stall
    /// torque 8.9 Nm), rotor inertia 536 g·cm², no-load current ≈ 0.24 A (→ ≈ 22 mNm
    /// friction). No-load speed at 48 V ≈ 4990 rpm.
    pub const fn re50_370356() -> Self {
        MotorParams {
            nominal_voltage: 48.0,
            torque_constant: 0.0917,
            resistance: 0.493,
            inertia: 536e-7 + GP52C_INERTIA,
            coulomb_friction: 0.016,
            viscous_friction: 1.2e-5,
            friction_reg_speed: 0.5,
            nominal_current: 4.58,
        }
    }

    /// Ideal no-load speed at voltage `v` (friction neglected): v / k_e [rad/s].
    pub fn ideal_no_load_speed(&self, v: f64) -> f64 {
        v / self.torque_constant
    }

    /// Same motor without any friction (for tests and idealised studies).
    pub fn frictionless(mut self) -> Self {
        self.coulomb_friction = 0.0;
        self.viscous_friction = 0.0;
        self
    }

    /// Friction torque at shaft speed `w` and its local slope d(τ_f)/dω (for the implicit step).
    #[inline]
    pub(crate) fn friction(&self, w: f64, extra_coulomb: f64) -> (f64, f64) {
        let tc = self.coulomb_friction + extra_coulomb;
        let reg = self.friction_reg_speed;
        let (c, slope_c) = if w > reg {
            (tc, 0.0)
        } else if w < -reg {
            (-tc, 0.0)
        } else {
            (tc * w / reg, tc / reg)
        };
        (
            c + self.viscous_friction * w,
            slope_c + self.viscous_friction,
        )
    }
}

/// Current-controlled PWM amplifier of one joint (thesis: 12 A = 100 % duty).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmplifierParams {
    /// Current at 100 % duty [A] (thesis §6.11: 12 A).
    pub max_current: f64,
    /// Supply voltage [V] (thesis Table 4-1: 40.34 V system supply; 40 V nominal).
    pub supply_voltage: f64,
    /// Closed current-loop bandwidth [Hz], modelled as a first-order lag. 2 kHz is a typical
    /// value for a PWM servo amplifier in current mode (plausible; not in the thesis).
    pub current_bandwidth: f64,
}

impl Default for AmplifierParams {
    fn default() -> Self {
        AmplifierParams {
            max_current: 12.0,
            supply_voltage: 40.0,
            current_bandwidth: 2000.0,
        }
    }
}

impl AmplifierParams {
    /// Commanded current for a duty in [0, 1] and a direction pin (`true` = negative), as the
    /// firmware's DIR GPIO + PWM compare drive it.
    #[inline]
    pub fn command(&self, duty: f64, dir_negative: bool) -> f64 {
        let d = if duty.is_finite() {
            duty.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let i = d * self.max_current;
        if dir_negative {
            -i
        } else {
            i
        }
    }

    /// Range of currents the supply can push against the back-EMF at motor speed `w`:
    /// i ∈ [(−V − k_e·ω)/R, (V − k_e·ω)/R].
    #[inline]
    pub fn current_window(&self, m: &MotorParams, w: f64) -> (f64, f64) {
        let emf = m.torque_constant * w;
        (
            (-self.supply_voltage - emf) / m.resistance,
            (self.supply_voltage - emf) / m.resistance,
        )
    }
}
