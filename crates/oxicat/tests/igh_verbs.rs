//! The verbs and spellings after the IgH `ethercat` tool, and the README's helper verbs:
//! `version`, `device list`, `fw-image`, `slaves -v`, `sii_read`/`reg_read`/`foe_read`.

use std::process::Command;

fn oxicat(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_oxicat"))
        .args(args)
        .env_remove("OXICAT_IFACE")
        .output()
        .expect("oxicat runs");
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn ok(args: &[&str]) -> String {
    let (s, out, err) = oxicat(args);
    assert!(s, "oxicat {args:?} failed: {err}");
    out
}

#[test]
fn version_and_device_list() {
    let out = ok(&["version"]);
    assert!(
        out.starts_with(&format!("oxicat {}", env!("CARGO_PKG_VERSION"))),
        "{out}"
    );
    let out = ok(&["device", "list"]);
    for name in [
        "demo",
        "demo-additions",
        "tue-es030",
        "cia402-joint",
        "axis-hub",
    ] {
        assert!(
            out.lines()
                .any(|l| l.split_whitespace().next() == Some(name)),
            "{out}"
        );
    }
}

#[test]
fn fw_image_builds_what_foe_write_installs() {
    let dir = std::env::temp_dir().join(format!("oxicat-fwimage-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let payload = dir.join("app.bin");
    std::fs::write(&payload, vec![0x5Au8; 1000]).unwrap();
    let img = dir.join("app.img");
    let out = ok(&[
        "fw-image",
        "demo",
        payload.to_str().unwrap(),
        "-o",
        img.to_str().unwrap(),
    ]);
    assert!(out.contains("1032 bytes"), "{out}");
    let built = std::fs::read(&img).unwrap();
    assert_eq!(
        built,
        oxicat_device::fwimage::build(&oxicat_devices::demo::DEF, &[0x5A; 1000])
    );
    let out = ok(&[
        "foe-write",
        "--sim",
        "demo:1",
        img.to_str().unwrap(),
        "--name",
        "firmware.bin",
    ]);
    assert!(out.contains("length=1000"), "{out}");
    let (s, _, err) = oxicat(&[
        "fw-image",
        "nosuch",
        payload.to_str().unwrap(),
        "-o",
        "x.img",
    ]);
    assert!(!s && err.contains("nosuch"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn igh_spellings_and_slaves_verbose() {
    let out = ok(&["slaves", "-v", "--sim", "demo:2"]);
    assert_eq!(out.matches("=== Slave ").count(), 2, "{out}");
    assert!(out.contains("  Vendor Id:       0xe0000000"), "{out}");
    assert!(out.contains("State: PREOP"), "{out}");
    let out = ok(&["sii_read", "--sim", "demo:1"]);
    assert!(out.contains("Vendor"), "{out}");
    let out = ok(&["reg_read", "0x0130", "1", "--sim", "demo:1"]);
    assert!(out.starts_with("0x02") || out.starts_with("02"), "{out}");
    let out = ok(&["foe_read", "version.txt", "--sim", "demo:1"]);
    assert!(out.contains("vendor_id=0xE0000000"), "{out}");
}
