//! The Laelaps II trotting experiment (thesis §4, Table 4-1) on the virtual segment:
//! four leg nodes (`crate::laelaps::rig`) in the thesis' chain order, ethercrab in this
//! process and on this thread, DC SYNC0 every 400 µs, the thesis' procedure, and every
//! input variable recorded every cycle.
//!
//! # Procedure, in master cycles
//!
//! 1. Bring-up (ethercrab: discovery, sync type DC via 0x1C32:01, DC configuration,
//!    SAFE-OP, OP). Its length in virtual time varies from run to run — ethercrab waits in
//!    real time — and nothing after it depends on it.
//! 2. Settle: `State_Machine = 0`, every Table 4-1 parameter written with a = b = 0, for
//!    `settle_s` (≥ `Transition_time`, so the gain transitions are complete). The rig holds
//!    the legs at their reset pose.
//! 3. Cycle 0 of the record: the one linked `State_Machine` variable is set to 1 in all four
//!    nodes' outputs in the same frame. Each node enters Operational at the same SYNC0, the
//!    rig lets its leg go there (see `crate::laelaps::rig`), and its trajectory clock
//!    starts. From here on every cycle is recorded.
//! 4. Stand (`stand_s`), b ramps to its value, then a (each over `Transition_time`, done by
//!    the firmware's linear transitions), steady trot (`trot_s`), a back to 0, b back to 0,
//!    stand, `State_Machine = 0`, `stop_s` more.
//!
//! Each leg node's firmware reaches its ESC directly (the software ESC is its `Pdi`) or, with
//! the scenario's `[pdi] route` (`oxicat trot --pdi`), through the LAN9252 or ET1100 driver
//! over the simulated SPI ([`oxicat_sim::pdi_path`]); [`TrotRun::pdi`] then holds each node's
//! SPI traffic over the recorded cycles. The firmware runs in zero virtual time either way,
//! so the CSV does not depend on the route.
//!
//! With `[pdi] exec_time` (`oxicat trot --bus-time`) the leg nodes run under the
//! execution-time model ([`oxicat_sim::exec_time`]): a handler keeps the MCU busy for its
//! SPI bus time + CPU time and its writes (the inputs in SM3) land at its end, and the
//! joint-loop timer waits for a running interrupt handler. [`NodePdi::timing`] then holds
//! what the model saw per node (SYNC0 busy and response times, delayed and lost events,
//! whole run: bring-up included).
//!
//! The recorded data depend only on the scenario: the master's outputs are a function of
//! the cycle number since step 3, each leg's physics of the time since its release, and no
//! wall-clock time, hash order or platform formatting enters the CSV.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::laelaps::device;
use crate::laelaps::rig::{
    attach_leg_routed, chain_legs, AnyLegRigHandle, BeltProfile, LegId, RigConfig, TOWER_CHAIN,
};
use ethercrab::subdevice_group::DcConfiguration;
use ethercrab::{DcSync, MainDevice, MainDeviceConfig, PduStorage};
use oxicat_esc::{Esc, EscConfig};
use oxicat_master::inprocess::{inprocess_task, InProcessConfig};
use oxicat_plant::{Body, BodyStats};
use oxicat_sim::exec_time::TimingStats;
use oxicat_sim::pdi_path::{BusStats as SpiStats, PdiRoute};
use oxicat_sim::segment::Segment;
use oxicat_slave::DeviceDef;

use crate::laelaps::scenario::Scenario;
use oxicat_master::MasterError;

type Storage = PduStorage<16, { PduStorage::element_size(1100) }>;
const MAX_SUBDEVICES: usize = 8;
const PDI_LEN: usize = 512;
/// Expected LRW working counter: every node's outputs written and inputs read (3 each).
pub const EXPECTED_WKC: u16 = 3 * 4;

/// Where a variable lives in a slave's process image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PdoPlace {
    /// Bit offset from the start of the slave's outputs or inputs.
    pub bit: usize,
    /// Bit length.
    pub bits: u8,
}

/// Finds `(index, sub)` in a PDO assignment of `def` (rx: outputs, else inputs) — the
/// layout a master derives from the SII/ESI, here from the same one definition.
pub fn pdo_place(def: &DeviceDef, rx: bool, index: u16, sub: u8) -> Option<PdoPlace> {
    let (assign, pdos) = if rx {
        (def.rx_assign, def.rx_pdos)
    } else {
        (def.tx_assign, def.tx_pdos)
    };
    let mut bit = 0usize;
    for a in assign {
        let pdo = pdos.iter().find(|p| p.index == *a)?;
        for e in pdo.entries {
            if e.index == index && e.sub == sub {
                return Some(PdoPlace { bit, bits: e.bits });
            }
            bit += usize::from(e.bits);
        }
    }
    None
}

