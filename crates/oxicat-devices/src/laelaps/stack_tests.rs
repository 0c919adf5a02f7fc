//! The leg node on the real slave stack and a software ESC, driven by master frames: the
//! SyncManager sizes a master computes (38/22 bytes), DC SYNC0 at 400 µs advancing the
//! trajectory clock, process data in and out through the ESC.

extern crate std;

use super::app::{LegNode, PwmOut};
use super::device::{self, IMAGE, INPUT_BYTES, OUTPUT_BYTES};
use super::encoder::{EncoderIn, QepSample};
use super::hw::{Joint, JOINT_LOOP_TIMER};
use super::kinematics::Side;
use super::piv::PwmCommand;
use crate::demo::Leds;
use oxicat_esc::{Esc, EscConfig};
use oxicat_slave::{DeviceDef, Slave, SyncMode};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::sii::{MailboxArea, SiiConfig, SiiIdentity, SiiMailboxConfig};
use oxicat_wire::{Command, DatagramHeader, EcatFrame};
use std::vec;
use std::vec::Vec;

const STATION: u16 = 0x1001;

struct Hw;
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

fn eeprom(def: &DeviceDef) -> Vec<u8> {
    let mut e = vec![0u8; 2048];
    SiiConfig {
        pdi_control: 0x0005,
        ..Default::default()
    }
    .write(&mut e)
    .unwrap();
    SiiIdentity {
        vendor_id: def.identity.vendor_id,
        product_code: def.identity.product_code,
        revision: def.identity.revision,
        serial: def.identity.serial,
    }
    .write(&mut e)
    .unwrap();
    let m = def.mailbox;
    let area = |offset, size| MailboxArea { offset, size };
    SiiMailboxConfig {
        bootstrap_rx: area(m.rx_start, m.rx_len),
        bootstrap_tx: area(m.tx_start, m.tx_len),
        standard_rx: area(m.rx_start, m.rx_len),
        standard_tx: area(m.tx_start, m.tx_len),
        protocols: oxicat_wire::mailbox::protocols::COE,
    }
    .write(&mut e)
    .unwrap();
    e
}

struct Bench {
    esc: Esc,
    s: Slave<Esc, IMAGE, 128>,
    app: LegNode<Hw, Hw, Hw>,
    t: u64,
    sync0: u64,
}

impl Bench {
    fn new(side: Side) -> Self {
        let def = device::device(side);
        let mut esc = Esc::new(EscConfig::et1100(), eeprom(def));
        let s = Slave::new(def, &mut esc).unwrap();
        let mut b = Bench {
            esc,
            s,
            app: LegNode::new(side, Hw, Hw, Hw),
            t: 0,
            sync0: 0,
        };
        b.frame(Command::Apwr, 0, 0x0010, &STATION.to_le_bytes());
        b
    }

    fn frame(&mut self, cmd: Command, adp: u16, ado: u16, data: &[u8]) -> (Vec<u8>, u16) {
        let mut buf = vec![0u8; 1600];
        let mut fb = FrameBuilder::new_bare(&mut buf).unwrap();
        fb.push(
            DatagramHeader::physical(cmd, 0, adp, ado, data.len() as u16),
            data,
        )
        .unwrap();
        let n = fb.finish();
        buf.truncate(n);
        self.t += 10_000;
        self.esc.forward(0, &mut buf, self.t, true);
        let f = EcatFrame::parse(&buf).unwrap();
        let d = f.datagrams().next().unwrap().unwrap();
        (d.data.to_vec(), d.wkc)
    }

    fn wr(&mut self, ado: u16, data: &[u8]) -> u16 {
        self.frame(Command::Fpwr, STATION, ado, data).1
    }

    fn rd(&mut self, ado: u16, len: usize) -> Vec<u8> {
        self.frame(Command::Fprd, STATION, ado, &vec![0u8; len]).0
    }

    fn poll(&mut self) {
        for _ in 0..3 {
            self.s.poll(&mut self.esc, &mut self.app).unwrap();
        }
    }

    fn request(&mut self, state: u16) -> (u16, u16) {
        self.wr(0x0120, &state.to_le_bytes());
        self.poll();
        let d = self.rd(0x0130, 6);
        (
            u16::from_le_bytes([d[0], d[1]]),
            u16::from_le_bytes([d[4], d[5]]),
        )
    }

