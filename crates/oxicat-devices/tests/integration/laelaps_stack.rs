//! The Laelaps leg node on the real slave stack, driven by master frames, through every
//! way its firmware can reach the ESC (software ESC; LAN9252 and ET1100 drivers over
//! simulated SPI): SyncManagers sized as a master sizes them (38/22 bytes), DC SYNC0 at
//! 400 µs advancing the trajectory clock, process data in and out.

use oxicat_devices::laelaps::device::{self, INPUT_BYTES, OUTPUT_BYTES};
use oxicat_devices::laelaps::hw::JOINT_LOOP_TIMER;
use oxicat_devices::laelaps::kinematics::{self, Side};
use oxicat_pdi::sim::BusConfig;
use oxicat_testkit::laelaps::{leg_to_op, trot_outputs};
use oxicat_testkit::Port;

/// One 400 µs cycle: SYNC0 (application) and four 10 kHz joint-loop events.
const STEPS: u64 = 4;

fn dc_sync0_on_the_stack<P: Port>() {
    let def = device::device(Side::Right);
    let mut b = leg_to_op::<P>(Side::Right, BusConfig::mhz(20), 400_000);
    // Advance past the first SYNC0s with State_Machine still 0: the clock stands.
    b.wr(def.sm2_start, &[0u8; OUTPUT_BYTES]);
    for _ in 0..5 {
        b.advance_steps(400_000, STEPS, Some(JOINT_LOOP_TIMER));
    }
    assert_eq!(b.app.clock().nanos(), 0, "{}", P::NAME);
    let out = trot_outputs();
    b.wr(def.sm2_start, &out);
    b.sync0 = 0;
    for _ in 0..250 {
        b.advance_steps(400_000, STEPS, Some(JOINT_LOOP_TIMER));
        b.wr(def.sm2_start, &out);
    }
    // The clock advanced by the SYNC0 cycle time (0x1C32:02) on every SYNC0 since
    // State_Machine = 1 arrived (frames take bus time too: more SYNC0s than loops).
    let cycles = b.sync0;
    assert!(cycles >= 250);
    assert_eq!(b.app.clock().nanos(), cycles * 400_000, "{}", P::NAME);
    assert_eq!(b.app.ellipse().y_centre, 0.599);
    let inp = b.rd(def.sm3_start, INPUT_BYTES).0;
    let time = u16::from_le_bytes([inp[4], inp[5]]);
    assert_eq!(
        time as u64,
        (cycles * 400_000 + 5_000_000) / 10_000_000,
        "Time"
    );
    // Right leg: the desired hip/knee angles in the PDO are the negated IK angles.
    let want = kinematics::inverse(0.0, 0.599).unwrap();
    let des_hip = i16::from_le_bytes([inp[2], inp[3]]);
    let des_knee = i16::from_le_bytes([inp[8], inp[9]]);
    let deg100 = |r: f32| (r * 18_000.0 / core::f32::consts::PI) as i16;
    assert!((des_hip - deg100(-want.hip)).abs() <= 1, "{des_hip}");
    assert!((des_knee - deg100(-want.knee)).abs() <= 1, "{des_knee}");
}

/// The left leg's device (22 input bytes as well) reaches OP and mirrors the signs.
fn left_leg_mirrors_the_angles<P: Port>() {
    let def = device::device(Side::Left);
    let mut b = leg_to_op::<P>(Side::Left, BusConfig::mhz(20), 400_000);
    let out = trot_outputs();
    b.wr(def.sm2_start, &out);
    for _ in 0..20 {
        b.advance_steps(400_000, STEPS, Some(JOINT_LOOP_TIMER));
        b.wr(def.sm2_start, &out);
    }
    let inp = b.rd(def.sm3_start, INPUT_BYTES).0;
    let want = kinematics::inverse(0.0, 0.599).unwrap();
    let des_hip = i16::from_le_bytes([inp[2], inp[3]]);
    let deg100 = |r: f32| (r * 18_000.0 / core::f32::consts::PI) as i16;
    assert!(
        (des_hip - deg100(want.hip)).abs() <= 1,
        "{des_hip} {}",
        P::NAME
    );
}

oxicat_testkit::every_pdi!(dc_sync0_on_the_stack, left_leg_mirrors_the_angles);
