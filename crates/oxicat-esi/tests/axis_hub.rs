//! The axis hub's definition generates an ESI and an SII that check clean against it.

use oxicat_devices::axis_hub::device::DEF;

#[test]
fn axis_hub_esi_and_sii_generate_and_check_clean() {
    let esi = oxicat_esi::esi::generate(&DEF).expect("ESI");
    assert!(esi.contains("AxisCommBoard slave"));
    assert!(esi.contains("#x1A00") && esi.contains("#x1600"));
    let sii = oxicat_esi::sii::generate(&DEF).expect("SII");
    assert!(!sii.is_empty());
    let findings = oxicat_esi::check(&DEF).expect("check runs");
    assert!(findings.is_empty(), "{findings:?}");
}
