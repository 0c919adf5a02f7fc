//! STM32F446 timers TIM1..TIM14 (RM0390 §16–§19): one model keyed by base address.
//!
//! The counter is evaluated lazily from the CPU cycle count: `sync` brings it up to a
//! cycle, counting prescaler ticks at the timer clock (cycles per tick from RCC's APB
//! prescalers) with the preloaded PSC (and ARR when ARPE) taking effect at update events,
//! up-, down- and center-aligned counting, the repetition counter of TIM1/TIM8, UDIS,
//! URS, OPM. SR flags: UIF on update, CCxIF/CCxOF on input capture; the IRQ lines follow
//! SR & DIER. Encoder mode (SMCR.SMS = 1, 2, 3) takes its position from the board
//! (`Board::set_encoder`); input capture latches CNT on an injected edge
//! (`Board::capture`). Output compare match flags (CCxIF in output mode) are not modelled;
//! CCR/CCMR/CCER are stored and the PWM duty is derived from them.
//!
//! Timer links (RM0390 §17.3.15, table "TIMx internal trigger connection"): a master's
//! TRGO in mode CR2.MMS = 011 (compare pulse) pulses whenever CC1IF is set by a capture
//! (an injected edge or EGR.CC1G); a timer whose SMCR.TS selects that master as ITR0..3
//! sees the pulse on TRGI, and its channels in input-capture mode on TRC (CCxS = 11,
//! enabled) capture. TRGO = OC1REF..OC4REF (MMS = 100..111) with the channel in PWM mode 1
//! or 2, or TRGO = the update event (MMS = 010, with the repetition counter of TIM1/TIM8
//! one per RCR + 1 over/underflows), is ADC1's injected trigger: its rising edges are
//! computed from the counter (`Timer::next_trgo_rise`), not pulsed; UG's own update pulse
//! is routed by the bus (`Periph::write`). The other master modes (reset, enable) and the
//! slave modes (reset, gated, trigger) do not produce or act on pulses here.
//!
//! Update events are counted (`Timer::updates`) and their times computed
//! (`Timer::update_cycle`): with DIER.UDE each one is a DMA request (`crate::dma`).

/// Register offsets.
const CR1: usize = 0x00;
const CR2: usize = 0x04;
const SMCR: usize = 0x08;
const DIER: usize = 0x0C;
const SR: usize = 0x10;
const EGR: usize = 0x14;
const CCMR1: usize = 0x18;
const CCER: usize = 0x20;
const CNT: usize = 0x24;
const PSC: usize = 0x28;
const ARR: usize = 0x2C;
const RCR: usize = 0x30;
const CCR1: usize = 0x34;
const BDTR: usize = 0x44;

const CEN: u32 = 1;
const UDIS: u32 = 1 << 1;
const URS: u32 = 1 << 2;
const OPM: u32 = 1 << 3;
const DIR: u32 = 1 << 4;
const ARPE: u32 = 1 << 7;
const UIF: u32 = 1;
/// BDTR: main output enable, automatic output enable.
const MOE: u32 = 1 << 15;
const AOE: u32 = 1 << 14;

/// Which timer, where, and its interrupt lines.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TimerKind {
    /// Register block base.
    pub base: u64,
    /// Timer number (1 for TIM1 …).
    pub number: u8,
    /// On APB2 (else APB1).
    pub apb2: bool,
    /// 32-bit counter (TIM2, TIM5).
    pub wide: bool,
    /// Advanced-control (TIM1, TIM8): repetition counter, BDTR.MOE.
    pub advanced: bool,
    /// Capture/compare channels (0 for the basic TIM6/TIM7).
    pub channels: u8,
    /// IRQs: update, capture/compare, trigger/commutation, break (all the same on
    /// timers with one vector).
    pub irq_up: u16,
    pub irq_cc: u16,
    pub irq_trg: u16,
    pub irq_brk: u16,
}

const fn kind(number: u8, base: u64, apb2: bool, wide: bool, channels: u8, irq: u16) -> TimerKind {
    TimerKind {
        base,
        number,
        apb2,
        wide,
        advanced: false,
        channels,
        irq_up: irq,
        irq_cc: irq,
        irq_trg: irq,
        irq_brk: irq,
    }
}

const fn advanced(number: u8, base: u64, up: u16, cc: u16, trg: u16, brk: u16) -> TimerKind {
    TimerKind {
        base,
        number,
        apb2: true,
        wide: false,
        advanced: true,
        channels: 4,
        irq_up: up,
        irq_cc: cc,
        irq_trg: trg,
        irq_brk: brk,
    }
}

/// The STM32F446's timers (RM0390 table 38 for the IRQ positions).
pub(crate) const TIMERS: [TimerKind; 14] = [
    advanced(1, 0x4001_0000, 25, 27, 26, 24),
    kind(2, 0x4000_0000, false, true, 4, 28),
    kind(3, 0x4000_0400, false, false, 4, 29),
    kind(4, 0x4000_0800, false, false, 4, 30),
    kind(5, 0x4000_0C00, false, true, 4, 50),
    kind(6, 0x4000_1000, false, false, 0, 54),
    kind(7, 0x4000_1400, false, false, 0, 55),
    advanced(8, 0x4001_0400, 44, 46, 45, 43),
    kind(9, 0x4001_4000, true, false, 2, 24),
    kind(10, 0x4001_4400, true, false, 1, 25),
    kind(11, 0x4001_4800, true, false, 1, 26),
    kind(12, 0x4000_1800, false, false, 2, 43),
    kind(13, 0x4000_1C00, false, false, 1, 44),
    kind(14, 0x4000_2000, false, false, 1, 45),
];

