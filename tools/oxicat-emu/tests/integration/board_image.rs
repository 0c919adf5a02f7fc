//! The STM32F446 + LAN9252 board image (`firmware/stm32f446-lan9252`, the demo device), the
//! bytes that would be flashed, executed instruction by instruction: it boots, brings the
//! LAN9252 up over the emulated SPI1, and its slave stack answers a master on the ECAT side
//! (INIT → PREOP, an SDO upload of 0x1018:01); hung in OP on purpose (its hang jumper), its
//! independent watchdog resets it into INIT, it reports the reset with a CoE emergency, and
//! a master brings it back to OP.

use oxicat_emu::{Board, EmuError};
use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::sim::{BusConfig, Lan9252Model};

use crate::common;

/// The board image (`firmware/stm32f446-lan9252`, or `OXICAT_BOARD_IMAGE`).
fn image() -> Option<Vec<u8>> {
    common::image("stm32f446-lan9252", "OXICAT_BOARD_IMAGE")
}

use common::Direct as Master;

fn boot() -> Option<(Board, Master)> {
    let img = image()?;
    let def = &oxicat_devices::demo::DEF;
    let esc = Esc::new(EscConfig::lan9252(), oxicat_testkit::device::eeprom(def));
    let chip = Lan9252Model::handle(esc, BusConfig::mhz(22));
    let board = Board::new(&img, chip.clone()).expect("the image loads");
    Some((board, Master { chip: chip.into() }))
}

#[test]
fn the_demo_board_image_boots_reaches_preop_and_answers_an_sdo() {
    let Some((mut b, m)) = boot() else { return };
    // Boot: clocks, the 50 ms power-on wait on SysTick, the LAN9252's init over SPI and the
    // stack's start-up, until the image is in its main loop (the stack polls AL control
    // over SPI every pass: the frame count keeps rising).
    let up = b
        .run_until(200_000, 100_000_000, |b| b.spi_stats().frames > 200)
        .unwrap_or_else(|e| panic!("{e}"));
    let s = b.spi_stats();
    assert!(
        up,
        "the image did not reach its main loop: {s:?}, PC {:#010x}",
        b.pc()
    );
    assert_eq!(s.bytes_without_cs, 0, "every byte inside a CS frame");
    assert!(
        b.time_ns() >= 50_000_000,
        "the 50 ms power-on wait ran on SysTick"
    );
    // That wait spins on SysTick's COUNTFLAG: skipped forward, not emulated (most of its
    // 9 M cycles at 180 MHz).
    assert!(
        b.polled_cycles() >= 40 * 180_000,
        "the delay loop was emulated in full: {} cycles skipped, {} instructions",
        b.polled_cycles(),
        b.instructions()
    );
    assert_eq!(
        m.chip.stats().protocol_errors,
        0,
        "the chip saw only well-formed frames"
    );
    assert_eq!(m.al_status(&b) & 0x1F, 0x01, "INIT after start-up");

    // Mailbox SMs as the SII says (demo: 0x1000 / 0x1080, 128 bytes), then PREOP.
    let sm = |start: u16, ctrl: u8| {
        let mut r = [0u8; 8];
        r[..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&128u16.to_le_bytes());
        r[4] = ctrl;
        r[6] = 1; // enable
        r
    };
    m.wr(&b, 0x0800, &sm(0x1000, 0x26));
    m.wr(&b, 0x0808, &sm(0x1080, 0x22));
    m.wr(&b, 0x0120, &2u16.to_le_bytes());
    let preop = b
        .run_until(50_000, 20_000_000, |b| m.al_status(b) & 0x1F == 0x02)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(preop, "AL status {:#06x}", m.al_status(&b));

    // SDO upload 0x1018:01 (vendor ID): mailbox header, CoE header (SDO request), expedited
    // initiate-upload request.
    let mut req = vec![0u8; 128];
    req[..6].copy_from_slice(&[10, 0, 0, 0, 0, 0x13]); // len 10, CoE, counter 1
    req[6..8].copy_from_slice(&0x2000u16.to_le_bytes());
    req[8..16].copy_from_slice(&[0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0]);
    m.wr(&b, 0x1000, &req);
    let full = |b: &mut Board| m.rd(b, 0x080D, 1)[0] & 0x08 != 0;
    let answered = b
        .run_until(50_000, 20_000_000, full)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(answered, "no SDO response from the image");
    let resp = m.rd(&b, 0x1080, 128);
    assert_eq!(resp[5] & 0x0F, 0x03, "a CoE reply");
    assert_eq!(
        u16::from_le_bytes([resp[6], resp[7]]) >> 12,
        3,
        "SDO response"
    );
    assert_eq!(resp[8], 0x43, "expedited upload of 4 bytes");
    let vendor = u32::from_le_bytes([resp[12], resp[13], resp[14], resp[15]]);
    assert_eq!(vendor, oxicat_devices::demo::DEF.identity.vendor_id);
    eprintln!(
        "image: {} instructions, {:.1} ms simulated, SPI {:?}",
        b.instructions(),
        b.time_ns() as f64 * 1e-6,
        b.spi_stats()
    );
}

