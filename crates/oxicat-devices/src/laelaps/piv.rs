//! The PIV joint controller: TI C2000 Digital Controller Library `DCL_runPID_C1` as the
//! thesis uses it (§3.6, Figure 3-14; Matlab `PIV_controller`, Appendix 7.3).
//!
//! Per call, with reference `r` and feedback `y` in revolutions (joint frame):
//!
//! ```text
//! v5  = Kr·r − y                                   proportional error
//! v8  = Ki·Kp·i14·(r − y) + i10;   i10 = v8         integrator, frozen while saturated
//! v1  = Kd·c1·y;  v4 = v1 − d2 − d3;  d2 = v1;  d3 = c2·v4
//!                                                   Tustin-filtered derivative of the
//!                                                   *feedback* (the "V" path)
//! v9  = Kp·(v5 − v4) + v8
//! u   = sat(v9, Umin, Umax)
//! i14 = lk · (u == v9)                              anti-windup flag for the next call
//! ```
//!
//! with the first-order filter of bandwidth `f_c`: `τ = 1/(2π f_c)`,
//! `c1 = 2/(T + 2τ)`, `c2 = (T − 2τ)/(T + 2τ)`, `T` the 10 kHz loop period. As in the
//! firmware, gains, filter and limits are reloaded every call, and `Ki = 0` clears the
//! integrator. The output `u` is a signed PWM fraction: direction pin from its sign, duty
//! from its magnitude.

use super::hw::CONTROL_PERIOD_S;
use core::f32::consts::TAU;

/// PIV gains (SI: the thesis' `Kp100/100`, `Kd1000/1000`, `Ki100/100`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Gains {
    /// Proportional gain [PWM fraction per revolution].
    pub kp: f32,
    /// Velocity (derivative) gain \[s\], multiplied by `kp` in the loop.
    pub kd: f32,
    /// Integral gain [1/s], multiplied by `kp` in the loop.
    pub ki: f32,
}

/// `DCL_runPID_C1` state and parameters (the DCL `PID` structure).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidC1 {
    /// Proportional gain.
    pub kp: f32,
    /// Integral gain.
    pub ki: f32,
    /// Derivative (velocity) gain.
    pub kd: f32,
    /// Reference weight (1 in the thesis).
    pub kr: f32,
    /// Derivative filter coefficient c1.
    pub c1: f32,
    /// Derivative filter coefficient c2.
    pub c2: f32,
    /// Upper output limit.
    pub umax: f32,
    /// Lower output limit.
    pub umin: f32,
    /// Derivative path: previous `v1`.
    pub d2: f32,
    /// Derivative path: `c2 ×` previous `v4`.
    pub d3: f32,
    /// Integrator state.
    pub i10: f32,
    /// Anti-windup flag from the previous call (0 or `lk`).
    pub i14: f32,
}

impl Default for PidC1 {
    fn default() -> Self {
        Self::new()
    }
}

/// Filter coefficients `(c1, c2)` for bandwidth `hz` at loop period `period_s`.
pub fn filter_coefficients(hz: f32, period_s: f32) -> (f32, f32) {
    let ftc = 1.0 / (hz * TAU);
    (
        2.0 / (period_s + 2.0 * ftc),
        (period_s - 2.0 * ftc) / (period_s + 2.0 * ftc),
    )
}

impl PidC1 {
    /// The DCL defaults: all gains zero except `Kr = 1`, limits ±1, states zero; then
    /// the thesis sets the filter and limits before each run.
    pub const fn new() -> Self {
        Self {
            kp: 0.0,
            ki: 0.0,
            kd: 0.0,
            kr: 1.0,
            c1: 0.0,
            c2: 0.0,
            umax: 1.0,
            umin: -1.0,
            d2: 0.0,
            d3: 0.0,
            i10: 0.0,
            i14: 0.0,
        }
    }

    /// Loads gains the way the thesis ISR does (`if (!pid.Ki) pid.i10 = 0`).
    pub fn set_gains(&mut self, g: Gains) {
        self.kp = g.kp;
        self.kd = g.kd;
        self.ki = g.ki;
        if self.ki == 0.0 {
            self.i10 = 0.0;
        }
    }

