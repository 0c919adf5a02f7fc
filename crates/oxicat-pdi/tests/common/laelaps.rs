//! The Laelaps leg on the driver bench (tests/stack.rs and examples/bus_time.rs).

use super::*;
use oxicat_devices::demo::Leds;
use oxicat_devices::laelaps::device::{self, IMAGE, INPUT_BYTES, OUTPUT_BYTES};
use oxicat_devices::laelaps::encoder::{EncoderIn, QepSample};
use oxicat_devices::laelaps::hw::{Joint, JOINT_LOOP_TIMER};
use oxicat_devices::laelaps::kinematics::{self, Side};
use oxicat_devices::laelaps::piv::PwmCommand;
use oxicat_devices::laelaps::{LegNode, PwmOut};
use oxicat_esc::EscConfig;
use oxicat_pdi::sim::BusConfig;
use oxicat_slave::SyncMode;

pub struct Hw;
impl PwmOut for Hw {
    fn set(&mut self, _: Joint, _: PwmCommand) {}
}
impl EncoderIn for Hw {
    fn sample(&mut self, _: Joint) -> QepSample {
        QepSample::default()
    }
}
impl Leds for Hw {
    fn set(&mut self, _: bool, _: bool) {}
}

pub type LegBench<C> = Bench<C, LegNode<Hw, Hw, Hw>, IMAGE>;

/// Brings a leg node to OP in DC SYNC0 mode at `cycle_ns`.
pub fn leg_to_op<C: Chip>(esc: EscConfig, bus: BusConfig, cycle_ns: u32) -> LegBench<C> {
    let def = device::device(Side::Right);
    let mut b = LegBench::<C>::with(def, LegNode::new(Side::Right, Hw, Hw, Hw), esc, bus);
    b.config_mailbox(def);
    assert_eq!(b.request(2), (2, 0));
    b.config_sm(2, def.sm2_start, OUTPUT_BYTES as u16, 0x64);
    b.config_sm(3, def.sm3_start, INPUT_BYTES as u16, 0x20);
    let st = b.rd(0x0910, 8).0;
    let now = u64::from_le_bytes(st.try_into().unwrap());
    b.wr(0x09A0, &cycle_ns.to_le_bytes());
    b.wr(0x0990, &(now + 1_000_000).to_le_bytes());
    b.wr(0x0981, &[0x03]);
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::DcSync0);
    assert_eq!(b.s.output_bytes(), 38);
    assert_eq!(b.s.input_bytes(), 22);
    assert_eq!(b.request(8), (8, 0));
    b
}

/// Outputs as the master writes them: State_Machine = 1, Table 4-1 (FR) parameters.
pub fn outputs() -> [u8; OUTPUT_BYTES] {
    let mut out = [0u8; OUTPUT_BYTES];
    out[0] = 0x01;
    out[1] = 3;
    out[6..8].copy_from_slice(&20u16.to_le_bytes());
    for (k, v) in [8000i16, 50, 0, 8000, 50, 0].iter().enumerate() {
        out[12 + 2 * k..14 + 2 * k].copy_from_slice(&v.to_le_bytes());
    }
    for (k, v) in [0i16, 599, 0, 0, 100, 0, 0].iter().enumerate() {
        out[24 + 2 * k..26 + 2 * k].copy_from_slice(&v.to_le_bytes());
    }
    out
}

pub fn dc_cycle<C: Chip>() {
    let def = device::device(Side::Right);
    let mut b = leg_to_op::<C>(EscConfig::et1100(), BusConfig::mhz(20), 400_000);
    let out = outputs();
    b.wr(def.sm2_start, &[0u8; OUTPUT_BYTES]);
    for _ in 0..5 {
        b.advance(400_000, 4, Some(JOINT_LOOP_TIMER));
    }
    assert_eq!(b.app.clock().nanos(), 0);
    b.wr(def.sm2_start, &out);
    b.sync0 = 0;
    for _ in 0..250 {
        b.advance(400_000, 4, Some(JOINT_LOOP_TIMER));
        b.wr(def.sm2_start, &out);
    }
    let cycles = b.sync0;
    assert!(cycles >= 250);
    assert_eq!(b.app.clock().nanos(), cycles * 400_000, "{}", C::NAME);
    assert_eq!(b.app.ellipse().y_centre, 0.599);
    let inp = b.rd(def.sm3_start, INPUT_BYTES).0;
    let time = u16::from_le_bytes([inp[4], inp[5]]);
    assert_eq!(time as u64, (cycles * 400_000 + 5_000_000) / 10_000_000);
    let want = kinematics::inverse(0.0, 0.599).unwrap();
    let des_hip = i16::from_le_bytes([inp[2], inp[3]]);
    let des_knee = i16::from_le_bytes([inp[8], inp[9]]);
    let deg100 = |r: f32| (r * 18_000.0 / core::f32::consts::PI) as i16;
    assert!((des_hip - deg100(-want.hip)).abs() <= 1, "{des_hip}");
    assert!((des_knee - deg100(-want.knee)).abs() <= 1, "{des_knee}");
    assert_eq!(b.h.stats().protocol_errors, 0, "{}", C::NAME);
}
