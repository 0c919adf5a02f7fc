//! The drive application: the state machine, the modes of operation and the cascaded
//! loops on [`JointHw`].
//!
//! | event | what runs |
//! |---|---|
//! | local timer [`CURRENT_LOOP_TIMER`], 20 kHz | [`CurrentLoop`]: current (q-axis) PI loop, `i_q` reference → voltage; over-current monitor — on the drive's [`PowerStage`] when [`JointHw::power_stage`] gives one (the host rig); a board runs the same loop in its ADC interrupt and hands [`CurrentCommand`] and [`CurrentFeedback`] over |
//! | DC SYNC0 (or the free-run / SM cycle) | encoder → position/velocity actual; state machine; mode set-point generation; position P loop → velocity PI loop → `i_q` reference; following-error and limit monitors; statusword and actual values |
//!
//! The joint torque sensor is sampled each cycle and reported in 0x2002 (mN·m, output
//! side); it is not used in the loops.

use super::device::OBJECTS;
use super::fsm::{cw, sw, Events, Fsm, Options, Ramp, State};
use oxicat_slave::{AlState, AlStatusCode, Application, Od, Var};

/// The joint's sensors, read in the drive's cycle, and where its power stage is.
pub trait JointHw {
    /// The power stage's type ([`NoPowerStage`] when the current loop runs elsewhere).
    type Power: PowerStage;
    /// The motor encoder counter (increments; wraps).
    fn encoder(&mut self) -> i32;
    /// The counter value latched at the last index pulse since the previous call.
    fn index_latch(&mut self) -> Option<i32>;
    /// The home switch input.
    fn home_switch(&mut self) -> bool;
    /// The joint torque sensor \[N·m\].
    fn joint_torque(&mut self) -> f32;
    /// The power stage, when the drive runs its current loop itself on its local timer
    /// ([`Cia402Drive::run_current_loop`]: the host rig, one context). `None` when the
    /// loop runs elsewhere with the power stage (a board's ADC interrupt, at a higher
    /// priority than the cycle): the drive then hands its [`CurrentCommand`] over
    /// ([`Cia402Drive::current_command`]) and takes the loop's [`CurrentFeedback`]
    /// ([`Cia402Drive::current_feedback`]).
    fn power_stage(&mut self) -> Option<&mut Self::Power>;
}

/// The bridge and its current sensing: what the current loop runs on, every tick.
pub trait PowerStage {
    /// The measured q-axis current \[A\].
    fn current(&mut self) -> f32;
    /// Drives the bridge: `enable` false switches it off (motor coasts), else applies `volts`
    /// on the q axis.
    fn set_voltage(&mut self, enable: bool, volts: f32);
}

/// The power stage of a drive whose current loop runs elsewhere: uninhabited, so
/// [`JointHw::power_stage`] can only return `None`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoPowerStage {}

impl PowerStage for NoPowerStage {
    fn current(&mut self) -> f32 {
        match *self {}
    }
    fn set_voltage(&mut self, _enable: bool, _volts: f32) {
        match *self {}
    }
}

/// What the drive's cycle asks of the current loop (a few words: a board hands it to its
/// current-loop interrupt in a short critical section).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentCommand {
    /// The bridge is driven; false: off (the motor coasts), the integrator reset.
    pub power: bool,
    /// q-axis current reference \[A\].
    pub iq_ref: f32,
    /// Proportional gain \[V/A\] (0x2000:01).
    pub kp: f32,
    /// Integral gain \[V/(A·s)\] (0x2000:02).
    pub ki: f32,
}

impl Default for CurrentCommand {
    /// Bridge off, no reference, the drive's default gains.
    fn default() -> Self {
        Self {
            power: false,
            iq_ref: 0.0,
            kp: super::device::gains::CURRENT_KP,
            ki: super::device::gains::CURRENT_KI,
        }
    }
}

/// What the current loop hands back to the cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CurrentFeedback {
    /// The last measured q-axis current \[A\].
    pub iq: f32,
    /// A tick since the last hand-over measured more than the trip level
    /// ([`DriveParams::max_current`]).
    pub overcurrent: bool,
}

/// The 20 kHz q-axis current loop: PI from the [`CurrentCommand`] and the measured current
/// to the q-axis voltage, and the over-current monitor. Its own value, so that it runs
/// where the power stage is: inside the drive on the host rig
/// ([`Cia402Drive::run_current_loop`]), in the ADC interrupt on a board, the same
/// [`CurrentLoop::step`] in both.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentLoop {
    cmd: CurrentCommand,
    integral: f32,
    feedback: CurrentFeedback,
    max_current: f32,
    bus_voltage: f32,
}

impl CurrentLoop {
    /// A loop at rest (bridge off) with the trip level and voltage limit of `params`.
    pub fn new(params: &DriveParams) -> Self {
        Self {
            cmd: CurrentCommand::default(),
            integral: 0.0,
            feedback: CurrentFeedback::default(),
            max_current: params.max_current,
            bus_voltage: params.bus_voltage,
        }
    }

    /// The command the loop runs on.
    pub fn command(&self) -> CurrentCommand {
        self.cmd
    }

    /// Replaces the command (takes effect at the next [`CurrentLoop::step`]).
    pub fn set_command(&mut self, cmd: CurrentCommand) {
        self.cmd = cmd;
    }

    /// One tick on `stage`: measures the current, flags an over-current, and drives the
    /// bridge — off (integrator reset) without power, else the PI output clamped to the
    /// bus voltage.
    pub fn step(&mut self, stage: &mut impl PowerStage) {
        let dt = 1.0 / CURRENT_LOOP_HZ as f32;
        let i = stage.current();
        self.feedback.iq = i;
        if i.abs() > self.max_current {
            self.feedback.overcurrent = true;
        }
        if !self.cmd.power {
            self.integral = 0.0;
            stage.set_voltage(false, 0.0);
            return;
        }
        let vb = self.bus_voltage;
        let e = self.cmd.iq_ref - i;
        self.integral = (self.integral + self.cmd.ki * e * dt).clamp(-vb, vb);
        let v = (self.cmd.kp * e + self.integral).clamp(-vb, vb);
        stage.set_voltage(true, v);
    }

