//! The one registry of devices (feature `bench`): every verb of the CLI (`device`, `device
//! list`, `sim`, `sim --list`, `--sim`, `sii-write --device`, `fw-image`, `cstruct
//! --device`) and every test that walks "all devices" reads [`kits`].
//!
//! A twin of a vendor's ESI ([`crate::twin`]) is a device too: [`resolve`] takes
//! `esi=FILE[:TYPE[:REVISION]]` wherever it takes a kit's name, and [`Device`] is either.
//!
//! Adding a device: its kit folder (firmware, definition, `rig.rs` with a [`Kit`] constant)
//! and one line in [`KITS`]. README section "Add a device" has the recipe.

use oxicat_esc::{Esc, EscConfig};
use oxicat_sim::firmware::AttachError;
use oxicat_sim::pdi_path::PdiRoute;
use oxicat_sim::segment::{Segment, SlaveId};
use oxicat_slave::{DeviceDef, SyncMode};

/// Boots a device's firmware (and its plant) on ESC `id` of the segment; `k` is the node's
/// number among the devices of its kind (0, 1, …) for per-node differences (button
/// patterns, which leg a Laelaps node drives); `route` is how the firmware reaches its ESC
/// (the software ESC directly, or a LAN9252 / ET1100 chip driver over the simulated SPI).
pub type AttachFn =
    fn(segment: &mut Segment, id: SlaveId, k: usize, route: PdiRoute) -> Result<(), AttachError>;

/// One device as every verb sees it.
#[derive(Clone, Copy)]
pub struct Kit {
    /// Name on the command line (`demo:4`, `oxicat device demo esi`).
    pub name: &'static str,
    /// One line for `oxicat device list` and `oxicat sim --list`.
    pub description: &'static str,
    /// The device definition of node `k` (ESI, SII and OD are generated from it; `device`
    /// uses node 0's).
    pub def: fn(k: usize) -> &'static DeviceDef,
    /// The ESC chip the board carries.
    pub esc: fn() -> EscConfig,
    /// Boots the firmware with its plant.
    pub attach: AttachFn,
    /// How the device's bench runs it: the sync mode (free run, SM-synchronous, DC) …
    pub sync: SyncMode,
    /// … and the cycle time in ns.
    pub cycle_ns: u32,
}

impl core::fmt::Debug for Kit {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Kit")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

/// Every device, one line each.
pub static KITS: &[Kit] = &[
    crate::demo::rig::KIT,
    crate::demo::rig::ADDITIONS_KIT,
    crate::laelaps::rig::KIT,
    crate::tue_es030::rig::KIT,
    crate::axis_hub::rig::KIT,
    crate::cia402::rig::KIT,
    #[cfg(feature = "toy")]
    crate::toy::rig::KIT,
];

/// Every device, in registry order.
pub fn kits() -> &'static [Kit] {
    KITS
}

/// The device called `name`.
pub fn find(name: &str) -> Option<&'static Kit> {
    KITS.iter().find(|k| k.name == name)
}

/// The device whose definition has this vendor ID, product code and revision, as a master
/// finds them in a slave's SII (node 0's definition: the Laelaps builds share one identity;
/// the revision tells the demo, its variant and the leg node apart, which share a product
/// code as in the thesis).
pub fn by_identity(vendor_id: u32, product_code: u32, revision: u32) -> Option<&'static Kit> {
    KITS.iter().find(|k| {
        let id = (k.def)(0).identity;
        (id.vendor_id, id.product_code, id.revision) == (vendor_id, product_code, revision)
    })
}

/// The names of every device, comma-separated (for "unknown device" messages).
pub fn names() -> String {
    KITS.iter().map(|k| k.name).collect::<Vec<_>>().join(", ")
}

/// Why a node could not be put on the segment.
#[derive(Debug)]
pub enum NodeError {
    /// The SII image could not be generated from the definition.
    Sii(oxicat_esi::Error),
    /// The firmware did not boot.
    Attach(AttachError),
}

/// A device a verb names: a kit of this repository or a twin of a vendor's ESI.
#[derive(Debug, Clone, Copy)]
pub enum Device {
    /// A kit of [`KITS`].
    Kit(&'static Kit),
    /// A twin ([`crate::twin`]).
    Twin(&'static crate::twin::Twin),
}

impl Device {
    /// The name users type (`demo`, `esi=EL2008.xml:EL2008`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Kit(k) => k.name,
            Self::Twin(t) => &t.spec,
        }
    }

    /// The definition of node `k`.
    pub fn def(&self, k: usize) -> &'static DeviceDef {
        match self {
            Self::Kit(kit) => (kit.def)(k),
            Self::Twin(t) => t.esi.def,
        }
    }

    /// The sync mode its bench runs (twins: free run).
    pub fn sync(&self) -> SyncMode {
        match self {
            Self::Kit(k) => k.sync,
            Self::Twin(_) => SyncMode::FreeRun,
        }
    }

    /// The cycle time of its bench in ns (twins: 1 ms).
    pub fn cycle_ns(&self) -> u32 {
        match self {
            Self::Kit(k) => k.cycle_ns,
            Self::Twin(_) => 1_000_000,
        }
    }
}

