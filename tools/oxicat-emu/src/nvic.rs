//! The System Control Space of the Cortex-M4: NVIC, SCB, SysTick, DWT cycle counter and
//! the FPU's control registers (ARMv7-M ARM B3.2–B3.4, C1.8; PM0214).
//!
//! Exceptions are numbered as in IPSR: 1 Reset, 2 NMI, 3 HardFault, 4 MemManage,
//! 5 BusFault, 6 UsageFault, 11 SVCall, 12 DebugMonitor, 14 PendSV, 15 SysTick, 16 + n
//! IRQ n. Enabled/pending/active states are bit sets over exception numbers (`u128`: the
//! STM32F446 has 97 IRQs, 113 exceptions in all). This module is the bookkeeping and the
//! priority rules; `cpu.rs` stacks and unstacks frames on the engine.

/// IRQ lines of the STM32F446 (RM0390 table 38: positions 0..=96).
pub(crate) const NUM_IRQ: usize = 97;
/// Exception numbers 0..NUM_EXC.
pub(crate) const NUM_EXC: usize = 16 + NUM_IRQ;

pub(crate) const NMI: u16 = 2;
pub(crate) const HARDFAULT: u16 = 3;
pub(crate) const MEMMANAGE: u16 = 4;
pub(crate) const BUSFAULT: u16 = 5;
pub(crate) const USAGEFAULT: u16 = 6;
pub(crate) const SVCALL: u16 = 11;
pub(crate) const PENDSV: u16 = 14;
pub(crate) const SYSTICK: u16 = 15;

/// Priority bits the STM32F4 implements: the upper four of each 8-bit field.
const PRIO_MASK: u8 = 0xF0;

/// Base of the SCS page.
pub(crate) const SCS_BASE: u64 = 0xE000_E000;
const SYST: u64 = 0xE000_E010;
const NVIC_ISER: u64 = 0xE000_E100;
const NVIC_ICER: u64 = 0xE000_E180;
const NVIC_ISPR: u64 = 0xE000_E200;
const NVIC_ICPR: u64 = 0xE000_E280;
const NVIC_IABR: u64 = 0xE000_E300;
const NVIC_IPR: u64 = 0xE000_E400;
const CPUID: u64 = 0xE000_ED00;
const ICSR: u64 = 0xE000_ED04;
const VTOR: u64 = 0xE000_ED08;
const AIRCR: u64 = 0xE000_ED0C;
pub(crate) const SCR: u64 = 0xE000_ED10;
const CCR: u64 = 0xE000_ED14;
const SHPR1: u64 = 0xE000_ED18;
const SHCSR: u64 = 0xE000_ED24;
pub(crate) const CPACR: u64 = 0xE000_ED88;
const DEMCR: u64 = 0xE000_EDFC;
const STIR: u64 = 0xE000_EF00;
const FPCCR: u64 = 0xE000_EF34;

/// DWT block base (its own page).
pub(crate) const DWT_BASE: u64 = 0xE000_1000;

/// Bit of exception `e` in a set.
pub(crate) fn bit(e: u16) -> u128 {
    1u128 << e
}

/// NVIC + SCB + SysTick + DWT state.
pub(crate) struct Scs {
    /// Raw storage of the page for registers without behaviour.
    pub raw: Vec<u32>,
    pub enabled: u128,
    pub pending: u128,
    pub active: u128,
    /// Raw 8-bit priorities (upper four bits kept).
    pub prio: [u8; NUM_EXC],
    pub prigroup: u32,
    /// The exception being handled (IPSR), 0 in thread mode.
    pub ipsr: u16,
    /// Exceptions taken, by number.
    pub taken: [u64; NUM_EXC],
    /// SYSRESETREQ was written.
    pub reset_requested: bool,
    /// Cycle count at SysTick's last reload.
    syst_ref: u64,
    countflag: bool,
    /// DWT: CYCCNT value at `dwt_ref` (active cycles), counting or not.
    dwt_ctrl: u32,
    dwt_base: u32,
    dwt_ref: u64,
    dwt_raw: Vec<u32>,
}

