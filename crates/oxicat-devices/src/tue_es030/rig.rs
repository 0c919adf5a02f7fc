//! The TUeES030 board on the virtual segment: the firmware host of `oxicat-sim` runs the
//! board's firmware (`crate::tue_es030`) on the slave stack behind its ESC and owns the
//! three motor channels it drives (`oxicat_plant::re30`: DRV8412 bridge, RE 30 motor,
//! LT1999 sense with its RC filter, encoder), the supply and the other I/O.
//!
//! # What happens when, in virtual time
//!
//! | event | what runs |
//! |---|---|
//! | ESC PDI IRQ (SM2 written) | `Slave::on_pdi_irq`: RxPDO → application → TxPDO (SM-synchronous) |
//! | tick every 50 µs (20 kHz, the PWM counter's top), on the firmware host's schedule | 1. the plants catch up ([`TuePlant`]) to now in [`TueConfig::substeps`] exact steps; the bridge duties the firmware wrote at the previous tick took effect at its counter bottom, 6.25 µs after it; 2. every 20th tick the 1 kHz service routine (encoders latched with their timestamps, line voltage); 3. the current loop (ADC2 sampled now) → new duties, effective 6.25 µs later; 4. the main loop (`Slave::poll`: ESM, mailbox, watchdog) |
//!
//! The line ([`TueConfig::line`]): by default the supply is stiff and also takes energy
//! back (a battery); with [`LineParams`] it is the board's bulk capacitor on a supply
//! that cannot sink current (`oxicat_plant::re30::Line`), so braking raises it, which the
//! firmware's over-voltage kill watches at 20 kHz.
//!
//! FoE: the firmware serves `firmware.bin` (BOOT only) and `version.txt` from two RAM
//! slots of [`SLOT_BYTES`] through `oxicat_slave::foe`'s update flow ([`files`]), the
//! factory image bootable in slot 0.
//!
//! At equal times ESC events come first (the segment's rule), then the tick in the order
//! above, so a run is a function of the frames and their virtual times only.

use crate::tue_es030::control::BoardRev;
use crate::tue_es030::{
    self, control, device, Adcs, Bridges, Encoders, Io, TuEs030, CURRENT_TIMER, SERVICE_TIMER,
};
use oxicat_esc::Esc;
use oxicat_plant::re30::{BridgeCommand, Re30Drive, Re30Params};
pub use oxicat_plant::re30::{Line, LineParams};
use oxicat_slave::foe::{FirmwareUpdate, RamStore, WithFoe};
use oxicat_slave::{DeviceDef, Slave};

use oxicat_sim::firmware::{
    attach_host, boot_stack, AttachError, Bench, FirmwareConfig, Host, HostHandle, Stack,
};
use oxicat_sim::pdi_path::{Direct, PdiPath, PdiRoute, SpiPath};
use oxicat_sim::segment::{Segment, SlaveId};

/// Mailbox size of the board (its definition: 128 bytes).
pub const MBX: usize = 128;
/// The board's stack on the firmware's `Pdi` of path `P` (the software ESC by default).
pub type TueSlave<P = Direct> = Slave<<P as PdiPath>::Pdi, { device::IMAGE }, MBX>;
/// Bytes per firmware slot of the simulated board.
pub const SLOT_BYTES: usize = 64 * 1024;
/// Name of the firmware file the board takes in BOOT.
pub const FIRMWARE_FILE: &str = crate::demo::rig::FIRMWARE_FILE;
/// The board's FoE files: the update flow on two RAM slots.
pub type TueFiles = FirmwareUpdate<RamStore<2, SLOT_BYTES>>;
/// The firmware on the bench hardware, with its FoE files (`app.board`, `app.motors`, …
/// through `Deref`; `app.files` the FoE side).
pub type TueApp = WithFoe<TuEs030<BenchBoard>, TueFiles>;

/// The FoE files of the simulated board: two RAM slots, the factory image (payload
/// `oxicat tue-es030 firmware <sw_version>`) bootable in slot 0, [`FIRMWARE_FILE`]
/// writable in BOOT, `version.txt` readable always.
pub fn files(def: &'static DeviceDef) -> TueFiles {
    crate::demo::rig::ram_files(def, "tue-es030")
}