    /// The measurement since the last take: the last current, and whether a tick since
    /// tripped (the flag is cleared).
    pub fn take_feedback(&mut self) -> CurrentFeedback {
        let f = self.feedback;
        self.feedback.overcurrent = false;
        f
    }
}

/// Local timer of the current loop.
pub const CURRENT_LOOP_TIMER: u8 = 0;
/// Current loop rate.
pub const CURRENT_LOOP_HZ: u32 = 20_000;

/// Modes of operation (0x6060 / 0x6061).
pub mod mode {
    /// Profile position.
    pub const PP: i8 = 1;
    /// Profile velocity.
    pub const PV: i8 = 3;
    /// Profile torque.
    pub const PT: i8 = 4;
    /// Homing.
    pub const HM: i8 = 6;
    /// Interpolated position (sub mode 0x60C0 = 0: linear interpolation between the
    /// set-points 0x60C1:01, one per interpolation period 0x60C2).
    pub const IP: i8 = 7;
    /// Cyclic synchronous position.
    pub const CSP: i8 = 8;
    /// Cyclic synchronous velocity.
    pub const CSV: i8 = 9;
    /// Cyclic synchronous torque.
    pub const CST: i8 = 10;
}

/// Error codes (0x603F, emergency) this drive raises.
pub mod error {
    /// Following error.
    pub const FOLLOWING_ERROR: u16 = 0x8611;
    /// Over-current (short circuit / earth leakage, motor side).
    pub const OVERCURRENT: u16 = 0x2310;
    /// Communication (the connection to the master was aborted and 0x6007 = 1).
    pub const COMMUNICATION: u16 = 0x8100;
}

/// Hardware constants of the drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveParams {
    /// Encoder increments per motor revolution.
    pub counts_per_rev: u32,
    /// Motor torque constant \[N·m/A\].
    pub kt: f32,
    /// DC bus voltage \[V\].
    pub bus_voltage: f32,
    /// Application cycle when 0x1C32:02 does not say \[s\].
    pub cycle_s: f32,
    /// Over-current trip \[A\].
    pub max_current: f32,
    /// Motor pole pairs. The drive's loops work on the q axis and do not use it; a board
    /// that commutates (electrical angle = pole pairs × motor angle) takes it from here, so
    /// the motor is described in one place.
    pub pole_pairs: u32,
}

impl Default for DriveParams {
    fn default() -> Self {
        Self {
            counts_per_rev: 16_384,
            kt: 0.05,
            bus_voltage: 48.0,
            cycle_s: 0.001,
            max_current: 20.0,
            pole_pairs: 4,
        }
    }
}

/// Where the drive finds its objects: resolved once (on PREOP -> SAFEOP, or at the first
/// cycle), then plain offset accesses. The controlword and statusword are needed; every other
/// object may be missing from a dictionary the drive did not declare itself (a twin of a
/// vendor's ESI): a missing set-point reads 0, a missing actual value is not written.
#[derive(Debug, Clone, Copy)]
struct Io {
    /// The dictionary is the drive's own ([`OBJECTS`]): its manufacturer objects (0x2000
    /// gains, 0x2002 joint torque) and its motor data (0x6072, 0x6075, 0x6076, 0x6080) are
    /// the drive's. On a foreign dictionary those are the drive's defaults (the motor is
    /// the plant the drive was made for, not the one the vendor's values describe), and a
    /// 0 in a profile parameter (ramps, windows, homing speeds: many ESIs leave them 0 for
    /// the firmware to fill) reads as not set.
    own: bool,
    /// The mode when the dictionary has no 0x6060: the cyclic mode its set-points allow
    /// (CSP with 0x607A, else CSV with 0x60FF, else CST with 0x6071; 0: none).
    fixed_mode: i8,
    controlword: Var<u16>,
    statusword: Var<u16>,
    mode: Option<Var<i8>>,
    mode_display: Option<Var<i8>>,
    target_position: Option<Var<i32>>,
    target_velocity: Option<Var<i32>>,
    target_torque: Option<Var<i16>>,
    position_actual: Option<Var<i32>>,
    position_demand: Option<Var<i32>>,
    velocity_actual: Option<Var<i32>>,
    torque_actual: Option<Var<i16>>,
    current_actual: Option<Var<i16>>,
    error_code: Option<Var<u16>>,
    following_error: Option<Var<i32>>,
    joint_torque: Option<Var<i32>>,
    digital_inputs: Option<Var<u32>>,
    position_offset: Option<Var<i32>>,
    velocity_offset: Option<Var<i32>>,
    torque_offset: Option<Var<i16>>,
    ip_data: Option<Var<i32>>,
}

impl Io {
    /// The handles on the drive's own dictionary, from the declaration ([`OBJECTS`]):
    /// offsets and types checked when the crate builds.
    const VARS: Self = Self {
        own: true,
        fixed_mode: 0,
        controlword: Var::of(OBJECTS, 0x6040, 0),
        statusword: Var::of(OBJECTS, 0x6041, 0),
        mode: Some(Var::of(OBJECTS, 0x6060, 0)),
        mode_display: Some(Var::of(OBJECTS, 0x6061, 0)),
        target_position: Some(Var::of(OBJECTS, 0x607A, 0)),
        target_velocity: Some(Var::of(OBJECTS, 0x60FF, 0)),
        target_torque: Some(Var::of(OBJECTS, 0x6071, 0)),
        position_actual: Some(Var::of(OBJECTS, 0x6064, 0)),
        position_demand: Some(Var::of(OBJECTS, 0x6062, 0)),
        velocity_actual: Some(Var::of(OBJECTS, 0x606C, 0)),
        torque_actual: Some(Var::of(OBJECTS, 0x6077, 0)),
        current_actual: Some(Var::of(OBJECTS, 0x6078, 0)),
        error_code: Some(Var::of(OBJECTS, 0x603F, 0)),
        following_error: Some(Var::of(OBJECTS, 0x60F4, 0)),
        joint_torque: Some(Var::of(OBJECTS, 0x2002, 0)),
        digital_inputs: Some(Var::of(OBJECTS, 0x60FD, 0)),
        position_offset: Some(Var::of(OBJECTS, 0x60B0, 0)),
        velocity_offset: Some(Var::of(OBJECTS, 0x60B1, 0)),
        torque_offset: Some(Var::of(OBJECTS, 0x60B2, 0)),
        ip_data: Some(Var::of(OBJECTS, 0x60C1, 1)),
    };

