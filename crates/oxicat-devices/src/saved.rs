//! A machine as `oxicat scan --save DIR` records it, and as `oxicat sim --segment DIR` serves
//! it again (feature `bench`): one directory,
//!
//! - `segment.toml`, the manifest ([`Manifest`]): `format = 1`, then a `[[slave]]` per slave
//!   in line order with what the scan found (position, station address, alias, AL state,
//!   name, vendor ID, product code, revision, serial number), the ESC's information
//!   registers 0x0000..0x0009 (`esc_registers`, hex bytes: type, revision, build, FMMU and
//!   SM count, process RAM, port descriptor, features), and the names of its files:
//! - `slave-<pos>-sii.bin`: the SII EEPROM, all of it, as `oxicat sii-read --raw` reads it;
//! - `slave-<pos>-dictionary.toml` (slaves with CoE and SDO information): a `[[object]]` per
//!   object (index, name, object_code, data_type, max_sub) with an `[[object.entry]]` per
//!   described entry (sub, data_type, bits, access, unit, name, and `value` in hex bytes,
//!   little endian, where the entry could be read).
//!
//! Numbers are TOML integers (decimal); file names are relative to the directory.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use oxicat_esi::twin::{SavedEntry, SavedObject};

/// The manifest's file name.
pub const MANIFEST: &str = "segment.toml";

/// The version of the format this build writes and reads.
pub const FORMAT: u32 = 1;

/// `segment.toml` of a saved machine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// [`FORMAT`].
    pub format: u32,
    /// Where it was scanned (`--udp 127.0.0.1:34980`, `--iface eth0`), for the reader.
    #[serde(default)]
    pub scanned_from: String,
    /// The slaves in line order.
    #[serde(rename = "slave")]
    pub slaves: Vec<SavedSlave>,
}

/// One slave of a [`Manifest`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedSlave {
    /// Position (0 = first).
    pub position: usize,
    /// Station address the master gave it.
    pub station_address: u16,
    /// Station alias.
    pub alias: u16,
    /// AL state when scanned.
    pub state: String,
    /// Name (SII).
    pub name: String,
    /// Vendor ID.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Serial number.
    pub serial: u32,
    /// ESC registers 0x0000..0x0009, hex bytes (`11 00 03 00 08 08 08 0f fc 01`).
    pub esc_registers: String,
    /// The SII image file.
    pub sii: String,
    /// The dictionary file (slaves with CoE).
    pub dictionary: Option<String>,
}

/// A dictionary file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DictionaryFile {
    /// The objects in the order the slave listed them.
    #[serde(default, rename = "object")]
    pub objects: Vec<ObjectRecord>,
}

/// One object of a [`DictionaryFile`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectRecord {
    /// Index.
    pub index: u16,
    /// Name.
    pub name: String,
    /// Object code (7 VAR, 8 ARRAY, 9 RECORD).
    pub object_code: u8,
    /// Data type code.
    pub data_type: u16,
    /// Highest subindex.
    pub max_sub: u8,
    /// The described entries.
    #[serde(default, rename = "entry")]
    pub entries: Vec<EntryRecord>,
}

/// One entry of an [`ObjectRecord`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EntryRecord {
    /// Subindex.
    pub sub: u8,
    /// Data type code.
    pub data_type: u16,
    /// Bit length.
    pub bits: u16,
    /// Access flags (SDO information).
    pub access: u16,
    /// Unit, if given.
    pub unit: Option<u32>,
    /// Name.
    pub name: String,
    /// Value, hex bytes, if read.
    pub value: Option<String>,
}

/// Why a saved machine cannot be read.
#[derive(Debug)]
pub enum SavedError {
    /// A file cannot be read.
    Read(PathBuf, std::io::Error),
    /// A file is not what the format says (TOML, keys, hex bytes, format version).
    Format(PathBuf, String),
}

impl std::fmt::Display for SavedError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Read(p, e) => write!(f, "cannot read {}: {e}", p.display()),
            Self::Format(p, e) => write!(f, "{}: {e}", p.display()),
        }
    }
}

impl std::error::Error for SavedError {}

/// Hex bytes separated by spaces.
pub fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Bytes of [`hex`] text (spaces optional).
pub fn unhex(s: &str) -> Option<Vec<u8>> {
    let t: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    if t.len() & 1 == 1 {
        return None;
    }
    (0..t.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(t.get(i..i + 2)?, 16).ok())
        .collect()
}

fn read_text(p: &Path) -> Result<String, SavedError> {
    std::fs::read_to_string(p).map_err(|e| SavedError::Read(p.to_path_buf(), e))
}

