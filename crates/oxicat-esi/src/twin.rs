//! Twins from ESI: a vendor's ESI `Device` → a runtime [`DeviceDef`] for the one no_std
//! slave stack, the SII image generated from it (with the ESI's sync managers), the ESC the
//! device carries, and what of the ESI is not served.
//!
//! The definition is built at run time and leaked (`Box::leak`) to get the `'static` data
//! the stack's definition holds: a std tool builds a handful of twins per process, and the
//! callers in `oxicat-devices` cache them per file and device, so nothing is leaked twice.
//!
//! Two kinds of twin, as the ESI says:
//! - a device with a mailbox runs the slave stack ([`Served::Stack`]): the object dictionary
//!   from the ESI's `Dictionary` (types, access, defaults, PDO mapping and assignment, SDO
//!   information), its mailbox sizes, DC op modes (0x1C32/0x1C33 sync modes);
//! - a device without one (digital terminals, couplers) is the ESC alone
//!   ([`Served::EscOnly`]): its ESI sets the ESC's device emulation (AL status follows AL
//!   control) as the real ESC-only terminal does, its process data sits in the sync
//!   managers the ESI names (`Outputs` at 0x0F00, …).

use std::collections::HashMap;

use oxicat_slave::device::{
    CoeInfo, DcOpMode, DeviceInfo, EscConfigArea, FmmuUsage, Group, Identity, MailboxDef,
    SmControl, SyncDef,
};
use oxicat_slave::od::{image_size, DefaultValue, MAX_ASSIGN, MAX_PDOS, MAX_PDO_ENTRIES};
use oxicat_slave::pdo::{MAX_ITEMS, MAX_PD_BYTES};
use oxicat_slave::{
    Access, DataType, DeviceDef, EntryDef, ObjectCode, ObjectDef, PdoDef, PdoEntry, PdoMapping,
    SyncMode,
};
use oxicat_wire::sii::{SiiSyncManager, SmType};
use roxmltree::Node;

use crate::esi::{parse_hex_bytes, parse_num};
use crate::model::{DeviceModel, FmmuKind, PdoModel, SmKind};
use crate::sii::SmLayout;

/// Largest object-dictionary image a twin gets (bytes of application object values).
pub const MAX_IMAGE: usize = 65536;
/// Largest mailbox a twin serves (bytes).
pub const MAX_MAILBOX: u16 = 1024;

/// One device type of an ESI file, as a selector names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Candidate {
    /// The `Type` text (order code), e.g. `EL3001`.
    pub type_name: String,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// The device name (`Name`, English where the ESI has several).
    pub name: String,
}

impl std::fmt::Display for Candidate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} (product code {:#010x}, revision {:#010x})",
            self.type_name, self.product_code, self.revision
        )
    }
}

/// Which device of an ESI file: `TYPE` or a product code, and optionally a revision.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Selector {
    /// A `Type` text, or a product code (`#x…`, `0x…` or decimal); `None`: the file's only
    /// device type.
    pub pick: Option<String>,
    /// The revision; `None`: the highest revision of the type.
    pub revision: Option<u32>,
}

impl Selector {
    /// Parses `TYPE[:REVISION]` (the part of `FILE:TYPE:REVISION` after the file).
    pub fn parse(s: &str) -> Result<Self, TwinError> {
        let mut it = s.splitn(2, ':');
        let pick = it.next().filter(|p| !p.is_empty()).map(str::to_string);
        let revision = match it.next() {
            None => None,
            Some(r) => Some(
                parse_num(r)
                    .and_then(|v| u32::try_from(v).ok())
                    .ok_or_else(|| TwinError::BadSelector(s.to_string()))?,
            ),
        };
        Ok(Self { pick, revision })
    }
}

/// How a twin is served.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Served {
    /// By the slave stack (devices with a mailbox).
    Stack,
    /// By the ESC alone, in device emulation (devices without a mailbox).
    EscOnly,
}

/// The ESC a twin's device carries, as far as its ESI says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EscSpec {
    /// FMMUs (the ESI's `EtherCATController/FmmuCount`, else enough for its `Fmmu`s).
    pub fmmu_count: u8,
    /// Sync managers (`SmCount`, else enough for its `Sm`s).
    pub sm_count: u8,
    /// Process RAM in KiB (`DpramSize`, else 8 KiB or what its SMs need).
    pub ram_kib: u8,
    /// Port descriptor (register 0x0007) from the `Physics` letters (`Y` MII, `K` E-bus);
    /// ports 0 and 1 always exist so the twin can sit anywhere in a line.
    pub port_descriptor: u8,
    /// The ESI gave `EtherCATController` (else the values are derived).
    pub from_esi: bool,
}

/// A twin: what the segment needs to serve one ESI device type.
#[derive(Debug, Clone)]
pub struct Twin {
    /// Which device type of the file.
    pub candidate: Candidate,
    /// The definition (leaked, `'static`).
    pub def: &'static DeviceDef,
    /// The SII EEPROM image.
    pub sii: Vec<u8>,
    /// The ESC.
    pub esc: EscSpec,
    /// Stack or ESC alone.
    pub served: Served,
    /// Bytes of the application object image the stack needs.
    pub image_bytes: usize,
    /// The larger of the two mailbox sizes (0 without a mailbox).
    pub mailbox_bytes: u16,
    /// The loop-back pairs of the default mapping ([`loop_pairs`]); a twin's firmware pairs
    /// the mapping the master left active when the process data starts.
    pub loopback: Vec<(PdoEntry, PdoEntry)>,
    /// What of the ESI the twin does not serve, one line each.
    pub left_out: Vec<String>,
    /// The ESI's `Profile/ProfileNo` (402: a CiA402 drive, 5001: a modular device, …).
    pub profile_no: Option<u32>,
}

/// Why an ESI device cannot be served.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TwinError {
    /// The file is not well-formed XML, or not an ESI.
    Xml(String),
    /// An ESI value does not parse.
    Esi(crate::Error),
    /// The file describes no device.
    NoDevices,
    /// No device type of that name or product code.
    NoSuchType {
        /// What was asked.
        asked: String,
        /// The file's types.
        choices: Vec<String>,
    },
    /// The type exists, the revision does not.
    NoSuchRevision {
        /// The type.
        type_name: String,
        /// The revision asked for.
        asked: u32,
        /// The type's revisions.
        choices: Vec<u32>,
    },
    /// Several device types match: say which.
    Ambiguous {
        /// What was asked (`None`: nothing).
        asked: Option<String>,
        /// The matching types.
        choices: Vec<String>,
    },
    /// `TYPE[:REVISION]` does not parse.
    BadSelector(String),
    /// The ESI contradicts itself (sizes of PDO entries and objects, SM sizes, excluded
    /// PDOs assigned together, a PDO entry its object lacks).
    Inconsistent(String),
    /// The device needs something the stack cannot represent.
    Unsupported(String),
    /// An SII image (of a twin from a slave's SII) is malformed.
    Sii(crate::Error),
}

impl std::fmt::Display for TwinError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Xml(e) => write!(f, "not a readable ESI: {e}"),
            Self::Esi(e) => write!(f, "ESI: {e}"),
            Self::NoDevices => write!(f, "the ESI describes no device"),
            Self::NoSuchType { asked, choices } => write!(
                f,
                "no device type {asked:?} (by Type or product code) in the ESI; it has: {}",
                choices.join(", ")
            ),
            Self::NoSuchRevision {
                type_name,
                asked,
                choices,
            } => write!(
                f,
                "{type_name} has no revision {asked:#010x}; it has: {}",
                choices
                    .iter()
                    .map(|r| format!("{r:#010x}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            Self::Ambiguous { asked, choices } => write!(
                f,
                "{} several device types; say which (FILE:TYPE or FILE:PRODUCTCODE[:REVISION]): {}",
                match asked {
                    Some(a) => format!("{a:?} matches"),
                    None => "the ESI has".to_string(),
                },
                choices.join(", ")
            ),
            Self::BadSelector(s) => write!(
                f,
                "{s:?} is not TYPE[:REVISION] (revision a number: 0x00120000, #x00120000 or decimal)"
            ),
            Self::Inconsistent(e) => write!(f, "inconsistent ESI: {e}"),
            Self::Unsupported(e) => write!(f, "cannot be served: {e}"),
            Self::Sii(e) => write!(f, "SII image: {e}"),
        }
    }
}

impl std::error::Error for TwinError {}

