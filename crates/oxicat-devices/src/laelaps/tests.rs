//! Application-level tests of the leg node on fake hardware: state machine, trajectory
//! clock, left/right sign conventions closed-loop, transitions through the PDO, filter
//! bandwidth from the PDO, simultaneous start of several nodes.

extern crate std;

use super::app::{LegNode, Mode, PwmOut};
use super::device::{self, Command, Feedback, IMAGE};
use super::encoder::{CaptureConfig, EncoderIn, QepSample};
use super::hw::{Joint, CONTROL_PERIOD_S, JOINT_LOOP_TIMER};
use super::kinematics::{forward, inverse, Side};
use super::piv::{filter_coefficients, Gains, PwmCommand};
use super::trajectory::Ellipse;
use crate::demo::Leds;
use core::f32::consts::{PI, TAU};
use oxicat_slave::{AlState, Application, Od};
use std::cell::RefCell;
use std::rc::Rc;
use std::vec::Vec;

/// A toy plant per joint: motor speed proportional to the signed PWM (no load), an encoder
/// with 2000 counts per motor turn, eQEP capture emulated with the thesis' configuration.
#[derive(Default)]
struct Plant {
    /// Motor angle [counts] (f64 for a smooth integration).
    counts: [f64; 2],
    /// Motor speed [counts/s].
    speed: [f64; 2],
    /// Counts at the last unit event.
    last_event: [f64; 2],
    /// Time since the last unit event \[s\].
    since: [f64; 2],
    /// Last PWM command per joint.
    pwm: [PwmCommand; 2],
    /// All commands with non-zero duty seen.
    active_cmds: usize,
}

/// Motor no-load speed at full PWM [counts/s]: 50 motor rev/s.
const FULL_SPEED: f64 = 50.0 * 2000.0;

fn idx(j: Joint) -> usize {
    match j {
        Joint::Knee => 0,
        Joint::Hip => 1,
    }
}

impl Plant {
    fn step(&mut self, dt: f64) {
        for i in 0..2 {
            self.speed[i] = FULL_SPEED * self.pwm[i].signed() as f64;
            self.counts[i] += self.speed[i] * dt;
            self.since[i] += dt;
        }
    }
}

#[derive(Clone, Default)]
struct Hw(Rc<RefCell<Plant>>);

impl PwmOut for Hw {
    fn set(&mut self, joint: Joint, cmd: PwmCommand) {
        let mut p = self.0.borrow_mut();
        p.pwm[idx(joint)] = cmd;
        if cmd.duty > 0.0 {
            p.active_cmds += 1;
        }
    }
}

impl EncoderIn for Hw {
    fn sample(&mut self, joint: Joint) -> QepSample {
        let mut p = self.0.borrow_mut();
        let i = idx(joint);
        let c = p.counts[i];
        let edges = 4.0; // UPPS = 2
        let mut s = QepSample {
            position: (c.floor() as i64) as u32,
            forward: p.speed[i] >= 0.0,
            ..QepSample::default()
        };
        if (c - p.last_event[i]).abs() >= edges {
            let ticks = p.since[i] / CaptureConfig::THESIS.tick_s() as f64;
            s.unit_event = true;
            s.capture_overflow = ticks > 65535.0;
            s.capture_period = ticks.min(65535.0) as u16;
            p.last_event[i] = c;
            p.since[i] = 0.0;
        }
        s
    }
}

#[derive(Clone, Default)]
struct FakeLeds(Rc<RefCell<(bool, bool)>>);

impl Leds for FakeLeds {
    fn set(&mut self, blue: bool, red: bool) {
        *self.0.borrow_mut() = (blue, red);
    }
}

type Node = LegNode<Hw, Hw, FakeLeds>;

struct Bench {
    od: Od<IMAGE>,
    node: Node,
    hw: Hw,
    leds: FakeLeds,
}

impl Bench {
    fn new(side: Side) -> Self {
        let hw = Hw::default();
        let leds = FakeLeds::default();
        let mut od = Od::<IMAGE>::new(device::device(side)).unwrap();
        od.set(0x1C32, 2, 400_000u32).unwrap();
        let node = LegNode::new(side, hw.clone(), hw.clone(), leds.clone());
        Self { od, node, hw, leds }
    }

