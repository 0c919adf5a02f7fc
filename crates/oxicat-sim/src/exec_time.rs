//! Opt-in execution-time model for firmware on the virtual segment: an event handler takes
//! the virtual time its SPI traffic takes on the bus, plus a configured CPU time, and the
//! MCU is busy meanwhile.
//!
//! Without it (the default) firmware runs in zero virtual time: a SYNC0 handler that needs
//! 70 µs of LAN9252 traffic has its inputs in SM3 at the SYNC0 instant. With
//! [`ExecTiming`] on a node ([`crate::firmware::FirmwareConfig::timing`],
//! [`crate::laelaps::RigConfig::timing`]):
//!
//! - **Duration.** A handler that starts at `t` keeps the MCU busy until
//!   `t_end = t + bus + cpu`: `bus` is the SPI bus time the handler's accesses took on the
//!   simulated chip (the [`BusStats::ps`](crate::pdi_path::BusStats) delta over the
//!   handler, rounded up to whole ns), `cpu` the configured CPU time of that kind of work
//!   ([`ExecTiming::cpu`], e.g. the thesis' 1 µs application on SYNC0). On the direct path
//!   there is no bus and no chip to hold writes back: only the CPU time counts (busy time,
//!   pending and lost events), and the handler's writes land at its start.
//! - **When effects land.** The handler's logic runs at its start `t`, so it reads what
//!   the ESC holds at `t` (outputs, AL control, mailbox); its **writes are held back** by
//!   the simulated chip ([`PdiPath::hold_writes`]; the firmware reads its own held writes
//!   back) and committed to the ESC, in order, at `t_end`. The master therefore sees the
//!   new inputs, AL status or mailbox reply no earlier than on hardware. The bias of this
//!   choice is one-sided and bounded by the handler's length: reads are taken at the
//!   earliest instant (on hardware the SM2 read starts after the SYNC0 status read and
//!   the AL event request: ≈ 10 µs later through a LAN9252 at 20 MHz), writes at the
//!   latest (on hardware the SM3 write completes just before the trailing AL event
//!   request: ≈ 4.5 µs earlier). Running the whole handler at `t_end` instead would need
//!   its duration before running it, and would let it read outputs that arrived while it
//!   was already on the bus.
//! - **One core, two levels.** SYNC0, SYNC1, the PDI IRQ and timers are interrupts; the
//!   main loop (`poll`) is thread level. An interrupt that arrives while another interrupt
//!   handler runs is held pending, like an NVIC pending bit, and runs when the CPU is free
//!   (priority SYNC0, SYNC1, IRQ, then due timers); a second one of the same kind arriving
//!   while one is pending is **lost** (counted). A timer that falls due while an interrupt
//!   runs waits; ticks it misses entirely are lost. An interrupt preempts a main-loop
//!   pass: it starts at once and the pass ends (and commits its writes) that much later.
//!   A main-loop pass starts only when the CPU is idle.
//!
//! Limits (documented, not hidden): a handler is atomic in virtual time — its reads all
//! happen at its start, its writes all at its end, and a preempting interrupt does not see
//! the preempted main-loop pass's writes before that pass ends, nor interleave with its
//! logic (the pass's logic ran whole at its start). So the stack's own end-of-cycle check
//! for a new SM2 buffer (0x1C32:0C, cycle time too small) reads the ESC as it was when the
//! cycle started and does not see an output frame that arrived during a long handler;
//! overruns show in [`TimingStats`] instead. Interrupts do not nest. Per-transaction MCU
//! overhead (driver code, DMA set-up between SPI frames) is not in the bus time; put an
//! estimate in the CPU time.
//!
//! Deterministic: durations come from byte counts on the simulated bus, nothing from the
//! host's clock.

use oxicat_esc::Esc;

use crate::pdi_path::{HeldWrite, PdiPath};

/// A kind of firmware work.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Work {
    /// SYNC0 interrupt.
    Sync0,
    /// SYNC1 interrupt.
    Sync1,
    /// PDI interrupt.
    Irq,
    /// A timer interrupt (e.g. the joint loop).
    Timer,
    /// A main-loop pass.
    Poll,
}

impl Work {
    /// All kinds, in priority order.
    pub const ALL: [Work; 5] = [Work::Sync0, Work::Sync1, Work::Irq, Work::Timer, Work::Poll];

    fn index(self) -> usize {
        match self {
            Work::Sync0 => 0,
            Work::Sync1 => 1,
            Work::Irq => 2,
            Work::Timer => 3,
            Work::Poll => 4,
        }
    }

    /// Whether the work runs as an interrupt (everything but the main loop).
    pub fn is_interrupt(self) -> bool {
        self != Work::Poll
    }

    /// `sync0`, `sync1`, `irq`, `timer`, `poll`.
    pub fn name(self) -> &'static str {
        match self {
            Work::Sync0 => "sync0",
            Work::Sync1 => "sync1",
            Work::Irq => "irq",
            Work::Timer => "timer",
            Work::Poll => "poll",
        }
    }
}

