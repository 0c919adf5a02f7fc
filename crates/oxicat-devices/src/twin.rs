//! Twins from a vendor's ESI on the virtual segment (feature `bench`): the description
//! ([`oxicat_esi::twin`]: definition, SII, ESC) booted on the one firmware host with the one
//! slave stack, or — for a device without a mailbox — the ESC alone in device emulation.
//!
//! Process data: a stack twin's inputs do what its [`behaviour::Behaviour`] says (by
//! default, by profile: a CiA402 device runs oxicat's drive on a motor plant, digital
//! outputs loop back to inputs, analog inputs follow a signal generator), on the segment's
//! virtual clock ([`firmware`]). An ESC-only twin has no firmware: its outputs go nowhere
//! and its inputs read 0, as a terminal's ESC with nothing wired to its pins.
//!
//! Twins are named `esi=FILE[:TYPE or PRODUCT CODE[:REVISION]]` wherever devices are named
//! (`oxicat sim`, `--sim`, a segment file); [`load`] builds each once per process (the
//! definition is leaked to be `'static`, see [`oxicat_esi::twin`]) and caches it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use oxicat_esc::{DcSupport, Esc, EscConfig};
use oxicat_esi::twin::{Candidate, Selector, Served, TwinError};
use oxicat_sim::firmware::{attach_host, boot_stack, AttachError};
use oxicat_sim::pdi_path::{Direct, PdiRoute, SpiPath};
use oxicat_sim::segment::{Segment, SlaveId};

use crate::registry::NodeError;

pub mod behaviour;
pub mod firmware;
pub mod pins;

use behaviour::{Behaviour, Mode};

/// The prefix that names a twin where a device name is expected.
pub const PREFIX: &str = "esi=";

/// The prefix that names a twin of a slave's SII image (`sii=FILE`, binary or Intel HEX):
/// the ESC with that EEPROM, and the stack when the SII has a mailbox ([`load_sii`]).
pub const SII_PREFIX: &str = "sii=";

/// A twin as the registry hands it out.
#[derive(Debug)]
pub struct Twin {
    /// The spec it was loaded from (`esi=FILE:TYPE`), its name in listings.
    pub spec: String,
    /// The description.
    pub esi: oxicat_esi::twin::Twin,
    /// The ESC information registers 0x0000..0x0009 of a recorded slave (type, revision,
    /// build, FMMU and SM count, RAM, ports, features), served instead of [`esc_config`]'s.
    pub esc_registers: Option<[u8; 10]>,
    /// What its process data does (by default: by profile).
    pub behaviour: Behaviour,
}

impl Twin {
    /// True when it runs the CiA402 drive: `behaviour = "drive"`, or by profile
    /// ([`behaviour::is_cia402`]).
    pub fn drives(&self) -> bool {
        match self.behaviour.mode {
            Mode::Drive => true,
            Mode::Auto => behaviour::is_cia402(self.esi.def, self.esi.profile_no),
            Mode::Loop | Mode::Hold => false,
        }
    }
}

/// The twin `t` with another behaviour, as a new twin (leaked like the others: one per
/// segment-file entry that gives a behaviour).
pub fn with_behaviour(t: &Twin, behaviour: Behaviour) -> &'static Twin {
    Box::leak(Box::new(Twin {
        spec: t.spec.clone(),
        esi: t.esi.clone(),
        esc_registers: t.esc_registers,
        behaviour,
    }))
}

/// Why a twin could not be loaded.
#[derive(Debug)]
pub enum LoadError {
    /// The ESI file could not be read.
    Read(PathBuf, std::io::Error),
    /// The ESI device cannot be served.
    Twin(PathBuf, TwinError),
    /// A recorded slave's files are not what `oxicat scan --save` writes.
    Saved(crate::saved::SavedError),
}

