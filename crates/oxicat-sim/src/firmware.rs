//! Firmware on a simulated ESC: a [`FirmwareNode`] hosts an `oxicat-slave` [`Slave`] and
//! its [`Application`] behind one ESC of a [`Segment`] and delivers the firmware's events
//! at their virtual times, as interrupts and the main loop do on a microcontroller:
//!
//! | MCU | simulator |
//! |---|---|
//! | PDI IRQ ISR | [`EscEvent::Irq`]: the ESC's IRQ line rose (e.g. a frame wrote SM2) → [`Slave::on_pdi_irq`] |
//! | SYNC0 / SYNC1 ISR | [`EscEvent::Sync0`] / [`EscEvent::Sync1`] → [`Slave::on_sync0`] / [`Slave::on_sync1`] |
//! | timer ISRs | periodic wakeups per [`FirmwareConfig::timers`] → [`Slave::on_timer`] |
//! | main loop | a wakeup every [`FirmwareConfig::poll_period_ns`] → [`Slave::poll`] |
//!
//! The segment owns the ESC; the firmware gets `&mut Esc` only while it handles an event.
//! How it reaches the ESC is the node's [`PdiPath`]: by default ([`Direct`]) the software
//! ESC is its [`oxicat_slave::Pdi`]; [`attach_firmware_via`] puts an `oxicat-pdi` chip
//! driver over the simulated SPI in between ([`SpiPath`]: LAN9252 or ET1100), so the
//! firmware runs exactly as on hardware and its bus traffic is counted
//! ([`Firmware::bus_stats`]). The stack and the application live behind a mutex shared with
//! the [`FirmwareHandle`] a test or tool keeps to look at them between cycles.
//!
//! By default every handler runs in zero virtual time. [`FirmwareConfig::timing`] turns on
//! the execution-time model of [`crate::exec_time`]: a handler takes its SPI bus time plus
//! a configured CPU time, its ESC writes land when it ends, and events that arrive while
//! the MCU is busy wait (or are lost) — counted in [`FirmwareHandle::timing`].

use std::sync::{Arc, Mutex, MutexGuard};

use oxicat_esc::{Esc, PdiError};
use oxicat_slave::{Application, DeviceDef, InitError, Pdi, Slave};

use crate::exec_time::{Cpu, ExecTiming, TimingStats, Work};
use crate::node::{EscEvent, Node};
use crate::pdi_path::{BusStats, Direct, PathInitError, PdiPath, PdiRoute, SpiPath};
use crate::segment::{Segment, SlaveId, TopologyError};

/// Default main-loop period: 50 µs of virtual time.
pub const DEFAULT_POLL_PERIOD_NS: u64 = 50_000;

/// How the simulated MCU runs the firmware.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FirmwareConfig {
    /// Virtual time between two main-loop passes ([`Slave::poll`]); at least 1 ns.
    pub poll_period_ns: u64,
    /// Periodic timers: `(id, period in ns)`, each delivered as [`Slave::on_timer`]`(id)`.
    pub timers: Vec<(u8, u64)>,
    /// The execution-time model ([`crate::exec_time`]); `None` (the default): handlers
    /// run in zero virtual time.
    pub timing: Option<ExecTiming>,
}

impl Default for FirmwareConfig {
    fn default() -> Self {
        Self {
            poll_period_ns: DEFAULT_POLL_PERIOD_NS,
            timers: Vec::new(),
            timing: None,
        }
    }
}

impl FirmwareConfig {
    /// Adds a periodic timer `id` every `period_ns` (builder style).
    pub fn timer(mut self, id: u8, period_ns: u64) -> Self {
        self.timers.push((id, period_ns));
        self
    }