/// One timer's state.
pub(crate) struct Timer {
    pub kind: TimerKind,
    regs: [u32; 0x54 / 4],
    cnt: u32,
    /// Prescaler ticks since the last counter tick.
    phase: u64,
    /// Cycle up to which the counter is evaluated.
    last: u64,
    /// CPU cycles per timer-clock tick.
    pub clk_div: u64,
    psc_sh: u32,
    arr_sh: u32,
    rep: u32,
    /// Center-aligned: counting down now.
    down: bool,
    /// Encoder: the last injected position in quadrature edges.
    enc: i64,
    /// TRGO pulses not yet routed to the linked timers.
    trgo_pending: u32,
    /// Cycle from which the counter has run undisturbed (started, written, or
    /// re-initialised by UG): computed OCxREF edges lie at or after it.
    epoch: u64,
    /// Update events so far (a DMA stream on the update request counts them).
    pub updates: u64,
}

/// The timer whose TRGO drives internal trigger ITR`ts` of timer `number` (RM0390 tables
/// 94, 99, 106: TIM1/8, TIM2..5, TIM9/12); `None` for TS values that are not ITRs.
pub(crate) fn itr_source(number: u8, ts: u32) -> Option<u8> {
    let table: [u8; 4] = match number {
        1 => [5, 2, 3, 4],
        2 => [1, 8, 3, 4],
        3 => [1, 2, 5, 4],
        4 => [1, 2, 3, 8],
        5 => [2, 3, 4, 8],
        8 => [1, 2, 4, 5],
        9 => [2, 3, 10, 11],
        12 => [4, 5, 13, 14],
        _ => return None,
    };
    table.get(ts as usize).copied()
}

impl Timer {
    pub fn new(kind: TimerKind) -> Self {
        let mut t = Timer {
            kind,
            regs: [0; 0x54 / 4],
            cnt: 0,
            phase: 0,
            last: 0,
            clk_div: 1,
            psc_sh: 0,
            arr_sh: 0,
            rep: 0,
            down: false,
            enc: 0,
            trgo_pending: 0,
            epoch: 0,
            updates: 0,
        };
        let max = t.max();
        t.regs[ARR / 4] = max;
        t.arr_sh = max;
        t
    }

    fn r(&self, off: usize) -> u32 {
        self.regs[off / 4]
    }

    fn max(&self) -> u32 {
        if self.kind.wide {
            u32::MAX
        } else {
            0xFFFF
        }
    }

    fn cms(&self) -> u32 {
        (self.r(CR1) >> 5) & 3
    }

    fn sms(&self) -> u32 {
        self.r(SMCR) & 7
    }

    fn encoder(&self) -> bool {
        (1..=3).contains(&self.sms())
    }

    /// Counting from its clock: enabled and not in encoder or external-clock mode.
    fn running(&self) -> bool {
        self.r(CR1) & CEN != 0 && !self.encoder() && self.sms() != 7
    }

    /// Counter ticks from CNT to the next overflow/underflow.
    fn ticks_to_event(&self) -> u64 {
        let (cnt, arr) = (u64::from(self.cnt), u64::from(self.arr_sh));
        if self.cms() != 0 {
            if self.down {
                cnt.max(1)
            } else if cnt < arr {
                arr - cnt
            } else {
                1
            }
        } else if self.r(CR1) & DIR != 0 {
            cnt + 1
        } else if cnt <= arr {
            arr - cnt + 1
        } else {
            u64::from(self.max()) - cnt + 1
        }
    }

    fn advance(&mut self, ticks: u64) {
        let t = ticks as u32;
        let down = if self.cms() != 0 {
            self.down
        } else {
            self.r(CR1) & DIR != 0
        };
        self.cnt = if down {
            self.cnt.wrapping_sub(t)
        } else {
            self.cnt.wrapping_add(t)
        } & self.max();
    }

    /// An overflow/underflow: the counter wraps; with the repetition counter at zero (and
    /// UDIS clear) it is an update event.
    fn overflow(&mut self) {
        if self.cms() != 0 {
            if self.down {
                self.cnt = 0;
                self.down = false;
            } else {
                self.cnt = self.arr_sh;
                self.down = true;
            }
        } else if self.r(CR1) & DIR != 0 {
            self.cnt = self.r(ARR);
        } else {
            self.cnt = 0;
        }
        if self.rep > 0 {
            self.rep -= 1;
            return;
        }
        self.update_event(true);
        if self.cms() == 0 && self.r(CR1) & DIR != 0 {
            self.cnt = self.arr_sh;
        }
    }

    fn update_event(&mut self, set_uif: bool) {
        if self.r(CR1) & UDIS != 0 {
            return;
        }
        self.psc_sh = self.r(PSC) & 0xFFFF;
        self.arr_sh = self.r(ARR);
        self.updates += 1;
        if self.kind.advanced {
            self.rep = self.r(RCR) & 0xFF;
        }
        if set_uif {
            self.regs[SR / 4] |= UIF;
        }
        self.automatic_output_enable();
        if self.r(CR1) & OPM != 0 {
            self.regs[CR1 / 4] &= !CEN;
        }
    }

