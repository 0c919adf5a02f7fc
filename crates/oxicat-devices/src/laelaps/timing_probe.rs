//! What SPI bus time does to a Laelaps leg's DC cycle, from a simulated run: one leg node
//! ([`crate::laelaps::rig`]) on a one-ESC segment, reaching its ESC through a chip driver
//! over the simulated SPI with the execution-time model on ([`oxicat_sim::exec_time`]), driven
//! by a minimal frame-level master (auto-increment addressing, no ethercrab: every frame
//! at a virtual time this module chooses, so a run is deterministic and fast).
//!
//! The master brings the node to OP in DC SYNC0 mode at the given cycle and then, every
//! cycle `k` with SYNC0 at `s_k`:
//!
//! 1. optionally probes SM3's status (0x081D, bit 0: a new input buffer is complete and
//!    the master has not read it) with one FPRD arriving at `s_k + L − 1` in even cycles
//!    and at `s_k + L` in odd ones, `L` being the SYNC0 handler's busy time the model
//!    reported for this cycle: the inputs are readable at exactly `s_k + L` when the even
//!    probes all see 0 and the odd ones all see 1 ([`ProbeReport::latency_confirmed`]);
//! 2. at `s_k + T − 14 µs` reads SM3's status, the 22 input bytes and writes the 38 output
//!    bytes in one frame (back before the next SYNC0); a set status bit 0 there means that
//!    cycle's inputs reached the master ([`ProbeReport::fresh_inputs`]).
//!
//! The outputs stay zero (the leg node stays in its Configuration mode, the plant at
//! rest); the SYNC0 handler still reads all 38 output and writes all 22 input bytes.

use crate::laelaps::device::{self, INPUT_BYTES, OUTPUT_BYTES};
use oxicat_esc::{Esc, EscConfig};
use oxicat_wire::{Command, DatagramHeader, EcatFrame, EthernetHeader, FrameBuilder};

use crate::laelaps::rig::{attach_leg_routed, AnyLegRigHandle, LegId, RigConfig, RigError};
use oxicat_sim::exec_time::{ExecTiming, TimingStats, Work};
use oxicat_sim::pdi_path::PdiRoute;
use oxicat_sim::segment::{Segment, DEFAULT_LINK_DELAY_NS};

/// How long before the next SYNC0 the master's process-data frame leaves \[ns\].
const IO_LEAD_NS: u64 = 14_000;
/// Room a status probe frame needs on the wire \[ns\] (84 bytes × 80 ns + delays).
const PROBE_ROOM_NS: u64 = 8_000;

/// One probe run.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeConfig {
    /// How the firmware reaches its ESC (an SPI route).
    pub route: PdiRoute,
    /// DC SYNC0 cycle \[ns\].
    pub cycle_ns: u32,
    /// Cycles measured after the node is in OP.
    pub cycles: u32,
    /// The execution-time model's settings.
    pub timing: ExecTiming,
    /// Probe SM3 around the expected input time (step 1 of the module documentation).
    pub probe_latency: bool,
}

impl ProbeConfig {
    /// `route` at `cycle_ns`, 200 cycles, the thesis' 1 µs application, latency probes on.
    pub fn new(route: PdiRoute, cycle_ns: u32) -> Self {
        Self {
            route,
            cycle_ns,
            cycles: 200,
            timing: ExecTiming::thesis(),
            probe_latency: true,
        }
    }
}

/// What a probe run measured (SYNC0 figures over the measured cycles only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProbeReport {
    /// Cycles measured (= SYNC0 edges in the window).
    pub cycles: u32,
    /// SYNC0 handlers run in the window.
    pub sync0_runs: u64,
    /// SYNC0 events lost in the window (one arrived while another was pending).
    pub sync0_lost: u64,
    /// SYNC0 handlers that started late in the window.
    pub sync0_delayed: u64,
    /// Shortest / longest SYNC0 busy time (bus + CPU) in the window \[ns\].
    pub busy_ns: (u64, u64),
    /// Longest time from a SYNC0 edge to its inputs landing in SM3 in the window \[ns\].
    pub max_latency_ns: u64,
    /// Cycles in which the master found a new input buffer.
    pub fresh_inputs: u32,
    /// Latency probes sent.
    pub probes: u32,
    /// Every probe agreed: the inputs were not there 1 ns before `s_k + L` and were there
    /// at `s_k + L`.
    pub latency_confirmed: bool,
    /// 0x1C32:0B, SM event missed counter, at the end.
    pub sm_event_missed: u16,
    /// 0x1C32:0C, cycle time too small counter, at the end.
    pub cycle_exceeded: u16,
    /// The model's figures since the node started (bring-up included).
    pub timing: TimingStats,
}

