//! The virtual EtherCAT segment: ESCs wired in a topology, a virtual clock in ns, lockstep
//! frame exchange with per-hop delays, event delivery to PDI-side nodes, and fault hooks.
//!
//! Time model: a frame sent by the master at `now()` reaches slave 0 port 0 after the master
//! link delay; every ESC it passes holds it for its forwarding delay, every cable adds its
//! delay (both directions alike, so DC delay measurement is exact when all ESCs have the
//! same forwarding delay). The frame is back at the master when its first bit leaves slave 0
//! port 0 plus the master link delay; the master has it when its last bit arrived, i.e. one
//! wire time later. `now()` then stands at that moment. Frames the master sends together
//! (a train, [`Segment::exchange_train`], as a NIC sends its queue) are on the line
//! together: each leaves the master one wire time after the one before, and every ESC
//! meets them in that order, each at its own time, with the nodes' events between them at
//! theirs; a cycle of several frames takes their wire times and one trip, as on a real
//! segment, not a trip per frame.

use std::sync::atomic::{AtomicU64, Ordering};

use oxicat_wire::EthernetHeader;

use crate::capture::{CaptureSink, Direction};
use crate::model::{AdvanceEvents, SegmentEsc};
use crate::node::{EscEvent, Node};
use crate::sched::{EventQueue, Kind};

/// Ports an ESC can have.
pub const MAX_PORTS: usize = 4;

/// Default forwarding delay of an ESC (arrival at a port to departure at the next), in ns.
pub const DEFAULT_ESC_DELAY_NS: u64 = 450;
/// Default cable delay of a link (about 10 m), in ns.
pub const DEFAULT_LINK_DELAY_NS: u64 = 50;
/// Time of one byte on a 100 Mbit/s wire, in ns.
pub const BYTE_TIME_NS: u64 = 80;
/// Bytes on the wire besides the frame itself: preamble + SFD (8), FCS (4), inter-frame gap (12).
pub const WIRE_OVERHEAD_BYTES: u64 = 24;
/// Minimum Ethernet frame length without FCS.
const ETH_MIN: usize = 60;
/// Hops after which a frame is considered lost (a loop the ESCs failed to break).
const MAX_HOPS: usize = 4096;

/// Index of an ESC in a segment, in the order it was added.
pub type SlaveId = usize;

/// Why a topology operation was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TopologyError {
    /// No ESC with this index.
    NoSuchSlave(SlaveId),
    /// Port number ≥ 4.
    NoSuchPort(u8),
    /// The port is already wired (or is the master link).
    PortInUse(SlaveId, u8),
    /// The port is not wired.
    NotWired(SlaveId, u8),
    /// A port cannot be wired to itself.
    SelfLoop,
}

impl core::fmt::Display for TopologyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoSuchSlave(s) => write!(f, "no slave {s}"),
            Self::NoSuchPort(p) => write!(f, "no port {p}"),
            Self::PortInUse(s, p) => write!(f, "slave {s} port {p} is already wired"),
            Self::NotWired(s, p) => write!(f, "slave {s} port {p} is not wired"),
            Self::SelfLoop => write!(f, "a port cannot be wired to itself"),
        }
    }
}

impl std::error::Error for TopologyError {}

/// A copyable handle on a segment's virtual clock, e.g. for ethercrab's `now` function.
#[derive(Debug, Clone, Copy)]
pub struct SimClock(&'static SimTime);

impl SimClock {
    /// Virtual time in ns.
    pub fn now(&self) -> u64 {
        oxicat_wire::pipe::VirtualClock::now(self.0)
    }
}

/// A segment's virtual time, readable from any thread (one per segment, for its lifetime
/// and beyond: handles on it are `'static` and `Copy`).
#[derive(Debug)]
pub struct SimTime(AtomicU64);

impl oxicat_wire::pipe::VirtualClock for SimTime {
    fn now(&self) -> u64 {
        self.0.load(Ordering::Acquire)
    }
}

/// What happened to the last frame given to [`Segment::exchange`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameFate {
    /// Back at the master intact.
    Returned,
    /// Not an EtherCAT frame; ignored.
    Ignored,
    /// Removed by the drop-frames fault.
    DroppedByFault,
    /// An ESC dropped it (circulating-frame rule).
    DroppedByEsc(SlaveId),
    /// It left through an unwired port whose loop was open.
    LostAtOpenPort(SlaveId, u8),
    /// It came back with a bad FCS (corrupted on the way); the master's NIC discards it.
    Corrupted,
    /// It was still circulating after many hops.
    Lost,
}

/// Counters of the master link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SegmentStats {
    /// Frames the master sent.
    pub sent: u64,
    /// Frames returned to the master intact.
    pub returned: u64,
    /// Frames that did not come back (or came back corrupted).
    pub lost: u64,
    /// Non-EtherCAT frames ignored.
    pub ignored: u64,
}

#[derive(Debug, Clone, Copy)]
struct Link {
    peer: SlaveId,
    peer_port: u8,
    delay_ns: u64,
    /// Cable plugged in (false after [`Segment::set_cable`] pulled it).
    up: bool,
}

struct Slot<E> {
    esc: E,
    node: Option<Box<dyn Node<E>>>,
    links: [Option<Link>; MAX_PORTS],
    delay_ns: u64,
    /// The time this slot's ESC was last brought to by [`Segment::advance_slot`]. Time
    /// reaches every slot lazily: a slot's events up to `max(advanced, Segment::now)` are
    /// done (see [`Segment::done_to`]), and its ESC is brought to a time only when the
    /// segment next touches it.
    advanced: u64,
    /// In [`Segment::stale`]: its ESC has an event at or before the time its events are
    /// done (a frame or its node scheduled one there).
    stale: bool,
    irq: bool,
    last_sync0: Option<u64>,
    last_sync1: Option<u64>,
    /// Time of the node's last wakeup (its next one must be later).
    last_wake: Option<u64>,
    /// The ESC's `next_event()` and the node's [`wakeup`](Slot::wakeup) as last asked
    /// (the reference scheduler's copy, valid inside one of its passes).
    due: Due,
    /// The ESC's [`SegmentEsc::query_epoch`] after the last hop of a frame here, when that
    /// hop had read its next event and IRQ line (see `Segment::walk_through`).
    hop_epoch: Option<u64>,
    /// The ESC's [`SegmentEsc::query_epoch`] when `irq` was last read from its line (see
    /// `Segment::check_irq`).
    irq_epoch: Option<u64>,
}

/// A slot's next times as the scheduler last read them.
#[derive(Debug, Clone, Copy, Default)]
struct Due {
    esc: Option<u64>,
    wake: Option<u64>,
}

impl<E: SegmentEsc> Slot<E> {
    /// The node's next wakeup, if it is still to come.
    fn wakeup(&self) -> Option<u64> {
        let w = self.node.as_ref()?.next_wakeup()?;
        self.last_wake.is_none_or(|l| w > l).then_some(w)
    }

    /// Reads the ESC's next event and the node's next wakeup into `due`.
    fn read_due(&mut self) {
        self.due = Due {
            esc: self.esc.next_event(),
            wake: self.wakeup(),
        };
    }
}

#[derive(Debug, Clone, Copy)]
struct Corruption {
    slave: SlaveId,
    port: u8,
    offset: usize,
}

/// A logged event (when event logging is on).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoggedEvent {
    /// The ESC.
    pub slave: SlaveId,
    /// What happened.
    pub event: EscEvent,
    /// Virtual time in ns.
    pub t: u64,
}

/// A chain/tree of ESCs with a virtual clock; the master link is slave 0 port 0.
pub struct Segment<E: SegmentEsc = oxicat_esc::Esc> {
    slots: Vec<Slot<E>>,
    now: u64,
    clock: &'static SimTime,
    master_link_delay_ns: u64,
    master_link_up: bool,
    /// Every slot's next ESC event and node wakeup, earliest first (see
    /// [`Segment::run_events_until`]).
    queue: EventQueue,
    /// Slots whose ESC was lent out ([`Segment::esc_mut`]): their next times are read again
    /// before the next pick.
    dirty: Vec<SlaveId>,
    /// Slots whose ESC has an event at or before the time their events are done: time
    /// reaching the next instant brings them there (see [`Segment::advance_to`]).
    stale: Vec<SlaveId>,
    capture: Option<Box<dyn CaptureSink>>,
    drop_next: u64,
    corruptions: Vec<Corruption>,
    stats: SegmentStats,
    last_fate: Option<FrameFate>,
    event_log: Option<Vec<LoggedEvent>>,
    /// The reference scheduler (see [`Segment::set_reference_scheduler`]).
    reference: bool,
    /// Configured-address dispatch on (the default; see [`Segment::set_configured_dispatch`]).
    dispatch_on: bool,
    /// The indexes of frames on their way, kept for their buffers.
    dispatch_pool: Vec<oxicat_esc::FrameDispatch>,
    /// The frames of the train on its way (kept for its buffer).
    flights: Vec<Flight>,
    /// The fates of a train sent through [`oxicat_wire::pipe::FramePipe`] (kept for its
    /// buffer).
    train_fates: Vec<FrameFate>,
}

