//! Issue 16 item 1: every device type of every ESI under `reference/esi/` and
//! `reference/esi-vendor/` (the Beckhoff catalogues hold hundreds) becomes a twin that
//! ethercrab (through `oxicat-master`, in process) scans with the ESI's identity and name
//! (the `Type` text, the SII order string), brings to OP and cycles for 100 cycles without
//! a working-counter error; a twin with CoE answers 0x1018 and its PDO assignment
//! 0x1C12/0x1C13 over SDO as the ESI says. Twins boot in batches on one segment per batch.
//!
//! The test writes a report (`twin_catalogue.txt` in the test's target tmp directory: every
//! type refused, with its reason, and what the served ones leave out) and fails on any type
//! refused for a reason outside [`ALLOWED`] (`oxicat_testkit::served::TWIN_REFUSALS_ALLOWED`), or any served type that misbehaves.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use oxicat_devices::registry::{add_device_node, Device};
use oxicat_devices::twin::{load_file, Twin};
use oxicat_esi::twin::Served;
use oxicat_master::cyclic::CycleOptions;
use oxicat_master::{Link, Master};
use oxicat_sim::pdi_path::PdiRoute;
use oxicat_sim::segment::Segment;
use oxicat_testkit::served::{esi_files, TWIN_REFUSALS_ALLOWED as ALLOWED};

const CYCLES: u64 = 100;
const BATCH: usize = 32;

fn u32_of(b: &[u8]) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(..4)?.try_into().ok()?))
}

/// Boots `twins` on one segment and checks each; `Err` names the position and what failed.
fn run_batch(twins: &[&'static Twin]) -> Result<(), String> {
    let mut seg = Segment::new();
    for t in twins {
        add_device_node(&mut seg, Device::Twin(t), 0, 0.0, PdiRoute::Direct)
            .map_err(|e| format!("{}: {e}", t.spec))?;
    }
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).map_err(|e| e.to_string())?;
    let scan = m.scan().map_err(|e| e.to_string())?;
    if scan.len() != twins.len() {
        return Err(format!(
            "{} slaves found, {} booted",
            scan.len(),
            twins.len()
        ));
    }
    for (p, (s, t)) in scan.iter().zip(twins).enumerate() {
        let id = t.esi.def.identity;
        let c = &t.esi.candidate;
        if (s.vendor_id, s.product_code, s.revision) != (id.vendor_id, id.product_code, id.revision)
            || s.name != c.type_name
        {
            return Err(format!(
                "{p} {}: scanned {:#x}/{:#x}/{:#x} {:?}",
                t.spec, s.vendor_id, s.product_code, s.revision, s.name
            ));
        }
        if t.esi.served == Served::Stack && t.esi.def.info().coe.enabled {
            for (sub, want) in [(1, id.vendor_id), (2, id.product_code), (3, id.revision)] {
                let v = m
                    .sdo_upload(p, 0x1018, sub)
                    .map_err(|e| format!("{p} {}: 0x1018:{sub}: {e}", t.spec))?;
                if u32_of(&v) != Some(want) {
                    return Err(format!("{p} {}: 0x1018:{sub} = {v:02x?}", t.spec));
                }
            }
            for (index, want) in [
                (0x1C12u16, t.esi.def.rx_assign),
                (0x1C13, t.esi.def.tx_assign),
            ] {
                let n = m
                    .sdo_upload(p, index, 0)
                    .map_err(|e| format!("{p} {}: {index:#x}:0: {e}", t.spec))?;
                let mut got = Vec::new();
                for k in 1..=n.first().copied().unwrap_or(0) {
                    let v = m
                        .sdo_upload(p, index, k)
                        .map_err(|e| format!("{p} {}: {index:#x}:{k}: {e}", t.spec))?;
                    got.push(u16::from_le_bytes([v[0], v.get(1).copied().unwrap_or(0)]));
                }
                if got != want {
                    return Err(format!(
                        "{p} {}: {index:#x} = {got:04x?}, the ESI says {want:04x?}",
                        t.spec
                    ));
                }
            }
        }
    }
    let opts = CycleOptions {
        cycle: Duration::from_millis(1),
        dc: false,
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
fn every_esi_device_type_becomes_a_twin_that_ethercrab_runs_in_op() {
    let t0 = Instant::now();
    let mut report = String::new();
    let mut bad = Vec::new();
    let (mut served, mut refused, mut types) = (0usize, 0usize, 0usize);
    for f in esi_files() {
        let name = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let all = load_file(&f).unwrap_or_else(|e| panic!("{e}"));
        let mut ok: Vec<&'static Twin> = Vec::new();
        for (c, r) in all {
            types += 1;
            match r {
                Ok(t) => {
                    for l in &t.esi.left_out {
                        report.push_str(&format!("{name}: {c}: served without: {l}\n"));
                    }
                    ok.push(t);
                }
                Err(e) => {
                    refused += 1;
                    let e = e.to_string();
                    let allowed = ALLOWED.iter().find(|(p, _)| e.contains(p));
                    report.push_str(&format!(
                        "{name}: {c}: REFUSED: {e}{}\n",
                        allowed.map_or(" (NOT ALLOWED)".into(), |(_, why)| format!(
                            " [allowed: {why}]"
                        ))
                    ));
                    if allowed.is_none() {
                        bad.push(format!("{name}: {c}: {e}"));
                    }
                }
            }
        }
        for batch in ok.chunks(BATCH) {
            match run_batch(batch) {
                Ok(()) => served += batch.len(),
                Err(e) => {
                    // One by one, to name the types that fail.
                    report.push_str(&format!("{name}: batch failed ({e}); one by one:\n"));
                    for t in batch {
                        match run_batch(&[t]) {
                            Ok(()) => served += 1,
                            Err(e) => {
                                report.push_str(&format!("{name}: {}: FAILED: {e}\n", t.spec));
                                bad.push(format!("{}: {e}", t.spec));
                            }
                        }
                    }
                }
            }
        }
    }
    report.push_str(&format!(
        "\n{types} device types: {served} served (scan, SDO, OP, {CYCLES} cycles), {refused} refused; {:?}\n",
        t0.elapsed()
    ));
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("twin_catalogue.txt");
    std::fs::write(&out, &report).expect("report written");
    println!("{report}\nreport: {}", out.display());
    assert!(types >= 240, "the catalogues hold {types} types");
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    assert_eq!(served + refused, types);
}
