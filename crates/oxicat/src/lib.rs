//! `oxicat`: the command-line tool. Verbs are subcommands of [`Command`]; each has a
//! function that returns its output so tests can call it without a process.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Parser, Subcommand, ValueEnum};
use oxicat_slave::DeviceDef;

pub mod cia402_cmd;
pub mod foe_cmd;
pub mod hub_cmd;
pub mod igh_cmd;
pub mod interrupt;
pub mod master_cmd;
pub mod output;
pub mod parquet_out;
pub mod scan_cmd;
pub mod sim_cmd;
pub mod sweep_cmd;
pub mod trot_cmd;
pub mod tue_cmd;
pub mod usage;

pub use usage::UsageError;

/// The command line.
#[derive(Debug, Parser)]
#[command(
    name = "oxicat",
    version,
    about = "EtherCAT device stack and virtual test bench"
)]
pub struct Cli {
    /// The verb.
    #[command(subcommand)]
    pub command: Command,
}

/// The verbs (later: trot, slaves, sim, …).
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Device definitions: write a device's ESI XML, SII EEPROM image or object dictionary.
    Device(DeviceArgs),
    /// CiA402 drives: `enable` (0x06/0x07/0x0F), `disable`, `mode`, `move` (CSP).
    Cia402(cia402_cmd::Cia402Args),
    /// The axis communication hub scenario (overheat, sensor lost, cable open) on the
    /// virtual segment.
    HubDemo(hub_cmd::HubDemoArgs),
    /// Master verbs (IgH `ethercat` style) on an interface or a virtual segment.
    #[command(flatten)]
    Master(master_cmd::MasterCommand),
    /// FoE verbs: `foe-write` (firmware download through BOOT), `foe-read`.
    #[command(flatten)]
    Foe(foe_cmd::FoeCommand),
    /// Serve a virtual segment in real time on a network interface or UDP until Ctrl-C.
    Sim(sim_cmd::SimArgs),
    /// The Laelaps II trotting experiment (thesis Table 4-1) on the virtual segment: CSV,
    /// figures, summary.
    Trot(trot_cmd::TrotArgs),
    /// The trot scenario for every point of a grid of values (`--set KEY=V1,V2,…`), in
    /// parallel, with one table of tracking errors (`sweep.csv`).
    Sweep(sweep_cmd::SweepArgs),
    /// The TUeES030 motor I/O board (normal-mode position loop, FRF current-loop
    /// identification) on the virtual segment.
    TueEs030(tue_cmd::TueArgs),
    /// The version of oxicat.
    Version,
    /// Build a firmware image for `foe-write`: the payload with the device's image header.
    FwImage {
        /// Device name (see `oxicat device list`).
        device: String,
        /// The payload (the application binary).
        payload: PathBuf,
        /// The image file to write.
        #[arg(short, long)]
        output: PathBuf,
    },
}

/// Arguments of `oxicat device`.
#[derive(Debug, clap::Args)]
pub struct DeviceArgs {
    /// Device name (`oxicat device list` lists them).
    pub name: String,
    /// What to produce.
    #[arg(value_enum, default_value = "od")]
    pub what: DeviceOutput,
    /// Output file (default: standard output).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

/// What `oxicat device` produces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DeviceOutput {
    /// ESI XML (ETG.2000).
    Esi,
    /// SII EEPROM image, binary (ETG.2010).
    Sii,
    /// The object dictionary as a table.
    Od,
    /// Consistency check of definition, ESI and SII (one line per finding).
    Check,
}

/// The definition of device `name` (node 0's) from the registry
/// (`oxicat_devices::registry`), which every verb reads.
pub fn device_def(name: &str) -> Result<&'static DeviceDef, CliError> {
    oxicat_devices::registry::find(name)
        .map(|k| (k.def)(0))
        .ok_or_else(|| CliError::UnknownDevice(name.to_string()))
}

