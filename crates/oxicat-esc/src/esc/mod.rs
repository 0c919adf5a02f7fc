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

use oxicat_wire::{view, Command, DatagramMut, WireError};

use crate::config::{DcSupport, EscConfig};
use crate::dc::Dc;
use crate::dispatch::FrameDispatch;
use crate::fmmu::{get_bit, set_bit, Fmmu, Overlap};
use crate::regs::{self, PERMISSIONS, P_CLEAR, P_ECAT, P_IMPL, P_PDI};
use crate::sii;
use crate::sm::{Side, Sm, CTRL_WD_TRIGGER};

mod datagram;
mod events;
mod fastpath;
mod regfile;

use events::QueryMemo;
use fastpath::{Fused, FusedPlan, PlanOp, PLAN_MAX};
use regfile::chip_permissions;

/// Where a frame leaves the ESC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Forward {
    /// Out of this port.
    Port(u8),
    /// Destroyed (circulating frame).
    Dropped,
}

impl Forward {
    /// The egress port, `None` when the frame was dropped.
    #[inline]
    pub fn port(self) -> Option<u8> {
        match self {
            Forward::Port(p) => Some(p),
            Forward::Dropped => None,
        }
    }
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

// Shared facts from `oxicat-wire`: the AL/ECAT event bits, the register-file end and the
// frame and datagram header sizes.
const AL_EV_CONTROL: u32 = regs::EV_AL_CONTROL;
const AL_EV_SM_CHANGE: u32 = regs::EV_SM_CHANGE;
const AL_EV_WD: u32 = regs::EV_WATCHDOG;
const ECAT_EV_DL: u16 = regs::ECAT_EV_DL_STATUS;
const ECAT_EV_AL: u16 = regs::ECAT_EV_AL_STATUS;
const REG_END: usize = regs::PROCESS_RAM as usize;
const ECAT_HEADER_LEN: usize = oxicat_wire::frame::ECAT_HEADER_LEN;
const DG_HEADER_LEN: usize = oxicat_wire::datagram::DATAGRAM_HEADER_LEN;
/// Command codes of the logical datagrams.
const CMD_LRD: u8 = Command::Lrd as u8;
const CMD_LWR: u8 = Command::Lwr as u8;
const CMD_LRW: u8 = Command::Lrw as u8;
const CMD_FPRD: u8 = Command::Fprd as u8;
const CMD_FPRW: u8 = Command::Fprw as u8;
/// Start of the next ESC's query epoch, in units of 2^32 ([`Esc::query_epoch`]): two
/// ESCs, e.g. an old and a new one in the same place, never share an epoch.
static EPOCH_BASE: AtomicU32 = AtomicU32::new(0);

/// [`Esc::pd_wd_forced`]: no injected expiry.
const NO_DEADLINE: u64 = u64::MAX;

/// [`Esc::route`]: no shortcut (the frame goes through the processing unit again).
const NO_ROUTE: u8 = 0xFF;
/// PDI control 0x0140 value of the digital I/O PDI.
const PDI_DIGITAL_IO: u8 = 0x04;

/// Copies `s` into `d` (equal lengths): process-data images are small, and a call into
/// `memcpy` costs more than the copy. 16..=64 bytes take two or four overlapping 16-byte
/// moves (no loop), 4..16 bytes two overlapping 4- or 8-byte moves; other lengths take
/// `copy_from_slice` out of line.
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
        copy_other(d, s);
    }
}

/// [`copy_small`] for lengths under 4 or over 64 (out of line: the fast paths' loops then
/// keep no state for it).
#[cold]
#[inline(never)]
fn copy_other(d: &mut [u8], s: &[u8]) {
    d.copy_from_slice(s);
}

/// The SyncManagers from a cache-line boundary: SM0..SM3 share one line (the usual
/// assignment: SM0/SM1 mailbox, SM2/SM3 process data), the one right after the fused
/// path's ([`Fused`]), so that a fused frame touches consecutive lines of the `Esc`.
/// Derefs to the array.
#[derive(Debug, Clone)]
#[repr(C, align(64))]
struct SmBank {
    sms: [Sm; 16],
}

impl core::ops::Deref for SmBank {
    type Target = [Sm; 16];
    #[inline(always)]
    fn deref(&self) -> &[Sm; 16] {
        &self.sms
    }
}

