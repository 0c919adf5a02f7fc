//! `oxicat tue-es030 <normal|frf>`: the TUeES030 motor I/O board on the virtual segment
//! (firmware + three RE 30 channels), driven as the manual's Simulink blocks do.
//!
//! - `normal`: parameters written and read back, then a 1 kHz position loop in the master
//!   moves M2 through a profile using current setpoints; `normal.csv` records every cycle.
//! - `frf`: switch to FRF mode, stream a multisine current excitation to M2 at 20 kHz (22
//!   setpoints per 1 ms cycle with the manual's flow control), check that no sample was
//!   lost, compute the closed-loop response, its bandwidth and phase margin, for the
//!   manual's P = 6, I = 4, limit 1 and for P = 10; `frf.csv`, `bode.png`/`bode.svg`;
//!   with `--excitation chirp|noise|manual` or `--setpoints FILE` the response is a Welch
//!   estimate with coherence; the plant estimate H = L/C against the manual's model
//!   (`plant.png`/`.svg`) with R and L fitted from it.
//! - `step`, `ff-r`, `ff-emf`: the manual's time-domain experiments (Figs. 6.5–6.8):
//!   current steps on a locked axis for several P and I, the resistance feed-forward, the
//!   back-EMF feed-forward under a velocity loop.
//! - `regen`: hard braking of M2 (400 rad/s at −5 A) on a line whose supply cannot sink:
//!   the regenerated energy charges the board's bulk capacitor; once with the firmware's
//!   over-voltage kill, once without; `regen-kill.csv`, `regen-nokill.csv`.
//!
//! `--board-rev` chooses how the firmware converts the PI gains (see
//! [`oxicat_devices::tue_es030::BoardRev`]).

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use indicatif::{ProgressBar, ProgressStyle};
use oxicat_devices::tue_es030::app::MSTATE_KILLED;
use oxicat_devices::tue_es030::control::{param2int_rev, MotorParams};
use oxicat_devices::tue_es030::experiment::{
    self as tue, FrfPoint, FrfRun, Margins, NormalOut, Panel, Series, TueMode, TueParams,
};
use oxicat_devices::tue_es030::ident;
use oxicat_devices::tue_es030::rig::LineParams;
use oxicat_devices::tue_es030::rig::{attach, TueConfig, TueHandle};
use oxicat_devices::tue_es030::BoardRev;
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
    /// Current steps on a locked axis for several P (I = 0) and several I (P = 2): the
    /// manual's Figs. 6.5 and 6.6.
    Step,
    /// Resistance feed-forward: P = 0.2, I = 0, steps for several R (Fig. 6.7).
    FfR,
    /// Back-EMF feed-forward: a velocity loop (P_v = 1) through the current loop
    /// (P = 1, I = 0, R = 0) for several KV (Fig. 6.8).
    FfEmf,
    /// Hard braking on a supply that cannot sink (manual §2.1): the line rises; with and
    /// without the firmware's over-voltage kill.
    Regen,
}

/// `--board-rev`: how the firmware converts the PI gains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BoardRevArg {
    /// P and I in V/A as the dictionary labels them, on the 10 mΩ board.
    Literal,
    /// The PI gains converted with the original 42 mΩ current scale (loop gain / 4.2):
    /// reproduces the manual's FRF.
    Sense42,
}

impl From<BoardRevArg> for BoardRev {
    fn from(a: BoardRevArg) -> Self {
        match a {
            BoardRevArg::Literal => BoardRev::Literal,
            BoardRevArg::Sense42 => BoardRev::Sense42,
        }
    }
}

/// `--line`: what feeds the board's 24 V line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LineArg {
    /// A stiff source that also takes braking energy back (a battery): the line stays at
    /// 24 V.
    Battery,
    /// A lab supply that cannot sink: braking energy charges the board's 470 µF bulk
    /// capacitor (`LineParams::tue_es030`).
    Lab,
}

impl LineArg {
    fn params(self) -> Option<LineParams> {
        match self {
            LineArg::Battery => None,
            LineArg::Lab => Some(LineParams::tue_es030()),
        }
    }
}

