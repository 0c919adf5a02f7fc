//! The Laelaps II trot (`oxicat trot`, thesis §4) with the four leg nodes' board images in
//! the loop: the same scenario, procedure, master, CSV and figures as the host-compiled run
//! (`oxicat_devices::laelaps::experiment::run_trot_on`), but each tower is the leg-node
//! image (`firmware/laelaps-leg`, its side's build) executed instruction by instruction on
//! an emulated STM32F446 with a LAN9252 on SPI1 ([`EmulatedNode`]), driving its leg through
//! PWM, direction pins and encoders ([`LegBoardPlant`], with the scenario's rig: plant rate,
//! belt profile).
//!
//! Per node the run reports what the image did over the recorded cycles ([`ImageLegFigures`],
//! [`markdown`]): SYNC0 pulses against SYNC0 handler runs (a lost SYNC0 is a pulse whose
//! handler never ran), the SYNC0 handler's time at 180 MHz (executed instructions and the
//! SPI bytes it waited for), the 10 kHz joint loop's load, the deepest stack (painted), and
//! the image's flash and RAM.
//!
//! Differences from the host-compiled run, by construction: the firmware takes time (its
//! SPI frames and instructions), so its inputs land later in the cycle; the host rig lets
//! the leg go when the node's application goes Operational, while a board shows only its
//! pins — [`LegBoardPlant`] lets it go at the first non-zero duty, and the belt profile runs
//! from there; and the image's trajectory clock is read from its `Time` input (10 ms steps).

use std::sync::{Arc, Mutex};

use oxicat_devices::laelaps::experiment::{
    run_trot_on, NodePdi, PdiReport, Progress, TrotNode, TrotNodeReport, TrotRun,
};
use oxicat_devices::laelaps::rig::LegId;
use oxicat_devices::laelaps::scenario::Scenario;
use oxicat_devices::laelaps::Side;
use oxicat_esc::{Esc, EscConfig};
use oxicat_master::MasterError;
use oxicat_pdi::sim::BusConfig;
use oxicat_sim::pdi_path::PdiRoute;

use crate::laelaps::{LegBoardPlant, LegState};
use crate::node::{EmulatedNode, NodeHandle, NodeReport};
use crate::{EmuError, HandlerStats, SpiStats, CPU_HZ};

/// SYNC0 on the leg-node board: EXTI3 (IRQ 9), exception 25.
pub const EXC_SYNC0: u16 = 16 + 9;
/// The 10 kHz joint loop: TIM6 (IRQ 54), exception 70.
pub const EXC_JOINT_LOOP: u16 = 16 + 54;
/// The LAN9252's PDI IRQ: EXTI15_10 (IRQ 40), exception 56.
pub const EXC_PDI_IRQ: u16 = 16 + 40;
/// The NVIC priority of the image's three ESC handlers (SYNC0, SYNC1, PDI IRQ;
/// `PRIO_ESC` in `firmware/laelaps-leg`): what the thread masks while it uses the stack.
pub const PRIO_ESC: u8 = 0x20;
/// SYNC0's EXTI line (PB3).
pub const EXTI_LINE_SYNC0: u8 = 3;

/// The boards boot before the master starts \[ns\]: the image's 50 ms power-on wait, then
/// the LAN9252's digital reset and start-up (a master that came first would lose the
/// station addresses it set to that reset).
const POWER_ON_NS: u64 = 100_000_000;

/// SPI1's clock in the leg-node image (PCLK2 90 MHz / 4), for the report's route; the
/// bytes' times come from the image's own prescaler setting.
pub const LEG_IMAGE_SCLK_HZ: u32 = 22_500_000;

/// How often an emulated board is woken besides the segment's events \[ns\].
const SLICE_NS: u64 = 100_000;

/// The two builds of the leg-node image (thesis `LEFT_LEG` / `RIGHT_LEG`).
#[derive(Clone)]
pub struct LegImages {
    left: Vec<u8>,
    right: Vec<u8>,
}

