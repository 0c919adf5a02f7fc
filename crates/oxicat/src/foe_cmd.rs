//! The FoE verbs of `oxicat`: `foe-write` (firmware download: the slave is walked
//! INIT → BOOT, the file written, and back to INIT, as TwinCAT does) and `foe-read`. The
//! demo devices' FoE files live in their kit (`oxicat_devices::demo::rig::files`).

use std::io::Write;
use std::path::PathBuf;

use clap::{Args, Subcommand};
use oxicat_master::value::parse_int;
use oxicat_master::MasterError;

use crate::master_cmd::{LinkArgs, PosArgs};
use crate::{CliError, UsageError};

/// The FoE verbs, each with its arguments; [`run`] hands them to the verb's function.
#[derive(Debug, Subcommand)]
pub enum FoeCommand {
    /// FoE write of a file (firmware download): INIT -> BOOT, write, back to INIT.
    #[command(alias = "foe_write")]
    FoeWrite(FoeWriteArgs),
    /// FoE read of a file.
    #[command(alias = "foe_read")]
    FoeRead(FoeReadArgs),
}

/// The arguments of `foe-write`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct FoeWriteArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// The file to send.
    pub file: PathBuf,
    /// File name on the slave (default: the file's name).
    #[arg(long)]
    pub name: Option<String>,
    /// FoE password (number, 0x… allowed; default none).
    #[arg(long)]
    pub password: Option<String>,
    /// Write in the slave's current state (no BOOT walk).
    #[arg(long)]
    pub no_boot: bool,
}

/// The arguments of `foe-read`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct FoeReadArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// File name on the slave.
    pub name: String,
    /// Output file (default: standard output).
    #[arg(long, short = 'o')]
    pub output: Option<PathBuf>,
    /// FoE password.
    #[arg(long)]
    pub password: Option<String>,
}

fn password(p: &Option<String>) -> Result<u32, UsageError> {
    match p {
        None => Ok(0),
        Some(s) => parse_int(s)
            .and_then(|v| u32::try_from(v).ok())
            .ok_or_else(|| UsageError::NotAPassword(s.clone())),
    }
}

fn bar(total: u64, what: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(total);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {bytes}/{total_bytes}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

fn io(e: std::io::Error) -> MasterError {
    MasterError::Output(e)
}

/// FoE 0x8009 ("not bootstrap": in BOOT, the slave takes no file of that name, as in
/// Beckhoff's SSC) and 0x8001 ("not found") on a write say that the name is wrong; the
/// message says so, and where the name came from.
fn explain_write_error(e: MasterError, name: &str, from_file: bool) -> MasterError {
    match e {
        MasterError::Foe {
            position,
            code: code @ (0x8009 | 0x8001),
            text,
        } => MasterError::Foe {
            position,
            code,
            text: format!(
                "{text}: the slave takes no file named {name:?}{} — give the name it expects \
                 with --name (the demo devices take {:?})",
                if from_file {
                    " (the name defaulted to the file's name)"
                } else {
                    ""
                },
                oxicat_devices::demo::rig::FIRMWARE_FILE
            ),
        },
        e => e,
    }
}

/// Runs an FoE verb, writing its report to `out`.
pub fn run(cmd: FoeCommand, out: &mut dyn Write) -> Result<(), CliError> {
    match cmd {
        FoeCommand::FoeWrite(a) => foe_write(a, out),
        FoeCommand::FoeRead(a) => foe_read(a, out),
    }
}

/// `foe-write`: INIT → BOOT (unless `no_boot`), the file, back to INIT; then what the slave
/// reports in `version.txt`.
fn foe_write(a: FoeWriteArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let FoeWriteArgs {
        link,
        pos,
        file,
        name,
        password: pw,
        no_boot,
    } = a;
    let data = std::fs::read(&file).map_err(|e| MasterError::File(file.clone(), e))?;
    let name_from_file = name.is_none();
    let name = match name {
        Some(n) => n,
        None => file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or(UsageError::NoFoeName)?,
    };
    let pw = password(&pw)?;
    let mut m = crate::master_cmd::open(&link)?;
    let p = pos.position.unwrap_or(0);
    m.address(p)?;
    if !no_boot {
        m.enter_boot(p)?;
    }
    let pb = bar(data.len() as u64, &format!("FoE write {name}"));
    let r = m.foe_write(p, &name, pw, &data, &mut |done, _| {
        pb.set_position(done as u64)
    });
    pb.finish_and_clear();
    // What the slave now reports (BOOT serves version.txt too), before leaving.
    let version = match &r {
        Ok(()) => m.foe_read(p, "version.txt", 0, &mut |_, _| {}).ok(),
        Err(_) => None,
    };
    if !no_boot {
        let back = m.leave_boot(p);
        back?;
    }
    r.map_err(|e| explain_write_error(e, &name, name_from_file))?;
    writeln!(
        out,
        "slave {p}: wrote {} bytes as {name:?}{}",
        data.len(),
        if no_boot {
            ""
        } else {
            " in BOOT; back in INIT"
        }
    )
    .map_err(io)?;
    if let Some(v) = version {
        write!(out, "slave {p} reports:\n{}", String::from_utf8_lossy(&v)).map_err(io)?;
    }
    Ok(())
}

/// `foe-read`: the file to `output` (a file, or standard output for none or `-`).
fn foe_read(a: FoeReadArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let FoeReadArgs {
        link,
        pos,
        name,
        output,
        password: pw,
    } = a;
    let pw = password(&pw)?;
    let m = crate::master_cmd::open(&link)?;
    let p = pos.position.unwrap_or(0);
    m.address(p)?;
    let data = m.foe_read(p, &name, pw, &mut |_, _| {})?;
    match output.filter(|f| !crate::output::is_stdout(f)) {
        Some(f) => {
            crate::output::write_file(&f, &data)?;
            writeln!(
                out,
                "slave {p}: read {} bytes of {name:?} into {}",
                data.len(),
                f.display()
            )
            .map_err(io)?;
            Ok(())
        }
        None => Ok(out.write_all(&data).map_err(io)?),
    }
}