#[test]
fn a_corrupt_image_is_a_fault_with_its_pc_not_a_hang() {
    let Some(mut img) = image() else { return };
    // Point the reset vector at an address no block maps: the first fetch faults.
    let segs = oxicat_emu::elf_segments(&img).unwrap();
    let flash = &segs[0];
    let vt = img
        .windows(flash.data.len().min(64))
        .position(|w| w == &flash.data[..flash.data.len().min(64)])
        .expect("the vector table is in the file");
    img[vt + 4..vt + 8].copy_from_slice(&0x3000_0001u32.to_le_bytes());
    let esc = Esc::new(
        EscConfig::lan9252(),
        oxicat_testkit::device::eeprom(&oxicat_devices::demo::DEF),
    );
    let mut b = Board::new(&img, Lan9252Model::handle(esc, BusConfig::mhz(22))).unwrap();
    match b.run(1000) {
        Err(EmuError::Fault { pc, reason }) => {
            assert_eq!(pc & !1, 0x3000_0000, "{reason}");
            assert!(
                reason.contains("FETCH") || reason.contains("UNMAPPED"),
                "{reason}"
            );
        }
        other => panic!("expected a fault, got {other:?}"),
    }
}

/// The machine-code route on the virtual segment: two demo boards, each its image on an
/// emulated STM32F446 with a LAN9252, under ethercrab (through `oxicat-master`): both reach
/// OP and exchange process data for 1,000 cycles with the right working counter each cycle.
#[test]
fn ethercrab_runs_two_emulated_demo_boards_in_op_with_the_right_wkc() {
    demo_boards_in_op(1_000);
}

/// The long run: 10,000 free-run cycles of 1 ms (`cargo test -p oxicat-emu --test
/// board_image -- --ignored`).
#[test]
#[ignore = "long: 10,000 cycles of two emulated boards"]
fn ethercrab_runs_two_emulated_demo_boards_for_10000_cycles() {
    demo_boards_in_op(10_000);
}

/// Two emulated demo boards in OP (free run, the demo's mode) for `cycles` cycles of 1 ms:
/// the right working counter every cycle.
fn demo_boards_in_op(cycles: u64) {
    use oxicat_master::cyclic::CycleOptions;
    use oxicat_master::{Link, Master};
    use oxicat_sim::segment::Segment;
    use std::sync::{Arc, Mutex};

    let Some(img) = image() else { return };
    let def = &oxicat_devices::demo::DEF;
    let mut seg = Segment::new();
    for _ in 0..2 {
        let sii = oxicat_esi::sii::generate(def).unwrap();
        let id = seg.add(Esc::new(EscConfig::lan9252(), sii));
        let node = oxicat_emu::node::EmulatedNode::new(img.clone(), 100_000).unwrap();
        seg.attach(id, Box::new(node)).unwrap();
    }
    let wall = std::time::Instant::now();
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).expect("ethercrab scans");
    let stats = m
        .run_cycles(
            CycleOptions {
                cycle: std::time::Duration::from_millis(1),
                dc: false,
            },
            cycles,
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((stats.cycles, stats.wkc_errors), (cycles, 0), "{stats:?}");
    eprintln!(
        "two emulated boards: {cycles} cycles of 1 ms in OP, {:.1} s wall",
        wall.elapsed().as_secs_f64()
    );
}

