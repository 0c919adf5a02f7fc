//! Configured-address dispatch: a frame's datagram headers walked once per frame instead
//! of once per ESC, so that a configured-address datagram (FPRD, FPWR, FPRW) is processed
//! only by the ESC(s) it addresses.
//!
//! Why: a master's per-slave state checks (ethercrab adds one FPRD of AL status per slave
//! to every cycle) make N datagrams per cycle that each of the N ESCs of a line walks —
//! O(N²) datagram visits. What a foreign FPRD/FPWR/FPRW does at an ESC is nothing but the
//! IRQ field: the ESC ORs its event-masked ECAT event request (0x0210 & 0x0200) into it.
//! That value changes only when the ESC processes a datagram itself, so between two
//! datagrams it processes it is constant over the foreign datagrams it passes: the ESC
//! records "OR `irq` into datagrams `from..to`" here (O(1) per range, per-bit difference
//! counts) and [`FrameDispatch::apply_irq`] ORs it into the frame when its walk is over.
//! The IRQ field is read by no ESC, so ORing it later gives the same bytes.
//!
//! Every other datagram — broadcast, auto-increment, logical, NOP, FRMW (which every ESC
//! but the addressed one writes) and reserved codes — still passes every ESC in frame
//! order, merged with the ESC's own configured-address datagrams (station address, and the
//! alias when 0x0103 enables it; two ESCs with the same address both find theirs). An ESC
//! whose station address, alias or alias enable changes during its walk (a datagram of the
//! frame wrote it) walks the rest of the frame datagram by datagram, as before.
//!
//! The seam: the segment owns the frame's walk through the topology (which ESC sees it
//! when, through which port), so it builds one `FrameDispatch` per frame and hands it to
//! [`crate::Esc::forward_dispatched`] at each ESC; which datagrams an ESC must see is
//! EtherCAT addressing, so it lives here beside the ESC.

use alloc::vec::Vec;

use oxicat_wire::{view, Command, WireError};

const CMD_FPRD: u8 = Command::Fprd as u8;
const CMD_FPRW: u8 = Command::Fprw as u8;
const ECAT_HEADER_LEN: usize = oxicat_wire::frame::ECAT_HEADER_LEN;

/// Where a datagram lies in the frame (from the EtherCAT header): its first byte and its
/// whole length (header, data, working counter).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Slice {
    pub(crate) at: u32,
    pub(crate) len: u32,
}

/// One frame's datagram index for configured-address dispatch (see the module doc).
/// Reusable: [`FrameDispatch::build`] clears what the previous frame left.
#[derive(Debug, Default, Clone)]
pub struct FrameDispatch {
    /// The frame has a configured-address datagram (the index is in use).
    active: bool,
    /// Every datagram the ESC's walker visits, in frame order.
    pub(crate) dgs: Vec<Slice>,
    /// Indices of the datagrams every ESC processes.
    pub(crate) every: Vec<u16>,
    /// (station address, index) of the FPRD/FPWR/FPRW datagrams, sorted.
    pub(crate) fp: Vec<(u16, u16)>,
    /// Lowest and highest station address in `fp` (`fp_lo > fp_hi` when empty) and a
    /// 256-bit set of their low bytes: [`FrameDispatch::may_address`] in O(1).
    fp_lo: u16,
    fp_hi: u16,
    fp_bits: [u64; 4],
    /// Per-bit difference counts of the deferred IRQ ranges (`dgs.len() + 1` rows).
    irq_diff: Vec<[i32; 16]>,
    /// Some range was recorded since the last build.
    irq_any: bool,
}

impl FrameDispatch {
    /// An empty index.
    pub fn new() -> Self {
        Self::default()
    }

