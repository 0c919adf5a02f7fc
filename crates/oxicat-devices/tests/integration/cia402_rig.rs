//! The CiA402 joint drive on its joint (firmware + plant, 1 kHz cycles, 20 kHz current
//! loop): the paper's experiment, the modes, the following-error fault and its reset.

use std::cell::RefCell;
use std::rc::Rc;

use oxicat_devices::cia402::rig::{drive_params, JointBench, JointBoard, TICK_NS};
use oxicat_devices::cia402::{
    device, error, fsm::sw, mode, Cia402Drive, CurrentLoop, DriveParams, State,
};
use oxicat_plant::bldc_joint::{BldcJoint, BldcJointParams};
use oxicat_slave::Od;

fn bench() -> JointBench {
    JointBench::new(BldcJointParams::default())
}

fn enable(b: &mut JointBench) {
    b.command(0x06);
    b.command(0x07);
    let s = b.command(0x0F);
    assert_eq!(State::decode(s), Some(State::OperationEnabled), "{s:#06x}");
}

/// The paper's Experiment 1: controlword 0x06, 0x07, 0x0F; the statusword read back at
/// each step decodes to Ready to switch on, Switched on, Operation enabled.
///
/// The paper prints 0x4663 for Operation enabled. That value has bit 2 (operation
/// enabled) clear and bit 6 (switch on disabled) set: `0x4663 & 0x6F = 0x63` is no state
/// at all (Operation enabled is `sw & 0x6F == 0x27`). This drive answers 0x1237 in its
/// power-on mode CSP: 0x37 (ready, switched on, operation enabled, voltage enabled, no
/// quick stop) + bit 9 remote + bit 12 (CSP: drive follows the command value).
#[test]
fn paper_experiment_0x06_0x07_0x0f_reaches_operation_enabled() {
    let mut b = bench();
    assert_eq!(
        b.statusword() & 0x4F,
        0x40,
        "switch on disabled after power on"
    );
    let s = b.command(0x06);
    assert_eq!(s & 0x6F, 0x21);
    assert_eq!(State::decode(s), Some(State::ReadyToSwitchOn));
    let s = b.command(0x07);
    assert_eq!(s & 0x6F, 0x23);
    assert_eq!(State::decode(s), Some(State::SwitchedOn));
    let s = b.command(0x0F);
    assert_eq!(s & 0x6F, 0x27);
    assert_eq!(State::decode(s), Some(State::OperationEnabled));
    assert_eq!(s, 0x1237);
    assert_eq!(State::decode(0x4663), None, "the paper's value is no state");
    assert_eq!(b.od.get::<i8>(0x6061, 0).unwrap(), mode::CSP);
    assert_eq!(b.od.get::<u32>(0x6502, 0).unwrap() & (1 << 7), 1 << 7);
}

#[test]
fn csp_tracks_a_smooth_trajectory() {
    let mut b = bench();
    enable(&mut b);
    let cpr = 16_384.0f64;
    let mut max_fe = 0i32;
    let amp = 2.0 * cpr; // two motor turns
    for k in 0..4000 {
        let t = k as f64 * 1e-3;
        let p = amp * (1.0 - (std::f64::consts::TAU * 0.5 * t).cos()) / 2.0;
        let v = amp * std::f64::consts::PI * 0.5 * (std::f64::consts::TAU * 0.5 * t).sin();
        b.od.set(0x607A, 0, p.round() as i32).unwrap();
        // The drive differentiates the set-points for its velocity feed-forward; 0x60B1
        // adds to it (a small constant offset here, which the loop must absorb).
        let _ = v;
        b.od.set(0x60B1, 0, 100i32).unwrap();
        b.cycle();
        if k > 10 {
            let fe = b.od.get::<i32>(0x60F4, 0).unwrap();
            max_fe = max_fe.max(fe.abs());
        }
    }
    assert!(max_fe < 300, "max following error {max_fe} counts");
    assert_eq!(State::decode(b.statusword()), Some(State::OperationEnabled));
    // Out (two motor turns) and back: the link is home again.
    let j = &b.app.hw.joint;
    assert!(j.link_angle.abs() < 0.01, "{}", j.link_angle);
}