    /// TIM1/TIM8: with BDTR.AOE an update event sets MOE (RM0390 §17.4.18).
    fn automatic_output_enable(&mut self) {
        if self.kind.advanced && self.r(BDTR) & AOE != 0 {
            self.regs[BDTR / 4] |= MOE;
        }
    }

    /// Prescaler ticks from now to the next over/underflow.
    fn pticks_to_event(&self) -> u64 {
        (self.ticks_to_event() * (u64::from(self.psc_sh) + 1)).saturating_sub(self.phase)
    }

    /// Brings the counter up to cycle `now`.
    pub fn sync(&mut self, now: u64) {
        if !self.running() {
            self.last = now;
            return;
        }
        if now <= self.last {
            return;
        }
        let k = self.clk_div.max(1);
        let mut pt = (now - self.last) / k;
        self.last += pt * k;
        // Bounded: after the first event, whole cycles of 2 × (RCR + 1) periods are
        // skipped at once, leaving at most that many events to step through.
        let mut fast_forwarded = false;
        loop {
            let need = self.pticks_to_event();
            if pt < need {
                let psc = u64::from(self.psc_sh) + 1;
                let total = self.phase + pt;
                self.advance(total / psc);
                self.phase = total % psc;
                return;
            }
            pt -= need;
            self.phase = 0;
            self.overflow();
            if !self.running() {
                return;
            }
            if !fast_forwarded {
                fast_forwarded = true;
                let psc = u64::from(self.psc_sh) + 1;
                let period = if self.cms() != 0 {
                    u64::from(self.arr_sh).max(1)
                } else {
                    u64::from(self.arr_sh) + 1
                };
                let reps = if self.kind.advanced {
                    u64::from(self.r(RCR) & 0xFF) + 1
                } else {
                    1
                };
                let cycle = 2 * reps * period * psc;
                if pt >= cycle {
                    if self.r(CR1) & UDIS == 0 {
                        self.regs[SR / 4] |= UIF;
                        // Two update events per skipped cycle (one per RCR + 1 periods).
                        self.updates += 2 * (pt / cycle);
                    }
                    pt %= cycle;
                }
            }
        }
    }

    /// The cycle of the next update event, when it would raise an interrupt that is not
    /// already raised.
    pub fn next_event(&self) -> Option<u64> {
        if !self.running()
            || self.r(DIER) & 1 == 0
            || self.r(SR) & UIF != 0
            || self.r(CR1) & UDIS != 0
        {
            return None;
        }
        let psc = u64::from(self.psc_sh) + 1;
        let period = if self.cms() != 0 {
            u64::from(self.arr_sh).max(1)
        } else {
            u64::from(self.arr_sh) + 1
        };
        let pt = self.pticks_to_event() + u64::from(self.rep) * period * psc;
        Some(self.last + pt * self.clk_div.max(1))
    }

    /// The cycle of the `k`-th update event from now (k ≥ 1), if the counter runs and
    /// updates are enabled (edge-aligned counting: one every (ARR + 1)·(PSC + 1)·(RCR + 1)
    /// timer ticks once the preloaded values are in).
    pub fn update_cycle(&self, k: u64) -> Option<u64> {
        if !self.running() || self.r(CR1) & UDIS != 0 || k == 0 {
            return None;
        }
        let psc = u64::from(self.psc_sh) + 1;
        let period = if self.cms() != 0 {
            u64::from(self.arr_sh).max(1)
        } else {
            u64::from(self.arr_sh) + 1
        };
        let reps = if self.kind.advanced {
            u64::from(self.r(RCR) & 0xFF) + 1
        } else {
            1
        };
        let first = self.pticks_to_event() + u64::from(self.rep) * period * psc;
        let pt = first + (k - 1) * reps * period * psc;
        Some(self.last + pt * self.clk_div.max(1))
    }

    /// DIER.UDE: the update event requests DMA.
    pub fn update_dma(&self) -> bool {
        self.r(DIER) & (1 << 8) != 0
    }

    /// Counter clock \[Hz\] and ticks per period (ARR + 1), as the preloaded values stand.
    pub fn period(&self) -> (f64, u32) {
        let tick =
            crate::CPU_HZ as f64 / (self.clk_div.max(1) as f64 * (f64::from(self.psc_sh) + 1.0));
        (tick, self.arr_sh.saturating_add(1))
    }

    /// The IRQ lines this timer drives high (exception-number bit set).
    pub fn irq_lines(&self) -> u128 {
        let on = self.r(SR) & self.r(DIER);
        let k = &self.kind;
        let mut lines = 0u128;
        let mut raise = |irq: u16, mask: u32| {
            if on & mask != 0 {
                lines |= crate::nvic::bit(16 + irq);
            }
        };
        raise(k.irq_up, UIF);
        raise(k.irq_cc, 0x1E);
        raise(k.irq_trg, 0x60);
        raise(k.irq_brk, 0x80);
        lines
    }

    fn ccs(&self, ch: u8) -> u32 {
        let ccmr = self.r(CCMR1 + 4 * usize::from((ch - 1) / 2));
        (ccmr >> (8 * u32::from((ch - 1) % 2))) & 3
    }

