//! Events and time: DL status, ECAT/AL event requests and the interrupt line, the
//! process-data and PDI watchdogs, DC and watchdog time passing.

use super::*;

/// Memo of the `&self` queries the segment makes after every time step: the event
/// requests ([`Esc::compute_events`], for `irq_line`, `al_event_request`,
/// `ecat_event_request`) and [`Esc::next_event`]. Between two state changes their answers
/// cannot change. Cleared on entry to every `&mut self` entry point (only `advance` keeps
/// it when neither the DC unit nor a watchdog changed anything, and `forward` when the frame
/// only passes: it is cleared where a frame is processed). Atomics rather than
/// `Cell` so that `Esc` stays `Sync`; 32-bit ones, because Cortex-M (thumbv7em) has no
/// 64-bit atomics. Each value is published by a release store of its valid flag after its
/// parts; concurrent `&self` writers can only store the same answer.
#[derive(Debug, Default)]
pub(super) struct QueryMemo {
    /// AL event request (meaningful when `ecat` has [`Self::VALID`]).
    pub(super) al: AtomicU32,
    /// Bits 0..16 ECAT event request, bit 16 valid.
    pub(super) ecat: AtomicU32,
    /// `next_event()`: 0 unknown, 1 `None`, 2 `Some(next)`.
    pub(super) next_state: AtomicU8,
    pub(super) next_lo: AtomicU32,
    pub(super) next_hi: AtomicU32,
    /// Bumped by every [`QueryMemo::clear`]: while it stays the same, the memo's answers
    /// stay valid once computed ([`Esc::query_epoch`]).
    pub(super) epoch: u64,
}

impl QueryMemo {
    const VALID: u32 = 1 << 16;

    #[inline(always)]
    pub(super) fn events(&self) -> Option<(u16, u32)> {
        let v = self.ecat.load(Ordering::Acquire);
        (v & Self::VALID != 0).then(|| (v as u16, self.al.load(Ordering::Relaxed)))
    }

    #[inline(always)]
    pub(super) fn set_events(&self, e: u16, a: u32) {
        self.al.store(a, Ordering::Relaxed);
        self.ecat.store(Self::VALID | e as u32, Ordering::Release);
    }

    #[inline(always)]
    pub(super) fn next_event(&self) -> Option<Option<u64>> {
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
    pub(super) fn set_next_event(&self, n: Option<u64>) {
        if let Some(n) = n {
            self.next_lo.store(n as u32, Ordering::Relaxed);
            self.next_hi.store((n >> 32) as u32, Ordering::Relaxed);
            self.next_state.store(2, Ordering::Release);
        } else {
            self.next_state.store(1, Ordering::Release);
        }
    }

    #[inline(always)]
    pub(super) fn clear(&mut self) {
        *self.ecat.get_mut() = 0;
        *self.next_state.get_mut() = 0;
        self.epoch = self.epoch.wrapping_add(1);
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
            epoch: self.epoch,
        }
    }
}

impl Esc {
    pub(super) fn update_dl_status(&mut self, event: bool) {
        self.open_ports = (0..4u8)
            .filter(|&p| self.compute_port_open(p))
            .fold(0, |m, p| m | (1 << p));
        self.rebuild_routes();
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

    pub(super) fn compute_events(&self) -> (u16, u32) {
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

    pub(super) fn refresh_events(&mut self) {
        let (e, a) = self.compute_events();
        self.mem[0x0210..0x0212].copy_from_slice(&e.to_le_bytes());
        self.mem[0x0220..0x0224].copy_from_slice(&a.to_le_bytes());
        self.ecat_mask = self.reg16(regs::ECAT_EVENT_MASK);
        self.ecat_irq = e & self.ecat_mask;
        self.events_dirty = false;
    }

    // ------------------------------------------------------------------ PDI side

    pub(super) fn wd_unit_ns(&self) -> u64 {
        (self.reg16(regs::WD_DIVIDER) as u64 + 2) * 40
    }

    pub(super) fn pd_wd_deadline(&self) -> Option<u64> {
        let t = self.reg16(regs::WD_TIME_PD) as u64;
        match self.pd_wd_last {
            Some(l) if t != 0 => {
                let d = l + t * self.wd_unit_ns();
                Some(self.pd_wd_forced.min(d))
            }
            _ => None,
        }
    }

    pub(super) fn pdi_wd_deadline(&self) -> Option<u64> {
        let t = self.reg16(regs::WD_TIME_PDI) as u64;
        match self.pdi_wd_last {
            Some(l) if t != 0 => Some(l + t * self.wd_unit_ns()),
            _ => None,
        }
    }

    pub(super) fn pdi_access(&mut self) {
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
        self.sii_settle(t);
        let quiet = self.dc.advance_quiet(t);
        if quiet && !self.fast_off {
            // The memo's next event, when known, is the earliest of the DC edge, both
            // watchdog deadlines and the loop revert as the state stands (the memo is
            // cleared whenever that changes): before it, none of them is due.
            if let Some(n) = self.memo.next_event() {
                if n.is_none_or(|n| t < n) {
                    self.events_dirty = true;
                    return EscEvents::default();
                }
            }
        }
        let dce = if quiet {
            crate::dc::DcEvents::default()
        } else {
            // The DC unit may change its status bits (AL event request bits 2/3).
            self.memo.clear();
            self.dc.advance_slow(&mut self.mem[..REG_END], t)
        };
        let mut ev = dce;
        if let Some(d) = self.pd_wd_deadline() {
            if t >= d {
                self.pd_wd_last = None;
                self.pd_wd_forced = NO_DEADLINE;
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

    pub(super) fn compute_next_event(&self) -> Option<u64> {
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

    /// [`compute_events`](Self::compute_events) through [`QueryMemo`].
    #[inline]
    pub(super) fn events_now(&self) -> (u16, u32) {
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

    /// A number that changes whenever the answers of [`next_event`](Self::next_event) and
    /// [`irq_line`](Self::irq_line) may change (the query memo's generation: every entry
    /// point that can change them clears the memo). A caller that read both at epoch `e`
    /// may skip reading them again while the epoch is still `e` (the segment does after
    /// each hop of a frame). `None` with the fast paths off ([`Esc::set_fast_paths`]).
    #[inline]
    pub fn query_epoch(&self) -> Option<u64> {
        (!self.fast_off).then_some(self.memo.epoch)
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
}