impl PdoPlace {
    /// Writes `v` (its low `bits`) into a process-data image at this place.
    pub fn put(self, image: &mut [u8], v: i64) {
        if self.bits == 1 {
            let (byte, b) = (self.bit / 8, self.bit % 8);
            if v != 0 {
                image[byte] |= 1 << b;
            } else {
                image[byte] &= !(1 << b);
            }
            return;
        }
        let byte = self.bit / 8;
        let n = usize::from(self.bits) / 8;
        let v = v.to_le_bytes();
        // The master writes 15 of these per leg and cycle: fixed-size copies for the
        // sizes there are, not a `memcpy` call of a run-time length.
        match n {
            1 => image[byte] = v[0],
            2 => image[byte..byte + 2].copy_from_slice(&v[..2]),
            4 => image[byte..byte + 4].copy_from_slice(&v[..4]),
            _ => image[byte..byte + n].copy_from_slice(&v[..n]),
        }
    }

    /// Reads the integer at this place of a process-data image (sign-extended if `signed`).
    pub fn get(self, image: &[u8], signed: bool) -> i32 {
        let byte = self.bit / 8;
        let n = usize::from(self.bits) / 8;
        let mut b = [0u8; 4];
        b[..n].copy_from_slice(&image[byte..byte + n]);
        let u = u32::from_le_bytes(b);
        if signed && n < 4 {
            let shift = 32 - 8 * n as u32;
            ((u << shift) as i32) >> shift
        } else {
            u as i32
        }
    }
}

/// The 9 input variables of a leg node (Table 3-2), in record order, under their CSV
/// names; type, unit and scaling come from the device's one declaration
/// ([`crate::laelaps::device`]'s `pd_table!`).
pub const INPUTS: [InputVar; 9] = [
    InputVar::of("hip_angle", 0x6010, 1),
    InputVar::of("Desired_hip_angle", 0x6010, 2),
    InputVar::of("Time", 0x6012, 1),
    InputVar::of("knee_angle", 0x6014, 1),
    InputVar::of("Desired_knee_angle", 0x6014, 2),
    InputVar::of("PWM_knee", 0x6020, 1),
    InputVar::of("PWM_hip", 0x6020, 2),
    InputVar::of("velocity_knee", 0x6030, 1),
    InputVar::of("velocity_hip", 0x6030, 2),
];

/// Index of each variable in [`INPUTS`].
pub mod var {
    /// hip_angle.
    pub const HIP: usize = 0;
    /// Desired_hip_angle.
    pub const HIP_DES: usize = 1;
    /// Time.
    pub const TIME: usize = 2;
    /// knee_angle.
    pub const KNEE: usize = 3;
    /// Desired_knee_angle.
    pub const KNEE_DES: usize = 4;
    /// PWM_knee.
    pub const PWM_KNEE: usize = 5;
    /// PWM_hip.
    pub const PWM_HIP: usize = 6;
    /// velocity_knee.
    pub const VEL_KNEE: usize = 7;
    /// velocity_hip.
    pub const VEL_HIP: usize = 8;
}

/// One recorded input variable: where it is and how its integer scales to its unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputVar {
    /// Column name after `<leg>.`.
    pub name: &'static str,
    /// Object index.
    pub index: u16,
    /// Subindex.
    pub sub: u8,
    /// Signed integer.
    pub signed: bool,
    /// Unit of the scaled value.
    pub unit: &'static str,
    /// Raw value = scaled value × `divisor` (10^decimals).
    pub divisor: i32,
}

impl InputVar {
    /// Input `index:sub` of the leg node's declaration, recorded as `name`. The build stops
    /// if the entry is missing or declares no `raw / 10^k` scaling.
    const fn of(name: &'static str, index: u16, sub: u8) -> Self {
        let Some(e) = oxicat_slave::find_entry(crate::laelaps::device::OBJECTS, index, sub) else {
            panic!("not a leg-node input");
        };
        let Some(scale) = e.scale() else {
            panic!("a recorded input declares its unit");
        };
        assert!(scale.num == 1 && scale.den <= i32::MAX as u32);
        Self {
            name,
            index,
            sub,
            signed: e.dtype.is_signed(),
            unit: scale.unit,
            divisor: scale.den as i32,
        }
    }

    /// The value in its unit.
    pub fn scale(&self, raw: i32) -> f64 {
        f64::from(raw) / f64::from(self.divisor)
    }
}

/// The master's outputs for one leg, as Table 3-1 integers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct LegOutputs {
    state_machine: bool,
    transition_time: i8,
    filter_hz: u16,
    gains: [i16; 6],
    traj: [i16; 7],
}

struct OutputMap {
    state_machine: PdoPlace,
    transition_time: PdoPlace,
    filter: PdoPlace,
    gains: [PdoPlace; 6],
    traj: [PdoPlace; 7],
}

impl OutputMap {
    fn new(def: &DeviceDef) -> Result<Self, MasterError> {
        let p = |i: u16, s: u8| {
            pdo_place(def, true, i, s).ok_or_else(|| {
                MasterError::Usage(format!("leg node has no output {i:#06x}:{s:02}"))
            })
        };
        let mut gains = [PdoPlace { bit: 0, bits: 0 }; 6];
        for (k, g) in gains.iter_mut().enumerate() {
            *g = p(0x7020, k as u8 + 1)?;
        }
        let mut traj = [PdoPlace { bit: 0, bits: 0 }; 7];
        for (k, g) in traj.iter_mut().enumerate() {
            *g = p(0x7030, k as u8 + 1)?;
        }
        Ok(Self {
            state_machine: p(0x7000, 1)?,
            transition_time: p(0x7000, 9)?,
            filter: p(0x7012, 1)?,
            gains,
            traj,
        })
    }