    /// The handles for `od`: the build-time ones on the drive's own dictionary, else the
    /// CiA402 objects located by index (subindex 0, bit length checked) in whatever
    /// dictionary `od` is; `None` without a 16-bit 0x6040 and 0x6041.
    fn resolve<const N: usize>(od: &Od<N>) -> Option<Self> {
        if od.built_on(OBJECTS) {
            return Some(Self::VARS);
        }
        Self::locate(od)
    }

    /// The objects located by index in a foreign dictionary (see [`Io::resolve`]).
    fn locate<const N: usize>(od: &Od<N>) -> Option<Self> {
        fn v<T: oxicat_slave::OdType, const N: usize>(od: &Od<N>, i: u16) -> Option<Var<T>> {
            od.var(i, 0).ok()
        }
        let target_position = v(od, 0x607A);
        let target_velocity = v(od, 0x60FF);
        let target_torque = v(od, 0x6071);
        let fixed_mode = if target_position.is_some() {
            mode::CSP
        } else if target_velocity.is_some() {
            mode::CSV
        } else if target_torque.is_some() {
            mode::CST
        } else {
            0
        };
        Some(Self {
            own: false,
            fixed_mode,
            controlword: od.var(0x6040, 0).ok()?,
            statusword: od.var(0x6041, 0).ok()?,
            mode: v(od, 0x6060),
            mode_display: v(od, 0x6061),
            target_position,
            target_velocity,
            target_torque,
            position_actual: v(od, 0x6064),
            position_demand: v(od, 0x6062),
            velocity_actual: v(od, 0x606C),
            torque_actual: v(od, 0x6077),
            current_actual: v(od, 0x6078),
            error_code: v(od, 0x603F),
            following_error: v(od, 0x60F4),
            joint_torque: None,
            digital_inputs: v(od, 0x60FD),
            position_offset: v(od, 0x60B0),
            velocity_offset: v(od, 0x60B1),
            torque_offset: v(od, 0x60B2),
            ip_data: od.var(0x60C1, 1).ok(),
        })
    }

    /// A profile parameter (see [`Io::own`]): the dictionary's value, the default `d` if the
    /// object is missing or, on a foreign dictionary, 0.
    fn param<const N: usize>(&self, od: &Od<N>, i: u16, s: u8, d: u32) -> u32 {
        od.get::<u32>(i, s)
            .ok()
            .filter(|&v| self.own || v != 0)
            .unwrap_or(d)
    }

    /// Motor data and tuning (see [`Io::own`]): the dictionary's value on the drive's own
    /// dictionary, else the default `d`.
    fn motor<T: oxicat_slave::OdType, const N: usize>(&self, od: &Od<N>, i: u16, s: u8, d: T) -> T {
        if self.own {
            od.get::<T>(i, s).unwrap_or(d)
        } else {
            d
        }
    }
}

/// The value behind an optional handle (0 when the dictionary lacks the object).
fn ld<T: oxicat_slave::OdType + Default, const N: usize>(od: &Od<N>, v: Option<Var<T>>) -> T {
    v.map_or_else(T::default, |v| od.load(v))
}

/// Writes through an optional handle (nothing when the dictionary lacks the object).
fn st<T: oxicat_slave::OdType, const N: usize>(od: &mut Od<N>, v: Option<Var<T>>, x: T) {
    if let Some(v) = v {
        od.store(v, x);
    }
}

/// Position/velocity demand of the profile generator: integer increments plus a fraction,
/// so that f32 keeps sub-increment resolution over the whole i32 range.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Profile {
    pos: i32,
    frac: f32,
    vel: f32,
}

impl Profile {
    fn at(pos: i32) -> Self {
        Self {
            pos,
            frac: 0.0,
            vel: 0.0,
        }
    }

    fn advance(&mut self, dt: f32) {
        self.frac += self.vel * dt;
        let whole = libm_floor(self.frac);
        self.pos = self.pos.wrapping_add(whole as i32);
        self.frac -= whole;
    }

    fn shift(&mut self, d: i32) {
        self.pos = self.pos.wrapping_sub(d);
    }

    /// One step of a trapezoidal move towards `target`; true when there.
    fn move_to(&mut self, target: i32, vmax: f32, acc: f32, dec: f32, dt: f32) -> bool {
        let rem = target.wrapping_sub(self.pos) as f32 - self.frac;
        if rem.abs() < 0.5 && self.vel.abs() <= dec * dt {
            self.pos = target;
            self.frac = 0.0;
            self.vel = 0.0;
            return true;
        }
        let dir = if rem >= 0.0 { 1.0 } else { -1.0 };
        // Velocity that still stops in the remaining distance (v² = 2 a d), one step early.
        let v_stop = sqrtf(2.0 * dec * (rem.abs() - (self.vel.abs() * dt).min(rem.abs())));
        let v_goal = dir * vmax.min(v_stop);
        self.ramp_to(v_goal, acc, dec, dt);
        // Never overshoot within a step.
        let step = self.vel * dt;
        if (step > 0.0 && step > rem) || (step < 0.0 && step < rem) {
            self.pos = target;
            self.frac = 0.0;
            self.vel = 0.0;
            return true;
        }
        self.advance(dt);
        false
    }

