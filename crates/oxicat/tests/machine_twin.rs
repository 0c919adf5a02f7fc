//! Issue 16 item 3, a twin of a whole machine: `oxicat scan --save DIR` of a served segment,
//! served again with `oxicat sim --segment DIR`, is indistinguishable to a master (the same
//! `slaves`, `sii-read --raw`, `sdos` and `pdos`, byte for byte); an ENI of slaves from
//! different ESI files serves and reaches OP; bad recordings and ENIs are refused with what
//! is wrong.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use oxicat_master::cyclic::CycleOptions;
use oxicat_master::{Link, Master};
use oxicat_testkit::served::{reference, spawn_udp};

mod served_common;
use served_common::{cli, ok, serve, serve_file, Served};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("oxicat-machine-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn reference_file(dir: &str, file: &str) -> String {
    let p = reference().join(dir).join(file);
    assert!(p.exists(), "reference file {} missing", p.display());
    p.display().to_string()
}

/// What a master sees of a segment: `slaves`, `sdos`, `pdos`, and each slave's raw SII.
fn seen(s: &Served, n: usize, scratch: &Path) -> (String, String, String, Vec<Vec<u8>>) {
    let slaves = ok(s, &["slaves"]);
    // `sdos` of every slave stops at one without a mailbox: those with CoE one by one.
    let sdos = ok(s, &["sdos", "-p", "0"]) + &ok(s, &["sdos", "-p", "1"]);
    let pdos = ok(s, &["pdos"]);
    std::fs::create_dir_all(scratch).unwrap();
    let sii = (0..n)
        .map(|p| {
            let f = scratch.join(format!("sii-{p}.bin"));
            let f_s = f.display().to_string();
            ok(s, &["sii-read", "--raw", "-p", &p.to_string(), "-o", &f_s]);
            std::fs::read(&f).unwrap()
        })
        .collect();
    (slaves, sdos, pdos, sii)
}

