//! The register file and its access rules: reads and writes from either side with
//! permissions, read-only bits, side effects, SyncManager buffers and mailboxes.

use super::*;

/// Which side owns the SYNC/latch unit register byte `a` per cyclic unit control 0x0980
/// (`Some(true)`: ECAT), or `None` when `a` is not such a register.
#[inline]
pub(super) fn dc_unit_owner(a: usize, ctrl: u8) -> Option<bool> {
    match a {
        0x0981 | 0x0990..=0x0997 | 0x09A0..=0x09A7 => Some(ctrl & 0x01 == 0),
        0x09A8 => Some(ctrl & 0x10 == 0),
        0x09A9 => Some(ctrl & 0x20 == 0),
        _ => None,
    }
}

/// The register permissions of the chip `cfg` describes: the generic table without the
/// FMMUs/SMs beyond its counts and without the DC parts it lacks.
pub(super) fn chip_permissions(cfg: &EscConfig) -> Vec<u8> {
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
pub(super) fn bit_mask(a: usize) -> u8 {
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

impl Esc {
    /// The next piece of `[cur, end)`: its end and the SM that covers it, if any.
    #[inline]
    pub(super) fn piece(&self, cur: u32, end: u32) -> (u32, Option<usize>) {
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
    pub(super) fn phys_read(&mut self, side: Side, addr: u32, out: &mut [u8], or: bool) -> bool {
        if self.plain_registers(addr, out.len()) {
            // What `plain_read` does for registers that all exist, with no DC or event
            // refresh due and no SyncManager over them: the firmware's polls (SM status,
            // watchdog status, AL control) and the master's AL-status reads.
            let c = addr as usize;
            let e = c + out.len();
            let src = &self.mem[c..e];
            if or {
                for (x, y) in out.iter_mut().zip(src) {
                    *x |= *y;
                }
            } else {
                out.copy_from_slice(src);
            }
            self.read_side_effects(side, c, e);
            return true;
        }
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

    /// Whether `[addr, addr + len)` is a non-empty run of registers that all exist in this
    /// chip, outside the DC unit (0x0900..0x09FF: its reads latch and acknowledge) and the
    /// event registers (0x0210..0x0223: read after a refresh), with no active SyncManager
    /// over any of its bytes: [`Esc::phys_read`] then reads it as plain memory. Never with
    /// the fast paths off (the general path is the reference).
    #[inline(always)]
    fn plain_registers(&self, addr: u32, len: usize) -> bool {
        let c = addr as usize;
        let e = c + len;
        if self.fast_off
            || len == 0
            || e > REG_END
            || (c < 0x0A00 && e > 0x0900)
            || (c < 0x0224 && e > 0x0210)
        {
            return false;
        }
        let Some(perm) = self.perm.get(c..e) else {
            return false;
        };
        if perm.iter().any(|&p| p & P_IMPL == 0) {
            return false;
        }
        self.active_sms.iter().all(|&i| {
            let sm = &self.sms[i as usize];
            sm.start as u32 >= e as u32 || sm.end() <= addr
        })
    }

    /// Writes physical memory as `side` (SyncManager rules and register permissions
    /// applied); `mask` selects the bits to write. Returns true when the access counts: at
    /// least one byte is writable by `side` in this chip and no SyncManager refused.
    pub(super) fn phys_write(
        &mut self,
        side: Side,
        addr: u32,
        data: &[u8],
        mask: Option<&[u8]>,
    ) -> bool {
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

    pub(super) fn copy_out(&self, from: u32, o: &mut [u8], or: bool) {
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

    pub(super) fn store(&mut self, to: u32, d: &[u8], m: Option<&[u8]>) {
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
    pub(super) fn plain_read(&mut self, side: Side, cur: u32, o: &mut [u8], or: bool) -> bool {
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

    pub(super) fn read_side_effects(&mut self, side: Side, c: usize, e: usize) {
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
    pub(super) fn plain_write(&mut self, side: Side, cur: u32, d: &[u8], m: Option<&[u8]>) -> bool {
        let c = cur as usize;
        let full_end = c + d.len();
        if c >= REG_END {
            self.store(cur, d, m);
            return c < self.mem.len();
        }
        if c >= 0x0910 && full_end <= 0x0918 && !self.fast_off {
            return self.system_time_write(side, c, d, m);
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

    /// [`plain_write`](Self::plain_write) of bytes within the DC system time
    /// 0x0910..0x0917 (the FRMW that distributes the reference time, every cycle): what
    /// the general path does there, without its checks for the registers elsewhere (AL
    /// control, SII, SyncManagers, the SYNC unit's owner, read-only bits: none of them
    /// applies to these bytes) — the permissions, the good-FCS rule, the store and the
    /// only side effect, the DC unit's.
    fn system_time_write(&mut self, side: Side, c: usize, d: &[u8], m: Option<&[u8]>) -> bool {
        let e = c + d.len();
        let bit = if side == Side::Ecat { P_ECAT } else { P_PDI };
        if !self.perm[c..e].iter().any(|&p| p & bit != 0) {
            return false;
        }
        if side == Side::Ecat && !self.frame_ok {
            return true;
        }
        for (k, a) in (c..e).enumerate() {
            let p = self.perm[a];
            if p & bit == 0 {
                continue;
            }
            if p & P_CLEAR != 0 {
                self.mem[a] = 0;
                continue;
            }
            let bm = m.map_or(0xFF, |m| m[k]);
            self.mem[a] = (self.mem[a] & !bm) | (d[k] & bm);
        }
        self.dc.set_sof0(self.sof0);
        self.dc.after_write(
            &mut self.mem[..REG_END],
            c as u16,
            (e - c) as u16,
            self.now,
            side == Side::Ecat,
        );
        self.gate_routes();
        self.events_dirty = true;
        true
    }

    pub(super) fn write_side_effects(
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
            if ok_owner && self.sii_busy_until.is_some() {
                // A write cycle runs: the EEPROM acknowledges nothing (bit 13).
                sii::refuse_while_busy(&mut self.mem, written);
            } else if ok_owner {
                let read8 = self.cfg.sii_read_8_bytes;
                let out = sii::execute(
                    &mut self.mem,
                    &mut self.eeprom,
                    written,
                    read8,
                    self.eeprom_writable_words,
                );
                match out {
                    sii::SiiOutcome::Reloaded(_) => self.update_dl_status(true),
                    sii::SiiOutcome::Written => {
                        sii::begin_write_cycle(&mut self.mem);
                        self.sii_busy_until = Some(self.now.saturating_add(sii::WRITE_CYCLE_NS));
                        self.gate_routes();
                    }
                    _ => {}
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
            // The frame time of ECAT writes: the start of frame the ESC kept.
            self.dc.set_sof0(self.sof0);
            self.dc.after_write(
                &mut self.mem[..REG_END],
                a as u16,
                (b - a) as u16,
                self.now,
                ecat,
            );
            // A write to 0x0900 arms the receive-time latches.
            self.gate_routes();
            self.events_dirty = true;
        }
        if over(0x0F00, 0x0F04) && side == Side::Ecat {
            let mut v = [0u8; 4];
            v.copy_from_slice(&self.mem[0x0F00..0x0F04]);
            self.dout = u32::from_le_bytes(v);
        }
    }

    pub(super) fn sm_read(
        &mut self,
        i: usize,
        side: Side,
        cur: u32,
        o: &mut [u8],
        or: bool,
    ) -> bool {
        let sm = &mut self.sms[i];
        let refuse = sm.is_producer(side)
            || if cur == sm.start as u32 {
                !sm.open_read()
            } else {
                !sm.read_open()
            };
        if refuse {
            if side == Side::Pdi {
                // The PDI sees the raw memory; nothing changes.
                self.copy_out(cur, o, or);
            }
            return false;
        }
        let off = sm.buf_offset(sm.user_buf());
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
    pub(super) fn sm_read_whole(&mut self, i: usize, o: &mut [u8]) -> bool {
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
    pub(super) fn sm_write_whole(&mut self, i: usize, d: &[u8]) -> bool {
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

    pub(super) fn sm_write(
        &mut self,
        i: usize,
        side: Side,
        cur: u32,
        d: &[u8],
        m: Option<&[u8]>,
    ) -> bool {
        let sm = &mut self.sms[i];
        let refuse = !sm.is_producer(side)
            || if cur == sm.start as u32 {
                !sm.open_write()
            } else {
                !sm.write_open()
            };
        if refuse {
            return false;
        }
        let off = sm.buf_offset(sm.write_buf());
        let done = cur + d.len() as u32 == sm.end();
        let to = cur + off;
        if (to as usize) < REG_END {
            self.sm_register_store(side, to, d, m);
        } else {
            self.store(to, d, m);
        }
        let sm = &mut self.sms[i];
        if done {
            if side == Side::Ecat {
                sm.close_write_pending();
                self.pending_sms |= 1 << i;
            } else {
                sm.close_write();
                self.commit_sm(i, side);
                return true;
            }
        }
        let status = self.sms[i].status_reg();
        self.mem[regs::sm_reg(i, 5)] = status;
        self.events_dirty = true;
        true
    }

    /// A SyncManager over registers buffers the access, but its bytes land in registers.
    /// The digital outputs (0x0F00..0x0F04) are the registers an SM is meant for: their
    /// bytes are stored and take effect at commit, as RAM buffers do (ECAT: only with a
    /// good FCS). Any other register is written as a plain register write: its write
    /// rights, the good-FCS rule and its side effects apply.
    fn sm_register_store(&mut self, side: Side, to: u32, d: &[u8], m: Option<&[u8]>) {
        const DOUT: core::ops::Range<u32> = 0x0F00..0x0F04;
        let end = to + d.len() as u32;
        let mut cur = to;
        while cur < end {
            let in_dout = DOUT.contains(&cur);
            let pe = if in_dout {
                end.min(DOUT.end)
            } else if cur < DOUT.start {
                end.min(DOUT.start)
            } else {
                end
            };
            let (a, b) = ((cur - to) as usize, (pe - to) as usize);
            let m = m.map(|m| &m[a..b]);
            if !in_dout {
                let _ = self.plain_write(side, cur, &d[a..b], m);
            } else if side == Side::Pdi || self.frame_ok {
                self.store(cur, &d[a..b], m);
            }
            cur = pe;
        }
    }

    pub(super) fn commit_sm(&mut self, i: usize, side: Side) {
        let sm = &mut self.sms[i];
        sm.commit();
        let status = sm.status_reg();
        let wd = sm.ctrl & CTRL_WD_TRIGGER != 0;
        let start = sm.start as u32;
        let end = sm.end();
        let off = sm.buf_offset(sm.last_written().min(2));
        self.mem[regs::sm_reg(i, 5)] = status;
        self.events_dirty = true;
        if side == Side::Ecat && wd {
            self.pd_wd_last = Some(self.now);
            self.pd_wd_forced = NO_DEADLINE;
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

    pub(super) fn reload_sm(&mut self, i: usize) {
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
}
