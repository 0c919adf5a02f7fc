//! EXTI and SYSCFG's EXTI multiplexer (RM0390 §10, §8.2.3–8.2.6).
//!
//! Lines 0..=15 follow a GPIO pin each, the port chosen by SYSCFG_EXTICR1..4. The board
//! samples the pins (its own output levels, injected inputs and the LAN9252's IRQ/SYNC
//! pins) after every engine run and after every SPI frame; a selected edge (RTSR/FTSR) on
//! an unmasked line (IMR) sets its PR bit. PR is write-1-to-clear (which also clears the
//! SWIER bit); writing 1 to SWIER sets PR on an unmasked line. The NVIC sees PR & IMR on
//! EXTI0..4 (IRQ 6..10), EXTI9_5 (23) and EXTI15_10 (40). Lines 16..=22 (PVD, RTC, USB
//! wake-up …) have no source here: only SWIER reaches them.

pub(crate) const EXTI_BASE: u64 = 0x4001_3C00;
pub(crate) const SYSCFG_BASE: u64 = 0x4001_3800;

use crate::stats::LostEdge;

const LINES: u32 = 0x7F_FFFF;

/// The EXTI controller and the EXTICR multiplexer.
#[derive(Default)]
pub(crate) struct Exti {
    pub imr: u32,
    emr: u32,
    rtsr: u32,
    ftsr: u32,
    swier: u32,
    pub pr: u32,
    /// Pin level of lines 0..=15 at the last sample.
    levels: u32,
    /// Port of each line at the last sample (a changed selection is not an edge).
    ports: [u8; 16],
    /// SYSCFG registers (EXTICR1..4 at 0x08..0x14).
    syscfg: [u32; 12],
    /// Edges of lines 0..=15 that found their PR bit still set, per line.
    pub lost_count: [u64; 16],
    /// The first [`LOST_KEPT`] of them.
    pub lost: Vec<LostEdge>,
}

/// Lost edges kept with their time (the count goes on).
pub(crate) const LOST_KEPT: usize = 64;

impl Exti {
    /// The port (0 = A …) line `line` (0..=15) follows.
    pub fn port_of(&self, line: u32) -> u8 {
        let cr = self.syscfg[2 + (line / 4) as usize];
        ((cr >> (4 * (line % 4))) & 0xF) as u8
    }

    /// Whether any of lines 0..=15 can trigger (worth sampling pins for).
    pub fn watching(&self) -> bool {
        (self.imr | self.emr) & 0xFFFF != 0
    }

    /// Samples lines 0..=15 through `level(port, pin)` at cycle `at`; returns whether PR
    /// gained bits. A selected edge on a line whose PR bit is still set is lost (one
    /// interrupt for two edges): counted and, the first [`LOST_KEPT`], kept with `at`.
    pub fn sample(&mut self, at: u64, mut level: impl FnMut(u8, u32) -> bool) -> bool {
        let before = self.pr;
        for line in 0..16 {
            let port = self.port_of(line);
            let now = level(port, line);
            let was = self.levels & (1 << line) != 0;
            let b = 1 << line;
            if self.ports[line as usize] == port && now != was {
                let edge = if now { self.rtsr } else { self.ftsr };
                if edge & self.imr & b != 0 {
                    if self.pr & b != 0 {
                        self.lost_count[line as usize] += 1;
                        if self.lost.len() < LOST_KEPT {
                            self.lost.push(LostEdge {
                                line: line as u8,
                                cycle: at,
                            });
                        }
                    }
                    self.pr |= b;
                }
            }
            self.ports[line as usize] = port;
            self.levels = (self.levels & !b) | (u32::from(now) << line);
        }
        self.pr != before
    }

    /// The IRQ lines EXTI drives high (exception-number bits).
    pub fn irq_lines(&self) -> u128 {
        let on = self.pr & self.imr;
        let mut lines = 0u128;
        for line in 0..5 {
            if on & (1 << line) != 0 {
                lines |= crate::nvic::bit(16 + 6 + line as u16);
            }
        }
        if on & 0x3E0 != 0 {
            lines |= crate::nvic::bit(16 + 23);
        }
        if on & 0xFC00 != 0 {
            lines |= crate::nvic::bit(16 + 40);
        }
        lines
    }

    /// The word a sub-word write merges into (zero for the write-one registers).
    pub fn merge_base(&self, addr: u64) -> u32 {
        match addr {
            a if a == EXTI_BASE + 0x10 || a == EXTI_BASE + 0x14 => 0,
            a => self.read(a),
        }
    }

