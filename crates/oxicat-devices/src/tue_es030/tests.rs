//! Definition-level checks of the TUeES030 device.

use super::device::{self, DEF};
use oxicat_slave::Od;

fn bytes(index: u16) -> usize {
    let p = DEF.pdo(index).expect("pdo");
    p.entries.iter().map(|e| e.bits as usize).sum::<usize>() / 8
}

#[test]
fn pdo_sizes_are_the_manuals() {
    // The manual's packed structs: rxpdo1_t 20, txpdo1_t 64, rxpdo2_t 46, txpdo2_t 49 bytes.
    assert_eq!(bytes(0x1600), 20);
    assert_eq!(bytes(0x1A00), 64);
    assert_eq!(bytes(0x1601), 46);
    assert_eq!(bytes(0x1A01), 49);
    assert_eq!(
        [
            device::NORMAL_RX_BYTES,
            device::NORMAL_TX_BYTES,
            device::FRF_RX_BYTES,
            device::FRF_TX_BYTES
        ],
        [20, 64, 46, 49]
    );
    assert_eq!(DEF.default_output_bits(), 160);
    assert_eq!(DEF.default_input_bits(), 512);
}

#[test]
fn dictionary_builds_with_manual_defaults() {
    let od = Od::<{ device::IMAGE }>::new(&DEF).expect("definition is consistent");
    for i in 0x8000..=0x8002u16 {
        assert_eq!(od.get::<f32>(i, 1), Ok(0.61));
        assert_eq!(od.get::<f32>(i, 3), Ok(2.0));
        assert_eq!(od.get::<i8>(i, 6), Ok(1));
        assert_eq!(od.get::<u16>(i, 7), Ok(1024));
        assert_eq!(od.get::<i16>(i, 8), Ok(2168));
    }
    assert_eq!(od.get::<u16>(0x1C12, 1), Ok(0x1600));
    assert_eq!(od.get::<u16>(0x1C13, 1), Ok(0x1A00));
}
