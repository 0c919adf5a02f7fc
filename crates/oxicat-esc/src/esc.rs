//! The ESC core: register file + process RAM, datagram execution with working-counter
//! rules, SyncManager and FMMU redirection, AL/DL state, events, watchdogs, SII and the
//! PDI side.
//!
//! Silicon behaviour modelled (Beckhoff ESC datasheet section I/II, ET1100 class):
//! - reads of unimplemented registers / memory return 0, writes to them and to read-only
//!   registers are ignored; the working counter is still incremented (the slave was
//!   addressed and the access executed). The only accesses that do not count are those a
//!   SyncManager refuses (read of an empty mailbox, write to a full mailbox, access to a
//!   buffer that does not begin at its start address, access in the wrong direction).
//! - ECAT writes to registers (< 0x1000) take effect only if the frame ends with a good
//!   FCS (`frame_ok`); SyncManager buffer writes are committed (mailbox full / buffer
//!   exchange) only at the end of a good frame; reads take effect immediately.
//! - BRD/BRW OR the memory into the datagram data.

use alloc::vec;
use alloc::vec::Vec;
use core::mem::take;
use core::sync::atomic::{AtomicU32, AtomicU8, Ordering};

use oxicat_wire::{Command, DatagramMut};

use crate::config::{DcSupport, EscConfig};
use crate::dc::Dc;
use crate::fmmu::{get_bit, set_bit, Fmmu, Overlap};
use crate::regs::{self, PERMISSIONS, P_CLEAR, P_ECAT, P_IMPL, P_PDI};
use crate::sii;
use crate::sm::{Side, Sm, CTRL_WD_TRIGGER};

/// Where a frame leaves the ESC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Forward {
    /// Out of this port.
    Port(u8),
    /// Destroyed (circulating frame).
    Dropped,
}

/// How long a temporary loop control setting (0x0100 bit 1) lasts: "about 1 second"
/// (ETG.1000.4 table 33).
pub const TEMPORARY_LOOP_NS: u64 = 1_000_000_000;

/// Things that happened on the PDI side while time advanced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EscEvents {
    /// Global time of a SYNC0 rising edge.
    pub sync0: Option<u64>,
    /// Global time of a SYNC1 rising edge.
    pub sync1: Option<u64>,
    /// The process-data watchdog expired (digital outputs were cleared).
    pub pd_watchdog_expired: bool,
    /// The PDI watchdog expired.
    pub pdi_watchdog_expired: bool,
}

/// Why a PDI access failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PdiError {
    /// The address range lies (partly) outside the implemented memory.
    OutOfRange,
}

impl core::fmt::Display for PdiError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PdiError::OutOfRange => write!(f, "PDI access outside implemented memory"),
        }
    }
}

impl core::error::Error for PdiError {}

/// AL event request bit 0: AL control written.
const AL_EV_CONTROL: u32 = 1 << 0;
/// AL event request bit 4: SM activation register changed.
const AL_EV_SM_CHANGE: u32 = 1 << 4;
/// AL event request bit 6: process-data watchdog expired.
const AL_EV_WD: u32 = 1 << 6;
/// ECAT event request bit 2: DL status changed.
const ECAT_EV_DL: u16 = 1 << 2;
/// ECAT event request bit 3: AL status changed.
const ECAT_EV_AL: u16 = 1 << 3;

const REG_END: usize = 0x1000;
/// EtherCAT frame header length and the type code of a frame carrying datagrams.
const ECAT_HEADER_LEN: usize = 2;
const ECAT_TYPE_DATAGRAMS: u16 = 1;
/// Datagram header length (before the data).
const DG_HEADER_LEN: usize = 10;
/// Command codes of the logical datagrams.
const CMD_LRD: u8 = Command::Lrd as u8;
const CMD_LWR: u8 = Command::Lwr as u8;
const CMD_LRW: u8 = Command::Lrw as u8;
/// PDI control 0x0140 value of the digital I/O PDI.
const PDI_DIGITAL_IO: u8 = 0x04;

/// One step of the logical fast path: a whole SyncManager buffer mapped byte-aligned by
/// an FMMU, pre-resolved when FMMUs or SMs change.
#[derive(Debug, Clone, Copy, Default)]
struct PlanOp {
    /// Offset of the FMMU's logical range from the plan window's start.
    off: u32,
    /// Length in bytes (= the SM length).
    len: u32,
    /// SM index.
    sm: u8,
}

/// Most FMMUs a fast-path plan holds (more take the general route).
const PLAN_MAX: usize = 4;

/// One step of the fused path: a whole buffered-mode SM buffer, byte-aligned.
#[derive(Debug, Clone, Copy, Default)]
struct FusedStep {
    /// Offset of the step's bytes from the plan window's start in the datagram data.
    off: u16,
    /// The SM's start address relative to `REG_END` and length (one buffer).
    ram: u16,
    len: u16,
    /// SM index.
    sm: u8,
    /// ECAT writes the SM (a write step; otherwise a read step).
    write: bool,
    /// The SM triggers the process-data watchdog (write steps).
    wd: bool,
}

/// The fused path (`Esc::forward_fused`): a frame entering port 0 with a good FCS that
/// holds a single logical datagram covering the plan window, at an ESC whose plan steps
/// are all distinct buffered-mode (3-buffer) SMs in process RAM and which has an open
/// port (the frame does not loop back into the processing unit). Rebuilt with the plan and on port changes.
#[derive(Debug, Clone, Copy, Default)]
struct Fused {
    /// The fused path applies to this ESC's configuration.
    ok: bool,
    /// Port the frame leaves through (first open port after port 0).
    exit: u8,
    /// The steps LRD, LWR and LRW run: `steps[range[c].0..range[c].1]` (reads come
    /// first, then writes).
    range: [(u8, u8); 3],
    /// Plan window `[lo, hi)` (logical bytes).
    lo: u64,
    hi: u64,
    /// Working-counter increment for LRD, LWR, LRW.
    inc: [u16; 3],
    steps: [FusedStep; PLAN_MAX],
}

/// Copies `s` into `d` (equal lengths): process-data images are small, and a call into
/// `memcpy` costs more than the copy. 16..=64 bytes take two or four overlapping 16-byte
/// moves (no loop), 4..16 bytes two overlapping 4- or 8-byte moves; longer images go in
/// 16-byte chunks.
#[inline(always)]
pub(crate) fn copy_small(d: &mut [u8], s: &[u8]) {
    let n = d.len();
    let s = &s[..n];
    if (16..=32).contains(&n) {
        d[..16].copy_from_slice(&s[..16]);
        d[n - 16..].copy_from_slice(&s[n - 16..]);
    } else if (33..=64).contains(&n) {
        d[..32].copy_from_slice(&s[..32]);
        d[n - 32..].copy_from_slice(&s[n - 32..]);
    } else if (8..16).contains(&n) {
        d[..8].copy_from_slice(&s[..8]);
        d[n - 8..].copy_from_slice(&s[n - 8..]);
    } else if (4..8).contains(&n) {
        d[..4].copy_from_slice(&s[..4]);
        d[n - 4..].copy_from_slice(&s[n - 4..]);
    } else {
        let mut dc = d.chunks_exact_mut(16);
        let mut sc = s.chunks_exact(16);
        for (x, y) in (&mut dc).zip(&mut sc) {
            x.copy_from_slice(y);
        }
        for (x, y) in dc.into_remainder().iter_mut().zip(sc.remainder()) {
            *x = *y;
        }
    }
}

/// Memo of the `&self` queries the segment makes after every time step: the event
/// requests ([`Esc::compute_events`], for `irq_line`, `al_event_request`,
/// `ecat_event_request`) and [`Esc::next_event`]. Between two state changes their answers
/// cannot change. Cleared on entry to every `&mut self` entry point (only `advance` keeps
/// it when neither the DC unit nor a watchdog changed anything). Atomics rather than
/// `Cell` so that `Esc` stays `Sync`; 32-bit ones, because Cortex-M (thumbv7em) has no
/// 64-bit atomics. Each value is published by a release store of its valid flag after its
/// parts; concurrent `&self` writers can only store the same answer.
#[derive(Debug, Default)]
struct QueryMemo {
    /// AL event request (meaningful when `ecat` has [`Self::VALID`]).
    al: AtomicU32,
    /// Bits 0..16 ECAT event request, bit 16 valid.
    ecat: AtomicU32,
    /// `next_event()`: 0 unknown, 1 `None`, 2 `Some(next)`.
    next_state: AtomicU8,
    next_lo: AtomicU32,
    next_hi: AtomicU32,
}

impl QueryMemo {
    const VALID: u32 = 1 << 16;

    #[inline(always)]
    fn events(&self) -> Option<(u16, u32)> {
        let v = self.ecat.load(Ordering::Acquire);
        (v & Self::VALID != 0).then(|| (v as u16, self.al.load(Ordering::Relaxed)))
    }

    #[inline(always)]
    fn set_events(&self, e: u16, a: u32) {
        self.al.store(a, Ordering::Relaxed);
        self.ecat.store(Self::VALID | e as u32, Ordering::Release);
    }

    #[inline(always)]
    fn next_event(&self) -> Option<Option<u64>> {
        match self.next_state.load(Ordering::Acquire) {
            0 => None,
            1 => Some(None),
            _ => {
                let lo = self.next_lo.load(Ordering::Relaxed) as u64;
                let hi = self.next_hi.load(Ordering::Relaxed) as u64;
                Some(Some(hi << 32 | lo))
            }
        }
    }

    #[inline(always)]
    fn set_next_event(&self, n: Option<u64>) {
        if let Some(n) = n {
            self.next_lo.store(n as u32, Ordering::Relaxed);
            self.next_hi.store((n >> 32) as u32, Ordering::Relaxed);
            self.next_state.store(2, Ordering::Release);
        } else {
            self.next_state.store(1, Ordering::Release);
        }
    }

    #[inline(always)]
    fn clear(&mut self) {
        *self.ecat.get_mut() = 0;
        *self.next_state.get_mut() = 0;
    }
}

