//! Frames and datagrams: the fused and generic forward paths, the datagram walk, physical
//! and logical addressing with the working-counter rules, FMMU redirection.

use super::*;

/// The circulating bit of the first datagram, `None` if the frame has no datagram.
pub(super) fn circulating(frame: &[u8]) -> Option<bool> {
    frame.get(9).map(|b| b & 0x40 != 0)
}

pub(super) fn set_circulating(frame: &mut [u8]) {
    if let Some(b) = frame.get_mut(9) {
        *b |= 0x40;
    }
}

impl Esc {
    /// A frame's first bit reaches `port` at time `t`; see the API contract. Returns the
    /// port the frame leaves through or `Dropped` (circulating frame rule).
    #[inline(always)]
    pub fn forward(&mut self, port: u8, frame: &mut [u8], t: u64, frame_ok: bool) -> Forward {
        // The pass-through shortcut first, inlined into the caller: on a line every frame
        // passes every ESC but the last once without being processed (the way back).
        if let Some(out) = self.pass_through(port, t, frame_ok) {
            return out;
        }
        // The fused path inlined too (a call's register saves cost as much as a third of
        // it); every other frame out of line.
        if port == 0 && frame_ok && self.fused.on {
            return self.forward_fused(frame, t);
        }
        self.forward_generic(port, frame, t, frame_ok, None)
    }

    /// [`Esc::forward`] for a good frame entering port 0 at an ESC where the fused path
    /// applies: the fused path if it takes the frame, the general path after the arrival
    /// otherwise.
    #[inline(always)]
    fn forward_fused(&mut self, frame: &mut [u8], t: u64) -> Forward {
        // The memo is cleared where the frame is processed (`process_frame`, the fused
        // path): a frame that only passes (arriving at port 1..3 and leaving without a
        // visit to the processing unit) changes the SII settle, a DC receive time and the
        // RX error counters, none of which the memo's answers read.
        //
        // The SII settle is left to the next access that can see it (every other entry
        // settles first: a frame on any other path, the PDI, `advance`): the fused path
        // reads and writes nothing of the EEPROM interface.
        //
        // The DC arrival: `fused.on` says it is the start-of-frame time alone, kept here.
        self.memo.clear();
        self.now = t;
        self.sof0 = t;
        if let Some(out) = self.process_fused(frame, t) {
            return out;
        }
        self.fused_declined(frame, t, None)
    }

    /// A frame the fused path declined after its arrival: the general path from there
    /// (the SII settle first, as in `forward_generic`).
    #[cold]
    #[inline(never)]
    fn fused_declined(
        &mut self,
        frame: &mut [u8],
        t: u64,
        d: Option<&mut FrameDispatch>,
    ) -> Forward {
        self.sii_settle(t);
        self.forward_after_arrival(0, frame, true, d)
    }

    /// The pass-through shortcut: a good frame entering port 1..3 that leaves again
    /// without reaching the processing unit (`route`). What `forward_generic` does for it,
    /// without its port loop: the time; the SII settle and the DC arrival have nothing to
    /// do (`route` sends the frame the general way while the EEPROM write cycle runs or a
    /// receive-time latch is armed for the port: [`Esc::gate_routes`]); no RX error to
    /// count, nothing processed, the memo untouched (as there).
    #[inline(always)]
    fn pass_through(&mut self, port: u8, t: u64, frame_ok: bool) -> Option<Forward> {
        let p = port & 3;
        let out = self.route[p as usize];
        if p == 0 || out == NO_ROUTE || !frame_ok {
            return None;
        }
        #[cfg(test)]
        {
            self.pass_hits += 1;
        }
        self.now = t;
        Some(Forward::Port(out))
    }