/// Why a probe run did not get to measure.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ProbeError {
    /// The rig did not start.
    Rig(RigError),
    /// A frame did not come back or a datagram was not answered (what).
    Frame(&'static str),
    /// The node did not reach the requested AL state: (requested, AL status, status code).
    State(u16, u16, u16),
}

impl core::fmt::Display for ProbeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Rig(e) => write!(f, "{e}"),
            Self::Frame(w) => write!(f, "frame failed: {w}"),
            Self::State(r, s, c) => {
                write!(f, "requested state {r:#x}, AL status {s:#x}, code {c:#06x}")
            }
        }
    }
}

impl std::error::Error for ProbeError {}

/// A datagram of a probe frame: command, ADO, data (its length is the datagram's).
struct Dg<'a>(Command, u16, &'a [u8]);

/// The frame-level master on a one-ESC segment.
struct Master {
    seg: Segment,
}

impl Master {
    /// Sends one frame now; every datagram's data and WKC.
    fn frame(&mut self, dgs: &[Dg<'_>]) -> Result<Vec<(Vec<u8>, u16)>, ProbeError> {
        let mut buf = vec![0u8; 1514];
        let eth = EthernetHeader {
            dst: [0xFF; 6],
            src: [0x10; 6],
            vlan_tci: None,
            payload_offset: 14,
        };
        let bad = |_| ProbeError::Frame("build");
        let mut b = FrameBuilder::new(&mut buf, &eth).map_err(bad)?;
        for (i, d) in dgs.iter().enumerate() {
            b.push(
                DatagramHeader::physical(d.0, i as u8, 0, d.1, d.2.len() as u16),
                d.2,
            )
            .map_err(bad)?;
        }
        let n = b.finish();
        let back = self
            .seg
            .exchange(&buf[..n])
            .ok_or(ProbeError::Frame("lost"))?;
        let (_, f) = EcatFrame::parse_ethernet(&back).map_err(|_| ProbeError::Frame("parse"))?;
        let mut out = Vec::new();
        for d in f.datagrams() {
            let d = d.map_err(|_| ProbeError::Frame("parse"))?;
            if d.wkc == 0 {
                return Err(ProbeError::Frame("not answered"));
            }
            out.push((d.data.to_vec(), d.wkc));
        }
        Ok(out)
    }

    fn wr(&mut self, ado: u16, data: &[u8]) -> Result<(), ProbeError> {
        self.frame(&[Dg(Command::Apwr, ado, data)]).map(|_| ())
    }

    fn rd(&mut self, ado: u16, len: usize) -> Result<Vec<u8>, ProbeError> {
        let z = vec![0u8; len];
        let mut r = self.frame(&[Dg(Command::Aprd, ado, &z)])?;
        Ok(r.pop().map(|x| x.0).unwrap_or_default())
    }

    /// Configures SyncManager `n` (deactivated first, as a master must).
    fn sm(&mut self, n: u16, start: u16, len: u16, ctrl: u8) -> Result<(), ProbeError> {
        self.wr(oxicat_wire::regs::sm(n as u8, 6), &[0])?;
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&len.to_le_bytes());
        r[4] = ctrl;
        r[6] = u8::from(len > 0);
        self.wr(oxicat_wire::regs::sm(n as u8, 0), &r)
    }

    /// Requests AL state `st` and lets the firmware run until it answers (≤ 20 ms).
    fn request(&mut self, st: u16) -> Result<(), ProbeError> {
        self.wr(0x0120, &st.to_le_bytes())?;
        let mut last = (0, 0);
        for _ in 0..40 {
            self.seg.advance_by(500_000);
            let d = self.rd(0x0130, 6)?;
            last = (
                u16::from_le_bytes([d[0], d[1]]),
                u16::from_le_bytes([d[4], d[5]]),
            );
            if last.0 & 0x1F == st || last.0 & 0x10 != 0 {
                break;
            }
        }
        if last == (st, 0) {
            Ok(())
        } else {
            Err(ProbeError::State(st, last.0, last.1))
        }
    }
}

