//! The firmware host: one simulated MCU behind one ESC of a [`Segment`], delivering its
//! image's events at their virtual times as interrupts and the main loop do on a
//! microcontroller. Every device runs in it: a [`Host`] is generic over the image
//! ([`Image`]: the `oxicat-slave` [`Stack`] with an [`Application`], or a firmware that
//! wraps the stack itself), the route to the ESC ([`PdiPath`]) and the plant around the
//! MCU ([`Bench`]).
//!
//! | MCU | simulator |
//! |---|---|
//! | PDI IRQ ISR | [`EscEvent::Irq`]: the ESC's IRQ line rose (e.g. a frame wrote SM2) → [`Image::on_pdi_irq`] |
//! | SYNC0 / SYNC1 ISR | [`EscEvent::Sync0`] / [`EscEvent::Sync1`] → [`Image::on_sync0`] / [`Image::on_sync1`] |
//! | timer ISRs | periodic wakeups per [`FirmwareConfig::timers`] → [`Image::on_timer`], with the plant brought up to the instant first ([`Bench::before_timers`]) and taking the timers' outputs after ([`Bench::after_timers`]) |
//! | main loop | a wakeup every [`FirmwareConfig::poll_period_ns`] → [`Image::poll`] |
//!
//! The segment owns the ESC; the firmware gets `&mut Esc` only while it handles an event.
//! How it reaches the ESC is the node's [`PdiPath`]: by default ([`Direct`]) the software
//! ESC is its [`oxicat_slave::Pdi`]; [`attach_firmware_via`] puts an `oxicat-pdi` chip
//! driver over the simulated SPI in between ([`SpiPath`]: LAN9252 or ET1100), so the
//! firmware runs exactly as on hardware and its bus traffic is counted
//! ([`Host::bus_stats`]). The host lives behind a mutex shared with the [`HostHandle`] a
//! test or tool keeps to look at it between cycles.
//!
//! By default every handler runs in zero virtual time. [`FirmwareConfig::timing`] turns on
//! the execution-time model of [`crate::exec_time`]: a handler takes its SPI bus time plus
//! a configured CPU time, its ESC writes land when it ends, and events that arrive while
//! the MCU is busy wait (or are lost) — counted in [`Host::timing`].

use oxicat_esc::{Esc, PdiError};
use oxicat_slave::{Application, DeviceDef, InitError, Pdi, Slave};

use crate::exec_time::{Cpu, ExecTiming, TimingStats, Work};
use crate::node::{EscEvent, Node, Shared};
use crate::pdi_path::{BusStats, Direct, PathInitError, PdiPath, PdiRoute, SpiPath};
use crate::segment::{Segment, SlaveId, TopologyError};

/// Default main-loop period: 50 µs of virtual time.
pub const DEFAULT_POLL_PERIOD_NS: u64 = 50_000;

/// A periodic timer interrupt of the simulated MCU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timer {
    /// Delivered as [`Image::on_timer`]`(id)`.
    pub id: u8,
    /// Period \[ns\] (at least 1).
    pub period_ns: u64,
    /// First expiry, after the schedule's start \[ns\].
    pub first_ns: u64,
}

/// How the simulated MCU runs the firmware.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FirmwareConfig {
    /// Virtual time between two main-loop passes ([`Image::poll`]); at least 1 ns.
    pub poll_period_ns: u64,
    /// First main-loop pass, after the schedule's start \[ns\].
    pub poll_first_ns: u64,
    /// At an instant where both are due, the main loop runs before the timers (`true`) or
    /// after them (`false`, the default).
    pub poll_before_timers: bool,
    /// `Some(k)`: the main loop falls due after every `k`-th timer instant (at that
    /// instant) instead of on its own period, as a firmware that runs it from its control
    /// loop's timer.
    pub poll_after_timer_instants: Option<u64>,
    /// Periodic timers, run in this order when several are due at one instant.
    pub timers: Vec<Timer>,
    /// The schedule starts at the first multiple of this \[ns\] at or after the attach
    /// time (1: at the attach time), so a board's timers fall on a fixed grid.
    pub align_ns: u64,
    /// The execution-time model ([`crate::exec_time`]); `None` (the default): handlers
    /// run in zero virtual time.
    pub timing: Option<ExecTiming>,
}