impl Clone for QueryMemo {
    fn clone(&self) -> Self {
        // Valid flags first (acquire), then the parts they publish.
        let ecat = AtomicU32::new(self.ecat.load(Ordering::Acquire));
        let next_state = AtomicU8::new(self.next_state.load(Ordering::Acquire));
        let copy = |a: &AtomicU32| AtomicU32::new(a.load(Ordering::Relaxed));
        Self {
            al: copy(&self.al),
            ecat,
            next_state,
            next_lo: copy(&self.next_lo),
            next_hi: copy(&self.next_hi),
        }
    }
}

/// A software EtherCAT Slave Controller.
#[derive(Debug, Clone)]
pub struct Esc {
    /// See [`QueryMemo`].
    memo: QueryMemo,
    /// Hot state of the fused LRW path.
    fused: Fused,
    /// Test switch: never take the fused path (differential tests).
    fused_disabled: bool,
    /// Frames the fused path processed (tests).
    #[cfg(test)]
    pub(crate) fused_hits: u64,
    cfg: EscConfig,
    mem: Vec<u8>,
    /// Per-byte permissions of this chip's register file (the generic table with the
    /// FMMUs, SMs and DC parts the chip lacks removed).
    perm: Vec<u8>,
    /// AL control written by ECAT and not yet read by the PDI (no device emulation: the
    /// register then behaves like a mailbox and refuses further ECAT writes).
    al_ctl_unread: bool,
    eeprom: Vec<u8>,
    /// Words below this acknowledge writes ([`Esc::protect_eeprom_from`]).
    eeprom_writable_words: usize,
    dc: Dc,
    link: [bool; 4],
    /// SyncManagers; the chip has the first `cfg.sm_count` (the others stay disabled).
    sms: [Sm; 16],
    active_sms: Vec<u8>,
    fmmus: Vec<Fmmu>,
    fmmu_rw_overlap: bool,
    /// Every active FMMU is byte-aligned and maps a whole SM buffer (`Fmmu::sm`).
    fmmu_all_sm: bool,
    /// Logical fast path: usable (every FMMU a whole SM buffer, no read/write overlap,
    /// at most `PLAN_MAX`), the window `[plan_lo, plan_hi)` (bytes) covering all of them,
    /// and the steps (reads first, then writes, each in FMMU order).
    plan_ok: bool,
    plan_len: u8,
    plan_reads: u8,
    plan_lo: u64,
    plan_hi: u64,
    plan: [PlanOp; PLAN_MAX],
    /// Union of the active FMMUs' logical bit ranges: `[log_bit_lo, log_bit_hi)`.
    log_bit_lo: u64,
    log_bit_hi: u64,
    fmmu_any_read: bool,
    fmmu_any_write: bool,
    scratch: Vec<u8>,
    scratch_bits: Vec<u8>,
    scratch_mask: Vec<u8>,
    now: u64,
    frame_ok: bool,
    /// SMs (bit n) with a producer write completed by ECAT in the current frame.
    pending_sms: u16,
    events_dirty: bool,
    ecat_mask: u16,
    open_ports: u8,
    ecat_irq: u16,
    ecat_ev: u16,
    al_ev: u32,
    dout: u32,
    pd_wd_last: Option<u64>,
    pdi_wd_last: Option<u64>,
    latch_inputs: [bool; 2],
    /// Loop control (0x0101) as last written permanently (0x0100 bit 1 clear).
    loop_permanent: u8,
    /// When a temporary loop control setting (0x0100 bit 1) gives way to
    /// [`Esc::loop_permanent`] again.
    loop_revert_at: Option<u64>,
}

impl Esc {
    /// Power-on: register file reset values, EEPROM loaded (config area words 0..7 into PDI
    /// control, PDI config, SYNC pulse length, alias), CRC error flagged in 0x0502 if the
    /// CRC of words 0..6 (word 7) is wrong.
    pub fn new(config: EscConfig, eeprom: Vec<u8>) -> Self {
        let mut cfg = config;
        cfg.fmmu_count = cfg.fmmu_count.min(16);
        cfg.sm_count = cfg.sm_count.min(16);
        let mut mem = vec![0u8; cfg.memory_end()];
        mem[regs::TYPE as usize] = cfg.esc_type;
        mem[regs::REVISION as usize] = cfg.revision;
        mem[2..4].copy_from_slice(&cfg.build.to_le_bytes());
        mem[regs::FMMU_COUNT as usize] = cfg.fmmu_count;
        mem[regs::SM_COUNT as usize] = cfg.sm_count;
        mem[regs::RAM_SIZE as usize] = cfg.ram_kib;
        mem[regs::PORT_DESC as usize] = cfg.port_descriptor;
        mem[8..10].copy_from_slice(&cfg.features.to_le_bytes());
        mem[0x0100] = 0x01;
        mem[0x0102] = 0x07;
        mem[0x0120] = 0x01;
        mem[0x0130] = 0x01;
        mem[0x0204..0x0208].copy_from_slice(&0x00FF_FF0Fu32.to_le_bytes());
        mem[0x0400..0x0402].copy_from_slice(&2498u16.to_le_bytes());
        mem[0x0410..0x0412].copy_from_slice(&1000u16.to_le_bytes());
        mem[0x0420..0x0422].copy_from_slice(&1000u16.to_le_bytes());
        let mut ctl = 0u16;
        if cfg.sii_read_8_bytes {
            ctl |= sii::CTL_READ_8;
        }
        if eeprom.len() > 2048 {
            ctl |= sii::CTL_ADDR_2BYTES;
        }
        ctl |= u16::from(cfg.sii_control_extra & 0x1E);
        sii::write_ctl(&mut mem, ctl);
        sii::load_config(&mut mem, &eeprom);
        let perm = chip_permissions(&cfg);
        let mut sms: [Sm; 16] = core::array::from_fn(|_| Sm::default());
        for sm in sms.iter_mut() {
            sm.reset_state();
        }
        let mut dc = Dc::new(cfg.clock);
        dc.reset(&mut mem[..REG_END]);
        let mut esc = Self {
            memo: QueryMemo::default(),
            fused: Fused::default(),
            fused_disabled: false,
            #[cfg(test)]
            fused_hits: 0,
            cfg,
            mem,
            perm,
            al_ctl_unread: false,
            eeprom,
            eeprom_writable_words: usize::MAX,
            dc,
            link: [true, false, false, false],
            sms,
            active_sms: Vec::with_capacity(16),
            fmmus: Vec::with_capacity(16),
            fmmu_rw_overlap: false,
            fmmu_all_sm: false,
            plan_ok: false,
            plan_len: 0,
            plan_reads: 0,
            plan_lo: 0,
            plan_hi: 0,
            plan: [PlanOp::default(); PLAN_MAX],
            log_bit_lo: u64::MAX,
            log_bit_hi: 0,
            fmmu_any_read: false,
            fmmu_any_write: false,
            scratch: Vec::with_capacity(2048),
            scratch_bits: Vec::with_capacity(2050),
            scratch_mask: Vec::with_capacity(2050),
            now: 0,
            frame_ok: true,
            pending_sms: 0,
            events_dirty: true,
            ecat_mask: 0,
            open_ports: 0,
            ecat_irq: 0,
            ecat_ev: 0,
            al_ev: 0,
            dout: 0,
            pd_wd_last: None,
            pdi_wd_last: None,
            latch_inputs: [false; 2],
            loop_permanent: 0,
            loop_revert_at: None,
        };
        esc.update_dl_status(false);
        // Power-on is a DL status change (links come up, EEPROM loaded): the event is
        // pending until the master reads 0x0110 (soem-sdinfo-ek1100-el1004: the last
        // slave, whose links never change later, still shows IRQ 0x0004 until frame 200).
        esc.ecat_ev = ECAT_EV_DL;
        esc.refresh_events();
        esc
    }

    /// The configuration this ESC was built with.
    pub fn config(&self) -> &EscConfig {
        &self.cfg
    }

    /// The DC unit (for inspection by the simulator and tests).
    pub fn dc(&self) -> &Dc {
        &self.dc
    }

    /// Configured station address (0x0010).
    pub fn station_address(&self) -> u16 {
        self.reg16(regs::STATION_ADDR)
    }

    /// AL status register (0x0130).
    pub fn al_status(&self) -> u16 {
        self.reg16(regs::AL_STATUS)
    }

    /// AL control register (0x0120), without the read side effect.
    pub fn al_control(&self) -> u16 {
        self.reg16(regs::AL_CONTROL)
    }

    /// True when the port's loop is open (frames leave through it).
    #[inline]
    pub fn port_open(&self, port: u8) -> bool {
        self.open_ports & (1 << (port & 3)) != 0
    }

    fn compute_port_open(&self, port: u8) -> bool {
        if port > 3 || !self.cfg.port_present(port) {
            return false;
        }
        match (self.mem[regs::DL_LOOP_CONTROL as usize] >> (2 * port)) & 3 {
            2 => true,
            3 => false,
            _ => self.link[port as usize],
        }
    }

    /// Current levels of the latch inputs as set by [`Esc::set_latch_input`].
    pub fn latch_inputs(&self) -> [bool; 2] {
        self.latch_inputs
    }

    #[inline]
    fn reg16(&self, a: u16) -> u16 {
        let a = a as usize;
        u16::from_le_bytes([self.mem[a], self.mem[a + 1]])
    }

    // ------------------------------------------------------------------ ECAT side

    /// Physical link state of a port (set by the simulator's topology / fault hooks).
    /// Power-on default: port 0 up, the others down.
    pub fn set_link(&mut self, port: u8, up: bool) {
        self.memo.clear();
        if port > 3 {
            return;
        }
        let p = port as usize;
        let up = up && self.cfg.port_present(port);
        if self.link[p] && !up {
            let a = regs::LOST_LINK_COUNTER as usize + p;
            self.mem[a] = self.mem[a].saturating_add(1);
        }
        self.link[p] = up;
        self.update_dl_status(true);
    }