/// Why a device name does not resolve.
#[derive(Debug)]
pub enum ResolveError {
    /// No kit of that name.
    Unknown(String),
    /// The twin could not be built.
    Twin(crate::twin::LoadError),
}

impl core::fmt::Display for ResolveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Unknown(n) => write!(
                f,
                "unknown device {n:?}; known: {}, esi=FILE[:TYPE[:REVISION]] for a twin of a vendor's ESI, or sii=FILE for a twin of a slave's SII image",
                names()
            ),
            Self::Twin(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for ResolveError {}

/// The device `name` names: a kit, `esi=FILE[:TYPE[:REVISION]]` for a twin of an ESI, or
/// `sii=FILE` for a twin of a slave's SII image.
pub fn resolve(name: &str) -> Result<Device, ResolveError> {
    if let Some(file) = name.strip_prefix(crate::twin::SII_PREFIX) {
        return crate::twin::load_sii(std::path::Path::new(file), None, None)
            .map(Device::Twin)
            .map_err(ResolveError::Twin);
    }
    if let Some(spec) = name.strip_prefix(crate::twin::PREFIX) {
        return crate::twin::load(spec)
            .map(Device::Twin)
            .map_err(ResolveError::Twin);
    }
    find(name)
        .map(Device::Kit)
        .ok_or_else(|| ResolveError::Unknown(name.to_string()))
}

/// [`add_node_via`] for any [`Device`]: node `k` at the end of the line.
pub fn add_device_node(
    segment: &mut Segment,
    dev: Device,
    k: usize,
    drift_ppm: f64,
    route: PdiRoute,
) -> Result<SlaveId, NodeError> {
    match dev {
        Device::Kit(kit) => add_node_via(segment, kit, k, drift_ppm, route),
        Device::Twin(t) => crate::twin::add_node(segment, t, drift_ppm, route),
    }
}

impl core::fmt::Display for NodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Sii(e) => write!(f, "SII image: {e}"),
            Self::Attach(e) => write!(f, "firmware: {e}"),
        }
    }
}

impl std::error::Error for NodeError {}

/// Adds node `k` of `kit` at the end of the segment's line, with its oscillator off by
/// `drift_ppm`, and boots its firmware on the software ESC directly; returns its index.
pub fn add_node(
    segment: &mut Segment,
    kit: &Kit,
    k: usize,
    drift_ppm: f64,
) -> Result<SlaveId, NodeError> {
    add_node_via(segment, kit, k, drift_ppm, PdiRoute::Direct)
}

/// [`add_node`] with the firmware reaching its ESC through `route`.
pub fn add_node_via(
    segment: &mut Segment,
    kit: &Kit,
    k: usize,
    drift_ppm: f64,
    route: PdiRoute,
) -> Result<SlaveId, NodeError> {
    let def = (kit.def)(k);
    let mut sii = oxicat_esi::sii::generate(def).map_err(NodeError::Sii)?;
    if matches!(route, PdiRoute::Et1100 { .. }) {
        spi_pdi(&mut sii).map_err(|e| NodeError::Sii(e.into()))?;
    }
    add_node_with_sii(segment, (kit.esc)(), sii, drift_ppm, |s, id| {
        (kit.attach)(s, id, k, route)
    })
}

/// The ET1100 route is the device's firmware on a board with an ET1100 on SPI, whose
/// EEPROM selects the SPI PDI (PDI control 0x05; the ET1100 driver refuses anything else). A
/// definition made for another chip says otherwise (the axis hub's LAN9252 needs 0x80, its
/// on-chip bus), so the image gets the byte of that board (CRC recomputed); everything
/// else stays the definition's.
fn spi_pdi(sii: &mut [u8]) -> Result<(), oxicat_wire::WireError> {
    let mut c = oxicat_wire::sii::SiiConfig::parse(sii)?;
    c.pdi_control = (c.pdi_control & 0xFF00) | 0x0005;
    c.write(sii).map(drop)
}

/// Adds node `k` of `kit` on an ESC configured as `esc` (with its oscillator off by
/// `drift_ppm`) and its SII, and lets `boot` put firmware on it: the seam for firmware
/// other than the host-compiled application (a board image on an emulated MCU, whose ESC
/// is the chip the board carries).
pub fn add_node_on(
    segment: &mut Segment,
    kit: &Kit,
    k: usize,
    esc: EscConfig,
    drift_ppm: f64,
    boot: impl FnOnce(&mut Segment, SlaveId) -> Result<(), AttachError>,
) -> Result<SlaveId, NodeError> {
    let def = (kit.def)(k);
    let sii = oxicat_esi::sii::generate(def).map_err(NodeError::Sii)?;
    add_node_with_sii(segment, esc, sii, drift_ppm, boot)
}

fn add_node_with_sii(
    segment: &mut Segment,
    mut esc: EscConfig,
    sii: Vec<u8>,
    drift_ppm: f64,
    boot: impl FnOnce(&mut Segment, SlaveId) -> Result<(), AttachError>,
) -> Result<SlaveId, NodeError> {
    esc.clock.drift_ppm = drift_ppm;
    let id = segment.add(Esc::new(esc, sii));
    boot(segment, id).map_err(NodeError::Attach)?;
    Ok(id)
}