    /// Sets the derivative filter for bandwidth `hz` at period `period_s`.
    pub fn set_filter(&mut self, hz: f32, period_s: f32) {
        let (c1, c2) = filter_coefficients(hz, period_s);
        self.c1 = c1;
        self.c2 = c2;
    }

    /// Symmetric output limits ±`umax`.
    pub fn set_limit(&mut self, umax: f32) {
        self.umax = umax;
        self.umin = -umax;
    }

    /// One controller step (`DCL_runPID_C1(&pid, rk, yk, lk)`).
    pub fn run(&mut self, rk: f32, yk: f32, lk: f32) -> f32 {
        let v5 = self.kr * rk - yk;
        let v8 = (rk - yk) * self.ki * self.kp * self.i14 + self.i10;
        self.i10 = v8;
        let v1 = yk * self.kd * self.c1;
        let v4 = v1 - self.d2 - self.d3;
        self.d2 = v1;
        self.d3 = v4 * self.c2;
        let v9 = self.kp * (v5 - v4) + v8;
        let v10 = if v9 > self.umax {
            self.umax
        } else if v9 < self.umin {
            self.umin
        } else {
            v9
        };
        let v12 = if v10 == v9 { 1.0 } else { 0.0 };
        self.i14 = v12 * lk;
        v10
    }

    /// Clears the dynamic states (derivative path, integrator, anti-windup flag).
    pub fn reset_states(&mut self) {
        self.d2 = 0.0;
        self.d3 = 0.0;
        self.i10 = 0.0;
        self.i14 = 0.0;
    }
}

/// What goes to one motor's amplifier: duty and direction pin.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PwmCommand {
    /// Duty cycle 0..=1 (the thesis' `CMPA = (1 − duty)·SP`, active low).
    pub duty: f32,
    /// Direction pin (`DIRx_GPIO`): false for `u ≥ 0`, true for `u < 0`.
    pub reverse: bool,
}

impl PwmCommand {
    /// Direction + duty of a signed controller output (`u < 0` → pin 1, duty `−u`).
    pub fn from_output(u: f32) -> Self {
        if u >= 0.0 {
            Self {
                duty: u,
                reverse: false,
            }
        } else {
            Self {
                duty: -u,
                reverse: true,
            }
        }
    }

    /// Zero duty (Configuration state: `CMPA = SP`).
    pub const OFF: PwmCommand = PwmCommand {
        duty: 0.0,
        reverse: false,
    };

    /// The signed fraction the command represents.
    pub fn signed(&self) -> f32 {
        if self.reverse {
            -self.duty
        } else {
            self.duty
        }
    }
}

/// Which control law the joint loop runs (a firmware build choice, like the thesis'
/// compile-time output limits; the gains still come through the PDO).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ControlLaw {
    /// The thesis' PIV: `DCL_runPID_C1` (series form, `Kp` multiplies `Ki` and `Kd`).
    #[default]
    Piv,
    /// `DCL_runPID_C4`-style parallel ideal PID ([`PidC4`]).
    DclPid,
}

impl ControlLaw {
    /// `"piv"` or `"dcl-pid"`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "piv" => Some(Self::Piv),
            "dcl-pid" => Some(Self::DclPid),
            _ => None,
        }
    }

    /// The scenario spelling.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Piv => "piv",
            Self::DclPid => "dcl-pid",
        }
    }
}

