//! The leg-node application (thesis §3.3–§3.8): Configuration / Operational states from
//! `State_Machine`, trajectory clock + ellipse + inverse kinematics on every application
//! cycle (SYNC0 in DC mode), two PIV joint loops on the 10 kHz timer event.
//!
//! Per application cycle ([`Application::cycle`], the thesis' `APPL_Application`):
//! 1. decode the outputs ([`Command::read`]); `dt` = the SYNC0 cycle time from 0x1C32:02
//!    ([`DEFAULT_CYCLE_NS`] if none is configured);
//! 2. `Transition_time` and `FilterBandwidth` are taken when non-zero; LEDs follow;
//! 3. Operational: advance the clock by `dt`, evaluate the ellipse, solve the IK (holding the
//!    last valid point outside the workspace), set the desired joint angles
//!    (joint frame, `σ·θ/2π` revolutions). Configuration: clock to 0, desired angles held;
//! 4. report angles, desired angles, PIV outputs, motor speeds and time ([`Feedback`]);
//! 5. move gains and semi-axes a step along their linear transitions; take the ellipse
//!    centre, phase, flatness and (if positive) frequency directly — these apply from the
//!    next cycle, as in the thesis.
//!
//! Per 10 kHz timer event ([`JOINT_LOOP_TIMER`]; the thesis' `epwm1_isr`/`epwm2_isr`), for
//! the knee then the hip: read the eQEP, update angle and speed, run the PIV with the
//! current gains and filter, and drive the PWM — zero duty in the Configuration state.

use super::device::{Command, Feedback, PdoVars};
use super::encoder::{CaptureConfig, EncoderIn, JointEncoder, SpeedEstimator};
use super::hw::{
    Joint, CONTROL_PERIOD_S, DEFAULT_CYCLE_NS, DEFAULT_FILTER_HZ, DEFAULT_TRANSITION_TIME_S,
    JOINT_LOOP_TIMER,
};
use super::kinematics::{Ik, LegAngles, Side};
use super::piv::{ControlLaw, Gains, JointController, PwmCommand};
use super::trajectory::{Ellipse, TrajectoryClock};
use super::transition::Ramp;
use crate::demo::Leds;
use core::f32::consts::TAU;
use oxicat_slave::{AlState, AlStatusCode, Application, Od};

/// The motor amplifiers of a leg node (ePWM1 + DIR1 knee, ePWM2 + DIR2 hip).
pub trait PwmOut {
    /// Sets one motor's duty and direction.
    fn set(&mut self, joint: Joint, cmd: PwmCommand);
}

/// The leg-node state from `State_Machine` (thesis §3.8).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// `State_Machine = 0`: clock at 0, PWM duty 0, parameters may be set.
    Configuration,
    /// `State_Machine = 1`: the clock runs, the trajectory is tracked.
    Operational,
}

/// Per-joint state of the 10 kHz loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointState {
    /// Encoder zeroed at the reset pose.
    pub encoder: JointEncoder,
    /// eQEP capture speed estimate.
    pub speed: SpeedEstimator,
    /// Joint controller (PIV or the DCL C4 PID).
    pub controller: JointController,
    /// Measured angle \[rev\], joint frame.
    pub angle_rev: f32,
    /// Desired angle \[rev\], joint frame.
    pub desired_rev: f32,
    /// Last PIV output (signed PWM fraction).
    pub u: f32,
    /// Last command sent to the amplifier.
    pub pwm: PwmCommand,
}

impl JointState {
    fn new(position: u32, cfg: CaptureConfig) -> Self {
        Self {
            encoder: JointEncoder::zeroed_at(position),
            speed: SpeedEstimator::new(cfg),
            controller: JointController::new(),
            angle_rev: 0.0,
            desired_rev: 0.0,
            u: 0.0,
            pwm: PwmCommand::OFF,
        }
    }
}

/// PIV gains following their linear transitions.
#[derive(Debug, Clone, Copy, PartialEq)]
struct GainRamps {
    kp: Ramp,
    kd: Ramp,
    ki: Ramp,
}

impl GainRamps {
    const fn new() -> Self {
        Self {
            kp: Ramp::new(0.0),
            kd: Ramp::new(0.0),
            ki: Ramp::new(0.0),
        }
    }

    fn update(&mut self, g: Gains, t: f32, cycle_ns: u32) {
        self.kp.update(g.kp, t, cycle_ns);
        self.kd.update(g.kd, t, cycle_ns);
        self.ki.update(g.ki, t, cycle_ns);
    }

    fn gains(&self) -> Gains {
        Gains {
            kp: self.kp.value(),
            kd: self.kd.value(),
            ki: self.ki.value(),
        }
    }
}

