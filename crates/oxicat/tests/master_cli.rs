//! The master verbs of the `oxicat` binary against an in-process virtual segment of demo
//! devices running their firmware (`--sim demo:2`).

mod bin_common;

fn oxicat(args: &[&str]) -> (bool, String, String) {
    // In a directory of its own: `sii-write` leaves its backup of the old image there.
    let cwd = std::env::temp_dir().join(format!("oxicat-master-cli-cwd-{}", std::process::id()));
    std::fs::create_dir_all(&cwd).expect("work dir");
    bin_common::oxicat_in(Some(&cwd), args)
}

fn ok(args: &[&str]) -> String {
    let (s, out, err) = oxicat(args);
    assert!(s, "oxicat {args:?} failed: {err}");
    out
}

fn fails(args: &[&str]) -> String {
    let (s, _, err) = oxicat(args);
    assert!(!s, "oxicat {args:?} should fail");
    err
}

#[test]
fn slaves_states_upload_download() {
    let out = ok(&["slaves", "--sim", "demo:2"]);
    assert_eq!(out.lines().count(), 3, "{out}");
    assert!(
        out.contains("0xe0000000") && out.contains("EtherCAT_Application_SPI"),
        "{out}"
    );
    let out = ok(&["states", "op", "--sim", "demo:2"]);
    assert_eq!(
        out,
        "0: OP, free run (0x1C32:01 = 0)\n1: OP, free run (0x1C32:01 = 0)\n"
    );
    let out = ok(&["upload", "-p", "0", "0x1018", "1", "--sim", "demo:2"]);
    assert!(out.starts_with("3758096384 (0xe0000000)"), "{out}");
    ok(&["download", "-p", "1", "0x10f1", "2", "9", "--sim", "demo:2"]);
    let err = fails(&["upload", "-p", "0", "0x5555", "0", "--sim", "demo:1"]);
    assert!(
        err.contains("0x06020000 The object does not exist"),
        "{err}"
    );
    let err = fails(&[
        "download", "0x10f1", "2", "70000", "--type", "u16", "--sim", "demo:1",
    ]);
    assert!(err.contains("not valid for type u16"), "{err}");
    let err = fails(&["slaves", "--iface", "nosuch0"]);
    assert!(err.contains("does not exist"), "{err}");
}

