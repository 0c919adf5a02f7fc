//! Replay bench: captures of real masters with real hardware, fed into software ESCs.
//!
//! A capture holds the master's frames (source MAC bit 0x02 of the first octet clear)
//! and the frames that came back from the real segment (bit set by the first ESC).
//! [`pair`] matches each returned frame to the master frame it answers; [`Bench`] walks
//! every master frame through a line of [`Esc`]s at its capture timestamp (virtual time)
//! and [`Bench::replay`] compares the produced reply with the recorded one datagram by
//! datagram, applying only the explicit [`Mask`]s a capture declares.
#![allow(dead_code)]

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;

use oxicat_esc::{Esc, EscConfig, Forward};
use oxicat_sim::pcapng;
use oxicat_wire::{EcatFrame, EthernetHeader};

/// The reference directory (env `OXICAT_REFERENCE`, default `../../../shared/reference`).
pub fn reference_dir() -> PathBuf {
    std::env::var_os("OXICAT_REFERENCE")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference")
        })
}

/// Reads a reference file; a missing file fails the test.
pub fn reference_file(rel: &str) -> Vec<u8> {
    let p = reference_dir().join(rel);
    std::fs::read(&p).unwrap_or_else(|e| panic!("reference file {} is missing: {e}", p.display()))
}

/// One EtherCAT frame of a capture.
#[derive(Debug, Clone)]
pub struct CapFrame {
    /// 1-based frame number in the capture file (as Wireshark counts).
    pub number: usize,
    /// Capture timestamp in ns.
    pub ts: u64,
    /// The whole Ethernet frame.
    pub data: Vec<u8>,
}

/// A master frame and the frame that came back for it, if any.
#[derive(Debug, Clone)]
pub struct Exchange {
    /// The frame the master sent.
    pub sent: CapFrame,
    /// The frame the segment returned.
    pub reply: Option<CapFrame>,
}

/// Decoded datagram (owned) for comparison.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Dg {
    /// Command byte.
    pub cmd: u8,
    /// Index.
    pub idx: u8,
    /// 32-bit address.
    pub addr: u32,
    /// Length/flags word as on the wire.
    pub len_flags: u16,
    /// IRQ field.
    pub irq: u16,
    /// Data.
    pub data: Vec<u8>,
    /// Working counter.
    pub wkc: u16,
}

impl Dg {
    /// ADP (low half of the address).
    pub fn adp(&self) -> u16 {
        self.addr as u16
    }
    /// ADO (high half of the address).
    pub fn ado(&self) -> u16 {
        (self.addr >> 16) as u16
    }
    /// True for LRD/LWR/LRW.
    pub fn logical(&self) -> bool {
        matches!(self.cmd, 10..=12)
    }
    /// Mnemonic.
    pub fn name(&self) -> &'static str {
        oxicat_wire::Command::from_u8(self.cmd).map_or("?", |c| c.name())
    }
    /// Short description for reports.
    pub fn describe(&self) -> String {
        if self.logical() {
            format!(
                "{} idx {:#04x} logical {:#010x} len {}",
                self.name(),
                self.idx,
                self.addr,
                self.data.len()
            )
        } else {
            format!(
                "{} idx {:#04x} adp {:#06x} ado {:#06x} len {}",
                self.name(),
                self.idx,
                self.adp(),
                self.ado(),
                self.data.len()
            )
        }
    }
}

/// Parses the datagrams of an Ethernet frame carrying EtherCAT.
pub fn datagrams(eth: &[u8]) -> Option<Vec<Dg>> {
    let (_, f) = EcatFrame::parse_ethernet(eth).ok()?;
    let mut v = Vec::new();
    for d in f.datagrams() {
        let d = d.ok()?;
        v.push(Dg {
            cmd: d.header.command,
            idx: d.header.index,
            addr: d.header.address,
            len_flags: d.header.len_flags(),
            irq: d.header.irq,
            data: d.data.to_vec(),
            wkc: d.wkc,
        });
    }
    Some(v)
}

