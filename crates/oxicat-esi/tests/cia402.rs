//! The CiA402 joint drive: definition, generated ESI and generated SII agree; the profile
//! objects and the default PDOs are where ETG.6010 puts them.

use oxicat_devices::cia402::device;
use oxicat_esi::{check, esi, sii};

#[test]
fn cia402_definition_esi_and_sii_agree() {
    let f = check(&device::DEF).unwrap();
    assert!(f.is_empty(), "{f:#?}");
    assert_eq!(device::DEF.device_type, 0x0002_0192);
    let xml = esi::generate(&device::DEF).unwrap();
    for idx in [
        "#x6040", "#x6041", "#x6060", "#x6061", "#x6502", "#x1600", "#x1a00",
    ] {
        assert!(
            xml.to_lowercase().contains(idx),
            "{idx} missing from the ESI"
        );
    }
    let img = sii::generate(&device::DEF).unwrap();
    assert!(img.len() >= 128);
    // 2 + 1 + 4 + 4 + 2 out, 2 + 1 + 4 + 4 + 2 + 2 in (sizes derived from the entries).
    assert_eq!(device::DEF.default_output_bits(), 8 * 13);
    assert_eq!(device::DEF.default_input_bits(), 8 * 15);
    assert_eq!((device::OUTPUT_BYTES, device::INPUT_BYTES), (13, 15));
}

#[test]
fn esi_profile_number_is_the_low_word_of_0x1000_and_check_compares_it() {
    let def = &oxicat_devices::cia402::DEF;
    let xml = oxicat_esi::esi::generate(def).unwrap();
    let esi = &oxicat_esi::esi::parse(&xml).unwrap()[0];
    assert_eq!(def.device_type & 0xFFFF, 402);
    assert_eq!(esi.profile_no, Some(402));
    // An ESI that says 5001 for a drive whose 0x1000 says 402 is a finding.
    let wrong = xml.replace("<ProfileNo>402</ProfileNo>", "<ProfileNo>5001</ProfileNo>");
    assert_ne!(wrong, xml);
    let esi = &oxicat_esi::esi::parse(&wrong).unwrap()[0];
    let f = oxicat_esi::model::compare(&oxicat_esi::model::from_def(def), esi);
    assert!(
        f.iter().any(|f| matches!(
            f,
            oxicat_esi::model::Finding::Identity {
                field: "profile_no",
                left: 402,
                right: 5001
            }
        )),
        "{f:#?}"
    );
}