#[test]
fn following_error_trips_fault_0x8611_and_fault_reset_recovers() {
    let mut b = bench();
    enable(&mut b);
    b.app.hw.joint.link_locked = true;
    b.od.set(0x607A, 0, 200_000i32).unwrap();
    let mut tripped = false;
    for _ in 0..200 {
        b.cycle();
        if b.statusword() & sw::FAULT != 0 {
            tripped = true;
            break;
        }
    }
    assert!(tripped, "following error must trip");
    assert_eq!(b.app.fault(), Some(error::FOLLOWING_ERROR));
    assert_eq!(b.app.take_emergency(), Some((0x8611, 0x01)));
    b.run(50);
    assert_eq!(State::decode(b.statusword()), Some(State::Fault));
    assert_eq!(b.od.get::<u16>(0x603F, 0).unwrap(), 0x8611);
    // The joint is freed, the master takes the actual position as its target and resets.
    b.app.hw.joint.link_locked = false;
    b.run(100);
    let p = b.position();
    b.od.set(0x607A, 0, p).unwrap();
    b.command(0x00);
    let s = b.command(0x80);
    assert_eq!(State::decode(s), Some(State::SwitchOnDisabled), "{s:#06x}");
    assert_eq!(b.od.get::<u16>(0x603F, 0).unwrap(), 0);
    assert_eq!(
        b.app.take_emergency(),
        Some((0x0000, 0x00)),
        "error reset emergency"
    );
    let p = b.position();
    b.od.set(0x607A, 0, p).unwrap();
    enable(&mut b);
    b.run(100);
    assert_eq!(State::decode(b.statusword()), Some(State::OperationEnabled));
}

#[test]
fn homing_method_37_and_35_set_the_current_position_to_the_home_offset() {
    for method in [37i8, 35] {
        let mut b = bench();
        b.app.hw.joint.place(3.0);
        b.run(20); // the encoder jump settles in the velocity filter
        b.od.set(0x6060, 0, mode::HM).unwrap();
        b.od.set(0x6098, 0, method).unwrap();
        b.od.set(0x607C, 0, 1234i32).unwrap();
        enable(&mut b);
        b.command(0x1F);
        b.run(200);
        let s = b.statusword();
        assert!(
            s & sw::OMS12 != 0 && s & sw::TARGET_REACHED != 0,
            "{s:#06x}"
        );
        assert!((b.position() - 1234).abs() <= 2, "{}", b.position());
    }
}

#[test]
fn homing_method_3_finds_the_index_pulse_after_the_home_switch() {
    let p = BldcJointParams::default();
    let mut b = JointBench::new(p);
    b.od.set(0x6060, 0, mode::HM).unwrap();
    b.od.set(0x6098, 0, 3i8).unwrap();
    b.od.set(0x607C, 0, 0i32).unwrap();
    enable(&mut b);
    b.command(0x1F);
    let mut done = false;
    for _ in 0..10_000 {
        b.cycle();
        if b.statusword() & (sw::OMS12 | sw::TARGET_REACHED) == sw::OMS12 | sw::TARGET_REACHED {
            done = true;
            break;
        }
        assert!(b.statusword() & sw::OMS13 == 0, "homing error");
    }
    assert!(done, "homing attained");
    // Home is the first index pulse below the switch edge (link 0.1 rad = motor 10 rad):
    // motor index at 0.3 + k·2π → k = 1 (6.58 rad). Actual 0 there.
    let j = &b.app.hw.joint;
    let home_motor = 0.3 + std::f64::consts::TAU;
    let expect = (j.motor_angle - home_motor) / std::f64::consts::TAU * p.counts_per_rev as f64;
    assert!(
        (b.position() as f64 - expect).abs() <= 3.0,
        "actual {} expected {expect}",
        b.position()
    );
    assert!(!j.home_switch());
}