/// Errors of the CLI.
#[derive(Debug)]
pub enum CliError {
    /// No device of that name.
    UnknownDevice(String),
    /// Generation failed.
    Device(oxicat_esi::Error),
    /// Writing the output failed.
    Io(std::io::Error),
    /// `oxicat sim` failed.
    Sim(sim_cmd::SimError),
    /// A master verb failed.
    Master(oxicat_master::MasterError),
    /// A mistake in the arguments (see [`UsageError`]).
    Usage(UsageError),
    /// The SII image of an experiment's virtual device could not be generated.
    BenchSii {
        /// The device (`TUeES030`).
        bench: &'static str,
        /// Why.
        error: oxicat_esi::Error,
    },
    /// The firmware of an experiment's virtual device could not be attached to its ESC.
    BenchFirmware {
        /// The device.
        bench: &'static str,
        /// Why.
        error: oxicat_sim::firmware::AttachError,
    },
    /// `sii-write` failed after it had written words: the EEPROM is half written, and the
    /// message says how to restore the old image.
    SiiHalfWritten {
        /// Why the write stopped.
        error: oxicat_master::MasterError,
        /// The slave.
        position: usize,
        /// Where its old image is (see [`master_cmd::restore_hint`]).
        backup: PathBuf,
        /// Words written.
        written: usize,
        /// Words of the image.
        words: usize,
    },
    /// Points of `oxicat sweep` failed (the table has the others).
    SweepFailed {
        /// How many failed.
        failed: usize,
        /// Points in all.
        points: usize,
        /// The table written (`sweep.csv`).
        table: PathBuf,
        /// The first failure.
        first: String,
    },
    /// `scan --save` cannot write its directory.
    SaveDir {
        /// The directory.
        dir: PathBuf,
        /// Why.
        why: String,
    },
    /// `device <name> check` found disagreements (listed on standard output).
    CheckFailed {
        /// The device.
        device: String,
        /// How many.
        findings: usize,
    },
    /// A recording could not be converted to Parquet.
    Parquet {
        /// The Parquet file.
        path: PathBuf,
        /// Why.
        error: String,
    },
}

impl From<oxicat_master::MasterError> for CliError {
    fn from(e: oxicat_master::MasterError) -> Self {
        CliError::Master(e)
    }
}

impl From<UsageError> for CliError {
    fn from(e: UsageError) -> Self {
        CliError::Usage(e)
    }
}

impl std::fmt::Display for CliError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CliError::UnknownDevice(n) => {
                write!(
                    f,
                    "unknown device {n:?}; known: {}",
                    oxicat_devices::registry::names()
                )
            }
            CliError::Device(e) => write!(f, "{e}"),
            CliError::Io(e) => write!(f, "writing the output failed: {e}"),
            CliError::Sim(e) => write!(f, "{e}"),
            CliError::Master(e) => write!(f, "{e}"),
            CliError::Usage(e) => write!(f, "{e}"),
            CliError::BenchSii { bench, error } => write!(f, "SII of the {bench}: {error}"),
            CliError::BenchFirmware { bench, error } => write!(f, "{bench} firmware: {error}"),
            CliError::SiiHalfWritten {
                error,
                position,
                backup,
                written,
                words,
            } => write!(
                f,
                "{error}\n{} ({written} of {words} words were written)",
                master_cmd::restore_hint(*position, backup)
            ),
            CliError::SweepFailed {
                failed,
                points,
                table,
                first,
            } => write!(
                f,
                "{failed} of {points} points failed (see {}): {first}",
                table.display()
            ),
            CliError::CheckFailed { device, findings } => write!(
                f,
                "{device}: {findings} finding(s): its definition, ESI and SII disagree (listed above)"
            ),
            CliError::Parquet { path, error } => write!(f, "{}: {error}", path.display()),
            CliError::SaveDir { dir, why } => {
                write!(f, "cannot save the scan in {}: {why}", dir.display())
            }
        }
    }
}

