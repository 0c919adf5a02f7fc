//! `SlaveSlot`: the stack built in place (a board image's static) is the stack
//! `Slave::new` builds, and starting a used slot again gives a fresh one.

use crate::common;

use oxicat_esc::{Esc, EscConfig};
use oxicat_slave::{AlState, InitError, Slave, SlaveSlot};
use oxicat_testkit::device::{eeprom, DEF, IMG, MBX};

type Stack = Slave<Esc, IMG, MBX>;

fn esc() -> Esc {
    Esc::new(EscConfig::default(), eeprom(&DEF))
}

/// Every object's every entry, as bytes, and the AL status the stack wrote to the ESC.
fn snapshot(s: &Stack, esc: &mut Esc) -> (Vec<Vec<u8>>, Vec<u8>) {
    let od = s.od();
    let mut all = Vec::new();
    for n in 0..od.object_count() {
        let o = od.object_info(n).expect("object");
        for e in o.entries {
            all.push(od.bytes(o.index, e.sub).expect("entry").to_vec());
        }
    }
    let mut al = [0u8; 6];
    esc.pdi_read(0x0130, &mut al).expect("AL status");
    (all, al.to_vec())
}

#[test]
fn a_slot_builds_the_stack_new_builds() {
    let (mut e1, mut e2) = (esc(), esc());
    let new = Stack::new(&DEF, &mut e1).expect("new");
    let mut slot = Box::new(SlaveSlot::<Esc, IMG, MBX>::new());
    let started = slot.start(&DEF, &mut e2).expect("start");
    assert_eq!(started.state(), AlState::Init);
    assert_eq!(
        (started.output_bytes(), started.input_bytes()),
        (new.output_bytes(), new.input_bytes())
    );
    assert_eq!(started.od().app_image(), new.od().app_image());
    assert_eq!(snapshot(started, &mut e2), snapshot(&new, &mut e1));
    assert!(snapshot(&new, &mut e1)
        .0
        .iter()
        .any(|v| v.iter().any(|&b| b != 0)));
}

#[test]
fn starting_a_used_slot_again_resets_it() {
    let mut e = esc();
    let mut slot = Box::new(SlaveSlot::<Esc, IMG, MBX>::new());
    let s = slot.start(&DEF, &mut e).expect("start");
    // Change the dictionary (a writable entry) and the stack's state.
    let n = s.od().object_count();
    let writable = (0..n)
        .filter_map(|k| s.od().object_info(k))
        .find_map(|o| {
            o.entries
                .iter()
                .find(|e| e.access.writable() && e.bits == 16)
                .map(|e| (o.index, e.sub))
        })
        .expect("a writable 16-bit entry");
    let old: u16 = s.od().get(writable.0, writable.1).expect("get");
    s.od_mut()
        .set(writable.0, writable.1, old ^ 0x5A5A)
        .expect("set");
    s.set_stepwise_safeop(true);
    let s = slot.start(&DEF, &mut e).expect("start again");
    assert_eq!(s.od().get::<u16>(writable.0, writable.1), Ok(old));
    assert_eq!(s.state(), AlState::Init);
    let fresh = Stack::new(&DEF, &mut esc()).expect("new");
    assert_eq!(snapshot(s, &mut e).0, snapshot(&fresh, &mut esc()).0);
}

#[test]
fn a_slot_refuses_a_definition_the_stack_refuses() {
    // Mailbox buffers smaller than the definition's mailboxes.
    let mut slot = Box::new(SlaveSlot::<Esc, IMG, 16>::new());
    assert!(matches!(
        slot.start(&DEF, &mut esc()),
        Err(InitError::MailboxSize)
    ));
    assert!(matches!(
        Slave::<Esc, IMG, 16>::new(&DEF, &mut esc()),
        Err(InitError::MailboxSize)
    ));
}

#[test]
fn a_slot_hands_out_its_stack_only_while_it_runs() {
    let mut e = esc();
    let mut slot = Box::new(SlaveSlot::<Esc, IMG, MBX>::new());
    assert!(slot.slave().is_none() && slot.slave_mut().is_none());
    slot.start(&DEF, &mut e).expect("start");
    assert_eq!(slot.slave().map(|s| s.state()), Some(AlState::Init));
    assert!(slot.slave_mut().is_some());
    slot.stop();
    assert!(slot.slave().is_none() && slot.slave_mut().is_none());
    slot.start(&DEF, &mut e).expect("start again");
    assert!(slot.slave().is_some());
    // A failed start leaves the slot stopped, not holding the previous stack.
    let mut small = Box::new(SlaveSlot::<Esc, IMG, 16>::new());
    assert!(small.start(&DEF, &mut e).is_err());
    assert!(small.slave().is_none());
}

