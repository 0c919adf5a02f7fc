//! What the master sends each cycle of the trot, as the thesis' Table 2-4 counts it for its
//! one-node segment: the datagrams of the cyclic frame, its size on the wire, its duration
//! at 100 Mbit/s, its trip through the chain, and the SYNC0/SYNC1 shifts the nodes run
//! with.
//!
//! The datagrams are those ethercrab 0.7's `SubDeviceGroup::tx_rx_dc` builds, the call the
//! trot makes every cycle: an FRMW of the reference clock's system time (0x0910, 8 bytes),
//! one LRW over the group's process data image (every node's outputs and inputs), and, while
//! the frame has room, one FPRD of each node's AL status (0x0130, 2 bytes). The delays are
//! the virtual segment's defaults (`oxicat_sim::segment`), which the trot does not change.

use std::fmt::Write as _;

use oxicat_sim::segment::{BYTE_TIME_NS, DEFAULT_ESC_DELAY_NS, DEFAULT_LINK_DELAY_NS};

use crate::laelaps::device::{INPUT_BYTES, OUTPUT_BYTES};
use crate::laelaps::rig::TOWER_CHAIN;
use crate::laelaps::scenario::Scenario;

/// Ethernet header (destination, source, EtherType) \[bytes\].
pub const ETHERNET_HEADER: usize = 14;
/// EtherCAT frame header \[bytes\].
pub const ECAT_HEADER: usize = 2;
/// Datagram header (command, index, address, length, IRQ) \[bytes\].
pub const DATAGRAM_HEADER: usize = 10;
/// Working counter closing every datagram \[bytes\].
pub const WKC: usize = 2;
/// Shortest Ethernet frame without FCS \[bytes\].
pub const MIN_FRAME: usize = 60;
/// Frame check sequence \[bytes\].
pub const FCS: usize = 4;
/// Preamble + start-of-frame delimiter \[bytes\].
pub const PREAMBLE: usize = 8;
/// Inter-frame gap \[bytes\].
pub const IFG: usize = 12;

/// One datagram of the cyclic frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Datagram {
    /// Command (`FRMW`, `LRW`, `FPRD`).
    pub cmd: &'static str,
    /// What it carries.
    pub what: String,
    /// Data bytes.
    pub data: usize,
}

/// The cyclic frame of a scenario and the DC shifts its nodes run with.
#[derive(Debug, Clone, PartialEq)]
pub struct FramePlan {
    /// Nodes in the chain.
    pub nodes: usize,
    /// Output bytes of one node (RxPDO, SM2).
    pub node_outputs: usize,
    /// Input bytes of one node (TxPDO, SM3).
    pub node_inputs: usize,
    /// The frame's datagrams in order.
    pub datagrams: Vec<Datagram>,
    /// SYNC0 period \[ns\].
    pub cycle_ns: u64,
    /// Shift of SYNC0 against the master's cycle (ethercrab's `sync0_shift`) \[ns\].
    pub sync0_shift_ns: u64,
    /// Sync type written to 0x1C32:01 (2 = DC SYNC0, 3 = DC SYNC1).
    pub sync_mode: u16,
    /// SYNC1 after SYNC0 (0x09A4, reported in 0x1C33:03) \[ns\]; `None` without SYNC1.
    pub sync1_shift_ns: Option<u64>,
}

impl FramePlan {
    /// The cyclic frame the trot's master sends for scenario `s`.
    pub fn of(s: &Scenario) -> Self {
        let nodes = TOWER_CHAIN.len();
        let pdi = nodes * (OUTPUT_BYTES + INPUT_BYTES);
        let mut datagrams = vec![
            Datagram {
                cmd: "FRMW",
                what: "DC system time 0x0910 of the reference clock".into(),
                data: 8,
            },
            Datagram {
                cmd: "LRW",
                what: format!("process data: {nodes} × ({OUTPUT_BYTES} out + {INPUT_BYTES} in)"),
                data: pdi,
            },
        ];
        for i in 0..nodes {
            datagrams.push(Datagram {
                cmd: "FPRD",
                what: format!("AL status 0x0130 of node {i}"),
                data: 2,
            });
        }
        let sync1 = s.bus.sync1;
        FramePlan {
            nodes,
            node_outputs: OUTPUT_BYTES,
            node_inputs: INPUT_BYTES,
            datagrams,
            cycle_ns: s.cycle_ns(),
            sync0_shift_ns: u64::from(s.bus.sync0_shift_us) * 1000,
            sync_mode: if sync1 { 3 } else { 2 },
            sync1_shift_ns: sync1.then(|| u64::from(s.bus.sync1_shift_us) * 1000),
        }
    }

