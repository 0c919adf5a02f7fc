//! Arbitrary frames through a line of 3 software ESCs built from a small SII image made in
//! this target (identity, mailbox, strings, general, SMs, FMMU usage): the ESCs must never
//! panic, whatever the frames and PDI accesses, and no datagram's working counter may grow
//! by more than its addressing allows (ETG.1000.4 table 12: 1 for an auto-increment read
//! or write, 3 for an auto-increment read-write; per ESC the same for configured-address
//! (ESCs may share a station address), broadcast and logical commands; nothing for NOP or
//! an unknown command), a frame with a bad FCS commits no SyncManager buffer (see
//! `check_bad_frame_left_sms`), and logical datagrams write process RAM only through
//! writing FMMUs (`check_logical_writes_stay_in_fmmus`).
//!
//! Input: byte 0 selects the chip model and fault options; then a sequence of
//! `[len_lo len_hi frame[len]]` records, each frame starting at the EtherCAT header.
#![no_main]

use libfuzzer_sys::fuzz_target;
use oxicat_esc::{Esc, EscConfig, Forward};
use oxicat_wire::mailbox::protocols;
use oxicat_wire::sii::{
    write_category, write_strings, CategoryType, MailboxArea, SiiConfig, SiiGeneral, SiiIdentity,
    SiiMailboxConfig, SiiSyncManager, SmType, FIXED_AREA_LEN, GENERAL_LEN,
};
use oxicat_wire::{Command, EcatFrame};
use std::sync::OnceLock;

/// A 1 KiB EEPROM of a CoE device with 4 SMs, built with the oxicat-wire SII writers.
fn eeprom() -> Vec<u8> {
    let mut img = vec![0xFFu8; 1024];
    img[..FIXED_AREA_LEN].fill(0);
    SiiConfig {
        pdi_control: 0x0005,
        pdi_config: 0x0000,
        sync_impulse_len: 100,
        ..Default::default()
    }
    .write(&mut img)
    .unwrap();
    SiiIdentity {
        vendor_id: 0x0000_0F0F,
        product_code: 0x0001_0001,
        revision: 1,
        serial: 42,
    }
    .write(&mut img)
    .unwrap();
    let mbx = |offset| MailboxArea { offset, size: 128 };
    SiiMailboxConfig {
        bootstrap_rx: mbx(0x1000),
        bootstrap_tx: mbx(0x1080),
        standard_rx: mbx(0x1000),
        standard_tx: mbx(0x1080),
        protocols: protocols::COE | protocols::FOE,
    }
    .write(&mut img)
    .unwrap();
    img[0x7C..0x7E].copy_from_slice(&7u16.to_le_bytes()); // 1 KiB
    img[0x7E..0x80].copy_from_slice(&1u16.to_le_bytes());
    let mut s = [0u8; 64];
    let n = write_strings(&mut s, &[b"oxicat", b"FuzzDev", b"Fuzz device"]).unwrap();
    let mut o = write_category(&mut img, FIXED_AREA_LEN, CategoryType::Strings, &s[..n]).unwrap();
    let mut g = [0u8; GENERAL_LEN];
    SiiGeneral {
        group_idx: 1,
        order_idx: 2,
        name_idx: 3,
        coe_details: 0x23,
        foe_details: 1,
        ..Default::default()
    }
    .write(&mut g)
    .unwrap();
    o = write_category(&mut img, o, CategoryType::General, &g).unwrap();
    o = write_category(&mut img, o, CategoryType::Fmmu, &[1, 2, 3, 0]).unwrap();
    let mut sms = [0u8; 32];
    let sm = |start, length, control, sm_type| SiiSyncManager {
        start,
        length,
        control,
        status: 0,
        enable: 1,
        sm_type,
    };
    sm(0x1000, 128, 0x26, SmType::MailboxOut)
        .write(&mut sms[0..])
        .unwrap();
    sm(0x1080, 128, 0x22, SmType::MailboxIn)
        .write(&mut sms[8..])
        .unwrap();
    sm(0x1100, 8, 0x64, SmType::Outputs)
        .write(&mut sms[16..])
        .unwrap();
    sm(0x1180, 8, 0x20, SmType::Inputs)
        .write(&mut sms[24..])
        .unwrap();
    o = write_category(&mut img, o, CategoryType::SyncManager, &sms).unwrap();
    img[o..o + 2].copy_from_slice(&0xFFFFu16.to_le_bytes());
    img
}

