//! The Laelaps II leg node on the bench: no motors or encoders attached, brought to OP in
//! DC SYNC0 mode the way a master does it.

use crate::bench::Bench;
use crate::ports::Port;
use oxicat_devices::demo::Leds;
use oxicat_devices::laelaps::device::{self, IMAGE, INPUT_BYTES, OUTPUT_BYTES};
use oxicat_devices::laelaps::encoder::{EncoderIn, QepSample};
use oxicat_devices::laelaps::hw::Joint;
use oxicat_devices::laelaps::kinematics::Side;
use oxicat_devices::laelaps::piv::PwmCommand;
use oxicat_devices::laelaps::{LegNode, PwmOut};
use oxicat_pdi::sim::BusConfig;
use oxicat_slave::SyncMode;

/// Hardware stand-in: PWM goes nowhere, the encoders stand still, the LEDs are dark.
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

/// A leg node on the bench.
pub type LegBench<P> = Bench<P, LegNode<Hw, Hw, Hw>, IMAGE>;

/// Brings a `side` leg node to OP in DC SYNC0 mode at `cycle_ns`, SyncManagers sized as
/// a master sizes them (38 output and 22 input bytes).
pub fn leg_to_op<P: Port>(side: Side, bus: BusConfig, cycle_ns: u32) -> LegBench<P> {
    let def = device::device(side);
    let app = LegNode::new(side, Hw, Hw, Hw);
    let mut b = LegBench::<P>::with(def, app, P::esc_config(), bus);
    b.config_mailbox();
    assert_eq!(b.request(2), (2, 0), "{}", P::NAME);
    assert_eq!(def.default_output_bits(), OUTPUT_BYTES as u32 * 8);
    b.config_sm(2, def.sm2_start, OUTPUT_BYTES as u16, 0x64);
    b.config_sm(3, def.sm3_start, INPUT_BYTES as u16, 0x20);
    let st = b.rd(0x0910, 8).0;
    let now = u64::from_le_bytes(st.try_into().unwrap());
    b.wr(0x09A0, &cycle_ns.to_le_bytes());
    b.wr(0x0990, &(now + 1_000_000).to_le_bytes());
    b.wr(0x0981, &[0x03]);
    assert_eq!(b.request(4), (4, 0), "{}", P::NAME);
    assert_eq!(b.s.sync_mode(), SyncMode::DcSync0);
    assert_eq!(b.s.output_bytes(), OUTPUT_BYTES);
    assert_eq!(b.s.input_bytes(), INPUT_BYTES);
    assert_eq!(b.request(8), (8, 0), "{}", P::NAME);
    b
}

/// Outputs as the master writes them: State_Machine = 1, Transition_time 3, filter
/// bandwidth 20, the Table 4-1 (FR) gains and ellipse (y centre 0.599 m, height 0.1 m).
pub fn trot_outputs() -> [u8; OUTPUT_BYTES] {
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
