//! The master verbs of the `oxicat` binary as a new user runs them (README "Master tool"):
//! `oxicat sim --iface <veth end> laelaps-leg:4` in a network namespace, and separate
//! `oxicat` processes on the other end — scan, `states op` that sticks between
//! invocations, SDO upload, online write, DC recording to CSV, and the failure messages.
//! Needs root; skipped (with the reason) elsewhere, mandatory in CI.

mod netns_common;

use std::process::Command;

use netns_common::{oxicat_bin, NetnsSim};

fn oxicat(args: &[&str]) -> (bool, String, String) {
    // In a directory of its own: `sii-write` leaves its backup of the old image there.
    let cwd = std::env::temp_dir().join(format!("oxicat-master-netns-cwd-{}", std::process::id()));
    std::fs::create_dir_all(&cwd).expect("work dir");
    let o = Command::new(oxicat_bin())
        .args(args)
        .current_dir(&cwd)
        .env_remove("OXICAT_IFACE")
        // The sim and every master run as processes on a small, possibly loaded CI box: a
        // frame may wait for a CPU far longer than on a real NIC, so allow 2 s per frame.
        .env("OXICAT_TIMEOUT_MS", "2000")
        .output()
        .expect("oxicat runs");
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn ok(bench: &NetnsSim, args: &[&str]) -> String {
    let mut a = args.to_vec();
    a.extend(["--iface", bench.master_if()]);
    let (s, out, err) = oxicat(&a);
    assert!(s, "oxicat {a:?} failed: {err}\nsim: {:?}", bench.sim_log());
    out
}

fn fails(bench: &NetnsSim, args: &[&str]) -> String {
    let mut a = args.to_vec();
    a.extend(["--iface", bench.master_if()]);
    let (s, out, err) = oxicat(&a);
    assert!(!s, "oxicat {a:?} should fail: {out}");
    err
}

/// The state column of `oxicat slaves` (one per slave).
fn states(out: &str) -> Vec<String> {
    out.lines()
        .skip(1)
        .map(|l| l.split_whitespace().nth(3).unwrap_or_default().to_string())
        .collect()
}

#[test]
fn master_verbs_on_a_veth_as_a_new_user() {
    let Some(bench) = NetnsSim::start(&["laelaps-leg:4"]) else {
        return;
    };
    let out = ok(&bench, &["slaves"]);
    assert_eq!(out.lines().count(), 5, "four legs: {out}");
    assert!(out.contains("EtherCAT_Laelaps_Motion_Control"), "{out}");
    assert_eq!(states(&out), vec!["PREOP"; 4], "{out}");

    let out = ok(&bench, &["states", "op"]);
    assert_eq!(out.lines().count(), 4, "{out}");
    for l in out.lines() {
        assert!(l.contains(": OP, free run (0x1C32:01 = 0)"), "{out}");
    }
    // A new process finds them in OP (nothing resets them).
    let out = ok(&bench, &["slaves"]);
    assert_eq!(states(&out), vec!["OP"; 4], "{out}");

    let out = ok(&bench, &["upload", "-p", "0", "0x1018", "1"]);
    assert!(out.starts_with("3758096384 (0xe0000000)"), "{out}");
    let out = ok(&bench, &["slaves", "-p", "2"]);
    assert_eq!(states(&out), vec!["OP"], "upload leaves the state: {out}");

    // Online write of an output (read back while cycling); afterwards the slaves are back in
    // PREOP without an error (nobody cycles: no watchdog left to expire), outputs safe.
    // In the entry's declared unit: 12.34 × 100 = 1234 on the wire.
    let out = ok(&bench, &["write", "1.Kp100_knee", "12.34"]);
    assert_eq!(out, "1.Kp100_knee = 12.34\n");
    let out = ok(&bench, &["slaves"]);
    assert_eq!(states(&out), vec!["PREOP"; 4], "{out}");

    // DC-synchronous recording.
    let dir = std::env::temp_dir().join(format!("oxicat-netns-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("run.csv");
    let out = ok(
        &bench,
        &[
            "record",
            "--cycle",
            "400us",
            "--duration",
            "1s",
            "0.knee_angle",
            "3.hip_angle",
            "-o",
            csv.to_str().unwrap(),
        ],
    );
    assert!(out.contains("cycles of 2 variables"), "{out}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "cycle,time [s],0.knee_angle [deg],3.hip_angle [deg]"
    );
    assert!(lines.len() > 100, "{} rows", lines.len() - 1);
    assert!(lines[1..].iter().all(|l| l.split(',').count() == 4));
    let _ = std::fs::remove_dir_all(&dir);

    // After the DC recording, a free-run verb still reaches OP.
    let out = ok(
        &bench,
        &["watch", "0.knee_angle", "--every", "10", "--count", "2"],
    );
    assert_eq!(out.lines().count(), 2, "{out}");

    // Failure messages.
    let err = fails(&bench, &["upload", "-p", "0", "0x5555", "0"]);
    assert!(
        err.contains("0x06020000 The object does not exist"),
        "{err}"
    );
    let err = fails(
        &bench,
        &["download", "-p", "0", "0x7020", "1", "70000", "-t", "u16"],
    );
    assert!(err.contains("not valid for type u16"), "{err}");
    let err = fails(&bench, &["sii-write", "-p", "0", "--device", "demo"]);
    assert!(err.contains("--force"), "{err}");
    let err = fails(&bench, &["upload", "-p", "7", "0x1018", "1"]);
    assert!(err.contains("no slave at position 7"), "{err}");
    let (s, _, err) = oxicat(&["slaves", "--iface", "nosuch0"]);
    assert!(!s);
    assert!(err.contains("does not exist"), "{err}");
}

#[test]
fn no_slaves_when_the_sim_is_not_running() {
    let Some(bench) = NetnsSim::bare() else {
        return;
    };
    let err = fails(&bench, &["slaves"]);
    assert!(err.contains("no slaves"), "{err}");
    assert!(err.contains("oxicat sim"), "{err}");
}
