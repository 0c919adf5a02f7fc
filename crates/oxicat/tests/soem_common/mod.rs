//! SOEM (pysoem) against a served segment, shared by the tests that drive it: what SOEM
//! should find on a device's segment (the JSON `soem/soem_check.py` reads, from the device's
//! definition and ESI), running the script on a bench's veth and collecting its `CHECK`
//! lines. `crates/oxicat/tests/soem_netns.rs` serves the host-compiled devices with `oxicat
//! sim`; `tools/oxicat-emu/tests/soem_firmware.rs` (which includes this module by path)
//! serves board images with `oxicat-emu sim --firmware`.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use oxicat::output::json_string as json_str;
use oxicat_devices::registry::Kit;
use oxicat_esi::model::DeviceModel;
use oxicat_slave::od::{DataType, ObjectCode};
use oxicat_slave::{AlState, DeviceDef, SyncMode};

use crate::netns_common::NetnsSim;

/// The check script.
pub fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../crates/oxicat/tests/soem/soem_check.py")
        .canonicalize()
        .expect("crates/oxicat/tests/soem/soem_check.py")
}

/// How a segment is driven: cycles in OP, the base cycle, and how many times slower than
/// real time the segment runs (`--slowdown`: the script stretches its own waits by it).
#[derive(Debug, Clone, Copy)]
pub struct Drive {
    /// Process-data cycles in OP.
    pub cycles: u32,
    /// Cycle time (and SYNC0 cycle) in the segment's time, ns, unless a device needs more.
    pub cycle_ns: u32,
    /// Nodes of the device on its segment.
    pub nodes: usize,
    /// The segment's clock runs this many times slower than real time.
    pub slowdown: u32,
    /// SM watchdog time in the segment's time, ms (`None`: the script's 500 ms).
    pub watchdog_ms: Option<u32>,
    /// The sync mode the slaves run in, checked in 0x1C32:01 after the cycles (`None`: DC
    /// SYNC0 where the device has it, else whatever the device defaults to, unchecked).
    pub sync: Option<SyncMode>,
}

/// Check results: check name → (device, slave position, passed, detail).
pub type Results = BTreeMap<String, Vec<(String, usize, bool, String)>>;

