//! `oxicat sweep`: the trot scenario run for every point of a grid of values, in parallel on
//! the local cores, with one summary table (`oxicat_devices::laelaps::sweep`).

use std::path::PathBuf;

use oxicat_devices::laelaps::scenario::DEFAULT_TOML;
use oxicat_devices::laelaps::sweep::{self, Axis};
use oxicat_master::MasterError;

use crate::{CliError, UsageError};

/// Arguments of `oxicat sweep`.
#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// Scenario file to vary (default: the built-in Table 4-1 trot,
    /// `scenarios/laelaps-trot.toml`).
    pub scenario: Option<PathBuf>,
    /// `KEY=V1,V2,…`: a scenario key and its values; several `--set` span a grid (the last
    /// varies fastest). Keys: `control.knee.kp`, `procedure.trot_s`, `leg.FL.a_cm`, …
    #[arg(long = "set", value_name = "KEY=V1,V2,…", required = true)]
    pub set: Vec<String>,
    /// Worker threads (default: the machine's cores).
    #[arg(long, short)]
    pub jobs: Option<usize>,
    /// `I/N`: run only every N-th point starting at the I-th (1-based), for spreading a
    /// sweep over machines; the tables of all shards together are the whole sweep.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<String>,
    /// Output directory: `sweep.csv` (and `point-K/trot.csv` with `--csv`).
    #[arg(long, default_value = "out/sweep")]
    pub out: PathBuf,
    /// Keep every point's `trot.csv`.
    #[arg(long)]
    pub csv: bool,
    /// No progress line.
    #[arg(long, short)]
    pub quiet: bool,
}

fn parse_shard(s: &str) -> Result<(usize, usize), UsageError> {
    s.split_once('/')
        .and_then(|(i, n)| Some((i.trim().parse().ok()?, n.trim().parse().ok()?)))
        .ok_or_else(|| UsageError::BadShard(s.to_string()))
}

/// Runs `oxicat sweep`; returns what it prints.
pub fn run(a: SweepArgs) -> Result<String, CliError> {
    let base = match &a.scenario {
        Some(p) => std::fs::read_to_string(p).map_err(|e| MasterError::File(p.clone(), e))?,
        None => DEFAULT_TOML.to_string(),
    };
    let axes = a
        .set
        .iter()
        .map(|s| Axis::parse(s))
        .collect::<Result<Vec<_>, _>>()?;
    let shard = a.shard.as_deref().map(parse_shard).transpose()?;
    let points = sweep::points(&base, &axes, shard)?;
    let jobs = a
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if jobs == 0 {
        return Err(UsageError::OutOfRange {
            option: "--jobs",
            value: jobs.to_string(),
            allowed: "at least 1".into(),
        }
        .into());
    }
    std::fs::create_dir_all(&a.out).map_err(|e| MasterError::File(a.out.clone(), e))?;
    let quiet = a.quiet || !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let t0 = std::time::Instant::now();
    let results = sweep::run(&points, jobs, a.csv, &|k, n| {
        if !quiet {
            eprint!("\rsweep: {k}/{n} points");
        }
    });
    if !quiet {
        eprintln!();
    }
    let table = sweep::table(&axes, &results);
    let path = a.out.join("sweep.csv");
    crate::output::write_file(&path, table.as_bytes())?;
    let mut files = 1;
    for p in results.iter().flatten() {
        if let Some(text) = &p.csv {
            let dir = a.out.join(format!("point-{}", p.index));
            std::fs::create_dir_all(&dir).map_err(|e| MasterError::File(dir.clone(), e))?;
            crate::output::write_file(&dir.join("trot.csv"), text.as_bytes())?;
            files += 1;
        }
    }
    let mut out = String::from("point");
    for ax in &axes {
        out.push_str(&format!("  {}", ax.key));
    }
    out.push_str("  knee_rms_mean [deg]  hip_rms_mean [deg]\n");
    let mut failed = Vec::new();
    for r in &results {
        match r {
            Ok(p) => {
                out.push_str(&format!("{:>5}", p.index));
                for (_, v) in &p.values {
                    out.push_str(&format!("  {v}"));
                }
                let mean = |f: fn(&oxicat_devices::laelaps::results::LegSummary) -> f64| {
                    p.legs.iter().map(f).sum::<f64>() / p.legs.len() as f64
                };
                out.push_str(&format!(
                    "  {:.4}  {:.4}\n",
                    mean(|l| l.knee_rms_deg),
                    mean(|l| l.hip_rms_deg)
                ));
            }
            Err(e) => failed.push(e.to_string()),
        }
    }
    out.push_str(&format!(
        "{} points ({} failed) on {} workers in {:.1} s; wrote {} files to {}\n",
        results.len(),
        failed.len(),
        jobs.min(points.len().max(1)),
        t0.elapsed().as_secs_f64(),
        files,
        a.out.display()
    ));
    if !failed.is_empty() {
        return Err(CliError::SweepFailed {
            failed: failed.len(),
            points: results.len(),
            table: path,
            first: failed.swap_remove(0),
        });
    }
    Ok(out)
}
