//! The demo board on the virtual segment (feature `bench`): an ET1100 with LEDs (changes
//! logged) and buttons (a fixed pattern per node), and its FoE files — two firmware slots in
//! RAM, the factory image bootable, `firmware.bin` writable in BOOT, `version.txt` readable.

use oxicat_esc::EscConfig;
use oxicat_sim::firmware::{attach_firmware, attach_firmware_via, AttachError, FirmwareConfig};
use oxicat_sim::pdi_path::PdiRoute;
use oxicat_sim::segment::{Segment, SlaveId};
use oxicat_slave::foe::{FirmwareUpdate, RamStore, UpdateConfig, WithFoe};
use oxicat_slave::DeviceDef;

use super::{Buttons, Demo, Leds};
use crate::registry::Kit;

/// The demo in the registry.
pub const KIT: Kit = Kit {
    name: "demo",
    description: "thesis Table 2-2 generic EtherCAT Application on an ET1100 (LEDs, \
                  buttons 0xA0+node, loop-back of outputs to inputs)",
    def: |_| &super::DEF,
    esc: EscConfig::et1100,
    attach,
    sync: oxicat_slave::SyncMode::FreeRun,
    cycle_ns: 1_000_000,
};

/// The demo with the thesis' section 6.7 change in the registry.
pub const ADDITIONS_KIT: Kit = Kit {
    name: "demo-additions",
    description: "demo + record Additions 0x7030 (thesis section 6.7, one edit)",
    def: |_| &super::additions::DEF,
    esc: EscConfig::et1100,
    attach: attach_additions,
    sync: oxicat_slave::SyncMode::FreeRun,
    cycle_ns: 1_000_000,
};

/// Mailbox size of the demo device.
const MBX: usize = 128;

/// Bytes per firmware slot of the simulated demo devices.
pub const SLOT_BYTES: usize = 16 * 1024;

/// Name of the firmware file the demo devices take in BOOT.
pub const FIRMWARE_FILE: &str = "firmware.bin";

/// The FoE files of a simulated demo device: two RAM slots, the factory image (payload
/// `oxicat demo firmware <sw_version>`) bootable in slot 0, `firmware.bin` writable in BOOT,
/// `version.txt` readable always.
pub fn files(def: &'static DeviceDef) -> FirmwareUpdate<RamStore<2, SLOT_BYTES>> {
    ram_files(def, "demo")
}

/// The FoE files of simulated device `name` (two RAM slots of `N` bytes): the factory image
/// (payload `oxicat <name> firmware <sw_version>`) bootable in slot 0, [`FIRMWARE_FILE`]
/// writable in BOOT, `version.txt` readable always.
pub fn ram_files<const N: usize>(
    def: &'static DeviceDef,
    name: &str,
) -> FirmwareUpdate<RamStore<2, N>> {
    let payload = format!("oxicat {name} firmware {}", def.sw_version);
    let img = oxicat_esi::fwimage::build(def, payload.as_bytes());
    let store = RamStore::with_image(&img).unwrap_or_default();
    FirmwareUpdate::new(
        store,
        UpdateConfig {
            identity: def.identity,
            file_name: FIRMWARE_FILE,
            password: 0,
            read_back: true,
        },
    )
}

/// The board's LEDs: changes are logged.
pub struct LogLeds(usize, Option<(bool, bool)>);

impl Leds for LogLeds {
    fn set(&mut self, blue: bool, red: bool) {
        if self.1 != Some((blue, red)) {
            log::debug!("node {}: blue LED {blue}, red LED {red}", self.0);
            self.1 = Some((blue, red));
        }
    }
}

/// The board's buttons: a fixed pattern per node (0xA0 + node).
pub struct FixedButtons(u8);

impl Buttons for FixedButtons {
    fn read(&mut self) -> u8 {
        self.0
    }
}

fn app(k: usize) -> Demo<LogLeds, FixedButtons> {
    Demo::new(LogLeds(k, None), FixedButtons(0xA0 | (k as u8 & 0x0F)))
}

/// Boots demo node `k` on ESC `id`, the firmware reaching it through `route`.
pub fn attach(
    segment: &mut Segment,
    id: SlaveId,
    k: usize,
    route: PdiRoute,
) -> Result<(), AttachError> {
    boot::<{ super::IMAGE }>(segment, id, &super::DEF, k, route)
}

/// Boots demo-additions node `k` on ESC `id`, the firmware reaching it through `route`.
pub fn attach_additions(
    segment: &mut Segment,
    id: SlaveId,
    k: usize,
    route: PdiRoute,
) -> Result<(), AttachError> {
    boot::<{ super::additions::IMAGE }>(segment, id, &super::additions::DEF, k, route)
}

fn boot<const N: usize>(
    segment: &mut Segment,
    id: SlaveId,
    def: &'static DeviceDef,
    k: usize,
    route: PdiRoute,
) -> Result<(), AttachError> {
    let app = WithFoe {
        app: app(k),
        files: files(def),
    };
    let cfg = FirmwareConfig::default();
    match route {
        PdiRoute::Direct => attach_firmware::<_, N, MBX>(segment, id, def, app, &cfg).map(drop),
        route => attach_firmware_via::<_, N, MBX>(segment, id, def, app, &cfg, route).map(drop),
    }
}