    /// Ramps the velocity towards `v` (acceleration away from 0, deceleration towards it).
    fn ramp_to(&mut self, v: f32, acc: f32, dec: f32, dt: f32) {
        let dv = v - self.vel;
        let speeding_up = v.abs() > self.vel.abs() && v * self.vel >= 0.0;
        let a = if speeding_up { acc } else { dec } * dt;
        self.vel += dv.clamp(-a, a);
    }
}

fn libm_floor(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// Square root for `no_std` (Newton iterations from the bit-level estimate).
fn sqrtf(x: f32) -> f32 {
    if x <= 0.0 {
        return 0.0;
    }
    let mut y = f32::from_bits((x.to_bits() >> 1) + 0x1FBD_1DF5);
    for _ in 0..3 {
        y = 0.5 * (y + x / y);
    }
    y
}

/// Homing phases.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Homing {
    /// Not started (or interrupted).
    Idle,
    /// Method 3: moving positive to find the home switch.
    SeekSwitch,
    /// Method 3: moving negative until the switch releases.
    LeaveSwitch,
    /// Method 3: moving negative to the first index pulse.
    SeekIndex,
    /// Home found; coming to rest.
    Stopping,
    /// Homing attained.
    Done,
    /// Homing error (unsupported method).
    Error,
}

/// The CiA402 joint drive application.
pub struct Cia402Drive<H: JointHw> {
    /// The hardware.
    pub hw: H,
    /// Hardware constants.
    pub params: DriveParams,
    fsm: Fsm,
    io: Option<Io>,
    /// The current loop: run here on the host rig; on a board, its command and the last
    /// feedback, handed to and from the loop in the ADC interrupt.
    current: CurrentLoop,
    // Position / velocity (cycle context).
    zero: i32,
    last_raw: Option<i32>,
    vel: f32,
    vel_int: f32,
    prof: Profile,
    torque_dem: f32,
    active_mode: i8,
    fault: Option<u16>,
    fault_new: bool,
    cycle_measured: Option<f32>,
    fe_time: f32,
    in_window_time: f32,
    last_cw: u16,
    pp_target: i32,
    pp_buffered: Option<i32>,
    pp_done: bool,
    ack: bool,
    homing: Homing,
    limit_active: bool,
    emcy: [Option<(u16, u8)>; 4],
    transitions: u32,
    last_transition: Option<u8>,
    ip: Interpolator,
    in_op: bool,
}

/// Linear interpolation of interpolated position mode: the demand goes from the previous
/// set-point to the current one in `n` equal steps, one per drive cycle, `n` = the
/// interpolation period 0x60C2 in drive cycles; a new set-point 0x60C1:01 is taken every
/// `n` cycles.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Interpolator {
    /// Taking set-points (controlword bit 4 "enable ip mode").
    active: bool,
    prev: i32,
    next: i32,
    /// Cycles into the current period (1 ..= n).
    k: u32,
}

impl<H: JointHw> Cia402Drive<H> {
    /// A drive on `hw`.
    pub fn new(hw: H, params: DriveParams) -> Self {
        Self {
            hw,
            params,
            fsm: Fsm::new(),
            io: None,
            current: CurrentLoop::new(&params),
            zero: 0,
            last_raw: None,
            vel: 0.0,
            vel_int: 0.0,
            prof: Profile::default(),
            torque_dem: 0.0,
            active_mode: 0,
            fault: None,
            fault_new: false,
            cycle_measured: None,
            fe_time: 0.0,
            in_window_time: 0.0,
            last_cw: 0,
            pp_target: 0,
            pp_buffered: None,
            pp_done: true,
            ack: false,
            homing: Homing::Idle,
            limit_active: false,
            emcy: [None; 4],
            transitions: 0,
            last_transition: None,
            ip: Interpolator::default(),
            in_op: false,
        }
    }

    /// The state of the drive.
    pub fn state(&self) -> State {
        self.fsm.state()
    }

    /// The last state-machine transition taken.
    pub fn last_transition(&self) -> Option<u8> {
        self.last_transition
    }

    /// The pending fault code.
    pub fn fault(&self) -> Option<u16> {
        self.fault
    }

    /// The current reference of the current loop \[A\].
    pub fn current_reference(&self) -> f32 {
        self.current.cmd.iq_ref
    }

    /// What the current loop is to do, as the last hook left it: a board whose loop runs
    /// in an interrupt hands it over after each hook ([`JointHw::power_stage`]).
    pub fn current_command(&self) -> CurrentCommand {
        self.current.command()
    }

    /// Takes the current loop's measurement (the host rig after each tick, a board before
    /// each hook): the q-axis current for the actual values, an over-current as a fault.
    pub fn current_feedback(&mut self, fb: CurrentFeedback) {
        self.current.feedback = CurrentFeedback {
            iq: fb.iq,
            overcurrent: false,
        };
        if fb.overcurrent {
            self.raise_fault(error::OVERCURRENT);
        }
    }

    /// Takes the next queued emergency `(error code, error register)` (the stack takes them
    /// through `Application::next_emergency`).
    pub fn take_emergency(&mut self) -> Option<(u16, u8)> {
        let e = self.emcy[0].take();
        self.emcy.rotate_left(1);
        e
    }

    fn queue_emergency(&mut self, code: u16, reg: u8) {
        if let Some(slot) = self.emcy.iter_mut().find(|e| e.is_none()) {
            *slot = Some((code, reg));
        }
    }

    /// Raises a fault (0x603F, emergency; the state machine takes transition 13 on the
    /// next cycle). A latched fault is kept until a fault reset (transition 15) clears it.
    pub fn raise_fault(&mut self, code: u16) {
        if self.fault.is_none() {
            self.fault = Some(code);
            self.fault_new = true;
            // Error register 0x1001: generic, + current (0x2xxx), + communication (0x81xx).
            let reg = if code & 0xF000 == 0x2000 {
                0x03
            } else if code & 0xFF00 == 0x8100 {
                0x11
            } else {
                0x01
            };
            self.queue_emergency(code, reg);
        }
    }

