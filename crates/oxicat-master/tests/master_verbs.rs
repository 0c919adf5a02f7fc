//! Every master function against an in-process segment of demo devices running their
//! firmware (oxicat-slave + the Demo application).

mod common;

use oxicat_master::cyclic::CycleOptions;
use oxicat_master::value::ValueType;
use oxicat_master::{AlState, MasterError};
use std::time::Duration;

#[test]
fn scan_lists_names_identities_and_ports() {
    let (m, _seg, _fws, _) = common::demo_master(2);
    let s = m.scan().unwrap();
    assert_eq!(s.len(), 2);
    for (i, sl) in s.iter().enumerate() {
        assert_eq!(sl.position, i);
        assert_eq!(sl.vendor_id, oxicat_devices::demo::DEF.identity.vendor_id);
        assert_eq!(
            sl.product_code,
            oxicat_devices::demo::DEF.identity.product_code
        );
        assert_eq!(sl.status.state(), Some(AlState::PreOp));
        assert!(!sl.name.is_empty());
        assert!(sl.links[0], "port 0 linked");
    }
    assert!(s[0].links[1], "first slave's port 1 goes on to the second");
}

#[test]
fn states_op_reaches_op_and_back_to_init() {
    let (mut m, _seg, _fws, _) = common::demo_master(2);
    let r = m.request_state(&[0, 1], AlState::Op).unwrap();
    for (_, st) in &r {
        assert_eq!(st.state(), Some(AlState::Op));
    }
    let r = m.request_state(&[1], AlState::Init).unwrap();
    assert_eq!(r[0].1.state(), Some(AlState::Init));
    assert_eq!(m.al_status(0).unwrap().state(), Some(AlState::Op));
}

#[test]
fn sdo_upload_vendor_id_and_abort_text() {
    let (m, _seg, _fws, _) = common::demo_master(1);
    let v = m.sdo_upload(0, 0x1018, 1).unwrap();
    assert_eq!(
        ValueType::U32.format_plain(&v),
        oxicat_devices::demo::DEF.identity.vendor_id.to_string()
    );
    let name = m.sdo_upload(0, 0x1008, 0).unwrap();
    assert!(ValueType::String.format(&name).starts_with("EtherCAT"));
    match m.sdo_upload(0, 0x5555, 0) {
        Err(e @ MasterError::SdoAbort { .. }) => {
            let t = e.to_string();
            assert!(t.contains("0x06020000"), "{t}");
            assert!(t.contains("does not exist"), "{t}");
        }
        other => panic!("expected an abort, got {other:?}"),
    }
}

#[test]
fn sdo_info_lists_the_dictionary() {
    let (m, _seg, _fws, _) = common::demo_master(1);
    let list = m.sdo_list(0).unwrap();
    assert!(
        list.contains(&0x1018) && list.contains(&0x7000),
        "{list:x?}"
    );
    let o = m.sdo_describe(0, 0x1018).unwrap();
    assert_eq!(o.name, "Identity");
    assert!(o.entries.iter().any(|e| e.name == "Vendor ID"));
}

#[test]
fn sii_read_decode_and_pdos() {
    let (m, _seg, _fws, _) = common::demo_master(1);
    let img = m.sii_read(0, false).unwrap();
    let gen = oxicat_esi::sii::generate(&oxicat_devices::demo::DEF).unwrap();
    assert_eq!(&img[..], &gen[..img.len()]);
    let text = oxicat_master::sii::decode(&img).unwrap();
    assert!(text.contains("Vendor ID:       0xe0000000"), "{text}");
    let p = m.pdos(0).unwrap();
    assert_eq!(p.source, oxicat_master::pdo::PdoSource::Coe);
    assert_eq!(
        p.rx.iter().map(|x| x.index).collect::<Vec<_>>(),
        vec![0x1600, 0x1601, 0x1602]
    );
    assert!(p.rx[0].entries.iter().any(|e| e.name == "Blue_LED"));
}