    /// A frame's first bit reaches `port` at time `t`; see the API contract. Returns the
    /// port the frame leaves through or `Dropped` (circulating frame rule).
    #[inline]
    pub fn forward(&mut self, port: u8, frame: &mut [u8], t: u64, frame_ok: bool) -> Forward {
        self.memo.clear();
        if port == 0 && frame_ok && self.fused.ok {
            self.now = t;
            self.dc.frame_arrival_port0(&mut self.mem[..REG_END], t);
            if let Some(out) = self.process_fused(frame, t) {
                return out;
            }
            return self.forward_after_arrival(0, frame, true);
        }
        self.forward_generic(port, frame, t, frame_ok)
    }

    /// The fused path (see `Fused`), after the frame's arrival: the checks first (no state
    /// touched when they fail and the generic path takes over), then the plan steps with
    /// the end-of-frame commit of each written SM, IRQ and working counter, exit port.
    /// Same effects as `process_frame` plus the exit-port search on such a frame.
    #[inline(always)]
    fn process_fused(&mut self, frame: &mut [u8], t: u64) -> Option<Forward> {
        // Frame header, command, index, address and length word in one load.
        let h = u64::from_le_bytes(*frame.first_chunk::<8>()?);
        let lf = u16::from_le_bytes(*frame.get(8..10)?.first_chunk::<2>()?);
        let w = h as u16;
        let cmd = (h >> 16) as u8;
        let len = (lf & 0x07FF) as usize;
        // Frame end (header length); the single datagram must fit in it.
        let end = ECAT_HEADER_LEN + (w & 0x07FF) as usize;
        let dg_end = ECAT_HEADER_LEN + DG_HEADER_LEN + len + 2;
        // One logical datagram (no more-follows) in a datagram frame.
        if w >> 12 != ECAT_TYPE_DATAGRAMS
            || cmd.wrapping_sub(CMD_LRD) > CMD_LRW - CMD_LRD
            || lf & 0x8000 != 0
            || dg_end > end
            || end > frame.len()
        {
            return None;
        }
        let ds = h >> 32;
        let (lo, hi) = (self.fused.lo, self.fused.hi);
        if ds > lo || hi > ds + len as u64 {
            return None;
        }
        if self.events_dirty && self.ecat_mask != 0 {
            self.refresh_events();
        }
        #[cfg(test)]
        {
            self.fused_hits += 1;
        }
        let irq = self.ecat_irq;
        // The plan window in the frame (inside the datagram data, checked above).
        let wstart = ECAT_HEADER_LEN + DG_HEADER_LEN + (lo - ds) as usize;
        let win = frame.get_mut(wstart..wstart + (hi - lo) as usize)?;
        // Registers (SM status, watchdog status) and process RAM (the SM buffers, which
        // the fused path requires to lie at or above `REG_END`).
        let (regs, ram) = self.mem.split_at_mut(REG_END);
        let regs: &mut [u8; REG_END] = regs.try_into().ok()?;
        // The steps this command runs (reads come first, then writes): one loop.
        let c = (cmd - CMD_LRD) as usize;
        let (from_step, to_step) = self.fused.range[c];
        for st in self.fused.steps.get(from_step as usize..to_step as usize)? {
            let i = st.sm as usize & 15;
            let sm = &mut self.sms[i];
            let l = st.len as usize;
            let o = st.off as usize;
            if st.write {
                let b = sm.buffered_write_commit();
                regs[regs::sm_reg(i, 5)] = sm.buffered_status_reg();
                let to = st.ram as usize + b as usize * l;
                copy_small(&mut ram[to..to + l], &win[o..o + l]);
                if st.wd {
                    self.pd_wd_last = Some(t);
                    regs[regs::WD_STATUS_PD as usize] |= 1;
                }
            } else {
                let b = sm.buffered_read_whole();
                regs[regs::sm_reg(i, 5)] = sm.buffered_status_reg();
                let from = st.ram as usize + b as usize * l;
                copy_small(&mut win[o..o + l], &ram[from..from + l]);
            }
        }
        let inc = self.fused.inc[(cmd - CMD_LRD) as usize];
        // Some step ran exactly when the working counter counts.
        self.events_dirty |= inc != 0;
        let hirq = u16::from_le_bytes([frame[10], frame[11]]);
        if irq & !hirq != 0 {
            frame[10..12].copy_from_slice(&(hirq | irq).to_le_bytes());
        }
        if inc != 0 {
            let wkc = &mut frame[dg_end - 2..dg_end];
            let w = u16::from_le_bytes([wkc[0], wkc[1]]).wrapping_add(inc);
            wkc.copy_from_slice(&w.to_le_bytes());
        }
        Some(Forward::Port(self.fused.exit))
    }

    /// `forward` for every frame (the fused path is a shortcut for one kind).
    fn forward_generic(&mut self, port: u8, frame: &mut [u8], t: u64, frame_ok: bool) -> Forward {
        let port = port & 3;
        self.now = t;
        self.dc.frame_arrival(&mut self.mem[..REG_END], port, t);
        self.forward_after_arrival(port, frame, frame_ok)
    }

    /// `forward` after the DC unit saw the frame's arrival.
    fn forward_after_arrival(&mut self, port: u8, frame: &mut [u8], frame_ok: bool) -> Forward {
        if !frame_ok {
            let a = regs::RX_ERROR_COUNTER as usize + 2 * port as usize;
            self.mem[a] = self.mem[a].saturating_add(1);
        }
        if port == 0 {
            self.process_frame(frame, frame_ok);
        }
        let mut cur = port;
        for _ in 0..8 {
            let nxt = match cur {
                0 => 3,
                3 => 1,
                1 => 2,
                _ => 0,
            };
            if self.port_open(nxt) {
                return Forward::Port(nxt);
            }
            if nxt == 0 {
                // Port 0 closed: the frame loops back into the processing unit.
                match circulating(frame) {
                    Some(true) => return Forward::Dropped,
                    Some(false) => set_circulating(frame),
                    None => {}
                }
                self.process_frame(frame, frame_ok);
            }
            cur = nxt;
        }
        Forward::Dropped
    }

    fn process_frame(&mut self, frame: &mut [u8], frame_ok: bool) {
        self.frame_ok = frame_ok;
        self.walk_datagrams(frame);
        if !frame_ok {
            // A bad frame also abandons a buffer write ECAT had opened.
            for k in 0..self.active_sms.len() {
                let i = self.active_sms[k] as usize;
                let sm = &mut self.sms[i];
                if sm.write_open && sm.ecat_writes() {
                    sm.write_open = false;
                    let st = sm.status_reg();
                    self.mem[regs::sm_reg(i, 5)] = st;
                }
            }
        }
        // Only SMs flagged in this frame can have a pending commit (deactivating or
        // reconfiguring an SM clears its flag); lowest index first, as before.
        let mut pending = take(&mut self.pending_sms);
        while pending != 0 {
            let i = pending.trailing_zeros() as usize;
            pending &= pending - 1;
            if self.sms[i].pending_commit {
                if frame_ok {
                    self.commit_sm(i, Side::Ecat);
                } else {
                    self.sms[i].discard();
                }
            }
        }
        self.frame_ok = true;
    }

    /// Walks the datagrams of `frame` exactly as `oxicat_wire::frame::for_each_datagram_mut`
    /// does (same bounds checks, stops at the first malformed datagram), but hands logical
    /// datagrams to [`Esc::logical_datagram`] without building a decoded header.
    #[inline]
    fn walk_datagrams(&mut self, frame: &mut [u8]) {
        let Some(hdr) = frame.get(..ECAT_HEADER_LEN) else {
            return;
        };
        let w = u16::from_le_bytes([hdr[0], hdr[1]]);
        if w >> 12 != ECAT_TYPE_DATAGRAMS {
            return;
        }
        let end = ECAT_HEADER_LEN + (w & 0x07FF) as usize;
        let Some(mut rest) = frame.get_mut(ECAT_HEADER_LEN..end) else {
            return;
        };
        loop {
            let Some(h) = rest.get(..DG_HEADER_LEN) else {
                return;
            };
            let cmd = h[0];
            let lf = u16::from_le_bytes([h[6], h[7]]);
            let len = (lf & 0x07FF) as usize;
            let total = DG_HEADER_LEN + len + 2;
            if rest.len() < total {
                return;
            }
            let (dg, tail) = take(&mut rest).split_at_mut(total);
            if (CMD_LRD..=CMD_LRW).contains(&cmd) {
                self.logical_datagram(dg, cmd);
            } else if let Ok((mut d, _)) = DatagramMut::parse(dg) {
                self.process_datagram(&mut d);
            }
            if lf & 0x8000 == 0 {
                return;
            }
            rest = tail;
        }
    }

    /// A logical datagram (`dg`: header, data and working counter, already bounds-checked;
    /// `cmd` is LRD, LWR or LRW): what [`Esc::process_datagram`] does for it, on the raw bytes.
    #[inline]
    fn logical_datagram(&mut self, dg: &mut [u8], cmd: u8) {
        if self.events_dirty && self.ecat_mask != 0 {
            self.refresh_events();
        }
        let irq = self.ecat_irq;
        let (hdr, rest) = dg.split_at_mut(DG_HEADER_LEN);
        let (data, wkc) = rest.split_at_mut(rest.len() - 2);
        let addr = u32::from_le_bytes([hdr[2], hdr[3], hdr[4], hdr[5]]);
        let cmd = match cmd {
            CMD_LRD => Command::Lrd,
            CMD_LWR => Command::Lwr,
            _ => Command::Lrw,
        };
        let inc = self.logical(cmd, addr, data);
        let hirq = u16::from_le_bytes([hdr[8], hdr[9]]);
        if irq & !hirq != 0 {
            hdr[8..10].copy_from_slice(&(hirq | irq).to_le_bytes());
        }
        if inc != 0 {
            let w = u16::from_le_bytes([wkc[0], wkc[1]]).wrapping_add(inc);
            wkc.copy_from_slice(&w.to_le_bytes());
        }
    }

