//! Per-node figures of the Laelaps II leg image in the loop (`firmware/laelaps-leg`, built
//! first): one emulated leg node with its leg on the board's pins, ethercrab in DC mode at
//! 400 µs, the trot (Table 4-1, Transition_time 1 s): Configuration for 1.1 s, then
//! `State_Machine = 1` for `secs` seconds (default 2). Printed, from the emulator's clock
//! (one cycle per instruction at 180 MHz, plus SPI wait and exception entry/return):
//!
//! - the SYNC0 handler (EXTI3): from its entry to its exception return, with the joint-loop
//!   ticks that preempted it and without them;
//! - the 10 kHz joint loop's load: share of the cycles in TIM6_DAC's own code;
//! - the stack high-water mark by a painted stack: since reset (start-up included) and in
//!   the loop (repainted below the SP when the measurement window starts);
//! - flash and static RAM from the ELF.
//!
//! `cargo run --release -p oxicat-emu --example laelaps_loop [elf] [secs]`

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use oxicat_devices::laelaps::experiment::pdo_place;
use oxicat_devices::laelaps::rig::{LegId, RigConfig, KIT};
use oxicat_devices::laelaps::scenario::Scenario;
use oxicat_devices::laelaps::{device, Side};
use oxicat_emu::laelaps::LegBoardPlant;
use oxicat_emu::node::EmulatedNode;
use oxicat_emu::{HandlerStats, CPU_HZ};
use oxicat_esc::{Esc, EscConfig};
use oxicat_master::cyclic::{CycleOptions, Flow};
use oxicat_master::{Link, Master};
use oxicat_sim::segment::Segment;

const EXTI3: u16 = 16 + 9;
const TIM6_DAC: u16 = 16 + 54;
const EXTI15_10: u16 = 16 + 40;