/// The Laelaps II leg-node application on hardware `P` (PWM), `E` (encoders), `L` (LEDs).
pub struct LegNode<P: PwmOut, E: EncoderIn, L: Leds> {
    /// Which build (sign convention) this node runs.
    pub side: Side,
    /// Motor amplifiers.
    pub pwm: P,
    /// Encoders.
    pub encoders: E,
    /// LaunchPad LEDs.
    pub leds: L,
    mode: Mode,
    clock: TrajectoryClock,
    ellipse: Ellipse,
    a: Ramp,
    b: Ramp,
    knee_gains: GainRamps,
    hip_gains: GainRamps,
    transition_s: f32,
    filter_hz: f32,
    cycle_ns: u32,
    ik: Ik,
    target: (f32, f32),
    knee: JointState,
    hip: JointState,
    /// Process-data handles, resolved on the first cycle.
    io: Option<PdoVars>,
}

impl<P: PwmOut, E: EncoderIn, L: Leds> LegNode<P, E, L> {
    /// A node in the Configuration state, encoders zeroed at their current counts (the
    /// leg is in the reset pose at power-on/Reset), the thesis' eQEP capture setup.
    pub fn new(side: Side, pwm: P, encoders: E, leds: L) -> Self {
        Self::with_capture(side, pwm, encoders, leds, CaptureConfig::THESIS)
    }

    /// As [`LegNode::new`] with another eQEP capture configuration.
    pub fn with_capture(
        side: Side,
        pwm: P,
        mut encoders: E,
        leds: L,
        capture: CaptureConfig,
    ) -> Self {
        let k = encoders.sample(Joint::Knee).position;
        let h = encoders.sample(Joint::Hip).position;
        Self {
            side,
            pwm,
            encoders,
            leds,
            mode: Mode::Configuration,
            clock: TrajectoryClock::new(),
            ellipse: Ellipse::default(),
            a: Ramp::new(0.0),
            b: Ramp::new(0.0),
            knee_gains: GainRamps::new(),
            hip_gains: GainRamps::new(),
            transition_s: DEFAULT_TRANSITION_TIME_S,
            filter_hz: DEFAULT_FILTER_HZ,
            cycle_ns: DEFAULT_CYCLE_NS,
            ik: Ik::new(),
            target: (0.0, 0.0),
            knee: JointState::new(k, capture),
            hip: JointState::new(h, capture),
            io: None,
        }
    }

    /// Builds the node with another joint control law (default: the thesis' PIV); both
    /// controllers start from their default states.
    pub fn with_law(mut self, law: ControlLaw) -> Self {
        self.knee.controller = JointController::with_law(law);
        self.hip.controller = JointController::with_law(law);
        self
    }

    /// The joint control law this node runs.
    pub fn law(&self) -> ControlLaw {
        self.knee.controller.law
    }

    /// Re-zeroes both encoders at their current counts (the LaunchPad Reset button).
    pub fn zero_encoders(&mut self) {
        let k = self.encoders.sample(Joint::Knee).position;
        let h = self.encoders.sample(Joint::Hip).position;
        self.knee.encoder = JointEncoder::zeroed_at(k);
        self.hip.encoder = JointEncoder::zeroed_at(h);
    }

    /// Current state.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Trajectory clock.
    pub fn clock(&self) -> TrajectoryClock {
        self.clock
    }

    /// The ellipse in use (a, b as far along their transitions as they are).
    pub fn ellipse(&self) -> Ellipse {
        self.ellipse
    }

    /// Current knee and hip gains (after transitions).
    pub fn gains(&self) -> (Gains, Gains) {
        (self.knee_gains.gains(), self.hip_gains.gains())
    }

    /// Derivative-filter bandwidth in use \[Hz\].
    pub fn filter_hz(&self) -> f32 {
        self.filter_hz
    }

    /// `Transition_time` in use \[s\].
    pub fn transition_s(&self) -> f32 {
        self.transition_s
    }

    /// The last toe target of the ellipse `(x, y)` \[m\] (may be outside the workspace).
    pub fn target(&self) -> (f32, f32) {
        self.target
    }

    /// The last reachable toe target, whose IK solution is being tracked.
    pub fn tracked_point(&self) -> (f32, f32) {
        self.ik.point()
    }

    /// The desired angles, kinematic frame \[rad\].
    pub fn desired_angles(&self) -> LegAngles {
        self.ik.angles()
    }

    /// A joint's loop state.
    pub fn joint(&self, joint: Joint) -> &JointState {
        match joint {
            Joint::Knee => &self.knee,
            Joint::Hip => &self.hip,
        }
    }

    fn joint_mut(&mut self, joint: Joint) -> &mut JointState {
        match joint {
            Joint::Knee => &mut self.knee,
            Joint::Hip => &mut self.hip,
        }
    }

    /// Measured angles, kinematic frame \[rad\].
    pub fn measured_angles(&self) -> LegAngles {
        LegAngles {
            hip: self.side.to_kinematic(self.hip.angle_rev * TAU),
            knee: self.side.to_kinematic(self.knee.angle_rev * TAU),
        }
    }