    /// The time between application cycles as its host measures it \[s\] (a twin: the
    /// virtual time between two cycles, whatever the sync mode); it takes precedence over
    /// 0x1C32:02 and [`DriveParams::cycle_s`]. `None`: not measured.
    pub fn set_cycle_time(&mut self, s: Option<f32>) {
        self.cycle_measured = s.filter(|s| s.is_finite() && *s > 0.0);
    }

    fn cycle_s<const N: usize>(&self, od: &Od<N>) -> f32 {
        if let Some(s) = self.cycle_measured {
            return s;
        }
        match od.get::<u32>(0x1C32, 2) {
            Ok(ns) if ns > 0 => ns as f32 * 1e-9,
            _ => self.params.cycle_s,
        }
    }

    /// The interpolation period 0x60C2 (sub 1 × 10^sub 2 s) in drive cycles of `dt`, at
    /// least 1 (a period below the cycle interpolates nothing).
    fn ip_cycles<const N: usize>(od: &Od<N>, dt: f32) -> u32 {
        let units = od.get::<u8>(0x60C2, 1).unwrap_or(1).max(1) as f32;
        let index = od.get::<i8>(0x60C2, 2).unwrap_or(-3).clamp(-6, 0);
        let mut period = units;
        for _ in 0..-index {
            period *= 0.1;
        }
        let n = period / dt + 0.5;
        if n >= 1.0 {
            n.min(1_000_000.0) as u32
        } else {
            1
        }
    }

    /// What the drive does when its connection to the master is aborted (leaving OP: the
    /// SM watchdog expired, or the master took it down), by the abort connection option
    /// code 0x6007: 0 nothing (the last set-points stay), 1 a fault ([`error::COMMUNICATION`],
    /// then the fault reaction 0x605E), 2 the Disable voltage command (the motor coasts),
    /// 3 the Quick stop command (ramp by 0x605A). A dictionary without 0x6007 (a twin) does
    /// 3.
    fn abort_connection<const N: usize>(&mut self, od: &mut Od<N>) {
        match od
            .get::<i16>(0x6007, 0)
            .unwrap_or(super::device::ABORT_CONNECTION_DEFAULT)
        {
            0 => {}
            1 => self.raise_fault(error::COMMUNICATION),
            2 => {
                let _ = od.set(0x6040, 0, cw::DISABLE_VOLTAGE);
            }
            _ => {
                let _ = od.set(0x6040, 0, cw::QUICK_STOP_CMD);
            }
        }
    }

    fn rad_per_count(&self) -> f32 {
        core::f32::consts::TAU / self.params.counts_per_rev as f32
    }

    fn rated_torque_nm<const N: usize>(io: &Io, od: &Od<N>) -> f32 {
        io.motor::<u32, N>(od, 0x6076, 0, 200) as f32 * 1e-3
    }

    fn shift_zero(&mut self, new_zero: i32) {
        let d = new_zero.wrapping_sub(self.zero);
        self.zero = new_zero;
        self.prof.shift(d);
        self.pp_target = self.pp_target.wrapping_sub(d);
    }

    fn limits<const N: usize>(od: &Od<N>) -> Option<(i32, i32)> {
        let lo = od.get::<i32>(0x607D, 1).unwrap_or(0);
        let hi = od.get::<i32>(0x607D, 2).unwrap_or(0);
        (lo < hi).then_some((lo, hi))
    }

    fn clamp_limits<const N: usize>(&mut self, od: &Od<N>, p: i32) -> i32 {
        match Self::limits(od) {
            Some((lo, hi)) if p < lo || p > hi => {
                self.limit_active = true;
                p.clamp(lo, hi)
            }
            _ => p,
        }
    }