#[test]
fn profile_position_handshake_and_target_reached() {
    let mut b = bench();
    b.od.set(0x6060, 0, mode::PP).unwrap();
    enable(&mut b);
    b.od.set(0x607A, 0, 50_000i32).unwrap();
    let s = b.command(0x1F); // new set-point
    assert!(s & sw::OMS12 != 0, "set-point acknowledge");
    assert!(s & sw::TARGET_REACHED == 0);
    let s = b.command(0x0F);
    assert!(s & sw::OMS12 == 0, "acknowledge follows bit 4 down");
    let mut reached = false;
    for _ in 0..3000 {
        b.cycle();
        if b.statusword() & sw::TARGET_REACHED != 0 {
            reached = true;
            break;
        }
    }
    assert!(reached);
    assert!((b.position() - 50_000).abs() <= 200);
    // Relative, change immediately.
    b.od.set(0x607A, 0, -10_000i32).unwrap();
    b.command(0x0F | 0x10 | 0x20 | 0x40);
    b.command(0x0F);
    b.run(2000);
    assert!((b.position() - 40_000).abs() <= 200, "{}", b.position());
    // Software limits clamp the target.
    b.od.set(0x607D, 1, -100_000i32).unwrap();
    b.od.set(0x607D, 2, 60_000i32).unwrap();
    b.od.set(0x607A, 0, 90_000i32).unwrap();
    b.command(0x1F);
    b.command(0x0F);
    b.run(2000);
    assert!((b.position() - 60_000).abs() <= 200, "{}", b.position());
}

fn stop_distance(quick_stop_code: i16) -> (i32, State) {
    let mut b = bench();
    b.od.set(0x6060, 0, mode::PV).unwrap();
    b.od.set(0x605A, 0, quick_stop_code).unwrap();
    b.od.set(0x6084, 0, 500_000u32).unwrap();
    b.od.set(0x6085, 0, 4_000_000u32).unwrap();
    enable(&mut b);
    b.od.set(0x60FF, 0, 150_000i32).unwrap();
    b.run(800);
    let v = b.od.get::<i32>(0x606C, 0).unwrap();
    assert!((v - 150_000).abs() < 3000, "{v}");
    assert!(b.statusword() & sw::TARGET_REACHED != 0);
    let p0 = b.position();
    b.command(0x02);
    b.run(1500);
    (b.position() - p0, State::decode(b.statusword()).unwrap())
}

#[test]
fn quick_stop_ramps_follow_the_option_code() {
    let (slow, s1) = stop_distance(1);
    let (quick, s2) = stop_distance(2);
    let (climit, s3) = stop_distance(3);
    let (quick_stay, s6) = stop_distance(6);
    assert_eq!(s1, State::SwitchOnDisabled);
    assert_eq!(s2, State::SwitchOnDisabled);
    assert_eq!(s3, State::SwitchOnDisabled);
    assert_eq!(s6, State::QuickStopActive);
    // v²/2a: 150000²/(2·500000) = 22500 counts on the slow ramp, 2812 on the quick one.
    assert!((slow - 22_500).abs() < 2500, "{slow}");
    assert!((quick - 2_812).abs() < 1000, "{quick}");
    assert!(climit < quick, "current limit {climit} vs quick {quick}");
    assert!((quick_stay - quick).abs() < 300);
}

#[test]
fn profile_torque_and_cyclic_torque_drive_the_motor_current() {
    let mut b = bench();
    b.od.set(0x6060, 0, mode::PT).unwrap();
    b.app.hw.joint.link_locked = true;
    enable(&mut b);
    b.od.set(0x6071, 0, 500i16).unwrap(); // 50 % of 0.2 N·m
    b.run(300);
    let t = b.od.get::<i16>(0x6077, 0).unwrap();
    assert!((t - 500).abs() < 20, "{t}");
    assert!(b.statusword() & sw::TARGET_REACHED != 0);
    // The torque sensor (0x2002, mN·m, output side) sees N × the motor torque.
    let jt = b.od.get::<i32>(0x2002, 0).unwrap();
    assert!((jt - 10_000).abs() < 1000, "{jt}");
    b.od.set(0x6060, 0, mode::CST).unwrap();
    b.od.set(0x6071, 0, -200i16).unwrap();
    b.od.set(0x60B2, 0, -100i16).unwrap();
    b.run(50);
    let t = b.od.get::<i16>(0x6077, 0).unwrap();
    assert!((t + 300).abs() < 20, "{t}");
    assert_eq!(b.od.get::<i8>(0x6061, 0).unwrap(), mode::CST);
}

