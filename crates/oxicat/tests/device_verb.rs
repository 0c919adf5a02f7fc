//! `oxicat device <name> esi|sii|od|check`: the binary runs and its output parses.

use std::process::Command;

fn oxicat(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_oxicat"))
        .args(args)
        .output()
        .expect("run oxicat")
}

#[test]
fn device_esi_to_stdout_parses() {
    let o = oxicat(&["device", "demo", "esi"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let xml = String::from_utf8(o.stdout).unwrap();
    let m = oxicat_esi::esi::parse(&xml).unwrap().remove(0);
    assert_eq!(m.name.as_deref(), Some("EtherCAT Application (SPI)"));
}

#[test]
fn device_sii_to_file_parses() {
    let dir = std::env::temp_dir().join(format!("oxicat-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("demo-additions.bin");
    let o = oxicat(&["device", "demo-additions", "sii", "-o", f.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m = oxicat_esi::sii::parse(&std::fs::read(&f).unwrap()).unwrap();
    assert!(m.rx_pdos.iter().any(|p| p.index == 0x1603));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn device_od_is_a_table_with_every_object() {
    let o = oxicat(&["device", "demo", "od"]);
    assert!(o.status.success());
    let t = String::from_utf8(o.stdout).unwrap();
    let rows: Vec<Vec<&str>> = t
        .lines()
        .skip(1)
        .map(|l| l.split_whitespace().collect())
        .collect();
    let has = |idx: &str, sub: &str| {
        rows.iter()
            .any(|r| r.len() > 2 && r[0] == idx && r[1] == sub)
    };
    for (i, s) in [
        ("0x1018", "02"),
        ("0x7000", "05"),
        ("0x7000", "09"),
        ("0x6030", "02"),
        ("0x1c12", "03"),
    ] {
        assert!(has(i, s), "{i}:{s} missing in\n{t}");
    }
    let blue = rows
        .iter()
        .find(|r| r[0] == "0x7000" && r[1] == "05")
        .unwrap();
    assert_eq!(&blue[2..5], ["Blue_LED", "BOOL", "1"]);
}

#[test]
fn device_check_reports_no_findings_and_unknown_device_fails() {
    let o = oxicat(&["device", "demo", "check"]);
    assert!(o.status.success());
    assert_eq!(String::from_utf8(o.stdout).unwrap().trim(), "0 findings");
    let o = oxicat(&["device", "nope", "esi"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown device"));
}

/// The check's text names what disagrees in words; a definition whose 0x1000 disagrees with
/// its dictionary gives a finding (the binary then exits 1: `CliError::CheckFailed`).
#[test]
fn check_text_explains_a_profile_disagreement() {
    let mut joint = oxicat_devices::cia402::DEF;
    joint.device_type = 0x0000_1389;
    let joint: &'static _ = Box::leak(Box::new(joint));
    let f = oxicat_esi::check(joint).unwrap();
    let text = oxicat::check_text(&f);
    assert!(text.contains("Def: profile number"), "{text}");
    assert!(text.contains("0x6040"), "{text}");
    assert!(!text.ends_with("0 findings\n"), "{text}");
    let e = oxicat::CliError::CheckFailed {
        device: "x".into(),
        findings: f.len(),
    }
    .to_string();
    assert!(e.contains("disagree"), "{e}");
}