static EEPROM: OnceLock<Vec<u8>> = OnceLock::new();

/// How often one ESC's processing unit may see a frame on one pass through the ESC: on
/// entry at port 0, and again each time the frame comes back to a closed port 0 (loop
/// back into the processing unit, ESC datasheet: that is what the circulating bit stops);
/// the ESC model lets a frame round its four ports at most twice.
const PASSES_PER_ESC: u16 = 3;

/// The most a datagram's working counter may grow on its way through `n` ESCs (each may
/// process it up to [`PASSES_PER_ESC`] times, e.g. when the frame itself reopens port 0
/// between passes; found by this target).
fn max_wkc_increment(command: u8, n: u16) -> u16 {
    PASSES_PER_ESC * max_wkc_increment_once(command, n)
}

/// [`max_wkc_increment`] for one processing pass per ESC.
fn max_wkc_increment_once(command: u8, n: u16) -> u16 {
    match Command::from_u8(command) {
        None | Some(Command::Nop) => 0,
        // Auto-increment: only the ESC that sees position 0.
        Some(Command::Aprd | Command::Apwr) => 1,
        Some(Command::Aprw) => 3,
        // Configured address: every ESC with that station address answers (before the
        // master sets them, all have 0), as real ESCs do.
        Some(Command::Fprd | Command::Fpwr) => n,
        Some(Command::Fprw) => 3 * n,
        Some(
            Command::Brd
            | Command::Bwr
            | Command::Lrd
            | Command::Lwr
            | Command::Armw
            | Command::Frmw,
        ) => n,
        Some(Command::Brw | Command::Lrw) => 3 * n,
    }
}

/// The SyncManager registers, 8 bytes per SM (start, length, control, status, activate,
/// PDI control).
const SM_REGS: std::ops::Range<usize> = 0x0800..0x0880;

/// A frame with a bad FCS commits no SyncManager buffer (ET1100 datasheet: a buffer is
/// written only by a frame that ends well; a mailbox counts as written or read only then):
/// where the frame left an SM's configuration as it was, its status byte (mailbox full,
/// last written buffer) must be as it was.
fn check_bad_frame_left_sms(before: &[u8], after: &[u8]) {
    for (k, (b, a)) in before.chunks(8).zip(after.chunks(8)).enumerate() {
        let config_same = (0..8).filter(|&i| i != 5).all(|i| b[i] == a[i]);
        if config_same {
            assert_eq!(
                b[5] & 0x38,
                a[5] & 0x38,
                "SM{k}: a frame with a bad FCS changed its buffer state"
            );
        }
    }
}

/// Process RAM starts here (registers below).
const RAM_START: usize = 0x1000;

/// A frame of logical datagrams changes process RAM only where a writing FMMU maps it
/// (its physical bytes) or where a SyncManager over those bytes keeps its other buffers
/// (3-buffer mode: start .. start + 3 × length).
fn check_logical_writes_stay_in_fmmus(before: &[u8], mem: &[u8]) {
    let reg16 = |a: usize| u16::from_le_bytes([mem[a], mem[a + 1]]) as usize;
    let mut allowed: Vec<(usize, usize)> = Vec::new();
    for k in 0..16 {
        let f = 0x0600 + 16 * k;
        if mem[f + 12] & 1 == 0 || mem[f + 11] & 2 == 0 {
            continue;
        }
        let (start, len) = (reg16(f + 8), reg16(f + 4));
        allowed.push((start, start + len + 1));
    }
    for k in 0..16 {
        let r = 0x0800 + 8 * k;
        let (start, len) = (reg16(r), reg16(r + 2));
        if mem[r + 6] & 1 != 0 && allowed.iter().any(|&(a, b)| a < start + 3 * len && start < b) {
            allowed.push((start, start + 3 * len));
        }
    }
    for (i, (b, a)) in before.iter().zip(&mem[RAM_START..]).enumerate() {
        let addr = RAM_START + i;
        if b != a {
            assert!(
                allowed.iter().any(|&(lo, hi)| (lo..hi).contains(&addr)),
                "a logical frame wrote 0x{addr:04x}, which no writing FMMU maps ({allowed:x?})"
            );
        }
    }
}

