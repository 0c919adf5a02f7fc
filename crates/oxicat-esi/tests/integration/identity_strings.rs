//! The strings a master shows for a device agree everywhere, for every seed device:
//! 0x1008/0x1009/0x100A as the object dictionary serves them, the ESI and the SII, and the
//! SII's general category points where Beckhoff's images point (string 1 = type / order
//! code, which SOEM takes as the slave's name; name index = the device name, which IgH
//! shows).

use oxicat_esi::{check, sii, Pair};
use oxicat_slave::{DeviceDef, Od};
use oxicat_wire::sii::SiiImage;

fn seed_devices() -> Vec<&'static DeviceDef> {
    vec![
        &oxicat_devices::demo::DEF,
        &oxicat_devices::demo::additions::DEF,
        &oxicat_devices::laelaps::device::LEFT,
        &oxicat_devices::laelaps::device::RIGHT,
        &oxicat_devices::tue_es030::device::DEF,
        &oxicat_devices::axis_hub::device::DEF,
        &oxicat_devices::cia402::DEF,
    ]
}

fn served_string(od: &Od<4096>, index: u16) -> String {
    let b = od.bytes(index, 0).expect("object exists");
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8(b[..end].to_vec()).expect("UTF-8")
}

#[test]
fn od_serves_the_whole_identity_strings() {
    for def in seed_devices() {
        let od = Od::<4096>::new(def).expect("definition accepted");
        assert_eq!(
            served_string(&od, 0x1008),
            def.name,
            "0x1008 of {}",
            def.name
        );
        assert_eq!(
            served_string(&od, 0x1009),
            def.hw_version,
            "0x1009 of {}",
            def.name
        );
        assert_eq!(
            served_string(&od, 0x100A),
            def.sw_version,
            "0x100A of {}",
            def.name
        );
    }
}

#[test]
fn check_compares_identity_strings_with_esi_and_sii() {
    for def in seed_devices() {
        let f = check(def).expect("check runs");
        assert!(f.is_empty(), "{}: {f:#?}", def.name);
    }
}

#[test]
fn check_reports_a_served_name_that_differs() {
    // A definition whose OD serves another 0x1008 than its name: the check must see it.
    let mut model = oxicat_esi::model::from_def(&oxicat_devices::demo::DEF);
    let esi = model.clone();
    model.id_strings[0].1.push_str(" (longer)");
    let f = oxicat_esi::model::compare(&model, &esi);
    assert!(
        f.iter().any(|f| matches!(
            f,
            oxicat_esi::model::Finding::Text {
                field: "0x1008",
                ..
            }
        )),
        "{f:#?}"
    );
    let _ = Pair::DefEsi;
}

#[test]
fn a_name_the_od_cannot_hold_is_refused() {
    static LONG: DeviceDef = DeviceDef {
        name: "A device name far longer than the sixty-four bytes 0x1008 holds in the OD",
        ..oxicat_devices::demo::DEF
    };
    assert!(matches!(
        Od::<4096>::new(&LONG),
        Err(oxicat_slave::DefError::StringTooLong(0x1008))
    ));
    assert!(check(&LONG).is_err(), "the generators refuse it too");
}

#[test]
fn sii_general_points_at_order_code_and_name_like_beckhoff() {
    for def in seed_devices() {
        let img = sii::generate(def).unwrap();
        let im = SiiImage::new(&img[..]).unwrap();
        let strings = im.strings().unwrap().expect("strings category");
        let s = |i: u8| strings.get_str(i).map(str::to_string);
        let g = im.general().unwrap().expect("general category");
        // SOEM names a slave by string 1, Beckhoff's images hold the type there.
        assert_eq!(s(1).as_deref(), Some(def.info().order_code), "{}", def.name);
        assert_eq!(g.order_idx, 1, "{}", def.name);
        assert_eq!(s(g.name_idx).as_deref(), Some(def.name), "{}", def.name);
        assert_eq!(
            s(g.group_idx).as_deref(),
            Some(def.info().group.type_name),
            "{}",
            def.name
        );
    }
}

/// A definition whose strings hold characters XML 1.0 cannot carry (a vendor ESI's name with
/// U+0001, as one reference ESI has, reaches a twin's definition): the generated ESI is
/// still XML — each such character becomes U+FFFD — and parses back with the name.
#[test]
fn control_characters_in_strings_do_not_break_the_generated_esi() {
    let def: &'static DeviceDef = Box::leak(Box::new(DeviceDef {
        name: "odd\u{1}name\u{7}",
        ..oxicat_devices::demo::DEF
    }));
    let xml = oxicat_esi::esi::generate(def).expect("ESI");
    assert!(!xml.contains('\u{1}') && !xml.contains('\u{7}'));
    let models = oxicat_esi::esi::parse(&xml).expect("the generated ESI parses");
    assert_eq!(
        models[0].name.as_deref(),
        Some("odd\u{FFFD}name\u{FFFD}"),
        "the name, its control characters replaced"
    );
}