    /// [`Esc::forward`] with the frame's configured-address index `d` (built by the
    /// segment once per frame, see [`FrameDispatch`]): the same effects on the ESC and the
    /// frame, except that the IRQ bits this ESC ORs into configured-address datagrams for
    /// other stations are recorded in `d` ([`FrameDispatch::apply_irq`] writes them).
    #[inline]
    pub fn forward_dispatched(
        &mut self,
        port: u8,
        frame: &mut [u8],
        t: u64,
        frame_ok: bool,
        d: &mut FrameDispatch,
    ) -> Forward {
        if !d.is_active() {
            return self.forward(port, frame, t, frame_ok);
        }
        if let Some(out) = self.pass_through(port, t, frame_ok) {
            return out;
        }
        self.forward_dispatched_processed(port, frame, t, frame_ok, d)
    }

    /// [`Esc::forward_dispatched`] for an active index and a frame the pass-through
    /// shortcut declined.
    fn forward_dispatched_processed(
        &mut self,
        port: u8,
        frame: &mut [u8],
        t: u64,
        frame_ok: bool,
        d: &mut FrameDispatch,
    ) -> Forward {
        if port == 0 && frame_ok {
            if let Some(out) = self.pass_foreign(t, d) {
                return out;
            }
        }
        if port == 0 && frame_ok && self.fused.ok {
            self.memo.clear();
            // As `forward`; the fused path declines the frame (it takes frames of one
            // logical datagram, and this one has a configured-address datagram).
            self.now = t;
            self.dc_arrival(0, t);
            return self.fused_declined(frame, t, Some(d));
        }
        self.forward_generic(port, frame, t, frame_ok, Some(d))
    }

    /// The DC unit sees a frame's first bit at `port` (`Dc::frame_arrival`), the register
    /// file only when the unit needs it.
    #[inline(always)]
    fn dc_arrival(&mut self, port: u8, t: u64) {
        if port == 0 {
            self.sof0 = t;
        }
        // At port 0 an armed latch anywhere: the window ends, and the routes reopen.
        let slow = if port == 0 {
            self.dc.arrival0_needs_more()
        } else {
            self.dc.arrival_needs_regs(port)
        };
        if slow {
            self.dc_arrival_slow(port, t);
        } else {
            self.dc.frame_arrival_quiet(port, t);
        }
    }

    #[cold]
    #[inline(never)]
    fn dc_arrival_slow(&mut self, port: u8, t: u64) {
        self.dc.frame_arrival(&mut self.mem[..REG_END], port, t);
        // The arrival may have latched a receive time or ended the latch window.
        self.gate_routes();
    }

    /// The foreign-frame shortcut: a good frame entering port 0 whose datagrams are all
    /// configured-address ones for other stations (`d` has none every ESC processes and
    /// none for this station address or enabled alias), leaving through `route[0]`. What
    /// the general path does for it: time, the SII settle, the DC arrival, this ESC's IRQ
    /// bits recorded for the whole frame (`walk_dispatched` finds one run), the exit
    /// port; nothing is processed, so the memo stays (its answers read nothing this
    /// changes: `refresh_events` stores what the memo computes).
    #[inline(always)]
    fn pass_foreign(&mut self, t: u64, d: &mut FrameDispatch) -> Option<Forward> {
        let out = self.route[0];
        if out == NO_ROUTE || !d.every.is_empty() {
            return None;
        }
        let (station, alias_on, alias) = self.address_key();
        if d.may_address(station) || (alias_on && d.may_address(alias)) {
            return None;
        }
        self.now = t;
        self.sii_settle(t);
        self.dc_arrival(0, t);
        let n = d.dgs.len();
        if n > 0 {
            self.pass_run(d, 0, n);
        }
        Some(Forward::Port(out))
    }

