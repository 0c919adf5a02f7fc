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

/// The report's ESI (Listing D.1): `<Eeprom><ByteSize>512</ByteSize><ConfigData>
/// 800200cc8813ff00CACA0080</ConfigData>`, the state-machine timeouts 8000/36000/20000/800
/// ms, the mailbox timeouts 400/8000 ms, `<CoE SdoInfo="true" PdoConfig="false"
/// SegmentedSdo="true" PdoAssign="false" PdoUpload="true">`. Read back from the generated
/// SII bytes and the generated XML, against the report's numbers written out here.
#[test]
fn axis_hub_sii_and_esi_carry_the_reports_lan9252_settings() {
    let sii = oxicat_esi::sii::generate(&DEF).expect("SII");
    let w = |i: usize| u16::from_le_bytes([sii[2 * i], sii[2 * i + 1]]);
    // Not the report's 512 bytes: the image with the names of all 22 PDO entries is 870
    // bytes (README), so the EEPROM is 1024 bytes, word 0x3E = (1024 / 128) - 1 = 7 ...
    assert_eq!(sii.len(), 1024);
    assert_eq!(w(0x3E), 7);
    // ... and 512 bytes are refused, not cut.
    let mut small = DEF;
    small.info = Some(Box::leak(Box::new(oxicat_slave::device::DeviceInfo {
        eeprom_bytes: 512,
        ..*DEF.info()
    })));
    assert!(matches!(
        oxicat_esi::sii::generate(&small),
        Err(oxicat_esi::Error::DoesNotFit(_))
    ));
    // ConfigData bytes 80 02 / 00 cc / 88 13 / ff 00: PDI control 0x80 (LAN9252 on-chip
    // bus), ESC configuration 0x02, PDI configuration 0x00 / SYNC configuration 0xCC, SYNC
    // impulse 5000 × 10 ns, extended PDI configuration 0x00FF.
    assert_eq!(&sii[..8], &[0x80, 0x02, 0x00, 0xCC, 0x88, 0x13, 0xFF, 0x00]);
    // Not the report's 0xCACA: every board would carry the same alias (README).
    assert_eq!(w(4), 0);
    // The ESC configuration area's CRC still holds.
    let cfg = oxicat_wire::sii::SiiConfig::parse(&sii).unwrap();
    assert_eq!(
        cfg.checksum as u8,
        oxicat_wire::crc::sii_crc8(&sii[..14]),
        "CRC of words 0-6"
    );
    // The ESC loads it: PDI control 0x0140 reads 0x80 after the EEPROM load.
    let esc = oxicat_esc::Esc::new(oxicat_esc::EscConfig::lan9252(), sii.clone());
    assert_eq!(&esc.memory()[0x0140..0x0142], &[0x80, 0x02]);

    let xml = oxicat_esi::esi::generate(&DEF).expect("ESI");
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let text = |path: &[&str]| -> String {
        let mut n = doc.root_element();
        for p in path {
            n = n
                .descendants()
                .find(|c| c.has_tag_name(*p))
                .unwrap_or_else(|| panic!("{p} missing in {path:?}"));
        }
        n.text().unwrap_or("").trim().to_string()
    };
    assert_eq!(text(&["Eeprom", "ByteSize"]), "1024");
    assert!(
        text(&["Eeprom", "ConfigData"])
            .to_lowercase()
            .starts_with("800200cc8813ff00"),
        "{}",
        text(&["Eeprom", "ConfigData"])
    );
    for (path, v) in [
        (["StateMachine", "PreopTimeout"], "8000"),
        (["StateMachine", "SafeopOpTimeout"], "36000"),
        (["StateMachine", "BackToInitTimeout"], "20000"),
        (["StateMachine", "BackToSafeopTimeout"], "800"),
        (["Info", "RequestTimeout"], "400"),
        (["Info", "ResponseTimeout"], "8000"),
    ] {
        assert_eq!(text(&path), v, "{path:?}");
    }
    // The mailbox timeouts sit in Info/Mailbox, as ETG.2000 has them.
    let info_mbx = doc
        .descendants()
        .find(|n| n.has_tag_name("Info"))
        .and_then(|i| i.children().find(|c| c.has_tag_name("Mailbox")));
    assert!(info_mbx.is_some(), "Info/Mailbox");
    let coe = doc.descendants().find(|n| n.has_tag_name("CoE")).unwrap();
    for (attr, v) in [
        ("SdoInfo", "true"),
        ("PdoAssign", "false"),
        ("PdoConfig", "false"),
        ("PdoUpload", "true"),
        ("SegmentedSdo", "true"),
        // The report's false: SOES of 2020 (README); oxicat's stack serves complete access.
        ("CompleteAccess", "true"),
    ] {
        assert_eq!(coe.attribute(attr), Some(v), "CoE {attr}");
    }
    // The SII's general category says the same CoE details (PdoUpload bit 4).
    let model = oxicat_esi::sii::parse(&sii).unwrap();
    let c = model.mailbox.unwrap().coe.unwrap();
    assert!(c.pdo_upload && c.sdo_info && !c.pdo_assign && !c.pdo_config);
    // The parser reads the timeouts back, so the check compares them.
    let m = &oxicat_esi::esi::parse(&xml).unwrap()[0];
    let t = m.timeouts.expect("timeouts parsed");
    assert_eq!(
        (t.preop, t.safeop_op, t.back_to_init, t.back_to_safeop),
        (8000, 36000, 20000, 800)
    );
    assert_eq!((t.mailbox_request, t.mailbox_response), (400, 8000));
}