    pub fn read(&mut self, off: usize, now: u64) -> u32 {
        self.sync(now);
        match off {
            CR1 => {
                let down = if self.cms() != 0 {
                    self.down
                } else {
                    self.r(CR1) & DIR != 0
                };
                (self.r(CR1) & !DIR) | if down { DIR } else { 0 }
            }
            CNT => self.cnt,
            EGR => 0,
            o if (CCR1..CCR1 + 16).contains(&o) => {
                let ch = ((o - CCR1) / 4 + 1) as u8;
                if ch <= self.kind.channels && self.ccs(ch) != 0 {
                    // Reading an input-capture CCR clears CCxIF.
                    self.regs[SR / 4] &= !(1 << ch);
                }
                self.r(o)
            }
            o => self.regs.get(o / 4).copied().unwrap_or(0),
        }
    }

    /// Returns whether the interrupt lines may have changed.
    pub fn write(&mut self, off: usize, v: u32, now: u64) -> bool {
        self.sync(now);
        match off {
            CR1 => {
                let was = self.running();
                let cms_was = self.cms();
                self.regs[CR1 / 4] = v & 0x3FF;
                if self.cms() != 0 && cms_was == 0 {
                    self.down = false;
                }
                if !was && self.running() {
                    self.last = now;
                    self.epoch = now;
                }
                if self.r(CR1) & ARPE == 0 {
                    self.arr_sh = self.r(ARR);
                }
            }
            SR => self.regs[SR / 4] &= v, // rc_w0
            EGR => {
                if v & 1 != 0 {
                    // UG: re-initialise the counter and the prescaler; unless UDIS, an
                    // update event (UIF only when URS is clear).
                    let down = self.cms() == 0 && self.r(CR1) & DIR != 0;
                    self.phase = 0;
                    if self.r(CR1) & UDIS == 0 {
                        self.psc_sh = self.r(PSC) & 0xFFFF;
                        self.arr_sh = self.r(ARR);
                        if self.kind.advanced {
                            self.rep = self.r(RCR) & 0xFF;
                        }
                        if self.r(CR1) & URS == 0 {
                            self.regs[SR / 4] |= UIF;
                        }
                        self.automatic_output_enable();
                    }
                    self.cnt = if down { self.arr_sh } else { 0 };
                    self.down = false;
                    self.epoch = now;
                }
                for ch in 1..=self.kind.channels {
                    if v & (1 << ch) != 0 {
                        self.capture_channel(ch);
                    }
                }
            }
            CNT => {
                self.cnt = v & self.max();
                self.epoch = now;
            }
            PSC => self.regs[PSC / 4] = v & 0xFFFF,
            ARR => {
                self.regs[ARR / 4] = v & self.max();
                if self.r(CR1) & ARPE == 0 {
                    self.arr_sh = v & self.max();
                }
            }
            SMCR => {
                let was = self.encoder();
                self.regs[SMCR / 4] = v;
                if !was && self.encoder() {
                    self.last = now;
                }
            }
            o if (CCR1..CCR1 + 16).contains(&o) => {
                let ch = ((o - CCR1) / 4 + 1) as u8;
                if ch > self.kind.channels || self.ccs(ch) == 0 {
                    self.regs[o / 4] = v & self.max();
                }
            }
            o if o < self.regs.len() * 4 => self.regs[o / 4] = v,
            _ => {}
        }
        matches!(off, CR1 | SR | EGR | DIER)
    }

    /// Latches CNT into CCRx (an input-capture event on channel `ch`); a capture on CH1
    /// of a master in compare-pulse mode pulses TRGO (`trgo_pending`).
    fn capture_channel(&mut self, ch: u8) {
        let f = 1u32 << ch;
        if self.ccs(ch) != 0 {
            if self.r(SR) & f != 0 {
                self.regs[SR / 4] |= 1 << (8 + ch); // CCxOF
            }
            self.regs[(CCR1 + 4 * usize::from(ch - 1)) / 4] = self.cnt;
        }
        self.regs[SR / 4] |= f;
        if ch == 1 && (self.r(CR2) >> 4) & 7 == 3 {
            self.trgo_pending += 1;
        }
    }

    /// Counting from its clock (enabled, not in encoder or external-clock mode).
    pub fn counting(&self) -> bool {
        self.running()
    }

    /// CR2.MMS: what TRGO carries.
    pub fn mms(&self) -> u32 {
        (self.r(CR2) >> 4) & 7
    }

    /// Whether [`Timer::next_trgo_rise`] models the master mode: MMS = 010, TRGO = the
    /// update event; or MMS = 100..111, TRGO = OC1REF..OC4REF, with that channel in PWM
    /// mode 1 or 2 on a centre-aligned or up-counting timer.
    pub fn trgo_edges_modelled(&self) -> bool {
        let mms = self.mms();
        if mms == 2 {
            return true;
        }
        if !(4..=7).contains(&mms) {
            return false;
        }
        let ch = (mms - 3) as u8;
        let ccmr = self.r(CCMR1 + 4 * usize::from((ch - 1) / 2));
        let ocm = (ccmr >> (4 + 8 * u32::from((ch - 1) % 2))) & 7;
        self.ccs(ch) == 0 && matches!(ocm, 6 | 7) && (self.cms() != 0 || self.r(CR1) & DIR == 0)
    }