    /// The feedback the node reports (SI, joint frame).
    pub fn feedback(&self) -> Feedback {
        Feedback {
            hip: self.hip.angle_rev * TAU,
            hip_desired: self.hip.desired_rev * TAU,
            knee: self.knee.angle_rev * TAU,
            knee_desired: self.knee.desired_rev * TAU,
            time_s: self.clock.seconds(),
            u_knee: self.knee.u,
            u_hip: self.hip.u,
            velocity_knee: self.knee.speed.speed(),
            velocity_hip: self.hip.speed.speed(),
        }
    }

    /// One application cycle with command `cmd` and SYNC0 cycle `cycle_ns` (0: unknown).
    pub fn application(&mut self, cmd: &Command, cycle_ns: u32) -> Feedback {
        if cycle_ns != 0 {
            self.cycle_ns = cycle_ns;
        }
        let dt_ns = self.cycle_ns;
        self.mode = if cmd.operational {
            Mode::Operational
        } else {
            Mode::Configuration
        };
        if cmd.transition_time_s > 0.0 {
            self.transition_s = cmd.transition_time_s;
        }
        self.leds.set(cmd.blue_led, cmd.red_led);
        if cmd.filter_hz > 0.0 {
            self.filter_hz = cmd.filter_hz;
        }
        match self.mode {
            Mode::Operational => {
                self.clock.advance(dt_ns);
                self.target = self.ellipse.point(self.clock.seconds());
                let a = self.ik.solve(self.target.0, self.target.1);
                self.hip.desired_rev = self.side.to_joint(a.hip) / TAU;
                self.knee.desired_rev = self.side.to_joint(a.knee) / TAU;
            }
            Mode::Configuration => self.clock.reset(),
        }
        let fb = self.feedback();
        // Parameter updates, effective from the next cycle.
        let t = self.transition_s;
        self.knee_gains.update(cmd.knee, t, dt_ns);
        self.hip_gains.update(cmd.hip, t, dt_ns);
        let e = &cmd.ellipse;
        self.ellipse.a = self.a.update(e.a, t, dt_ns);
        self.ellipse.b = self.b.update(e.b, t, dt_ns);
        self.ellipse.x_centre = e.x_centre;
        self.ellipse.y_centre = e.y_centre;
        if e.freq > 0.0 {
            self.ellipse.freq = e.freq;
        }
        self.ellipse.phase = e.phase;
        self.ellipse.flatness = e.flatness;
        fb
    }

    /// One 10 kHz joint-loop step for both joints (knee, then hip).
    pub fn joint_loop(&mut self) {
        let gains = self.gains();
        for j in Joint::ALL {
            let s = self.encoders.sample(j);
            let g = match j {
                Joint::Knee => gains.0,
                Joint::Hip => gains.1,
            };
            let filter = self.filter_hz;
            let operational = self.mode == Mode::Operational;
            let st = self.joint_mut(j);
            st.angle_rev = st.encoder.joint_revs(s.position, j);
            st.speed.update(&s, CONTROL_PERIOD_S);
            st.u = st
                .controller
                .step(st.desired_rev, st.angle_rev, g, filter, j.u_max());
            st.pwm = if operational {
                PwmCommand::from_output(st.u)
            } else {
                PwmCommand::OFF
            };
            let cmd = st.pwm;
            self.pwm.set(j, cmd);
        }
    }

    fn stop(&mut self) {
        self.mode = Mode::Configuration;
        self.clock.reset();
        for j in Joint::ALL {
            self.joint_mut(j).pwm = PwmCommand::OFF;
            self.pwm.set(j, PwmCommand::OFF);
        }
    }
}

impl<const N: usize, P: PwmOut, E: EncoderIn, L: Leds> Application<N> for LegNode<P, E, L> {
    fn state_change(
        &mut self,
        _from: AlState,
        to: AlState,
        _od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        if to != AlState::Op {
            self.stop();
        }
        if matches!(to, AlState::Init | AlState::PreOp) {
            self.leds.set(false, false);
        }
        Ok(())
    }

    fn safe_outputs(&mut self, od: &mut Od<N>) {
        Command::default().write(od);
        let _ = od.set(0x7010, 1, 0i32);
        let _ = od.set(0x7014, 1, 0i32);
        for sub in [2u8, 3, 4, 7, 8] {
            let _ = od.set(0x7000, sub, false);
        }
        self.stop();
        self.leds.set(false, false);
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        if self.io.is_none() {
            self.io = PdoVars::resolve(od);
        }
        if let Some(io) = self.io {
            let cmd = Command::load(od, &io);
            let cycle_ns = io.cycle_ns(od);
            let fb = self.application(&cmd, cycle_ns);
            fb.store(od, &io);
        } else {
            let cmd = Command::read(od);
            let cycle_ns = od.get::<u32>(0x1C32, 2).unwrap_or(0);
            let fb = self.application(&cmd, cycle_ns);
            fb.write(od);
        }
    }

    fn timer(&mut self, id: u8, _od: &mut Od<N>) {
        if id == JOINT_LOOP_TIMER {
            self.joint_loop();
        }
    }
}
