//! Unit tests of the ESC core (register rules, WKC, SM, FMMU, SII, AL, DL).

use alloc::vec;
use alloc::vec::Vec;

use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::{Command, DatagramHeader, EcatFrame};

use crate::sii::crc8;
use crate::{Esc, EscConfig, Forward};

/// An EEPROM with a valid config area (given PDI control word and alias) and 2 KiB size.
pub(crate) fn eeprom(pdi_ctrl: u16, alias: u16) -> Vec<u8> {
    let mut e = vec![0u8; 2048];
    e[0..2].copy_from_slice(&pdi_ctrl.to_le_bytes());
    e[8..10].copy_from_slice(&alias.to_le_bytes());
    e[14] = crc8(&e[..14]);
    e[0x10] = 0xAA; // vendor id word 8
    e[0x11] = 0x55;
    e
}

pub(crate) fn esc() -> Esc {
    Esc::new(EscConfig::et1100(), eeprom(0x0005, 0x1234))
}

/// Builds a bare EtherCAT frame with the given datagrams.
pub(crate) fn frame(dgs: &[(DatagramHeader, &[u8])]) -> Vec<u8> {
    let mut buf = vec![0u8; 1600];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    for (h, d) in dgs {
        b.push(*h, d).unwrap();
    }
    let n = b.finish();
    buf.truncate(n);
    buf
}

/// (data, wkc, header) of datagram `i` of a frame.
pub(crate) fn dg(f: &[u8], i: usize) -> (Vec<u8>, u16, DatagramHeader) {
    let fr = EcatFrame::parse(f).unwrap();
    let d = fr.datagrams().nth(i).unwrap().unwrap();
    (d.data.to_vec(), d.wkc, d.header)
}

fn phys(cmd: Command, adp: u16, ado: u16, data: &[u8]) -> DatagramHeader {
    DatagramHeader::physical(cmd, 0, adp, ado, data.len() as u16)
}

/// Runs one datagram through `e` entering port 0; returns (data, wkc).
pub(crate) fn run(e: &mut Esc, cmd: Command, adp: u16, ado: u16, data: &[u8]) -> (Vec<u8>, u16) {
    let mut f = frame(&[(phys(cmd, adp, ado, data), data)]);
    e.forward(0, &mut f, 0, true);
    let (d, w, _) = dg(&f, 0);
    (d, w)
}

pub(crate) fn fpwr(e: &mut Esc, ado: u16, data: &[u8]) -> u16 {
    let sa = e.station_address();
    run(e, Command::Fpwr, sa, ado, data).1
}

pub(crate) fn fprd(e: &mut Esc, ado: u16, len: usize) -> (Vec<u8>, u16) {
    let sa = e.station_address();
    run(e, Command::Fprd, sa, ado, &vec![0u8; len])
}

#[allow(dead_code)]
pub(crate) fn lrw(e: &mut Esc, addr: u32, data: &[u8]) -> (Vec<u8>, u16) {
    let mut f = frame(&[(
        DatagramHeader::logical(Command::Lrw, 0, addr, data.len() as u16),
        data,
    )]);
    e.forward(0, &mut f, 0, true);
    let (d, w, _) = dg(&f, 0);
    (d, w)
}

/// Configures SM `n`.
#[allow(dead_code)]
pub(crate) fn sm(e: &mut Esc, n: u16, start: u16, len: u16, ctrl: u8, act: u8) {
    let mut r = [0u8; 8];
    r[0..2].copy_from_slice(&start.to_le_bytes());
    r[2..4].copy_from_slice(&len.to_le_bytes());
    r[4] = ctrl;
    r[6] = act;
    assert_eq!(fpwr(e, 0x0800 + 8 * n, &r), 1);
}