impl Default for FirmwareConfig {
    fn default() -> Self {
        Self {
            poll_period_ns: DEFAULT_POLL_PERIOD_NS,
            poll_first_ns: 0,
            poll_before_timers: false,
            poll_after_timer_instants: None,
            timers: Vec::new(),
            align_ns: 1,
            timing: None,
        }
    }
}

impl FirmwareConfig {
    /// Adds a periodic timer `id` every `period_ns`, first one period after the start
    /// (builder style).
    pub fn timer(self, id: u8, period_ns: u64) -> Self {
        self.timer_from(id, period_ns, period_ns)
    }

    /// Adds a periodic timer `id` every `period_ns`, first `first_ns` after the start
    /// (builder style).
    pub fn timer_from(mut self, id: u8, period_ns: u64, first_ns: u64) -> Self {
        self.timers.push(Timer {
            id,
            period_ns: period_ns.max(1),
            first_ns,
        });
        self
    }

    /// Sets the main-loop period (builder style).
    pub fn poll_every(mut self, period_ns: u64) -> Self {
        self.poll_period_ns = period_ns;
        self
    }

    /// Starts the schedule on a multiple of `align_ns` (builder style).
    pub fn aligned(mut self, align_ns: u64) -> Self {
        self.align_ns = align_ns.max(1);
        self
    }

    /// Turns the execution-time model on (builder style).
    pub fn timing(mut self, timing: ExecTiming) -> Self {
        self.timing = Some(timing);
        self
    }
}

/// Counters of what the simulated MCU delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FirmwareCounters {
    /// Main-loop passes.
    pub polls: u64,
    /// PDI interrupts.
    pub irqs: u64,
    /// SYNC0 interrupts.
    pub sync0: u64,
    /// SYNC1 interrupts.
    pub sync1: u64,
    /// Timer interrupts (all ids).
    pub timers: u64,
    /// PDI accesses the ESC refused (the event handler stopped there).
    pub pdi_errors: u64,
}