    /// The cycle of the first rising edge of TRGO = OCxREF (see
    /// [`Timer::trgo_edges_modelled`]) after cycle `after`, with the present PSC, ARR and
    /// CCRx; `None` when the timer stands still or OCxREF never rises.
    ///
    /// RM0390 PWM modes: mode 1 is active while CNT < CCRx counting up, and from CNT =
    /// CCRx on counting down; mode 2 the complement. Centre-aligned, the counter's
    /// position in its period of 2 · ARR ticks is CNT counting up and 2 · ARR − CNT
    /// counting down: OCxREF rises at CCRx (mode 2) or 2 · ARR − CCRx (mode 1). Counting
    /// up (edge-aligned, period ARR + 1) it rises at CCRx (mode 2) or at 0 (mode 1).
    pub fn next_trgo_rise(&self, after: u64) -> Option<u64> {
        if !self.running() || !self.trgo_edges_modelled() {
            return None;
        }
        if self.mms() == 2 {
            return self.next_update_after(after);
        }
        let ch = (self.mms() - 3) as u8;
        let ccmr = self.r(CCMR1 + 4 * usize::from((ch - 1) / 2));
        let ocm = (ccmr >> (4 + 8 * u32::from((ch - 1) % 2))) & 7;
        let ccr = u64::from(self.r(CCR1 + 4 * usize::from(ch - 1)));
        let arr = u64::from(self.arr_sh);
        let cnt = u64::from(self.cnt);
        let (period, pos, rise) = if self.cms() != 0 {
            let arr = arr.max(1);
            let pos = if self.down {
                2 * arr - cnt.min(arr)
            } else {
                cnt.min(arr)
            };
            let rise = match ocm {
                7 if ccr <= arr => ccr,
                6 if ccr <= arr => (2 * arr - ccr) % (2 * arr),
                _ => return None, // never changes
            };
            (2 * arr, pos, rise)
        } else {
            let rise = match ocm {
                7 if (1..=arr).contains(&ccr) => ccr,
                6 if (1..=arr).contains(&ccr) => 0,
                _ => return None, // always or never active
            };
            (arr + 1, cnt.min(arr), rise)
        };
        let div = self.clk_div.max(1);
        let tick = (u64::from(self.psc_sh) + 1) * div;
        // When the counter reached `pos`, and the last rise at or before that.
        let at_pos = i128::from(self.last) - i128::from(self.phase * div);
        let back = (pos + period - rise) % period;
        let step = i128::from(period * tick);
        let mut t = at_pos - i128::from(back * tick);
        let lo = i128::from(after.saturating_add(1).max(self.epoch));
        if t < lo {
            t += (lo - t + step - 1) / step * step;
        }
        u64::try_from(t).ok()
    }

    /// The cycle of the first update event after cycle `after` (MMS = 010: TRGO pulses at
    /// each update event, RM0390 TIMx_CR2). The counter may already have run past `after`:
    /// the update events since then lie on the same grid as the next ones (one every
    /// (RCR + 1) over/underflows), back to the cycle it started from undisturbed.
    fn next_update_after(&self, after: u64) -> Option<u64> {
        let u1 = self.update_cycle(1)?;
        let period = self.update_cycle(2)?.checked_sub(u1).filter(|&p| p > 0)?;
        let lo = after.saturating_add(1).max(self.epoch.saturating_add(1));
        Some(if u1 >= lo {
            u1 - (u1 - lo) / period * period
        } else {
            u1 + (lo - u1).div_ceil(period) * period
        })
    }

    /// TRGO pulses since the last call (the bus routes them to the linked timers).
    pub fn take_trgo(&mut self) -> u32 {
        std::mem::take(&mut self.trgo_pending)
    }

    /// The timer number whose TRGO is this timer's trigger input (SMCR.TS = ITR0..3), if
    /// one is selected.
    pub fn trigger_source(&self) -> Option<u8> {
        let ts = (self.r(SMCR) >> 4) & 7;
        itr_source(self.kind.number, ts)
    }

    /// A pulse on TRGI at `now`: every input-capture channel on TRC (CCxS = 11) that is
    /// enabled captures. Returns how many captured.
    pub fn trigger(&mut self, now: u64) -> usize {
        self.sync(now);
        let mut n = 0;
        for ch in 1..=self.kind.channels {
            let enabled = self.r(CCER) & (1 << (4 * (ch - 1))) != 0;
            if self.ccs(ch) == 3 && enabled {
                self.capture_channel(ch);
                n += 1;
            }
        }
        n
    }

    /// An active edge on input TIn (1..=4) at `now`: every channel in input-capture mode
    /// mapped to it (CCxS = 01 for its own input, 10 for its pair's) and enabled (CCxE)
    /// captures. Returns how many channels captured.
    pub fn capture(&mut self, input: u8, now: u64) -> usize {
        self.sync(now);
        let mut n = 0;
        for ch in 1..=self.kind.channels {
            let pair = if ch % 2 == 1 { ch + 1 } else { ch - 1 };
            let mapped = match self.ccs(ch) {
                1 => input == ch,
                2 => input == pair,
                _ => false,
            };
            let enabled = self.r(CCER) & (1 << (4 * (ch - 1))) != 0;
            if mapped && enabled {
                self.capture_channel(ch);
                n += 1;
            }
        }
        n
    }