    fn write(&self, o: &LegOutputs, image: &mut [u8]) {
        self.state_machine.put(image, i64::from(o.state_machine));
        self.transition_time
            .put(image, i64::from(o.transition_time));
        self.filter.put(image, i64::from(o.filter_hz));
        for (p, v) in self.gains.iter().zip(o.gains) {
            p.put(image, i64::from(v));
        }
        for (p, v) in self.traj.iter().zip(o.traj) {
            p.put(image, i64::from(v));
        }
    }

    /// [`write`](Self::write) unless `o` is `last`, what was last written into `image`
    /// (then updated). Skipping leaves the same bytes: a place's `put` sets exactly its
    /// bits whatever they held, so writing `o` again changes nothing but the
    /// `State_Machine` place, which [`LinkedVariable::apply`] sets after it every cycle
    /// (`o.state_machine` is false, the linked value goes over it). The trot's outputs
    /// change at a few phase boundaries; the 16 places of each of the 4 images were
    /// written every cycle.
    fn write_changed(&self, o: &LegOutputs, last: &mut Option<LegOutputs>, image: &mut [u8]) {
        if *last != Some(*o) {
            self.write(o, image);
            *last = Some(*o);
        }
    }
}

/// A variable of the master linked to the same PDO entry of several slaves (TwinCAT's
/// multi-link): one write sets it in every slave's outputs of the same cycle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkedVariable {
    /// Its name.
    pub name: &'static str,
    /// `(slave position, place in that slave's outputs)`.
    pub targets: Vec<(usize, PdoPlace)>,
    /// The value.
    pub value: i64,
}

impl LinkedVariable {
    /// Writes the value into each linked slave's output image.
    pub fn apply(&self, images: &mut [Vec<u8>]) {
        for (pos, place) in &self.targets {
            place.put(&mut images[*pos], self.value);
        }
    }
}

fn round_i16(v: f64) -> i16 {
    v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

/// The procedure's cycle numbers (0 = the cycle that sets `State_Machine = 1`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Phases {
    /// b starts its ramp.
    pub ramp_b: u64,
    /// a starts its ramp.
    pub ramp_a: u64,
    /// Steady trot starts (a and b at their values).
    pub trot: u64,
    /// a ramps back.
    pub back_a: u64,
    /// b ramps back.
    pub back_b: u64,
    /// `State_Machine = 0`.
    pub stop: u64,
    /// Cycles recorded.
    pub end: u64,
}

impl Phases {
    /// The phases of `s`.
    pub fn of(s: &Scenario) -> Self {
        let p = &s.procedure;
        let tr = s.cycles(f64::from(p.transition_time_s));
        let ramp_b = s.cycles(p.stand_s);
        let ramp_a = ramp_b + tr;
        let trot = ramp_a + tr;
        let back_a = trot + s.cycles(p.trot_s);
        let back_b = back_a + tr;
        let stop = back_b + tr + s.cycles(p.stand_s);
        let end = stop + s.cycles(p.stop_s).max(1);
        Self {
            ramp_b,
            ramp_a,
            trot,
            back_a,
            back_b,
            stop,
            end,
        }
    }

    /// `(a, b)` commanded in cycle `k` as fractions of their Table 4-1 values.
    pub fn ab(&self, k: u64) -> (bool, bool) {
        let a = k >= self.ramp_a && k < self.back_a;
        let b = k >= self.ramp_b && k < self.back_b;
        (a, b)
    }
}

/// One recorded cycle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Row {
    /// `State_Machine` written this cycle.
    pub state_machine: bool,
    /// a commanded per leg (Table 3-1 `a_ellipse100`: whole cm), Table 4-1 order.
    pub a_cmd: [i16; 4],
    /// b commanded per leg (whole cm).
    pub b_cmd: [i16; 4],
    /// The inputs of each leg (Table 4-1 order FL, FR, HL, HR), raw PDO integers in
    /// [`INPUTS`] order.
    pub inputs: [[i32; 9]; 4],
    /// Working counter of the cycle's LRW.
    pub wkc: u16,
}

/// Bus statistics of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusStats {
    /// Recorded cycles.
    pub cycles: u64,
    /// Cycles whose working counter was not [`EXPECTED_WKC`].
    pub wkc_errors: u64,
    /// Largest spread of one SYNC0 pulse's time across the four nodes \[ns\].
    pub sync0_spread_max_ns: u64,
    /// Cycles with more or fewer than one SYNC0 per node since the previous cycle.
    pub sync0_missed: u64,
    /// SYNC0 count (per node, since boot) at which each node released its leg; all equal
    /// when the four trajectory clocks started in the same cycle (`None`: not released, or
    /// a board image, whose release the host does not see).
    pub release_sync0: [Option<u64>; 4],
    /// Virtual time the bring-up took \[ns\] (varies between runs; not in the CSV).
    pub bringup_ns: u64,
}