impl Scs {
    pub fn new() -> Self {
        let mut s = Scs {
            raw: vec![0; 0x1000 / 4],
            enabled: 0,
            pending: 0,
            active: 0,
            prio: [0; NUM_EXC],
            prigroup: 0,
            ipsr: 0,
            taken: [0; NUM_EXC],
            reset_requested: false,
            syst_ref: 0,
            countflag: false,
            dwt_ctrl: 0x4000_0000, // NUMCOMP = 4
            dwt_base: 0,
            dwt_ref: 0,
            dwt_raw: vec![0; 0x1000 / 4],
        };
        // CCR: STKALIGN set at reset on the Cortex-M4 (r0p1); FPCCR: ASPEN | LSPEN.
        s.put(CCR, 0x200);
        s.put(FPCCR, 0xC000_0000);
        s
    }

    fn idx(addr: u64) -> usize {
        ((addr - SCS_BASE) / 4) as usize
    }

    fn get(&self, addr: u64) -> u32 {
        self.raw[Self::idx(addr)]
    }

    fn put(&mut self, addr: u64, v: u32) {
        self.raw[Self::idx(addr)] = v;
    }

    /// The word a sub-word write is merged into: zero for the write-one-to-act registers
    /// (a byte written to ISER must not re-write the other bytes' ones).
    pub fn merge_base(&self, addr: u64) -> u32 {
        match addr {
            a if (NVIC_ISER..NVIC_IABR).contains(&a) => 0,
            ICSR | STIR => 0,
            a => self.get(a),
        }
    }

    /// CPACR grants CP10 and CP11 (the FPU) some access.
    pub fn fpu_enabled(&self) -> bool {
        let c = self.get(CPACR);
        (c >> 20) & 3 != 0 && (c >> 22) & 3 != 0
    }

    pub fn vtor(&self) -> u32 {
        self.get(VTOR)
    }

    /// SCR.SLEEPONEXIT.
    pub fn sleep_on_exit(&self) -> bool {
        self.get(SCR) & 2 != 0
    }

    /// The 8-bit priority of exception `e` (negative for Reset, NMI, HardFault).
    pub fn priority(&self, e: u16) -> i16 {
        match e {
            1 => -3,
            NMI => -2,
            HARDFAULT => -1,
            e => i16::from(self.prio[usize::from(e)]),
        }
    }

    /// The group (preemption) part of a priority under PRIGROUP.
    pub fn group(&self, p: i16) -> i16 {
        if p < 0 {
            return p;
        }
        let sub = (2i16 << self.prigroup) - 1;
        p & !sub
    }

    /// Whether exception `e` is enabled (IRQs: ISER; the configurable faults: SHCSR).
    fn is_enabled(&self, e: u16) -> bool {
        match e {
            MEMMANAGE => self.get(SHCSR) & (1 << 16) != 0,
            BUSFAULT => self.get(SHCSR) & (1 << 17) != 0,
            USAGEFAULT => self.get(SHCSR) & (1 << 18) != 0,
            e if e >= 16 => self.enabled & bit(e) != 0,
            _ => true,
        }
    }

    /// Highest-priority pending and enabled exception (lowest priority value, then lowest
    /// number), if any.
    pub fn top_pending(&self) -> Option<u16> {
        let mut set = self.pending;
        let mut best: Option<(i16, u16)> = None;
        while set != 0 {
            let e = set.trailing_zeros() as u16;
            set &= set - 1;
            if !self.is_enabled(e) {
                continue;
            }
            let p = self.priority(e);
            if best.is_none_or(|(bp, _)| p < bp) {
                best = Some((p, e));
            }
        }
        best.map(|(_, e)| e)
    }

    /// The priority of the active exceptions alone (256 in thread mode with none active).
    pub fn active_priority(&self) -> i16 {
        let mut set = self.active;
        let mut pri = 256;
        while set != 0 {
            let e = set.trailing_zeros() as u16;
            set &= set - 1;
            pri = pri.min(self.group(self.priority(e)));
        }
        pri
    }

    /// ARMv7-M ExecutionPriority: the active exceptions' priority boosted by PRIMASK,
    /// BASEPRI and FAULTMASK.
    pub fn execution_priority(&self, m: Masks) -> i16 {
        let mut boost = 256;
        if m.primask & 1 != 0 {
            boost = 0;
        }
        let basepri = (m.basepri & 0xFF) as i16;
        if basepri != 0 {
            boost = boost.min(self.group(basepri));
        }
        if m.faultmask & 1 != 0 {
            boost = -1;
        }
        self.active_priority().min(boost)
    }

    /// The exception to take now under `masks`, if one preempts.
    pub fn takeable(&self, m: Masks) -> Option<u16> {
        let e = self.top_pending()?;
        (self.group(self.priority(e)) < self.execution_priority(m)).then_some(e)
    }

