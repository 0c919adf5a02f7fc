//! What the board measures about an image: handler times per exception (from entry to
//! exception return, with the time of handlers that preempted it counted apart), stack
//! high-water mark by a painted stack, and the image's flash and RAM from its ELF.

use crate::nvic::NUM_EXC;
use crate::{EmuError, FLASH, SRAM};

/// The handler times of one exception, in CPU cycles (at [`crate::CPU_HZ`]).
///
/// An invocation runs from the cycle its entry starts (stacking, or the tail-chain from
/// the previous handler) to the cycle its exception return has unstacked (or it
/// tail-chains into the next one). `max_cycles`/`total_cycles` are that span, including
/// the handlers that preempted it; `own` excludes them (their whole spans, entry and
/// return included), so the own cycles of all exceptions plus the thread's add up to the
/// board's active cycles.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HandlerStats {
    /// Invocations completed.
    pub runs: u64,
    /// Invocations that were preempted at least once.
    pub preempted_runs: u64,
    /// Sum of the spans (preemptions included).
    pub total_cycles: u64,
    /// Sum of the spans without the preempting handlers.
    pub own_cycles: u64,
    /// Longest span (preemptions included).
    pub max_cycles: u64,
    /// Longest span without the preempting handlers.
    pub max_own_cycles: u64,
    /// Shortest span.
    pub min_cycles: u64,
}

impl HandlerStats {
    /// Mean span in µs at `cpu_hz`.
    pub fn mean_us(&self, cpu_hz: u64) -> f64 {
        if self.runs == 0 {
            return 0.0;
        }
        self.total_cycles as f64 / self.runs as f64 * 1e6 / cpu_hz as f64
    }

    /// Cycles to µs at `cpu_hz`.
    pub fn us(cycles: u64, cpu_hz: u64) -> f64 {
        cycles as f64 * 1e6 / cpu_hz as f64
    }
}

/// One invocation in progress.
#[derive(Debug, Clone, Copy)]
struct Frame {
    exc: u16,
    start: u64,
    preempted: u64,
}

/// Per-exception handler statistics, kept by the exception entry/return code.
#[derive(Debug, Clone)]
pub(crate) struct Profile {
    stats: Vec<HandlerStats>,
    frames: Vec<Frame>,
    /// Cycle of the last reset: spans that started before count from here.
    since: u64,
}

impl Default for Profile {
    fn default() -> Self {
        Profile {
            stats: vec![HandlerStats::default(); NUM_EXC],
            frames: Vec::new(),
            since: 0,
        }
    }
}

impl Profile {
    /// Exception `exc` is entered at cycle `now` (before its entry cycles).
    pub fn enter(&mut self, exc: u16, now: u64) {
        self.frames.push(Frame {
            exc,
            start: now,
            preempted: 0,
        });
    }

    /// The running handler ends at `now` (returned, or tail-chained to another).
    pub fn leave(&mut self, now: u64) {
        let Some(f) = self.frames.pop() else {
            return;
        };
        let span = now.saturating_sub(f.start.max(self.since));
        let own = span.saturating_sub(f.preempted);
        if let Some(s) = self.stats.get_mut(usize::from(f.exc)) {
            s.runs += 1;
            s.preempted_runs += u64::from(f.preempted > 0);
            s.total_cycles += span;
            s.own_cycles += own;
            s.max_cycles = s.max_cycles.max(span);
            s.max_own_cycles = s.max_own_cycles.max(own);
            s.min_cycles = if s.runs == 1 {
                span
            } else {
                s.min_cycles.min(span)
            };
        }
        if let Some(parent) = self.frames.last_mut() {
            parent.preempted += span;
        }
    }

    pub fn get(&self, exc: u16) -> HandlerStats {
        self.stats
            .get(usize::from(exc))
            .copied()
            .unwrap_or_default()
    }

    /// The handlers in progress will never return (a system reset): dropped uncounted.
    pub fn abandon(&mut self) {
        self.frames.clear();
    }

    /// Clears the figures (invocations in progress count from `now`).
    pub fn reset(&mut self, now: u64) {
        self.stats = vec![HandlerStats::default(); NUM_EXC];
        self.since = now;
        for f in &mut self.frames {
            f.preempted = 0;
        }
    }
}

