//! The Laelaps II rig on the virtual segment: the firmware host of `oxicat-sim`, one per
//! EtherCAT Control Tower, that runs the leg-node firmware (`crate::laelaps`) on the slave
//! stack behind its ESC **and** owns the leg it drives (`oxicat_plant::Leg`: amplifiers,
//! motors, gearheads, coupler, pulley, encoders, two links, treadmill belt).
//!
//! # What happens when, in virtual time
//!
//! | event | what runs |
//! |---|---|
//! | ESC SYNC0 | `Slave::on_sync0` → application cycle (trajectory clock, ellipse, IK) |
//! | ESC PDI IRQ | `Slave::on_pdi_irq` |
//! | tick, every 100 µs (10 kHz) | 1. the leg catches up to now, integrated in fixed substeps of `plant_period_ns` (default 50 µs: 20 kHz) with the PWM the firmware last wrote; 2. eQEP registers latched from the plant's encoders (position, direction, unit-event capture period) → `Slave::on_timer(JOINT_LOOP_TIMER)` (the two PIV loops) → PWM into the plant's amplifiers; 3. every `poll_every` ticks the main loop, `Slave::poll` (ESM, mailbox) |
//!
//! The plant is integrated at 20 kHz but only *observed* (encoders) and *driven* (PWM) at
//! the 10 kHz joint-loop instants, as on the real board, so it is stepped in one go per
//! tick: one segment wakeup per node per 100 µs. At equal times ESC events come first (the
//! segment's rule), then the tick in the fixed order above, so a run is a function of the
//! frames and their virtual times only.
//!
//! # The support rig holds the legs until the node starts
//!
//! ethercrab's bring-up waits in real time, so how much virtual time passes before OP
//! differs from run to run (and with it the phase of SYNC0 against virtual time zero). The
//! rig therefore holds each leg at its reset pose — the plant is not stepped — while the
//! node is in its Configuration state. At the first SYNC0 whose application cycle enters
//! the Operational state (`State_Machine = 1`), the rig lets go: from that SYNC0 time `T0`
//! on, plant ticks fall at `T0 + k·plant_period` and joint-loop ticks at
//! `T0 + 50 µs + k·100 µs` (half a plant period away from SYNC0, so SYNC0's DC jitter can
//! never reorder them). Everything the leg does afterwards depends only on `t − T0` and on
//! the outputs the node sees at each SYNC0. Joint-loop ticks before `T0` run with the leg
//! at rest (zero error, zero duty), which leaves the firmware in the same state however
//! many there were.
//!
//! # The whole robot (optional)
//!
//! With [`RigConfig::body`] the leg's hip is on a body the four rigs share
//! ([`BodyLink`], `crate::laelaps::robot`): the catch-up then runs
//! [`advance_on_body`], substep by substep, with the hip's motion of each 100 µs body step
//! (times since the release, which is the same SYNC0 for all four) and the impulse the leg
//! puts into its hip handed back. A body step waits for all four legs' impulses of two
//! steps before, so nothing depends on which node the segment wakes first.
//!
//! # Towers and legs
//!
//! Network order follows the towers (thesis §3.1): the chain starts at the tower by the
//! Hind Right leg and ends at the tower by the Fore Right leg ([`TOWER_CHAIN`]). Because
//! of the motor mounting each tower drives the leg **on the opposite side**
//! ([`LegId::driven_by_tower_at`]): the tower by Hind Right drives Hind Left, with the
//! `LEFT_LEG` build. Both the firmware build and the plant's mirrored motors follow the
//! driven leg, never the tower's location.
//!
//! # How the firmware reaches its ESC
//!
//! [`attach_leg`] gives the firmware the software ESC as its `Pdi`; [`attach_leg_routed`]
//! can put a LAN9252 or ET1100 driver over the simulated SPI in between
//! ([`oxicat_sim::pdi_path`]), with the node's SPI traffic counted ([`LegRig::bus_stats`]).
//!
//! # Execution time (opt-in)
//!
//! With [`RigConfig::timing`] set, the node runs under the execution-time model of
//! [`oxicat_sim::exec_time`]: the SYNC0 handler takes its SPI bus time (+ CPU time), its writes
//! (the inputs in SM3) land when it ends, and an interrupt arriving while the MCU is busy
//! waits or is lost ([`LegRig::timing`]). The joint-loop tick is a timer interrupt: it
//! waits for a running interrupt handler and then runs (plant catch-up, encoders, PIV,
//! PWM) at the time it actually runs; the main loop is a thread-level pass interrupts
//! preempt. The release instant `T0` is the SYNC0 edge. Off (the default), everything
//! above holds unchanged.

