//! `oxicat cia402 <enable|disable|mode|move>`: CiA402 drives driven from the master
//! (`oxicat_devices::cia402::master`), on a virtual segment of `--joints` CiA402 joint drives
//! (firmware + BLDC joint plant) or on a network interface (`--iface`).
//!
//! - `enable`: fault reset if needed, then 0x06 → 0x07 → 0x0F, the statusword printed and
//!   checked after each step;
//! - `disable`: 0x07 (if enabled), then 0x00 → Switch on disabled;
//! - `mode <m>`: 0x6060 until 0x6061 shows it;
//! - `move <target>`: CSP, enable, a smooth move of every drive, then per joint RMS and
//!   max following error; `cia402.csv` (every cycle) and `following-error.png`/`.svg` in `--out`.
//! - `task-period`: the paper's Experiment 2 (task period 1000 µs on the wire) on the virtual
//!   segment: a table of the frame period, SYNC0 period and round trip
//!   (`oxicat_devices::cia402::task_period`).
//!
//! A virtual segment starts fresh with each invocation, so `disable` and `mode` there
//! first enable (to have something to disable / to show the mode in Operation enabled).

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_devices::cia402::master::{self as cia402, mode, Action};
use oxicat_devices::cia402::rig::{attach, BldcJointParams};
use oxicat_master::{Link, Master, MasterError};
use oxicat_sim::segment::Segment;

use crate::{CliError, UsageError};

/// Arguments of `oxicat cia402`.
#[derive(Debug, clap::Args)]
pub struct Cia402Args {
    /// What to do.
    #[command(subcommand)]
    pub verb: Cia402Verb,
    /// CiA402 joint drives on the virtual segment (1 … 1000).
    #[arg(long, default_value_t = 1)]
    pub joints: usize,
    /// A network interface instead of the virtual segment.
    #[arg(long)]
    pub iface: Option<String>,
    /// Cycle time in µs (100 … 50000).
    #[arg(long, default_value_t = 1000)]
    pub cycle_us: u64,
    /// Free run instead of DC SYNC0.
    #[arg(long)]
    pub no_dc: bool,
    /// Output directory (`move`).
    #[arg(long, default_value = "out/cia402")]
    pub out: PathBuf,
    /// Recording format of `cia402.csv`: `csv`, `parquet` or `both`.
    #[arg(long, value_enum, default_value = "csv")]
    pub format: crate::output::Format,
}

/// The verbs.
#[derive(Debug, clap::Subcommand)]
pub enum Cia402Verb {
    /// 0x06 → 0x07 → 0x0F (fault reset first if needed).
    Enable,
    /// Disable operation, then disable voltage.
    Disable,
    /// Switch the mode of operation: pp, pv, pt, hm, csp, csv, cst or a number.
    Mode {
        /// The mode.
        mode: String,
    },
    /// CSP move of every drive.
    Move {
        /// Target position in increments.
        target: i32,
        /// Relative to the position at the start of the move.
        #[arg(long)]
        relative: bool,
        /// Duration of the move in ms (1 … 3600000).
        #[arg(long, default_value_t = 1000)]
        duration_ms: u64,
        /// Move the joints as a six-axis arm: each joint its own share of the target, signs
        /// alternating (base 1, shoulder −0.75, elbow 0.5, wrist −1, 0.6, −0.3).
        #[arg(long)]
        arm: bool,
    },
    /// The paper's task-period experiment on the virtual segment: frame period, SYNC0
    /// period and round trip as a table (virtual segment only).
    TaskPeriod {
        /// Cycles measured (10 … 1000000).
        #[arg(long, default_value_t = 1000)]
        cycles: u64,
    },
}

/// Parses a mode name or number.
pub fn parse_mode(s: &str) -> Result<i8, UsageError> {
    Ok(match s.to_ascii_lowercase().as_str() {
        "pp" => mode::PP,
        "pv" => mode::PV,
        "pt" => mode::PT,
        "hm" => mode::HM,
        "csp" => mode::CSP,
        "csv" => mode::CSV,
        "cst" => mode::CST,
        n => n
            .parse()
            .map_err(|_| UsageError::UnknownMode(s.to_string()))?,
    })
}

/// Shortest cycle: below 100 µs the master's user-space loop cannot keep the cycle (a
/// frame of a few drives alone takes tens of µs), and on the virtual segment such a run
/// does not end.
pub const MIN_CYCLE_US: u64 = 100;
/// Longest cycle: half the drive's 100 ms process-data watchdog.
pub const MAX_CYCLE_US: u64 = 50_000;