/// (command, working counter) of every datagram of a well-formed frame.
fn datagrams(frame: &[u8]) -> Option<Vec<(u8, u16)>> {
    let f = EcatFrame::parse(frame).ok()?;
    f.datagrams()
        .map(|d| d.ok().map(|d| (d.header.command, d.wkc)))
        .collect()
}

fuzz_target!(|data: &[u8]| {
    let Some((&flags, mut rest)) = data.split_first() else {
        return;
    };
    let cfg = match flags & 3 {
        0 => EscConfig::et1100(),
        1 => EscConfig::et1200(),
        _ => EscConfig::lan9252(),
    };
    let eeprom = EEPROM.get_or_init(eeprom);
    let mut escs: Vec<Esc> = (0..3)
        .map(|_| Esc::new(cfg.clone(), eeprom.clone()))
        .collect();
    for (i, e) in escs.iter_mut().enumerate() {
        e.set_link(0, true);
        e.set_link(1, i < 2);
    }
    let mut t: u64 = 1_000;
    let mut frame_no = 0u32;
    while rest.len() >= 2 && frame_no < 64 {
        let len = (u16::from_le_bytes([rest[0], rest[1]]) as usize)
            .min(1514)
            .min(rest.len() - 2);
        let mut frame = rest[2..2 + len].to_vec();
        rest = &rest[2 + len..];
        frame_no += 1;
        let before = datagrams(&frame);
        // Frames of logical datagrams only: their writes reach process RAM through FMMUs.
        let logical_only = before.as_ref().is_some_and(|d| {
            !d.is_empty()
                && d.iter().all(|&(c, _)| {
                    matches!(
                        Command::from_u8(c),
                        Some(Command::Lrd | Command::Lwr | Command::Lrw)
                    )
                })
        });
        // Outbound: processed by each ESC entering port 0.
        let mut dropped = false;
        for (i, e) in escs.iter_mut().enumerate() {
            let ok = !(flags & 4 != 0 && i == 1 && frame_no % 3 == 0);
            let sms_before: Vec<u8> = e.memory()[SM_REGS].to_vec();
            let ram_before = logical_only.then(|| e.memory()[RAM_START..].to_vec());
            let out = e.forward(0, &mut frame, t, ok);
            if !ok {
                check_bad_frame_left_sms(&sms_before, &e.memory()[SM_REGS]);
            }
            if let Some(before) = ram_before {
                check_logical_writes_stay_in_fmmus(&before, e.memory());
            }
            match out {
                Forward::Dropped => {
                    dropped = true;
                    break;
                }
                Forward::Port(_) => {}
            }
            t += 500;
        }
        if let (false, Some(before), Some(after)) = (dropped, &before, datagrams(&frame)) {
            assert_eq!(
                before.len(),
                after.len(),
                "the ESCs changed the datagram count"
            );
            for (k, (&(cmd, w0), &(cmd1, w1))) in before.iter().zip(&after).enumerate() {
                assert_eq!(cmd, cmd1, "datagram {k}: command changed");
                let grew = w1.wrapping_sub(w0);
                assert!(
                    grew <= max_wkc_increment(cmd, escs.len() as u16),
                    "datagram {k} (command {cmd}): working counter {w0} -> {w1}"
                );
            }
        }
        // Return path: through port 1 of ESC 1 and 0 (DC receive-time latching only).
        for e in escs.iter_mut().take(2).rev() {
            let _ = e.forward(1, &mut frame, t, true);
            t += 500;
        }
        // PDI side: read what the frame may have changed, write back an input image.
        for e in escs.iter_mut() {
            let _ = e.advance(t);
            let _ = e.next_event();
            let mut b = [0u8; 16];
            let addr = frame
                .get(4..6)
                .map(|a| u16::from_le_bytes([a[0], a[1]]))
                .unwrap_or(0x0130);
            let _ = e.pdi_read(addr, &mut b);
            if flags & 8 != 0 {
                let _ = e.pdi_write(0x1180, &b[..8]);
                let _ = e.pdi_write(addr, &b[..2]);
            }
            let _ = (e.al_event_request(), e.irq_line(), e.sync_lines());
        }
        t += 10_000;
    }
});
