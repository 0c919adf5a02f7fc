//! SOEM, an independent master (through the `pysoem` package), against segments served by
//! `oxicat sim --iface` on a veth pair in a network namespace: one segment per device of
//! the `oxicat sim` registry (one node each), driven by `tests/soem/soem_check.py`. It
//! scans (identity, and the name SOEM shows, against the device's ESI), reads and writes
//! SDOs (identity, 0x1008/0x1009/0x100A, abort codes of a missing object and of a
//! read-only entry, a write read back), exchanges process data in OP for
//! [`CYCLES`] cycles without a working-counter error, runs on DC SYNC0 where the device
//! has DC, and goes the watchdog path (no process data → SAFEOP+ERR 0x001B → ack → OP).
//!
//! The segments are driven once (the first test to ask runs them all); each `#[test]`
//! then asserts one check for every slave of every device, so a failure names the check
//! and the devices it fails on.
//!
//! Needs root and pysoem (`.ci/run` installs it into `.venv`; `OXICAT_PYTHON` names
//! another interpreter); skipped (with the reason) elsewhere, mandatory in CI.

mod netns_common;
mod soem_common;

use std::path::Path;
use std::sync::OnceLock;

use netns_common::NetnsSim;
use oxicat_devices::registry::{kits, Kit};
use soem_common::{has_dc, python_with_pysoem, Drive, Results};

/// Process-data cycles in OP per segment (issue 13 item 18).
const CYCLES: u32 = 10_000;
/// Nodes of each device on its segment: one, because a debug-build simulator of the
/// TUeES030 (three motors stepped at 640 kHz) needs about 40 % of a core per node to keep
/// real time, and SOEM waits only 20 ms for the first answer of a scan.
const NODES: usize = 1;
/// Cycle time (and SYNC0 cycle) in ns, unless a device needs a longer one.
const CYCLE_NS: u32 = 1_000_000;

/// The devices to drive: every registry device, or those named (comma-separated) in
/// `OXICAT_SOEM_DEVICES` (for looking at one device by hand).
fn devices() -> Vec<Kit> {
    let only = std::env::var("OXICAT_SOEM_DEVICES").unwrap_or_default();
    let only: Vec<&str> = only.split(',').filter(|s| !s.is_empty()).collect();
    kits()
        .iter()
        .copied()
        .filter(|d| only.is_empty() || only.contains(&d.name))
        .collect()
}

/// How every device's segment is driven.
const DRIVE: Drive = Drive {
    cycles: CYCLES,
    cycle_ns: CYCLE_NS,
    nodes: NODES,
    slowdown: 1,
    watchdog_ms: None,
    sync: None,
};

/// Serves `dev:NODES` and runs soem_check.py on it.
fn drive_device(py: &Path, dev: &Kit, results: &mut Results) {
    let segment = format!("{}:{NODES}", dev.name);
    let bench = NetnsSim::start(&[&segment]).expect("root was checked before");
    soem_common::drive(py, &bench, &segment, dev, DRIVE, results);
}

/// Drives every registry device once (shared by the tests); `None` when skipped here.
fn results() -> Option<&'static Results> {
    static RESULTS: OnceLock<Option<Results>> = OnceLock::new();
    RESULTS
        .get_or_init(|| {
            // Root and `ip` first (the bench skips or, in CI, fails without them).
            drop(NetnsSim::bare()?);
            let py = match python_with_pysoem() {
                Ok(p) => p,
                Err(e) => {
                    assert!(!netns_common::in_ci(), "SOEM test cannot run in CI: {e}");
                    eprintln!("skipped: {e}");
                    return None;
                }
            };
            let mut results = Results::new();
            for dev in devices() {
                drive_device(&py, &dev, &mut results);
            }
            Some(results)
        })
        .as_ref()
}

/// Asserts that `check` ran on every slave of every device (or, with `dc_only`, on every
/// DC slave) and passed.
fn assert_check(check: &str, dc_only: bool) {
    let Some(results) = results() else {
        return;
    };
    let rows = results.get(check).map(Vec::as_slice).unwrap_or_default();
    let mut missing = Vec::new();
    for dev in devices() {
        for k in 0..NODES {
            if dc_only && !has_dc((dev.def)(k)) {
                continue;
            }
            if !rows.iter().any(|(d, p, _, _)| d == dev.name && *p == k) {
                missing.push(format!("{}#{k}", dev.name));
            }
        }
    }
    let failed: Vec<String> = rows
        .iter()
        .filter(|r| !r.2)
        .map(|(d, p, _, detail)| format!("  {d}#{p}: {detail}"))
        .collect();
    assert!(
        missing.is_empty() && failed.is_empty(),
        "SOEM check `{check}`: not run on {missing:?}; failed on {} slave(s):\n{}",
        failed.len(),
        failed.join("\n")
    );
}

#[test]
fn soem_scan_finds_identity() {
    assert_check("scan_identity", false);
}

#[test]
fn soem_scan_name_is_the_esi_type() {
    assert_check("scan_name", false);
}

#[test]
fn soem_sdo_reads_identity() {
    assert_check("sdo_read_identity", false);
}

#[test]
fn soem_sdo_reads_whole_name_and_versions() {
    assert_check("sdo_read_strings", false);
}

#[test]
fn soem_sdo_abort_missing_object_0x06020000() {
    assert_check("sdo_abort_missing_object", false);
}

#[test]
fn soem_sdo_abort_read_only_0x06010002() {
    assert_check("sdo_abort_read_only", false);
}

#[test]
fn soem_sdo_write_reads_back() {
    assert_check("sdo_write_read_back", false);
}

#[test]
fn soem_reaches_safeop_and_op() {
    assert_check("to_safeop", false);
    assert_check("to_op", false);
}

#[test]
fn soem_pdo_exchange_without_wkc_errors() {
    assert_check("pdo_exchange", false);
}

#[test]
fn soem_dc_sync0_where_the_device_has_dc() {
    assert_check("dc_sync0", true);
}

#[test]
fn soem_watchdog_safeop_err_0x001b() {
    assert_check("watchdog_safeop_err", false);
}

#[test]
fn soem_watchdog_ack_back_to_op() {
    assert_check("watchdog_ack_to_op", false);
}
