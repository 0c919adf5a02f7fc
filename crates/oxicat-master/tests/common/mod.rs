//! Segments of demo devices (oxicat-devices `demo`: definition, SII from oxicat-esi,
//! the `Demo` application on the oxicat-slave stack) for the master tests.
#![allow(dead_code)]

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex};

use oxicat_devices::demo::{self, Buttons, Demo, Leds};
use oxicat_esc::{Esc, EscConfig};
use oxicat_master::{Link, Master};
use oxicat_sim::firmware::{attach_firmware, FirmwareConfig, FirmwareHandle};
use oxicat_sim::segment::Segment;

/// LEDs the test can look at: bit 0 blue, bit 1 red.
#[derive(Clone, Default)]
pub struct SharedLeds(pub Arc<AtomicU8>);
impl Leds for SharedLeds {
    fn set(&mut self, blue: bool, red: bool) {
        self.0
            .store(blue as u8 | (red as u8) << 1, Ordering::Relaxed);
    }
}

/// Fixed buttons.
pub struct FixedButtons(pub u8);
impl Buttons for FixedButtons {
    fn read(&mut self) -> u8 {
        self.0
    }
}

/// Mailbox size of the demo device.
pub const MBX: usize = 128;
/// The demo firmware.
pub type DemoFw = Demo<SharedLeds, FixedButtons>;
/// Handle on one demo node.
pub type Handle = FirmwareHandle<DemoFw, { demo::IMAGE }, MBX>;

/// A line of `n` ET1100s running the demo firmware.
pub fn demo_segment(n: usize) -> (Arc<Mutex<Segment>>, Vec<Handle>, Vec<SharedLeds>) {
    let sii = oxicat_esi::sii::generate(&demo::DEF).expect("demo SII");
    let mut seg = Segment::new();
    let mut fws = Vec::new();
    let mut leds = Vec::new();
    for k in 0..n {
        let id = seg.add(Esc::new(EscConfig::et1100(), sii.clone()));
        let l = SharedLeds::default();
        leds.push(l.clone());
        let app = Demo::new(l, FixedButtons(0xA0 | k as u8));
        fws.push(
            attach_firmware::<_, { demo::IMAGE }, MBX>(
                &mut seg,
                id,
                &demo::DEF,
                app,
                &FirmwareConfig::default(),
            )
            .expect("firmware boots"),
        );
    }
    (Arc::new(Mutex::new(seg)), fws, leds)
}

/// A line of `n` ESC-only slaves (no firmware) with the demo SII.
pub fn esc_only_segment(n: usize) -> Arc<Mutex<Segment>> {
    let sii = oxicat_esi::sii::generate(&demo::DEF).expect("demo SII");
    let mut seg = Segment::new();
    for _ in 0..n {
        seg.add(Esc::new(EscConfig::et1100(), sii.clone()));
    }
    Arc::new(Mutex::new(seg))
}

/// A master on a demo segment of `n` nodes.
pub fn demo_master(n: usize) -> (Master, Arc<Mutex<Segment>>, Vec<Handle>, Vec<SharedLeds>) {
    let (seg, fws, leds) = demo_segment(n);
    let m = Master::open(Link::Sim(seg.clone())).expect("master opens");
    (m, seg, fws, leds)
}
