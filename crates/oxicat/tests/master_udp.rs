//! Master verbs on a segment served with EtherCAT over UDP (`--udp host:port`, as
//! `oxicat sim --udp` serves it), each verb its own master as each `oxicat` invocation is:
//! state sequences, mailbox after state changes, two masters on one segment.

mod served_common;

use served_common::{cli, fails, ok, serve};

#[test]
fn udp_reaches_a_served_segment() {
    let s = serve(&["demo:2"]);
    let out = ok(&s, &["slaves"]);
    assert_eq!(out.lines().count(), 3, "{out}");
    assert!(out.contains("0xe0000000"), "{out}");
    let out = ok(&s, &["upload", "-p", "1", "0x1018", "1"]);
    assert!(out.starts_with("3758096384 (0xe0000000)"), "{out}");
    let out = ok(&s, &["states", "op"]);
    assert!(out.contains("0: OP") && out.contains("1: OP"), "{out}");
    // The segment keeps the state between masters.
    let out = ok(&s, &["slaves"]);
    assert_eq!(out.matches(" OP ").count(), 2, "{out}");
    drop(s);
    let err = served_common::cli(&["slaves", "--udp", "no.such.host.invalid:34980"]).unwrap_err();
    assert!(err.contains("no.such.host.invalid:34980"), "{err}");
}

/// Each command is a new master; the slave drops a mailbox message that repeats the counter
/// of the one before (ETG.1000.4), so a new master must not start where the last one ended.
#[test]
fn foe_read_right_after_init_and_preop() {
    let s = serve(&["demo:1"]);
    ok(&s, &["states", "init"]);
    ok(&s, &["states", "preop"]);
    let out = ok(&s, &["foe-read", "version.txt"]);
    assert!(out.contains("vendor_id=0xE0000000"), "{out}");
    // After an SDO exchange of another master, and after an FoE read of another master.
    ok(&s, &["upload", "0x1018", "1"]);
    let out = ok(&s, &["foe-read", "version.txt"]);
    assert!(out.contains("vendor_id=0xE0000000"), "{out}");
    let out = ok(&s, &["foe-read", "version.txt"]);
    assert!(out.contains("vendor_id=0xE0000000"), "{out}");
}

/// `--sim` and `oxicat sim` take the same devices (one registry) in the same syntaxes:
/// `dev:n,dev:n` and `dev:n dev:n`.
#[test]
fn sim_and_served_take_both_syntaxes_and_every_device() {
    for spec in [
        "demo:1,tue-es030:1",
        "demo:1 tue-es030:1",
        " demo , tue-es030:1 ",
    ] {
        let out = cli(&["slaves", "--sim", spec]).unwrap_or_else(|e| panic!("{spec:?}: {e}"));
        assert_eq!(out.lines().count(), 3, "{spec:?}: {out}");
        assert!(out.contains("0x0000e030"), "{out}");
    }
    let err = cli(&["slaves", "--sim", "demo:1,nosuch:2"]).unwrap_err();
    assert!(err.contains("nosuch") && err.contains("tue-es030"), "{err}");
    let s = serve(&["demo:1,demo-additions:1", "tue-es030"]);
    let out = ok(&s, &["slaves"]);
    assert_eq!(out.lines().count(), 4, "{out}");
    let _ = fails;
}

/// BOOT has no CoE: `states boot` must not ask the slave for anything over CoE.
#[test]
fn states_boot_and_back() {
    let s = serve(&["demo:1"]);
    let out = ok(&s, &["states", "boot"]);
    assert_eq!(out, "0: BOOT\n");
    let out = ok(&s, &["slaves"]);
    assert!(out.contains(" BOOT "), "{out}");
    let out = ok(&s, &["states", "preop"]);
    assert_eq!(out, "0: PREOP\n");
    let out = ok(&s, &["upload", "0x1018", "1"]);
    assert!(out.starts_with("3758096384"), "{out}");
}

/// TUeES030 refuses free run (0x1C32:01 range, 0x1C32:04 = SM-synchronous only): `states op`
/// gives it SM2-synchronous, says so, and takes every slave to OP.
#[test]
fn states_op_with_a_slave_that_does_not_run_free() {
    let s = serve(&["demo:1,tue-es030:1,demo:1"]);
    let out = ok(&s, &["states", "op"]);
    let lines: Vec<_> = out.lines().collect();
    assert_eq!(lines.len(), 3, "{out}");
    assert_eq!(lines[0], "0: OP, free run (0x1C32:01 = 0)");
    assert!(
        lines[1].starts_with("1: OP, SM2 synchronous (0x1C32:01 = 1)")
            && lines[1].contains("does not run free (0x1C32:04 = 0x0002)"),
        "{out}"
    );
    assert_eq!(lines[2], "2: OP, free run (0x1C32:01 = 0)");
    let out = ok(&s, &["slaves"]);
    assert_eq!(out.matches(" OP ").count(), 3, "{out}");
    // And again from OP, and back down and up.
    ok(&s, &["states", "op"]);
    ok(&s, &["states", "preop"]);
    let out = ok(&s, &["states", "safeop", "-p", "1"]);
    assert!(out.starts_with("1: SAFEOP, SM2 synchronous"), "{out}");
}

/// The cyclic verbs start from any state (ethercrab takes every slave through INIT) and
/// leave the segment in PREOP without an error when they end (no process-data watchdog
/// left to expire).
#[test]
fn cyclic_verbs_start_from_init_and_leave_preop() {
    let s = serve(&["demo:2"]);
    ok(&s, &["states", "init"]);
    let out = ok(
        &s,
        &["watch", "0.InINT32Var3", "--every", "1", "--count", "2"],
    );
    assert_eq!(out.lines().count(), 2, "{out}");
    let out = ok(&s, &["write", "1.OutINT32Var1", "-5", "--settle", "3"]);
    assert!(out.contains("1.OutINT32Var1 = -5"), "{out}");
    // Longer than the demo's process-data watchdog (100 ms).
    std::thread::sleep(std::time::Duration::from_millis(400));
    let out = ok(&s, &["slaves"]);
    assert_eq!(out.matches(" PREOP ").count(), 2, "{out}");
    assert!(!out.contains("ERR"), "{out}");
}
