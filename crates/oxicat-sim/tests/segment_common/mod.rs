//! Helpers shared by oxicat-sim's integration tests: reference data by path, real devices.
#![allow(dead_code)]

use std::path::PathBuf;

use oxicat_esc::{Esc, EscConfig};
use oxicat_sim::segment::Segment;

/// `$OXICAT_REFERENCE`, or `<repo>/../shared/reference`.
pub fn reference_dir() -> PathBuf {
    std::env::var_os("OXICAT_REFERENCE")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference")
        })
}

/// A raw SII image from `reference/sii/`; a missing file fails the test.
pub fn sii(name: &str) -> Vec<u8> {
    let p = reference_dir().join("sii").join(name);
    std::fs::read(&p).unwrap_or_else(|e| panic!("reference SII image {} missing: {e}", p.display()))
}

/// ET1100 as in an EK1100: ports 0/1 MII, port 3 EBUS to the terminals.
pub fn ek1100_config() -> EscConfig {
    let mut c = EscConfig::et1100();
    c.port_descriptor = 0b10_00_11_11;
    c
}

/// ET1200 as in EL terminals: ports 0/1 EBUS.
pub fn terminal_config() -> EscConfig {
    EscConfig::et1200()
}

/// Word offset of the first SII category.
const CAT_START: usize = 0x80;

/// Calls `f(type, body)` for every SII category of `img`.
fn for_each_category(img: &mut [u8], mut f: impl FnMut(u16, &mut [u8]) -> Option<u16>) {
    let mut i = CAT_START;
    while i + 4 <= img.len() {
        let t = u16::from_le_bytes([img[i], img[i + 1]]);
        let words = u16::from_le_bytes([img[i + 2], img[i + 3]]) as usize;
        if t == 0xFFFF || i + 4 + 2 * words > img.len() {
            break;
        }
        if let Some(nt) = f(t, &mut img[i + 4..i + 4 + 2 * words]) {
            img[i..i + 2].copy_from_slice(&nt.to_le_bytes());
        }
        i += 4 + 2 * words;
    }
}

/// An EL1004-like 4-channel digital input terminal derived from the real EL2004 image:
/// product code 0x03EC3052, name "EL1004", SM0 at 0x1000 read by ECAT (inputs), its PDO
/// turned into a TxPDO. (No EL1004 EEPROM is in `reference/sii/`.)
pub fn el1004_from_el2004() -> Vec<u8> {
    let mut img = sii("el2004-eeprom-dump.bin");
    img[0x14..0x18].copy_from_slice(&0x03EC_3052u32.to_le_bytes());
    for_each_category(&mut img, |t, body| match t {
        10 => {
            // Strings: rename every "EL2004" to "EL1004" (same length).
            for k in 0..body.len().saturating_sub(6) {
                if &body[k..k + 6] == b"EL2004" {
                    body[k + 2] = b'1';
                }
            }
            None
        }
        41 => {
            // SM0: start 0x1000, control 0x00 (3-buffer, ECAT reads), type 4 (inputs).
            body[0..2].copy_from_slice(&0x1000u16.to_le_bytes());
            body[4] = 0x00;
            body[7] = 4;
            None
        }
        40 => {
            // FMMU 0 used for inputs.
            body[0] = 2;
            None
        }
        51 => Some(50),
        _ => None,
    });
    img
}

/// The devices of the real-device segment, in network order.
pub const DEVICES: &[(&str, &str, u32)] = &[
    ("EK1100", "ek1100.hex", 0x044C_2C52),
    ("EL2004", "el2004-eeprom-dump.bin", 0x07D4_3052),
    ("EL2828", "el2828.hex", 0x0B0C_3052),
    ("EL2889", "el2889.hex", 0x0B49_3052),
    ("EL2262", "el2262.bin", 0x08D6_3052),
];

/// EK1100 + EL2004 + EL2828 + EL2889 + EL2262 + EL1004 (from EL2004): the EK1100's port 3
/// feeds the terminals, which form a line through their ports 0/1.
pub fn real_segment() -> Segment {
    let mut seg = Segment::new();
    let ek = seg.add_unwired(Esc::new(ek1100_config(), sii(DEVICES[0].1)));
    let mut prev = (ek, 3u8);
    for (_, file, _) in &DEVICES[1..] {
        let id = seg.add_unwired(Esc::new(terminal_config(), sii(file)));
        seg.connect(prev.0, prev.1, id, 0).expect("wiring");
        prev = (id, 1);
    }
    let id = seg.add_unwired(Esc::new(terminal_config(), el1004_from_el2004()));
    seg.connect(prev.0, prev.1, id, 0).expect("wiring");
    seg
}

/// ethercrab timeouts for a loaded test machine: the segment answers at once, but the
/// host may be busy (real-time timeouts are not what these tests are about).
pub fn timeouts() -> ethercrab::Timeouts {
    oxicat_master::inprocess::virtual_timeouts()
}