/// Where a frame on its way is: the ESC port it reaches next and when.
#[derive(Debug, Clone, Copy)]
struct Hop {
    at: (SlaveId, u8),
    t: u64,
    /// Not corrupted so far.
    ok: bool,
    hops: usize,
}

/// A frame of a train ([`Segment::exchange_train`]).
#[derive(Debug)]
struct Flight {
    /// Offset of the EtherCAT header in the Ethernet frame.
    off: usize,
    /// When its first bit left the master.
    sent: u64,
    /// Its wire time (0: ignored, never sent).
    wire: u64,
    hop: Hop,
    /// The frame's index for configured-address dispatch, if it has one.
    dispatch: Option<oxicat_esc::FrameDispatch>,
    /// Its fate and the time its first bit was back at the master (or was lost).
    done: Option<(FrameFate, u64)>,
}

impl Flight {
    /// A frame that is not EtherCAT: never on the line.
    fn ignored(t: u64) -> Self {
        Self {
            off: 0,
            sent: t,
            wire: 0,
            hop: Hop {
                at: (0, 0),
                t,
                ok: false,
                hops: 0,
            },
            dispatch: None,
            done: Some((FrameFate::Ignored, t)),
        }
    }
}

/// The master's side of an in-process segment ([`oxicat_wire::pipe`]).
impl<E: SegmentEsc> oxicat_wire::pipe::FramePipe for Segment<E> {
    fn exchange_in_place(&mut self, frame: &mut [u8]) -> bool {
        Segment::exchange_in_place(self, frame)
    }

    fn exchange_train(&mut self, frames: &mut [&mut [u8]], back: &mut [bool], spacing_ns: u64) {
        let n = frames.len().min(back.len());
        let mut fates = core::mem::take(&mut self.train_fates);
        fates.clear();
        fates.resize(n, FrameFate::Lost);
        Segment::exchange_train(self, &mut frames[..n], &mut fates, spacing_ns);
        for (b, f) in back.iter_mut().zip(&fates) {
            *b = *f == FrameFate::Returned;
        }
        self.train_fates = fates;
    }

    fn now(&self) -> u64 {
        Segment::now(self)
    }

    fn advance_to(&mut self, t: u64) {
        Segment::advance_to(self, t);
    }

    fn clock(&self) -> &'static dyn oxicat_wire::pipe::VirtualClock {
        self.clock
    }
}

impl<E: SegmentEsc> Default for Segment<E> {
    fn default() -> Self {
        Self::new()
    }
}

