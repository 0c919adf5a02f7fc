//! The demo device: its definition, generated ESI and generated SII agree; the ESI is
//! well-formed and uses ESI element names; the SII is what the definition says.

use oxicat_devices::demo;
use oxicat_esi::model::{FmmuKind, SmKind};
use oxicat_esi::{check, esi, model, sii};

#[test]
fn definition_esi_and_sii_agree() {
    for def in [&demo::DEF, &demo::additions::DEF] {
        let f = check(def).unwrap();
        assert!(f.is_empty(), "{}: {f:#?}", def.name);
    }
}

#[test]
fn esi_is_well_formed_and_uses_reference_element_names() {
    let xml = esi::generate(&demo::DEF).unwrap();
    let doc = roxmltree::Document::parse(&xml).expect("well-formed");
    let refdir = std::env::var_os("OXICAT_REFERENCE")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference")
        })
        .join("esi");
    let mut known = std::collections::BTreeSet::new();
    for e in std::fs::read_dir(&refdir).expect("reference/esi") {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "xml") {
            let t = std::fs::read_to_string(&p).unwrap();
            let d = roxmltree::Document::parse(&t).unwrap();
            for n in d.descendants().filter(|n| n.is_element()) {
                known.insert(n.tag_name().name().to_string());
                for a in n.attributes() {
                    known.insert(format!("@{}", a.name()));
                }
            }
        }
    }
    // ETG.2000 names the reference files happen not to use (DC SYNC timing, comment).
    let etg_only = [
        "Comment",
        "CycleTimeSync0",
        "ShiftTimeSync0",
        "CycleTimeSync1",
        "ShiftTimeSync1",
        "@Factor",
    ];
    for n in doc.descendants().filter(|n| n.is_element()) {
        let name = n.tag_name().name();
        assert!(
            known.contains(name) || etg_only.contains(&name),
            "element {name} not in the reference ESIs"
        );
        for a in n.attributes() {
            let an = format!("@{}", a.name());
            assert!(
                known.contains(&an) || etg_only.contains(&an.as_str()),
                "attribute {an} on {name}"
            );
        }
    }
    // Order of a Device's children as in the reference files.
    let dev = doc
        .descendants()
        .find(|n| n.has_tag_name("Device"))
        .unwrap();
    let order: Vec<&str> = dev
        .children()
        .filter(|n| n.is_element())
        .map(|n| n.tag_name().name())
        .collect();
    let pos = |t: &str| order.iter().position(|x| *x == t).unwrap();
    for w in [
        "Type",
        "Name",
        "GroupType",
        "Profile",
        "Fmmu",
        "Sm",
        "RxPdo",
        "TxPdo",
        "Mailbox",
        "Dc",
        "Eeprom",
    ]
    .windows(2)
    {
        assert!(pos(w[0]) < pos(w[1]), "{} before {}", w[0], w[1]);
    }
    // TwinCAT-style record/array data types.
    for dt in [
        "DT1018",
        "DT1600",
        "DT1C12ARR",
        "DT1C12",
        "DT1C32",
        "DT7000",
        "DT7020",
    ] {
        assert!(xml.contains(&format!("<Name>{dt}</Name>")), "{dt}");
    }
    assert!(xml.contains("<AssignActivate>#x0300</AssignActivate>"));
    assert!(xml.contains(
        r##"<Sm DefaultSize="24" StartAddress="#x1100" ControlByte="#x64" Enable="1">Outputs</Sm>"##
    ));
    assert!(xml.contains(
        r##"<Sm DefaultSize="22" StartAddress="#x1400" ControlByte="#x20" Enable="1">Inputs</Sm>"##
    ));
}

#[test]
fn esi_model_is_table_2_2() {
    let m = esi::parse(&esi::generate(&demo::DEF).unwrap())
        .unwrap()
        .remove(0);
    assert_eq!(m.product_code, 0x1111_0141);
    assert_eq!(m.name.as_deref(), Some("EtherCAT Application (SPI)"));
    let rx: Vec<u16> = m.rx_pdos.iter().map(|p| p.index).collect();
    let tx: Vec<u16> = m.tx_pdos.iter().map(|p| p.index).collect();
    assert_eq!(rx, [0x1600, 0x1601, 0x1602]);
    assert_eq!(tx, [0x1A01, 0x1A02, 0x1A03]);
    let bits = |p: &[oxicat_esi::model::PdoModel]| -> u32 {
        p.iter()
            .flat_map(|p| &p.entries)
            .map(|e| e.bits as u32)
            .sum()
    };
    assert_eq!(bits(&m.rx_pdos), 24 * 8);
    assert_eq!(bits(&m.tx_pdos), 22 * 8);
    let b = &m.rx_pdos[0].entries;
    assert_eq!(b[4].name.as_deref(), Some("Blue_LED"));
    assert_eq!(b[5].name.as_deref(), Some("Red_LED"));
    assert_eq!(b[8].name.as_deref(), Some("Sync"));
    assert_eq!(b[8].data_type, Some(0x0002));
    let objs: Vec<u16> = m.objects.iter().map(|o| o.index).collect();
    for i in [
        0x1000, 0x1018, 0x1C12, 0x1C13, 0x1C32, 0x6010, 0x6030, 0x7000, 0x7020,
    ] {
        assert!(objs.contains(&i), "{i:#x}");
    }
    assert!(!objs.contains(&0x1A00), "no 0x1A00 in the thesis");
}

#[test]
fn sii_is_the_definition() {
    let img = sii::generate(&demo::DEF).unwrap();
    assert_eq!(img.len(), 2048);
    let im = oxicat_wire::sii::SiiImage::new(&img).unwrap();
    assert!(im.crc_ok());
    assert_eq!(im.identity().product_code, 0x1111_0141);
    assert_eq!(im.eeprom_size_bytes(), 2048);
    let m = sii::parse(&img).unwrap();
    assert_eq!(m.name.as_deref(), Some("EtherCAT Application (SPI)"));
    assert_eq!(
        m.fmmus,
        [FmmuKind::Outputs, FmmuKind::Inputs, FmmuKind::MBoxState]
    );
    let sms: Vec<_> = m
        .sms
        .iter()
        .map(|s| (s.kind, s.start, s.default_size))
        .collect();
    assert_eq!(
        sms,
        [
            (SmKind::MBoxOut, 0x1000, Some(128)),
            (SmKind::MBoxIn, 0x1080, Some(128)),
            (SmKind::Outputs, 0x1100, Some(24)),
            (SmKind::Inputs, 0x1400, Some(22)),
        ]
    );
    assert_eq!(m.dc.len(), 3);
    assert_eq!(m.dc[2].assign_activate, 0x0700);
    assert_eq!(m.dc[1].name.as_deref(), Some("DC_Sync0"));
    let c = m.mailbox.unwrap().coe.unwrap();
    assert!(c.sdo_info && c.complete_access && !c.pdo_assign);
    assert_eq!(model::from_def(&demo::DEF).rx_pdos, m.rx_pdos);
}