/// How one leg node reached its ESC during the recorded cycles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NodePdi {
    /// PDI accesses that failed (driver or ESC errors), whole run.
    pub pdi_errors: u64,
    /// The node's SPI traffic over the recorded cycles (`None` on the direct route).
    pub spi: Option<SpiStats>,
    /// What the execution-time model saw, whole run (`None` when it is off).
    pub timing: Option<TimingStats>,
    /// SYNC1 interrupts, whole run (0 unless `bus.sync1_shift_us`; `None` where the host
    /// does not count them).
    pub sync1: Option<u64>,
    /// The node's input sync mode 0x1C33:01 and input shift 0x1C33:03 \[ns\] at the end
    /// (`None` where the host cannot read its dictionary).
    pub input_sync: Option<(u16, u32)>,
}

impl NodePdi {
    /// SPI bus time per recorded cycle \[µs\] (`None` on the direct route).
    pub fn spi_us_per_cycle(&self, cycles: u64) -> Option<f64> {
        self.spi.map(|b| b.us() / cycles.max(1) as f64)
    }
}

/// The PDI route of a run and what it carried.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PdiReport {
    /// The route every leg node used.
    pub route: PdiRoute,
    /// The nodes ran board images instruction by instruction (oxicat-emu) rather than the
    /// host-compiled firmware: their SPI bus time is simulated, not only counted.
    pub machine_code: bool,
    /// Per leg, Table 4-1 order (FL, FR, HL, HR).
    pub nodes: [NodePdi; 4],
}

/// Everything a run produced.
#[derive(Debug, Clone)]
pub struct TrotRun {
    /// The scenario.
    pub scenario: Scenario,
    /// The procedure's cycle numbers.
    pub phases: Phases,
    /// One row per recorded cycle.
    pub rows: Vec<Row>,
    /// Bus statistics.
    pub bus: BusStats,
    /// Wall-clock time of the whole run (bring-up included).
    pub wall: Duration,
    /// Wall-clock time of the recorded part.
    pub wall_recorded: Duration,
    /// Virtual time simulated in total \[s\].
    pub simulated_s: f64,
    /// Trajectory clock of each leg's firmware at the end, ns (Table 4-1 order).
    pub final_clock_ns: [u64; 4],
    /// How the leg nodes reached their ESCs, PDI errors and SPI traffic.
    pub pdi: PdiReport,
    /// With `[robot] body`: body steps a leg asked for before every leg had reported what
    /// they depend on (0: the coupling was exact lock-step); `None`: hips fixed.
    pub body_late: Option<u64>,
    /// With `[robot] body`: the legs' loads, the body's heave and pitch over the steady trot
    /// (cycles [`Phases::trot`] to [`Phases::back_a`]; the whole run if it has none).
    pub body_stats: Option<BodyStats>,
}

/// Progress of a run, for a progress bar.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// Recorded cycles done.
    pub done: u64,
    /// Recorded cycles in total.
    pub total: u64,
}

/// Position of a Table 4-1 leg in [`LegId::TABLE`].
pub fn table_index(leg: LegId) -> usize {
    LegId::TABLE
        .iter()
        .position(|l| *l == leg)
        .expect("a leg of the table")
}

/// The rig of `leg` for scenario `s`.
pub fn rig_config(s: &Scenario, leg: LegId, phases: &Phases) -> RigConfig {
    let cyc = s.cycle_ns() as f64 * 1e-9;
    let tr = f64::from(s.procedure.transition_time_s);
    let v = s.rig.belt_speed_m_s;
    let (a0, a1) = (phases.ramp_a as f64 * cyc, phases.back_a as f64 * cyc);
    let mut c = RigConfig::laelaps(leg).belt_depth(s.rig.belt_depth_m);
    c.leg = crate::laelaps::robot::leg_params(&s.robot, leg, c.leg);
    c.plant_period_ns = 1_000_000_000 / u64::from(s.rig.plant_rate_hz);
    c.law = s.control.law();
    c.belt = BeltProfile {
        points: vec![(a0, 0.0), (a0 + tr, v), (a1, v), (a1 + tr, 0.0)],
    };
    match s.pdi.exec_time.timing() {
        Some(t) => c.timing(t),
        None => c,
    }
}

/// What a run reports about one leg node ([`TrotNode::trot_report`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TrotNodeReport {
    /// The firmware's trajectory clock \[ns\], where the host can read it (a board image
    /// shows only its pins and process data: `None`, and the run takes the clock from the
    /// node's `Time` input).
    pub clock_ns: Option<u64>,
    /// SYNC0 count at which the node released its leg, where the host knows it.
    pub released_at_sync0: Option<u64>,
    /// PDI errors, SPI traffic and execution-time figures.
    pub pdi: NodePdi,
}

/// A leg node on the trot's segment, whatever runs its firmware: the host-compiled leg
/// node on a firmware host ([`AnyLegRigHandle`], [`run_trot`]) or a board image executed
/// instruction by instruction (oxicat-emu's `trot`, through [`run_trot_on`]).
pub trait TrotNode {
    /// The node's figures now.
    fn trot_report(&self) -> TrotNodeReport;
    /// Clears what the run reports over the recorded cycles: the SPI counters (and a board
    /// image's handler times and painted stack). Called when the record starts.
    fn reset_stats(&self);
}

