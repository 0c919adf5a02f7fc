//! The logical fast path: plans of whole SyncManager buffers mapped byte-aligned by FMMUs,
//! and the fused path that runs a cyclic LRW without the generic walk.

use super::*;

/// One step of the logical fast path: a whole SyncManager buffer mapped byte-aligned by
/// an FMMU, pre-resolved when FMMUs or SMs change.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct PlanOp {
    /// Offset of the FMMU's logical range from the plan window's start.
    pub(super) off: u32,
    /// Length in bytes (= the SM length).
    pub(super) len: u32,
    /// SM index.
    pub(super) sm: u8,
}

/// Most FMMUs a fast-path plan holds (more take the general route).
pub(super) const PLAN_MAX: usize = 4;

/// One step of the fused path: a whole buffered-mode SM buffer, byte-aligned.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct FusedStep {
    /// Offset of the step's bytes in the frame the key describes (set with the key, from
    /// the plan step's window offset).
    pub(super) at: u16,
    /// The SM's start address (in process RAM) and length (one buffer).
    pub(super) ram: u16,
    pub(super) len: u16,
    /// SM index.
    pub(super) sm: u8,
    /// ECAT writes the SM (a write step; otherwise a read step).
    pub(super) write: bool,
}

/// The fused path (`Esc::forward_fused`): a frame entering port 0 with a good FCS that
/// holds a single logical datagram covering the plan window, at an ESC whose plan steps
/// are all distinct buffered-mode (3-buffer) SMs in process RAM and which has an open
/// port (the frame does not loop back into the processing unit). Rebuilt with the plan and
/// on port changes. What a frame reads, in one cache line ([`FusedPlan`] holds what only
/// the frame checks read).
#[derive(Debug, Clone, Copy, Default)]
#[repr(C)]
pub(super) struct Fused {
    /// The last frame the fused path took (see [`FusedKey`]); a cyclic master sends the
    /// same headers every cycle, so the frame checks reduce to one comparison.
    pub(super) key: FusedKey,
    /// The fused path applies to this ESC's configuration.
    pub(super) ok: bool,
    /// `ok`, and a frame's arrival at port 0 needs nothing of the DC unit but the
    /// start-of-frame time (no receive-time latch armed; [`Esc::gate_routes`]): the
    /// fused path then does not touch the DC unit.
    pub(super) on: bool,
    /// Port the frame leaves through (first open port after port 0).
    pub(super) exit: u8,
    /// The steps the key's command runs (`key.n` of them, in plan order: the reads for
    /// LRD, the writes for LWR, all for LRW), with their frame offsets; set with the key.
    pub(super) run: [FusedStep; PLAN_MAX],
}

/// The rest of the fused path's pre-resolved state (rebuilt with [`Fused`]), read only by
/// the frame checks when the key changes.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct FusedPlan {
    /// Some write step's SM triggers the process-data watchdog.
    pub(super) wd: bool,
    /// The plan's steps (`steps[k]` is `plan[k]`): `nr` read steps (run by LRD and LRW),
    /// then `nw` write steps (run by LWR and LRW), each in FMMU order.
    pub(super) nr: u8,
    pub(super) nw: u8,
    pub(super) steps: [FusedStep; PLAN_MAX],
    /// Plan window `[lo, hi)` (logical bytes).
    pub(super) lo: u64,
    pub(super) hi: u64,
}

/// [`Fused`] fills one cache line: with the `Esc` fields before it, the `SmBank` after it
/// starts the next line.
const _: () = assert!(core::mem::size_of::<Fused>() <= 64);

/// What the fused path's frame checks depend on, and what they derived, for the last frame
/// they accepted (with this configuration: `rebuild_fused` starts afresh). The checks read
/// nothing but the EtherCAT header word, the datagram header's command, address and
/// length/flags words and the frame's length, so a frame equal in those passes them with
/// the same results; what the frame then does (which steps run, where the window and the
/// working counter lie in the frame, the counter's increment) follows from them too.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C)]
pub(super) struct FusedKey {
    /// Frame bytes 0..8 (EtherCAT header word, command, index, address) with the index
    /// masked out ([`FusedKey::words`]).
    pub(super) lo: u64,
    /// Frame bytes 8..10 (datagram length and flags) and, from bit 16, the frame length
    /// (0: no frame accepted yet; a taken frame has at least 12 bytes).
    pub(super) hi: u64,
    /// Offset of the working counter in the frame.
    pub(super) wkc_at: u16,
    /// Working-counter increment (LRD, LWR, LRW: from the read and write steps).
    pub(super) inc: u16,
    /// How many steps the command runs ([`Fused::run`]).
    pub(super) n: u8,
    /// The command runs a watchdog-triggering write step.
    pub(super) wd: bool,
}