    /// Indexes `frame` (from its EtherCAT header) with the ESC's own walker (which stops at
    /// the first malformed datagram); returns whether it has a configured-address datagram
    /// — only then is dispatch worth anything, and only then is it used.
    pub fn build(&mut self, frame: &mut [u8]) -> bool {
        self.dgs.clear();
        self.every.clear();
        self.fp.clear();
        if self.irq_any {
            self.irq_diff.iter_mut().for_each(|r| *r = [0; 16]);
            self.irq_any = false;
        }
        let mut at = ECAT_HEADER_LEN;
        let (dgs, every, fp) = (&mut self.dgs, &mut self.every, &mut self.fp);
        let _ = view::walk_datagrams::<WireError>(frame, |dg| {
            let i = dgs.len();
            let len = dg.total_len();
            // An 11-bit frame length holds at most 2,047 / 12 datagrams.
            let i16 = i as u16;
            dgs.push(Slice {
                at: at as u32,
                len: len as u32,
            });
            let cmd = dg.command_raw();
            if (CMD_FPRD..=CMD_FPRW).contains(&cmd) {
                fp.push((dg.adp(), i16));
            } else {
                every.push(i16);
            }
            at += len;
            Ok(())
        });
        self.fp.sort_unstable();
        self.fp_bits = [0; 4];
        for &(a, _) in &self.fp {
            self.fp_bits[usize::from(a >> 6 & 3)] |= 1 << (a & 63);
        }
        self.fp_lo = self.fp.first().map_or(1, |f| f.0);
        self.fp_hi = self.fp.last().map_or(0, |f| f.0);
        if self.irq_diff.len() < self.dgs.len() + 1 {
            self.irq_diff.resize(self.dgs.len() + 1, [0; 16]);
        }
        self.active = !self.fp.is_empty();
        self.active
    }

    /// Whether the last [`build`](Self::build) found a configured-address datagram.
    pub fn is_active(&self) -> bool {
        self.active
    }

    /// Datagrams indexed.
    pub fn len(&self) -> usize {
        self.dgs.len()
    }

    /// True when the frame had no datagram.
    pub fn is_empty(&self) -> bool {
        self.dgs.is_empty()
    }

    /// False when no FPRD/FPWR/FPRW of the frame is addressed to `adp` (true: maybe).
    #[inline(always)]
    pub(crate) fn may_address(&self, adp: u16) -> bool {
        adp >= self.fp_lo
            && adp <= self.fp_hi
            && self.fp_bits[usize::from(adp >> 6 & 3)] & (1 << (adp & 63)) != 0
    }

    /// The run of `fp` addressed to `adp`: `(start, end)` indices.
    #[inline]
    pub(crate) fn fp_run(&self, adp: u16) -> (usize, usize) {
        let s = self.fp.partition_point(|&(a, _)| a < adp);
        let e = s + self.fp[s..].partition_point(|&(a, _)| a == adp);
        (s, e)
    }

    /// Records "OR `irq` into the IRQ fields of datagrams `from..to`".
    #[inline]
    pub(crate) fn or_irq_range(&mut self, from: usize, to: usize, irq: u16) {
        let mut bits = irq;
        while bits != 0 {
            let b = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            self.irq_diff[from][b] += 1;
            self.irq_diff[to][b] -= 1;
        }
        self.irq_any = true;
    }

    /// ORs the deferred IRQ ranges into `frame` (the frame [`build`](Self::build) indexed,
    /// after its walk through the segment).
    pub fn apply_irq(&mut self, frame: &mut [u8]) {
        if !self.irq_any {
            return;
        }
        let mut count = [0i32; 16];
        for (i, s) in self.dgs.iter().enumerate() {
            let mut irq = 0u16;
            for (b, c) in count.iter_mut().enumerate() {
                *c += self.irq_diff[i][b];
                if *c > 0 {
                    irq |= 1 << b;
                }
            }
            if irq != 0 {
                let (a, l) = (s.at as usize, s.len as usize);
                if let Some(d) = frame.get_mut(a..a + l) {
                    view::Datagram::new_unchecked(d).or_irq(irq);
                }
            }
        }
        self.irq_diff.iter_mut().for_each(|r| *r = [0; 16]);
        self.irq_any = false;
    }
}
