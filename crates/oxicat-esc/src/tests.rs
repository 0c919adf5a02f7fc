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
    run_at(e, 0, cmd, adp, ado, data)
}

/// [`run`] with the frame arriving at virtual time `t` (ns).
pub(crate) fn run_at(
    e: &mut Esc,
    t: u64,
    cmd: Command,
    adp: u16,
    ado: u16,
    data: &[u8],
) -> (Vec<u8>, u16) {
    let mut f = frame(&[(phys(cmd, adp, ado, data), data)]);
    e.forward(0, &mut f, t, true);
    let (d, w, _) = dg(&f, 0);
    (d, w)
}

/// Lets the EEPROM write cycle under way (if any) end.
pub(crate) fn sii_wait(e: &mut Esc) {
    if let Some(d) = e.sii_busy_until {
        e.advance(d);
    }
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
    // Writes to read-only registers are ignored and, with no writable byte in the
    // range, not counted (captures: BWR 0x092C gets WKC 0 from every real ESC).
    let (_, w) = run(&mut e, Command::Apwr, 0, 0, &[0xFF; 4]);
    assert_eq!(w, 0);
    assert_eq!(e.memory()[0], 0x11);
    // One writable byte in the range is enough.
    let (_, w) = run(&mut e, Command::Apwr, 0, 0x000E, &[0, 0, 0, 0]);
    assert_eq!(w, 1);
}

#[test]
fn auto_increment_addressing() {
    let mut a = esc();
    let mut b = esc();
    let mut f = frame(&[(
        phys(Command::Apwr, 0xFFFF, 0x0010, &[0x01, 0x10]),
        &[0x01, 0x10],
    )]);
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
    // Bit 4 (error indication acknowledge) is copied too (captures: BWR 0x0120 `11 00`,
    // then 0x0130 reads `11 00`).
    fpwr(&mut k, 0x0120, &[0x18, 0]);
    assert_eq!(k.al_status(), 0x18);
}

#[test]
fn al_control_is_a_mailbox_without_device_emulation() {
    // soem-single-lan9252 frames 3/5: the second BWR 0x0120 before the firmware read
    // AL control gets WKC 0 and does not change it.
    let mut e = esc();
    assert_eq!(fpwr(&mut e, 0x0120, &[0x02, 0]), 1);
    assert_eq!(fpwr(&mut e, 0x0120, &[0x04, 0]), 0);
    assert_eq!(e.al_control(), 2);
    let mut b = [0u8; 1];
    e.pdi_read(0x0121, &mut b).unwrap();
    assert_eq!(fpwr(&mut e, 0x0120, &[0x04, 0]), 1);
    assert_eq!(e.al_control(), 4);
    // With device emulation the register is always writable.
    let mut k = Esc::new(EscConfig::et1100(), eeprom(0x0100, 0));
    assert_eq!(fpwr(&mut k, 0x0120, &[0x02, 0]), 1);
    assert_eq!(fpwr(&mut k, 0x0120, &[0x04, 0]), 1);
}

#[test]
fn dl_status_event_pending_from_power_on_until_read() {
    let mut e = esc();
    assert_eq!(e.ecat_event_request() & 4, 4);
    fpwr(&mut e, 0x0200, &[0x04, 0]);
    // The datagram that reads DL status still carries the IRQ; the next one does not.
    let f0 = frame(&[(phys(Command::Fprd, 0x0000, 0x0110, &[0; 2]), &[0; 2])]);
    let mut f = f0.clone();
    e.forward(0, &mut f, 0, true);
    assert_eq!(dg(&f, 0).2.irq, 4);
    let mut f = f0.clone();
    e.forward(0, &mut f, 0, true);
    assert_eq!(dg(&f, 0).2.irq, 0);
}

#[test]
fn unimplemented_registers_do_not_count() {
    use crate::DcSupport;
    let cfg = EscConfig {
        dc: DcSupport::ReceiveTimesOnly,
        ..EscConfig::et1200()
    };
    let mut e = Esc::new(cfg, eeprom(0x0104, 0));
    // FMMU 3 and SM 4 do not exist on a 3-FMMU / 4-SM chip; FMMU 2 and SM 3 do.
    assert_eq!(fpwr(&mut e, 0x0630, &[0; 16]), 0);
    assert_eq!(fpwr(&mut e, 0x0620, &[0; 16]), 1);
    assert_eq!(fpwr(&mut e, 0x0820, &[0; 8]), 0);
    assert_eq!(fpwr(&mut e, 0x0818, &[0; 8]), 1);
    // Receive times exist, system time does not.
    assert_eq!(fpwr(&mut e, 0x0900, &[0; 4]), 1);
    assert_eq!(fprd(&mut e, 0x0900, 16).1, 1);
    assert_eq!(fpwr(&mut e, 0x0910, &[0; 8]), 0);
    let (d, w) = fprd(&mut e, 0x0918, 8);
    assert_eq!((d, w), (vec![0; 8], 0));
    // Process RAM beyond the chip's size.
    assert_eq!(fprd(&mut e, 0x1000 + 1024, 4).1, 0);
    assert_eq!(fprd(&mut e, 0x1000 + 1020, 4).1, 1);
    // Full DC: all counted.
    let mut f = esc();
    assert_eq!(fpwr(&mut f, 0x0910, &[0; 8]), 1);
}