    fn configured_match(&self, adp: u16) -> bool {
        adp == self.reg16(regs::STATION_ADDR)
            || (self.mem[regs::DL_ALIAS_ENABLE as usize] & 1 != 0
                && adp == self.reg16(regs::STATION_ALIAS))
    }

    fn process_datagram(&mut self, dg: &mut DatagramMut<'_>) {
        if self.events_dirty && self.ecat_mask != 0 {
            self.refresh_events();
        }
        let Some(cmd) = dg.header.command() else {
            return;
        };
        // The IRQ field passes the ESC before the data: it shows the event state from
        // before this datagram's own access (a write to the mask 0x0200 or a read of DL
        // status does not change its own IRQ field).
        let irq = self.ecat_irq;
        let mut header_changed = false;
        let mut inc: u16 = 0;
        let adp = dg.header.adp();
        let ado = dg.header.ado() as u32;
        match cmd {
            Command::Nop => {}
            Command::Aprd | Command::Apwr | Command::Aprw | Command::Armw => {
                if adp == 0 {
                    inc = self.physical(cmd, ado, dg.data, false);
                } else if cmd == Command::Armw {
                    inc = self.physical(Command::Apwr, ado, dg.data, false);
                }
                dg.header.address = (dg.header.address & 0xFFFF_0000) | adp.wrapping_add(1) as u32;
                header_changed = true;
            }
            Command::Fprd | Command::Fpwr | Command::Fprw | Command::Frmw => {
                if self.configured_match(adp) {
                    inc = self.physical(cmd, ado, dg.data, false);
                } else if cmd == Command::Frmw {
                    inc = self.physical(Command::Fpwr, ado, dg.data, false);
                }
            }
            Command::Brd | Command::Bwr | Command::Brw => {
                inc = self.physical(cmd, ado, dg.data, true);
                dg.header.address = (dg.header.address & 0xFFFF_0000) | adp.wrapping_add(1) as u32;
                header_changed = true;
            }
            Command::Lrd | Command::Lwr | Command::Lrw => {
                inc = self.logical(cmd, dg.header.address, dg.data);
            }
        }
        if irq & !dg.header.irq != 0 {
            dg.header.irq |= irq;
            header_changed = true;
        }
        if header_changed {
            dg.commit_header();
        }
        if inc != 0 {
            let w = dg.wkc().wrapping_add(inc);
            dg.set_wkc(w);
        }
    }

    /// Physical access by a datagram addressed to this slave; returns the WKC increment.
    fn physical(&mut self, cmd: Command, ado: u32, data: &mut [u8], or: bool) -> u16 {
        // ARMW/FRMW at the addressed slave read only.
        let r = cmd.reads();
        let w = cmd.writes() && !matches!(cmd, Command::Armw | Command::Frmw);
        match (r, w) {
            (true, false) => u16::from(self.phys_read(Side::Ecat, ado, data, or)),
            (false, true) => u16::from(self.phys_write(Side::Ecat, ado, data, None)),
            (true, true) => {
                let mut orig = take(&mut self.scratch);
                orig.clear();
                orig.extend_from_slice(data);
                let mut inc = 0;
                if self.phys_read(Side::Ecat, ado, data, or) {
                    inc += 1;
                }
                if self.phys_write(Side::Ecat, ado, &orig, None) {
                    inc += 2;
                }
                self.scratch = orig;
                inc
            }
            (false, false) => 0,
        }
    }

    /// Logical access through the FMMUs; returns the WKC increment.
    #[inline]
    fn logical(&mut self, cmd: Command, addr: u32, data: &mut [u8]) -> u16 {
        let ds = addr as u64;
        let de = ds + data.len() as u64;
        // O(1) rejection: the datagram misses every FMMU's logical range.
        if self.log_bit_lo >= de * 8 || self.log_bit_hi <= ds * 8 {
            return 0;
        }
        let do_read = cmd != Command::Lwr && self.fmmu_any_read;
        let do_write = cmd != Command::Lrd && self.fmmu_any_write;
        if !do_read && !do_write {
            return 0;
        }
        if self.plan_ok && ds <= self.plan_lo && self.plan_hi <= de {
            // The datagram covers every FMMU: each step is a whole-buffer SM access.
            return self.logical_plan(cmd, (self.plan_lo - ds) as usize, data);
        }
        let need_copy = do_read && do_write && self.fmmu_rw_overlap;
        if need_copy || !self.fmmu_all_sm {
            return self.logical_generic(cmd, addr, data, do_read, do_write, need_copy);
        }
        // Every FMMU maps a whole SyncManager buffer byte-aligned (the usual process-data
        // layout): a datagram covering an FMMU's range accesses the SM buffer in one go;
        // a partial cover takes the general per-FMMU route.
        let mut rd = false;
        let mut wr = false;
        let n = self.fmmus.len();
        if do_read {
            for k in 0..n {
                let f = &self.fmmus[k];
                let (s, e) = (f.log_start as u64, f.log_end);
                if !f.read || s >= de || e <= ds {
                    continue;
                }
                if s >= ds && e <= de {
                    let i = f.sm.unwrap_or(0) as usize;
                    let out = &mut data[(s - ds) as usize..(e - ds) as usize];
                    rd |= self.sm_read_whole(i, out);
                } else {
                    let f = *f;
                    rd |= self.fmmu_read(&f, addr, data);
                }
            }
        }
        if do_write {
            for k in 0..n {
                let f = &self.fmmus[k];
                let (s, e) = (f.log_start as u64, f.log_end);
                if !f.write || s >= de || e <= ds {
                    continue;
                }
                if s >= ds && e <= de {
                    let i = f.sm.unwrap_or(0) as usize;
                    let inp = &data[(s - ds) as usize..(e - ds) as usize];
                    wr |= self.sm_write_whole(i, inp);
                } else {
                    let f = *f;
                    wr |= self.fmmu_write(&f, addr, data);
                }
            }
        }
        let wr_inc = if cmd == Command::Lwr { 1 } else { 2 };
        u16::from(rd) + wr_inc * u16::from(wr)
    }

    /// The logical fast path: `data[base..]` starts at the plan window.
    #[inline(always)]
    fn logical_plan(&mut self, cmd: Command, base: usize, data: &mut [u8]) -> u16 {
        let Some(win) = data.get_mut(base..) else {
            return 0;
        };
        let mut rd = false;
        let mut wr = false;
        let n = self.plan_len as usize;
        let nr = self.plan_reads as usize;
        if cmd != Command::Lwr {
            for k in 0..nr.min(n) {
                let op = self.plan[k];
                let (o, l) = (op.off as usize, op.len as usize);
                if let Some(out) = win.get_mut(o..o + l) {
                    rd |= self.sm_read_whole(op.sm as usize, out);
                }
            }
        }
        if cmd != Command::Lrd {
            for k in nr..n.min(PLAN_MAX) {
                let op = self.plan[k];
                let (o, l) = (op.off as usize, op.len as usize);
                if let Some(inp) = win.get(o..o + l) {
                    wr |= self.sm_write_whole(op.sm as usize, inp);
                }
            }
        }
        let wr_inc = if cmd == Command::Lwr { 1 } else { 2 };
        u16::from(rd) + wr_inc * u16::from(wr)
    }

    /// Logical access through arbitrary (bit-granular, overlapping, non-SM) FMMUs.
    fn logical_generic(
        &mut self,
        cmd: Command,
        addr: u32,
        data: &mut [u8],
        do_read: bool,
        do_write: bool,
        need_copy: bool,
    ) -> u16 {
        let mut rd = false;
        let mut wr = false;
        let n = self.fmmus.len();
        // Only a logical datagram that touches the FMMUs' logical ranges does work.
        let ds = addr as u64;
        let de = ds + data.len() as u64;
        // Writes use the data as it arrived (before this ESC's reads) when a read and a
        // write FMMU overlap.
        let orig = if need_copy {
            let mut o = take(&mut self.scratch);
            o.clear();
            o.extend_from_slice(data);
            Some(o)
        } else {
            None
        };
        if do_read {
            for k in 0..n {
                let f = self.fmmus[k];
                if f.read
                    && f.log_bit_start < de * 8
                    && f.log_bit_end > ds * 8
                    && self.fmmu_read(&f, addr, data)
                {
                    rd = true;
                }
            }
        }
        if do_write {
            for k in 0..n {
                let f = self.fmmus[k];
                if f.write && f.log_bit_start < de * 8 && f.log_bit_end > ds * 8 {
                    let src: &[u8] = orig.as_deref().unwrap_or(data);
                    if self.fmmu_write(&f, addr, src) {
                        wr = true;
                    }
                }
            }
        }
        if let Some(o) = orig {
            self.scratch = o;
        }
        let wr_inc = if cmd == Command::Lwr { 1 } else { 2 };
        u16::from(rd) + wr_inc * u16::from(wr)
    }

    fn fmmu_read(&mut self, f: &Fmmu, addr: u32, data: &mut [u8]) -> bool {
        let (n, dbit, p0) = match f.overlap(addr, data.len()) {
            Overlap::None => return false,
            Overlap::WholeSm { sm, at } => {
                return self.sm_read_whole(sm, &mut data[at..at + f.len as usize])
            }
            Overlap::Bytes { phys, d0, d1 } => {
                return self.phys_read(Side::Ecat, phys, &mut data[d0..d1], false)
            }
            Overlap::Bits { n, dbit, pbit0 } => (n, dbit, pbit0),
        };
        let (pb0, pb1) = (p0 / 8, (p0 + n - 1) / 8);
        let mut tmp = take(&mut self.scratch_bits);
        tmp.clear();
        tmp.resize(pb1 - pb0 + 1, 0);
        let ok = self.phys_read(Side::Ecat, pb0 as u32, &mut tmp, false);
        if ok {
            let pbit = p0 % 8;
            for i in 0..n {
                set_bit(data, dbit + i, get_bit(&tmp, pbit + i));
            }
        }
        self.scratch_bits = tmp;
        ok
    }