/// The DCL "C4" PID: parallel ideal form, derivative of the feedback through the same
/// Tustin first-order filter as [`PidC1`], integrator clamped (frozen) while the output
/// saturates. Per call, with `T` the loop period:
///
/// ```text
/// v5  = Kr·r − y                                   proportional error
/// v8  = Ki·T·i14·(r − y) + i10;   i10 = v8          integrator [Ki in 1/s], frozen while saturated
/// v1  = Kd·c1·y;  v4 = v1 − d2 − d3;  d2 = v1;  d3 = c2·v4
///                                                   filtered derivative of the feedback
/// v9  = Kp·v5 + v8 − v4                             parallel sum (Ki, Kd not scaled by Kp)
/// u   = sat(v9, Umin, Umax);   i14 = lk·(u == v9)
/// ```
///
/// Units (joint frame, PWM fraction per revolution): `Kp` [1/rev], `Ki` [1/(rev·s)],
/// `Kd` [s/rev]. With `c1 = 2/(T + 2τ)`, `c2 = (T − 2τ)/(T + 2τ)` the derivative path is
/// `Kd·s/(τs + 1)` discretised by Tustin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidC4 {
    /// Proportional gain.
    pub kp: f32,
    /// Integral gain per second.
    pub ki: f32,
    /// Derivative gain.
    pub kd: f32,
    /// Reference weight of the proportional path.
    pub kr: f32,
    /// Derivative filter coefficient c1.
    pub c1: f32,
    /// Derivative filter coefficient c2.
    pub c2: f32,
    /// Loop period \[s\].
    pub period_s: f32,
    /// Upper output limit.
    pub umax: f32,
    /// Lower output limit.
    pub umin: f32,
    /// Derivative path: previous `v1`.
    pub d2: f32,
    /// Derivative path: `c2 ×` previous `v4`.
    pub d3: f32,
    /// Integrator state.
    pub i10: f32,
    /// Anti-windup flag from the previous call (0 or `lk`).
    pub i14: f32,
}

impl Default for PidC4 {
    fn default() -> Self {
        Self::new()
    }
}

impl PidC4 {
    /// Gains zero, `Kr = 1`, limits ±1, states zero, the 10 kHz period; the anti-windup
    /// flag starts at 1 so the integrator runs from the first call.
    pub const fn new() -> Self {
        Self {
            kp: 0.0,
            ki: 0.0,
            kd: 0.0,
            kr: 1.0,
            c1: 0.0,
            c2: 0.0,
            period_s: CONTROL_PERIOD_S,
            umax: 1.0,
            umin: -1.0,
            d2: 0.0,
            d3: 0.0,
            i10: 0.0,
            i14: 1.0,
        }
    }

    /// Loads gains (`Ki = 0` clears the integrator, as the firmware does for the PIV).
    pub fn set_gains(&mut self, g: Gains) {
        self.kp = g.kp;
        self.kd = g.kd;
        self.ki = g.ki;
        if self.ki == 0.0 {
            self.i10 = 0.0;
        }
    }

    /// Sets the derivative filter for bandwidth `hz` at period `period_s`.
    pub fn set_filter(&mut self, hz: f32, period_s: f32) {
        let (c1, c2) = filter_coefficients(hz, period_s);
        self.c1 = c1;
        self.c2 = c2;
        self.period_s = period_s;
    }

    /// Symmetric output limits ±`umax`.
    pub fn set_limit(&mut self, umax: f32) {
        self.umax = umax;
        self.umin = -umax;
    }

    /// One controller step with reference `rk`, feedback `yk`, anti-windup input `lk`.
    pub fn run(&mut self, rk: f32, yk: f32, lk: f32) -> f32 {
        let v5 = self.kr * rk - yk;
        let v8 = (rk - yk) * self.ki * self.period_s * self.i14 + self.i10;
        self.i10 = v8;
        let v1 = yk * self.kd * self.c1;
        let v4 = v1 - self.d2 - self.d3;
        self.d2 = v1;
        self.d3 = v4 * self.c2;
        let v9 = self.kp * v5 + v8 - v4;
        let v10 = if v9 > self.umax {
            self.umax
        } else if v9 < self.umin {
            self.umin
        } else {
            v9
        };
        let v12 = if v10 == v9 { 1.0 } else { 0.0 };
        self.i14 = v12 * lk;
        v10
    }
}

/// One joint's controller as the thesis ISR runs it: reload gains, filter and limit, run
/// `DCL_runPID_C1` (or, by [`ControlLaw`], the C4 PID) with `lk = 1`, return the signed
/// output.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointController {
    /// The controller.
    pub pid: PidC1,
    /// The C4 PID, used when `law` is [`ControlLaw::DclPid`].
    pub c4: PidC4,
    /// Which of the two runs.
    pub law: ControlLaw,
}

