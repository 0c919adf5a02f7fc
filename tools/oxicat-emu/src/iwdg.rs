//! The independent watchdog (IWDG) of the STM32F446, from RM0390 §20, and the system reset
//! it causes.
//!
//! Registers at 0x4000_3000: KR (write-only, reads 0) takes the keys 0xCCCC (start),
//! 0xAAAA (reload the counter from RLR; also ends write access) and 0x5555 (unlocks PR and
//! RLR; any other key locks them again); PR (prescaler /4 · 2^PR, /256 for 6 and 7); RLR
//! (12-bit reload value, reset 0xFFF); SR (PVU, RVU: set while a PR or RLR write crosses
//! into the LSI domain, 5 LSI periods; a write while its flag is set is ignored, "can be
//! updated only when PVU/RVU is reset").
//!
//! The counter is clocked by the LSI (17–47 kHz on silicon, [`LSI_HZ`] nominal: a
//! parameter of the board, [`crate::Board::set_lsi_hz`]). Start loads it with 0xFFF — not
//! RLR: RM0390 §20.3.1, "the counter starts counting down from the reset value of 0xFFF" —
//! and each reload with RLR; it expires when it has counted down through 0, (count + 1)
//! prescaled ticks after the load (the table of RM0390: RL = 0 at /4 is 0.125 ms at 32 kHz),
//! and the board then goes through a system reset ([`crate::Board`]). A new prescaler or
//! a new LSI frequency applies from the moment it is written (the rest of the count at the
//! new rate), a new RLR at the next reload. Once started it cannot be stopped but by a
//! reset; the debug freeze (DBGMCU_APB1_FZ.DBG_IWDG_STOP) is not modelled (no core is ever
//! halted here). The window watchdog (WWDG, 0x4000_2C00) is not modelled: any access to it
//! stops the image with a fault naming the register.

/// IWDG's register page.
pub const IWDG_BASE: u64 = 0x4000_3000;
/// WWDG's register page (not modelled: an access is a fault).
pub const WWDG_BASE: u64 = 0x4000_2C00;
/// Nominal LSI frequency \[Hz\] (RM0390: 32 kHz; 17–47 kHz over process, voltage and
/// temperature per the STM32F446 datasheet).
pub const LSI_HZ: u32 = 32_000;
/// LSI periods a PR or RLR write takes to reach the watchdog's clock domain (SR.PVU/RVU).
const UPDATE_LSI_PERIODS: u64 = 5;

/// The independent watchdog's state.
#[derive(Debug, Clone)]
pub struct Iwdg {
    /// The LSI frequency \[Hz\] (a parameter of the board, kept across resets).
    pub lsi_hz: u32,
    unlocked: bool,
    pr: u32,
    rlr: u32,
    /// Cycles until which a PR / RLR write is in flight (SR.PVU / SR.RVU).
    pvu_until: u64,
    rvu_until: u64,
    /// Running: (cycle of the last load, count loaded then, prescaler divider then).
    run: Option<(u64, u32, u32)>,
}

impl Default for Iwdg {
    fn default() -> Self {
        Iwdg {
            lsi_hz: LSI_HZ,
            unlocked: false,
            pr: 0,
            rlr: 0xFFF,
            pvu_until: 0,
            rvu_until: 0,
            run: None,
        }
    }
}

fn divider(pr: u32) -> u32 {
    4 << (pr & 7).min(6)
}

impl Iwdg {
    /// CPU cycles of `ticks` LSI periods (rounded up).
    fn lsi_cycles(&self, ticks: u64) -> u64 {
        (ticks * crate::CPU_HZ).div_ceil(u64::from(self.lsi_hz.max(1)))
    }

    /// The state after a system reset: stopped, registers at their reset values (the LSI
    /// frequency stays, it is the board's).
    pub fn reset(&mut self) {
        *self = Iwdg {
            lsi_hz: self.lsi_hz,
            ..Iwdg::default()
        };
    }

    /// Started (until the next reset).
    pub fn running(&self) -> bool {
        self.run.is_some()
    }

    /// The timeout of a load of `count` at prescaler divider `div`, in CPU cycles.
    fn span(&self, count: u32, div: u32) -> u64 {
        self.lsi_cycles((u64::from(count) + 1) * u64::from(div))
    }

    /// The cycle the counter runs out, if running.
    pub fn expires(&self) -> Option<u64> {
        self.run.map(|(at, count, div)| at + self.span(count, div))
    }

    /// The counter's value at `now` (while running).
    fn count_at(&self, now: u64) -> Option<u32> {
        let (at, count, div) = self.run?;
        let ticks = (u128::from(now.saturating_sub(at)) * u128::from(self.lsi_hz)
            / (u128::from(crate::CPU_HZ) * u128::from(div))) as u64;
        Some(count.saturating_sub(u32::try_from(ticks).unwrap_or(u32::MAX)))
    }