    /// Encoder mode: the shaft is at `edges` quadrature edges (four per line). SMS = 3
    /// counts every edge, SMS = 1/2 the edges of one input (half); CC1P xor CC2P reverses
    /// the direction. CNT wraps within 0..=ARR with an update event per wrap.
    pub fn set_encoder(&mut self, edges: i64) {
        let prev = self.enc;
        self.enc = edges;
        if !self.encoder() || self.r(CR1) & CEN == 0 {
            return;
        }
        let mut delta = match self.sms() {
            3 => edges.wrapping_sub(prev),
            _ => edges.div_euclid(2).wrapping_sub(prev.div_euclid(2)),
        };
        let ccer = self.r(CCER);
        if ((ccer >> 1) ^ (ccer >> 5)) & 1 != 0 {
            delta = delta.wrapping_neg();
        }
        if delta == 0 {
            return;
        }
        let span = i128::from(self.arr_sh) + 1;
        let pos = i128::from(self.cnt) + i128::from(delta);
        let wraps = pos.div_euclid(span);
        self.cnt = pos.rem_euclid(span) as u32;
        if delta < 0 {
            self.regs[CR1 / 4] |= DIR;
        } else {
            self.regs[CR1 / 4] &= !DIR;
        }
        if wraps != 0 && self.r(CR1) & UDIS == 0 {
            self.update_event(true);
        }
    }