/// Settings of the execution-time model: the CPU time of each kind of work, added to the
/// bus time its PDI accesses take.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ExecTiming {
    cpu_ns: [u64; 5],
}

impl ExecTiming {
    /// Bus time only (no CPU time).
    pub fn bus_only() -> Self {
        Self::default()
    }

    /// The thesis' application time: 1 µs of CPU per SYNC0 cycle (Table 2-3), bus time
    /// for the rest.
    pub fn thesis() -> Self {
        Self::bus_only().cpu(Work::Sync0, 1_000)
    }

    /// Sets the CPU time of `work` in ns (builder style).
    pub fn cpu(mut self, work: Work, ns: u64) -> Self {
        self.cpu_ns[work.index()] = ns;
        self
    }

    /// The CPU time of `work` in ns.
    pub fn cpu_ns(&self, work: Work) -> u64 {
        self.cpu_ns[work.index()]
    }
}

/// What the model saw of one kind of work.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WorkStats {
    /// Handlers run.
    pub runs: u64,
    /// Handlers that started later than their event (held pending / waiting for the CPU).
    pub delayed: u64,
    /// Events lost: an interrupt arriving while one of its kind was already pending, or
    /// timer ticks skipped entirely.
    pub lost: u64,
    /// Longest wait from the event to the handler's start \[ns\].
    pub max_wait_ns: u64,
    /// Busy time (bus + CPU) of the last handler \[ns\].
    pub last_busy_ns: u64,
    /// Shortest busy time of a handler \[ns\] (0 before the first).
    pub min_busy_ns: u64,
    /// Longest busy time of a handler \[ns\].
    pub max_busy_ns: u64,
    /// Longest time from the event to the handler's writes landing in the ESC \[ns\]
    /// (wait + busy, + preemption for a main-loop pass): for SYNC0 in DC mode, the input
    /// latency.
    pub max_response_ns: u64,
    /// The last such time \[ns\].
    pub last_response_ns: u64,
}

/// What the model saw, per kind of work.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TimingStats {
    per: [WorkStats; 5],
}

impl TimingStats {
    /// The figures of `work`.
    pub fn get(&self, work: Work) -> WorkStats {
        self.per[work.index()]
    }

    fn at(&mut self, work: Work) -> &mut WorkStats {
        &mut self.per[work.index()]
    }
}

/// A handler whose writes have not landed yet.
struct Run {
    work: Work,
    arrival: u64,
    end: u64,
    writes: Vec<HeldWrite>,
}

/// The MCU's state under the model (one per node).
pub struct Cpu {
    timing: ExecTiming,
    isr: Option<Run>,
    main: Option<Run>,
    /// Arrival times of pending SYNC0, SYNC1, IRQ.
    pending: [Option<u64>; 3],
    stats: TimingStats,
}

impl Cpu {
    /// An idle MCU under `timing`.
    pub fn new(timing: ExecTiming) -> Self {
        Self {
            timing,
            isr: None,
            main: None,
            pending: [None; 3],
            stats: TimingStats::default(),
        }
    }

    /// What the model counted so far.
    pub fn stats(&self) -> TimingStats {
        self.stats
    }

    /// No interrupt handler is running.
    pub fn isr_free(&self) -> bool {
        self.isr.is_none()
    }

    /// Nothing is running.
    pub fn idle(&self) -> bool {
        self.isr.is_none() && self.main.is_none()
    }

    /// The earliest end of a running handler.
    pub fn next_end(&self) -> Option<u64> {
        [self.isr.as_ref(), self.main.as_ref()]
            .into_iter()
            .flatten()
            .map(|r| r.end)
            .min()
    }

    /// Commits the writes of every handler that ended by `t`, earliest end first.
    pub fn retire(&mut self, esc: &mut Esc, t: u64) {
        loop {
            let isr_end = self.isr.as_ref().map(|r| r.end).filter(|&e| e <= t);
            let main_end = self.main.as_ref().map(|r| r.end).filter(|&e| e <= t);
            let run = match (isr_end, main_end) {
                (Some(a), Some(b)) if b < a => self.main.take(),
                (Some(_), _) => self.isr.take(),
                (None, Some(_)) => self.main.take(),
                (None, None) => return,
            };
            if let Some(r) = run {
                self.land(esc, r);
            }
        }
    }

    fn land(&mut self, esc: &mut Esc, r: Run) {
        for w in &r.writes {
            // Range-checked when the chip held it back.
            let _ = esc.pdi_write(w.addr, &w.data);
        }
        let s = self.stats.at(r.work);
        let resp = r.end.saturating_sub(r.arrival);
        s.last_response_ns = resp;
        s.max_response_ns = s.max_response_ns.max(resp);
    }