#[test]
fn a_saved_machine_served_again_is_indistinguishable() {
    let el3001 = format!(
        "esi={}:EL3001",
        reference_file("esi-vendor", "Beckhoff-EL30xx.xml")
    );
    let el2004 = format!("sii={}", reference_file("sii", "el2004-eeprom-dump.bin"));
    let dir = tmp("saved");
    let before;
    {
        let a = serve(&["demo:1", &el3001, &el2004]);
        before = seen(&a, 3, &tmp("scratch-a"));
        let out = ok(&a, &["scan", "--save", &dir.display().to_string()]);
        assert_eq!(out.lines().count(), 4, "{out}");
        assert!(
            out.contains("CoE objects") && out.contains("no CoE dictionary"),
            "{out}"
        );
    }
    // What was written: the manifest, three SII images, two dictionaries.
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert_eq!(
        files,
        [
            "segment.toml",
            "slave-0-dictionary.toml",
            "slave-0-sii.bin",
            "slave-1-dictionary.toml",
            "slave-1-sii.bin",
            "slave-2-sii.bin"
        ]
    );
    let b = serve_file(&dir);
    let after = seen(&b, 3, &tmp("scratch-b"));
    assert!(before.0.lines().count() == 4, "{}", before.0);
    assert_eq!(before.0, after.0, "slaves");
    assert!(before.1.contains("SDO 0x1018"), "{}", before.1);
    assert_eq!(before.1, after.1, "sdos");
    assert!(
        before.2.contains("0x1a00") || before.2.contains("0x1A00"),
        "{}",
        before.2
    );
    assert_eq!(before.2, after.2, "pdos");
    for p in 0..3 {
        assert!(before.3[p].len() >= 256, "slave {p}'s SII");
        assert!(before.3[p] == after.3[p], "slave {p}'s SII differs");
    }
    // The served copy reaches OP as the original does.
    let run = std::thread::Builder::new()
        .stack_size(16 << 20)
        .spawn({
            let addr = b.addr.clone();
            move || {
                let mut m = Master::open(Link::Udp(addr)).expect("master on UDP");
                m.run_cycles(
                    CycleOptions {
                        cycle: Duration::from_millis(2),
                        dc: false,
                    },
                    100,
                )
                .map(|s| (s.cycles, s.wkc_errors))
                .map_err(|e| e.to_string())
            }
        })
        .unwrap();
    assert_eq!(run.join().unwrap(), Ok((100, 0)));
    drop(b);
    // A second save into the same directory is refused, and allowed with --force.
    let c = serve(&["demo:1"]);
    let e = served_common::fails(&c, &["scan", "--save", &dir.display().to_string()]);
    assert!(e.contains("not empty") && e.contains("--force"), "{e}");
    let out = ok(
        &c,
        &["scan", "--save", &dir.display().to_string(), "--force"],
    );
    assert!(out.contains("saved in"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}

fn build_dir(dir: &Path) -> Result<usize, String> {
    let desc = oxicat::sim_cmd::read_segment_file(dir).map_err(|e| e.to_string())?;
    oxicat::sim_cmd::build_segment(&desc)
        .map(|(s, _)| s.len())
        .map_err(|e| e.to_string())
}

#[test]
fn a_bad_recording_is_refused_with_what_is_wrong() {
    let dir = tmp("bad");
    // Not there, and no manifest.
    let e = build_dir(&dir).unwrap_err();
    assert!(e.contains("oxicat-machine-bad"), "{e}");
    std::fs::create_dir_all(&dir).unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(
        e.contains("segment.toml") && e.contains("cannot read"),
        "{e}"
    );
    // A good recording of one demo node, to break piece by piece.
    let out = cli(&[
        "scan",
        "--save",
        &dir.display().to_string(),
        "--force",
        "--sim",
        "demo:1",
    ])
    .unwrap();
    assert!(out.contains("saved in"), "{out}");
    assert_eq!(build_dir(&dir), Ok(1));
    let manifest = std::fs::read_to_string(dir.join("segment.toml")).unwrap();
    let sii = std::fs::read(dir.join("slave-0-sii.bin")).unwrap();
    let dict = std::fs::read_to_string(dir.join("slave-0-dictionary.toml")).unwrap();
    let restore = || {
        std::fs::write(dir.join("segment.toml"), &manifest).unwrap();
        std::fs::write(dir.join("slave-0-sii.bin"), &sii).unwrap();
        std::fs::write(dir.join("slave-0-dictionary.toml"), &dict).unwrap();
    };
    // A missing file.
    std::fs::remove_file(dir.join("slave-0-sii.bin")).unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(e.contains("slave-0-sii.bin"), "{e}");
    restore();
    std::fs::remove_file(dir.join("slave-0-dictionary.toml")).unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(e.contains("slave-0-dictionary.toml"), "{e}");
    restore();
    // A corrupt SII: cut short, and a category running past the end.
    std::fs::write(dir.join("slave-0-sii.bin"), &sii[..40]).unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(e.contains("slave-0-sii.bin") && e.contains("SII"), "{e}");
    let mut bad = sii.clone();
    bad[0x82..0x84].copy_from_slice(&0x7FFFu16.to_le_bytes());
    std::fs::write(dir.join("slave-0-sii.bin"), &bad).unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(e.contains("slave-0-sii.bin") && e.contains("SII"), "{e}");
    restore();
    // A corrupt dictionary and manifest.
    std::fs::write(
        dir.join("slave-0-dictionary.toml"),
        "[[object]]\nindex = \"x\"\n",
    )
    .unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(
        e.contains("slave-0-dictionary.toml") && e.contains("index"),
        "{e}"
    );
    restore();
    std::fs::write(
        dir.join("segment.toml"),
        manifest.replace("format = 1", "format = 9"),
    )
    .unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(e.contains("format = 9"), "{e}");
    let regs = manifest
        .lines()
        .find(|l| l.starts_with("esc_registers"))
        .unwrap()
        .to_string();
    std::fs::write(
        dir.join("segment.toml"),
        manifest.replace(&regs, "esc_registers = \"11 00\""),
    )
    .unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(
        e.contains("esc_registers") && e.contains("10 hex bytes"),
        "{e}"
    );
    std::fs::write(
        dir.join("segment.toml"),
        manifest.replace("\"slave-0-sii.bin\"", "\"../../etc/passwd\""),
    )
    .unwrap();
    let e = build_dir(&dir).unwrap_err();
    assert!(e.contains("not a file name in the directory"), "{e}");
    restore();
    // A file where the directory should be.
    let f = dir.join("segment.toml");
    let e = cli(&[
        "scan",
        "--save",
        &f.display().to_string(),
        "--sim",
        "demo:1",
    ])
    .unwrap_err();
    assert!(e.contains("not a directory"), "{e}");
    assert_eq!(std::fs::read_to_string(&f).unwrap(), manifest, "untouched");
    let _ = std::fs::remove_dir_all(&dir);
}

fn eni() -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/four-slaves.eni.xml")
        .display()
        .to_string()
}

#[test]
fn an_eni_of_four_esi_files_serves_and_reaches_op() {
    let vendor = reference().join("esi-vendor").display().to_string();
    let soes = reference().join("esi").display().to_string();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_oxicat"));
    cmd.args(["sim", "--quiet", "--udp", "127.0.0.1:0", "--eni", &eni()]);
    cmd.args(["--esi-dir", &vendor, "--esi-dir", &soes]);
    let (_sim, addr) = spawn_udp(cmd);
    let run = std::thread::Builder::new()
        .stack_size(16 << 20)
        .spawn(move || {
            let mut m = Master::open(Link::Udp(addr)).expect("master on UDP");
            let s = m.scan().expect("scan");
            let ids: Vec<_> = s
                .iter()
                .map(|s| (s.vendor_id, s.product_code, s.revision))
                .collect();
            let stats = m
                .run_cycles(
                    CycleOptions {
                        cycle: Duration::from_millis(2),
                        dc: false,
                    },
                    200,
                )
                .expect("OP and cycling");
            (ids, stats.cycles, stats.wkc_errors)
        })
        .unwrap();
    let (ids, cycles, wkc_errors) = run.join().expect("master thread");
    assert_eq!(
        ids,
        [
            (2, 0x044C_2C52, 0x0012_0000),
            (2, 0x07D8_3052, 0x0012_0000),
            (2, 0x0BB9_3052, 0x0012_0000),
            (0x1337, 0x1278_3456, 1)
        ]
    );
    assert_eq!((cycles, wkc_errors), (200, 0));
}

#[test]
fn an_eni_that_cannot_be_served_says_which_slave_and_what_was_searched() {
    let vendor = reference().join("esi-vendor");
    // The SOES demo's ESI is not in esi-vendor.
    let e = oxicat::sim_cmd::eni_devices(Path::new(&eni()), std::slice::from_ref(&vendor))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("slave 3")
            && e.contains("Box 4")
            && e.contains("0x12783456")
            && e.contains(&vendor.display().to_string()),
        "{e}"
    );
    // Malformed, and missing.
    let f = tmp("eni").with_extension("xml");
    std::fs::write(
        &f,
        "<EtherCATConfig><Config><Slave><Info><Name>x</Name></Info></Slave>",
    )
    .unwrap();
    let e = oxicat::sim_cmd::eni_devices(&f, &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a readable ENI"), "{e}");
    std::fs::write(&f, "<EtherCATConfig><Config><Slave><Info><Name>x</Name></Info></Slave></Config></EtherCATConfig>").unwrap();
    let e = oxicat::sim_cmd::eni_devices(&f, &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("slave 0") && e.contains("VendorId"), "{e}");
    let _ = std::fs::remove_file(&f);
    let e = oxicat::sim_cmd::eni_devices(&f, &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("cannot read"), "{e}");
    // A segment file naming an ENI.
    let desc = oxicat::sim_cmd::parse_segment(
        &format!(
            "eni = {:?}\nesi_dirs = [{:?}, {:?}]\n[[device]]\nname = \"demo\"\n",
            eni(),
            vendor.display().to_string(),
            reference().join("esi").display().to_string()
        ),
        Path::new("seg.toml"),
    )
    .unwrap();
    assert_eq!(desc.devices.len(), 5);
    assert!(desc.devices[0].esi.as_deref().unwrap().contains("EK1100"));
    assert_eq!(desc.devices[4].name, "demo");
}
