//! The compiled PDO mappings sized to the device: a stack's `K` (copy steps per direction),
//! `pdo::map_steps` computing it from a definition, and the refusals when a mapping needs
//! more than the stack holds (at start-up for the default mapping, at PREOP → SAFEOP for one
//! the master configured): a typed error or an AL status code, never a cut mapping.

use crate::common;

use oxicat_esc::{Esc, EscConfig};
use oxicat_slave::pdo::{map_steps, steps, Dir};
use oxicat_slave::{InitError, Od, Slave};
use oxicat_testkit::device::{eeprom, App, IMG};
use oxicat_testkit::ports::Soft;
use oxicat_testkit::Bench;

/// Every board device: `map_steps` is at least what its default mapping compiles to, and
/// exactly that for a fixed assignment of fixed mappings (the demo: 13 output steps, 5
/// input steps).
#[test]
fn map_steps_is_what_each_board_device_needs() {
    use oxicat_devices::{axis_hub, demo};
    let defs = common::board_devices();
    for (name, def) in defs {
        let od = Box::new(Od::<4096>::new(def).expect(name));
        let (rx, tx) = (
            steps(&od, Dir::Rx).expect(name),
            steps(&od, Dir::Tx).expect(name),
        );
        let fixed = !def.assign_configurable
            && def
                .rx_pdos
                .iter()
                .chain(def.tx_pdos.iter())
                .all(|p| !p.configurable);
        let k = map_steps(def);
        println!("{name}: map_steps {k}, default mapping {rx} output / {tx} input steps");
        if fixed {
            assert_eq!(k, rx.max(tx), "{name}: {rx} / {tx} steps");
        } else {
            assert!(k >= rx.max(tx), "{name}: {k} < {rx} / {tx} steps");
        }
    }
    let od = Box::new(Od::<{ demo::IMAGE }>::new(&demo::DEF).expect("demo"));
    assert_eq!((steps(&od, Dir::Rx), steps(&od, Dir::Tx)), (Ok(13), Ok(5)));
    assert_eq!(map_steps(&demo::DEF), 13);
    // The hub's stack type states its capacity as a number.
    assert_eq!(axis_hub::app::MAP, map_steps(&axis_hub::device::DEF));
}

/// A stack that cannot hold the device's default mapping does not start: a typed error with
/// the figures, from `Slave::new` and from a slot alike.
#[test]
fn a_stack_too_small_for_the_default_mapping_is_refused() {
    use oxicat_devices::demo;
    const MAP: usize = map_steps(&demo::DEF);
    let mut e = Esc::new(EscConfig::default(), eeprom(&demo::DEF));
    let small = Slave::<Esc, { demo::IMAGE }, 128, { MAP - 1 }>::new(&demo::DEF, &mut e);
    assert_eq!(
        small.err(),
        Some(InitError::MappingCapacity {
            assign: 0x1C12,
            needed: 13,
            capacity: 12
        })
    );
    let mut slot = Box::new(oxicat_slave::SlaveSlot::<Esc, { demo::IMAGE }, 128, 12>::new());
    assert!(matches!(
        slot.start(&demo::DEF, &mut e),
        Err(InitError::MappingCapacity { needed: 13, .. })
    ));
    assert!(slot.slave().is_none());
    assert!(Slave::<Esc, { demo::IMAGE }, 128, MAP>::new(&demo::DEF, &mut e).is_ok());
}

/// The test device (configurable assignment): its default mapping compiles to 2 output and
/// 3 input steps; a master that assigns TxPDO 0x1A01 as well needs a fourth input step. A
/// stack of 3 steps refuses SAFEOP with "invalid input mapping" (0x0024) and keeps serving
/// PREOP; one of 4 takes it, with the whole mapping.
#[test]
fn a_configured_mapping_beyond_the_capacity_is_refused_at_safeop() {
    fn assign_both<const K: usize>(b: &mut Bench<Soft, App, IMG, K>) {
        b.enter_preop();
        b.download(0x1C13, 0, false, &[0]).expect("count 0");
        b.download(0x1C13, 2, false, &0x1A01u16.to_le_bytes())
            .expect("0x1A01");
        b.download(0x1C13, 0, false, &[2]).expect("count 2");
        b.config_pd();
    }
    let mut b = Bench::<Soft, App, IMG, 3>::with_steps();
    assign_both(&mut b);
    assert_eq!(b.request(4), (0x12, 0x0024));
    assert_eq!(b.s.input_bytes(), 0);
    assert_eq!(b.upload(0x1C13, 0, false), Ok(vec![2]));

    let mut b = Bench::<Soft, App, IMG, 4>::with_steps();
    assign_both(&mut b);
    assert_eq!(b.request(4), (4, 0));
    // 0x1A00 (56 bits) and 0x1A01 (0x6000:3, 16 bits).
    assert_eq!(b.s.input_bytes(), 9);
}
