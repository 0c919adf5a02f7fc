//! The toy on the virtual segment: an ET1100, no plant.

use oxicat_sim::firmware::{attach_firmware, attach_firmware_via, FirmwareConfig};
use oxicat_sim::pdi_path::PdiRoute;

use crate::registry::Kit;

/// The toy in the registry.
pub const KIT: Kit = Kit {
    name: "toy",
    description: "test-only toy device (README \"Add a device\"): Echo = Value + 1",
    def: |_| &super::DEF,
    esc: oxicat_esc::EscConfig::et1100,
    attach: |segment, id, _k, route| match route {
        PdiRoute::Direct => attach_firmware::<_, { super::IMAGE }, 128>(
            segment,
            id,
            &super::DEF,
            super::Toy::default(),
            &FirmwareConfig::default(),
        )
        .map(drop),
        route => attach_firmware_via::<_, { super::IMAGE }, 128>(
            segment,
            id,
            &super::DEF,
            super::Toy::default(),
            &FirmwareConfig::default(),
            route,
        )
        .map(drop),
    },
    sync: oxicat_slave::SyncMode::FreeRun,
    cycle_ns: 1_000_000,
};