/// Reads `DIR/segment.toml`.
pub fn read_manifest(dir: &Path) -> Result<Manifest, SavedError> {
    let p = dir.join(MANIFEST);
    let m: Manifest = toml::from_str(&read_text(&p)?)
        .map_err(|e| SavedError::Format(p.clone(), e.to_string()))?;
    if m.format != FORMAT {
        return Err(SavedError::Format(
            p,
            format!(
                "format = {} is not {FORMAT} (the format this oxicat reads)",
                m.format
            ),
        ));
    }
    if m.slaves.is_empty() {
        return Err(SavedError::Format(p, "no [[slave]]".into()));
    }
    for (k, s) in m.slaves.iter().enumerate() {
        let regs = unhex(&s.esc_registers);
        if regs.as_ref().is_none_or(|r| r.len() != 10) {
            return Err(SavedError::Format(
                p,
                format!(
                    "slave[{k}].esc_registers = {:?} is not 10 hex bytes (ESC registers 0x0000..0x0009)",
                    s.esc_registers
                ),
            ));
        }
        for f in std::iter::once(&s.sii).chain(&s.dictionary) {
            if Path::new(f).components().count() != 1 {
                return Err(SavedError::Format(
                    p,
                    format!("slave[{k}]: {f:?} is not a file name in the directory"),
                ));
            }
        }
    }
    Ok(m)
}

/// The ESC registers 0x0000..0x0009 of a slave of a manifest read by [`read_manifest`].
pub fn esc_registers(s: &SavedSlave) -> [u8; 10] {
    let mut r = [0u8; 10];
    if let Some(b) = unhex(&s.esc_registers).filter(|b| b.len() == 10) {
        r.copy_from_slice(&b);
    }
    r
}

/// Reads a dictionary file into the objects a twin is built from.
pub fn read_dictionary(p: &Path) -> Result<Vec<SavedObject>, SavedError> {
    let d: DictionaryFile = toml::from_str(&read_text(p)?)
        .map_err(|e| SavedError::Format(p.to_path_buf(), e.to_string()))?;
    d.objects
        .into_iter()
        .map(|o| {
            let entries = o
                .entries
                .into_iter()
                .map(|e| {
                    let value = match &e.value {
                        None => None,
                        Some(v) => Some(unhex(v).ok_or_else(|| {
                            SavedError::Format(
                                p.to_path_buf(),
                                format!(
                                    "object 0x{:04X}:{} value {v:?} is not hex bytes",
                                    o.index, e.sub
                                ),
                            )
                        })?),
                    };
                    Ok(SavedEntry {
                        sub: e.sub,
                        data_type: e.data_type,
                        bits: e.bits,
                        access: e.access,
                        unit: e.unit,
                        name: e.name,
                        value,
                    })
                })
                .collect::<Result<Vec<_>, SavedError>>()?;
            Ok(SavedObject {
                index: o.index,
                name: o.name,
                object_code: o.object_code,
                data_type: o.data_type,
                max_sub: o.max_sub,
                entries,
            })
        })
        .collect()
}

/// The dictionary file of `objects`.
pub fn dictionary_file(objects: &[SavedObject]) -> DictionaryFile {
    DictionaryFile {
        objects: objects
            .iter()
            .map(|o| ObjectRecord {
                index: o.index,
                name: o.name.clone(),
                object_code: o.object_code,
                data_type: o.data_type,
                max_sub: o.max_sub,
                entries: o
                    .entries
                    .iter()
                    .map(|e| EntryRecord {
                        sub: e.sub,
                        data_type: e.data_type,
                        bits: e.bits,
                        access: e.access,
                        unit: e.unit,
                        name: e.name.clone(),
                        value: e.value.as_deref().map(hex),
                    })
                    .collect(),
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_round_trips_and_refuses_junk() {
        assert_eq!(hex(&[0x11, 0, 0xfc]), "11 00 fc");
        assert_eq!(unhex("11 00 fc"), Some(vec![0x11, 0, 0xfc]));
        assert_eq!(unhex("1100FC"), Some(vec![0x11, 0, 0xfc]));
        assert_eq!(unhex("1"), None);
        assert_eq!(unhex("zz"), None);
        assert_eq!(unhex("é1"), None);
    }

    #[test]
    fn a_dictionary_round_trips_through_its_file() {
        let objs = vec![SavedObject {
            index: 0x1018,
            name: "Identity".into(),
            object_code: 9,
            data_type: 0x2A,
            max_sub: 1,
            entries: vec![SavedEntry {
                sub: 1,
                data_type: 7,
                bits: 32,
                access: 7,
                unit: Some(0),
                name: "Vendor ID".into(),
                value: Some(vec![2, 0, 0, 0]),
            }],
        }];
        let text = toml::to_string(&dictionary_file(&objs)).unwrap();
        let dir = std::env::temp_dir().join(format!("oxicat-saved-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("d.toml");
        std::fs::write(&f, &text).unwrap();
        assert_eq!(read_dictionary(&f).unwrap(), objs);
        std::fs::write(&f, text.replace("02 00 00 00", "nothex")).unwrap();
        let e = read_dictionary(&f).unwrap_err().to_string();
        assert!(e.contains("0x1018:1") && e.contains("not hex"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