impl From<crate::Error> for TwinError {
    fn from(e: crate::Error) -> Self {
        TwinError::Esi(e)
    }
}

/// The text of an ESI file's bytes: UTF-8 (a byte-order mark dropped), UTF-16 with a
/// byte-order mark, or else ISO-8859-1 (as some vendors write them, e.g. ASIX).
pub fn decode(bytes: &[u8]) -> String {
    if let Some(b) = bytes.strip_prefix(&[0xEF, 0xBB, 0xBF]) {
        return String::from_utf8_lossy(b).into_owned();
    }
    let utf16 = |b: &[u8], le: bool| {
        let units: Vec<u16> = b
            .chunks_exact(2)
            .map(|c| {
                if le {
                    u16::from_le_bytes([c[0], c[1]])
                } else {
                    u16::from_be_bytes([c[0], c[1]])
                }
            })
            .collect();
        String::from_utf16_lossy(&units)
    };
    if let Some(b) = bytes.strip_prefix(&[0xFF, 0xFE]) {
        return utf16(b, true);
    }
    if let Some(b) = bytes.strip_prefix(&[0xFE, 0xFF]) {
        return utf16(b, false);
    }
    match std::str::from_utf8(bytes) {
        Ok(s) => s.to_string(),
        Err(_) => bytes.iter().map(|&c| c as char).collect(),
    }
}

// ------------------------------------------------------------------ document access

fn child<'a, 'i>(n: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(name))
}

fn children<'a, 'i: 'a>(n: Node<'a, 'i>, name: &'a str) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    n.children().filter(move |c| c.has_tag_name(name))
}

fn text(n: Option<Node>) -> Option<String> {
    n.map(|n| n.text().unwrap_or("").trim().to_string())
}

/// The English `Name` (LcId 1033) of an element, else its first.
fn name_of(n: Node) -> Option<String> {
    children(n, "Name")
        .find(|c| c.attribute("LcId") == Some("1033"))
        .or_else(|| child(n, "Name"))
        .map(|c| c.text().unwrap_or("").trim().to_string())
}

fn leak(s: &str) -> &'static str {
    Box::leak(s.to_string().into_boxed_str())
}

/// Gives `e` default `d`: in the entry's own word when it fits there, else in (leaked)
/// limits that keep the entry's unit, range and scaling.
pub(crate) fn set_default(e: &mut EntryDef, d: DefaultValue) {
    let inline = match d.as_bits() {
        Some(v) => e.limits.default.is_none() && e.set_default_word(v),
        None => false,
    };
    if !inline {
        e.limits = Box::leak(Box::new(e.limits.with_default(d)));
    }
}

struct Esi<'a, 'i> {
    root: Node<'a, 'i>,
    vendor_id: u32,
    vendor_name: Option<String>,
    devices: Vec<Node<'a, 'i>>,
}

fn open<'a, 'i>(doc: &'a roxmltree::Document<'i>) -> Result<Esi<'a, 'i>, TwinError> {
    let root = doc.root_element();
    if !root.has_tag_name("EtherCATInfo") {
        return Err(TwinError::Xml(format!(
            "the root element is <{}>, not <EtherCATInfo>",
            root.tag_name().name()
        )));
    }
    let vendor = child(root, "Vendor").ok_or(crate::Error::Missing("Vendor"))?;
    let vid = text(child(vendor, "Id")).ok_or(crate::Error::Missing("Vendor/Id"))?;
    let vendor_id = crate::esi::num_u32("Vendor/Id", &vid)?;
    let devices: Vec<_> = child(root, "Descriptions")
        .and_then(|d| child(d, "Devices"))
        .map(|d| children(d, "Device").collect())
        .unwrap_or_default();
    if devices.is_empty() {
        return Err(TwinError::NoDevices);
    }
    Ok(Esi {
        root,
        vendor_id,
        vendor_name: name_of(vendor),
        devices,
    })
}

fn parse_doc(xml: &str) -> Result<roxmltree::Document<'_>, TwinError> {
    // ESI files are often written with a DTD-less BOM'd UTF-8 header; roxmltree takes that.
    let opts = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    roxmltree::Document::parse_with_options(xml, opts).map_err(|e| TwinError::Xml(e.to_string()))
}

fn candidate(d: Node) -> Result<Candidate, TwinError> {
    let t = child(d, "Type").ok_or(crate::Error::Missing("Device/Type"))?;
    let num = |a: &'static str| -> Result<u32, TwinError> {
        Ok(t.attribute(a)
            .map(|v| crate::esi::num_u32(a, v))
            .transpose()?
            .unwrap_or(0))
    };
    Ok(Candidate {
        type_name: t.text().unwrap_or("").trim().to_string(),
        product_code: num("ProductCode")?,
        revision: num("RevisionNo")?,
        name: name_of(d).unwrap_or_default(),
    })
}

/// The device types of an ESI file, in file order.
pub fn candidates(xml: &str) -> Result<Vec<Candidate>, TwinError> {
    let doc = parse_doc(xml)?;
    let esi = open(&doc)?;
    esi.devices.iter().map(|d| candidate(*d)).collect()
}

/// The vendor ID of an ESI file and its device types, in file order (what a search by
/// identity, e.g. for an ENI's slaves, reads of each file).
pub fn catalogue(xml: &str) -> Result<(u32, Vec<Candidate>), TwinError> {
    let doc = parse_doc(xml)?;
    let esi = open(&doc)?;
    let c = esi
        .devices
        .iter()
        .map(|d| candidate(*d))
        .collect::<Result<_, _>>()?;
    Ok((esi.vendor_id, c))
}

/// Which of `cands` `sel` names (its position), or why none or several.
pub fn select(cands: &[Candidate], sel: &Selector) -> Result<usize, TwinError> {
    let types = |list: &mut dyn Iterator<Item = &Candidate>| {
        let mut v: Vec<String> = Vec::new();
        for c in list {
            if !v.contains(&c.type_name) {
                v.push(c.type_name.clone());
            }
        }
        v
    };
    let matching: Vec<usize> = match &sel.pick {
        None => (0..cands.len()).collect(),
        Some(p) => {
            let by_type: Vec<usize> = (0..cands.len())
                .filter(|&i| cands[i].type_name.eq_ignore_ascii_case(p))
                .collect();
            if !by_type.is_empty() {
                by_type
            } else {
                let code = parse_num(p).and_then(|v| u32::try_from(v).ok());
                (0..cands.len())
                    .filter(|&i| Some(cands[i].product_code) == code)
                    .collect()
            }
        }
    };
    if matching.is_empty() {
        return Err(TwinError::NoSuchType {
            asked: sel.pick.clone().unwrap_or_default(),
            choices: types(&mut cands.iter()),
        });
    }
    let matching: Vec<usize> = match sel.revision {
        None => matching,
        Some(r) => {
            let m: Vec<usize> = matching
                .iter()
                .copied()
                .filter(|&i| cands[i].revision == r)
                .collect();
            if m.is_empty() {
                return Err(TwinError::NoSuchRevision {
                    type_name: cands[matching[0]].type_name.clone(),
                    asked: r,
                    choices: matching.iter().map(|&i| cands[i].revision).collect(),
                });
            }
            m
        }
    };
    let names = types(&mut matching.iter().map(|&i| &cands[i]));
    if names.len() > 1 {
        return Err(TwinError::Ambiguous {
            asked: sel.pick.clone(),
            choices: matching.iter().map(|&i| cands[i].to_string()).collect(),
        });
    }
    // One type: its highest revision (the first of equals).
    let mut best = matching[0];
    for &i in &matching[1..] {
        if cands[i].revision > cands[best].revision {
            best = i;
        }
    }
    Ok(best)
}

/// The twin of the device `sel` names in the ESI text `xml`.
pub fn build(xml: &str, sel: &Selector) -> Result<Twin, TwinError> {
    let doc = parse_doc(xml)?;
    let esi = open(&doc)?;
    let cands = esi
        .devices
        .iter()
        .map(|d| candidate(*d))
        .collect::<Result<Vec<_>, _>>()?;
    let i = select(&cands, sel)?;
    build_device(&esi, esi.devices[i], cands[i].clone())
}

/// One device type of a file and its twin, or why it cannot be served.
pub type Built = (Candidate, Result<Twin, TwinError>);

