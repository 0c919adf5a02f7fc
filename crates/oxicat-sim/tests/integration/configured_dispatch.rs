//! Configured-address dispatch against the per-ESC walk: for random segments (lines and
//! branches, duplicate station addresses, aliases, IRQ masks, device emulation, pulled
//! cables) and random frames (every datagram kind, AL control writes, station-address,
//! alias, loop-control and mask writes in the same frame as configured-address datagrams
//! for those stations, malformed tails), a segment with dispatch and one without return
//! the same frames (bytes, working counters, IRQ fields), fates and times, and leave every
//! ESC with the same registers and process RAM. Both against the reference: the per-ESC
//! walk with the ESCs' fast paths off (`Esc::set_fast_paths(false)`: no fused path, no
//! pass-through shortcuts, every hop re-reads next event and IRQ line), which also gives
//! the same events (IRQ edges, SYNC, watchdogs) at the same times.

use oxicat_esc::{Esc, EscConfig};
use oxicat_sim::segment::Segment;
use proptest::prelude::*;

/// Station addresses and aliases come from this small set, so that duplicates, alias hits
/// and misses are common.
const ADDRS: [u16; 4] = [0x1001, 0x1002, 0x1003, 0x0000];

/// Register offsets the random datagrams touch (and how many bytes at most).
const OFFSETS: [(u16, usize); 14] = [
    (0x0010, 2),  // station address
    (0x0012, 2),  // station alias
    (0x0100, 4),  // DL control: loop control (0x0101), alias enable (0x0103)
    (0x0103, 1),  // alias enable alone
    (0x0110, 2),  // DL status (a read clears the DL event)
    (0x0120, 2),  // AL control
    (0x0130, 2),  // AL status
    (0x0134, 2),  // AL status code
    (0x0200, 2),  // ECAT event mask
    (0x0210, 2),  // ECAT event request
    (0x0220, 4),  // AL event request
    (0x0600, 16), // FMMU 0
    (0x0900, 4),  // DC receive times (a write latches)
    (0x1000, 8),  // process RAM
];

#[derive(Debug, Clone)]
struct EscSpec {
    four_ports: bool,
    emulation: bool,
    alias: u16,
    station: u16,
    alias_enable: bool,
    mask: u16,
}

#[derive(Debug, Clone)]
struct Topo {
    escs: Vec<EscSpec>,
    /// (ESC, ESC) pairs: the second hangs off the first's port 3 instead of the line.
    branch: Option<(usize, usize)>,
    /// A cable pulled: (ESC, port).
    pulled: Option<(usize, u8)>,
}

#[derive(Debug, Clone)]
struct Dg {
    cmd: u8,
    adp: u16,
    ado: u16,
    data: Vec<u8>,
    irq: u16,
    wkc: u16,
}

#[derive(Debug, Clone)]
struct Frame {
    dgs: Vec<Dg>,
    /// Bytes cut from the declared frame length (a malformed last datagram).
    cut: usize,
    /// Time before the frame is sent, ns.
    gap_ns: u64,
}

fn esc_spec() -> impl Strategy<Value = EscSpec> {
    (
        any::<bool>(),
        any::<bool>(),
        0..ADDRS.len(),
        0..ADDRS.len(),
        any::<bool>(),
        prop_oneof![Just(0u16), Just(0x000C), Just(0xFFFF), any::<u16>()],
    )
        .prop_map(
            |(four_ports, emulation, a, s, alias_enable, mask)| EscSpec {
                four_ports,
                emulation,
                alias: ADDRS[a],
                station: ADDRS[s],
                alias_enable,
                mask,
            },
        )
}

fn topo() -> impl Strategy<Value = Topo> {
    prop::collection::vec(esc_spec(), 1..7).prop_flat_map(|escs| {
        let n = escs.len();
        (
            Just(escs),
            prop::option::weighted(0.3, (0..n, 0..n)),
            prop::option::weighted(0.2, (0..n, 0u8..4)),
        )
            .prop_map(|(escs, branch, pulled)| Topo {
                escs,
                branch,
                pulled,
            })
    })
}

