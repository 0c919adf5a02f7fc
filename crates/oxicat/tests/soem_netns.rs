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

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use netns_common::NetnsSim;
use oxicat_devices::registry::{kits, Kit};
use oxicat_esi::model::DeviceModel;
use oxicat_slave::od::{DataType, DefaultValue, ObjectCode};
use oxicat_slave::{AlState, DeviceDef, SyncMode};

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

/// Check results: check name → (device, slave position, passed, detail).
type Results = BTreeMap<String, Vec<(String, usize, bool, String)>>;

fn python_with_pysoem() -> Result<PathBuf, String> {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.venv/bin/python");
    let candidates: Vec<PathBuf> = match std::env::var_os("OXICAT_PYTHON") {
        Some(p) => vec![PathBuf::from(p)],
        None => vec![venv, PathBuf::from("python3")],
    };
    for py in &candidates {
        let ok = Command::new(py)
            .args(["-c", "import pysoem"])
            .output()
            .is_ok_and(|o| o.status.success());
        if ok {
            return Ok(py.clone());
        }
    }
    Err(format!(
        "no Python with pysoem (tried {}; `.ci/run` installs it into .venv)",
        candidates
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    ))
}

use oxicat::output::json_string as json_str;

/// An application entry SOEM can write in PREOP and read back: an unsigned integer of 1,
/// 2 or 4 bytes, with a value beside its default that its range allows.
fn writable_entry(def: &DeviceDef) -> Option<String> {
    for o in def.objects {
        for e in o.entries {
            if e.sub == 0 && o.code != ObjectCode::Var {
                continue;
            }
            let size = match e.dtype {
                DataType::Unsigned8 => 1u32,
                DataType::Unsigned16 => 2,
                DataType::Unsigned32 => 4,
                _ => continue,
            };
            if !e.access.write_in(AlState::PreOp) || !e.access.read_in(AlState::PreOp) {
                continue;
            }
            let DefaultValue::Bits(default) = e.default else {
                continue;
            };
            let (lo, hi) = if e.range.0 <= e.range.1 {
                (e.range.0, e.range.1)
            } else {
                (0, (1i64 << (8 * size)) - 1)
            };
            let default = default as i64;
            let Some(value) = [default + 1, default - 1]
                .into_iter()
                .find(|v| (lo..=hi).contains(v) && *v >= 0 && *v < (1i64 << (8 * size)))
            else {
                continue;
            };
            return Some(format!(
                "{{\"index\": {}, \"sub\": {}, \"size\": {size}, \"value\": {value}}}",
                o.index, e.sub
            ));
        }
    }
    None
}

/// An index in the application range that the device does not have.
fn missing_index(def: &DeviceDef) -> u16 {
    (0x2000..0x6000u16)
        .rev()
        .find(|i| def.objects.iter().all(|o| o.index != *i))
        .expect("a free index")
}

/// The device's ESI (as `oxicat device <name> esi` writes it), parsed.
fn esi_model(def: &'static DeviceDef) -> DeviceModel {
    let esi = oxicat_esi::esi::generate(def).expect("ESI of the definition");
    let mut models = oxicat_esi::esi::parse(&esi).expect("our ESI parses");
    assert_eq!(models.len(), 1, "one device per ESI");
    models.remove(0)
}

/// The device has DC SYNC0: an ESI DC op mode that activates SYNC0, and the definition
/// supports the mode.
fn has_dc(def: &'static DeviceDef) -> bool {
    esi_model(def)
        .dc
        .iter()
        .any(|d| d.assign_activate & 0x0300 == 0x0300)
        && def.sync.supported & SyncMode::DcSync0.support_bit() != 0
}

/// What SOEM should find on the segment `dev:NODES`, as the JSON soem_check.py reads.
fn spec(dev: &Kit) -> (String, u32) {
    let mut cycle_ns = CYCLE_NS;
    let mut slaves = Vec::new();
    for k in 0..NODES {
        let def = (dev.def)(k);
        let m = esi_model(def);
        let dc = has_dc(def);
        cycle_ns = cycle_ns.max(def.sync.min_cycle_ns);
        slaves.push(format!(
            "{{\"vendor_id\": {}, \"product_code\": {}, \"revision\": {}, \
             \"order_code\": {}, \"name\": {}, \"device_name\": {}, \"hw_version\": {}, \
             \"sw_version\": {}, \"dc\": {dc}, \"missing_index\": {}, \"rw\": {}}}",
            m.vendor_id,
            m.product_code,
            m.revision,
            json_str(m.order_code.as_deref().unwrap_or_default()),
            json_str(m.name.as_deref().unwrap_or_default()),
            json_str(def.name),
            json_str(def.hw_version),
            json_str(def.sw_version),
            missing_index(def),
            writable_entry(def).unwrap_or_else(|| "null".into()),
        ));
    }
    let cycle_ns = cycle_ns.div_ceil(CYCLE_NS) * CYCLE_NS;
    (
        format!(
            "{{\"cycles\": {CYCLES}, \"cycle_ns\": {cycle_ns}, \"slaves\": [{}]}}",
            slaves.join(", ")
        ),
        cycle_ns,
    )
}

/// Serves `dev:NODES`, runs soem_check.py on it and collects its CHECK lines.
fn drive(py: &Path, dev: &Kit, results: &mut Results) {
    let segment = format!("{}:{NODES}", dev.name);
    let bench = NetnsSim::start(&[&segment]).expect("root was checked before");
    let (spec, _) = spec(dev);
    let spec_path = std::env::temp_dir().join(format!(
        "oxicat-soem-{}-{}.json",
        std::process::id(),
        dev.name
    ));
    std::fs::write(&spec_path, &spec).expect("write the spec");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/soem/soem_check.py");
    let out = Command::new(py)
        .arg(&script)
        .arg(bench.master_if())
        .arg(&spec_path)
        .output()
        .expect("run soem_check.py");
    let _ = std::fs::remove_file(&spec_path);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("--- SOEM on `{segment}`:\n{stdout}{stderr}");
    assert!(
        out.status.success(),
        "soem_check.py on `{segment}` did not get through: {stderr}\nsim: {:?}",
        bench.sim_log()
    );
    for line in stdout.lines() {
        let Some(rest) = line.strip_prefix("CHECK ") else {
            continue;
        };
        let mut f = rest.splitn(4, ' ');
        let (Some(check), Some(pos), Some(verdict)) = (f.next(), f.next(), f.next()) else {
            panic!("malformed line from soem_check.py: {line}");
        };
        results.entry(check.to_string()).or_default().push((
            dev.name.to_string(),
            pos.parse().expect("slave position"),
            verdict == "PASS",
            f.next().unwrap_or_default().to_string(),
        ));
    }
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
                drive(&py, &dev, &mut results);
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
