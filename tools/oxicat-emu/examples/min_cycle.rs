//! The shortest DC cycle a board image sustains, measured in the loop: one emulated node —
//! the Laelaps leg node (`firmware/laelaps-leg`, LAN9252 on SPI1 at the image's 22.5 MHz,
//! its leg on the pins) or the CiA402 joint (`firmware/cia402-joint`, ET1100 on SPI1 at the
//! image's 11.25 MHz or, with `--spi-mhz`, at another clock as a what-if; its joint on the
//! pins) — ethercrab in DC mode, SYNC0 every `cycle`, `n` cycles counted in steady OP (from
//! 200 cycles after OP), for cycles from the kit's down to the device's minimum (0x1C32:05:
//! leg 100 µs, joint 250 µs). A cycle is sustained when
//! every cycle has the right working counter, the image's SYNC0 handler (EXTI3) ran once for
//! every SYNC0 pulse the segment delivered (a pulse that comes while the previous one is
//! still pending is lost), its longest run (entry to return, joint-loop ticks included)
//! is shorter than the cycle, and — the joint — its 20 kHz current loop ran once per ADC
//! sequence; the answer is the shortest cycle sustained with every longer one.
//!
//! Printed per cycle: WKC errors, SYNC0 pulses and handler runs, the handler's mean and
//! longest span at 180 MHz (with the joint-loop ticks that preempt it), its share of the
//! cycle, and the share of the run the CPU was awake; then the shortest sustained cycle
//! (the thesis' F28379D node: 200 µs minimum, 85 µs of stack time per cycle).
//!
//! The axis hub (`firmware/axis-hub`, LAN9252, no sensors on its 1-Wire line) from its 10 ms
//! kit cycle down to its 1 ms minimum, in DC mode.
//!
//! `cargo run --release -p oxicat-emu --example min_cycle [laelaps-leg|cia402-joint|axis-hub] [elf]
//! [cycles per step] [--spi-mhz MHZ]` (the master refuses cycles below a slave's
//! 0x1C32:05, so the device's minimum is the floor).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_devices::laelaps::rig::{LegId, RigConfig};
use oxicat_devices::laelaps::{device, Side};
use oxicat_emu::cia402::JointBoardPlant;
use oxicat_emu::laelaps::LegBoardPlant;
use oxicat_emu::node::EmulatedNode;
use oxicat_emu::trot::EXC_SYNC0;
use oxicat_emu::ChipKind;
use oxicat_emu::{HandlerStats, CPU_HZ};
use oxicat_esc::{Esc, EscConfig};
use oxicat_master::cyclic::{CycleOptions, Flow};
use oxicat_master::{Link, Master};
use oxicat_sim::segment::Segment;

/// Cycles in OP before the count starts.
const WARM: u64 = 200;

/// What one cycle time gave.
struct Step {
    cycle_us: u64,
    wkc_errors: u64,
    pulses: u64,
    handled: u64,
    mean_us: f64,
    max_us: f64,
    awake: f64,
    /// ADC sequences without a current-loop tick, and the longest JEOC → handler time
    /// [µs] (the CiA402 joint's 20 kHz loop; none on the leg node).
    current_loop: Option<(u64, f64)>,
}

impl Step {
    /// SYNC0 pulses without a handler run; the last pulse's handler may still be pending
    /// when the counts are read (the segment delivers the pulse, the board enters the
    /// handler after it), so one short is not a loss.
    fn lost(&self) -> u64 {
        self.pulses.saturating_sub(self.handled + 1)
    }

    /// Right WKC every cycle, no SYNC0 lost, every handler done within its cycle (the
    /// next pulse does not find it still running), and on the joint no current-loop tick
    /// lost (a sequence still converting when the counts are read is not a loss).
    fn sustained(&self, cycles: u64) -> bool {
        self.wkc_errors == 0
            && self.lost() == 0
            && self.pulses + 1 >= cycles
            && self.max_us < self.cycle_us as f64
            && self.current_loop.is_none_or(|(lost, _)| lost <= 1)
    }
}

/// The board image under test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Dev {
    /// The Laelaps II leg node (LAN9252).
    Leg,
    /// The CiA402 joint (ET1100).
    Joint,
    /// The axis hub (LAN9252; DC-capable, free run by default; no sensors on its line).
    Hub,
}