use crate::demo::Leds;
use crate::laelaps::{
    self, device, CaptureConfig, ControlLaw, EncoderIn, Joint, LegNode, Mode, PwmCommand, PwmOut,
    QepSample, Side, JOINT_LOOP_TIMER,
};
use oxicat_esc::Esc;
use oxicat_plant::{Body, Leg, LegParams, Treadmill};
use oxicat_slave::{Pdi, Slave};
use std::sync::{Arc, Mutex};

use oxicat_sim::exec_time::{ExecTiming, TimingStats};
use oxicat_sim::firmware::{
    attach_host, boot_stack, Bench, FirmwareConfig, Host, HostHandle, Stack,
};
use oxicat_sim::node::EscEvent;
use oxicat_sim::pdi_path::{BusStats, Direct, PathInitError, PdiPath, PdiRoute, SpiPath};
use oxicat_sim::segment::{Segment, SlaveId};

/// Mailbox size of the leg node (its device definition: 128 bytes).
pub const MBX: usize = 128;
/// The leg node's stack type on a software ESC.
pub type LegSlave = Slave<Esc, { device::IMAGE }, MBX>;
/// The leg-node application wired to the rig.
pub type LegApp = LegNode<PwmLatch, QepRegisters, NoLeds>;

/// Joint-loop period: 10 kHz, the thesis' control loop (`hw::CONTROL_PERIOD_S`).
pub const JOINT_LOOP_NS: u64 = 100_000;
/// Offset of the joint-loop ticks after the release SYNC0.
pub const JOINT_LOOP_PHASE_NS: u64 = 50_000;

/// A leg of Laelaps II.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LegId {
    /// Fore Left.
    ForeLeft,
    /// Fore Right.
    ForeRight,
    /// Hind Left.
    HindLeft,
    /// Hind Right.
    HindRight,
}

/// Tower locations in network order: Hind Right first, Fore Right last (thesis §3.1).
pub const TOWER_CHAIN: [LegId; 4] = [
    LegId::HindRight,
    LegId::HindLeft,
    LegId::ForeLeft,
    LegId::ForeRight,
];

impl LegId {
    /// All legs in the order of the thesis' Table 4-1 (FL, FR, HL, HR).
    pub const TABLE: [LegId; 4] = [
        LegId::ForeLeft,
        LegId::ForeRight,
        LegId::HindLeft,
        LegId::HindRight,
    ];

    /// The thesis' prefix: `FL`, `FR`, `HL`, `HR`.
    pub const fn code(self) -> &'static str {
        match self {
            LegId::ForeLeft => "FL",
            LegId::ForeRight => "FR",
            LegId::HindLeft => "HL",
            LegId::HindRight => "HR",
        }
    }

    /// Parses `FL`/`FR`/`HL`/`HR` (any case).
    pub fn parse(s: &str) -> Option<Self> {
        LegId::TABLE
            .into_iter()
            .find(|l| l.code().eq_ignore_ascii_case(s))
    }

    /// The firmware build / mirrored-motor side of this leg.
    pub const fn side(self) -> Side {
        match self {
            LegId::ForeLeft | LegId::HindLeft => Side::Left,
            LegId::ForeRight | LegId::HindRight => Side::Right,
        }
    }

    /// The plant's side of this leg.
    pub const fn plant_side(self) -> oxicat_plant::Side {
        match self.side() {
            Side::Left => oxicat_plant::Side::Left,
            Side::Right => oxicat_plant::Side::Right,
        }
    }

    /// The leg on the other side at the same end.
    pub const fn opposite(self) -> Self {
        match self {
            LegId::ForeLeft => LegId::ForeRight,
            LegId::ForeRight => LegId::ForeLeft,
            LegId::HindLeft => LegId::HindRight,
            LegId::HindRight => LegId::HindLeft,
        }
    }

    /// The leg the tower next to `tower` drives: the opposite one (thesis §3.1).
    pub const fn driven_by_tower_at(tower: LegId) -> Self {
        tower.opposite()
    }
}

