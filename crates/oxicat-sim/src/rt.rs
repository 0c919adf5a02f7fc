//! Real-time scheduling for a thread that serves a segment (or runs a master's cycle):
//! `SCHED_FIFO` at a chosen priority, the process's memory locked (no page fault on the
//! frame path), the thread pinned to one CPU.
//!
//! This is what the usual EtherCAT master set-ups do (IgH's and SOEM's examples, TwinCAT's
//! isolated cores): the Linux kernel then runs the thread before every normal one, so a
//! compiler or a browser beside it no longer delays a frame by a time slice. It needs root
//! or `CAP_SYS_NICE` (plus a large enough `RLIMIT_MEMLOCK` for the lock, or
//! `CAP_IPC_LOCK`). Two things stay with the machine's owner and are only reported: the
//! kernel's RT throttling (`/proc/sys/kernel/sched_rt_runtime_us`, by default 0.95 s of
//! every second for all FIFO threads together — a thread that busy-polls with `--spin` is
//! stopped for the remaining 50 ms), and isolating the core (`isolcpus=`).
//!
//! The system calls are made through `thread-priority` and `nix`, whose wrappers are safe:
//! the crate keeps `forbid(unsafe_code)`.

use std::fmt;

/// Lowest and highest `SCHED_FIFO` priority Linux takes.
pub const PRIORITY_RANGE: std::ops::RangeInclusive<u8> = 1..=99;

/// Priority `--rt` takes without a value: above the kernel's interrupt threads' default
/// (50 under PREEMPT_RT) would starve the NIC's own IRQ thread, so just below it.
pub const DEFAULT_PRIORITY: u8 = 49;

/// How a thread should run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RtOptions {
    /// `SCHED_FIFO` priority, in [`PRIORITY_RANGE`].
    pub priority: u8,
    /// Pin the thread to this CPU (index as the kernel numbers them).
    pub cpu: Option<usize>,
    /// Lock all of the process's memory, present and future (`mlockall`).
    pub lock_memory: bool,
}

impl RtOptions {
    /// `SCHED_FIFO` at `priority`, memory locked, not pinned.
    pub fn fifo(priority: u8) -> Self {
        Self {
            priority,
            cpu: None,
            lock_memory: true,
        }
    }
}

/// What [`enter`] did, for a log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RtReport {
    /// The priority the thread runs at.
    pub priority: u8,
    /// The CPU it is pinned to.
    pub cpu: Option<usize>,
    /// Whether memory is locked.
    pub memory_locked: bool,
    /// The kernel's RT runtime per period in µs (`None`: unknown; `-1`: throttling off).
    pub rt_runtime_us: Option<i64>,
}

impl fmt::Display for RtReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "SCHED_FIFO priority {}", self.priority)?;
        if let Some(c) = self.cpu {
            write!(f, ", pinned to CPU {c}")?;
        }
        if self.memory_locked {
            write!(f, ", memory locked")?;
        }
        match self.rt_runtime_us {
            Some(-1) => write!(f, ", RT throttling off"),
            Some(us) => write!(
                f,
                ", RT throttling at {:.0} ms/s (a spinning thread pauses {:.0} ms each second)",
                us as f64 / 1000.0,
                1000.0 - us as f64 / 1000.0
            ),
            None => Ok(()),
        }
    }
}

/// Why a thread could not be made real-time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RtError {
    /// The priority is outside [`PRIORITY_RANGE`].
    BadPriority(u8),
    /// The CPU is not one this process may run on.
    BadCpu {
        /// The CPU asked for.
        cpu: usize,
        /// The CPUs the process may use.
        allowed: Vec<usize>,
    },
    /// The kernel refused `SCHED_FIFO` (no root or `CAP_SYS_NICE`, `RLIMIT_RTPRIO` 0, or a
    /// container without the right).
    Scheduler(String),
    /// The kernel refused to lock memory (`RLIMIT_MEMLOCK`, `CAP_IPC_LOCK`).
    Lock(String),
    /// The kernel refused the CPU affinity.
    Affinity(String),
    /// Not available on this operating system.
    Unsupported,
}

impl fmt::Display for RtError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RtError::BadPriority(p) => write!(
                f,
                "real-time priority {p} is not in {} … {}",
                PRIORITY_RANGE.start(),
                PRIORITY_RANGE.end()
            ),
            RtError::BadCpu { cpu, allowed } => {
                write!(f, "CPU {cpu} is not one this process may use (")?;
                for (i, c) in allowed.iter().enumerate() {
                    write!(f, "{}{c}", if i > 0 { ", " } else { "" })?;
                }
                write!(f, ")")
            }
            RtError::Scheduler(e) => write!(
                f,
                "SCHED_FIFO refused: {e} (needs root or CAP_SYS_NICE and an RLIMIT_RTPRIO above 0)"
            ),
            RtError::Lock(e) => write!(
                f,
                "locking memory refused: {e} (needs root or CAP_IPC_LOCK, or a larger RLIMIT_MEMLOCK)"
            ),
            RtError::Affinity(e) => write!(f, "CPU affinity refused: {e}"),
            RtError::Unsupported => write!(f, "real-time scheduling is only available on Linux"),
        }
    }
}

impl std::error::Error for RtError {}