    /// The fused path (see `Fused`), after the frame's arrival: the checks first (no state
    /// touched when they fail and the generic path takes over), then the plan steps with
    /// the end-of-frame commit of each written SM, IRQ and working counter, exit port.
    /// Same effects as `process_frame` plus the exit-port search on such a frame.
    #[inline(always)]
    pub(super) fn process_fused(&mut self, frame: &mut [u8], t: u64) -> Option<Forward> {
        // The frame header and the first datagram's header from a fixed-size copy of the
        // first 12 bytes (one load per field, no bounds check); the checks only when the
        // headers differ from the last frame taken (`FusedKey`), which also holds what
        // they derived.
        let head: &[u8; ECAT_HEADER_LEN + DG_HEADER_LEN] = frame.first_chunk()?;
        let irq_in = u16::from_le_bytes([head[10], head[11]]);
        let (lo, hi) = fastpath::FusedKey::words(head, frame.len());
        let k = &self.fused.key;
        // One test for all the compared fields.
        if (lo ^ k.lo) | (hi ^ k.hi) != 0 {
            let head = *head;
            self.fused_accept(&head, frame.len())?;
        }
        // The mask first: with no ECAT event unmasked (a master that polls) one test.
        if self.ecat_mask != 0 && self.events_dirty {
            self.refresh_events();
        }
        #[cfg(test)]
        {
            self.fused_hits += 1;
        }
        // Registers (SM status, watchdog status) and process RAM (the SM buffers, which
        // the fused path requires to lie at or above `REG_END` with all three buffers):
        // one slice whose length is known to cover the registers, so that register
        // indices need no bounds check.
        let mem = &mut self.mem[..];
        if mem.len() < REG_END {
            return None;
        }
        // The IRQ field (as it came in, ORed with this ESC's bits as they stand before the
        // datagram's own access), the working counter where the checked length put it and
        // the watchdog trigger first: the steps touch none of them (the plan window lies
        // inside the datagram data), and with them done few values stay live in the steps.
        let irq = self.ecat_irq;
        if irq & !irq_in != 0 {
            frame[10..12].copy_from_slice(&(irq_in | irq).to_le_bytes());
        }
        let k = &self.fused.key;
        if k.inc != 0 {
            let at = k.wkc_at as usize;
            let wkc = &mut frame[at..at + 2];
            let w = u16::from_le_bytes([wkc[0], wkc[1]]).wrapping_add(k.inc);
            wkc.copy_from_slice(&w.to_le_bytes());
            // Some step runs exactly when the working counter counts.
            self.events_dirty = true;
        }
        if k.wd {
            // 0x0440 bit 0 is set exactly while the watchdog runs (`pd_wd_last` is some:
            // both set by a triggering write, both cleared by the expiry): its line is
            // touched only when the watchdog starts.
            match &mut self.pd_wd_last {
                Some(last) => *last = t,
                None => {
                    mem[regs::WD_STATUS_PD as usize] |= 1;
                    self.pd_wd_last = Some(t);
                }
            }
            self.pd_wd_forced = NO_DEADLINE;
        }
        // The steps' bytes lie inside the datagram data (checked with the key); unrolled
        // (`n <= PLAN_MAX`), one test per step.
        let n = usize::from(k.n);
        let run = &self.fused.run;
        let sms = &mut self.sms;
        let [s0, s1, s2, s3] = run;
        if n > 0 {
            fused_step(sms, mem, frame, s0);
            if n > 1 {
                fused_step(sms, mem, frame, s1);
                if n > 2 {
                    fused_step(sms, mem, frame, s2);
                    if n > 3 {
                        fused_step(sms, mem, frame, s3);
                    }
                }
            }
        }
        Some(Forward::Port(self.fused.exit))
    }