impl core::ops::DerefMut for SmBank {
    #[inline(always)]
    fn deref_mut(&mut self) -> &mut [Sm; 16] {
        &mut self.sms
    }
}

/// A software EtherCAT Slave Controller.
///
/// `repr(C)`: the fields a frame touches come first, in the order of use (the pass-through
/// shortcut, then the fused LRW path), so that a hop touches few cache lines (a line of
/// hundreds of ESCs does not fit in L1), from a cache-line boundary.
#[derive(Debug, Clone)]
#[repr(C, align(64))]
pub struct Esc {
    now: u64,
    /// End of the EEPROM write cycle under way ([`sii::WRITE_CYCLE_NS`] after the write
    /// command): until then 0x0502 shows busy and refuses commands.
    pub(crate) sii_busy_until: Option<u64>,
    pd_wd_last: Option<u64>,
    /// An injected expiry ([`Esc::expire_pd_watchdog`]): the deadline, until it expires or
    /// a write retriggers the watchdog ([`NO_DEADLINE`]: none).
    pd_wd_forced: u64,
    /// Arrival time of the last frame at port 0 (the DC unit's start-of-frame time, which
    /// the fused path keeps here: handed to the DC unit before a write to its registers).
    sof0: u64,
    /// Where a frame entering port `p` leaves when it does not reach the processing unit
    /// on its way (the port order 0 → 3 → 1 → 2 → 0 over the open ports, stopping at port
    /// 0 if it is open); [`NO_ROUTE`] when it would loop back through a closed port 0 into
    /// the processing unit, or when the fast paths are off. For port 0, where the frame
    /// leaves after processing. Rebuilt with the open ports. For ports 1..3 also
    /// [`NO_ROUTE`] while the EEPROM write cycle is under way or a receive-time latch is
    /// armed for the port ([`Esc::gate_routes`]): then the SII settle and the DC arrival
    /// have work, and the general path does it.
    route: [u8; 4],
    /// Reference switch ([`Esc::set_fast_paths`]): no fused path, no pass-through
    /// shortcut, no [`Esc::query_epoch`].
    fast_off: bool,
    events_dirty: bool,
    ecat_mask: u16,
    ecat_irq: u16,
    /// See [`QueryMemo`].
    memo: QueryMemo,
    mem: Vec<u8>,
    /// Hot state of the fused LRW path (one line).
    fused: Fused,
    /// SyncManagers; the chip has the first `cfg.sm_count` (the others stay disabled).
    sms: SmBank,
    /// The fused path's state that only its frame checks read.
    fused_plan: FusedPlan,
    dc: Dc,
    /// Frames the fused path processed (tests).
    #[cfg(test)]
    pub(crate) fused_hits: u64,
    /// Frames the pass-through shortcut passed (tests).
    #[cfg(test)]
    pub(crate) pass_hits: u64,
    cfg: EscConfig,
    /// Per-byte permissions of this chip's register file (the generic table with the
    /// FMMUs, SMs and DC parts the chip lacks removed).
    perm: Vec<u8>,
    /// AL control written by ECAT and not yet read by the PDI (no device emulation: the
    /// register then behaves like a mailbox and refuses further ECAT writes).
    al_ctl_unread: bool,
    eeprom: Vec<u8>,
    /// Words below this acknowledge writes ([`Esc::protect_eeprom_from`]).
    eeprom_writable_words: usize,
    link: [bool; 4],
    /// [`Esc::route`] from the open ports alone (before [`Esc::gate_routes`]).
    route_base: [u8; 4],
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
    frame_ok: bool,
    /// SMs (bit n) with a producer write completed by ECAT in the current frame.
    pending_sms: u16,
    open_ports: u8,
    ecat_ev: u16,
    al_ev: u32,
    dout: u32,
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
        let memo = QueryMemo {
            epoch: u64::from(EPOCH_BASE.fetch_add(1, Ordering::Relaxed)) << 32,
            ..QueryMemo::default()
        };
        let mut esc = Self {
            memo,
            fused: Fused::default(),
            fused_plan: FusedPlan::default(),
            fast_off: false,
            route: [NO_ROUTE; 4],
            route_base: [NO_ROUTE; 4],
            #[cfg(test)]
            fused_hits: 0,
            #[cfg(test)]
            pass_hits: 0,
            cfg,
            mem,
            perm,
            al_ctl_unread: false,
            eeprom,
            eeprom_writable_words: usize::MAX,
            sii_busy_until: None,
            dc,
            link: [true, false, false, false],
            sms: SmBank { sms },
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
            pd_wd_forced: NO_DEADLINE,
            sof0: u64::MAX,
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
    ///
    /// The memo of the event requests ([`QueryMemo`]) outlives a read that cannot have
    /// changed them: one of registers outside the DC unit (0x0900..0x09FF) and every
    /// SyncManager's area, whose side effects (AL control, watchdog status, SM activate
    /// reads, the PDI watchdog's DL status bit) left the ECAT and AL event bits as they
    /// were. The firmware's main loop polls SM0 status and SM1 activate that way at every
    /// pass; the interrupt line after it is then read from the memo instead of computed,
    /// and such a read of the SyncManager registers (0x0800..0x08FF, no SM-change event
    /// to clear) copies the bytes without the general path's piece-by-piece walk. The
    /// next-event memo always goes (the access retriggers the PDI watchdog). With the
    /// fast paths off ([`Esc::set_fast_paths`]) neither shortcut is taken.
    pub fn pdi_read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), PdiError> {
        let events = if self.fast_off {
            None
        } else {
            self.memo.events()
        };
        self.memo.clear();
        self.pdi_range(addr, buf.len())?;
        let bits = (self.ecat_ev, self.al_ev);
        self.sii_settle(self.now);
        self.pdi_access();
        let start = addr as u32;
        let end = start + buf.len() as u32;
        let plain = (end <= 0x0900 || start >= 0x0A00) && self.piece(start, end) == (end, None);
        if plain
            && !self.fast_off
            && start >= 0x0800
            && end <= 0x0900
            && self.al_ev & AL_EV_SM_CHANGE == 0
        {
            // What `plain_read` does there: the bytes the chip has, 0 for the others, and
            // no side effect (SM activate clears only a pending SM-change event).
            for (o, a) in buf.iter_mut().zip(start as usize..) {
                *o = if self.perm[a] & P_IMPL != 0 {
                    self.mem[a]
                } else {
                    0
                };
            }
        } else {
            self.phys_read(Side::Pdi, start, buf, false);
        }
        if let Some((e, a)) = events {
            if plain && (self.ecat_ev, self.al_ev) == bits {
                self.memo.set_events(e, a);
            }
        }
        Ok(())
    }