impl TrotNode for AnyLegRigHandle {
    fn trot_report(&self) -> TrotNodeReport {
        let r = self.report();
        TrotNodeReport {
            clock_ns: Some(r.clock_ns),
            released_at_sync0: r.released_at_sync0,
            pdi: NodePdi {
                pdi_errors: r.counters.pdi_errors,
                spi: r.bus,
                timing: r.timing,
                sync1: Some(r.counters.sync1),
                input_sync: r.sync_mode.zip(r.input_shift_ns),
            },
        }
    }

    fn reset_stats(&self) {
        self.reset_bus_stats()
    }
}

/// Puts the node of one leg on the segment: its ESC (with the SII it is given) and its
/// firmware with the leg's rig (`RigConfig`: plant, substep, belt profile of the scenario).
pub type AttachLeg<'a> = dyn FnMut(&mut Segment, LegId, Vec<u8>, RigConfig) -> Result<Box<dyn TrotNode>, MasterError>
    + 'a;

/// Runs scenario `s`; `progress` is called every 250 recorded cycles.
pub fn run_trot(s: &Scenario, progress: &mut dyn FnMut(Progress)) -> Result<TrotRun, MasterError> {
    // Four towers, each an ET1100-class ESC (the FB1111; the LAN9252's own core when the
    // nodes reach it through a LAN9252) with the host-compiled leg node on the route.
    let route = s.pdi_route();
    let pdi = PdiReport {
        route,
        ..PdiReport::default()
    };
    run_trot_on(s, progress, pdi, 0, &mut |seg, leg, sii, rig| {
        let id = seg.add(Esc::new(route.esc_config(EscConfig::et1100()), sii));
        let h = attach_leg_routed(seg, id, leg, rig, route)
            .map_err(|e| MasterError::Usage(format!("tower {id}: {e}")))?;
        Ok(Box::new(h) as Box<dyn TrotNode>)
    })
}

/// [`run_trot`] with the leg nodes `attach` puts on the segment (`pdi`: the route they
/// use, for the report); the segment runs alone for `power_on_ns` before the master starts,
/// as boards that boot (and reset their ESC chip) before the master comes up.
pub fn run_trot_on(
    s: &Scenario,
    progress: &mut dyn FnMut(Progress),
    pdi: PdiReport,
    power_on_ns: u64,
    attach: &mut AttachLeg<'_>,
) -> Result<TrotRun, MasterError> {
    let wall0 = Instant::now();
    let phases = Phases::of(s);

    // The segment: four towers in chain order, each with the SII generated from its
    // build's definition, each driving the opposite leg.
    let mut seg = Segment::new();
    let mut handles: Vec<(LegId, Box<dyn TrotNode>)> = Vec::new();
    // With `[robot] body`, the four hips on one body (`crate::laelaps::robot`).
    let body = crate::laelaps::robot::body(&s.robot);
    for leg in chain_legs() {
        let def = device::device(leg.side());
        let sii = oxicat_esi::sii::generate(def)
            .map_err(|e| MasterError::Usage(format!("SII of the leg node: {e}")))?;
        let mut rig = rig_config(s, leg, &phases);
        rig.body = body.as_ref().map(|b| crate::laelaps::robot::link(b, leg));
        let h = attach(&mut seg, leg, sii, rig)?;
        handles.push((leg, h));
    }
    debug_assert_eq!(TOWER_CHAIN.len(), handles.len());
    if power_on_ns > 0 {
        seg.advance_to(power_on_ns);
    }
    let segment = Arc::new(Mutex::new(seg));

    let storage: &'static Storage = Box::leak(Box::new(Storage::new()));
    let (tx, rx, pdu_loop) = storage
        .try_split()
        .map_err(|_| MasterError::Usage("PDU storage already in use".into()))?;
    let md = MainDevice::new(
        pdu_loop,
        oxicat_master::inprocess::virtual_timeouts(),
        MainDeviceConfig {
            dc_static_sync_iterations: 1000,
            ..MainDeviceConfig::default()
        },
    );
    let transport = inprocess_task(
        segment.clone(),
        tx,
        rx,
        InProcessConfig {
            frame_gap_ns: oxicat_master::SIM_FRAME_GAP_NS,
        },
    );
    let mut steady_body = None;
    let master = run_master(
        s,
        &phases,
        &md,
        &segment,
        &handles,
        progress,
        (body.as_ref(), &mut steady_body),
    );
    // async-io's executor: ethercrab's PDU timers live in its reactor, which then runs on
    // this thread instead of waking a reactor thread for every frame. `SelfWoken` re-polls
    // in place while the master and the transport wake each other (every frame), so the
    // reactor (epoll) is only entered when the run really waits on a timer (bring-up).
    let out = async_io::block_on(SelfWoken::new(Box::pin(futures_lite::future::or(
        master,
        async {
            let r = transport.await;
            Err(MasterError::Usage(format!(
                "the in-process transport stopped: {:?}",
                r.err()
            )))
        },
    ))));
    let (rows, mut bus, wall_recorded) = out?;
    let end_ns = segment.lock().unwrap_or_else(|e| e.into_inner()).now();
    let body_report = body.and_then(|b| {
        let b = b.lock().unwrap_or_else(|e| e.into_inner());
        (b.steps() > 0).then(|| (b.late(), steady_body.unwrap_or_else(|| b.stats())))
    });
    let mut final_clock_ns = [0u64; 4];
    let mut pdi = pdi;
    for (leg, h) in &handles {
        let r = h.trot_report();
        let ti = table_index(*leg);
        final_clock_ns[ti] = match r.clock_ns {
            Some(c) => c,
            None => last_time_input_ns(&rows, ti),
        };
        bus.release_sync0[ti] = r.released_at_sync0;
        pdi.nodes[ti] = r.pdi;
    }
    Ok(TrotRun {
        scenario: s.clone(),
        phases,
        rows,
        bus,
        wall: wall0.elapsed(),
        wall_recorded,
        simulated_s: end_ns as f64 * 1e-9,
        final_clock_ns,
        pdi,
        // A body no leg stepped (board images keep their hips fixed): `None`.
        body_late: body_report.map(|b| b.0),
        body_stats: body_report.map(|b| b.1),
    })
}