/// The longest time thread mode held one priority level masked (PRIMASK, FAULTMASK, or
/// BASEPRI at that level or more urgent): the exceptions of that priority could not be
/// taken for that long, whatever preempted the thread meanwhile (handlers of a more urgent
/// priority count in the span). Priority levels are the upper nibble the STM32F446
/// implements.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MaskedSpan {
    /// Length of the longest span \[cycles\] (0: the level was never masked).
    pub max_cycles: u64,
    /// Cycle at which it began.
    pub start_cycle: u64,
    /// Address of the instruction (MSR or CPS) that began it.
    pub pc: u32,
}

/// Priority levels tracked: the upper nibble of the priority byte.
pub(crate) const LEVELS: usize = 16;

/// The thread's mask spans per priority level, kept by the code hooks on the image's
/// MSR PRIMASK/BASEPRI/BASEPRI_MAX/FAULTMASK and CPSID/CPSIE instructions.
#[derive(Debug, Clone)]
pub(crate) struct MaskTracker {
    /// The most urgent level the thread's masks hold back now (`LEVELS`: none).
    level: usize,
    /// Where and when the span of each masked level began: (cycle, PC).
    began: [(u64, u32); LEVELS],
    longest: [MaskedSpan; LEVELS],
}

impl Default for MaskTracker {
    fn default() -> Self {
        MaskTracker {
            level: LEVELS,
            began: [(0, 0); LEVELS],
            longest: [MaskedSpan::default(); LEVELS],
        }
    }
}

impl MaskTracker {
    /// The level masks `primask`, `basepri`, `faultmask` hold back: every priority whose
    /// upper nibble is at least this one.
    pub fn level_of(primask: u32, basepri: u32, faultmask: u32) -> usize {
        if primask & 1 != 0 || faultmask & 1 != 0 {
            return 0;
        }
        match (basepri & 0xF0) >> 4 {
            0 => LEVELS,
            n => n as usize,
        }
    }

    /// The thread's masks now hold back `level` from cycle `now`, set by the instruction
    /// at `pc`.
    pub fn set(&mut self, level: usize, now: u64, pc: u32) {
        let old = self.level;
        for k in 0..LEVELS {
            let (was, is) = (old <= k, level <= k);
            if !was && is {
                self.began[k] = (now, pc);
            } else if was && !is {
                self.close(k, now);
            }
        }
        self.level = level.min(LEVELS);
    }

    fn close(&mut self, k: usize, now: u64) {
        let (start, pc) = self.began[k];
        let span = now.saturating_sub(start);
        if span > self.longest[k].max_cycles {
            self.longest[k] = MaskedSpan {
                max_cycles: span,
                start_cycle: start,
                pc,
            };
        }
    }

    /// The longest span of priority `priority` (a span still open counts up to `now`).
    pub fn longest(&self, priority: u8, now: u64) -> MaskedSpan {
        let k = usize::from(priority >> 4);
        let mut t = self.clone();
        if t.level <= k {
            t.close(k, now);
        }
        t.longest[k]
    }
}

/// An edge on an EXTI line whose pending bit was still set: the interrupt it should have
/// caused merged with the one already pending (one handler run for two edges).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LostEdge {
    /// EXTI line (SYNC0 on the Laelaps leg board: 3).
    pub line: u8,
    /// Cycle of the sample that saw the edge.
    pub cycle: u64,
}

/// Flash and RAM of an image, from its ELF program headers (what `llvm-size` adds up).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ImageSize {
    /// Bytes stored in flash: every loadable segment's file bytes (code, read-only data,
    /// the initial values of `.data`).
    pub flash: u64,
    /// Static RAM: the memory size of the loadable segments that run in SRAM (`.data` +
    /// `.bss` + `.uninit`), the stack excluded.
    pub ram: u64,
    /// First address after the static RAM (where the stack region's painting starts).
    pub ram_end: u32,
}