    /// Rebases the running count at `now` (before a change of rate).
    fn rebase(&mut self, now: u64, div: u32) {
        if let Some(count) = self.count_at(now) {
            self.run = Some((now, count, div));
        }
    }

    /// A new LSI frequency from `now` on (the count so far at the old one).
    pub fn set_lsi_hz(&mut self, hz: u32, now: u64) {
        let div = self.run.map(|r| r.2);
        if let Some(div) = div {
            self.rebase(now, div);
        }
        self.lsi_hz = hz.max(1);
    }

    /// A register read at offset `off` of the page.
    pub fn read(&self, off: u64, now: u64) -> Result<u32, String> {
        Ok(match off {
            0x00 => 0, // KR is write-only
            0x04 => self.pr,
            0x08 => self.rlr,
            0x0C => u32::from(now < self.pvu_until) | (u32::from(now < self.rvu_until) << 1),
            o => return Err(unmodelled(o)),
        })
    }

    /// A register write at offset `off` of the page.
    pub fn write(&mut self, off: u64, v: u32, now: u64) -> Result<(), String> {
        match off {
            0x00 => match v & 0xFFFF {
                0xCCCC => {
                    self.unlocked = false;
                    if self.run.is_none() {
                        self.run = Some((now, 0xFFF, divider(self.pr)));
                    }
                }
                0xAAAA => {
                    self.unlocked = false;
                    if self.run.is_some() {
                        self.run = Some((now, self.rlr, divider(self.pr)));
                    }
                }
                0x5555 => self.unlocked = true,
                _ => self.unlocked = false,
            },
            0x04 if self.unlocked && now >= self.pvu_until => {
                self.rebase(now, divider(v));
                self.pr = v & 7;
                self.pvu_until = now + self.lsi_cycles(UPDATE_LSI_PERIODS);
            }
            0x08 if self.unlocked && now >= self.rvu_until => {
                self.rlr = v & 0xFFF;
                self.rvu_until = now + self.lsi_cycles(UPDATE_LSI_PERIODS);
            }
            0x04 | 0x08 | 0x0C => {} // protected, busy or read-only: ignored
            o => return Err(unmodelled(o)),
        }
        Ok(())
    }
}

fn unmodelled(off: u64) -> String {
    format!(
        "IWDG register at {:#010x} (offset {off:#x}) is not modelled (KR, PR, RLR, SR only)",
        IWDG_BASE + off
    )
}

/// The fault for an access to the window watchdog.
pub fn wwdg_fault(addr: u64) -> String {
    let name = match addr - WWDG_BASE {
        0 => "WWDG_CR",
        4 => "WWDG_CFR",
        8 => "WWDG_SR",
        _ => "WWDG",
    };
    format!("{name} ({addr:#010x}): the window watchdog is not modelled")
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = crate::CPU_HZ / 1000;

    #[test]
    fn start_counts_from_0xfff_and_a_reload_from_rlr_at_the_prescaled_lsi() {
        let mut w = Iwdg::default();
        w.write(0, 0x5555, 0).unwrap();
        w.write(4, 6, 0).unwrap(); // /256: 8 ms per tick at 32 kHz
        w.write(8, 24, 0).unwrap();
        assert_eq!(
            w.read(0x0C, 0).unwrap(),
            3,
            "PVU and RVU while the writes cross"
        );
        assert_eq!(w.read(0x0C, MS).unwrap(), 0, "5 LSI periods later: done");
        assert_eq!(w.expires(), None, "not started");
        w.write(0, 0xCCCC, 0).unwrap();
        assert_eq!(w.expires(), Some(4096 * 8 * MS), "0xFFF + 1 ticks");
        w.write(0, 0xAAAA, 10 * MS).unwrap();
        assert_eq!(
            w.expires(),
            Some(10 * MS + 25 * 8 * MS),
            "(RLR + 1) ticks: 200 ms"
        );
    }

    #[test]
    fn pr_and_rlr_are_write_protected_without_the_unlock_key() {
        let mut w = Iwdg::default();
        w.write(4, 3, 0).unwrap();
        w.write(8, 7, 0).unwrap();
        assert_eq!((w.read(4, 0).unwrap(), w.read(8, 0).unwrap()), (0, 0xFFF));
        w.write(0, 0x5555, 0).unwrap();
        w.write(0, 0x1234, 0).unwrap(); // another key locks again
        w.write(4, 3, 0).unwrap();
        assert_eq!(w.read(4, 0).unwrap(), 0);
        assert!(w.read(0x10, 0).unwrap_err().contains("0x40003010"));
    }

    #[test]
    fn a_slower_lsi_stretches_the_timeout() {
        let mut w = Iwdg::default();
        w.set_lsi_hz(16_000, 0);
        w.write(0, 0xCCCC, 0).unwrap(); // /4, 0xFFF: 4096 × 4 / 16 kHz = 1.024 s
        assert_eq!(w.expires(), Some(1024 * MS));
    }
}