impl std::fmt::Display for LoadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Read(p, e) => write!(f, "cannot read the ESI {}: {e}", p.display()),
            Self::Twin(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Saved(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for LoadError {}

/// Splits `FILE[:SELECTOR]` (without the `esi=` prefix) into the file and the selector.
pub fn split_spec(spec: &str) -> Result<(PathBuf, Selector), LoadError> {
    let (file, sel) = match spec.split_once(':') {
        Some((f, s)) => (f, s),
        None => (spec, ""),
    };
    let path = PathBuf::from(file);
    let sel = Selector::parse(sel).map_err(|e| LoadError::Twin(path.clone(), e))?;
    Ok((path, sel))
}

type Cache = Mutex<HashMap<String, &'static Twin>>;

fn cache() -> &'static Cache {
    static C: std::sync::OnceLock<Cache> = std::sync::OnceLock::new();
    C.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The twin of `spec` (`FILE[:TYPE[:REVISION]]`, with or without `esi=`), built once per
/// process.
pub fn load(spec: &str) -> Result<&'static Twin, LoadError> {
    let spec = spec.strip_prefix(PREFIX).unwrap_or(spec);
    let key = format!("{PREFIX}{spec}");
    if let Some(t) = cache().lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return Ok(t);
    }
    let (path, sel) = split_spec(spec)?;
    let text = read(&path)?;
    let esi = oxicat_esi::twin::build(&text, &sel).map_err(|e| LoadError::Twin(path, e))?;
    let t: &'static Twin = Box::leak(Box::new(Twin {
        spec: key.clone(),
        esi,
        esc_registers: None,
        behaviour: Behaviour::default(),
    }));
    cache()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(key, t);
    Ok(t)
}

fn read(path: &Path) -> Result<String, LoadError> {
    let bytes = std::fs::read(path).map_err(|e| LoadError::Read(path.to_path_buf(), e))?;
    Ok(oxicat_esi::twin::decode(&bytes))
}

/// The twin of the slave whose SII image is the file `sii` (binary or Intel HEX), with the
/// CoE dictionary of `dictionary` (a `oxicat scan --save` dictionary file) and the ESC
/// registers `esc_registers` where it was recorded with them; built once per process.
pub fn load_sii(
    sii: &Path,
    dictionary: Option<&Path>,
    esc_registers: Option<[u8; 10]>,
) -> Result<&'static Twin, LoadError> {
    // The files are read each time (a recording may change between two builds in one
    // process); the twin is built once per content.
    let bytes = std::fs::read(sii).map_err(|e| LoadError::Read(sii.to_path_buf(), e))?;
    let dict_text = dictionary
        .map(|d| std::fs::read(d).map_err(|e| LoadError::Read(d.to_path_buf(), e)))
        .transpose()?;
    let key = {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (&bytes, &dict_text, esc_registers).hash(&mut h);
        format!("{SII_PREFIX}{}#{:016x}", sii.display(), h.finish())
    };
    if let Some(t) = cache().lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return Ok(t);
    }
    let img = if bytes.first() == Some(&b':') {
        oxicat_esi::sii::intel_hex(&bytes)
            .map_err(|e| LoadError::Twin(sii.to_path_buf(), TwinError::Sii(e)))?
    } else {
        bytes
    };
    let dict = dictionary
        .map(crate::saved::read_dictionary)
        .transpose()
        .map_err(LoadError::Saved)?;
    let esi = oxicat_esi::twin::from_sii(&img, dict.as_deref())
        .map_err(|e| LoadError::Twin(sii.to_path_buf(), e))?;
    let t: &'static Twin = Box::leak(Box::new(Twin {
        spec: format!("{SII_PREFIX}{}", sii.display()),
        esi,
        esc_registers,
        behaviour: Behaviour::default(),
    }));
    cache()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(key, t);
    Ok(t)
}

