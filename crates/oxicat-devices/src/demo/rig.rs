//! The demo board on the virtual segment (feature `bench`): an ET1100 with LEDs (changes
//! logged) and buttons (a fixed pattern per node), and its FoE files — two firmware slots in
//! RAM, the factory image bootable, `firmware.bin` writable in BOOT, `version.txt` readable.

use oxicat_esc::EscConfig;
use oxicat_sim::firmware::{attach_firmware, AttachError, FirmwareConfig};
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
};

/// The demo with the thesis' section 6.7 change in the registry.
pub const ADDITIONS_KIT: Kit = Kit {
    name: "demo-additions",
    description: "demo + record Additions 0x7030 (thesis section 6.7, one edit)",
    def: |_| &super::additions::DEF,
    esc: EscConfig::et1100,
    attach: attach_additions,
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
    let payload = format!("oxicat demo firmware {}", def.sw_version);
    let img = oxicat_device::fwimage::build(def, payload.as_bytes());
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

/// Boots demo node `k` on ESC `id`.
pub fn attach(segment: &mut Segment, id: SlaveId, k: usize) -> Result<(), AttachError> {
    attach_firmware::<_, { super::IMAGE }, MBX>(
        segment,
        id,
        &super::DEF,
        WithFoe {
            app: app(k),
            files: files(&super::DEF),
        },
        &FirmwareConfig::default(),
    )
    .map(drop)
}

/// Boots demo-additions node `k` on ESC `id`.
pub fn attach_additions(segment: &mut Segment, id: SlaveId, k: usize) -> Result<(), AttachError> {
    attach_firmware::<_, { super::additions::IMAGE }, MBX>(
        segment,
        id,
        &super::additions::DEF,
        WithFoe {
            app: app(k),
            files: files(&super::additions::DEF),
        },
        &FirmwareConfig::default(),
    )
    .map(drop)
}