/// `--excitation` of `frf`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Excitation {
    /// 49-line multisine, response by DFT at its lines.
    Multisine,
    /// Logarithmic swept sine 10 Hz – 9.9 kHz, `--amp` mA, Welch estimate.
    Chirp,
    /// White Gaussian noise of σ = `--amp`/3 mA (clipped at 3σ), Welch estimate.
    Noise,
    /// The manual's five signals (Fig. 6.2): chirp low (200 mA) and high (600 mA), WGN of
    /// σ 50, 100, 200 mA.
    Manual,
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
    /// Current-loop P gains [V/A]: `frf` identifies each (default 6, 10), `step` steps
    /// each with I = 0 (default 1, 2, 4, 6, 10); `ff-r` (default 0.2) and `ff-emf`
    /// (default 1) take the first.
    #[arg(long, value_delimiter = ',')]
    pub p: Vec<f32>,
    /// Current-loop I gains: `frf` takes the first (default 4), `step` steps each with
    /// P = 2 (default 0, 1, 2, 4, 8).
    #[arg(long, value_delimiter = ',')]
    pub i: Vec<f32>,
    /// Integrator limit in A s.
    #[arg(long, default_value_t = 1.0)]
    pub limit: f32,
    /// `ff-r`: resistance feed-forward values [Ω] (default 0, 0.3, 0.611 = the RE 30's,
    /// 1, 1.5 = the manual's "expected").
    #[arg(long, value_delimiter = ',')]
    pub r: Vec<f32>,
    /// `ff-emf`: KV feed-forward values [V s/rad] (default 0, 0.01, 0.02, 0.0259 = the
    /// manufacturer's).
    #[arg(long, value_delimiter = ',')]
    pub kv: Vec<f32>,
    /// `ff-emf`: velocity-loop gain in mA per 0.1 rad/s (the PDO's units).
    #[arg(long, default_value_t = 1.0)]
    pub pv: f32,
    /// Amplitude [mA]: the step of `step`/`ff-r` (default 1000), the peak of the multisine
    /// and chirp (default 400), 3σ of the noise (default 450).
    #[arg(long)]
    pub amp: Option<f32>,
    /// FRF: multisine periods (of 100 ms, 10 Hz resolution); the first is discarded.
    #[arg(long, default_value_t = 6)]
    pub periods: usize,
    /// FRF: the excitation.
    #[arg(long, value_enum, default_value = "multisine")]
    pub excitation: Excitation,
    /// FRF: length of a chirp or noise excitation [s].
    #[arg(long, default_value_t = 2.0)]
    pub duration: f32,
    /// FRF: the user's own excitation, one current setpoint in mA per line (`#` comments);
    /// replaces `--excitation`.
    #[arg(long)]
    pub setpoints: Option<PathBuf>,
    /// How the firmware converts the PI gains (`sense42`: the manual's FRF).
    #[arg(long, value_enum, default_value = "sense42")]
    pub board_rev: BoardRevArg,
    /// What feeds the line (every experiment but `regen`, which always runs on `lab`).
    #[arg(long, value_enum, default_value = "battery")]
    pub line: LineArg,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
    /// Recording format: `csv`, `parquet` (same table, typed, units in its metadata) or
    /// `both`.
    #[arg(long, value_enum, default_value = "csv")]
    pub format: crate::output::Format,
}

fn bench(cfg: &TueConfig) -> Result<Link, CliError> {
    bench_handle(cfg).map(|(link, _)| link)
}

/// [`bench`] and the board's handle (the plant's side of the experiment).
fn bench_handle(cfg: &TueConfig) -> Result<(Link, TueHandle), CliError> {
    let mut seg = Segment::new();
    let def = &oxicat_devices::tue_es030::device::DEF;
    let sii = oxicat_esi::sii::generate(def).map_err(|error| CliError::BenchSii {
        bench: BENCH,
        error,
    })?;
    let id = seg.add(oxicat_esc::Esc::new(oxicat_esc::EscConfig::et1200(), sii));
    let h = attach(&mut seg, id, cfg).map_err(|error| CliError::BenchFirmware {
        bench: BENCH,
        error,
    })?;
    Ok((Link::Sim(Arc::new(Mutex::new(seg))), h))
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
    let count = |option: &'static str, n: usize| {
        if n <= 8 {
            Ok(())
        } else {
            Err(UsageError::OutOfRange {
                option,
                value: format!("({n} values)"),
                allowed: "at most 8 values (one run and one curve each)".into(),
            })
        }
    };
    for &p in &a.p {
        range("--p", p, 0.01, 1000.0, "current-loop P gain, V/A")?;
    }
    for &i in &a.i {
        range("--i", i, 0.0, 1000.0, "current-loop I gain")?;
    }
    for &r in &a.r {
        range("--r", r, 0.0, 10.0, "resistance feed-forward, ohm")?;
    }
    for &kv in &a.kv {
        range("--kv", kv, 0.0, 1.0, "back-EMF feed-forward, V s/rad")?;
    }
    count("--p", a.p.len())?;
    count("--i", a.i.len())?;
    count("--r", a.r.len())?;
    count("--kv", a.kv.len())?;
    range("--limit", a.limit, 0.0, 100.0, "integrator limit, A s")?;
    range(
        "--pv",
        a.pv,
        0.0,
        100.0,
        "velocity-loop gain, mA per 0.1 rad/s",
    )?;
    if let Some(amp) = a.amp {
        range(
            "--amp",
            amp,
            1.0,
            7500.0,
            "mA; the M2 sense reads -8.7 … +7.6 A",
        )?;
    }
    range(
        "--duration",
        a.duration,
        0.2,
        100.0,
        "s of chirp or noise at 20 kHz",
    )?;
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