#[test]
fn xml_parses_with_the_esi_parser() {
    let (m, _seg, _fws, _) = common::demo_master(1);
    let xml = m.esi(0).unwrap();
    let devs = oxicat_esi::esi::parse(&xml).expect("ESI parses");
    assert_eq!(devs.len(), 1);
    let d = &devs[0];
    assert_eq!(d.vendor_id, oxicat_devices::demo::DEF.identity.vendor_id);
    assert_eq!(
        d.product_code,
        oxicat_devices::demo::DEF.identity.product_code
    );
    assert!(d.objects.iter().any(|o| o.index == 0x1018));
    assert_eq!(d.rx_pdos.len(), 3);
}

#[test]
fn register_read_and_write() {
    let (m, _seg, _fws, _) = common::demo_master(1);
    let t = m.reg_read(0, 0x0000, 1).unwrap();
    assert_eq!(t[0], 0x11, "ET1100 type");
    // Station address (0x0010) as ethercrab configured it.
    let a = m.reg_read(0, 0x0010, 2).unwrap();
    assert_eq!(u16::from_le_bytes([a[0], a[1]]), m.address(0).unwrap());
    // User RAM.
    m.reg_write(0, 0x0F80, &[0x34, 0x12]).unwrap();
    assert_eq!(m.reg_read(0, 0x0F80, 2).unwrap(), vec![0x34, 0x12]);
}

#[test]
fn write_changes_an_output_the_firmware_sees_on_all_linked_slaves() {
    let (mut m, _seg, fws, leds) = common::demo_master(2);
    let layouts = m.layouts().unwrap();
    let name = m.name(0).unwrap().to_string();
    let vars = m
        .resolve(&[format!("{name}.OutINT32Var1")], &layouts)
        .unwrap()
        .remove(0);
    assert_eq!(vars.len(), 2, "the device name links both slaves");
    let led = m
        .resolve(&["1.Blue_LED".into()], &layouts)
        .unwrap()
        .remove(0);
    // What the firmware holds while the master cycles (the slaves leave OP at the end, and
    // outputs go to their safe values outside OP).
    let mut seen = Vec::new();
    m.run_cyclic(CycleOptions::default(), |io| {
        if io.cycle == 5 {
            for v in &vars {
                io.set(v, &1234i32.to_le_bytes())?;
            }
        }
        if io.cycle == 15 {
            seen = fws
                .iter()
                .map(|fw| fw.lock().slave.od().get::<i32>(0x7010, 1).unwrap())
                .collect();
            return Ok(oxicat_master::cyclic::Flow::Stop);
        }
        Ok(oxicat_master::cyclic::Flow::Continue)
    })
    .unwrap();
    assert_eq!(seen, vec![1234, 1234]);
    for p in 0..2 {
        assert_eq!(m.al_status(p).unwrap().state(), Some(AlState::PreOp));
    }
    let _ = (led, leds);
}

#[test]
fn record_writes_a_csv_with_header_and_rows() {
    let (mut m, _seg, _fws, _) = common::demo_master(2);
    let layouts = m.layouts().unwrap();
    let vars: Vec<_> = m
        .resolve(&["0.InINT32Var1".into(), "1.InINT16Var1".into()], &layouts)
        .unwrap()
        .into_iter()
        .flatten()
        .collect();
    let mut csv = Vec::new();
    let mut last = 0;
    let stats = m
        .record(
            CycleOptions {
                cycle: Duration::from_micros(400),
                dc: true,
            },
            &vars,
            50,
            &mut csv,
            &mut |k, _| last = k,
        )
        .unwrap();
    assert_eq!(stats.cycles, 50);
    assert_eq!(last, 50);
    let text = String::from_utf8(csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "cycle,time [s],0.InINT32Var1 [DINT],1.InINT16Var1 [INT]"
    );
    assert_eq!(lines.len(), 51);
    let t = |k: usize| -> f64 { lines[k].split(',').nth(1).unwrap().parse().unwrap() };
    assert_eq!(t(1), 0.0);
    let dt = t(40) - t(30);
    assert!(
        (dt - 0.004).abs() < 1e-7,
        "DC cycle of 400 µs (DC system time): {dt}"
    );
}

