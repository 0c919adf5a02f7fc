//! Property tests: SM/FMMU invariants and robustness against arbitrary frames.

use alloc::vec;
use alloc::vec::Vec;

use oxicat_wire::{Command, DatagramHeader, EcatFrame};
use proptest::prelude::*;

use crate::tests::{dg, esc, fmmu, frame, sm};

proptest! {
    /// The 3-buffer consumer (PDI) only ever sees a buffer that was written completely
    /// in one good frame: never a torn mix of two writes, never a bad frame's data.
    #[test]
    fn three_buffer_never_torn(ops in proptest::collection::vec((0u8..4, any::<u8>(), any::<bool>()), 1..60)) {
        let mut e = esc();
        sm(&mut e, 2, 0x1000, 4, 0x24, 1);
        let sa = e.station_address();
        let mut committed: Vec<[u8; 4]> = vec![[0; 4]];
        let mut open: Option<u8> = None;
        for (op, v, ok) in ops {
            match op {
                0 => {
                    // complete write in one datagram
                    let h = DatagramHeader::physical(Command::Fpwr, 0, sa, 0x1000, 4);
                    let mut f = frame(&[(h, &[v; 4])]);
                    e.forward(0, &mut f, 0, ok);
                    if ok { committed.push([v; 4]); }
                    open = None;
                }
                1 => {
                    // partial write: first half only
                    let h = DatagramHeader::physical(Command::Fpwr, 0, sa, 0x1000, 2);
                    let mut f = frame(&[(h, &[v; 2])]);
                    e.forward(0, &mut f, 0, ok);
                    open = if ok { Some(v) } else { None };
                }
                2 => {
                    // second half only (not starting at the start address)
                    let h = DatagramHeader::physical(Command::Fpwr, 0, sa, 0x1002, 2);
                    let mut f = frame(&[(h, &[v; 2])]);
                    e.forward(0, &mut f, 0, ok);
                    if let (Some(a), true) = (open, ok) {
                        committed.push([a, a, v, v]);
                    }
                    open = None;
                }
                _ => {
                    let mut b = [0u8; 4];
                    e.pdi_read(0x1000, &mut b).unwrap();
                    // The newest complete buffer is what the consumer gets, whole.
                    prop_assert_eq!(b, *committed.last().unwrap());
                }
            }
        }
    }

    /// LWR/LRD through one bit-granular FMMU equal a bit-by-bit reference model.
    #[test]
    fn fmmu_matches_bit_model(
        log in 0u32..16, len in 1u16..4, sbit in 0u8..8, ebit in 0u8..8, pbit in 0u8..8,
        dstart in 0u32..20, data in proptest::collection::vec(any::<u8>(), 1..12),
        init in proptest::collection::vec(any::<u8>(), 8),
    ) {
        let phys = 0x0F80u16;
        let mut e = esc();
        e.pdi_write(phys, &init).unwrap();
        fmmu(&mut e, 0, log, len, sbit, ebit, phys, pbit, 3);
        let bstart = log as i64 * 8 + sbit as i64;
        let bend = (log as i64 + len as i64 - 1) * 8 + ebit as i64 + 1;
        // Reference model for the write.
        let mut mem: Vec<u8> = init.clone();
        let mut hit = false;
        for i in 0..data.len() * 8 {
            let lb = dstart as i64 * 8 + i as i64;
            if lb >= bstart && lb < bend {
                hit = true;
                let pb = (pbit as i64 + lb - bstart) as usize;
                let v = data[i / 8] >> (i % 8) & 1;
                if pb / 8 < mem.len() {
                    mem[pb / 8] = (mem[pb / 8] & !(1 << (pb % 8))) | (v << (pb % 8));
                }
            }
        }
        let h = DatagramHeader::logical(Command::Lwr, 0, dstart, data.len() as u16);
        let mut f = frame(&[(h, &data)]);
        e.forward(0, &mut f, 0, true);
        prop_assert_eq!(dg(&f, 0).1, u16::from(hit));
        prop_assert_eq!(&e.memory()[phys as usize..phys as usize + 8], &mem[..]);
        // Read back with LRD: mapped bits come from memory, the others stay.
        let fill: Vec<u8> = data.iter().map(|b| !b).collect();
        let mut expect = fill.clone();
        for i in 0..data.len() * 8 {
            let lb = dstart as i64 * 8 + i as i64;
            if lb >= bstart && lb < bend {
                let pb = (pbit as i64 + lb - bstart) as usize;
                let v = mem.get(pb / 8).map_or(0, |m| m >> (pb % 8) & 1);
                expect[i / 8] = (expect[i / 8] & !(1 << (i % 8))) | (v << (i % 8));
            }
        }
        let h = DatagramHeader::logical(Command::Lrd, 0, dstart, data.len() as u16);
        let mut f = frame(&[(h, &fill)]);
        e.forward(0, &mut f, 0, true);
        prop_assert_eq!(dg(&f, 0).0, expect);
    }

    /// Arbitrary bytes as a frame never panic.
    #[test]
    fn random_frames_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300), port in 0u8..4, ok in any::<bool>()) {
        let mut e = esc();
        sm(&mut e, 2, 0x1000, 4, 0x64, 1);
        fmmu(&mut e, 0, 0, 4, 3, 5, 0x1000, 1, 3);
        let mut f = bytes.clone();
        e.forward(port, &mut f, 0, ok);
        let mut f = bytes;
        e.forward(0, &mut f, 0, ok);
        let _ = e.advance(1_000_000_000);
    }

    /// Datagrams after a malformed one (truncated / length mismatch) are left untouched,
    /// in particular their working counters.
    #[test]
    fn malformed_tail_untouched(cut in 1usize..14, cmd in 0u8..20) {
        let mut e = esc();
        let h0 = DatagramHeader::physical(Command::Aprd, 0, 0, 0, 2);
        let mut h1 = DatagramHeader::physical(Command::Aprd, 0, 0, 0x10, 2);
        h1.command = cmd;
        let mut f = frame(&[(h0, &[0, 0]), (h1, &[0, 0])]);
        let n = f.len() - cut;
        let mut g = f[..n].to_vec();
        // Header length still claims the full frame: the second datagram is truncated.
        let before_tail = g[16..].to_vec();
        e.forward(0, &mut g, 0, true);
        prop_assert_eq!(&g[16..], &before_tail[..]);
        // And the frame header parse of the intact frame still works.
        e.forward(0, &mut f, 0, true);
        prop_assert!(EcatFrame::parse(&f).is_ok());
    }
}