/// Reads the EtherCAT frames of a capture in `reference/captures/`.
pub fn load_capture(name: &str) -> Vec<CapFrame> {
    let bytes = reference_file(&format!("captures/{name}"));
    let pk = pcapng::read_all(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
    pk.into_iter()
        .enumerate()
        .filter(|(_, p)| {
            EthernetHeader::parse(&p.data)
                .map(|h| {
                    p.data.get(h.payload_offset - 2..h.payload_offset) == Some(&[0x88, 0xA4][..])
                })
                .unwrap_or(false)
        })
        .map(|(i, p)| CapFrame {
            number: i + 1,
            ts: p.ts_ns.unwrap_or(0),
            data: p.data,
        })
        .collect()
}

fn is_returned(f: &CapFrame) -> bool {
    f.data.get(6).is_some_and(|b| b & 0x02 != 0)
}

fn signature(f: &CapFrame) -> Vec<(u8, u8, u16)> {
    datagrams(&f.data)
        .unwrap_or_default()
        .iter()
        .map(|d| (d.cmd, d.idx, d.len_flags & 0x07FF))
        .collect()
}

/// Pairs master frames with the frames that came back: a returned frame answers the oldest
/// unanswered master frame with the same datagram commands, indices and lengths.
pub fn pair(frames: &[CapFrame]) -> Vec<Exchange> {
    let mut out: Vec<Exchange> = Vec::new();
    let mut open: Vec<usize> = Vec::new();
    for f in frames {
        if !is_returned(f) {
            open.push(out.len());
            out.push(Exchange {
                sent: f.clone(),
                reply: None,
            });
            continue;
        }
        let sig = signature(f);
        if let Some(pos) = open.iter().position(|&i| signature(&out[i].sent) == sig) {
            let i = open.remove(pos);
            out[i].reply = Some(f.clone());
        }
    }
    out
}

/// An Ethernet frame as a master sends it, with one physical datagram (cmd, adp, ado, data)
/// of index `idx`.
pub fn master_frame(idx: u8, cmd: u8, adp: u16, ado: u16, data: &[u8]) -> Vec<u8> {
    use oxicat_wire::{Command, DatagramHeader, FrameBuilder};
    let mut buf = vec![0u8; 14 + 2 + 12 + data.len() + 64];
    let eth = EthernetHeader {
        dst: [0xFF; 6],
        src: [0; 6],
        vlan_tci: None,
        payload_offset: 14,
    };
    let mut b = FrameBuilder::new(&mut buf, &eth).expect("frame");
    let c = Command::from_u8(cmd).expect("command");
    b.push(
        DatagramHeader::physical(c, idx, adp, ado, data.len() as u16),
        data,
    )
    .expect("datagram");
    let n = b.finish();
    buf.truncate(n);
    buf
}

// ------------------------------------------------------------------ SII reconstruction

/// Rebuilds per-slave SII images (indexed by ring position) from the EEPROM traffic of a
/// capture. A read command (0x0502 bits 8..10 = 1) and the word address (0x0504) written by
/// APWR/FPWR, in one datagram or in several, then the data register (0x0508..) read by
/// APRD/FPRD: either a read of the data alone (ethercrab, SOEM read 0x0508) or one read
/// of control, address and data together (0x0502..0x050F, as TwinCAT polls). In the
/// second form the read itself shows whether the data is valid: not while 0x0502 shows busy
/// (bit 15) or an error (bits 13/14); the address is the one it shows, and it shows how
/// many bytes a read gives (bit 6: 8, else 4). A write command in between makes the data
/// register hold the written word, not a read; writing 0 (clear errors) changes nothing.
/// Words never read are absent.
pub fn sii_from_capture(ex: &[Exchange]) -> BTreeMap<u16, BTreeMap<u32, [u8; 2]>> {
    use oxicat_wire::regs::sii_control::{ACK_ERROR, BUSY, READ_8, WE_ERROR};
    const CTL: usize = 0x0502;
    const ADDR: usize = 0x0504;
    const DATA: usize = 0x0508;
    let mut station_pos: HashMap<u16, u16> = HashMap::new();
    // Per position: the word address last written, and whether the last command was a read.
    let mut addr: HashMap<u16, u32> = HashMap::new();
    let mut reading: HashMap<u16, bool> = HashMap::new();
    let mut words: BTreeMap<u16, BTreeMap<u32, [u8; 2]>> = BTreeMap::new();
    for e in ex {
        let Some(r) = &e.reply else { continue };
        let (Some(sent), Some(back)) = (datagrams(&e.sent.data), datagrams(&r.data)) else {
            continue;
        };
        for (a, b) in sent.iter().zip(&back) {
            if b.wkc == 0 {
                continue;
            }
            let pos = match a.cmd {
                1..=3 => Some(a.adp().wrapping_neg()),
                4..=6 => station_pos.get(&a.adp()).copied(),
                _ => None,
            };
            if a.cmd == 2 && a.ado() == 0x0010 && a.data.len() >= 2 {
                station_pos.insert(
                    u16::from_le_bytes([a.data[0], a.data[1]]),
                    a.adp().wrapping_neg(),
                );
            }
            let Some(pos) = pos else { continue };
            let lo = usize::from(a.ado());
            // Bytes `at..at + n` of a datagram's data, if the datagram covers them.
            let part = |d: &[u8], at: usize, n: usize| -> Option<Vec<u8>> {
                d.get(at.checked_sub(lo)?..at.checked_sub(lo)? + n)
                    .map(<[u8]>::to_vec)
            };
            let le32 = |v: Vec<u8>| u32::from_le_bytes([v[0], v[1], v[2], v[3]]);
            if matches!(a.cmd, 2 | 5) {
                if let Some(c) = part(&a.data, CTL + 1, 1) {
                    match c[0] & 0x07 {
                        0 => {}
                        c => {
                            reading.insert(pos, c == 1);
                        }
                    }
                }
                if let Some(v) = part(&a.data, ADDR, 4) {
                    addr.insert(pos, le32(v));
                }
                continue;
            }
            if !matches!(a.cmd, 1 | 4) || reading.get(&pos) != Some(&true) {
                continue;
            }
            // Where the data read starts (a word boundary inside the data register).
            let from = lo.max(DATA);
            if from >= DATA + 8 || !(from - DATA).is_multiple_of(2) || lo + b.data.len() <= from {
                continue;
            }
            // Bytes a read gives: as the control word in this read shows, else the register.
            let n = match part(&b.data, CTL, 2) {
                Some(c) => {
                    let c = u16::from_le_bytes([c[0], c[1]]);
                    if c & (BUSY | ACK_ERROR | WE_ERROR) != 0 {
                        continue;
                    }
                    if c & READ_8 != 0 {
                        8
                    } else {
                        4
                    }
                }
                None => 8,
            };
            // The word address: as this read shows it, else as last written.
            let Some(w) = part(&b.data, ADDR, 4)
                .map(le32)
                .or_else(|| addr.get(&pos).copied())
            else {
                continue;
            };
            let m = words.entry(pos).or_default();
            let mut at = from;
            while at + 2 <= DATA + n {
                let Some(c) = part(&b.data, at, 2) else { break };
                m.insert(w.wrapping_add(((at - DATA) / 2) as u32), [c[0], c[1]]);
                at += 2;
            }
        }
    }
    words
}

/// ETG.1000 CRC-8 (polynomial 0x07, initial 0xFF) of the SII configuration area.
pub fn sii_crc(data: &[u8]) -> u8 {
    let mut crc: u8 = 0xFF;
    for &b in data {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x07
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// An SII image from reconstructed words, with the configuration area (words 0..6, never
/// read by these masters) taken from `config` (14 bytes: PDI control as 0x0140..0x0141
/// shows it, then the rest of a sibling device's area) and its CRC in word 7.
pub fn sii_image(words: &BTreeMap<u32, [u8; 2]>, config: &[u8; 14], size: usize) -> Vec<u8> {
    let mut img = vec![0xFFu8; size];
    for (&a, w) in words {
        let i = a as usize * 2;
        if i + 2 <= img.len() {
            img[i..i + 2].copy_from_slice(w);
        }
    }
    img[0..14].copy_from_slice(config);
    img[14] = sii_crc(&img[0..14]);
    img[15] = 0;
    img
}

// ------------------------------------------------------------------ segment

/// A slave of the emulated line.
pub struct SlaveSpec {
    /// What the datagrams and reports call it.
    pub name: &'static str,
    /// Chip constants (from the capture where it shows them).
    pub config: EscConfig,
    /// SII EEPROM image.
    pub eeprom: Vec<u8>,
    /// The port that leads to the next slave (None: last slave, or the line ends here).
    pub out_port: u8,
    /// Firmware echo: a µC that acknowledges AL control in AL status (see [`firmware_echo`]).
    pub firmware_echo: bool,
}

/// The state a capture finds the segment in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StartState {
    /// Power-on reset values: the segment was power-cycled before the capture.
    #[default]
    PowerOn,
    /// Not power-cycled: a previous master's run left registers set. An ESC resets its
    /// registers only at power-on or reset (ESC datasheet section I, 17.4 "ESC Reset"; a
    /// master's new run does not reset them), so the next run starts from them.
    LeftByMaster(LeftByMaster),
}

/// What a previous master left in every ESC of a segment that was not power-cycled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LeftByMaster {
    /// ECAT event mask 0x0200 (which ECAT event requests reach the datagrams' IRQ field).
    pub event_mask: u16,
    /// DL control 0x0100..0x0103, when the previous master changed it from its reset value.
    pub dl_control: Option<u32>,
    /// The previous master read DL status 0x0110 after the last DL status change, which
    /// acknowledges the DL-status-change event (0x0210 bit 2) power-on raised; false when a
    /// link changed since (the event is pending again).
    pub dl_event_read: bool,
}

/// A line of ESCs: slave i's `out_port` is wired to slave i+1's port 0.
pub struct Bench {
    /// The ESCs in ring order.
    pub escs: Vec<Esc>,
    specs: Vec<(u8, bool)>,
    /// Propagation + forwarding delay per hop in ns.
    pub hop_ns: u64,
    /// Virtual time of the last frame.
    pub now: u64,
    /// Virtual time before which the µC firmware does not touch its ESC (a slow
    /// application start or poll loop; see the capture that sets it).
    pub firmware_from: u64,
}

impl Bench {
    /// Builds the line and raises the links of wired ports.
    pub fn new(slaves: Vec<SlaveSpec>) -> Self {
        let n = slaves.len();
        let mut escs = Vec::new();
        let mut specs = Vec::new();
        for (i, s) in slaves.into_iter().enumerate() {
            let mut e = Esc::new(s.config, s.eeprom);
            e.set_link(0, true);
            if i + 1 < n {
                e.set_link(s.out_port, true);
            }
            specs.push((s.out_port, s.firmware_echo));
            escs.push(e);
        }
        Self {
            escs,
            specs,
            hop_ns: 600,
            now: 0,
            firmware_from: 0,
        }
    }

    /// Walks one Ethernet frame through the line at virtual time `t`; returns the frame
    /// as it comes back out of slave 0's port 0 (source MAC bit 0x02 set), or None if it
    /// was destroyed or lost on an open unwired port.
    pub fn exchange(&mut self, eth: &[u8], t: u64) -> Option<Vec<u8>> {
        let t = t.max(self.now);
        self.now = t;
        for e in &mut self.escs {
            let _ = e.advance(t);
        }
        let off = EthernetHeader::parse(eth).ok()?.payload_offset;
        let mut buf = eth.to_vec();
        let n = self.escs.len();
        let (mut i, mut port, mut now) = (0usize, 0u8, t);
        for _ in 0..(8 * n + 8) {
            let fwd = self.escs[i].forward(port, &mut buf[off..], now, true);
            now += self.hop_ns;
            match fwd {
                Forward::Dropped => return None,
                Forward::Port(p) => {
                    let out = self.specs[i].0;
                    if p == 0 {
                        if i == 0 {
                            buf[6] |= 0x02;
                            self.firmware_step(now);
                            return Some(buf);
                        }
                        i -= 1;
                        port = self.specs[i].0;
                    } else if p == out && i + 1 < n {
                        i += 1;
                        port = 0;
                    } else {
                        return None;
                    }
                }
            }
        }
        None
    }

    /// Sends configuration datagrams (cmd, adp, ado, data), one frame each, through the line
    /// at t = 0, before the capture's first frame (not compared); each must be acknowledged.
    pub fn preroll(&mut self, dgs: &[(u8, u16, u16, &[u8])]) {
        for (i, &(cmd, adp, ado, data)) in dgs.iter().enumerate() {
            let f = master_frame(i as u8, cmd, adp, ado, data);
            let back = self.exchange(&f, 0).expect("pre-roll frame returned");
            let d = datagrams(&back).expect("pre-roll reply");
            assert!(d[0].wkc > 0, "pre-roll datagram {i} not acknowledged");
        }
    }

    /// Brings every ESC of the line to `start` (see [`StartState`]) before the capture's
    /// first frame.
    pub fn start_from(&mut self, start: StartState) {
        let StartState::LeftByMaster(m) = start else {
            return;
        };
        let mask = m.event_mask.to_le_bytes();
        self.preroll(&[(8, 0, 0x0200, &mask)]);
        if let Some(dl) = m.dl_control {
            self.preroll(&[(8, 0, 0x0100, &dl.to_le_bytes())]);
        }
        if m.dl_event_read {
            self.preroll(&[(7, 0, 0x0110, &[0, 0])]);
        }
    }

    /// Runs the firmware echo of every µC slave (after each frame).
    fn firmware_step(&mut self, t: u64) {
        if t < self.firmware_from {
            return;
        }
        for (e, &(_, echo)) in self.escs.iter_mut().zip(&self.specs) {
            if echo {
                let _ = e.advance(t);
                firmware_echo(e);
                firmware_drain_mailbox(e);
            }
        }
    }
}

/// Minimal PDI-side firmware of a µC slave: when the AL control event (0x0220 bit 0) is
/// pending, read AL control (which clears the event, as on silicon) and acknowledge the
/// requested state in AL status (no error, status code 0). Real firmware also starts
/// mailboxes and process data; what it does beyond the state echo is masked per capture.
pub fn firmware_echo(e: &mut Esc) {
    if e.al_event_request() & 1 == 0 {
        return;
    }
    let mut ctl = [0u8; 2];
    if e.pdi_read(0x0120, &mut ctl).is_err() {
        return;
    }
    let state = ctl[0] & 0x0F;
    let _ = e.pdi_write(0x0130, &[state, 0]);
    let _ = e.pdi_write(0x0134, &[0, 0]);
}

/// The firmware's mailbox receive: when SM0 (master→slave mailbox) is full, read the
/// whole buffer through the PDI, which empties it as on silicon (the request itself is
/// not served: responses are masked per capture).
pub fn firmware_drain_mailbox(e: &mut Esc) {
    let mut sm = [0u8; 8];
    if e.pdi_read(0x0800, &mut sm).is_err() || sm[5] & 0x08 == 0 {
        return;
    }
    let start = u16::from_le_bytes([sm[0], sm[1]]);
    let len = usize::from(u16::from_le_bytes([sm[2], sm[3]]));
    let mut buf = vec![0u8; len];
    let _ = e.pdi_read(start, &mut buf);
}

// ------------------------------------------------------------------ masks and comparison

/// When a mask applies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum When {
    /// Always.
    Always,
    /// Only when the recorded byte at `addr` has any of `bits` set.
    RecordedBits(u16, u8),
}