fn datagram() -> impl Strategy<Value = Dg> {
    // Configured-address kinds are weighted up: they are what the dispatch changes.
    let cmd = prop_oneof![
        4 => Just(0x04u8), // FPRD
        3 => Just(0x05),   // FPWR
        2 => Just(0x06),   // FPRW
        1 => Just(0x0E),   // FRMW
        1 => Just(0x01),   // APRD
        1 => Just(0x02),   // APWR
        1 => Just(0x03),   // APRW
        1 => Just(0x0D),   // ARMW
        1 => Just(0x07),   // BRD
        1 => Just(0x08),   // BWR
        1 => Just(0x09),   // BRW
        1 => Just(0x0A),   // LRD
        1 => Just(0x0B),   // LWR
        1 => Just(0x0C),   // LRW
        1 => Just(0x00),   // NOP
        1 => Just(0x0F),   // reserved
    ];
    (
        cmd,
        0..ADDRS.len(),
        0u16..8,
        0..OFFSETS.len(),
        prop::collection::vec(any::<u8>(), 1..17),
        prop_oneof![3 => Just(0u16), 1 => any::<u16>()],
        prop_oneof![3 => Just(0u16), 1 => any::<u16>()],
    )
        .prop_map(|(cmd, a, pos, o, mut data, irq, wkc)| {
            let (ado, max) = OFFSETS[o];
            data.truncate(max);
            let (adp, ado) = match cmd {
                // Auto-increment: the ESC at position `pos` (adp = -pos).
                0x01..=0x03 | 0x0D => (0u16.wrapping_sub(pos), ado),
                // Logical: the FMMU's logical window (set up below) or elsewhere.
                0x0A..=0x0C => {
                    return Dg {
                        cmd,
                        adp: 0x0001,
                        ado: if pos < 6 { 0x0000 } else { 0x0100 },
                        data,
                        irq,
                        wkc,
                    }
                }
                0x04..=0x06 | 0x0E => (ADDRS[a], ado),
                _ => (pos, ado),
            };
            Dg {
                cmd,
                adp,
                ado,
                data,
                irq,
                wkc,
            }
        })
}

fn frame() -> impl Strategy<Value = Frame> {
    (
        prop::collection::vec(datagram(), 1..14),
        prop_oneof![6 => Just(0usize), 1 => 1usize..12],
        prop_oneof![Just(0u64), 1_000u64..2_000_000],
    )
        .prop_map(|(dgs, cut, gap_ns)| Frame { dgs, cut, gap_ns })
}

/// An Ethernet frame holding `dgs` (the EtherCAT length shortened by `cut`).
fn ethernet(dgs: &[Dg], cut: usize) -> Vec<u8> {
    let mut f = vec![0xFF; 6];
    f.extend_from_slice(&[0x02, 0, 0, 0, 0, 1, 0x88, 0xA4]);
    let mut body = Vec::new();
    for (i, d) in dgs.iter().enumerate() {
        let more = if i + 1 < dgs.len() { 0x8000 } else { 0 };
        body.push(d.cmd);
        body.push(i as u8);
        body.extend_from_slice(&d.adp.to_le_bytes());
        body.extend_from_slice(&d.ado.to_le_bytes());
        body.extend_from_slice(&(d.data.len() as u16 | more).to_le_bytes());
        body.extend_from_slice(&d.irq.to_le_bytes());
        body.extend_from_slice(&d.data);
        body.extend_from_slice(&d.wkc.to_le_bytes());
    }
    let len = body.len().saturating_sub(cut) as u16;
    f.extend_from_slice(&(0x1000 | len).to_le_bytes());
    f.extend_from_slice(&body);
    f
}

/// An SII image whose configuration area sets device emulation and the alias.
fn eeprom(s: &EscSpec) -> Vec<u8> {
    let mut e = vec![0u8; 256];
    e[1] = u8::from(s.emulation); // 0x0141 bit 0: device emulation
    e[8..10].copy_from_slice(&s.alias.to_le_bytes());
    e
}

/// Builds the segment of `t` and sets it up through frames (identical for both walks):
/// station addresses, alias enables, IRQ masks and an FMMU over process RAM.
fn build(t: &Topo, dispatch: bool) -> Segment<Esc> {
    build_with(t, dispatch, true)
}

/// [`build`] with the ESCs' fast paths on or off (the reference), event logging on.
fn build_with(t: &Topo, dispatch: bool, fast: bool) -> Segment<Esc> {
    let mut seg = Segment::<Esc>::new();
    seg.set_configured_dispatch(dispatch);
    seg.log_events(true);
    let n = t.escs.len();
    for s in &t.escs {
        let mut c = EscConfig::et1100();
        if s.four_ports {
            c.port_descriptor = 0xFF;
        }
        let mut e = Esc::new(c, eeprom(s));
        e.set_fast_paths(fast);
        seg.add_unwired(e);
    }
    let mut prev = 0;
    for i in 1..n {
        let hang = match t.branch {
            Some((a, b)) if b == i && a < i && t.escs[a].four_ports => seg.connect(a, 3, i, 0),
            _ => Err(oxicat_sim::segment::TopologyError::SelfLoop),
        };
        if hang.is_err() {
            seg.connect(prev, 1, i, 0).expect("line wiring");
            prev = i;
        }
    }
    let mut setup = Vec::new();
    for (i, s) in t.escs.iter().enumerate() {
        let adp = 0u16.wrapping_sub(i as u16);
        let dg = |ado: u16, data: Vec<u8>| Dg {
            cmd: 0x02,
            adp,
            ado,
            data,
            irq: 0,
            wkc: 0,
        };
        setup.push(dg(0x0010, s.station.to_le_bytes().to_vec()));
        setup.push(dg(0x0103, vec![u8::from(s.alias_enable)]));
        setup.push(dg(0x0200, s.mask.to_le_bytes().to_vec()));
        // FMMU 0: logical 0x0000..0x0008 <-> 0x1000, read and write, enabled.
        let mut fmmu = vec![0u8; 16];
        fmmu[4..6].copy_from_slice(&8u16.to_le_bytes());
        fmmu[7] = 7;
        fmmu[8..10].copy_from_slice(&0x1000u16.to_le_bytes());
        fmmu[11] = 3;
        fmmu[12] = 1;
        setup.push(dg(0x0600, fmmu));
    }
    for chunk in setup.chunks(8) {
        assert!(
            seg.exchange(&ethernet(chunk, 0)).is_some(),
            "setup frame lost"
        );
    }
    if let Some((a, p)) = t.pulled {
        let _ = seg.set_cable(a, p, false);
    }
    seg
}

