//! Issue 13, items 9–13: bad input gets a clear error, never a panic, a hang or lost data.
//! Each test runs the `oxicat` binary, in a temporary working directory of its own.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};

mod bin_common;
mod served_common;

fn work_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("oxicat-bad-input-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("work dir");
    d
}

/// Runs `oxicat args` in `dir`: (success, stdout, stderr).
fn oxicat_in(dir: &std::path::Path, args: &[&str]) -> (bool, String, String) {
    bin_common::oxicat_in(Some(dir), args)
}

/// The error of a failing `oxicat args` (no panic).
fn error_in(dir: &std::path::Path, args: &[&str]) -> String {
    let (ok, _, err) = oxicat_in(dir, args);
    assert!(!ok, "oxicat {args:?} should fail");
    assert!(!err.contains("panicked"), "oxicat {args:?} panicked: {err}");
    err
}

fn ok_in(dir: &std::path::Path, args: &[&str]) -> String {
    let (ok, out, err) = oxicat_in(dir, args);
    assert!(ok, "oxicat {args:?} failed: {err}");
    out
}

// --- item 9: numbers of scenario files and experiment options ---

#[test]
fn trot_scenario_with_nan_or_inf_is_refused_with_key_and_range() {
    let d = work_dir("trot-nan");
    let text = oxicat_devices::laelaps::scenario::DEFAULT_TOML;
    for (bad, want) in [
        ("nan", "rig.belt_speed_m_s = NaN is not in 0 … 5 m/s"),
        ("inf", "rig.belt_speed_m_s = inf is not in 0 … 5 m/s"),
    ] {
        let f = d.join("s.toml");
        std::fs::write(
            &f,
            text.replace("belt_speed_m_s = 0.2", &format!("belt_speed_m_s = {bad}")),
        )
        .expect("write");
        let err = error_in(
            &d,
            &[
                "trot",
                "--scenario",
                "s.toml",
                "--out",
                "o",
                "--no-plots",
                "-q",
            ],
        );
        assert!(err.contains(want), "{err}");
    }
}

#[test]
fn tue_es030_numbers_are_range_checked() {
    let d = work_dir("tue");
    let err = error_in(&d, &["tue-es030", "frf", "--i", "NaN", "--out", "o"]);
    assert!(err.contains("--i NaN is not in 0 … 1000"), "{err}");
    let err = error_in(&d, &["tue-es030", "frf", "--periods", "1", "--out", "o"]);
    assert!(err.contains("--periods 1 is not in 2 … 1000"), "{err}");
    let err = error_in(&d, &["tue-es030", "ff-r", "--r", "inf", "--out", "o"]);
    assert!(err.contains("--r inf is not in 0 … 10"), "{err}");
    let err = error_in(&d, &["tue-es030", "step", "--amp", "9000", "--out", "o"]);
    assert!(err.contains("--amp 9000 is not in 1 … 7500"), "{err}");
    let err = error_in(&d, &["tue-es030", "ff-emf", "--kv", "NaN", "--out", "o"]);
    assert!(err.contains("--kv NaN is not in 0 … 1"), "{err}");
}

#[test]
fn tue_es030_setpoints_file_errors_name_the_line() {
    let d = work_dir("tue-setpoints");
    let good: String = (0..4000).map(|k| format!("{}\n", (k % 40) * 10)).collect();
    for (bad, want) in [
        ("12abc", "line 3: \"12abc\" is not a number"),
        ("NaN", "line 3: NaN is not a finite current"),
        ("inf", "line 3: inf is not a finite current"),
        ("-9000", "line 3: -9000 mA is not in -7500 … 7500 mA"),
    ] {
        std::fs::write(d.join("sp.txt"), format!("# mA\n100\n{bad}\n{good}")).expect("write");
        let err = error_in(
            &d,
            &[
                "tue-es030",
                "frf",
                "--setpoints",
                "sp.txt",
                "--out",
                "o",
                "-q",
            ],
        );
        assert!(err.contains("--setpoints sp.txt: "), "{err}");
        assert!(err.contains(want), "{err}");
    }
    std::fs::write(d.join("short.txt"), "1\n2\n3\n").expect("write");
    let err = error_in(
        &d,
        &["tue-es030", "frf", "--setpoints", "short.txt", "--out", "o"],
    );
    assert!(err.contains("3 setpoints: give 3072 … 2000000"), "{err}");
    let err = error_in(
        &d,
        &[
            "tue-es030",
            "frf",
            "--setpoints",
            "missing.txt",
            "--out",
            "o",
        ],
    );
    assert!(err.contains("missing.txt"), "{err}");
    // Nothing was written for a refused file.
    assert!(!d.join("o").exists());
    // A good file runs: its own excitation, a Welch estimate.
    std::fs::write(d.join("ok.txt"), &good).expect("write");
    let out = ok_in(
        &d,
        &[
            "tue-es030",
            "frf",
            "--setpoints",
            "ok.txt",
            "--p",
            "6",
            "--out",
            "o",
            "-q",
        ],
    );
    assert!(out.contains("4000 setpoints from ok.txt"), "{out}");
    assert!(out.contains("4000 currents back"), "{out}");
    let csv = std::fs::read_to_string(d.join("o/frf.csv")).expect("frf.csv");
    assert!(csv.starts_with("f [Hz],|T| P=6 file [dB]"), "{csv}");
}