/// Reads and checks a `--setpoints` file.
pub fn read_setpoints(path: &std::path::Path) -> Result<Vec<i16>, UsageError> {
    let text = std::fs::read_to_string(path).map_err(|error| UsageError::UnreadableFile {
        path: path.to_path_buf(),
        error,
    })?;
    ident::parse_setpoints(&text).map_err(|error| UsageError::Setpoints {
        path: path.to_path_buf(),
        error,
    })
}

/// Runs `oxicat tue-es030`; returns the text it printed.
pub fn run(a: TueArgs) -> Result<String, CliError> {
    check_args(&a)?;
    let file = match &a.setpoints {
        Some(p) => Some(read_setpoints(p)?),
        None => None,
    };
    std::fs::create_dir_all(&a.out).map_err(|e| MasterError::File(a.out.clone(), e))?;
    match a.experiment {
        TueExperiment::Normal => normal(&a),
        TueExperiment::Frf => frf(&a, file),
        TueExperiment::Step => step(&a),
        TueExperiment::FfR => ff_r(&a),
        TueExperiment::FfEmf => ff_emf(&a),
        TueExperiment::Regen => regen(&a),
    }
}

/// One braking run and what it measured.
struct RegenRun {
    rows: Vec<tue::NormalRow>,
    /// The plant's line peak \[V\] (every 1.5625 µs step).
    plant_peak: f64,
    /// 0x8040 after the run \[10 mV\].
    volts: [u16; 4],
    /// Current-loop runs with the line above the threshold.
    kills: u64,
}

fn regen_run(a: &TueArgs, kill: bool, plan: tue::Braking) -> Result<RegenRun, CliError> {
    let cfg = TueConfig::default()
        .rev(a.board_rev.into())
        .line(Some(LineParams::tue_es030()))
        .kill(kill);
    let (link, h) = bench_handle(&cfg)?;
    let mut m = Master::open(link)?;
    tue::write_params(&m, 0, &bench_params())?;
    let b = bar(
        a.quiet,
        if kill {
            "regen (kill)"
        } else {
            "regen (no kill)"
        },
    );
    b.set_length(plan.cycles);
    let mut control = plan.control();
    let rows = tue::run_normal(&mut m, 0, plan.cycles, |k, inp| {
        b.set_position(k);
        control(k, inp)
    })?;
    b.finish_and_clear();
    let volts = tue::internal_voltages(&m, 0)?;
    let g = h.lock();
    Ok(RegenRun {
        rows,
        plant_peak: g
            .app
            .board
            .line
            .map(|l| l.peak)
            .unwrap_or(g.app.board.supply),
        volts,
        kills: g.app.counters.kills,
    })
}

fn regen(a: &TueArgs) -> Result<String, CliError> {
    let plan = tue::Braking::default();
    let line = LineParams::tue_es030();
    let mut out = String::new();
    let re30 = TueConfig::default().motors[1];
    let _ = writeln!(
        out,
        "Line: {:.0} uF bulk capacitor, {:.2} A own draw, 24 V supply that cannot sink; M2 \
         spun to {} rad/s, braked at {} mA from cycle {}.",
        line.capacitance * 1e6,
        line.quiescent,
        plan.speed,
        plan.brake_ma,
        plan.brake_at
    );
    let mut files = Vec::new();
    for kill in [true, false] {
        let r = regen_run(a, kill, plan)?;
        let name = if kill { "regen-kill" } else { "regen-nokill" };
        files.extend(crate::output::write_recording(
            &a.out,
            name,
            &tue::regen_csv(&r.rows),
            a.format,
        )?);
        let w0 = r
            .rows
            .get(plan.brake_at as usize)
            .map(|x| x.input.velocity[1] as f64 * 0.1)
            .unwrap_or(0.0);
        let pdo_peak = r
            .rows
            .iter()
            .map(|x| x.input.linevoltage)
            .max()
            .unwrap_or(0) as f64
            * 0.01;
        let killed: Vec<u64> = r
            .rows
            .iter()
            .filter(|x| x.input.mstate[1] & MSTATE_KILLED != 0)
            .map(|x| x.cycle)
            .collect();
        let _ = writeln!(
            out,
            "{}: speed at the brake {w0:.1} rad/s (rotor energy {:.3} J); line peak {:.3} V \
             (plant), {:.2} V (0x8040:03, 20 kHz), {:.2} V (PDO, 1 kHz); kill threshold \
             {:.2} V; {} current loops killed, mstate kill bit in {} cycles{}",
            if kill {
                "with the kill"
            } else {
                "without the kill"
            },
            0.5 * re30.inertia * w0 * w0,
            r.plant_peak,
            r.volts[2] as f64 * 0.01,
            pdo_peak,
            r.volts[3] as f64 * 0.01,
            r.kills,
            killed.len(),
            match (killed.first(), killed.last()) {
                (Some(f), Some(l)) => format!(" ({f}..{l})"),
                _ => String::new(),
            }
        );
    }
    let _ = writeln!(out, "Wrote {}", file_list(&files));
    Ok(out)
}

