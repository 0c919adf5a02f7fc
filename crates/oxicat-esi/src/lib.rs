//! `oxicat-esi`: device description tooling around the one static
//! [`oxicat_slave::DeviceDef`] of a device.
//!
//! - [`esi::generate`]: definition → ESI XML (ETG.2000 `EtherCATInfo`),
//! - [`sii::generate`]: definition → SII EEPROM image (ETG.2010, built with
//!   `oxicat_wire::sii`),
//! - [`esi::parse`] / [`sii::parse`]: ESI XML / SII image → a comparable [`DeviceModel`],
//! - [`model::from_def`] and [`check`]: the definition, its ESI and its SII compared field
//!   by field; differences are typed [`Finding`]s,
//! - [`od::table`]: the object dictionary as the stack serves it, as a text table,
//! - [`fwimage::build`]: a firmware image (header + payload) for the FoE update flow,
//! - [`eni::parse`] / [`eni::resolve`]: an ENI (EtherCATConfig) → its slaves, each found in
//!   ESI files by identity,
//! - [`twin::from_sii`]: a slave recorded by a master (SII image, dictionary) → a twin,
//! - [`twin::build`]: a vendor's ESI device → a runtime definition + SII image + ESC
//!   description that the one slave stack serves as a virtual twin.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod eni;
pub mod esi;
pub mod fwimage;
pub mod model;
pub mod od;
pub mod sii;
pub mod twin;

pub use model::{compare, DeviceModel, Finding};

use oxicat_slave::DeviceDef;

/// Errors of the generators and parsers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// The XML is not well-formed.
    Xml(String),
    /// A required ESI element or attribute is missing.
    Missing(&'static str),
    /// An ESI value does not parse as a number / boolean.
    BadValue {
        /// Element or attribute.
        what: &'static str,
        /// The text found.
        text: String,
    },
    /// The SII image is malformed.
    Sii(oxicat_wire::WireError),
    /// The definition does not fit the SII (too many strings, image too small…).
    DoesNotFit(&'static str),
    /// The definition is rejected by the stack's object dictionary.
    Definition(String),
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Xml(e) => write!(f, "XML not well-formed: {e}"),
            Error::Missing(w) => write!(f, "missing ESI element/attribute {w}"),
            Error::BadValue { what, text } => write!(f, "bad value {text:?} for {what}"),
            Error::Sii(e) => write!(f, "malformed SII: {e}"),
            Error::DoesNotFit(w) => write!(f, "definition does not fit the SII: {w}"),
            Error::Definition(e) => write!(f, "definition rejected: {e}"),
        }
    }
}

impl std::error::Error for Error {}

impl From<oxicat_wire::WireError> for Error {
    fn from(e: oxicat_wire::WireError) -> Self {
        Error::Sii(e)
    }
}

/// Three-way consistency check of a definition, its generated ESI and its generated SII:
/// definition vs ESI, definition vs SII, ESI vs SII (each finding tagged with the pair).
pub fn check(def: &'static DeviceDef) -> Result<Vec<(Pair, Finding)>, Error> {
    let d = model::from_def(def);
    let e = esi::parse(&esi::generate(def)?)?
        .into_iter()
        .next()
        .ok_or(Error::Missing("Device"))?;
    let s = sii::parse(&sii::generate(def)?)?;
    let mut out = Vec::new();
    out.extend(profile_check(def).into_iter().map(|f| (Pair::Def, f)));
    out.extend(model::self_check(&e).into_iter().map(|f| (Pair::Esi, f)));
    out.extend(compare(&d, &e).into_iter().map(|f| (Pair::DefEsi, f)));
    out.extend(compare(&d, &s).into_iter().map(|f| (Pair::DefSii, f)));
    out.extend(compare(&e, &s).into_iter().map(|f| (Pair::EsiSii, f)));
    Ok(out)
}

/// The definition's profile number (the low word of 0x1000, which the ESI's
/// `Profile/ProfileNo` repeats) against the profile its dictionary implements: the
/// controlword 0x6040 and statusword 0x6041 make a CiA402 drive (402), the object 0xF000 a
/// modular device (5001; a dictionary with both is not judged). A drive whose 0x1000 says
/// 5001 gets no drive tab in a configuration tool, and a non-drive that says 402 gets one.
pub fn profile_check(def: &DeviceDef) -> Vec<Finding> {
    let p = def.device_type & 0xFFFF;
    let drive = def.object(0x6040).is_some() && def.object(0x6041).is_some();
    let modular = def.object(0xF000).is_some();
    let mut f = Vec::new();
    let stated_by = "the low word of 0x1000 (and so the ESI's Profile/ProfileNo)";
    if drive && !modular && p != 402 {
        f.push(Finding::Profile {
            stated: p,
            stated_by,
            implied: 402,
            implied_by: "the dictionary's 0x6040 controlword and 0x6041 statusword",
        });
    } else if modular && !drive && p != 5001 {
        f.push(Finding::Profile {
            stated: p,
            stated_by,
            implied: 5001,
            implied_by: "the dictionary's 0xF000 modular device profile object",
        });
    } else if p == 402 && !drive {
        f.push(Finding::Profile {
            stated: p,
            stated_by,
            implied: 0,
            implied_by: "a dictionary without the 0x6040 controlword and 0x6041 statusword",
        });
    }
    f
}

/// Which two descriptions a [`Finding`] of [`check`] compares (left, right), or the one
/// that disagrees with itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pair {
    /// The definition on its own (its 0x1000 against its dictionary).
    Def,
    /// The generated ESI on its own (its `ProfileNo` against its 0x1000).
    Esi,
    /// Definition vs generated ESI.
    DefEsi,
    /// Definition vs generated SII.
    DefSii,
    /// Generated ESI vs generated SII.
    EsiSii,
}
