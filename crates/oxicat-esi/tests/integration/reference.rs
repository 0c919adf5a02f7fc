//! The reference ESI and SII files (read by path from `OXICAT_REFERENCE`, default
//! `../../../shared/reference`) parse, and each reference ESI is compared with its SII.

use std::path::PathBuf;

use oxicat_esi::model::{FmmuKind, SmKind};
use oxicat_esi::{compare, esi, sii, Finding};

fn reference() -> PathBuf {
    std::env::var_os("OXICAT_REFERENCE")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference")
        })
}

fn read(rel: &str) -> Vec<u8> {
    let p = reference().join(rel);
    std::fs::read(&p).unwrap_or_else(|e| panic!("reference file {} missing: {e}", p.display()))
}

fn files(dir: &str, ext: &[&str]) -> Vec<String> {
    let d = reference().join(dir);
    let mut v: Vec<String> = std::fs::read_dir(&d)
        .unwrap_or_else(|e| panic!("reference dir {} missing: {e}", d.display()))
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| ext.iter().any(|x| n.ends_with(x)))
        .collect();
    v.sort();
    v
}

#[test]
fn every_reference_esi_parses() {
    let names = files("esi", &[".xml"]);
    assert_eq!(names.len(), 5, "{names:?}");
    for n in names {
        let xml = String::from_utf8(read(&format!("esi/{n}"))).expect("UTF-8");
        let devs = esi::parse(&xml).unwrap_or_else(|e| panic!("{n}: {e}"));
        assert!(!devs.is_empty(), "{n}: no device");
        for d in &devs {
            assert_ne!(d.vendor_id, 0, "{n}");
            assert!(d.name.as_deref().is_some_and(|s| !s.is_empty()), "{n}");
            assert!(d.sms.len() >= 2, "{n}: {:?}", d.sms);
            assert_eq!(d.sms[0].kind, SmKind::MBoxOut, "{n}");
            assert!(d.fmmus.contains(&FmmuKind::Outputs) || d.fmmus.contains(&FmmuKind::Inputs));
            assert!(d.eeprom.is_some(), "{n}: Eeprom");
        }
    }
}

#[test]
fn every_reference_sii_parses() {
    let mut n = 0;
    for f in files("sii", &[".bin", ".hex"]) {
        let m = sii::parse_any(&read(&format!("sii/{f}"))).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(m.name.is_some(), "{f}: name");
        assert!(m.vendor_id != 0, "{f}");
        n += 1;
    }
    for f in files("esi", &[".bin"]) {
        let m = sii::parse(&read(&format!("esi/{f}"))).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(m.vendor_id, 0x1337, "{f}: rt-labs vendor id");
        n += 1;
    }
    assert_eq!(n, 11);
    // A Beckhoff EK1100 dump: vendor 2, product 0x044C2C52.
    let ek = sii::parse_any(&read("sii/ek1100-eeprom-dump.bin")).unwrap();
    assert_eq!((ek.vendor_id, ek.product_code), (2, 0x044C_2C52));
    assert_eq!(ek.order_code.as_deref(), Some("EK1100"));
    assert!(ek.name.as_deref().is_some_and(|n| n.starts_with("EK1100")));
}

fn pair(xml: &str, bin: &str) -> Vec<Finding> {
    let x = String::from_utf8(read(&format!("esi/{xml}"))).unwrap();
    let e = esi::parse(&x).unwrap().remove(0);
    let s = sii::parse(&read(&format!("esi/{bin}"))).unwrap();
    compare(&e, &s)
}

#[test]
fn reference_esi_matches_its_sii_in_identity_and_layout() {
    for (xml, bin) in [
        (
            "soes-linux_lan9252demo-slave.xml",
            "soes-linux_lan9252demo-slave.bin",
        ),
        (
            "soes-rtl_xmc4_dynpdo-slave.xml",
            "soes-rtl_xmc4_dynpdo-sii_eeprom.bin",
        ),
        (
            "soes-xmc4300_slavedemo-esi.xml",
            "soes-xmc4300_slavedemo-sii_eeprom.bin",
        ),
    ] {
        let f = pair(xml, bin);
        eprintln!("{xml}: {f:#?}");
        assert!(
            !f.iter().any(|f| matches!(f, Finding::Identity { .. })),
            "{xml}: {f:?}"
        );
        assert!(
            !f.iter().any(|f| matches!(
                f,
                Finding::Sm { field: "start", .. } | Finding::SmCount { .. }
            )),
            "{xml}: {f:?}"
        );
    }
}

#[test]
fn a_wrong_pair_is_reported_as_typed_findings() {
    let f = pair(
        "soes-linux_lan9252demo-slave.xml",
        "soes-rtl_xmc4_dynpdo-sii_eeprom.bin",
    );
    assert!(
        f.iter().any(|f| matches!(
            f,
            Finding::Identity {
                field: "product_code",
                ..
            }
        )),
        "{f:?}"
    );
    assert!(f.iter().any(|f| matches!(f, Finding::Sm { .. })), "{f:?}");
}

#[test]
fn bad_input_is_a_typed_error_not_a_panic() {
    assert!(matches!(
        esi::parse("<EtherCATInfo>"),
        Err(oxicat_esi::Error::Xml(_))
    ));
    assert!(matches!(
        esi::parse("<Other/>"),
        Err(oxicat_esi::Error::Missing(_))
    ));
    let bad = "<EtherCATInfo><Vendor><Id>#xZZ</Id></Vendor><Descriptions><Devices/></Descriptions></EtherCATInfo>";
    assert!(matches!(
        esi::parse(bad),
        Err(oxicat_esi::Error::BadValue { .. })
    ));
    assert!(matches!(
        sii::parse(&[0u8; 10]),
        Err(oxicat_esi::Error::Sii(_))
    ));
    // A category running past the image end.
    let mut img = vec![0u8; 256];
    img[128..132].copy_from_slice(&[10, 0, 0xFF, 0x7F]);
    assert!(sii::parse(&img).is_err());
    assert!(sii::parse_any(b":zz\n").is_err());
    // Truncations of a good image never panic.
    let good = read("esi/soes-linux_lan9252demo-slave.bin");
    for n in 0..good.len() {
        let _ = sii::parse(&good[..n]);
    }
}
