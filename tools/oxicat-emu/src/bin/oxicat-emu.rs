//! `oxicat-emu`: board images on a served virtual segment.
//!
//! `oxicat-emu sim --firmware NAME=ELF[,ELF…] [oxicat sim's options] DEVICES…` is
//! `oxicat sim` with the nodes of device NAME running the board image ELF on an emulated
//! STM32F446 + LAN9252 (instruction by instruction) instead of the host-compiled firmware;
//! node k of NAME runs the k-th image of the list, cycling (the Laelaps leg node is built
//! per side: `--firmware laelaps-leg=left.elf,right.elf,right.elf,left.elf` for the chain
//! HL HR FR FL). Devices without `--firmware` keep their host-compiled firmware, so one
//! segment can mix both. A leg node's image gets its leg on the board's pins.
//!
//! The MIT/Apache `oxicat` CLI cannot link this GPL tool, hence a binary of its own over
//! the CLI's serving functions (`oxicat::sim_cmd::serve_until_with`).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use clap::{Parser, Subcommand};
use oxicat::sim_cmd::{host_node, serve_until_with, SimArgs};
use oxicat_devices::laelaps::rig::{chain_legs, RigConfig};
use oxicat_devices::registry::{add_node_on, Device, Kit, NodeError};
use oxicat_emu::laelaps::LegBoardPlant;
use oxicat_emu::node::EmulatedNode;
use oxicat_emu::plant::BoardPlant;
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
}

#[derive(clap::Args)]
struct EmuSimArgs {
    /// NAME=ELF[,ELF…]: the nodes of device NAME run these images (node k the k-th,
    /// cycling). Repeat for several devices.
    #[arg(long = "firmware", value_name = "NAME=ELF[,ELF…]", required = true)]
    firmware: Vec<String>,
    /// SPI clock of the boards' LAN9252 in MHz.
    #[arg(long, default_value_t = 22, value_parser = clap::value_parser!(u32).range(1..=30))]
    spi_mhz: u32,
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
    (kit.name == "laelaps-leg").then(|| {
        let leg = chain_legs()[k % 4];
        Box::new(LegBoardPlant::new(leg, RigConfig::laelaps(leg))) as Box<dyn BoardPlant>
    })
}

fn run(args: EmuSimArgs) -> Result<(), String> {
    let images = images(&args.firmware)?;
    let spi_mhz = args.spi_mhz;
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
        // The board carries a LAN9252, whatever the device's host bench uses.
        add_node_on(seg, kit, k, EscConfig::lan9252(), drift_ppm, |seg, id| {
            let node = EmulatedNode::with_plant(image, spi_mhz, SLICE_NS, plant_for(kit, k))
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

fn main() -> ExitCode {
    let Cli { verb } = Cli::parse();
    let r = match verb {
        Verb::Sim(a) => run(a),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("oxicat-emu: {e}");
            ExitCode::FAILURE
        }
    }
}