#[test]
fn csv_follows_target_velocity_plus_offset() {
    let mut b = bench();
    b.od.set(0x6060, 0, mode::CSV).unwrap();
    enable(&mut b);
    b.od.set(0x60FF, 0, 40_000i32).unwrap();
    b.od.set(0x60B1, 0, 10_000i32).unwrap();
    b.run(1000);
    let v = b.od.get::<i32>(0x606C, 0).unwrap();
    assert!((v - 50_000).abs() < 2000, "{v}");
}

#[test]
fn halt_stops_profile_velocity_and_stays_enabled() {
    let mut b = bench();
    b.od.set(0x6060, 0, mode::PV).unwrap();
    enable(&mut b);
    b.od.set(0x60FF, 0, 100_000i32).unwrap();
    b.run(500);
    b.command(0x10F);
    b.run(1000);
    let v = b.od.get::<i32>(0x606C, 0).unwrap();
    assert!(v.abs() < 2000, "{v}");
    let s = b.statusword();
    assert_eq!(State::decode(s), Some(State::OperationEnabled));
    assert!(s & sw::OMS12 != 0, "speed = 0");
}

#[test]
fn disable_operation_and_shutdown_ramps_then_switch_off() {
    for (cw, to) in [(0x07u16, State::SwitchedOn), (0x06, State::ReadyToSwitchOn)] {
        let mut b = bench();
        b.od.set(0x6060, 0, mode::PV).unwrap();
        b.od.set(0x605B, 0, 1i16).unwrap();
        b.od.set(0x605C, 0, 1i16).unwrap();
        enable(&mut b);
        b.od.set(0x60FF, 0, 100_000i32).unwrap();
        b.run(500);
        let s = b.command(cw);
        assert_eq!(State::decode(s), Some(State::OperationEnabled), "ramping");
        b.run(1000);
        assert_eq!(State::decode(b.statusword()), Some(to));
        assert!(b.app.hw.joint.motor_velocity.abs() < 1.0);
    }
}

/// Interpolated position mode (7), linear interpolation (0x60C0 = 0), interpolation period
/// 0x60C2 = 4 × 10⁻³ s on a 1 ms drive cycle: the master hands over one set-point of a ramp
/// in 0x60C1:01 per 4 ms; the drive interpolates between them, so its position demand
/// 0x6062 moves by the same step every 1 ms cycle (no staircase), the joint follows the
/// ramp, and statusword bit 12 says ip mode active while controlword bit 4 enables it.
#[test]
fn interpolated_position_mode_follows_a_ramp_with_linear_interpolation() {
    let mut b = bench();
    assert_ne!(
        b.od.get::<u32>(0x6502, 0).unwrap() & (1 << 6),
        0,
        "IP supported"
    );
    b.od.set(0x6060, 0, mode::IP).unwrap();
    b.od.set(0x60C0, 0, 0i16).unwrap();
    b.od.set(0x60C2, 1, 4u8).unwrap();
    b.od.set(0x60C2, 2, -3i8).unwrap();
    enable(&mut b);
    assert_eq!(b.od.get::<i8>(0x6061, 0).unwrap(), mode::IP);
    let x0 = b.position();
    b.od.set(0x60C1, 1, x0).unwrap();
    // Ramp: 20 000 inc/s = 80 inc per 4 ms period, 20 inc per 1 ms cycle.
    let v = 20_000i32;
    let mut demand = Vec::new();
    let mut max_err = 0i32;
    for k in 0..2000i32 {
        // The master's set-point generator runs at the interpolation period.
        if k % 4 == 0 {
            b.od.set(0x60C1, 1, x0 + v * k / 1000).unwrap();
        }
        b.command(0x1F); // enable operation + bit 4: enable ip mode
        demand.push(b.od.get::<i32>(0x6062, 0).unwrap());
        let s = b.statusword();
        assert_ne!(s & sw::OMS12, 0, "ip mode active at cycle {k}: {s:#06x}");
        if k > 100 {
            // Behind the ramp by the interpolation delay (≤ 2 periods) at most, plus the loop.
            let err = (x0 + v * k / 1000) - b.position();
            max_err = max_err.max(err.abs());
        }
    }
    // Linear interpolation: every cycle after the start moves the demand by 20 ± 1.
    let steps: Vec<i32> = demand.windows(2).map(|w| w[1] - w[0]).collect();
    for (k, d) in steps.iter().enumerate().skip(8) {
        assert!(
            (19..=21).contains(d),
            "cycle {k}: demand step {d} (not interpolated)"
        );
    }
    eprintln!("IP ramp: max distance to the ramp {max_err} counts");
    assert!(max_err < 400, "max distance to the ramp {max_err} counts");
    let end = b.position();
    assert!(
        (end - (x0 + 40_000)).abs() < 400,
        "{end} vs {}",
        x0 + 40_000
    );
    // Bit 4 off: ip mode inactive, the demand holds.
    b.command(0x0F);
    let held = b.od.get::<i32>(0x6062, 0).unwrap();
    b.run(50);
    assert_eq!(b.statusword() & sw::OMS12, 0);
    assert_eq!(b.od.get::<i32>(0x6062, 0).unwrap(), held);
    assert_eq!(State::decode(b.statusword()), Some(State::OperationEnabled));
}