/// The trajectory clock the node of Table 4-1 position `ti` last reported in its `Time`
/// input (centiseconds on the wire: ±5 ms) \[ns\].
fn last_time_input_ns(rows: &[Row], ti: usize) -> u64 {
    rows.last().map_or(0, |r| {
        u64::try_from(r.inputs[ti][var::TIME]).unwrap_or(0) * 10_000_000
    })
}

/// Wraps a future for `async_io::block_on` and re-polls it in place as long as it woke
/// itself during the last poll (the in-process transport completing a frame wakes the
/// master in the same poll). `async_io::block_on` would instead run its reactor (a
/// zero-timeout `epoll_wait`) before every such re-poll. Wakes are forwarded to the outer
/// waker, so timers (bring-up wait loops) and wakes after a `Pending` work as before; the
/// poll order is unchanged, so the run stays deterministic.
struct SelfWoken<F> {
    f: F,
    waker: Option<(Arc<WakeFlag>, std::task::Waker)>,
}

struct WakeFlag {
    woken: std::sync::atomic::AtomicBool,
    outer: std::task::Waker,
}

impl std::task::Wake for WakeFlag {
    fn wake(self: Arc<Self>) {
        self.wake_by_ref()
    }
    fn wake_by_ref(self: &Arc<Self>) {
        self.woken.store(true, std::sync::atomic::Ordering::Release);
        self.outer.wake_by_ref();
    }
}

impl<F> SelfWoken<F> {
    fn new(f: F) -> Self {
        Self { f, waker: None }
    }
}

impl<F: std::future::Future + Unpin> std::future::Future for SelfWoken<F> {
    type Output = F::Output;

    fn poll(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<F::Output> {
        use std::sync::atomic::Ordering;
        let this = &mut *self;
        let fresh = match &this.waker {
            Some((w, _)) => !w.outer.will_wake(cx.waker()),
            None => true,
        };
        if fresh {
            let flag = Arc::new(WakeFlag {
                woken: false.into(),
                outer: cx.waker().clone(),
            });
            let waker = std::task::Waker::from(flag.clone());
            this.waker = Some((flag, waker));
        }
        let Some((flag, waker)) = &this.waker else {
            unreachable!()
        };
        let mut inner = std::task::Context::from_waker(waker);
        // Bounded: every `REPOLLS` re-polls the (forwarded, hence pending) wake makes
        // `async_io::block_on` run its reactor once with a zero timeout. That processes the
        // timer queue ethercrab's per-PDU timeouts fill and keeps async-io's helper thread
        // backing off instead of taking the reactor and being woken for every new timer.
        const REPOLLS: usize = 64;
        for _ in 0..REPOLLS {
            flag.woken.store(false, Ordering::Release);
            if let std::task::Poll::Ready(v) = std::pin::Pin::new(&mut this.f).poll(&mut inner) {
                return std::task::Poll::Ready(v);
            }
            if !flag.woken.load(Ordering::Acquire) {
                return std::task::Poll::Pending;
            }
        }
        std::task::Poll::Pending
    }
}

fn eth(what: &str) -> impl Fn(ethercrab::error::Error) -> MasterError + '_ {
    move |e| MasterError::Ethercrab(what.to_string(), e)
}

