//! The TUeES030: definition, generated ESI and generated SII agree.

use oxicat_devices::tue_es030::device;
use oxicat_esi::{check, esi, sii};

#[test]
fn tue_es030_definition_esi_and_sii_agree() {
    let f = check(&device::DEF).unwrap();
    assert!(f.is_empty(), "{f:#?}");
    let xml = esi::generate(&device::DEF).unwrap();
    assert!(xml.contains("#x1601") && xml.contains("#x1a01") || xml.contains("#x1A01"));
    let img = sii::generate(&device::DEF).unwrap();
    assert!(img.len() >= 128);
}