    /// The fused path's frame checks for a frame of `frame_len` bytes that starts with
    /// `head` and whose headers differ from the last one taken: `None` when the fused path
    /// does not take it; otherwise the key for it is stored and the steps' frame offsets
    /// set. Reads the headers through wire's views.
    #[cold]
    #[inline(never)]
    fn fused_accept(
        &mut self,
        head: &[u8; ECAT_HEADER_LEN + DG_HEADER_LEN],
        frame_len: usize,
    ) -> Option<()> {
        let dg_at = ECAT_HEADER_LEN;
        let f = view::Frame::new_unchecked(&head[..]);
        let d = view::Datagram::new_unchecked(&head[dg_at..]);
        let cmd = d.command_raw();
        let len = d.data_len();
        // Frame end (header length); the single datagram must fit in it.
        let end = f.end();
        let dg_end = dg_at + DG_HEADER_LEN + len + 2;
        // One logical datagram (no more-follows) in a datagram frame.
        if !f.is_datagrams()
            || cmd.wrapping_sub(CMD_LRD) > CMD_LRW - CMD_LRD
            || d.more_follows()
            || dg_end > end
            || end > frame_len
        {
            return None;
        }
        let ds = u64::from(d.address());
        let (lo, hi) = (self.fused_plan.lo, self.fused_plan.hi);
        if ds > lo || hi > ds + len as u64 {
            return None;
        }
        // The window offset fits: `hi - ds <= len` < 2^11.
        let woff = (lo - ds) as usize;
        let c = cmd - CMD_LRD;
        let (nr, nw) = (self.fused_plan.nr, self.fused_plan.nw);
        // LRD runs the reads, LWR the writes, LRW both; a write counts 1 in LWR, 2 in LRW.
        let nr = if c == 1 { 0 } else { nr };
        let nw = if c == 0 { 0 } else { nw };
        let inc = u16::from(nr > 0) + u16::from(nw > 0) * if c == 1 { 1 } else { 2 };
        // The command's steps in plan order (reads, then writes), with the frame offsets
        // of their bytes: < 2^11 + the headers.
        let base = dg_at + DG_HEADER_LEN + woff;
        let (s0, s1) = (
            if c == 1 { self.fused_plan.nr } else { 0 },
            self.fused_plan.nr + nw,
        );
        let mut run = [fastpath::FusedStep::default(); PLAN_MAX];
        for (r, (st, op)) in run.iter_mut().zip(
            self.fused_plan
                .steps
                .iter()
                .zip(&self.plan)
                .take(s1 as usize)
                .skip(s0 as usize),
        ) {
            *r = fastpath::FusedStep {
                at: (base + op.off as usize) as u16,
                ..*st
            };
        }
        self.fused.run = run;
        let (lo, hi) = fastpath::FusedKey::words(head, frame_len);
        self.fused.key = fastpath::FusedKey {
            lo,
            hi,
            wkc_at: (dg_at + view::field::wkc(len).start) as u16,
            inc,
            n: s1 - s0,
            wd: nw > 0 && self.fused_plan.wd,
        };
        Some(())
    }

    /// `forward` for every frame (the fused path is a shortcut for one kind).
    pub(super) fn forward_generic(
        &mut self,
        port: u8,
        frame: &mut [u8],
        t: u64,
        frame_ok: bool,
        d: Option<&mut FrameDispatch>,
    ) -> Forward {
        let port = port & 3;
        self.now = t;
        self.sii_settle(t);
        // The DC unit's own entry (the reference for the shortcuts' `dc_arrival`).
        if port == 0 {
            self.sof0 = t;
        }
        self.dc.frame_arrival(&mut self.mem[..REG_END], port, t);
        self.gate_routes();
        self.forward_after_arrival(port, frame, frame_ok, d)
    }

