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

#[test]
fn internal_voltages_are_four_read_only_10mv_words_and_foe_is_declared() {
    let obj = DEF
        .objects
        .iter()
        .find(|o| o.index == 0x8040)
        .expect("0x8040 Internal voltages (Fig. 7.4)");
    assert_eq!(obj.entries.len(), 5, "sub 0 and the manual's 4 entries");
    for e in &obj.entries[1..] {
        assert_eq!(e.dtype, oxicat_slave::DataType::Unsigned16);
        assert_eq!(e.access, oxicat_slave::Access::RO);
        assert_eq!(DEF.scale(0x8040, e.sub), DEF.scale(0x6010, 12), "10 mV");
    }
    let od = Od::<{ device::IMAGE }>::new(&DEF).expect("definition is consistent");
    assert_eq!(od.get::<u8>(0x8040, 0), Ok(4));
    assert!(DEF.info().foe, "the firmware runs ESC_foeprocess");
    assert!(
        DEF.boot_mailbox.is_some(),
        "firmware.bin is written in BOOT"
    );
}

#[test]
fn a_kill_is_reported_in_mstate_bit_3_once() {
    use super::app::{ADC2_LINE, MSTATE_KILLED};
    use super::{Adcs, Bridges, Encoders, Io, TuEs030};
    use oxicat_slave::{AlState, Application};

    struct Hw(u16);
    impl Bridges for Hw {
        fn set_bridge(&mut self, _: usize, _: u16, _: u16, _: bool) {}
    }
    impl Adcs for Hw {
        fn adc1(&mut self, _: usize) -> u16 {
            0
        }
        fn adc2(&mut self, ch: usize) -> u16 {
            if ch == ADC2_LINE {
                self.0
            } else {
                2168
            }
        }
    }
    impl Encoders for Hw {
        fn latch(&mut self, _: usize) -> (u32, u32) {
            (0, 0)
        }
    }
    impl Io for Hw {
        fn digin(&mut self) -> u8 {
            0
        }
        fn digout(&mut self, _: u8) {}
        fn dac(&mut self, _: usize, _: u16) {}
        fn calipers(&mut self) -> [u16; 2] {
            [0; 2]
        }
    }
    let mut od = Od::<{ device::IMAGE }>::new(&DEF).unwrap();
    let mut fw = TuEs030::new(Hw(2708));
    for to in [AlState::PreOp, AlState::SafeOp, AlState::Op] {
        fw.state_change(AlState::Init, to, &mut od).unwrap();
    }
    let mstate = |od: &Od<{ device::IMAGE }>| od.get::<u8>(0x6001, 1).unwrap();
    fw.current_loop();
    fw.cycle(&mut od);
    assert_eq!(mstate(&od) & MSTATE_KILLED, 0, "24 V");
    fw.board.0 = super::control::KILLVOLTAGE + 1;
    fw.current_loop();
    fw.board.0 = 2708;
    fw.current_loop();
    fw.cycle(&mut od);
    assert_ne!(mstate(&od) & MSTATE_KILLED, 0, "killed in between");
    fw.cycle(&mut od);
    assert_eq!(mstate(&od) & MSTATE_KILLED, 0, "reported once");
    assert_eq!(fw.line_peak_counts, super::control::KILLVOLTAGE + 1);
}