/// The driven legs in network order (HL, HR, FR, FL).
pub fn chain_legs() -> [LegId; 4] {
    TOWER_CHAIN.map(LegId::driven_by_tower_at)
}

/// Belt speed as a piecewise-linear function of the time since the rig released the leg.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BeltProfile {
    /// `(time since release [s], belt speed [m/s])`, times increasing; constant outside.
    pub points: Vec<(f64, f64)>,
}

impl BeltProfile {
    /// The belt speed at `t` seconds after release.
    pub fn at(&self, t: f64) -> f64 {
        let p = &self.points;
        match p.len() {
            0 => 0.0,
            _ if t <= p[0].0 => p[0].1,
            _ => {
                for w in p.windows(2) {
                    let ((t0, v0), (t1, v1)) = (w[0], w[1]);
                    if t <= t1 {
                        return if t1 > t0 {
                            v0 + (v1 - v0) * (t - t0) / (t1 - t0)
                        } else {
                            v1
                        };
                    }
                }
                p[p.len() - 1].1
            }
        }
    }
}

/// How one leg and its rig are set up.
#[derive(Debug, Clone, PartialEq)]
pub struct RigConfig {
    /// The leg's physics (side, links, drives, contact, belt height).
    pub leg: LegParams,
    /// Plant integration substep \[ns\] (≤ 100 µs; default 50 µs = 20 kHz).
    pub plant_period_ns: u64,
    /// The main loop runs every `poll_every` joint-loop ticks (≥ 1).
    pub poll_every: u64,
    /// Belt speed after release.
    pub belt: BeltProfile,
    /// The execution-time model ([`oxicat_sim::exec_time`]); `None` (the default): the firmware
    /// runs in zero virtual time.
    pub timing: Option<ExecTiming>,
    /// The joint control law the firmware is built with (default: the thesis' PIV).
    pub law: ControlLaw,
    /// The body this leg's hip is on (`None`, the default: the hip is fixed, the leg alone).
    pub body: Option<BodyLink>,
}

/// A leg's place on the shared body ([`oxicat_plant::body`]): the four rigs of a trot hold
/// the same body, each with its own leg index (Table 4-1 order, FL FR HL HR).
#[derive(Clone)]
pub struct BodyLink {
    /// The body, shared by the legs' rigs.
    pub body: Arc<Mutex<Body>>,
    /// This leg's index on the body.
    pub leg: usize,
}

impl BodyLink {
    /// The body, locked (a poisoned lock still gives the body: it holds plain numbers).
    pub fn lock(&self) -> std::sync::MutexGuard<'_, Body> {
        self.body.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl PartialEq for BodyLink {
    fn eq(&self, o: &Self) -> bool {
        Arc::ptr_eq(&self.body, &o.body) && self.leg == o.leg
    }
}

impl std::fmt::Debug for BodyLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BodyLink").field("leg", &self.leg).finish()
    }
}

impl RigConfig {
    /// The thesis' leg for `leg`, encoders set up as the firmware's eQEP capture unit
    /// (`2^UPPS` edges per unit event), 20 kHz plant, main loop every 400 µs, belt at rest.
    pub fn laelaps(leg: LegId) -> Self {
        let mut p = LegParams::laelaps(leg.plant_side());
        p.encoder_unit_prescaler = 1 << CaptureConfig::THESIS.upps;
        Self {
            leg: p,
            plant_period_ns: 50_000,
            poll_every: 4,
            belt: BeltProfile::default(),
            timing: None,
            law: ControlLaw::Piv,
            body: None,
        }
    }

    /// Turns the execution-time model on (builder style).
    pub fn timing(mut self, timing: ExecTiming) -> Self {
        self.timing = Some(timing);
        self
    }

    /// Sets the belt surface depth below the hip axis \[m\] (builder style).
    pub fn belt_depth(mut self, depth_m: f64) -> Self {
        self.leg.treadmill = Treadmill {
            height: depth_m,
            ..self.leg.treadmill
        };
        self
    }
}

/// The amplifier inputs the firmware last wrote (ePWM + DIR pins), per joint.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PwmLatch {
    /// Hip command.
    pub hip: PwmCommand,
    /// Knee command.
    pub knee: PwmCommand,
}