    fn fmmu_write(&mut self, f: &Fmmu, addr: u32, src: &[u8]) -> bool {
        let (n, dbit, p0) = match f.overlap(addr, src.len()) {
            Overlap::None => return false,
            Overlap::WholeSm { sm, at } => {
                return self.sm_write_whole(sm, &src[at..at + f.len as usize])
            }
            Overlap::Bytes { phys, d0, d1 } => {
                return self.phys_write(Side::Ecat, phys, &src[d0..d1], None)
            }
            Overlap::Bits { n, dbit, pbit0 } => (n, dbit, pbit0),
        };
        let (pb0, pb1) = (p0 / 8, (p0 + n - 1) / 8);
        let mut tmp = take(&mut self.scratch_bits);
        let mut mask = take(&mut self.scratch_mask);
        tmp.clear();
        tmp.resize(pb1 - pb0 + 1, 0);
        mask.clear();
        mask.resize(pb1 - pb0 + 1, 0);
        let pbit = p0 % 8;
        for i in 0..n {
            set_bit(&mut tmp, pbit + i, get_bit(src, dbit + i));
            set_bit(&mut mask, pbit + i, true);
        }
        let ok = self.phys_write(Side::Ecat, pb0 as u32, &tmp, Some(&mask));
        self.scratch_bits = tmp;
        self.scratch_mask = mask;
        ok
    }

    // ------------------------------------------------------------------ memory layer

    /// The next piece of `[cur, end)`: its end and the SM that covers it, if any.
    #[inline]
    fn piece(&self, cur: u32, end: u32) -> (u32, Option<usize>) {
        let mut pend = end;
        for &i in &self.active_sms {
            let sm = &self.sms[i as usize];
            let s = sm.start as u32;
            let e = sm.end();
            if cur >= s && cur < e {
                return (e.min(end), Some(i as usize));
            }
            if s > cur && s < pend {
                pend = s;
            }
        }
        (pend, None)
    }

    /// Reads physical memory as `side` sees it (SyncManager rules applied). Returns true
    /// when the access counts: at least one byte exists in this chip and no SyncManager
    /// refused (part of) the access.
    fn phys_read(&mut self, side: Side, addr: u32, out: &mut [u8], or: bool) -> bool {
        let end = addr + out.len() as u32;
        let mut cur = addr;
        let mut ok = true;
        let mut any = false;
        while cur < end {
            let (pe, sm) = self.piece(cur, end);
            let o = &mut out[(cur - addr) as usize..(pe - addr) as usize];
            match sm {
                Some(i) => {
                    let r = self.sm_read(i, side, cur, o, or);
                    ok &= r;
                    any |= r;
                }
                None => any |= self.plain_read(side, cur, o, or),
            }
            cur = pe;
        }
        ok && any
    }

    /// Writes physical memory as `side` (SyncManager rules and register permissions
    /// applied); `mask` selects the bits to write. Returns true when the access counts: at
    /// least one byte is writable by `side` in this chip and no SyncManager refused.
    fn phys_write(&mut self, side: Side, addr: u32, data: &[u8], mask: Option<&[u8]>) -> bool {
        let end = addr + data.len() as u32;
        let mut cur = addr;
        let mut ok = true;
        let mut any = false;
        while cur < end {
            let (pe, sm) = self.piece(cur, end);
            let a = (cur - addr) as usize;
            let b = (pe - addr) as usize;
            let d = &data[a..b];
            let m = mask.map(|m| &m[a..b]);
            match sm {
                Some(i) => {
                    let r = self.sm_write(i, side, cur, d, m);
                    ok &= r;
                    any |= r;
                }
                None => any |= self.plain_write(side, cur, d, m),
            }
            cur = pe;
        }
        ok && any
    }

    fn copy_out(&self, from: u32, o: &mut [u8], or: bool) {
        let from = from as usize;
        let len = self.mem.len();
        let avail = len.saturating_sub(from).min(o.len());
        let (a, rest) = o.split_at_mut(avail);
        if avail > 0 {
            let src = &self.mem[from..from + avail];
            if or {
                for (x, y) in a.iter_mut().zip(src) {
                    *x |= *y;
                }
            } else {
                a.copy_from_slice(src);
            }
        }
        if !or {
            rest.fill(0);
        }
    }

    fn store(&mut self, to: u32, d: &[u8], m: Option<&[u8]>) {
        let to = to as usize;
        let avail = self.mem.len().saturating_sub(to).min(d.len());
        if avail == 0 {
            return;
        }
        let dst = &mut self.mem[to..to + avail];
        match m {
            None => dst.copy_from_slice(&d[..avail]),
            Some(m) => {
                for ((x, y), k) in dst.iter_mut().zip(d).zip(m) {
                    *x = (*x & !*k) | (*y & *k);
                }
            }
        }
    }

    /// Reads a piece not covered by a SyncManager; returns true when at least one byte of
    /// it exists in this chip. Bytes that do not exist read as 0 (BRD: contribute nothing).
    fn plain_read(&mut self, side: Side, cur: u32, o: &mut [u8], or: bool) -> bool {
        let c = cur as usize;
        let full_end = c + o.len();
        let ram_any = full_end > REG_END && c.max(REG_END) < self.mem.len();
        if c < REG_END {
            let e = full_end.min(REG_END);
            let impl_n = self.perm[c..e].iter().filter(|&&p| p & P_IMPL != 0).count();
            if impl_n == 0 && !ram_any {
                if !or {
                    o.fill(0);
                }
                return false;
            }
            if c < 0x0A00 && e > 0x0900 {
                let a = c.max(0x0900);
                let b = e.min(0x0A00);
                self.dc
                    .before_read(&mut self.mem[..REG_END], a as u16, (b - a) as u16, self.now);
            }
            if c < 0x0224 && e > 0x0210 {
                self.refresh_events();
            }
            if impl_n == e - c {
                self.copy_out(cur, o, or);
            } else {
                // Bytes the chip does not have read as 0 (the DC unit may keep shadows
                // there); BRD: they contribute nothing.
                for (k, a) in (c..e).enumerate() {
                    let v = if self.perm[a] & P_IMPL != 0 {
                        self.mem[a]
                    } else {
                        0
                    };
                    if or {
                        o[k] |= v;
                    } else {
                        o[k] = v;
                    }
                }
                if full_end > REG_END {
                    self.copy_out(REG_END as u32, &mut o[e - c..], or);
                }
            }
            if c < 0x0A00 && e > 0x0900 {
                let a = c.max(0x0900);
                let b = e.min(0x0A00);
                let ecat = side == Side::Ecat;
                self.dc.after_read(
                    &mut self.mem[..REG_END],
                    a as u16,
                    (b - a) as u16,
                    self.now,
                    ecat,
                );
                self.events_dirty = true;
            }
            self.read_side_effects(side, c, e);
            true
        } else {
            self.copy_out(cur, o, or);
            ram_any
        }
    }

    fn read_side_effects(&mut self, side: Side, c: usize, e: usize) {
        let hit = |a: usize| c <= a && a < e;
        match side {
            Side::Ecat => {
                if hit(regs::AL_STATUS as usize) && self.ecat_ev & ECAT_EV_AL != 0 {
                    self.ecat_ev &= !ECAT_EV_AL;
                    self.events_dirty = true;
                }
                // Reading DL status acknowledges the DL-status-change event.
                if (hit(0x0110) || hit(0x0111)) && self.ecat_ev & ECAT_EV_DL != 0 {
                    self.ecat_ev &= !ECAT_EV_DL;
                    self.events_dirty = true;
                }
            }
            Side::Pdi => {
                // AL control is a mailbox for ECAT until the PDI reads (either byte of) it.
                if hit(0x0120) || hit(0x0121) {
                    self.al_ctl_unread = false;
                }
                if hit(regs::AL_CONTROL as usize) && self.al_ev & AL_EV_CONTROL != 0 {
                    self.al_ev &= !AL_EV_CONTROL;
                    self.events_dirty = true;
                }
                if hit(regs::WD_STATUS_PD as usize) && self.al_ev & AL_EV_WD != 0 {
                    self.al_ev &= !AL_EV_WD;
                    self.events_dirty = true;
                }
                if self.al_ev & AL_EV_SM_CHANGE != 0
                    && (0..self.cfg.sm_count as usize).any(|i| hit(regs::sm_reg(i, 6)))
                {
                    self.al_ev &= !AL_EV_SM_CHANGE;
                    self.events_dirty = true;
                }
            }
        }
    }