/// The flash and static RAM of `elf`.
pub fn image_size(elf: &[u8]) -> Result<ImageSize, EmuError> {
    let bad = |w: &str| EmuError::BadImage(w.to_string());
    let word = |o: usize| -> Result<u32, EmuError> {
        elf.get(o..o + 4)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes)
            .ok_or_else(|| bad("truncated header"))
    };
    let half = |o: usize| -> Result<u16, EmuError> {
        elf.get(o..o + 2)
            .and_then(|b| b.try_into().ok())
            .map(u16::from_le_bytes)
            .ok_or_else(|| bad("truncated header"))
    };
    crate::elf_segments(elf)?;
    let (phoff, phentsize, phnum) = (word(28)? as usize, half(42)? as usize, half(44)?);
    let mut size = ImageSize {
        ram_end: SRAM.0 as u32,
        ..ImageSize::default()
    };
    let in_ram = |a: u64| (SRAM.0..SRAM.0 + SRAM.1).contains(&a);
    for k in 0..usize::from(phnum) {
        let p = phoff + k * phentsize;
        if word(p)? != 1 {
            continue;
        }
        let (vaddr, paddr, filesz, memsz) =
            (word(p + 8)?, word(p + 12)?, word(p + 16)?, word(p + 20)?);
        if (FLASH.0..FLASH.0 + FLASH.1).contains(&u64::from(paddr)) {
            size.flash += u64::from(filesz);
        }
        if in_ram(u64::from(vaddr)) {
            size.ram += u64::from(memsz);
            size.ram_end = size.ram_end.max(vaddr.saturating_add(memsz));
        }
    }
    Ok(size)
}

/// Stack figures from the painted region.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StackStats {
    /// Initial main stack pointer (vector table word 0).
    pub top: u32,
    /// Lowest address of the painted region.
    pub bottom: u32,
    /// Deepest use: `top` − the lowest word no longer holding the pattern since the paint
    /// (0 if the pattern is intact).
    pub max_depth: u32,
}

/// The paint pattern.
pub(crate) const PAINT: u32 = 0xC5AC_CE55;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_preempting_handler_counts_in_the_span_but_not_in_the_own_time() {
        let mut p = Profile::default();
        p.enter(25, 100); // EXTI3
        p.enter(70, 150); // TIM6 preempts
        p.leave(170);
        p.leave(300);
        let s = p.get(25);
        assert_eq!((s.runs, s.preempted_runs), (1, 1));
        assert_eq!((s.max_cycles, s.max_own_cycles), (200, 180));
        assert_eq!(p.get(70).own_cycles, 20);
        // Tail-chain: one ends where the next starts.
        p.enter(25, 400);
        p.leave(450);
        p.enter(56, 450);
        p.leave(460);
        assert_eq!((p.get(25).runs, p.get(25).min_cycles), (2, 50));
        p.reset(1_000);
        assert_eq!(p.get(25), HandlerStats::default());
        assert_eq!(
            p.get(999),
            HandlerStats::default(),
            "out of range reads as none"
        );
        p.leave(5); // no frame: ignored
    }

    #[test]
    fn a_mask_span_runs_from_the_instruction_that_raised_it_to_the_one_that_lowered_it() {
        let mut m = MaskTracker::default();
        assert_eq!(MaskTracker::level_of(0, 0, 0), LEVELS);
        assert_eq!(MaskTracker::level_of(0, 0x20, 0), 2);
        assert_eq!(MaskTracker::level_of(1, 0x20, 0), 0);
        // BASEPRI 0x20 at cycle 100 (PC 0x0800_0100): 0x20 and less urgent are held back.
        m.set(2, 100, 0x0800_0100);
        // A critical section inside it: every level, for 10 cycles.
        m.set(0, 150, 0x0800_0200);
        m.set(2, 160, 0x0800_0204);
        m.set(LEVELS, 500, 0x0800_0104);
        let s = m.longest(0x20, 600);
        assert_eq!((s.max_cycles, s.start_cycle, s.pc), (400, 100, 0x0800_0100));
        assert_eq!(
            m.longest(0x10, 600).max_cycles,
            10,
            "the joint loop's level"
        );
        assert_eq!(m.longest(0xF0, 600).max_cycles, 400);
        // An open span counts up to now; a shorter one later does not replace the longest.
        m.set(2, 1_000, 0x0800_0300);
        assert_eq!(m.longest(0x20, 1_100).max_cycles, 400);
        assert_eq!(m.longest(0x20, 2_000).start_cycle, 1_000);
    }

    #[test]
    fn a_file_that_is_not_an_elf_has_no_size() {
        assert!(image_size(b"nope").is_err());
    }
}