/// Every device of the ESI text `xml` (one parse for a catalogue of hundreds), each with
/// its twin or why it cannot be served.
pub fn build_all(xml: &str) -> Result<Vec<Built>, TwinError> {
    let doc = parse_doc(xml)?;
    let esi = open(&doc)?;
    let mut out = Vec::new();
    for d in &esi.devices {
        let c = candidate(*d)?;
        let r = build_device(&esi, *d, c.clone());
        out.push((c, r));
    }
    Ok(out)
}

// ------------------------------------------------------------------ data types

/// A scalar or string type: CoE type and bit length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Base {
    dtype: DataType,
    bits: u16,
}

/// The ESI base type names (ETG.2000) the stack can hold. `BITn` (n = 2..8) and the odd
/// widths (`INT24`, …) are held in the next wider type with their own bit length (the SDO
/// information reports that wider type).
fn base_type(name: &str) -> Option<Base> {
    use DataType::*;
    let b = |dtype, bits| Some(Base { dtype, bits });
    let n = name.trim();
    if let Some(len) = n
        .strip_prefix("STRING(")
        .and_then(|r| r.strip_suffix(')'))
        .and_then(|l| l.trim().parse::<u16>().ok())
    {
        return (len > 0 && len <= 8191).then_some(Base {
            dtype: VisibleString,
            bits: len * 8,
        });
    }
    if let Some(k) = n.strip_prefix("BIT").and_then(|k| k.parse::<u16>().ok()) {
        return match k {
            1 => b(Bool, 1),
            2..=8 => b(Unsigned8, k),
            _ => None,
        };
    }
    match n {
        "BOOL" | "BOOLEAN" | "BIT" => b(Bool, 1),
        "SINT" => b(Int8, 8),
        "INT" => b(Int16, 16),
        "INT24" => b(Int32, 24),
        "DINT" => b(Int32, 32),
        "INT40" => b(Int64, 40),
        "INT48" => b(Int64, 48),
        "INT56" => b(Int64, 56),
        "LINT" => b(Int64, 64),
        "USINT" | "BYTE" | "BITARR8" => b(Unsigned8, 8),
        "UINT" | "WORD" | "BITARR16" => b(Unsigned16, 16),
        "UINT24" => b(Unsigned32, 24),
        "UDINT" | "DWORD" | "BITARR32" => b(Unsigned32, 32),
        "UINT40" => b(Unsigned64, 40),
        "UINT48" => b(Unsigned64, 48),
        "UINT56" => b(Unsigned64, 56),
        "ULINT" | "LWORD" => b(Unsigned64, 64),
        "REAL" | "FLOAT" => b(Real32, 32),
        "LREAL" | "DOUBLE" => b(Real64, 64),
        _ => None,
    }
}

/// A data type of a device's dictionary, resolved.
#[derive(Debug, Clone)]
enum Ty {
    /// One value.
    Scalar(Base),
    /// `elements` values of one type, subindices from `lbound` (an array type).
    Array {
        elem: Base,
        elements: u16,
        lbound: u16,
    },
    /// Subitems: (subindex, name, type, flags node id).
    Struct(Vec<Sub>),
}

#[derive(Debug, Clone)]
struct Sub {
    sub: u8,
    name: String,
    base: Base,
    access: Option<Access>,
    pdo: PdoMapping,
}

struct Types<'a, 'i> {
    by_name: HashMap<String, Node<'a, 'i>>,
}

impl<'a, 'i> Types<'a, 'i> {
    fn new(dict: Option<Node<'a, 'i>>) -> Self {
        let mut by_name = HashMap::new();
        if let Some(dt) = dict.and_then(|d| child(d, "DataTypes")) {
            for t in children(dt, "DataType") {
                if let Some(n) = text(child(t, "Name")) {
                    by_name.entry(n).or_insert(t);
                }
            }
        }
        Self { by_name }
    }

    fn bit_size(n: Node) -> Option<u16> {
        text(child(n, "BitSize"))
            .and_then(|s| parse_num(&s))
            .and_then(|v| u16::try_from(v).ok())
    }

    /// A scalar/string type by name (base names, enums, `ARRAY … OF BYTE` as an octet
    /// string); `depth` stops a type that names itself.
    fn scalar(&self, name: &str, depth: u8) -> Result<Base, String> {
        if let Some(b) = base_type(name) {
            return Ok(b);
        }
        if depth > 8 {
            return Err(format!("type {name} refers to itself"));
        }
        let node = self
            .by_name
            .get(name.trim())
            .ok_or_else(|| format!("type {name} is not a base type and not in DataTypes"))?;
        if child(*node, "SubItem").is_some() {
            return Err(format!("type {name} is a structure inside a structure"));
        }
        let bits = Self::bit_size(*node);
        let base = text(child(*node, "BaseType"));
        if let Some(ai) = child(*node, "ArrayInfo") {
            let b = self.scalar(base.as_deref().unwrap_or(""), depth + 1)?;
            let n = text(child(ai, "Elements"))
                .and_then(|s| parse_num(&s))
                .unwrap_or(0);
            if b.bits == 8 && !b.dtype.is_string() && (1..=8191).contains(&n) {
                return Ok(Base {
                    dtype: DataType::OctetString,
                    bits: 8 * n as u16,
                });
            }
            return Err(format!("type {name} is an array of {} bits", b.bits));
        }
        match base {
            Some(bt) => {
                let mut b = self.scalar(&bt, depth + 1)?;
                if let Some(bits) = bits.filter(|&x| x > 0 && x < b.bits && !b.dtype.is_string()) {
                    b.bits = bits;
                }
                Ok(b)
            }
            None => Err(format!("type {name} has neither a base type nor subitems")),
        }
    }

    /// The type of an object.
    fn object_type(&self, name: &str) -> Result<Ty, String> {
        if let Some(b) = base_type(name) {
            return Ok(Ty::Scalar(b));
        }
        let node = self
            .by_name
            .get(name.trim())
            .ok_or_else(|| format!("type {name} is not a base type and not in DataTypes"))?;
        if child(*node, "SubItem").is_none() {
            if let Some(ai) = child(*node, "ArrayInfo") {
                let base = text(child(*node, "BaseType")).unwrap_or_default();
                let elem = self.scalar(&base, 1)?;
                if elem.bits == 8 && !elem.dtype.is_string() {
                    return self.scalar(name, 0).map(Ty::Scalar);
                }
                let (elements, lbound) = array_info(ai);
                return Ok(Ty::Array {
                    elem,
                    elements,
                    lbound,
                });
            }
            return self.scalar(name, 0).map(Ty::Scalar);
        }
        let mut subs = Vec::new();
        let mut next_sub: u16 = 0;
        for s in children(*node, "SubItem") {
            let sname = text(child(s, "Name")).unwrap_or_default();
            let tname = text(child(s, "Type")).unwrap_or_default();
            let (access, pdo) = flags(child(s, "Flags"));
            let explicit = text(child(s, "SubIdx")).and_then(|v| parse_num(&v));
            // A subitem of an array type ("Elements" of DT1C12ARR): its elements.
            // (An array of bytes is one octet string.)
            let arr = self.by_name.get(tname.trim()).filter(|t| {
                child(**t, "ArrayInfo").is_some()
                    && child(**t, "SubItem").is_none()
                    && self.scalar(&tname, 0).is_err()
            });
            match arr {
                Some(at) => {
                    let base = text(child(*at, "BaseType")).unwrap_or_default();
                    let elem = self.scalar(&base, 1)?;
                    let ai = child(*at, "ArrayInfo").expect("filtered on ArrayInfo");
                    let (elements, lbound) = array_info(ai);
                    let first = explicit.map_or(lbound.max(1), |v| v as u16);
                    for k in 0..elements {
                        let sub = first + k;
                        let sub = u8::try_from(sub)
                            .map_err(|_| format!("type {name}: subindex {sub} above 255"))?;
                        subs.push(Sub {
                            sub,
                            name: format!("{sname} {}", k + 1),
                            base: elem,
                            access,
                            pdo,
                        });
                    }
                    next_sub = first + elements;
                }
                None => {
                    let base = self
                        .scalar(&tname, 1)
                        .map_err(|e| format!("type {name}, subitem {sname:?}: {e}"))?;
                    let sub = explicit.map_or(next_sub, |v| v as u16);
                    let sub = u8::try_from(sub)
                        .map_err(|_| format!("type {name}: subindex {sub} above 255"))?;
                    subs.push(Sub {
                        sub,
                        name: sname,
                        base,
                        access,
                        pdo,
                    });
                    next_sub = sub as u16 + 1;
                }
            }
        }
        Ok(Ty::Struct(subs))
    }
}