fn normal(a: &TueArgs) -> Result<String, CliError> {
    let link = bench(
        &TueConfig::default()
            .rev(a.board_rev.into())
            .line(a.line.params()),
    )?;
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
         {} mA; line voltage {:.2} V (highest {:.2} V).\nWrote {}",
        rows.len(),
        err,
        imax,
        rows.last().map(|r| r.input.linevoltage).unwrap_or(0) as f64 * 0.01,
        rows.iter().map(|r| r.input.linevoltage).max().unwrap_or(0) as f64 * 0.01,
        csv
    );
    Ok(out)
}

/// The gains of one run on the bench parameters, feed-forwards as given.
fn gains(p: f32, i: f32, limit: f32, r: f32, kv: f32) -> TueParams {
    TueParams {
        pgain: [p; 3],
        igain: [i; 3],
        ilimit: [limit; 3],
        r: [r; 3],
        kv: [kv; 3],
        ..bench_params()
    }
}

/// A fresh bench `cfg` with parameters `par`, in FRF mode, streaming `sp` to M2.
fn stream(
    cfg: &TueConfig,
    par: &TueParams,
    sp: &[i16],
    quiet: bool,
    label: &str,
) -> Result<FrfRun, CliError> {
    let link = bench(cfg)?;
    let m = Master::open(link.clone())?;
    tue::write_params(&m, 0, par)?;
    let (mut m, _) = tue::set_mode(&link, m, 0, TueMode::Frf)?;
    let b = bar(quiet, label);
    b.set_length(sp.len() as u64);
    let run = tue::run_frf(&mut m, 0, 1, sp, &mut |got, _| b.set_position(got as u64))?;
    b.finish_and_clear();
    Ok(run)
}

fn rev_line(rev: BoardRev) -> String {
    match rev {
        BoardRev::Literal => "board revision literal (PI gains in V/A as labelled)".into(),
        BoardRev::Sense42 => format!(
            "board revision sense42 (PI gains converted with the 42 mOhm scale: loop gain x{:.3})",
            rev.pi_scale()
        ),
    }
}