    /// One 400 µs bus cycle: SYNC0 application, then four 10 kHz loops with the plant.
    fn bus_cycle(&mut self) {
        self.node.cycle(&mut self.od);
        for _ in 0..4 {
            self.node.timer(JOINT_LOOP_TIMER, &mut self.od);
            self.hw.0.borrow_mut().step(CONTROL_PERIOD_S as f64);
        }
    }
}

/// Table 4-1 for one leg, with a and b as given.
fn table_4_1(a: f32, b: f32, phase_deg: f32, operational: bool) -> Command {
    let g = Gains {
        kp: 80.0,
        kd: 0.05,
        ki: 0.0,
    };
    Command {
        operational,
        blue_led: true,
        red_led: false,
        transition_time_s: 3.0,
        filter_hz: 20.0,
        knee: g,
        hip: g,
        ellipse: Ellipse {
            x_centre: 0.0,
            y_centre: 0.55,
            a,
            b,
            freq: 1.0,
            phase: phase_deg * PI / 180.0,
            flatness: 0.0,
        },
    }
}

#[test]
fn configuration_state_holds_clock_and_pwm() {
    let mut b = Bench::new(Side::Left);
    table_4_1(0.05, 0.04, 0.0, false).write(&mut b.od);
    for _ in 0..100 {
        b.bus_cycle();
    }
    assert_eq!(b.node.mode(), Mode::Configuration);
    assert_eq!(b.node.clock().nanos(), 0);
    assert_eq!(b.hw.0.borrow().active_cmds, 0, "no duty in Configuration");
    assert_eq!(*b.leds.0.borrow(), (true, false));
    assert_eq!(Feedback::read(&b.od).time_s, 0.0);

    // State_Machine = 1: the clock advances by the SYNC0 cycle (0x1C32:02) per cycle.
    b.od.set(0x7000, 1, true).unwrap();
    for k in 1..=250u64 {
        b.bus_cycle();
        assert_eq!(b.node.clock().nanos(), k * 400_000);
    }
    assert_eq!(b.node.mode(), Mode::Operational);
    assert!(b.hw.0.borrow().active_cmds > 0);
    assert_eq!(b.od.get::<u16>(0x6012, 1), Ok(10)); // 0.1 s in units of 0.01 s

    // Back to 0: clock reset, duty 0 from the next joint loop on.
    b.od.set(0x7000, 1, false).unwrap();
    b.bus_cycle();
    assert_eq!(b.node.clock().nanos(), 0);
    assert_eq!(b.hw.0.borrow().pwm, [PwmCommand::OFF; 2]);
}

#[test]
fn leaving_op_stops_the_motors() {
    let mut b = Bench::new(Side::Right);
    table_4_1(0.05, 0.04, 0.0, true).write(&mut b.od);
    for _ in 0..2500 {
        b.bus_cycle();
    }
    assert!(b.hw.0.borrow().pwm.iter().any(|p| p.duty > 0.0));
    Application::<IMAGE>::safe_outputs(&mut b.node, &mut b.od);
    let _ =
        Application::<IMAGE>::state_change(&mut b.node, AlState::Op, AlState::SafeOp, &mut b.od);
    assert_eq!(b.hw.0.borrow().pwm, [PwmCommand::OFF; 2]);
    assert_eq!(b.node.mode(), Mode::Configuration);
    assert_eq!(b.od.get::<bool>(0x7000, 1), Ok(false));
    b.node.timer(JOINT_LOOP_TIMER, &mut b.od);
    assert_eq!(b.hw.0.borrow().pwm, [PwmCommand::OFF; 2]);
}

#[test]
fn sync0_cycle_time_drives_the_clock() {
    let mut b = Bench::new(Side::Left);
    b.od.set(0x1C32, 2, 250_000u32).unwrap();
    table_4_1(0.0, 0.0, 0.0, true).write(&mut b.od);
    for _ in 0..8 {
        b.bus_cycle();
    }
    assert_eq!(b.node.clock().nanos(), 2_000_000);
}