fn array_info(ai: Node) -> (u16, u16) {
    let g = |n: &str| {
        text(child(ai, n))
            .and_then(|s| parse_num(&s))
            .and_then(|v| u16::try_from(v).ok())
            .unwrap_or(0)
    };
    (g("Elements"), g("LBound"))
}

/// Access bits of a `Flags` element (`Access` ro/rw/wo with Read/WriteRestrictions) and
/// its `PdoMapping` (R, T, RT); `None` when there is no `Access`.
fn flags(f: Option<Node>) -> (Option<Access>, PdoMapping) {
    let Some(f) = f else {
        return (None, PdoMapping::None);
    };
    let states = |r: Option<&str>| match r {
        Some("PreOP") => 1,
        Some("SafeOP") => 2,
        Some("OP") => 4,
        Some("PreOP_SafeOP") => 3,
        Some("PreOP_OP") => 5,
        Some("SafeOP_OP") => 6,
        _ => 7,
    };
    let access = child(f, "Access").map(|a| {
        let t = a.text().unwrap_or("").trim().to_ascii_lowercase();
        let r = states(a.attribute("ReadRestrictions"));
        let w = states(a.attribute("WriteRestrictions"));
        Access(match t.as_str() {
            "rw" => r | (w << 3),
            "wo" => w << 3,
            _ => r,
        })
    });
    let pdo = match text(child(f, "PdoMapping"))
        .unwrap_or_default()
        .to_ascii_uppercase()
        .as_str()
    {
        "R" => PdoMapping::Rx,
        "T" => PdoMapping::Tx,
        "RT" | "TR" => PdoMapping::RxTx,
        _ => PdoMapping::None,
    };
    (access, pdo)
}

/// The default of an `Info` element (`DefaultData` little-endian hex, `DefaultValue`
/// number, `DefaultString`).
fn default_of(info: Option<Node>, base: Base) -> DefaultValue {
    let Some(info) = info else {
        return DefaultValue::bits(0);
    };
    if base.dtype.is_string() {
        if let Some(s) = info
            .children()
            .find(|c| c.has_tag_name("DefaultString"))
            .and_then(|c| c.text())
        {
            return DefaultValue::Bytes(Box::leak(s.as_bytes().to_vec().into_boxed_slice()));
        }
        if let Some(b) = text(child(info, "DefaultData")).and_then(|s| parse_hex_bytes(&s)) {
            return DefaultValue::Bytes(Box::leak(b.into_boxed_slice()));
        }
        return DefaultValue::bits(0);
    }
    if let Some(b) = text(child(info, "DefaultData")).and_then(|s| parse_hex_bytes(&s)) {
        let mut a = [0u8; 8];
        let n = b.len().min(8);
        a[..n].copy_from_slice(&b[..n]);
        return DefaultValue::bits(u64::from_le_bytes(a));
    }
    if let Some(v) = text(child(info, "DefaultValue")).and_then(|s| parse_num(&s)) {
        return DefaultValue::bits(v as u64);
    }
    DefaultValue::bits(0)
}

fn entry(sub: u8, name: &str, base: Base, access: Access, pdo: PdoMapping) -> EntryDef {
    let mut e = EntryDef::new(sub, leak(name), base.dtype, access);
    e.bits = base.bits;
    e.pdo = pdo;
    e
}

/// The stack's own objects (served from the definition, not from the ESI's dictionary).
fn stack_owned(index: u16) -> bool {
    matches!(
        index,
        0x1000 | 0x1001 | 0x1008 | 0x1009 | 0x100A | 0x1018 | 0x10F1
    ) || (0x1600..=0x17FF).contains(&index)
        || (0x1A00..=0x1BFF).contains(&index)
        || (0x1C00..=0x1C3F).contains(&index)
}

/// An object of the ESI dictionary as the stack holds it, with the defaults from its
/// `Info`.
fn object(types: &Types, o: Node, index: u16) -> Result<(ObjectDef, Option<String>), String> {
    let name = text(child(o, "Name")).unwrap_or_default();
    let tname = text(child(o, "Type")).unwrap_or_default();
    let ty = types.object_type(&tname)?;
    let (oacc, opdo) = flags(child(o, "Flags"));
    let oacc_or_ro = oacc.unwrap_or(Access::RO);
    let info = child(o, "Info");
    let info_subs: Vec<Node> = info
        .map(|i| children(i, "SubItem").collect())
        .unwrap_or_default();
    let sub_info = |k: usize, sname: &str| -> (Option<Node>, Option<Access>, PdoMapping) {
        let n = info_subs
            .iter()
            .find(|s| text(child(**s, "Name")).as_deref() == Some(sname))
            .or_else(|| info_subs.get(k));
        match n {
            Some(n) => {
                let (a, p) = flags(child(*n, "Flags"));
                (child(*n, "Info"), a, p)
            }
            None => (None, None, PdoMapping::None),
        }
    };
    let (code, entries) = match ty {
        Ty::Scalar(b) => (
            ObjectCode::Var,
            vec![{
                let mut e = entry(0, &name, b, oacc_or_ro, opdo);
                set_default(&mut e, default_of(info, b));
                e
            }],
        ),
        Ty::Array {
            elem,
            elements,
            lbound,
        } => {
            let u8b = Base {
                dtype: DataType::Unsigned8,
                bits: 8,
            };
            let mut v = vec![{
                let mut e = entry(0, "SubIndex 000", u8b, Access::RO, PdoMapping::None);
                set_default(&mut e, DefaultValue::bits(u64::from(elements)));
                e
            }];
            let first = lbound.max(1);
            for k in 0..elements {
                let sub = u8::try_from(first + k).map_err(|_| "subindex above 255".to_string())?;
                let sname = format!("SubIndex {sub:03}");
                let (inf, a, p) = sub_info(k as usize + 1, &sname);
                let mut e = entry(sub, &sname, elem, a.unwrap_or(oacc_or_ro), pdo_or(p, opdo));
                set_default(&mut e, default_of(inf, elem));
                v.push(e);
            }
            (ObjectCode::Array, v)
        }
        Ty::Struct(subs) => {
            let mut v: Vec<EntryDef> = Vec::new();
            for (k, s) in subs.iter().enumerate() {
                let (inf, a, p) = sub_info(k, &s.name);
                let access = a.or(s.access).unwrap_or(oacc_or_ro);
                let mut e = entry(
                    s.sub,
                    &s.name,
                    s.base,
                    access,
                    pdo_or(pdo_or(p, s.pdo), opdo),
                );
                set_default(&mut e, default_of(inf, s.base));
                v.push(e);
            }
            if v.first().is_none_or(|e| e.sub != 0) {
                let mut e = entry(
                    0,
                    "SubIndex 000",
                    Base {
                        dtype: DataType::Unsigned8,
                        bits: 8,
                    },
                    Access::RO,
                    PdoMapping::None,
                );
                set_default(
                    &mut e,
                    DefaultValue::bits(v.last().map_or(0, |e| u64::from(e.sub))),
                );
                v.insert(0, e);
            }
            if v[0].bits != 8 {
                return Err(format!("subindex 0 has {} bits, not 8", v[0].bits));
            }
            // Sub 0 read as UNSIGNED8 whatever the ESI's type name.
            v[0].dtype = DataType::Unsigned8;
            v.sort_by_key(|e| e.sub);
            if v.windows(2).any(|w| w[0].sub == w[1].sub) {
                return Err("two subitems with one subindex".into());
            }
            let code = if subs.len() > 1 && subs.iter().all(|s| s.base == subs[0].base) {
                ObjectCode::Array
            } else {
                ObjectCode::Record
            };
            (code, v)
        }
    };
    let _ = index;
    Ok((
        ObjectDef {
            index,
            name: leak(&name),
            code,
            entries: Box::leak(entries.into_boxed_slice()),
        },
        None,
    ))
}

fn pdo_or(a: PdoMapping, b: PdoMapping) -> PdoMapping {
    if a == PdoMapping::None {
        b
    } else {
        a
    }
}

fn with_mapping(p: PdoMapping, rx: bool) -> PdoMapping {
    match (p, rx) {
        (PdoMapping::None, true) => PdoMapping::Rx,
        (PdoMapping::None, false) => PdoMapping::Tx,
        (PdoMapping::Tx, true) | (PdoMapping::Rx, false) => PdoMapping::RxTx,
        (p, _) => p,
    }
}