    /// Writes a piece not covered by a SyncManager; returns true when at least one byte of
    /// it is writable by `side` in this chip (the access counts even if a rule then
    /// discards the value, e.g. EEPROM ownership; it does not count for read-only or
    /// missing registers, nor for AL control still unread by the PDI).
    fn plain_write(&mut self, side: Side, cur: u32, d: &[u8], m: Option<&[u8]>) -> bool {
        let c = cur as usize;
        let full_end = c + d.len();
        if c >= REG_END {
            self.store(cur, d, m);
            return c < self.mem.len();
        }
        let mut counted = false;
        if full_end > REG_END {
            let k = REG_END - c;
            self.store(REG_END as u32, &d[k..], m.map(|m| &m[k..]));
            counted = REG_END < self.mem.len();
        }
        let e = full_end.min(REG_END);
        let bit = if side == Side::Ecat { P_ECAT } else { P_PDI };
        let al_ctl_locked = side == Side::Ecat
            && self.al_ctl_unread
            && c < 0x0122
            && e > 0x0120
            && self.mem[regs::ESC_CONFIG as usize] & 1 == 0;
        for a in c..e {
            if self.perm[a] & bit != 0 && !(al_ctl_locked && (0x0120..0x0122).contains(&a)) {
                counted = true;
                break;
            }
        }
        if !counted {
            return false;
        }
        if side == Side::Ecat && !self.frame_ok {
            // Register writes take effect only with a good FCS.
            return true;
        }
        let sii_owner_ok = match side {
            Side::Ecat => !sii::pdi_owns(&self.mem),
            Side::Pdi => sii::pdi_owns(&self.mem),
        };
        let old_al_ctl = self.reg16(regs::AL_CONTROL);
        // Only `write_side_effects` of a write to the SM registers looks at these.
        let old_activate: [u8; 16] = if c < 0x0880 && e > 0x0800 {
            core::array::from_fn(|i| {
                self.mem
                    .get(regs::sm_reg(i, 6))
                    .copied()
                    .unwrap_or_default()
            })
        } else {
            [0; 16]
        };
        let dc_ctrl = self.mem[0x0980];
        for (k, a) in (c..e).enumerate() {
            let p = self.perm[a];
            if p & bit == 0 {
                continue;
            }
            if al_ctl_locked && (0x0120..0x0122).contains(&a) {
                continue;
            }
            if (0x0502..0x0510).contains(&a) && !sii_owner_ok {
                continue;
            }
            if a == regs::SII_PDI_ACCESS as usize && self.mem[regs::SII_CONFIG as usize] & 1 == 0 {
                continue;
            }
            if p & P_CLEAR != 0 {
                self.mem[a] = 0;
                continue;
            }
            if (0x0800..0x0880).contains(&a)
                && (a - 0x0800) % 8 < 5
                && old_activate[(a - 0x0800) / 8] & 1 != 0
            {
                // SM start, length and control: "r/(w)", written only while the
                // SyncManager is disabled (+0x6.0 = 0) when the datagram arrives.
                continue;
            }
            let mut bm = bit_mask(a) & m.map_or(0xFF, |m| m[k]);
            if let Some(owner_ecat) = dc_unit_owner(a, dc_ctrl) {
                // SYNC/latch unit registers: writable only by the side 0x0980 assigns.
                if owner_ecat != (side == Side::Ecat) {
                    continue;
                }
                if a == 0x09A8 || a == 0x09A9 {
                    bm &= 0x03;
                }
            }
            let v = d[k];
            self.mem[a] = (self.mem[a] & !bm) | (v & bm);
        }
        if side == Side::Ecat
            && c < 0x0122
            && e > 0x0120
            && !al_ctl_locked
            && self.mem[regs::ESC_CONFIG as usize] & 1 == 0
        {
            self.al_ctl_unread = true;
        }
        self.write_side_effects(side, c, e, old_al_ctl, &old_activate);
        true
    }

    fn write_side_effects(
        &mut self,
        side: Side,
        c: usize,
        e: usize,
        old_al_ctl: u16,
        old_activate: &[u8; 16],
    ) {
        let over = |a: usize, b: usize| c < b && e > a;
        if over(0x0100, 0x0104) && side == Side::Ecat {
            if over(0x0100, 0x0102) {
                // 0x0100 bit 1 (ETG.1000.4 table 33): loop control used for about a
                // second, then the permanent setting again; bit 1 clear makes it permanent.
                if self.mem[regs::DL_CONTROL as usize] & 0x02 != 0 {
                    self.loop_revert_at = Some(self.now + TEMPORARY_LOOP_NS);
                } else {
                    self.loop_permanent = self.mem[regs::DL_LOOP_CONTROL as usize];
                    self.loop_revert_at = None;
                }
                self.memo.clear();
            }
            self.update_dl_status(true);
        }
        if over(0x0120, 0x0122) && side == Side::Ecat {
            let _ = old_al_ctl;
            self.al_ev |= AL_EV_CONTROL;
            if self.mem[regs::ESC_CONFIG as usize] & 1 != 0 {
                // Device emulation: AL status follows AL control including the error
                // indication acknowledge bit 4 (captures: BWR 0x0120 `11 00` -> 0x0130
                // reads `11 00`).
                let ctl = self.mem[regs::AL_CONTROL as usize];
                let st = ctl & 0x1F;
                if self.mem[regs::AL_STATUS as usize] != st || self.mem[0x0131] != 0 {
                    self.ecat_ev |= ECAT_EV_AL;
                }
                self.mem[regs::AL_STATUS as usize] = st;
                self.mem[0x0131] = 0;
            }
            self.events_dirty = true;
        }
        if over(0x0130, 0x0132) && side == Side::Pdi {
            self.ecat_ev |= ECAT_EV_AL;
            self.events_dirty = true;
        }
        if over(0x0200, 0x0208) {
            self.refresh_events();
        }
        if over(0x0500, 0x0501) && side == Side::Ecat && self.mem[0x0500] & 2 != 0 {
            // Force ECAT access: the PDI loses the EEPROM.
            self.mem[0x0501] &= !1;
        }
        if over(0x0502, 0x0504) {
            let written = self.reg16(regs::SII_CONTROL);
            let ok_owner = match side {
                Side::Ecat => !sii::pdi_owns(&self.mem),
                Side::Pdi => sii::pdi_owns(&self.mem),
            };
            if ok_owner {
                let read8 = self.cfg.sii_read_8_bytes;
                let out = sii::execute(
                    &mut self.mem,
                    &mut self.eeprom,
                    written,
                    read8,
                    self.eeprom_writable_words,
                );
                if let sii::SiiOutcome::Reloaded(_) = out {
                    self.update_dl_status(true);
                }
            }
        }
        if over(0x0600, 0x0700) {
            self.rebuild_fmmus();
        }
        if over(0x0800, 0x0880) {
            let first = (c.max(0x0800) - 0x0800) / 8;
            let last = (e.min(0x0880) - 1 - 0x0800) / 8;
            let n = self.cfg.sm_count as usize;
            for (i, &old) in old_activate.iter().enumerate().take(last + 1).skip(first) {
                if i >= n {
                    break;
                }
                if side == Side::Ecat && old != self.mem[regs::sm_reg(i, 6)] {
                    self.al_ev |= AL_EV_SM_CHANGE;
                }
                self.reload_sm(i);
            }
            self.rebuild_active_sms();
            self.rebuild_fmmus();
            self.events_dirty = true;
        }
        if over(0x0900, 0x0A00) {
            let a = c.max(0x0900);
            let b = e.min(0x0A00);
            let ecat = side == Side::Ecat;
            self.dc.after_write(
                &mut self.mem[..REG_END],
                a as u16,
                (b - a) as u16,
                self.now,
                ecat,
            );
            self.events_dirty = true;
        }
        if over(0x0F00, 0x0F04) && side == Side::Ecat {
            let mut v = [0u8; 4];
            v.copy_from_slice(&self.mem[0x0F00..0x0F04]);
            self.dout = u32::from_le_bytes(v);
        }
    }

    fn sm_read(&mut self, i: usize, side: Side, cur: u32, o: &mut [u8], or: bool) -> bool {
        let sm = &mut self.sms[i];
        let refuse = sm.is_producer(side)
            || if cur == sm.start as u32 {
                !sm.open_read()
            } else {
                !sm.read_open
            };
        if refuse {
            if side == Side::Pdi {
                // The PDI sees the raw memory; nothing changes.
                self.copy_out(cur, o, or);
            }
            return false;
        }
        let off = sm.buf_offset(sm.user_buf);
        let done = cur + o.len() as u32 == sm.end();
        if done {
            sm.close_read();
        }
        let status = sm.status_reg();
        self.mem[regs::sm_reg(i, 5)] = status;
        self.events_dirty = true;
        self.copy_out(cur + off, o, or);
        true
    }

    /// ECAT reads a whole SM buffer in one access (FMMU fast path).
    #[inline(always)]
    fn sm_read_whole(&mut self, i: usize, o: &mut [u8]) -> bool {
        let sm = &mut self.sms[i];
        let Some(off) = sm.read_whole() else {
            return false;
        };
        let from = (sm.start as u32 + off) as usize;
        let status = sm.status_reg();
        self.mem[regs::sm_reg(i, 5)] = status;
        self.events_dirty = true;
        match self.mem.get(from..from + o.len()) {
            Some(src) => copy_small(o, src),
            None => self.copy_out(from as u32, o, false),
        }
        true
    }

    /// ECAT writes a whole SM buffer in one access (FMMU fast path).
    #[inline(always)]
    fn sm_write_whole(&mut self, i: usize, d: &[u8]) -> bool {
        let sm = &mut self.sms[i];
        let Some(off) = sm.write_whole() else {
            return false;
        };
        self.pending_sms |= 1 << i;
        let to = (sm.start as u32 + off) as usize;
        let status = sm.status_reg();
        self.mem[regs::sm_reg(i, 5)] = status;
        self.events_dirty = true;
        match self.mem.get_mut(to..to + d.len()) {
            Some(dst) => copy_small(dst, d),
            None => self.store(to as u32, d, None),
        }
        true
    }

    fn sm_write(&mut self, i: usize, side: Side, cur: u32, d: &[u8], m: Option<&[u8]>) -> bool {
        let sm = &mut self.sms[i];
        let refuse = !sm.is_producer(side)
            || if cur == sm.start as u32 {
                !sm.open_write()
            } else {
                !sm.write_open
            };
        if refuse {
            return false;
        }
        let off = sm.buf_offset(sm.write_buf);
        let done = cur + d.len() as u32 == sm.end();
        self.store(cur + off, d, m);
        let sm = &mut self.sms[i];
        if done {
            sm.write_open = false;
            if side == Side::Ecat {
                sm.pending_commit = true;
                self.pending_sms |= 1 << i;
            } else {
                self.commit_sm(i, side);
                return true;
            }
        }
        let status = self.sms[i].status_reg();
        self.mem[regs::sm_reg(i, 5)] = status;
        self.events_dirty = true;
        true
    }