/// A firmware stuck in a loop, as a master sees it: the ESC keeps answering and the AL
/// status stays where the firmware left it, but the PDI watchdog (0x0410, 100 ms by
/// default) is no longer retriggered — DL status 0x0110 bit 1 clears and the PDI watchdog
/// counter 0x0443 counts the expiry. (The SM watchdog 0x001B path needs a live firmware:
/// the ESC's process-data watchdog is retriggered by the master's writes, not by the MCU.)
/// The healthy demo image on the same segment keeps bit 1 set.
#[test]
fn a_stuck_firmware_shows_as_an_expired_pdi_watchdog() {
    use oxicat_sim::segment::Segment;
    use oxicat_wire::frame::FrameBuilder;
    use oxicat_wire::{Command, DatagramHeader, EcatFrame, EthernetHeader};

    let Some(healthy) = image() else { return };
    let def = &oxicat_devices::demo::DEF;
    let mut seg = Segment::new();
    let stuck = include_bytes!("../asm/stuck.elf").to_vec();
    for img in [stuck, healthy] {
        let sii = oxicat_esi::sii::generate(def).unwrap();
        let id = seg.add(Esc::new(EscConfig::lan9252(), sii));
        let node = oxicat_emu::node::EmulatedNode::new(img, 100_000).unwrap();
        seg.attach(id, Box::new(node)).unwrap();
    }
    // A master's APRD of `len` bytes at `ado` of the slave at position `p`.
    let aprd = |seg: &mut Segment, p: u16, ado: u16, len: u16| -> Vec<u8> {
        let mut buf = vec![0u8; 128];
        let eth = EthernetHeader {
            dst: [0xFF; 6],
            src: [0x10; 6],
            vlan_tci: None,
            payload_offset: 14,
        };
        let mut fb = FrameBuilder::new(&mut buf, &eth).unwrap();
        fb.push(
            DatagramHeader::physical(Command::Aprd, 0, 0u16.wrapping_sub(p), ado, len),
            &vec![0; usize::from(len)],
        )
        .unwrap();
        let n = fb.finish();
        let back = seg.exchange(&buf[..n]).expect("the frame comes back");
        let (_, f) = EcatFrame::parse_ethernet(&back).unwrap();
        let d = f.datagrams().next().unwrap().unwrap();
        assert_eq!(d.wkc, 1, "APRD {ado:#06x} of slave {p}");
        d.data.to_vec()
    };
    // 60 ms: both boards have accessed their ESC (the demo image after its 50 ms power-on
    // wait), within the first watchdog time of the stuck board's one access.
    seg.advance_to(60_000_000);
    assert_eq!(
        aprd(&mut seg, 0, 0x0110, 2)[0] & 2,
        2,
        "reloaded by the one access"
    );
    assert_eq!(aprd(&mut seg, 1, 0x0110, 2)[0] & 2, 2);
    seg.advance_to(250_000_000);
    assert_eq!(
        aprd(&mut seg, 0, 0x0110, 2)[0] & 2,
        0,
        "stuck: the PDI watchdog expired"
    );
    assert_eq!(aprd(&mut seg, 0, 0x0443, 1)[0], 1, "one expiry counted");
    assert_eq!(
        aprd(&mut seg, 1, 0x0110, 2)[0] & 2,
        2,
        "the healthy image keeps accessing its ESC"
    );
    assert_eq!(aprd(&mut seg, 1, 0x0443, 1)[0], 0);
    assert_eq!(
        aprd(&mut seg, 0, 0x0130, 2),
        [1, 0],
        "the AL status stays where the firmware left it"
    );
}