// --- item 10: what cannot work is refused, with the limit ---

#[test]
fn record_cycle_beyond_the_watchdog_or_dc_limit_is_refused() {
    let d = work_dir("record-cycle");
    // 200 ms: above the demo slaves' 100 ms process-data watchdog (it spun at 100 % CPU).
    let err = error_in(
        &d,
        &[
            "record",
            "0.Button1",
            "--cycle",
            "200ms",
            "--duration",
            "1s",
            "-o",
            "r.csv",
            "--sim",
            "demo:1",
        ],
    );
    assert!(err.contains("process-data watchdog of 100ms"), "{err}");
    // 2 s in DC: the SYNC0 cycle does not fit (it said "failed to convert between integer types").
    let err = error_in(
        &d,
        &[
            "record",
            "0.Button1",
            "--cycle",
            "2s",
            "--duration",
            "4s",
            "-o",
            "r.csv",
            "--sim",
            "demo:1",
        ],
    );
    assert!(
        err.contains("at most 1s") && !err.contains("convert"),
        "{err}"
    );
    assert!(!d.join("r.csv").exists(), "nothing written");
}

#[test]
fn cia402_cycle_and_joints_that_cannot_work_are_refused() {
    let d = work_dir("cia402");
    for c in ["0", "1"] {
        let err = error_in(&d, &["cia402", "--cycle-us", c, "enable"]);
        assert!(
            err.contains(&format!("--cycle-us {c}: 100 … 50000 µs")),
            "{err}"
        );
    }
    let err = error_in(&d, &["cia402", "--joints", "0", "enable"]);
    assert!(err.contains("--joints 0: 1 … 1000 drives"), "{err}");
    // A cycle under the drive's 0x1C32:05 (250 µs) is refused instead of timing out.
    let err = error_in(&d, &["cia402", "--cycle-us", "200", "enable"]);
    assert!(
        err.contains("minimum cycle time of 250µs (0x1C32:05)"),
        "{err}"
    );
}

#[test]
fn slave_counts_beyond_the_limit_are_refused() {
    let d = work_dir("counts");
    let err = error_in(&d, &["slaves", "--sim", "demo:65536"]);
    assert!(
        err.contains("demo:65536 = 65536 is not in 1 … 1000 slaves"),
        "{err}"
    );
    let err = error_in(&d, &["sim", "--udp", "127.0.0.1:0", "demo:100000"]);
    assert!(err.contains("1 … 1000 slaves"), "{err}");
}

#[cfg(unix)]
#[test]
fn sim_stops_on_ctrl_c_while_it_boots_the_segment() {
    // The most a served segment may hold and the slowest to build: the firmware-hosting
    // devices' limit and ESC twins with a slave stack (CoE) up to 1,000 slaves in all.
    let demo = format!("demo:{}", oxicat::sim_cmd::MAX_SERVED_FIRMWARE_NODES);
    let twins = format!(
        "esi={}:EL3002*{}",
        oxicat_testkit::served::reference()
            .join("esi-vendor/Beckhoff-EL30xx.xml")
            .display(),
        oxicat::sim_cmd::MAX_SIM_SLAVES - oxicat::sim_cmd::MAX_SERVED_FIRMWARE_NODES
    );
    let mut child = Command::new(env!("CARGO_BIN_EXE_oxicat"))
        .args(["sim", "-q", "--udp", "127.0.0.1:0", &demo, &twins])
        .stdin(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut err = BufReader::new(child.stderr.take().expect("stderr"));
    let mut line = String::new();
    err.read_line(&mut line).expect("first line");
    assert!(line.contains("booting 1000 slave(s)"), "{line}");
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(kill.success());
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).expect("stderr");
    let status = child.wait().expect("wait");
    assert!(
        rest.contains("interrupted while building the segment") && !rest.contains("serving"),
        "{status:?}: {rest}"
    );
}

// --- item 11: no lost data ---