/// Current-loop tick \[ns\] (20 kHz).
pub const TICK_NS: u64 = 50_000;
/// Ticks per service-routine run (1 kHz).
pub const TICKS_PER_SERVICE: u64 = 20;
/// Delay from the ADC sample (counter top) to the new duty (counter bottom) \[ns\]: half
/// an 80 kHz period.
pub const PWM_UPDATE_DELAY_NS: u64 = 6_250;

/// How the board is set up.
#[derive(Debug, Clone, PartialEq)]
pub struct TueConfig {
    /// Motor on M1, M2, M3.
    pub motors: [Re30Params; 3],
    /// Supply (line) voltage \[V\].
    pub supply: f64,
    /// Plant steps per 50 µs tick (a multiple of 8 keeps the 6.25 µs PWM update on a step
    /// boundary).
    pub substeps: u32,
    /// The board revision: which current scaling the firmware converts the PI gains with
    /// (default [`BoardRev::Sense42`], the one that reproduces the manual's FRF).
    pub board_rev: BoardRev,
    /// The line: `None` (default) a stiff supply that also sinks (a battery); `Some` the
    /// bulk capacitor on a supply that cannot sink ([`Line`]).
    pub line: Option<LineParams>,
    /// The firmware's over-voltage kill is active (default; `false` runs it without).
    pub kill: bool,
}

impl TueConfig {
    /// The default bench with every rotor held (the manual's "axis fixed" step tests).
    pub fn locked(mut self, locked: bool) -> Self {
        for m in &mut self.motors {
            m.locked = locked;
        }
        self
    }

    /// The bench with board revision `rev`.
    pub fn rev(mut self, rev: BoardRev) -> Self {
        self.board_rev = rev;
        self
    }

    /// The bench with the line `line` (see [`TueConfig::line`]).
    pub fn line(mut self, line: Option<LineParams>) -> Self {
        self.line = line;
        self
    }

    /// The bench with the firmware's over-voltage kill on or off.
    pub fn kill(mut self, kill: bool) -> Self {
        self.kill = kill;
        self
    }
}

impl Default for TueConfig {
    /// Maxon RE 30 310007 on every channel (M1 with its 5 mΩ sense), 24 V, 32 steps per
    /// tick (1.5625 µs), board revision [`BoardRev::Sense42`].
    fn default() -> Self {
        Self {
            motors: [
                Re30Params::maxon_310007_on_m1(),
                Re30Params::maxon_310007(),
                Re30Params::maxon_310007(),
            ],
            supply: 24.0,
            substeps: 32,
            board_rev: BoardRev::default(),
            line: None,
            kill: true,
        }
    }
}

/// The board's hardware as the firmware sees it, with the plant behind it.
#[derive(Debug, Clone)]
pub struct BenchBoard {
    /// Motor channels M1..M3.
    pub drives: [Re30Drive; 3],
    /// Supply voltage \[V\] (tests raise it to trip the kill threshold).
    pub supply: f64,
    /// The line's capacitor when the supply cannot sink ([`TueConfig::line`]).
    pub line: Option<Line>,
    /// The 5 V rail \[V\] (read back through ADC2 as the reference check).
    pub rail_5v: f64,
    /// ADC1 inputs (hall positions, forces, spare analog) in counts.
    pub adc1: [u16; 8],
    /// Digital inputs 0–3 from the outside.
    pub digin_low: u8,
    /// Last digital output byte.
    pub digout: u8,
    /// Last DAC codes.
    pub dac: [u16; 2],
    /// Caliper readings.
    pub calipers: [u16; 2],
    /// Bridge commands the firmware wrote, not yet at the counter's bottom.
    pending: [BridgeCommand; 3],
}

impl BenchBoard {
    fn new(cfg: &TueConfig) -> Self {
        Self {
            drives: cfg.motors.map(Re30Drive::new),
            supply: cfg.supply,
            line: cfg.line.map(|p| Line::new(p, cfg.supply)),
            rail_5v: 5.0,
            adc1: [0; 8],
            digin_low: 0,
            digout: 0,
            dac: [2048; 2],
            calipers: [0; 2],
            pending: [BridgeCommand::default(); 3],
        }
    }