    /// Whether a pending exception would wake the core from WFI: it would preempt with
    /// PRIMASK clear (PRIMASK does not stop the wake-up; BASEPRI and FAULTMASK do).
    pub fn wakes(&self, m: Masks) -> bool {
        self.takeable(Masks { primask: 0, ..m }).is_some()
    }

    /// Marks `e` active and no longer pending; IPSR becomes `e`.
    pub fn activate(&mut self, e: u16) {
        self.pending &= !bit(e);
        self.active |= bit(e);
        self.ipsr = e;
        self.taken[usize::from(e)] += 1;
    }

    /// Level-sensitive interrupt inputs: a high line pends its IRQ unless it is active
    /// (it pends again after the handler returns if still high).
    pub fn assert_lines(&mut self, lines: u128) {
        self.pending |= lines & !self.active;
    }

    /// SysTick: the period in CPU cycles, if counting.
    fn syst_period(&self) -> Option<u64> {
        let csr = self.get(SYST);
        if csr & 1 == 0 {
            return None;
        }
        let rvr = u64::from(self.get(SYST + 4) & 0x00FF_FFFF);
        // CLKSOURCE (bit 2): the processor clock, else the external reference HCLK/8.
        let k = if csr & 4 != 0 { 1 } else { 8 };
        Some((rvr + 1) * k)
    }

    /// Brings SysTick up to `now`: COUNTFLAG on a wrap, and the SysTick exception pended
    /// when TICKINT is set.
    pub fn syst_sync(&mut self, now: u64) {
        let Some(period) = self.syst_period() else {
            return;
        };
        let elapsed = now.saturating_sub(self.syst_ref);
        if elapsed >= period {
            self.countflag = true;
            self.syst_ref += elapsed / period * period;
            if self.get(SYST) & 2 != 0 {
                self.pending |= bit(SYSTICK);
            }
        }
    }

    /// The cycle of SysTick's first wrap after `now`, if it counts.
    pub fn syst_wrap_after(&self, now: u64) -> Option<u64> {
        let period = self.syst_period()?;
        Some(self.syst_ref + (now.saturating_sub(self.syst_ref) / period + 1) * period)
    }

    /// The cycle of SysTick's next wrap, when it raises an exception.
    pub fn syst_next(&self) -> Option<u64> {
        let period = self.syst_period()?;
        (self.get(SYST) & 2 != 0).then(|| self.syst_ref + period)
    }

    fn dwt_counting(&self) -> bool {
        self.get(DEMCR) & (1 << 24) != 0 && self.dwt_ctrl & 1 != 0
    }

    fn cyccnt(&self, active: u64) -> u32 {
        if self.dwt_counting() {
            self.dwt_base
                .wrapping_add(active.saturating_sub(self.dwt_ref) as u32)
        } else {
            self.dwt_base
        }
    }

    /// Re-bases CYCCNT at `active` before its counting condition changes.
    fn dwt_rebase(&mut self, active: u64) {
        self.dwt_base = self.cyccnt(active);
        self.dwt_ref = active;
    }

    /// A read of the DWT page (`active`: cycles the core ran, not slept).
    pub fn dwt_read(&self, addr: u64, active: u64) -> u32 {
        match addr - DWT_BASE {
            0 => self.dwt_ctrl,
            4 => self.cyccnt(active),
            o => self.dwt_raw[(o / 4) as usize],
        }
    }

    pub fn dwt_write(&mut self, addr: u64, v: u32, active: u64) {
        match addr - DWT_BASE {
            0 => {
                self.dwt_rebase(active);
                // NUMCOMP and the NOxxx bits are read-only.
                self.dwt_ctrl = (self.dwt_ctrl & 0xFF00_0000) | (v & 0x00FF_FFFF);
            }
            4 => {
                self.dwt_base = v;
                self.dwt_ref = active;
            }
            o => self.dwt_raw[(o / 4) as usize] = v,
        }
    }