#[test]
fn pdi_writes_sync_unit_when_assigned() {
    let mut e = esc();
    // SYNC unit owned by ECAT: the PDI cannot write the cycle time.
    e.pdi_write(0x09A0, &[0x10, 0x27, 0, 0]).unwrap();
    assert_eq!(&e.memory()[0x09A0..0x09A4], &[0, 0, 0, 0]);
    // 0x0980 bit 0 assigns it to the PDI: now the PDI can, ECAT cannot.
    fpwr(&mut e, 0x0980, &[0x01]);
    e.pdi_write(0x09A0, &[0x10, 0x27, 0, 0]).unwrap();
    assert_eq!(&e.memory()[0x09A0..0x09A4], &[0x10, 0x27, 0, 0]);
    fpwr(&mut e, 0x09A0, &[0, 0, 0, 0]);
    assert_eq!(&e.memory()[0x09A0..0x09A4], &[0x10, 0x27, 0, 0]);
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

/// ESC with SM2 (0x1000, 4 bytes, 3-buffer, ECAT writes) and SM3 (0x1100, 4 bytes,
/// 3-buffer, ECAT reads), FMMU0 log 0..4 -> SM2, FMMU1 log 4..8 <- SM3.
fn pd_esc() -> Esc {
    let mut e = esc();
    sm(&mut e, 2, 0x1000, 4, 0x64, 1);
    sm(&mut e, 3, 0x1100, 4, 0x20, 1);
    fmmu(&mut e, 0, 0, 4, 0, 7, 0x1000, 0, 2);
    fmmu(&mut e, 1, 4, 4, 0, 7, 0x1100, 0, 1);
    e
}

#[test]
fn lrw_through_three_buffer_sms() {
    let mut e = pd_esc();
    e.pdi_write(0x1100, &[9, 8, 7, 6]).unwrap();
    let (d, w) = lrw(&mut e, 0, &[1, 2, 3, 4, 0, 0, 0, 0]);
    assert_eq!(w, 3);
    assert_eq!(d, vec![1, 2, 3, 4, 9, 8, 7, 6]);
    let mut b = [0u8; 4];
    e.pdi_read(0x1000, &mut b).unwrap();
    assert_eq!(b, [1, 2, 3, 4]);
    // AL event for SM2 (control bit 5) was raised and cleared by the PDI read.
    assert_eq!(e.al_event_request() & (1 << 10), 0);
    // LRD only reads, LWR only writes.
    let mut f = frame(&[(DatagramHeader::logical(Command::Lrd, 0, 0, 8), &[0; 8])]);
    e.forward(0, &mut f, 0, true);
    assert_eq!(dg(&f, 0).1, 1);
    let mut f = frame(&[(DatagramHeader::logical(Command::Lwr, 0, 0, 8), &[5; 8])]);
    e.forward(0, &mut f, 0, true);
    assert_eq!(dg(&f, 0).1, 1);
}

#[test]
fn three_buffer_consumer_sees_newest_complete() {
    let mut e = pd_esc();
    lrw(&mut e, 0, &[1, 1, 1, 1, 0, 0, 0, 0]);
    lrw(&mut e, 0, &[2, 2, 2, 2, 0, 0, 0, 0]);
    let mut b = [0u8; 4];
    e.pdi_read(0x1000, &mut b).unwrap();
    assert_eq!(b, [2, 2, 2, 2]);
    // A write in a bad frame does not become visible.
    let mut f = frame(&[(
        DatagramHeader::logical(Command::Lwr, 0, 0, 4),
        &[3, 3, 3, 3],
    )]);
    e.forward(0, &mut f, 0, false);
    e.pdi_read(0x1000, &mut b).unwrap();
    assert_eq!(b, [2, 2, 2, 2]);
    // Partial write not starting at the start address: ignored, no WKC.
    let sa = e.station_address();
    let (_, w) = run(&mut e, Command::Fpwr, sa, 0x1001, &[7, 7, 7]);
    assert_eq!(w, 0);
    // Write without the last byte: not visible.
    let (_, w) = run(&mut e, Command::Fpwr, sa, 0x1000, &[4, 4]);
    assert_eq!(w, 1);
    e.pdi_read(0x1000, &mut b).unwrap();
    assert_eq!(b, [2, 2, 2, 2]);
    // Consumer reading in two pieces keeps its buffer even if a new one arrives.
    lrw(&mut e, 0, &[5, 5, 5, 5, 0, 0, 0, 0]);
    let mut h = [0u8; 2];
    e.pdi_read(0x1000, &mut h).unwrap();
    lrw(&mut e, 0, &[6, 6, 6, 6, 0, 0, 0, 0]);
    e.pdi_read(0x1002, &mut h).unwrap();
    assert_eq!(h, [5, 5]);
    e.pdi_read(0x1000, &mut b).unwrap();
    assert_eq!(b, [6, 6, 6, 6]);
}

#[test]
fn mailbox_full_empty_and_lock() {
    let mut e = esc();
    sm(&mut e, 0, 0x1800, 8, 0x26, 1); // mailbox, ECAT writes, AL irq
    sm(&mut e, 1, 0x1900, 8, 0x22, 1); // mailbox, ECAT reads
    let sa = e.station_address();
    let (_, w) = run(&mut e, Command::Fpwr, sa, 0x1800, &[1; 8]);
    assert_eq!(w, 1);
    assert_eq!(e.memory()[0x0805] & 0x08, 0x08);
    assert_ne!(e.al_event_request() & (1 << 8), 0);
    // Full: second write refused.
    let (_, w) = run(&mut e, Command::Fpwr, sa, 0x1800, &[2; 8]);
    assert_eq!(w, 0);
    let mut b = [0u8; 8];
    e.pdi_read(0x1800, &mut b).unwrap();
    assert_eq!(b, [1; 8]);
    assert_eq!(e.memory()[0x0805] & 0x08, 0);
    // Read mailbox empty: ECAT read refused.
    let (_, w) = run(&mut e, Command::Fprd, sa, 0x1900, &[0; 8]);
    assert_eq!(w, 0);
    e.pdi_write(0x1900, &[3; 8]).unwrap();
    assert_eq!(e.memory()[0x080D] & 0x08, 0x08);
    let (d, w) = run(&mut e, Command::Fprd, sa, 0x1900, &[0; 8]);
    assert_eq!((d, w), (vec![3; 8], 1));
    assert_eq!(e.memory()[0x080D] & 0x08, 0);
    // Repeat request toggle raises the SM-change event; PDI acks in its control byte.
    fpwr(&mut e, 0x080E, &[0x03]);
    assert_ne!(e.al_event_request() & (1 << 4), 0);
    e.pdi_write(0x080F, &[0x02]).unwrap();
    assert_eq!(fprd(&mut e, 0x080F, 1).0, vec![0x02]);
    // PDI deactivation makes the area plain memory.
    e.pdi_write(0x080F, &[0x01]).unwrap();
    let (_, w) = run(&mut e, Command::Fprd, sa, 0x1900, &[0; 8]);
    assert_eq!(w, 1);
}

#[test]
fn fmmu_bit_mapping() {
    let mut e = esc();
    // Logical bits 2..5 of byte 0x10 -> physical 0x0F80 bits 4..7.
    fmmu(&mut e, 0, 0x10, 1, 2, 5, 0x0F80, 4, 3);
    let mut f = frame(&[(
        DatagramHeader::logical(Command::Lwr, 0, 0x10, 1),
        &[0b0011_1100],
    )]);
    e.forward(0, &mut f, 0, true);
    assert_eq!(dg(&f, 0).1, 1);
    assert_eq!(e.memory()[0x0F80], 0xF0);
    e.pdi_write(0x0F80, &[0b1010_0000]).unwrap();
    let mut f = frame(&[(DatagramHeader::logical(Command::Lrd, 0, 0x10, 1), &[0xFF])]);
    e.forward(0, &mut f, 0, true);
    assert_eq!(dg(&f, 0).0, vec![0b1110_1011]);
}

#[test]
fn digital_outputs_and_watchdog() {
    // EL2004 style: PDI digital I/O, SM2 at 0x0F00 len 1, 3-buffer, watchdog trigger.
    let mut e = Esc::new(EscConfig::et1100(), eeprom(0x0104, 0));
    sm(&mut e, 2, 0x0F00, 1, 0x44, 1);
    fmmu(&mut e, 0, 0x100, 1, 0, 7, 0x0F00, 0, 2);
    let mut f = frame(&[(DatagramHeader::logical(Command::Lrw, 0, 0x100, 1), &[0x0A])]);
    e.forward(0, &mut f, 1000, true);
    assert_eq!(dg(&f, 0).1, 2);
    assert_eq!(e.digital_outputs(), 0x0A);
    assert_eq!(e.memory()[0x0440] & 1, 1);
    // Default watchdog: 1000 * 100 us = 100 ms.
    assert_eq!(e.next_event(), Some(1000 + 100_000_000));
    let ev = e.advance(50_000_000);
    assert!(!ev.pd_watchdog_expired);
    let ev = e.advance(100_001_000);
    assert!(ev.pd_watchdog_expired);
    assert_eq!(e.digital_outputs(), 0);
    assert_eq!(e.memory()[0x0442], 1);
    assert_eq!(e.memory()[0x0440] & 1, 0);
}

/// The injected watchdog fault: not running before an output write, then the expiry at
/// the next time step (1 ns on) with its effects, and the next write retriggers it.
#[test]
fn an_injected_pd_watchdog_expiry_acts_at_the_next_time_step() {
    let mut e = Esc::new(EscConfig::et1100(), eeprom(0x0104, 0));
    sm(&mut e, 2, 0x0F00, 1, 0x44, 1);
    fmmu(&mut e, 0, 0x100, 1, 0, 7, 0x0F00, 0, 2);
    assert!(!e.expire_pd_watchdog());
    let mut f = frame(&[(DatagramHeader::logical(Command::Lrw, 0, 0x100, 1), &[0x0A])]);
    e.forward(0, &mut f, 1000, true);
    assert_eq!(e.digital_outputs(), 0x0A);
    e.advance(2000);
    assert!(e.expire_pd_watchdog());
    assert_eq!(e.next_event(), Some(2001), "at the next time step");
    let ev = e.advance(2001);
    assert!(ev.pd_watchdog_expired);
    assert_eq!(e.digital_outputs(), 0);
    assert_eq!(e.memory()[0x0442], 1);
    assert_eq!(e.memory()[0x0440] & 1, 0);
    let mut f = frame(&[(DatagramHeader::logical(Command::Lrw, 0, 0x100, 1), &[0x0B])]);
    e.forward(0, &mut f, 3000, true);
    assert_eq!(e.memory()[0x0440] & 1, 1);
    assert_eq!(e.next_event(), Some(3000 + 100_000_000));
}

/// Two buffered SMs of one byte each over neighbouring digital-output registers (the
/// AX58100 DIO board's ESI: 0x0F02 and 0x0F03, control 0x44): each keeps its own byte. A
/// buffered SM over registers does not spread its three buffers over the registers after
/// it (0x0F02's second buffer would be 0x0F03): the registers are its one buffer.
#[test]
fn buffered_sms_over_neighbouring_output_registers_keep_their_own_bytes() {
    let mut e = Esc::new(EscConfig::et1100(), eeprom(0x0104, 0));
    sm(&mut e, 0, 0x0F02, 1, 0x44, 1);
    sm(&mut e, 1, 0x0F03, 1, 0x44, 1);
    fmmu(&mut e, 0, 0x100, 2, 0, 7, 0x0F02, 0, 2);
    for (k, v) in [[0x12u8, 0x34], [0x56, 0x78], [0x9A, 0xBC], [0xDE, 0xF0]]
        .iter()
        .enumerate()
    {
        let mut f = frame(&[(DatagramHeader::logical(Command::Lwr, 0, 0x100, 2), &v[..])]);
        e.forward(0, &mut f, 1000 * (k as u64 + 1), true);
        assert_eq!(dg(&f, 0).1, 1, "frame {k}");
        assert_eq!(
            e.digital_outputs(),
            u32::from(v[0]) << 16 | u32::from(v[1]) << 24,
            "frame {k}"
        );
    }
}

#[test]
fn sii_read_write_reload_and_ownership() {
    let mut e = esc();
    // Read word 8 (vendor id low) -> 8 bytes.
    fpwr(&mut e, 0x0504, &[8, 0, 0, 0]);
    fpwr(&mut e, 0x0502, &[0x00, 0x01]);
    let (d, _) = fprd(&mut e, 0x0502, 14);
    assert_eq!(u16::from_le_bytes([d[0], d[1]]) & 0x8700, 0);
    assert_ne!(d[0] & 0x40, 0);
    assert_eq!(&d[6..8], &[0xAA, 0x55]);
    // Write without write enable: error bit 14.
    fpwr(&mut e, 0x0508, &[0x11, 0x22]);
    fpwr(&mut e, 0x0502, &[0x00, 0x02]);
    assert_ne!(fprd(&mut e, 0x0503, 1).0[0] & 0x40, 0);
    fpwr(&mut e, 0x0502, &[0x01, 0x02]);
    assert_eq!(&e.eeprom()[16..18], &[0x11, 0x22]);
    sii_wait(&mut e);
    // Corrupt the config area (alias word 4) and reload: CRC error flagged.
    fpwr(&mut e, 0x0504, &[4, 0, 0, 0]);
    fpwr(&mut e, 0x0508, &[0x99, 0x99]);
    fpwr(&mut e, 0x0502, &[0x01, 0x02]);
    sii_wait(&mut e);
    fpwr(&mut e, 0x0502, &[0x00, 0x04]);
    assert_ne!(fprd(&mut e, 0x0503, 1).0[0] & 0x08, 0);
    // PDI ownership: ECAT commands ignored.
    fpwr(&mut e, 0x0500, &[1]);
    fpwr(&mut e, 0x0504, &[0x20, 0, 0, 0]);
    assert_eq!(e.memory()[0x0504], 4);
    e.pdi_write(0x0504, &[8, 0, 0, 0]).unwrap();
    e.pdi_write(0x0502, &[0, 1]).unwrap();
    let mut b = [0u8; 2];
    e.pdi_read(0x0508, &mut b).unwrap();
    assert_eq!(b, [0x11, 0x22]);
}

/// An EEPROM write takes the EEPROM's write cycle (ESC datasheet section I 11.2.1.1, t_WR of
/// the I²C EEPROM, [`crate::sii::WRITE_CYCLE_NS`]): 0x0502 shows busy with the write command
/// meanwhile, a command issued then is not executed and ends with bit 13 (section I table
/// 40: missing acknowledge, the EEPROM is busy internally), and when the cycle is over on
/// the virtual clock the interface is idle and the retried command works. Before, every
/// write completed at once.
#[test]
fn eeprom_write_cycle_keeps_the_interface_busy() {
    use crate::sii::WRITE_CYCLE_NS;
    let mut e = esc();
    let sa = e.station_address();
    let ctl = |e: &mut Esc, t: u64| {
        let d = run_at(e, t, Command::Fprd, sa, 0x0502, &[0; 2]).0;
        u16::from_le_bytes([d[0], d[1]])
    };
    let t0 = 1_000_000;
    run_at(&mut e, t0, Command::Fpwr, sa, 0x0504, &[0x20, 0, 0, 0]);
    run_at(&mut e, t0, Command::Fpwr, sa, 0x0508, &[0x11, 0x22]);
    run_at(&mut e, t0, Command::Fpwr, sa, 0x0502, &[0x01, 0x02]);
    assert_eq!(&e.eeprom()[0x40..0x42], &[0x11, 0x22]);
    // Busy, the write command shown, no error.
    let c = ctl(&mut e, t0 + 1_000);
    assert_eq!(c & 0xE700, 0x8200, "0x0502 = {c:#06x}");
    // A read of word 8 issued now: refused with bit 13, still busy, data register kept.
    run_at(&mut e, t0 + 2_000, Command::Fpwr, sa, 0x0504, &[8, 0, 0, 0]);
    run_at(&mut e, t0 + 2_000, Command::Fpwr, sa, 0x0502, &[0x00, 0x01]);
    let c = ctl(&mut e, t0 + 3_000);
    assert_eq!(c & 0xE700, 0xA200, "0x0502 = {c:#06x}");
    let d = run_at(&mut e, t0 + 3_000, Command::Fprd, sa, 0x0508, &[0; 2]).0;
    assert_eq!(d, [0x11, 0x22], "the read was not executed");
    // Writing 0 while busy neither starts nor clears anything.
    run_at(&mut e, t0 + 4_000, Command::Fpwr, sa, 0x0502, &[0x00, 0x00]);
    assert_eq!(ctl(&mut e, t0 + 4_000) & 0xE700, 0xA200);
    // Still busy just before the end of the cycle (on a frame or on the PDI side).
    assert_ne!(ctl(&mut e, t0 + WRITE_CYCLE_NS - 1) & 0x8000, 0);
    // Over: idle, the error of the refused command kept until the next command.
    e.advance(t0 + WRITE_CYCLE_NS);
    let mut b = [0u8; 2];
    e.pdi_read(0x0502, &mut b).unwrap();
    assert_eq!(u16::from_le_bytes(b) & 0xE700, 0x2000);
    // The retried read is executed and clears the error.
    let t1 = t0 + WRITE_CYCLE_NS + 1_000;
    run_at(&mut e, t1, Command::Fpwr, sa, 0x0502, &[0x00, 0x01]);
    assert_eq!(ctl(&mut e, t1) & 0xE700, 0);
    let d = run_at(&mut e, t1, Command::Fprd, sa, 0x0508, &[0; 2]).0;
    assert_eq!(d, [0xAA, 0x55]);
    // The PDI owns the EEPROM: its writes run the same cycle.
    run_at(&mut e, t1, Command::Fpwr, sa, 0x0500, &[1]);
    e.pdi_write(0x0501, &[1]).unwrap();
    e.pdi_write(0x0504, &[0x21, 0, 0, 0]).unwrap();
    e.pdi_write(0x0508, &[0x33, 0x44]).unwrap();
    e.pdi_write(0x0502, &[0x01, 0x02]).unwrap();
    e.pdi_write(0x0502, &[0x00, 0x01]).unwrap();
    e.pdi_read(0x0502, &mut b).unwrap();
    assert_eq!(u16::from_le_bytes(b) & 0xE700, 0xA200);
    e.advance(t1 + WRITE_CYCLE_NS);
    e.pdi_read(0x0502, &mut b).unwrap();
    assert_eq!(u16::from_le_bytes(b) & 0x8700, 0);
    assert_eq!(&e.eeprom()[0x42..0x44], &[0x33, 0x44]);
}

#[test]
fn write_protected_eeprom_area_does_not_acknowledge() {
    let mut e = esc();
    e.protect_eeprom_from(0x20);
    // Below the protected area a write lands.
    fpwr(&mut e, 0x0504, &[0x1F, 0, 0, 0]);
    fpwr(&mut e, 0x0508, &[0x11, 0x22]);
    fpwr(&mut e, 0x0502, &[0x01, 0x02]);
    assert_eq!(fprd(&mut e, 0x0503, 1).0[0] & 0x20, 0);
    assert_eq!(&e.eeprom()[0x3E..0x40], &[0x11, 0x22]);
    sii_wait(&mut e);
    // From word 0x20 on: missing acknowledge (bit 13), the word keeps its value.
    let before = [e.eeprom()[0x40], e.eeprom()[0x41]];
    fpwr(&mut e, 0x0504, &[0x20, 0, 0, 0]);
    fpwr(&mut e, 0x0508, &[0x33, 0x44]);
    fpwr(&mut e, 0x0502, &[0x01, 0x02]);
    assert_ne!(fprd(&mut e, 0x0503, 1).0[0] & 0x20, 0);
    assert_eq!([e.eeprom()[0x40], e.eeprom()[0x41]], before);
    // Reads of the protected area still work.
    fpwr(&mut e, 0x0502, &[0x00, 0x01]);
    assert_eq!(fprd(&mut e, 0x0503, 1).0[0] & 0x20, 0);
    assert_eq!(&fprd(&mut e, 0x0508, 2).0[..2], &before);
}

#[test]
fn eeprom_crc_error_on_power_up() {
    let mut ee = eeprom(0x0005, 0x1234);
    ee[14] ^= 1;
    let e = Esc::new(EscConfig::et1100(), ee);
    assert_ne!(e.memory()[0x0503] & 0x08, 0);
    assert_eq!(e.memory()[0x0110] & 1, 0);
    assert_eq!(e.memory()[0x0012], 0);
}

#[test]
fn port_routing_and_circulating() {
    let mut e = esc();
    let mut f = frame(&[(phys(Command::Nop, 0, 0, &[0]), &[0])]);
    assert_eq!(e.forward(0, &mut f, 0, true), Forward::Port(0));
    e.set_link(1, true);
    assert_eq!(e.forward(0, &mut f, 0, true), Forward::Port(1));
    assert_eq!(e.forward(1, &mut f, 0, true), Forward::Port(0));
    assert_eq!(e.memory()[0x0110] & 0x30, 0x30);
    e.set_link(1, false);
    assert_eq!(e.memory()[0x0311], 1);
    // Port 0 closed (forced): frame circulates once, then is dropped.
    e.set_link(1, true);
    fpwr(&mut e, 0x0101, &[0x03]);
    assert_eq!(e.forward(1, &mut f, 0, true), Forward::Port(1));
    assert!(dg(&f, 0).2.circulating);
    assert_eq!(e.forward(1, &mut f, 0, true), Forward::Dropped);
}

#[test]
fn irq_field_ored() {
    let mut e = esc();
    fpwr(&mut e, 0x0200, &[0x08, 0]);
    e.pdi_write(0x0130, &[0x02, 0]).unwrap();
    let (_, _) = run(&mut e, Command::Nop, 0, 0, &[0]);
    let mut f = frame(&[(phys(Command::Brd, 0, 0x0F80, &[0]), &[0])]);
    e.forward(0, &mut f, 0, true);
    assert_eq!(dg(&f, 0).2.irq, 0x08);
}

/// Datagrams addressed to other stations (a master's per-slave state checks) pass with the
/// IRQ field ORed and nothing else touched; an FRMW for another station is still written,
/// and one for this station read.
#[test]
fn configured_datagrams_for_other_stations_only_carry_the_irq() {
    let mut e = esc();
    let me = e.station_address();
    fpwr(&mut e, 0x0200, &[0x08, 0]);
    e.pdi_write(0x0130, &[0x02, 0]).unwrap();
    let other = me.wrapping_add(1);
    let mut f = frame(&[
        (
            phys(Command::Fprd, other, 0x0130, &[0xAA, 0xBB]),
            &[0xAA, 0xBB],
        ),
        (phys(Command::Fpwr, other, 0x0F80, &[1, 2]), &[1, 2]),
        (phys(Command::Fprw, other, 0x0F80, &[3, 4]), &[3, 4]),
        (phys(Command::Fprd, me, 0x0130, &[0, 0]), &[0, 0]),
    ]);
    e.forward(0, &mut f, 0, true);
    for k in 0..3 {
        let (data, wkc, h) = dg(&f, k);
        assert_eq!(
            h.irq, 0x08,
            "datagram {k}: the ESC's event in the IRQ field"
        );
        assert_eq!(wkc, 0, "datagram {k}: not counted");
        assert_eq!(
            data,
            [[0xAA, 0xBB], [1, 2], [3, 4]][k],
            "datagram {k}: data untouched"
        );
    }
    let (data, wkc, _) = dg(&f, 3);
    assert_eq!(
        (data, wkc),
        (vec![0x02, 0], 1),
        "its own FPRD reads AL status"
    );
    assert_eq!(fprd(&mut e, 0x0F80, 2).0, [0, 0], "no write landed");
    // FRMW: the addressed station reads, every other one writes.
    e.pdi_write(0x0F80, &[0x11, 0x22]).unwrap();
    let mut f = frame(&[(phys(Command::Frmw, other, 0x0F80, &[5, 6]), &[5, 6])]);
    e.forward(0, &mut f, 0, true);
    assert_eq!(dg(&f, 0).1, 1, "FRMW for another station writes here");
    assert_eq!(fprd(&mut e, 0x0F80, 2).0, [5, 6]);
}

/// Through a frame index ([`crate::FrameDispatch`]) the ESC processes its own
/// configured-address datagram and the others only through the index: their IRQ bits are
/// recorded, not written, until `apply_irq`; the bytes then equal the per-ESC walk's. A
/// station-address write in the frame makes the rest of the frame the ESC's own again.
#[test]
fn dispatched_walk_defers_foreign_irqs_and_follows_an_address_change() {
    let mut e = esc();
    let me = e.station_address();
    fpwr(&mut e, 0x0200, &[0x08, 0]);
    e.pdi_write(0x0130, &[0x02, 0]).unwrap();
    let other = me.wrapping_add(1);
    let mk = || {
        frame(&[
            (phys(Command::Fprd, other, 0x0130, &[0, 0]), &[0, 0]),
            (phys(Command::Fprd, me, 0x0130, &[0, 0]), &[0, 0]),
            (
                phys(Command::Fpwr, me, 0x0010, &[0, 0]),
                &other.to_le_bytes(),
            ),
            (phys(Command::Fprd, other, 0x0130, &[0, 0]), &[0, 0]),
        ])
    };
    let mut reference = e.clone();
    let mut want = mk();
    reference.forward(0, &mut want, 0, true);
    let mut d = crate::FrameDispatch::new();
    let mut f = mk();
    assert!(d.build(&mut f));
    assert_eq!(d.len(), 4);
    assert_eq!(
        e.forward_dispatched(0, &mut f, 0, true, &mut d),
        Forward::Port(0)
    );
    assert_eq!(
        dg(&f, 0).2.irq,
        0,
        "the foreign FPRD's IRQ bits wait in the index"
    );
    assert_eq!(dg(&f, 1).1, 1, "its own FPRD answered");
    assert_eq!(
        dg(&f, 3).1,
        1,
        "after the address write, the last FPRD is its own"
    );
    d.apply_irq(&mut f);
    assert_eq!(dg(&f, 0).2.irq, 0x08);
    assert_eq!(f, want, "same bytes as the per-ESC walk");
    assert_eq!(e.memory(), reference.memory());
}

/// An ESC in the benchmark's configuration (SM2/SM3 3-buffer, two FMMUs mapping a 64-byte
/// LRW's halves), with its fast paths on or off.
fn bench_shape(fast: bool) -> Esc {
    let mut e = esc();
    e.set_fast_paths(fast);
    sm(&mut e, 2, 0x1000, 32, 0x64, 1);
    sm(&mut e, 3, 0x1100, 32, 0x20, 1);
    fmmu(&mut e, 0, 0x0001_0000, 32, 0, 7, 0x1000, 0, 2);
    fmmu(&mut e, 1, 0x0001_0020, 32, 0, 7, 0x1100, 0, 1);
    e
}

/// The benchmark's configuration (SM2/SM3 3-buffer, two FMMUs mapping a 64-byte LRW's
/// halves) takes the fused path, and it gives the generic path's results.
#[test]
fn fused_path_taken_for_the_lrw_benchmark_shape() {
    let (mut a, mut b) = (bench_shape(true), bench_shape(false));
    for k in 0..5u8 {
        e_pdi(&mut a, k);
        e_pdi(&mut b, k);
        let (da, wa) = lrw(&mut a, 0x0001_0000, &[k; 64]);
        let (db, wb) = lrw(&mut b, 0x0001_0000, &[k; 64]);
        assert_eq!((da, wa), (db, wb));
        assert_eq!(wa, 3);
        assert_eq!(a.memory(), b.memory());
    }
    assert_eq!(a.fused_hits, 5);
    assert_eq!(b.fused_hits, 0);

    fn e_pdi(e: &mut Esc, k: u8) {
        e.pdi_write(0x1100, &[k.wrapping_mul(3); 32]).unwrap();
        let mut o = [0u8; 32];
        e.pdi_read(0x1000, &mut o).unwrap();
    }
}

/// The fused path's header key holds the frame length: after an LRW the fused path took,
/// the same headers in a frame cut short (the datagram no longer fits) or padded go the
/// way the general path does, without a panic (a key without the length would reuse the
/// stored WKC and window offsets past the end of the short frame).
#[test]
fn fused_key_holds_the_frame_length() {
    let (mut a, mut b) = (bench_shape(true), bench_shape(false));
    let f = frame(&[(
        DatagramHeader::logical(Command::Lrw, 0, 0x0001_0000, 64),
        &[7; 64],
    )]);
    let mut t = 1000;
    let mut whole = 0;
    for cut in [0usize, 1, 2, 30, 0, 66, 0] {
        for pad in [0usize, 3] {
            let mut fa = f[..f.len() - cut].to_vec();
            fa.resize(fa.len() + pad, 0xEE);
            // The datagram fits in the frame (a longer frame carries padding).
            whole += usize::from(fa.len() >= f.len());
            let mut fb = fa.clone();
            t += 1000;
            assert_eq!(
                a.forward(0, &mut fa, t, true),
                b.forward(0, &mut fb, t, true)
            );
            assert_eq!(fa, fb, "frame cut by {cut}, padded by {pad}");
            assert_eq!(a.memory(), b.memory());
        }
    }
    assert_eq!(
        a.fused_hits, whole as u64,
        "the frames the datagram fits in"
    );
    assert_eq!(whole, 8);
}

/// A receive-time latch armed by a write to 0x0900 takes the time a frame reaches port 1
/// on its way back (the pass-through shortcut's DC arrival), with the fast paths on and
/// off alike.
#[test]
fn receive_time_latched_on_the_way_back() {
    for fast in [true, false] {
        let mut e = esc();
        e.set_fast_paths(fast);
        e.set_link(1, true);
        let sa = e.station_address();
        assert_eq!(
            run_at(&mut e, 10_000, Command::Fpwr, sa, 0x0900, &[0; 4]).1,
            1
        );
        let mut f = frame(&[(phys(Command::Nop, 0, 0, &[0; 2]), &[0; 2])]);
        assert_eq!(e.forward(1, &mut f, 10_700, true), Forward::Port(0));
        assert_eq!(e.pass_hits, 0, "the armed port takes the general path");
        let p0 = u32::from_le_bytes(fprd(&mut e, 0x0900, 4).0.try_into().unwrap());
        let p1 = u32::from_le_bytes(fprd(&mut e, 0x0904, 4).0.try_into().unwrap());
        assert_eq!(p1.wrapping_sub(p0), 700, "fast paths {fast}");
        // Latched: the shortcut is open again (the route is gated no longer).
        assert_eq!(e.forward(1, &mut f, 10_900, true), Forward::Port(0));
        assert_eq!(e.pass_hits, u64::from(fast), "fast paths {fast}");
    }
}

/// The small-copy helper of the fast paths equals `copy_from_slice` for every length.
#[test]
fn copy_small_equals_copy_from_slice() {
    for n in 0..200usize {
        let s: Vec<u8> = (0..n).map(|i| (i * 7 + 3) as u8).collect();
        let mut d = vec![0xEEu8; n];
        crate::esc::copy_small(&mut d, &s);
        assert_eq!(d, s, "length {n}");
    }
}

/// (start, length, control, activate) of SM `n` as the master reads them.
fn sm_regs(e: &mut Esc, n: u16) -> (u16, u16, u8, u8) {
    let r = fprd(e, 0x0800 + 8 * n, 8).0;
    (
        u16::from_le_bytes([r[0], r[1]]),
        u16::from_le_bytes([r[2], r[3]]),
        r[4],
        r[6],
    )
}

/// SM block (start, length, control, activate) as one 8-byte register write.
fn sm_block(start: u16, len: u16, ctrl: u8, act: u8) -> [u8; 8] {
    let mut r = [0u8; 8];
    r[0..2].copy_from_slice(&start.to_le_bytes());
    r[2..4].copy_from_slice(&len.to_le_bytes());
    r[4] = ctrl;
    r[6] = act;
    r
}

/// Start, length and control are "r/(w)": the master writes them only while the
/// SyncManager is disabled (+0x6.0 = 0 when the datagram arrives). Found by the
/// slave_stack fuzz target: a master laid an active SM3 over the AL registers.
#[test]
fn an_active_syncmanager_keeps_its_area() {
    let mut e = esc();
    sm(&mut e, 3, 0x1180, 7, 0x20, 1);
    // The datagram still counts (the registers exist); the area stays.
    assert_eq!(fpwr(&mut e, 0x0818, &sm_block(0x0130, 0x5B, 0x67, 1)), 1);
    assert_eq!(sm_regs(&mut e, 3), (0x1180, 7, 0x20, 1));
    assert_eq!(fpwr(&mut e, 0x081A, &[9]), 1);
    assert_eq!(sm_regs(&mut e, 3), (0x1180, 7, 0x20, 1));
    // Still SM3's buffer: the PDI writes inputs, the master reads them.
    e.pdi_write(0x1180, &[1, 2, 3, 4, 5, 6, 7]).unwrap();
    assert_eq!(fprd(&mut e, 0x1180, 7).0, vec![1, 2, 3, 4, 5, 6, 7]);
}

#[test]
fn a_disabled_syncmanager_takes_a_new_area() {
    let mut e = esc();
    sm(&mut e, 3, 0x1180, 7, 0x20, 1);
    // Deactivate first (as masters do), then reconfigure and activate in one write.
    assert_eq!(fpwr(&mut e, 0x081E, &[0]), 1);
    assert_eq!(sm_regs(&mut e, 3).3, 0);
    assert_eq!(fpwr(&mut e, 0x0818, &sm_block(0x1200, 12, 0x20, 1)), 1);
    assert_eq!(sm_regs(&mut e, 3), (0x1200, 12, 0x20, 1));
    // Deactivating and moving in one write takes only the deactivation.
    assert_eq!(fpwr(&mut e, 0x0818, &sm_block(0x1400, 4, 0x24, 0)), 1);
    assert_eq!(sm_regs(&mut e, 3), (0x1200, 12, 0x20, 0));
}

#[test]
fn the_pdi_cannot_move_a_syncmanager() {
    let mut e = esc();
    sm(&mut e, 2, 0x1100, 4, 0x64, 0);
    let _ = e.pdi_write(0x0810, &sm_block(0x0130, 8, 0x20, 0));
    assert_eq!(sm_regs(&mut e, 2), (0x1100, 4, 0x64, 0));
}

#[test]
fn temporary_loop_control_reverts_after_about_a_second() {
    // ETG.1000.4 table 33 / ET1100 0x0100 bit 1: "temporary use of Loop Control settings
    // for ~1 second", then the permanent settings apply again.
    let mut e = esc();
    e.set_link(1, true);
    let mut f = frame(&[(phys(Command::Nop, 0, 0, &[0]), &[0])]);
    // Port 1 forced closed (0x0101 bits 2..3 = 3), temporarily.
    assert_eq!(fpwr(&mut e, 0x0100, &[0x02, 0x0C]), 1);
    assert_eq!(e.forward(0, &mut f, 1_000, true), Forward::Port(0));
    let due = e.next_event().expect("the revert is an event");
    assert!((900_000_000..=1_100_000_000).contains(&due), "{due}");
    e.advance(due - 1);
    assert_eq!(e.forward(0, &mut f, due - 1, true), Forward::Port(0));
    e.advance(due);
    assert_eq!(e.memory()[0x0101], 0x00, "loop settings as before");
    assert_eq!(e.forward(0, &mut f, due, true), Forward::Port(1));
    assert_eq!(e.next_event(), None);
    // The same settings written permanently stay.
    assert_eq!(fpwr(&mut e, 0x0100, &[0x00, 0x0C]), 1);
    e.advance(5_000_000_000);
    assert_eq!(e.forward(0, &mut f, 5_000_000_000, true), Forward::Port(0));
    assert_eq!(e.memory()[0x0101], 0x0C);
    // A temporary setting on top of a permanent one returns to the permanent one.
    assert_eq!(fpwr(&mut e, 0x0100, &[0x02, 0x08]), 1);
    assert_eq!(e.forward(0, &mut f, 5_000_000_000, true), Forward::Port(1));
    let due = e.next_event().expect("revert");
    e.advance(due);
    assert_eq!(e.memory()[0x0101], 0x0C);
    assert_eq!(e.forward(0, &mut f, due, true), Forward::Port(0));
}

/// A SyncManager over registers (as over the digital outputs at 0x0F00) buffers the
/// access, but the bytes land in registers: their write rights and the rule that register
/// writes need a good FCS still hold. Found by the esc_process fuzz target (input kept in
/// `fuzz_regressions.rs`): SM0 laid over the SM registers let a bad-FCS frame change SM1's
/// status byte.
#[test]
fn a_syncmanager_over_registers_keeps_the_register_rules() {
    let mut e = esc();
    // Buffered, ECAT writes, over AL status (read-only for ECAT): the access counts (the
    // SM takes it), AL status stays.
    sm(&mut e, 2, 0x0130, 2, 0x04, 1);
    let st = e.al_status();
    assert_eq!(fpwr(&mut e, 0x0130, &[0x08, 0x00]), 1);
    assert_eq!(e.al_status(), st);
    // SM0 over the SM registers; a bad frame writes none of them.
    sm(&mut e, 0, 0x0804, 0x2001, 0xF4, 1);
    let before = fprd(&mut e, 0x0800, 0x20).0;
    let mut f = frame(&[(phys(Command::Bwr, 0, 0x0800, &[0; 16]), &[0; 16])]);
    e.forward(0, &mut f, 0, false);
    assert_eq!(fprd(&mut e, 0x0800, 0x20).0, before);
}

/// The esc_process fuzz input behind the test above (minimised by libFuzzer, three ET1200
/// ESCs): a BRW lays SM0 over 0x0804.. (activated), then a BWR of zeros over the SM
/// registers reaches the second ESC with a bad FCS. No SM register may change there.
#[test]
fn fuzz_input_bad_fcs_frame_under_an_sm_over_registers() {
    let frames: [&[u8]; 3] = [
        &[0x00, 0x04, 0x04, 0x08],
        &[
            0x21, 0x10, 0x09, 0x00, 0x00, 0x00, 0x00, 0x08, 0x10, 0xa8, 0x04, 0x05, 0x04, 0x08,
            0x01, 0x20, 0xf4, 0x00, 0x25, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
            0x6f, 0x54, 0x04, 0x00, 0x8a, 0x00, 0x00,
        ],
        &[
            0x21, 0x10, 0x08, 0x00, 0x00, 0x02, 0x00, 0x08, 0x10, 0xa8, 0x00, 0x00, 0x00, 0x00,
            0xff, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
            0x00, 0x00, 0x00, 0x00, 0x00, 0xff, 0xff,
        ],
    ];
    let mut escs: Vec<Esc> = (0..3)
        .map(|_| Esc::new(EscConfig::et1200(), eeprom(0x0005, 0)))
        .collect();
    for (i, e) in escs.iter_mut().enumerate() {
        e.set_link(0, true);
        e.set_link(1, i < 2);
    }
    for (n, f) in frames.iter().enumerate() {
        let mut f = f.to_vec();
        for (i, e) in escs.iter_mut().enumerate() {
            let ok = !(n == 2 && i == 1);
            let before = e.memory()[0x0800..0x0880].to_vec();
            e.forward(0, &mut f, 1_000, ok);
            if !ok {
                assert_eq!(&e.memory()[0x0800..0x0880], &before[..]);
            }
        }
    }
}

/// A frame the fused path declines at an ESC where it applies (here an FPRD of the EEPROM
/// control register, through `forward` and through `forward_dispatched`) sees the EEPROM
/// write cycle end at its arrival, as on the general path: the ESC's time is the frame's,
/// not that of the last `advance`. (The fused path left the settle out on its way to the
/// general path.)
#[test]
fn declined_fused_frame_settles_the_eeprom_cycle() {
    use crate::sii::WRITE_CYCLE_NS;
    for (fast, dispatched) in [(true, false), (true, true), (false, false), (false, true)] {
        let mut e = bench_shape(fast);
        let sa = e.station_address();
        let t0 = 1_000_000;
        run_at(&mut e, t0, Command::Fpwr, sa, 0x0504, &[0x20, 0, 0, 0]);
        run_at(&mut e, t0, Command::Fpwr, sa, 0x0508, &[0x11, 0x22]);
        run_at(&mut e, t0, Command::Fpwr, sa, 0x0502, &[0x01, 0x02]);
        let ctl = |e: &mut Esc, t: u64| {
            let h = phys(Command::Fprd, sa, 0x0502, &[0; 2]);
            let mut f = frame(&[(h, &[0; 2])]);
            if dispatched {
                let mut d = crate::FrameDispatch::new();
                assert!(d.build(&mut f));
                e.forward_dispatched(0, &mut f, t, true, &mut d);
                d.apply_irq(&mut f);
            } else {
                e.forward(0, &mut f, t, true);
            }
            let d = dg(&f, 0).0;
            u16::from_le_bytes([d[0], d[1]])
        };
        let c = ctl(&mut e, t0 + WRITE_CYCLE_NS - 1);
        assert_ne!(c & 0x8000, 0, "busy (fast {fast}, dispatched {dispatched})");
        let c = ctl(&mut e, t0 + WRITE_CYCLE_NS);
        assert_eq!(c & 0x8000, 0, "idle (fast {fast}, dispatched {dispatched})");
    }
}

/// A frame passing an ESC (in at port 1, out at port 0) after the EEPROM write cycle ended
/// leaves the registers as the general path does: the pass-through shortcut is closed
/// while the cycle runs (`Esc::gate_routes`), so the frame's arrival settles it.
#[test]
fn passing_frame_settles_the_eeprom_cycle() {
    use crate::sii::WRITE_CYCLE_NS;
    let mut escs = [bench_shape(true), bench_shape(false)];
    let t0 = 1_000_000;
    for e in escs.iter_mut() {
        e.set_link(1, true);
        let sa = e.station_address();
        run_at(e, t0, Command::Fpwr, sa, 0x0504, &[0x20, 0, 0, 0]);
        run_at(e, t0, Command::Fpwr, sa, 0x0508, &[0x11, 0x22]);
        run_at(e, t0, Command::Fpwr, sa, 0x0502, &[0x01, 0x02]);
        let mut f = frame(&[(phys(Command::Fprd, 0x7777, 0x0130, &[0; 2]), &[0; 2])]);
        assert_eq!(
            e.forward(1, &mut f, t0 + WRITE_CYCLE_NS, true),
            Forward::Port(0)
        );
    }
    let [a, b] = &mut escs;
    assert_eq!(
        a.memory()[0x0503] & 0x80,
        0,
        "busy ended at the frame's arrival"
    );
    assert_eq!(a.memory(), b.memory());
    assert_eq!(a.pass_hits, 0, "the general path settled it");
    // Settled: the shortcut is open again.
    let mut f = frame(&[(phys(Command::Fprd, 0x7777, 0x0130, &[0; 2]), &[0; 2])]);
    assert_eq!(
        a.forward(1, &mut f, t0 + WRITE_CYCLE_NS + 1, true),
        Forward::Port(0)
    );
    assert_eq!(a.pass_hits, 1);
    assert_eq!(b.pass_hits, 0);
}

/// The pass-through shortcut (and the fused path, for port 0) closes while its skipped
/// work is due and opens again as soon as it is done, whichever way: an EEPROM cycle
/// settled by `advance`; latches armed by a write to 0x0900 and ended by the next frame at
/// port 0, through `forward` (the general path then) and through `forward_dispatched`.
#[test]
fn pass_through_reopens_after_settle_and_latch_window() {
    use crate::sii::WRITE_CYCLE_NS;
    let mut e = bench_shape(true);
    e.set_link(1, true);
    let sa = e.station_address();
    let pass = |e: &mut Esc, t: u64| {
        let mut f = frame(&[(phys(Command::Fprd, 0x7777, 0x0130, &[0; 2]), &[0; 2])]);
        assert_eq!(e.forward(1, &mut f, t, true), Forward::Port(0));
        e.pass_hits
    };
    let lrw_at = |e: &mut Esc, t: u64, dispatched: bool| {
        let h = DatagramHeader::logical(Command::Lrw, 0, 0x0001_0000, 64);
        // Dispatched: with an FPRD for another station (an index needs one).
        let other = phys(Command::Fprd, 0x7777, 0x0130, &[0; 2]);
        let mut f = if dispatched {
            frame(&[(h, &[1; 64]), (other, &[0; 2])])
        } else {
            frame(&[(h, &[1; 64])])
        };
        let hits = e.fused_hits;
        if dispatched {
            let mut d = crate::FrameDispatch::new();
            assert!(d.build(&mut f));
            e.forward_dispatched(0, &mut f, t, true, &mut d);
        } else {
            e.forward(0, &mut f, t, true);
        }
        assert_eq!(dg(&f, 0).1, 3);
        e.fused_hits - hits
    };
    let t0 = 1_000_000;
    assert_eq!(pass(&mut e, t0), 1);
    run_at(&mut e, t0, Command::Fpwr, sa, 0x0504, &[0x20, 0, 0, 0]);
    run_at(&mut e, t0, Command::Fpwr, sa, 0x0502, &[0x01, 0x02]);
    e.advance(t0 + WRITE_CYCLE_NS);
    assert_eq!(
        pass(&mut e, t0 + WRITE_CYCLE_NS),
        2,
        "open after the settle"
    );
    for (k, dispatched) in [false, true].into_iter().enumerate() {
        let t1 = t0 + WRITE_CYCLE_NS + 10_000 * (k as u64 + 1);
        run_at(&mut e, t1, Command::Fpwr, sa, 0x0900, &[0; 4]);
        assert_eq!(
            lrw_at(&mut e, t1 + 100, dispatched),
            0,
            "armed: general path"
        );
        let hits = 3 + k as u64;
        assert_eq!(
            pass(&mut e, t1 + 1_000),
            hits,
            "open after the window ({k})"
        );
        assert_eq!(lrw_at(&mut e, t1 + 2_000, false), 1, "fused again ({k})");
    }
}