    /// Data bytes of all datagrams.
    pub fn data_bytes(&self) -> usize {
        self.datagrams.iter().map(|d| d.data).sum()
    }

    /// The Ethernet frame without FCS, padded to 60 \[bytes\].
    pub fn frame_bytes(&self) -> usize {
        let n = self.datagrams.len();
        (ETHERNET_HEADER + ECAT_HEADER + n * (DATAGRAM_HEADER + WKC) + self.data_bytes())
            .max(MIN_FRAME)
    }

    /// Bytes the frame holds the wire for: frame, FCS, preamble + SFD, inter-frame gap.
    pub fn wire_bytes(&self) -> usize {
        self.frame_bytes() + FCS + PREAMBLE + IFG
    }

    /// Wire time at 100 Mbit/s \[ns\].
    pub fn wire_ns(&self) -> u64 {
        self.wire_bytes() as u64 * BYTE_TIME_NS
    }

    /// Time the frame's first bit spends in the chain and its cables, out and back: the
    /// last node turns it round, so it passes `2n − 1` ESCs and `2n` cables (the master's
    /// included) \[ns\].
    pub fn forwarding_ns(&self) -> u64 {
        let n = self.nodes as u64;
        (2 * n).saturating_sub(1) * DEFAULT_ESC_DELAY_NS + 2 * n * DEFAULT_LINK_DELAY_NS
    }

    /// From the first bit sent to the last bit back at the master \[ns\].
    pub fn round_trip_ns(&self) -> u64 {
        self.forwarding_ns() + self.wire_ns()
    }

    /// Share of the cycle the wire is busy with the frame.
    pub fn utilisation(&self) -> f64 {
        self.wire_ns() as f64 / self.cycle_ns.max(1) as f64
    }

