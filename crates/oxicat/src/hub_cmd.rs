//! `oxicat hub-demo`: the axis communication hub scenario on the virtual segment — a motor
//! overheats and cools, a sensor is unplugged, a scratchpad fails its CRC, the master cable
//! is open for 2 s — with an in-process ethercrab master at a 10 ms cycle.

use oxicat_devices::axis_hub::rig::{run_scenario, HubSync, ScenarioConfig};

use crate::CliError;

/// Sync mode of the demo.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SyncArg {
    /// Free run (the report's mode).
    FreeRun,
    /// SM-synchronous.
    SmSync,
    /// DC SYNC0.
    Dc,
}

/// Arguments of `oxicat hub-demo`.
#[derive(Debug, clap::Args)]
pub struct HubDemoArgs {
    /// Synchronisation.
    #[arg(long, value_enum, default_value = "free-run")]
    pub sync: SyncArg,
    /// Only bring the hub to OP and read the temperatures.
    #[arg(long)]
    pub bring_up_only: bool,
}

/// Runs the scenario, printing one line per step; an error if a step was not reached.
pub fn run(a: HubDemoArgs) -> Result<(), CliError> {
    let sii = oxicat_esi::sii::generate(&oxicat_devices::axis_hub::device::DEF)
        .map_err(CliError::Device)?;
    let cfg = ScenarioConfig {
        sync: match a.sync {
            SyncArg::FreeRun => HubSync::FreeRun,
            SyncArg::SmSync => HubSync::SmSync,
            SyncArg::Dc => HubSync::Dc,
        },
        bring_up_only: a.bring_up_only,
        ..ScenarioConfig::default()
    };
    let r = run_scenario(sii, &cfg, &mut |l| println!("{l}"))
        .map_err(|e| CliError::Io(std::io::Error::other(e)))?;
    let errors: Vec<String> = r.errors_seen.iter().map(|e| e.to_string()).collect();
    println!(
        "{} cycles, {} sensors, errors seen at the master: {}",
        r.cycles,
        r.sensors_found,
        if errors.is_empty() {
            "none".to_string()
        } else {
            errors.join(", ")
        }
    );
    if r.ok() {
        println!("all steps reached");
        Ok(())
    } else {
        Err(CliError::Io(std::io::Error::other(
            "hub-demo: a step was not reached",
        )))
    }
}