impl JointController {
    /// A controller in the DCL default state.
    pub const fn new() -> Self {
        Self {
            pid: PidC1::new(),
            c4: PidC4::new(),
            law: ControlLaw::Piv,
        }
    }

    /// A controller running `law`.
    pub const fn with_law(law: ControlLaw) -> Self {
        Self {
            pid: PidC1::new(),
            c4: PidC4::new(),
            law,
        }
    }

    /// One 10 kHz step: `desired` and `measured` in revolutions (joint frame).
    pub fn step(
        &mut self,
        desired: f32,
        measured: f32,
        gains: Gains,
        filter_hz: f32,
        umax: f32,
    ) -> f32 {
        match self.law {
            ControlLaw::Piv => {
                self.pid.set_gains(gains);
                self.pid.set_filter(filter_hz, CONTROL_PERIOD_S);
                self.pid.set_limit(umax);
                self.pid.run(desired, measured, 1.0)
            }
            ControlLaw::DclPid => {
                self.c4.set_gains(gains);
                self.c4.set_filter(filter_hz, CONTROL_PERIOD_S);
                self.c4.set_limit(umax);
                self.c4.run(desired, measured, 1.0)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// The thesis' Matlab `PIV_controller` for one joint, transcribed line by line in f64
    /// (globals d2, d3, i10, i14; `ControlTesting.m` for c1, c2). Inputs in radians.
    struct MatlabPiv {
        d2: f64,
        d3: f64,
        i10: f64,
        i14: f64,
        c1: f64,
        c2: f64,
        umax: f64,
        umin: f64,
        kr: f64,
        kp: f64,
        kd: f64,
        ki: f64,
    }

    impl MatlabPiv {
        fn new(filter_bandwidth: f64, umax: f64, kp: f64, kd: f64, ki: f64) -> Self {
            let t = 1.0 / 10000.0;
            let ftc = 1.0 / (2.0 * std::f64::consts::PI * filter_bandwidth);
            Self {
                d2: 0.0,
                d3: 0.0,
                i10: 0.0,
                i14: 0.0,
                c1: 2.0 / (t + 2.0 * ftc),
                c2: (t - 2.0 * ftc) / (t + 2.0 * ftc),
                umax,
                umin: -umax,
                kr: 1.0,
                kp,
                kd,
                ki,
            }
        }

        /// Returns v10 (the PWM fraction; Matlab then multiplies by the torque scale).
        fn call(&mut self, th_rad: f64, th_des_rad: f64, lk: f64) -> f64 {
            let th_des = th_des_rad / (2.0 * std::f64::consts::PI);
            let th = th_rad / (2.0 * std::f64::consts::PI);
            let v5 = self.kr * th_des - th;
            let v8 = self.ki * self.kp * self.i14 * (th_des - th) + self.i10;
            self.i10 = v8;
            let v1 = self.kd * self.c1 * th;
            let v4 = v1 - self.d2 - self.d3;
            self.d2 = v1;
            self.d3 = v4 * self.c2;
            let v9 = self.kp * (v5 - v4) + v8;
            let v10 = if v9 > self.umax {
                self.umax
            } else if v9 < self.umin {
                self.umin
            } else {
                v9
            };
            let v12 = if v10 == v9 { 1.0 } else { 0.0 };
            self.i14 = v12 * lk;
            v10
        }
    }

    /// A joint trajectory that ramps, oscillates and saturates the controller.
    fn signals(n: usize) -> Vec<(f64, f64)> {
        (0..n)
            .map(|k| {
                let t = k as f64 * 1e-4;
                let des = 0.4 * (2.0 * std::f64::consts::PI * 1.0 * t).sin() - 0.2;
                let act = 0.35 * (2.0 * std::f64::consts::PI * 1.0 * (t - 0.03)).sin()
                    + 0.01 * (2.0 * std::f64::consts::PI * 37.0 * t).sin()
                    - 0.2;
                (act, des)
            })
            .collect()
    }

    fn compare(kp: f32, kd: f32, ki: f32, umax: f32, bw: f32) -> (usize, usize) {
        let mut m = MatlabPiv::new(bw as f64, umax as f64, kp as f64, kd as f64, ki as f64);
        let mut c = JointController::new();
        let g = Gains { kp, kd, ki };
        let (mut sat, mut lin) = (0, 0);
        for (act, des) in signals(20_000) {
            let r = m.call(act, des, 1.0);
            let u = c.step(
                (des / std::f64::consts::TAU) as f32,
                (act / std::f64::consts::TAU) as f32,
                g,
                bw,
                umax,
            );
            assert!(
                (u as f64 - r).abs() < 2e-4 * (1.0 + r.abs()),
                "kp {kp} kd {kd} ki {ki}: {u} vs {r}"
            );
            if r.abs() >= umax as f64 {
                sat += 1;
            } else {
                lin += 1;
            }
        }
        (sat, lin)
    }

    #[test]
    fn matches_matlab_piv_controller() {
        // ControlTesting.m / PIV_controller.m gains, knee and hip limits, 20 Hz filter.
        let (s, l) = compare(40.0, 0.01, 0.0, 0.3825, 20.0);
        assert!(s > 0 && l > 0, "exercise both regions: {s} {l}");
        compare(40.0, 0.01, 0.0, 0.4117, 20.0);
        // Table 4-1 gains.
        compare(80.0, 0.05, 0.0, 0.3825, 20.0);
        // With an integrator (anti-windup path active) and another filter bandwidth.
        let (s, l) = compare(5.0, 0.03, 2.0, 0.4117, 50.0);
        assert!(s > 0 && l > 0, "exercise both regions: {s} {l}");
    }

    #[test]
    fn control_testing_example_call() {
        // PIV_controller(0, π/6, 1, 0, −π/8, 1): first call from rest.
        let mut knee = MatlabPiv::new(20.0, 0.3825, 40.0, 0.01, 0.0);
        let mut hip = MatlabPiv::new(20.0, 0.4117, 40.0, 0.01, 0.0);
        let rk = knee.call(0.0, std::f64::consts::PI / 6.0, 1.0);
        let rh = hip.call(0.0, -std::f64::consts::PI / 8.0, 1.0);
        let g = Gains {
            kp: 40.0,
            kd: 0.01,
            ki: 0.0,
        };
        let mut ck = JointController::new();
        let mut ch = JointController::new();
        let uk = ck.step(1.0 / 12.0, 0.0, g, 20.0, 0.3825);
        let uh = ch.step(-1.0 / 16.0, 0.0, g, 20.0, 0.4117);
        // 40 × 1/12 = 3.33 and 40 × 1/16 = 2.5: both saturate.
        assert_eq!((rk, rh), (0.3825, -0.4117));
        assert_eq!((uk, uh), (0.3825, -0.4117));
        assert_eq!(ck.pid.i14, 0.0);
    }

    #[test]
    fn integrator_frozen_while_saturated() {
        let mut c = PidC1::new();
        c.set_gains(Gains {
            kp: 10.0,
            kd: 0.0,
            ki: 1.0,
        });
        c.set_filter(20.0, CONTROL_PERIOD_S);
        c.set_limit(0.4);
        // Large error: saturated from the first call, so i14 = 0 and i10 stays 0.
        for _ in 0..100 {
            assert_eq!(c.run(1.0, 0.0, 1.0), 0.4);
        }
        assert_eq!(c.i10, 0.0);
        // Small error: linear, the integrator runs.
        c.run(0.01, 0.0, 1.0);
        c.run(0.01, 0.0, 1.0);
        assert!(c.i10 > 0.0);
        // Ki = 0 clears the integral path.
        c.set_gains(Gains {
            kp: 10.0,
            kd: 0.0,
            ki: 0.0,
        });
        assert_eq!(c.i10, 0.0);
    }

    #[test]
    fn derivative_acts_on_feedback_only() {
        let g = Gains {
            kp: 1.0,
            kd: 0.1,
            ki: 0.0,
        };
        // A reference step gives a pure proportional jump, no derivative kick.
        let mut c = JointController::new();
        let u = c.step(0.1, 0.0, g, 20.0, 1.0);
        assert!((u - 0.1).abs() < 1e-7);
        // A feedback step gives the filtered-derivative kick Kp·Kd·c1·Δy on top.
        let mut c = JointController::new();
        let (c1, _) = filter_coefficients(20.0, CONTROL_PERIOD_S);
        let u = c.step(0.0, 0.001, g, 20.0, 1.0);
        let expect = -(0.001 + 0.1 * c1 * 0.001);
        assert!((u - expect).abs() < 1e-6, "{u} vs {expect}");
    }

    #[test]
    fn direction_and_duty() {
        assert_eq!(
            PwmCommand::from_output(0.3),
            PwmCommand {
                duty: 0.3,
                reverse: false
            }
        );
        assert_eq!(
            PwmCommand::from_output(-0.2),
            PwmCommand {
                duty: 0.2,
                reverse: true
            }
        );
        assert!(!PwmCommand::from_output(0.0).reverse);
        assert_eq!(PwmCommand::from_output(-0.2).signed(), -0.2);
    }

    fn c4(kp: f32, ki: f32, kd: f32, umax: f32) -> PidC4 {
        let mut p = PidC4::new();
        p.set_gains(Gains { kp, kd, ki });
        p.set_limit(umax);
        p
    }

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() <= 1e-6 * (1.0 + b.abs())
    }

    #[test]
    fn c4_steps_match_the_hand_computed_parallel_form() {
        // Kp = 0.5, Ki = 10 /s (× T = 1e-4 per call), Kd = 0.01 s, filter c1 = 100, c2 = −0.5.
        let mut p = c4(0.5, 10.0, 0.01, 1.0);
        p.c1 = 100.0;
        p.c2 = -0.5;
        p.period_s = 1e-4;
        // r = 1, y = 0: v5 = 1, v8 = 1·10·1e-4 = 0.001, v1 = v4 = 0 → u = 0.5 + 0.001.
        assert!(close(p.run(1.0, 0.0, 1.0), 0.501));
        // y = 0.1: v5 = 0.9, v8 = 0.001 + 0.9·1e-3 = 0.0019, v1 = 0.1·0.01·100 = 0.1,
        // v4 = 0.1, d2 = 0.1, d3 = −0.05 → u = 0.45 + 0.0019 − 0.1 = 0.3519.
        assert!(close(p.run(1.0, 0.1, 1.0), 0.3519));
        assert!(close(p.d3, -0.05));
        // y = 0.1 again: v8 = 0.0028, v4 = 0.1 − 0.1 + 0.05 = 0.05 → u = 0.45 + 0.0028 − 0.05.
        assert!(close(p.run(1.0, 0.1, 1.0), 0.4028));
        assert!(close(p.i10, 0.0028));
        // Kr weights only the proportional path: Kr = 0, r = 1, y = 0.1 → v5 = −0.1.
        p.kr = 0.0;
        let i = p.i10 + 0.9e-3;
        let v4 = 0.1 - 0.1 + 0.025;
        assert!(close(p.run(1.0, 0.1, 1.0), -0.05 + i - v4));
    }

    #[test]
    fn c4_anti_windup_clamp_holds_the_integrator() {
        let mut p = c4(1.0, 100.0, 0.0, 0.5);
        p.set_filter(20.0, 1e-4);
        // First call unsaturated flag (i14 = 1): integrates once, then saturates.
        assert_eq!(p.run(1.0, 0.0, 1.0), 0.5);
        let held = p.i10;
        assert!(close(held, 0.01));
        assert_eq!(p.i14, 0.0);
        for _ in 0..1000 {
            assert_eq!(p.run(1.0, 0.0, 1.0), 0.5);
        }
        assert_eq!(
            p.i10, held,
            "the clamp froze the integrator while saturated"
        );
        // Back inside the limits (e = 0.1): the first call still uses the flag of the
        // saturated call, then integration resumes.
        assert!(close(p.run(1.0, 0.9, 1.0), 0.1 + held));
        assert_eq!(p.i10, held);
        assert_eq!(p.i14, 1.0);
        p.run(1.0, 0.9, 1.0);
        assert!(close(p.i10, held + 0.1 * 100.0 * 1e-4));
        // lk = 0 holds the integrator too, from the next call on; Ki = 0 clears it.
        p.run(1.0, 0.9, 0.0);
        let before = p.i10;
        p.run(1.0, 0.9, 0.0);
        p.run(1.0, 0.9, 0.0);
        assert_eq!(p.i10, before);
        p.set_gains(Gains {
            kp: 1.0,
            kd: 0.0,
            ki: 0.0,
        });
        assert_eq!(p.i10, 0.0);
        // The lower limit clamps too.
        let mut n = c4(1.0, 100.0, 0.0, 0.5);
        assert_eq!(n.run(-1.0, 0.0, 1.0), -0.5);
    }

    #[test]
    fn c4_derivative_filter_is_a_first_order_lag_of_the_feedback_rate() {
        // Kp = Ki = 0, Kd = 0.02 s: a unit step of y gives u = −v4 with v4 = Kd·c1 first,
        // then decaying by −c2 each call, and Σ v4·T = Kd·Δy (Tustin keeps the DC gain).
        let (t, hz, kd) = (1e-4_f32, 20.0_f32, 0.02_f32);
        let mut p = c4(0.0, 0.0, kd, 1e6);
        p.set_filter(hz, t);
        let (c1, c2) = filter_coefficients(hz, t);
        let tau = 1.0 / (TAU * hz);
        assert!(close(c1, 2.0 / (t + 2.0 * tau)));
        let u0 = p.run(0.0, 1.0, 1.0);
        assert!(close(u0, -kd * c1));
        let mut prev = u0;
        let mut sum = f64::from(-u0) * f64::from(t);
        for _ in 0..20_000 {
            let u = p.run(0.0, 1.0, 1.0);
            assert!(close(u, -c2 * prev), "{u} vs {}", -c2 * prev);
            sum += f64::from(-u) * f64::from(t);
            prev = u;
        }
        assert!((sum - f64::from(kd)).abs() < 1e-4, "{sum}");
        // The derivative acts on the feedback only: a reference step gives no kick.
        let mut q = c4(0.0, 0.0, kd, 1e6);
        q.set_filter(hz, t);
        assert_eq!(q.run(1.0, 0.0, 1.0), 0.0);
    }

    #[test]
    fn joint_controller_runs_the_selected_law() {
        let g = Gains {
            kp: 40.0,
            kd: 0.01,
            ki: 0.0,
        };
        let mut piv = JointController::new();
        let mut pid = JointController::with_law(ControlLaw::DclPid);
        assert_eq!(piv.law, ControlLaw::Piv);
        // Same P action on the first call (no derivative yet, Ki = 0).
        let a = piv.step(0.001, 0.0, g, 20.0, 0.4);
        let b = pid.step(0.001, 0.0, g, 20.0, 0.4);
        assert!(close(a, 0.04) && close(b, 0.04), "{a} {b}");
        // The derivative path: C1 multiplies Kd by Kp, C4 does not.
        let a = piv.step(0.001, 0.0001, g, 20.0, 0.4);
        let b = pid.step(0.001, 0.0001, g, 20.0, 0.4);
        let (c1, _) = filter_coefficients(20.0, CONTROL_PERIOD_S);
        let d = 0.0001 * 0.01 * c1;
        assert!(close(a, 40.0 * (0.0009 - d)), "{a}");
        assert!(close(b, 40.0 * 0.0009 - d), "{b}");
        assert_eq!(ControlLaw::parse("dcl-pid"), Some(ControlLaw::DclPid));
        assert_eq!(ControlLaw::parse("PID"), None);
        assert_eq!(ControlLaw::DclPid.name(), "dcl-pid");
    }
}