/// What a microcontroller image offers its interrupt vector and main loop: the handlers
/// the [`Host`] delivers events to, each given the image's `Pdi` to its ESC.
///
/// [`Stack`] (the `oxicat-slave` stack and an [`Application`]) is the usual image; a
/// firmware that wraps the stack itself (the axis hub) implements it directly; an image
/// executed instruction by instruction would be another implementation.
pub trait Image<Pd: Pdi> {
    /// The PDI interrupt.
    fn on_pdi_irq(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error>;
    /// The SYNC0 interrupt.
    fn on_sync0(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error>;
    /// The SYNC1 interrupt.
    fn on_sync1(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error>;
    /// Timer interrupt `id`.
    fn on_timer(&mut self, id: u8, pdi: &mut Pd) -> Result<(), Pd::Error>;
    /// One main-loop pass.
    fn poll(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error>;
}

/// The slave stack and its application: the image of every oxicat device built on
/// `oxicat-slave`.
pub struct Stack<Pd: Pdi, A, const N: usize, const M: usize> {
    /// The slave stack.
    pub slave: Slave<Pd, N, M>,
    /// The application.
    pub app: A,
}

impl<Pd, A, const N: usize, const M: usize> Image<Pd> for Stack<Pd, A, N, M>
where
    Pd: Pdi,
    A: Application<N>,
{
    fn on_pdi_irq(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error> {
        self.slave.on_pdi_irq(pdi, &mut self.app)
    }
    fn on_sync0(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error> {
        self.slave.on_sync0(pdi, &mut self.app)
    }
    fn on_sync1(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error> {
        self.slave.on_sync1(pdi, &mut self.app)
    }
    fn on_timer(&mut self, id: u8, _pdi: &mut Pd) -> Result<(), Pd::Error> {
        self.slave.on_timer(id, &mut self.app);
        Ok(())
    }
    fn poll(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error> {
        self.slave.poll(pdi, &mut self.app)
    }
}

/// The hardware around the MCU that is not its ESC: the plant, its sensors and
/// actuators. The host calls it at the MCU's timer instants, where a board observes and
/// drives its plant, and around the handlers of ESC events; the defaults do nothing (a
/// board without a plant is `()`).
pub trait Bench<I>: Send + 'static {
    /// At `t`, before the timers due at `t` run (once per instant; under the
    /// execution-time model, before each timer handler, at the time it runs): bring the
    /// plant up to `t` and latch what the timers read.
    fn before_timers(&mut self, _image: &mut I, _t: u64) {}
    /// After the timers of the instant `t` ran: the plant takes what they wrote.
    fn after_timers(&mut self, _image: &mut I, _t: u64) {}
    /// Before the handler of ESC event `ev` that arrived at `t` runs.
    fn before_event(&mut self, _image: &mut I, _ev: EscEvent, _t: u64) {}
    /// After the handler of ESC event `ev` that arrived at `t` ran. `Some(at)`: the
    /// bench re-phases the MCU's timers, each next due at `at` (a rig that aligns its
    /// plant to the first synchronous cycle).
    fn after_event(&mut self, _image: &mut I, _ev: EscEvent, _t: u64) -> Option<u64> {
        None
    }
}

impl<I> Bench<I> for () {}

/// One simulated MCU: its image `I`, the way it reaches its ESC (`P`, [`Direct`] unless
/// attached through a driver), its schedule (timers and main loop), the bench `B` around
/// it and, optionally, the execution-time model. The one firmware host of the segment:
/// every device runs in one.
pub struct Host<I, P: PdiPath = Direct, B = ()> {
    /// The firmware image.
    pub image: I,
    /// The plant around the MCU.
    pub bench: B,
    /// What was delivered so far.
    pub counters: FirmwareCounters,
    /// The last PDI error, if any.
    pub last_pdi_error: Option<<P::Pdi as Pdi>::Error>,
    path: P,
    poll_period: u64,
    next_poll: u64,
    poll_before_timers: bool,
    /// See [`FirmwareConfig::poll_after_timer_instants`].
    poll_after_instants: Option<u64>,
    /// Timer instants so far.
    instants: u64,
    /// `(id, period, next due time)`.
    timers: Vec<(u8, u64, u64)>,
    /// The MCU under the execution-time model, if on.
    cpu: Option<Cpu>,
}

/// A node running an `oxicat-slave` stack with application `A` (and no plant).
pub type Firmware<A, const N: usize, const M: usize, P = Direct> =
    Host<Stack<<P as PdiPath>::Pdi, A, N, M>, P>;

impl<I, P: PdiPath, B> core::ops::Deref for Host<I, P, B> {
    type Target = I;
    fn deref(&self) -> &I {
        &self.image
    }
}

impl<I, P: PdiPath, B> core::ops::DerefMut for Host<I, P, B> {
    fn deref_mut(&mut self) -> &mut I {
        &mut self.image
    }
}

impl<I, P: PdiPath, B> Host<I, P, B> {
    /// How the firmware reaches its ESC.
    pub fn path(&self) -> &P {
        &self.path
    }

    /// What the SPI bus between MCU and ESC carried since the last reset (`None` on the
    /// direct path).
    pub fn bus_stats(&self) -> Option<BusStats> {
        self.path.bus_stats()
    }

    /// Clears the bus counters.
    pub fn reset_bus_stats(&self) {
        self.path.reset_bus_stats()
    }

    /// What the execution-time model saw (`None` when it is off).
    pub fn timing(&self) -> Option<TimingStats> {
        self.cpu.as_ref().map(Cpu::stats)
    }
}

impl<I: Image<P::Pdi>, P: PdiPath, B: Bench<I>> Host<I, P, B> {
    /// Boots nothing: wraps an image already started on `path`, its schedule starting at
    /// `now` aligned per `config`.
    pub fn new(image: I, bench: B, path: P, config: &FirmwareConfig, now: u64) -> Self {
        let align = config.align_ns.max(1);
        let start = now.div_ceil(align).saturating_mul(align);
        Self {
            image,
            bench,
            counters: FirmwareCounters::default(),
            last_pdi_error: None,
            path,
            poll_period: config.poll_period_ns.max(1),
            next_poll: match config.poll_after_timer_instants {
                Some(_) => u64::MAX,
                None => start.saturating_add(config.poll_first_ns),
            },
            poll_before_timers: config.poll_before_timers,
            poll_after_instants: config.poll_after_timer_instants.map(|k| k.max(1)),
            instants: 0,
            timers: config
                .timers
                .iter()
                .map(|t| (t.id, t.period_ns.max(1), start.saturating_add(t.first_ns)))
                .collect(),
            cpu: config.timing.map(Cpu::new),
        }
    }

    fn note(&mut self, r: Result<(), <P::Pdi as Pdi>::Error>) {
        if let Err(e) = r {
            self.counters.pdi_errors += 1;
            self.last_pdi_error = Some(e);
        }
    }

    fn next_wakeup(&self) -> u64 {
        if self.timers.is_empty() && self.cpu.is_none() {
            return self.next_poll;
        }
        let first_timer = self.timers.iter().map(|t| t.2).min();
        match &self.cpu {
            None => first_timer.map_or(self.next_poll, |t| t.min(self.next_poll)),
            Some(cpu) => {
                let mut w = cpu.next_end().unwrap_or(u64::MAX);
                if cpu.isr_free() {
                    w = w.min(first_timer.unwrap_or(u64::MAX));
                }
                if cpu.idle() {
                    w = w.min(self.next_poll);
                }
                w
            }
        }
    }

    /// Under the execution-time model: an ESC event at `t`.
    fn timed_event(&mut self, esc: &mut Esc, ev: EscEvent, t: u64) {
        let work = match ev {
            EscEvent::Irq => Work::Irq,
            EscEvent::Sync0 => Work::Sync0,
            EscEvent::Sync1 => Work::Sync1,
            EscEvent::PdWatchdog | EscEvent::PdiWatchdog => return,
        };
        if let Some(cpu) = self.cpu.as_mut() {
            cpu.retire(esc, t);
            cpu.raise(work, t);
        }
        self.dispatch(esc, t);
    }

    /// After the timers of one instant at `at` ran: the main loop may fall due.
    fn timer_instant_done(&mut self, at: u64) {
        self.instants += 1;
        if let Some(k) = self.poll_after_instants {
            if self.instants.is_multiple_of(k) && self.next_poll == u64::MAX {
                self.next_poll = at;
            }
        }
    }

    /// The next main-loop pass after the one due at `due` ran at `t`: on its own period, or
    /// none until a timer instant makes it due.
    fn poll_after(&self, due: u64, t: u64) -> u64 {
        match self.poll_after_instants {
            Some(_) => u64::MAX,
            None => next_after(due, self.poll_period, t),
        }
    }

    /// Re-phases the timers when the bench asks to.
    fn rephase(&mut self, at: Option<u64>) {
        if let Some(at) = at {
            for k in &mut self.timers {
                k.2 = at;
            }
        }
    }

    /// Under the execution-time model: lands finished handlers' writes and starts whatever
    /// may run at `t` (pending interrupts, due timers, then the main loop).
    fn dispatch(&mut self, esc: &mut Esc, t: u64) {
        loop {
            let Self {
                image,
                bench,
                path,
                cpu,
                counters,
                timers,
                ..
            } = self;
            let Some(cpu) = cpu.as_mut() else {
                return;
            };
            cpu.retire(esc, t);
            if cpu.isr_free() {
                if let Some((work, arrival)) = cpu.take_pending() {
                    let ev = match work {
                        Work::Sync0 => EscEvent::Sync0,
                        Work::Sync1 => EscEvent::Sync1,
                        _ => EscEvent::Irq,
                    };
                    bench.before_event(image, ev, arrival);
                    let r = cpu.run(path, esc, work, arrival, t, |path, esc| match work {
                        Work::Sync0 => {
                            counters.sync0 += 1;
                            path.with_pdi(esc, |pdi| image.on_sync0(pdi))
                        }
                        Work::Sync1 => {
                            counters.sync1 += 1;
                            path.with_pdi(esc, |pdi| image.on_sync1(pdi))
                        }
                        _ => {
                            counters.irqs += 1;
                            path.with_pdi(esc, |pdi| image.on_pdi_irq(pdi))
                        }
                    });
                    let at = bench.after_event(image, ev, arrival);
                    self.note(r);
                    self.rephase(at);
                    continue;
                }
                let due = (0..timers.len())
                    .filter(|&k| timers[k].2 <= t)
                    .min_by_key(|&k| timers[k].2);
                if let Some(k) = due {
                    let (id, period, at) = timers[k];
                    counters.timers += 1;
                    bench.before_timers(image, t);
                    let r = cpu.run(path, esc, Work::Timer, at, t, |path, esc| {
                        path.with_pdi(esc, |pdi| image.on_timer(id, pdi))
                    });
                    bench.after_timers(image, t);
                    cpu.lose(Work::Timer, (t - at) / period);
                    timers[k].2 = next_after(at, period, t);
                    self.note(r);
                    self.timer_instant_done(at);
                    continue;
                }
            }
            if cpu.idle() && self.next_poll <= t {
                let at = self.next_poll;
                counters.polls += 1;
                let r = cpu.run(path, esc, Work::Poll, at, t, |path, esc| {
                    path.with_pdi(esc, |pdi| image.poll(pdi))
                });
                self.next_poll = self.poll_after(at, t);
                self.note(r);
                continue;
            }
            return;
        }
    }

    fn event(&mut self, esc: &mut Esc, ev: EscEvent, t: u64) {
        if self.cpu.is_some() {
            return self.timed_event(esc, ev, t);
        }
        match ev {
            EscEvent::Irq => self.counters.irqs += 1,
            EscEvent::Sync0 => self.counters.sync0 += 1,
            EscEvent::Sync1 => self.counters.sync1 += 1,
            EscEvent::PdWatchdog | EscEvent::PdiWatchdog => {}
        }
        self.bench.before_event(&mut self.image, ev, t);
        let Self { image, path, .. } = self;
        let r = deliver(path, image, esc, ev);
        self.note(r);
        let at = self.bench.after_event(&mut self.image, ev, t);
        self.rephase(at);
    }

    fn poll_if_due(&mut self, esc: &mut Esc, t: u64) {
        if self.next_poll <= t {
            self.counters.polls += 1;
            let Self { image, path, .. } = self;
            let r = path.with_pdi(esc, |pdi| image.poll(pdi));
            self.note(r);
            self.next_poll = self.poll_after(self.next_poll, t);
        }
    }

    fn wakeup(&mut self, esc: &mut Esc, t: u64) {
        if self.cpu.is_some() {
            return self.dispatch(esc, t);
        }
        if self.timers.is_empty() {
            // The main loop alone (most devices): no timer instant to order it against.
            return self.poll_if_due(esc, t);
        }
        if self.poll_before_timers {
            self.poll_if_due(esc, t);
        }
        if self.timers.iter().any(|k| k.2 <= t) {
            self.bench.before_timers(&mut self.image, t);
            for k in 0..self.timers.len() {
                let (id, period, due) = self.timers[k];
                if due <= t {
                    self.counters.timers += 1;
                    let Self { image, path, .. } = self;
                    let r = path.with_pdi(esc, |pdi| image.on_timer(id, pdi));
                    self.note(r);
                    self.timers[k].2 = next_after(due, period, t);
                }
            }
            self.bench.after_timers(&mut self.image, t);
            self.timer_instant_done(t);
        }
        if !self.poll_before_timers {
            self.poll_if_due(esc, t);
        }
    }
}

/// Delivers ESC event `ev` to an image the way an MCU's ISRs do: the PDI interrupt,
/// SYNC0 and SYNC1 run their handler through `path`; the watchdogs raise AL events the main
/// loop handles (nothing to run).
pub fn deliver<I: Image<P::Pdi>, P: PdiPath>(
    path: &mut P,
    image: &mut I,
    esc: &mut Esc,
    ev: EscEvent,
) -> Result<(), PathPdiError<P>> {
    match ev {
        EscEvent::Irq => path.with_pdi(esc, |pdi| image.on_pdi_irq(pdi)),
        EscEvent::Sync0 => path.with_pdi(esc, |pdi| image.on_sync0(pdi)),
        EscEvent::Sync1 => path.with_pdi(esc, |pdi| image.on_sync1(pdi)),
        EscEvent::PdWatchdog | EscEvent::PdiWatchdog => Ok(()),
    }
}

/// The first `due + k·period` (k ≥ 1) after `t`: a late MCU skips missed ticks.
fn next_after(due: u64, period: u64, t: u64) -> u64 {
    let n = due.saturating_add(period);
    if n > t {
        n
    } else {
        let behind = (t - due) / period + 1;
        due.saturating_add(behind.saturating_mul(period))
    }
}

/// The PDI error type of path `P`.
pub type PathPdiError<P> = <<P as PdiPath>::Pdi as Pdi>::Error;

/// A new node and its handle, or why the stack did not start on path `P`.
pub type NodeResult<N, H, P> = Result<(N, H), InitError<PathPdiError<P>>>;

/// Access to a [`Host`] from outside the segment (tests, tools).
pub type HostHandle<I, P = Direct, B = ()> = Shared<Host<I, P, B>>;

/// Access to a node's [`Firmware`] from outside the segment (tests, tools).
pub type FirmwareHandle<A, const N: usize, const M: usize, P = Direct> =
    Shared<Firmware<A, N, M, P>>;

impl<I, P: PdiPath, B> Shared<Host<I, P, B>> {
    /// What the node's SPI bus carried since the last reset (`None` on the direct path).
    pub fn bus_stats(&self) -> Option<BusStats> {
        self.lock().bus_stats()
    }

    /// What the execution-time model saw (`None` when it is off): events delayed and lost,
    /// busy and response times per kind of work.
    pub fn timing(&self) -> Option<TimingStats> {
        self.lock().timing()
    }
}

/// The [`Node`] of a [`Host`] on its ESC; see the module documentation.
pub struct HostNode<I, P: PdiPath = Direct, B = ()> {
    host: Held<Host<I, P, B>>,
    /// The host's next wakeup as of the end of its last handler. Only the host's own
    /// handlers move its schedule (timers, main loop, MCU state are private to it; a
    /// handle reaches the image, the bench and the counters), so the segment's scheduler
    /// reads it here without taking the host's mutex.
    next: u64,
}

/// How a [`HostNode`] holds its host: shared with the [`HostHandle`]s behind the mutex
/// while one is left, its own once the last is gone (no handle can be made again, so
/// nothing outside can look at the host any more: it runs without the lock, which a
/// `perf` profile of 128 served demo devices had put at a tenth of the CPU, the locked
/// instructions of taking and releasing it at every main-loop pass).
enum Held<T> {
    Shared(Shared<T>),
    Own(Box<T>),
    /// Only while the host moves from `Shared` to `Own`.
    Moving,
}

impl<T> Held<T> {
    /// Runs `f` on the host: without the lock when no handle is left.
    #[inline]
    fn with(&mut self, f: impl FnOnce(&mut T)) {
        if let Held::Shared(s) = self {
            if s.is_last() {
                self.take_over();
            }
        }
        match self {
            Held::Own(h) => f(h),
            Held::Shared(s) => f(&mut s.lock()),
            Held::Moving => {}
        }
    }

    /// From `Shared` to `Own` (once). Out of line: the host passes through its stack
    /// frame, which inlined would make every pass's frame as large as the host (a stack
    /// probe per page at every main-loop pass).
    #[cold]
    #[inline(never)]
    fn take_over(&mut self) {
        if let Held::Shared(s) = core::mem::replace(self, Held::Moving) {
            *self = match s.into_last() {
                Ok(h) => Held::Own(Box::new(h)),
                Err(s) => Held::Shared(s),
            };
        }
    }
}

impl<I: Image<P::Pdi>, P: PdiPath, B: Bench<I>> HostNode<I, P, B> {
    /// The node of `host`.
    fn new(host: Shared<Host<I, P, B>>) -> Self {
        let next = host.lock().next_wakeup();
        Self {
            host: Held::Shared(host),
            next,
        }
    }
}

impl<I: Image<P::Pdi> + Send + 'static, P: PdiPath, B: Bench<I>> Node<Esc> for HostNode<I, P, B> {
    fn on_event(&mut self, esc: &mut Esc, ev: EscEvent, t: u64) {
        let next = &mut self.next;
        self.host.with(|h| {
            h.event(esc, ev, t);
            *next = h.next_wakeup();
        });
    }

    fn next_wakeup(&self) -> Option<u64> {
        Some(self.next)
    }

    fn on_wakeup(&mut self, esc: &mut Esc, t: u64) {
        let next = &mut self.next;
        self.host.with(|h| {
            h.wakeup(esc, t);
            *next = h.next_wakeup();
        });
    }
}

/// A [`HostNode`] running an `oxicat-slave` stack.
pub type FirmwareNode<A, const N: usize, const M: usize, P = Direct> =
    HostNode<Stack<<P as PdiPath>::Pdi, A, N, M>, P>;

/// Starts the stack of `def` on `esc` through `path` (as its firmware would at reset).
pub fn boot_stack<A, const N: usize, const M: usize, P: PdiPath>(
    def: &'static DeviceDef,
    esc: &mut Esc,
    app: A,
    path: &mut P,
) -> Result<Stack<P::Pdi, A, N, M>, AttachError> {
    let slave = path
        .with_pdi(esc, |pdi| Slave::new(def, pdi))
        .map_err(|e| AttachError::from(P::init_error(e)))?;
    Ok(Stack { slave, app })
}

/// Attaches a host to ESC `id` of `segment`: `boot` starts the image on the ESC through
/// the path `path` built in front of it; the schedule starts now (aligned per `config`).
pub fn attach_host<I: Image<P::Pdi> + Send + 'static, P: PdiPath, B: Bench<I>>(
    segment: &mut Segment,
    id: SlaveId,
    config: &FirmwareConfig,
    bench: B,
    path: impl FnOnce(&mut Esc) -> Result<P, PathInitError>,
    boot: impl FnOnce(&mut Esc, &mut P) -> Result<I, AttachError>,
) -> Result<HostHandle<I, P, B>, AttachError> {
    let now = segment.now();
    let esc = segment
        .esc_mut(id)
        .ok_or(AttachError::Topology(TopologyError::NoSuchSlave(id)))?;
    let mut path = path(esc)?;
    let image = boot(esc, &mut path)?;
    let host = Shared::new(Host::new(image, bench, path, config, now));
    segment
        .attach(id, Box::new(HostNode::new(host.clone())))
        .map_err(AttachError::Topology)?;
    Ok(host)
}

/// Why firmware could not be attached to a segment's ESC.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AttachError {
    /// No such ESC.
    Topology(TopologyError),
    /// The stack refused to start.
    Init(InitError<PdiError>),
    /// The chip driver, or the stack through it, did not start.
    Path(PathInitError),
    /// The machine-code route: the board image could not be loaded or faulted at boot
    /// (the emulator's own error, as text).
    Image(String),
}

impl From<PathInitError> for AttachError {
    fn from(e: PathInitError) -> Self {
        match e {
            PathInitError::Direct(e) => AttachError::Init(e),
            e => AttachError::Path(e),
        }
    }
}

impl core::fmt::Display for AttachError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Topology(e) => write!(f, "{e}"),
            Self::Init(e) => write!(f, "the slave stack did not start: {e:?}"),
            Self::Path(e) => write!(f, "{e}"),
            Self::Image(e) => write!(f, "board image: {e}"),
        }
    }
}

impl std::error::Error for AttachError {}

/// Boots firmware (`def` + `app`) on ESC `id` of `segment` now and attaches it as the ESC's
/// node; returns the handle to look at it.
pub fn attach_firmware<A: Application<N> + Send + 'static, const N: usize, const M: usize>(
    segment: &mut Segment,
    id: SlaveId,
    def: &'static DeviceDef,
    app: A,
    config: &FirmwareConfig,
) -> Result<FirmwareHandle<A, N, M>, AttachError> {
    attach_firmware_with(segment, id, def, app, config, |_| Ok(Direct))
}