pub fn python_with_pysoem() -> Result<PathBuf, String> {
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

/// An application entry SOEM can write in PREOP and read back: an unsigned integer of 1,
/// 2 or 4 bytes, with a value beside its default that its range allows.
pub fn writable_entry(def: &DeviceDef) -> Option<String> {
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
            let Some(default) = e.default().as_bits() else {
                continue;
            };
            let (lo, hi) = if e.limits.has_range() {
                (i64::from(e.limits.range.0), i64::from(e.limits.range.1))
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
pub fn missing_index(def: &DeviceDef) -> u16 {
    (0x2000..0x6000u16)
        .rev()
        .find(|i| def.objects.iter().all(|o| o.index != *i))
        .expect("a free index")
}

/// The device's ESI (as `oxicat device <name> esi` writes it), parsed.
pub fn esi_model(def: &'static DeviceDef) -> DeviceModel {
    let esi = oxicat_esi::esi::generate(def).expect("ESI of the definition");
    let mut models = oxicat_esi::esi::parse(&esi).expect("our ESI parses");
    assert_eq!(models.len(), 1, "one device per ESI");
    models.remove(0)
}

/// The device has DC SYNC0: an ESI DC op mode that activates SYNC0, and the definition
/// supports the mode.
pub fn has_dc(def: &'static DeviceDef) -> bool {
    def.info()
        .dc_modes
        .iter()
        .any(|d| d.assign_activate & 0x0300 == 0x0300)
        && def.sync.supported & SyncMode::DcSync0.support_bit() != 0
}

/// One slave as soem_check.py checks it.
#[derive(Debug, Clone)]
pub struct Expect {
    /// The definition it is served from.
    pub def: &'static DeviceDef,
    /// Served by the slave stack (mailbox, CoE, AL control by firmware): the SDO checks,
    /// DC SYNC0 (where the device has it) and the SM watchdog path apply. `false`: the ESC
    /// alone serves it (device emulation), and only the scan, the mapping and the process
    /// data are checked.
    pub stack: bool,
    /// The ESI's `Type` (order code): the name SOEM shows (SII string of the general
    /// category's name index).
    pub order_code: String,
    /// The ESI's device `Name`.
    pub name: String,
    /// Output and input bits SOEM should map, where not the definition's default PDO
    /// assignment (a twin the ESC serves alone from an SII dump: its PDO categories).
    pub pd_bits: Option<(u32, u32)>,
}

impl Expect {
    /// A slave of oxicat's own devices, served by the stack; its names from its ESI.
    pub fn stack(def: &'static DeviceDef) -> Self {
        let m = esi_model(def);
        Self {
            def,
            stack: true,
            order_code: m.order_code.unwrap_or_default(),
            name: m.name.unwrap_or_default(),
            pd_bits: None,
        }
    }
}

/// The JSON object soem_check.py reads for one slave.
fn slave_json(e: &Expect, sync: Option<SyncMode>) -> String {
    let def = e.def;
    let id = def.identity;
    let dc = e.stack
        && has_dc(def)
        && matches!(sync, None | Some(SyncMode::DcSync0 | SyncMode::DcSync1));
    // A mode other than DC: the script sets 0x1C32:01 in PREOP where the device's default
    // differs (as a SOEM application does before SAFEOP) and checks it in OP.
    let sync_mode = match sync {
        Some(m) if e.stack && !dc => format!("\"sync_mode\": {}, ", m as u16),
        _ => String::new(),
    };
    let (out_bits, in_bits) = e
        .pd_bits
        .unwrap_or((def.default_output_bits(), def.default_input_bits()));
    let (out_bytes, in_bytes) = (out_bits.div_ceil(8), in_bits.div_ceil(8));
    // The SM watchdog guards the outputs' sync manager where its control byte enables it
    // (bit 6), and it is the slave's firmware that leaves OP when it expires.
    let watchdog = e.stack && out_bytes > 0 && def.info().sm_control.outputs & 0x40 != 0;
    format!(
        "{{\"vendor_id\": {}, \"product_code\": {}, \"revision\": {}, \
         \"order_code\": {}, \"name\": {}, \"device_name\": {}, \"hw_version\": {}, \
         \"sw_version\": {}, \"dc\": {dc}, {sync_mode}\"stack\": {}, \"watchdog\": {watchdog}, \"out_bytes\": {out_bytes}, \
         \"in_bytes\": {in_bytes}, \"rx_assign\": {:?}, \"tx_assign\": {:?}, \
         \"missing_index\": {}, \"rw\": {}}}",
        id.vendor_id,
        id.product_code,
        id.revision,
        json_str(&e.order_code),
        json_str(&e.name),
        json_str(def.name),
        json_str(def.hw_version),
        json_str(def.sw_version),
        e.stack,
        def.rx_assign,
        def.tx_assign,
        missing_index(def),
        writable_entry(def).unwrap_or_else(|| "null".into()),
    )
}

/// What SOEM should find on a segment of `slaves` (in line order), as the JSON
/// soem_check.py reads; and the cycle it runs at (`drive.cycle_ns`, or a multiple of it
/// that every slave's minimum cycle allows). `drive.nodes` is not used.
pub fn spec_of(slaves: &[Expect], drive: Drive) -> (String, u32) {
    let cycle_ns = slaves
        .iter()
        .map(|e| e.def.sync.min_cycle_ns)
        .fold(drive.cycle_ns, u32::max);
    let cycle_ns = cycle_ns.div_ceil(drive.cycle_ns) * drive.cycle_ns;
    let slaves: Vec<String> = slaves.iter().map(|e| slave_json(e, drive.sync)).collect();
    (
        format!(
            "{{\"cycles\": {}, \"cycle_ns\": {cycle_ns}, \"slowdown\": {}, {}\"slaves\": [{}]}}",
            drive.cycles,
            drive.slowdown,
            drive
                .watchdog_ms
                .map_or(String::new(), |w| format!("\"watchdog_ms\": {w}, ")),
            slaves.join(", ")
        ),
        cycle_ns,
    )
}

/// What SOEM should find on the segment of `drive.nodes` nodes of `dev`, as the JSON
/// soem_check.py reads; and the cycle it runs at.
pub fn spec(dev: &Kit, drive: Drive) -> (String, u32) {
    let slaves: Vec<Expect> = (0..drive.nodes)
        .map(|k| Expect::stack((dev.def)(k)))
        .collect();
    spec_of(&slaves, drive)
}

/// Runs soem_check.py with `py` on `bench` (serving `drive.nodes` nodes of `dev`, named
/// `segment` in messages) and collects its CHECK lines into `results`.
pub fn drive(
    py: &Path,
    bench: &NetnsSim,
    segment: &str,
    dev: &Kit,
    drive: Drive,
    results: &mut Results,
) {
    let (spec, _) = spec(dev, drive);
    drive_spec(py, bench, segment, dev.name, &spec, results);
}

/// Runs soem_check.py with `py` on `bench` against `spec` (the JSON of [`spec_of`]) and
/// collects its CHECK lines into `results` under the device name `device`; `segment`
/// names the segment in messages.
pub fn drive_spec(
    py: &Path,
    bench: &NetnsSim,
    segment: &str,
    device: &str,
    spec: &str,
    results: &mut Results,
) {
    let spec_path = std::env::temp_dir().join(format!(
        "oxicat-soem-{}-{}.json",
        std::process::id(),
        device
            .chars()
            .rev()
            .take(48)
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect::<String>()
    ));
    std::fs::write(&spec_path, spec).expect("write the spec");
    let out = Command::new(py)
        .arg(script())
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
            device.to_string(),
            pos.parse().expect("slave position"),
            verdict == "PASS",
            f.next().unwrap_or_default().to_string(),
        ));
    }
}