/// Bits of a register range that the comparison ignores, and why.
#[derive(Debug, Clone, Copy)]
pub struct Mask {
    /// First physical address.
    pub start: u16,
    /// Last physical address (inclusive).
    pub end: u16,
    /// Bits of each byte that are ignored.
    pub bits: u8,
    /// Condition.
    pub when: When,
    /// Why these bits depend on time, the cable or firmware rather than on the ESC.
    pub reason: &'static str,
}

/// DC times: receive times, system time, ECAT receive time, system time difference,
/// speed counter difference, next SYNC0/SYNC1 times, latch times (all of them values of a
/// free-running real oscillator at the moment a real frame passed).
pub const DC_TIME_MASKS: &[Mask] = &[
    Mask {
        start: 0x0900,
        end: 0x091F,
        bits: 0xFF,
        when: When::Always,
        reason: "DC port receive times / system time / ECAT receive time (real oscillator)",
    },
    Mask {
        start: 0x092C,
        end: 0x092F,
        bits: 0xFF,
        when: When::Always,
        reason: "DC system time difference (real oscillator)",
    },
    Mask {
        start: 0x0932,
        end: 0x0933,
        bits: 0xFF,
        when: When::Always,
        reason: "DC speed counter difference (real drift)",
    },
    Mask {
        start: 0x0990,
        end: 0x099F,
        bits: 0xFF,
        when: When::Always,
        reason: "DC next SYNC0/SYNC1 time (depends on the real clock)",
    },
    Mask {
        start: 0x09B0,
        end: 0x09CF,
        bits: 0xFF,
        when: When::Always,
        reason: "DC latch times (real clock)",
    },
];