/// [`attach_firmware`] with the firmware reaching its ESC through the chip driver of `route`
/// ([`PdiRoute::Lan9252`] or [`PdiRoute::Et1100`]) over the simulated SPI; the driver starts
/// (as on hardware) before the stack. [`PdiRoute::Direct`] is refused
/// ([`PathInitError::NotSpi`]): use [`attach_firmware`].
pub fn attach_firmware_via<A: Application<N> + Send + 'static, const N: usize, const M: usize>(
    segment: &mut Segment,
    id: SlaveId,
    def: &'static DeviceDef,
    app: A,
    config: &FirmwareConfig,
    route: PdiRoute,
) -> Result<FirmwareHandle<A, N, M, SpiPath>, AttachError> {
    attach_firmware_with(segment, id, def, app, config, |esc| {
        SpiPath::new(route, esc)
    })
}

/// [`attach_firmware`] on any [`PdiPath`]: `path` builds it in front of the ESC.
pub fn attach_firmware_with<
    A: Application<N> + Send + 'static,
    const N: usize,
    const M: usize,
    P: PdiPath,
>(
    segment: &mut Segment,
    id: SlaveId,
    def: &'static DeviceDef,
    app: A,
    config: &FirmwareConfig,
    path: impl FnOnce(&mut Esc) -> Result<P, PathInitError>,
) -> Result<FirmwareHandle<A, N, M, P>, AttachError> {
    attach_host(segment, id, config, (), path, |esc, path| {
        boot_stack(def, esc, app, path)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use oxicat_esc::EscConfig;

    /// Counts its main-loop passes into its ESC's process RAM (0x1000) and its own field.
    struct Counter(u32);

    impl<Pd: Pdi> Image<Pd> for Counter {
        fn on_pdi_irq(&mut self, _: &mut Pd) -> Result<(), Pd::Error> {
            Ok(())
        }
        fn on_sync0(&mut self, _: &mut Pd) -> Result<(), Pd::Error> {
            Ok(())
        }
        fn on_sync1(&mut self, _: &mut Pd) -> Result<(), Pd::Error> {
            Ok(())
        }
        fn on_timer(&mut self, _: u8, _: &mut Pd) -> Result<(), Pd::Error> {
            Ok(())
        }
        fn poll(&mut self, pdi: &mut Pd) -> Result<(), Pd::Error> {
            self.0 += 1;
            pdi.write(0x1000, &self.0.to_le_bytes())
        }
    }

    fn ram(seg: &Segment, id: SlaveId) -> u32 {
        let m = seg.esc(id).expect("ESC").memory();
        u32::from_le_bytes([m[0x1000], m[0x1001], m[0x1002], m[0x1003]])
    }

    /// A host whose handles are all gone runs without its lock, from the first pass after
    /// the last went: the same passes as a host whose handle is kept (and as before the
    /// move: handles dropped half way), none lost in the move.
    #[test]
    fn a_host_without_handles_runs_as_one_with_a_handle() {
        let mut seg = Segment::line((0..3).map(|_| Esc::new(EscConfig::et1100(), Vec::new())));
        let cfg = FirmwareConfig::default();
        let attach = |seg: &mut Segment, id| {
            attach_host(seg, id, &cfg, (), |_| Ok(Direct), |_, _| Ok(Counter(0))).expect("attached")
        };
        let kept = attach(&mut seg, 0);
        let dropped_now = attach(&mut seg, 1);
        let dropped_later = attach(&mut seg, 2);
        drop(dropped_now);
        seg.advance_to(1_000_000);
        assert_eq!(kept.lock().image.0, 21);
        assert_eq!(dropped_later.lock().counters.polls, 21);
        drop(dropped_later);
        seg.advance_to(3_000_000);
        let n = kept.lock().image.0;
        assert_eq!(n, 61);
        assert_eq!(kept.lock().counters.polls, 61);
        for id in 0..3 {
            assert_eq!(ram(&seg, id), n, "ESC {id}");
        }
    }

    #[test]
    fn next_after_skips_missed_ticks() {
        assert_eq!(next_after(100, 50, 100), 150);
        assert_eq!(next_after(100, 50, 149), 150);
        assert_eq!(next_after(100, 50, 150), 200);
        assert_eq!(next_after(100, 50, 420), 450);
    }
}
