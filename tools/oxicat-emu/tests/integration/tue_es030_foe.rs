//! FoE on the TUeES030 motor-board image (`firmware/tue-es030`), the bytes that would be
//! flashed, on the emulated STM32F446: the stack's update flow (`FirmwareUpdate`, the host
//! rig's) on the image's flash store (sectors 6 and 7 through the FLASH interface, the
//! emulator's register-level FLASH model), driven by the master's FoE client in BOOT as
//! `crates/oxicat-devices/tests/integration/tue_es030_board.rs` drives the host-compiled board:
//!
//! - `version.txt` before any update is the host rig's (the same factory image);
//! - outside BOOT 0x8008, another file 0x8009, another device's image 0x800B, a flipped
//!   payload byte 0x800C, a truncated download 0x800B, an image larger than a slot 0x8003;
//!   none changes the bootable image, although the refused ones were erased into and
//!   programmed in the other slot;
//! - a good image installs: `version.txt` reports it, `firmware.bin` reads back equal,
//!   and the FLASH model's cells of the slot equal the file; the same image again 0x8006;
//! - a bad download after it (into the factory image's slot) keeps it the bootable one.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_devices::tue_es030::device::{with_identity, DEF};
use oxicat_devices::tue_es030::rig::{self, FIRMWARE_FILE};
use oxicat_emu::node::{EmulatedNode, NodeHandle};
use oxicat_emu::tue_es030::{TueBoardPlant, TueConfig};
use oxicat_esc::{Esc, EscConfig};
use oxicat_master::{Link, Master, MasterError, MasterOptions};
use oxicat_sim::segment::Segment;

use crate::common;

/// Slot 0 (sector 6) and slot 1 (sector 7) of the image's store; each a 16-byte mark,
/// then the image.
const SLOTS: [u32; 2] = [0x0804_0000, 0x0806_0000];
const MARK: u32 = 16;

fn image() -> Option<Vec<u8>> {
    common::image("tue-es030", "OXICAT_TUE_ES030_IMAGE")
}

fn foe_code(r: Result<(), MasterError>) -> u32 {
    r.err().and_then(|e| e.foe_code()).expect("an FoE refusal")
}

/// A master with room for the image's flash erases: a sector erase stalls the board's CPU
/// for 1 s of virtual time, which the master's polls (10 µs apart) take a while to cover.
fn master(link: Link) -> Master {
    let mut o = MasterOptions::for_link(&link);
    o.mailbox_timeout = Duration::from_secs(300);
    Master::open_with(link, o).expect("the master scans")
}

fn emulated(img: &[u8]) -> (Link, NodeHandle) {
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(&DEF).unwrap();
    let id = seg.add(Esc::new(EscConfig::lan9252(), sii));
    let plant = TueBoardPlant::new(&TueConfig::default());
    let node = EmulatedNode::with_plant(img.to_vec(), 100_000, Some(Box::new(plant))).unwrap();
    let handle = node.handle();
    seg.attach(id, Box::new(node)).unwrap();
    (Link::Sim(Arc::new(Mutex::new(seg))), handle)
}

fn version(m: &Master) -> String {
    let none = &mut |_: usize, _: usize| {};
    String::from_utf8(m.foe_read(0, "version.txt", 0, none).expect("version.txt")).unwrap()
}

fn flash(node: &NodeHandle, addr: u32, len: usize) -> Vec<u8> {
    node.read_memory(addr, len)
        .expect("the board thread runs")
        .expect("flash is readable")
}