#[test]
fn sii_read_write_pdos_sdos_xml_regs() {
    let out = ok(&["sii-read", "--sim", "demo:1"]);
    assert!(out.contains("Vendor ID:       0xe0000000"), "{out}");
    let out = ok(&["sii-read", "--hex", "--sim", "demo:1"]);
    assert!(out.starts_with("0000: "), "{out}");
    let out = ok(&["sii-write", "--device", "demo", "--sim", "demo:1"]);
    assert!(out.contains("wrote and verified"), "{out}");
    let err = fails(&["sii-write", "--device", "demo-additions", "--sim", "demo:1"]);
    // demo-additions has its own product code, or the same one: either refused or written.
    let _ = err;
    let dir = std::env::temp_dir().join(format!("oxicat-master-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut img = oxicat_esi::sii::generate(&oxicat_devices::demo::DEF).unwrap();
    img[0x10] ^= 0x55; // vendor id
    let other = dir.join("other.bin");
    std::fs::write(&other, &img).unwrap();
    let err = fails(&["sii-write", other.to_str().unwrap(), "--sim", "demo:1"]);
    assert!(
        err.contains("another device") && err.contains("--force"),
        "{err}"
    );
    img[2] ^= 1;
    std::fs::write(&other, &img).unwrap();
    let err = fails(&[
        "sii-write",
        other.to_str().unwrap(),
        "--force",
        "--sim",
        "demo:1",
    ]);
    assert!(err.contains("CRC"), "{err}");

    let out = ok(&["pdos", "--sim", "demo:1"]);
    assert!(
        out.contains("  RxPDO 0x1600 \"Buttons\"\n")
            && out.contains("    PDO entry 0x7000:05,  1 bit, \"Blue_LED\"\n"),
        "{out}"
    );
    let out = ok(&["sdos", "--sim", "demo:1"]);
    // The IgH tool's layout: per-state access, its type names.
    assert!(out.contains("SDO 0x1018, \"Identity\"\n"), "{out}");
    assert!(
        out.contains("  0x1018:01, r-r-r-, uint32, 32 bit, \"Vendor ID\"\n"),
        "{out}"
    );
    let xml = ok(&["xml", "--sim", "demo:1"]);
    let d = oxicat_esi::esi::parse(&xml).expect("ESI parses");
    assert_eq!(
        d[0].product_code,
        oxicat_devices::demo::DEF.identity.product_code
    );
    let out = ok(&["reg-read", "0x0130", "2", "--sim", "demo:1"]);
    // As the IgH tool prints raw register bytes.
    assert_eq!(out, "0x02 0x00\n");
    ok(&[
        "reg-write",
        "0x0f80",
        "0x1234",
        "-t",
        "u16",
        "--sim",
        "demo:1",
    ]);
}

#[test]
fn write_watch_record() {
    let out = ok(&[
        "write",
        "EtherCAT_Application_SPI.OutINT32Var1",
        "-77",
        "--sim",
        "demo:2",
    ]);
    assert_eq!(out, "0.OutINT32Var1 = -77\n1.OutINT32Var1 = -77\n");
    let out = ok(&[
        "watch",
        "0.InINT32Var3",
        "1.OutUINT16Var1",
        "--every",
        "5",
        "--count",
        "3",
        "--sim",
        "demo:2",
    ]);
    assert_eq!(out.lines().count(), 3, "{out}");
    assert!(
        out.lines().all(|l| l.starts_with("0.InINT32Var3=")),
        "{out}"
    );
    let err = fails(&["watch", "0.NoSuchVar", "--count", "1", "--sim", "demo:1"]);
    assert!(
        err.contains("no process data variable") && err.contains("0.Blue_LED"),
        "{err}"
    );
    let dir = std::env::temp_dir().join(format!("oxicat-master-rec-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("run.csv");
    let out = ok(&[
        "record",
        "--cycle",
        "400us",
        "--duration",
        "20ms",
        "0.InINT32Var1",
        "1.InINT16Var2",
        "-o",
        csv.to_str().unwrap(),
        "--sim",
        "demo:2",
    ]);
    assert!(out.starts_with("50 cycles of 2 variables"), "{out}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "cycle,time [s],0.InINT32Var1 [DINT],1.InINT16Var2 [INT]"
    );
    assert_eq!(lines.len(), 51);
}

/// A device's declared units (its `pd_table!`) are what `write`, `watch` and `record` speak:
/// the master finds the device by the slave's identity, the values are exact decimals.
#[test]
fn a_declared_unit_is_what_write_watch_and_record_speak() {
    // traj_freq100 is Hz × 100 on the wire: 1.5 Hz goes out as 150 and reads back as 1.50.
    let out = ok(&["write", "0.traj_freq100", "1.5", "--sim", "laelaps-leg:1"]);
    assert_eq!(out, "0.traj_freq100 = 1.50\n");
    // 400 Hz would be 40,000 steps: more than an INT16 holds.
    let err = fails(&["write", "0.traj_freq100", "400", "--sim", "laelaps-leg:1"]);
    assert!(
        err.contains("40000 steps") && err.contains("range"),
        "{err}"
    );
    let err = fails(&["write", "0.traj_freq100", "fast", "--sim", "laelaps-leg:1"]);
    assert!(err.contains("not a number of Hz"), "{err}");
    let out = ok(&[
        "watch",
        "0.Time",
        "--every",
        "2",
        "--count",
        "2",
        "--sim",
        "laelaps-leg:1",
    ]);
    assert!(
        out.lines()
            .all(|l| l.starts_with("0.Time=") && l.contains('.')),
        "{out}"
    );

    let dir = std::env::temp_dir().join(format!("oxicat-units-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("units.csv");
    ok(&[
        "record",
        "--cycle",
        "400us",
        "--duration",
        "8ms",
        "0.hip_angle",
        "0.velocity_knee1000",
        "0.State_Machine",
        "-o",
        csv.to_str().unwrap(),
        "--sim",
        "laelaps-leg:1",
    ]);
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "cycle,time [s],0.hip_angle [deg],0.velocity_knee1000 [rad/s motor],0.State_Machine [BOOL]"
    );
    for l in &lines[1..] {
        let f: Vec<&str> = l.split(',').collect();
        let decimals = |s: &str| s.split_once('.').map(|(_, d)| d.len());
        assert_eq!(decimals(f[2]), Some(2), "{l}");
        assert_eq!(decimals(f[3]), Some(3), "{l}");
        assert!(f[4] == "0" || f[4] == "1", "{l}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Beyond 64 slaves (ethercrab's group was sized for 64): a segment of 130 twins — 100
/// EL2008 (the ESC alone) and 30 EL3002 (CoE, the slave stack) — is scanned, brought to OP
/// and cycled by the verbs, and the last slave's input is recorded every cycle.
#[test]
fn a_segment_of_130_slaves_is_scanned_brought_to_op_and_cycled() {
    let r = oxicat_testkit::served::reference().join("esi-vendor");
    let sim = format!(
        "esi={}:EL2008*100 esi={}:EL3002*30",
        r.join("Beckhoff-EL2xxx.xml").display(),
        r.join("Beckhoff-EL30xx.xml").display()
    );
    let out = ok(&["slaves", "--sim", &sim]);
    let lines: Vec<&str> = out.lines().skip(1).collect();
    assert_eq!(lines.len(), 130, "{out}");
    assert!(
        lines[99].ends_with("EL2008") && lines[129].ends_with("EL3002"),
        "{out}"
    );
    let out = ok(&["states", "op", "--sim", &sim]);
    assert_eq!(
        out.lines().filter(|l| l.contains(": OP")).count(),
        130,
        "{out}"
    );
    let dir = std::env::temp_dir().join(format!("oxicat-master-130-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("run.csv");
    let out = ok(&[
        "record",
        "--free-run",
        "--cycle",
        "1ms",
        "--duration",
        "50ms",
        "129.0x6010:11",
        "-o",
        csv.to_str().unwrap(),
        "--sim",
        &sim,
    ]);
    assert!(
        out.starts_with("50 cycles of 1 variables") && out.contains("(0 working-counter errors)"),
        "{out}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().count(), 51, "{text}");
}

/// `--sync` gives every slave one sync mode; one a slave's 0x1C32:04 does not offer stops
/// the verb naming the slave (the TUeES030 offers SM-synchronous only); `--free-run` and
/// `--sync` together are refused.
#[test]
fn the_cyclic_verbs_take_an_explicit_sync_mode() {
    let dir = std::env::temp_dir().join(format!("oxicat-master-sync-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("sm.csv");
    let out = ok(&[
        "record",
        "--sync",
        "sm-sync",
        "--cycle",
        "1ms",
        "--duration",
        "20ms",
        "0.InINT32Var1",
        "-o",
        csv.to_str().unwrap(),
        "--sim",
        "demo:1",
    ]);
    assert!(
        out.starts_with("20 cycles of 1 variables") && out.contains("(0 working-counter"),
        "{out}"
    );
    let out = ok(&[
        "watch",
        "0.InINT32Var3",
        "--sync",
        "dc",
        "--every",
        "2",
        "--count",
        "2",
        "--sim",
        "demo:1",
    ]);
    assert_eq!(out.lines().count(), 2, "{out}");
    let err = fails(&[
        "watch",
        "0.Count",
        "--sync",
        "free-run",
        "--count",
        "1",
        "--sim",
        "tue-es030:1",
    ]);
    assert!(
        err.contains("slave 0 (TUeES030) does not offer the sync mode free run")
            && err.contains("0x1C32:04 = 0x0002: SM-synchronous")
            && err.contains("no slave was changed"),
        "{err}"
    );
    let err = fails(&[
        "record",
        "--sync",
        "sm-sync",
        "--free-run",
        "0.InINT32Var1",
        "-o",
        csv.to_str().unwrap(),
        "--sim",
        "demo:1",
    ]);
    assert!(err.contains("cannot be used with"), "{err}");
}

/// `record --exchange overlap`: 40 demo nodes' image (24 output and 22 input bytes each)
/// in one LRW with every node's inputs on its outputs' bytes, against two LRWs for the
/// lean exchange; a DC cycle takes no `--exchange`, refused before anything is opened.
#[test]
fn record_cycles_with_the_exchange_asked_for() {
    let dir = std::env::temp_dir().join(format!("oxicat-master-xchg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("x.csv");
    for (x, want) in [
        ("overlap", "; overlapped exchange, 2 frames per cycle"),
        ("lean", "; lean exchange, 3 frames per cycle"),
    ] {
        let out = ok(&[
            "record",
            "--free-run",
            "--exchange",
            x,
            "--duration",
            "30ms",
            "39.InINT32Var1",
            "-o",
            csv.to_str().unwrap(),
            "--sim",
            "demo:40",
        ]);
        assert!(
            out.starts_with("30 cycles of 1 variables")
                && out.contains("(0 working-counter errors)")
                && out.trim_end().ends_with(want),
            "{x}: {out}"
        );
        let text = std::fs::read_to_string(&csv).unwrap();
        assert_eq!(text.lines().count(), 31, "{text}");
    }
    std::fs::write(&csv, "kept\n").unwrap();
    let err = fails(&[
        "record",
        "--exchange",
        "overlap",
        "0.InINT32Var1",
        "-o",
        csv.to_str().unwrap(),
        "--sim",
        "demo:1",
    ]);
    assert!(
        err.contains("--exchange overlap") && err.contains("only with --free-run"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), "kept\n");
    let _ = std::fs::remove_dir_all(&dir);
}