#[test]
fn sii_write_verifies_refuses_other_device_and_bad_crc() {
    let (m, seg, _fws, _) = common::demo_master(1);
    let mut img = oxicat_esi::sii::generate(&oxicat_devices::demo::DEF).unwrap();
    // A changed serial number (same identity otherwise) is written and verified.
    img[0x1C] = 0x42;
    let mut calls = 0;
    m.sii_write(0, &img, Default::default(), &mut |_, _| calls += 1)
        .unwrap();
    assert_eq!(calls, img.len() / 2);
    assert_eq!(
        &seg.lock().unwrap().esc(0).unwrap().eeprom()[..img.len()],
        &img[..]
    );
    assert_eq!(m.sii_read(0, false).unwrap()[0x1C], 0x42);

    // Another device's image (product code changed) is refused without force.
    let mut other = img.clone();
    other[0x14] ^= 0xFF;
    match m.sii_write(0, &other, Default::default(), &mut |_, _| {}) {
        Err(e @ MasterError::SiiOtherDevice { .. }) => {
            assert!(e.to_string().contains("--force"), "{e}")
        }
        r => panic!("expected a refusal, got {r:?}"),
    }
    m.sii_write(
        0,
        &other,
        oxicat_master::sii::WriteOptions { force: true },
        &mut |_, _| {},
    )
    .unwrap();

    // A corrupted configuration area is rejected before anything is written.
    let mut bad = img.clone();
    bad[4] ^= 1;
    assert!(matches!(
        m.sii_write(0, &bad, Default::default(), &mut |_, _| {}),
        Err(MasterError::SiiCrc { .. })
    ));
}

#[test]
fn sdo_download_upload_round_trip() {
    let (m, _seg, _fws, _) = common::demo_master(1);
    // 0x10F1:02 UINT (rw).
    for v in [7u16, 0xBEEF] {
        m.sdo_download(0, 0x10F1, 2, &v.to_le_bytes()).unwrap();
        assert_eq!(m.sdo_upload(0, 0x10F1, 2).unwrap(), v.to_le_bytes());
    }
    // A value too long for the object: decoded abort.
    match m.sdo_download(0, 0x10F1, 2, &[1, 2, 3, 4, 5, 6]) {
        Err(e @ MasterError::SdoAbort { .. }) => assert!(e.to_string().contains("0x0607"), "{e}"),
        r => panic!("expected an abort, got {r:?}"),
    }
    // Writing a read-only object.
    match m.sdo_download(0, 0x1018, 1, &1u32.to_le_bytes()) {
        Err(e @ MasterError::SdoAbort { .. }) => {
            assert!(e.to_string().contains("read only"), "{e}")
        }
        r => panic!("expected an abort, got {r:?}"),
    }
}

#[test]
fn errors_have_clear_messages() {
    let e = oxicat_master::Master::open(oxicat_master::Link::Iface("nosuchif0".into()))
        .err()
        .unwrap();
    assert!(e.to_string().contains("does not exist"), "{e}");
    let seg = std::sync::Arc::new(std::sync::Mutex::new(oxicat_sim::segment::Segment::<
        oxicat_esc::Esc,
    >::new()));
    let e = oxicat_master::Master::open(oxicat_master::Link::Sim(seg))
        .err()
        .unwrap();
    assert!(e.to_string().contains("no slaves"), "{e}");
    let e = ValueType::U8.encode("300").unwrap_err();
    assert!(e.to_string().contains("not valid for type u8"), "{e}");
    let (m, _seg, _fws, _) = common::demo_master(1);
    let e = m.sdo_upload(3, 0x1018, 1).unwrap_err();
    assert!(e.to_string().contains("no slave at position 3"), "{e}");
}

