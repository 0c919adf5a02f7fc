//! The CiA402 joint drive: definition, generated ESI and generated SII agree; the profile
//! objects and the default PDOs are where ETG.6010 puts them.

use oxicat_device::{check, esi, sii};
use oxicat_devices::cia402::device;

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
    assert_eq!(
        device::DEF.default_output_bits(),
        8 * device::OUTPUT_BYTES as u32
    );
    assert_eq!(
        device::DEF.default_input_bits(),
        8 * device::INPUT_BYTES as u32
    );
}