/// `DeviceDef::for_image` (what a board image links) drops the ESI/SII description
/// (`DeviceInfo`, which the stack does not read) and keeps everything the stack serves: the
/// same dictionary, byte for byte.
#[test]
fn the_image_definition_serves_the_same_dictionary() {
    use oxicat_devices::demo;
    static IMAGE_DEF: oxicat_slave::DeviceDef = demo::DEF.for_image();
    type Demo = Slave<Esc, { demo::IMAGE }, 128>;
    assert!(IMAGE_DEF.info.is_none());
    assert_eq!(IMAGE_DEF.info(), &oxicat_slave::device::DeviceInfo::DEFAULT);
    assert!(!demo::DEF.info().vendor_name.is_empty() && !demo::DEF.info().dc_modes.is_empty());
    assert_eq!(
        (IMAGE_DEF.identity, IMAGE_DEF.mailbox, IMAGE_DEF.sync),
        (demo::DEF.identity, demo::DEF.mailbox, demo::DEF.sync)
    );
    // Every object's description (SDO information) and every entry's value.
    let dump = |def: &'static oxicat_slave::DeviceDef| {
        let mut e = Esc::new(EscConfig::default(), eeprom(&demo::DEF));
        let s = Demo::new(def, &mut e).expect("new");
        let od = s.od();
        let mut all = Vec::new();
        for n in 0..od.object_count() {
            let o = od.object_info(n).expect("object");
            for en in o.entries {
                let v = od.bytes(o.index, en.sub).expect("entry").to_vec();
                all.push((o.index, o.name, o.code, *en, v));
            }
        }
        all
    };
    assert_eq!(dump(&IMAGE_DEF), dump(&demo::DEF));
}

/// The PDO mapping objects lie in a pool of the communication image, each its own size (a
/// fixed mapping 1 + 4 bytes per entry): every device a board image runs fits the pool of
/// a microcontroller build, so no board stops at start-up with `MappingsTooLarge`.
#[test]
fn every_board_device_fits_the_microcontroller_mapping_pool() {
    use oxicat_devices::demo;
    use oxicat_slave::od::{map_storage, MAP_POOL_MCU, MAP_SHOWN};
    let defs = common::board_devices();
    for (name, def) in defs {
        let want: usize = def
            .rx_pdos
            .iter()
            .chain(def.tx_pdos.iter())
            .map(|p| {
                let shown = if p.configurable {
                    p.entries.len().max(MAP_SHOWN)
                } else {
                    p.entries.len()
                };
                1 + 4 * shown
            })
            .sum();
        assert_eq!(map_storage(def), want, "{name}");
        assert!(
            want <= MAP_POOL_MCU,
            "{name}: {want} bytes of mapping objects"
        );
    }
    // The demo's six fixed PDOs: 106 bytes (was 16 × 125 = 2,000 at the 31-entry capacity).
    assert_eq!(map_storage(&demo::DEF), 106);
}

/// A definition checked when the image is built (`const { CheckedDef::new(&DEF) }`, what
/// the board images start with) starts the same stack as `start`, which checks it at run
/// time.
#[test]
fn a_definition_checked_at_build_time_starts_the_same_stack() {
    use oxicat_slave::CheckedDef;
    let (mut e1, mut e2) = (esc(), esc());
    let mut checked = Box::new(SlaveSlot::<Esc, IMG, MBX>::new());
    let mut plain = Box::new(SlaveSlot::<Esc, IMG, MBX>::new());
    let a = checked
        .start_checked(const { CheckedDef::new(&DEF) }, &mut e1)
        .expect("start_checked");
    let b = plain.start(&DEF, &mut e2).expect("start");
    assert_eq!(a.state(), AlState::Init);
    assert_eq!(a.od().app_image(), b.od().app_image());
    assert_eq!(snapshot(a, &mut e1), snapshot(b, &mut e2));
    // The later start-up checks still run: buffers smaller than the mailboxes.
    let mut small = Box::new(SlaveSlot::<Esc, IMG, 16>::new());
    assert!(matches!(
        small.start_checked(const { CheckedDef::new(&DEF) }, &mut esc()),
        Err(InitError::MailboxSize)
    ));
}

/// `check_def` gives the same answer in a `const` as at run time for every board device,
/// and `CheckedDef::new` refuses what it refuses (here an image one byte too small).
#[test]
fn check_def_at_build_time_agrees_with_run_time() {
    use oxicat_slave::od::{check_def, image_size, DefError};
    use oxicat_slave::CheckedDef;
    const AT_BUILD: Result<(), DefError> = check_def(&DEF, IMG);
    assert_eq!(AT_BUILD, Ok(()));
    assert_eq!(check_def(&DEF, IMG), Ok(()));
    for (name, def) in common::board_devices() {
        let n = image_size(def.objects);
        assert_eq!(check_def(def, n), Ok(()), "{name}");
        assert_eq!(
            check_def(def, n - 1),
            Err(DefError::ImageTooSmall { needed: n }),
            "{name}"
        );
    }
    let refused = std::panic::catch_unwind(|| CheckedDef::<1>::new(&DEF));
    assert!(refused.is_err());
}