/// Error counters of a real cable: RX errors, forwarded RX errors, ECAT processing unit
/// errors, PDI errors, lost link counters (0x0300–0x0313).
pub const CABLE_MASKS: &[Mask] = &[Mask {
    start: 0x0300,
    end: 0x0313,
    bits: 0xFF,
    when: When::Always,
    reason: "error counters of the real cable and PHYs",
}];

/// The real EEPROM (I²C) needs longer than the gap between two polls, so the master saw
/// 0x0502 busy (bit 15) with the read command (bits 8–10) still set; the emulated EEPROM
/// answers at once. Ignored only where the recorded reply shows busy.
pub const EEPROM_TIMING_MASKS: &[Mask] = &[Mask {
    start: 0x0503,
    end: 0x0503,
    bits: 0x87,
    when: When::RecordedBits(0x0503, 0x80),
    reason: "SII EEPROM busy: real I2C EEPROM timing",
}];

/// Per-capture result counters.
#[derive(Debug, Default, Clone)]
pub struct Stats {
    /// Datagrams compared.
    pub total: usize,
    /// Identical bytes.
    pub exact: usize,
    /// Identical after masks.
    pub masked: usize,
    /// Different after masks.
    pub mismatched: usize,
    /// Master frames without a recorded reply (not compared).
    pub unanswered: usize,
    /// Master frames the emulation did not return although the real segment did.
    pub lost: usize,
    /// Masked-match counts by reason.
    pub by_reason: BTreeMap<&'static str, usize>,
    /// Descriptions of the first mismatches.
    pub details: Vec<String>,
    /// Mismatch classes (command, register, what differs) with count and first frame.
    pub classes: BTreeMap<String, (usize, usize)>,
}