    /// The line voltage now \[V\]: the supply, or the capacitor above it.
    pub fn line_voltage(&self) -> f64 {
        match &self.line {
            None => self.supply,
            Some(l) => l.voltage.max(self.supply),
        }
    }

    /// ADC2 counts of the line voltage (1/11 divider).
    pub fn line_counts(&self) -> u16 {
        (self.line_voltage() / control::LINE_DIVIDER as f64 / control::ADC_VREF as f64
            * control::ADC_COUNTS as f64)
            .clamp(0.0, 4095.0) as u16
    }
}

impl Bridges for BenchBoard {
    fn set_bridge(&mut self, ch: usize, cmp_a: u16, cmp_b: u16, enable: bool) {
        if let Some(p) = self.pending.get_mut(ch) {
            let top = control::PWMPER as f64;
            *p = BridgeCommand {
                duty_a: cmp_a as f64 / top,
                duty_b: cmp_b as f64 / top,
                enabled: enable,
            };
        }
    }
}

impl Adcs for BenchBoard {
    fn adc1(&mut self, ch: usize) -> u16 {
        self.adc1.get(ch).copied().unwrap_or(0)
    }
    fn adc2(&mut self, ch: usize) -> u16 {
        match ch {
            tue_es030::app::ADC2_LINE => self.line_counts(),
            tue_es030::app::ADC2_VREF5 => {
                (self.rail_5v / control::VREF5_DIVIDER as f64 / control::ADC_VREF as f64
                    * control::ADC_COUNTS as f64)
                    .clamp(0.0, 4095.0) as u16
            }
            3..=5 => self.drives[ch - 3].adc_counts(),
            _ => 0,
        }
    }
}

impl Encoders for BenchBoard {
    fn latch(&mut self, ch: usize) -> (u32, u32) {
        self.drives
            .get(ch)
            .map(|d| (d.count(), d.edge_timestamp()))
            .unwrap_or((0, 0))
    }
}

impl Io for BenchBoard {
    fn digin(&mut self) -> u8 {
        let d = &self.drives;
        let mut v = self.digin_low & 0x0F;
        if d[0].fault {
            v |= tue_es030::app::DI_M1_FAULT;
        }
        if d[0].otw {
            v |= tue_es030::app::DI_M1_OTW;
        }
        if d[1].fault || d[2].fault {
            v |= tue_es030::app::DI_M23_FAULT;
        }
        if d[1].otw || d[2].otw {
            v |= tue_es030::app::DI_M23_OTW;
        }
        v
    }
    fn digout(&mut self, v: u8) {
        self.digout = v;
    }
    fn dac(&mut self, ch: usize, code: u16) {
        if let Some(d) = self.dac.get_mut(ch) {
            *d = code;
        }
    }
    fn calipers(&mut self) -> [u16; 2] {
        self.calipers
    }
}

/// The three motor channels on the host: at each 20 kHz tick, before the firmware's
/// timers run, the plants catch up to now in exact substeps; the bridge duties the current
/// loop wrote at the previous tick take effect at its counter bottom,
/// [`PWM_UPDATE_DELAY_NS`] after it.
#[derive(Debug, Clone, Copy)]
pub struct TuePlant {
    substeps: u32,
    /// Plant time \[ns\] (`None` until the first tick).
    plant_ns: Option<u64>,
    /// From this plant time on, the bridges take the pending duties.
    apply_at: u64,
}

impl TuePlant {
    fn new(cfg: &TueConfig) -> Self {
        Self {
            substeps: cfg.substeps,
            plant_ns: None,
            apply_at: 0,
        }
    }
}

/// The board's image: stack and firmware.
pub type TueImage<P = Direct> = Stack<<P as PdiPath>::Pdi, TueApp, { device::IMAGE }, MBX>;