/// Runs a Laelaps (hind-left) leg node as the module documentation describes; `eeprom` is
/// its SII image (`oxicat_esi::sii::generate(laelaps::device::device(Side::Left))`).
pub fn run(cfg: &ProbeConfig, eeprom: Vec<u8>) -> Result<ProbeReport, ProbeError> {
    let leg = LegId::HindLeft;
    let mut seg = Segment::new();
    let id = seg.add(Esc::new(cfg.route.esc_config(EscConfig::et1100()), eeprom));
    let rig = RigConfig::laelaps(leg).timing(cfg.timing);
    let h = attach_leg_routed(&mut seg, id, leg, rig, cfg.route).map_err(ProbeError::Rig)?;
    let mut m = Master { seg };
    let def = device::device(leg.side());
    m.sm(0, def.mailbox.rx_start, def.mailbox.rx_len, 0x26)?;
    m.sm(1, def.mailbox.tx_start, def.mailbox.tx_len, 0x22)?;
    m.request(2)?;
    m.sm(2, def.sm2_start, OUTPUT_BYTES as u16, 0x64)?;
    m.sm(3, def.sm3_start, INPUT_BYTES as u16, 0x20)?;
    let st = m.rd(0x0910, 8)?;
    let now = u64::from_le_bytes(st.try_into().map_err(|_| ProbeError::Frame("0x0910"))?);
    let cyc = u64::from(cfg.cycle_ns.max(1));
    m.wr(0x09A0, &cfg.cycle_ns.to_le_bytes())?;
    m.wr(0x0990, &(now + 1_000_000).to_le_bytes())?;
    m.wr(0x0981, &[0x03])?;
    m.request(4)?;
    m.wr(def.sm2_start, &[0u8; OUTPUT_BYTES])?;
    m.request(8)?;

    let timing = |h: &AnyLegRigHandle| h.report().timing.unwrap_or_default();
    // The first SYNC0 edge of the window.
    let last = m.seg.last_sync(id).0.ok_or(ProbeError::Frame("no SYNC0"))?;
    let mut s = last + cyc;
    while s <= m.seg.now() {
        s += cyc;
    }
    let t0 = timing(&h).get(Work::Sync0);
    let (mut fresh, mut probes, mut confirmed) = (0u32, 0u32, true);
    let (mut min_busy, mut max_busy, mut max_lat) = (u64::MAX, 0u64, 0u64);
    let out = [0u8; OUTPUT_BYTES];
    let zin = [0u8; INPUT_BYTES];
    for k in 0..cfg.cycles {
        let before = timing(&h).get(Work::Sync0);
        m.seg.advance_to(s);
        let w = timing(&h).get(Work::Sync0);
        // This edge's handler started at the edge: its busy time is the input latency.
        let started_now = w.runs == before.runs + 1 && w.delayed == before.delayed;
        let l = w.last_busy_ns;
        if cfg.probe_latency
            && k > 0
            && started_now
            && l > 0
            && l + PROBE_ROOM_NS + IO_LEAD_NS <= cyc
        {
            let at = s + l - u64::from(k % 2 == 0) - DEFAULT_LINK_DELAY_NS;
            m.seg.advance_to(at);
            let st = m.rd(0x081D, 1)?;
            let there = st.first().is_some_and(|b| b & 1 != 0);
            confirmed &= there == (k % 2 == 1);
            probes += 1;
        }
        m.seg.advance_to(s + cyc - IO_LEAD_NS);
        let r = m.frame(&[
            Dg(Command::Aprd, 0x081D, &[0]),
            Dg(Command::Aprd, def.sm3_start, &zin),
            Dg(Command::Apwr, def.sm2_start, &out),
        ])?;
        if r.first()
            .and_then(|d| d.0.first())
            .is_some_and(|b| b & 1 != 0)
        {
            fresh += 1;
        }
        let w = timing(&h).get(Work::Sync0);
        if w.runs > 0 {
            min_busy = min_busy.min(w.last_busy_ns);
            max_busy = max_busy.max(w.last_busy_ns);
            max_lat = max_lat.max(w.last_response_ns);
        }
        s += cyc;
    }
    let all = timing(&h);
    let w = all.get(Work::Sync0);
    let (missed, exceeded) = match &h {
        AnyLegRigHandle::Spi(r) => {
            let r = r.lock();
            let od = r.slave.od();
            (
                od.get::<u16>(0x1C32, 0x0B).unwrap_or(0),
                od.get::<u16>(0x1C32, 0x0C).unwrap_or(0),
            )
        }
        AnyLegRigHandle::Direct(r) => {
            let r = r.lock();
            let od = r.slave.od();
            (
                od.get::<u16>(0x1C32, 0x0B).unwrap_or(0),
                od.get::<u16>(0x1C32, 0x0C).unwrap_or(0),
            )
        }
    };
    Ok(ProbeReport {
        cycles: cfg.cycles,
        sync0_runs: w.runs - t0.runs,
        sync0_lost: w.lost - t0.lost,
        sync0_delayed: w.delayed - t0.delayed,
        busy_ns: (if min_busy == u64::MAX { 0 } else { min_busy }, max_busy),
        max_latency_ns: max_lat,
        fresh_inputs: fresh,
        probes,
        latency_confirmed: confirmed && probes > 0,
        sm_event_missed: missed,
        cycle_exceeded: exceeded,
        timing: all,
    })
}