impl PwmOut for PwmLatch {
    fn set(&mut self, joint: Joint, cmd: PwmCommand) {
        match joint {
            Joint::Hip => self.hip = cmd,
            Joint::Knee => self.knee = cmd,
        }
    }
}

/// The eQEP registers as the rig last latched them from the plant's encoders; a read
/// clears the event flags, as the firmware's write-1-to-clear does.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct QepRegisters {
    /// Hip eQEP.
    pub hip: QepSample,
    /// Knee eQEP.
    pub knee: QepSample,
}

impl EncoderIn for QepRegisters {
    fn sample(&mut self, joint: Joint) -> QepSample {
        let r = match joint {
            Joint::Hip => &mut self.hip,
            Joint::Knee => &mut self.knee,
        };
        let s = *r;
        r.unit_event = false;
        r.capture_overflow = false;
        r.direction_change = false;
        s
    }
}

/// The LaunchPad LEDs (not modelled: remembered only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NoLeds {
    /// Blue, red.
    pub state: (bool, bool),
}

impl Leds for NoLeds {
    fn set(&mut self, blue: bool, red: bool) {
        self.state = (blue, red);
    }
}

/// The leg-node image: the stack and the leg-node application on the firmware's `Pdi`.
pub type LegImage<Pd> = Stack<Pd, LegApp, { device::IMAGE }, MBX>;

/// The leg a tower drives, as the firmware host's plant: before each joint-loop tick it
/// catches up to now (once released) and latches the eQEP registers from the encoders;
/// after the tick the amplifiers take the PWM; around SYNC0 it watches for the cycle that
/// enters Operational and releases the leg there (see the module documentation).
pub struct LegPlant {
    /// The leg this tower drives.
    pub leg_id: LegId,
    /// The leg.
    pub plant: Leg,
    /// SYNC0 time at which the rig released the leg (`T0`), if it has.
    pub released_at: Option<u64>,
    /// SYNC0 count (since boot) of the release.
    pub released_at_sync0: Option<u64>,
    /// Plant ticks so far.
    pub plant_ticks: u64,
    config: RigConfig,
    /// SYNC0s seen so far.
    sync0: u64,
    /// The application's mode before the running SYNC0 handler.
    mode_before: Mode,
    /// Virtual time the plant has advanced since the release \[ns\].
    plant_ns: u64,
}

impl LegPlant {
    /// The rig's configuration.
    pub fn config(&self) -> &RigConfig {
        &self.config
    }

    /// The plant catches up to `t` (in substeps of the plant period) if released.
    fn catch_up(&mut self, t: u64) {
        if let Some(t0) = self.released_at {
            let since = t - t0;
            if since > self.plant_ns {
                let belt = self.config.belt.at(self.plant_ns as f64 * 1e-9);
                if belt != self.plant.params().treadmill.speed {
                    self.plant.set_belt_speed(belt);
                }
                match &self.config.body {
                    None => self.plant.advance((since - self.plant_ns) as f64 * 1e-9),
                    Some(link) => advance_on_body(
                        &mut self.plant,
                        &mut link.lock(),
                        link.leg,
                        self.plant_ns,
                        since,
                    ),
                }
                self.plant_ticks += (since - self.plant_ns).div_ceil(self.config.plant_period_ns);
                self.plant_ns = since;
            }
        }
    }

    /// The body the leg is on, if any.
    pub fn body(&self) -> Option<&BodyLink> {
        self.config.body.as_ref()
    }

    fn sample_encoders(&mut self, app: &mut LegApp) {
        let tick = CaptureConfig::THESIS.tick_s() as f64;
        for (pj, fj) in [
            (oxicat_plant::Joint::Hip, Joint::Hip),
            (oxicat_plant::Joint::Knee, Joint::Knee),
        ] {
            let enc = self.plant.encoder_mut(pj);
            let mut s = QepSample {
                position: enc.count() as u32,
                forward: enc.forward(),
                ..QepSample::default()
            };
            if let Some(c) = enc.take_capture() {
                s.unit_event = true;
                s.direction_change = c.direction_changed;
                let ticks = (c.period / tick).round();
                if ticks > 65535.0 {
                    s.capture_overflow = true;
                    s.capture_period = 0xFFFF;
                } else {
                    s.capture_period = ticks.max(0.0) as u16;
                }
            }
            // Flags accumulate until the firmware reads them.
            let r = match fj {
                Joint::Hip => &mut app.encoders.hip,
                Joint::Knee => &mut app.encoders.knee,
            };
            let keep = *r;
            *r = s;
            if !s.unit_event && keep.unit_event {
                r.unit_event = true;
                r.capture_period = keep.capture_period;
                r.capture_overflow = keep.capture_overflow;
                r.direction_change = keep.direction_change;
            }
        }
    }