    fn config_sm(&mut self, n: u16, start: u16, len: u16, ctrl: u8) {
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&len.to_le_bytes());
        r[4] = ctrl;
        r[6] = u8::from(len > 0);
        self.wr(0x0800 + 8 * n, &r);
    }

    /// One 400 µs cycle: SYNC0 (application) and four 10 kHz joint-loop events.
    fn advance(&mut self, dt: u64) {
        for _ in 0..4 {
            self.t += dt / 4;
            let ev = self.esc.advance(self.t);
            if ev.sync0.is_some() {
                self.sync0 += 1;
                self.s.on_sync0(&mut self.esc, &mut self.app).unwrap();
            }
            self.s.on_timer(JOINT_LOOP_TIMER, &mut self.app);
        }
    }
}

#[test]
fn dc_sync0_on_the_stack() {
    let mut b = Bench::new(Side::Right);
    let def = device::device(Side::Right);
    b.config_sm(0, def.mailbox.rx_start, def.mailbox.rx_len, 0x26);
    b.config_sm(1, def.mailbox.tx_start, def.mailbox.tx_len, 0x22);
    assert_eq!(b.request(2), (2, 0));
    // A master sizes SM2/SM3 from the PDO assignment: 38 and 22 bytes.
    assert_eq!(def.default_output_bits(), 38 * 8);
    b.config_sm(2, def.sm2_start, OUTPUT_BYTES as u16, 0x64);
    b.config_sm(3, def.sm3_start, INPUT_BYTES as u16, 0x20);
    // DC SYNC0 at 400 µs.
    let st = b.rd(0x0910, 8);
    let now = u64::from_le_bytes(st.try_into().unwrap());
    b.wr(0x09A0, &400_000u32.to_le_bytes());
    b.wr(0x0990, &(now + 1_000_000).to_le_bytes());
    b.wr(0x0981, &[0x03]);
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::DcSync0);
    assert_eq!(b.s.output_bytes(), 38);
    assert_eq!(b.s.input_bytes(), 22);
    assert_eq!(b.request(8), (8, 0));

    // Outputs as the master writes them: State_Machine = 1, Table 4-1 (FR) parameters.
    let mut out = [0u8; OUTPUT_BYTES];
    out[0] = 0x01; // State_Machine
    out[1] = 3; // Transition_time
    out[6..8].copy_from_slice(&20u16.to_le_bytes()); // FilterBandwidth
    for (k, v) in [8000i16, 50, 0, 8000, 50, 0].iter().enumerate() {
        out[12 + 2 * k..14 + 2 * k].copy_from_slice(&v.to_le_bytes());
    }
    for (k, v) in [0i16, 599, 0, 0, 100, 0, 0].iter().enumerate() {
        out[24 + 2 * k..26 + 2 * k].copy_from_slice(&v.to_le_bytes());
    }
    // Advance to the first SYNC0 with State_Machine still 0.
    b.wr(def.sm2_start, &[0u8; OUTPUT_BYTES]);
    for _ in 0..5 {
        b.advance(400_000);
    }
    assert_eq!(b.app.clock().nanos(), 0);
    b.wr(def.sm2_start, &out);
    b.sync0 = 0;
    for _ in 0..250 {
        b.advance(400_000);
        b.wr(def.sm2_start, &out);
    }
    // The clock advanced by the SYNC0 cycle time (0x1C32:02) on every SYNC0 since
    // State_Machine = 1 arrived (frames take bus time too: more SYNC0s than loops).
    let cycles = b.sync0;
    assert!(cycles >= 250);
    assert_eq!(b.app.clock().nanos(), cycles * 400_000);
    assert_eq!(b.app.ellipse().y_centre, 0.599);
    let inp = b.rd(def.sm3_start, INPUT_BYTES);
    let time = u16::from_le_bytes([inp[4], inp[5]]);
    assert_eq!(
        time as u64,
        (cycles * 400_000 + 5_000_000) / 10_000_000,
        "Time"
    );
    // Right leg: the desired hip/knee angles in the PDO are the negated IK angles.
    let want = super::kinematics::inverse(0.0, 0.599).unwrap();
    let des_hip = i16::from_le_bytes([inp[2], inp[3]]);
    let des_knee = i16::from_le_bytes([inp[8], inp[9]]);
    let deg100 = |r: f32| (r * 18_000.0 / core::f32::consts::PI) as i16;
    assert!((des_hip - deg100(-want.hip)).abs() <= 1, "{des_hip}");
    assert!((des_knee - deg100(-want.knee)).abs() <= 1, "{des_knee}");
}