    /// The Markdown section for `summary.md`: the frame beside the thesis' Table 2-4.
    pub fn markdown(&self) -> String {
        let n = self.datagrams.len();
        let mut o = String::new();
        let _ = writeln!(o, "\n## Cyclic frame (thesis Table 2-4)\n");
        let _ = writeln!(
            o,
            "What the master sends every {} µs cycle (ethercrab `tx_rx_dc`); the thesis \
             counts its one-node TwinCAT segment.\n",
            self.cycle_ns as f64 / 1e3
        );
        let _ = writeln!(o, "| datagram | carries | data [bytes] |");
        let _ = writeln!(o, "|---|---|---|");
        for d in &self.datagrams {
            let _ = writeln!(o, "| {} | {} | {} |", d.cmd, d.what, d.data);
        }
        let data: Vec<String> = self.datagrams.iter().map(|d| d.data.to_string()).collect();
        let _ = writeln!(o);
        let _ = writeln!(o, "| component | this trot [bytes] | thesis [bytes] |");
        let _ = writeln!(o, "|---|---|---|");
        let _ = writeln!(o, "| Ethernet header | {ETHERNET_HEADER} | 14 |");
        let _ = writeln!(o, "| EtherCAT header | {ECAT_HEADER} | 2 |");
        let _ = writeln!(
            o,
            "| datagram headers | {DATAGRAM_HEADER} × {n} = {} | 10 × 5 = 50 |",
            DATAGRAM_HEADER * n
        );
        let _ = writeln!(
            o,
            "| datagram data | {} = {} | 4+4+1+24+2 = 35 |",
            data.join("+"),
            self.data_bytes()
        );
        let _ = writeln!(
            o,
            "| datagram WKCs | {WKC} × {n} = {} | 2 × 5 = 10 |",
            WKC * n
        );
        let _ = writeln!(o, "| Ethernet FCS | {FCS} | 4 |");
        let _ = writeln!(
            o,
            "| inter-frame gap + preamble + SFD | {IFG}+{}+1 = {} | 12+7+1 = 20 |",
            PREAMBLE - 1,
            IFG + PREAMBLE
        );
        let _ = writeln!(
            o,
            "| **total** | **{}** (frame {}) | **135** |",
            self.wire_bytes(),
            self.frame_bytes()
        );
        let _ = writeln!(
            o,
            "| duration at 100 Mbit/s (80 ns/byte) | {:.2} µs | 10.8 µs |",
            self.wire_ns() as f64 / 1e3
        );
        let _ = writeln!(
            o,
            "| wire utilisation | {:.2} % of {} µs | 5.40 % of 200 µs |",
            self.utilisation() * 100.0,
            self.cycle_ns as f64 / 1e3
        );
        let _ = writeln!(
            o,
            "| forwarding through {} nodes and back ({} ESC passes × {} ns, {} cables × {} ns) | {:.2} µs | — |",
            self.nodes,
            (2 * self.nodes).saturating_sub(1),
            DEFAULT_ESC_DELAY_NS,
            2 * self.nodes,
            DEFAULT_LINK_DELAY_NS,
            self.forwarding_ns() as f64 / 1e3
        );
        let _ = writeln!(
            o,
            "| round trip (forwarding + wire time) | {:.2} µs | — |",
            self.round_trip_ns() as f64 / 1e3
        );
        let _ = writeln!(
            o,
            "| sync type 0x1C32:01 | {} ({}) | DC SYNC0 |",
            self.sync_mode,
            if self.sync_mode == 3 {
                "DC SYNC1"
            } else {
                "DC SYNC0"
            }
        );
        let _ = writeln!(
            o,
            "| SYNC0 shift (master frame after SYNC0) | {:.0} µs | 0 (delay times set to 0) |",
            self.sync0_shift_ns as f64 / 1e3
        );
        let _ = writeln!(
            o,
            "| last bit back at the master, after SYNC0 | {:.2} µs (next SYNC0 at {:.0} µs) | — |",
            (self.sync0_shift_ns + self.round_trip_ns()) as f64 / 1e3,
            self.cycle_ns as f64 / 1e3
        );
        let _ = writeln!(
            o,
            "| SYNC1 shift 0x1C33:03 | {} | 0 (zero delay times) |",
            match self.sync1_shift_ns {
                Some(ns) => format!("{:.0} µs", ns as f64 / 1e3),
                None => "— (no SYNC1)".into(),
            }
        );
        o
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_trot_frame_is_counted_from_the_nodes_pdos() {
        let p = FramePlan::of(&Scenario::thesis());
        assert_eq!(p.nodes, 4);
        // Four nodes of 38 output and 22 input bytes in one LRW, the DC time, 4 AL statuses.
        let pdo: usize = 4 * (OUTPUT_BYTES + INPUT_BYTES);
        assert_eq!(pdo, 240);
        assert_eq!(p.datagrams.len(), 6);
        assert_eq!(p.data_bytes(), pdo + 8 + 4 * 2);
        let frame = 14 + 2 + 6 * (10 + 2) + pdo + 8 + 4 * 2;
        assert_eq!(p.frame_bytes(), frame);
        assert_eq!(frame, 344);
        assert_eq!(p.wire_bytes(), frame + 4 + 8 + 12);
        assert_eq!(p.wire_ns(), p.wire_bytes() as u64 * 80);
        assert_eq!(p.wire_ns(), 29_440);
        // 7 ESC passes of 450 ns and 8 cables of 50 ns.
        assert_eq!(p.forwarding_ns(), 7 * 450 + 8 * 50);
        assert_eq!(p.round_trip_ns(), p.forwarding_ns() + p.wire_ns());
        // The shipped scenario: the frame leaves 200 µs after SYNC0, DC SYNC0 mode, no SYNC1.
        assert_eq!(
            (p.sync_mode, p.sync1_shift_ns, p.sync0_shift_ns),
            (2, None, 200_000)
        );
        assert!(md_has(
            &p,
            "| SYNC0 shift (master frame after SYNC0) | 200 µs |"
        ));
        let md = p.markdown();
        assert!(
            md.contains("| **total** | **368** (frame 344) | **135** |"),
            "{md}"
        );
        assert!(md.contains("| 29.44 µs | 10.8 µs |"), "{md}");
    }

    fn md_has(p: &FramePlan, row: &str) -> bool {
        p.markdown().contains(row)
    }

    #[test]
    fn sync1_split_reports_mode_3_and_its_shift() {
        let p = FramePlan::of(&Scenario::thesis().with_sync1(100));
        assert_eq!((p.sync_mode, p.sync1_shift_ns), (3, Some(100_000)));
        assert!(p.markdown().contains("| SYNC1 shift 0x1C33:03 | 100 µs |"));
    }

    #[test]
    fn a_frame_shorter_than_60_bytes_is_padded() {
        let mut p = FramePlan::of(&Scenario::thesis());
        p.datagrams.truncate(1);
        assert_eq!(p.frame_bytes(), MIN_FRAME);
    }
}
