//! Twins from ESI on the command line: `oxicat sim --esi FILE:TYPE --udp` serves a vendor's
//! device and an ethercrab master in this process brings it to OP; `--sim esi=…*N` and a
//! segment file's `esi =` build twins in process; a bad ESI is refused with its reason.

use std::process::Command;
use std::time::Duration;

use oxicat_testkit::served::{reference, spawn_udp};

use oxicat_master::cyclic::CycleOptions;
use oxicat_master::{Link, Master};

mod served_common;

fn esi(file: &str) -> String {
    let p = reference().join("esi-vendor").join(file);
    assert!(p.exists(), "reference file {} missing", p.display());
    p.display().to_string()
}

#[test]
fn sim_esi_serves_a_vendor_device_on_udp_and_ethercrab_reaches_op() {
    let spec = format!("{}:EL3001", esi("Beckhoff-EL30xx.xml"));
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_oxicat"));
    cmd.args(["sim", "--quiet", "--udp", "127.0.0.1:0", "--esi", &spec]);
    let (_sim, addr) = spawn_udp(cmd);
    let run = std::thread::Builder::new()
        .stack_size(16 << 20)
        .spawn(move || {
            let mut m = Master::open(Link::Udp(addr)).expect("master on UDP");
            let s = m.scan().expect("scan");
            assert_eq!(s.len(), 1);
            assert_eq!((s[0].vendor_id, s[0].product_code), (2, 0x0BB9_3052));
            assert_eq!(s[0].name, "EL3001");
            let v = m.sdo_upload(0, 0x1018, 2).expect("0x1018:02");
            assert_eq!(v, 0x0BB9_3052u32.to_le_bytes());
            let stats = m
                .run_cycles(
                    CycleOptions {
                        cycle: Duration::from_millis(2),
                        dc: false,
                    },
                    200,
                )
                .expect("OP and cycling");
            (stats.cycles, stats.wkc_errors)
        })
        .unwrap();
    let (cycles, wkc_errors) = run.join().expect("master thread");
    assert_eq!(cycles, 200, "200 cycles in OP");
    assert_eq!(wkc_errors, 0);
}

#[test]
fn sim_option_and_segment_file_take_twins() {
    let f = esi("Beckhoff-EL2xxx.xml");
    let out = served_common::cli(&["slaves", "--sim", &format!("esi={f}:EL2008*2")]).unwrap();
    assert_eq!(out.matches("EL2008").count(), 2, "{out}");
    let desc = oxicat::sim_cmd::parse_segment(
        &format!(
            "[[device]]\nesi = {:?}\ncount = 2\n[[device]]\nname = \"demo\"\n",
            format!("{f}:EL2004")
        ),
        std::path::Path::new("seg.toml"),
    )
    .unwrap();
    let (seg, names) = oxicat::sim_cmd::build_segment(&desc).unwrap();
    assert_eq!(seg.len(), 3);
    assert!(
        names[0].ends_with(":EL2004") && names[2] == "demo",
        "{names:?}"
    );
}

#[test]
fn a_twin_that_cannot_be_built_says_why() {
    let f = esi("Beckhoff-EL2xxx.xml");
    let e = served_common::cli(&["slaves", "--sim", &format!("esi={f}:EL9999")]).unwrap_err();
    assert!(
        e.contains("no device type \"EL9999\"") && e.contains("EL2008"),
        "{e}"
    );
    let e = served_common::cli(&["slaves", "--sim", "esi=/nonexistent.xml:X"]).unwrap_err();
    assert!(e.contains("cannot read the ESI /nonexistent.xml"), "{e}");
    let both = oxicat::sim_cmd::parse_segment(
        "[[device]]\nname = \"demo\"\nesi = \"x.xml\"\n",
        std::path::Path::new("seg.toml"),
    )
    .unwrap_err();
    assert!(both.to_string().contains("one of them"), "{both}");
}
