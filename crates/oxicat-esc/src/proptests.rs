//! Property tests: SM/FMMU invariants and robustness against arbitrary frames.

use alloc::vec;
use alloc::vec::Vec;

use oxicat_wire::{Command, DatagramHeader, EcatFrame};
use proptest::prelude::*;

use crate::tests::{dg, eeprom, esc, fmmu, fpwr, frame, run_at, sm};
use crate::{Esc, EscConfig, FrameDispatch};

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

/// One SM of a random configuration: (start in 16-byte units or `None` for its own
/// 128-byte slot, length, control).
fn arb_sm() -> impl Strategy<Value = (Option<u16>, u16, u8)> {
    (
        proptest::option::weighted(0.15, 0u16..24),
        prop_oneof![Just(32u16), 1u16..40],
        prop_oneof![
            3 => Just(0x64u8),
            3 => Just(0x20u8),
            1 => Just(0x24u8),
            1 => Just(0x00u8),
            1 => Just(0x26u8),
            1 => Just(0x22u8),
            1 => any::<u8>()
        ],
    )
}

/// One FMMU of a random configuration: (gap before it in the logical layout, SM it maps
/// (`None`: FMMU n maps SM n, modulo their number; an index without an SM: a random
/// physical start), length override, type override, bit-aligned).
fn arb_fmmu() -> impl Strategy<Value = (u32, Option<u8>, Option<u16>, Option<u8>, bool)> {
    (
        prop_oneof![6 => Just(0u32), 2 => 0u32..8, 1 => Just(u32::MAX)],
        proptest::option::weighted(0.15, 0u8..5),
        proptest::option::weighted(0.1, 1u16..40),
        proptest::option::weighted(0.15, 1u8..4),
        proptest::bool::weighted(0.95),
    )
}

/// Logical layout base of the differential test.
const LOG_BASE: u32 = 0x40;

/// An operation of the differential test.
#[derive(Debug, Clone)]
enum Op {
    /// Logical datagram: command (0 LRD, 1 LWR, 2 LRW), start relative to the layout base
    /// (`None`: random), extra length, data pattern, IRQ field, good FCS, a second
    /// datagram behind it.
    Logical(u8, Option<i32>, u16, u8, u16, bool, bool),
    /// PDI read of `len` bytes at an offset from 0x1000.
    PdiRead(u16, u16),
    /// PDI write at an offset from 0x1000.
    PdiWrite(u16, Vec<u8>),
    /// PDI read of `len` bytes of the register file (0x0000..0x0A00): AL control, the
    /// watchdog status, SM activate and the DC unit clear events when read, the others
    /// leave the event memo valid ([`Esc::pdi_read`]).
    PdiReadReg(u16, u16),
    /// ECAT FPWR of a register that raises an AL event: AL control (0x0120), an SM's
    /// activate byte (0x0806 + 8·n, the SM-change event) with `data`.
    EcatEvent(u16, u8),
    /// ECAT FPWR of the event mask (IRQ field contents).
    Mask(u16),
    /// Link change on a port.
    Link(u8, bool),
    /// Time passes.
    Advance(u64),
    /// A frame (an FPRD of AL status with an IRQ field) entering a port, good FCS or not.
    Pass(u8, u16, bool),
    /// A frame of configured-address datagrams (FPRD of AL status) through
    /// `forward_dispatched` at port 0: station addresses from [`STATIONS`] (this ESC's,
    /// its alias, others), optionally an APRD behind them (a datagram every ESC
    /// processes), good FCS or not.
    Foreign(Vec<u8>, bool, bool),
    /// ECAT write of the DL control loop bits (0x0101) and alias enable (0x0103).
    DlControl(u8, bool),
    /// ECAT write of port 0 receive time: arms the receive-time latch of every port.
    ArmLatch,
    /// An access around the DC system time (0x0900 + offset): 0 FPWR, 1 FRMW of another
    /// station (a write), 2 BWR, 4 FRMW of this one (a read), with a good FCS or not;
    /// 3 a PDI write.
    DcWrite(u16, Vec<u8>, u8, bool),
    /// A read of `len` bytes of the register file at `addr`: 0 from the PDI, 1 an FPRD of
    /// this station, 2 a BRD (ORed into the frame's data `pat`).
    RegRead(u16, u16, u8, u8),
    /// SM 7 over registers: start, length, control byte, activate (ECAT writes).
    SmOverRegs(u16, u16, u8, bool),
}