    fn commit_sm(&mut self, i: usize, side: Side) {
        let sm = &mut self.sms[i];
        sm.commit();
        let status = sm.status_reg();
        let wd = sm.ctrl & CTRL_WD_TRIGGER != 0;
        let start = sm.start as u32;
        let end = sm.end();
        let off = sm.buf_offset(sm.last_written.min(2));
        self.mem[regs::sm_reg(i, 5)] = status;
        self.events_dirty = true;
        if side == Side::Ecat && wd {
            self.pd_wd_last = Some(self.now);
            self.mem[regs::WD_STATUS_PD as usize] |= 1;
        }
        if start < 0x0F04 && end > 0x0F00 {
            let mut v = self.dout.to_le_bytes();
            for a in start.max(0x0F00)..end.min(0x0F04) {
                v[(a - 0x0F00) as usize] = self.mem.get((a + off) as usize).copied().unwrap_or(0);
            }
            self.dout = u32::from_le_bytes(v);
        }
    }

    fn reload_sm(&mut self, i: usize) {
        let b = regs::sm_reg(i, 0);
        let mut r = [0u8; 8];
        r.copy_from_slice(&self.mem[b..b + 8]);
        let sm = &mut self.sms[i];
        let (os, ol, oc) = (sm.start, sm.len, sm.ctrl);
        sm.load_regs(&r);
        let was = sm.enabled;
        sm.enabled = sm.should_enable();
        if sm.enabled && (!was || os != sm.start || ol != sm.len || oc != sm.ctrl) {
            sm.reset_state();
        }
        if !sm.enabled {
            sm.reset_state();
        }
        let status = sm.status_reg();
        self.mem[b + 5] = status;
    }

    fn rebuild_active_sms(&mut self) {
        self.active_sms.clear();
        for (i, sm) in self.sms.iter().enumerate().take(self.cfg.sm_count as usize) {
            if sm.enabled {
                self.active_sms.push(i as u8);
            }
        }
    }

    fn rebuild_fmmus(&mut self) {
        self.fmmus.clear();
        for n in 0..self.cfg.fmmu_count as usize {
            let b = regs::fmmu_reg(n, 0);
            if let Some(f) = Fmmu::decode(&self.mem[b..b + 16]) {
                self.fmmus.push(f);
            }
        }
        for f in self.fmmus.iter_mut() {
            if !f.aligned || f.read == f.write {
                continue;
            }
            let ps = f.phys_start as u32;
            let pe = ps + f.len as u32;
            f.sm = self.active_sms.iter().copied().find(|&i| {
                let sm = &self.sms[i as usize];
                sm.start as u32 == ps && sm.end() == pe && sm.ecat_writes() == f.write
            });
        }
        self.fmmu_all_sm = self.fmmus.iter().all(|f| f.aligned && f.sm.is_some());
        self.log_bit_lo = self
            .fmmus
            .iter()
            .map(|f| f.log_bit_start)
            .min()
            .unwrap_or(u64::MAX);
        self.log_bit_hi = self.fmmus.iter().map(|f| f.log_bit_end).max().unwrap_or(0);
        self.fmmu_any_read = self.fmmus.iter().any(|f| f.read);
        self.fmmu_any_write = self.fmmus.iter().any(|f| f.write);
        self.fmmu_rw_overlap = self
            .fmmus
            .iter()
            .any(|r| r.read && self.fmmus.iter().any(|w| w.write && w.overlaps(r)));
        self.rebuild_plan();
    }

    /// Pre-resolves the FMMUs for the logical fast path (see `plan_ok`).
    fn rebuild_plan(&mut self) {
        self.plan_ok = self.fmmu_all_sm
            && !self.fmmu_rw_overlap
            && !self.fmmus.is_empty()
            && self.fmmus.len() <= PLAN_MAX;
        self.plan_len = 0;
        if !self.plan_ok {
            self.rebuild_fused();
            return;
        }
        self.plan_lo = self
            .fmmus
            .iter()
            .map(|f| f.log_start as u64)
            .min()
            .unwrap_or(0);
        self.plan_hi = self.fmmus.iter().map(|f| f.log_end).max().unwrap_or(0);
        // Reads first, then writes, each in FMMU order (the order `logical` executes).
        let reads = self.fmmus.iter().filter(|f| f.read);
        let writes = self.fmmus.iter().filter(|f| f.write);
        let mut n = 0;
        for f in reads.chain(writes) {
            self.plan[n] = PlanOp {
                off: (f.log_start as u64 - self.plan_lo) as u32,
                len: f.len as u32,
                sm: f.sm.unwrap_or(0),
            };
            n += 1;
        }
        self.plan_len = n as u8;
        self.plan_reads = self.fmmus.iter().filter(|f| f.read).count() as u8;
        self.rebuild_fused();
    }

    /// Decides whether the fused path applies (see `Fused`) and pre-resolves it.
    fn rebuild_fused(&mut self) {
        let mut f = Fused::default();
        // Exit port of a frame entering port 0: the first open port in processing order
        // (port 0 itself last; all closed: the frame loops back, generic path).
        let exit = [3u8, 1, 2, 0].into_iter().find(|&p| self.port_open(p));
        let n = self.plan_len as usize;
        let mut ok = !self.fused_disabled && self.plan_ok && n > 0 && exit.is_some();
        let mut seen = 0u32;
        for (k, op) in self.plan[..n].iter().enumerate() {
            let i = op.sm as usize;
            let Some(sm) = self.sms.get(i) else {
                ok = false;
                break;
            };
            let ram_ok = sm.start as usize >= REG_END
                && sm.start as usize + 3 * sm.len as usize <= self.mem.len();
            if sm.is_mailbox()
                || !ram_ok
                || seen & (1 << i) != 0
                || op.len != sm.len as u32
                || op.off > u16::MAX as u32
            {
                ok = false;
                break;
            }
            seen |= 1 << i;
            f.steps[k] = FusedStep {
                off: op.off as u16,
                ram: sm.start - REG_END as u16,
                len: sm.len,
                sm: op.sm,
                write: k >= self.plan_reads as usize,
                wd: sm.ctrl & CTRL_WD_TRIGGER != 0,
            };
        }
        if ok {
            let nr = self.plan_reads.min(self.plan_len);
            let rd = u16::from(nr > 0);
            let wr = u16::from(self.plan_len > nr);
            f.ok = true;
            f.exit = exit.unwrap_or(0);
            f.range = [(0, nr), (nr, self.plan_len), (0, self.plan_len)];
            f.lo = self.plan_lo;
            f.hi = self.plan_hi;
            f.inc = [rd, wr, rd + 2 * wr];
        }
        self.fused = f;
    }

    /// Test switch: `false` forces every frame through the generic path.
    #[cfg(test)]
    pub(crate) fn set_fused_enabled(&mut self, on: bool) {
        self.memo.clear();
        self.fused_disabled = !on;
        self.rebuild_fused();
    }

    fn update_dl_status(&mut self, event: bool) {
        self.open_ports = (0..4u8)
            .filter(|&p| self.compute_port_open(p))
            .fold(0, |m, p| m | (1 << p));
        self.rebuild_fused();
        let mut s: u16 = 0;
        if sii::read_ctl(&self.mem) & sii::CTL_NOT_LOADED == 0 {
            s |= 1;
        }
        if self.mem[regs::DL_STATUS as usize] & 2 != 0
            || (s & 1 != 0 && self.mem[regs::PDI_CONTROL as usize] == PDI_DIGITAL_IO)
        {
            // PDI watchdog reloaded: by PDI accesses, or continuously by the digital I/O
            // PDI of a bare-ESC device (captures: EL2828/EL1004 read 0x0110 bit 1 set).
            s |= 2;
        }
        if self.mem[regs::ESC_CONFIG as usize] & 0x02 != 0 {
            // Enhanced link detection enabled for all ports (0x0141 bit 1, from the SII).
            s |= 4;
        }
        for p in 0..4u8 {
            let link = self.link[p as usize] && self.cfg.port_present(p);
            if link {
                s |= 1 << (4 + p);
            }
            if !self.port_open(p) {
                s |= 1 << (8 + 2 * p);
            }
            if link {
                s |= 1 << (9 + 2 * p);
            }
        }
        let old = self.reg16(regs::DL_STATUS);
        if old != s {
            self.mem[0x0110..0x0112].copy_from_slice(&s.to_le_bytes());
            if event {
                self.ecat_ev |= ECAT_EV_DL;
                self.events_dirty = true;
            }
        }
    }

    fn compute_events(&self) -> (u16, u32) {
        let mut e = self.ecat_ev;
        let mut a = self.al_ev;
        for &i in &self.active_sms {
            let sm = &self.sms[i as usize];
            if sm.ecat_event() {
                e |= 1 << (4 + i);
            }
            if sm.al_event() {
                a |= 1 << (8 + i as u32);
            }
        }
        // DC: latch events, SYNC0/SYNC1 status gated by PDI config 0x0151 bits 3/7.
        let (dce, mut dca) = self.dc.event_bits();
        let gate = self.mem[0x0151];
        if gate & 0x08 == 0 {
            dca &= !(1 << 2);
        }
        if gate & 0x80 == 0 {
            dca &= !(1 << 3);
        }
        a |= dca;
        e |= dce;
        (e, a)
    }

    fn refresh_events(&mut self) {
        let (e, a) = self.compute_events();
        self.mem[0x0210..0x0212].copy_from_slice(&e.to_le_bytes());
        self.mem[0x0220..0x0224].copy_from_slice(&a.to_le_bytes());
        self.ecat_mask = self.reg16(regs::ECAT_EVENT_MASK);
        self.ecat_irq = e & self.ecat_mask;
        self.events_dirty = false;
    }

    // ------------------------------------------------------------------ PDI side

    fn wd_unit_ns(&self) -> u64 {
        (self.reg16(regs::WD_DIVIDER) as u64 + 2) * 40
    }

    fn pd_wd_deadline(&self) -> Option<u64> {
        let t = self.reg16(regs::WD_TIME_PD) as u64;
        match self.pd_wd_last {
            Some(l) if t != 0 => Some(l + t * self.wd_unit_ns()),
            _ => None,
        }
    }