async fn run_master(
    s: &Scenario,
    phases: &Phases,
    md: &MainDevice<'static>,
    segment: &Arc<Mutex<Segment>>,
    handles: &[(LegId, Box<dyn TrotNode>)],
    progress: &mut dyn FnMut(Progress),
    (body, steady_body): (Option<&Arc<Mutex<Body>>>, &mut Option<BodyStats>),
) -> Result<(Vec<Row>, BusStats, Duration), MasterError> {
    let lock = || segment.lock().unwrap_or_else(|e| e.into_inner());
    let clock = lock().clock();
    let cycle_ns = s.cycle_ns();
    let mut group = md
        .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(move || clock.now())
        .await
        .map_err(eth("discovery"))?;
    if group.len() != 4 {
        return Err(MasterError::Usage(format!(
            "expected 4 leg nodes, found {}",
            group.len()
        )));
    }
    let sync1_ns = u64::from(s.bus.sync1_shift_us) * 1000;
    for mut sd in group.iter_mut(md) {
        // Sync type: DC SYNC0 (0x1C32:01 = 2), then SYNC0 in the DC unit; with a SYNC1
        // `bus.sync1` the thesis' split, DC SYNC1 (3), SYNC1 `sync1_shift_us` after SYNC0.
        let (mode, dc) = if s.bus.sync1 {
            let sync1_period = Duration::from_nanos(sync1_ns);
            (3u16, DcSync::Sync01 { sync1_period })
        } else {
            (2u16, DcSync::Sync0)
        };
        sd.sdo_write(0x1C32, 1, mode)
            .await
            .map_err(eth("0x1C32:01 (sync type)"))?;
        sd.set_dc_sync(dc);
    }
    let group = group
        .into_pre_op_pdi(md)
        .await
        .map_err(eth("PDO configuration"))?;
    let group = group
        .configure_dc_sync(
            md,
            DcConfiguration {
                start_delay: Duration::from_millis(1),
                sync0_period: Duration::from_nanos(cycle_ns),
                sync0_shift: Duration::from_nanos(u64::from(s.bus.sync0_shift_us) * 1000),
            },
        )
        .await
        .map_err(eth("DC configuration"))?;
    let group = group.into_safe_op(md).await.map_err(eth("SAFE-OP"))?;
    let group = group.request_into_op(md).await.map_err(eth("OP request"))?;

    // Table 4-1 per node, in chain order; layouts from the node's own definition.
    let legs: Vec<LegId> = handles.iter().map(|h| h.0).collect();
    let def = device::device(legs[0].side());
    let map = OutputMap::new(def)?;
    let in_places: Vec<PdoPlace> = INPUTS
        .iter()
        .map(|v| {
            pdo_place(def, false, v.index, v.sub)
                .ok_or_else(|| MasterError::Usage(format!("no input {}", v.name)))
        })
        .collect::<Result<_, _>>()?;
    let mut state_machine = LinkedVariable {
        name: "State_Machine",
        targets: (0..4).map(|p| (p, map.state_machine)).collect(),
        value: 0,
    };
    let base: Vec<LegOutputs> = legs
        .iter()
        .map(|l| {
            let t = s.leg(*l);
            let c = &s.control;
            LegOutputs {
                state_machine: false,
                transition_time: s.procedure.transition_time_s,
                filter_hz: c.filter_hz,
                gains: [
                    round_i16(c.knee.kp * 100.0),
                    round_i16(c.knee.kd * 1000.0),
                    round_i16(c.knee.ki * 100.0),
                    round_i16(c.hip.kp * 100.0),
                    round_i16(c.hip.kd * 1000.0),
                    round_i16(c.hip.ki * 100.0),
                ],
                traj: [
                    round_i16(t.x_centre_cm * 10.0),
                    round_i16(t.y_centre_cm * 10.0),
                    0,
                    0,
                    round_i16(t.freq_hz * 100.0),
                    round_i16(t.phase_deg),
                    round_i16(t.flatness * 100.0),
                ],
            }
        })
        .collect();
    let ab_full: Vec<(i16, i16)> = legs
        .iter()
        .map(|l| {
            let t = s.leg(*l);
            // Table 3-1: a_ellipse100 / b_ellipse100 carry a × 100 in metres, i.e. whole cm.
            (round_i16(t.a_cm), round_i16(t.b_cm))
        })
        .collect();
    let out_len = group
        .iter(md)
        .map(|sd| sd.outputs_raw().len())
        .max()
        .unwrap_or(0);
    let mut images = vec![vec![0u8; out_len]; 4];
    // What each image was last written with (`OutputMap::write_changed`).
    let mut written = [None::<LegOutputs>; 4];

    // Bring the cycle in line with SYNC0 until everyone is in OP.
    let mut warm = 0;
    let mut guard = 0u32;
    loop {
        let t = clock.now();
        let r = group.tx_rx_dc(md).await.map_err(eth("cycle"))?;
        lock().advance_to(t + r.extra.next_cycle_wait.as_nanos() as u64);
        if r.all_op() {
            warm += 1;
            if warm == 10 {
                break;
            }
        }
        guard += 1;
        if guard > 100_000 {
            return Err(MasterError::Usage("the leg nodes did not reach OP".into()));
        }
    }
    let bringup_ns = clock.now();

    let mut bus = BusStats {
        bringup_ns,
        ..BusStats::default()
    };
    let settle = s.cycles(s.procedure.settle_s);
    let total = phases.end;
    let mut rows = Vec::with_capacity(total as usize);
    let mut last_sync = [None::<u64>; 4];
    let mut rec_start = Instant::now();
    for k in 0..settle + total {
        let recording = k >= settle;
        let j = k.saturating_sub(settle);
        // The body's figures over the steady trot (a and b at their values).
        if let Some(b) = body.filter(|_| recording) {
            let mut b = b.lock().unwrap_or_else(|e| e.into_inner());
            if j == phases.trot {
                b.reset_stats();
            } else if j == phases.back_a {
                *steady_body = Some(b.stats());
            }
        }
        if k == settle {
            rec_start = Instant::now();
            // SPI traffic is reported over the recorded cycles.
            for (_, h) in handles {
                h.reset_stats();
            }
        }
        // The master's outputs of this cycle.
        let (a_on, b_on) = if recording {
            phases.ab(j)
        } else {
            (false, false)
        };
        state_machine.value = i64::from(recording && j < phases.stop);
        let mut a_cmd = [0i16; 4];
        let mut b_cmd = [0i16; 4];
        for (pos, o) in base.iter().enumerate() {
            let mut o = *o;
            o.traj[2] = if a_on { ab_full[pos].0 } else { 0 };
            o.traj[3] = if b_on { ab_full[pos].1 } else { 0 };
            map.write_changed(&o, &mut written[pos], &mut images[pos]);
            let ti = table_index(legs[pos]);
            a_cmd[ti] = o.traj[2];
            b_cmd[ti] = o.traj[3];
        }
        state_machine.apply(&mut images);
        for (pos, sd) in group.iter(md).enumerate() {
            let mut o = sd.outputs_raw_mut();
            let n = o.len().min(images[pos].len());
            o[..n].copy_from_slice(&images[pos][..n]);
        }
        let t = clock.now();
        let r = group.tx_rx_dc(md).await.map_err(eth("cycle"))?;
        if recording {
            let mut inputs = [[0i32; 9]; 4];
            for (pos, sd) in group.iter(md).enumerate() {
                let img = sd.inputs_raw();
                let ti = table_index(legs[pos]);
                for (v, (var, place)) in INPUTS.iter().zip(&in_places).enumerate() {
                    inputs[ti][v] = place.get(&img, var.signed);
                }
            }
            if r.working_counter != EXPECTED_WKC {
                bus.wkc_errors += 1;
            }
            rows.push(Row {
                state_machine: state_machine.value != 0,
                a_cmd,
                b_cmd,
                inputs,
                wkc: r.working_counter,
            });
            if (j + 1) % 250 == 0 || j + 1 == total {
                progress(Progress { done: j + 1, total });
            }
        }
        let mut seg = lock();
        seg.advance_to(t + r.extra.next_cycle_wait.as_nanos() as u64);
        // SYNC0 of the four nodes: one pulse per cycle each, and how far apart.
        let now: [Option<u64>; 4] = core::array::from_fn(|i| seg.last_sync(i).0);
        drop(seg);
        if recording {
            if let [Some(a), Some(b), Some(c), Some(d)] = now {
                let spread = a.max(b).max(c).max(d) - a.min(b).min(c).min(d);
                bus.sync0_spread_max_ns = bus.sync0_spread_max_ns.max(spread);
            }
            for i in 0..4 {
                let fresh = match (last_sync[i], now[i]) {
                    (Some(a), Some(b)) => b > a && b - a <= cycle_ns + cycle_ns / 2,
                    (None, Some(_)) => true,
                    _ => false,
                };
                if !fresh {
                    bus.sync0_missed += 1;
                }
            }
        }
        last_sync = now;
    }
    bus.cycles = rows.len() as u64;
    Ok((rows, bus, rec_start.elapsed()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The images the master sends are the same bytes with `write_changed` as with
    /// `write` every cycle, over random runs of outputs (changing now and then, as the
    /// procedure's phases change them, or every cycle) and of the linked `State_Machine`,
    /// from images holding any bytes.
    #[test]
    fn writing_only_changed_outputs_leaves_the_same_images() {
        let def = device::device(crate::laelaps::Side::Left);
        let map = OutputMap::new(def).expect("the leg node's outputs");
        let len = map
            .traj
            .iter()
            .chain(&map.gains)
            .chain([&map.state_machine, &map.transition_time, &map.filter])
            .map(|p| (p.bit + usize::from(p.bits)).div_ceil(8))
            .max()
            .unwrap_or(0);
        let mut s = 0xA076_1D64_78BD_642Fu64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let mut sm = LinkedVariable {
            name: "State_Machine",
            targets: (0..4).map(|p| (p, map.state_machine)).collect(),
            value: 0,
        };
        let start: Vec<u8> = (0..len).map(|_| next() as u8).collect();
        let mut always = vec![start.clone(); 4];
        let mut changed = vec![start; 4];
        let mut written = [None::<LegOutputs>; 4];
        let mut outs = [LegOutputs::default(); 4];
        let mut skipped = 0;
        for cycle in 0..20_000 {
            let r = next();
            if r % 5 == 0 {
                sm.value = i64::from(r % 3 == 0);
            }
            for (pos, o) in outs.iter_mut().enumerate() {
                let r = next();
                // Mostly unchanged; a field now and then; everything at once sometimes.
                match r % 16 {
                    0 => o.traj[(r >> 8) as usize % 7] = (r >> 16) as i16,
                    1 => o.gains[(r >> 8) as usize % 6] = (r >> 16) as i16,
                    2 => o.transition_time = (r >> 16) as i8,
                    3 => o.filter_hz = (r >> 16) as u16,
                    4 => {
                        o.traj = core::array::from_fn(|k| (r >> (k * 8)) as i16);
                        o.gains = core::array::from_fn(|k| (r >> (k * 9)) as i16);
                    }
                    _ => {}
                }
                if written[pos] == Some(*o) {
                    skipped += 1;
                }
                map.write(o, &mut always[pos]);
                map.write_changed(o, &mut written[pos], &mut changed[pos]);
            }
            sm.apply(&mut always);
            sm.apply(&mut changed);
            assert_eq!(always, changed, "cycle {cycle}");
        }
        assert!(skipped > 40_000, "most writes were skipped: {skipped}");
    }
}
