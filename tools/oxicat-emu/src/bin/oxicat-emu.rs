//! `oxicat-emu`: board images on a served virtual segment.
//!
//! `oxicat-emu sim --firmware NAME=ELF[,ELF…] [oxicat sim's options] DEVICES…` is
//! `oxicat sim` with the nodes of device NAME running the board image ELF on an emulated
//! STM32F446 with its board's ESC chip — an ET1100 for `cia402-joint`, a LAN9252 for the
//! others — (instruction by instruction) instead of the host-compiled firmware;
//! node k of NAME runs the k-th image of the list, cycling (the Laelaps leg node is built
//! per side: `--firmware laelaps-leg=left.elf,right.elf,right.elf,left.elf` for the chain
//! HL HR FR FL). Devices without `--firmware` keep their host-compiled firmware, so one
//! segment can mix both. A leg node's image gets its leg on the board's pins, a CiA402
//! joint's its joint (`oxicat_emu::cia402`), a TUeES030's its three motors
//! (`oxicat_emu::tue_es030`).
//!
//! The MIT/Apache `oxicat` CLI cannot link this GPL tool, hence a binary of its own over
//! the CLI's serving functions (`oxicat::sim_cmd::serve_until_with`).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use clap::parser::ValueSource;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use oxicat::sim_cmd::{host_node, serve_until_with, SimArgs};
use oxicat_devices::laelaps::rig::{chain_legs, RigConfig};
use oxicat_devices::registry::{add_node_on, Device, Kit, NodeError};
use oxicat_emu::cia402::JointBoardPlant;
use oxicat_emu::laelaps::LegBoardPlant;
use oxicat_emu::node::EmulatedNode;
use oxicat_emu::plant::BoardPlant;
use oxicat_emu::tue_es030::{TueBoardPlant, TueConfig};
use oxicat_emu::ChipKind;
use oxicat_esc::EscConfig;
use oxicat_sim::firmware::AttachError;
use oxicat_sim::pdi_path::PdiRoute;
use oxicat_sim::segment::{Segment, SlaveId};

#[derive(Parser)]
#[command(
    name = "oxicat-emu",
    version,
    about = "Board images on oxicat's virtual segment"
)]
struct Cli {
    #[command(subcommand)]
    verb: Verb,
}

#[derive(Subcommand)]
enum Verb {
    /// Serve a segment (as `oxicat sim`) whose nodes of the named devices run board images.
    Sim(EmuSimArgs),
    /// The Laelaps II trot (as `oxicat trot`) with the four leg nodes' board images in the
    /// loop (the machine-code route); adds a "Board images" section to summary.md.
    Trot(EmuTrotArgs),
}

/// Where `.ci/run` and the firmware README build the two leg-node images.
const RIGHT_ELF: &str = "firmware/target/thumbv7em-none-eabihf/release/oxicat-firmware-laelaps-leg";
const LEFT_ELF: &str =
    "firmware/target/left/thumbv7em-none-eabihf/release/oxicat-firmware-laelaps-leg";

#[derive(clap::Args)]
struct EmuTrotArgs {
    /// The left legs' image (`cargo build --release --features left-leg --target-dir
    /// ../target/left` in firmware/laelaps-leg).
    #[arg(long, value_name = "ELF", default_value = LEFT_ELF)]
    left: PathBuf,
    /// The right legs' image (`cargo build --release` in firmware/laelaps-leg).
    #[arg(long, value_name = "ELF", default_value = RIGHT_ELF)]
    right: PathBuf,
    /// The trot's options (`--out` defaults to `out/trot-images`; `--pdi`, `--spi-mhz` and
    /// `--bus-time` are the host-compiled route's and refused).
    #[command(flatten)]
    trot: oxicat::trot_cmd::TrotArgs,
}

#[derive(clap::Args)]
struct EmuSimArgs {
    /// NAME=ELF[,ELF…]: the nodes of device NAME run these images (node k the k-th,
    /// cycling). Repeat for several devices.
    #[arg(long = "firmware", value_name = "NAME=ELF[,ELF…]", required = true)]
    firmware: Vec<String>,
    #[command(flatten)]
    sim: SimArgs,
}

/// How often an emulated board's CPU is woken besides the segment's events [ns].
const SLICE_NS: u64 = 100_000;

/// Images per device name, read and checked before anything boots.
fn images(specs: &[String]) -> Result<BTreeMap<String, Vec<Vec<u8>>>, String> {
    let mut out: BTreeMap<String, Vec<Vec<u8>>> = BTreeMap::new();
    for spec in specs {
        let (name, files) = spec
            .split_once('=')
            .ok_or_else(|| format!("--firmware {spec}: expected NAME=ELF[,ELF…]"))?;
        if oxicat_devices::registry::find(name).is_none() {
            return Err(format!(
                "--firmware {spec}: no device `{name}` (devices: {})",
                oxicat_devices::registry::names()
            ));
        }
        let list = out.entry(name.to_string()).or_default();
        for f in files.split(',').filter(|f| !f.is_empty()) {
            let path = PathBuf::from(f);
            let bytes =
                std::fs::read(&path).map_err(|e| format!("--firmware {}: {e}", path.display()))?;
            oxicat_emu::elf_segments(&bytes)
                .map_err(|e| format!("--firmware {}: {e}", path.display()))?;
            list.push(bytes);
        }
        if list.is_empty() {
            return Err(format!("--firmware {spec}: no image named"));
        }
    }
    Ok(out)
}