fn file_list(files: &[PathBuf]) -> String {
    files
        .iter()
        .map(|f| f.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A response curve: name, points, coherence per point (Welch), share of energy outside
/// the excited lines (multisine).
struct Curve {
    name: String,
    pts: Vec<FrfPoint>,
    coh: Option<Vec<f64>>,
    unstable: bool,
}

fn frf(a: &TueArgs, file: Option<Vec<i16>>) -> Result<String, CliError> {
    let rev: BoardRev = a.board_rev.into();
    let cfg = TueConfig::default().rev(rev).line(a.line.params());
    let ps = if a.p.is_empty() {
        vec![6.0, 10.0]
    } else {
        a.p.clone()
    };
    let i = a.i.first().copied().unwrap_or(4.0);
    let n = (a.duration as f64 * 20_000.0).round() as usize;
    let period = 2000;
    let amp = |d: f32| a.amp.unwrap_or(d) as f64;
    let mut bins = None;
    let mut out = String::new();
    let signals: Vec<(String, Vec<i16>)> = match (file, a.excitation) {
        (Some(v), _) => {
            let _ = writeln!(
                out,
                "Excitation: {} setpoints from {} ({:.2} s), Welch estimate (Hann, 2048 samples, 50 % overlap).",
                v.len(),
                a.setpoints.as_deref().map(|p| p.display().to_string()).unwrap_or_default(),
                v.len() as f64 / 20_000.0
            );
            vec![("file".into(), v)]
        }
        (None, Excitation::Multisine) => {
            let (sp, b) = tue::multisine(period, a.periods, 10.0, 9900.0, 60, amp(400.0));
            let _ = writeln!(
                out,
                "Multisine: {} lines 10 Hz..9.9 kHz, {} mA peak, {} periods of {} samples at 20 kHz \
                 ({:.1} s).",
                b.len(),
                amp(400.0),
                a.periods,
                period,
                sp.len() as f64 / 20_000.0,
            );
            bins = Some(b);
            vec![("multisine".into(), sp)]
        }
        (None, Excitation::Chirp) => {
            let _ = writeln!(
                out,
                "Chirp: log sweep 10 Hz..9.9 kHz, {} mA, {} s; Welch estimate (Hann, 2048, 50 %).",
                amp(400.0),
                a.duration
            );
            vec![("chirp".into(), ident::chirp(n, 10.0, 9900.0, amp(400.0)))]
        }
        (None, Excitation::Noise) => {
            let _ = writeln!(
                out,
                "White Gaussian noise: sigma {} mA (clipped at 3 sigma), {} s; Welch estimate (Hann, 2048, 50 %).",
                amp(450.0) / 3.0,
                a.duration
            );
            vec![("noise".into(), ident::white_noise(n, amp(450.0) / 3.0, 1))]
        }
        (None, Excitation::Manual) => {
            let _ = writeln!(
                out,
                "The manual's five signals (Fig. 6.2), {} s each: chirp low 200 mA, chirp high 600 mA, \
                 WGN 1/2/3 of sigma 50/100/200 mA; Welch estimate (Hann, 2048, 50 %).",
                a.duration
            );
            vec![
                ("chirp low".into(), ident::chirp(n, 10.0, 9900.0, 200.0)),
                ("chirp high".into(), ident::chirp(n, 10.0, 9900.0, 600.0)),
                ("WGN 1".into(), ident::white_noise(n, 50.0, 1)),
                ("WGN 2".into(), ident::white_noise(n, 100.0, 2)),
                ("WGN 3".into(), ident::white_noise(n, 200.0, 3)),
            ]
        }
    };
    let _ = writeln!(
        out,
        "M2, I = {i}, limit = {}, feed-forward off, axis free; {}.",
        a.limit,
        rev_line(rev)
    );
    let model = ident::PlantModel::of(&cfg.motors[1]);
    let mut curves: Vec<Curve> = Vec::new();
    let mut plants: Vec<(String, tue::PlantPoints)> = Vec::new();
    for &p in &ps {
        let ip = param2int_rev(
            &MotorParams {
                pgain: p,
                igain: i,
                ..MotorParams::DEFAULT
            },
            rev,
        );
        for (sig, sp) in &signals {
            let name = if signals.len() == 1 && bins.is_some() {
                format!("P={p}")
            } else {
                format!("P={p} {sig}")
            };
            let run = stream(&cfg, &gains(p, i, a.limit, 0.0, 0.0), sp, a.quiet, &name)?;
            let (pts, coh, unstable, mg, extra) = match &bins {
                Some(b) => {
                    let pts = tue::frequency_response(&run, period, b);
                    let share = tue::unexcited_share(&run, period, b);
                    let mg = tue::margins(&pts);
                    (pts, None, share > 0.3, mg, share)
                }
                None => {
                    let w = tue::welch_response(&run, 2048, 1024)
                        .map_err(|e| MasterError::Usage(format!("{name}: Welch estimate: {e}")))?;
                    let good: Vec<FrfPoint> =
                        w.iter().filter(|x| x.1 >= 0.8).map(|x| x.0).collect();
                    let mg = tue::margins(&good);
                    let peak_sp = sp.iter().map(|v| v.unsigned_abs()).max().unwrap_or(0);
                    let peak = run
                        .currents
                        .iter()
                        .map(|v| v.unsigned_abs())
                        .max()
                        .unwrap_or(0);
                    let mean_coh = w.iter().map(|x| x.1).sum::<f64>() / w.len().max(1) as f64;
                    let (pts, coh): (Vec<FrfPoint>, Vec<f64>) = w.into_iter().unzip();
                    (pts, Some(coh), peak > 3 * peak_sp.max(1), mg, mean_coh)
                }
            };
            let _ = writeln!(
                out,
                "{} ({} setpoints sent, {} currents back){}",
                describe_curve(&name, &mg, unstable, run.complete()),
                run.setpoints.len(),
                run.currents.len(),
                match bins {
                    Some(_) => format!("; energy outside the lines {:.1} %", extra * 100.0),
                    None => format!("; mean coherence {extra:.3}"),
                }
            );
            if !unstable {
                let est = tue::plant_estimate(&pts, ip.pgain, ip.igain, 24.0);
                let fit_pts: Vec<(f64, (f64, f64))> = match &coh {
                    Some(c) => est
                        .iter()
                        .zip(c)
                        .filter(|x| *x.1 >= 0.9)
                        .map(|x| *x.0)
                        .collect(),
                    None => est.clone(),
                };
                if let Some((r, l)) = ident::fit_r_l(&fit_pts, &model, 200.0, 3000.0) {
                    let _ = writeln!(
                        out,
                        "  plant H = L/C fitted 200 Hz..3 kHz: R = {r:.3} Ohm, L = {:.4} mH (model {:.3} Ohm, {:.4} mH)",
                        l * 1e3,
                        model.r,
                        model.l * 1e3
                    );
                }
                plants.push((name.clone(), est));
            }
            curves.push(Curve {
                name,
                pts,
                coh,
                unstable,
            });
        }
    }
    let mut csv = String::from("f [Hz]");
    for c in &curves {
        let n = &c.name;
        let _ = write!(
            csv,
            ",|T| {n} [dB],arg T {n} [deg],|L| {n} [dB],coherence {n},|H| {n} [dB A/V],arg H {n} [deg]"
        );
    }
    csv.push('\n');
    let grid: Vec<f64> = curves
        .first()
        .map(|c| c.pts.iter().map(|p| p.f).collect())
        .unwrap_or_default();
    for (j, f) in grid.iter().enumerate() {
        let _ = write!(csv, "{f:.1}");
        for c in &curves {
            match c.pts.get(j) {
                Some(q) => {
                    let _ = write!(csv, ",{:.3},{:.2},{:.3}", q.t_db(), q.t_deg(), q.l_db());
                    match c.coh.as_ref().and_then(|v| v.get(j)) {
                        Some(g) => {
                            let _ = write!(csv, ",{g:.4}");
                        }
                        None => csv.push(','),
                    }
                    match plants
                        .iter()
                        .find(|p| p.0 == c.name)
                        .and_then(|p| p.1.get(j))
                    {
                        Some(&(_, h)) if !c.unstable => {
                            let _ = write!(
                                csv,
                                ",{:.3},{:.2}",
                                20.0 * h.0.hypot(h.1).log10(),
                                h.1.atan2(h.0).to_degrees()
                            );
                        }
                        _ => csv.push_str(",,"),
                    }
                }
                None => csv.push_str(",,,,,"),
            }
        }
        csv.push('\n');
    }
    let mut files = crate::output::write_recording(&a.out, "frf", &csv, a.format)?;
    let refs: Vec<(&str, &[FrfPoint])> = curves
        .iter()
        .map(|c| (c.name.as_str(), &c.pts[..]))
        .collect();
    files.extend(tue::plot_bode(
        &refs,
        &a.out,
        "bode",
        "TUeES030 closed current loop T = I_meas / I_set (model, RE 30 on M2)",
    )?);
    files.extend(plot_lrr(&curves, &a.out)?);
    // The figure leaves out the lines a Welch estimate is unsure of (coherence < 0.5).
    let shown: Vec<(String, tue::PlantPoints)> = plants
        .iter()
        .map(|(name, est)| {
            let coh = curves
                .iter()
                .find(|c| &c.name == name)
                .and_then(|c| c.coh.as_ref());
            let pts = est
                .iter()
                .enumerate()
                .filter(|(j, _)| coh.and_then(|c| c.get(*j)).is_none_or(|&g| g >= 0.5))
                .map(|(_, p)| *p)
                .collect();
            (name.clone(), pts)
        })
        .collect();
    files.extend(tue::plot_plant(
        &shown,
        &model,
        &a.out,
        "plant",
        "TUeES030 plant H = L/C against the model M·LP (RE 30 on M2)",
    )?);
    let _ = writeln!(out, "Wrote {}", file_list(&files));
    Ok(out)
}

fn describe_curve(name: &str, mg: &Margins, unstable: bool, complete: bool) -> String {
    let f = |x: Option<f64>, unit: &str| {
        x.map(|v| format!("{v:.0} {unit}"))
            .unwrap_or_else(|| "beyond the lines".into())
    };
    format!(
        "{name}: bandwidth (|T| = -3 dB) {}, peak |T| {:.1} dB, loop crossover {}, phase margin {}{}{}",
        f(mg.bandwidth, "Hz"),
        mg.peak_db,
        f(mg.crossover, "Hz"),
        mg.phase_margin
            .map(|v| format!("{v:.1} deg"))
            .unwrap_or_else(|| "-".into()),
        if unstable {
            " -> UNSTABLE (limit cycle; the margins above are not meaningful)"
        } else {
            ""
        },
        if complete { "" } else { " (samples LOST: redo)" }
    )
}

/// The loop return ratio L = T/(1 − T) (manual Fig. 6.3): `lrr.png`/`.svg`.
fn plot_lrr(curves: &[Curve], dir: &std::path::Path) -> Result<Vec<PathBuf>, CliError> {
    let mut mag = Vec::new();
    let mut ph = Vec::new();
    for c in curves.iter().filter(|c| !c.unstable) {
        mag.push(Series {
            name: c.name.clone(),
            points: c.pts.iter().map(|p| (p.f.log10(), p.l_db())).collect(),
            reference: false,
        });
        let mut prev = 0.0f64;
        ph.push(Series {
            name: c.name.clone(),
            points: c
                .pts
                .iter()
                .map(|p| {
                    let mut d = p.l.1.atan2(p.l.0).to_degrees();
                    while d - prev > 180.0 {
                        d -= 360.0;
                    }
                    while d - prev < -180.0 {
                        d += 360.0;
                    }
                    prev = d;
                    (p.f.log10(), d)
                })
                .collect(),
            reference: false,
        });
    }
    if mag.is_empty() {
        return Ok(Vec::new());
    }
    let (lo, hi) = mag
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.0))
        .fold((f64::MAX, f64::MIN), |a, x| (a.0.min(x), a.1.max(x)));
    mag.push(Series {
        name: "0 dB".into(),
        points: vec![(lo, 0.0), (hi, 0.0)],
        reference: true,
    });
    ph.push(Series {
        name: "-180 deg".into(),
        points: vec![(lo, -180.0), (hi, -180.0)],
        reference: true,
    });
    Ok(tue::plot_time(
        &[
            Panel {
                y_desc: "|L| [dB]".into(),
                series: mag,
            },
            Panel {
                y_desc: "phase L [deg]".into(),
                series: ph,
            },
        ],
        "log10(frequency [Hz])",
        dir,
        "lrr",
        "TUeES030 loop return ratio L = T/(1 - T) (model, RE 30 on M2)",
    )?)
}