#[test]
fn alias_is_written_with_the_crc_and_reloaded_into_0x0012() {
    let (m, seg, _fws, _) = common::demo_master(2);
    assert_eq!(m.sii_set_alias(1, 0x1234).unwrap(), 0x1234);
    // SII word 4 holds it, the configuration area still checks (what ESCs load at power-up).
    let img = m.sii_read(1, false).unwrap();
    assert_eq!(&img[8..10], &[0x34, 0x12]);
    oxicat_master::sii::check_image(&img).unwrap();
    assert!(
        oxicat_master::sii::decode(&img)
            .unwrap()
            .contains("Station alias:   0x1234"),
        "{}",
        oxicat_master::sii::decode(&img).unwrap()
    );
    assert_eq!(
        &seg.lock().unwrap().esc(1).unwrap().eeprom()[8..10],
        &[0x34, 0x12]
    );
    // The other slave is untouched; a new master (the next command) lists the alias.
    assert_eq!(&m.sii_read(0, false).unwrap()[8..10], &[0, 0]);
    drop(m);
    let m = oxicat_master::Master::open(oxicat_master::Link::Sim(seg.clone())).unwrap();
    let list = m.scan().unwrap();
    assert_eq!((list[0].alias, list[1].alias), (0, 0x1234));
    assert!(matches!(
        m.sii_set_alias(2, 1),
        Err(MasterError::NoSuchSlave { .. })
    ));
}

/// An explicit SM-synchronous run: every slave in OP with 0x1C32:01 = 1, its stack running
/// the cycle on the SM2 event; `CycleOptions` alone (Auto) keeps free run on the demo.
#[test]
fn an_explicit_sync_mode_reaches_the_slaves() {
    use oxicat_master::cyclic::{Flow, SyncMode};
    use oxicat_slave::SyncMode as Slave;
    let (mut m, seg, fws, _) = common::demo_master(2);
    let opts = CycleOptions {
        cycle: Duration::from_millis(1),
        dc: false,
    };
    let mut seen = Vec::new();
    let stats = m
        .run_cyclic(opts.with_sync(SyncMode::SmSync), |io| {
            if io.cycle == 20 {
                seen = fws.iter().map(|f| f.lock().slave.sync_mode()).collect();
                return Ok(Flow::Stop);
            }
            Ok(Flow::Continue)
        })
        .unwrap();
    assert_eq!((stats.cycles, stats.wkc_errors), (21, 0));
    assert_eq!(seen, vec![Slave::SmSync, Slave::SmSync]);
    for p in 0..2 {
        assert_eq!(m.sdo_upload(p, 0x1C32, 1).unwrap(), 1u16.to_le_bytes());
    }
    // The default (Auto, no DC) sets the demo, which offers free run, back to free run (a
    // master cycles once: a new one on the same segment).
    let mut m = oxicat_master::Master::open(oxicat_master::Link::Sim(seg)).unwrap();
    let mut mode = None;
    m.run_cyclic(opts, |io| {
        if io.cycle == 5 {
            mode = Some(fws[0].lock().slave.sync_mode());
            return Ok(Flow::Stop);
        }
        Ok(Flow::Continue)
    })
    .unwrap();
    assert_eq!(mode, Some(Slave::FreeRun));
    assert_eq!(m.sdo_upload(0, 0x1C32, 1).unwrap(), 0u16.to_le_bytes());
    // An explicit mode without DC and `dc` set contradict: refused before anything runs.
    let e = CycleOptions {
        cycle: Duration::from_millis(1),
        dc: true,
    }
    .with_sync(SyncMode::FreeRun)
    .check()
    .unwrap_err();
    assert!(e.to_string().contains("contradict"), "{e}");
}