    fn apply_pwm(&mut self, app: &LegApp) {
        let p = app.pwm;
        self.plant
            .set_duty(oxicat_plant::Joint::Hip, p.hip.duty as f64, p.hip.reverse);
        self.plant.set_duty(
            oxicat_plant::Joint::Knee,
            p.knee.duty as f64,
            p.knee.reverse,
        );
    }
}

/// Advances `leg` (index `index` on `body`) from its time `from_ns` to `to_ns` in the
/// substeps `Leg::advance` would take, each with its hip's motion of the body step it
/// starts in, handing the body the impulse it put into the hip (see
/// [`oxicat_plant::body`]).
pub fn advance_on_body(leg: &mut Leg, body: &mut Body, index: usize, from_ns: u64, to_ns: u64) {
    let span_ns = to_ns - from_ns;
    let dt = span_ns as f64 * 1e-9;
    let n = leg.substep_count(dt);
    let h = dt / n as f64;
    // The momentum after a substep is the next one's before: the hip's motion, set in
    // between, does not enter it.
    let mut p0 = leg.vertical_momentum();
    // What `leg.advance(h)` would split `h` into, the same at every substep.
    let inner = leg.split(h);
    for k in 0..n {
        // The first substep starts at `from_ns` (`span_ns * 0 / n`, without the division).
        let at = if k == 0 { 0 } else { span_ns * k / n };
        let j = body.step_of(from_ns + at);
        leg.set_hip_motion(body.hip_motion(index, j));
        leg.run_split(inner);
        let p1 = leg.vertical_momentum();
        let impulse = h * leg.contact_force()[1] - (p1 - p0);
        body.add_impulse(index, j, impulse);
        p0 = p1;
    }
    body.reached(index, to_ns);
}

impl<Pd: Pdi> Bench<LegImage<Pd>> for LegPlant {
    fn before_timers(&mut self, image: &mut LegImage<Pd>, t: u64) {
        self.catch_up(t);
        self.sample_encoders(&mut image.app);
    }

    fn after_timers(&mut self, image: &mut LegImage<Pd>, _t: u64) {
        if self.released_at.is_some() {
            self.apply_pwm(&image.app);
        }
    }

    fn before_event(&mut self, image: &mut LegImage<Pd>, ev: EscEvent, _t: u64) {
        if ev == EscEvent::Sync0 {
            self.sync0 += 1;
            self.mode_before = image.app.mode();
        }
    }

    /// Lets the leg go at the SYNC0 edge `t` if this SYNC0's cycle entered Operational;
    /// the joint loop re-phases to `t` + [`JOINT_LOOP_PHASE_NS`].
    fn after_event(&mut self, image: &mut LegImage<Pd>, ev: EscEvent, t: u64) -> Option<u64> {
        if ev == EscEvent::Sync0
            && self.released_at.is_none()
            && self.mode_before == Mode::Configuration
            && image.app.mode() == Mode::Operational
        {
            self.released_at = Some(t);
            self.released_at_sync0 = Some(self.sync0);
            self.plant_ns = 0;
            return Some(t + JOINT_LOOP_PHASE_NS);
        }
        None
    }
}

/// Counters of one rig node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RigCounters {
    /// SYNC0 interrupts.
    pub sync0: u64,
    /// SYNC1 interrupts (the thesis' DC split latches the inputs on them).
    pub sync1: u64,
    /// Joint-loop ticks.
    pub joint_loops: u64,
    /// Plant ticks.
    pub plant_ticks: u64,
    /// Main-loop passes.
    pub polls: u64,
    /// PDI accesses the ESC refused.
    pub pdi_errors: u64,
}