/// Refuses arguments that cannot work, before a segment is built.
fn check_args(a: &Cia402Args) -> Result<(), UsageError> {
    let max = crate::master_cmd::MAX_IN_PROCESS_SLAVES;
    if a.iface.is_none() && !(1..=max).contains(&a.joints) {
        return Err(UsageError::OutOfRange {
            option: "--joints",
            value: a.joints.to_string(),
            allowed: format!("1 … {max} drives (what a virtual segment holds)"),
        });
    }
    if !(MIN_CYCLE_US..=MAX_CYCLE_US).contains(&a.cycle_us) {
        return Err(UsageError::OutOfRange {
            option: "--cycle-us",
            value: a.cycle_us.to_string(),
            allowed: format!("{MIN_CYCLE_US} … {MAX_CYCLE_US} µs (below {MIN_CYCLE_US} µs the master cannot keep the cycle; above {MAX_CYCLE_US} µs the drive's 100 ms process-data watchdog comes close)"),
        });
    }
    if let Cia402Verb::TaskPeriod { cycles } = a.verb {
        if !(10..=1_000_000).contains(&cycles) {
            return Err(UsageError::OutOfRange {
                option: "--cycles",
                value: cycles.to_string(),
                allowed: "10 … 1000000 cycles".into(),
            });
        }
        if let Some(i) = &a.iface {
            return Err(UsageError::OutOfRange {
                option: "--iface",
                value: i.clone(),
                allowed:
                    "none: task-period measures in the virtual segment's own capture and clock"
                        .into(),
            });
        }
    }
    if let Cia402Verb::Move { duration_ms, .. } = a.verb {
        if !(1..=3_600_000).contains(&duration_ms) {
            return Err(UsageError::OutOfRange {
                option: "--duration-ms",
                value: duration_ms.to_string(),
                allowed: "1 … 3600000 ms".into(),
            });
        }
    }
    Ok(())
}

/// The virtual device, as errors name it.
const BENCH: &str = "CiA402 joint";

fn link(a: &Cia402Args) -> Result<Link, CliError> {
    if let Some(i) = &a.iface {
        return Ok(Link::Iface(i.clone()));
    }
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(&oxicat_devices::cia402::DEF).map_err(|error| {
        CliError::BenchSii {
            bench: BENCH,
            error,
        }
    })?;
    for _ in 0..a.joints {
        let id = seg.add(oxicat_esc::Esc::new(
            oxicat_esc::EscConfig::et1100(),
            sii.clone(),
        ));
        attach(&mut seg, id, BldcJointParams::default()).map_err(|error| {
            CliError::BenchFirmware {
                bench: BENCH,
                error,
            }
        })?;
    }
    Ok(Link::Sim(Arc::new(Mutex::new(seg))))
}

/// Runs `oxicat cia402`; returns the text it printed.
pub fn run(a: Cia402Args) -> Result<String, CliError> {
    check_args(&a)?;
    if let Cia402Verb::TaskPeriod { cycles } = a.verb {
        let t = oxicat_devices::cia402::task_period::run(
            a.joints,
            cycles,
            Duration::from_micros(a.cycle_us),
            !a.no_dc,
        )?;
        return Ok(t.markdown());
    }
    let sim = a.iface.is_none();
    let mut m = Master::open(link(&a)?)?;
    let drives: Vec<usize> = (0..m.len()).collect();
    let mut actions = vec![Action::ClearFault];
    match &a.verb {
        Cia402Verb::Enable => actions.push(Action::Enable),
        Cia402Verb::Disable => {
            if sim {
                actions.push(Action::Enable);
            }
            actions.push(Action::Disable);
        }
        Cia402Verb::Mode { mode } => {
            actions.push(Action::Mode(parse_mode(mode)?));
            if sim {
                actions.push(Action::Enable);
            }
        }
        Cia402Verb::TaskPeriod { .. } => {}
        Cia402Verb::Move {
            target,
            relative,
            duration_ms,
            ..
        } => {
            actions.push(Action::Mode(mode::CSP));
            actions.push(Action::Enable);
            actions.push(Action::Move {
                target: *target,
                relative: *relative,
                duration: Duration::from_millis(*duration_ms),
            });
        }
    }
    let cycle = Duration::from_micros(a.cycle_us);
    let amplitude = match a.verb {
        Cia402Verb::Move { arm: true, .. } => cia402::arm_amplitudes(drives.len()),
        _ => Vec::new(),
    };
    let r = cia402::run_scaled(&mut m, &drives, &actions, cycle, !a.no_dc, &amplitude)?;
    let mut out = String::new();
    for s in &r.steps {
        let _ = writeln!(
            out,
            "drive {}: {:<34} statusword 0x{:04X} ({})",
            s.drive,
            s.what,
            s.statusword,
            s.state
                .map_or("no state".to_string(), |st| format!("{st:?}"))
        );
    }
    if let Cia402Verb::Move { .. } = a.verb {
        std::fs::create_dir_all(&a.out).map_err(|e| MasterError::File(a.out.clone(), e))?;
        let written = crate::output::write_recording(&a.out, "cia402", &r.csv(), a.format)?;
        let csv = written
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ");
        let figures = cia402::write_following_error_plots(&r, drives.len(), &a.out)?;
        for (d, (rms, max)) in r.following_error(drives.len()).iter().enumerate() {
            let _ = writeln!(
                out,
                "joint {d}: CSP following error RMS {rms:.1} counts, max {max} counts"
            );
        }
        let _ = writeln!(
            out,
            "wrote {}, {} and {}",
            csv,
            figures[0].display(),
            figures[1].display()
        );
    }
    Ok(out)
}