/// The plant a device's board image drives, where the emulator has an adapter for it.
fn plant_for(kit: &Kit, k: usize) -> Option<Box<dyn BoardPlant>> {
    match kit.name {
        "laelaps-leg" => {
            let leg = chain_legs()[k % 4];
            Some(Box::new(LegBoardPlant::new(leg, RigConfig::laelaps(leg))))
        }
        "cia402-joint" => Some(Box::new(JointBoardPlant::new(Default::default()))),
        "tue-es030" => Some(Box::new(TueBoardPlant::new(&TueConfig::default()))),
        _ => None,
    }
}

/// The ESC chip a device's board carries: the CiA402 joint's board an ET1100
/// (`firmware/cia402-joint`), the others a LAN9252.
fn chip_for(kit: &Kit) -> (ChipKind, EscConfig) {
    match kit.name {
        "cia402-joint" => (ChipKind::Et1100, EscConfig::et1100()),
        _ => (ChipKind::Lan9252, EscConfig::lan9252()),
    }
}

fn run(args: EmuSimArgs) -> Result<(), String> {
    let images = images(&args.firmware)?;
    let add = move |seg: &mut Segment,
                    dev: Device,
                    k: usize,
                    drift_ppm: f64,
                    route: PdiRoute|
          -> Result<SlaveId, NodeError> {
        let (kit, list) = match dev {
            Device::Kit(kit) => match images.get(kit.name) {
                Some(list) => (kit, list),
                None => return host_node(seg, dev, k, drift_ppm, route),
            },
            Device::Twin(_) => return host_node(seg, dev, k, drift_ppm, route),
        };
        let image = list[k % list.len()].clone();
        // The board's own chip, whatever route the device's host bench uses.
        let (chip, esc) = chip_for(kit);
        add_node_on(seg, kit, k, esc, drift_ppm, |seg, id| {
            let node = EmulatedNode::with_chip(image, SLICE_NS, plant_for(kit, k), chip)
                .map_err(|e| AttachError::Image(e.to_string()))?;
            seg.attach(id, Box::new(node))
                .map_err(AttachError::Topology)
        })
    };
    let stop = Arc::new(AtomicBool::new(false));
    let _ctrl_c = oxicat::interrupt::stop_on_ctrl_c(stop.clone());
    let _ = env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn"))
        .try_init();
    serve_until_with(&args.sim, stop, &add).map_err(|e| e.to_string())
}

fn trot(mut args: EmuTrotArgs, default_out: bool) -> Result<(), String> {
    if args.trot.pdi.is_some() || args.trot.spi_mhz.is_some() || args.trot.bus_time {
        return Err(
            "--pdi, --spi-mhz and --bus-time choose the host-compiled firmware's route \
             and timing model; the board images reach their LAN9252 over SPI1 in machine code, \
             at the clock the image sets"
                .into(),
        );
    }
    if default_out {
        // Next to the host-compiled run's out/trot, not over it.
        args.trot.out = PathBuf::from("out/trot-images");
    }
    let read = |p: &PathBuf| std::fs::read(p).map_err(|e| format!("{}: {e}", p.display()));
    let images = oxicat_emu::trot::LegImages::new(read(&args.left)?, read(&args.right)?)
        .map_err(|e| format!("{} / {}: {e}", args.left.display(), args.right.display()))?;
    let out = oxicat::trot_cmd::run_with(args.trot, &mut |s, progress| {
        let (run, figures) = oxicat_emu::trot::run(s, &images, progress)?;
        let md = oxicat_emu::trot::markdown(&run, &figures);
        Ok((run, md))
    })
    .map_err(|e| e.to_string())?;
    print!("{out}");
    Ok(())
}

fn main() -> ExitCode {
    let matches = Cli::command().get_matches();
    let verb = match Cli::from_arg_matches(&matches) {
        Ok(Cli { verb }) => verb,
        Err(e) => e.exit(),
    };
    let default_out = matches
        .subcommand_matches("trot")
        .and_then(|m| m.value_source("out"))
        .is_none_or(|s| s == ValueSource::DefaultValue);
    let r = match verb {
        Verb::Sim(a) => run(a),
        Verb::Trot(a) => trot(a, default_out),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("oxicat-emu: {e}");
            ExitCode::FAILURE
        }
    }
}