impl Stats {
    /// One line of the summary table.
    pub fn row(&self, name: &str) -> String {
        format!(
            "{name:<40} {:>6} {:>6} {:>6} {:>6}   (unanswered {}, lost {})",
            self.total, self.exact, self.masked, self.mismatched, self.unanswered, self.lost
        )
    }
}

/// A replay of one capture.
pub struct Replay<'a> {
    /// Capture file name in `reference/captures/`.
    pub name: &'a str,
    /// Masks that apply to physical reads.
    pub masks: Vec<Mask>,
    /// Ignore the data of logical datagrams at these logical byte ranges (start, end incl.).
    pub logical_masks: Vec<(u32, u32, &'static str)>,
    /// Frames (1-based numbers) whose data comparison is skipped entirely, with a reason.
    pub frame_masks: Vec<(usize, &'static str)>,
    /// Physical datagrams starting in [start, end] whose data and working counter are
    /// ignored (mailbox handshakes of firmware that is not emulated), with a reason.
    pub wkc_masks: Vec<(u16, u16, &'static str)>,
}

fn mask_reason(
    masks: &[Mask],
    rec: &Dg,
    phys: u16,
    byte_in_dg: usize,
    diff: u8,
) -> Option<&'static str> {
    let mut left = diff;
    let mut reason = None;
    for m in masks {
        if phys < m.start || phys > m.end {
            continue;
        }
        let ok = match m.when {
            When::Always => true,
            When::RecordedBits(a, bits) => {
                let o = a.wrapping_sub(rec.ado()) as usize;
                !rec.logical() && o < rec.data.len() && rec.data[o] & bits != 0
            }
        };
        if ok && left & m.bits != 0 {
            left &= !m.bits;
            reason = Some(m.reason);
        }
    }
    let _ = byte_in_dg;
    if left == 0 {
        reason
    } else {
        None
    }
}

impl Replay<'_> {
    /// Feeds every master frame into `bench` at its capture time (relative to the first
    /// frame, starting at 1 ms) and compares replies.
    pub fn run(&self, bench: &mut Bench, ex: &[Exchange]) -> Stats {
        let mut st = Stats::default();
        let t0 = ex.first().map_or(0, |e| e.sent.ts);
        for e in ex {
            let t = e.sent.ts.saturating_sub(t0) + 1_000_000;
            let got = bench.exchange(&e.sent.data, t);
            let Some(rec) = &e.reply else {
                st.unanswered += 1;
                continue;
            };
            let rec_d = datagrams(&rec.data).unwrap_or_default();
            let Some(got) = got else {
                st.lost += 1;
                st.total += rec_d.len();
                st.mismatched += rec_d.len();
                st.details.push(format!(
                    "frame {}: emulated segment returned nothing",
                    rec.number
                ));
                continue;
            };
            let got_d = datagrams(&got).unwrap_or_default();
            let frame_mask = self.frame_masks.iter().find(|(n, _)| *n == rec.number);
            for (k, r) in rec_d.iter().enumerate() {
                st.total += 1;
                let Some(g) = got_d.get(k) else {
                    st.mismatched += 1;
                    st.details.push(format!(
                        "frame {} dg {k}: missing in emulated reply",
                        rec.number
                    ));
                    continue;
                };
                if g == r {
                    st.exact += 1;
                    continue;
                }
                let mut problems = Vec::new();
                let mut reasons = Vec::new();
                if (g.cmd, g.idx, g.addr, g.len_flags) != (r.cmd, r.idx, r.addr, r.len_flags) {
                    problems.push(format!(
                        "header: expected cmd {} idx {:#x} addr {:#010x} lenflags {:#06x}, got cmd {} idx {:#x} addr {:#010x} lenflags {:#06x}",
                        r.cmd, r.idx, r.addr, r.len_flags, g.cmd, g.idx, g.addr, g.len_flags
                    ));
                }
                if g.irq != r.irq {
                    problems.push(format!("irq: expected {:#06x}, got {:#06x}", r.irq, g.irq));
                }
                let wkc_mask = if r.logical() || r.cmd == 0 {
                    None
                } else {
                    self.wkc_masks
                        .iter()
                        .find(|(s, e, _)| r.ado() >= *s && r.ado() <= *e)
                };
                if let Some((_, _, why)) = wkc_mask {
                    if g.wkc != r.wkc || g.data != r.data {
                        reasons.push(*why);
                    }
                } else if g.wkc != r.wkc {
                    problems.push(format!("wkc: expected {}, got {}", r.wkc, g.wkc));
                }
                if g.data.len() != r.data.len() {
                    problems.push("data length differs".into());
                } else if wkc_mask.is_some() {
                } else if let Some((_, why)) = frame_mask {
                    if g.data != r.data {
                        reasons.push(*why);
                    }
                } else {
                    let mut bad = Vec::new();
                    for (i, (&gb, &rb)) in g.data.iter().zip(&r.data).enumerate() {
                        if gb == rb {
                            continue;
                        }
                        let why = if r.logical() {
                            let la = r.addr.wrapping_add(i as u32);
                            self.logical_masks
                                .iter()
                                .find(|(s, e, _)| la >= *s && la <= *e)
                                .map(|m| m.2)
                        } else {
                            let phys = r.ado().wrapping_add(i as u16);
                            mask_reason(&self.masks, r, phys, i, gb ^ rb)
                        };
                        match why {
                            Some(w) => reasons.push(w),
                            None => bad.push(i),
                        }
                    }
                    if !bad.is_empty() {
                        let base = if r.logical() {
                            r.addr
                        } else {
                            u32::from(r.ado())
                        };
                        problems.push(format!(
                            "data at {}: expected {} got {}",
                            bad.iter()
                                .map(|i| format!("{:#06x}", base + *i as u32))
                                .collect::<Vec<_>>()
                                .join(","),
                            hex(&r.data),
                            hex(&g.data)
                        ));
                    }
                }
                if problems.is_empty() {
                    st.masked += 1;
                    reasons.sort();
                    reasons.dedup();
                    for w in reasons {
                        *st.by_reason.entry(w).or_default() += 1;
                    }
                } else {
                    st.mismatched += 1;
                    let what: Vec<&str> = problems
                        .iter()
                        .map(|p| p.split(':').next().unwrap_or(""))
                        .collect();
                    let reg = if r.logical() {
                        "logical".to_string()
                    } else {
                        format!("{:#06x}", r.ado())
                    };
                    let key = format!("{} {} [{}]", r.name(), reg, what.join(","));
                    st.classes.entry(key).or_insert((0, e.sent.number)).0 += 1;
                    if st.details.len() < 40 {
                        st.details.push(format!(
                            "frame {} (reply {}) dg {k} {}: {}",
                            e.sent.number,
                            rec.number,
                            r.describe(),
                            problems.join("; ")
                        ));
                    }
                }
            }
        }
        st
    }
}

/// Hex string of a byte slice.
pub fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// Prints the per-capture report.
pub fn report(name: &str, st: &Stats) {
    eprintln!(
        "{:<40} {:>6} {:>6} {:>6} {:>6}",
        "capture", "dgrams", "exact", "masked", "mism."
    );
    eprintln!("{}", st.row(name));
    for (r, n) in &st.by_reason {
        eprintln!("    masked {n:>5}: {r}");
    }
    for (k, (n, first)) in &st.classes {
        eprintln!("    CLASS {n:>5} x {k} (first frame {first})");
    }
    for d in &st.details {
        eprintln!("    MISMATCH {d}");
    }
}
