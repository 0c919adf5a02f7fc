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
    fn a_file_that_is_not_an_elf_has_no_size() {
        assert!(image_size(b"nope").is_err());
    }
}
