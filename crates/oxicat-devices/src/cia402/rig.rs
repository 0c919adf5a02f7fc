//! The CiA402 joint drive on the virtual segment: the firmware host of `oxicat-sim` runs
//! the drive firmware (`crate::cia402`) on the slave stack behind its ESC and owns the
//! joint it drives (`oxicat_plant::bldc_joint`: BLDC motor, compliant harmonic gear, link,
//! torque sensor, encoder with index pulse, home switch).
//!
//! # What happens when, in virtual time
//!
//! | event | what runs |
//! |---|---|
//! | ESC SYNC0 | `Slave::on_sync0` → drive cycle (state machine, modes, position and velocity loops) |
//! | ESC PDI IRQ | `Slave::on_pdi_irq` (SM-synchronous / free-run cycles) |
//! | tick every 50 µs (20 kHz), on the firmware host's schedule | 1. the joint catches up to now (fixed substeps) with the voltage the current loop last set ([`JointPlant`]); 2. `Slave::on_timer(CURRENT_LOOP_TIMER)`: current loop → new voltage; 3. `Slave::poll` (ESM, mailbox); the stack sends the drive's queued emergencies (`Application::next_emergency`) |
//!
//! At equal times ESC events come first (the segment's rule), then the tick, so a run is a
//! function of the frames and their virtual times only.
//!
//! [`JointBench`] is the same firmware and plant without an ESC, for tests of the drive
//! itself at exactly 1 kHz.

use crate::cia402::{device, Cia402Drive, DriveParams, JointHw, PowerStage, CURRENT_LOOP_TIMER};
use oxicat_esc::Esc;
pub use oxicat_plant::bldc_joint::{BldcJoint, BldcJointParams};
use oxicat_slave::{Od, Slave};

use oxicat_sim::firmware::{
    attach_host, boot_stack, AttachError, Bench, FirmwareConfig, Host, HostHandle, Stack,
};
use oxicat_sim::pdi_path::{Direct, PdiPath, PdiRoute, SpiPath};
use oxicat_sim::segment::{Segment, SlaveId};

/// Mailbox size of the drive (its definition: 128 bytes).
pub const MBX: usize = 128;
/// The drive's stack on the firmware's `Pdi` of path `P` (the software ESC by default).
pub type JointSlave<P = Direct> = Slave<<P as PdiPath>::Pdi, { device::IMAGE }, MBX>;
/// The drive firmware on the joint.
pub type JointApp = Cia402Drive<JointBoard>;

/// Current-loop tick \[ns\] (20 kHz).
pub const TICK_NS: u64 = 50_000;

/// The joint as the drive's hardware traits see it.
#[derive(Debug, Clone)]
pub struct JointBoard {
    /// The plant.
    pub joint: BldcJoint,
}

impl JointHw for JointBoard {
    type Power = Self;
    fn encoder(&mut self) -> i32 {
        self.joint.encoder_count()
    }
    fn index_latch(&mut self) -> Option<i32> {
        self.joint.take_index_latch()
    }
    fn home_switch(&mut self) -> bool {
        self.joint.home_switch()
    }
    fn joint_torque(&mut self) -> f32 {
        self.joint.gear_torque() as f32
    }
    /// The drive runs the current loop itself, on its local timer: one context.
    fn power_stage(&mut self) -> Option<&mut Self> {
        Some(self)
    }
}

impl PowerStage for JointBoard {
    fn current(&mut self) -> f32 {
        self.joint.current as f32
    }
    fn set_voltage(&mut self, enable: bool, volts: f32) {
        self.joint.set_voltage(enable, volts as f64);
    }
}

/// Drive parameters that match a plant.
pub fn drive_params(p: &BldcJointParams) -> DriveParams {
    DriveParams {
        counts_per_rev: p.counts_per_rev,
        kt: p.kt as f32,
        ..DriveParams::default()
    }
}

/// A new drive on a new joint.
pub fn new_app(p: BldcJointParams) -> JointApp {
    Cia402Drive::new(
        JointBoard {
            joint: BldcJoint::new(p),
        },
        drive_params(&p),
    )
}

/// The joint's plant on the host: stepped 50 µs at each current-loop tick, before the
/// loop reads its sensors (the voltage it set last acts over the step).
#[derive(Debug, Clone, Copy, Default)]
pub struct JointPlant;

impl<Pd: oxicat_slave::Pdi> Bench<Stack<Pd, JointApp, { device::IMAGE }, MBX>> for JointPlant {
    fn before_timers(&mut self, image: &mut Stack<Pd, JointApp, { device::IMAGE }, MBX>, _t: u64) {
        image.app.hw.joint.step(TICK_NS as f64 * 1e-9);
    }
}

