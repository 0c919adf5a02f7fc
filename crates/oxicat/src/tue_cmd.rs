//! `oxicat tue-es030 <normal|frf>`: the TUeES030 motor I/O board on the virtual segment
//! (firmware + three RE 30 channels), driven as the manual's Simulink blocks do.
//!
//! - `normal`: parameters written and read back, then a 1 kHz position loop in the master
//!   moves M2 through a profile using current setpoints; `normal.csv` records every cycle.
//! - `frf`: switch to FRF mode, stream a multisine current excitation to M2 at 20 kHz (22
//!   setpoints per 1 ms cycle with the manual's flow control), check that no sample was
//!   lost, compute the closed-loop response, its bandwidth and phase margin, for the
//!   manual's P = 6, I = 4, limit 1 and for P = 10; `frf.csv`, `bode.png`/`bode.svg`.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use indicatif::{ProgressBar, ProgressStyle};
use oxicat_devices::tue_es030::experiment::{
    self as tue, FrfPoint, Margins, NormalOut, TueMode, TueParams,
};
use oxicat_devices::tue_es030::rig::{attach, TueConfig};
use oxicat_master::{Link, Master, MasterError};
use oxicat_sim::segment::Segment;

use crate::{CliError, UsageError};

/// The virtual device, as errors name it.
const BENCH: &str = "TUeES030";

/// Which experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TueExperiment {
    /// Normal mode: position loop in the master through current setpoints.
    Normal,
    /// FRF mode: closed current-loop identification.
    Frf,
}

/// Arguments of `oxicat tue-es030`.
#[derive(Debug, clap::Args)]
pub struct TueArgs {
    /// The experiment.
    #[arg(value_enum)]
    pub experiment: TueExperiment,
    /// Output directory.
    #[arg(long, default_value = "out/tue-es030")]
    pub out: PathBuf,
    /// FRF: current-loop P gains to identify (the manual's 6 and 10 by default).
    #[arg(long, value_delimiter = ',', default_values_t = vec![6.0, 10.0])]
    pub p: Vec<f32>,
    /// FRF: I gain.
    #[arg(long, default_value_t = 4.0)]
    pub i: f32,
    /// FRF: integrator limit in A s.
    #[arg(long, default_value_t = 1.0)]
    pub limit: f32,
    /// FRF: multisine periods (of 100 ms, 10 Hz resolution); the first is discarded.
    #[arg(long, default_value_t = 6)]
    pub periods: usize,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
    /// Recording format: `csv`, `parquet` (same table, typed, units in its metadata) or
    /// `both`.
    #[arg(long, value_enum, default_value = "csv")]
    pub format: crate::output::Format,
}

fn bench() -> Result<Link, CliError> {
    let mut seg = Segment::new();
    let def = &oxicat_devices::tue_es030::device::DEF;
    let sii = oxicat_esi::sii::generate(def).map_err(|error| CliError::BenchSii {
        bench: BENCH,
        error,
    })?;
    let id = seg.add(oxicat_esc::Esc::new(oxicat_esc::EscConfig::et1200(), sii));
    attach(&mut seg, id, &TueConfig::default()).map_err(|error| CliError::BenchFirmware {
        bench: BENCH,
        error,
    })?;
    Ok(Link::Sim(Arc::new(Mutex::new(seg))))
}

fn bar(quiet: bool, msg: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(0);
    b.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    b.set_message(msg.to_string());
    b
}

/// The bench's motor parameters: the RE 30's R and KV, its 500-line encoder.
pub fn bench_params() -> TueParams {
    TueParams {
        r: [0.611; 3],
        kv: [0.0259; 3],
        encres: [500; 3],
        ..TueParams::default()
    }
}

