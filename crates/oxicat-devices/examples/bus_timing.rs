//! What SPI bus time does to a Laelaps leg's DC cycle, from simulated runs with the
//! execution-time model on (`oxicat_sim::exec_time`, `oxicat_devices::laelaps::timing_probe`): for the
//! LAN9252 and the ET1100 at 10/20/30 MHz and 100/200/400 µs cycles, SYNC0s lost and the
//! input latency (SYNC0 edge to the inputs readable in SM3), with the thesis' 1 µs
//! application as CPU time.
//!
//! `cargo run --release -p oxicat-devices --example bus_timing [cycles]`

use oxicat_devices::laelaps::timing_probe::{self, ProbeConfig};
use oxicat_devices::laelaps::{device, Side};
use oxicat_sim::pdi_path::PdiRoute;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cycles: u32 = match std::env::args().nth(1) {
        Some(a) => a.parse()?,
        None => 1000,
    };
    let sii = oxicat_esi::sii::generate(device::device(Side::Left))?;
    println!("Laelaps leg node, DC SYNC0, {cycles} cycles per run, CPU 1 µs per SYNC0 (thesis), SYNC0 handler = 38-byte RxPDO read + 22-byte TxPDO write");
    println!();
    println!("| chip | SPI MHz | cycle µs | SYNC0 lost | SYNC0 delayed | busy µs (bus + CPU) | input latency µs (max) | cycles with fresh inputs | 0x1C32:0B / 0C |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for (name, route) in [
        ("LAN9252", PdiRoute::lan9252 as fn(u32) -> PdiRoute),
        ("ET1100", PdiRoute::et1100),
    ] {
        for mhz in [10, 20, 30] {
            for cycle_us in [100u32, 200, 400] {
                let mut cfg = ProbeConfig::new(route(mhz), cycle_us * 1000);
                cfg.cycles = cycles;
                let r = timing_probe::run(&cfg, sii.clone())?;
                println!(
                    "| {name} | {mhz} | {cycle_us} | {} | {} | {:.1} | {:.1}{} | {} / {} | {} / {} |",
                    r.sync0_lost,
                    r.sync0_delayed,
                    r.busy_ns.1 as f64 / 1e3,
                    r.max_latency_ns as f64 / 1e3,
                    if r.latency_confirmed { " ✓" } else { "" },
                    r.fresh_inputs,
                    r.cycles,
                    r.sm_event_missed,
                    r.cycle_exceeded,
                );
            }
        }
    }
    println!();
    println!("✓: the master's SM3 status probes confirmed the latency to the ns (inputs absent 1 ns before, present at it).");
    Ok(())
}