impl<E: SegmentEsc> core::fmt::Debug for Segment<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Segment")
            .field("slaves", &self.slots.len())
            .field("now", &self.now)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl<E: SegmentEsc> Segment<E> {
    /// An empty segment at virtual time 0.
    pub fn new() -> Self {
        Self {
            slots: Vec::new(),
            now: 0,
            clock: Box::leak(Box::new(SimTime(AtomicU64::new(0)))),
            master_link_delay_ns: DEFAULT_LINK_DELAY_NS,
            master_link_up: true,
            queue: EventQueue::default(),
            dirty: Vec::new(),
            stale: Vec::new(),
            capture: None,
            drop_next: 0,
            corruptions: Vec::new(),
            stats: SegmentStats::default(),
            last_fate: None,
            event_log: None,
            reference: false,
            dispatch_on: true,
            dispatch_pool: Vec::new(),
            flights: Vec::new(),
            train_fates: Vec::new(),
        }
    }

    /// A line: ESC k port 1 wired to ESC k+1 port 0, default delays.
    pub fn line(escs: impl IntoIterator<Item = E>) -> Self {
        let mut s = Self::new();
        for e in escs {
            s.add(e);
        }
        s
    }

    /// Adds an ESC at the end of the line (wired to the previous ESC's port 1 if that port is
    /// free) and returns its index.
    pub fn add(&mut self, esc: E) -> SlaveId {
        let id = self.add_unwired(esc);
        if id > 0 && self.slots[id - 1].links[1].is_none() {
            // Cannot fail: both ports exist and are free.
            let _ = self.connect(id - 1, 1, id, 0);
        }
        id
    }

    /// Adds an ESC with no cables (slave 0's port 0 is the master link); wire it with
    /// [`connect`](Self::connect).
    pub fn add_unwired(&mut self, mut esc: E) -> SlaveId {
        let id = self.slots.len();
        for p in 0..MAX_PORTS as u8 {
            esc.set_link(p, id == 0 && p == 0 && self.master_link_up);
        }
        self.slots.push(Slot {
            esc,
            node: None,
            links: [None; MAX_PORTS],
            delay_ns: DEFAULT_ESC_DELAY_NS,
            advanced: self.now,
            stale: false,
            irq: false,
            last_sync0: None,
            last_sync1: None,
            last_wake: None,
            due: Due::default(),
            hop_epoch: None,
            irq_epoch: None,
        });
        self.queue.grow_to(self.slots.len());
        self.requeue(id);
        id
    }

    fn check(&self, s: SlaveId, p: u8) -> Result<(), TopologyError> {
        if s >= self.slots.len() {
            return Err(TopologyError::NoSuchSlave(s));
        }
        if p as usize >= MAX_PORTS {
            return Err(TopologyError::NoSuchPort(p));
        }
        Ok(())
    }

    fn is_master_port(s: SlaveId, p: u8) -> bool {
        s == 0 && p == 0
    }

    /// Wires `a`'s port `pa` to `b`'s port `pb` with the default cable delay.
    pub fn connect(&mut self, a: SlaveId, pa: u8, b: SlaveId, pb: u8) -> Result<(), TopologyError> {
        self.connect_with_delay(a, pa, b, pb, DEFAULT_LINK_DELAY_NS)
    }

    /// Wires `a`'s port `pa` to `b`'s port `pb`; the cable delays frames by `delay_ns` in
    /// each direction.
    pub fn connect_with_delay(
        &mut self,
        a: SlaveId,
        pa: u8,
        b: SlaveId,
        pb: u8,
        delay_ns: u64,
    ) -> Result<(), TopologyError> {
        self.check(a, pa)?;
        self.check(b, pb)?;
        if a == b && pa == pb {
            return Err(TopologyError::SelfLoop);
        }
        for (s, p) in [(a, pa), (b, pb)] {
            if Self::is_master_port(s, p) || self.slots[s].links[p as usize].is_some() {
                return Err(TopologyError::PortInUse(s, p));
            }
        }
        self.slots[a].links[pa as usize] = Some(Link {
            peer: b,
            peer_port: pb,
            delay_ns,
            up: true,
        });
        self.slots[b].links[pb as usize] = Some(Link {
            peer: a,
            peer_port: pa,
            delay_ns,
            up: true,
        });
        self.set_link(a, pa, true);
        self.set_link(b, pb, true);
        Ok(())
    }

    /// Removes the cable at `a`'s port `pa` (both ends see link down).
    pub fn disconnect(&mut self, a: SlaveId, pa: u8) -> Result<(), TopologyError> {
        self.check(a, pa)?;
        let l = self.slots[a].links[pa as usize]
            .take()
            .ok_or(TopologyError::NotWired(a, pa))?;
        self.slots[l.peer].links[l.peer_port as usize] = None;
        self.set_link(a, pa, false);
        self.set_link(l.peer, l.peer_port, false);
        Ok(())
    }

    /// Pulls (`plugged == false`) or re-plugs the cable at `a`'s port `pa`: both ends see the
    /// link change and close/open their loops as silicon does. Slave 0 port 0 is the master
    /// link.
    pub fn set_cable(&mut self, a: SlaveId, pa: u8, plugged: bool) -> Result<(), TopologyError> {
        self.check(a, pa)?;
        if Self::is_master_port(a, pa) {
            self.master_link_up = plugged;
            self.set_link(0, 0, plugged);
            return Ok(());
        }
        let l = self.slots[a].links[pa as usize].ok_or(TopologyError::NotWired(a, pa))?;
        for (s, p) in [(a, pa), (l.peer, l.peer_port)] {
            if let Some(x) = self.slots[s].links[p as usize].as_mut() {
                x.up = plugged;
            }
            self.set_link(s, p, plugged);
        }
        Ok(())
    }

    /// ESC `s` sees its port `p`'s link go up or down (brought to `now` first, its next
    /// times read again after).
    fn set_link(&mut self, s: SlaveId, p: u8, up: bool) {
        self.settle(s);
        self.slots[s].esc.set_link(p, up);
        self.requeue(s);
    }

    /// Sets the cable delay of the link at `a`'s port `pa` (the master link for slave 0
    /// port 0).
    pub fn set_link_delay(
        &mut self,
        a: SlaveId,
        pa: u8,
        delay_ns: u64,
    ) -> Result<(), TopologyError> {
        self.check(a, pa)?;
        if Self::is_master_port(a, pa) {
            self.master_link_delay_ns = delay_ns;
            return Ok(());
        }
        let l = self.slots[a].links[pa as usize].ok_or(TopologyError::NotWired(a, pa))?;
        for (s, p) in [(a, pa), (l.peer, l.peer_port)] {
            if let Some(x) = self.slots[s].links[p as usize].as_mut() {
                x.delay_ns = delay_ns;
            }
        }
        Ok(())
    }

    /// Sets how long ESC `s` holds a frame between arrival and departure, in ns.
    pub fn set_esc_delay(&mut self, s: SlaveId, delay_ns: u64) -> Result<(), TopologyError> {
        self.check(s, 0)?;
        self.slots[s].delay_ns = delay_ns;
        Ok(())
    }

    /// The peer (slave, port) wired to `a`'s port `pa`, if any.
    pub fn peer(&self, a: SlaveId, pa: u8) -> Option<(SlaveId, u8)> {
        self.slots
            .get(a)?
            .links
            .get(pa as usize)?
            .map(|l| (l.peer, l.peer_port))
    }

    /// Attaches the PDI-side party of ESC `s` (replacing any previous one).
    pub fn attach(&mut self, s: SlaveId, node: Box<dyn Node<E>>) -> Result<(), TopologyError> {
        self.check(s, 0)?;
        self.slots[s].node = Some(node);
        self.slots[s].last_wake = None;
        self.requeue(s);
        Ok(())
    }

    /// Number of ESCs.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether the segment has no ESC.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// ESC `s`, as the segment last touched it: registers that only time changes (the
    /// SII EEPROM's busy bit at the end of a write cycle, the ESC's own idea of the time)
    /// may be those of an earlier instant than [`now`](Self::now) — every event up to
    /// `now` has been delivered, and [`esc_mut`](Self::esc_mut) brings the ESC to `now`.
    pub fn esc(&self, s: SlaveId) -> Option<&E> {
        self.slots.get(s).map(|x| &x.esc)
    }

    /// ESC `s`, mutably (PDI-side pokes between cycles).
    pub fn esc_mut(&mut self, s: SlaveId) -> Option<&mut E> {
        if s < self.slots.len() {
            // Brought to `now` first (what it reads of time is then current); a PDI access
            // may change the ESC's schedule: read it again before the next pick.
            self.settle(s);
            self.dirty.push(s);
        }
        self.slots.get_mut(s).map(|x| &mut x.esc)
    }

    /// Global time of the last SYNC0 / SYNC1 rising edge of ESC `s`.
    pub fn last_sync(&self, s: SlaveId) -> (Option<u64>, Option<u64>) {
        self.slots
            .get(s)
            .map_or((None, None), |x| (x.last_sync0, x.last_sync1))
    }

    /// Starts (or stops, with `false`) logging every delivered event.
    pub fn log_events(&mut self, on: bool) {
        self.event_log = if on { Some(Vec::new()) } else { None };
    }

    /// Removes and returns the logged events.
    pub fn take_events(&mut self) -> Vec<LoggedEvent> {
        self.event_log
            .as_mut()
            .map(std::mem::take)
            .unwrap_or_default()
    }

    /// Sends captured frames to `sink` from now on (replacing any previous sink).
    pub fn set_capture(
        &mut self,
        sink: Option<Box<dyn CaptureSink>>,
    ) -> Option<Box<dyn CaptureSink>> {
        std::mem::replace(&mut self.capture, sink)
    }

    /// Flushes the capture sink, if any.
    pub fn flush_capture(&mut self) -> std::io::Result<()> {
        self.capture.as_mut().map_or(Ok(()), |c| c.flush())
    }

    /// Master link counters.
    pub fn stats(&self) -> SegmentStats {
        self.stats
    }

    /// What happened to the last frame given to [`exchange`](Self::exchange).
    pub fn last_fate(&self) -> Option<FrameFate> {
        self.last_fate
    }

    // ---------------------------------------------------------------- faults

    /// Fault: the next `n` EtherCAT frames are lost on the master link (never reach an ESC).
    pub fn drop_next_frames(&mut self, n: u64) {
        self.drop_next += n;
    }

    /// Fault: the next frame arriving at `slave`'s `port` has byte `offset` (counted from the
    /// EtherCAT header, wrapped to the frame length) inverted on the cable just before; that
    /// ESC and all after it see a bad FCS.
    pub fn corrupt_next_at(
        &mut self,
        slave: SlaveId,
        port: u8,
        offset: usize,
    ) -> Result<(), TopologyError> {
        self.check(slave, port)?;
        self.corruptions.push(Corruption {
            slave,
            port,
            offset,
        });
        Ok(())
    }

    // ---------------------------------------------------------------- time

    /// Virtual time in ns.
    pub fn now(&self) -> u64 {
        self.now
    }

    /// A copyable handle that reads this segment's virtual time from anywhere.
    pub fn clock(&self) -> SimClock {
        SimClock(self.clock)
    }

    fn set_now(&mut self, t: u64) {
        if t > self.now {
            self.now = t;
            self.clock.0.store(t, Ordering::Release);
        }
    }

    /// Advances virtual time by `dt` ns, delivering events on the way.
    pub fn advance_by(&mut self, dt: u64) {
        self.advance_to(self.now.saturating_add(dt));
    }

    /// Advances virtual time to `t` (no-op if `t` is in the past), delivering every ESC's
    /// events in time order.
    ///
    /// Slots are brought to `t` lazily: every event up to `t` is delivered here, but an ESC
    /// with none is brought to the time only when the segment next touches it (a frame
    /// passes it, its node runs, [`esc_mut`](Self::esc_mut), a cable). At 1,000 ESCs a
    /// pass over every slot after each frame was a tenth of the serving CPU; nothing it
    /// did is observable through a frame or a node (an ESC's interrupt line and next times
    /// change only where the segment touches it, and is re-read there).
    /// [`set_reference_scheduler`](Self::set_reference_scheduler) keeps that pass.
    pub fn advance_to(&mut self, t: u64) {
        if t < self.now {
            // Every event up to `now` was delivered when time reached it (a frame's trip
            // can take virtual time past a real-time server's clock; its next advance then
            // comes here).
            return;
        }
        self.run_events_until(t);
        if self.reference {
            for i in 0..self.slots.len() {
                self.advance_slot(i, t);
                self.requeue(i);
            }
            for i in core::mem::take(&mut self.stale) {
                self.slots[i].stale = false;
            }
        } else if !self.stale.is_empty() {
            // The slots that pass would have found an event at: in slot order, as it went.
            let mut stale = core::mem::take(&mut self.stale);
            stale.sort_unstable();
            for i in stale {
                self.slots[i].stale = false;
                if t > self.done_to(i) {
                    self.advance_esc(i, t);
                }
                self.requeue(i);
            }
        }
        self.set_now(t);
    }

    /// Brings slot `i` to [`now`](Self::now), as time reaching it would have (see
    /// [`advance_to`](Self::advance_to)), before the segment lends or changes its ESC.
    fn settle(&mut self, i: usize) {
        if self.catch_up(i) {
            self.requeue(i);
        }
    }

    /// Brings a slot time has lazily passed to `now` (see [`advance_to`](Self::advance_to));
    /// whether it was behind.
    #[inline]
    fn catch_up(&mut self, i: usize) -> bool {
        let behind = self.slots[i].advanced < self.now;
        if behind {
            self.advance_esc(i, self.now);
        }
        behind
    }

    /// The time up to which slot `i`'s events are done: the time its ESC was last brought
    /// to, or `now`, which time reached for every slot.
    #[inline]
    fn done_to(&self, i: usize) -> u64 {
        self.slots[i].advanced.max(self.now)
    }

    /// The reference scheduler (off by default): every pass reads every slot's next times
    /// afresh and picks the earliest by a pass over all slots, as the scheduler did before
    /// its event queue. Both deliver the same events in the same order (a slot's next times
    /// change only when the segment touches its ESC or its node runs, and each such touch
    /// re-queues the slot); equivalence tests run both.
    pub fn set_reference_scheduler(&mut self, on: bool) {
        self.reference = on;
        self.dirty.extend(0..self.slots.len());
    }

    /// Slot `i`'s next ESC event still to come and its node's next wakeup, as they are
    /// now. An ESC event at or before the time the slot's events are done (a frame or the
    /// node scheduled it there) is not one to come: the slot is noted in `stale`, and the
    /// time's next step brings its ESC there.
    #[inline]
    fn due_now(&mut self, i: usize) -> (Option<u64>, Option<u64>) {
        let done = self.done_to(i);
        let s = &mut self.slots[i];
        let esc = match s.esc.next_event() {
            Some(ne) if ne <= done => {
                if !s.stale {
                    s.stale = true;
                    self.stale.push(i);
                }
                None
            }
            ne => ne,
        };
        (esc, s.wakeup())
    }

    /// Brings slot `i`'s entries in the event queue up to date after anything that may
    /// have moved its next times (its ESC advanced, a frame passed it, its node ran, a cable
    /// or the node changed): an earlier or new time is queued at once; a later one (or none)
    /// is left for [`run_events_until`](Self::run_events_until) to find when the entry comes
    /// first (an entry is never later than its slot's time, so the first entry, once checked,
    /// is the earliest). A firmware's PDI watchdog deadline moves later at every main-loop
    /// pass; this way it costs a comparison, not a sift.
    #[inline]
    fn requeue(&mut self, i: usize) {
        let (esc, wake) = self.due_now(i);
        self.queue.lower(i, Kind::Esc, esc);
        self.queue.lower(i, Kind::Wake, wake);
    }

    /// Delivers all events and node wakeups due up to `t`, earliest first across ESCs: by
    /// time, then ESC event before wakeup, then lowest slot index.
    ///
    /// The candidates come from the event queue, which holds an entry per slot and kind no
    /// later than the slot's next ESC event or next wakeup. A slot's entries are brought up
    /// to date after whatever may move its times — its ESC advanced
    /// ([`advance_slot`](Self::advance_slot)), a frame passed it, its node handled an event
    /// or a wakeup, its ESC was lent out ([`esc_mut`](Self::esc_mut)), a cable or its node
    /// changed — and only then: handling an event touches that slot's ESC and node only, so
    /// the others' times still hold. The first entry is checked against its slot before it
    /// runs (an entry left early is moved to its time and the next one looked at). Each pick
    /// costs O(log n) instead of a read of every slot
    /// ([`set_reference_scheduler`](Self::set_reference_scheduler) keeps that way, to
    /// compare).
    #[inline(always)]
    fn run_events_until(&mut self, t: u64) {
        // Nothing due, the common case at a frame's hop: one look at the first entry.
        if self.dirty.is_empty()
            && !self.reference
            && self.queue.peek().is_none_or(|(at, _, _)| at > t)
        {
            return;
        }
        self.run_events_due(t);
    }

    /// [`run_events_until`](Self::run_events_until) when something may be due.
    #[inline(never)]
    fn run_events_due(&mut self, t: u64) {
        if self.reference {
            return self.run_events_reference(t);
        }
        while let Some(i) = self.dirty.pop() {
            self.requeue(i);
        }
        while let Some((at, i, kind)) = self.queue.peek() {
            if at > t {
                break;
            }
            let (esc, wake) = self.due_now(i);
            let now = match kind {
                Kind::Esc => esc,
                Kind::Wake => wake,
            };
            if now != Some(at) {
                // Left early: to its time (or out), and look again.
                self.queue.set(i, kind, now);
                continue;
            }
            match kind {
                Kind::Esc => self.advance_slot(i, at),
                Kind::Wake => self.wake(i, at),
            }
            // Taken: the entry moves to the slot's next time of that kind (one sift), the
            // other kind's entry is lowered if it must. Neither can be `at` again — an ESC
            // event must be later than the time its ESC was brought to, a wakeup later than
            // the last — but an entry left at `at` would be picked forever, so make sure.
            let (esc, wake) = self.due_now(i);
            let (this, other, other_kind) = match kind {
                Kind::Esc => (esc, wake, Kind::Wake),
                Kind::Wake => (wake, esc, Kind::Esc),
            };
            self.queue.set(i, kind, this.filter(|&n| n != at));
            self.queue.lower(i, other_kind, other);
        }
    }

    /// The reference of [`run_events_until`](Self::run_events_until): each slot's next
    /// times read on entry and, after it ran, for the slot that ran; the earliest picked by
    /// a pass over all slots, with the same tie-break.
    fn run_events_reference(&mut self, t: u64) {
        self.dirty.clear();
        for s in &mut self.slots {
            s.read_due();
        }
        loop {
            // (time, is a wakeup, slot)
            let mut best: Option<(u64, bool, usize)> = None;
            for (i, s) in self.slots.iter().enumerate() {
                if let Some(ne) = s.due.esc {
                    if ne <= t && ne > s.advanced && best.is_none_or(|b| (ne, false) < (b.0, b.1)) {
                        best = Some((ne, false, i));
                    }
                }
                if let Some(w) = s.due.wake {
                    if w <= t && best.is_none_or(|b| (w, true) < (b.0, b.1)) {
                        best = Some((w, true, i));
                    }
                }
            }
            let i = match best {
                Some((ne, false, i)) => {
                    self.advance_slot(i, ne);
                    i
                }
                Some((w, true, i)) => {
                    self.wake(i, w);
                    i
                }
                None => break,
            };
            self.slots[i].read_due();
        }
    }

    /// Runs node `i`'s wakeup at `w` (the ESC first brought to `w`, unless it is already
    /// past it).
    fn wake(&mut self, i: usize, w: u64) {
        self.advance_slot(i, w);
        let slot = &mut self.slots[i];
        slot.last_wake = Some(w);
        if let Some(node) = slot.node.as_mut() {
            node.on_wakeup(&mut slot.esc, w);
        }
        let t = w.max(self.done_to(i));
        self.check_irq(i, t);
    }

    /// Brings slot `i`'s ESC to `t` (to `now` at least) and delivers what that brought. A
    /// slot time has lazily passed is first brought to `now`, as the time reaching it
    /// would have (see [`advance_to`](Self::advance_to)).
    fn advance_slot(&mut self, i: usize, t: u64) {
        self.catch_up(i);
        self.advance_esc(i, t);
    }

    /// Brings slot `i`'s ESC to `t` and delivers what that brought (nothing when it is
    /// there already).
    fn advance_esc(&mut self, i: usize, t: u64) {
        let slot = &mut self.slots[i];
        if t <= slot.advanced {
            return;
        }
        slot.advanced = t;
        let ev = slot.esc.advance(t);
        if ev == AdvanceEvents::default() {
            // Nothing happened on the ESC (the common case between SYNC edges).
            self.check_irq(i, t);
            return;
        }
        let mut list: [(Option<u64>, EscEvent); 4] = [
            (ev.sync0, EscEvent::Sync0),
            (ev.sync1, EscEvent::Sync1),
            (ev.pd_watchdog_expired.then_some(t), EscEvent::PdWatchdog),
            (ev.pdi_watchdog_expired.then_some(t), EscEvent::PdiWatchdog),
        ];
        list.sort_by_key(|(t, _)| t.unwrap_or(u64::MAX));
        for (et, e) in list {
            if let Some(et) = et {
                match e {
                    EscEvent::Sync0 => self.slots[i].last_sync0 = Some(et),
                    EscEvent::Sync1 => self.slots[i].last_sync1 = Some(et),
                    _ => {}
                }
                self.deliver(i, e, et);
            }
        }
        self.check_irq(i, t);
    }

    fn deliver(&mut self, i: usize, ev: EscEvent, t: u64) {
        if let Some(log) = self.event_log.as_mut() {
            log.push(LoggedEvent {
                slave: i,
                event: ev,
                t,
            });
        }
        let slot = &mut self.slots[i];
        if let Some(node) = slot.node.as_mut() {
            // Every caller re-queues the slot after it (its next times may have moved).
            node.on_event(&mut slot.esc, ev, t);
        }
    }

    /// Delivers an IRQ if the line rose; returns whether it did. Skipped while the ESC's
    /// query epoch is the one `irq` was read at: the line cannot have moved since.
    #[inline]
    fn check_irq(&mut self, i: usize, t: u64) -> bool {
        let slot = &self.slots[i];
        let epoch = slot.esc.query_epoch();
        if epoch.is_some() && epoch == slot.irq_epoch {
            return false;
        }
        self.read_irq(i, t)
    }

    /// [`check_irq`](Self::check_irq) when the line may have moved.
    #[inline(never)]
    fn read_irq(&mut self, i: usize, t: u64) -> bool {
        let slot = &mut self.slots[i];
        let level = slot.esc.irq_line();
        let rising = level && !slot.irq;
        slot.irq = level;
        if rising {
            self.deliver(i, EscEvent::Irq, t);
            let slot = &mut self.slots[i];
            slot.irq = slot.esc.irq_line();
        }
        let slot = &mut self.slots[i];
        slot.irq_epoch = slot.esc.query_epoch();
        rising
    }

    // ---------------------------------------------------------------- frames

    /// Wire time of an Ethernet frame of `len` bytes (padded to 60, plus preamble, FCS, gap).
    pub fn wire_time_ns(len: usize) -> u64 {
        (len.max(ETH_MIN) as u64 + WIRE_OVERHEAD_BYTES) * BYTE_TIME_NS
    }

    /// Sends a whole Ethernet frame from the master at `now()` and returns the frame that
    /// comes back (with the U/L bit 0x02 set in the first source-MAC octet, as the first
    /// slave does), or `None` when it is lost, corrupted or not EtherCAT (see
    /// [`last_fate`](Self::last_fate)). Virtual time advances by the frame's trip.
    pub fn exchange(&mut self, frame: &[u8]) -> Option<Vec<u8>> {
        let mut buf = frame.to_vec();
        self.exchange_in_place(&mut buf).then_some(buf)
    }

    /// Like [`exchange`](Self::exchange) but processes `frame` in place; returns whether the
    /// frame came back (then `frame` holds the returned frame). A train of one
    /// ([`exchange_train`](Self::exchange_train)).
    pub fn exchange_in_place(&mut self, frame: &mut [u8]) -> bool {
        let mut fate = [FrameFate::Lost];
        self.exchange_train(&mut [frame], &mut fate, 0);
        fate[0] == FrameFate::Returned
    }

    /// Sends `frames` from the master back to back, as a NIC sends its queue: the first at
    /// `now()`, each next one when the last bit (and gap) of the one before has left, one
    /// wire time later, or `spacing_ns` after the one before left (the master's own time
    /// per frame) when that is later. They are on the line together, as on a real segment: every ESC
    /// meets them in that order, each at its own time, with the nodes' events between
    /// them at theirs (a train of frames takes its wire times plus one trip, not one trip
    /// per frame). `fates[k]` tells what became of frame k (the first `min(frames.len(),
    /// fates.len())` frames are sent); a returned frame is in place, as
    /// [`exchange_in_place`](Self::exchange_in_place) leaves it. Virtual time advances to
    /// the moment the last bit of the last frame to come back is at the master (of the last
    /// one sent, when that is later); [`last_fate`](Self::last_fate) is the last frame's.
    pub fn exchange_train<F: AsMut<[u8]>>(
        &mut self,
        frames: &mut [F],
        fates: &mut [FrameFate],
        spacing_ns: u64,
    ) {
        let n = frames.len().min(fates.len());
        let mut flights = core::mem::take(&mut self.flights);
        flights.clear();
        let t0 = self.now;
        // Records of a train of several frames wait until their times are all known, so
        // that the capture stays in time order (a reply can come before a later request).
        let mut records: Vec<(u64, Direction, Vec<u8>)> = Vec::new();
        let defer = n > 1 && self.capture.is_some();
        let mut line = t0;
        for frame in frames.iter_mut().take(n) {
            let frame = frame.as_mut();
            let Ok(eth) = EthernetHeader::parse(frame) else {
                self.stats.ignored += 1;
                flights.push(Flight::ignored(t0));
                continue;
            };
            let sent = line;
            let wire = Self::wire_time_ns(frame.len());
            line = sent + wire.max(spacing_ns);
            self.stats.sent += 1;
            if defer {
                records.push((sent, Direction::ToSegment, frame.to_vec()));
            } else if let Some(c) = self.capture.as_mut() {
                c.record(sent, Direction::ToSegment, frame);
            }
            let mut f = Flight {
                off: eth.payload_offset,
                sent,
                wire,
                hop: Hop {
                    at: (0, 0),
                    t: sent + self.master_link_delay_ns,
                    ok: true,
                    hops: 0,
                },
                dispatch: None,
                done: None,
            };
            if self.drop_next > 0 {
                self.drop_next -= 1;
                f.done = Some((FrameFate::DroppedByFault, sent));
            } else if self.slots.is_empty() || !self.master_link_up {
                f.done = Some((FrameFate::LostAtOpenPort(0, 0), sent));
            } else if self.dispatch_on && self.corruptions.is_empty() {
                // A corruption on the way changes the bytes (headers included) under the
                // index: such a frame takes the per-ESC walk.
                let mut d = self.dispatch_pool.pop().unwrap_or_default();
                if d.build(&mut frame[f.off..]) {
                    f.dispatch = Some(d);
                } else {
                    self.dispatch_pool.push(d);
                }
            }
            flights.push(f);
        }
        // Hop by hop, the frame that is earliest first (the one sent first on a tie: frames
        // on a line do not overtake each other).
        loop {
            let mut next: Option<usize> = None;
            for (k, f) in flights.iter().enumerate() {
                if f.done.is_none() && next.is_none_or(|j| f.hop.t < flights[j].hop.t) {
                    next = Some(k);
                }
            }
            let Some(k) = next else { break };
            let f = &mut flights[k];
            let ecat = &mut frames[k].as_mut()[f.off..];
            if let Some(done) = self.hop(ecat, &mut f.hop, f.dispatch.as_mut()) {
                f.done = Some(done);
                if let Some(mut d) = f.dispatch.take() {
                    d.apply_irq(ecat);
                    self.dispatch_pool.push(d);
                }
            }
        }
        let end = flights
            .iter()
            .filter_map(|f| f.done.map(|(_, t)| t.max(f.sent) + f.wire))
            .fold(t0, u64::max);
        self.advance_to(end);
        for (k, f) in flights.iter().enumerate() {
            let (fate, t_back) = f.done.unwrap_or((FrameFate::Lost, f.sent));
            fates[k] = fate;
            self.last_fate = Some(fate);
            match fate {
                FrameFate::Ignored => continue,
                FrameFate::Returned => {}
                _ => {
                    self.stats.lost += 1;
                    continue;
                }
            }
            self.stats.returned += 1;
            let frame = frames[k].as_mut();
            frame[6] |= 0x02;
            let t = t_back.max(f.sent) + f.wire;
            if defer {
                records.push((t, Direction::ToMaster, frame.to_vec()));
            } else if let Some(c) = self.capture.as_mut() {
                c.record(t, Direction::ToMaster, frame);
            }
        }
        if let Some(c) = self.capture.as_mut() {
            // Stable: a request before a reply of the same instant, each in its order.
            records.sort_by_key(|r| r.0);
            for (t, dir, bytes) in &records {
                c.record(*t, *dir, bytes);
            }
        }
        self.flights = flights;
    }

    /// Configured-address dispatch (on by default): each frame's datagram headers are
    /// indexed once and an FPRD/FPWR/FPRW datagram is processed only by the ESC(s) it
    /// addresses, the others adding their IRQ bits to it without walking it
    /// ([`oxicat_esc::FrameDispatch`]); without it every ESC walks every datagram, the
    /// reference the dispatch is tested against (same frames, working counters and
    /// registers). A frame meeting an injected corruption always takes the per-ESC walk.
    pub fn set_configured_dispatch(&mut self, on: bool) {
        self.dispatch_on = on;
    }

    /// Moves a frame (its EtherCAT part, from the header) one hop on: through the ESC port
    /// it is at, at its time, and the cable to the next. Returns its fate and the time its
    /// first bit is back at the master (or was lost) when its trip ended there; `d` is the
    /// frame's index, if any.
    #[inline(always)]
    fn hop(
        &mut self,
        ecat: &mut [u8],
        h: &mut Hop,
        d: Option<&mut oxicat_esc::FrameDispatch>,
    ) -> Option<(FrameFate, u64)> {
        if h.hops == MAX_HOPS {
            return Some((FrameFate::Lost, h.t));
        }
        h.hops += 1;
        if !self.corruptions.is_empty() {
            if let Some(k) = self
                .corruptions
                .iter()
                .position(|c| c.slave == h.at.0 && c.port == h.at.1)
            {
                let c = self.corruptions.remove(k);
                if !ecat.is_empty() {
                    let o = c.offset % ecat.len();
                    ecat[o] ^= 0xFF;
                }
                h.ok = false;
            }
        }
        let t = h.t;
        self.run_events_until(t);
        let (s, p) = h.at;
        let slot = &mut self.slots[s];
        // Keep the ESC's own timeline in step so its events come before the frame.
        let out = match d {
            Some(d) => slot.esc.forward_dispatched(p, ecat, t, h.ok, d),
            None => slot.esc.forward(p, ecat, t, h.ok),
        };
        // The ESC's IRQ line and the slot's queue entries, unless the ESC's query epoch
        // is the one the last hop here left: then neither its next event nor its IRQ
        // line can have changed since that hop re-queued the slot (every other change
        // to the slot's times re-queues it where it happens) and set `irq` to the
        // line's level (which every later `check_irq` sets to the same level), so both
        // would be no-ops. A frame that only passes an ESC leaves its epoch alone.
        let epoch = slot.esc.query_epoch();
        if epoch.is_none() || epoch != slot.hop_epoch {
            self.check_irq(s, t);
            // The frame (and the node, if it handled an interrupt) may have moved the
            // slot's next times.
            self.requeue(s);
            let slot = &mut self.slots[s];
            slot.hop_epoch = slot.esc.query_epoch();
        }
        let Some(out) = out else {
            return Some((FrameFate::DroppedByEsc(s), t));
        };
        let t = t + self.slots[s].delay_ns;
        if s == 0 && out == 0 {
            let t_back = t + self.master_link_delay_ns;
            return Some((
                if h.ok {
                    FrameFate::Returned
                } else {
                    FrameFate::Corrupted
                },
                t_back,
            ));
        }
        match self.slots[s].links.get(out as usize).copied().flatten() {
            Some(l) if l.up => {
                h.t = t + l.delay_ns;
                h.at = (l.peer, l.peer_port);
                None
            }
            _ => Some((FrameFate::LostAtOpenPort(s, out), t)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    /// A stand-in ESC: ET1100 port order, counts frames in byte 2 of the EtherCAT payload,
    /// SYNC0 every `period` ns from `start`.
    #[derive(Debug, Default)]
    struct Fake {
        links: [bool; 4],
        seen: Seen,
        period: u64,
        next: Option<u64>,
        irq: bool,
        /// The time of the last `advance` or frame (as given: an earlier time shows).
        clock: u64,
    }

    impl SegmentEsc for Fake {
        fn forward(&mut self, port: u8, frame: &mut [u8], t: u64, ok: bool) -> Option<u8> {
            // A frame brings the ESC to its time, as `oxicat_esc::Esc::forward` does.
            self.clock = t;
            self.seen.lock().unwrap().push((port, t, ok));
            if port == 0 && frame.len() > 2 {
                frame[2] = frame[2].wrapping_add(1);
            }
            // A marker in byte 3 reschedules the ESC's next SYNC edge and sets its IRQ
            // line, as a frame writing the DC start time or an SM does.
            if port == 0 && frame.len() > 3 && frame[3] != 0 && self.period > 0 {
                self.next = Some(t + u64::from(frame[3]) * 10);
                self.irq = frame[3].is_multiple_of(3);
            }
            let order = [0u8, 3, 1, 2];
            let i = order.iter().position(|&x| x == port).unwrap();
            for k in 1..=4 {
                let p = order[(i + k) % 4];
                if p == 0 || self.links[p as usize] {
                    return Some(p);
                }
            }
            Some(0)
        }
        fn set_link(&mut self, port: u8, up: bool) {
            self.links[port as usize] = up;
        }
        fn advance(&mut self, t: u64) -> AdvanceEvents {
            self.clock = t;
            let mut ev = AdvanceEvents::default();
            while let Some(n) = self.next {
                if n > t {
                    break;
                }
                ev.sync0 = Some(n);
                self.next = Some(n + self.period);
            }
            ev
        }
        fn next_event(&self) -> Option<u64> {
            self.next
        }
        fn irq_line(&self) -> bool {
            self.irq
        }
    }

    fn eth_frame() -> Vec<u8> {
        let mut f = vec![0xFF; 6];
        f.extend_from_slice(&[0x10; 6]);
        f.extend_from_slice(&[0x88, 0xA4]);
        f.extend_from_slice(&[0x0C, 0x10]); // header, len 12
        f.extend_from_slice(&[0; 12]);
        f.resize(60, 0);
        f
    }

    type Seen = Arc<Mutex<Vec<(u8, u64, bool)>>>;

    fn fakes(n: usize) -> (Vec<Fake>, Vec<Seen>) {
        let v: Vec<Fake> = (0..n).map(|_| Fake::default()).collect();
        let seen = v.iter().map(|f| f.seen.clone()).collect();
        (v, seen)
    }

    #[test]
    fn line_walk_order_times_and_mac_bit() {
        let (v, seen) = fakes(3);
        let mut seg = Segment::line(v);
        seg.set_link_delay(1, 1, 100).unwrap(); // cable 1-2
        let back = seg.exchange(&eth_frame()).unwrap();
        assert_eq!(back[6], 0x12);
        assert_eq!(back[16], 3, "each ESC processed it once");
        let l = DEFAULT_LINK_DELAY_NS;
        let d = DEFAULT_ESC_DELAY_NS;
        assert_eq!(
            *seen[0].lock().unwrap(),
            vec![
                (0, l, true),
                (1, l + d + l + d + 100 + d + 100 + d + l, true)
            ]
        );
        assert_eq!(
            *seen[1].lock().unwrap(),
            vec![
                (0, l + d + l, true),
                (1, l + d + l + d + 100 + d + 100, true)
            ]
        );
        assert_eq!(
            *seen[2].lock().unwrap(),
            vec![(0, l + d + l + d + 100, true)]
        );
        let t_back = l + d + l + d + 100 + d + 100 + d + l + d + l;
        assert_eq!(seg.now(), t_back + Segment::<Fake>::wire_time_ns(60));
        assert_eq!(seg.clock().now(), seg.now());
        assert_eq!(seg.last_fate(), Some(FrameFate::Returned));
    }

    #[test]
    fn branch_wiring_visits_port3_before_port1() {
        let (v, seen) = fakes(3);
        let mut seg = Segment::new();
        for f in v {
            seg.add_unwired(f);
        }
        seg.connect(0, 3, 1, 0).unwrap();
        seg.connect(0, 1, 2, 0).unwrap();
        assert_eq!(seg.connect(0, 1, 2, 1), Err(TopologyError::PortInUse(0, 1)));
        assert_eq!(seg.connect(0, 0, 2, 1), Err(TopologyError::PortInUse(0, 0)));
        assert!(seg.exchange(&eth_frame()).is_some());
        let s0: Vec<u8> = seen[0].lock().unwrap().iter().map(|x| x.0).collect();
        assert_eq!(s0, vec![0, 3, 1]);
        let t1 = seen[1].lock().unwrap()[0].1;
        let t2 = seen[2].lock().unwrap()[0].1;
        assert!(t1 < t2);
    }

    #[test]
    fn non_ethercat_is_ignored() {
        let (v, seen) = fakes(1);
        let mut seg = Segment::line(v);
        let mut f = eth_frame();
        f[12] = 0x08;
        f[13] = 0x00;
        assert!(seg.exchange(&f).is_none());
        assert_eq!(seg.last_fate(), Some(FrameFate::Ignored));
        assert!(seen[0].lock().unwrap().is_empty());
        assert_eq!(seg.now(), 0);
    }

    #[test]
    fn drop_next_frames() {
        let (v, seen) = fakes(2);
        let mut seg = Segment::line(v);
        seg.drop_next_frames(2);
        assert!(seg.exchange(&eth_frame()).is_none());
        assert!(seg.exchange(&eth_frame()).is_none());
        assert_eq!(seg.last_fate(), Some(FrameFate::DroppedByFault));
        assert!(seen[0].lock().unwrap().is_empty());
        assert!(seg.now() > 0, "time moves even for lost frames");
        assert!(seg.exchange(&eth_frame()).is_some());
        assert_eq!(seg.stats().lost, 2);
        assert_eq!(seg.stats().returned, 1);
    }

    #[test]
    fn corruption_marks_downstream_bad() {
        let (v, seen) = fakes(3);
        let mut seg = Segment::line(v);
        seg.corrupt_next_at(1, 0, 5).unwrap();
        let f = eth_frame();
        assert!(seg.exchange(&f).is_none());
        assert_eq!(seg.last_fate(), Some(FrameFate::Corrupted));
        let oks = |i: usize| -> Vec<bool> { seen[i].lock().unwrap().iter().map(|x| x.2).collect() };
        assert_eq!(oks(0), vec![true, false]);
        assert_eq!(oks(1), vec![false, false]);
        assert_eq!(oks(2), vec![false]);
        // Only the next frame is hit.
        assert!(seg.exchange(&f).is_some());
    }

    #[test]
    fn pulled_cable_closes_loop_and_replug_opens_it() {
        let (v, seen) = fakes(3);
        let mut seg = Segment::line(v);
        seg.set_cable(1, 1, false).unwrap();
        assert!(seg.exchange(&eth_frame()).is_some());
        assert!(
            seen[2].lock().unwrap().is_empty(),
            "slave 2 is behind the pulled cable"
        );
        assert_eq!(
            seen[1].lock().unwrap().len(),
            1,
            "slave 1 loops back at port 1"
        );
        seg.set_cable(2, 0, true).unwrap();
        assert!(seg.exchange(&eth_frame()).is_some());
        assert_eq!(seen[2].lock().unwrap().len(), 1);
        seg.set_cable(0, 0, false).unwrap();
        assert!(seg.exchange(&eth_frame()).is_none());
        assert_eq!(seg.last_fate(), Some(FrameFate::LostAtOpenPort(0, 0)));
    }

    /// A node that wakes every `period` ns from `start` (and sometimes raises its ESC's
    /// IRQ line) and logs what it saw, in the order it saw it.
    struct Ticker {
        id: usize,
        next: u64,
        period: u64,
        log: TickLog,
    }

    /// (node, time, what, the time its ESC was last advanced to) as a [`Ticker`] saw it.
    type TickLog = Arc<Mutex<Vec<(usize, u64, &'static str, u64)>>>;

    impl Node<Fake> for Ticker {
        fn on_event(&mut self, e: &mut Fake, ev: EscEvent, t: u64) {
            let what = match ev {
                EscEvent::Sync0 => "sync0",
                EscEvent::Irq => "irq",
                _ => "other",
            };
            self.log.lock().unwrap().push((self.id, t, what, e.clock));
            if ev == EscEvent::Irq {
                // The interrupt handler asks for an early wakeup.
                self.next = self.next.min(t + 37);
            }
        }
        fn next_wakeup(&self) -> Option<u64> {
            Some(self.next)
        }
        fn on_wakeup(&mut self, e: &mut Fake, t: u64) {
            self.log.lock().unwrap().push((self.id, t, "wake", e.clock));
            self.next = t + self.period;
            // Every third wakeup toggles the IRQ line (an event of its own on the rise).
            e.irq = (t / self.period).is_multiple_of(3);
            // Every fifth brings its ESC's next SYNC edge close (a PDI write of the DC start
            // time).
            if e.period > 0 && (t / self.period).is_multiple_of(5) {
                e.next = Some(t + 7);
            }
        }
    }

    /// The event queue delivers exactly what the reference scheduler (every slot read
    /// afresh at every pass, linear pick) delivers, in the same order — ties included: equal
    /// times across slots, ESC events and wakeups at the same time — with frames walking the
    /// line between advances, frames that reschedule an ESC's events and raise its IRQ (the
    /// node then asks for an early wakeup), wakeups that bring their ESC's next event close,
    /// PDI-side pokes through `esc_mut`, and nodes attached with a first wakeup already
    /// past. The reference also brings every slot to the time after each advance and
    /// frame, where the queue leaves a slot behind until it is touched; the nodes log the
    /// time their ESC was brought to. It fails when a slot is not re-queued after a frame
    /// passed it, after `esc_mut`, or after its node ran (either kind of entry), and when a
    /// slot left behind is not brought to the time before a late wakeup or `esc_mut`.
    /// Both layouts of the queue: 40 slots (heap) and 5 (arrays, see `sched::SMALL_SLOTS`).
    #[test]
    fn event_queue_delivers_what_the_reference_scheduler_delivers() {
        const { assert!(5 <= crate::sched::SMALL_SLOTS && 40 > crate::sched::SMALL_SLOTS) };
        let run = |reference: bool, seed: u64, n: usize| {
            let (mut v, seen) = fakes(n);
            for (i, f) in v.iter_mut().enumerate() {
                f.period = [1000, 700, 400, 1000, 250][i % 5];
                f.next = Some([0, 300, 1000, 50, 700][i % 5] + (i as u64 / 5) * 50);
            }
            let mut seg = Segment::line(v);
            seg.set_reference_scheduler(reference);
            seg.log_events(true);
            let log = Arc::new(Mutex::new(Vec::new()));
            for i in 0..n {
                seg.attach(
                    i,
                    Box::new(Ticker {
                        id: i,
                        next: 100 + (i as u64 % 7) * 100,
                        period: [500, 300, 1000, 250][i % 4],
                        log: log.clone(),
                    }),
                )
                .unwrap();
            }
            let mut x = seed;
            let mut rnd = move || {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x
            };
            let mut late = 0;
            for _ in 0..120 {
                match rnd() % 5 {
                    0 => {
                        // Now and then a step to the time it is (a poke's past event waits).
                        let dt = if rnd() % 4 == 0 { 0 } else { rnd() % 700 };
                        seg.advance_to(seg.now() + dt);
                    }
                    1 => {
                        // A PDI-side poke: the ESC's next SYNC edge moves, now and then to
                        // a time already passed (an event that is due at once); the poke logs
                        // the ESC's time.
                        let (k, dt) = ((rnd() % n as u64) as usize, rnd() % 900);
                        let now = seg.now();
                        let at = if dt % 3 == 0 {
                            now.saturating_sub(dt / 3)
                        } else {
                            now + 1 + dt
                        };
                        if let Some(e) = seg.esc_mut(k) {
                            e.next = Some(at);
                            log.lock().unwrap().push((k, now, "poke", e.clock));
                        }
                    }
                    2 => {
                        // A new node whose first wakeup has passed (it runs at once).
                        let k = (rnd() % n as u64) as usize;
                        let next = seg.now().saturating_sub(rnd() % 300);
                        late += 1;
                        seg.attach(
                            k,
                            Box::new(Ticker {
                                id: n + late,
                                next,
                                period: 450,
                                log: log.clone(),
                            }),
                        )
                        .unwrap();
                    }
                    _ => {
                        let mut f = eth_frame();
                        f[17] = if rnd() % 2 == 0 {
                            (rnd() % 60) as u8
                        } else {
                            0
                        };
                        assert!(seg.exchange(&f).is_some());
                    }
                }
            }
            let events: Vec<(usize, u64)> =
                seg.take_events().iter().map(|e| (e.slave, e.t)).collect();
            let nodes = log.lock().unwrap().clone();
            let frames: Vec<_> = seen.iter().map(|s| s.lock().unwrap().clone()).collect();
            (events, nodes, frames)
        };
        for (seed, n) in [0x9E37_79B9_7F4A_7C15, 0x2545_F491_4F6C_DD1D, 7]
            .into_iter()
            .flat_map(|seed| [(seed, 40), (seed, 5)])
        {
            let (q_ev, q_nodes, q_frames) = run(false, seed, n);
            let (r_ev, r_nodes, r_frames) = run(true, seed, n);
            assert!(
                q_ev.len() > 5 * n && q_nodes.len() > 25 * n,
                "{} {}",
                q_ev.len(),
                q_nodes.len()
            );
            assert!(q_nodes.iter().any(|e| e.2 == "irq"), "frames raised IRQs");
            assert_eq!(q_ev, r_ev);
            assert_eq!(q_nodes, r_nodes);
            assert_eq!(q_frames, r_frames);
        }
    }

    /// Events an ESC has at or before the time its slot is done (a PDI poke set them
    /// there) are delivered when time next moves, in slot order, whatever order the pokes
    /// came in — as the reference, which brings every slot to the time, delivers them.
    #[test]
    fn events_already_due_come_at_the_next_step_in_slot_order() {
        let run = |reference: bool| {
            let (mut v, _) = fakes(4);
            for f in &mut v {
                f.period = 1_000_000;
            }
            let mut seg = Segment::line(v);
            seg.set_reference_scheduler(reference);
            seg.log_events(true);
            seg.advance_to(5_000);
            for (k, at) in [(3, 4_000), (1, 4_500), (2, 5_000)] {
                seg.esc_mut(k).unwrap().next = Some(at);
            }
            // Not yet: time has not moved.
            seg.advance_to(5_000);
            let before = seg.take_events().len();
            assert!(seg.exchange(&eth_frame()).is_some());
            let after: Vec<(usize, u64)> =
                seg.take_events().iter().map(|e| (e.slave, e.t)).collect();
            (before, after)
        };
        let lazy = run(false);
        assert_eq!(lazy, run(true));
        assert_eq!(lazy, (0, vec![(1, 4_500), (2, 5_000), (3, 4_000)]));
    }

    #[test]
    fn events_in_time_order_across_escs() {
        let (mut v, _) = fakes(3);
        v[0].period = 1000;
        v[0].next = Some(1000);
        v[1].period = 700;
        v[1].next = Some(300);
        v[2].period = 5000;
        v[2].next = None;
        let mut seg = Segment::line(v);
        seg.log_events(true);
        let got = Arc::new(Mutex::new(Vec::new()));
        let g = got.clone();
        seg.attach(
            1,
            Box::new(move |_e: &mut Fake, ev: EscEvent, t: u64| g.lock().unwrap().push((ev, t))),
        )
        .unwrap();
        seg.advance_to(3000);
        let ev = seg.take_events();
        let times: Vec<(usize, u64)> = ev.iter().map(|e| (e.slave, e.t)).collect();
        assert_eq!(
            times,
            vec![
                (1, 300),
                (0, 1000),
                (1, 1000),
                (1, 1700),
                (0, 2000),
                (1, 2400),
                (0, 3000)
            ]
        );
        assert_eq!(
            *got.lock().unwrap(),
            vec![
                (EscEvent::Sync0, 300),
                (EscEvent::Sync0, 1000),
                (EscEvent::Sync0, 1700),
                (EscEvent::Sync0, 2400)
            ]
        );
        assert_eq!(seg.last_sync(0).0, Some(3000));
        assert_eq!(seg.now(), 3000);
        seg.advance_to(10);
        assert_eq!(seg.now(), 3000, "time never goes back");
    }

    #[test]
    fn capture_both_directions() {
        let (v, _) = fakes(1);
        let mut seg = Segment::line(v);
        let cap = crate::capture::MemoryCapture::new();
        seg.set_capture(Some(Box::new(cap.clone())));
        let f = eth_frame();
        seg.exchange(&f).unwrap();
        let c = cap.frames();
        assert_eq!(c.len(), 2);
        assert_eq!(c[0].dir, Direction::ToSegment);
        assert_eq!(c[0].t_ns, 0);
        assert_eq!(c[0].data, f);
        assert_eq!(c[1].dir, Direction::ToMaster);
        assert_eq!(c[1].t_ns, seg.now());
        assert_eq!(c[1].data[6], 0x12);
    }

    /// Frames of `lens` bytes, each a fake EtherCAT frame.
    fn frames_of(lens: &[usize]) -> Vec<Vec<u8>> {
        lens.iter()
            .map(|&n| {
                let mut f = eth_frame();
                f.resize(n, 0);
                f
            })
            .collect()
    }

    /// What one ESC saw: (port, time, frame intact) per frame.
    type Visits = Vec<(u8, u64, bool)>;

    /// What each ESC saw of one frame on its own, from a fresh line of `n`, and the time
    /// its first bit was back.
    fn single_trip(n: usize) -> (Vec<Visits>, u64) {
        let (v, seen) = fakes(n);
        let mut seg = Segment::line(v);
        seg.exchange(&eth_frame()).unwrap();
        let w = Segment::<Fake>::wire_time_ns(60);
        let lists = seen.iter().map(|s| s.lock().unwrap().clone()).collect();
        (lists, seg.now() - w)
    }

    #[test]
    fn a_train_is_on_the_line_together() {
        let (alone, t_back) = single_trip(3);
        let (v, seen) = fakes(3);
        let mut seg = Segment::line(v);
        let mut frames = frames_of(&[60, 300, 60]);
        let wire: Vec<u64> = frames
            .iter()
            .map(|f| Segment::<Fake>::wire_time_ns(f.len()))
            .collect();
        let sent = [0, wire[0], wire[0] + wire[1]];
        let mut fates = [FrameFate::Lost; 3];
        let mut refs: Vec<&mut [u8]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
        seg.exchange_train(&mut refs, &mut fates, 0);
        assert_eq!(fates, [FrameFate::Returned; 3]);
        for f in &frames {
            assert_eq!(f[6], 0x12);
            assert_eq!(f[16], 3, "each ESC processed each frame once");
        }
        // Every ESC met each frame where it meets a frame alone, shifted by the frame's
        // start, in time order: the frames overlap on the line.
        for (esc, got) in seen.iter().enumerate() {
            let mut want: Visits = sent
                .iter()
                .flat_map(|&s| alone[esc].iter().map(move |&(p, t, ok)| (p, t + s, ok)))
                .collect();
            want.sort_by_key(|e| e.1);
            assert_eq!(*got.lock().unwrap(), want, "ESC {esc}");
        }
        // Its last bit back at the master: the last frame's start, one trip, its wire time.
        assert_eq!(seg.now(), sent[2] + t_back + wire[2]);
        let serial: u64 = wire.iter().map(|w| t_back + w).sum();
        assert!(seg.now() < serial);
        assert_eq!(seg.stats().sent, 3);
        assert_eq!(seg.stats().returned, 3);
    }

    #[test]
    fn a_train_of_one_is_the_single_exchange() {
        let (alone, t_back) = single_trip(4);
        let (v, seen) = fakes(4);
        let mut seg = Segment::line(v);
        let mut f = eth_frame();
        let mut fates = [FrameFate::Lost];
        seg.exchange_train(&mut [f.as_mut_slice()], &mut fates, 0);
        assert_eq!(fates, [FrameFate::Returned]);
        assert_eq!(seg.now(), t_back + Segment::<Fake>::wire_time_ns(60));
        for (esc, got) in seen.iter().enumerate() {
            assert_eq!(*got.lock().unwrap(), alone[esc]);
        }
        assert_eq!(f[16], 4);
    }

    #[test]
    fn a_train_skips_what_is_not_ethercat_and_loses_what_is_dropped() {
        let (v, _) = fakes(2);
        let mut seg = Segment::line(v);
        let mut frames = frames_of(&[60, 60, 60]);
        frames[1][12] = 0x08; // IPv4: not EtherCAT
        frames[1][13] = 0x00;
        seg.drop_next_frames(1);
        let mut fates = [FrameFate::Lost; 3];
        let mut refs: Vec<&mut [u8]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
        seg.exchange_train(&mut refs, &mut fates, 0);
        assert_eq!(
            fates,
            [
                FrameFate::DroppedByFault,
                FrameFate::Ignored,
                FrameFate::Returned
            ]
        );
        let s = seg.stats();
        assert_eq!((s.sent, s.returned, s.lost, s.ignored), (2, 1, 1, 1));
        assert_eq!(seg.last_fate(), Some(FrameFate::Returned));
        // The dropped frame had the line for its wire time, the ignored one never did.
        let w = Segment::<Fake>::wire_time_ns(60);
        let (_, t_back) = single_trip(2);
        assert_eq!(seg.now(), w + t_back + w);
    }

    #[test]
    fn a_train_is_captured_in_time_order() {
        let (v, _) = fakes(8);
        let mut seg = Segment::line(v);
        let cap = crate::capture::MemoryCapture::new();
        seg.set_capture(Some(Box::new(cap.clone())));
        let mut frames = frames_of(&[60, 60, 60]);
        let sent_bytes = frames.clone();
        let mut fates = [FrameFate::Lost; 3];
        let mut refs: Vec<&mut [u8]> = frames.iter_mut().map(|f| f.as_mut_slice()).collect();
        seg.exchange_train(&mut refs, &mut fates, 0);
        let c = cap.frames();
        assert_eq!(c.len(), 6);
        assert!(
            c.windows(2).all(|w| w[0].t_ns <= w[1].t_ns),
            "in time order"
        );
        let to_seg: Vec<_> = c.iter().filter(|r| r.dir == Direction::ToSegment).collect();
        let back: Vec<_> = c.iter().filter(|r| r.dir == Direction::ToMaster).collect();
        assert_eq!(to_seg.len(), 3);
        for (r, f) in to_seg.iter().zip(&sent_bytes) {
            assert_eq!(&r.data, f, "as sent, before the ESCs changed it");
        }
        for (r, f) in back.iter().zip(&frames) {
            assert_eq!(&r.data, f);
        }
        assert_eq!(back[2].t_ns, seg.now());
        // Eight ESCs: the first reply is back after the second and third frames left.
        assert!(back[0].t_ns > to_seg[2].t_ns);
    }
}