/// Refuses a number that cannot work (NaN, infinite, out of range), naming the option and
/// its range, before anything runs.
pub fn check_args(a: &TueArgs) -> Result<(), UsageError> {
    let range = |option: &'static str, v: f32, lo: f32, hi: f32, why: &'static str| {
        if v.is_finite() && (lo..=hi).contains(&v) {
            Ok(())
        } else {
            Err(UsageError::OutOfBounds {
                option,
                value: v.to_string(),
                lo: lo.to_string(),
                hi: hi.to_string(),
                why,
            })
        }
    };
    if a.p.is_empty() {
        return Err(UsageError::NoGain);
    }
    for &p in &a.p {
        range("--p", p, 0.01, 1000.0, "current-loop P gain, V/A")?;
    }
    range("--i", a.i, 0.0, 1000.0, "current-loop I gain")?;
    range("--limit", a.limit, 0.0, 100.0, "integrator limit, A s")?;
    if !(2..=1000).contains(&a.periods) {
        return Err(UsageError::OutOfBounds {
            option: "--periods",
            value: a.periods.to_string(),
            lo: "2".into(),
            hi: "1000".into(),
            why: "the first period is discarded; 1000 are 100 s",
        });
    }
    Ok(())
}

/// Runs `oxicat tue-es030`; returns the text it printed.
pub fn run(a: TueArgs) -> Result<String, CliError> {
    check_args(&a)?;
    std::fs::create_dir_all(&a.out).map_err(|e| MasterError::File(a.out.clone(), e))?;
    match a.experiment {
        TueExperiment::Normal => normal(&a),
        TueExperiment::Frf => frf(&a),
    }
}

fn normal(a: &TueArgs) -> Result<String, CliError> {
    let link = bench()?;
    let m = Master::open(link.clone())?;
    let (mut m, _) = tue::set_mode(&link, m, 0, TueMode::Normal)?;
    let back = tue::write_params(&m, 0, &bench_params())?;
    let mut out = String::new();
    let _ = writeln!(out, "Motor parameters written and read back: {back:?}");
    let cycles = 2000u64;
    let b = bar(a.quiet, "normal");
    b.set_length(cycles);
    // M2 to 10 revolutions and back (smoothstep moves of 500 ms); PD into the current
    // setpoint: 2 A/rad, 0.02 A s/rad.
    let profile = |t: f64| {
        let s = |x: f64| {
            let x = x.clamp(0.0, 1.0);
            3.0 * x * x - 2.0 * x * x * x
        };
        10.0 * 2.0 * std::f64::consts::PI * (s(t / 0.5) - s((t - 1.0) / 0.5))
    };
    let cpr = 2000.0 / (2.0 * std::f64::consts::PI);
    let mut c0 = None;
    let rows = tue::run_normal(&mut m, 0, cycles, |k, inp| {
        b.set_position(k);
        let mut o = NormalOut::default();
        if k >= 20 {
            let c0 = *c0.get_or_insert(inp.count[1]);
            let pos = inp.count[1].wrapping_sub(c0) as i32 as f64 / cpr;
            let t = (k - 20) as f64 * 1e-3;
            let i = 2.0 * (profile(t) - pos) - 0.02 * inp.velocity[1] as f64 * 0.1;
            o.mcom[1] = 1;
            o.setpoint[1] = (i.clamp(-3.0, 3.0) * 1000.0) as i16;
        }
        o
    })?;
    b.finish_and_clear();
    let written =
        crate::output::write_recording(&a.out, "normal", &tue::normal_csv(&rows), a.format)?;
    let csv = written
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(" and ");
    let c0 = c0.unwrap_or(0);
    let err = rows[20..]
        .iter()
        .map(|r| {
            let t = (r.cycle - 20) as f64 * 1e-3;
            (profile(t) - r.input.count[1].wrapping_sub(c0) as i32 as f64 / cpr).abs()
        })
        .fold(0.0, f64::max);
    let imax = rows
        .iter()
        .map(|r| r.input.current[1].unsigned_abs())
        .max()
        .unwrap_or(0);
    let _ = writeln!(
        out,
        "{} cycles at 1 kHz; M2 followed 0 -> 10 rev -> 0 with max error {:.3} rad, peak current \
         {} mA; line voltage {:.2} V.\nWrote {}",
        rows.len(),
        err,
        imax,
        rows.last().map(|r| r.input.linevoltage).unwrap_or(0) as f64 * 0.01,
        csv
    );
    Ok(out)
}