/// The drive on its host: stack, firmware and joint, reaching its ESC through `P`
/// (`image.slave`, `image.app`, or through `Deref`: `slave`, `app`).
pub type JointDrive<P = Direct> =
    Host<Stack<<P as PdiPath>::Pdi, JointApp, { device::IMAGE }, MBX>, P, JointPlant>;

/// Access to the drive from outside the segment.
pub type JointHandle<P = Direct> =
    HostHandle<Stack<<P as PdiPath>::Pdi, JointApp, { device::IMAGE }, MBX>, P, JointPlant>;

/// The host's schedule: current loop and main loop every 50 µs on the 50 µs grid, the
/// loop first.
fn schedule() -> FirmwareConfig {
    FirmwareConfig::default()
        .aligned(TICK_NS)
        .timer_from(CURRENT_LOOP_TIMER, TICK_NS, 0)
        .poll_every(TICK_NS)
}

/// Boots the drive firmware on ESC `id` of `segment` with a joint of `params`; the ticks
/// start at the next multiple of 50 µs.
pub fn attach(
    segment: &mut Segment,
    id: SlaveId,
    params: BldcJointParams,
) -> Result<JointHandle, AttachError> {
    attach_with(segment, id, params, |_| Ok(Direct))
}

/// [`attach`] with the firmware reaching its ESC through the chip driver of `route` over
/// the simulated SPI (`PdiRoute::Direct` is refused: use [`attach`]).
pub fn attach_via(
    segment: &mut Segment,
    id: SlaveId,
    params: BldcJointParams,
    route: PdiRoute,
) -> Result<JointHandle<SpiPath>, AttachError> {
    attach_with(segment, id, params, |esc| SpiPath::new(route, esc))
}

fn attach_with<P: PdiPath>(
    segment: &mut Segment,
    id: SlaveId,
    params: BldcJointParams,
    path: impl FnOnce(&mut Esc) -> Result<P, oxicat_sim::pdi_path::PathInitError>,
) -> Result<JointHandle<P>, AttachError> {
    attach_host(segment, id, &schedule(), JointPlant, path, |esc, path| {
        boot_stack(&device::DEF, esc, new_app(params), path)
    })
}

/// The drive and its joint without an ESC: the object dictionary stands in for the
/// process data; [`JointBench::cycle`] is one 1 ms DC cycle (20 current-loop ticks, then
/// the drive cycle).
pub struct JointBench {
    /// The drive (its `hw.joint` is the plant).
    pub app: JointApp,
    /// The dictionary the master would write through PDOs and SDOs.
    pub od: Od<{ device::IMAGE }>,
}

impl JointBench {
    /// A bench with a joint of `params`; one cycle has run (transition 1 taken).
    pub fn new(params: BldcJointParams) -> Self {
        let mut b = Self {
            app: new_app(params),
            od: Od::new(&device::DEF).expect("the drive's definition is valid"),
        };
        b.cycle();
        b
    }

    /// One 1 ms cycle.
    pub fn cycle(&mut self) {
        for _ in 0..20 {
            self.app.hw.joint.step(TICK_NS as f64 * 1e-9);
            self.app.run_current_loop();
        }
        self.app.run_cycle(&mut self.od);
    }

    /// `n` cycles.
    pub fn run(&mut self, n: usize) {
        for _ in 0..n {
            self.cycle();
        }
    }

    /// Writes the controlword and runs one cycle; returns the statusword.
    pub fn command(&mut self, cw: u16) -> u16 {
        self.od.set(0x6040, 0, cw).expect("0x6040");
        self.cycle();
        self.statusword()
    }

    /// The statusword.
    pub fn statusword(&self) -> u16 {
        self.od.get::<u16>(0x6041, 0).unwrap_or(0)
    }

    /// Position actual value 0x6064.
    pub fn position(&self) -> i32 {
        self.od.get::<i32>(0x6064, 0).unwrap_or(0)
    }
}

/// The CiA402 joint drive in the registry.
pub const KIT: crate::registry::Kit = crate::registry::Kit {
    name: "cia402-joint",
    description: "CiA402 joint drive (ET1100) on a BLDC joint with a compliant harmonic \
                  gear, joint torque sensor, encoder with index, home switch \
                  (PP/PV/PT/HM/CSP/CSV/CST)",
    def: |_| &crate::cia402::DEF,
    esc: oxicat_esc::EscConfig::et1100,
    attach: |segment, id, _k, route| match route {
        PdiRoute::Direct => attach(segment, id, BldcJointParams::default()).map(drop),
        route => attach_via(segment, id, BldcJointParams::default(), route).map(drop),
    },
    sync: oxicat_slave::SyncMode::DcSync0,
    cycle_ns: 1_000_000,
};
