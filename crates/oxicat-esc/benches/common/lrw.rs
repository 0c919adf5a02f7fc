//! The setup shared by the `lrw_chain` benchmark and the `lrw_profile` example: an ESC with
//! SM2/SM3 (32 bytes, 3-buffer) and two FMMUs mapping a 64-byte logical window's halves,
//! and the 64-byte LRW frame that goes through a chain of them.

use oxicat_esc::{Esc, EscConfig};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::{Command, DatagramHeader};

fn pdi_config_eeprom() -> Vec<u8> {
    let mut e = vec![0u8; 2048];
    e[0] = 0x05; // SPI PDI
    e[14] = oxicat_esc::sii::crc8(&e[..14]);
    e
}

fn fpwr(esc: &mut Esc, ado: u16, data: &[u8]) {
    let mut buf = vec![0u8; 128];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    b.push(
        DatagramHeader::physical(Command::Apwr, 0, 0, ado, data.len() as u16),
        data,
    )
    .unwrap();
    let n = b.finish();
    esc.forward(0, &mut buf[..n], 0, true);
}

pub fn make_esc() -> Esc {
    let mut e = Esc::new(EscConfig::et1100(), pdi_config_eeprom());
    let sm = |start: u16, ctrl: u8| {
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&32u16.to_le_bytes());
        r[4] = ctrl;
        r[6] = 1;
        r
    };
    fpwr(&mut e, 0x0810, &sm(0x1000, 0x64));
    fpwr(&mut e, 0x0818, &sm(0x1100, 0x20));
    let fmmu = |log: u32, phys: u16, ty: u8| {
        let mut r = [0u8; 16];
        r[0..4].copy_from_slice(&log.to_le_bytes());
        r[4..6].copy_from_slice(&32u16.to_le_bytes());
        r[7] = 7;
        r[8..10].copy_from_slice(&phys.to_le_bytes());
        r[11] = ty;
        r[12] = 1;
        r
    };
    fpwr(&mut e, 0x0600, &fmmu(0x0001_0000, 0x1000, 2));
    fpwr(&mut e, 0x0610, &fmmu(0x0001_0020, 0x1100, 1));
    e
}

pub fn lrw_frame() -> Vec<u8> {
    let mut buf = vec![0u8; 128];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    b.push(
        DatagramHeader::logical(Command::Lrw, 0, 0x0001_0000, 64),
        &[0x5A; 64],
    )
    .unwrap();
    let n = b.finish();
    buf.truncate(n);
    buf
}