    /// A read of the SCS page at `now` (CPU cycles).
    pub fn read(&mut self, addr: u64, now: u64) -> u32 {
        match addr {
            SYST => {
                self.syst_sync(now);
                let v = self.get(SYST) | (u32::from(self.countflag) << 16);
                self.countflag = false;
                v
            }
            a if a == SYST + 8 => {
                self.syst_sync(now);
                match self.syst_period() {
                    Some(period) => {
                        let k = if self.get(SYST) & 4 != 0 { 1 } else { 8 };
                        let left = period - (now - self.syst_ref) % period;
                        ((left / k) % (period / k)) as u32
                    }
                    None => self.get(a),
                }
            }
            // CALIB: NOREF, 10 ms at HCLK/8.
            a if a == SYST + 0xC => 0x4000_0000 | (crate::CPU_HZ / 8 / 100) as u32,
            a if (NVIC_ISER..NVIC_ISER + 0x20).contains(&a) => self.irq_word(self.enabled, a),
            a if (NVIC_ICER..NVIC_ICER + 0x20).contains(&a) => self.irq_word(self.enabled, a),
            a if (NVIC_ISPR..NVIC_ISPR + 0x20).contains(&a) => self.irq_word(self.pending, a),
            a if (NVIC_ICPR..NVIC_ICPR + 0x20).contains(&a) => self.irq_word(self.pending, a),
            a if (NVIC_IABR..NVIC_IABR + 0x20).contains(&a) => self.irq_word(self.active, a),
            a if (NVIC_IPR..NVIC_IPR + 0xF0).contains(&a) => {
                let first = 16 + (a - NVIC_IPR) as usize;
                self.prio_word(first)
            }
            CPUID => 0x410F_C241,
            ICSR => self.icsr(),
            AIRCR => 0xFA05_0000 | (self.prigroup << 8),
            a if (SHPR1..SHPR1 + 12).contains(&a) => self.prio_word(4 + (a - SHPR1) as usize),
            SHCSR => self.shcsr(),
            a => self.get(a),
        }
    }

    fn irq_word(&self, set: u128, addr: u64) -> u32 {
        let word = ((addr & 0x1F) / 4) as u32;
        let irqs = (set >> 16) & ((1u128 << NUM_IRQ) - 1);
        irqs.checked_shr(32 * word).unwrap_or(0) as u32
    }

    fn prio_word(&self, first: usize) -> u32 {
        (0..4).fold(0, |w, k| {
            let p = self.prio.get(first + k).copied().unwrap_or(0);
            w | (u32::from(p) << (8 * k))
        })
    }

    fn set_prio_word(&mut self, first: usize, v: u32) {
        for k in 0..4 {
            if let Some(p) = self.prio.get_mut(first + k) {
                *p = (v >> (8 * k)) as u8 & PRIO_MASK;
            }
        }
    }

    fn icsr(&self) -> u32 {
        let mut v = u32::from(self.ipsr);
        // RETTOBASE: no active exception other than the current one.
        if self.active & !bit(self.ipsr) == 0 {
            v |= 1 << 11;
        }
        if let Some(e) = self.top_pending() {
            v |= u32::from(e) << 12;
        }
        if self.pending >> 16 != 0 {
            v |= 1 << 22;
        }
        if self.pending & bit(SYSTICK) != 0 {
            v |= 1 << 26;
        }
        if self.pending & bit(PENDSV) != 0 {
            v |= 1 << 28;
        }
        if self.pending & bit(NMI) != 0 {
            v |= 1 << 31;
        }
        v
    }

    fn shcsr(&self) -> u32 {
        let mut v = self.get(SHCSR) & (7 << 16);
        for (e, b) in [
            (MEMMANAGE, 0),
            (BUSFAULT, 1),
            (USAGEFAULT, 3),
            (SVCALL, 7),
            (12, 8),
            (PENDSV, 10),
            (SYSTICK, 11),
        ] {
            if self.active & bit(e) != 0 {
                v |= 1 << b;
            }
        }
        for (e, b) in [
            (USAGEFAULT, 12),
            (MEMMANAGE, 13),
            (BUSFAULT, 14),
            (SVCALL, 15),
        ] {
            if self.pending & bit(e) != 0 {
                v |= 1 << b;
            }
        }
        v
    }

