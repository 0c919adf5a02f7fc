//! Issue 14: one registry. This test walks `oxicat_devices::registry::kits()` — no list of
//! its own — and runs every device through every verb that names devices: `device NAME
//! esi|sii|od|check`, `device list`, `sim --list`, `slaves` and `states op` on an
//! in-process `--sim NAME:2`, and `slaves` over EtherCAT-over-UDP from a served segment
//! (ethercrab in this process). The registry of this test build includes the toy device
//! of the README's "Add a device" recipe (feature `toy`).

use oxicat_devices::registry::kits;
use oxicat_esi::model::{compare, from_def};

mod bin_common;
mod served_common;

fn ok(args: &[&str]) -> String {
    let (ok, out, err) = bin_common::oxicat_in(None, args);
    assert!(ok, "oxicat {args:?} failed: {err}");
    out
}

#[test]
fn every_registered_device_generates_consistent_esi_sii_and_od() {
    let dir = std::env::temp_dir().join(format!("oxicat-registry-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    for kit in kits() {
        let def = (kit.def)(0);
        let name = kit.name;
        // ESI: parses, and describes the definition (the same device model).
        let esi = ok(&["device", name, "esi"]);
        let models = oxicat_esi::esi::parse(&esi).expect("the ESI parses");
        assert_eq!(models.len(), 1, "{name}");
        let findings = compare(&from_def(def), &models[0]);
        assert!(findings.is_empty(), "{name} ESI: {findings:?}");
        // SII: the generated image, byte for byte, written to a file.
        let file = dir.join(format!("{name}.bin"));
        ok(&["device", name, "sii", "-o", file.to_str().expect("path")]);
        let sii = std::fs::read(&file).expect("SII file");
        assert_eq!(sii, oxicat_esi::sii::generate(def).expect("SII"), "{name}");
        let parsed = oxicat_esi::sii::parse(&sii).expect("the SII parses");
        assert_eq!(parsed.product_code, def.identity.product_code, "{name}");
        // The object dictionary table lists the identity object.
        let od = ok(&["device", name, "od"]);
        assert!(od.contains("0x1018"), "{name}: {od}");
        // The consistency check of definition, ESI and SII finds nothing.
        let check = ok(&["device", name, "check"]);
        assert!(check.ends_with("0 findings\n"), "{name}: {check}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn device_list_and_sim_list_name_every_registered_device() {
    let device_list = ok(&["device", "list"]);
    let sim_list = ok(&["sim", "--list"]);
    assert_eq!(device_list, sim_list, "one list");
    for kit in kits() {
        assert!(
            device_list
                .lines()
                .any(|l| l.split_whitespace().next() == Some(kit.name)),
            "{} missing:\n{device_list}",
            kit.name
        );
    }
    assert_eq!(device_list.lines().count(), kits().len());
    assert!(kits().iter().any(|k| k.name == "toy"), "the recipe's toy");
}

#[test]
fn every_registered_device_scans_and_reaches_op_on_an_in_process_segment() {
    for kit in kits() {
        let spec = format!("{}:2", kit.name);
        let slaves = ok(&["slaves", "--sim", &spec]);
        let rows: Vec<&str> = slaves.lines().skip(1).collect();
        assert_eq!(rows.len(), 2, "{spec}: {slaves}");
        assert!(
            rows[0].starts_with("0 ") && rows[1].starts_with("1 "),
            "{spec}: {slaves}"
        );
        let product = format!("0x{:08x}", (kit.def)(0).identity.product_code);
        assert!(
            rows.iter().all(|r| r.contains(&product)),
            "{spec}: {slaves}"
        );
        let op = ok(&["states", "op", "--sim", &spec]);
        assert!(
            op.lines().any(|l| l.starts_with("0: OP"))
                && op.lines().any(|l| l.starts_with("1: OP")),
            "{spec}: {op}"
        );
    }
}

#[test]
fn every_registered_device_is_served_over_udp_to_ethercrab() {
    for kit in kits() {
        let spec = format!("{}:2", kit.name);
        let served = served_common::serve(&[&spec]);
        let slaves = served_common::cli(&["slaves", "--udp", &served.addr])
            .unwrap_or_else(|e| panic!("{spec}: {e}"));
        let product = format!("0x{:08x}", (kit.def)(0).identity.product_code);
        assert_eq!(
            slaves.lines().filter(|l| l.contains(&product)).count(),
            2,
            "{spec}: {slaves}"
        );
    }
}