fn state(seg: &Segment<Esc>) -> Vec<Vec<u8>> {
    (0..seg.len())
        .map(|i| seg.esc(i).expect("esc").memory().to_vec())
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn dispatch_matches_the_per_esc_walk(t in topo(), frames in prop::collection::vec(frame(), 1..6)) {
        let mut new = build(&t, true);
        let mut old = build(&t, false);
        let mut reference = build_with(&t, false, false);
        prop_assert_eq!(state(&new), state(&reference));
        prop_assert_eq!(state(&old), state(&reference));
        prop_assert_eq!(new.take_events(), reference.take_events());
        prop_assert_eq!(old.take_events(), reference.take_events());
        for f in &frames {
            new.advance_by(f.gap_ns);
            old.advance_by(f.gap_ns);
            reference.advance_by(f.gap_ns);
            let bytes = ethernet(&f.dgs, f.cut);
            let r = reference.exchange(&bytes);
            for seg in [&mut new, &mut old] {
                let a = seg.exchange(&bytes);
                prop_assert_eq!(&a, &r);
                prop_assert_eq!(seg.last_fate(), reference.last_fate());
                prop_assert_eq!(seg.now(), reference.now());
                let (sa, sb) = (state(seg), state(&reference));
                for (i, (x, y)) in sa.iter().zip(&sb).enumerate() {
                    if let Some(k) = x.iter().zip(y).position(|(p, q)| p != q) {
                        prop_assert!(false, "ESC {} differs at 0x{:04X}: {:#04x} vs {:#04x}", i, k, x[k], y[k]);
                    }
                }
            }
            let events = reference.take_events();
            prop_assert_eq!(new.take_events(), events.clone());
            prop_assert_eq!(old.take_events(), events);
        }
    }
}

/// Two ESCs with the same station address both answer an FPRD (working counter 2) and an
/// ESC with another address leaves it alone; the IRQ field shows the event-masked requests
/// of every ESC the datagram passed, including those that did not process it.
#[test]
fn duplicate_addresses_both_answer_and_every_esc_ors_its_irq() {
    let specs = [0x1001u16, 0x1002, 0x1001];
    let t = Topo {
        escs: specs
            .iter()
            .map(|&s| EscSpec {
                four_ports: false,
                emulation: true,
                alias: 0,
                station: s,
                alias_enable: false,
                mask: 0,
            })
            .collect(),
        branch: None,
        pulled: None,
    };
    let mut seg = build(&t, true);
    // ESC 1 (address 0x1002) unmasks the DL status event (pending since power-on).
    let mask = Dg {
        cmd: 0x05,
        adp: 0x1002,
        ado: 0x0200,
        data: vec![0x04, 0x00],
        irq: 0,
        wkc: 0,
    };
    let rd = |adp: u16| Dg {
        cmd: 0x04,
        adp,
        ado: 0x0130,
        data: vec![0; 2],
        irq: 0,
        wkc: 0,
    };
    let back = seg
        .exchange(&ethernet(&[mask, rd(0x1001), rd(0x1003)], 0))
        .expect("frame back");
    // Datagram headers at 16 (the mask write, 2 data bytes), 30 and 44.
    let wkc = |at: usize| u16::from_le_bytes([back[at + 12], back[at + 13]]);
    let irq = |at: usize| u16::from_le_bytes([back[at + 8], back[at + 9]]);
    assert_eq!(wkc(16), 1, "the mask write reached 0x1002");
    assert_eq!(wkc(30), 2, "both ESCs at 0x1001 answered");
    assert_eq!(wkc(44), 0, "nobody is 0x1003");
    // The mask write's own IRQ field shows the state before it; the FPRDs after it carry
    // ESC 1's DL status event although ESC 1 did not process them.
    assert_eq!(irq(16), 0);
    assert_eq!(irq(30), 0x0004);
    assert_eq!(irq(44), 0x0004);
}
