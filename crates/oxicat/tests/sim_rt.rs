//! `oxicat sim --rt`: the serving thread under SCHED_FIFO with memory locked, a master
//! cycling against it, and the options refused with their ranges. Needs root (CI runs as
//! root); elsewhere the test that changes scheduling reports itself skipped.

use std::process::Command;
use std::time::{Duration, Instant};

use oxicat_master::cyclic::CycleOptions;
use oxicat_master::{Link, Master};
use oxicat_testkit::served::spawn_udp;

mod bin_common;

fn is_root() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Uid:"))
                .map(|l| l.split_whitespace().nth(2) == Some("0"))
        })
        .unwrap_or(false)
}

/// (policy, rt_priority) of every thread of `pid`, from `/proc/PID/task/*/stat` (fields 41
/// and 40, counted after the parenthesised name).
fn thread_policies(pid: u32) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return out;
    };
    for t in dir.flatten() {
        let Ok(stat) = std::fs::read_to_string(t.path().join("stat")) else {
            continue;
        };
        // Fields after "pid (comm)": the state is field 3, so field n is index n - 3.
        let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else {
            continue;
        };
        let f: Vec<&str> = rest.split_whitespace().collect();
        if let (Some(prio), Some(policy)) = (f.get(40 - 3), f.get(41 - 3)) {
            out.push((policy.parse().unwrap_or(0), prio.parse().unwrap_or(0)));
        }
    }
    out
}

fn vm_locked_kb(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmLck:"))
                .and_then(|l| l.split_whitespace().nth(1).map(str::to_string))
        })
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

#[test]
fn a_served_segment_runs_from_one_fifo_thread_with_memory_locked() {
    if !is_root() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI runs as root: SCHED_FIFO must be tested there"
        );
        eprintln!("skipped: SCHED_FIFO needs root");
        return;
    }
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_oxicat"));
    cmd.args(["sim", "--quiet", "--rt=7", "--udp", "127.0.0.1:0", "demo:2"]);
    let (sim, addr) = spawn_udp(cmd);
    let pid = sim.id();
    // The thread enters SCHED_FIFO right after printing where it serves.
    let deadline = Instant::now() + Duration::from_secs(20);
    let fifo = loop {
        let fifo: Vec<_> = thread_policies(pid)
            .into_iter()
            .filter(|&(policy, _)| policy == 1)
            .collect();
        if !fifo.is_empty() || Instant::now() > deadline {
            break fifo;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(
        fifo,
        [(1, 7)],
        "exactly one SCHED_FIFO thread, at priority 7"
    );
    assert!(vm_locked_kb(pid) > 0, "the process's memory is locked");
    let run = std::thread::Builder::new()
        .stack_size(16 << 20)
        .spawn(move || {
            let mut m = Master::open(Link::Udp(addr)).expect("master on UDP");
            m.scan().expect("scan");
            m.run_cycles(
                CycleOptions {
                    cycle: Duration::from_millis(1),
                    dc: false,
                },
                200,
            )
            .expect("OP and cycling")
        })
        .unwrap();
    let stats = run.join().expect("master thread");
    assert_eq!((stats.cycles, stats.wkc_errors), (200, 0));
}

/// `oxicat sim ARGS`, which must fail; its standard error.
fn sim_error(args: &[&str]) -> String {
    let args = [&["sim"][..], args].concat();
    let (ok, _, err) = bin_common::oxicat_in(None, &args);
    assert!(!ok, "{args:?} must fail");
    err
}

#[test]
fn real_time_options_out_of_range_are_refused() {
    let udp = ["--udp", "127.0.0.1:0", "demo:1"];
    for bad in ["--rt=0", "--rt=100"] {
        let m = sim_error(&[&[bad][..], &udp[..]].concat());
        assert!(m.contains("--rt") && m.contains("1..=99"), "{bad}: {m}");
    }
    let m = sim_error(&[&["--rt=x"][..], &udp[..]].concat());
    assert!(m.contains("invalid value 'x' for '--rt"), "{m}");
    let m = sim_error(&[&["--rt-cpu", "0"][..], &udp[..]].concat());
    assert!(m.contains("--rt"), "--rt-cpu alone: {m}");
    // `--rt` takes its value only as `--rt=PRIO`: a bare `--rt` keeps the next word a device.
    let m = sim_error(&["--rt", "--udp", "127.0.0.1:0", "nosuchdevice:1"]);
    assert!(m.contains("unknown device \"nosuchdevice\""), "{m}");
    if is_root() {
        let m = sim_error(&[
            "--rt=5",
            "--rt-cpu",
            "4096",
            "--quiet",
            "--udp",
            "127.0.0.1:0",
            "demo:1",
        ]);
        assert!(
            m.contains("CPU 4096 is not one this process may use"),
            "{m}"
        );
    }
}