/// A slave whose 0x1C32:04 does not offer the mode asked for stops the run before any slave
/// is changed, naming the slave and what it offers.
#[test]
fn a_sync_mode_a_slave_does_not_offer_is_refused_naming_it() {
    use oxicat_devices::demo::{self, Demo};
    use oxicat_esc::{Esc, EscConfig};
    use oxicat_master::cyclic::SyncMode;
    use oxicat_master::{Link, Master};
    use oxicat_sim::firmware::{attach_firmware, FirmwareConfig};
    // Slave 0 the demo (all modes), slave 1 the demo offering free run only.
    let mut free_only = demo::DEF;
    free_only.sync.supported = 0x0001;
    let free_only: &'static _ = Box::leak(Box::new(free_only));
    let mut seg = oxicat_sim::segment::Segment::new();
    let mut fws = Vec::new();
    for def in [&demo::DEF, free_only] {
        let sii = oxicat_esi::sii::generate(def).expect("SII");
        let id = seg.add(Esc::new(EscConfig::et1100(), sii));
        let app = Demo::new(common::SharedLeds::default(), common::FixedButtons(0));
        fws.push(
            attach_firmware::<_, { demo::IMAGE }, { common::MBX }>(
                &mut seg,
                id,
                def,
                app,
                &FirmwareConfig::default(),
            )
            .expect("firmware boots"),
        );
    }
    let mut m = Master::open(Link::Sim(std::sync::Arc::new(std::sync::Mutex::new(seg)))).unwrap();
    let opts = CycleOptions {
        cycle: Duration::from_millis(1),
        dc: false,
    };
    for mode in [SyncMode::SmSync, SyncMode::Dc] {
        let e = m.run_cycles(opts.with_sync(mode), 5).unwrap_err();
        match &e {
            MasterError::SyncModeUnsupported {
                position,
                supported,
                ..
            } => assert_eq!((*position, *supported), (1, Some(0x0001)), "{e}"),
            e => panic!("{mode:?}: {e}"),
        }
        let text = e.to_string();
        assert!(
            text.contains("slave 1") && text.contains("0x1C32:04 = 0x0001: free run"),
            "{text}"
        );
        // Slave 0 was not changed.
        assert_eq!(m.sdo_upload(0, 0x1C32, 1).unwrap(), 0u16.to_le_bytes());
        assert_eq!(
            fws[0].lock().slave.sync_mode(),
            oxicat_slave::SyncMode::FreeRun
        );
    }
    // What both offer runs.
    let stats = m.run_cycles(opts.with_sync(SyncMode::FreeRun), 10).unwrap();
    assert_eq!((stats.cycles, stats.wkc_errors), (10, 0));
}

/// A segment that notes the thread every frame goes through it on.
struct ThreadNoting {
    seg: std::sync::Arc<std::sync::Mutex<oxicat_sim::segment::Segment>>,
    threads: std::sync::Arc<std::sync::Mutex<Vec<std::thread::ThreadId>>>,
}

impl oxicat_wire::pipe::FramePipe for ThreadNoting {
    fn exchange_in_place(&mut self, frame: &mut [u8]) -> bool {
        self.threads
            .lock()
            .unwrap()
            .push(std::thread::current().id());
        oxicat_wire::pipe::FramePipe::exchange_in_place(&mut *self.seg.lock().unwrap(), frame)
    }
    fn now(&self) -> u64 {
        oxicat_wire::pipe::FramePipe::now(&*self.seg.lock().unwrap())
    }
    fn advance_to(&mut self, t: u64) {
        oxicat_wire::pipe::FramePipe::advance_to(&mut *self.seg.lock().unwrap(), t)
    }
    fn clock(&self) -> &'static dyn oxicat_wire::pipe::VirtualClock {
        oxicat_wire::pipe::FramePipe::clock(&*self.seg.lock().unwrap())
    }
}

/// On a virtual segment the master carries its frames itself, on the thread that calls
/// it (no transport thread to hand each frame to and back: that hand-over was most of
/// the CPU of a verb on `--sim`), through discovery, mailbox traffic and state changes.
#[test]
fn frames_go_through_the_virtual_segment_on_the_callers_thread() {
    let (seg, _fws, _) = common::demo_segment(2);
    let threads = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let pipe = ThreadNoting {
        seg,
        threads: threads.clone(),
    };
    let mut m = oxicat_master::Master::open(oxicat_master::Link::Sim(std::sync::Arc::new(
        std::sync::Mutex::new(pipe),
    )))
    .expect("master opens");
    m.sdo_upload(0, 0x1018, 1).expect("vendor id");
    m.request_state(&[0, 1], AlState::Op).expect("to OP");
    let me = std::thread::current().id();
    let seen = threads.lock().unwrap().clone();
    assert!(seen.len() > 50, "{} frames", seen.len());
    assert!(
        seen.iter().all(|&t| t == me),
        "{} of {} frames on another thread",
        seen.iter().filter(|&&t| t != me).count(),
        seen.len()
    );
}