/// The demo image's independent watchdog, as a master sees it: in OP with the hang jumper
/// (PC0 to GND) the image stops in a loop that neither feeds the IWDG nor touches the ESC;
/// 200 ms later (25 ticks of 8 ms at the LSI's nominal 32 kHz) the IWDG resets the MCU — the
/// ESC, a chip of its own, is not reset and keeps its station address — and the restarted
/// image puts the ESC back in INIT. With the jumper off the master requests PREOP, finds the
/// emergency 0x6010 "software reset (watchdog)" (RCC_CSR's IWDGRSTF and PINRSTF in its
/// data) in SM1, and brings the board back to OP.
#[test]
fn a_demo_image_hung_in_op_is_reset_by_its_watchdog_and_the_master_brings_it_back() {
    use oxicat_master::{AlState, Link, Master};
    use oxicat_sim::segment::Segment;
    use std::sync::{Arc, Mutex};

    let Some(img) = image() else { return };
    let def = &oxicat_devices::demo::DEF;
    let seg = Arc::new(Mutex::new(Segment::new()));
    let node = oxicat_emu::node::EmulatedNode::new(img, 100_000).unwrap();
    let board = node.handle();
    {
        let mut s = seg.lock().unwrap();
        let id = s.add(Esc::new(
            EscConfig::lan9252(),
            oxicat_esi::sii::generate(def).unwrap(),
        ));
        s.attach(id, Box::new(node)).unwrap();
        // Booted (the image resets its LAN9252 at start-up) before the master scans.
        s.advance_to(100_000_000);
    }
    let now = || seg.lock().unwrap().now();
    let wall = std::time::Instant::now();
    let advance = |dt: u64| {
        let mut s = seg.lock().unwrap();
        let t = s.now() + dt;
        s.advance_to(t);
    };
    let mut m = Master::open(Link::Sim(seg.clone())).expect("the master scans");
    let op = |m: &mut Master| {
        let st = m.request_state(&[0], AlState::Op).expect("OP requested");
        assert_eq!(st[0].1.state(), Some(AlState::Op), "{:?}", st[0].1);
    };
    op(&mut m);
    advance(50_000_000);
    assert_eq!(m.al_status(0).unwrap().state(), Some(AlState::Op));
    assert_eq!(board.report().unwrap().watchdog_resets, 0, "fed in OP");

    board.set_input('C', 0, false); // the hang jumper on
    let hung_at = now();
    for _ in 0..30 {
        advance(10_000_000);
        if board.report().unwrap().watchdog_resets > 0 {
            break;
        }
    }
    let r = board.report().unwrap();
    assert_eq!(r.fault, None);
    assert_eq!(r.watchdog_resets, 1, "the IWDG reset the hung image once");
    let after = r.last_watchdog_reset_ns.unwrap() - hung_at;
    assert!(
        (199_900_000..200_100_000).contains(&after),
        "reset {after} ns after the hang, not the 200 ms the image configured"
    );
    board.set_input('C', 0, true); // the jumper off
    advance(100_000_000);
    let st = m.al_status(0).unwrap();
    assert_eq!(
        st.state(),
        Some(AlState::Init),
        "the restarted image is in INIT: {st:?}"
    );

    // PREOP: the mailbox runs and the image's first message is the emergency.
    let st = m.request_state(&[0], AlState::PreOp).unwrap();
    assert_eq!(st[0].1.state(), Some(AlState::PreOp), "{:?}", st[0].1);
    let mut full = false;
    for _ in 0..100 {
        advance(1_000_000);
        full = m.reg_read(0, 0x080D, 1).unwrap()[0] & 0x08 != 0;
        if full {
            break;
        }
    }
    assert!(full, "nothing in SM1 within 100 ms of PREOP");
    let mbx = m.reg_read(0, 0x1080, 128).unwrap();
    assert_eq!(mbx[5] & 0x0F, 0x03, "a CoE message: {:02x?}", &mbx[..16]);
    assert_eq!(
        u16::from_le_bytes([mbx[6], mbx[7]]) >> 12,
        1,
        "an emergency"
    );
    assert_eq!(
        u16::from_le_bytes([mbx[8], mbx[9]]),
        0x6010,
        "software reset (watchdog)"
    );
    assert_eq!(mbx[11], 0x24, "RCC_CSR flags: IWDGRSTF | PINRSTF");

    op(&mut m);
    advance(250_000_000);
    assert_eq!(m.al_status(0).unwrap().state(), Some(AlState::Op));
    let r = board.report().unwrap();
    assert_eq!(
        (r.watchdog_resets, r.fault),
        (1, None),
        "back in OP and fed"
    );
    eprintln!(
        "hung at {:.1} ms, reset {:.3} ms later, back in OP: {:.1} s wall",
        hung_at as f64 * 1e-6,
        after as f64 * 1e-6,
        wall.elapsed().as_secs_f64()
    );
}