    /// A write to the SCS page at `now` (`active`: cycles the core ran). Returns whether
    /// the interrupt state may have changed.
    pub fn write(&mut self, addr: u64, v: u32, now: u64, active: u64) -> bool {
        let irq_bits = |a: u64| -> u128 {
            let word = ((a & 0x1F) / 4) as u32;
            u128::from(v).checked_shl(16 + 32 * word).unwrap_or(0)
                & (((1u128 << NUM_IRQ) - 1) << 16)
        };
        match addr {
            SYST => {
                self.syst_sync(now);
                if v & 1 != 0 && self.get(SYST) & 1 == 0 {
                    self.syst_ref = now;
                }
                self.put(SYST, v & 7);
            }
            a if a == SYST + 4 => self.put(a, v & 0x00FF_FFFF),
            a if a == SYST + 8 => {
                // Any write clears CVR and COUNTFLAG.
                self.syst_ref = now;
                self.countflag = false;
            }
            a if (NVIC_ISER..NVIC_ISER + 0x20).contains(&a) => self.enabled |= irq_bits(a),
            a if (NVIC_ICER..NVIC_ICER + 0x20).contains(&a) => self.enabled &= !irq_bits(a),
            a if (NVIC_ISPR..NVIC_ISPR + 0x20).contains(&a) => self.pending |= irq_bits(a),
            a if (NVIC_ICPR..NVIC_ICPR + 0x20).contains(&a) => self.pending &= !irq_bits(a),
            a if (NVIC_IABR..NVIC_IABR + 0x20).contains(&a) => {}
            a if (NVIC_IPR..NVIC_IPR + 0xF0).contains(&a) => {
                self.set_prio_word(16 + (a - NVIC_IPR) as usize, v)
            }
            CPUID => {}
            ICSR => {
                if v & (1 << 31) != 0 {
                    self.pending |= bit(NMI);
                }
                if v & (1 << 28) != 0 {
                    self.pending |= bit(PENDSV);
                } else if v & (1 << 27) != 0 {
                    self.pending &= !bit(PENDSV);
                }
                if v & (1 << 26) != 0 {
                    self.pending |= bit(SYSTICK);
                } else if v & (1 << 25) != 0 {
                    self.pending &= !bit(SYSTICK);
                }
            }
            VTOR => self.put(VTOR, v & 0xFFFF_FF80),
            AIRCR => {
                if v >> 16 == 0x05FA {
                    self.prigroup = (v >> 8) & 7;
                    if v & 4 != 0 {
                        self.reset_requested = true;
                    }
                }
            }
            a if (SHPR1..SHPR1 + 12).contains(&a) => {
                self.set_prio_word(4 + (a - SHPR1) as usize, v)
            }
            SHCSR => {
                // Enables stored; active/pending bits written by software are not modelled.
                self.put(SHCSR, v & (7 << 16));
            }
            DEMCR => {
                self.dwt_rebase(active);
                self.put(DEMCR, v);
            }
            STIR => {
                let irq = (v & 0x1FF) as usize;
                if irq < NUM_IRQ {
                    self.pending |= bit(16 + irq as u16);
                }
            }
            a => {
                self.put(a, v);
                return false;
            }
        }
        true
    }
}