    /// PDI write of `data` at `addr` (bytes the PDI may not write are ignored, as in
    /// silicon; SyncManager rules apply).
    pub fn pdi_write(&mut self, addr: u16, data: &[u8]) -> Result<(), PdiError> {
        self.memo.clear();
        self.pdi_range(addr, data.len())?;
        self.sii_settle(self.now);
        self.pdi_access();
        self.phys_write(Side::Pdi, addr as u32, data, None);
        Ok(())
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

    /// Ends the EEPROM write cycle if it is over at `t` (0x0502 busy clears). Called where
    /// 0x0502 can be seen or written (frames, PDI accesses, time passing), so the cycle
    /// follows the virtual clock without an event of its own.
    #[inline]
    pub(super) fn sii_settle(&mut self, t: u64) {
        if let Some(d) = self.sii_busy_until {
            if t >= d {
                self.sii_busy_until = None;
                sii::end_write_cycle(&mut self.mem);
                self.gate_routes();
            }
        }
    }

    /// A fault: the process-data (SM) watchdog expires at the next time step, as when the
    /// master's outputs stop for longer than the watchdog time (a late cycle), with what an
    /// expiry does (0x0440 bit 0 cleared, 0x0442 counted, the AL event, digital outputs
    /// cleared); the master's next output write retriggers it. `false` when it is not
    /// running (no write to a watchdog-triggering SM yet, or watchdog time 0).
    pub fn expire_pd_watchdog(&mut self) -> bool {
        if self.pd_wd_deadline().is_none() {
            return false;
        }
        // One nanosecond on: a caller that already brought this ESC to `now` (the segment)
        // takes an event at `now` as done.
        self.pd_wd_forced = self.now + 1;
        self.memo.clear();
        true
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