    pub fn read(&self, addr: u64) -> u32 {
        if addr >= EXTI_BASE {
            match addr - EXTI_BASE {
                0x00 => self.imr,
                0x04 => self.emr,
                0x08 => self.rtsr,
                0x0C => self.ftsr,
                0x10 => self.swier,
                0x14 => self.pr,
                _ => 0,
            }
        } else {
            let i = ((addr - SYSCFG_BASE) / 4) as usize;
            self.syscfg.get(i).copied().unwrap_or(0)
        }
    }

    pub fn write(&mut self, addr: u64, v: u32) {
        let v_lines = v & LINES;
        if addr >= EXTI_BASE {
            match addr - EXTI_BASE {
                0x00 => self.imr = v_lines,
                0x04 => self.emr = v_lines,
                0x08 => self.rtsr = v_lines,
                0x0C => self.ftsr = v_lines,
                0x10 => {
                    let rising = v_lines & !self.swier;
                    self.swier |= v_lines;
                    self.pr |= rising & self.imr;
                }
                0x14 => {
                    self.pr &= !v_lines;
                    self.swier &= !v_lines;
                }
                _ => {}
            }
        } else {
            let i = ((addr - SYSCFG_BASE) / 4) as usize;
            if let Some(r) = self.syscfg.get_mut(i) {
                *r = if (2..6).contains(&i) { v & 0xFFFF } else { v };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_selected_edge_on_an_unmasked_line_pends_its_irq_until_pr_is_cleared() {
        let mut e = Exti::default();
        // Line 10 on port A (EXTICR3 = 0), falling edge; line 3 on port B (EXTICR1).
        e.write(SYSCFG_BASE + 0x08, 1 << 12);
        e.write(EXTI_BASE + 0x0C, 1 << 10);
        e.write(EXTI_BASE + 0x08, 1 << 3);
        e.write(EXTI_BASE, (1 << 10) | (1 << 3));
        let mut pa10 = true;
        let mut pb3 = false;
        e.sample(0, |p, l| {
            (p == 0 && l == 10 && pa10) || (p == 1 && l == 3 && pb3)
        });
        assert_eq!(e.pr, 0, "the first sample is a baseline");
        pb3 = true;
        assert!(e.sample(0, |p, l| (p == 0 && l == 10 && pa10)
            || (p == 1 && l == 3 && pb3)));
        assert_eq!(e.irq_lines(), crate::nvic::bit(16 + 9), "EXTI3");
        pa10 = false;
        e.sample(0, |p, l| {
            (p == 0 && l == 10 && pa10) || (p == 1 && l == 3 && pb3)
        });
        assert_eq!(e.pr, (1 << 10) | (1 << 3));
        assert_ne!(e.irq_lines() & crate::nvic::bit(16 + 40), 0, "EXTI15_10");
        // The rising edge back on PA10 is not selected.
        e.write(EXTI_BASE + 0x14, 1 << 10);
        pa10 = true;
        e.sample(0, |p, l| {
            (p == 0 && l == 10 && pa10) || (p == 1 && l == 3 && pb3)
        });
        assert_eq!(e.pr, 1 << 3);
        assert_eq!(e.merge_base(EXTI_BASE + 0x14), 0);
        // PB3 falls and rises again before its PR bit was cleared: that edge is lost.
        assert_eq!(e.lost_count[3], 0);
        e.sample(10, |p, l| p == 0 && l == 10);
        e.sample(20, |p, l| (p == 0 && l == 10) || (p == 1 && l == 3));
        assert_eq!(e.lost_count[3], 1);
        assert_eq!(e.lost, vec![LostEdge { line: 3, cycle: 20 }]);
    }

    #[test]
    fn swier_pends_an_unmasked_line_and_a_masked_edge_is_lost() {
        let mut e = Exti::default();
        e.write(EXTI_BASE + 0x10, 1 << 5);
        assert_eq!(e.pr, 0, "masked");
        e.write(EXTI_BASE, 1 << 6);
        e.write(EXTI_BASE + 0x10, 1 << 6);
        assert_eq!(e.irq_lines(), crate::nvic::bit(16 + 23), "EXTI9_5");
        e.write(EXTI_BASE + 0x14, 1 << 6);
        assert_eq!(e.read(EXTI_BASE + 0x10) & (1 << 6), 0, "PR clears SWIER");
        // Masked line 7: its edge sets nothing.
        e.write(EXTI_BASE + 0x08, 1 << 7);
        e.sample(0, |_, _| false);
        e.sample(0, |_, l| l == 7);
        assert_eq!(e.pr, 0);
        assert_eq!(
            e.lost_count[7], 0,
            "a masked line loses nothing: it never pends"
        );
    }
}