    /// One application cycle (SYNC0 / free run): see the module table.
    pub fn run_cycle<const N: usize>(&mut self, od: &mut Od<N>) {
        if self.io.is_none() {
            self.io = Io::resolve(od);
        }
        let Some(io) = self.io else {
            return;
        };
        let dt = self.cycle_s(od);
        let u32o = |i: u16, s: u8, d: u32| io.param(od, i, s, d) as f32;
        let motor = |i: u16, d: u32| io.motor::<u32, N>(od, i, 0, d) as f32;
        let i16o = |i: u16, d: i16| od.get::<i16>(i, 0).unwrap_or(d);
        let f32o = |s: u8, d: f32| io.motor::<f32, N>(od, 0x2000, s, d);
        let pp_vmax = u32o(0x6081, 0, 200_000);
        let pp_win = u32o(0x6067, 0, 200);
        let pp_wtime = u32o(0x6068, 0, 5) * 1e-3;
        let t_slope = u32o(0x6087, 0, 10_000);
        let rated_i = motor(0x6075, 4000) * 1e-3;
        let opt = Options {
            quick_stop: i16o(0x605A, 2),
            shutdown: i16o(0x605B, 0),
            disable_operation: i16o(0x605C, 1),
            halt: i16o(0x605D, 1),
            fault_reaction: i16o(0x605E, 2),
        };
        let acc = u32o(0x6083, 0, 2_000_000).max(1.0);
        let dec = u32o(0x6084, 0, 2_000_000).max(1.0);
        let qdec = u32o(0x6085, 0, 8_000_000).max(1.0);
        let vmax_motor = motor(0x6080, 1_000_000);
        let rated = Self::rated_torque_nm(&io, od);
        let max_torque = motor(0x6072, 3000) * 1e-3 * rated;
        let vel_window = u32o(0x606D, 0, 2000);
        let kp_v = f32o(3, super::device::gains::VELOCITY_KP);
        let ki_v = f32o(4, super::device::gains::VELOCITY_KI);
        let kp_p = f32o(5, super::device::gains::POSITION_KP);
        self.current.cmd.kp = f32o(1, super::device::gains::CURRENT_KP);
        self.current.cmd.ki = f32o(2, super::device::gains::CURRENT_KI);

        // Feedback.
        let raw = self.hw.encoder();
        let mut pos = raw.wrapping_sub(self.zero);
        let v_now = match self.last_raw {
            Some(l) => raw.wrapping_sub(l) as f32 / dt,
            None => 0.0,
        };
        self.last_raw = Some(raw);
        // First-order filter (≈ 160 Hz at 1 kHz).
        self.vel += 0.5 * (v_now - self.vel);
        let home_switch = self.hw.home_switch();

        // Following error monitor (position modes, drive powered, not coasting).
        let fe = self.prof.pos.wrapping_sub(pos);
        let position_mode = matches!(self.active_mode, mode::PP | mode::HM | mode::IP | mode::CSP);
        let fe_window = io.param(od, 0x6065, 0, u32::MAX);
        let fe_timeout = od.get::<u16>(0x6066, 0).unwrap_or(0) as f32 * 1e-3;
        let fe_over = self.current.cmd.power
            && position_mode
            && fe_window != u32::MAX
            && fe.unsigned_abs() > fe_window
            && self.fsm.state() == State::OperationEnabled;
        if fe_over {
            self.fe_time += dt;
            if self.fe_time > fe_timeout {
                self.raise_fault(error::FOLLOWING_ERROR);
            }
        } else {
            self.fe_time = 0.0;
        }

        // State machine.
        let cwv = od.load(io.controlword);
        let ramp_done = self.prof.vel == 0.0 && self.vel.abs() <= vel_window;
        let ev = Events {
            fault: core::mem::take(&mut self.fault_new),
            stopped: ramp_done,
        };
        let before = self.fsm.state();
        let t = self.fsm.step(cwv, ev, &opt);
        if let Some(t) = t {
            self.transitions += 1;
            self.last_transition = Some(t);
            if t == 15 {
                self.fault = None;
                self.queue_emergency(0x0000, 0x00);
            }
        }
        let state = self.fsm.state();
        let entering = state.powered() && !before.powered();
        if entering || (state == State::OperationEnabled && t == Some(16)) {
            self.prof = Profile::at(pos);
            self.vel_int = 0.0;
            self.pp_target = pos;
            self.pp_buffered = None;
            self.pp_done = true;
            self.ip.active = false;
        }

        // Mode switch (takes effect at once; unsupported values are ignored).
        let want = io.mode.map_or(io.fixed_mode, |m| od.load(m));
        if want != self.active_mode
            && matches!(
                want,
                mode::PP
                    | mode::PV
                    | mode::PT
                    | mode::HM
                    | mode::IP
                    | mode::CSP
                    | mode::CSV
                    | mode::CST
            )
        {
            self.active_mode = want;
            self.pp_target = self.prof.pos;
            self.pp_buffered = None;
            self.pp_done = true;
            self.homing = Homing::Idle;
            self.ip.active = false;
            self.torque_dem = ld(od, io.torque_actual) as f32;
        }

        let rising4 = cwv & cw::NEW_SET_POINT != 0 && self.last_cw & cw::NEW_SET_POINT == 0;
        let halt = cwv & cw::HALT != 0;
        self.last_cw = cwv;
        self.limit_active = false;

        // Set-points: None = velocity control only.
        let mut pos_control = true;
        let mut vel_dem = 0.0f32;
        let mut vff = 0.0f32;
        let mut tff = 0.0f32;
        let mut torque_only: Option<f32> = None;
        let mut torque_limit = max_torque;
        let mut target_reached = false;
        let mut oms12 = false;
        let mut oms13 = false;

        if !state.powered() || self.fault_coasting() {
            self.current.cmd.power = false;
            self.prof = Profile::at(pos);
            self.vel_int = 0.0;
            self.current.cmd.iq_ref = 0.0;
        } else if let Some(stop) = self.fsm.stopping() {
            self.stop_ramp(
                stop.ramp,
                dec,
                qdec,
                dt,
                pos,
                &mut pos_control,
                &mut torque_limit,
                max_torque,
            );
        } else {
            let m = self.active_mode;
            if halt && matches!(m, mode::PP | mode::PV | mode::HM) {
                let r = Options::halt_ramp(opt.halt);
                self.stop_ramp(
                    r,
                    dec,
                    qdec,
                    dt,
                    pos,
                    &mut pos_control,
                    &mut torque_limit,
                    max_torque,
                );
                target_reached = self.prof.vel == 0.0;
                oms12 = m == mode::PV && self.vel.abs() <= vel_window;
                if m == mode::HM && self.homing != Homing::Done {
                    self.homing = Homing::Idle;
                }
            } else {
                match m {
                    mode::PP => {
                        if rising4 {
                            let mut t = ld(od, io.target_position);
                            if cwv & cw::RELATIVE != 0 {
                                t = self.pp_target.wrapping_add(t);
                            }
                            let t = self.clamp_limits(od, t);
                            if cwv & cw::CHANGE_SET_IMMEDIATELY != 0 || self.pp_done {
                                self.pp_target = t;
                                self.pp_buffered = None;
                                self.pp_done = false;
                            } else {
                                self.pp_buffered = Some(t);
                            }
                            self.ack = true;
                        } else if cwv & cw::NEW_SET_POINT == 0 {
                            self.ack = false;
                        }
                        let vmax = pp_vmax.min(vmax_motor);
                        if !self.pp_done {
                            self.pp_done = self.prof.move_to(self.pp_target, vmax, acc, dec, dt);
                        }
                        if self.pp_done {
                            if let Some(b) = self.pp_buffered.take() {
                                self.pp_target = b;
                                self.pp_done = false;
                            }
                        }
                        vff = self.prof.vel;
                        let win = pp_win;
                        let wtime = pp_wtime;
                        if self.pp_done
                            && (self.pp_target.wrapping_sub(pos).unsigned_abs() as f32) <= win
                        {
                            self.in_window_time += dt;
                        } else {
                            self.in_window_time = 0.0;
                        }
                        target_reached = self.pp_done && self.in_window_time >= wtime;
                        oms12 = self.ack;
                        oms13 = self.fe_time > 0.0;
                    }
                    mode::PV => {
                        pos_control = false;
                        let target =
                            (ld(od, io.target_velocity) as f32).clamp(-vmax_motor, vmax_motor);
                        self.prof.ramp_to(target, acc, dec, dt);
                        vel_dem = self.prof.vel;
                        self.prof.pos = pos;
                        self.prof.frac = 0.0;
                        target_reached = (self.vel - target).abs() <= vel_window;
                        oms12 = self.vel.abs() <= vel_window;
                    }
                    mode::PT => {
                        let target = ld(od, io.target_torque) as f32;
                        let slope = t_slope * dt;
                        self.torque_dem += (target - self.torque_dem).clamp(-slope, slope);
                        torque_only = Some(self.torque_dem * 1e-3 * rated);
                        target_reached = self.torque_dem == target;
                    }
                    mode::HM => {
                        self.homing_step(&io, od, rising4, home_switch, raw, acc, dec, dt);
                        // Homing may have moved the zero.
                        pos = raw.wrapping_sub(self.zero);
                        vff = self.prof.vel;
                        oms12 = self.homing == Homing::Done;
                        oms13 = self.homing == Homing::Error;
                        target_reached =
                            matches!(self.homing, Homing::Done | Homing::Error | Homing::Idle)
                                && self.prof.vel == 0.0;
                    }
                    mode::IP => {
                        // Controlword bit 4: enable ip mode; sub mode 0 (linear) only.
                        let enabled = cwv & cw::NEW_SET_POINT != 0
                            && od.get::<i16>(0x60C0, 0).unwrap_or(0) == 0;
                        if enabled {
                            let n = Self::ip_cycles(od, dt);
                            let x = ld(od, io.ip_data);
                            if !self.ip.active {
                                // From where the demand is to the first set-point.
                                self.ip = Interpolator {
                                    active: true,
                                    prev: self.prof.pos,
                                    next: self.clamp_limits(od, x),
                                    k: 0,
                                };
                            }
                            self.ip.k += 1;
                            if self.ip.k > n {
                                self.ip.k = 1;
                                self.ip.prev = self.ip.next;
                                self.ip.next = self.clamp_limits(od, x);
                            }
                            let d = i64::from(self.ip.next.wrapping_sub(self.ip.prev));
                            let num = d * i64::from(self.ip.k);
                            let den = i64::from(n);
                            self.prof = Profile {
                                pos: self.ip.prev.wrapping_add((num / den) as i32),
                                frac: (num % den) as f32 / den as f32,
                                vel: d as f32 / (den as f32 * dt),
                            };
                            vff = self.prof.vel;
                        } else {
                            // Not enabled: hold the demand where it is.
                            self.ip.active = false;
                            self.prof.vel = 0.0;
                        }
                        // Statusword bit 12: ip mode active; bit 10: the demand is at rest.
                        oms12 = self.ip.active;
                        target_reached = !self.ip.active;
                    }
                    mode::CSP => {
                        let t = ld(od, io.target_position).wrapping_add(ld(od, io.position_offset));
                        let t = self.clamp_limits(od, t);
                        let v = t.wrapping_sub(self.prof.pos) as f32 / dt;
                        self.prof = Profile {
                            pos: t,
                            frac: 0.0,
                            vel: v,
                        };
                        // Velocity feed-forward: the set-point's own rate plus 0x60B1.
                        vff = v + ld(od, io.velocity_offset) as f32;
                        tff = ld(od, io.torque_offset) as f32 * 1e-3 * rated;
                        oms12 = true;
                        oms13 = self.fe_time > 0.0;
                    }
                    mode::CSV => {
                        pos_control = false;
                        vel_dem = (ld(od, io.target_velocity)
                            .wrapping_add(ld(od, io.velocity_offset))
                            as f32)
                            .clamp(-vmax_motor, vmax_motor);
                        tff = ld(od, io.torque_offset) as f32 * 1e-3 * rated;
                        self.prof = Profile {
                            pos,
                            frac: 0.0,
                            vel: vel_dem,
                        };
                        oms12 = true;
                    }
                    mode::CST => {
                        let t = ld(od, io.target_torque) as f32 + ld(od, io.torque_offset) as f32;
                        torque_only = Some(t * 1e-3 * rated);
                        self.prof = Profile {
                            pos,
                            frac: 0.0,
                            vel: self.vel,
                        };
                        oms12 = true;
                    }
                    _ => {
                        // No mode: hold position.
                    }
                }
            }
            self.current.cmd.power = true;
        }

        // Cascade.
        if self.current.cmd.power {
            let torque = match torque_only {
                Some(t) => {
                    self.vel_int = 0.0;
                    t
                }
                None => {
                    if pos_control {
                        let e = self.prof.pos.wrapping_sub(pos) as f32 + self.prof.frac;
                        vel_dem = kp_p * e + vff;
                    }
                    let vel_dem = vel_dem.clamp(-vmax_motor, vmax_motor);
                    let ev = (vel_dem - self.vel) * self.rad_per_count();
                    self.vel_int =
                        (self.vel_int + ki_v * ev * dt).clamp(-torque_limit, torque_limit);
                    kp_v * ev + self.vel_int + tff
                }
            };
            let torque = torque.clamp(-torque_limit, torque_limit);
            if (torque - torque_limit).abs() < 1e-9 || (torque + torque_limit).abs() < 1e-9 {
                self.limit_active = true;
            }
            self.current.cmd.iq_ref = torque / self.params.kt;
        }

        // Actual values and statusword.
        let fe_now = self.prof.pos.wrapping_sub(pos);
        st(od, io.position_actual, pos);
        st(od, io.position_demand, self.prof.pos);
        st(od, io.velocity_actual, self.vel as i32);
        st(od, io.following_error, fe_now);
        let t_act = self.current.feedback.iq * self.params.kt;
        st(od, io.torque_actual, (t_act / rated * 1000.0) as i16);
        st(
            od,
            io.current_actual,
            (self.current.feedback.iq / rated_i * 1000.0) as i16,
        );
        st(
            od,
            io.joint_torque,
            (self.hw.joint_torque() * 1000.0) as i32,
        );
        st(od, io.digital_inputs, if home_switch { 1 << 2 } else { 0 });
        st(od, io.mode_display, self.active_mode);
        st(od, io.error_code, self.fault.unwrap_or(0));
        let mut s = state.statusword_bits() | sw::REMOTE;
        if state == State::OperationEnabled {
            if target_reached {
                s |= sw::TARGET_REACHED;
            }
            if oms12 {
                s |= sw::OMS12;
            }
            if oms13 {
                s |= sw::OMS13;
            }
            if self.limit_active {
                s |= sw::INTERNAL_LIMIT;
            }
        }
        od.store(io.statusword, s);
    }