#[test]
fn record_that_fails_leaves_the_users_file_as_it_was() {
    let d = work_dir("keep");
    std::fs::write(d.join("keep.csv"), "precious\n").expect("write");
    // Fails after the segment is up (the DC configuration), and with a bad variable.
    for args in [
        &[
            "record",
            "0.Button1",
            "--cycle",
            "5s",
            "--duration",
            "10s",
            "-o",
            "keep.csv",
            "--sim",
            "demo:1",
        ][..],
        &["record", "0.NoSuch", "-o", "keep.csv", "--sim", "demo:1"][..],
    ] {
        error_in(&d, args);
        assert_eq!(
            std::fs::read_to_string(d.join("keep.csv")).expect("read"),
            "precious\n"
        );
    }
    let names: Vec<_> = std::fs::read_dir(&d).expect("dir").collect();
    assert_eq!(names.len(), 1, "no temporary file left");
}

#[test]
fn sii_write_of_an_image_larger_than_the_eeprom_writes_nothing() {
    let d = work_dir("sii-large");
    let img = oxicat_esi::sii::generate(&oxicat_devices::demo::DEF).expect("image");
    let mut big = img.clone();
    big.resize(img.len() * 2, 0xFF);
    std::fs::write(d.join("big.bin"), &big).expect("write");
    let err = error_in(&d, &["sii-write", "big.bin", "--sim", "demo:1"]);
    assert!(
        err.contains(&format!(
            "{} bytes do not fit slave 0's EEPROM of {} bytes",
            big.len(),
            img.len()
        )) && err.contains("nothing was written"),
        "{err}"
    );
    assert!(
        !d.join("sii-backup-0.bin").exists(),
        "refused before the backup"
    );
    // An image for another device: refused before the backup too.
    let mut other = img.clone();
    other[0x10] ^= 0x55;
    std::fs::write(d.join("other.bin"), &other).expect("write");
    let err = error_in(&d, &["sii-write", "other.bin", "--sim", "demo:1"]);
    assert!(err.contains("--force"), "{err}");
    assert!(
        !d.join("sii-backup-0.bin").exists(),
        "no backup for a refused image"
    );
}

#[test]
fn sii_write_keeps_a_backup_of_the_old_image_and_names_it() {
    let d = work_dir("sii-backup");
    let out = ok_in(&d, &["sii-write", "--device", "demo", "--sim", "demo:1"]);
    assert!(
        out.contains("the old image is in sii-backup-0.bin"),
        "{out}"
    );
    let old = std::fs::read(d.join("sii-backup-0.bin")).expect("backup");
    let img = oxicat_esi::sii::generate(&oxicat_devices::demo::DEF).expect("image");
    assert_eq!(old, img, "the slave's whole EEPROM before the write");
    // A second write keeps the first backup.
    let out = ok_in(&d, &["sii-write", "--device", "demo", "--sim", "demo:1"]);
    assert!(out.contains("sii-backup-0-1.bin"), "{out}");
}

#[test]
fn sii_write_that_stops_half_way_says_half_written_and_names_the_backup() {
    let d = work_dir("sii-half");
    // A demo node whose EEPROM acknowledges no write from word 0x40 on.
    let seg = d.join("segment.toml");
    std::fs::write(
        &seg,
        "[[device]]\nname = \"demo\"\neeprom_protect_from_word = 0x40\n",
    )
    .expect("write");
    let served = served_common::serve_file(&seg);
    let udp = served.addr.as_str();
    let img = oxicat_esi::sii::generate(&oxicat_devices::demo::DEF).expect("image");
    let err = error_in(&d, &["sii-write", "--device", "demo", "--udp", udp]);
    assert!(err.contains("write of word 0x0040 refused"), "{err}");
    assert!(
        err.contains("the EEPROM of slave 0 is half written; the old image is in sii-backup-0.bin")
            && err.contains("oxicat sii-write -p 0 --force sii-backup-0.bin")
            && err.contains(&format!("(64 of {} words were written)", img.len() / 2)),
        "{err}"
    );
    let backup = std::fs::read(d.join("sii-backup-0.bin")).expect("backup");
    assert_eq!(backup, img, "the backup is the whole old image");
}

// --- item 12: no silently wrong values ---

#[test]
fn a_type_that_does_not_fit_the_object_is_an_error() {
    let d = work_dir("types");
    for t in ["u8", "double"] {
        let err = error_in(&d, &["upload", "0x1018", "1", "-t", t, "--sim", "demo:1"]);
        assert!(err.contains("0x1018:01 holds 4 byte(s)"), "{t}: {err}");
    }
    let err = error_in(
        &d,
        &[
            "download", "0x10f1", "2", "1", "-t", "u8", "--sim", "demo:1",
        ],
    );
    assert!(err.contains("0x10F1:02 holds"), "{err}");
    let err = error_in(&d, &["reg-read", "0x0130", "0", "--sim", "demo:1"]);
    assert!(err.contains("length 0"), "{err}");
    let err = error_in(
        &d,
        &["reg-read", "0x0130", "1", "-t", "u32", "--sim", "demo:1"],
    );
    assert!(
        err.contains("type u32 is 4 byte(s), the length given is 1"),
        "{err}"
    );
}