/// Register addresses the reads start near: the ones with read side effects (DL status,
/// AL control, AL status, the watchdog status, SM status and activation), those whose
/// ranges the plain-register path leaves to the general one (the event registers, the DC
/// unit), missing registers and the end of the register file.
const REG_SPOTS: [u16; 22] = [
    0x0000, 0x0008, 0x0100, 0x0110, 0x0120, 0x0130, 0x0134, 0x0200, 0x020C, 0x0220, 0x0300, 0x0310,
    0x0440, 0x0442, 0x0502, 0x0600, 0x0800, 0x080D, 0x0838, 0x08FC, 0x0E00, 0x0FFC,
];

/// Station addresses of the `Foreign` frames: the ESC's station address (set up), its
/// alias (from the EEPROM), two others.
const STATIONS: [u16; 4] = [0x1001, 0x1234, 0x1002, 0x2001];

fn arb_op() -> impl Strategy<Value = Op> {
    prop_oneof![
        8 => (0u8..3, proptest::option::weighted(0.9, -3i32..2), 0u16..0x60, any::<u8>(),
              prop_oneof![3 => Just(0u16), 1 => any::<u16>()],
              proptest::bool::weighted(0.9), proptest::bool::weighted(0.1))
            .prop_map(|(c, a, x, d, i, ok, two)| Op::Logical(c, a, x, d, i, ok, two)),
        3 => (0u16..0x280, 1u16..48).prop_map(|(a, l)| Op::PdiRead(a, l)),
        3 => (0u16..0x280, proptest::collection::vec(any::<u8>(), 1..48))
            .prop_map(|(a, d)| Op::PdiWrite(a, d)),
        1 => any::<u16>().prop_map(Op::Mask),
        3 => (prop_oneof![
                  2 => (0x0110u16..0x0130, 1u16..4),
                  2 => (0x0200u16..0x0230, 1u16..8),
                  1 => (0x0440u16..0x0444, 1u16..3),
                  3 => (0x0800u16..0x0900, 1u16..8),
                  1 => (0x0900u16..0x09F0, 1u16..16),
                  1 => (0u16..0x0A00, 1u16..64),
              ])
            .prop_map(|(a, l)| Op::PdiReadReg(a, l)),
        2 => (prop_oneof![Just(0x0120u16), (0u16..4).prop_map(|n| 0x0806 + 8 * n)], any::<u8>())
            .prop_map(|(a, d)| Op::EcatEvent(a, d)),
        1 => (1u8..4, any::<bool>()).prop_map(|(p, up)| Op::Link(p, up)),
        1 => (0u64..2_000_000).prop_map(Op::Advance),
        4 => (0u8..6, prop_oneof![3 => Just(0u16), 1 => any::<u16>()], proptest::bool::weighted(0.9))
            .prop_map(|(p, irq, ok)| Op::Pass(p, irq, ok)),
        4 => (proptest::collection::vec(prop_oneof![6 => 2u8..4, 1 => 0u8..2], 1..6),
              proptest::bool::weighted(0.1), proptest::bool::weighted(0.9))
            .prop_map(|(a, every, ok)| Op::Foreign(a, every, ok)),
        1 => (any::<u8>(), any::<bool>()).prop_map(|(l, a)| Op::DlControl(l, a)),
        1 => Just(Op::ArmLatch),
        2 => (0x08u16..0x20, proptest::collection::vec(any::<u8>(), 1..12), 0u8..5,
              proptest::bool::weighted(0.9))
            .prop_map(|(a, d, c, ok)| Op::DcWrite(a, d, c, ok)),
        3 => (prop_oneof![3 => (0usize..REG_SPOTS.len(), 0u16..8)
                  .prop_map(|(k, o)| REG_SPOTS[k] + o), 1 => 0u16..0x1000],
              1u16..16, 0u8..3, any::<u8>())
            .prop_map(|(a, l, h, p)| Op::RegRead(a, l, h, p)),
        1 => (prop_oneof![0x0E00u16..0x0E20, 0x0800u16..0x0820, 0x0120u16..0x0140],
              0u16..8, any::<u8>(), any::<bool>())
            .prop_map(|(a, l, c, on)| Op::SmOverRegs(a, l, c, on)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(600))]

    /// The fast paths — the fused LRW path, the pass-through of frames entering ports
    /// 1..3 and the foreign-frame pass of dispatched frames with no datagram for this ESC —
    /// and the general path leave identical frames, exit ports, memory, registers and
    /// events for random SM/FMMU configurations, two- and four-port ESCs, random logical
    /// frames, frames entering every port, dispatched frames of configured-address
    /// datagrams, link and loop-control changes, armed receive-time latches, writes and
    /// FRMW reads around the DC system time (the system-time write path; in the DC unit
    /// its fast paths against its general ones) and time. And
    /// while [`Esc::query_epoch`] stays the same, `next_event` and `irq_line` answer the
    /// same (the segment skips reading them then).
    #[test]
    fn fast_paths_equal_general(
        sms in proptest::collection::vec(arb_sm(), 1..5),
        fmmus in proptest::collection::vec(arb_fmmu(), 1..5),
        fmmus_per_sm in proptest::bool::weighted(0.8),
        four_ports in any::<bool>(),
        ops in proptest::collection::vec(arb_op(), 1..40),
    ) {
        let mk = || {
            let mut c = EscConfig::et1100();
            if four_ports {
                c.port_descriptor = 0xFF;
            }
            let mut e = Esc::new(c, eeprom(0x0005, STATIONS[1]));
            fpwr(&mut e, 0x0010, &STATIONS[0].to_le_bytes());
            e
        };
        let mut a = mk();
        let mut b = mk();
        b.set_fast_paths(false);
        let sm_start = |n: usize| match sms[n].0 {
            Some(u) => 0x1000 + 16 * u,
            None => 0x1000 + 0x80 * n as u16,
        };
        // Logical layout: FMMUs one after the other (with gaps; `u32::MAX`: random).
        let mut layout = Vec::new();
        let mut log = LOG_BASE;
        let mut hi = LOG_BASE;
        // Mostly at most one FMMU per SM (the usual process-data layout).
        let nf = if fmmus_per_sm { fmmus.len().min(sms.len()) } else { fmmus.len() };
        for (n, &(gap, k, len, ty, aligned)) in fmmus.iter().take(nf).enumerate() {
            let k = k.map_or(n % sms.len(), usize::from);
            let (phys, slen, ctrl) = match sms.get(k) {
                Some(&(_, l, c)) => (sm_start(k), l, c),
                None => (0x1000 + 16 * k as u16, 8, 0),
            };
            let len = len.unwrap_or(slen);
            let ty = ty.unwrap_or(if ctrl & 0x0C == 0x04 { 2 } else { 1 });
            let start = if gap == u32::MAX { (n as u32 * 29) % 0x50 } else { log + gap };
            log = start + len as u32;
            hi = hi.max(log);
            layout.push((n as u16, start, len, aligned, phys, ty));
        }
        let window = hi.saturating_sub(LOG_BASE);
        for e in [&mut a, &mut b] {
            for (n, &(_, len, ctrl)) in sms.iter().enumerate() {
                sm(e, n as u16, sm_start(n), len, ctrl, 1);
            }
            for &(n, start, len, aligned, phys, ty) in &layout {
                let (sbit, ebit) = if aligned { (0, 7) } else { (1, 5) };
                fmmu(e, n, start, len, sbit, ebit, phys, 0, ty);
            }
        }
        let mut t = 0u64;
        let mut da = FrameDispatch::new();
        let mut db = FrameDispatch::new();
        let mut seen: Option<(Option<u64>, Option<u64>, bool)> = None;
        for op in ops {
            t += 1000;
            match op {
                Op::Logical(c, rel, extra, pat, irq, ok, two) => {
                    let cmd = [Command::Lrd, Command::Lwr, Command::Lrw][c as usize];
                    let (addr, len) = match rel {
                        Some(r) => {
                            let addr = (LOG_BASE as i32 + r) as u32;
                            let len = (window as i32 - r).clamp(0, 0x200) as u16;
                            (addr, len + extra % 4)
                        }
                        None => (extra as u32, pat as u16 % 0x90),
                    };
                    let data: Vec<u8> = (0..len).map(|i| pat.wrapping_add(i as u8)).collect();
                    let mut h = DatagramHeader::logical(cmd, 0, addr, data.len() as u16);
                    h.irq = irq;
                    let mut f = if two {
                        frame(&[(h, &data), (h, &data)])
                    } else {
                        frame(&[(h, &data)])
                    };
                    let mut g = f.clone();
                    let ra = a.forward(0, &mut f, t, ok);
                    let rb = b.forward(0, &mut g, t, ok);
                    prop_assert_eq!(ra, rb);
                    prop_assert_eq!(f, g);
                }
                Op::PdiRead(off, len) => {
                    let mut x = vec![0u8; len as usize];
                    let mut y = vec![0u8; len as usize];
                    prop_assert_eq!(a.pdi_read(0x1000 + off, &mut x), b.pdi_read(0x1000 + off, &mut y));
                    prop_assert_eq!(x, y);
                }
                Op::PdiWrite(off, d) => {
                    prop_assert_eq!(a.pdi_write(0x1000 + off, &d), b.pdi_write(0x1000 + off, &d));
                }
                Op::PdiReadReg(addr, len) => {
                    let mut x = vec![0u8; len as usize];
                    let mut y = vec![0u8; len as usize];
                    prop_assert_eq!(a.pdi_read(addr, &mut x), b.pdi_read(addr, &mut y));
                    prop_assert_eq!(x, y);
                }
                Op::EcatEvent(addr, d) => {
                    // AL control as the master writes it (state 1..8), an SM activate byte
                    // with its enable bit mostly set.
                    let d = if addr == 0x0120 { 1 + d % 8 } else { d | u8::from(d % 4 != 0) };
                    for e in [&mut a, &mut b] {
                        run_at(e, t, Command::Fpwr, STATIONS[0], addr, &[d]);
                    }
                }
                Op::Mask(m) => {
                    prop_assert_eq!(fpwr(&mut a, 0x0200, &m.to_le_bytes()), fpwr(&mut b, 0x0200, &m.to_le_bytes()));
                }
                Op::Link(p, up) => {
                    a.set_link(p, up);
                    b.set_link(p, up);
                }
                Op::Pass(port, irq, ok) => {
                    let mut h = DatagramHeader::physical(Command::Fprd, 0, STATIONS[2], 0x0130, 2);
                    h.irq = irq;
                    let mut f = frame(&[(h, &[0, 0])]);
                    let mut g = f.clone();
                    prop_assert_eq!(a.forward(port, &mut f, t, ok), b.forward(port, &mut g, t, ok));
                    prop_assert_eq!(f, g);
                }
                Op::Foreign(who, every, ok) => {
                    let mut dgs: Vec<(DatagramHeader, &[u8])> = who
                        .iter()
                        .map(|&k| {
                            let h = DatagramHeader::physical(Command::Fprd, 0, STATIONS[k as usize], 0x0130, 2);
                            (h, &[0u8, 0][..])
                        })
                        .collect();
                    if every {
                        dgs.push((DatagramHeader::physical(Command::Aprd, 0, 0, 0x0130, 2), &[0, 0]));
                    }
                    let mut f = frame(&dgs);
                    let mut g = f.clone();
                    prop_assert!(da.build(&mut f));
                    prop_assert!(db.build(&mut g));
                    let ra = a.forward_dispatched(0, &mut f, t, ok, &mut da);
                    let rb = b.forward_dispatched(0, &mut g, t, ok, &mut db);
                    da.apply_irq(&mut f);
                    db.apply_irq(&mut g);
                    prop_assert_eq!(ra, rb);
                    prop_assert_eq!(f, g);
                }
                Op::DlControl(lc, alias) => {
                    for e in [&mut a, &mut b] {
                        run_at(e, t, Command::Fpwr, STATIONS[0], 0x0101, &[lc]);
                        run_at(e, t, Command::Fpwr, STATIONS[0], 0x0103, &[u8::from(alias)]);
                    }
                }
                Op::ArmLatch => {
                    for e in [&mut a, &mut b] {
                        run_at(e, t, Command::Fpwr, STATIONS[0], 0x0900, &[0; 4]);
                    }
                }
                Op::Advance(dt) => {
                    t += dt;
                    prop_assert_eq!(a.advance(t), b.advance(t));
                }
                Op::DcWrite(off, d, c, ok) => {
                    let ado = 0x0900 + off;
                    if c == 3 {
                        prop_assert_eq!(a.pdi_write(ado, &d), b.pdi_write(ado, &d));
                    } else {
                        let h = match c {
                            0 => DatagramHeader::physical(Command::Fpwr, 0, STATIONS[0], ado, d.len() as u16),
                            1 => DatagramHeader::physical(Command::Frmw, 0, STATIONS[2], ado, d.len() as u16),
                            4 => DatagramHeader::physical(Command::Frmw, 0, STATIONS[0], ado, d.len() as u16),
                            _ => DatagramHeader::physical(Command::Bwr, 0, 0, ado, d.len() as u16),
                        };
                        let mut f = frame(&[(h, &d)]);
                        let mut g = f.clone();
                        prop_assert_eq!(a.forward(0, &mut f, t, ok), b.forward(0, &mut g, t, ok));
                        prop_assert_eq!(f, g);
                    }
                }
                Op::RegRead(addr, len, how, pat) => {
                    if how == 0 {
                        let mut x = vec![pat; len as usize];
                        let mut y = x.clone();
                        prop_assert_eq!(a.pdi_read(addr, &mut x), b.pdi_read(addr, &mut y));
                        prop_assert_eq!(x, y);
                    } else {
                        let (cmd, adp) = if how == 1 { (Command::Fprd, STATIONS[0]) } else { (Command::Brd, 0) };
                        let d = vec![pat; len as usize];
                        prop_assert_eq!(run_at(&mut a, t, cmd, adp, addr, &d), run_at(&mut b, t, cmd, adp, addr, &d));
                    }
                }
                Op::SmOverRegs(start, len, ctrl, on) => {
                    let mut r = [0u8; 8];
                    r[0..2].copy_from_slice(&start.to_le_bytes());
                    r[2..4].copy_from_slice(&len.to_le_bytes());
                    r[4] = ctrl;
                    r[6] = u8::from(on);
                    prop_assert_eq!(fpwr(&mut a, 0x0838, &r), fpwr(&mut b, 0x0838, &r));
                }
            }
            prop_assert_eq!(a.memory(), b.memory());
            prop_assert_eq!(a.al_event_request(), b.al_event_request());
            prop_assert_eq!(a.ecat_event_request(), b.ecat_event_request());
            prop_assert_eq!(a.irq_line(), b.irq_line());
            prop_assert_eq!(a.digital_outputs(), b.digital_outputs());
            prop_assert_eq!(a.next_event(), b.next_event());
            // The epoch: unchanged means the same answers as when it was last seen.
            let now = (a.query_epoch(), a.next_event(), a.irq_line());
            prop_assert!(now.0.is_some());
            prop_assert_eq!(b.query_epoch(), None);
            if let Some(was) = seen {
                if was.0 == now.0 {
                    prop_assert_eq!((was.1, was.2), (now.1, now.2), "same epoch, other answers");
                }
            }
            seen = Some(now);
        }
        prop_assert_eq!(b.fused_hits, 0);
    }
}