impl<Pd: oxicat_slave::Pdi> Bench<Stack<Pd, TueApp, { device::IMAGE }, MBX>> for TuePlant {
    fn before_timers(&mut self, image: &mut Stack<Pd, TueApp, { device::IMAGE }, MBX>, t: u64) {
        let n = self.substeps.max(1) as u64;
        let h_ns = TICK_NS / n;
        let plant_ns = self.plant_ns.get_or_insert(t);
        let b = &mut image.app.board;
        while *plant_ns + h_ns <= t {
            if *plant_ns >= self.apply_at {
                for (d, p) in b.drives.iter_mut().zip(b.pending) {
                    d.bridge = p;
                }
            }
            let supply = b.line_voltage();
            for d in &mut b.drives {
                d.step(h_ns as f64 * 1e-9, supply);
            }
            if let Some(line) = &mut b.line {
                let bridges = b.drives.iter().map(|d| d.bus_current).sum();
                line.step(h_ns as f64 * 1e-9, b.supply, bridges);
            }
            *plant_ns += h_ns;
        }
    }

    fn after_timers(&mut self, _image: &mut Stack<Pd, TueApp, { device::IMAGE }, MBX>, t: u64) {
        self.apply_at = t + PWM_UPDATE_DELAY_NS;
    }
}

/// The board on its host: stack, firmware and plant, reaching its ESC through `P`
/// (`image.slave`, `image.app`, or through `Deref`: `slave`, `app`).
pub type TueBoard<P = Direct> = Host<TueImage<P>, P, TuePlant>;

/// Access to the board from outside the segment.
pub type TueHandle<P = Direct> = HostHandle<TueImage<P>, P, TuePlant>;

/// The host's schedule on the 50 µs grid: at each tick the 1 kHz service routine (every
/// 20th tick, the first one included), the current loop, then the main loop.
fn schedule() -> FirmwareConfig {
    FirmwareConfig::default()
        .aligned(TICK_NS)
        .timer_from(SERVICE_TIMER, TICK_NS * TICKS_PER_SERVICE, 0)
        .timer_from(CURRENT_TIMER, TICK_NS, 0)
        .poll_every(TICK_NS)
}

/// Boots the TUeES030 firmware on ESC `id` of `segment` with the bench `config`; the
/// ticks start at the next multiple of 50 µs.
pub fn attach(
    segment: &mut Segment,
    id: SlaveId,
    config: &TueConfig,
) -> Result<TueHandle, AttachError> {
    attach_with(segment, id, config, |_| Ok(Direct))
}

/// [`attach`] with the firmware reaching its ESC through the chip driver of `route` over
/// the simulated SPI (`PdiRoute::Direct` is refused: use [`attach`]).
pub fn attach_via(
    segment: &mut Segment,
    id: SlaveId,
    config: &TueConfig,
    route: PdiRoute,
) -> Result<TueHandle<SpiPath>, AttachError> {
    attach_with(segment, id, config, |esc| SpiPath::new(route, esc))
}

fn attach_with<P: PdiPath>(
    segment: &mut Segment,
    id: SlaveId,
    config: &TueConfig,
    path: impl FnOnce(&mut Esc) -> Result<P, oxicat_sim::pdi_path::PathInitError>,
) -> Result<TueHandle<P>, AttachError> {
    let plant = TuePlant::new(config);
    attach_host(segment, id, &schedule(), plant, path, |esc, path| {
        let mut app = TuEs030::with_rev(BenchBoard::new(config), config.board_rev);
        if !config.kill {
            app.kill_counts = u16::MAX;
        }
        let app = WithFoe {
            app,
            files: files(&device::DEF),
        };
        boot_stack(&device::DEF, esc, app, path)
    })
}

/// The TUeES030 board in the registry.
pub const KIT: crate::registry::Kit = crate::registry::Kit {
    name: "tue-es030",
    description: "TUeES030 motor I/O board (ET1200) with three Maxon RE 30 motors on its \
                  bridges (current loops, encoders, line voltage; normal/FRF PDO modes)",
    def: |_| &crate::tue_es030::device::DEF,
    esc: oxicat_esc::EscConfig::et1200,
    attach: |segment, id, _k, route| match route {
        PdiRoute::Direct => attach(segment, id, &TueConfig::default()).map(drop),
        route => attach_via(segment, id, &TueConfig::default(), route).map(drop),
    },
    sync: oxicat_slave::SyncMode::SmSync,
    cycle_ns: 1_000_000,
};