    /// An interrupt of kind `work` arrived at `t`: pending until it can run (lost if one of
    /// its kind already is).
    pub fn raise(&mut self, work: Work, t: u64) {
        let k = match work {
            Work::Sync0 => 0,
            Work::Sync1 => 1,
            Work::Irq => 2,
            Work::Timer | Work::Poll => return,
        };
        if self.pending[k].is_some() {
            self.stats.at(work).lost += 1;
        } else {
            self.pending[k] = Some(t);
        }
    }

    /// The highest-priority pending interrupt and its arrival time, taken.
    pub fn take_pending(&mut self) -> Option<(Work, u64)> {
        let kinds = [Work::Sync0, Work::Sync1, Work::Irq];
        (0..3).find_map(|k| self.pending[k].take().map(|a| (kinds[k], a)))
    }

    /// Counts `n` lost events of `work` (skipped timer ticks).
    pub fn lose(&mut self, work: Work, n: u64) {
        self.stats.at(work).lost += n;
    }

    /// Runs handler `f` of `work` (event at `arrival`) at `t` on `path`: measures its bus
    /// time, holds its writes back and keeps the CPU busy for bus + CPU time. An interrupt
    /// needs [`isr_free`](Self::isr_free), a main-loop pass [`idle`](Self::idle).
    pub fn run<P: PdiPath, T>(
        &mut self,
        path: &mut P,
        esc: &mut Esc,
        work: Work,
        arrival: u64,
        t: u64,
        f: impl FnOnce(&mut P, &mut Esc) -> T,
    ) -> T {
        let bus0 = path.bus_stats().map_or(0, |s| s.ps);
        path.hold_writes(true);
        let r = f(path, esc);
        let writes = path.take_held_writes();
        path.hold_writes(false);
        let bus_ps = path.bus_stats().map_or(0, |s| s.ps).saturating_sub(bus0);
        let busy = bus_ps.div_ceil(1000) + self.timing.cpu_ns(work);
        let wait = t.saturating_sub(arrival);
        let s = self.stats.at(work);
        s.runs += 1;
        if wait > 0 {
            s.delayed += 1;
        }
        s.max_wait_ns = s.max_wait_ns.max(wait);
        s.last_busy_ns = busy;
        s.min_busy_ns = if s.runs == 1 {
            busy
        } else {
            s.min_busy_ns.min(busy)
        };
        s.max_busy_ns = s.max_busy_ns.max(busy);
        let run = Run {
            work,
            arrival,
            end: t.saturating_add(busy),
            writes,
        };
        if busy == 0 {
            self.land(esc, run);
        } else if work.is_interrupt() {
            if let Some(m) = self.main.as_mut() {
                m.end = m.end.saturating_add(busy);
            }
            self.isr = Some(run);
        } else {
            self.main = Some(run);
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pdi_path::Direct;
    use oxicat_esc::EscConfig;

    #[test]
    fn pending_interrupts_run_by_priority_and_a_second_one_is_lost() {
        let mut c = Cpu::new(ExecTiming::bus_only().cpu(Work::Irq, 10));
        assert_eq!(c.take_pending(), None);
        c.raise(Work::Irq, 1);
        c.raise(Work::Sync1, 2);
        c.raise(Work::Sync0, 3);
        c.raise(Work::Sync0, 4);
        assert_eq!(c.stats().get(Work::Sync0).lost, 1);
        assert_eq!(c.take_pending(), Some((Work::Sync0, 3)));
        assert_eq!(c.take_pending(), Some((Work::Sync1, 2)));
        assert_eq!(c.take_pending(), Some((Work::Irq, 1)));
        assert_eq!(c.take_pending(), None);
    }

    #[test]
    fn an_interrupt_preempts_the_main_loop_and_pushes_its_end() {
        let mut esc = Esc::new(EscConfig::et1100(), Vec::new());
        let mut c = Cpu::new(
            ExecTiming::bus_only()
                .cpu(Work::Poll, 100)
                .cpu(Work::Sync0, 30),
        );
        let mut p = Direct;
        c.run(&mut p, &mut esc, Work::Poll, 0, 0, |_, _| ());
        assert!(!c.idle() && c.isr_free());
        assert_eq!(c.next_end(), Some(100));
        c.run(&mut p, &mut esc, Work::Sync0, 40, 50, |_, _| ());
        assert_eq!(c.next_end(), Some(80));
        c.retire(&mut esc, 80);
        assert!(c.isr_free());
        assert_eq!(c.next_end(), Some(130));
        c.retire(&mut esc, 130);
        assert!(c.idle());
        let s = c.stats().get(Work::Sync0);
        assert_eq!((s.runs, s.delayed, s.max_wait_ns), (1, 1, 10));
        assert_eq!((s.max_busy_ns, s.max_response_ns), (30, 40));
        assert_eq!(c.stats().get(Work::Poll).max_response_ns, 130);
    }
}