/// Every device type of the ESI file `path` (parsed once), each with its twin or why it
/// cannot be served (a catalogue walk).
pub type Loaded = (Candidate, Result<&'static Twin, TwinError>);

/// See [`Loaded`].
pub fn load_file(path: &Path) -> Result<Vec<Loaded>, LoadError> {
    let text = read(path)?;
    let all =
        oxicat_esi::twin::build_all(&text).map_err(|e| LoadError::Twin(path.to_path_buf(), e))?;
    Ok(all
        .into_iter()
        .map(|(c, r)| {
            let r = r.map(|esi| {
                let spec = format!(
                    "{PREFIX}{}:{}:{:#010x}",
                    path.display(),
                    c.type_name,
                    c.revision
                );
                &*Box::leak(Box::new(Twin {
                    spec,
                    esi,
                    esc_registers: None,
                    behaviour: Behaviour::default(),
                }))
            });
            (c, r)
        })
        .collect())
}

/// The ESC of a twin: an ET1100's registers with the ESI's FMMU/SM counts, process RAM and
/// ports, and the full DC unit.
pub fn esc_config(t: &Twin) -> EscConfig {
    if let Some(r) = t.esc_registers {
        let features = u16::from_le_bytes([r[8], r[9]]);
        return EscConfig {
            esc_type: r[0],
            revision: r[1],
            build: u16::from_le_bytes([r[2], r[3]]),
            fmmu_count: r[4].clamp(1, 16),
            sm_count: r[5].clamp(1, 16),
            ram_kib: r[6].clamp(1, 60),
            port_descriptor: r[7],
            features,
            // Feature bit 2: distributed clocks.
            dc: if features & 0x0004 != 0 {
                DcSupport::Full
            } else {
                DcSupport::None
            },
            ..EscConfig::et1100()
        };
    }
    let e = t.esi.esc;
    EscConfig {
        fmmu_count: e.fmmu_count,
        sm_count: e.sm_count,
        ram_kib: e.ram_kib,
        port_descriptor: e.port_descriptor,
        dc: DcSupport::Full,
        ..EscConfig::et1100()
    }
}

/// Adds node `k` of twin `t` at the end of the segment's line (oscillator off by
/// `drift_ppm`) and boots it: the stack through `route`, or nothing for an ESC-only twin.
pub fn add_node(
    segment: &mut Segment,
    t: &'static Twin,
    drift_ppm: f64,
    route: PdiRoute,
) -> Result<SlaveId, NodeError> {
    let mut cfg = esc_config(t);
    cfg.clock.drift_ppm = drift_ppm;
    let id = segment.add(Esc::new(cfg, t.esi.sii.clone()));
    if t.esi.served == Served::EscOnly {
        // No firmware: the ESC's digital I/O, its input pins as the behaviour says (a
        // behaviour a segment file gives was checked against the pins when it was read).
        if let Ok(p) = pins::Pins::new(t.esi.def, &t.esi.sii, &t.behaviour) {
            if !p.is_empty() {
                segment
                    .attach(id, Box::new(p))
                    .expect("the ESC was added just now");
            }
        }
        return Ok(id);
    }
    let small_image = t.esi.image_bytes <= 4096;
    let small_mbx = t.esi.mailbox_bytes <= 256;
    match (small_image, small_mbx) {
        (true, true) => boot::<4096, 256>(segment, id, t, route),
        (true, false) => boot::<4096, 1024>(segment, id, t, route),
        (false, true) => boot::<{ oxicat_esi::twin::MAX_IMAGE }, 256>(segment, id, t, route),
        (false, false) => boot::<{ oxicat_esi::twin::MAX_IMAGE }, 1024>(segment, id, t, route),
    }
    .map_err(NodeError::Attach)?;
    Ok(id)
}

fn boot<const N: usize, const M: usize>(
    segment: &mut Segment,
    id: SlaveId,
    t: &'static Twin,
    route: PdiRoute,
) -> Result<(), AttachError> {
    let app = firmware::TwinApp::new(t.esi.def, &t.behaviour, t.drives());
    let cfg = firmware::schedule();
    let bench = firmware::TwinBench;
    let def = t.esi.def;
    match route {
        PdiRoute::Direct => attach_host(
            segment,
            id,
            &cfg,
            bench,
            |_| Ok(Direct),
            |esc, path| boot_stack::<_, N, M, _>(def, esc, app, path),
        )
        .map(drop),
        route => attach_host(
            segment,
            id,
            &cfg,
            bench,
            |esc| SpiPath::new(route, esc),
            |esc, path| boot_stack::<_, N, M, _>(def, esc, app, path),
        )
        .map(drop),
    }
}