/// Left and right nodes given the same command: desired joint-frame angles (PDO) of
/// opposite sign, motors turning opposite ways, the same kinematic motion of the leg.
#[test]
fn left_and_right_sign_conventions() {
    let mut l = Bench::new(Side::Left);
    let mut r = Bench::new(Side::Right);
    for b in [&mut l, &mut r] {
        table_4_1(0.0, 0.0, 0.0, true).write(&mut b.od);
    }
    // Stand (a = b = 0) at (0, 0.55) for 5 s (gains ramp in over the first 3 s).
    for _ in 0..2500 * 5 {
        l.bus_cycle();
        r.bus_cycle();
    }
    let want = inverse(0.0, 0.55).unwrap();
    let (fl, fr) = (Feedback::read(&l.od), Feedback::read(&r.od));
    // PDO (joint frame): left = +θ, right = −θ.
    assert!((fl.hip_desired - want.hip).abs() < 1e-3);
    assert!((fl.knee_desired - want.knee).abs() < 1e-3);
    assert!((fr.hip_desired + want.hip).abs() < 1e-3);
    assert!((fr.knee_desired + want.knee).abs() < 1e-3);
    // Both track; the right motors turned the other way (encoder counts opposite).
    for (f, sgn) in [(fl, 1.0), (fr, -1.0)] {
        assert!((f.hip - sgn * want.hip).abs() < 2e-3, "{f:?}");
        assert!((f.knee - sgn * want.knee).abs() < 2e-3, "{f:?}");
    }
    let (cl, cr) = (l.hw.0.borrow().counts, r.hw.0.borrow().counts);
    assert!(cl[0] * cr[0] < 0.0 && cl[1] * cr[1] < 0.0, "{cl:?} {cr:?}");
    // In the kinematic frame both legs are at the same place.
    for n in [&l.node, &r.node] {
        let (x, y) = forward(n.measured_angles());
        assert!(x.abs() < 2e-3 && (y - 0.55).abs() < 2e-3, "({x}, {y})");
    }
}

/// Ramps of a and b through the PDO are linear over Transition_time; gains ramp too.
#[test]
fn transitions_through_the_pdo() {
    let mut b = Bench::new(Side::Left);
    let mut cmd = table_4_1(0.0, 0.0, 0.0, false);
    cmd.transition_time_s = 2.0;
    cmd.write(&mut b.od);
    // Gains ramp from 0 to 80 over 2 s = 5000 cycles.
    let mut kps = Vec::new();
    for _ in 0..5000 {
        b.bus_cycle();
        kps.push(b.node.gains().0.kp);
    }
    for (k, kp) in kps.iter().enumerate() {
        let expect = 80.0 * (k + 1) as f32 / 5000.0;
        assert!((kp - expect).abs() < 1e-3, "cycle {k}: {kp}");
    }
    // b to 4 cm over 2 s.
    b.od.set(0x7030, 4, 4i16).unwrap();
    let mut bs = Vec::new();
    for _ in 0..5001 {
        b.bus_cycle();
        bs.push(b.node.ellipse().b);
    }
    for (k, b) in bs.iter().take(5000).enumerate() {
        let expect = 0.04 * (k + 1) as f32 / 5000.0;
        assert!((b - expect).abs() < 1e-6, "cycle {k}: {b}");
    }
    assert_eq!(bs[5000], 0.04);
    // Transition_time 0 in the PDO keeps the previous value.
    b.od.set(0x7000, 9, 0i8).unwrap();
    b.bus_cycle();
    assert_eq!(b.node.transition_s(), 2.0);
}

#[test]
fn filter_bandwidth_from_the_pdo() {
    let mut b = Bench::new(Side::Left);
    table_4_1(0.0, 0.0, 0.0, true).write(&mut b.od);
    b.bus_cycle();
    let (c1, c2) = filter_coefficients(20.0, CONTROL_PERIOD_S);
    let pid = b.node.joint(Joint::Knee).controller.pid;
    assert_eq!((pid.c1, pid.c2), (c1, c2));
    b.od.set(0x7012, 1, 35u16).unwrap();
    b.bus_cycle();
    let (c1, c2) = filter_coefficients(35.0, CONTROL_PERIOD_S);
    let pid = b.node.joint(Joint::Hip).controller.pid;
    assert_eq!((pid.c1, pid.c2), (c1, c2));
    // 0 keeps the last bandwidth.
    b.od.set(0x7012, 1, 0u16).unwrap();
    b.bus_cycle();
    assert_eq!(b.node.filter_hz(), 35.0);
    // Limits are the compile-time constants.
    assert_eq!(b.node.joint(Joint::Knee).controller.pid.umax, 0.3825);
    assert_eq!(b.node.joint(Joint::Hip).controller.pid.umin, -0.4117);
}