impl Dev {
    fn name(self) -> &'static str {
        match self {
            Dev::Leg => "laelaps-leg",
            Dev::Joint => "cia402-joint",
            Dev::Hub => "axis-hub",
        }
    }

    fn def(self) -> &'static oxicat_slave::DeviceDef {
        match self {
            Dev::Leg => device::device(Side::Right),
            Dev::Joint => &oxicat_devices::cia402::DEF,
            Dev::Hub => &oxicat_devices::axis_hub::device::DEF,
        }
    }

    /// The cycles tried, longest first (the kit's cycle down).
    fn cycles_us(self) -> &'static [u64] {
        match self {
            Dev::Leg => &[400, 300, 250, 200, 175, 150, 140, 130, 125, 110, 100],
            Dev::Joint => &[1000, 750, 500, 400, 350, 300, 275, 250],
            Dev::Hub => &[10_000, 4000, 2000, 1000],
        }
    }
}

fn step(
    dev: Dev,
    img: &[u8],
    cycle_us: u64,
    cycles: u64,
    spi_hz: Option<u32>,
) -> Result<Step, String> {
    let sii = oxicat_esi::sii::generate(dev.def()).map_err(|e| e.to_string())?;
    let mut seg = Segment::new();
    let (node, boot_ns) = match dev {
        Dev::Leg => {
            let leg = LegId::ForeRight;
            let plant = LegBoardPlant::new(leg, RigConfig::laelaps(leg));
            let node = EmulatedNode::with_plant(img.to_vec(), 100_000, Some(Box::new(plant)));
            // Power-on wait, LAN9252 reset.
            (node, 100_000_000)
        }
        Dev::Joint => {
            let plant = JointBoardPlant::new(Default::default());
            let node = EmulatedNode::with_chip(
                img.to_vec(),
                100_000,
                Some(Box::new(plant)),
                ChipKind::Et1100,
            );
            // Current-sense calibration, 500 ms alignment, the ET1100's init.
            (node, 800_000_000)
        }
        Dev::Hub => {
            // Boot to the task tick under 0.7 s of board time (README).
            (EmulatedNode::new(img.to_vec(), 100_000), 800_000_000)
        }
    };
    let esc = match dev {
        Dev::Leg | Dev::Hub => EscConfig::lan9252(),
        Dev::Joint => EscConfig::et1100(),
    };
    let id = seg.add(Esc::new(esc, sii));
    let node = node.map_err(|e| e.to_string())?;
    let h = node.handle();
    h.set_spi_sclk_hz(spi_hz);
    seg.attach(id, Box::new(node))
        .map_err(|e| format!("{e:?}"))?;
    // The board boots before the master starts.
    seg.advance_to(boot_ns);
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).map_err(|e| e.to_string())?;
    // Counted in steady OP: from WARM cycles after OP (the transitions before it run the
    // stack's poll with the ESC handlers masked) to WARM + `cycles`, both inside the loop
    // (after it the master takes the slave back to PRE-OP).
    type Snap = (u64, oxicat_emu::node::NodeReport);
    let mut snaps: Vec<Snap> = Vec::new();
    let mut err = None;
    let stats = m
        .run_cyclic(
            CycleOptions {
                cycle: Duration::from_micros(cycle_us),
                dc: true,
            },
            |io| {
                if io.cycle == WARM {
                    h.reset_stats();
                }
                if io.cycle == WARM || io.cycle == WARM + cycles {
                    match h.report() {
                        Some(r) => snaps.push((h.sync0_events(), r)),
                        None => err = Some("the board thread ended".to_string()),
                    }
                }
                Ok(if io.cycle >= WARM + cycles {
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            },
        )
        .map_err(|e| e.to_string())?;
    if let Some(e) = err {
        return Err(e);
    }
    let [(pulses0, before), (pulses1, r)] =
        <[Snap; 2]>::try_from(snaps).map_err(|s| format!("{} snapshots", s.len()))?;
    if let Some(f) = &r.fault {
        return Err(f.to_string());
    }
    let taken0 = before.taken[usize::from(EXC_SYNC0)];
    let s0 = r.handler(EXC_SYNC0);
    let cyc = (r.cycles - before.cycles).max(1);
    let slept = r.slept_cycles - before.slept_cycles;
    Ok(Step {
        cycle_us,
        wkc_errors: stats.wkc_errors,
        pulses: pulses1 - pulses0,
        handled: r.taken[usize::from(EXC_SYNC0)] - taken0,
        mean_us: s0.mean_us(CPU_HZ),
        max_us: HandlerStats::us(s0.max_cycles, CPU_HZ),
        awake: 1.0 - slept as f64 / cyc as f64,
        current_loop: (r.adc_sequences > before.adc_sequences).then(|| {
            let adc = usize::from(16 + oxicat_emu::adc::IRQ);
            let ticks = r.taken[adc] - before.taken[adc];
            (
                (r.adc_sequences - before.adc_sequences).saturating_sub(ticks),
                HandlerStats::us(r.adc_irq_latency_max, CPU_HZ),
            )
        }),
    })
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut spi_hz = None;
    if let Some(k) = args.iter().position(|a| a == "--spi-mhz") {
        let v = args.get(k + 1).and_then(|v| v.parse::<f64>().ok());
        match v {
            Some(mhz) if (0.1..=100.0).contains(&mhz) => spi_hz = Some((mhz * 1e6) as u32),
            _ => {
                eprintln!("--spi-mhz: a clock in MHz, 0.1..=100");
                std::process::exit(2);
            }
        }
        args.drain(k..k + 2);
    }
    let mut args = args.into_iter().peekable();
    let dev = match args.peek().map(String::as_str) {
        Some("cia402-joint") => {
            args.next();
            Dev::Joint
        }
        Some("laelaps-leg") => {
            args.next();
            Dev::Leg
        }
        Some("axis-hub") => {
            args.next();
            Dev::Hub
        }
        _ => Dev::Leg,
    };
    let path = args.next().unwrap_or_else(|| {
        format!(
            "{}/../../firmware/target/thumbv7em-none-eabihf/release/oxicat-firmware-{}",
            env!("CARGO_MANIFEST_DIR"),
            dev.name()
        )
    });
    let cycles: u64 = match args.next().map(|a| a.parse()) {
        None => 2_000,
        Some(Ok(n)) if n > 0 => n,
        Some(_) => {
            eprintln!("cycles per step: a positive number");
            std::process::exit(2);
        }
    };
    let img = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) => {
            eprintln!(
                "{path}: {e} (build it: cd firmware/{} && cargo build --release --locked)",
                dev.name()
            );
            std::process::exit(2);
        }
    };
    let min_us = u64::from(dev.def().sync.min_cycle_ns) / 1000;
    let spi = match (dev, spi_hz) {
        (_, Some(hz)) => format!("SPI1 at {:.2} MHz (what-if)", f64::from(hz) / 1e6),
        (Dev::Leg | Dev::Hub, None) => "LAN9252, SPI1 at the image's 22.5 MHz".to_string(),
        (Dev::Joint, None) => "ET1100, SPI1 at the image's 11.25 MHz".to_string(),
    };
    println!(
        "{} image, {spi}, {cycles} DC cycles per step, one node:\n",
        dev.name()
    );
    println!("| cycle [µs] | WKC errors | SYNC0 pulses | SYNC0 handler runs | lost | handler mean / max [µs] | max / cycle | CPU awake | sustained | current-loop ticks lost, JEOC → handler max |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    // The shortest cycle with every longer one sustained too.
    let mut shortest = None;
    let mut all_ok = true;
    for &cycle_us in dev.cycles_us() {
        if cycle_us < min_us {
            break;
        }
        match step(dev, &img, cycle_us, cycles, spi_hz) {
            Ok(s) => {
                let ok = s.sustained(cycles);
                println!(
                    "| {} | {} | {} | {} | {} | {:.1} / {:.1} | {:.0} % | {:.0} % | {} | {} |",
                    s.cycle_us,
                    s.wkc_errors,
                    s.pulses,
                    s.handled,
                    s.lost(),
                    s.mean_us,
                    s.max_us,
                    100.0 * s.max_us / s.cycle_us as f64,
                    100.0 * s.awake,
                    if ok { "yes" } else { "no" },
                    match s.current_loop {
                        Some((lost, lat)) => format!("{lost}, {lat:.1} µs"),
                        None => "–".to_string(),
                    }
                );
                all_ok &= ok;
                if all_ok {
                    shortest = Some(cycle_us);
                }
            }
            Err(e) => {
                all_ok = false;
                println!("| {cycle_us} | – | – | – | – | – | – | – | no: {e} | – |")
            }
        }
    }
    match shortest {
        Some(c) => println!("\nShortest sustained DC cycle: {c} µs (device minimum {min_us} µs)."),
        None => println!("\nNo cycle sustained."),
    }
}