fn put(image: &mut [u8], index: u16, sub: u8, v: i64) {
    let def = device::device(Side::Right);
    let Some(p) = pdo_place(def, true, index, sub) else {
        return;
    };
    if p.bits == 1 {
        let (byte, b) = (p.bit / 8, p.bit % 8);
        image[byte] = (image[byte] & !(1 << b)) | (u8::from(v != 0) << b);
        return;
    }
    let n = usize::from(p.bits) / 8;
    image[p.bit / 8..p.bit / 8 + n].copy_from_slice(&v.to_le_bytes()[..n]);
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../firmware/target/thumbv7em-none-eabihf/release/oxicat-firmware-laelaps-leg"
        )
        .to_string()
    });
    let secs: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(2.0);
    let img = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) => {
            eprintln!(
                "{path}: {e} (build it: cd firmware/laelaps-leg && cargo build --release --locked)"
            );
            std::process::exit(2);
        }
    };
    let leg = LegId::ForeRight;
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(device::device(Side::Right)).expect("SII");
    let id = seg.add(Esc::new(EscConfig::lan9252(), sii));
    let plant = LegBoardPlant::new(leg, RigConfig::laelaps(leg));
    let node = match EmulatedNode::with_plant(img, 100_000, Some(Box::new(plant))) {
        Ok(n) => n,
        Err(e) => {
            eprintln!("{path}: {e}");
            std::process::exit(2);
        }
    };
    let h = node.handle();
    seg.attach(id, Box::new(node)).expect("attach");
    let mut boot = h.report().expect("board");

    let s = Scenario::thesis();
    let (t, c) = (s.leg(leg), &s.control);
    let cyc = f64::from(KIT.cycle_ns) * 1e-9;
    let settle = (1.1 / cyc) as u64;
    let end = settle + (secs / cyc) as u64;
    let wall = Instant::now();
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).expect("ethercrab scans");
    let mut window_from = 0u64;
    let stats = m
        .run_cyclic(
            CycleOptions {
                cycle: Duration::from_nanos(u64::from(KIT.cycle_ns)),
                dc: true,
            },
            |io| {
                let k = io.cycle;
                let op = k + 1 >= settle;
                let o = &mut io.outputs[0];
                let r = |v: f64| v.round() as i64;
                put(o, 0x7000, 1, i64::from(op));
                put(o, 0x7000, 9, 1);
                put(o, 0x7012, 1, i64::from(c.filter_hz));
                for (i, g) in [
                    c.knee.kp * 100.0,
                    c.knee.kd * 1000.0,
                    c.knee.ki * 100.0,
                    c.hip.kp * 100.0,
                    c.hip.kd * 1000.0,
                    c.hip.ki * 100.0,
                ]
                .into_iter()
                .enumerate()
                {
                    put(o, 0x7020, i as u8 + 1, r(g));
                }
                let (a, b) = if op { (t.a_cm, t.b_cm) } else { (0.0, 0.0) };
                for (i, v) in [
                    t.x_centre_cm * 10.0,
                    t.y_centre_cm * 10.0,
                    a,
                    b,
                    t.freq_hz * 100.0,
                    t.phase_deg,
                    t.flatness * 100.0,
                ]
                .into_iter()
                .enumerate()
                {
                    put(o, 0x7030, i as u8 + 1, r(v));
                }
                if k == settle {
                    // The window: the node in OP, the trot starting.
                    if let Some(b) = h.report() {
                        boot = b;
                    }
                    h.reset_stats();
                    window_from = k;
                }
                Ok(if k + 1 >= end {
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            },
        )
        .expect("cyclic run");
    let r = h.report().expect("board");
    let us = |c: u64| HandlerStats::us(c, CPU_HZ);
    let s0 = r.handler(EXTI3);
    let jl = r.handler(TIM6_DAC);
    let pdi = r.handler(EXTI15_10);
    println!(
        "Laelaps leg image in the loop: {} DC cycles of 400 µs ({} in the window), {} WKC errors, {:.1} s wall",
        stats.cycles,
        stats.cycles - window_from,
        stats.wkc_errors,
        wall.elapsed().as_secs_f64()
    );
    if let Some(f) = &r.fault {
        println!("FAULT: {f}");
    }
    println!(
        "window: {:.3} s of the board's time",
        (r.cycles - r.stats_since_cycle) as f64 / CPU_HZ as f64
    );
    println!(
        "SYNC0 handler (EXTI3), {} runs: entry → return mean {:.1} µs, max {:.1} µs, min {:.1} µs \
         (with the joint-loop ticks that preempted it, {} of the runs); without them mean {:.1} µs, max {:.1} µs",
        s0.runs,
        s0.mean_us(CPU_HZ),
        us(s0.max_cycles),
        us(s0.min_cycles),
        s0.preempted_runs,
        us(s0.own_cycles) / s0.runs.max(1) as f64,
        us(s0.max_own_cycles),
    );
    println!(
        "joint loop (TIM6_DAC), {} runs: mean {:.2} µs, max {:.2} µs; load {:.1} % of the cycles",
        jl.runs,
        jl.mean_us(CPU_HZ),
        us(jl.max_cycles),
        100.0 * r.load(TIM6_DAC)
    );
    println!(
        "PDI IRQ (EXTI15_10), {} runs: mean {:.1} µs, max {:.1} µs; SYNC0 load {:.1} %; asleep {:.1} % of the whole run",
        pdi.runs,
        pdi.mean_us(CPU_HZ),
        us(pdi.max_cycles),
        100.0 * r.load(EXTI3),
        100.0 * r.slept_cycles as f64 / r.cycles.max(1) as f64
    );
    println!(
        "stack: {} B deepest since reset (start-up included, before the window: {} B), {} B in the window (repainted below the SP at its start); region {:#010x}..{:#010x}",
        boot.stack.max_depth.max(r.stack.max_depth),
        boot.stack.max_depth,
        r.stack.max_depth,
        r.stack.bottom,
        r.stack.top
    );
    println!(
        "image: flash {} B, static RAM {} B (.data + .bss), SPI {} frames / {} bytes",
        r.image.flash, r.image.ram, r.spi.frames, r.spi.bytes
    );
}