impl LegImages {
    /// The left and right builds, checked: each must be an image for the board and carry
    /// its side (`OXICAT_LEG_SIDE`, `L` or `R`) — swapped or wrong-side images are refused,
    /// as they would drive their legs against the sign conventions.
    pub fn new(left: Vec<u8>, right: Vec<u8>) -> Result<Self, EmuError> {
        for (img, want, name) in [(&left, b'L', "left"), (&right, b'R', "right")] {
            match crate::elf_symbol_bytes(img, "OXICAT_LEG_SIDE")?.as_deref() {
                Some([s]) if *s == want => {}
                Some([s]) => {
                    return Err(EmuError::BadImage(format!(
                        "the {name} leg's image is the {} build (OXICAT_LEG_SIDE = {:?})",
                        if *s == b'L' { "left" } else { "right" },
                        char::from(*s)
                    )))
                }
                _ => {
                    return Err(EmuError::BadImage(format!(
                        "the {name} leg's image has no OXICAT_LEG_SIDE: not a leg-node build \
                         of firmware/laelaps-leg"
                    )))
                }
            }
        }
        Ok(LegImages { left, right })
    }

    /// The image for a leg on `side`.
    pub fn for_side(&self, side: Side) -> &[u8] {
        match side {
            Side::Left => &self.left,
            Side::Right => &self.right,
        }
    }
}

/// One tower's board image on the trot's segment.
struct ImageLeg {
    leg: LegId,
    node: NodeHandle,
    state: Arc<Mutex<LegState>>,
    /// The SPI traffic when the record started.
    spi_base: Mutex<SpiStats>,
    /// The figures as of the last [`TrotNode::trot_report`]: the run asks once at its end,
    /// before the segment (and with it the board thread) goes.
    last: Arc<Mutex<Option<Result<ImageLegFigures, String>>>>,
}

impl TrotNode for ImageLeg {
    fn trot_report(&self) -> TrotNodeReport {
        let report = self.node.report();
        let base = *self.spi_base.lock().unwrap_or_else(|e| e.into_inner());
        let spi = report.as_ref().map(|r| {
            let bytes = r.spi.bytes - base.bytes;
            oxicat_pdi::sim::BusStats {
                transactions: r.spi.frames - base.frames,
                bytes,
                ps: bytes * 8 * (1_000_000_000_000 / u64::from(r.spi_sclk_hz.max(1))),
                protocol_errors: self.node.bus_stats().protocol_errors,
            }
        });
        let figures = match report {
            None => Err(format!("{}: the board thread ended", self.leg.code())),
            Some(report) => match &report.fault {
                Some(f) => Err(format!("{}: the board image stopped: {f}", self.leg.code())),
                None => Ok(ImageLegFigures {
                    leg: self.leg,
                    sync0_pulses: self.node.sync0_events(),
                    leg_state: *self.state.lock().unwrap_or_else(|e| e.into_inner()),
                    report,
                }),
            },
        };
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = Some(figures);
        TrotNodeReport {
            clock_ns: None,
            released_at_sync0: None,
            pdi: NodePdi {
                pdi_errors: 0,
                spi,
                timing: None,
                sync1: None,
                input_sync: None,
            },
        }
    }

    fn reset_stats(&self) {
        if let Some(r) = self.node.report() {
            *self.spi_base.lock().unwrap_or_else(|e| e.into_inner()) = r.spi;
        }
        self.node.reset_bus_stats();
        self.node.reset_stats();
    }
}

/// What one leg node's image did in a run (handler times and stack: the recorded cycles).
#[derive(Debug, Clone)]
pub struct ImageLegFigures {
    /// The leg its tower drives.
    pub leg: LegId,
    /// The board's figures at the end.
    pub report: NodeReport,
    /// SYNC0 pulses the segment delivered to the node (since boot).
    pub sync0_pulses: u64,
    /// The leg at the end (release time, plant steps, encoder events).
    pub leg_state: LegState,
}

impl ImageLegFigures {
    /// SYNC0 pulses whose handler never ran (since boot).
    pub fn sync0_lost(&self) -> u64 {
        self.sync0_pulses
            .saturating_sub(self.report.taken[usize::from(EXC_SYNC0)])
    }
}