impl FusedKey {
    /// The key words ([`FusedKey::lo`], [`FusedKey::hi`]) of a frame of `len` bytes that
    /// starts with `head`.
    #[inline(always)]
    pub(super) fn words(head: &[u8; 12], len: usize) -> (u64, u64) {
        let (a, rest) = head.split_first_chunk::<8>().unwrap_or((&[0; 8], &[]));
        let lo = u64::from_le_bytes(*a) & !0xFF00_0000;
        let hi = u64::from(u16::from_le_bytes([rest[0], rest[1]])) | (len as u64) << 16;
        (lo, hi)
    }
}

impl Esc {
    pub(super) fn rebuild_active_sms(&mut self) {
        self.active_sms.clear();
        for (i, sm) in self.sms.iter().enumerate().take(self.cfg.sm_count as usize) {
            if sm.enabled {
                self.active_sms.push(i as u8);
            }
        }
    }

    pub(super) fn rebuild_fmmus(&mut self) {
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
                // Not over registers: the fused copies bypass register write rights.
                sm.start as usize >= REG_END
                    && sm.start as u32 == ps
                    && sm.end() == pe
                    && sm.ecat_writes() == f.write
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
    pub(super) fn rebuild_plan(&mut self) {
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
    pub(super) fn rebuild_fused(&mut self) {
        let mut f = Fused::default();
        let mut p = FusedPlan::default();
        // Exit port of a frame entering port 0: the first open port in processing order
        // (port 0 itself last; all closed: the frame loops back, generic path).
        let exit = [3u8, 1, 2, 0].into_iter().find(|&p| self.port_open(p));
        let n = self.plan_len as usize;
        let mut ok = !self.fast_off && self.plan_ok && n > 0 && exit.is_some();
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
            let st = FusedStep {
                at: 0,
                write: k >= self.plan_reads as usize,
                ram: sm.start,
                len: sm.len,
                sm: op.sm,
            };
            // Reads first, then writes (the plan's order).
            p.steps[k] = st;
            if k >= self.plan_reads as usize {
                p.nw += 1;
                p.wd |= sm.ctrl & CTRL_WD_TRIGGER != 0;
            } else {
                p.nr += 1;
            }
        }
        if ok {
            f.ok = true;
            f.exit = exit.unwrap_or(0);
            p.lo = self.plan_lo;
            p.hi = self.plan_hi;
        } else {
            f = Fused::default();
            p = FusedPlan::default();
        }
        self.fused = f;
        self.fused_plan = p;
        self.gate_routes();
    }

    /// Rebuilds [`Esc::route`] from the open ports: the exit `forward_after_arrival`'s
    /// port loop finds for a frame entering each port, where it finds one before the
    /// frame would loop back through a closed port 0 into the processing unit.
    pub(super) fn rebuild_routes(&mut self) {
        let open = self.open_ports;
        self.route_base = core::array::from_fn(|p| {
            let mut cur = p as u8;
            for _ in 0..8 {
                let nxt = next_port(cur);
                if open & (1 << nxt) != 0 {
                    return if self.fast_off { NO_ROUTE } else { nxt };
                }
                if nxt == 0 {
                    break;
                }
                cur = nxt;
            }
            NO_ROUTE
        });
        self.gate_routes();
    }

    /// [`Esc::route`] from [`Esc::route_base`]: ports 1..3 take the general path while the
    /// EEPROM write cycle is under way (its end is settled there) or a receive-time latch
    /// is armed for the port (latched there); and [`Fused::on`]: port 0 takes it while a
    /// latch is armed anywhere (the window ends there). Called wherever either changes:
    /// the write command that starts the cycle, the settle that ends it, DC writes (0x0900
    /// arms the latches), the DC unit's frame arrivals (which latch or end the window)
    /// and the fused path's rebuild.
    pub(super) fn gate_routes(&mut self) {
        self.fused.on = self.fused.ok && !self.dc.arrival0_needs_more();
        let busy = self.sii_busy_until.is_some();
        let base = self.route_base;
        let dc = &self.dc;
        self.route = core::array::from_fn(|p| {
            if p != 0 && (busy || dc.arrival_needs_regs(p as u8)) {
                NO_ROUTE
            } else {
                base[p]
            }
        });
    }

    /// Reference switch for differential tests and benchmarks: with `false` every frame
    /// takes the general path (`forward_generic`: no fused LRW path, no pass-through
    /// shortcut for frames that only pass the ESC) and [`Esc::query_epoch`] answers
    /// `None`, so a segment re-reads the ESC's next event and IRQ line after every hop;
    /// the system-time write (0x0910..0x0917) takes the general register path (and in
    /// the crate's tests the DC unit its general paths too).
    /// The observable behaviour is the same either way; on by default.
    pub fn set_fast_paths(&mut self, on: bool) {
        self.memo.clear();
        self.fast_off = !on;
        #[cfg(test)]
        self.dc.set_slow(!on);
        self.rebuild_routes();
        self.rebuild_fused();
    }
}

/// The port after `p` in the ESC's processing order 0 → 3 → 1 → 2 → 0.
#[inline(always)]
pub(super) fn next_port(p: u8) -> u8 {
    match p {
        0 => 3,
        3 => 1,
        1 => 2,
        _ => 0,
    }
}