fn describe(p: f32, mg: &Margins, share: f64, complete: bool) -> String {
    let f = |x: Option<f64>, unit: &str| {
        x.map(|v| format!("{v:.0} {unit}"))
            .unwrap_or_else(|| "beyond the lines".into())
    };
    format!(
        "P = {p}: bandwidth (|T| = -3 dB) {}, peak |T| {:.1} dB, loop crossover {}, phase margin \
         {}, energy outside the excited lines {:.1} %{}{}",
        f(mg.bandwidth, "Hz"),
        mg.peak_db,
        f(mg.crossover, "Hz"),
        mg.phase_margin
            .map(|v| format!("{v:.1} deg"))
            .unwrap_or_else(|| "-".into()),
        share * 100.0,
        if share > 0.3 {
            " -> UNSTABLE (limit cycle; the margins above are not meaningful)"
        } else {
            ""
        },
        if complete {
            ""
        } else {
            " (samples LOST: redo)"
        }
    )
}

fn frf(a: &TueArgs) -> Result<String, CliError> {
    let period = 2000;
    let periods = a.periods;
    let (sp, bins) = tue::multisine(period, periods, 10.0, 9900.0, 60, 400.0);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Multisine: {} lines 10 Hz..9.9 kHz, 400 mA peak, {} periods of {} samples at 20 kHz \
         ({:.1} s), M2, I = {}, limit = {}, feed-forward off.",
        bins.len(),
        periods,
        period,
        sp.len() as f64 / 20_000.0,
        a.i,
        a.limit
    );
    let mut curves: Vec<(String, Vec<FrfPoint>)> = Vec::new();
    let mut csv = String::from("f [Hz]");
    for &p in &a.p {
        let link = bench()?;
        let m = Master::open(link.clone())?;
        let par = TueParams {
            pgain: [p; 3],
            igain: [a.i; 3],
            ilimit: [a.limit; 3],
            r: [0.0; 3],
            kv: [0.0; 3],
            ..bench_params()
        };
        tue::write_params(&m, 0, &par)?;
        let (mut m, _) = tue::set_mode(&link, m, 0, TueMode::Frf)?;
        let b = bar(a.quiet, &format!("FRF P={p}"));
        b.set_length(sp.len() as u64);
        let run = tue::run_frf(&mut m, 0, 1, &sp, &mut |got, _| b.set_position(got as u64))?;
        b.finish_and_clear();
        let pts = tue::frequency_response(&run, period, &bins);
        let mg = tue::margins(&pts);
        let share = tue::unexcited_share(&run, period, &bins);
        let _ = writeln!(
            out,
            "{} ({} setpoints sent, {} currents back)",
            describe(p, &mg, share, run.complete()),
            run.setpoints.len(),
            run.currents.len()
        );
        let _ = write!(csv, ",|T| P={p} [dB],arg T P={p} [deg],|L| P={p} [dB]");
        curves.push((format!("P = {p}"), pts));
    }
    csv.push('\n');
    for (j, &bin) in bins.iter().enumerate() {
        let _ = write!(csv, "{:.1}", bin as f64 * 20_000.0 / period as f64);
        for (_, pts) in &curves {
            match pts.get(j) {
                Some(q) => {
                    let _ = write!(csv, ",{:.3},{:.2},{:.3}", q.t_db(), q.t_deg(), q.l_db());
                }
                None => csv.push_str(",,,"),
            }
        }
        csv.push('\n');
    }
    let mut files = crate::output::write_recording(&a.out, "frf", &csv, a.format)?;
    let refs: Vec<(&str, &[FrfPoint])> = curves.iter().map(|(n, p)| (n.as_str(), &p[..])).collect();
    files.extend(tue::plot_bode(
        &refs,
        &a.out,
        "bode",
        "TUeES030 closed current loop T = I_meas / I_set (model, RE 30 on M2)",
    )?);
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    let _ = writeln!(out, "Wrote {}", names.join(", "));
    Ok(out)
}