/// Samples before the step, of the step, after it (20 kHz): 1 ms, 10 ms, 3 ms.
const STEP_PRE: usize = 20;
const STEP_ON: usize = 200;
const STEP_POST: usize = 60;

fn metrics_line(label: &str, m: &tue::StepMetrics) -> String {
    format!(
        "{label:>14}: final {:7.1} mA (error {:6.1} mA), peak {:7.1} mA, overshoot {:5.1} %, rise 10-90 % {}{}",
        m.final_ma,
        m.error_ma,
        m.peak_ma,
        m.overshoot_pct,
        m.rise_s
            .map(|r| format!("{:.0} us", r * 1e6))
            .unwrap_or_else(|| "-".into()),
        if m.unstable() { "  UNSTABLE (oscillates)" } else { "" }
    )
}

fn step_panel(runs: &[(String, FrfRun)], title_y: &str) -> Panel {
    let t = |k: usize| (k as f64 - STEP_PRE as f64) / 20_000.0;
    let mut series = Vec::new();
    if let Some((_, r)) = runs.first() {
        series.push(Series {
            name: "setpoint".into(),
            points: r
                .setpoints
                .iter()
                .enumerate()
                .map(|(k, &v)| (t(k), v as f64 * 1e-3))
                .collect(),
            reference: true,
        });
    }
    for (l, r) in runs {
        series.push(Series {
            name: l.clone(),
            points: r
                .currents
                .iter()
                .enumerate()
                .map(|(k, &v)| (t(k), v as f64 * 1e-3))
                .collect(),
            reference: false,
        });
    }
    Panel {
        y_desc: title_y.into(),
        series,
    }
}

