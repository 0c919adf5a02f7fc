//! Issue 14: every registered device × every PDI route. For each device of the registry
//! (no list of its own) and each route the firmware can reach its ESC by — the software
//! ESC directly, a LAN9252 and an ET1100 over simulated SPI (oxicat-pdi's drivers) —
//! ethercrab (through `oxicat-master`) brings two nodes to OP in the sync mode and cycle
//! of the device's bench and exchanges process data for 1,000 cycles; every cycle's
//! working counter must be the expected one.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_devices::registry::{add_node_via, kits, Kit};
use oxicat_master::cyclic::CycleOptions;
use oxicat_master::{Link, Master};
use oxicat_sim::pdi_path::PdiRoute;
use oxicat_sim::segment::Segment;
use oxicat_slave::SyncMode;

const CYCLES: u64 = 1_000;
const SPI_MHZ: u32 = 20;

fn routes() -> [PdiRoute; 3] {
    [
        PdiRoute::Direct,
        PdiRoute::lan9252(SPI_MHZ),
        PdiRoute::et1100(SPI_MHZ),
    ]
}

/// Runs two nodes of `kit` through `route`; `Err` says what went wrong.
fn run(kit: &Kit, route: PdiRoute) -> Result<(), String> {
    let mut seg = Segment::new();
    for k in 0..2 {
        add_node_via(&mut seg, kit, k, 0.0, route).map_err(|e| format!("node {k}: {e}"))?;
    }
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).map_err(|e| e.to_string())?;
    let opts = CycleOptions {
        cycle: Duration::from_nanos(u64::from(kit.cycle_ns)),
        dc: matches!(kit.sync, SyncMode::DcSync0 | SyncMode::DcSync1),
    };
    let stats = m.run_cycles(opts, CYCLES).map_err(|e| e.to_string())?;
    if stats.cycles != CYCLES || stats.wkc_errors != 0 {
        return Err(format!(
            "{} cycles, {} with a wrong working counter",
            stats.cycles, stats.wkc_errors
        ));
    }
    Ok(())
}

#[test]
fn every_device_through_every_route_reaches_op_and_cycles_with_the_right_wkc() {
    let mut failed = Vec::new();
    let mut ran = 0;
    for kit in kits() {
        for route in routes() {
            ran += 1;
            if let Err(e) = run(kit, route) {
                failed.push(format!("{} via {}: {e}", kit.name, route.name()));
            }
        }
    }
    assert!(ran >= 6 * 3, "the registry holds the seed devices");
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}