/// One tower on its firmware host: the leg-node image (`image`, or through `Deref` its
/// `slave` and `app`) and the leg it drives (`bench`); `P` is how the firmware reaches its
/// ESC ([`Direct`]: the software ESC is its `Pdi`).
pub type LegRig<P = Direct> = Host<LegImage<<P as PdiPath>::Pdi>, P, LegPlant>;

/// What a tool reports about a node.
pub fn report<P: PdiPath>(rig: &LegRig<P>) -> LegReport {
    let c = rig.counters;
    LegReport {
        leg_id: rig.bench.leg_id,
        clock_ns: rig.app.clock().nanos(),
        released_at_sync0: rig.bench.released_at_sync0,
        counters: RigCounters {
            sync0: c.sync0,
            sync1: c.sync1,
            joint_loops: c.timers,
            plant_ticks: rig.bench.plant_ticks,
            polls: c.polls,
            pdi_errors: c.pdi_errors,
        },
        bus: rig.bus_stats(),
        timing: rig.timing(),
        sync_mode: rig.slave.od().get::<u16>(0x1C33, 1).ok(),
        input_shift_ns: rig.slave.od().get::<u32>(0x1C33, 3).ok(),
    }
}

/// A snapshot of one rig node (any path).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LegReport {
    /// The leg the tower drives.
    pub leg_id: LegId,
    /// The firmware's trajectory clock \[ns\].
    pub clock_ns: u64,
    /// SYNC0 count of the release, if released.
    pub released_at_sync0: Option<u64>,
    /// What ran so far (PDI errors included).
    pub counters: RigCounters,
    /// The SPI bus since the last reset (`None` on the direct path).
    pub bus: Option<BusStats>,
    /// The execution-time model's figures (`None` when it is off).
    pub timing: Option<TimingStats>,
    /// Input sync mode in its dictionary, 0x1C33:01 (2 DC SYNC0, 3 DC SYNC1).
    pub sync_mode: Option<u16>,
    /// Shift of the input latch after SYNC0 in its dictionary, 0x1C33:03 \[ns\].
    pub input_shift_ns: Option<u32>,
}

/// Access to a rig node from outside the segment (tests, tools).
pub type LegRigHandle<P = Direct> = HostHandle<LegImage<<P as PdiPath>::Pdi>, P, LegPlant>;

/// A rig node's handle whatever its path ([`attach_leg_routed`]).
#[derive(Clone)]
pub enum AnyLegRigHandle {
    /// The software ESC is the firmware's `Pdi`.
    Direct(LegRigHandle),
    /// A chip driver over the simulated SPI.
    Spi(LegRigHandle<SpiPath>),
}

impl AnyLegRigHandle {
    /// A snapshot of the node.
    pub fn report(&self) -> LegReport {
        match self {
            Self::Direct(h) => report(&h.lock()),
            Self::Spi(h) => report(&h.lock()),
        }
    }

    /// Clears the node's bus counters.
    pub fn reset_bus_stats(&self) {
        match self {
            Self::Direct(h) => h.lock().reset_bus_stats(),
            Self::Spi(h) => h.lock().reset_bus_stats(),
        }
    }
}

/// Why a tower could not be put on the segment: the same reasons as for any hosted
/// firmware.
pub type RigError = oxicat_sim::firmware::AttachError;

/// Boots the leg-node firmware for `leg` (its side's build) on ESC `id` and attaches it with
/// the leg's plant; the leg is held at its reset pose (encoders zeroed there) until the node
/// goes Operational.
pub fn attach_leg(
    segment: &mut Segment,
    id: SlaveId,
    leg: LegId,
    config: RigConfig,
) -> Result<LegRigHandle, RigError> {
    attach_leg_with(segment, id, leg, config, |_| Ok(Direct))
}

/// [`attach_leg`] with the firmware reaching its ESC the way `route` says: directly, or
/// through the LAN9252 / ET1100 driver over the simulated SPI (the driver starts first, as
/// on hardware). For a LAN9252 the ESC should be [`oxicat_esc::EscConfig::lan9252`]
/// ([`PdiRoute::esc_config`]).
pub fn attach_leg_routed(
    segment: &mut Segment,
    id: SlaveId,
    leg: LegId,
    config: RigConfig,
    route: PdiRoute,
) -> Result<AnyLegRigHandle, RigError> {
    Ok(match route {
        PdiRoute::Direct => AnyLegRigHandle::Direct(attach_leg(segment, id, leg, config)?),
        _ => AnyLegRigHandle::Spi(attach_leg_with(segment, id, leg, config, |esc| {
            SpiPath::new(route, esc)
        })?),
    })
}