/// The joint seen as a board with its current loop split off: the drive's sensors alone
/// (the image's `Sensors`), and the power stage the [`CurrentLoop`] runs on (its
/// `Bridge`), one plant behind both.
mod split {
    use std::cell::RefCell;
    use std::rc::Rc;

    use oxicat_devices::cia402::{JointHw, NoPowerStage, PowerStage};
    use oxicat_plant::bldc_joint::BldcJoint;

    /// The sensors: the drive's hardware, without a power stage.
    pub struct Sensors(pub Rc<RefCell<BldcJoint>>);

    impl JointHw for Sensors {
        type Power = NoPowerStage;
        fn encoder(&mut self) -> i32 {
            self.0.borrow().encoder_count()
        }
        fn index_latch(&mut self) -> Option<i32> {
            self.0.borrow_mut().take_index_latch()
        }
        fn home_switch(&mut self) -> bool {
            self.0.borrow().home_switch()
        }
        fn joint_torque(&mut self) -> f32 {
            self.0.borrow().gear_torque() as f32
        }
        fn power_stage(&mut self) -> Option<&mut NoPowerStage> {
            None
        }
    }

    /// The power stage, the current loop's.
    pub struct Bridge(pub Rc<RefCell<BldcJoint>>);

    impl PowerStage for Bridge {
        fn current(&mut self) -> f32 {
            self.0.borrow().current as f32
        }
        fn set_voltage(&mut self, enable: bool, volts: f32) {
            self.0.borrow_mut().set_voltage(enable, volts as f64);
        }
    }
}

