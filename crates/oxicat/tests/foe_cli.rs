//! `oxicat foe-write` / `foe-read` end to end: the binary's master against the demo device's
//! firmware (FoE server + firmware update flow in RAM slots) on an in-process virtual
//! segment (`--sim demo:1`).

use std::path::PathBuf;

use oxicat_slave::{DeviceDef, Identity};

mod bin_common;

fn oxicat(args: &[&str]) -> (bool, String, String) {
    bin_common::oxicat_in(None, args)
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("oxicat-foe-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn demo_with(identity: Identity) -> DeviceDef {
    DeviceDef {
        identity,
        ..oxicat_devices::demo::DEF
    }
}

fn write_image(name: &str, def: &DeviceDef, payload: &[u8]) -> PathBuf {
    let p = tmp(name);
    std::fs::write(&p, oxicat_esi::fwimage::build(def, payload)).unwrap();
    p
}

fn demo_id() -> Identity {
    oxicat_devices::demo::DEF.identity
}

#[test]
fn foe_write_installs_a_good_image_through_boot() {
    let def = demo_with(Identity {
        revision: 2,
        ..demo_id()
    });
    let payload: Vec<u8> = (0..3000u32).map(|i| (i * 7) as u8).collect();
    let f = write_image("good.bin", &def, &payload);
    let (ok, out, err) = oxicat(&[
        "foe-write",
        "--sim",
        "demo:1",
        "-p",
        "0",
        f.to_str().unwrap(),
        "--name",
        "firmware.bin",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("wrote 3032 bytes"), "{out}");
    assert!(out.contains("back in INIT"), "{out}");
    // The device reports the new image (read in BOOT after the download).
    assert!(out.contains("revision=0x00000002"), "{out}");
    assert!(out.contains("length=3000"), "{out}");
}

#[test]
fn foe_write_rejects_wrong_device_corrupted_and_outside_boot() {
    let other = demo_with(Identity {
        product_code: 0x1234,
        ..demo_id()
    });
    let f = write_image("other.bin", &other, b"someone else's firmware");
    let (ok, _, err) = oxicat(&[
        "foe-write",
        "--sim",
        "demo:1",
        f.to_str().unwrap(),
        "--name",
        "firmware.bin",
    ]);
    assert!(!ok);
    assert!(
        err.contains("0x800B") && err.contains("another device"),
        "{err}"
    );

    let def = demo_with(Identity {
        revision: 3,
        ..demo_id()
    });
    let mut img = oxicat_esi::fwimage::build(&def, &[0x5A; 500]);
    img[300] ^= 0xFF;
    let f = tmp("corrupt.bin");
    std::fs::write(&f, img).unwrap();
    let (ok, _, err) = oxicat(&[
        "foe-write",
        "--sim",
        "demo:1",
        f.to_str().unwrap(),
        "--name",
        "firmware.bin",
    ]);
    assert!(!ok);
    assert!(err.contains("0x800C"), "{err}");

    // Outside BOOT (the slave stays in PREOP): bootstrap only.
    let f = write_image("preop.bin", &def, &[1; 100]);
    let (ok, _, err) = oxicat(&[
        "foe-write",
        "--sim",
        "demo:1",
        f.to_str().unwrap(),
        "--name",
        "firmware.bin",
        "--no-boot",
    ]);
    assert!(!ok);
    assert!(err.contains("0x8008"), "{err}");
}

#[test]
fn foe_read_serves_version_txt() {
    let o = tmp("version.txt");
    let (ok, out, err) = oxicat(&[
        "foe-read",
        "--sim",
        "demo:1",
        "-p",
        "0",
        "version.txt",
        "-o",
        o.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("read"), "{out}");
    let v = std::fs::read_to_string(&o).unwrap();
    assert!(v.contains("vendor_id=0xE0000000"), "{v}");
    assert!(v.contains("product_code=0x11110141"), "{v}");
    // A file the device does not have.
    let (ok, _, err) = oxicat(&["foe-read", "--sim", "demo:1", "nothing.txt"]);
    assert!(!ok);
    assert!(err.contains("0x8001"), "{err}");
}