/// [`attach_leg`] on any [`PdiPath`]: `path` builds it in front of the ESC.
pub fn attach_leg_with<P: PdiPath>(
    segment: &mut Segment,
    id: SlaveId,
    leg: LegId,
    config: RigConfig,
    path: impl FnOnce(&mut Esc) -> Result<P, PathInitError>,
) -> Result<LegRigHandle<P>, RigError> {
    let def = device::device(leg.side());
    let mut params = config.leg;
    params.substep = config.plant_period_ns.clamp(1_000, 100_000) as f64 * 1e-9;
    let mut schedule = FirmwareConfig::default().timer(JOINT_LOOP_TIMER, JOINT_LOOP_NS);
    schedule.poll_after_timer_instants = Some(config.poll_every);
    schedule.timing = config.timing;
    let law = config.law;
    let plant = LegPlant {
        leg_id: leg,
        plant: Leg::new(params),
        released_at: None,
        released_at_sync0: None,
        plant_ticks: 0,
        config,
        sync0: 0,
        mode_before: Mode::Configuration,
        plant_ns: 0,
    };
    let app = laelaps::LegNode::new(
        leg.side(),
        PwmLatch::default(),
        QepRegisters::default(),
        NoLeds::default(),
    )
    .with_law(law);
    attach_host(segment, id, &schedule, plant, path, |esc, path| {
        boot_stack(def, esc, app, path)
    })
}

/// The Laelaps II leg node in the registry.
pub const KIT: crate::registry::Kit = crate::registry::Kit {
    name: "laelaps-leg",
    description: "Laelaps II leg node (F28379D + FB1111) driving its leg on the treadmill \
                  (motors, gears, coupler, encoders); nodes in tower order HR HL FL FR, \
                  each driving the opposite leg",
    def: |k| crate::laelaps::device::device(kit_leg(k).side()),
    esc: oxicat_esc::EscConfig::et1100,
    attach: kit_attach,
    sync: oxicat_slave::SyncMode::DcSync0,
    cycle_ns: 400_000,
};

/// The leg driven by registry node `k` (the thesis' chain order, repeating).
fn kit_leg(k: usize) -> LegId {
    chain_legs()[k % 4]
}

fn kit_attach(
    segment: &mut Segment,
    id: SlaveId,
    k: usize,
    route: PdiRoute,
) -> Result<(), RigError> {
    let leg = kit_leg(k);
    attach_leg_routed(segment, id, leg, RigConfig::laelaps(leg), route).map(drop)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn towers_drive_the_opposite_leg() {
        assert_eq!(TOWER_CHAIN[0], LegId::HindRight);
        assert_eq!(TOWER_CHAIN[3], LegId::ForeRight);
        let legs = chain_legs();
        assert_eq!(
            legs,
            [
                LegId::HindLeft,
                LegId::HindRight,
                LegId::ForeRight,
                LegId::ForeLeft
            ]
        );
        assert_eq!(LegId::HindLeft.side(), Side::Left);
        assert_eq!(LegId::ForeRight.side(), Side::Right);
    }

    #[test]
    fn belt_profile_is_piecewise_linear() {
        let b = BeltProfile {
            points: vec![(1.0, 0.0), (3.0, 0.2), (5.0, 0.2), (6.0, 0.0)],
        };
        assert_eq!(b.at(0.0), 0.0);
        assert!((b.at(2.0) - 0.1).abs() < 1e-12);
        assert_eq!(b.at(4.0), 0.2);
        assert!((b.at(5.5) - 0.1).abs() < 1e-12);
        assert_eq!(b.at(9.0), 0.0);
    }

    #[test]
    fn qep_read_clears_flags() {
        let mut q = QepRegisters::default();
        q.knee.unit_event = true;
        q.knee.capture_period = 100;
        assert!(q.sample(Joint::Knee).unit_event);
        assert!(!q.sample(Joint::Knee).unit_event);
    }
}