/// The CoE type of a PDO entry without a dictionary object: its `DataType`, else by bits.
fn entry_base(data_type: Option<&str>, bits: u8) -> Base {
    if let Some(b) = data_type.and_then(base_type) {
        if b.bits == u16::from(bits) {
            return b;
        }
    }
    use DataType::*;
    let dtype = match bits {
        1 => Bool,
        2..=8 => Unsigned8,
        9..=16 => Unsigned16,
        17..=32 => Unsigned32,
        _ => Unsigned64,
    };
    Base {
        dtype,
        bits: u16::from(bits),
    }
}

// ------------------------------------------------------------------ the device

fn hx(v: u16) -> String {
    format!("0x{v:04X}")
}

fn build_device(esi: &Esi, d: Node, cand: Candidate) -> Result<Twin, TwinError> {
    let m: DeviceModel = crate::esi::device(esi.vendor_id, esi.vendor_name.clone(), d)?;
    let mut left_out = Vec::new();
    let has_mailbox = m.mailbox.is_some();
    let served = if has_mailbox {
        Served::Stack
    } else {
        Served::EscOnly
    };

    if let Some((k, v)) = children(d, "Sm").enumerate().find(|(_, s)| {
        s.attribute("Virtual")
            .is_some_and(|v| v == "true" || v == "1")
    }) {
        return Err(TwinError::Unsupported(format!(
            "SM{k} is virtual (its process data are ESC registers at {}, mapped by an FMMU \
             without a sync manager); twins do not model virtual sync managers",
            v.attribute("StartAddress").unwrap_or("?")
        )));
    }
    // Sync managers: the stack serves SM0/SM1 mailbox, SM2 outputs, SM3 inputs.
    let kinds: Vec<SmKind> = m.sms.iter().map(|s| s.kind).collect();
    if served == Served::Stack {
        check_stack_sms(&kinds, "ESI")?;
        if kinds.len() > 4 {
            left_out.push(format!(
                "sync managers 4..{} (unused by the stack)",
                kinds.len() - 1
            ));
        }
    }
    let pd_sm_ok = |p: &PdoModel, rx: bool| match p.sm {
        None => true,
        Some(s) => m
            .sms
            .get(s as usize)
            .is_some_and(|sm| sm.kind == if rx { SmKind::Outputs } else { SmKind::Inputs }),
    };
    for (list, rx) in [(&m.rx_pdos, true), (&m.tx_pdos, false)] {
        for p in list {
            if !pd_sm_ok(p, rx) {
                return Err(TwinError::Inconsistent(format!(
                    "PDO {} is assigned to SM{}, which is not an {} sync manager",
                    hx(p.index),
                    p.sm.unwrap_or(0),
                    if rx { "Outputs" } else { "Inputs" }
                )));
            }
            if served == Served::Stack && p.sm.is_some_and(|s| s != if rx { 2 } else { 3 }) {
                return Err(TwinError::Unsupported(format!(
                    "PDO {} is assigned to SM{}; the stack serves outputs on SM2 and inputs on SM3",
                    hx(p.index),
                    p.sm.unwrap_or(0)
                )));
            }
            if let Some(e) = p.entries.iter().find(|e| e.bits == 0) {
                return Err(TwinError::Inconsistent(format!(
                    "PDO {} maps {}:{} with 0 bits",
                    hx(p.index),
                    hx(e.index),
                    e.sub
                )));
            }
        }
    }
    // Excluded PDOs must not be assigned together by default.
    for (list, tag) in [(&m.rx_pdos, "RxPdo"), (&m.tx_pdos, "TxPdo")] {
        let excludes = |p: &PdoModel| -> Vec<u16> {
            children(d, tag)
                .find(|n| {
                    text(child(*n, "Index")).and_then(|s| parse_num(&s)) == Some(i64::from(p.index))
                })
                .map(|n| {
                    children(n, "Exclude")
                        .filter_map(|x| text(Some(x)).and_then(|s| parse_num(&s)))
                        .filter_map(|v| u16::try_from(v).ok())
                        .collect()
                })
                .unwrap_or_default()
        };
        for p in list.iter().filter(|p| p.sm.is_some()) {
            for x in excludes(p) {
                if x != p.index && list.iter().any(|q| q.index == x && q.sm.is_some()) {
                    return Err(TwinError::Inconsistent(format!(
                        "PDOs {} and {} exclude each other but are both assigned by default",
                        hx(p.index),
                        hx(x)
                    )));
                }
            }
        }
    }

    // The dictionary.
    let dict = child(d, "Profile").and_then(|p| child(p, "Dictionary"));
    let types = Types::new(dict);
    let mut objects: Vec<ObjectDef> = Vec::new();
    let mut dict_indices: Vec<u16> = Vec::new();
    let mut dropped: Vec<(u16, String)> = Vec::new();
    let mut hw_version = String::new();
    let mut sw_version = String::new();
    let mut device_type = m.profile_no.unwrap_or(0) & 0xFFFF;
    if let Some(objs) = dict.and_then(|d| child(d, "Objects")) {
        for o in children(objs, "Object") {
            let idx = text(child(o, "Index")).unwrap_or_default();
            let index = parse_num(&idx)
                .and_then(|v| u16::try_from(v).ok())
                .ok_or_else(|| crate::Error::BadValue {
                    what: "Object/Index",
                    text: idx.clone(),
                })?;
            dict_indices.push(index);
            let info = child(o, "Info");
            let string_default = |n: Option<Node>| -> String {
                let Some(i) = n else { return String::new() };
                if let Some(s) = text(child(i, "DefaultString")) {
                    return s;
                }
                text(child(i, "DefaultData"))
                    .and_then(|s| parse_hex_bytes(&s))
                    .map(|b| {
                        let end = b.iter().position(|c| *c == 0).unwrap_or(b.len());
                        String::from_utf8_lossy(&b[..end]).into_owned()
                    })
                    .unwrap_or_default()
            };
            match index {
                0x1000 => {
                    if let Some(v) = default_of(
                        info,
                        Base {
                            dtype: DataType::Unsigned32,
                            bits: 32,
                        },
                    )
                    .as_bits()
                    {
                        if v != 0 {
                            device_type = v as u32;
                        }
                    }
                }
                0x1009 => hw_version = string_default(info),
                0x100A => sw_version = string_default(info),
                _ => {}
            }
            if stack_owned(index) {
                continue;
            }
            if objects.iter().any(|x| x.index == index) {
                return Err(TwinError::Inconsistent(format!(
                    "object {} is in the dictionary twice",
                    hx(index)
                )));
            }
            match object(&types, o, index) {
                Ok((od, _)) => objects.push(od),
                Err(e) => dropped.push((index, e)),
            }
        }
    }
    let has_dict = !dict_indices.is_empty();

    // PDOs: entries must agree with the dictionary; objects without one are made from the
    // PDO entries (a device without a dictionary, or one its ESI leaves out).
    let mut made: Vec<(u16, Vec<EntryDef>)> = Vec::new();
    let mut drop_pdos: Vec<u16> = Vec::new();
    for (list, rx) in [(&m.rx_pdos, true), (&m.tx_pdos, false)] {
        for p in list {
            for e in p.entries.iter().filter(|e| e.index != 0) {
                let sync_error = matches!(e.index, 0x1C32 | 0x1C33) && e.sub == 0x20 && e.bits == 1;
                if served == Served::Stack && stack_owned(e.index) && !sync_error {
                    return Err(TwinError::Unsupported(format!(
                        "PDO {} maps {}:{}, an object the stack keeps to itself",
                        hx(p.index),
                        hx(e.index),
                        e.sub
                    )));
                }
                if sync_error && served == Served::Stack {
                    continue;
                }
                if let Some(o) = objects.iter_mut().find(|o| o.index == e.index) {
                    let Some(k) = o.entries.iter().position(|x| x.sub == e.sub) else {
                        return Err(TwinError::Inconsistent(format!(
                            "PDO {} maps {}:{}, which object {} ({}) does not have",
                            hx(p.index),
                            hx(e.index),
                            e.sub,
                            hx(e.index),
                            o.name
                        )));
                    };
                    let en = o.entries[k];
                    if en.bits != u16::from(e.bits) && p.sm.is_none() {
                        // An alternative PDO that maps the entry narrower (Beckhoff's
                        // 16-bit counter PDOs of a 32-bit value): not served.
                        left_out.push(format!(
                            "PDO {} (maps {}:{} with {} bits, the dictionary gives {}; the \
                             stack maps entries whole)",
                            hx(p.index),
                            hx(e.index),
                            e.sub,
                            e.bits,
                            en.bits
                        ));
                        drop_pdos.push(p.index);
                        break;
                    }
                    if en.bits != u16::from(e.bits) {
                        return Err(TwinError::Inconsistent(format!(
                            "inconsistent sizes: PDO {} maps {}:{} with BitLen {}, the \
                             dictionary gives it {} bits",
                            hx(p.index),
                            hx(e.index),
                            e.sub,
                            e.bits,
                            en.bits
                        )));
                    }
                    if !(if rx { en.pdo.rx() } else { en.pdo.tx() }) {
                        let mut v = o.entries.to_vec();
                        v[k].pdo = with_mapping(v[k].pdo, rx);
                        o.entries = Box::leak(v.into_boxed_slice());
                    }
                    continue;
                }
                if let Some((_, why)) = dropped.iter().find(|(i, _)| *i == e.index) {
                    left_out.push(format!(
                        "object {} as the dictionary describes it ({why}); served as its PDO entries",
                        hx(e.index)
                    ));
                    dropped.retain(|(i, _)| *i != e.index);
                }
                let base = entry_base(e.data_type.map(type_name).as_deref(), e.bits);
                let name = e
                    .name
                    .clone()
                    .unwrap_or_else(|| format!("SubIndex {:03}", e.sub));
                let access = if rx { Access::RW } else { Access::RO };
                let en = entry(
                    e.sub,
                    &name,
                    base,
                    access,
                    with_mapping(PdoMapping::None, rx),
                );
                match made.iter_mut().find(|(i, _)| *i == e.index) {
                    Some((_, v)) => match v.iter_mut().find(|x| x.sub == e.sub) {
                        Some(x) if x.bits != en.bits => {
                            return Err(TwinError::Inconsistent(format!(
                                "inconsistent sizes: {}:{} is mapped with {} and with {} bits",
                                hx(e.index),
                                e.sub,
                                x.bits,
                                en.bits
                            )));
                        }
                        Some(x) => x.pdo = with_mapping(x.pdo, rx),
                        None => v.push(en),
                    },
                    None => made.push((e.index, vec![en])),
                }
            }
        }
    }
    if has_dict && !made.is_empty() {
        left_out.push(format!(
            "objects {} mapped in PDOs but missing from the dictionary: made from the PDO entries",
            made.iter()
                .map(|(i, _)| hx(*i))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    for (index, mut v) in made {
        v.sort_by_key(|e| e.sub);
        let code = if v.len() == 1 && v[0].sub == 0 {
            ObjectCode::Var
        } else {
            if v[0].sub != 0 {
                let mut e0 = EntryDef::new(0, "SubIndex 000", DataType::Unsigned8, Access::RO);
                set_default(
                    &mut e0,
                    DefaultValue::bits(v.last().map_or(0, |e| u64::from(e.sub))),
                );
                v.insert(0, e0);
            } else if v[0].bits != 8 {
                return Err(TwinError::Unsupported(format!(
                    "{}:0 is mapped with {} bits next to other subindices (subindex 0 of a record is 8 bits)",
                    hx(index),
                    v[0].bits
                )));
            }
            ObjectCode::Record
        };
        let name = m
            .rx_pdos
            .iter()
            .chain(&m.tx_pdos)
            .find(|p| p.entries.iter().any(|e| e.index == index))
            .and_then(|p| p.name.clone())
            .unwrap_or_default();
        objects.push(ObjectDef {
            index,
            name: leak(&name),
            code,
            entries: Box::leak(v.into_boxed_slice()),
        });
    }
    for (index, why) in &dropped {
        left_out.push(format!("object {} ({why})", hx(*index)));
    }
    let served_elsewhere: Vec<u16> = dict_indices
        .iter()
        .copied()
        .filter(|i| {
            stack_owned(*i)
                && !matches!(
                    i,
                    0x1000
                        | 0x1001
                        | 0x1008
                        | 0x1009
                        | 0x100A
                        | 0x1018
                        | 0x10F1
                        | 0x1C00
                        | 0x1C12
                        | 0x1C13
                        | 0x1C32
                        | 0x1C33
                )
                && !(0x1600..=0x17FF).contains(i)
                && !(0x1A00..=0x1BFF).contains(i)
        })
        .collect();
    if !served_elsewhere.is_empty() {
        left_out.push(format!(
            "objects {} (the stack serves its own SM objects 0x1C00/0x1C12/0x1C13/0x1C32/0x1C33 only)",
            served_elsewhere.iter().map(|i| hx(*i)).collect::<Vec<_>>().join(", ")
        ));
    }
    objects.sort_by_key(|o| o.index);

    // PDO definitions; the stack holds at most MAX_PDOS per direction.
    let mut pdo_defs =
        |list: &[PdoModel], rx: bool| -> Result<(Vec<PdoDef>, Vec<u16>), TwinError> {
            let assign: Vec<u16> = list
                .iter()
                .filter(|p| p.sm.is_some())
                .map(|p| p.index)
                .collect();
            let mut keep: Vec<&PdoModel> = list.iter().filter(|p| p.sm.is_some()).collect();
            for p in list
                .iter()
                .filter(|p| p.sm.is_none() && !drop_pdos.contains(&p.index))
            {
                if served == Served::EscOnly || keep.len() < MAX_PDOS {
                    keep.push(p);
                } else {
                    left_out.push(format!(
                        "PDO {} (the stack holds {MAX_PDOS} {} PDOs; the default ones are served)",
                        hx(p.index),
                        if rx { "Rx" } else { "Tx" }
                    ));
                }
            }
            let mut defs = Vec::new();
            for p in keep {
                if served == Served::Stack {
                    let range = if rx { 0x1600..=0x17FF } else { 0x1A00..=0x1BFF };
                    if !range.contains(&p.index) {
                        return Err(TwinError::Unsupported(format!(
                            "PDO index {} is outside {:#06X}..{:#06X}",
                            hx(p.index),
                            range.start(),
                            range.end()
                        )));
                    }
                    if p.entries.len() > MAX_PDO_ENTRIES {
                        return Err(TwinError::Unsupported(format!(
                            "PDO {} has {} entries; the stack maps at most {MAX_PDO_ENTRIES}",
                            hx(p.index),
                            p.entries.len()
                        )));
                    }
                }
                let entries: Vec<PdoEntry> = p
                    .entries
                    .iter()
                    .map(|e| PdoEntry::new(e.index, if e.index == 0 { 0 } else { e.sub }, e.bits))
                    .collect();
                defs.push(PdoDef {
                    index: p.index,
                    name: leak(p.name.as_deref().unwrap_or("")),
                    entries: Box::leak(entries.into_boxed_slice()),
                    configurable: !p.fixed,
                });
            }
            defs.sort_by_key(|p| p.index);
            if defs.windows(2).any(|w| w[0].index == w[1].index) {
                return Err(TwinError::Inconsistent(format!(
                    "a {} PDO index is listed twice",
                    if rx { "Rx" } else { "Tx" }
                )));
            }
            if served == Served::Stack && (assign.len() > MAX_ASSIGN || defs.len() > MAX_PDOS) {
                return Err(TwinError::Unsupported(format!(
                    "{} {} PDOs assigned by default; the stack assigns at most {MAX_ASSIGN}",
                    assign.len(),
                    if rx { "Rx" } else { "Tx" }
                )));
            }
            Ok((defs, assign))
        };
    let (rx_pdos, rx_assign) = pdo_defs(&m.rx_pdos, true)?;
    let (tx_pdos, tx_assign) = pdo_defs(&m.tx_pdos, false)?;
    let bits_of = |defs: &[PdoDef], assign: &[u16]| -> (u32, usize) {
        let mut bits = 0u32;
        let mut n = 0;
        for a in assign {
            if let Some(p) = defs.iter().find(|p| p.index == *a) {
                bits += p.entries.iter().map(|e| u32::from(e.bits)).sum::<u32>();
                n += p.entries.len();
            }
        }
        (bits, n)
    };
    let (out_bits, out_n) = bits_of(&rx_pdos, &rx_assign);
    let (in_bits, in_n) = bits_of(&tx_pdos, &tx_assign);
    if served == Served::Stack {
        for (bits, n, what) in [(out_bits, out_n, "output"), (in_bits, in_n, "input")] {
            if bits.div_ceil(8) as usize > MAX_PD_BYTES || n > MAX_ITEMS {
                return Err(TwinError::Unsupported(format!(
                    "{} bytes of {what} process data in {n} entries; the stack maps at most \
                     {MAX_PD_BYTES} bytes in {MAX_ITEMS} entries",
                    bits.div_ceil(8)
                )));
            }
        }
    }

    // Sync managers of the SII: the ESI's, process-data sizes from the default PDOs.
    let mut sms = Vec::new();
    let mut pdo_sm = Vec::new();
    for (k, s) in m.sms.iter().enumerate() {
        let k8 = k as u8;
        let pd_bits = |list: &[PdoModel]| -> u32 {
            list.iter()
                .filter(|p| p.sm == Some(k8))
                .flat_map(|p| p.entries.iter())
                .map(|e| u32::from(e.bits))
                .sum()
        };
        let (length, sm_type) = match s.kind {
            SmKind::MBoxOut => (s.default_size.unwrap_or(0), SmType::MailboxOut),
            SmKind::MBoxIn => (s.default_size.unwrap_or(0), SmType::MailboxIn),
            SmKind::Outputs => (pd_bits(&m.rx_pdos).div_ceil(8) as u16, SmType::Outputs),
            SmKind::Inputs => (pd_bits(&m.tx_pdos).div_ceil(8) as u16, SmType::Inputs),
            SmKind::Other => (s.default_size.unwrap_or(0), SmType::Unused),
        };
        if matches!(s.kind, SmKind::Outputs | SmKind::Inputs) {
            if let Some(ds) = s.default_size.filter(|&ds| ds != 0 && ds != length) {
                left_out.push(format!(
                    "SM{k} DefaultSize {ds} bytes: sized {length} from its default PDOs"
                ));
            }
        }
        if matches!(s.kind, SmKind::MBoxOut | SmKind::MBoxIn)
            && !(16..=MAX_MAILBOX).contains(&length)
        {
            return Err(TwinError::Unsupported(format!(
                "SM{k} mailbox of {length} bytes; a twin serves 16..{MAX_MAILBOX}"
            )));
        }
        let pd = matches!(s.kind, SmKind::Outputs | SmKind::Inputs);
        sms.push(SiiSyncManager {
            start: s.start,
            length,
            control: s.control,
            status: 0,
            enable: u8::from(s.enable && (!pd || length > 0)),
            sm_type,
        });
    }
    for p in m.rx_pdos.iter().chain(&m.tx_pdos) {
        if let Some(s) = p.sm {
            pdo_sm.push((p.index, s));
        }
    }
    let end = sms
        .iter()
        .map(|s| u32::from(s.start) + u32::from(s.length))
        .max()
        .unwrap_or(0x1000);

    // ESC.
    let ctl = child(d, "Info").and_then(|i| child(i, "EtherCATController"));
    let ctl_num = |n: &str| {
        ctl.and_then(|c| text(child(c, n)))
            .and_then(|s| parse_num(&s))
            .and_then(|v| u32::try_from(v).ok())
    };
    let need_kib = end.saturating_sub(0x1000).div_ceil(1024).max(1);
    let ram_kib = ctl_num("DpramSize")
        .map(|b| b / 1024)
        .unwrap_or(8)
        .max(need_kib);
    if ram_kib > 60
        || u32::from(m.sms.iter().map(|s| s.start).max().unwrap_or(0)) + 1 > 0x1000 + 60 * 1024
    {
        return Err(TwinError::Unsupported(format!(
            "sync managers up to {end:#06x} need {ram_kib} KiB of process RAM; an ESC has at most 60"
        )));
    }
    let physics = d.attribute("Physics").unwrap_or("YY");
    let mut port_descriptor = 0u8;
    for (p, c) in physics.chars().take(4).enumerate() {
        let t = match c {
            'Y' | 'H' => 3,
            'K' => 2,
            _ => 0,
        };
        port_descriptor |= t << (2 * p);
    }
    for p in 0..2 {
        if (port_descriptor >> (2 * p)) & 3 < 2 {
            port_descriptor |= 3 << (2 * p);
        }
    }
    let esc = EscSpec {
        // A master maps each process-data SM with an FMMU of its own (ethercrab does).
        fmmu_count: ctl_num("FmmuCount")
            .map_or(
                m.fmmus.len().max(3).max(
                    sms.iter()
                        .filter(|s| matches!(s.sm_type, SmType::Outputs | SmType::Inputs))
                        .count(),
                ) as u32,
                |v| v,
            )
            .clamp(1, 16) as u8,
        sm_count: ctl_num("SmCount")
            .map_or(m.sms.len().max(4) as u32, |v| v)
            .clamp(m.sms.len().max(1) as u32, 16) as u8,
        ram_kib: ram_kib as u8,
        port_descriptor,
        from_esi: ctl.is_some(),
    };

    // ESC configuration area from ConfigData; a device without a mailbox is the ESC alone
    // and needs its device emulation.
    let cfg = m
        .eeprom
        .as_ref()
        .map(|e| e.config_data.clone())
        .unwrap_or_default();
    let w = |k: usize| {
        u16::from_le_bytes([
            cfg.get(2 * k).copied().unwrap_or(0),
            cfg.get(2 * k + 1).copied().unwrap_or(0),
        ])
    };
    let mut esc_area = EscConfigArea {
        pdi_control: w(0),
        pdi_config: w(1),
        sync_impulse_len: w(2),
        pdi_config2: w(3),
        station_alias: w(4),
    };
    if served == Served::EscOnly && esc_area.pdi_control & 0x0100 == 0 {
        esc_area.pdi_control |= 0x0100;
        left_out.push(
            "ConfigData without device emulation: set (no firmware answers AL control)".into(),
        );
    }
    if served == Served::Stack && esc_area.pdi_control & 0x0100 != 0 {
        esc_area.pdi_control &= !0x0100;
        left_out
            .push("ConfigData's device emulation: cleared (the stack answers AL control)".into());
    }

    let fmmus: Vec<FmmuUsage> = m
        .fmmus
        .iter()
        .map(|f| match f {
            FmmuKind::Outputs => FmmuUsage::Outputs,
            FmmuKind::Inputs => FmmuUsage::Inputs,
            FmmuKind::MBoxState => FmmuUsage::SyncManagerStatus,
            FmmuKind::Other => FmmuUsage::Unused,
        })
        .collect();

    // DC op modes.
    let mut dc_modes = Vec::new();
    let mut supported = SyncMode::FreeRun.support_bit() | SyncMode::SmSync.support_bit();
    for dcm in &m.dc {
        let a = dcm.assign_activate;
        if a & 0x0300 == 0x0300 {
            supported |= SyncMode::DcSync0.support_bit();
        }
        if a & 0x0700 == 0x0700 {
            supported |= SyncMode::DcSync1.support_bit();
        }
        dc_modes.push(DcOpMode {
            name: leak(dcm.name.as_deref().unwrap_or("")),
            desc: leak(dcm.desc.as_deref().unwrap_or("")),
            assign_activate: a,
            cycle_sync0: dcm.cycle0,
            sync0_factor: dcm.sync0_factor,
            shift_sync0: dcm.shift0 as u32,
            sync1_factor: dcm.sync1_factor,
            shift_sync1: dcm.shift1 as u32,
        });
    }

    let mbx = m.mailbox.unwrap_or_default();
    if mbx.eoe || mbx.foe || mbx.soe || child(d, "Mailbox").and_then(|x| child(x, "AoE")).is_some()
    {
        left_out.push(
            "mailbox protocols other than CoE (EoE/FoE/SoE/AoE): not served and not announced in the SII"
                .into(),
        );
    }
    let coe = match mbx.coe {
        Some(c) => CoeInfo {
            enabled: true,
            sdo_info: c.sdo_info,
            complete_access: c.complete_access,
            pdo_upload: c.pdo_upload,
            segmented_sdo: true,
        },
        None => CoeInfo {
            enabled: false,
            sdo_info: false,
            complete_access: false,
            pdo_upload: false,
            segmented_sdo: false,
        },
    };
    if m.eeprom.as_ref().is_some_and(|e| e.bootstrap.is_some()) {
        left_out.push("BOOT (bootstrap mailbox, firmware update)".into());
    }
    let mailbox = if served == Served::Stack {
        MailboxDef {
            rx_start: m.sms[0].start,
            rx_len: sms[0].length,
            tx_start: m.sms[1].start,
            tx_len: sms[1].length,
        }
    } else {
        MailboxDef::STANDARD
    };
    let sm_control = SmControl {
        mbx_out: m.sms.first().map_or(0x26, |s| s.control),
        mbx_in: m.sms.get(1).map_or(0x22, |s| s.control),
        outputs: m.sms.get(2).map_or(0x64, |s| s.control),
        inputs: m.sms.get(3).map_or(0x20, |s| s.control),
    };
    let size_range = child(d, "Sm").and_then(|s| {
        let g = |a| {
            s.attribute(a)
                .and_then(parse_num)
                .and_then(|v| u16::try_from(v).ok())
        };
        Some((g("MinSize")?, g("MaxSize")?))
    });
    let group_type = m.group_type.clone().unwrap_or_default();
    let group_name = child(esi.root, "Descriptions")
        .and_then(|x| child(x, "Groups"))
        .and_then(|g| {
            children(g, "Group").find(|g| text(child(*g, "Type")).as_deref() == Some(&group_type))
        })
        .and_then(name_of)
        .unwrap_or_default();
    let fit = |s: &str, what: &str, left_out: &mut Vec<String>| -> &'static str {
        if s.len() <= 64 {
            return leak(s);
        }
        let mut n = 64;
        while !s.is_char_boundary(n) {
            n -= 1;
        }
        left_out.push(format!(
            "{what} beyond 64 bytes (the stack's 0x1008/0x1009/0x100A)"
        ));
        leak(&s[..n])
    };
    let name = fit(&cand.name, "the name", &mut left_out);
    let hw = fit(&hw_version, "the hardware version", &mut left_out);
    let sw = fit(&sw_version, "the software version", &mut left_out);
    let eeprom_bytes = m
        .eeprom
        .as_ref()
        .map_or(2048, |e| e.byte_size)
        .max(256)
        .next_power_of_two();
    let ebus = child(d, "Info")
        .and_then(|i| child(i, "Electrical"))
        .and_then(|e| text(child(e, "EBusCurrent")))
        .and_then(|s| parse_num(&s))
        .and_then(|v| i16::try_from(v).ok())
        .unwrap_or(0);

    let image_bytes = image_size(&objects);
    if served == Served::Stack && image_bytes > MAX_IMAGE {
        return Err(TwinError::Unsupported(format!(
            "the object dictionary needs {image_bytes} bytes; a twin holds at most {MAX_IMAGE}"
        )));
    }
    let mut def = DeviceDef {
        identity: Identity {
            vendor_id: m.vendor_id,
            product_code: m.product_code,
            revision: m.revision,
            serial: 0,
        },
        device_type,
        name,
        hw_version: hw,
        sw_version: sw,
        mailbox,
        boot_mailbox: None,
        sm2_start: m.sms.get(2).map_or(0x1100, |s| s.start),
        sm3_start: m.sms.get(3).map_or(0x1180, |s| s.start),
        objects: Box::leak(objects.into_boxed_slice()),
        rx_pdos: Box::leak(rx_pdos.into_boxed_slice()),
        tx_pdos: Box::leak(tx_pdos.into_boxed_slice()),
        rx_assign: Box::leak(rx_assign.into_boxed_slice()),
        tx_assign: Box::leak(tx_assign.into_boxed_slice()),
        assign_configurable: mbx.coe.is_some_and(|c| c.pdo_assign),
        sync: SyncDef {
            supported,
            default_mode: SyncMode::FreeRun,
            min_cycle_ns: 100_000,
            calc_copy_ns: 0,
        },
        info: Some(Box::leak(Box::new(DeviceInfo {
            vendor_name: leak(esi.vendor_name.as_deref().unwrap_or("")),
            group: Group {
                type_name: leak(&group_type),
                name: leak(&group_name),
            },
            order_code: leak(&cand.type_name),
            description: None,
            image: None,
            physics: leak(physics),
            esc: esc_area,
            eeprom_bytes,
            sii_version: 1,
            fmmus: Box::leak(fmmus.into_boxed_slice()),
            sm_control,
            mailbox_size_range: size_range,
            coe,
            foe: false,
            eoe: false,
            dc_modes: Box::leak(dc_modes.into_boxed_slice()),
            ebus_current_ma: ebus,
            timeouts: m.timeouts,
        }))),
    };
    let layout = SmLayout {
        sms,
        pdo_sm,
        mailbox: has_mailbox,
    };
    // The ESI's EEPROM size, or the next that holds the generated categories.
    let sii = loop {
        match crate::sii::generate_with(&def, Some(&layout)) {
            Ok(s) => break s,
            Err(crate::Error::DoesNotFit(_)) if def.info().eeprom_bytes < 65536 => {
                let info = DeviceInfo {
                    eeprom_bytes: def.info().eeprom_bytes * 2,
                    ..*def.info()
                };
                def.info = Some(Box::leak(Box::new(info)));
            }
            Err(e) => return Err(TwinError::Esi(e)),
        }
    };
    if def.info().eeprom_bytes != eeprom_bytes {
        left_out.push(format!(
            "EEPROM size {eeprom_bytes} bytes: the generated SII needs {}",
            def.info().eeprom_bytes
        ));
    }
    let def: &'static DeviceDef = Box::leak(Box::new(def));
    if served == Served::Stack {
        oxicat_slave::od::check_def(def, MAX_IMAGE)
            .map_err(|e| TwinError::Unsupported(format!("the slave stack refuses it: {e}")))?;
    }

    let loopback = if served == Served::Stack {
        loopback_of(def)
    } else {
        Vec::new()
    };
    Ok(Twin {
        candidate: cand,
        def,
        sii,
        esc,
        served,
        image_bytes,
        mailbox_bytes: if served == Served::Stack {
            mailbox.rx_len.max(mailbox.tx_len)
        } else {
            0
        },
        loopback,
        left_out,
        profile_no: m.profile_no,
    })
}

/// The sync managers of a twin the slave stack serves, in the order it serves them: SM0
/// mailbox out, SM1 mailbox in, then SM2 outputs and SM3 inputs where there are any
/// (`source` names where `kinds` came from, for the refusal).
pub(crate) fn check_stack_sms(kinds: &[SmKind], source: &str) -> Result<(), TwinError> {
    let want = [
        SmKind::MBoxOut,
        SmKind::MBoxIn,
        SmKind::Outputs,
        SmKind::Inputs,
    ];
    if kinds.len() < 2 || kinds.iter().zip(want).any(|(k, w)| *k != w) {
        return Err(TwinError::Unsupported(format!(
            "the slave stack serves SM0 MBoxOut, SM1 MBoxIn, SM2 Outputs, SM3 Inputs; the \
             {source} has {kinds:?}"
        )));
    }
    Ok(())
}

/// The loop-back of a stack twin's default mapping ([`loop_pairs`] of its assigned PDOs).
pub(crate) fn loopback_of(def: &DeviceDef) -> Vec<(PdoEntry, PdoEntry)> {
    let mapped = |defs: &[PdoDef], assign: &[u16]| -> Vec<PdoEntry> {
        assign
            .iter()
            .filter_map(|a| defs.iter().find(|p| p.index == *a))
            .flat_map(|p| p.entries.iter().copied())
            .collect()
    };
    loop_pairs(
        def,
        &mapped(def.rx_pdos, def.rx_assign),
        &mapped(def.tx_pdos, def.tx_assign),
    )
}

/// The loop-back pairs of a mapping: the k-th mapped output entry to the k-th mapped input
/// entry (gaps skipped) where both have the same bit length and neither is a string. The
/// twin's default for digital I/O, where outputs and inputs pair up.
pub fn loop_pairs(
    def: &DeviceDef,
    outputs: &[PdoEntry],
    inputs: &[PdoEntry],
) -> Vec<(PdoEntry, PdoEntry)> {
    let scalar = |e: &PdoEntry| {
        def.entry_def(e.index, e.sub)
            .is_some_and(|d| !d.dtype.is_string())
    };
    outputs
        .iter()
        .filter(|e| e.index != 0)
        .zip(inputs.iter().filter(|e| e.index != 0))
        .filter(|(o, i)| o.bits == i.bits && scalar(o) && scalar(i))
        .map(|(o, i)| (*o, *i))
        .collect()
}

/// The ESI type name of a CoE data type code (for PDO entries without a dictionary).
fn type_name(code: u16) -> String {
    oxicat_wire::datatype::by_code(code).map_or_else(String::new, |d| d.name.to_string())
}

mod from_sii;
pub use from_sii::{from_sii, SavedEntry, SavedObject};

#[cfg(test)]
mod tests;