    /// The duty of channel `ch` (1..=4) as a PWM output: `None` unless the channel is an
    /// enabled output (CCxE, and BDTR.MOE on TIM1/TIM8) in PWM mode 1 or 2 on a running
    /// counter. Active-low polarity (CCxP) inverts it.
    pub fn pwm_duty(&self, ch: u8) -> Option<f64> {
        if ch == 0 || ch > self.kind.channels || self.ccs(ch) != 0 || !self.running() {
            return None;
        }
        let mut ccer = self.r(CCER) >> (4 * (ch - 1));
        if ccer & 1 == 0 && self.kind.advanced && ch < 4 && ccer & 4 != 0 {
            // The complementary output alone (CCxE = 0, CCxNE = 1): OCxN = OCxREF xor
            // CCxNP (RM0390 §17.4.9, output control bits), the channel's PWM itself.
            ccer = 1 | ((ccer >> 2) & 2);
        }
        if ccer & 1 == 0 || (self.kind.advanced && self.r(BDTR) & MOE == 0) {
            return None;
        }
        let ccmr = self.r(CCMR1 + 4 * usize::from((ch - 1) / 2));
        let ocm = (ccmr >> (4 + 8 * u32::from((ch - 1) % 2))) & 7;
        let ccr = f64::from(self.r(CCR1 + 4 * usize::from(ch - 1)));
        let arr = f64::from(self.arr_sh);
        let high = if self.cms() != 0 {
            (ccr / arr.max(1.0)).min(1.0)
        } else {
            (ccr / (arr + 1.0)).min(1.0)
        };
        let duty = match ocm {
            6 => high,
            7 => 1.0 - high,
            _ => return None,
        };
        Some(if ccer & 2 != 0 { 1.0 - duty } else { duty })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tim6() -> Timer {
        let mut t = Timer::new(TIMERS[5]);
        t.clk_div = 2; // 90 MHz timer clock at 180 MHz
        t
    }

    #[test]
    fn an_upcounter_reaches_its_update_event_at_psc_and_arr_and_sets_uif() {
        let mut t = tim6();
        t.write(PSC, 8, 0); // 10 MHz counter clock
        t.write(ARR, 999, 0); // 10 kHz updates
        t.write(EGR, 1, 0); // load PSC
        t.write(SR, 0, 0);
        t.write(DIER, 1, 0);
        t.write(CR1, CEN, 100);
        // 1,000 counter ticks × 9 × 2 cycles = 18,000 cycles.
        assert_eq!(t.next_event(), Some(100 + 18_000));
        assert_eq!(t.read(CNT, 100 + 18 * 500), 500);
        assert_eq!(t.read(SR, 100 + 17_999) & UIF, 0);
        assert_eq!(t.read(SR, 100 + 18_000) & UIF, UIF);
        assert_eq!(t.irq_lines(), crate::nvic::bit(16 + 54));
        assert_eq!(t.read(CNT, 100 + 18_000), 0);
        t.write(SR, !UIF, 100 + 18_000);
        assert_eq!(t.irq_lines(), 0);
        assert_eq!(t.next_event(), Some(100 + 36_000));
        // Many periods at once.
        assert_eq!(t.read(CNT, 100 + 18_000 * 1_000 + 18 * 7), 7);
        assert_eq!(t.read(SR, 100 + 18_000 * 1_000 + 18 * 7) & UIF, UIF);
    }

    #[test]
    fn psc_waits_for_the_update_event_and_arr_preloads_only_with_arpe() {
        let mut t = tim6();
        t.clk_div = 1;
        t.write(ARR, 9, 0);
        t.write(CR1, CEN, 0);
        t.write(PSC, 1, 0); // takes effect at the first update (10 ticks)
        assert_eq!(t.read(CNT, 10), 0);
        assert_eq!(t.read(CNT, 14), 2);
        // ARPE: the new ARR waits for the next update.
        t.write(CR1, CEN | ARPE, 14);
        t.write(ARR, 3, 14);
        assert_eq!(t.read(CNT, 29), 9);
        assert_eq!(t.read(CNT, 30), 0);
        assert_eq!(t.read(CNT, 38), 0, "period 4 × 2 now");
    }

    #[test]
    fn downcounting_and_center_aligned_counting_follow_dir_and_cms() {
        let mut t = Timer::new(TIMERS[2]); // TIM3
        t.write(ARR, 4, 0);
        t.write(CR1, CEN | DIR, 0);
        t.write(EGR, 1, 0);
        assert_eq!(t.read(CNT, 0), 4);
        assert_eq!(t.read(CNT, 4), 0);
        assert_eq!(t.read(CNT, 5), 4, "underflow reloads ARR");
        let mut c = Timer::new(TIMERS[2]);
        c.write(ARR, 4, 0);
        c.write(CR1, CEN | (1 << 5), 0);
        assert_eq!(c.read(CNT, 3), 3);
        assert_eq!(c.read(CNT, 4), 4);
        assert_eq!(
            c.read(CR1, 4) & DIR,
            DIR,
            "counting down after the overflow"
        );
        assert_eq!(c.read(CNT, 7), 1);
        assert_eq!(c.read(CNT, 8), 0);
        assert_eq!(c.read(CNT, 9), 1);
    }

    #[test]
    fn tim1_updates_every_rcr_plus_one_periods_and_opm_stops_the_counter() {
        let mut t = Timer::new(TIMERS[0]);
        t.write(ARR, 9, 0);
        t.write(RCR, 2, 0);
        t.write(EGR, 1, 0);
        t.write(SR, 0, 0);
        t.write(DIER, 1, 0);
        t.write(CR1, CEN, 0);
        assert_eq!(t.next_event(), Some(30));
        assert_eq!(t.read(SR, 29) & UIF, 0);
        assert_eq!(t.read(SR, 30) & UIF, UIF);
        let mut o = Timer::new(TIMERS[5]);
        o.write(ARR, 9, 0);
        o.write(CR1, CEN | OPM, 0);
        assert_eq!(o.read(CNT, 100), 0);
        assert_eq!(o.read(CR1, 100) & CEN, 0, "one pulse");
    }

    #[test]
    fn encoder_mode_takes_cnt_from_the_position_and_wraps_at_arr() {
        let mut t = Timer::new(TIMERS[1]); // TIM2, 32-bit
        t.write(ARR, 999, 0);
        t.write(SMCR, 3, 0);
        t.write(CR1, CEN, 0);
        t.set_encoder(250);
        assert_eq!(t.read(CNT, 1_000_000), 250, "no counting from the clock");
        t.set_encoder(-10);
        assert_eq!(t.read(CNT, 0), 990);
        assert_eq!(t.read(CR1, 0) & DIR, DIR);
        assert_eq!(t.read(SR, 0) & UIF, UIF, "underflow is an update");
        // SMS = 1 counts half the edges; CC1P reverses.
        t.write(SMCR, 1, 0);
        t.write(CNT, 0, 0);
        t.write(CCER, 1 << 1, 0);
        t.set_encoder(-10 + 20);
        assert_eq!(t.read(CNT, 0), 990);
    }

    #[test]
    fn an_edge_captures_cnt_into_the_mapped_channels_with_overcapture() {
        let mut t = Timer::new(TIMERS[2]); // TIM3
        t.write(CCMR1, 1 | (2 << 8), 0); // CC1 ← TI1, CC2 ← TI1
        t.write(CCER, 1 | (1 << 4), 0);
        t.write(DIER, 1 << 1, 0);
        t.write(CR1, CEN, 0);
        assert_eq!(t.capture(1, 1234), 2);
        assert_eq!(t.read(SR, 1234) & 0x6, 0x6);
        assert_eq!(t.irq_lines(), crate::nvic::bit(16 + 29));
        assert_eq!(t.capture(2, 1300), 0, "nothing mapped to TI2");
        t.capture(1, 2000);
        assert_eq!(t.read(SR, 2000) & (1 << 9), 1 << 9, "CC1OF");
        assert_eq!(t.read(CCR1, 2000), 2000);
        assert_eq!(t.read(SR, 2000) & 2, 0, "reading CCR1 cleared CC1IF");
        t.write(CCR1, 5, 2000);
        assert_eq!(t.read(CCR1, 2000), 2000, "read-only in input mode");
    }

    #[test]
    fn a_capture_on_ch1_of_a_compare_pulse_master_captures_trc_of_its_itr_slaves() {
        assert_eq!(itr_source(5, 0), Some(2), "TIM5 ITR0 = TIM2");
        assert_eq!(itr_source(4, 2), Some(3), "TIM4 ITR2 = TIM3");
        assert_eq!(itr_source(6, 0), None);
        let mut enc = Timer::new(TIMERS[1]); // TIM2
        enc.write(CCMR1, 1 | (1 << 8), 0);
        enc.write(CCER, 1 | (1 << 4), 0);
        enc.write(SMCR, 3, 0);
        enc.write(CR1, CEN, 0);
        enc.capture(1, 10);
        assert_eq!(enc.take_trgo(), 0, "MMS = 000: no pulse");
        enc.write(CR2, 3 << 4, 10);
        enc.capture(2, 20);
        assert_eq!(enc.take_trgo(), 0, "only CH1 pulses");
        enc.capture(1, 30);
        assert_eq!(enc.take_trgo(), 1);
        let mut cap = Timer::new(TIMERS[4]); // TIM5
        cap.write(SMCR, 0 << 4, 0);
        cap.write(CCMR1, 3, 0); // CC1 on TRC
        cap.write(CCER, 1, 0);
        cap.write(CR1, CEN, 0);
        assert_eq!(cap.trigger_source(), Some(2));
        assert_eq!(cap.trigger(500), 1);
        assert_eq!(cap.read(SR, 500) & 2, 2);
        assert_eq!(cap.read(CCR1, 500), 500);
    }

    #[test]
    fn oc4ref_as_trgo_rises_where_the_pwm_mode_puts_it_in_the_counting_period() {
        const CCMR2: usize = 0x1C;
        let mut t = Timer::new(TIMERS[0]); // TIM1 at the CPU clock
        t.write(ARR, 100, 0);
        t.write(CCMR2, 7 << 12, 0); // OC4M: PWM mode 2
        t.write(CCR1 + 12, 80, 0);
        t.write(CR2, 7 << 4, 0); // MMS: OC4REF
        assert_eq!(t.next_trgo_rise(0), None, "not counting");
        // Centre-aligned: a period of 2 × ARR = 200 ticks; mode 2 rises counting up at 80.
        t.write(CR1, CEN | (1 << 5), 1000);
        assert!(t.trgo_edges_modelled());
        assert_eq!(t.next_trgo_rise(1000), Some(1080));
        assert_eq!(t.next_trgo_rise(1080), Some(1280));
        t.sync(1150); // counting down at 50
        assert_eq!(t.next_trgo_rise(1100), Some(1280));
        // Mode 1 rises counting down at 80: 2 × 100 − 80 = 120 ticks into the period.
        t.write(CCMR2, 6 << 12, 1150);
        assert_eq!(t.next_trgo_rise(1150), Some(1120 + 200));
        // Edge-aligned up-counting: a period of ARR + 1; mode 1 rises at the update (0),
        // mode 2 at CCR.
        let mut e = Timer::new(TIMERS[0]);
        e.write(ARR, 99, 0);
        e.write(CCMR2, 6 << 12, 0);
        e.write(CCR1 + 12, 30, 0);
        e.write(CR2, 7 << 4, 0);
        e.write(CR1, CEN, 500);
        assert_eq!(e.next_trgo_rise(500), Some(600));
        e.write(CCMR2, 7 << 12, 500);
        assert_eq!(e.next_trgo_rise(500), Some(530));
        // CCR beyond ARR: OC4REF never changes; other master modes are not modelled.
        e.write(CCR1 + 12, 200, 500);
        assert_eq!(e.next_trgo_rise(500), None);
        e.write(CR2, 1 << 4, 500);
        assert!(!e.trgo_edges_modelled(), "MMS = 001 (enable)");
    }

    #[test]
    fn the_update_event_as_trgo_rises_every_rcr_plus_one_half_periods_centre_aligned() {
        let mut t = Timer::new(TIMERS[0]); // TIM1 at the CPU clock
        t.write(ARR, 100, 0);
        t.write(RCR, 7, 0);
        t.write(CR2, 2 << 4, 0); // MMS: update
        t.write(EGR, 1, 0);
        assert!(t.trgo_edges_modelled());
        assert_eq!(t.next_trgo_rise(0), None, "not counting");
        t.write(CR1, CEN | (1 << 5), 1000);
        // Eight over/underflows of 100 ticks: the 8th, an underflow, is the update.
        assert_eq!(t.next_trgo_rise(1000), Some(1800));
        assert_eq!(t.next_trgo_rise(1800), Some(2600));
        assert_eq!(t.read(CNT, 1800), 0, "at the bottom");
        // The counter ran past two updates: the one after 1000 is still found.
        t.sync(3000);
        assert_eq!(t.next_trgo_rise(1000), Some(1800));
        assert_eq!(t.next_trgo_rise(2599), Some(2600));
        assert_eq!(t.next_trgo_rise(2600), Some(3400));
        // UDIS: no update event, no pulse.
        t.write(CR1, CEN | (1 << 5) | UDIS, 3000);
        assert_eq!(t.next_trgo_rise(3000), None);
    }

    #[test]
    fn pwm_duty_follows_ccr_arr_mode_polarity_and_moe() {
        let mut t = Timer::new(TIMERS[0]); // TIM1
        t.write(ARR, 8999, 0);
        t.write(CCMR1, (6 << 4) | (7 << 12), 0); // CH1 PWM1, CH2 PWM2
        t.write(CCR1, 2250, 0);
        t.write(CCR1 + 4, 2250, 0);
        t.write(CCER, 1 | (1 << 4), 0);
        t.write(CR1, CEN, 0);
        assert_eq!(t.pwm_duty(1), None, "MOE off");
        // AOE: the next update event sets MOE.
        t.write(BDTR, AOE, 0);
        assert_eq!(t.pwm_duty(1), None, "MOE waits for an update event");
        t.read(CNT, 9000);
        assert_eq!(t.read(BDTR, 9000) & MOE, MOE, "set by the update");
        t.write(BDTR, MOE, 9000);
        assert_eq!(t.pwm_duty(1), Some(0.25));
        assert_eq!(t.pwm_duty(2), Some(0.75));
        t.write(CCER, 1 | 2 | (1 << 4), 0);
        assert_eq!(t.pwm_duty(1), Some(0.75));
        assert_eq!(t.pwm_duty(3), None);
        // CH3N alone (CC3E = 0, CC3NE = 1) outputs OC3REF itself; CC3NP inverts it.
        t.write(0x1C, 6 << 4, 0); // CCMR2: OC3M PWM mode 1
        t.write(CCR1 + 8, 900, 0);
        t.write(CCER, 1 | (1 << 4) | (1 << 10), 0);
        assert_eq!(t.pwm_duty(3), Some(0.1));
        t.write(CCER, 1 | (1 << 4) | (1 << 10) | (1 << 11), 0);
        assert_eq!(t.pwm_duty(3), Some(0.9));
        // Offsets past the register file read as zero and ignore writes.
        t.write(0x3FC, 7, 0);
        assert_eq!(t.read(0x3FC, 0), 0);
    }
}