    fn fault_coasting(&self) -> bool {
        matches!(
            self.fsm.stopping(),
            Some(super::fsm::Stop {
                ramp: Ramp::Coast,
                ..
            })
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn stop_ramp(
        &mut self,
        ramp: Ramp,
        dec: f32,
        qdec: f32,
        dt: f32,
        pos: i32,
        pos_control: &mut bool,
        torque_limit: &mut f32,
        max_torque: f32,
    ) {
        match ramp {
            Ramp::SlowDown | Ramp::QuickStop => {
                let d = if ramp == Ramp::SlowDown { dec } else { qdec };
                self.prof.ramp_to(0.0, d, d, dt);
                self.prof.advance(dt);
            }
            Ramp::CurrentLimit | Ramp::VoltageLimit => {
                *pos_control = false;
                self.prof = Profile::at(pos);
                *torque_limit = if ramp == Ramp::VoltageLimit {
                    3.0 * max_torque
                } else {
                    max_torque
                };
            }
            Ramp::Coast => {}
        }
        self.current.cmd.power = true;
    }

    #[allow(clippy::too_many_arguments)]
    fn homing_step<const N: usize>(
        &mut self,
        io: &Io,
        od: &Od<N>,
        start: bool,
        switch: bool,
        raw: i32,
        _acc: f32,
        _dec: f32,
        dt: f32,
    ) {
        let method = od.get::<i8>(0x6098, 0).unwrap_or(37);
        let offset = od.get::<i32>(0x607C, 0).unwrap_or(0);
        let v_switch = io.param(od, 0x6099, 1, 100_000) as f32;
        let v_zero = io.param(od, 0x6099, 2, 20_000) as f32;
        let hacc = io.param(od, 0x609A, 0, 1_000_000).max(1) as f32;
        if start {
            self.homing = match method {
                35 | 37 => {
                    // Current position is the home position: actual = home offset.
                    self.shift_zero(raw.wrapping_sub(offset));
                    self.prof = Profile::at(offset);
                    Homing::Done
                }
                3 => {
                    if switch {
                        Homing::LeaveSwitch
                    } else {
                        Homing::SeekSwitch
                    }
                }
                _ => Homing::Error,
            };
            let _ = self.hw.index_latch();
        }
        let v_goal = match self.homing {
            Homing::SeekSwitch => {
                if switch {
                    self.homing = Homing::LeaveSwitch;
                }
                v_switch
            }
            Homing::LeaveSwitch => {
                if !switch {
                    self.homing = Homing::SeekIndex;
                    let _ = self.hw.index_latch();
                }
                -v_zero
            }
            Homing::SeekIndex => {
                if let Some(l) = self.hw.index_latch() {
                    self.shift_zero(l.wrapping_sub(offset));
                    self.homing = Homing::Stopping;
                    0.0
                } else {
                    -v_zero
                }
            }
            _ => 0.0,
        };
        self.prof.ramp_to(v_goal, hacc, hacc, dt);
        self.prof.advance(dt);
        if self.homing == Homing::Stopping && self.prof.vel == 0.0 {
            self.homing = Homing::Done;
        }
    }

    /// The 20 kHz current loop on the drive's own power stage ([`JointHw::power_stage`];
    /// nothing without one): one [`CurrentLoop::step`], then its feedback.
    pub fn run_current_loop(&mut self) {
        if let Some(stage) = self.hw.power_stage() {
            self.current.step(stage);
            let fb = self.current.take_feedback();
            self.current_feedback(fb);
        }
    }
}

impl<const N: usize, H: JointHw> Application<N> for Cia402Drive<H> {
    fn next_emergency(&mut self) -> Option<(u16, u8, [u8; 5])> {
        self.take_emergency().map(|(code, reg)| (code, reg, [0; 5]))
    }

    fn state_change(
        &mut self,
        _from: AlState,
        to: AlState,
        od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        if to == AlState::SafeOp && self.io.is_none() {
            self.io = Io::resolve(od);
        }
        self.in_op = to == AlState::Op;
        if matches!(to, AlState::Init | AlState::PreOp) {
            // No cycle runs below SAFEOP: the drive cannot control, so it lets go.
            self.current.cmd.power = false;
            self.current.cmd.iq_ref = 0.0;
            if let Some(stage) = self.hw.power_stage() {
                stage.set_voltage(false, 0.0);
            }
            let _ = od.set(0x6040, 0, 0u16);
        }
        Ok(())
    }

    /// Leaving OP (the SM watchdog, or the master): the connection is aborted, and the
    /// abort connection option code 0x6007 says what the drive does while SAFEOP cycles
    /// run (`Cia402Drive::abort_connection`). Entering SAFEOP from below: the controlword
    /// is Quick stop (0x0002), as no master has sent one yet.
    fn safe_outputs(&mut self, od: &mut Od<N>) {
        if core::mem::take(&mut self.in_op) {
            self.abort_connection(od);
        } else {
            let _ = od.set(0x6040, 0, cw::QUICK_STOP_CMD);
        }
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        self.run_cycle(od);
    }

    fn timer(&mut self, id: u8, _od: &mut Od<N>) {
        if id == CURRENT_LOOP_TIMER {
            self.run_current_loop();
        }
    }
}
