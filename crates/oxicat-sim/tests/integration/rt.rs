//! `oxicat_sim::rt` on this machine: a thread enters SCHED_FIFO, pinned, with the process's
//! memory locked (its own test binary, since `mlockall` holds for the whole process). Needs
//! root (CI runs as root); elsewhere it reports itself skipped.

use oxicat_sim::rt;

fn vm_locked_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
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
fn a_thread_enters_sched_fifo_pinned_with_memory_locked() {
    let root = std::fs::read_to_string("/proc/self/status")
        .map(|s| {
            s.lines()
                .any(|l| l.starts_with("Uid:") && l.split_whitespace().nth(2) == Some("0"))
        })
        .unwrap_or(false);
    if !root {
        assert!(std::env::var_os("CI").is_none(), "CI runs as root");
        eprintln!("skipped: SCHED_FIFO needs root");
        return;
    }
    let cpus = rt::allowed_cpus();
    assert!(!cpus.is_empty(), "the process may run somewhere");
    let cpu = *cpus.last().unwrap();
    let before = vm_locked_kb();
    let (report, inside, outside) = std::thread::spawn(move || {
        let report = rt::enter(&rt::RtOptions {
            cpu: Some(cpu),
            ..rt::RtOptions::fifo(7)
        });
        (report, rt::current(), rt::allowed_cpus())
    })
    .join()
    .unwrap();
    let report = report.expect("SCHED_FIFO as root");
    assert_eq!(
        (report.priority, report.cpu, report.memory_locked),
        (7, Some(cpu), true)
    );
    assert_eq!(
        inside,
        Some(("SCHED_FIFO", 7)),
        "the thread itself runs FIFO 7"
    );
    assert_eq!(outside, vec![cpu], "… pinned to its CPU");
    assert_ne!(
        rt::current().map(|c| c.0),
        Some("SCHED_FIFO"),
        "other threads are left alone"
    );
    assert!(
        vm_locked_kb() > before,
        "memory is locked ({before} kB before)"
    );
}