/// Runs each (label, params) with a current pulse on a locked M2; returns the runs and
/// the lines describing them.
fn pulses(
    a: &TueArgs,
    cfg: &TueConfig,
    sets: &[(String, TueParams)],
    out: &mut String,
) -> Result<Vec<(String, FrfRun)>, CliError> {
    let amp = a.amp.unwrap_or(1000.0).round() as i16;
    let sp = tue::pulse(STEP_PRE, STEP_ON, STEP_POST, amp);
    let mut runs = Vec::new();
    for (label, par) in sets {
        let run = stream(cfg, par, &sp, a.quiet, label)?;
        if let Some(m) = tue::step_metrics(&run.setpoints, &run.currents) {
            let _ = writeln!(out, "{}", metrics_line(label, &m));
        }
        runs.push((label.clone(), run));
    }
    Ok(runs)
}

fn step(a: &TueArgs) -> Result<String, CliError> {
    let rev: BoardRev = a.board_rev.into();
    let cfg = TueConfig::default()
        .rev(rev)
        .locked(true)
        .line(a.line.params());
    let ps = if a.p.is_empty() {
        vec![1.0, 2.0, 4.0, 6.0, 10.0]
    } else {
        a.p.clone()
    };
    let is = if a.i.is_empty() {
        vec![0.0, 1.0, 2.0, 4.0, 8.0]
    } else {
        a.i.clone()
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Current steps of {} mA on M2, axis locked, feed-forward off, limit {}; {}.",
        a.amp.unwrap_or(1000.0),
        a.limit,
        rev_line(rev)
    );
    let _ = writeln!(out, "Fig. 6.5, P with I = 0:");
    let pset: Vec<(String, TueParams)> = ps
        .iter()
        .map(|&p| (format!("P={p} I=0"), gains(p, 0.0, a.limit, 0.0, 0.0)))
        .collect();
    let prun = pulses(a, &cfg, &pset, &mut out)?;
    let _ = writeln!(out, "Fig. 6.6, I with P = 2:");
    let iset: Vec<(String, TueParams)> = is
        .iter()
        .map(|&i| (format!("P=2 I={i}"), gains(2.0, i, a.limit, 0.0, 0.0)))
        .collect();
    let irun = pulses(a, &cfg, &iset, &mut out)?;
    let all: Vec<(String, &FrfRun)> = prun
        .iter()
        .chain(&irun)
        .map(|(l, r)| (l.clone(), r))
        .collect();
    let n = all.first().map(|r| r.1.setpoints.len()).unwrap_or(0);
    let csv = tue::step_csv(&all, STEP_PRE, 0, n);
    let mut files = crate::output::write_recording(&a.out, "step", &csv, a.format)?;
    files.extend(tue::plot_time(
        &[step_panel(&prun, "current [A]")],
        "time [s]",
        &a.out,
        "step-p",
        "Step response for different proportional gains (I = 0, axis locked; manual Fig. 6.5)",
    )?);
    files.extend(tue::plot_time(
        &[step_panel(&irun, "current [A]")],
        "time [s]",
        &a.out,
        "step-i",
        "Step response for different integral gains (P = 2, axis locked; manual Fig. 6.6)",
    )?);
    let _ = writeln!(out, "Wrote {}", file_list(&files));
    Ok(out)
}