    /// `forward` after the DC unit saw the frame's arrival.
    pub(super) fn forward_after_arrival(
        &mut self,
        port: u8,
        frame: &mut [u8],
        frame_ok: bool,
        mut d: Option<&mut FrameDispatch>,
    ) -> Forward {
        if !frame_ok {
            let a = regs::RX_ERROR_COUNTER as usize + 2 * port as usize;
            self.mem[a] = self.mem[a].saturating_add(1);
        }
        if port == 0 {
            self.process_frame(frame, frame_ok, d.as_deref_mut());
        }
        let mut cur = port;
        for _ in 0..8 {
            let nxt = fastpath::next_port(cur);
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
                self.process_frame(frame, frame_ok, d.as_deref_mut());
            }
            cur = nxt;
        }
        Forward::Dropped
    }

    pub(super) fn process_frame(
        &mut self,
        frame: &mut [u8],
        frame_ok: bool,
        d: Option<&mut FrameDispatch>,
    ) {
        self.memo.clear();
        self.frame_ok = frame_ok;
        match d {
            Some(d) => self.walk_dispatched(frame, d),
            None => self.walk_datagrams(frame),
        }
        if !frame_ok {
            // A bad frame also abandons a buffer write ECAT had opened.
            for k in 0..self.active_sms.len() {
                let i = self.active_sms[k] as usize;
                let sm = &mut self.sms[i];
                if sm.write_open() && sm.ecat_writes() {
                    sm.close_write();
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
            if self.sms[i].pending_commit() {
                if frame_ok {
                    self.commit_sm(i, Side::Ecat);
                } else {
                    self.sms[i].discard();
                }
            }
        }
        self.frame_ok = true;
    }

    /// Walks the datagrams of `frame` with wire's one walker (it stops at the first
    /// malformed datagram, as an ESC does: the rest of the frame passes untouched) and hands
    /// each to [`Esc::datagram`]. The reference for [`Esc::walk_dispatched`].
    #[inline]
    pub(super) fn walk_datagrams(&mut self, frame: &mut [u8]) {
        let _ = view::walk_datagrams::<WireError>(frame, |dg| {
            self.datagram(dg);
            Ok(())
        });
    }

    /// One datagram of a frame at this ESC: logical datagrams as views, without decoding
    /// a header; a configured-address datagram for another station only ORs the IRQ
    /// field.
    #[inline]
    pub(super) fn datagram(&mut self, dg: view::Datagram<&mut [u8]>) {
        let cmd = dg.command_raw();
        if (CMD_LRD..=CMD_LRW).contains(&cmd) {
            self.logical_datagram(dg, cmd);
        } else if (CMD_FPRD..=CMD_FPRW).contains(&cmd) && !self.configured_match(dg.adp()) {
            // FPRD/FPWR/FPRW for another slave (a master's per-slave state checks: every
            // ESC of the line sees every one): only the IRQ field passes this ESC, as
            // `process_datagram` would leave it (FRMW, which all ESCs but the addressed
            // one write, takes the full path).
            let irq = self.passing_irq();
            let mut dg = dg;
            dg.or_irq(irq);
        } else if let Ok((mut d, _)) = DatagramMut::parse(dg.into_inner()) {
            self.process_datagram(&mut d);
        }
    }

    /// The IRQ bits this ESC ORs into a datagram passing it now (events brought up to
    /// date first, as for every datagram).
    #[inline]
    fn passing_irq(&mut self) -> u16 {
        if self.events_dirty && self.ecat_mask != 0 {
            self.refresh_events();
        }
        self.ecat_irq
    }

    /// The registers that decide which configured-address datagrams are this ESC's:
    /// station address, alias enable, alias.
    #[inline]
    fn address_key(&self) -> (u16, bool, u16) {
        (
            self.reg16(regs::STATION_ADDR),
            self.mem[regs::DL_ALIAS_ENABLE as usize] & 1 != 0,
            self.reg16(regs::STATION_ALIAS),
        )
    }

    /// [`Esc::walk_datagrams`] through the frame's index `d`: the datagrams every ESC
    /// processes and those addressed to this ESC's station address (or its alias, when
    /// enabled), in frame order; for the foreign configured-address datagrams between them
    /// only the IRQ bits, recorded in `d` per run (this ESC's state cannot change while it
    /// passes them, so one value holds for the run). If a processed datagram changes the
    /// station address, the alias or its enable, the rest of the frame takes the
    /// datagram-by-datagram walk.
    pub(super) fn walk_dispatched(&mut self, frame: &mut [u8], d: &mut FrameDispatch) {
        let n = d.dgs.len();
        let key = self.address_key();
        let (mut a, a_end) = if d.may_address(key.0) {
            d.fp_run(key.0)
        } else {
            (0, 0)
        };
        let (mut b, b_end) = if key.1 && key.2 != key.0 && d.may_address(key.2) {
            d.fp_run(key.2)
        } else {
            (0, 0)
        };
        let (mut e, e_end) = (0, d.every.len());
        let mut pos = 0;
        loop {
            let mut j = usize::MAX;
            if e < e_end {
                j = d.every[e] as usize;
            }
            if a < a_end {
                j = j.min(d.fp[a].1 as usize);
            }
            if b < b_end {
                j = j.min(d.fp[b].1 as usize);
            }
            if j == usize::MAX {
                break;
            }
            if e < e_end && d.every[e] as usize == j {
                e += 1;
            } else if a < a_end && d.fp[a].1 as usize == j {
                a += 1;
            } else {
                b += 1;
            }
            if j > pos {
                self.pass_run(d, pos, j);
            }
            self.dispatch_one(frame, d, j);
            pos = j + 1;
            if self.address_key() != key {
                for k in pos..n {
                    self.dispatch_one(frame, d, k);
                }
                return;
            }
        }
        if pos < n {
            self.pass_run(d, pos, n);
        }
    }

    /// Datagram `j` of the index through [`Esc::datagram`].
    #[inline]
    fn dispatch_one(&mut self, frame: &mut [u8], d: &FrameDispatch, j: usize) {
        let s = d.dgs[j];
        let (at, len) = (s.at as usize, s.len as usize);
        if let Some(dg) = frame.get_mut(at..at + len) {
            self.datagram(view::Datagram::new_unchecked(dg));
        }
    }

    /// Foreign configured-address datagrams `from..to` pass this ESC: their IRQ bits.
    #[inline]
    fn pass_run(&mut self, d: &mut FrameDispatch, from: usize, to: usize) {
        let irq = self.passing_irq();
        if irq != 0 {
            d.or_irq_range(from, to, irq);
        }
    }

    /// A logical datagram (a checked view; `cmd` is LRD, LWR or LRW): what
    /// [`Esc::process_datagram`] does for it, in place.
    #[inline]
    pub(super) fn logical_datagram(&mut self, mut dg: view::Datagram<&mut [u8]>, cmd: u8) {
        if self.events_dirty && self.ecat_mask != 0 {
            self.refresh_events();
        }
        let irq = self.ecat_irq;
        let addr = dg.address();
        let cmd = match cmd {
            CMD_LRD => Command::Lrd,
            CMD_LWR => Command::Lwr,
            _ => Command::Lrw,
        };
        let inc = self.logical(cmd, addr, dg.data_mut());
        dg.or_irq(irq);
        dg.add_wkc(inc);
    }

    pub(super) fn configured_match(&self, adp: u16) -> bool {
        adp == self.reg16(regs::STATION_ADDR)
            || (self.mem[regs::DL_ALIAS_ENABLE as usize] & 1 != 0
                && adp == self.reg16(regs::STATION_ALIAS))
    }

    pub(super) fn process_datagram(&mut self, dg: &mut DatagramMut<'_>) {
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
    pub(super) fn physical(&mut self, cmd: Command, ado: u32, data: &mut [u8], or: bool) -> u16 {
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
    pub(super) fn logical(&mut self, cmd: Command, addr: u32, data: &mut [u8]) -> u16 {
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
    pub(super) fn logical_plan(&mut self, cmd: Command, base: usize, data: &mut [u8]) -> u16 {
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
    pub(super) fn logical_generic(
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

    pub(super) fn fmmu_read(&mut self, f: &Fmmu, addr: u32, data: &mut [u8]) -> bool {
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

    pub(super) fn fmmu_write(&mut self, f: &Fmmu, addr: u32, src: &[u8]) -> bool {
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
}

/// One step of the fused path ([`Esc::process_fused`]): a read step takes the newest
/// buffer and copies it into the frame, a write step writes the free buffer from the frame
/// and commits it; the SM status register follows.
#[inline(always)]
fn fused_step(sms: &mut [Sm; 16], mem: &mut [u8], frame: &mut [u8], st: &fastpath::FusedStep) {
    let i = st.sm as usize & 15;
    let sm = &mut sms[i];
    let l = st.len as usize;
    let at = st.at as usize;
    if st.write {
        let b = sm.buffered_write_commit();
        mem[regs::sm_reg(i, 5)] = sm.buffered_status_reg();
        let to = st.ram as usize + b as usize * l;
        copy_small(&mut mem[to..to + l], &frame[at..at + l]);
    } else {
        let b = sm.buffered_read_whole();
        mem[regs::sm_reg(i, 5)] = sm.buffered_status_reg();
        let from = st.ram as usize + b as usize * l;
        copy_small(&mut frame[at..at + l], &mem[from..from + l]);
    }
}