/// Configures FMMU `n` (bit granular).
#[allow(clippy::too_many_arguments, dead_code)]
pub(crate) fn fmmu(
    e: &mut Esc,
    n: u16,
    log: u32,
    len: u16,
    sbit: u8,
    ebit: u8,
    phys: u16,
    pbit: u8,
    ty: u8,
) {
    let mut r = [0u8; 16];
    r[0..4].copy_from_slice(&log.to_le_bytes());
    r[4..6].copy_from_slice(&len.to_le_bytes());
    r[6] = sbit;
    r[7] = ebit;
    r[8..10].copy_from_slice(&phys.to_le_bytes());
    r[10] = pbit;
    r[11] = ty;
    r[12] = 1;
    assert_eq!(fpwr(e, 0x0600 + 16 * n, &r), 1);
}

#[test]
fn info_registers_and_read_only() {
    let mut e = esc();
    let (d, w) = run(&mut e, Command::Aprd, 0, 0, &[0; 10]);
    assert_eq!(w, 1);
    assert_eq!(d[0], 0x11);
    assert_eq!(d[4], 8);
    assert_eq!(d[5], 8);
    assert_eq!(d[6], 8);
    // Writes to read-only registers are ignored but counted.
    let (_, w) = run(&mut e, Command::Apwr, 0, 0, &[0xFF; 4]);
    assert_eq!(w, 1);
    assert_eq!(e.memory()[0], 0x11);
}

#[test]
fn auto_increment_addressing() {
    let mut a = esc();
    let mut b = esc();
    let mut f = frame(&[(phys(Command::Apwr, 0xFFFF, 0x0010, &[0x01, 0x10]), &[0x01, 0x10])]);
    a.forward(0, &mut f, 0, true);
    b.forward(0, &mut f, 0, true);
    let (_, w, h) = dg(&f, 0);
    assert_eq!(w, 1);
    assert_eq!(h.adp(), 1);
    assert_eq!(a.station_address(), 0);
    assert_eq!(b.station_address(), 0x1001);
}

#[test]
fn configured_and_alias_addressing() {
    let mut e = esc();
    assert_eq!(e.memory()[0x12], 0x34);
    run(&mut e, Command::Apwr, 0, 0x10, &[0x05, 0x10]);
    assert_eq!(run(&mut e, Command::Fprd, 0x1005, 0x130, &[0, 0]).1, 1);
    assert_eq!(run(&mut e, Command::Fprd, 0x1234, 0x130, &[0, 0]).1, 0);
    // Enable alias (DL control bit 24).
    run(&mut e, Command::Fpwr, 0x1005, 0x0103, &[1]);
    assert_eq!(run(&mut e, Command::Fprd, 0x1234, 0x130, &[0, 0]).1, 1);
    // Alias is not ECAT-writable.
    run(&mut e, Command::Fpwr, 0x1005, 0x0012, &[9, 9]);
    assert_eq!(e.memory()[0x12], 0x34);
    e.pdi_write(0x0012, &[0x78, 0x56]).unwrap();
    assert_eq!(run(&mut e, Command::Fprd, 0x5678, 0x130, &[0, 0]).1, 1);
}

#[test]
fn broadcast_ors_and_counts() {
    let mut a = esc();
    let mut b = esc();
    a.pdi_write(0x0130, &[0x02, 0]).unwrap();
    b.pdi_write(0x0130, &[0x14, 0]).unwrap();
    let mut f = frame(&[(phys(Command::Brd, 0, 0x130, &[0, 0]), &[0, 0])]);
    a.forward(0, &mut f, 0, true);
    b.forward(0, &mut f, 0, true);
    let (d, w, h) = dg(&f, 0);
    assert_eq!(d, vec![0x16, 0]);
    assert_eq!(w, 2);
    assert_eq!(h.adp(), 2);
}

#[test]
fn read_write_wkc_is_three() {
    let mut e = esc();
    run(&mut e, Command::Apwr, 0, 0x10, &[0x01, 0x10]);
    let (d, w) = run(&mut e, Command::Fprw, 0x1001, 0x0F80, &[7, 8]);
    assert_eq!(w, 3);
    assert_eq!(d, vec![0, 0]);
    assert_eq!(&e.memory()[0x0F80..0x0F82], &[7, 8]);
}