/// Runs `cycles` 1 ms cycles of the drive twice on the same joint and script: as the rig
/// runs it (the current loop inside the drive, `run_current_loop` on the drive's power
/// stage) and as the board image does (the drive on the sensors alone, a separate
/// [`CurrentLoop`] stepping the power stage, the command handed to it after each cycle
/// and its feedback taken before). Asserts every cycle that both give the same
/// dictionary values, the same joint state and the same emergencies, bit for bit;
/// returns the one-context drive's dictionary and the emergencies it sent.
fn run_split_and_whole(
    params: DriveParams,
    cycles: usize,
    script: impl Fn(usize, &mut Od<{ device::IMAGE }>),
) -> (Od<{ device::IMAGE }>, Vec<(u16, u8)>) {
    let p = BldcJointParams::default();
    let mut whole = Cia402Drive::new(
        JointBoard {
            joint: BldcJoint::new(p),
        },
        params,
    );
    let mut od_w = Od::new(&device::DEF).unwrap();
    let joint = Rc::new(RefCell::new(BldcJoint::new(p)));
    let mut drive = Cia402Drive::new(split::Sensors(joint.clone()), params);
    let mut current = CurrentLoop::new(&params);
    let mut bridge = split::Bridge(joint.clone());
    let mut od_s = Od::new(&device::DEF).unwrap();
    let mut emergencies = Vec::new();
    for k in 0..cycles {
        script(k, &mut od_w);
        script(k, &mut od_s);
        for _ in 0..20 {
            whole.hw.joint.step(TICK_NS as f64 * 1e-9);
            whole.run_current_loop();
            joint.borrow_mut().step(TICK_NS as f64 * 1e-9);
            current.step(&mut bridge);
        }
        whole.run_cycle(&mut od_w);
        drive.current_feedback(current.take_feedback());
        drive.run_cycle(&mut od_s);
        current.set_command(drive.current_command());
        assert_eq!(
            whole.current_command(),
            drive.current_command(),
            "cycle {k}"
        );
        for (i, s) in [
            (0x6041u16, 0u8),
            (0x6064, 0),
            (0x6062, 0),
            (0x606C, 0),
            (0x6077, 0),
            (0x6078, 0),
            (0x603F, 0),
            (0x60F4, 0),
            (0x2002, 0),
        ] {
            assert_eq!(
                od_w.bytes(i, s).expect("the drive's object"),
                od_s.bytes(i, s).expect("the drive's object"),
                "cycle {k}: {i:#06x}:{s}"
            );
        }
        assert_eq!(whole.hw.joint, *joint.borrow(), "cycle {k}: the joint");
        let e = whole.take_emergency();
        assert_eq!(e, drive.take_emergency(), "cycle {k}: emergency");
        emergencies.extend(e);
    }
    (od_w, emergencies)
}

/// The board image's split (the current loop in its ADC interrupt, command and feedback
/// handed over around the drive's hooks) is the rig's drive, not an approximation of it:
/// enable and a 40,000-count CSP move give the same values every cycle.
#[test]
fn the_current_loop_split_off_as_on_the_board_runs_exactly_as_the_rig() {
    let (od, emergencies) =
        run_split_and_whole(drive_params(&BldcJointParams::default()), 1_000, |k, od| {
            let cw: u16 = match k {
                0..=9 => 0x06,
                10..=19 => 0x07,
                _ => 0x0F,
            };
            od.set(0x6040, 0, cw).unwrap();
            // A cosine move of 40,000 counts over 800 ms from cycle 50.
            let t = (k.saturating_sub(50) as f64 / 800.0).min(1.0);
            let x = 20_000.0 * (1.0 - (std::f64::consts::PI * t).cos());
            od.set(0x607A, 0, x.round() as i32).unwrap();
        });
    assert_eq!(emergencies, []);
    let s = od.get::<u16>(0x6041, 0).unwrap();
    assert_eq!(State::decode(s), Some(State::OperationEnabled), "{s:#06x}");
    let pos = od.get::<i32>(0x6064, 0).unwrap();
    assert!((pos - 40_000).abs() < 50, "at {pos}");
}

/// An over-current found by the split-off loop becomes the same fault and emergency in
/// the same cycle as when the drive runs the loop itself: CST at the rated torque (4 A)
/// with the trip lowered to 2 A.
#[test]
fn an_over_current_in_the_split_off_loop_faults_the_drive_as_on_the_rig() {
    let params = DriveParams {
        max_current: 2.0,
        ..drive_params(&BldcJointParams::default())
    };
    let (od, emergencies) = run_split_and_whole(params, 200, |k, od| {
        let cw: u16 = match k {
            0..=9 => 0x06,
            10..=19 => 0x07,
            _ => 0x0F,
        };
        od.set(0x6040, 0, cw).unwrap();
        od.set(0x6060, 0, mode::CST).unwrap();
        od.set(0x6071, 0, if k >= 50 { 1000i16 } else { 0 })
            .unwrap();
    });
    assert_eq!(emergencies, [(error::OVERCURRENT, 0x03)]);
    assert_eq!(od.get::<u16>(0x603F, 0).unwrap(), error::OVERCURRENT);
    let s = od.get::<u16>(0x6041, 0).unwrap();
    assert_eq!(State::decode(s), Some(State::Fault), "{s:#06x}");
}