    fn pdi_wd_deadline(&self) -> Option<u64> {
        let t = self.reg16(regs::WD_TIME_PDI) as u64;
        match self.pdi_wd_last {
            Some(l) if t != 0 => Some(l + t * self.wd_unit_ns()),
            _ => None,
        }
    }

    fn pdi_access(&mut self) {
        self.pdi_wd_last = Some(self.now);
        if self.mem[regs::DL_STATUS as usize] & 2 == 0 {
            self.mem[regs::DL_STATUS as usize] |= 2;
            self.ecat_ev |= ECAT_EV_DL;
            self.events_dirty = true;
        }
    }

    /// Time passes: watchdogs, SYNC0/1, latch.
    pub fn advance(&mut self, t: u64) -> EscEvents {
        if t > self.now {
            self.now = t;
        }
        let dce = if self.dc.advance_quiet(t) {
            crate::dc::DcEvents::default()
        } else {
            // The DC unit may change its status bits (AL event request bits 2/3).
            self.memo.clear();
            self.dc.advance_slow(&mut self.mem[..REG_END], t)
        };
        let mut ev = EscEvents {
            sync0: dce.sync0,
            sync1: dce.sync1,
            ..EscEvents::default()
        };
        if let Some(d) = self.pd_wd_deadline() {
            if t >= d {
                self.pd_wd_last = None;
                self.mem[regs::WD_STATUS_PD as usize] &= !1;
                let a = regs::WD_COUNTER_PD as usize;
                self.mem[a] = self.mem[a].saturating_add(1);
                self.al_ev |= AL_EV_WD;
                self.dout = 0;
                ev.pd_watchdog_expired = true;
                self.memo.clear();
            }
        }
        if let Some(d) = self.loop_revert_at {
            if t >= d {
                self.loop_revert_at = None;
                self.mem[regs::DL_LOOP_CONTROL as usize] = self.loop_permanent;
                self.update_dl_status(true);
                self.memo.clear();
            }
        }
        if let Some(d) = self.pdi_wd_deadline() {
            if t >= d {
                self.pdi_wd_last = None;
                self.mem[regs::DL_STATUS as usize] &= !2;
                let a = regs::WD_COUNTER_PDI as usize;
                self.mem[a] = self.mem[a].saturating_add(1);
                self.ecat_ev |= ECAT_EV_DL;
                ev.pdi_watchdog_expired = true;
                self.memo.clear();
            }
        }
        self.events_dirty = true;
        ev
    }

    /// Global time of the next SYNC edge or watchdog expiry.
    #[inline]
    pub fn next_event(&self) -> Option<u64> {
        // The scheduler asks after every event and wakeup.
        if let Some(n) = self.memo.next_event() {
            return n;
        }
        let n = self.compute_next_event();
        self.memo.set_next_event(n);
        n
    }

    fn compute_next_event(&self) -> Option<u64> {
        let mut n = self.dc.next_event();
        if let Some(d) = self.pd_wd_deadline() {
            n = Some(n.map_or(d, |x| x.min(d)));
        }
        if let Some(d) = self.pdi_wd_deadline() {
            n = Some(n.map_or(d, |x| x.min(d)));
        }
        if let Some(d) = self.loop_revert_at {
            n = Some(n.map_or(d, |x| x.min(d)));
        }
        n
    }

    fn pdi_range(&self, addr: u16, len: usize) -> Result<(), PdiError> {
        if addr as usize + len > self.mem.len() {
            Err(PdiError::OutOfRange)
        } else {
            Ok(())
        }
    }

    /// Whether a PDI access of `len` bytes at `addr` lies inside the implemented memory
    /// ([`pdi_read`](Self::pdi_read) / [`pdi_write`](Self::pdi_write) refuse it otherwise);
    /// no side effects, for a PDI that holds a write back to commit it later.
    pub fn pdi_check(&self, addr: u16, len: usize) -> Result<(), PdiError> {
        self.pdi_range(addr, len)
    }

    /// PDI read of `buf.len()` bytes at `addr` (SyncManager rules apply; reading AL
    /// control clears its event; reading a buffer's last byte frees it).
    pub fn pdi_read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), PdiError> {
        self.memo.clear();
        self.pdi_range(addr, buf.len())?;
        self.pdi_access();
        self.phys_read(Side::Pdi, addr as u32, buf, false);
        Ok(())
    }

    /// PDI write of `data` at `addr` (bytes the PDI may not write are ignored, as in
    /// silicon; SyncManager rules apply).
    pub fn pdi_write(&mut self, addr: u16, data: &[u8]) -> Result<(), PdiError> {
        self.memo.clear();
        self.pdi_range(addr, data.len())?;
        self.pdi_access();
        self.phys_write(Side::Pdi, addr as u32, data, None);
        Ok(())
    }

    /// [`compute_events`](Self::compute_events) through [`QueryMemo`].
    #[inline]
    fn events_now(&self) -> (u16, u32) {
        if let Some(v) = self.memo.events() {
            return v;
        }
        let (e, a) = self.compute_events();
        self.memo.set_events(e, a);
        (e, a)
    }

    /// AL event request 0x0220..0x0223.
    pub fn al_event_request(&self) -> u32 {
        self.events_now().1
    }

    /// ECAT event request 0x0210 (what is ORed into datagram IRQ fields, before the mask).
    pub fn ecat_event_request(&self) -> u16 {
        self.events_now().0
    }

    /// The PDI interrupt line: AL event request & AL event mask (0x0204) != 0.
    pub fn irq_line(&self) -> bool {
        let m = u32::from_le_bytes([
            self.mem[0x0204],
            self.mem[0x0205],
            self.mem[0x0206],
            self.mem[0x0207],
        ]);
        m != 0 && self.al_event_request() & m != 0
    }

    /// SYNC0 and SYNC1 output levels now.
    pub fn sync_lines(&self) -> (bool, bool) {
        self.dc.sync_levels()
    }

    /// Sets the level of latch input `n` (0 or 1) from the current time on (the time of
    /// the last `advance`/`forward`).
    pub fn set_latch_input(&mut self, n: u8, level: bool) {
        self.memo.clear();
        if let Some(l) = self.latch_inputs.get_mut(n as usize) {
            *l = level;
        }
        let t = self.now;
        self.dc.latch_input(&mut self.mem[..REG_END], n, level, t);
        self.events_dirty = true;
    }

    /// Digital outputs 0x0F00..0x0F03 (digital-I/O PDI devices); cleared by the
    /// process-data watchdog.
    pub fn digital_outputs(&self) -> u32 {
        self.dout
    }

    /// Digital inputs sampled into 0x1000..0x1003 (through the SM covering 0x1000, if any).
    pub fn set_digital_inputs(&mut self, v: u32) {
        self.memo.clear();
        let bytes = v.to_le_bytes();
        let n = self
            .active_sms
            .iter()
            .map(|&i| &self.sms[i as usize])
            .find(|sm| sm.start == regs::PROCESS_RAM)
            .map_or(4, |sm| (sm.len as usize).min(4));
        if self.mem.len() >= 0x1004 {
            self.phys_write(Side::Pdi, regs::PROCESS_RAM as u32, &bytes[..n], None);
        }
    }

    /// A fault: the EEPROM acknowledges no write to word `word` or above (a part whose upper
    /// area is write-protected, or worn out). A write command there ends with 0x0502 bit 13
    /// (missing acknowledge), as on a chip whose EEPROM does not answer; reads still work.
    pub fn protect_eeprom_from(&mut self, word: u16) {
        self.eeprom_writable_words = usize::from(word);
    }

    /// Current SII EEPROM content.
    pub fn eeprom(&self) -> &[u8] {
        &self.eeprom
    }

    /// Raw view of 0x0000..end of process RAM (tests).
    pub fn memory(&self) -> &[u8] {
        &self.mem
    }
}

/// Which side owns the SYNC/latch unit register byte `a` per cyclic unit control 0x0980
/// (`Some(true)`: ECAT), or `None` when `a` is not such a register.
#[inline]
fn dc_unit_owner(a: usize, ctrl: u8) -> Option<bool> {
    match a {
        0x0981 | 0x0990..=0x0997 | 0x09A0..=0x09A7 => Some(ctrl & 0x01 == 0),
        0x09A8 => Some(ctrl & 0x10 == 0),
        0x09A9 => Some(ctrl & 0x20 == 0),
        _ => None,
    }
}

/// The register permissions of the chip `cfg` describes: the generic table without the
/// FMMUs/SMs beyond its counts and without the DC parts it lacks.
fn chip_permissions(cfg: &EscConfig) -> Vec<u8> {
    let mut p = PERMISSIONS.to_vec();
    for f in cfg.fmmu_count as usize..16 {
        p[regs::fmmu_reg(f, 0)..regs::fmmu_reg(f + 1, 0)].fill(0);
    }
    for n in cfg.sm_count as usize..16 {
        p[regs::sm_reg(n, 0)..regs::sm_reg(n + 1, 0)].fill(0);
    }
    match cfg.dc {
        DcSupport::Full => {}
        DcSupport::ReceiveTimesOnly => p[0x0910..0x0A00].fill(0),
        DcSupport::None => p[0x0900..0x0A00].fill(0),
    }
    p
}

/// Writable bits of register byte `a` (for registers with read-only bits).
#[inline]
fn bit_mask(a: usize) -> u8 {
    match a {
        0x0120 => 0x3F,
        0x0121 => 0x00,
        0x0500 => 0x03,
        0x0501 => 0x01,
        0x0502 => 0x01,
        0x0503 => 0x07,
        0x0800..=0x087F if a % 8 == 6 => 0x03,
        0x0800..=0x087F if a % 8 == 7 => 0x03,
        _ => 0xFF,
    }
}

/// The circulating bit of the first datagram, `None` if the frame has no datagram.
fn circulating(frame: &[u8]) -> Option<bool> {
    frame.get(9).map(|b| b & 0x40 != 0)
}

fn set_circulating(frame: &mut [u8]) {
    if let Some(b) = frame.get_mut(9) {
        *b |= 0x40;
    }
}