/// An ellipse leaving the workspace: the node keeps tracking the last reachable point.
#[test]
fn unreachable_trajectory_holds_last_point() {
    let mut b = Bench::new(Side::Left);
    let mut cmd = table_4_1(0.0, 0.0, 0.0, true);
    cmd.ellipse.y_centre = 0.58;
    cmd.ellipse.b = 0.04; // reaches y = 0.62 > l1 + l2
    cmd.ellipse.flatness = 1.0;
    cmd.transition_time_s = 1.0;
    cmd.operational = false;
    cmd.write(&mut b.od);
    b.bus_cycle(); // parameters are taken in Configuration
    b.od.set(0x7000, 1, true).unwrap();
    let mut held = 0;
    for _ in 0..2500 * 2 {
        b.bus_cycle();
        let (x, y) = b.node.target();
        if inverse(x, y).is_none() {
            held += 1;
            let (px, py) = b.node.tracked_point();
            assert!(inverse(px, py).is_some());
            let d = b.node.desired_angles();
            assert_eq!(Some(d), inverse(px, py));
        }
    }
    assert!(held > 100, "the ellipse must leave the workspace ({held})");
}

/// Four nodes with `State_Machine` set in the same cycle run bit-identical clocks, and
/// diagonal legs (same phase) get identical desired angles.
#[test]
fn four_nodes_start_in_the_same_cycle() {
    // HR, HL, FL, FR (chain order from Hind Right), Table 4-1 phases.
    let legs = [
        (Side::Right, 180.0),
        (Side::Left, 0.0),
        (Side::Left, 180.0),
        (Side::Right, 0.0),
    ];
    let mut nodes: Vec<Bench> = legs.iter().map(|(s, _)| Bench::new(*s)).collect();
    for (b, (_, ph)) in nodes.iter_mut().zip(legs) {
        table_4_1(0.05, 0.04, ph, false).write(&mut b.od);
    }
    for k in 0..3000 {
        if k == 1234 {
            for b in nodes.iter_mut() {
                b.od.set(0x7000, 1, true).unwrap();
            }
        }
        for b in nodes.iter_mut() {
            b.bus_cycle();
        }
        let t0 = nodes[0].node.clock().nanos();
        assert!(nodes.iter().all(|b| b.node.clock().nanos() == t0));
        if k > 1234 {
            // HR (180°) and FL (180°) are diagonal: same kinematic targets.
            assert_eq!(nodes[0].node.target(), nodes[2].node.target());
            assert_eq!(nodes[1].node.target(), nodes[3].node.target());
        }
    }
    assert_eq!(nodes[0].node.clock().nanos(), (3000 - 1234) * 400_000);
}

#[test]
fn velocity_reported_motor_side_in_joint_frame() {
    let mut b = Bench::new(Side::Right);
    table_4_1(0.05, 0.04, 0.0, true).write(&mut b.od);
    let mut seen = false;
    for _ in 0..2500 * 3 {
        b.bus_cycle();
        let fb = Feedback::read(&b.od);
        let plant = b.hw.0.borrow();
        // Compare with the plant's motor speed in rad/s (same sign convention: counts).
        let w = (plant.speed[0] / 2000.0 * TAU as f64) as f32;
        if w.abs() > 5.0 && fb.velocity_knee != 0.0 {
            seen = true;
            assert_eq!(fb.velocity_knee.signum(), w.signum());
        }
    }
    assert!(seen);
}

/// `cycle_ns` 0 (free run without a SYNC0 cycle) falls back to 400 µs.
#[test]
fn default_cycle_without_sync0() {
    let mut b = Bench::new(Side::Left);
    b.od.set(0x1C32, 2, 0u32).unwrap();
    table_4_1(0.0, 0.0, 0.0, true).write(&mut b.od);
    b.bus_cycle();
    assert_eq!(b.node.clock().nanos(), 400_000);
}