/// Makes the calling thread real-time as `opts` says: pinned first (so it never runs FIFO
/// on a CPU it should not), then memory locked, then `SCHED_FIFO`. Nothing is changed when
/// an option is out of range.
pub fn enter(opts: &RtOptions) -> Result<RtReport, RtError> {
    if !PRIORITY_RANGE.contains(&opts.priority) {
        return Err(RtError::BadPriority(opts.priority));
    }
    imp::enter(opts)
}

/// The CPUs this process may run on (its affinity mask), in order.
pub fn allowed_cpus() -> Vec<usize> {
    imp::allowed_cpus()
}

/// The calling thread's scheduling policy and priority as the kernel reports them, e.g.
/// `("SCHED_FIFO", 7)` — for tests and status lines.
pub fn current() -> Option<(&'static str, u8)> {
    imp::current()
}

/// The kernel's RT runtime per period, µs (`-1`: throttling off).
pub fn rt_runtime_us() -> Option<i64> {
    std::fs::read_to_string("/proc/sys/kernel/sched_rt_runtime_us")
        .ok()?
        .trim()
        .parse()
        .ok()
}

#[cfg(target_os = "linux")]
mod imp {
    use super::*;
    use nix::sched::{sched_getaffinity, sched_setaffinity, CpuSet};
    use nix::sys::mman::{mlockall, MlockAllFlags};
    use nix::unistd::Pid;
    use thread_priority::unix::{
        set_thread_priority_and_policy, thread_native_id, thread_schedule_policy_param,
        RealtimeThreadSchedulePolicy, ThreadSchedulePolicy,
    };
    use thread_priority::{ThreadPriority, ThreadPriorityValue};

    pub fn allowed_cpus() -> Vec<usize> {
        match sched_getaffinity(Pid::from_raw(0)) {
            Ok(set) => (0..CpuSet::count())
                .filter(|&c| set.is_set(c).unwrap_or(false))
                .collect(),
            Err(_) => Vec::new(),
        }
    }

    pub fn enter(opts: &RtOptions) -> Result<RtReport, RtError> {
        if let Some(cpu) = opts.cpu {
            let allowed = allowed_cpus();
            if !allowed.contains(&cpu) {
                return Err(RtError::BadCpu { cpu, allowed });
            }
            let mut set = CpuSet::new();
            set.set(cpu).map_err(|e| RtError::Affinity(e.to_string()))?;
            // Pid 0 is the calling thread for sched_setaffinity.
            sched_setaffinity(Pid::from_raw(0), &set)
                .map_err(|e| RtError::Affinity(e.to_string()))?;
        }
        if opts.lock_memory {
            mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE)
                .map_err(|e| RtError::Lock(e.to_string()))?;
        }
        let value = ThreadPriorityValue::try_from(opts.priority)
            .map_err(|_| RtError::BadPriority(opts.priority))?;
        set_thread_priority_and_policy(
            thread_native_id(),
            ThreadPriority::Crossplatform(value),
            ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
        )
        .map_err(|e| RtError::Scheduler(format!("{e:?}")))?;
        Ok(RtReport {
            priority: opts.priority,
            cpu: opts.cpu,
            memory_locked: opts.lock_memory,
            rt_runtime_us: rt_runtime_us(),
        })
    }

    pub fn current() -> Option<(&'static str, u8)> {
        let (policy, params) = thread_schedule_policy_param(thread_native_id()).ok()?;
        let name = match policy {
            ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo) => "SCHED_FIFO",
            ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::RoundRobin) => "SCHED_RR",
            ThreadSchedulePolicy::Realtime(_) => "SCHED_DEADLINE",
            ThreadSchedulePolicy::Normal(_) => "SCHED_OTHER",
        };
        Some((name, u8::try_from(params.sched_priority).unwrap_or(0)))
    }
}

#[cfg(not(target_os = "linux"))]
mod imp {
    use super::*;

    pub fn allowed_cpus() -> Vec<usize> {
        Vec::new()
    }

    pub fn enter(_opts: &RtOptions) -> Result<RtReport, RtError> {
        Err(RtError::Unsupported)
    }

    pub fn current() -> Option<(&'static str, u8)> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_range_options_are_refused_before_anything_changes() {
        let before = current();
        for p in [0, 100, 255] {
            let e = enter(&RtOptions::fifo(p)).unwrap_err();
            assert_eq!(e, RtError::BadPriority(p));
            assert!(e.to_string().contains("1 … 99"), "{e}");
        }
        let e = enter(&RtOptions {
            cpu: Some(100_000),
            ..RtOptions::fifo(5)
        })
        .unwrap_err();
        assert!(matches!(e, RtError::BadCpu { cpu: 100_000, .. }), "{e:?}");
        assert!(e.to_string().contains("CPU 100000 is not one"), "{e}");
        assert_eq!(current(), before, "the thread was left as it was");
    }

    #[test]
    fn the_report_names_throttling() {
        let r = RtReport {
            priority: 7,
            cpu: Some(1),
            memory_locked: true,
            rt_runtime_us: Some(950_000),
        };
        assert_eq!(
            r.to_string(),
            "SCHED_FIFO priority 7, pinned to CPU 1, memory locked, RT throttling at 950 ms/s \
             (a spinning thread pauses 50 ms each second)"
        );
    }
}
