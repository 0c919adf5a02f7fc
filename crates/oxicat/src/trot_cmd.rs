//! `oxicat trot`: the Laelaps II trotting experiment (thesis §4, Table 4-1) on the virtual
//! segment — four leg nodes, ethercrab at a 400 µs DC cycle, the thesis' procedure — and
//! its results: `trot.csv`, the seven §4.1 figures (PNG + SVG) and `summary.md`.

use std::path::PathBuf;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use oxicat_devices::laelaps::experiment::{run_trot, Progress, TrotRun};
use oxicat_devices::laelaps::frame::FramePlan;
use oxicat_devices::laelaps::results::{csv, summarize, summary_markdown};
use oxicat_devices::laelaps::scenario::{ExecTime, PdiChip, Scenario};
use oxicat_devices::laelaps::{legs, plot};
use oxicat_master::MasterError;
use oxicat_sim::exec_time::Work;

use crate::{CliError, UsageError};

/// Arguments of `oxicat trot`.
#[derive(Debug, clap::Args)]
pub struct TrotArgs {
    /// Scenario file (TOML; default: the shipped Table 4-1 scenario,
    /// `scenarios/laelaps-trot.toml`).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Length of the steady trot in seconds (the ramps and stands around it stay).
    #[arg(long)]
    pub duration: Option<f64>,
    /// How each leg node's firmware reaches its ESC: `direct` (the software ESC is its PDI),
    /// `lan9252` or `et1100` (the chip driver over the simulated SPI); default: the
    /// scenario's `[pdi] route`.
    #[arg(long, value_name = "direct|lan9252|et1100")]
    pub pdi: Option<String>,
    /// SPI clock in MHz for `--pdi lan9252|et1100` (default: the scenario's `[pdi] spi_mhz`).
    #[arg(long, value_name = "MHZ")]
    pub spi_mhz: Option<u32>,
    /// Run the leg nodes' firmware under the execution-time model (`exec_time = "thesis"`):
    /// each handler keeps the MCU busy for its SPI bus time + 1 µs CPU per SYNC0, and its
    /// writes (the inputs) land when it ends; reports SYNC0 busy/response time and
    /// delayed/lost SYNC0s per node (default: the scenario's `[pdi] exec_time`, off).
    #[arg(long)]
    pub bus_time: bool,
    /// The thesis' DC split with SYNC1 this many µs after SYNC0 (0: with SYNC0, as the
    /// thesis' delay times): the leg nodes map their outputs on the SM2 event, run the
    /// application on SYNC0 and latch their inputs on SYNC1 (0x1C32:01 = 3, 0x1C33:03 =
    /// the shift). Default: the scenario's `bus.sync1` (off: all three on SYNC0).
    #[arg(long, value_name = "US")]
    pub sync1: Option<u32>,
    /// Output directory.
    #[arg(long, default_value = "out/trot")]
    pub out: PathBuf,
    /// Skip the figures.
    #[arg(long)]
    pub no_plots: bool,
    /// Recording format: `csv` (`trot.csv`), `parquet` (`trot.parquet`: the same table,
    /// typed columns, units in its metadata) or `both`.
    #[arg(long, value_enum, default_value = "csv")]
    pub format: crate::output::Format,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs `oxicat trot`; returns the text it printed.
pub fn run(a: TrotArgs) -> Result<String, CliError> {
    run_with(a, &mut |s, progress| {
        Ok((run_trot(s, progress)?, String::new()))
    })
}

/// How a trot is run on a scenario: the run and a Markdown section for `summary.md` about
/// its nodes (empty for none).
pub type TrotRunner<'a> =
    dyn FnMut(&Scenario, &mut dyn FnMut(Progress)) -> Result<(TrotRun, String), MasterError> + 'a;

/// `oxicat trot` with the run made by `runner` (oxicat-emu's `trot` runs the leg nodes'
/// board images): the same options, files and summary.
pub fn run_with(a: TrotArgs, runner: &mut TrotRunner<'_>) -> Result<String, CliError> {
    let mut s = match &a.scenario {
        Some(p) => Scenario::load(p)?,
        None => Scenario::thesis(),
    };
    if let Some(d) = a.duration {
        if !(0.0..=3600.0).contains(&d) {
            return Err(UsageError::OutOfRange {
                option: "--duration",
                value: d.to_string(),
                allowed: "0…3600 s".into(),
            }
            .into());
        }
        s = s.with_trot(d);
    }
    if let Some(p) = &a.pdi {
        let chip = PdiChip::parse(p).ok_or_else(|| UsageError::UnknownPdi(p.clone()))?;
        s = s.with_pdi(chip);
    }
    if let Some(m) = a.spi_mhz {
        if !(1..=100).contains(&m) {
            return Err(UsageError::OutOfRange {
                option: "--spi-mhz",
                value: m.to_string(),
                allowed: "1…100".into(),
            }
            .into());
        }
        s.pdi.spi_mhz = m;
    }
    if a.bus_time {
        s = s.with_exec_time(ExecTime::Thesis);
    }
    if let Some(us) = a.sync1 {
        if us >= s.bus.cycle_us {
            return Err(UsageError::OutOfRange {
                option: "--sync1",
                value: us.to_string(),
                allowed: format!(
                    "0…{} µs (below bus.cycle_us)",
                    s.bus.cycle_us.saturating_sub(1)
                ),
            }
            .into());
        }
        s = s.with_sync1(us);
    }
    std::fs::create_dir_all(&a.out).map_err(|e| MasterError::File(a.out.clone(), e))?;
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        let b = ProgressBar::new(0);
        b.set_style(
            ProgressStyle::with_template(
                "{msg} [{bar:40}] {pos}/{len} cycles ({elapsed}, {eta} left)",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        b.set_message("trot");
        b
    };
    let (run, nodes_md) = runner(&s, &mut |p| {
        bar.set_length(p.total);
        bar.set_position(p.done);
    })?;
    bar.finish_and_clear();
    let t_out = Instant::now();
    let mut files = crate::output::write_recording(&a.out, "trot", &csv(&run), a.format)?;
    let sum = summarize(&run);
    let mut md = summary_markdown(&run, &sum);
    // The thesis' planning check: where the ellipse leaves the reach (held there).
    let reach = s.reach_check();
    if !reach.is_empty() {
        md.push_str("\n## Workspace check\n\n");
        for w in &reach {
            md.push_str(&format!("- {}\n", w.line()));
        }
    }
    // The thesis' Table 2-4: what the master sends each cycle, beside the thesis' frame.
    md.push_str(&FramePlan::of(&run.scenario).markdown());
    let rec_s = run.rows.len() as f64 * s.cycle_ns() as f64 * 1e-9;
    let speed = format!(
        "\nSimulated {:.1} s ({:.1} s recorded) in {:.2} s of wall-clock time ({:.2} s for the \
         recorded part: {}× real time; bring-up {:.2} s).\n",
        run.simulated_s,
        rec_s,
        run.wall.as_secs_f64(),
        run.wall_recorded.as_secs_f64(),
        ratio(rec_s / run.wall_recorded.as_secs_f64().max(1e-9)),
        (run.wall - run.wall_recorded).as_secs_f64(),
    );
    md.push_str(&nodes_md);
    let sum_path = a.out.join("summary.md");
    crate::output::write_file(&sum_path, md.as_bytes())?;
    files.push(sum_path);
    if !a.no_plots {
        files.extend(plot::write_figures(&run, &a.out)?);
        // The desired and measured legs over two steps of the steady trot, animated.
        let legs_path = a.out.join("legs.svg");
        crate::output::write_file(&legs_path, legs::run_svg(&run).as_bytes())?;
        files.push(legs_path);
    }
    md.push_str(&speed);
    if let Some(line) = spi_line(&run) {
        md.push_str(&line);
    }
    md.push_str(&timing_lines(&run));
    md.push_str(&format!(
        "Wrote {} files to {} in {:.2} s.\n",
        files.len(),
        a.out.display(),
        t_out.elapsed().as_secs_f64()
    ));
    Ok(md)
}

/// A speed ratio: one decimal from 1× up, three below (board images run
/// at a few hundredths of real time).
fn ratio(x: f64) -> String {
    if x >= 1.0 {
        format!("{x:.1}")
    } else {
        format!("{x:.3}")
    }
}

/// One line on the SPI bus time per cycle per node, when the nodes used a driver.
fn spi_line(run: &oxicat_devices::laelaps::experiment::TrotRun) -> Option<String> {
    let cycles = run.bus.cycles;
    let per: Vec<f64> = run
        .pdi
        .nodes
        .iter()
        .filter_map(|n| n.spi_us_per_cycle(cycles))
        .collect();
    if per.is_empty() {
        return None;
    }
    let lo = per.iter().copied().fold(f64::MAX, f64::min);
    let hi = per.iter().copied().fold(f64::MIN, f64::max);
    let errors: u64 = run.pdi.nodes.iter().map(|n| n.pdi_errors).sum();
    let range = if hi - lo < 0.005 {
        format!("{lo:.2}")
    } else {
        format!("{lo:.2}–{hi:.2}")
    };
    Some(format!(
        "PDI {}: {range} µs of SPI bus time per {} µs cycle per node; {errors} PDI errors.\n",
        run.pdi.route, run.scenario.bus.cycle_us
    ))
}

/// One line per node on the SYNC0 handler under the execution-time model (nothing when it is
/// off).
fn timing_lines(run: &oxicat_devices::laelaps::experiment::TrotRun) -> String {
    let mut out = String::new();
    for (leg, n) in oxicat_devices::laelaps::rig::LegId::TABLE
        .iter()
        .zip(&run.pdi.nodes)
    {
        let Some(t) = n.timing else { continue };
        let s0 = t.get(Work::Sync0);
        out.push_str(&format!(
            "Exec time {} ({}): SYNC0 busy max {:.3} µs, response max {:.3} µs, {} SYNC0s: {} \
             delayed, {} lost.\n",
            leg.code(),
            run.scenario.pdi.exec_time.name(),
            s0.max_busy_ns as f64 / 1e3,
            s0.max_response_ns as f64 / 1e3,
            s0.runs,
            s0.delayed,
            s0.lost
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use crate::{Cli, Command};

    fn trot(args: &[&str]) -> super::TrotArgs {
        let mut v = vec!["oxicat", "trot"];
        v.extend_from_slice(args);
        match Cli::try_parse_from(v).expect("parses").command {
            Command::Trot(a) => a,
            c => panic!("{c:?}"),
        }
    }

    #[test]
    fn bus_time_is_opt_in() {
        assert!(!trot(&[]).bus_time);
        assert!(!trot(&["--pdi", "lan9252"]).bus_time);
        let a = trot(&["--pdi", "lan9252", "--bus-time"]);
        assert!(a.bus_time);
        assert_eq!(a.pdi.as_deref(), Some("lan9252"));
    }

    #[test]
    fn sync1_is_opt_in_and_range_checked_before_anything_runs() {
        assert_eq!(trot(&[]).sync1, None);
        assert_eq!(trot(&["--sync1", "0"]).sync1, Some(0));
        let mut a = trot(&["--sync1", "400", "--no-plots", "-q"]);
        a.out = std::env::temp_dir().join(format!("oxicat-sync1-{}", std::process::id()));
        let e = super::run_with(a, &mut |_, _| panic!("must not run"))
            .expect_err("400 µs is the whole cycle")
            .to_string();
        assert!(
            e.contains("--sync1") && e.contains("400") && e.contains("0…399"),
            "{e}"
        );
    }
}