#[test]
fn armw_reads_at_addressed_and_writes_elsewhere() {
    let mut a = esc();
    let mut b = esc();
    a.pdi_write(0x0F80, &[0xAB]).unwrap();
    let mut f = frame(&[(phys(Command::Armw, 0, 0x0F80, &[0]), &[0])]);
    a.forward(0, &mut f, 0, true);
    b.forward(0, &mut f, 0, true);
    let (d, w, _) = dg(&f, 0);
    assert_eq!(d, vec![0xAB]);
    assert_eq!(w, 2);
    assert_eq!(b.memory()[0x0F80], 0xAB);
}

#[test]
fn reserved_command_and_nop_untouched() {
    let mut e = esc();
    let mut h = phys(Command::Aprd, 0, 0, &[0; 4]);
    h.command = 0x20;
    let mut f = frame(&[(h, &[1, 2, 3, 4])]);
    let before = f.clone();
    e.forward(0, &mut f, 0, true);
    assert_eq!(f, before);
    let mut f = frame(&[(phys(Command::Nop, 0, 0, &[0; 4]), &[1, 2, 3, 4])]);
    let before = f.clone();
    e.forward(0, &mut f, 0, true);
    assert_eq!(f, before);
}

#[test]
fn truncated_datagram_not_processed() {
    let mut e = esc();
    let mut f = frame(&[(phys(Command::Aprd, 0, 0, &[0; 4]), &[0; 4])]);
    // Claim more data than present.
    f[8] = 0x40;
    let before = f.clone();
    assert_eq!(e.forward(0, &mut f, 0, true), Forward::Port(0));
    assert_eq!(f, before);
}

#[test]
fn al_control_event_and_device_emulation() {
    // PDI SPI, no device emulation.
    let mut e = esc();
    fpwr(&mut e, 0x0120, &[0x02, 0]);
    assert_eq!(e.al_event_request() & 1, 1);
    assert!(e.irq_line());
    assert_eq!(e.al_status(), 1);
    let mut b = [0u8; 2];
    e.pdi_read(0x0120, &mut b).unwrap();
    assert_eq!(b, [2, 0]);
    assert_eq!(e.al_event_request() & 1, 0);
    // Device emulation (EK1100 style): status follows control.
    let mut k = Esc::new(EscConfig::et1100(), eeprom(0x0100, 0));
    fpwr(&mut k, 0x0120, &[0x02, 0]);
    assert_eq!(k.al_status(), 2);
    fpwr(&mut k, 0x0120, &[0x18, 0]);
    assert_eq!(k.al_status(), 8);
}

#[test]
fn pdi_write_permissions() {
    let mut e = esc();
    e.pdi_write(0x0010, &[5, 5]).unwrap();
    assert_eq!(e.station_address(), 0);
    e.pdi_write(0x0130, &[0x04, 0]).unwrap();
    assert_eq!(e.al_status(), 4);
    // ECAT cannot write AL status.
    fpwr(&mut e, 0x0130, &[0x08, 0]);
    assert_eq!(e.al_status(), 4);
    // ECAT event: AL status change, cleared by an ECAT read of 0x0130.
    assert_ne!(e.ecat_event_request() & 8, 0);
    fprd(&mut e, 0x0130, 2);
    assert_eq!(e.ecat_event_request() & 8, 0);
    assert!(e.pdi_read(0xFFFF, &mut [0; 2]).is_err());
}

#[test]
fn error_counters_clear_on_write() {
    let mut e = esc();
    let mut f = frame(&[(phys(Command::Nop, 0, 0, &[0]), &[0])]);
    e.forward(0, &mut f, 0, false);
    e.forward(0, &mut f, 0, false);
    assert_eq!(e.memory()[0x0300], 2);
    fpwr(&mut e, 0x0300, &[0x55]);
    assert_eq!(e.memory()[0x0300], 0);
}

#[test]
fn bad_fcs_register_write_ignored() {
    let mut e = esc();
    let mut f = frame(&[(phys(Command::Apwr, 0, 0x10, &[1, 2]), &[1, 2])]);
    e.forward(0, &mut f, 0, false);
    assert_eq!(e.station_address(), 0);
}