#[test]
fn dash_means_standard_output() {
    let d = work_dir("dash");
    let (ok, out, err) = {
        let o = Command::new(env!("CARGO_BIN_EXE_oxicat"))
            .args(["sii-read", "--raw", "-o", "-", "--sim", "demo:1"])
            .current_dir(&d)
            .output()
            .expect("runs");
        (
            o.status.success(),
            o.stdout,
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    assert!(ok, "{err}");
    assert_eq!(out.len(), 2048, "the raw image on stdout");
    let out = ok_in(&d, &["device", "demo", "esi", "-o", "-"]);
    assert!(out.starts_with("<?xml"), "{out}");
    let out = ok_in(
        &d,
        &[
            "record",
            "0.Button1",
            "--cycle",
            "1ms",
            "--duration",
            "3ms",
            "-o",
            "-",
            "--sim",
            "demo:1",
        ],
    );
    assert_eq!(out.lines().count(), 4, "{out}");
    assert!(!d.join("-").exists(), "no file called -");
}

#[test]
fn a_device_name_on_two_slaves_records_two_named_columns() {
    let d = work_dir("names");
    let slaves = ok_in(&d, &["slaves", "--sim", "demo:1"]);
    let name = slaves
        .lines()
        .nth(1)
        .and_then(|l| l.split_whitespace().last())
        .expect("name");
    let var = format!("{name}.Button1");
    let out = ok_in(
        &d,
        &[
            "record",
            &var,
            "--cycle",
            "1ms",
            "--duration",
            "2ms",
            "-o",
            "-",
            "--sim",
            "demo:2",
        ],
    );
    assert_eq!(
        out.lines().next(),
        Some("cycle,time [s],0.Button1 [BOOL],1.Button1 [BOOL]"),
        "{out}"
    );
}

// --- item 13: messages that say what is wrong ---

#[test]
fn messages_name_the_real_problem() {
    let d = work_dir("messages");
    let err = error_in(&d, &["trot", "--scenario", "/nope.toml", "-q"]);
    assert!(
        err.contains("/nope.toml: ") && !err.contains("interface"),
        "{err}"
    );
    let err = error_in(&d, &["reg-read", "0xfff0", "32", "--sim", "demo:1"]);
    assert!(
        err.contains("beyond the ESC's address space") && !err.contains("not answering"),
        "{err}"
    );
    let err = error_in(&d, &["slaves", "--sim", ","]);
    assert!(
        err.contains("names no devices") && !err.contains("cable"),
        "{err}"
    );
    let err = error_in(
        &d,
        &["xml", "-o", "/nonexistent-dir/x.xml", "--sim", "demo:1"],
    );
    assert!(err.contains("/nonexistent-dir/x.xml"), "{err}");
    // FoE: the default name (the file's) is not one the slave takes.
    std::fs::write(d.join("fw.bin"), b"not firmware").expect("write");
    let err = error_in(&d, &["foe-write", "fw.bin", "--sim", "demo:1"]);
    assert!(
        err.contains("no file named \"fw.bin\"") && err.contains("--name"),
        "{err}"
    );
    // Intel HEX with a wrong checksum.
    std::fs::write(d.join("bad.hex"), ":0400000001020304F0\n:00000001FF\n").expect("write");
    let err = error_in(&d, &["sii-write", "bad.hex", "--sim", "demo:1"]);
    assert!(err.contains("checksum"), "{err}");
}

#[test]
fn help_text_has_no_markdown_escapes() {
    use clap::CommandFactory;
    fn walk(c: &mut clap::Command, path: &str) {
        let help = c.render_long_help().to_string();
        assert!(!help.contains("\\["), "{path}: {help}");
        for s in c.get_subcommands_mut() {
            let p = format!("{path} {}", s.get_name());
            walk(s, &p);
        }
    }
    walk(&mut oxicat::Cli::command(), "oxicat");
}

#[test]
fn a_closed_standard_output_ends_quietly() {
    // Every kind of printing verb: a master verb, and the ones that need no segment
    // (`device list`, `version` printed with `print!` and panicked on a closed pipe).
    for args in [
        &["sdos", "--sim", "demo:1"][..],
        &["device", "list"][..],
        &["version"][..],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_oxicat"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn");
        // The reader goes away before anything is written (`| head -0`).
        drop(child.stdout.take());
        let o = child.wait_with_output().expect("wait");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{args:?}: {:?}: {err}", o.status);
        assert!(err.is_empty(), "{args:?}: {err}");
    }
}
