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

/// A definition whose 0x1000 names another profile than its dictionary implements is
/// refused by the check, with a message that says which and why: the joint with 0x1000 =
/// 5001 (what its ESI used to say), and the hub (a modular device) with 0x1000 = 402.
#[test]
fn check_refuses_a_definition_whose_0x1000_disagrees_with_its_dictionary() {
    let mut joint = oxicat_devices::cia402::DEF;
    joint.device_type = 0x0000_1389;
    let joint: &'static _ = Box::leak(Box::new(joint));
    let f = oxicat_esi::check(joint).unwrap();
    let (pair, finding) = f
        .iter()
        .find(|(_, f)| matches!(f, oxicat_esi::Finding::Profile { .. }))
        .unwrap_or_else(|| panic!("no profile finding: {f:#?}"));
    assert_eq!(*pair, oxicat_esi::Pair::Def);
    assert!(matches!(
        finding,
        oxicat_esi::Finding::Profile {
            stated: 5001,
            implied: 402,
            ..
        }
    ));
    let msg = finding.to_string();
    for part in ["5001", "402", "0x6040", "CiA402 drive", "ProfileNo"] {
        assert!(msg.contains(part), "{part} missing from: {msg}");
    }

    let mut hub = oxicat_devices::axis_hub::device::DEF;
    hub.device_type = 0x0002_0192;
    let hub: &'static _ = Box::leak(Box::new(hub));
    let f = oxicat_esi::check(hub).unwrap();
    assert!(
        f.iter().any(|(p, f)| *p == oxicat_esi::Pair::Def
            && matches!(
                f,
                oxicat_esi::Finding::Profile {
                    stated: 402,
                    implied: 5001,
                    ..
                }
            )),
        "{f:#?}"
    );
    // The registered devices agree.
    for def in [
        &oxicat_devices::cia402::DEF,
        &oxicat_devices::axis_hub::device::DEF,
    ] {
        assert!(oxicat_esi::profile_check(def).is_empty());
    }
}

/// An ESI whose ProfileNo disagrees with its own 0x1000 default is found on its own.
#[test]
fn an_esi_whose_profile_no_disagrees_with_its_0x1000_is_found() {
    let xml = oxicat_esi::esi::generate(&oxicat_devices::cia402::DEF).unwrap();
    let m = &oxicat_esi::esi::parse(&xml).unwrap()[0];
    assert_eq!(m.device_type, Some(0x0002_0192), "0x1000 read from the ESI");
    assert!(oxicat_esi::model::self_check(m).is_empty());
    let wrong = xml.replace("<ProfileNo>402</ProfileNo>", "<ProfileNo>5001</ProfileNo>");
    let m = &oxicat_esi::esi::parse(&wrong).unwrap()[0];
    let f = oxicat_esi::model::self_check(m);
    assert!(
        matches!(
            f.as_slice(),
            [oxicat_esi::Finding::Profile {
                stated: 5001,
                implied: 402,
                ..
            }]
        ),
        "{f:#?}"
    );
}