    /// Sets the main-loop period (builder style).
    pub fn poll_every(mut self, period_ns: u64) -> Self {
        self.poll_period_ns = period_ns;
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

/// The firmware of one node: the stack, the application, the MCU's schedule and the way
/// it reaches its ESC (`P`, [`Direct`] unless attached through a driver).
pub struct Firmware<A, const N: usize, const M: usize, P: PdiPath = Direct> {
    /// The slave stack.
    pub slave: Slave<P::Pdi, N, M>,
    /// The application.
    pub app: A,
    /// What was delivered so far.
    pub counters: FirmwareCounters,
    /// The last PDI error, if any.
    pub last_pdi_error: Option<<P::Pdi as Pdi>::Error>,
    path: P,
    poll_period: u64,
    next_poll: u64,
    /// `(id, period, next due time)`.
    timers: Vec<(u8, u64, u64)>,
    /// The MCU under the execution-time model, if on.
    cpu: Option<Cpu>,
}

impl<A, const N: usize, const M: usize, P: PdiPath> Firmware<A, N, M, P> {
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

impl<A: Application<N>, const N: usize, const M: usize, P: PdiPath> Firmware<A, N, M, P> {
    fn note(&mut self, r: Result<(), <P::Pdi as Pdi>::Error>) {
        if let Err(e) = r {
            self.counters.pdi_errors += 1;
            self.last_pdi_error = Some(e);
        }
    }

    fn next_wakeup(&self) -> u64 {
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

    /// Under the execution-time model: lands finished handlers' writes and starts whatever
    /// may run at `t` (pending interrupts, due timers, then the main loop).
    fn dispatch(&mut self, esc: &mut Esc, t: u64) {
        loop {
            let Self {
                slave,
                app,
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
                    let r = cpu.run(path, esc, work, arrival, t, |path, esc| match work {
                        Work::Sync0 => {
                            counters.sync0 += 1;
                            path.with_pdi(esc, |pdi| slave.on_sync0(pdi, app))
                        }
                        Work::Sync1 => {
                            counters.sync1 += 1;
                            path.with_pdi(esc, |pdi| slave.on_sync1(pdi, app))
                        }
                        _ => {
                            counters.irqs += 1;
                            path.with_pdi(esc, |pdi| slave.on_pdi_irq(pdi, app))
                        }
                    });
                    self.note(r);
                    continue;
                }
                let due = (0..timers.len())
                    .filter(|&k| timers[k].2 <= t)
                    .min_by_key(|&k| timers[k].2);
                if let Some(k) = due {
                    let (id, period, at) = timers[k];
                    counters.timers += 1;
                    cpu.run(path, esc, Work::Timer, at, t, |_, _| {
                        slave.on_timer(id, app)
                    });
                    cpu.lose(Work::Timer, (t - at) / period);
                    timers[k].2 = next_after(at, period, t);
                    continue;
                }
            }
            if cpu.idle() && self.next_poll <= t {
                let at = self.next_poll;
                counters.polls += 1;
                let r = cpu.run(path, esc, Work::Poll, at, t, |path, esc| {
                    path.with_pdi(esc, |pdi| slave.poll(pdi, app))
                });
                self.next_poll = next_after(at, self.poll_period, t);
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
        let Self {
            slave, app, path, ..
        } = self;
        let r = deliver(path, slave, app, esc, ev);
        self.note(r);
    }

    fn wakeup(&mut self, esc: &mut Esc, t: u64) {
        if self.cpu.is_some() {
            return self.dispatch(esc, t);
        }
        for k in 0..self.timers.len() {
            let (id, period, due) = self.timers[k];
            if due <= t {
                self.counters.timers += 1;
                self.slave.on_timer(id, &mut self.app);
                self.timers[k].2 = next_after(due, period, t);
            }
        }
        if self.next_poll <= t {
            self.counters.polls += 1;
            let Self {
                slave, app, path, ..
            } = self;
            let r = path.with_pdi(esc, |pdi| slave.poll(pdi, app));
            self.note(r);
            self.next_poll = next_after(self.next_poll, self.poll_period, t);
        }
    }
}

/// Delivers ESC event `ev` to the slave stack the way an MCU's ISRs do: the PDI interrupt,
/// SYNC0 and SYNC1 run their handler through `path`; the watchdogs raise AL events the main
/// loop handles (nothing to run). One dispatch for every firmware host on the segment.
pub fn deliver<A: Application<N>, const N: usize, const M: usize, P: PdiPath>(
    path: &mut P,
    slave: &mut Slave<P::Pdi, N, M>,
    app: &mut A,
    esc: &mut Esc,
    ev: EscEvent,
) -> Result<(), PathPdiError<P>> {
    match ev {
        EscEvent::Irq => path.with_pdi(esc, |pdi| slave.on_pdi_irq(pdi, app)),
        EscEvent::Sync0 => path.with_pdi(esc, |pdi| slave.on_sync0(pdi, app)),
        EscEvent::Sync1 => path.with_pdi(esc, |pdi| slave.on_sync1(pdi, app)),
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

/// Access to a node's [`Firmware`] from outside the segment (tests, tools).
pub struct FirmwareHandle<A, const N: usize, const M: usize, P: PdiPath = Direct>(
    Arc<Mutex<Firmware<A, N, M, P>>>,
);

impl<A, const N: usize, const M: usize, P: PdiPath> Clone for FirmwareHandle<A, N, M, P> {
    fn clone(&self) -> Self {
        Self(self.0.clone())
    }
}

impl<A, const N: usize, const M: usize, P: PdiPath> FirmwareHandle<A, N, M, P> {
    /// Locks the firmware (do not hold it while waiting for the segment).
    pub fn lock(&self) -> MutexGuard<'_, Firmware<A, N, M, P>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

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

/// A [`Node`] running firmware on its ESC; see the module documentation.
pub struct FirmwareNode<A, const N: usize, const M: usize, P: PdiPath = Direct>(
    Arc<Mutex<Firmware<A, N, M, P>>>,
);

impl<A: Application<N> + Send + 'static, const N: usize, const M: usize> FirmwareNode<A, N, M> {
    /// Boots the firmware on `esc` (the stack initialises the ESC through its PDI); the
    /// main loop and the timers start at virtual time `start_ns`.
    pub fn new(
        def: &'static DeviceDef,
        esc: &mut Esc,
        app: A,
        config: &FirmwareConfig,
        start_ns: u64,
    ) -> Result<(Self, FirmwareHandle<A, N, M>), InitError<PdiError>> {
        Self::with_path(def, esc, app, config, start_ns, Direct)
    }
}

impl<A: Application<N> + Send + 'static, const N: usize, const M: usize, P: PdiPath>
    FirmwareNode<A, N, M, P>
{
    /// [`FirmwareNode::new`] with the firmware reaching `esc` through `path` (its driver
    /// already started).
    pub fn with_path(
        def: &'static DeviceDef,
        esc: &mut Esc,
        app: A,
        config: &FirmwareConfig,
        start_ns: u64,
        mut path: P,
    ) -> NodeResult<Self, FirmwareHandle<A, N, M, P>, P> {
        let slave = path.with_pdi(esc, |pdi| Slave::new(def, pdi))?;
        let poll_period = config.poll_period_ns.max(1);
        let fw = Firmware {
            slave,
            app,
            counters: FirmwareCounters::default(),
            last_pdi_error: None,
            path,
            poll_period,
            next_poll: start_ns,
            timers: config
                .timers
                .iter()
                .map(|&(id, p)| (id, p.max(1), start_ns.saturating_add(p.max(1))))
                .collect(),
            cpu: config.timing.map(Cpu::new),
        };
        let inner = Arc::new(Mutex::new(fw));
        Ok((Self(inner.clone()), FirmwareHandle(inner)))
    }

    fn lock(&self) -> MutexGuard<'_, Firmware<A, N, M, P>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl<A: Application<N> + Send + 'static, const N: usize, const M: usize, P: PdiPath> Node<Esc>
    for FirmwareNode<A, N, M, P>
{
    fn on_event(&mut self, esc: &mut Esc, ev: EscEvent, t: u64) {
        self.lock().event(esc, ev, t);
    }

    fn next_wakeup(&self) -> Option<u64> {
        Some(self.lock().next_wakeup())
    }

    fn on_wakeup(&mut self, esc: &mut Esc, t: u64) {
        self.lock().wakeup(esc, t);
    }
}

/// Why firmware could not be attached to a segment's ESC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AttachError {
    /// No such ESC.
    Topology(TopologyError),
    /// The stack refused to start.
    Init(InitError<PdiError>),
    /// The chip driver, or the stack through it, did not start.
    Path(PathInitError),
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
    let now = segment.now();
    let esc = segment
        .esc_mut(id)
        .ok_or(AttachError::Topology(TopologyError::NoSuchSlave(id)))?;
    let path = path(esc)?;
    let (node, handle) = FirmwareNode::<A, N, M, P>::with_path(def, esc, app, config, now, path)
        .map_err(|e| AttachError::from(P::init_error(e)))?;
    segment
        .attach(id, Box::new(node))
        .map_err(AttachError::Topology)?;
    Ok(handle)
}

#[cfg(test)]
mod tests {
    use super::next_after;

    #[test]
    fn next_after_skips_missed_ticks() {
        assert_eq!(next_after(100, 50, 100), 150);
        assert_eq!(next_after(100, 50, 149), 150);
        assert_eq!(next_after(100, 50, 150), 200);
        assert_eq!(next_after(100, 50, 420), 450);
    }
}