fn mark(node: &NodeHandle, slot: usize) -> u32 {
    let b = flash(node, SLOTS[slot], 4);
    u32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

#[test]
fn foe_on_the_image_refuses_bad_images_as_the_host_and_installs_a_good_one_in_flash() {
    common::big(body);
}

fn body() {
    let Some(img) = image() else { return };
    // The host-compiled board's version.txt (its factory image).
    let host_version = {
        let mut seg = Segment::new();
        let sii = oxicat_esi::sii::generate(&DEF).unwrap();
        let id = seg.add(Esc::new(EscConfig::et1200(), sii));
        let _h = rig::attach(&mut seg, id, &TueConfig::default()).unwrap();
        version(&Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).unwrap())
    };
    let (link, node) = emulated(&img);
    let mut m = master(link);
    let none = &mut |_: usize, _: usize| {};
    let v0 = version(&m);
    assert_eq!(
        v0, host_version,
        "the image's factory image is the host rig's"
    );
    assert!(v0.contains("revision=0x00000001"), "{v0}");
    assert_eq!((mark(&node, 0), mark(&node, 1)), (1, 0xFFFF_FFFF));

    let good_def = with_identity(2, DEF.identity.product_code);
    let payload: Vec<u8> = (0..5000u32).map(|i| (i * 13 + 7) as u8).collect();
    let good = oxicat_esi::fwimage::build(&good_def, &payload);
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &good, none)),
        0x8008,
        "outside BOOT"
    );
    m.enter_boot(0).unwrap();
    assert_eq!(foe_code(m.foe_write(0, "app.bin", 0, &good, none)), 0x8009);
    let other = oxicat_esi::fwimage::build(&with_identity(2, 0x1234), &payload);
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &other, none)),
        0x800B,
        "another device's image"
    );
    let before = node.report().unwrap().flash;
    let mut corrupt = good.clone();
    corrupt[1000] ^= 0xFF;
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &corrupt, none)),
        0x800C,
        "a flipped payload byte"
    );
    let after = node.report().unwrap().flash;
    assert_eq!(
        after.erases,
        before.erases + 1,
        "the refused image went to flash"
    );
    assert!(after.programs > before.programs && after.stalled_cycles > 0);
    assert_eq!(
        flash(&node, SLOTS[1] + MARK, 1100)[..],
        corrupt[..1100],
        "slot 1 holds the corrupt image, unmarked"
    );
    assert_eq!(mark(&node, 1), 0xFFFF_FFFF);
    // A download cut short (the file ends before its header's length).
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &good[..3000], none)),
        0x800B,
        "a truncated download"
    );
    let huge = oxicat_esi::fwimage::build(&good_def, &vec![0x5A; 128 * 1024]);
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &huge, none)),
        0x8003,
        "larger than a slot"
    );
    assert_eq!(
        version(&m),
        v0,
        "nothing of that changed the bootable image"
    );

    m.foe_write(0, FIRMWARE_FILE, 0, &good, none)
        .expect("the good image installs");
    let v = version(&m);
    assert!(
        v.contains("revision=0x00000002") && v.contains("length=5000"),
        "{v}"
    );
    assert_eq!(m.foe_read(0, FIRMWARE_FILE, 0, none).unwrap(), good);
    assert_eq!(
        flash(&node, SLOTS[1] + MARK, good.len()),
        good,
        "the flash cells of slot 1 are the file"
    );
    assert_eq!(mark(&node, 1), 2, "slot 1 marked after slot 0's 1");
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &good, none)),
        0x8006,
        "the same image again"
    );
    // A bad download now goes into slot 0 (the factory image's): refused, and the image
    // just installed stays the bootable one.
    let next = oxicat_esi::fwimage::build(&with_identity(3, DEF.identity.product_code), &payload);
    let mut bad = next.clone();
    bad[4000] ^= 0x01;
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &bad, none)),
        0x800C
    );
    assert_eq!(
        mark(&node, 0),
        0xFFFF_FFFF,
        "the factory slot was erased into"
    );
    assert_eq!(version(&m), v);
    assert_eq!(m.foe_read(0, FIRMWARE_FILE, 0, none).unwrap(), good);
    m.leave_boot(0).unwrap();
    m.request_state(&[0], oxicat_master::AlState::PreOp)
        .unwrap();
    assert_eq!(version(&m), v, "after BOOT");
    let r = node.report().unwrap();
    assert_eq!(r.fault, None);
    eprintln!(
        "FoE on the image: {} sector erases, {} program operations, the CPU stalled {:.2} s \
         on the flash; {:.1} s simulated",
        r.flash.erases,
        r.flash.programs,
        r.flash.stalled_cycles as f64 / 180e6,
        r.time_ns as f64 * 1e-9
    );
}