fn ff_r(a: &TueArgs) -> Result<String, CliError> {
    let rev: BoardRev = a.board_rev.into();
    let cfg = TueConfig::default()
        .rev(rev)
        .locked(true)
        .line(a.line.params());
    let p = a.p.first().copied().unwrap_or(0.2);
    let i = a.i.first().copied().unwrap_or(0.0);
    let rs = if a.r.is_empty() {
        vec![0.0, 0.3, 0.611, 1.0, 1.5]
    } else {
        a.r.clone()
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Resistance feed-forward (Fig. 6.7): steps of {} mA on M2, axis locked, P = {p}, I = {i}, \
         KV = 0; the motor's R is {} Ohm; {}.",
        a.amp.unwrap_or(1000.0),
        cfg.motors[1].resistance,
        rev_line(rev)
    );
    let sets: Vec<(String, TueParams)> = rs
        .iter()
        .map(|&r| (format!("R={r}"), gains(p, i, a.limit, r, 0.0)))
        .collect();
    let runs = pulses(a, &cfg, &sets, &mut out)?;
    let all: Vec<(String, &FrfRun)> = runs.iter().map(|(l, r)| (l.clone(), r)).collect();
    let n = all.first().map(|r| r.1.setpoints.len()).unwrap_or(0);
    let csv = tue::step_csv(&all, STEP_PRE, 0, n);
    let mut files = crate::output::write_recording(&a.out, "ff-r", &csv, a.format)?;
    files.extend(tue::plot_time(
        &[step_panel(&runs, "current [A]")],
        "time [s]",
        &a.out,
        "ff-r",
        &format!("Step response for different resistance feed-forward (P = {p}; manual Fig. 6.7)"),
    )?);
    let _ = writeln!(out, "Wrote {}", file_list(&files));
    Ok(out)
}

fn ff_emf(a: &TueArgs) -> Result<String, CliError> {
    let rev: BoardRev = a.board_rev.into();
    let cfg = TueConfig::default().rev(rev).line(a.line.params());
    let p = a.p.first().copied().unwrap_or(1.0);
    let i = a.i.first().copied().unwrap_or(0.0);
    let kvs = if a.kv.is_empty() {
        vec![0.0, 0.01, 0.02, 0.0259]
    } else {
        a.kv.clone()
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Back-EMF feed-forward (Fig. 6.8): velocity loop P_v = {} mA per 0.1 rad/s on M2 (axis free) \
         following 0 -> 200 rad/s -> 0; current loop P = {p}, I = {i}, R = 0; {}.",
        a.pv,
        rev_line(rev)
    );
    let mut runs = Vec::new();
    for &kv in &kvs {
        let link = bench(&cfg)?;
        let m = Master::open(link.clone())?;
        let (mut m, _) = tue::set_mode(&link, m, 0, TueMode::Normal)?;
        tue::write_params(&m, 0, &gains(p, i, a.limit, 0.0, kv))?;
        let label = format!("Kv={kv}");
        let b = bar(a.quiet, &label);
        b.set_length(tue::EMF_CYCLES);
        let rows = tue::run_velocity_loop(&mut m, 0, 1, a.pv as f64)?;
        b.finish_and_clear();
        let peak = rows
            .iter()
            .map(|r| r.input.velocity[1] as f64 * 0.1)
            .fold(f64::MIN, f64::max);
        let _ = writeln!(
            out,
            "{label:>10}: RMS velocity error {:6.2} rad/s, top speed {peak:6.1} rad/s (reference 200)",
            tue::emf_rms_error(&rows, 1)
        );
        runs.push((label, rows));
    }
    let refs: Vec<(String, &[tue::NormalRow])> =
        runs.iter().map(|(l, r)| (l.clone(), &r[..])).collect();
    let csv = tue::emf_csv(&refs, 1);
    let mut files = crate::output::write_recording(&a.out, "ff-emf", &csv, a.format)?;
    let t = |r: &tue::NormalRow| r.cycle as f64 * 1e-3;
    let mut vel = vec![Series {
        name: "reference".into(),
        points: runs
            .first()
            .map(|(_, rows)| {
                rows.iter()
                    .map(|r| (t(r), tue::emf_trajectory(t(r))))
                    .collect()
            })
            .unwrap_or_default(),
        reference: true,
    }];
    let mut cur = Vec::new();
    for (l, rows) in &runs {
        vel.push(Series {
            name: l.clone(),
            points: rows
                .iter()
                .map(|r| (t(r), r.input.velocity[1] as f64 * 0.1))
                .collect(),
            reference: false,
        });
        cur.push(Series {
            name: l.clone(),
            points: rows
                .iter()
                .map(|r| (t(r), r.input.current[1] as f64 * 1e-3))
                .collect(),
            reference: false,
        });
    }
    files.extend(tue::plot_time(
        &[
            Panel {
                y_desc: "velocity [rad/s]".into(),
                series: vel,
            },
            Panel {
                y_desc: "current [A]".into(),
                series: cur,
            },
        ],
        "time [s]",
        &a.out,
        "ff-emf",
        "Velocity loop with different back-EMF feed-forward (manual Fig. 6.8)",
    )?);
    let _ = writeln!(out, "Wrote {}", file_list(&files));
    Ok(out)
}