/// Runs scenario `s` with the leg-node images; returns the run and the figures of each
/// node (Table 4-1 order FL, FR, HL, HR).
pub fn run(
    s: &Scenario,
    images: &LegImages,
    progress: &mut dyn FnMut(Progress),
) -> Result<(TrotRun, Vec<ImageLegFigures>), MasterError> {
    type Slot = Arc<Mutex<Option<Result<ImageLegFigures, String>>>>;
    let mut slots: Vec<(LegId, Slot)> = Vec::new();
    let pdi = PdiReport {
        route: PdiRoute::Lan9252 {
            bus: BusConfig {
                sclk_hz: LEG_IMAGE_SCLK_HZ,
                cs_overhead_ns: 0,
            },
            fast_read: false,
        },
        machine_code: true,
        ..PdiReport::default()
    };
    let run = run_trot_on(s, progress, pdi, POWER_ON_NS, &mut |seg, leg, sii, rig| {
        let id = seg.add(Esc::new(EscConfig::lan9252(), sii));
        let plant = LegBoardPlant::new(leg, rig);
        let state = plant.observer();
        let image = images.for_side(leg.side()).to_vec();
        let node = EmulatedNode::with_plant(image, SLICE_NS, Some(Box::new(plant)))
            .map_err(|e| MasterError::Usage(format!("{}: {e}", leg.code())))?;
        let node_handle = node.handle();
        seg.attach(id, Box::new(node))
            .map_err(|e| MasterError::Usage(format!("tower {id}: {e:?}")))?;
        let last = Slot::default();
        slots.push((leg, last.clone()));
        Ok(Box::new(ImageLeg {
            leg,
            node: node_handle,
            state,
            spi_base: Mutex::default(),
            last,
        }) as Box<dyn TrotNode>)
    })?;
    let mut figures = Vec::new();
    for leg in LegId::TABLE {
        let Some((_, slot)) = slots.iter().find(|n| n.0 == leg) else {
            continue;
        };
        let f = slot
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
            .unwrap_or_else(|| Err(format!("{}: no figures", leg.code())));
        figures.push(f.map_err(MasterError::Usage)?);
    }
    Ok((run, figures))
}

/// The per-node section of `summary.md`.
pub fn markdown(run: &TrotRun, figures: &[ImageLegFigures]) -> String {
    use std::fmt::Write;
    let us = |c: u64| HandlerStats::us(c, CPU_HZ);
    let mut o = String::new();
    let _ = writeln!(
        o,
        "\n## Board images\n\nEach leg node ran `firmware/laelaps-leg` (its side's build) \
         instruction by instruction on an emulated STM32F446 at {} MHz with a LAN9252 on SPI \
         ({}); handler times, loads and stack over the recorded cycles, SYNC0 since boot:\n",
        CPU_HZ / 1_000_000,
        run.pdi.route
    );
    let _ = writeln!(
        o,
        "| leg | SYNC0 pulses | SYNC0 lost (EXTI3 edges lost) | SYNC0 handler mean / max [µs] | joint loop (10 kHz) mean / max [µs], load | PDI IRQ runs | CPU awake (whole run) | ESC handlers masked by the thread, longest [µs] (since boot, where) | stack deepest [B] | flash / RAM [B] | instructions |"
    );
    let _ = writeln!(o, "|---|---|---|---|---|---|---|---|---|---|---|");
    for f in figures {
        let r = &f.report;
        let s0 = r.handler(EXC_SYNC0);
        let jl = r.handler(EXC_JOINT_LOOP);
        let span = r.cycles.saturating_sub(r.stats_since_cycle).max(1);
        let busy = 1.0 - r.slept_cycles as f64 / r.cycles.max(1) as f64;
        let (masked, masked_fn) = r.masked(PRIO_ESC);
        let _ = writeln!(
            o,
            "| {} | {} | {} ({}) | {:.1} / {:.1} | {:.1} / {:.1}, {:.1} % | {} | {:.1} % | {:.1} (at {:.2} ms, {}) | {} | {} / {} | {} |",
            f.leg.code(),
            f.sync0_pulses,
            f.sync0_lost(),
            r.lost_edges_on(EXTI_LINE_SYNC0),
            s0.mean_us(CPU_HZ),
            us(s0.max_cycles),
            jl.mean_us(CPU_HZ),
            us(jl.max_cycles),
            100.0 * jl.own_cycles as f64 / span as f64,
            r.handler(EXC_PDI_IRQ).runs,
            100.0 * busy,
            us(masked.max_cycles),
            us(masked.start_cycle) * 1e-3,
            masked_fn.unwrap_or("?"),
            r.stack.max_depth,
            r.image.flash,
            r.image.ram,
            r.instructions
        );
    }
    o
}
