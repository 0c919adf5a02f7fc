//! SII views against real EEPROM images from `$OXICAT_REFERENCE` (default
//! `../../../shared/reference` relative to this crate). Missing files fail the test.

use oxicat_wire::sii::{CategoryType, FmmuUsage, SiiImage, SmType};
use std::path::PathBuf;

fn reference_dir() -> PathBuf {
    match std::env::var_os("OXICAT_REFERENCE") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference"),
    }
}

fn read(rel: &str) -> Vec<u8> {
    let p = reference_dir().join(rel);
    std::fs::read(&p).unwrap_or_else(|e| panic!("reference file {} missing: {e}", p.display()))
}

/// (file, vendor, product, order-number string or "" to skip)
const IMAGES: &[(&str, u32, u32, &str)] = &[
    ("sii/ek1100.hex", 2, 0x044c_2c52, "EK1100"),
    ("sii/ek1100-eeprom-dump.bin", 2, 0x044c_2c52, "EK1100"),
    ("sii/el2004-eeprom-dump.bin", 2, 0x07d4_3052, "EL2004"),
    ("sii/el2262.bin", 2, 0x08d6_3052, "EL2262"),
    ("sii/el2828.hex", 2, 0x0b0c_3052, "EL2828"),
    ("sii/el2889.hex", 2, 0x0b49_3052, "EL2889"),
    ("sii/akd.hex", 0x6a, 0x0041_4b44, ""),
    ("sii/hbm_clipx_eeprom_dump.bin", 0x11d, 0x0f01, ""),
    ("esi/soes-linux_lan9252demo-slave.bin", 0x1337, 0x04d2, ""),
    (
        "esi/soes-rtl_xmc4_dynpdo-sii_eeprom.bin",
        0x1337,
        0x4800,
        "",
    ),
    (
        "esi/soes-xmc4300_slavedemo-sii_eeprom.bin",
        0x1337,
        0x1278_3456,
        "",
    ),
];

/// Walks every category of `img`, decoding each standard one, and returns a summary line.
fn walk(name: &str, img: &SiiImage<'_>) -> String {
    let mut out = format!("{name}: ");
    let strings = img.strings().unwrap();
    for c in img.categories() {
        let c = c.unwrap_or_else(|e| panic!("{name}: category error {e}"));
        out += &format!("{:?}({}) ", c.kind, c.data.len());
        match c.kind {
            CategoryType::Strings => {
                let s = c.strings().unwrap();
                let n = s.iter().collect::<Result<Vec<_>, _>>().unwrap().len();
                assert_eq!(n, s.count() as usize, "{name}: string count");
            }
            CategoryType::General => {
                let g = c.general().unwrap();
                let st = strings.expect("general without strings");
                if g.name_idx != 0 {
                    assert!(st.get(g.name_idx).is_some(), "{name}: name string");
                }
                if g.order_idx != 0 {
                    assert!(st.get(g.order_idx).is_some(), "{name}: order string");
                }
            }
            CategoryType::SyncManager => {
                assert_eq!(c.data.len() % 8, 0, "{name}: SM size");
                for sm in c.sync_managers() {
                    let sm = sm.unwrap();
                    assert!(!matches!(sm.sm_type, SmType::Other(_)), "{name}: {sm:?}");
                }
            }
            CategoryType::Fmmu => {
                for f in c.fmmus() {
                    assert!(!matches!(f, FmmuUsage::Other(_)), "{name}: fmmu {f:?}");
                }
            }
            CategoryType::FmmuExtended => {
                for f in c.fmmus_extended() {
                    f.unwrap();
                }
            }
            CategoryType::TxPdo | CategoryType::RxPdo => {
                for p in c.pdos() {
                    let p = p.unwrap_or_else(|e| panic!("{name}: pdo {e}"));
                    // Real images are not strict about the Rx/Tx ranges (EL2262 lists 0x1702
                    // in its TxPDO category), so only check it is a PDO mapping object.
                    let idx = p.header.index;
                    assert!((0x1600..=0x1BFF).contains(&idx), "{name}: {idx:#x}");
                    assert_eq!(p.entries().count(), p.header.entry_count as usize);
                    for e in p.entries() {
                        e.unwrap();
                    }
                }
            }
            CategoryType::Dc => {
                assert_eq!(c.data.len() % 24, 0, "{name}: DC size");
                for d in c.dc() {
                    d.unwrap();
                }
            }
            _ => {}
        }
    }
    out
}

#[test]
fn reference_images() {
    for (file, vendor, product, dev_name) in IMAGES {
        let bytes = read(file);
        let img = SiiImage::new(&bytes).unwrap();
        let id = img.identity();
        assert_eq!(id.vendor_id, *vendor, "{file}");
        assert_eq!(id.product_code, *product, "{file}");
        assert!(img.crc_ok(), "{file}: configuration-area CRC");
        assert_eq!(img.version(), 1, "{file}");
        let summary = walk(file, &img);
        let general = img.general().unwrap().expect("general category");
        let strings = img.strings().unwrap().expect("strings category");
        let name = strings.get_str(general.name_idx).unwrap_or("?");
        let order = strings.get_str(general.order_idx).unwrap_or("?");
        println!(
            "{summary}\n   name {name:?} order {order:?} {:?}",
            img.mailbox()
        );
        if !dev_name.is_empty() {
            assert_eq!(order, *dev_name, "{file}");
        }
    }
}

#[test]
fn ek1100_details() {
    let bytes = read("sii/ek1100.hex");
    let img = SiiImage::new(&bytes).unwrap();
    assert_eq!(img.identity().revision, 0x0012_0000);
    assert_eq!(img.eeprom_size_bytes(), 2048);
    assert_eq!(img.mailbox().protocols, 0);
    let g = img.general().unwrap().unwrap();
    let s = img.strings().unwrap().unwrap();
    assert_eq!(s.count(), 4);
    assert_eq!(s.get_str(g.order_idx), Some("EK1100"));
    assert_eq!(s.get_str(g.group_idx), Some("SystemBk"));
    // The dump and the hex image are the same device.
    assert_eq!(read("sii/ek1100-eeprom-dump.bin"), bytes);
}

#[test]
fn soes_lan9252_mailbox() {
    let bytes = read("esi/soes-linux_lan9252demo-slave.bin");
    let img = SiiImage::new(&bytes).unwrap();
    let m = img.mailbox();
    assert_eq!(m.protocols & oxicat_wire::mailbox::protocols::COE, 0x4);
    assert!(m.standard_rx.size > 0 && m.standard_tx.size > 0);
    let sms: Vec<_> = img
        .find(CategoryType::SyncManager)
        .unwrap()
        .unwrap()
        .sync_managers()
        .map(|s| s.unwrap())
        .collect();
    assert_eq!(sms.len(), 4);
    assert_eq!(sms[0].sm_type, SmType::MailboxOut);
    assert_eq!(sms[0].start, m.standard_rx.offset);
    assert_eq!(sms[1].sm_type, SmType::MailboxIn);
    assert_eq!(sms[1].start, m.standard_tx.offset);
}