impl std::error::Error for CliError {}

impl CliError {
    /// Whether the error is standard output closed by its reader (`oxicat sdos | head -1`):
    /// the command then ends quietly with success, as other Unix tools do.
    pub fn is_broken_pipe(&self) -> bool {
        let io = match self {
            CliError::Io(e) | CliError::Master(oxicat_master::MasterError::Output(e)) => e,
            _ => return false,
        };
        io.kind() == std::io::ErrorKind::BrokenPipe
    }
}

/// Prints a verb's text on standard output (an error, not a panic, when it is closed).
fn print_text(text: &str) -> Result<(), CliError> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(CliError::Io)
}

/// The bytes `oxicat device <name> <what>` writes.
pub fn device_output(name: &str, what: DeviceOutput) -> Result<Vec<u8>, CliError> {
    let def = device_def(name)?;
    let r = match what {
        DeviceOutput::Esi => oxicat_esi::esi::generate(def).map(String::into_bytes),
        DeviceOutput::Sii => oxicat_esi::sii::generate(def),
        DeviceOutput::Od => oxicat_esi::od::table(def).map(String::into_bytes),
        DeviceOutput::Check => oxicat_esi::check(def).map(|f| check_text(&f).into_bytes()),
    };
    r.map_err(CliError::Device)
}

/// Runs a parsed command line: one function per verb (`master_cmd::run` and `foe_cmd::run`
/// dispatch their verbs the same way).
pub fn run(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::Device(a) if a.name == "list" => device_list(),
        Command::Device(a) => device(a),
        Command::Version => version(),
        Command::FwImage {
            device,
            payload,
            output,
        } => fw_image(&device, &payload, &output),
        Command::Cia402(a) => print_text(&cia402_cmd::run(a)?),
        Command::Sim(a) => sim_cmd::run(a).map_err(CliError::Sim),
        Command::HubDemo(a) => hub_cmd::run(a),
        Command::Master(c) => master_cmd::run(c, &mut std::io::stdout().lock()),
        Command::Foe(c) => foe_cmd::run(c, &mut std::io::stdout().lock()),
        Command::Trot(a) => print_text(&trot_cmd::run(a)?),
        Command::Sweep(a) => print_text(&sweep_cmd::run(a)?),
        Command::TueEs030(a) => print_text(&tue_cmd::run(a)?),
    }
}

/// `oxicat device list`.
fn device_list() -> Result<(), CliError> {
    print_text(&igh_cmd::device_list())
}

/// The text of `device <name> check`: one line per finding (which descriptions, what),
/// then the count.
pub fn check_text(f: &[(oxicat_esi::Pair, oxicat_esi::Finding)]) -> String {
    let mut s = String::new();
    for (pair, finding) in f {
        s.push_str(&format!("{pair:?}: {finding}\n"));
    }
    s.push_str(&format!("{} findings\n", f.len()));
    s
}

/// `oxicat device <name> <what> [-o file]`; `check` fails when it finds anything.
fn device(a: DeviceArgs) -> Result<(), CliError> {
    let bytes = device_output(&a.name, a.what)?;
    output::write_output(a.output.as_deref(), &bytes, &mut std::io::stdout().lock())?;
    if a.what == DeviceOutput::Check {
        let n = oxicat_esi::check(device_def(&a.name)?)
            .map_err(CliError::Device)?
            .len();
        if n > 0 {
            return Err(CliError::CheckFailed {
                device: a.name,
                findings: n,
            });
        }
    }
    Ok(())
}

/// `oxicat version`.
fn version() -> Result<(), CliError> {
    print_text(&igh_cmd::version())
}

/// `oxicat fw-image <device> <payload> -o <image>`.
fn fw_image(device: &str, payload: &Path, output: &Path) -> Result<(), CliError> {
    print_text(&igh_cmd::fw_image(device, payload, output)?)
}