/// The special registers that mask exceptions, as read from the core.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Masks {
    pub primask: u32,
    pub basepri: u32,
    pub faultmask: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn irq(n: u16) -> u16 {
        16 + n
    }

    #[test]
    fn the_highest_priority_pending_enabled_exception_preempts_only_a_lower_group() {
        let mut s = Scs::new();
        // IRQ 3 at 0x40, IRQ 5 at 0x20; both pending, only IRQ 3 enabled.
        s.write(NVIC_IPR, 0x40 << 24, 0, 0);
        s.write(NVIC_IPR + 4, 0x20 << 8, 0, 0);
        s.write(NVIC_ISPR, (1 << 3) | (1 << 5), 0, 0);
        s.write(NVIC_ISER, 1 << 3, 0, 0);
        let m = Masks::default();
        assert_eq!(s.takeable(m), Some(irq(3)));
        s.write(NVIC_ISER, 1 << 5, 0, 0);
        assert_eq!(s.takeable(m), Some(irq(5)));
        // In IRQ 5's handler (0x20), IRQ 3 (0x40) waits.
        s.activate(irq(5));
        assert_eq!(s.takeable(m), None);
        assert_eq!(s.read(ICSR, 0) & 0x1FF, u32::from(irq(5)));
        assert_eq!((s.read(ICSR, 0) >> 12) & 0x1FF, u32::from(irq(3)));
        // PRIGROUP 5: group bits [7:6], 0x20 and 0x40 differ in group ...
        s.write(AIRCR, 0x05FA_0500, 0, 0);
        assert_eq!(s.group(0x40), 0x40);
        assert_eq!(s.group(0x20), 0x00);
        // ... PRIGROUP 6: one group bit: 0x20 and 0x40 are the same group: no preemption.
        s.write(AIRCR, 0x05FA_0600, 0, 0);
        s.write(NVIC_IPR + 4, 0x50 << 8, 0, 0);
        s.pending |= bit(irq(5));
        s.active = bit(irq(3));
        assert_eq!(
            s.takeable(m),
            None,
            "0x50 does not preempt 0x40 with one group bit"
        );
        // AIRCR needs its key.
        s.write(AIRCR, 0x0000_0300, 0, 0);
        assert_eq!(s.read(AIRCR, 0), 0xFA05_0600);
    }

    #[test]
    fn primask_basepri_and_faultmask_raise_the_execution_priority() {
        let mut s = Scs::new();
        s.write(NVIC_IPR, 0x80, 0, 0); // IRQ 0 at 0x80
        s.write(NVIC_ISER, 1, 0, 0);
        s.write(NVIC_ISPR, 1, 0, 0);
        let none = Masks::default();
        assert_eq!(s.takeable(none), Some(16));
        let pm = Masks { primask: 1, ..none };
        assert_eq!(s.takeable(pm), None);
        assert!(s.wakes(pm), "PRIMASK does not stop WFI waking");
        let bp = Masks {
            basepri: 0x80,
            ..none
        };
        assert_eq!(s.takeable(bp), None);
        assert!(!s.wakes(bp));
        let bp_hi = Masks {
            basepri: 0x90,
            ..none
        };
        assert_eq!(s.takeable(bp_hi), Some(16));
        // FAULTMASK blocks even priority 0, NMI still preempts.
        let fm = Masks {
            faultmask: 1,
            ..none
        };
        s.write(NVIC_IPR, 0, 0, 0);
        assert_eq!(s.takeable(fm), None);
        s.write(ICSR, 1 << 31, 0, 0);
        assert_eq!(s.takeable(fm), Some(NMI));
    }

    #[test]
    fn pendsv_and_systick_pend_through_icsr_and_stir_pends_an_irq() {
        let mut s = Scs::new();
        s.write(ICSR, 1 << 28, 0, 0);
        assert_eq!(s.read(ICSR, 0) & (1 << 28), 1 << 28);
        s.write(ICSR, 1 << 27, 0, 0);
        assert_eq!(s.pending & bit(PENDSV), 0);
        s.write(STIR, 40, 0, 0);
        assert_eq!(s.read(NVIC_ISPR + 4, 0), 1 << 8);
        s.write(STIR, 500, 0, 0); // out of range: ignored
                                  // Words past the 97 IRQs read as zero and ignore writes.
        s.write(NVIC_ISER + 0x1C, u32::MAX, 0, 0);
        assert_eq!(s.read(NVIC_ISER + 0x1C, 0), 0);
        assert_eq!(s.read(NVIC_ISER + 0x0C, 0), 0);
        // A byte write to ISER sets only its own bits.
        assert_eq!(s.merge_base(NVIC_ISER), 0);
    }

    #[test]
    fn systick_pends_its_exception_on_each_wrap_only_with_tickint() {
        let mut s = Scs::new();
        s.write(SYST + 4, 99, 0, 0);
        s.write(SYST, 0b101, 0, 0); // processor clock, no TICKINT
        s.syst_sync(250);
        assert_eq!(s.pending & bit(SYSTICK), 0);
        assert_eq!(s.syst_next(), None);
        assert_eq!(s.read(SYST, 250) >> 16, 1, "COUNTFLAG");
        s.write(SYST, 0b111, 250, 0);
        assert_eq!(s.syst_next(), Some(300));
        s.syst_sync(299);
        assert_eq!(s.pending & bit(SYSTICK), 0);
        s.syst_sync(300);
        assert_ne!(s.pending & bit(SYSTICK), 0);
    }

    #[test]
    fn cyccnt_counts_only_with_trcena_and_cyccntena() {
        let mut s = Scs::new();
        s.dwt_write(DWT_BASE, 1, 0);
        assert_eq!(s.dwt_read(DWT_BASE + 4, 1000), 0, "TRCENA off");
        s.write(DEMCR, 1 << 24, 0, 1000);
        assert_eq!(s.dwt_read(DWT_BASE + 4, 1500), 500);
        s.dwt_write(DWT_BASE + 4, 10, 1500);
        assert_eq!(s.dwt_read(DWT_BASE + 4, 1600), 110);
        s.dwt_write(DWT_BASE, 0, 1600);
        assert_eq!(s.dwt_read(DWT_BASE + 4, 9000), 110);
        assert_eq!(s.dwt_read(DWT_BASE, 0) >> 28, 4, "NUMCOMP");
    }
}
